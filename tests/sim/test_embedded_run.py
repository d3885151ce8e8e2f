"""Continuous runs on compiled Dormand-Prince steps (flexctl.sim.embedded_rk.EmbeddedRun): the
8(5,3) pair that ``method="auto"`` takes (``"dop853"``), and the 5(4) pair (``"RK45"``)."""

import threading

import numpy as np
import pytest

import flexctl
from conftest import in_threads
from controllers import PD
from flexctl.sim.maneuvers import TorqueSamples
from flexctl.sim.embedded_rk import (DENSE_OUTPUT, DORMAND_PRINCE, DOP853_OMEGA_H, PAIR_OMEGA_H,
                                     EmbeddedRun, PairScheme)
from flexctl.sim.request import (PAIR_INSTRUCTIONS, PAIR_WORK, choose_continuous,
                                 rhs_instructions, state_scale)


@pytest.fixture(scope="module")
def slew():
    """slew-90's 6-mode first_order plant, 90 deg off, under a saturated PD law, and a tight
    CVODES reference."""
    model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=6)
    x0 = np.zeros(model.n_states)
    x0[0] = -np.pi / 2
    law = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    tight = flexctl.simulate(model, 4.0, controller=law, x0=x0, rtol=1e-12, method="cvodes",
                             output_step=0.005, check_validity=False)
    return model, x0, law, tight


def test_the_continuous_extension_is_of_order_four():
    # y(t + theta h) of y' = y: the extension's error shrinks as h^5 at theta = 1/2
    errors = []
    for h in (0.2, 0.1):
        ks, c, a = [], DORMAND_PRINCE["c"], DORMAND_PRINCE["a"]
        for node, row in zip(c, a):
            ks.append(1.0 + h * sum(w * k for w, k in zip(row, ks)))
        y5 = 1.0 + h * sum(b * k for b, k in zip(DORMAND_PRINCE["b"], ks))
        dy, theta = y5 - 1.0, 0.5
        spline = h * ks[0] - dy
        r4, r5 = dy - h * ks[6] - spline, h * sum(d * k for d, k in zip(DENSE_OUTPUT, ks))
        value = 1.0 + theta * (dy + (1 - theta) * (spline + theta * (r4 + (1 - theta) * r5)))
        errors.append(abs(value - np.exp(theta * h)))
    assert 2 ** 4.5 < errors[0] / errors[1] < 2 ** 5.5


@pytest.mark.parametrize("name, order", [("dopri5", 4), ("dop853", 7)])
def test_each_pair_steps_and_interpolates_to_its_order(name, order):
    # one step of y' = y from 1, as the compiled runs build it: the step's error shrinks as
    # h^(p + 1) (p = 5 and 8), its continuous extension's at theta = 0.37 as h^(order + 1)
    import casadi as ca

    scheme = PairScheme(name)
    y, h = ca.SX.sym("y"), ca.SX.sym("h")
    y_new, norm, dense = scheme.attempt(lambda t, state: state, 0.0, y, h, 1e-12, 1e-12)
    step = ca.Function("step", [y, h], [y_new, norm, dense])
    stepped, extended, theta = [], [], 0.37
    for length in (0.4, 0.2):
        value, _, rows = (np.array(v, dtype=float).ravel() for v in step(1.0, length))
        stepped.append(abs(value[0] - np.exp(length)))
        inside = scheme.interpolate(rows.reshape(1, scheme.dense_rows, 1), np.array([[theta]]))
        extended.append(abs(inside[0, 0] - np.exp(theta * length)))
    p = 5 if name == "dopri5" else 8
    assert 2 ** (p + 0.5) < stepped[0] / stepped[1] < 2 ** (p + 1.5)
    assert 2 ** (order + 0.5) < extended[0] / extended[1] < 2 ** (order + 1.5)
    # the evaluations a step counts: its stages, the end's derivative, the extension's
    assert scheme.evaluations == (7 if name == "dopri5" else 16)


@pytest.mark.parametrize("name, bound", [("dopri5", PAIR_OMEGA_H), ("dop853", DOP853_OMEGA_H)])
def test_an_undamped_oscillation_does_not_grow_at_the_bound_or_its_check(name, bound):
    # x'' = -omega^2 x stepped a thousand times at the run's bound and at twice it (the
    # accuracy check's), as when the error control sees nothing: its energy does not grow;
    # past the pair's stability interval on the imaginary axis it does
    import casadi as ca

    scheme, omega = PairScheme(name), 40.0
    y, h = ca.SX.sym("y", 2), ca.SX.sym("h")
    y_new, _, _ = scheme.attempt(lambda t, s: ca.vertcat(s[1], -omega ** 2 * s[0]), 0.0, y, h,
                                 1.0, 1.0)
    step = ca.Function("step", [y, h], [y_new])

    def growth(radians):
        state = np.array([1.0, 0.0])
        for _ in range(1000):
            state = np.array(step(state, radians / omega), dtype=float).ravel()
        return (omega ** 2 * state[0] ** 2 + state[1] ** 2) / omega ** 2

    # 5(4) at 1 rad a step: |R| = 1 + 1.4e-6, the energy 1.0028 after a thousand steps
    limit = 1.0 if name == "dop853" else 1.01
    assert growth(bound) <= limit and growth(2 * bound) <= limit
    assert growth(6.1 if name == "dop853" else 3.0) > 10.0


@pytest.mark.parametrize("method", ["auto", "RK45"])
def test_segments_and_a_prescribed_hub_motion_run_on_the_pair(method):
    scene = flexctl.load_scene("kane-spinup")
    model = flexctl.build_model(scene.system, n_modes=3)
    motion = scene.maneuver
    run = flexctl.simulate(model, 20.0, hub_motion=motion, rtol=1e-6, output_step=0.05,
                           check_validity=False, method=method)
    tight = flexctl.simulate(model, 20.0, hub_motion=motion, rtol=1e-12, method="cvodes",
                             output_step=0.05, check_validity=False)
    assert run.method == ("dop853" if method == "auto" else method) and run.ok
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    assert actual <= run.integration_error <= 1e-4 * tight.peak_tip_deflection


@pytest.mark.parametrize("method", ["dop853", "RK45"])
def test_a_held_torque_sees_each_hold_from_the_left(method):
    # torque samples jump at their breakpoints: each segment ends on one
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=3)
    torque = TorqueSamples(times=[0.0, 0.3, 0.7, 1.0], values=[1.0, -2.0, 0.5, 0.0])
    run = flexctl.simulate(model, 1.5, torque=torque, rtol=1e-8, check_validity=False,
                           method=method)
    tight = flexctl.simulate(model, 1.5, torque=torque, rtol=1e-12, method="cvodes",
                             check_validity=False)
    assert run.method == method
    assert np.max(np.abs(run.tip_deflection - tight.tip_deflection)) <= run.integration_error


def test_expensive_or_stiff_runs_keep_cvodes():
    system = flexctl.load_scene("slew-90").system
    cheap = flexctl.build_model(system, n_modes=6)
    exact = flexctl.build_model(system, n_modes=4, variant="exact")
    omega = float(cheap.natural_frequencies(0.0, hub="free")[-1])
    assert rhs_instructions(cheap) <= PAIR_INSTRUCTIONS < rhs_instructions(exact)
    assert choose_continuous(cheap, 6.0, omega) == "dop853"
    assert choose_continuous(exact, 6.0, omega) == "cvodes"
    # a run so long that the pair's steps, bound by the fastest mode, times the right-hand
    # side's instructions pass the work it is allowed
    steps = PAIR_WORK / rhs_instructions(cheap)
    assert choose_continuous(cheap, 0.9 * steps * PAIR_OMEGA_H / omega, omega) == "dop853"
    assert choose_continuous(cheap, 1.1 * steps * PAIR_OMEGA_H / omega, omega) == "cvodes"
    # a spin far above the modes counts as the fastest pole
    assert choose_continuous(cheap, 6.0, 1e6) == "cvodes"


def test_a_python_torque_keeps_scipy():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    state = {"n": 0}

    def torque(t):
        state["n"] += 1               # a side effect: opted out of a CasADi form
        return 0.1 if t < 0.5 else 0.0
    torque.has_casadi_form = False
    run = flexctl.simulate(model, 1.0, torque=torque, check_validity=False)
    assert run.ok and run.method == "DOP853"


def test_a_step_budget_and_a_non_finite_state_fail_the_segment(slew):
    model, x0, law, _ = slew
    scale = state_scale(model, model.layout)
    run = EmbeddedRun(model, controller=law, scale=scale, rtol=1e-10, max_steps=1,
                      h_first=1e-3)
    with pytest.raises(RuntimeError, match="steps"):
        run(0.0, np.array([1.0]), x0)
    run = EmbeddedRun(model, controller=law, scale=scale, rtol=1e-6, max_steps=1000,
                      h_first=1e-3)
    bad = x0.copy()
    bad[1] = np.nan
    with pytest.raises(RuntimeError):
        run(0.0, np.array([0.5, 1.0]), bad)


def test_threads_share_the_compiled_steps_and_agree(slew):
    model, x0, law, _ = slew
    results = in_threads(lambda k: flexctl.simulate(
        model, 2.0, controller=law, x0=x0, rtol=1e-7, check_validity=False).tip_deflection)
    np.testing.assert_array_equal(results[0], results[1])
    np.testing.assert_array_equal(results[0], results[2])


@pytest.mark.parametrize("method", ["dop853", "RK45"])
@pytest.mark.parametrize("options", [{"rtol": 0.5}, {"rtol": 1e-2}, {"atol": 99.0}],
                         ids=["rtol-0.5", "rtol-1e-2", "atol-loosest"])
def test_a_loose_tolerance_is_held_stable_by_the_step_bound(slew, options, method):
    # the error control sees nothing at these tolerances: the bound on the steps in radians
    # of the fastest pole keeps the undamped modes from growing, and the check still bounds
    # the error
    model, x0, law, tight = slew
    if "atol" in options:
        # just inside the loosest accepted: 100 times each state's physical size
        options = {"atol": options["atol"] * state_scale(model, model.layout)}
    run = flexctl.simulate(model, 4.0, controller=law, x0=x0, output_step=0.005,
                           check_validity=False, method=method, **options)
    assert run.ok and run.method == method, run.message
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    assert actual <= run.integration_error <= 1e-2 * tight.peak_tip_deflection


def test_a_run_whose_steps_are_all_bound_still_has_an_estimate(slew):
    model, _, _, _ = slew
    torque = flexctl.SineTorque(peak_torque=2.0, duration=2.0)
    run = flexctl.simulate(model, 3.0, torque=torque, max_step=1e-4, check_validity=False)
    tight = flexctl.simulate(model, 3.0, torque=torque, rtol=1e-12, method="cvodes",
                             check_validity=False)
    assert run.method == "dop853"
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    # 3e4 steps: both errors are at the rounding level, some 1e-11 of the peak
    assert 0.0 < run.integration_error
    assert actual <= max(run.integration_error, 1e-10 * tight.peak_tip_deflection)


def test_a_diverging_run_stops_where_it_passes_the_length(slew):
    model, _, _, _ = slew
    torque = flexctl.SineTorque(peak_torque=1e6, duration=2.0)
    run = flexctl.simulate(model, 3.0, torque=torque, check_validity=False)
    assert run.status == "diverged" and "passed the beam length" in run.message
    assert run.t[-1] < 0.05 and np.all(np.isfinite(run.states))
    # the compiled steps end within a call of the stop, not at the segment's end (2 s)
    assert run.n_evaluations < 16 * 128 * 20


def test_a_replay_ends_when_cancelled_or_past_a_stop(slew):
    # an abandoned accuracy check must not integrate on beside the next run
    from flexctl.sim.strategies import replay_steps

    model, x0, law, _ = slew
    scale = state_scale(model, model.layout)
    segments = [(0.0, np.linspace(0.5, 4.0, 8))]
    cancelled = threading.Event()

    def steps():
        return EmbeddedRun(model, controller=law, scale=scale, rtol=1e-6, max_steps=1000,
                           h_first=1e-3)
    whole = replay_steps(steps(), segments, x0, lambda states: None, cancelled)
    assert whole is not None and whole[0].shape == (model.n_states, 8)
    # past a stop (here the first sample), the replay gives no states
    assert replay_steps(steps(), segments, x0, lambda states: 0, cancelled) is None
    cancelled.set()
    assert replay_steps(steps(), segments, x0, lambda states: None, cancelled) is None


@pytest.mark.parametrize("rtol", [1e-4, 1e-6])
def test_auto_runs_the_pair_where_its_estimate_holds_past_a_corner(rtol):
    # a torque with a corner at t = 2 s that no breakpoint declares: past rtol 1e-6 the
    # 8(5,3) pair's error stalls near the tolerance and its check falls short of it, so
    # "auto" runs it at 1e-6 (flexctl.sim.request.DOP853_RTOL) and says so
    from flexctl.sim.request import DOP853_RTOL

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=4)

    def torque(t):
        return np.where(t <= 2.0, 2.0 * np.sin(np.pi * t), 0.0)
    tight = flexctl.simulate(model, 20.0, torque=torque, rtol=1e-12, method="cvodes",
                             output_step=0.01, check_validity=False)
    run = flexctl.simulate(model, 20.0, torque=torque, rtol=rtol, output_step=0.01,
                           check_validity=False)
    assert run.method == "dop853" and run.rtol == min(rtol, DOP853_RTOL)
    assert ("tightened to 1e-06" in run.message) == (rtol > DOP853_RTOL)
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    assert actual <= run.integration_error
    # asked for by name, the pair runs at the tolerance given
    named = flexctl.simulate(model, 20.0, torque=torque, rtol=rtol, output_step=0.01,
                             method="dop853", check_validity=False)
    assert named.rtol == rtol and "tightened" not in named.message


def test_the_compiled_pair_refuses_what_it_cannot_take():
    from flexctl.sim.digital import ZeroOrderHold

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)

    def torque(t):
        return 0.1 if t < 0.5 else 0.0
    torque.has_casadi_form = False
    with pytest.raises(ValueError, match="method 'dop853' needs inputs with a CasADi form"):
        flexctl.simulate(model, 1.0, torque=torque, method="dop853")
    law = ZeroOrderHold(PD(kp=12.0, kd=8.0, torque_limit=6.0), sample_time=0.01)
    with pytest.raises(ValueError, match="a sampled controller .* use method 'auto'"):
        flexctl.simulate(model, 1.0, controller=law, method="dop853")
    # SciPy's name keeps SciPy's integrator, calling the torque from Python
    run = flexctl.simulate(model, 1.0, torque=torque, method="DOP853", check_validity=False)
    assert run.ok and run.method == "DOP853"
