"""Exponential steps (:mod:`flexctl.sim.exponential`): the phi functions, exactness on a linear
model, the error control on a stiff nonlinear one, and the spatial runs that take them."""

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from flexctl.sim import spatial_run
from flexctl.sim.exponential import (ExponentialSegments, SegmentFailed, central_jacobian,
                                     phi_functions)
from flexctl.sim.spatial_run import ConstantTorque, VectorTorque

SLOW, FAST = 2.0, 3000.0
SCENE = Path(__file__).resolve().parents[2] / "examples" / "scenes" / "spatial-two-arrays.toml"


def _block_reference(a: np.ndarray, order: int) -> list:
    """``exp(A), phi_1(A), ...`` from the exponential of the block matrix that holds them."""
    n = a.shape[0]
    big = np.zeros(((order + 1) * n, (order + 1) * n))
    big[:n, :n] = a
    for k in range(order):
        big[k * n:(k + 1) * n, (k + 1) * n:(k + 2) * n] = np.eye(n)
    top = scipy.linalg.expm(big)[:n]
    return [top[:, k * n:(k + 1) * n] for k in range(order + 1)]


@pytest.mark.parametrize("size", [1e-6, 0.3, 4.0, 3e3])
def test_phi_functions_match_the_exponential_of_their_block_matrix(size):
    """Random matrices from tiny to stiff (an undamped 3e3 rad/s oscillator over a 1 s step
    among them): every function to 1e-10 of its largest entry."""
    rng = np.random.default_rng(7)
    a = rng.normal(size=(6, 6))
    a *= min(size, 1.0) / np.max(np.sum(np.abs(a), axis=0))
    if size > 1.0:              # a stiff, undamped oscillation (a random matrix would blow up)
        a[:2, :2] = [[0.0, size], [-size, 0.0]]
    for mine, ref in zip(phi_functions(a, 3), _block_reference(a, 3)):
        assert np.max(np.abs(mine - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_phi_functions_of_zero_and_of_a_nilpotent_matrix():
    """``phi_k(0) = I / k!``, and a nilpotent ``A`` (A^2 = 0) gives ``I / k! + A / (k+1)!``
    exactly; the identities ``phi_k(A) A = phi_(k-1)(A) - I / (k-1)!`` hold."""
    for k, value in enumerate(phi_functions(np.zeros((3, 3)), 4)):
        np.testing.assert_allclose(value, np.eye(3) / math.factorial(k), rtol=0, atol=1e-16)
    a = np.array([[0.0, 2.0], [0.0, 0.0]])
    for k, value in enumerate(phi_functions(a, 3)):
        np.testing.assert_allclose(value, np.eye(2) / math.factorial(k)
                                   + a / math.factorial(k + 1), rtol=0, atol=1e-15)
    b = np.array([[0.1, 30.0], [-30.0, -0.2]])
    funcs = phi_functions(b, 3)
    for k in range(1, 4):
        np.testing.assert_allclose(funcs[k] @ b, funcs[k - 1] - np.eye(2) / math.factorial(k - 1),
                                   rtol=0, atol=1e-12)


@pytest.mark.parametrize("matrix, order, words", [
    ([[1.0, 2.0]], 3, "must be square"),
    ([[np.nan]], 3, "matrix"),
    ("abc", 3, "matrix"),
    ([[1.0]], 0, "order must be an integer from 1 to 6"),
    ([[1.0]], 7, "order must be an integer from 1 to 6"),
    ([[1.0]], True, "order must be an integer from 1 to 6"),
    ([[1.0]], 2.0, "order must be an integer from 1 to 6"),
    ([[1e301, 0.0], [0.0, 1.0]], 3, "too large"),
])
def test_phi_functions_refuse_what_they_cannot_take(matrix, order, words):
    with pytest.raises((TypeError, ValueError), match=words):
        phi_functions(matrix, order)


def _linear_rhs(cubic: float = 0.0):
    """Two undamped modes (2 and 3000 rad/s) driven by the first two torque components, with
    a cubic spring on the slow one: ``x = [q1, q2, v1, v2]``."""
    x, torque = ca.MX.sym("x", 4), ca.MX.sym("torque", 3)
    rate = ca.vertcat(x[2], x[3], -SLOW ** 2 * x[0] - cubic * x[0] ** 3 + torque[0],
                      -FAST ** 2 * x[1] + 1e3 * torque[1])
    return ca.Function("toy", [x, torque], [rate])


def _segments(rhs, drive, rtol, line=False):
    return ExponentialSegments(rhs, 4, drive, rtol, rtol * 1e-3, line, 100_000,
                               modal=(np.array([0, 1]), np.array([2, 3])))


def test_a_linear_model_under_a_torque_linear_in_time_is_exact_in_few_steps():
    """The scheme is exact for ``x_t = A x + B u`` with ``u`` linear in time: the states at
    the samples equal the exponential of the augmented matrix to round-off, the fast mode
    (3000 rad/s, 48 periods a 0.1 s interval) stepped over in one or two steps an interval."""
    times = np.linspace(0.0, 1.0, 11)
    values = np.column_stack([np.sin(3 * times), np.cos(2 * times), np.zeros(11)])
    drive = VectorTorque(times, values)
    segments = _segments(_linear_rhs(), drive, 1e-10, line=True)
    x0 = np.array([0.01, 1e-6, 0.0, 0.0])
    out = segments.advance(0.0, 1.0, x0, times[1:])
    a = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [-SLOW ** 2, 0, 0, 0], [0, -FAST ** 2, 0, 0]])
    b = np.array([[0, 0], [0, 0], [1, 0], [0, 1e3]])
    x, exact = x0.copy(), []
    for k in range(10):
        dt = times[k + 1] - times[k]
        u0, slope = values[k, :2], (values[k + 1, :2] - values[k, :2]) / dt
        big = np.zeros((6, 6))
        big[:4, :4], big[:4, 4] = a * dt, b @ slope * dt * dt
        big[:4, 5], big[4, 5] = b @ u0 * dt, 1.0        # the states [x; s; 1]
        x = (scipy.linalg.expm(big) @ np.concatenate([x, [0.0, 1.0]]))[:4]   # s = t / dt
        exact.append(x)
    exact = np.array(exact).T
    scale = np.max(np.abs(exact), axis=1, keepdims=True)
    assert np.max(np.abs(out - exact) / scale) < 1e-9
    assert segments.steps <= 20


def test_the_error_falls_with_the_tolerance_on_a_stiff_nonlinear_model():
    """A cubic spring on the slow mode (its remainder) under a constant torque, the fast
    mode at 3000 rad/s: against SciPy's DOP853 at rtol 1e-13, the error of the slow mode's
    displacement falls with rtol, and is within 100 rtol of its peak."""
    rhs = _linear_rhs(cubic=4e4)
    x0 = np.array([0.02, 1e-6, 0.0, 0.0])
    wanted = np.linspace(0.05, 2.0, 40)
    reference = solve_ivp(lambda t, y: rhs(y, [0.05, 0.0, 0.0]).full().ravel(), (0.0, 2.0),
                          x0, method="DOP853", rtol=1e-13, atol=1e-16, t_eval=wanted).y
    peak = np.max(np.abs(reference[0]))
    errors, steps = [], []
    for rtol in (1e-5, 1e-7, 1e-9):
        segments = _segments(rhs, ConstantTorque(np.array([0.05, 0.0, 0.0])), rtol)
        out = segments.advance(0.0, 2.0, x0, wanted)
        errors.append(float(np.max(np.abs(out[0] - reference[0])) / peak))
        steps.append(segments.steps)
        assert errors[-1] < 100 * rtol, (rtol, errors[-1])
    assert errors[0] > errors[1] > errors[2]
    assert steps[0] < steps[1] < steps[2]


def test_a_blow_up_ends_the_run_with_the_step_that_could_not_be_taken():
    """A cubic spring of the wrong sign blows up within 4 ms: the steps shrink with it until
    none is short enough, and the failure says so."""
    segments = _segments(_linear_rhs(cubic=-1e6), ConstantTorque(np.zeros(3)), 1e-6)
    with pytest.raises(SegmentFailed, match=r"step size .* s at t = 0\.00[0-9]+ s: the error "
                                            r"control found no step short enough"):
        segments.advance(0.0, 2.0, np.array([0.5, 0.0, 0.0, 0.0]), np.linspace(0.1, 2.0, 20))


def test_a_state_that_leaves_the_model_is_not_returned_as_numbers():
    """A rate that is NaN past ``q1 = 1`` (a square root of ``1 - q1``), reached under a
    constant push: no step keeps the state finite, and the states from there on are NaN
    (the spatial run then reports ``diverged``), those before it numbers."""
    x, torque = ca.MX.sym("x", 4), ca.MX.sym("torque", 3)
    rate = ca.vertcat(x[2], x[3], torque[0] + 1e-30 * ca.sqrt(1.0 - x[0]), -FAST ** 2 * x[1])
    rhs = ca.Function("edge", [x, torque], [rate])
    segments = _segments(rhs, ConstantTorque(np.array([2.0, 0.0, 0.0])), 1e-6)
    out = segments.advance(0.0, 2.0, np.array([0.0, 0.0, 0.0, 0.0]), np.linspace(0.1, 2.0, 20))
    # q1 = t^2 reaches 1 at t = 1 s, the tenth output
    assert np.all(np.isfinite(out[:, :10])) and np.all(np.isnan(out[:, 10:]))
    np.testing.assert_allclose(out[0, :10], np.linspace(0.1, 1.0, 10) ** 2, rtol=1e-8)


def test_central_jacobian_of_a_linear_model_is_its_matrix():
    rhs = _linear_rhs()
    jacobian = central_jacobian(rhs.map(8), np.array([0.3, -0.2, 1.0, 5.0]), [0.1, 0.2, 0.0])
    expected = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [-SLOW ** 2, 0, 0, 0],
                         [0, -FAST ** 2, 0, 0]])
    np.testing.assert_allclose(jacobian, expected, rtol=1e-7, atol=1e-7)


def test_samples_a_hair_off_the_output_grid_leave_no_sliver_of_a_step():
    """Samples 1e-17 s from output times (0.1 from a float sum, 0.1 from a linspace) are one
    breakpoint with them: the run does not try a step of 1e-17 s."""
    times = np.cumsum(np.full(20, 0.05)) - 0.05
    drive = VectorTorque(times, np.outer(np.sin(times), [1.0, 0.5, 0.0]))
    segments = _segments(_linear_rhs(), drive, 1e-8, line=True)
    wanted = np.linspace(0.01, 0.95, 95)
    out = segments.advance(0.0, 0.95, np.array([0.0, 0.0, 0.0, 0.0]), wanted)
    assert np.all(np.isfinite(out))


def _two_arrays():
    import flexctl
    from flexctl.model.spatial_structure import SpatialStructure

    scene = flexctl.load_scene(SCENE)
    return SpatialStructure(hub=scene.structure.hub, appendages=scene.structure.appendages[:2])


def _tilted_slew(t_final: float) -> VectorTorque:
    times = np.linspace(0.0, t_final, round(t_final / 0.01) + 1)
    magnitude = 0.5 * np.sin(2.0 * np.pi * times / t_final)
    return VectorTorque(times, np.outer(magnitude, [0.6, 0.0, 0.8]))


def _tip_error(result, reference) -> float:
    worst = 0.0
    for name, tips in reference.tips.items():
        peaks = np.max(np.abs(tips), axis=1)
        worst = max(worst, float(np.max(np.max(np.abs(result.tips[name] - tips), axis=1)
                                        / peaks)))
    return worst


@pytest.mark.slow
def test_a_stiff_spatial_slew_agrees_with_adams_moulton_and_knows_its_error(monkeypatch):
    """The two arrays of ``spatial-two-arrays.toml`` (3 modes per field), a 2 s tilted slew
    from samples, rtol 1e-8: the exponential steps (taken: the fastest mode turns some 26
    radians between outputs) and Adams-Moulton agree with a run at rtol 1e-11 to 1e-6 of each
    tip component's peak, the exponential run with under a third of the evaluations (measured:
    6 723 against 25 656); its error estimate is within a factor 10 of its error."""
    from flexctl.sim.spatial_run import simulate_spatial

    arrays, torque = _two_arrays(), _tilted_slew(2.0)

    def run(rtol, check=True):
        return simulate_spatial(arrays, 2.0, torque, n_modes=3, rtol=rtol, output_step=0.01,
                                check_accuracy=check)

    reference = run(1e-11, check=False)
    fast = run(1e-8)
    monkeypatch.setattr(spatial_run, "EXPONENTIAL", False)
    adams = run(1e-8)
    assert fast.status == adams.status == "ok"
    errors = {"exponential": _tip_error(fast, reference), "adams": _tip_error(adams, reference)}
    assert max(errors.values()) < 1e-6, errors
    assert fast.n_evaluations * 3 < adams.n_evaluations, (fast.n_evaluations,
                                                         adams.n_evaluations)
    assert errors["exponential"] / 10 < fast.integration_error < 10 * errors["exponential"]
    assert fast.quaternion_drift < 1e-8


def test_runs_that_are_not_stiff_or_carry_wheels_stay_on_adams_moulton():
    """The choice of :class:`~flexctl.sim.spatial_run._Plan`: exponential steps for the two
    arrays sampled every 0.01 s; Adams-Moulton for the same arrays sampled every 1e-4 s (the
    fastest mode then turns under a radian between outputs), for a structure with reaction
    wheels, and with ``EXPONENTIAL`` off."""
    from flexctl.model.spatial_dynamics import spatial_equations
    from flexctl.model.wheel_cluster import Wheel, WheelCluster
    from flexctl.sim.spatial_run import _Plan, _torque_function, _with_wheels, initial_state

    equations = spatial_equations(_two_arrays(), 2, "exact")
    x0 = initial_state(equations)
    drive, breakpoints = _torque_function(np.array([0.1, 0.0, 0.0]))

    def plan(equations, step):
        times = np.arange(0.0, 0.5 + step / 2, step)
        return _Plan(equations, initial_state(equations), times, drive, breakpoints)

    assert plan(equations, 0.01).jacobian is not None
    fastest = np.max(np.abs(np.linalg.eigvals(plan(equations, 0.01).jacobian)))
    assert fastest * 0.01 > spatial_run.STIFF_SPACING > fastest * 1e-4
    assert plan(equations, 1e-4).jacobian is None
    cluster = WheelCluster(wheels=tuple(Wheel(axis=axis, inertia=0.01, torque_limit=0.05,
                                              speed_limit=40.0)
                                        for axis in ((1, 0, 0), (0, 1, 0), (0, 0, 1))))
    assert plan(_with_wheels(equations, cluster), 0.01).jacobian is None
    spatial_run.EXPONENTIAL, saved = False, spatial_run.EXPONENTIAL
    try:
        assert plan(equations, 0.01).jacobian is None
    finally:
        spatial_run.EXPONENTIAL = saved
    assert x0.size == equations.layout.n_states


@pytest.mark.parametrize("change, words", [
    ({"rtol": 0.0}, "rtol"), ({"rtol": float("nan")}, "rtol"), ({"atol": -1.0}, "atol"),
    ({"n_states": 0}, "n_states"), ({"n_states": 2.5}, "n_states"),
    ({"max_steps": 0}, "max_steps"), ({"drive": lambda t: np.zeros(3)}, "segment_form"),
    ({"modal": (np.array([0, 1]), np.array([2]))}, "modal"),
    ({"modal": (np.array([0, 9]), np.array([2, 3]))}, "modal"),
])
def test_exponential_segments_refuse_bad_arguments_by_name(change, words):
    arguments = {"rhs": _linear_rhs(), "n_states": 4, "drive": ConstantTorque(np.zeros(3)),
                 "rtol": 1e-6, "atol": 1e-9, "line": False, "max_steps": 100,
                 "modal": (np.array([0, 1]), np.array([2, 3]))}
    with pytest.raises((TypeError, ValueError), match=words):
        ExponentialSegments(**{**arguments, **change})


@pytest.mark.parametrize("x, torque, mapped_columns, words", [
    ([0.0, np.nan, 0.0, 0.0], [0.0, 0.0, 0.0], 8, "x"),
    ([0.0, 0.0, 0.0, 0.0], [0.0, 0.0], 8, "torque"),
    ([0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 5, "mapped"),
    ("four", [0.0, 0.0, 0.0], 8, "x"),
])
def test_central_jacobian_refuses_bad_arguments_by_name(x, torque, mapped_columns, words):
    with pytest.raises((TypeError, ValueError), match=words):
        central_jacobian(_linear_rhs().map(mapped_columns), x, torque)


def test_a_spin_up_that_holds_the_exponential_steps_goes_on_adams_moulton(monkeypatch):
    """1000 N m on the two arrays spins the hub to 67 rad/s in 0.2 s: the exponential steps'
    error estimate holds them below a radian of the fastest mode, so the run gives the segment
    to Adams-Moulton (from its start) and ends as Adams-Moulton alone does, to its error."""
    from flexctl.sim.spatial_run import simulate_spatial

    arrays = _two_arrays()
    given = simulate_spatial(arrays, 0.2, [1e3, 0.0, 0.0], n_modes=3, output_step=0.02)
    monkeypatch.setattr(spatial_run, "EXPONENTIAL", False)
    adams = simulate_spatial(arrays, 0.2, [1e3, 0.0, 0.0], n_modes=3, output_step=0.02)
    assert given.status == adams.status == "ok"
    assert given.n_steps > adams.n_steps            # the abandoned steps are counted
    assert _tip_error(given, adams) < 10 * max(given.integration_error,
                                               adams.integration_error)
    np.testing.assert_allclose(given.angular_velocity, adams.angular_velocity, rtol=1e-6)


def test_a_held_run_beside_the_caller_goes_on_where_no_integrator_may_be_built():
    """Held torques of six lengths (Adams-Moulton would need six integrators, not built ahead):
    the 1000 N m spin-up abandons its exponential steps in the caller's thread (the fallback
    built there) and keeps them, its floor dropped, in another thread (CasADi's symbolic work
    is not thread-safe); both runs end ok and agree."""
    import threading

    from flexctl.model.spatial_dynamics import spatial_equations
    from flexctl.sim.spatial_run import _Plan, _torque_function, initial_state

    equations = spatial_equations(_two_arrays(), 3, "exact")
    ends = [0.0, 0.01, 0.03, 0.06, 0.1, 0.15, 0.21]
    drive, breakpoints = _torque_function(VectorTorque(ends, [[1e3, 0.0, 0.0]] * 7, "hold"))
    plan = _Plan(equations, initial_state(equations), np.linspace(0.0, 0.21, 22), drive,
                 breakpoints)
    here, beside = plan.integration(1e-8, 1e-11), plan.integration(1e-8, 1e-11)
    assert not here.fallback_built and not beside.fallback_built
    out = {}
    thread = threading.Thread(target=lambda: out.update(beside=beside()))
    thread.start()
    thread.join()
    out["here"] = here()
    assert out["here"][0] == out["beside"][0] == "ok"
    assert isinstance(here.segments, spatial_run.SpatialSegments)
    assert isinstance(beside.segments, ExponentialSegments)
    # each state within 1e-4 of its largest value over the run (measured: 1.6e-5)
    here_states, beside_states = out["here"][1], out["beside"][1]
    peaks = np.maximum(np.max(np.abs(here_states), axis=1), 1e-12)
    assert np.max(np.max(np.abs(beside_states - here_states), axis=1) / peaks) < 1e-4
