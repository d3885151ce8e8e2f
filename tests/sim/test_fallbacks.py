"""Every fallback of a compiled path says so: a segment CVODES cannot take goes to SciPy and the
run says its accuracy check could not run; a torque function that can be neither traced nor
sampled is called at every step, and the run says why."""

from __future__ import annotations

import numpy as np
import pytest

from flexctl import build_model, load_scene, simulate
from flexctl.model.errors import InputError
from flexctl.sim import function_samples, strategies
from flexctl.sim.inputs import SampledTorque


@pytest.fixture(scope="module")
def model():
    return build_model(load_scene("hub-beam-mass").system, n_modes=2)


def test_a_segment_cvodes_fails_goes_to_scipy_and_the_check_is_said_not_run(model,
                                                                            monkeypatch):
    held = SampledTorque([0.0, 1.0, 2.0, 3.0], [0.5, -0.5, 0.2, 0.0], interpolation="hold")
    whole = simulate(model, 3.0, torque=held, method="cvodes", check_validity=False)
    assert whole.ok and whole.integration_error is not None
    original = strategies.CvodesSegments.integrate

    def failing(self, lo, t_eval, y):
        if 1.0 <= lo < 2.0:
            raise RuntimeError("CVODES failed (made to, for this test)")
        return original(self, lo, t_eval, y)
    monkeypatch.setattr(strategies.CvodesSegments, "integrate", failing)
    run = simulate(model, 3.0, torque=held, method="cvodes", check_validity=False)
    assert run.ok and run.integration_error is None
    assert "accuracy check not run: the compiled integrator failed on a segment" in run.message
    # SciPy's segment is the same motion, within the tolerance
    peak = np.max(np.abs(whole.tip_deflection))
    assert np.max(np.abs(run.tip_deflection - whole.tip_deflection)) < 1e-5 * peak


def test_a_torque_function_neither_traced_nor_sampled_says_why(model, monkeypatch):
    monkeypatch.setattr(function_samples, "MAX_EVALUATIONS", 500)

    def torque(t):
        return 0.5 if t < 1.0 else -0.5
    run = simulate(model, 2.0, torque=torque, check_validity=False)
    assert run.ok and run.method == "DOP853"
    assert "could not be traced" in run.message
    assert "nor sampled (it needed more than 500 calls)" in run.message


@pytest.mark.parametrize("declared", ["not times", [0.5, "x"], [float("nan")], 3.0])
def test_a_torque_function_with_bad_breakpoints_is_refused_by_name(model, declared):
    def torque(t):
        return 0.5 if t < 1.0 else -0.5
    torque.breakpoints = declared
    with pytest.raises(InputError, match="torque.breakpoints must be"):
        simulate(model, 2.0, torque=torque, check_validity=False)


def test_scipys_bdf_growing_on_undamped_modes_says_it_may_be_the_method():
    """SciPy's BDF (taken where the compiled one cannot be built: 30 modes) steps at orders 3
    to 5, which amplify undamped oscillations: the run's overflow names that, and Radau, an
    A-stable method, integrates the same run."""
    from flexctl import SineTorque

    many = build_model(load_scene("hub-beam-mass").system, 30)
    sine = SineTorque(peak_torque=2.0, duration=2.0)
    with pytest.warns(Warning):
        run = simulate(many, 2.0, torque=sine, method="BDF", rtol=1e-6, check_validity=False)
    if run.status == "ok":
        pytest.skip("the compiled BDF took this run")
    assert run.status == "diverged" and "amplify undamped oscillations" in run.message
    with pytest.warns(Warning):
        radau = simulate(many, 2.0, torque=sine, method="Radau", rtol=1e-6,
                         check_validity=False)
    assert radau.status == "ok"
