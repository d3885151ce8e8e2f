"""The spatial model against an independent computation: the rigid-element chain of
``tests/model/spatial_reference.py`` (a discrete geometrically exact rod, its equations derived
by CasADi from the Lagrangian), extrapolated in its element count (``fine + (fine - coarse) /
3`` from 10 and 20 elements, the chain converging as ``h^2``).

Four cases, each tip component whose peak is not negligible compared relative to its own peak,
the tips computed alike by both models (each tip's displacement from where the rigidly moving
undeformed tip would be, in hub-frame components):

- two rods on a hub with products of inertia (one with a tip mass, one whose section is
  tilted), a one-period sine torque about all three axes;
- one array of the example scenes (``examples/scenes/spatial-two-arrays.toml``: soft along
  its normal, 100 times stiffer laterally, a tip mass) on that hub under a bang-bang torque
  about two axes, its jumps on the integrations' breakpoints;
- three rods (two arrays, one bending out of the other's plane, and a round boom along ``z``)
  on a free hub with mass: tips and the hub centre's path (its first 0.6 s);
- two arrays on a hub spinning at 3 rad/s about ``z`` under a transverse torque pulse
  (``examples/scenes/spatial-spin.toml``, shortened).

What limits the comparison is the reference. Its histories converge as ``h^2`` but a
component that vibrates at a high frequency (the stiff lateral plane of an array, about
100 rad/s with the hub, after a torque's jumps) carries a phase error growing in time, and
the extrapolation removes it only to first order: 1 % of that component's peak left by the
10/20 extrapolation at 1.5 s, 0.1 % by 20/40 (the bang-bang case, whose 20/40 errors are in
its test's docstring: 44 s of processor time, not repeated in the suite). The assertions rest
on the 10/20 extrapolation.
The chain runs with a joint-rate tolerance of 1e-6 rad/s (cheaper than its default 1e-8):
measured at 10 elements, it moves the compared components by at most 2.9e-4
of their peaks.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from spatial_reference import chain_response  # noqa: E402

from flexctl.model.parameters import PointMass  # noqa: E402
from flexctl.model.spatial_structure import (SpatialAppendage, SpatialHub,  # noqa: E402
                                             SpatialStructure)
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial  # noqa: E402

#: The modal model (3 modes per field) within this of the extrapolated chain, relative to each
#: tip component's peak, in the sine case. Measured: 5.3e-4 at most (1.1e-4 to 5.3e-4 over the
#: six components), where the 20-element chain alone is 1.5e-3 to 5.2e-3 from the
#: extrapolation.
AGREEMENT = 2e-3
#: Components whose peak is below this fraction of their tip's largest are not compared
#: (a foreshortening of microns under a bending of centimetres).
NEGLIGIBLE = 1e-3
#: Elements of the chain's two runs.
ELEMENTS = (10, 20)
#: The chain's tolerance on the joint rates (and the hub's angular velocity) in the new
#: cases, rad/s (see the module's description).
CHAIN_ATOL_RATE = 1e-6
#: Modes per field of the modal model in the new cases (simulate_spatial's default).
MODES = 4

RHO, AREA, E, G = 2766.0, 2.5e-4, 6.9e10, 2.6e10
#: ``(I_n, I_l, J)`` of the sine case's rods, m^4.
ROD = (1.3021e-10, 5.2e-9, 5e-10)
#: ``(I_n, I_l, J)`` of the example scenes' arrays (100 times stiffer laterally), m^4.
ARRAY = (5.2083e-10, 5.2083e-8, 1.9531e-9)
#: ``(I_n, I_l, J)`` of a round boom, m^4.
ROUND = (5.2083e-10, 5.2083e-10, 1.0417e-9)
INERTIA = np.array([[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]])
PEAK = np.array([0.4, -0.3, 0.8])
DURATION = 1.0


def rod(name, root, direction, normal, masses=(), length=1.8, section=ARRAY) -> dict:
    """One appendage of a case: ``masses`` as ``(kg, arc length m)``, ``section`` as
    ``(I_n, I_l, J)`` m^4, aluminium."""
    return {"name": name, "root": root, "direction": direction, "normal": normal,
            "masses": tuple(masses), "length": length, "section": section}


RODS = [rod("a", (0.06, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), [(0.085, 1.62)],
            section=ROD),
        rod("b", (0.0, 0.06, 0.0), (0.0, 1.0, 0.0), (0.6, 0.0, 0.8), section=ROD)]


def torque(t):
    return PEAK * np.sin(2 * np.pi * t / DURATION) if t <= DURATION else np.zeros(3)


class _Sine:
    """The same torque with its breakpoint and segment form for the modal run."""

    breakpoints = np.array([DURATION])

    def __call__(self, t):
        return torque(t)

    def segment_form(self, a, b):
        inside = b <= DURATION + 1e-12
        return np.concatenate([np.zeros(6), PEAK if inside else np.zeros(3),
                               [2 * np.pi / DURATION, a]])


def _structure(rods=RODS, inertia=INERTIA, hub_mass=None):
    hub = SpatialHub(inertia=inertia, radius=0.06, mass=hub_mass or 0.0,
                     support="pinned" if hub_mass is None else "free")
    return SpatialStructure(hub=hub, appendages=tuple(
        SpatialAppendage(name=r["name"], direction=r["direction"], normal=r["normal"],
                         root=r["root"], length=r["length"], density=RHO, area=AREA,
                         youngs_modulus=E, second_moment=r["section"][0],
                         second_moment_lateral=r["section"][1], shear_modulus=G,
                         torsion_constant=r["section"][2],
                         masses=tuple(PointMass(mass=m, position=p) for m, p in r["masses"]))
        for r in rods))


def _chain_rods(rods=RODS):
    return [{"name": r["name"], "root": r["root"], "direction": r["direction"],
             "normal": r["normal"], "length": r["length"], "rhoA": RHO * AREA,
             "EI_n": E * r["section"][0], "EI_l": E * r["section"][1],
             "GJ": G * r["section"][2], "rho_Ip": RHO * (r["section"][0] + r["section"][1]),
             "masses": list(r["masses"])}
            for r in rods]


def _relative(reference, values):
    """Largest difference of each row, relative to that row of the reference's peak (NaN where
    the peak is negligible)."""
    peaks = np.max(np.abs(reference), axis=1)
    error = np.max(np.abs(values - reference), axis=1) / peaks
    return np.where(peaks > NEGLIGIBLE * np.max(peaks), error, np.nan)


def _against_chain(rods, torque, t_final, *, inertia=INERTIA, spin=(0.0, 0.0, 0.0),
                   hub_mass=None, modes=(MODES,), atol_rate=CHAIN_ATOL_RATE):
    """The modal model and the extrapolated chain on one case.

    Returns
    -------
    dict
        ``tips``: ``{modes: {name: (3,) error relative to each component's peak}}``;
        ``position``: ``{modes: (3,) error of the hub centre's path relative to each
        coordinate's peak}`` (free hub); ``chain`` and ``results``: the fine chain run and the
        modal runs.
    """
    times = np.round(np.arange(0.0, t_final + 0.005, 0.01), 12)
    breakpoints = getattr(torque, "breakpoints", ())
    coarse, fine = (chain_response(inertia, _chain_rods(rods), torque, t_final, times,
                                   angular_velocity=spin, n_elements=n, hub_mass=hub_mass,
                                   breakpoints=breakpoints, atol_rate=atol_rate)
                    for n in ELEMENTS)
    reference = {name: fine["tips"][name] + (fine["tips"][name] - coarse["tips"][name]) / 3
                 for name in fine["tips"]}
    out = {"tips": {}, "position": {}, "chain": fine, "results": {}}
    for n_modes in modes:
        result = simulate_spatial(_structure(rods, inertia, hub_mass), t_final, torque,
                                  n_modes=n_modes, angular_velocity=spin, output_step=0.01,
                                  rtol=1e-9, check_accuracy=False)
        assert result.status == "ok", result.message
        np.testing.assert_allclose(result.t, times, atol=1e-12)
        out["results"][n_modes] = result
        out["tips"][n_modes] = {name: _relative(reference[name], result.tips[name])
                                for name in reference}
        if hub_mass is not None:
            path = fine["position"] + (fine["position"] - coarse["position"]) / 3
            out["position"][n_modes] = np.max(np.abs(result.hub_position - path), axis=1) \
                / np.max(np.abs(path), axis=1)
    return out


def _check(errors: dict, limits: dict):
    """Every compared component within its limit; the limits' NaN (not compared) where the
    component is negligible."""
    for name, error in errors.items():
        limit = np.asarray(limits[name], dtype=float)
        assert np.array_equal(np.isnan(error), np.isnan(limit)), (name, error)
        compared = ~np.isnan(limit)
        assert np.all(error[compared] < limit[compared]), (name, error, limit)


@pytest.mark.slow
def test_tips_agree_with_an_independent_rigid_element_chain():
    """Two rods, a sine torque about three axes, 1.5 s (the chain at its default tolerances).
    Measured against the 10/20 extrapolation: 3 modes 1.1e-4 to 5.3e-4, 4 modes 1.6e-5 to
    2.3e-4 of each component's peak."""
    out = _against_chain(RODS, _Sine(), 1.5, modes=(3, MODES), atol_rate=1e-8)
    for n_modes in (3, MODES):
        for name, error in out["tips"][n_modes].items():
            assert np.all(error[~np.isnan(error)] < AGREEMENT), (n_modes, name, error)


#: Bang-bang about x and z (examples/scenes/bang-bang-tilted.csv, in 0.5 s steps), N m.
BANG_BANG = VectorTorque([0.0, 0.5, 1.0], [[0.3, 0.0, 0.4], [-0.3, 0.0, -0.4], [0.0, 0.0, 0.0]],
                         interpolation="hold")
ONE_ARRAY = [rod("wing_a", (0.0, 0.06, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), [(0.085, 1.62)])]


@pytest.mark.slow
def test_one_array_under_a_two_axis_bang_bang_torque():
    """One array along ``y`` (normal ``z``, tip mass) on the hub with products of inertia,
    the torque jumping at 0, 0.5 and 1 s, 1.5 s. Peaks: tip ``x`` (lateral, the stiff plane)
    0.16 mm, ``y`` (axial) 0.04 mm, ``z`` (normal) 11 mm. Measured, modal model (4 modes)
    against the 20/40 extrapolation: lateral 1.1e-3, axial 1.2e-4, normal 5.4e-5; against the
    10/20 extrapolation the test compares with: 1.0e-2, 2.3e-4, 2.3e-4 (the lateral
    component's is the extrapolation's: it vibrates at about 100 rad/s, whose phase error the
    10/20 extrapolation leaves at 1 %)."""
    out = _against_chain(ONE_ARRAY, BANG_BANG, 1.5)
    _check(out["tips"][MODES], {"wing_a": (2e-2, AGREEMENT, AGREEMENT)})


THREE_RODS = [rod("wing_a", (0.0, 0.06, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), [(0.085, 1.62)]),
              rod("wing_b", (0.0, -0.06, 0.0), (0.0, -1.0, 0.0), (1.0, 0.0, 0.0)),
              rod("boom", (0.0, 0.0, 0.06), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), length=1.0,
                  section=ROUND)]
HUB_MASS = 3.0


@pytest.mark.slow
def test_three_rods_on_a_free_hub():
    """Two arrays (one bending along ``z``, the other along ``x``) and a 1 m round boom along
    ``z`` (torsion constant the polar moment) on a free hub of 3 kg with products of inertia,
    the sine torque about three axes, its first 0.6 s (the chain's two runs take 8 s of
    processor time, the modal model's some 50 s: its boom's torsion, 3.4e4 rad/s at 4 modes,
    holds its steps to 10 us). Tips and the hub centre's path are compared; the centre of mass
    stays at rest in both (the modal model's linear momentum stays zero). Measured, modal
    model (4 modes) against the 10/20 extrapolation: wing_a 2.4e-4, 1.2e-4, 5.7e-5; wing_b
    1.3e-5, 1.4e-5, 3.3e-4; boom 3.6e-5, 5.5e-5 (its axial component, 1e-7 m, not compared);
    the hub centre's path 5.7e-6, 9.1e-7, 7.5e-6 of each coordinate's peak."""
    out = _against_chain(THREE_RODS, _Sine(), 0.6, hub_mass=HUB_MASS)
    _check(out["tips"][MODES], {"wing_a": (AGREEMENT,) * 3, "wing_b": (AGREEMENT,) * 3,
                                "boom": (AGREEMENT, AGREEMENT, np.nan)})
    assert np.all(out["position"][MODES] < AGREEMENT), out["position"][MODES]
    centre = out["chain"]["centre_of_mass"]
    assert np.ptp(centre, axis=1).max() < 1e-8
    linear = out["results"][MODES].momentum()[1]
    # zero but for the integration's error (exponential steps at rtol 1e-9: 1.9e-9 N s)
    assert np.abs(linear).max() < 1e-8


#: A transverse torque pulse about x, 0.5 s, N m (examples/scenes/spatial-spin.toml).
PULSE = VectorTorque([0.0, 0.5], [[0.5, 0.0, 0.0], [0.0, 0.0, 0.0]], interpolation="hold")
SPINNING_ARRAYS = [rod("wing_a", (0.06, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
                   rod("wing_b", (-0.06, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))]


@pytest.mark.slow
def test_spinning_hub_under_a_transverse_torque():
    """Two arrays along ``x`` and ``-x`` (normals ``z``) on a hub spinning at 3 rad/s about
    ``z`` (principal inertias 1.30, 1.16, 1.45 kg m^2), a torque pulse about ``x``: the spin
    axis nutates, the arrays bend out of the spin plane. 1.5 s. Peaks: tips ``z`` 4.6 mm,
    ``x`` (foreshortening) 6.7 um, ``y`` 4 um (not compared). Measured, modal model (4 modes)
    against the 10/20 extrapolation: 1.7e-4 (x) and 7.9e-5 (z) for both arrays."""
    out = _against_chain(SPINNING_ARRAYS, PULSE, 1.5, inertia=np.diag([1.30, 1.16, 1.45]),
                         spin=(0.0, 0.0, 3.0))
    _check(out["tips"][MODES], {"wing_a": (AGREEMENT, np.nan, AGREEMENT),
                                "wing_b": (AGREEMENT, np.nan, AGREEMENT)})
