"""One contract for every integration method of :func:`flexctl.simulate`, one suite for all.

Each method that ``simulate(method=...)`` takes (CVODES, the compiled fixed-step RK4, the
compiled Dormand-Prince pair, the compiled BDF and Adams-Moulton methods, SciPy's ``solve_ivp``
methods) is held to the same promises, as SciPy's ``OdeSolver`` classes share one test suite and
Drake's integrators one set of tests:

- its error falls as its tolerance tightens, at the rate of its order where the step is fixed;
- its own estimate of its integration error (``result.integration_error``) bounds the error
  it made;
- a jump of the input is a breakpoint, not a step it straddles;
- a run that diverges is stopped and reported as such, at the same time by every method;
- the same run twice gives the same numbers, bit for bit.

The true error is measured against an independent solution: SciPy's DOP853 at a tolerance
far below the runs', on the model's own right-hand side, segment by segment between the
input's jumps.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flexctl import SineTorque, build_model, simulate
from flexctl.sim.inputs import SampledTorque
from flexctl.sim.maneuvers import SpinUp
from flexctl.sim.request import METHODS

#: Every method a continuous run takes by name ("auto" chooses among them).
NAMED = tuple(m for m in METHODS if m != "auto")
#: Run length, s: the sine push (2 s) and a free vibration after it.
T_FINAL = 4.0
#: The independent solution's tolerance (relative, and absolute per unit of a state's size).
REFERENCE_RTOL = 1e-13


@pytest.fixture(scope="module")
def model(hub_beam_mass_system):
    return build_model(hub_beam_mass_system, n_modes=2)


def reference_tip(model, torque, t, jumps=()):
    """The tip deflection at times ``t`` (ending at the run's end) by DOP853 at
    :data:`REFERENCE_RTOL`, restarted at each of the input's ``jumps`` (s), each piece seeing
    the input of its own side of them."""
    edges = [0.0, *jumps, float(t[-1])]
    y, tips = model.rest_state(), []
    for lo, hi in zip(edges[:-1], edges[1:]):
        inside = t[(t >= lo) & (t < hi)]
        side = 0.5 * (lo + hi)

        def rhs(time, x, lo=lo, hi=hi, side=side):
            return model.dynamics(time, x, float(torque(time if lo < time < hi else side)))

        sol = solve_ivp(rhs, (lo, hi), y, method="DOP853", t_eval=np.append(inside, hi),
                        rtol=REFERENCE_RTOL, atol=1e-15)
        assert sol.success, sol.message
        tips.append(model.tip_deflection(sol.y[:, :-1]))
        y = sol.y[:, -1]
    return np.append(np.concatenate(tips), model.tip_deflection(y))


@pytest.fixture(scope="module")
def sine_case(model):
    torque = SineTorque(peak_torque=2.0, duration=2.0)
    t = np.linspace(0.0, T_FINAL, 401)
    return torque, reference_tip(model, torque, t)


def run(model, method, rtol, torque, **kwargs):
    return simulate(model, T_FINAL, torque=torque, rtol=rtol, method=method,
                    output_step=0.01, check_validity=False, **kwargs)


def true_error(result, reference) -> float:
    assert result.t.shape == reference.shape
    return float(np.max(np.abs(result.tip_deflection - reference)))


@pytest.mark.parametrize("method", NAMED)
def test_error_falls_as_the_tolerance_tightens(model, sine_case, method):
    torque, reference = sine_case
    peak = np.max(np.abs(reference))
    errors = [true_error(run(model, method, rtol, torque), reference) for rtol in (1e-4, 1e-8)]
    # four decades of tolerance buy at least two of accuracy, and the tight run is accurate
    assert errors[1] <= 1e-2 * max(errors[0], 1e-7 * peak), errors
    assert errors[1] <= 1e-6 * peak, errors


@pytest.mark.parametrize("method", NAMED)
@pytest.mark.parametrize("rtol", [1e-5, 1e-7], ids=["rtol-1e-5", "rtol-1e-7"])
def test_error_estimate_bounds_the_true_error(model, sine_case, method, rtol):
    torque, reference = sine_case
    result = run(model, method, rtol, torque)
    assert result.status == "ok"
    assert result.integration_error is not None, f"{method}: {result.message}"
    assert np.isfinite(result.integration_error)
    assert true_error(result, reference) <= result.integration_error


def test_fixed_step_rk4_converges_at_fourth_order(model, sine_case):
    torque, reference = sine_case
    errors = [true_error(run(model, "rk4", 0.5, torque, max_step=h), reference)
              for h in (0.02, 0.01)]
    # halving the step divides RK4's global error by 2^4 = 16
    assert 10.0 <= errors[0] / errors[1] <= 24.0, errors


@pytest.mark.parametrize("method", NAMED)
def test_a_jump_of_the_input_is_a_breakpoint(model, method):
    # a held command that drops from 1 N m to -0.5 N m at 1.3 s and to 0 at 2.7 s
    torque = SampledTorque([0.0, 1.3, 2.7, T_FINAL], [1.0, -0.5, 0.0, 0.0],
                           interpolation="hold")
    t = np.linspace(0.0, T_FINAL, 401)
    reference = reference_tip(model, torque, t, jumps=(1.3, 2.7))
    result = run(model, method, 1e-8, torque)
    assert result.status == "ok"
    # a step across a jump errs to first order in its length, whatever the tolerance
    # (3e-4 m here before the jumps of a hold were breakpoints)
    error = true_error(result, reference)
    assert error <= 1e-7 * np.max(np.abs(reference))
    assert error <= result.integration_error


@pytest.mark.parametrize("method", NAMED)
def test_a_diverging_run_is_stopped_by_every_method_at_the_same_time(kane_system, method):
    # zero_order loses its stiffness above the first clamped frequency (2.9 rad/s here): a
    # spin-up to 6 rad/s makes the beam diverge
    model = build_model(kane_system, n_modes=2, variant="zero_order")
    spin = SpinUp(spin_rate=6.0, ramp_time=5.0)
    result = simulate(model, 30.0, hub_motion=spin, method=method, rtol=1e-8,
                      check_validity=False)
    assert result.status == "diverged", result.message
    reference = simulate(model, 30.0, hub_motion=spin, method="DOP853", rtol=1e-10,
                         check_validity=False)
    assert result.t[-1] == pytest.approx(reference.t[-1], rel=1e-3)


@pytest.mark.parametrize("method", NAMED)
def test_the_same_run_twice_gives_the_same_numbers(model, sine_case, method):
    torque = sine_case[0]
    first, second = (run(model, method, 1e-6, torque) for _ in range(2))
    np.testing.assert_array_equal(first.states, second.states)
    assert first.integration_error == second.integration_error
