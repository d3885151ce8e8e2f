"""Self-checks of the spatial rigid-element chain reference (``tests/model/spatial_reference.py``).

The reference imports nothing from flexctl; these checks judge it against closed forms, the
conservation laws, planar symmetry and the independent planar chain of
``tests/fe_multibody.py``. Fast (about 15 s in all); run with ``-s`` to see the numbers.
"""

import os
import sys

import numpy as np
import pytest
from scipy.integrate import simpson

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
    h0, e0 = invariants[0]["angular"], invariants[0]["energy"]
    drift_h = max(np.linalg.norm(i["angular"] - h0) for i in invariants) / np.linalg.norm(h0)
    drift_e = max(abs(i["energy"] - e0) for i in invariants) / e0
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


def _free_run(torque, t_final=1.0, count=41):
    """The soft structure on a free hub (2 kg), spinning and drifting at the start, sampled
    at ``count`` times; its invariants at every sample."""
    hub, appendages = soft_structure()
    system = ChainSystem(hub, appendages, n_elements=3, hub_mass=2.0)
    times = np.linspace(0.0, t_final, count)
    sol = system.simulate(torque, t_final, times, angular_velocity=(0.6, -0.4, 1.0),
                          velocity=(0.1, -0.2, 0.05))
    invariants = [system.invariants(sol.y[:, j]) for j in range(times.size)]
    stacked = {k: np.array([i[k] for i in invariants]) for k in invariants[0]}
    return system, times, sol, stacked


def test_free_hub_keeps_momenta_energy_and_a_uniformly_moving_centre_of_mass():
    """No torque, a free hub spinning about an oblique axis and drifting: the angular
    momentum about the centre of mass, the linear momentum (both in N) and the energy stay
    constant, the centre of mass moves on a straight line at ``L / m`` while the hub's centre
    wanders by centimetres. Measured over 1 s: drifts 1.2e-13 (H), 8e-13 (energy), 8e-13
    (L, relative), 1.5e-13 m (centre of mass)."""
    system, times, sol, inv = _free_run(lambda t: np.zeros(3))
    h, e, lin, com = inv["angular"], inv["energy"], inv["linear"], inv["centre_of_mass"]
    drift_h = np.abs(h - h[0]).max() / np.linalg.norm(h[0])
    drift_e = np.abs(e - e[0]).max() / e[0]
    drift_l = np.abs(lin - lin[0]).max() / np.linalg.norm(lin[0])
    drift_c = np.abs(com - com[0] - np.outer(times, lin[0]) / system.total_mass).max()
    wander = np.abs(sol.y[4:7] - np.outer(sol.y[4:7, 0], np.ones(times.size))).max(axis=1)
    print(f"drifts: H {drift_h:.1e}, energy {drift_e:.1e}, L {drift_l:.1e}, "
          f"centre of mass {drift_c:.1e} m; hub centre moves {wander.round(3).tolist()} m, "
          f"{sol.stats}")
    assert max(drift_h, drift_e, drift_l) < 1e-8 and drift_c < 1e-9
    assert wander.min() > 0.01


def test_free_hub_under_torque_keeps_linear_momentum_and_turns_h_by_the_impulse():
    """A torque (a couple) on the free hub: the linear momentum and the centre of mass's
    uniform motion stay as without it, and the angular momentum about the centre of mass
    changes by the torque's impulse in N, ``int R(q) tau dt`` (Simpson's rule on 81
    samples). Measured: L to 1.3e-12, the centre of mass to 9e-14 m, the change of H
    (0.41 N m s) equals the impulse to 1.1e-8 (Simpson's error)."""
    def torque(t):
        return np.array([0.3, -0.2, 0.5]) * np.sin(3.0 * t)

    system, times, sol, inv = _free_run(torque, count=81)
    h, lin, com = inv["angular"], inv["linear"], inv["centre_of_mass"]
    drift_l = np.abs(lin - lin[0]).max() / np.linalg.norm(lin[0])
    drift_c = np.abs(com - com[0] - np.outer(times, lin[0]) / system.total_mass).max()
    q = sol.y[:4]
    w0, wv = q[0], q[1:]
    rates = np.array([(w0[j] ** 2 - wv[:, j] @ wv[:, j]) * torque(t)
                      + 2 * wv[:, j] * (wv[:, j] @ torque(t)) + 2 * w0[j] * np.cross(wv[:, j],
                                                                                    torque(t))
                      for j, t in enumerate(times)])               # R(q) tau in N
    impulse = simpson(rates, x=times, axis=0)
    change = h[-1] - h[0]
    error = np.linalg.norm(change - impulse) / np.linalg.norm(change)
    print(f"L drift {drift_l:.1e}, centre of mass {drift_c:.1e} m, H change "
          f"{np.linalg.norm(change):.3f} against the impulse to {error:.1e}")
    assert drift_l < 1e-8 and drift_c < 1e-9
    assert error < 1e-6


def test_free_planar_motion_matches_the_planar_chain():
    """A free hub (1.5 kg) with MODEL.md's rod, a torque about the axis normal to the bending
    plane: the motion stays in the plane and equals the independent planar chain's
    (``tests/fe_multibody.py``, free support, same 10-element mesh, its implicit-midpoint
    steps extrapolated): measured, tip deflection 3.7e-8, axial tip motion 1.6e-9, hub
    angle (times the rod length) 2.6e-8 and the hub centre's two coordinates 2.4e-10 and
    7.0e-9 of the tip's peak (the hub moves by 23 mm)."""
    from fe_multibody import BeamSpec, MultiSystem, simulate_multibody

    amplitude, period, t_final, n, hub_mass = 0.5, 1.0, 1.5, 10, 1.5

    def torque(t):
        return np.array([0.0, 0.0, amplitude * np.sin(2 * np.pi * t / period)
                         if t <= period else 0.0])

    times = np.linspace(0.0, t_final, 31)
    hub = np.array([[1.16, 0.01, 0.0], [0.01, 1.17, 0.0], [0.0, 0.0, 1.16]])
    a = _example_appendage()
    out = chain_response(hub, [a], torque, t_final, times, n_elements=n, hub_mass=hub_mass)
    system = MultiSystem(hub_inertia=hub[2, 2], hub_radius=0.06, hub_mass=hub_mass,
                         support="free",
                         beams=(BeamSpec(length=a["length"], linear_density=a["rhoA"],
                                         bending_stiffness=a["EI_n"],
                                         masses=tuple(map(tuple, a["masses"]))),))
    spacing = times[1] - times[0]
    planar = [simulate_multibody(system, t_final, torque=lambda t: torque(t)[2],
                                 n_elements=n, t_eval=times, dt=spacing / k, tol=1e-13)
              for k in (64, 128)]

    def extrapolate(key, index=None):
        coarse, fine = (p[key] if index is None else p[key][index] for p in planar)
        return fine + (fine - coarse) / 3.0

    tip, q, position = out["tips"]["a"], out["quaternion"], out["position"]
    peak = np.abs(extrapolate("tip_deflection", 0)).max()
    errors = {
        "tip deflection": np.abs(tip[1] - extrapolate("tip_deflection", 0)).max(),
        "tip axial": np.abs(tip[0] - (extrapolate("tip_axial", 0) - 0.06 - a["length"])).max(),
        "hub angle (x l)": a["length"] * np.abs(2 * np.arctan2(q[3], q[0])
                                                  - extrapolate("theta")).max(),
        "hub x": np.abs(position[0] - extrapolate("hub_x")).max(),
        "hub y": np.abs(position[1] - extrapolate("hub_y")).max(),
    }
    print({k: f"{v / peak:.1e}" for k, v in errors.items()}, "of the tip peak",
          f"{peak:.4f} m; hub moves {np.abs(position).max(axis=1).round(4).tolist()} m")
    assert np.abs(position[1]).max() > 0.01                       # the hub does move
    assert max(np.abs(tip[2]).max(), np.abs(position[2]).max(), np.abs(out["w"][:2]).max(),
               np.ptp(out["centre_of_mass"], axis=1).max()) <= 1e-12
    assert max(errors.values()) < 3e-7 * peak
