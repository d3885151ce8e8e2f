"""A fast actuator is seen before the run: ``method="auto"`` takes an implicit method, says by
how much the actuator outruns the structure, and lags down to 1e-6 s run to the end."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from flexctl import build_model, load_scene, simulate
from flexctl.model.actuators import ReactionWheel
from flexctl.sim.inputs import SampledTorque
from flexctl.sim.request import StiffnessWarning, actuator_frequency

#: A held command table with a jump every second (N m).
TIMES = np.arange(0.0, 10.01, 1.0)
VALUES = 0.05 * np.array([1.0, -1.0, 0.5, 0.0, 1.0, -1.0, 0.0, 0.2, 0.0, -0.3, 0.0])


def wheel_model(lag: float):
    wheel = ReactionWheel(inertia=0.05, torque_limit=0.2, speed_limit=600.0,
                          time_constant=lag)
    return build_model(load_scene("hub-beam-mass").system, n_modes=4, actuator=wheel)


@pytest.fixture(scope="module")
def held():
    return SampledTorque(TIMES, VALUES, interpolation="hold")


def test_the_actuator_pole_is_its_lag_when_faster_than_the_structure():
    model = wheel_model(1e-5)
    assert actuator_frequency(model) == pytest.approx(1e5, rel=1e-6)
    assert actuator_frequency(model.mechanical) == 0.0


@pytest.mark.parametrize("lag", [1e-3, 1e-4, 1e-5, 1e-6])
def test_auto_steps_over_a_fast_lag_and_its_estimate_holds(held, lag):
    model = wheel_model(lag)
    with warnings.catch_warnings():
        warnings.simplefilter("error", StiffnessWarning)
        run = simulate(model, 10.0, torque=held)
        reference = simulate(model, 10.0, torque=held, rtol=1e-11)
    assert run.status == "ok" and reference.status == "ok"
    assert run.method == "cvodes"
    omega = float(model.natural_frequencies(0.0, hub="free")[-1])
    assert f"is {1.0 / lag / omega:.3g} times the structure's fastest mode" in run.message
    error = np.max(np.abs(run.tip_deflection - reference.tip_deflection))
    peak = np.max(np.abs(reference.tip_deflection))
    assert peak > 1e-3
    assert run.integration_error is not None and error <= run.integration_error


def test_a_lag_of_a_microsecond_runs_at_a_tight_tolerance(held):
    tight = simulate(wheel_model(1e-6), 10.0, torque=held, rtol=1e-10)
    assert tight.status == "ok" and tight.t[-1] == pytest.approx(10.0)
    assert tight.integration_error is not None and tight.integration_error < 1e-7


def test_a_python_torque_behind_a_fast_lag_moves_to_an_implicit_method():
    model = wheel_model(1e-5)

    def command(t, x):              # of the state, with a branch: stays a Python function
        return 0.05 if t < 1.0 else -0.05 - 0.0 * x[0]
    with pytest.warns(StiffnessWarning, match="the actuator's fastest pole"):
        run = simulate(model, 4.0, torque=command)
    assert run.status == "ok" and run.method == "LSODA"
