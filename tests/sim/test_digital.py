"""Sampled (digital) controllers: zero-order hold, sessions, and their runs."""

import numpy as np
import pytest

import flexctl
from controllers import PD, LQG, design_lqg, LQRWeights
from controllers.feedback.lqg import NoiseLevels
from flexctl.model.errors import InputError
from flexctl.sim.digital import ZeroOrderHold, is_sampled


@pytest.fixture(scope="module")
def plant():
    system = flexctl.load_scene("slew-90").system
    return flexctl.build_model(system, n_modes=4, variant="first_order")


def _start(model, angle=-np.pi / 2):
    x0 = np.zeros(model.n_states)
    x0[0] = angle
    return x0


PD_LAW = PD(kp=12.0, kd=8.0, torque_limit=6.0)


def test_held_torque_is_the_law_at_each_sample(plant):
    x0 = _start(plant)
    result = flexctl.simulate(plant, 3.0, controller=ZeroOrderHold(PD_LAW, 0.02), x0=x0,
                              output_step=0.005)
    assert result.ok
    samples = np.arange(0.0, 3.0, 0.02)
    at = np.isclose(result.t[:, None], samples[None, :], atol=1e-9).any(axis=1)
    # at each sample the torque is the law of the state there ...
    law = np.array([PD_LAW.torque(t, result.states[:, k], None)
                    for k, t in enumerate(result.t) if at[k]])
    assert np.allclose(result.torque[at], law, rtol=0, atol=1e-9)
    # ... and it is held until the next sample
    index = np.searchsorted(samples, result.t, side="right") - 1
    for k in range(result.t.size):
        first = int(np.argmax(index == index[k]))
        assert result.torque[k] == result.torque[first]
    assert result.controller_report["samples"] == 150
    assert result.controller_report["sample_time"] == 0.02


def test_sampled_law_converges_to_continuous_at_first_order(plant):
    x0 = _start(plant)
    continuous = flexctl.simulate(plant, 4.0, controller=PD_LAW, x0=x0, output_step=0.01)
    errors = []
    for sample_time in (0.02, 0.01, 0.005):
        sampled = flexctl.simulate(plant, 4.0, controller=ZeroOrderHold(PD_LAW, sample_time),
                                   x0=x0, output_step=0.01)
        assert np.allclose(sampled.t, continuous.t)
        errors.append(np.max(np.abs(sampled.theta - continuous.theta)))
    # a zero-order hold delays the command by half a sample: error proportional to T
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 1.6) & (ratios < 2.5)), (errors, ratios)


def test_integration_error_estimate_bounds_the_actual_error(plant):
    x0 = _start(plant)
    law = ZeroOrderHold(PD_LAW, 0.01)
    reference = flexctl.simulate(plant, 3.0, controller=law, x0=x0, rtol=1e-12,
                                 output_step=0.01)
    for method in ("cvodes", "rk4"):
        run = flexctl.simulate(plant, 3.0, controller=law, x0=x0, method=method,
                               output_step=0.01)
        assert run.method == method
        actual = np.max(np.abs(run.tip_deflection - reference.tip_deflection))
        assert run.integration_error is not None
        assert actual <= 2.0 * run.integration_error + 1e-12, (method, actual,
                                                                 run.integration_error)


def test_partial_last_sample_and_output_grid(plant):
    result = flexctl.simulate(plant, 1.005, controller=ZeroOrderHold(PD_LAW, 0.01),
                              x0=_start(plant), output_step=0.01)
    assert result.ok
    assert result.t[-1] == pytest.approx(1.005)
    assert result.controller_report["samples"] == 101
    assert np.all(np.diff(result.t) > 0)


def test_custom_session_protocol(plant):
    class Bang:
        sample_time = 0.05

        def start(self, model, x0):
            calls = []

            class Session:
                def step(self, t, x):
                    calls.append(t)
                    return 1.0 if t < 0.5 else -1.0

                def report(self):
                    return {"calls": len(calls)}
            return Session()

    controller = Bang()
    assert is_sampled(controller)
    result = flexctl.simulate(plant, 1.0, controller=controller)
    assert result.ok
    assert result.controller_report["calls"] == 20
    # the rigid hub answers the +1/-1 N m bang-bang: at rest-ish at 1 s, moved forward
    assert result.theta[-1] > 0.0
    assert set(np.round(result.torque, 12)) == {1.0, -1.0}


def test_sampled_divergence_is_reported(plant):
    class Runaway:
        sample_time = 0.01

        def start(self, model, x0):
            class Session:
                def step(self, t, x):
                    return 1e4

                def report(self):
                    return {}
            return Session()

    result = flexctl.simulate(plant, 5.0, controller=Runaway())
    assert result.status == "diverged"
    assert "tip deflection passed the beam length" in result.message
    assert np.all(np.isfinite(result.states))


@pytest.mark.parametrize("value", [0.0, -0.01, np.inf, np.nan, "0.01", True, None])
def test_zero_order_hold_rejects_bad_sample_time(value):
    with pytest.raises(InputError, match="sample_time"):
        ZeroOrderHold(PD_LAW, value)


def test_zero_order_hold_rejects_estimator_and_nesting(plant):
    lqg = design_lqg(plant, LQRWeights(hub_angle=0.05, torque=1.0),
                     NoiseLevels(angle=1e-3, root_moment=0.1, torque=0.1))
    assert isinstance(lqg, LQG)
    with pytest.raises(InputError, match="internal states"):
        ZeroOrderHold(lqg, 0.01)
    with pytest.raises(InputError, match="already sampled"):
        ZeroOrderHold(ZeroOrderHold(PD_LAW, 0.01), 0.01)
    with pytest.raises(InputError, match="law"):
        ZeroOrderHold(3.0, 0.01)


def test_sampled_controller_refuses_other_methods_and_python_torque(plant):
    law = ZeroOrderHold(PD_LAW, 0.01)
    with pytest.raises(InputError, match="sampled controller"):
        flexctl.simulate(plant, 1.0, controller=law, method="DOP853")
    # (a torque of the state CasADi cannot trace: a branch on t; a function of time alone is
    # traced or sampled and runs compiled)
    with pytest.raises(InputError, match="CasADi form"):
        flexctl.simulate(plant, 1.0, controller=law,
                         torque=lambda t, x: 0.1 if t < 0.5 else 0.0 * x[0])
    run = flexctl.simulate(plant, 1.0, controller=law, torque=lambda t: 0.1 if t < 0.5 else 0.0,
                           check_validity=False)
    assert run.ok and "cubic pieces" in run.message


def test_too_many_samples_refused(plant):
    with pytest.raises(InputError, match="samples"):
        flexctl.simulate(plant, 100.0, controller=ZeroOrderHold(PD_LAW, 1e-5))


def test_callable_law_and_rk4_agree(plant):
    def law(t, x):
        return float(np.clip(12.0 * (0.0 - x[0]) - 8.0 * x[plant.n_modes + 1], -6.0, 6.0))

    x0 = _start(plant)
    by_callable = flexctl.simulate(plant, 2.0, controller=ZeroOrderHold(law, 0.01), x0=x0,
                                   output_step=0.01)
    by_pd = flexctl.simulate(plant, 2.0, controller=ZeroOrderHold(PD_LAW, 0.01), x0=x0,
                             output_step=0.01, method="rk4")
    assert np.max(np.abs(by_callable.theta - by_pd.theta)) < 1e-5


@pytest.mark.parametrize("t_start, t_end, numbers", [
    (float("nan"), 1.0, (0.1,)), (0.0, float("inf"), (0.1,)), (1.0, 1.0, (0.1,)),
    (2.0, 1.0, (0.1,)), (0.0, 1.0, ()), (0.0, 1.0, (0.1, 0.2)), (0.0, 1.0, (float("nan"),))],
    ids=["nan-start", "inf-end", "empty", "backwards", "too-few", "too-many", "nan-number"])
def test_a_moved_segment_integrator_refuses_bad_times_and_numbers(t_start, t_end, numbers):
    from flexctl.sim.compiled import SegmentIntegrator
    from flexctl.sim.embedded_rk import HeldTorque

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 2)
    integ = SegmentIntegrator(model, 0.0, np.array([0.5, 1.0]), np.ones(model.n_states), 1e-8,
                              controller=HeldTorque(0.1))
    with pytest.raises(ValueError, match="SegmentIntegrator.moved"):
        integ.moved(t_start, t_end, numbers)


def test_a_moved_segment_integrator_runs_the_later_segment():
    """Moved to a later hold with another held torque, it integrates what a new integrator
    built for that segment does."""
    from flexctl.sim.compiled import SegmentIntegrator
    from flexctl.sim.embedded_rk import HeldTorque

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 2)
    scale, y0 = np.ones(model.n_states), np.linspace(0.01, 0.02, model.n_states)
    first = SegmentIntegrator(model, 0.0, np.array([0.5, 1.0]), scale, 1e-10,
                              controller=HeldTorque(0.1))
    fresh = SegmentIntegrator(model, 3.0, np.array([3.5, 4.0]), scale, 1e-10,
                              controller=HeldTorque(-0.4))
    np.testing.assert_allclose(first.moved(3.0, 4.0, (-0.4,))(y0), fresh(y0), rtol=1e-12,
                               atol=1e-15)
