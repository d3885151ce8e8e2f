"""Sample-to-sample integration by the Dormand-Prince pair (flexctl.sim.embedded_rk)."""

import warnings

import numpy as np
import pytest

import flexctl
from controllers import PD
from flexctl.model.errors import InputError
from flexctl.sim.digital import ZeroOrderHold
from flexctl.sim.embedded_rk import DORMAND_PRINCE, STIFF_SAMPLE, EmbeddedHold, choose_hold
from flexctl.sim.request import state_scale


def test_tableau_meets_the_order_conditions():
    c, a, b, e = (np.array(DORMAND_PRINCE[k], dtype=object) for k in "cabe")
    b, e, c = np.array(b, float), np.array(e, float), np.array(c, float)
    # consistency: each row of a sums to its node; both weight sets sum to one
    for node, row in zip(c, DORMAND_PRINCE["a"]):
        assert np.isclose(sum(row), node, atol=1e-15)
    assert np.isclose(b.sum(), 1.0) and np.isclose(e.sum(), 0.0, atol=1e-15)
    # the fifth-order weights integrate t^k exactly for k < 5 (quadrature conditions)
    for k in range(5):
        assert np.isclose(b @ c ** k, 1.0 / (k + 1), atol=1e-14)
    # the embedded solution is of order four, not five: the error weights miss t^4
    assert all(np.isclose(e @ c ** k, 0.0, atol=1e-14) for k in range(4))
    assert not np.isclose(e @ c ** 4, 0.0, atol=1e-6)


@pytest.fixture(scope="module")
def slew():
    model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=6)
    x0 = np.zeros(model.n_states)
    x0[0] = -np.pi / 2
    law = ZeroOrderHold(PD(kp=12.0, kd=8.0, torque_limit=6.0), sample_time=0.01)
    tight = flexctl.simulate(model, 3.0, controller=law, x0=x0, rtol=1e-12, method="cvodes",
                             output_step=0.0025, check_validity=False)
    return model, x0, law, tight


@pytest.mark.parametrize("sampled", [True, False], ids=["sampled", "continuous"])
@pytest.mark.parametrize("rtol", [1e-5, 1e-8])
def test_auto_takes_the_pair_and_meets_its_estimate(slew, rtol, sampled):
    model, x0, law, tight = slew
    if not sampled:
        # the PD law itself, continuous: the pair's steps over the whole run
        # (flexctl.sim.embedded_rk.EmbeddedRun), its outputs from the continuous extension
        law = law.law
        tight = flexctl.simulate(model, 3.0, controller=law, x0=x0, rtol=1e-12,
                                 method="cvodes", output_step=0.0025, check_validity=False)
    # four outputs a sample: a sampled loop's steps end on them, a continuous run reads them
    run = flexctl.simulate(model, 3.0, controller=law, x0=x0, rtol=rtol, output_step=0.0025,
                           check_validity=False)
    # a sampled loop's holds take 5(4) from sample to sample, a continuous run 8(5,3) (at
    # rtol 1e-6 at the loosest)
    assert run.method == ("RK45" if sampled else "dop853") and run.ok
    np.testing.assert_array_equal(run.t, tight.t)
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    assert actual <= run.integration_error
    assert run.integration_error <= 100 * rtol * tight.peak_tip_deflection
    # the torques are the law's, as on CVODES
    cvodes = flexctl.simulate(model, 3.0, controller=law, x0=x0, rtol=rtol, method="cvodes",
                              output_step=0.0025, check_validity=False)
    assert cvodes.method == "cvodes"
    np.testing.assert_allclose(run.torque, cvodes.torque, atol=1e3 * rtol * 6.0)


def test_the_exact_plant_runs_on_the_pair(slew):
    _, _, law, _ = slew
    model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2,
                                variant="exact")
    x0 = model.rest_state(-np.pi / 2)
    run = flexctl.simulate(model, 2.0, controller=law, x0=x0, method="RK45",
                           check_validity=False)
    tight = flexctl.simulate(model, 2.0, controller=law, x0=x0, rtol=1e-12, method="cvodes",
                             check_validity=False)
    assert run.method == "RK45"
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    assert actual <= run.integration_error <= 1e-5 * tight.peak_tip_deflection


def test_a_stiff_plant_keeps_cvodes():
    # 60 modes: the fastest at some 3.9e4 rad/s, 387 radians of it in a 10 ms sample
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=60)
    method, omega = choose_hold(model, 0.01)
    fastest = float(model.natural_frequencies(0.0, hub="free")[-1])
    assert method == "cvodes" and omega * 0.01 > STIFF_SAMPLE
    assert omega == pytest.approx(fastest, rel=1e-3)
    few = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=3)
    assert choose_hold(few, 0.01)[0] == "RK45"
    # a spin far above the modes makes a fast plant of a slow one
    assert choose_hold(few, 0.01, spin_frequency=2e4)[0] == "cvodes"
    for name, bad in (("sample_time", 0.0), ("sample_time", np.nan), ("sample_time", "0.01"),
                      ("spin_frequency", np.inf), ("model", None)):
        arguments = dict(model=few, sample_time=0.01, spin_frequency=0.0)
        arguments[name] = bad
        with pytest.raises(InputError, match=name):
            choose_hold(**arguments)


def test_a_state_that_blows_up_fails_the_sample():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    scale = state_scale(model, model.layout)
    hold = EmbeddedHold(model, None, scale, 1e-8, 1000, h_first=1e-3)
    y = np.zeros(model.n_states)
    states, evaluations = hold(0.0, np.array([0.005, 0.01]), y, 0.5)
    assert states.shape == (model.n_states, 2) and evaluations % 7 == 0
    assert np.all(np.isfinite(states)) and states[0, -1] > 0.0
    y[1] = np.nan
    with pytest.raises(RuntimeError):
        hold(0.01, np.array([0.02]), y, 0.5)
    for bad in (0.0, -1e-3, np.inf, np.nan, "1e-3", None):
        with pytest.raises(InputError, match="h_first"):
            EmbeddedHold(model, None, scale, 1e-8, 1000, h_first=bad)
    for name, bad in (("scale", scale[:-1]), ("scale", -scale), ("scale", scale * np.nan),
                      ("rtol", 0.0), ("rtol", np.inf), ("rtol", 2.0), ("max_steps", 0),
                      ("max_steps", 10.5), ("model", "plant"), ("torque", lambda t: 1.0)):
        arguments = dict(model=model, torque=None, scale=scale, rtol=1e-8, max_steps=1000,
                         h_first=1e-3)
        arguments[name] = bad
        with pytest.raises(InputError, match=name):
            EmbeddedHold(**arguments)
    tiny = EmbeddedHold(model, None, scale, 1e-8, 3, h_first=1e-3)
    with pytest.raises(RuntimeError, match="more than 3 steps"):
        tiny(0.0, np.array([1.0]), np.zeros(model.n_states), 0.5)


@pytest.mark.parametrize("method", ["DOP853", "Radau", "RK23"])
def test_other_methods_are_refused_for_a_sampled_law_by_name(slew, method):
    model, x0, law, _ = slew
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(InputError, match=f"method '{method}'.*'RK45'"):
            flexctl.simulate(model, 1.0, controller=law, x0=x0, method=method)


def test_threads_running_sampled_loops_get_their_own_runs():
    """Sampled runs on threads share one model's compiled step (the gains and the held torque
    are numbers): each thread's run is the one it makes alone."""
    from concurrent.futures import ThreadPoolExecutor

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 3)
    x0 = model.rest_state(-0.5)
    gains = [(3.0 + k, 2.0 + 0.5 * k) for k in range(6)]

    def run(gain):
        law = ZeroOrderHold(PD(kp=gain[0], kd=gain[1]), sample_time=0.02)
        result = flexctl.simulate(model, 2.0, controller=law, x0=x0, check_validity=False)
        assert result.method == "RK45"
        return result.states

    alone = [run(gain) for gain in gains]
    with ThreadPoolExecutor(max_workers=3) as pool:
        together = list(pool.map(run, gains * 2))
    for k, states in enumerate(together):
        np.testing.assert_array_equal(states, alone[k % len(gains)])
