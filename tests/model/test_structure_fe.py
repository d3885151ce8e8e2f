"""Several appendages on a pinned or free hub: flexctl against independent finite elements.

The references live in ``tests/fe_multibody.py`` (which imports neither flexctl nor
``fe_reference``):

- linear frequencies: Hermite cubic finite elements of every beam rigidly clamped to the hub
  (converged: 40 against 80 elements per beam), checked against closed forms and against the
  linearisation of the rigid-finite-element chain;
- nonlinear histories: the geometrically exact rigid-finite-element chains on one hub,
  Richardson-extrapolated from 32 and 64 elements per beam, its own convergence checked by
  the extrapolation from 16 and 32 elements before flexctl is judged against it.

The reference's own checks run first (they need no flexctl); then flexctl's first_order
frequencies (6 cantilever modes per beam, lowest two modes per beam within 1e-4), its exact
variant's tip histories (5 modes per beam, within 0.3 % of each tip's peak) and its
conservation laws. ``docs/theory/free_hub.md`` is the contract.

Run with ``-s`` to see the measured numbers.
"""

import functools
import os
import sys
import time
from dataclasses import dataclass

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))

from fe_multibody import (BeamSpec, MultiSystem, bang_bang_torque,  # noqa: E402
                          chain_linear_frequencies, clamped_first_frequency,
                          linear_frequencies, simulate_multibody, sine_torque,
                          torque_impulse)
from fe_reference import FESystem, simulate_fe  # noqa: E402

# --------------------------------------------------------------------------------------------
# the structures, in plain numbers (so the reference tests run even if flexctl's API breaks)

#: beams: the paper-000 beam with its 0.085 kg mass at 0.9 l, a softer shorter bare beam, and
#: a third with a tip mass (d = l, where cantilever modes converge slowest)
BEAMS = {
    "a": dict(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
              youngs_modulus=6.9e10, masses=((0.085, 1.62),)),
    "b": dict(length=1.5, density=2766.0, area=2.0e-4, second_moment=6.0e-11,
              youngs_modulus=6.9e10, masses=()),
    "c": dict(length=1.4, density=2766.0, area=2.2e-4, second_moment=8.0e-11,
              youngs_modulus=6.9e10, masses=((0.04, 1.4),)),
}
HUB = dict(inertia=1.16, radius=0.06, mass=3.0)
THIRD = 2.0 * np.pi / 3.0


@dataclass(frozen=True)
class Case:
    """A hub (``support``) carrying ``appendages``: ``(name, beam key, angle, radius)``."""

    support: str
    appendages: tuple


STRUCTURES = {
    "pinned_two": Case("pinned", (("wing_a", "a", 0.0, None), ("wing_b", "b", np.pi, None))),
    "pinned_three_120": Case("pinned", (("wing_a", "a", 0.0, None), ("wing_b", "b", THIRD, None),
                                        ("wing_c", "c", 2 * THIRD, None))),
    "pinned_twin": Case("pinned", (("wing_a", "a", 0.0, None), ("wing_b", "a", np.pi, None))),
    "free_wing": Case("free", (("wing_a", "a", 0.0, None),)),
    "free_two": Case("free", (("wing_a", "a", 0.0, None), ("wing_b", "b", 2.0, 0.1))),
    "free_twin": Case("free", (("wing_a", "a", 0.0, None), ("wing_b", "a", np.pi, None))),
    "free_star": Case("free", (("wing_a", "a", 0.0, None), ("wing_b", "a", THIRD, None),
                               ("wing_c", "a", 2 * THIRD, None))),
    "free_three_120": Case("free", (("wing_a", "a", 0.0, None), ("wing_b", "b", THIRD, None),
                                    ("wing_c", "c", 2 * THIRD, None))),
}


def reference_system(case: Case) -> MultiSystem:
    beams = []
    for _, key, angle, radius in case.appendages:
        p = BEAMS[key]
        beams.append(BeamSpec(p["length"], p["density"] * p["area"],
                              p["youngs_modulus"] * p["second_moment"], angle=angle,
                              radius=radius, masses=p["masses"]))
    return MultiSystem(HUB["inertia"], HUB["radius"], HUB["mass"], case.support, tuple(beams))


def flexctl_structure(case: Case):
    from flexctl import Appendage, Beam, Hub, PointMass, Structure
    apps = []
    for name, key, angle, radius in case.appendages:
        p = dict(BEAMS[key])
        masses = tuple(PointMass(mass=m, position=d) for m, d in p.pop("masses"))
        apps.append(Appendage(name=name, beam=Beam(**p), masses=masses, angle=angle,
                              radius=radius))
    return Structure(hub=Hub(inertia=HUB["inertia"], radius=HUB["radius"], mass=HUB["mass"],
                             support=case.support), appendages=tuple(apps))


def sci(values) -> str:
    """A short scientific rendering of an array, for the printed reports."""
    return "[" + ", ".join(f"{v:.2e}" for v in np.ravel(values)) + "]"


def compared_count(case: Case) -> int:
    """The lowest two modes per beam."""
    return 2 * len(case.appendages)


# --------------------------------------------------------------------------------------------
# the reference's own checks (no flexctl)

Z = np.array([1.8751040687119611, 4.6940911329741746, 7.8547574382376126])


def test_hermite_clamped_closed_forms():
    """Hermite FE, hub held: a bare cantilever's z_i^2 sqrt(EI / rhoA l^4), and MODEL.md's tip
    mass check (R_M = 1 on the paper-000 beam: 1.7325 rad/s)."""
    p = BEAMS["b"]
    rho_a, ei = p["density"] * p["area"], p["youngs_modulus"] * p["second_moment"]
    exact = Z ** 2 * np.sqrt(ei / (rho_a * p["length"] ** 4))
    system = MultiSystem(0.0, 0.1, 0.0, "pinned", (BeamSpec(p["length"], rho_a, ei),))
    errors = linear_frequencies(system, 40, hub="clamped")[:3] / exact - 1.0
    a = BEAMS["a"]
    rho_a, ei = a["density"] * a["area"], a["youngs_modulus"] * a["second_moment"]
    tip = MultiSystem(0.0, 0.06, 0.0, "pinned", (BeamSpec(
        a["length"], rho_a, ei, masses=((rho_a * a["length"], a["length"]),)),))
    tip_error = linear_frequencies(tip, 40, hub="clamped")[0] / 1.7325 - 1.0
    print(f"\nHermite 40 el: bare cantilever errors {errors}; tip mass R_M = 1: "
          f"{tip_error:+.1e} against the 5-digit 1.7325")
    assert np.max(np.abs(errors[:2])) < 2e-7 and abs(errors[2]) < 2e-6
    assert abs(tip_error) < 5e-5


@pytest.mark.parametrize("name", ["pinned_two", "pinned_three_120", "free_wing", "free_two",
                                  "free_twin", "free_star", "free_three_120"])
def test_reference_frequencies_converged_and_agree(name):
    """Hermite FE converged in elements (40 vs 80 per beam), and the rigid-element chain
    linearised at rest (64, 128 elements, Richardson) agrees with it: two independent
    discretizations of the same linear structure, hub held and hub free."""
    case = STRUCTURES[name]
    system = reference_system(case)
    n = compared_count(case)
    for hub in ("clamped", "free"):
        h40 = linear_frequencies(system, 40, hub)[:n]
        h80 = linear_frequencies(system, 80, hub)[:n]
        c64 = chain_linear_frequencies(system, 64, hub)[:n]
        c128 = chain_linear_frequencies(system, 128, hub)[:n]
        chain = c128 + (c128 - c64) / 3.0
        mesh = np.max(np.abs(h40 / h80 - 1.0))
        agree = np.max(np.abs(chain / h80 - 1.0))
        print(f"\n{name}, hub {hub}: {np.array2string(h80, precision=6)} rad/s; Hermite 40 vs "
              f"80 el {mesh:.1e}; rigid-element chain (extrapolated) vs Hermite {agree:.1e}")
        assert mesh < 1e-6
        assert agree < 5e-6


def test_reference_single_beam_reproduces_fe_reference():
    """One beam on a pinned hub, mounted at any angle: fe_reference's chain to round-off."""
    a = BEAMS["a"]
    rho_a, ei = a["density"] * a["area"], a["youngs_modulus"] * a["second_moment"]
    fe = FESystem(HUB["inertia"], HUB["radius"], a["length"], rho_a, ei, masses=a["masses"])
    old = simulate_fe(fe, 2.0, torque=sine_torque(2.0, 2.0), n_elements=24)
    peak = np.max(np.abs(old["tip_deflection"]))
    for angle, radius in ((0.0, None), (2.3, HUB["radius"])):
        system = MultiSystem(HUB["inertia"], 0.5 if radius else HUB["radius"], 7.0, "pinned",
                             (BeamSpec(a["length"], rho_a, ei, angle=angle, radius=radius,
                                       masses=a["masses"]),))
        new = simulate_multibody(system, 2.0, torque=sine_torque(2.0, 2.0), n_elements=24,
                                 dt=old["dt"])
        tip = np.max(np.abs(new["tip_deflection"][0] - old["tip_deflection"])) / peak
        hub = np.max(np.abs(new["theta"] - old["theta"])) / np.max(np.abs(old["theta"]))
        mom = np.max(np.abs(new["angular_momentum"] - old["angular_momentum"]))
        print(f"\nangle {angle}: tip {tip:.1e} of peak, hub angle {hub:.1e}, angular momentum "
              f"{mom:.1e}")
        assert tip < 1e-9 and hub < 1e-9 and mom < 1e-9


def test_reference_conservation_unforced_free_hub():
    """Free hub, no torque, two beams pre-bent by 15-20 % and a spinning start: energy, linear
    momentum (centre of mass at rest) and angular momentum about O are conserved."""
    system = reference_system(STRUCTURES["free_two"])

    def bent(scale):
        return lambda s: scale * (2.0 * s - s * s / 1.8)

    r = simulate_multibody(system, 3.0, n_elements=24, initial_theta_dot=0.8,
                           initial_slopes=(bent(0.1), bent(-0.14)))
    y0 = r["tip_deflection"][:, 0]
    e, h = r["energy"], r["angular_momentum"]
    drift_e = np.max(np.abs(e - e[0])) / e[0]
    drift_h = np.max(np.abs(h - h[0])) / abs(h[0])
    # the centre starts at rest, but the spinning asymmetric structure's centre of mass moves:
    # the initial momentum is that of the beams; it must stay constant
    drift_p = np.max(np.abs(r["momentum"] - r["momentum"][:, :1]))
    print(f"\ninitial tips {y0} m; hub centre moves {np.ptp(r['hub_x']):.3f} x "
          f"{np.ptp(r['hub_y']):.3f} m; drifts: energy {drift_e:.1e}, angular momentum "
          f"{drift_h:.1e}, momentum {drift_p:.1e} kg m/s; cpu {r['cpu_time']:.1f} s")
    assert np.min(np.abs(y0) / np.array([1.8, 1.5])) > 0.1
    # the midpoint rule conserves them to O(dt^2), not exactly (they are not quadratic)
    p0 = r["momentum"][:, 0]
    assert drift_e < 1e-5 and drift_h < 1e-6 and drift_p < 1e-5 * np.linalg.norm(p0)
    expected = r["com"][:, :1] + p0[:, None] / system.total_mass * r["t"][None, :]
    assert np.max(np.abs(r["com"] - expected)) / system.reach < 1e-6


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_reference_momentum_and_centre_of_mass_under_torque(support):
    """Angular momentum about O equals the torque impulse; a free hub's centre of mass stays
    at rest (a pinned hub's does not: the support pushes)."""
    case = STRUCTURES["free_two"]
    system = reference_system(Case(support, case.appendages))
    r = simulate_multibody(system, 3.0, torque=sine_torque(3.0, 2.0), n_elements=24)
    impulse = torque_impulse(r["t"], r["torque"])
    err_h = np.max(np.abs(r["angular_momentum"] - impulse)) / np.max(np.abs(impulse))
    com = np.max(np.abs(r["com"] - r["com"][:, :1])) / system.reach
    after = r["t"] > 2.0
    e = r["energy"][after]
    print(f"\n{support}: |H - impulse| {err_h:.1e} of the peak impulse; centre of mass moves "
          f"{com:.1e} of the reach; energy after the torque varies {np.ptp(e) / e.max():.1e}")
    assert err_h < 1e-5
    assert np.ptp(e) / e.max() < 1e-7
    if support == "free":
        assert com < 1e-7
    else:
        assert com > 1e-3


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_reference_symmetric_twin(support):
    """Identical beams at 0 and 180 deg: a hub torque bends them alike (their antisymmetric
    modes are not excited) and a free hub does not translate; the antisymmetric modes have
    the clamped frequencies on a pinned hub."""
    case = STRUCTURES[f"{support}_twin"]
    system = reference_system(case)
    r = simulate_multibody(system, 3.0, torque=sine_torque(2.0, 2.0), n_elements=24)
    ya, yb = r["tip_deflection"]
    peak = np.max(np.abs(ya))
    print(f"\n{support} twin: |y_a - y_b| {np.max(np.abs(ya - yb)) / peak:.1e} of the peak "
          f"{peak:.3f} m; hub moves {np.max(np.abs(np.r_[r['hub_x'], r['hub_y']])):.1e} m")
    assert np.max(np.abs(ya - yb)) < 1e-9 * peak
    assert np.max(np.abs(np.r_[r["hub_x"], r["hub_y"]])) < 1e-9 * system.reach
    if support == "pinned":
        free = linear_frequencies(system, 40, "free")
        clamped = linear_frequencies(system, 40, "clamped")[::2][:2]   # each twice
        assert np.all(np.min(np.abs(free[:, None] / clamped[None, :] - 1.0), axis=0) < 1e-8)


# --------------------------------------------------------------------------------------------
# nonlinear reference runs, shared by the reference's convergence test and flexctl's

@dataclass(frozen=True)
class Run:
    structure: str
    t_final: float
    kind: str          # "sine" or "bang"
    amplitude: float
    duration: float
    #: reference time steps per shortest first clamped period: the torque jumps of a
    #: bang-bang excite the chain's stiff modes, and its tips converge in the step only
    #: from about 4000 steps per period on (1000 leave an error of 3e-4 of the peak)
    steps: int = 1000

    def reference_torque(self):
        if self.kind == "sine":
            return sine_torque(self.amplitude, self.duration)
        return bang_bang_torque(self.amplitude, self.duration)

    def flexctl_torque(self):
        from flexctl import SineTorque
        if self.kind == "sine":
            return SineTorque(peak_torque=self.amplitude, duration=self.duration)
        from flexctl.sim.maneuvers import TorqueSamples
        return TorqueSamples(times=[0.0, self.duration / 2, self.duration],
                             values=[self.amplitude, -self.amplitude, 0.0],
                             interpolation="hold")

    def impulse(self, t):
        """Exact time integral of the torque."""
        t = np.asarray(t, dtype=float)
        a, d = self.amplitude, self.duration
        if self.kind == "sine":
            return np.where(t <= d, a * d / (2 * np.pi) * (1 - np.cos(2 * np.pi * t / d)), 0.0)
        return np.where(t < d / 2, a * t, np.where(t < d, a * (d - t), 0.0))


RUNS = {
    "pinned_two_sine": Run("pinned_two", 3.0, "sine", 2.5, 2.0),
    "pinned_two_bang": Run("pinned_two", 3.0, "bang", 1.5, 2.0, steps=4000),
    "free_wing_sine": Run("free_wing", 3.0, "sine", 2.0, 2.0),
    "free_two_sine": Run("free_two", 3.0, "sine", 3.0, 2.0),
    "free_three_120_sine": Run("free_three_120", 3.0, "sine", 3.0, 2.0),
}
OUTPUT_STEP = 0.01
#: tip histories: largest error relative to each tip's peak (the bar of MODEL.md section 7)
TIP_TOLERANCE = 3e-3
#: the reference must be ten times better than that bar (mesh), and its time step thirty times
REFERENCE_TOLERANCE = 3e-4
TIME_STEP_TOLERANCE = 1e-4
EXACT_MODES = 5


def output_grid(t_final):
    return np.linspace(0.0, t_final, int(round(t_final / OUTPUT_STEP)) + 1)


@functools.lru_cache(maxsize=None)
def reference_run(name: str):
    """Extrapolated histories (32, 64 elements), the convergence estimates and wall time."""
    run = RUNS[name]
    system = reference_system(STRUCTURES[run.structure])
    grid = output_grid(run.t_final)
    # a step dividing the torque's switching times (the midpoint rule samples the torque at
    # step midpoints)
    t1 = 2 * np.pi / max(clamped_first_frequency(b) for b in system.beams)
    dt = (run.duration / 2) / np.ceil((run.duration / 2) / (t1 / run.steps))
    start = time.perf_counter()
    runs = {n: simulate_multibody(system, run.t_final, torque=run.reference_torque(), dt=dt,
                                  n_elements=n, t_eval=grid) for n in (16, 32, 64)}
    half = simulate_multibody(system, run.t_final, torque=run.reference_torque(), dt=dt / 2,
                              n_elements=32, t_eval=grid)
    wall = time.perf_counter() - start

    def extrapolate(key, coarse, fine):
        return runs[fine][key] + (runs[fine][key] - runs[coarse][key]) / 3.0

    out = {key: extrapolate(key, 32, 64)
           for key in ("tip_deflection", "theta", "theta_dot", "hub_x", "hub_y", "energy",
                       "angular_momentum")}
    lower = extrapolate("tip_deflection", 16, 32)
    peaks = np.max(np.abs(out["tip_deflection"]), axis=1)
    out["t"] = grid
    out["peaks"] = peaks
    out["convergence"] = np.max(np.abs(lower - out["tip_deflection"]), axis=1) / peaks
    out["mesh_change"] = np.max(np.abs(runs[64]["tip_deflection"] - runs[32]["tip_deflection"]),
                                axis=1) / peaks
    out["step_change"] = np.max(np.abs(half["tip_deflection"] - runs[32]["tip_deflection"]),
                                axis=1) / peaks
    out["dt"] = dt
    out["wall"] = wall
    out["lengths"] = np.array([b.length for b in system.beams])
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RUNS))
def test_reference_nonlinear_converged(name):
    """The extrapolated reference is converged to well within the bar flexctl is held to, in
    elements (the extrapolations from 16 and 32 and from 32 and 64 elements agree) and in the
    time step (halving it changes little), and the manoeuvre bends the beams far enough
    (5-20 % of the length) to be nonlinear."""
    ref = reference_run(name)
    ratio = ref["peaks"] / ref["lengths"]
    print(f"\n{name}: peak tips {np.array2string(ref['peaks'], precision=4)} m "
          f"({np.array2string(100 * ratio, precision=1)} % of length); 32 vs 64 el "
          f"{sci(ref['mesh_change'])}, extrapolated (16,32) vs "
          f"(32,64) {sci(ref['convergence'])} of each peak; dt {ref['dt']:.2e} s vs dt/2 "
          f"{sci(ref['step_change'])}; wall {ref['wall']:.1f} s for 16+32+64 el + 32 el at dt/2")
    assert np.all(ref["convergence"] < REFERENCE_TOLERANCE)
    assert np.all(ref["step_change"] < TIME_STEP_TOLERANCE)
    assert 0.05 <= ratio.max() <= 0.25 and ratio.min() >= 0.03


# --------------------------------------------------------------------------------------------
# flexctl against the reference

def _outputs_on(result, names, grid):
    t = np.asarray(result.t)
    return {n: np.interp(grid, t, np.asarray(result.outputs[n])) for n in names}


@functools.lru_cache(maxsize=None)
def flexctl_run(name: str, variant: str = "exact", n_modes: int = EXACT_MODES):
    from flexctl import build_model, simulate
    run = RUNS[name]
    model = build_model(flexctl_structure(STRUCTURES[run.structure]), n_modes=n_modes,
                        variant=variant)
    start = time.perf_counter()
    result = simulate(model, run.t_final, torque=run.flexctl_torque(), output_step=OUTPUT_STEP)
    return model, result, time.perf_counter() - start


@pytest.mark.parametrize("hub", ["clamped", "free"])
@pytest.mark.parametrize("name", ["pinned_two", "pinned_three_120", "free_wing", "free_two",
                                  "free_twin", "free_star", "free_three_120"])
def test_flexctl_frequencies(name, hub):
    """first_order's natural frequencies at rest (6 cantilever modes per beam) against the
    converged Hermite FE: the lowest two modes per beam within 1e-4."""
    from flexctl import build_model
    case = STRUCTURES[name]
    n = compared_count(case)
    reference = linear_frequencies(reference_system(case), 60, hub)[:n]
    model = build_model(flexctl_structure(case), n_modes=6, variant="first_order")
    ours = np.sort(np.asarray(model.natural_frequencies(0.0, hub=hub), dtype=float))[:n]
    errors = ours / reference - 1.0
    print(f"\n{name}, hub {hub}: reference {np.array2string(reference, precision=5)}; flexctl "
          f"relative errors {sci(errors)}")
    assert ours.shape == reference.shape
    assert np.max(np.abs(errors)) < 1e-4


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RUNS))
def test_flexctl_exact_tips_against_reference(name):
    """The exact variant's tip deflections (5 modes per beam) follow the converged
    geometrically exact finite elements within 0.3 % of each tip's peak."""
    ref = reference_run(name)
    assert np.all(ref["convergence"] < REFERENCE_TOLERANCE), "reference not converged"
    assert np.all(ref["step_change"] < TIME_STEP_TOLERANCE), "reference time step too long"
    case = STRUCTURES[RUNS[name].structure]
    names = [f"{app[0]}.tip_deflection" for app in case.appendages]
    model, result, wall = flexctl_run(name)
    ours = _outputs_on(result, names, ref["t"])
    errors = np.array([np.max(np.abs(ours[n] - ref["tip_deflection"][k])) / ref["peaks"][k]
                       for k, n in enumerate(names)])
    print(f"\n{name}: tip errors {sci(errors)} of peaks "
          f"{np.array2string(ref['peaks'], precision=4)} m; flexctl simulate {wall:.1f} s, "
          f"reference {ref['wall']:.1f} s")
    assert np.all(errors < TIP_TOLERANCE)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RUNS))
def test_flexctl_exact_hub_motion_against_reference(name):
    """The hub angle (and a free hub's centre) follow the reference within 0.3 % of their
    peaks too."""
    ref = reference_run(name)
    case = STRUCTURES[RUNS[name].structure]
    names = ["theta"] + (["hub_x", "hub_y"] if case.support == "free" else [])
    model, result, _ = flexctl_run(name)
    ours = _outputs_on(result, names, ref["t"])
    errors = {n: np.max(np.abs(ours[n] - ref[n])) / np.max(np.abs(ref[n])) for n in names}
    print(f"\n{name}: " + ", ".join(f"{n} error {e:.1e} of peak {np.max(np.abs(ref[n])):.4f}"
                                    for n, e in errors.items()))
    assert all(e < TIP_TOLERANCE for e in errors.values())


@pytest.mark.slow
@pytest.mark.parametrize("name", ["free_wing_sine", "free_two_sine", "free_three_120_sine"])
@pytest.mark.parametrize("variant", ["exact", "first_order"])
def test_flexctl_free_hub_centre_of_mass_at_rest(name, variant):
    """No external force: the centre of mass of a free structure does not move, and the
    linear momentum stays 0 (free_hub.md sections 2 and 6)."""
    model, result, _ = flexctl_run(name, variant, EXACT_MODES)
    x = np.asarray(result.states)
    com = np.asarray(model.center_of_mass(x))
    momentum = np.asarray(model.linear_momentum(x))
    reach = flexctl_structure(STRUCTURES[RUNS[name].structure]).reach
    hub_travel = np.max(np.abs(np.asarray(result.outputs["hub_x"])))
    drift = np.max(np.abs(com - com[:, :1])) / reach
    scale = flexctl_structure(STRUCTURES[RUNS[name].structure]).total_mass * hub_travel
    print(f"\n{name} ({variant}): centre of mass moves {drift:.1e} of the reach (hub centre "
          f"travels {hub_travel:.3f} m); |P| {np.max(np.abs(momentum)):.1e} kg m/s")
    assert com.shape == (2, x.shape[1])
    assert drift < 1e-6
    assert np.max(np.abs(momentum)) < 1e-6 * max(scale, 1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RUNS))
def test_flexctl_angular_momentum_is_torque_impulse(name):
    """Exact variant: the angular momentum about the inertial origin equals the torque
    impulse, and the energy stays constant once the torque is off; both match the
    reference's."""
    run = RUNS[name]
    model, result, _ = flexctl_run(name)
    x = np.asarray(result.states)
    t = np.asarray(result.t)
    h = np.asarray(model.angular_momentum(x))
    impulse = run.impulse(t)
    err_h = np.max(np.abs(h - impulse)) / np.max(np.abs(impulse))
    e = np.asarray(model.energy(x))
    after = t > run.duration + 1e-9
    drift_e = np.ptp(e[after]) / np.max(e[after])
    ref = reference_run(name)
    e_ref = np.interp(t, ref["t"], ref["energy"])
    err_e = np.max(np.abs(e - e_ref)) / np.max(e_ref)
    print(f"\n{name}: |H - impulse| {err_h:.1e} of the peak impulse; energy drift after the "
          f"torque {drift_e:.1e}; energy against the reference {err_e:.1e} of its peak")
    assert err_h < 1e-6
    assert drift_e < 1e-6
    assert err_e < TIP_TOLERANCE


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_flexctl_symmetric_twin(support):
    """Identical beams at 0 and 180 deg: the hub torque cannot excite the beams' antisymmetric
    motion, so their tips move alike in their own frames and a free hub stays put; on a
    pinned hub the antisymmetric modes keep the clamped frequencies."""
    from flexctl import SineTorque, build_model, simulate
    case = STRUCTURES[f"{support}_twin"]
    structure = flexctl_structure(case)
    model = build_model(structure, n_modes=4, variant="exact")
    result = simulate(model, 3.0, torque=SineTorque(peak_torque=2.0, duration=2.0),
                      output_step=OUTPUT_STEP)
    ya = np.asarray(result.outputs["wing_a.tip_deflection"])
    yb = np.asarray(result.outputs["wing_b.tip_deflection"])
    peak = np.max(np.abs(ya))
    asym = np.max(np.abs(ya - yb)) / peak
    line = f"\n{support} twin: |y_a - y_b| {asym:.1e} of the peak {peak:.3f} m"
    if support == "free":
        travel = max(np.max(np.abs(np.asarray(result.outputs[k]))) for k in ("hub_x", "hub_y"))
        line += f"; hub centre travels {travel:.1e} m"
    print(line)
    assert peak > 0.05
    assert asym < 1e-6
    if support == "free":
        assert travel < 1e-6 * structure.reach
    else:
        first = build_model(structure, n_modes=6, variant="first_order")
        free = np.asarray(first.natural_frequencies(0.0, hub="free"))
        clamped = np.asarray(first.natural_frequencies(0.0, hub="clamped"))[::2][:2]
        gaps = np.min(np.abs(free[:, None] / clamped[None, :] - 1.0), axis=0)
        print(f"  clamped frequencies {clamped} found among the free ones to {gaps}")
        assert np.all(gaps < 1e-8)


def test_flexctl_api_shapes():
    """The state and output names of free_hub.md, and the batch shapes of the new methods."""
    from flexctl import build_model
    structure = flexctl_structure(STRUCTURES["free_two"])
    model = build_model(structure, n_modes={"wing_a": 3, "wing_b": 2}, variant="exact")
    assert model.state_names == (
        "theta", "hub_x", "hub_y", "wing_a.q1", "wing_a.q2", "wing_a.q3", "wing_b.q1",
        "wing_b.q2", "theta_dot", "hub_x_dot", "hub_y_dot", "wing_a.q1_dot", "wing_a.q2_dot",
        "wing_a.q3_dot", "wing_b.q1_dot", "wing_b.q2_dot")
    assert model.output_names[:4] == ("theta", "theta_dot", "hub_x", "hub_y")
    for app in ("wing_a", "wing_b"):
        for out in ("tip_deflection", "root_moment", "tip_angle"):
            assert f"{app}.{out}" in model.output_names
    n = len(model.state_names)
    x = np.random.default_rng(3).normal(size=(n, 5)) * 0.01
    assert np.asarray(model.outputs(x)).shape == (len(model.output_names), 5)
    assert np.asarray(model.outputs(x[:, 0])).shape == (len(model.output_names),)
    assert np.asarray(model.center_of_mass(x)).shape == (2, 5)
    assert np.asarray(model.linear_momentum(x)).shape == (2, 5)
    assert np.asarray(model.angular_momentum(x)).shape == (5,)
    np.testing.assert_allclose(np.asarray(model.center_of_mass(x))[:, 2],
                               np.asarray(model.center_of_mass(x[:, 2])), rtol=1e-12)
    pinned = build_model(flexctl_structure(STRUCTURES["pinned_two"]), n_modes=(2, 3))
    assert "hub_x" not in pinned.output_names and "hub_x" not in pinned.state_names
    assert pinned.state_names[:3] == ("theta", "wing_a.q1", "wing_a.q2")
