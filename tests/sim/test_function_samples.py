"""A torque function CasADi cannot trace is sampled into a piecewise cubic that runs compiled:
the cubic follows the function within its tolerance, jumps are located and become breakpoints,
the run says what it did and its error estimate counts the sampling's error."""

from __future__ import annotations

import numpy as np
import pytest

from flexctl import build_model, load_scene, simulate
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim import function_samples
from flexctl.sim.function_samples import (JUMP_FRACTION, SampledFunction, recorded_sampling,
                                          sample_function)
from flexctl.sim.validity import geometric_error


def branching_push(t):
    return 2.0 * np.sin(np.pi * t) if t <= 2.0 else 0.0


def bang_bang(t):
    return 1.0 if t < 1.0 else (-1.0 if t < 2.5 else 0.0)


@pytest.fixture(scope="module")
def model():
    return build_model(load_scene("hub-beam-mass").system, n_modes=4)


def test_the_cubic_follows_a_smooth_function_within_its_tolerance():
    samples, reason = sample_function(branching_push, 10.0, 1e-9)
    assert reason == "" and samples.jumps == ()
    t = np.linspace(0.0, 10.0, 200_001)
    exact = np.array([branching_push(v) for v in t])
    # the checks look at three points an interval; between them the cubic is as close
    assert np.max(np.abs(samples(t) - exact)) < 3e-9


def test_a_cubic_is_sampled_exactly_on_the_start_intervals():
    samples, _ = sample_function(lambda t: 1.0 - 2.0 * t + 0.5 * t ** 3, 4.0, 1e-12)
    assert samples.coefficients.shape[0] == function_samples.START_INTERVALS
    t = np.linspace(0.0, 4.0, 1001)
    assert np.allclose(samples(t), 1.0 - 2.0 * t + 0.5 * t ** 3, rtol=0.0, atol=1e-12)


def test_jumps_are_located_and_held_to_the_right():
    samples, _ = sample_function(bang_bang, 4.0, 1e-10)
    assert len(samples.jumps) == 2
    for found, true in zip(samples.jumps, (1.0, 2.5)):
        assert true - JUMP_FRACTION * 4.0 <= found <= true
    assert samples.breakpoints == samples.jumps
    t = np.array([0.0, 0.99, 1.0, 1.7, 2.5, 3.9, 4.0])
    assert np.allclose(samples(t), [bang_bang(v) for v in t], rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("function, t_final", [
    (branching_push, 4.0), (bang_bang, 4.0),
    # a cubic: exactly the start intervals, a full size class (its last interval once
    # extrapolated to)
    (lambda t: 1.0 - 2.0 * t + 0.5 * t ** 3, 1.0)])
def test_the_compiled_form_equals_the_numpy_form(function, t_final):
    import casadi as ca

    samples, _ = sample_function(function, t_final, 1e-9)
    t = ca.SX.sym("t")
    numbers = ca.SX.sym("c", samples.casadi_parameters[1].size)
    fixed = ca.Function("fixed", [t], [samples.casadi(t)])
    parametric = ca.Function("parametric", [t, numbers], [samples.casadi(t, numbers)])
    grid = np.concatenate([np.linspace(-1.0, t_final + 1.0, 3001), samples.knots,
                           samples.knots[-1] - np.logspace(-12, -2, 11)])
    expected = samples(grid)
    assert np.array_equal(np.array(fixed.map(grid.size)(grid[None, :])).ravel(), expected)
    assert np.array_equal(np.array(parametric.map(grid.size)(
        grid[None, :], samples.casadi_parameters[1])).ravel(), expected)


def test_samplings_of_one_size_class_share_their_structure():
    a, _ = sample_function(branching_push, 10.0, 1e-9)
    b, _ = sample_function(lambda t: 1.5 * np.cos(2.0 * t) if t <= 3.0 else 0.2, 10.0, 1e-9)
    assert a.size_class == b.size_class
    assert a.casadi_parameters[0] == b.casadi_parameters[0]
    assert a.casadi_parameters[1].size == b.casadi_parameters[1].size


def test_a_declared_breakpoint_shows_a_pulse_the_start_grid_misses():
    def pulse(t):
        return 1.0 if 5.01 <= t < 5.0105 else 0.0

    blind, _ = sample_function(pulse, 10.0, 1e-9)
    assert np.max(np.abs(blind(np.linspace(5.01, 5.0105, 11)))) == 0.0
    pulse.breakpoints = (5.01, 5.0105)
    seen, _ = sample_function(pulse, 10.0, 1e-9)
    assert float(seen(5.0102)) == pytest.approx(1.0, abs=1e-12)
    assert float(seen(5.011)) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("bad, why", [
    (lambda t: float("nan") if t > 1.0 else 0.0, "calling it at t = "),
    (lambda t: 1.0 / (t - t) if t > 2.0 else 0.0, "ZeroDivisionError"),
])
def test_a_function_with_a_bad_value_is_not_sampled(bad, why):
    samples, reason = sample_function(bad, 4.0, 1e-9)
    assert samples is None and why in reason


def test_noise_exceeds_the_call_budget(monkeypatch):
    monkeypatch.setattr(function_samples, "MAX_EVALUATIONS", 5000)
    rng = np.random.default_rng(3)
    samples, reason = sample_function(lambda t: float(rng.normal()), 4.0, 1e-6)
    assert samples is None and reason == "it needed more than 5000 calls"


@pytest.mark.parametrize("argument, value", [("t_final", 0.0), ("t_final", np.inf),
                                             ("tolerance", -1.0), ("tolerance", np.nan),
                                             ("t_final", "4"), ("function", 3.0)])
def test_bad_arguments_are_refused_by_name(argument, value):
    kwargs = {"function": branching_push, "t_final": 4.0, "tolerance": 1e-9, argument: value}
    with pytest.raises((InputValueError, InputTypeError), match=f"sample_function.{argument}"):
        sample_function(**kwargs)


@pytest.mark.parametrize("function", [branching_push, bang_bang])
def test_simulate_runs_a_sampled_function_compiled_and_its_estimate_holds(model, function):
    run = simulate(model, 6.0, torque=function, check_validity=False)
    assert run.status == "ok" and run.method != "DOP853"
    assert "could not be traced" in run.message and "cubic pieces" in run.message
    # the replay beside the run took the looser sampling: no third run
    assert "the accuracy check ran on the function sampled at 10 times" in run.message
    reference = simulate(model, 6.0, torque=function, method="DOP853", rtol=1e-12,
                         check_validity=False)
    error = np.max(np.abs(run.tip_deflection - reference.tip_deflection))
    assert np.max(np.abs(reference.tip_deflection)) > 1e-2
    assert error <= run.integration_error < 1e-5


def test_a_looser_tolerance_samples_coarser(model):
    # two function objects: a sampling made for one is not the other's
    fine = simulate(model, 4.0, torque=lambda t: branching_push(t), rtol=1e-10,
                    check_validity=False)
    coarse = simulate(model, 4.0, torque=lambda t: branching_push(t), rtol=1e-5,
                      check_validity=False)
    pieces = [int(r.message.split(" cubic pieces")[0].split()[-1]) for r in (fine, coarse)]
    assert pieces[0] > 2 * pieces[1]


def test_a_run_with_its_checks_asks_the_function_once_per_time(model):
    """The run's sampling, the torque's size before it and the accuracy check's looser
    sampling share the function's values: no time is asked twice (a run with its checks
    called it 6 223 times before, 1 882 since, at rtol 1e-5 over 20 s)."""
    asked = []

    def counted(t):
        asked.append(t)
        return branching_push(t)

    run = simulate(model, 20.0, torque=counted, rtol=1e-5)
    assert run.status == "ok" and run.integration_error is not None
    assert len(asked) == len(set(asked))


def test_the_validity_estimate_replays_the_run_sampling(model):
    """The estimate's two runs take the run's sampled torque, not the function: the same
    calls with the estimate as without it, and the estimate of the traced function's."""
    calls = []

    def counted(t):
        calls.append(t)
        return branching_push(t)

    def fresh(t):                  # another function object: sampled anew
        return branching_push(t)

    without = simulate(model, 6.0, torque=counted, rtol=1e-6, check_validity=False)
    asked = len(calls)
    calls.clear()
    run = simulate(model, 6.0, torque=lambda t: counted(t), rtol=1e-6)
    assert without.status == run.status == "ok" and asked > 100
    assert len(calls) == asked, "the validity estimate called the function again"
    traced = geometric_error(model, 6.0, torque=lambda t: np.where(
        t <= 2.0, 2.0 * np.sin(np.pi * t), 0.0))
    assert traced > 1e-5
    assert run.validity.geometric_error == pytest.approx(traced, rel=1e-3)
    # a function never sampled is called by the estimate (nothing recorded to replay)
    assert recorded_sampling(fresh, 6.0) is fresh
    assert isinstance(recorded_sampling(counted, 6.0), SampledFunction)
    assert recorded_sampling(counted, 5.0) is counted


def test_a_state_feedback_function_is_called_at_every_step_and_says_so(model):
    def law(t, x):
        return -50.0 * x[0] if t > 0.5 else 0.0
    run = simulate(model, 1.0, torque=law, check_validity=False,
                   x0=np.r_[0.01, np.zeros(model.n_states - 1)])
    assert run.status == "ok" and run.method == "DOP853"
    assert "the torque function was called at every step" in run.message


def test_the_bad_value_is_reported_with_its_time_by_the_python_path(model):
    with pytest.raises(InputValueError, match=r"t = 1\.\d* s"):
        simulate(model, 2.0, torque=lambda t: float("nan") if t > 1.0 else 0.0,
                 check_validity=False)


def test_the_sampled_function_is_the_run_input_type():
    samples, _ = sample_function(branching_push, 3.0, 1e-8)
    assert isinstance(samples, SampledFunction) and not samples.state_dependent
    assert "cubic pieces" in repr(samples)


def test_a_check_that_cannot_take_the_looser_sampling_reruns_on_it(model):
    # the fixed step's step doubling integrates the run's own torque: the sampling's error
    # comes from a run on the looser sampling, added to the estimate
    run = simulate(model, 2.0, torque=branching_push, method="rk4", rtol=1e-4,
                   check_validity=False)
    assert run.status == "ok" and run.method == "rk4"
    assert "integration_error includes the sampling's," in run.message
    reference = simulate(model, 2.0, torque=branching_push, method="DOP853", rtol=1e-12,
                         check_validity=False)
    assert np.max(np.abs(run.tip_deflection - reference.tip_deflection)) <= \
        run.integration_error
