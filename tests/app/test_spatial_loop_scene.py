"""A spatial scene with an attitude loop (``[controller]``, ``[sensors]``): run as written,
and refused by key."""

import csv
import json
import textwrap

import numpy as np
import pytest
from spatial_craft import CRAFT_TOML

from flexctl.app.cli import main
from flexctl.app.scenes import load_scene
from flexctl.model.errors import InputError
from flexctl.sim.quaternions import error_angles, from_rotation_vector

SCENE = CRAFT_TOML + textwrap.dedent("""\
    [model]
    modes = 1

    [actuator]
    kind = "wheels"
    arrangement = "pyramid"
    pyramid_angle = 54.7356
    [actuator.wheel]
    inertia = 0.01
    torque_limit = 0.1
    speed_limit = 300.0

    [controller]
    kind = "quaternion_feedback"
    sample_time = 0.1
    slew_axis = [0.6, 0.0, 0.8]
    slew_angle = 20.0
    bandwidth = 0.5
    damping = 0.9

    [sensors]
    seed = 4
    [sensors.star_tracker]
    cross_noise = 2e-5
    boresight_noise = 1e-4
    sample_time = 1.0
    latency = 0.2
    [sensors.gyro]
    angle_random_walk = 3e-5
    initial_bias = [1e-4, 0.0, -1e-4]

    [simulation]
    t_final = 25.0
    """)


def test_a_scene_flies_its_loop_and_writes_its_run(tmp_path):
    """The law slews 20 degrees about (0.6, 0, 0.8) through the wheels, reading the sensors
    through the filter; the run's samples are the loop's, its torque the commands."""
    path = tmp_path / "loop.toml"
    path.write_text(SCENE)
    scene = load_scene(path)
    assert scene.loop.sample_time == 0.1 and scene.loop.sensors.tracker_every == 10
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 0
    with open(out / "timeseries.csv") as handle:
        rows = list(csv.reader(handle))
    column = dict(zip(rows[0], np.array(rows[1:], dtype=float).T))
    np.testing.assert_allclose(np.diff(column["t"]), 0.1, atol=1e-12)
    target = from_rotation_vector(np.radians(20.0) * np.array([0.6, 0.0, 0.8]))
    final = [column[k][-1] for k in ("qw", "qx", "qy", "qz")]
    error = np.linalg.norm(error_angles(target, final))
    print(f"final pointing error {error:.1e} rad")
    assert error < 2e-3
    assert "wheel4.speed" in column and np.abs(column["wheel1.speed"]).max() > 1.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok"
    # the law's disk margins about the target, on the linear plant with the run's modes
    margins = summary["loop_margins"]
    assert margins["closed_loop_stable"] and len(margins["gain_margin_db"]) == 3
    assert all(6.0 < g < 40.0 for g in margins["gain_margin_db"])
    assert all(30.0 < p <= 90.0 for p in margins["phase_margin_deg"])
    assert margins["multiloop"][0] <= min(margins["disk_margin"]) * (1 + 1e-6)


@pytest.mark.parametrize("old, new, pattern", [
    ('kind = "quaternion_feedback"', 'kind = "h_infinity"', r"controller\.kind"),
    ("bandwidth = 0.5\n", "", r"controller\.bandwidth is required"),
    ("slew_angle = 20.0\n", "", r"controller needs a target"),
    ("bandwidth = 0.5", "bandwidth = -0.5", r"controller\.bandwidth"),
    ("sample_time = 1.0\nlatency = 0.2", "sample_time = 0.25\nlatency = 0.2",
     r"whole multiple of the gyro's sample time, controller\.sample_time"),
    ("latency = 0.2", "latency = 0.25", "whole number of gyro samples"),
    ("angle_random_walk = 3e-5", "angle_random_walk = 3e-5\nnoise = 1", r"sensors\.gyro"),
    ("[simulation]", '[maneuver]\nkind = "sine_torque"\npeak_torque = [0.1, 0, 0]\n'
                     "duration = 1.0\n\n[simulation]", "maneuver.kind = 'none'"),
], ids=["unknown law", "no bandwidth", "no target", "negative bandwidth",
        "tracker between gyro samples", "latency between samples", "unknown gyro key",
        "a manoeuvre too"])
def test_a_bad_loop_is_refused_by_its_key(tmp_path, old, new, pattern):
    assert old in SCENE
    path = tmp_path / "loop.toml"
    path.write_text(SCENE.replace(old, new, 1))
    with pytest.raises(InputError, match=pattern):
        load_scene(path)
