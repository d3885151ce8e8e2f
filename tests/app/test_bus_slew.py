"""The built-in ``bus-slew``, end to end as a user runs it: a free bus with unequal arrays and
a boom, a reaction wheel, an LQG on a gyro and an attitude sensor read at 10 Hz.

From Python: the design is the LQG the scene asks for (its process noise used), its loop as it
flies (sampled, late, through the filter) is stable with the same verdict ``check_loop``
gives, and the slew ends within a few of the attitude sensor's error of the target with its
vibration damped below the slew's own peak. From the command line: the run writes its files,
its summary calls it ``ok`` with a stable loop, and the sensors it read are the two the scene
lists (no strain gauges).
"""

import json
import math
import warnings

import pytest

import flexctl
from controllers import check_loop, loop_margins, loop_transfer
from flexctl.app.cli import EXIT_OK, main
from flexctl.app.scenes import run_slew
from flexctl.app.verdict import summary_verdict

pytestmark = pytest.mark.slow


def test_bus_slew_from_python():
    scene = flexctl.load_scene("bus-slew")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result, built, metrics = run_slew(scene, error_estimate=False)
    assert built.kind == "lqg" and built.info["design"].startswith("LQG")
    assert built.controller.process_noise == scene.controller.get("process_torque")
    assert result.status == "ok"
    sensors = scene.sensors
    attitude_error = math.hypot(sensors.attitude_noise, sensors.attitude_bias)
    assert abs(metrics.final_error) < 3.0 * attitude_error
    assert metrics.residual_vibration < metrics.peak_tip_deflection
    assert metrics.peak_torque <= scene.actuator.torque_limit * (1.0 + 1e-9)
    plant = result.model
    margins = loop_margins(loop_transfer(plant, built.controller))
    check = check_loop(plant, built.controller)
    assert margins.closed_loop_stable and check.stable
    assert margins.gain_margin > 1.0 and margins.phase_margin > 0.0


def test_bus_slew_from_the_command_line(tmp_path):
    assert main(["run", "bus-slew", "--out", str(tmp_path)]) == EXIT_OK
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "ok" and summary_verdict(summary) == "ok"
    assert summary["slew"]["controller"] == "lqg"
    assert summary["slew"]["loop_stability"]["closed_loop_stable"]
    assert set(summary["sensors"]["largest_error"]) == {"theta", "theta_dot"}
    assert (tmp_path / "timeseries.csv").exists() and (tmp_path / "response.png").exists()
