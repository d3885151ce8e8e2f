"""Sampled torques and traced Python torque functions (issue 9, item 2).

The interpolants are checked against numpy and SciPy (``np.interp``; ``CubicSpline`` with the
not-a-knot ends CasADi's spline has; an explicit zero-order hold), their numpy and CasADi forms
against each other bit for bit, the compiled runs against SciPy runs and against an explicit
piecewise-constant integration, and tracing against the Python function it replaces.
"""

import math
import pickle

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from flexctl import build_model, simulate
from flexctl.model.errors import InputError, InputTypeError, InputValueError
from flexctl.sim import fixed_step
from flexctl.sim.digital import ZeroOrderHold
from flexctl.sim.inputs import SampledTorque, sampled_torque
from flexctl.sim.tracing import TracedStateTorque, TracedTorque, trace_torque

#: numpy and CasADi linear interpolation differ by rounding only (relative to the peak)
ROUNDING = 1e-14
#: a not-a-knot spline solved by two codes (a banded solve each): a few hundred roundings
SPLINE_AGREEMENT = 1e-10
#: compiled and SciPy runs at RTOL agree on the tip within this fraction of its peak
RTOL = 1e-10
PATHS_AGREE = 1e-7
T_FINAL = 3.0
INTERPOLATIONS = ("hold", "linear", "spline")

#: The compiled paths a run with CasADi inputs may take under method="auto".
COMPILED = ("cvodes", "RK45", "dop853")


@pytest.fixture(scope="module")
def model(hub_beam_mass_system):
    return build_model(hub_beam_mass_system, n_modes=2)


def random_samples(rng, count, start=0.0, stop=T_FINAL):
    """Uneven sample times from ``start`` to ``stop`` and torques of mixed sizes."""
    gaps = rng.uniform(0.2, 1.0, count - 1)
    times = start + np.concatenate(([0.0], np.cumsum(gaps))) * (stop - start) / gaps.sum()
    times[-1] = stop
    return times, rng.normal(size=count) * 10.0 ** rng.uniform(-2, 1, count)


def query_times(times, rng):
    """The sample times, their float neighbours, random times inside and outside."""
    return np.concatenate([times, np.nextafter(times, -np.inf), np.nextafter(times, np.inf),
                           rng.uniform(times[0] - 1.0, times[-1] + 1.0, 400)])


def casadi_values(torque, t, sym=ca.SX):
    """The CasADi form of ``torque`` evaluated at the times ``t`` (through ``sym`` symbols)."""
    ts = sym.sym("t")
    form = ca.Function("form", [ts], [torque.casadi(ts)])
    return np.array(form.map(t.size)(t[None, :])).reshape(-1)


# ------------------------------------------------------------------ the interpolants
@pytest.mark.parametrize("count", [4, 9, 200], ids=["4-samples", "9-samples", "200-samples"])
def test_linear_is_numpy_interp(rng, count):
    times, values = random_samples(rng, count)
    t = query_times(times, rng)
    torque = SampledTorque(times, values)
    np.testing.assert_allclose(torque(t), np.interp(t, times, values), rtol=0,
                               atol=ROUNDING * np.max(np.abs(values)))


@pytest.mark.parametrize("count", [4, 9, 200], ids=["4-samples", "9-samples", "200-samples"])
def test_spline_is_scipy_not_a_knot_inside_and_holds_the_ends_outside(rng, count):
    times, values = random_samples(rng, count)
    t = query_times(times, rng)
    torque = SampledTorque(times, values, interpolation="spline")
    inside = (t >= times[0]) & (t <= times[-1])
    reference = CubicSpline(times, values, bc_type="not-a-knot")(t[inside])
    np.testing.assert_allclose(torque(t[inside]), reference, rtol=0,
                               atol=SPLINE_AGREEMENT * np.max(np.abs(values)))
    assert np.all(torque(t[t < times[0]]) == torque(times[0]))
    assert np.all(torque(t[t > times[-1]]) == torque(times[-1]))
    # a natural spline (zero curvature at the ends) is a different curve: the test can tell
    natural = CubicSpline(times, values, bc_type="natural")(t[inside])
    assert np.max(np.abs(torque(t[inside]) - natural)) > 1e3 * SPLINE_AGREEMENT


@pytest.mark.parametrize("count", [2, 9, 200], ids=["2-samples", "9-samples", "200-samples"])
def test_hold_is_the_explicit_zero_order_hold(rng, count):
    times, values = random_samples(rng, count)
    t = query_times(times, rng)
    # values[k] on [times[k], times[k+1]), the first before, the last after, written out
    expected = np.empty_like(t)
    for i, ti in enumerate(t):
        k = 0
        while k + 1 < count and times[k + 1] <= ti:
            k += 1
        expected[i] = values[k]
    torque = SampledTorque(times, values, interpolation="hold")
    np.testing.assert_array_equal(torque(t), expected)
    np.testing.assert_array_equal(casadi_values(torque, t), expected)


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
@pytest.mark.parametrize("sym", [ca.SX, ca.MX], ids=["SX", "MX"])
def test_numpy_form_is_the_casadi_form_bit_for_bit(rng, interpolation, sym):
    times, values = random_samples(rng, 50)
    torque = SampledTorque(times, values, interpolation=interpolation)
    t = query_times(times, rng)
    np.testing.assert_array_equal(torque(t), casadi_values(torque, t, sym))
    assert float(torque(float(t[7]))) == casadi_values(torque, t[7:8], sym)[0]
    assert torque(t.reshape(2, -1)).shape == (2, t.size // 2)


@pytest.mark.parametrize("interpolation", ["linear", "spline"])
def test_a_near_uniform_grid_bounds_the_step_by_its_shortest_interval(rng, interpolation):
    times, values = random_samples(rng, 9)          # intervals within a factor 5 of each other
    torque = SampledTorque(times, values, interpolation=interpolation)
    assert torque.max_step == np.min(np.diff(times))
    assert torque.breakpoints == (times[0], times[-1])


def test_every_jump_of_a_hold_is_a_breakpoint_on_any_grid(rng):
    # a step across a jump is wrong to first order in its length, whatever its tolerance
    for times in (random_samples(rng, 9)[0], np.linspace(0.0, 3.0, 7)):
        torque = SampledTorque(times, rng.normal(size=times.size), interpolation="hold")
        assert torque.max_step is None
        assert torque.breakpoints == tuple(times)


@pytest.mark.parametrize("interpolation, restarts", [
    ("hold", True), ("linear", True), ("spline", False)])
def test_an_uneven_grid_restarts_at_every_sample_where_the_torque_is_not_smooth(
        rng, interpolation, restarts):
    times = np.array([0.0, 1e-3, 1.0, 2.0, 3.0])    # one interval 1/750 of the mean
    torque = SampledTorque(times, rng.normal(size=5), interpolation=interpolation)
    assert torque.max_step is None
    assert torque.breakpoints == (tuple(times) if restarts else (times[0], times[-1]))


def test_a_pickled_torque_is_the_same_torque(rng):
    times, values = random_samples(rng, 12)
    torque = SampledTorque(times, values, interpolation="spline")
    torque.casadi(ca.SX.sym("t"))            # builds the CasADi function, which is not pickled
    again = pickle.loads(pickle.dumps(torque))
    t = query_times(times, rng)
    np.testing.assert_array_equal(again(t), torque(t))


# ------------------------------------------------------------------ sampled runs
def sampled_push(rng, count=31):
    """Samples of a smooth push over the run, with a little noise."""
    times = np.linspace(0.0, T_FINAL, count)
    return times, 0.5 * np.sin(2.0 * times) + 0.05 * rng.standard_normal(count)


@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_compiled_and_scipy_paths_agree(model, rng, interpolation):
    torque = SampledTorque(*sampled_push(rng), interpolation=interpolation)
    compiled = simulate(model, T_FINAL, torque=torque, rtol=RTOL)
    scipy_run = simulate(model, T_FINAL, torque=torque, rtol=RTOL, method="DOP853")
    assert compiled.method in COMPILED and scipy_run.method == "DOP853"
    np.testing.assert_allclose(compiled.tip_deflection, scipy_run.tip_deflection, rtol=0,
                               atol=PATHS_AGREE * scipy_run.peak_tip_deflection)
    np.testing.assert_array_equal(compiled.torque, torque(compiled.t))


def test_a_pair_is_linear_interpolation(model, rng):
    times, values = sampled_push(rng)
    pair = simulate(model, T_FINAL, torque=(times, values), rtol=RTOL)
    explicit = simulate(model, T_FINAL, torque=SampledTorque(times, values), rtol=RTOL)
    assert pair.method in COMPILED
    np.testing.assert_array_equal(pair.states, explicit.states)
    np.testing.assert_allclose(pair.torque, np.interp(pair.t, times, values), rtol=0,
                               atol=ROUNDING * np.max(np.abs(values)))


@pytest.mark.parametrize("method", ["cvodes", "DOP853", "rk4"])
def test_max_step_bounds_every_path(model, method):
    free = simulate(model, 1.0, torque=TRACEABLE["sine"], method=method, rtol=1e-3,
                    check_accuracy=False)
    bounded = simulate(model, 1.0, torque=TRACEABLE["sine"], method=method, rtol=1e-3,
                       check_accuracy=False, max_step=1e-3)
    assert free.n_evaluations < 1000 <= bounded.n_evaluations


def piecewise_constant_reference(model, times, values, t_out):
    """The model integrated hold by hold with the torque a constant, at rtol 1e-12."""
    x = np.zeros(model.n_states)
    states = [x]
    for k in range(len(times) - 1):
        lo, hi = times[k], times[k + 1]
        inside = t_out[(t_out > lo) & (t_out <= hi)]
        sol = solve_ivp(lambda t, y, u=values[k]: model.dynamics(t, y, u), (lo, hi), x,
                        method="DOP853", rtol=1e-12, atol=1e-15,
                        t_eval=np.append(inside, hi) if inside.size == 0 or inside[-1] < hi
                        else inside)
        keep = np.isin(sol.t, inside)
        states.append(sol.y[:, keep])
        x = sol.y[:, -1]
    return np.column_stack(states)


def test_hold_matches_a_piecewise_constant_integration(model, rng):
    times = np.linspace(0.0, T_FINAL, 13)
    values = rng.uniform(-1.0, 1.0, times.size)
    result = simulate(model, T_FINAL, torque=SampledTorque(times, values, interpolation="hold"),
                      rtol=RTOL, output_step=0.05)
    reference = piecewise_constant_reference(model, times, values, result.t)
    tip = model.tip_deflection(reference)
    np.testing.assert_allclose(result.tip_deflection, tip, rtol=0,
                               atol=PATHS_AGREE * np.max(np.abs(tip)))
    np.testing.assert_allclose(result.theta, reference[0], rtol=0,
                               atol=PATHS_AGREE * np.max(np.abs(reference[0])))


@pytest.mark.parametrize("interpolation", ["hold", "linear"])
@pytest.mark.parametrize("grid", ["uniform", "uneven"])
@pytest.mark.parametrize("method", ["cvodes", "DOP853"])
def test_a_short_pulse_after_a_quiet_start_is_not_stepped_over(model, interpolation, grid,
                                                               method):
    """At rest the integrator's steps grow long; a one-sample pulse between two samples is
    seen only because no step may be longer than a sample interval (a line on a uniform grid)
    or the integration restarts at every sample time (a hold, an uneven grid)."""
    times = np.linspace(0.0, T_FINAL, 301)
    if grid == "uneven":
        times = np.insert(times, 1, 1e-5)
    values = np.zeros(times.size)
    values[np.searchsorted(times, 2.0)] = 1.0       # 2.00 s to 2.01 s
    torque = SampledTorque(times, values, interpolation=interpolation)
    assert (torque.max_step is None) == (grid == "uneven" or interpolation == "hold")
    result = simulate(model, T_FINAL, torque=torque, rtol=1e-8, method=method)
    # the angular momentum about the hub axis is the torque's impulse, 0.01 N m s for the
    # 0.01 s hold and for the triangle of the linear interpolation, 0.02 s wide
    assert model.angular_momentum(result.states[:, 0]) == 0.0
    assert model.angular_momentum(result.states[:, -1]) == pytest.approx(0.01, rel=1e-6)


# ------------------------------------------------------------------ traced functions
def _state_feedback(model):
    n = model.n_modes
    gains = np.zeros(model.n_states)
    gains[0], gains[n + 1] = 2.0, 3.0
    return lambda t, x: -gains @ x + 0.3 * np.sin(2.0 * t)


TRACEABLE = {
    "sine": lambda t: 0.5 * np.sin(3.0 * t),
    "exp-cos": lambda t: np.exp(-t) * np.cos(4.0 * t),
    "where": lambda t: np.where(t < 1.0, 0.5, -0.25),
    "clip": lambda t: np.clip(2.0 * t - 1.0, -0.3, 0.3),
}


@pytest.mark.parametrize("name", sorted(TRACEABLE))
def test_a_traceable_function_runs_compiled_and_matches_dop853(model, name):
    torque = TRACEABLE[name]
    traced = simulate(model, T_FINAL, torque=torque, rtol=RTOL)
    python = simulate(model, T_FINAL, torque=torque, rtol=RTOL, method="DOP853")
    assert traced.method in COMPILED and python.method == "DOP853"
    np.testing.assert_allclose(traced.tip_deflection, python.tip_deflection, rtol=0,
                               atol=PATHS_AGREE * python.peak_tip_deflection)
    np.testing.assert_allclose(traced.torque, python.torque, rtol=0, atol=1e-12)


def test_a_traceable_feedback_of_the_state_runs_compiled(model):
    torque = _state_feedback(model)
    x0 = np.zeros(model.n_states)
    x0[0] = 0.2
    traced = simulate(model, T_FINAL, torque=torque, x0=x0, rtol=RTOL)
    python = simulate(model, T_FINAL, torque=torque, x0=x0, rtol=RTOL, method="DOP853")
    assert traced.method in COMPILED
    for name in ("theta", "tip_deflection", "torque"):
        expected = getattr(python, name)
        np.testing.assert_allclose(getattr(traced, name), expected, rtol=0,
                                   atol=PATHS_AGREE * np.max(np.abs(expected)), err_msg=name)


def _counting():
    calls = []

    def torque(t):
        calls.append(t)
        return 1e-3 * len(calls)
    return torque


def _no_casadi_form():
    def torque(t):
        return 0.5 * np.sin(3.0 * t)
    torque.has_casadi_form = False
    return torque


UNTRACEABLE = {
    "branch": lambda t: 0.5 if t < 1.0 else -0.25,
    "math-module": lambda t: 0.5 * math.sin(3.0 * t),
    "type-test": lambda t: 0.5 * np.sin(t) if isinstance(t, float) else 0.0 * t,
    "opted-out": _no_casadi_form(),
}
#: functions that are not functions of their arguments: their trace is a frozen snapshot,
#: which the checks catch (and which no integrator can follow: not run here)
IMPURE = {
    "random": lambda t: 0.5 * np.sin(3.0 * t) + 1e-3 * np.random.default_rng().normal(),
    "counter": _counting(),
}


@pytest.mark.parametrize("name", sorted(UNTRACEABLE))
def test_an_untraceable_function_is_sampled_unless_it_opts_out(model, name):
    torque = UNTRACEABLE[name]
    assert trace_torque(torque, t_final=T_FINAL)[0] is None
    result = simulate(model, 0.5, torque=torque, rtol=1e-6, check_accuracy=False)
    if name == "opted-out":
        assert result.method == "DOP853"
        assert "the torque function was called at every step" in result.message
    else:
        assert result.method != "DOP853" and "cubic pieces" in result.message


@pytest.mark.parametrize("name", sorted(IMPURE))
def test_an_impure_function_is_not_traced(name):
    traced, reason = trace_torque(IMPURE[name], t_final=T_FINAL)
    assert traced is None and "not a pure function" in reason


def test_tracing_says_why_when_cvodes_is_demanded(model):
    with pytest.raises(InputValueError, match=r"method 'cvodes'.*could not be traced: "
                                              r"calling it with a CasADi symbol raised"):
        simulate(model, 1.0, torque=lambda t, x: 0.5 if t < 1.0 else -0.25 + 0.0 * x[0],
                 method="cvodes")


def test_a_scipy_method_calls_the_function_itself(model):
    calls = []

    def torque(t):
        calls.append(t)
        return 0.5 * np.sin(3.0 * t)
    result = simulate(model, 0.5, torque=torque, rtol=1e-6, method="DOP853")
    assert result.method == "DOP853" and len(calls) > 50


def test_a_python_controller_keeps_a_traceable_torque_on_scipy(model):
    result = simulate(model, 0.5, torque=TRACEABLE["sine"], controller=lambda t, x: -x[0],
                      rtol=1e-6)
    assert result.method == "DOP853"


class _SineForm:
    """``0.3 sin(2 t)`` written with its CasADi form by hand, to compare a trace with."""

    def casadi(self, t):
        return 0.3 * ca.sin(2.0 * t)

    def __call__(self, t):
        return 0.3 * np.sin(2.0 * np.asarray(t, dtype=float))


def test_a_traced_torque_joins_a_sampled_controller(model):
    law = ZeroOrderHold(lambda t, x: -2.0 * x[0] - 3.0 * x[model.n_modes + 1], 0.05)
    traced = simulate(model, 1.0, torque=lambda t: 0.3 * np.sin(2.0 * t), controller=law,
                      rtol=1e-8)
    by_hand = simulate(model, 1.0, torque=_SineForm(), controller=law, rtol=1e-8)
    # both on a compiled sample-to-sample integrator (not SciPy's)
    assert traced.method == by_hand.method and traced.method in ("cvodes", "RK45")
    np.testing.assert_array_equal(traced.states, by_hand.states)


@pytest.mark.parametrize("torque", ["samples", "traced"])
def test_the_fixed_step_path_takes_them(model, rng, torque, monkeypatch):
    # the CasADi virtual machine: compiling to C (seconds a new input) is fixed_step's concern
    monkeypatch.setattr(fixed_step, "USE_JIT", False)
    torque = (SampledTorque(*sampled_push(rng), interpolation="spline") if torque == "samples"
              else TRACEABLE["sine"])
    fixed = simulate(model, T_FINAL, torque=torque, method="rk4", rtol=1e-3)
    tight = simulate(model, T_FINAL, torque=torque, rtol=RTOL)
    assert fixed.method == "rk4"
    np.testing.assert_allclose(fixed.tip_deflection, tight.tip_deflection, rtol=0,
                               atol=1e-3 * tight.peak_tip_deflection)


def test_a_function_passed_again_reuses_its_trace_unless_it_changed():
    amplitude = [0.5]

    def torque(t):
        return amplitude[0] * np.sin(3.0 * t)
    first = trace_torque(torque, t_final=T_FINAL)[0]
    assert trace_torque(torque, t_final=T_FINAL)[0] is first     # compiled caches hit
    amplitude[0] = 0.5 + 1e-9
    changed = trace_torque(torque, t_final=T_FINAL)[0]
    assert changed is not first and float(changed(1.0)) == torque(1.0)


def test_equal_samples_give_one_torque(model, rng):
    times, values = sampled_push(rng)
    first = sampled_torque((times, values), T_FINAL)
    assert sampled_torque((times.copy(), list(values)), T_FINAL) is first
    values[3] += 1e-9
    changed = sampled_torque((times, values), T_FINAL)
    assert changed is not first and changed(times[3]) == values[3]


def test_trace_kinds_and_forms(model):
    traced, reason = trace_torque(TRACEABLE["sine"], t_final=T_FINAL)
    assert isinstance(traced, TracedTorque) and not traced.state_dependent and reason == ""
    t = np.linspace(0.0, T_FINAL, 7)
    np.testing.assert_allclose(traced(t), TRACEABLE["sine"](t), rtol=1e-15)
    feedback, _ = trace_torque(_state_feedback(model), t_final=T_FINAL,
                               n_states=model.n_states)
    assert isinstance(feedback, TracedStateTorque) and feedback.state_dependent
    assert trace_torque(_state_feedback(model), t_final=T_FINAL)[0] is None   # no state size


# ------------------------------------------------------------------ bad input
BAD_SAMPLES = [
    (([0.0, 1.0], [1.0, 2.0, 3.0]), InputValueError,
     r"values must hold one torque per sample time.*shape \(2,\).*got shape \(3,\)"),
    (([0.0, 1.0, 1.0, 3.0], [1.0, 2.0, 3.0, 4.0]), InputValueError,
     r"times must be strictly increasing.*times\[2\] = 1\.0 after times\[1\] = 1\.0"),
    (([0.0, np.nan, 3.0], [1.0, 2.0, 3.0]), InputValueError,
     r"times must be finite.*times\[1\] = nan"),
    (([0.0, 1.0, 3.0], [1.0, np.inf, 3.0]), InputValueError,
     r"values must be finite.*values\[1\] = inf"),
    (([0.0], [1.0]), InputValueError, r"'linear' needs at least 2 samples; got 1"),
    ({"interpolation": "spline"}, InputValueError, r"'spline' needs at least 4 samples; "
                                                   r"got 3"),
    (([[0.0, 1.0], [2.0, 3.0]], [1.0, 2.0]), InputValueError,
     r"times must be one-dimensional.*got shape \(2, 2\)"),
    (([0.0, 3.0], [1.0, 2.0], [3.0]), InputTypeError, r"a pair \(times, values\).*3 items"),
    ((["a", "b"], [1.0, 2.0]), InputTypeError, r"times must be an array of sample times"),
    (([0.0, 1.0], 2.0), InputValueError, r"values must hold one torque per sample time"),
    (([0.0, 1.0], [1.0, 2.0]), InputValueError,
     r"must cover the run up to t_final = 3 s; got times\[-1\] = 1\.0"),
    (([0.5, 3.0], [1.0, 2.0]), InputValueError,
     r"must start at or before t = 0 s; got times\[0\] = 0\.5"),
    ({"interpolation": "cubic"}, InputValueError,
     r"interpolation must be one of 'hold', 'linear', 'spline'; got 'cubic'"),
    ({"interpolation": 3}, InputTypeError, r"interpolation must be one of .*; got 3 of type int"),
]


@pytest.mark.parametrize("torque, error, match", BAD_SAMPLES, ids=[
    "length", "not-increasing", "nan-time", "inf-value", "one-sample", "spline-3",
    "times-2d", "triple", "strings", "scalar-values", "short", "late-start",
    "unknown-interpolation", "interpolation-type"])
def test_bad_samples_are_named(model, torque, error, match):
    with pytest.raises(error, match=r"torque samples.*" + match):
        if isinstance(torque, dict):        # the class, with three samples
            torque = SampledTorque([0.0, 1.0, 3.0], [1.0, 2.0, 3.0], **torque)
        simulate(model, T_FINAL, torque=torque)


def test_a_rounding_shortfall_of_the_last_sample_is_accepted(model):
    times = np.linspace(0.0, T_FINAL, 7)
    times[-1] = T_FINAL * (1.0 - 1e-12)
    result = simulate(model, T_FINAL, torque=(times, np.ones(7)), rtol=1e-6)
    assert result.ok and result.torque[-1] == 1.0


@settings(max_examples=60, deadline=None, derandomize=True)
@given(times=st.lists(st.floats(-1e3, 1e3) | st.sampled_from([np.nan, np.inf]), max_size=8),
       values=st.lists(st.floats(-1e3, 1e3) | st.sampled_from([np.nan, -np.inf]), max_size=8),
       interpolation=st.sampled_from(["hold", "linear"]))
def test_samples_give_a_clear_error_or_a_bounded_torque(times, values, interpolation):
    try:
        torque = SampledTorque(times, values, interpolation=interpolation)
    except (TypeError, ValueError) as exc:
        assert isinstance(exc, InputError) and str(exc).startswith("torque samples:"), exc
        return
    t = np.linspace(torque.times[0] - 1.0, torque.times[-1] + 1.0, 101)
    u = torque(t)
    assert np.all(np.isfinite(u))
    assert np.all((u >= np.min(values)) & (u <= np.max(values)))
