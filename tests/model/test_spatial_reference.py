"""Self-checks of the spatial rigid-element chain reference (``tests/model/spatial_reference.py``).

The reference imports nothing from flexctl; these checks judge it against closed forms, the
conservation laws, planar symmetry and the independent planar chain of
``tests/fe_multibody.py``. Fast (about 15 s in all); run with ``-s`` to see the numbers.
"""

import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))

from spatial_reference import (
    ChainSystem,
    _example_appendage,
    chain_frequencies,
    chain_response,
)

#: Cantilever roots ``z_i`` (``omega_i = z_i^2 sqrt(EI / (rhoA l^4))``).
ROOTS = np.array([1.8751040687, 4.6940911330, 7.8547574382])


def exact_frequencies(a: dict) -> dict:
    """Closed-form clamped frequencies of a bare rod, rad/s."""
    scale = a["rhoA"] * a["length"] ** 4
    k = np.arange(1, 4)
    return {"normal": ROOTS ** 2 * np.sqrt(a["EI_n"] / scale),
            "lateral": ROOTS ** 2 * np.sqrt(a["EI_l"] / scale),
            "torsion": (2 * k - 1) * np.pi / (2 * a["length"]) * np.sqrt(a["GJ"] / a["rho_Ip"])}


def test_frequencies_converge_to_closed_forms():
    """Relative errors of the first three modes per family at 20, 40 and 80 elements: they
    fall as ``1 / n^2`` (ratio about 4 per doubling) and are below 1e-4 at 80."""
    bare = _example_appendage(masses=())
    exact = exact_frequencies(bare)
    errors = {n: {f: chain_frequencies(bare, n, count=3)[f] / exact[f] - 1 for f in exact}
              for n in (20, 40, 80)}
    for family in exact:
        print(family, {n: np.array2string(errors[n][family], formatter={"float": "{:.2e}".format})
                       for n in errors})
        e20, e40, e80 = (np.abs(errors[n][family]) for n in (20, 40, 80))
        assert np.all(e40 < e20) and np.all(e80 < e40)
        assert np.all((3.5 < e40 / e80) & (e40 / e80 < 4.5))          # second order
        assert e80[0] < 1e-4 and e80.max() < 1e-3


def test_frequency_families_follow_their_stiffness():
    """Bending along the normal uses EI_n, along the lateral direction EI_l, twist GJ."""
    a = _example_appendage(masses=())
    f = chain_frequencies(a, 12, count=2)
    b = dict(a, EI_n=a["EI_n"] * 4, GJ=a["GJ"] * 9)
    g = chain_frequencies(b, 12, count=2)
    np.testing.assert_allclose(g["normal"], 2 * f["normal"], rtol=1e-12)
    np.testing.assert_allclose(g["lateral"], f["lateral"], rtol=1e-12)
    np.testing.assert_allclose(g["torsion"], 3 * f["torsion"], rtol=1e-12)


def soft_structure():
    """Two soft, obliquely mounted rods with point masses on a hub with products of inertia
    (soft so that twist and both bending planes move a lot in a short, cheap run)."""
    d2 = np.array([-0.2, 1.0, 0.3]) / np.linalg.norm([-0.2, 1.0, 0.3])
    n2 = np.cross(d2, [0.0, 0.0, 1.0])
    n2 /= np.linalg.norm(n2)
    appendages = [
        {"name": "s1", "root": (0.1, 0.05, -0.02), "direction": (1, 0, 0),
         "normal": (0, 0.6, 0.8), "length": 1.0, "rhoA": 1.0, "EI_n": 2.0, "EI_l": 5.0,
         "GJ": 3.0, "rho_Ip": 0.02, "masses": [(0.3, 1.0), (0.1, 0.5)]},
        {"name": "s2", "root": (-0.05, 0.1, 0.03), "direction": d2, "normal": n2,
         "length": 0.8, "rhoA": 0.7, "EI_n": 1.5, "EI_l": 3.0, "GJ": 2.0, "rho_Ip": 0.01,
         "masses": [(0.2, 0.8)]},
    ]
    hub = np.array([[1.2, 0.05, -0.03], [0.05, 1.0, 0.04], [-0.03, 0.04, 0.9]])
    return hub, appendages


def test_spin_conserves_angular_momentum_and_energy():
    """No torque, initial spin about an oblique axis: ``H_N`` (hub, rods and masses about the
    pinned centre, in N) and the energy stay constant to 1e-8 over 2 s, while the tips move
    by centimetres in all three directions."""
    hub, appendages = soft_structure()
    system = ChainSystem(hub, appendages, n_elements=3)
    times = np.linspace(0.0, 2.0, 21)
    sol = system.simulate(lambda t: np.zeros(3), 2.0, times, angular_velocity=(0.6, -0.4, 1.0))
    invariants = [system.invariants(sol.y[:, j]) for j in range(times.size)]
    h0, e0 = invariants[0]
    drift_h = max(np.linalg.norm(h - h0) for h, _ in invariants) / np.linalg.norm(h0)
    drift_e = max(abs(e - e0) for _, e in invariants) / e0
    tips = np.array([[d for d in system.tip_displacements(sol.y[:, j]).values()]
                     for j in range(times.size)])
    print(f"momentum drift {drift_h:.1e}, energy drift {drift_e:.1e}, "
          f"tip motion {np.abs(tips).max(axis=0).round(4).tolist()} m, {sol.stats}")
    assert drift_h < 1e-8 and drift_e < 1e-8
    assert np.abs(tips).max(axis=0).min() > 1e-3        # every tip moves in every direction


@pytest.fixture(scope="module")
def planar_run():
    """MODEL.md's rod (normal along y) on a pinned hub, a one-period sine torque about z
    (10 elements: the planar chain meshes uniformly too, with the mass at 0.9 l on a node)."""
    amplitude, period, t_final, n = 0.5, 1.0, 1.5, 10

    def torque(t):
        return np.array([0.0, 0.0, amplitude * np.sin(2 * np.pi * t / period)
                         if t <= period else 0.0])

    times = np.linspace(0.0, t_final, 31)
    hub = np.array([[1.16, 0.01, 0.0], [0.01, 1.17, 0.0], [0.0, 0.0, 1.16]])
    out = chain_response(hub, [_example_appendage()], torque, t_final, times, n_elements=n)
    return {"out": out, "hub": hub, "torque": torque, "times": times, "n": n}


def test_planar_motion_stays_planar(planar_run):
    """Torque about the axis perpendicular to the bending plane: the tip's out-of-plane
    component, ``w_x``, ``w_y`` and the quaternion's x, y parts stay zero."""
    out = planar_run["out"]
    tip = out["tips"]["a"]
    print(f"tip in-plane peak {np.abs(tip[1]).max():.4f} m, out of plane "
          f"{np.abs(tip[2]).max():.1e} m")
    assert np.abs(tip[1]).max() > 0.05
    assert np.abs(tip[2]).max() <= 1e-12 * np.abs(tip[1]).max()
    assert np.abs(out["w"][:2]).max() <= 1e-14
    assert np.abs(out["quaternion"][1:3]).max() <= 1e-14
    np.testing.assert_allclose(np.linalg.norm(out["quaternion"], axis=0), 1.0, atol=1e-15)


def test_planar_motion_matches_the_planar_chain(planar_run):
    """The same chain built independently in the plane (``tests/fe_multibody.py``, implicit
    midpoint steps on the output grid, Richardson-extrapolated in the step): tip deflection,
    axial tip motion and hub angle agree to about 1e-8 of the tip peak."""
    from fe_multibody import BeamSpec, MultiSystem, simulate_multibody

    a = _example_appendage()
    run = planar_run
    system = MultiSystem(hub_inertia=run["hub"][2, 2], hub_radius=0.06,
                         beams=(BeamSpec(length=a["length"], linear_density=a["rhoA"],
                                         bending_stiffness=a["EI_n"],
                                         masses=tuple(map(tuple, a["masses"]))),))
    spacing = run["times"][1] - run["times"][0]
    planar = [simulate_multibody(system, run["times"][-1], torque=lambda t: run["torque"](t)[2],
                                 n_elements=run["n"], t_eval=run["times"], dt=spacing / k,
                                 tol=1e-13) for k in (64, 128)]

    def extrapolate(key, index=0):
        coarse, fine = (p[key][index] if p[key].ndim > 1 else p[key] for p in planar)
        return fine + (fine - coarse) / 3.0

    out = run["out"]
    peak = np.abs(extrapolate("tip_deflection")).max()
    q = out["quaternion"]
    errors = {
        "tip deflection": np.abs(out["tips"]["a"][1] - extrapolate("tip_deflection")).max(),
        "tip axial": np.abs(out["tips"]["a"][0] - (extrapolate("tip_axial") - 0.06
                                                     - a["length"])).max(),
        "hub angle (x l)": a["length"] * np.abs(2 * np.arctan2(q[3], q[0])
                                                  - extrapolate("theta")).max(),
    }
    print({k: f"{v / peak:.1e}" for k, v in errors.items()}, "of the tip peak",
          f"{peak:.4f} m")
    assert max(errors.values()) < 3e-7 * peak
