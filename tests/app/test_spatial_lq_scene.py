"""A spatial scene flown by a three-axis LQR or LQG (``[controller] kind = "lqr"`` or
``"lqg"``): run as written, judged on the linear plant with every mode of the run, refused by
key."""

import json
from pathlib import Path

import numpy as np
import pytest

from flexctl.app.cli import main
from flexctl.app.scenes import load_scene
from flexctl.model.errors import InputError
from flexctl.sim.quaternions import error_angles, from_rotation_vector

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scenes" / "spatial-lqg-slew.toml"
SCENE = EXAMPLE.read_text()


def _final_error(out):
    rows = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    target = from_rotation_vector(np.radians(20.0) * np.array([0.6, 0.0, 0.8]))
    final = [rows[k][-1] for k in ("qw", "qx", "qy", "qz")]
    return float(np.linalg.norm(error_angles(target, final)))


def test_the_lqg_example_slews_through_its_sensors_and_filters(tmp_path):
    """The LQG reads the attitude filter of the star tracker and gyro, its own filter the
    arrays' modes; the wheels carry the torque."""
    out = tmp_path / "out"
    assert main(["run", str(EXAMPLE), "--out", str(out), "--set", "simulation.t_final=20",
                 "--set", "model.modes=1"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok"
    verdict = summary["loop_margins"]
    assert verdict["closed_loop_stable"] and verdict["spectral_abscissa"] < 0
    assert verdict["held_at"] == 0.1
    assert "cannot be moved by the inputs" in verdict["design_note"]
    assert all(6.0 < g for g in verdict["gain_margin_db"])
    assert verdict["multiloop"][0] <= min(verdict["disk_margin"]) * (1 + 1e-6)
    error = _final_error(out)
    print(f"final pointing error {error:.1e} rad")
    assert error < 1e-3                      # the sensors' noise, not the law, sets the floor


def _lqr_scene(sensors: bool) -> str:
    text = SCENE.replace('kind = "lqg"', 'kind = "lqr"')
    for key in ("angle_noise", "rate_noise", "process_torque"):
        text = "\n".join(line for line in text.splitlines() if not line.startswith(key))
    return text if sensors else text[:text.index("[sensors]")] + text[text.index("[simulation]"):]


def test_an_lqr_scene_flies_on_the_whole_state(tmp_path):
    path = tmp_path / "lqr.toml"
    path.write_text(_lqr_scene(sensors=False))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--set", "simulation.t_final=20",
                 "--set", "model.modes=1"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["loop_margins"]["closed_loop_stable"]
    assert _final_error(out) < 1e-4


def test_an_lqr_scene_with_sensors_is_refused(tmp_path):
    path = tmp_path / "lqr.toml"
    path.write_text(_lqr_scene(sensors=True))
    with pytest.raises(InputError, match=r"controller\.kind = 'lqr' feeds back .* 'lqg'"):
        load_scene(path)


@pytest.mark.parametrize("old, new, pattern", [
    ("hub_angle = 0.05\n", "", r"controller\.hub_angle is required"),
    ("torque = 0.1\n", "", r"controller\.torque is required"),
    ("hub_angle = 0.05", "hub_angle = -0.05", r"controller\.hub_angle"),
    ("hub_angle = 0.05", 'hub_angle = "small"', r"controller\.hub_angle"),
    ("angle_noise = 1e-4", "angle_noise = 0.0", r"controller\.angle_noise"),
    ("design_modes = 1", "design_modes = 0", r"controller\.design_modes"),
    ("angle_noise = 1e-4", "angle_noise = 1e-4\nbandwidth = 0.5", r"controller"),
    ("slew_angle = 20.0", "slew_angle = 20.0\nmax_frequency = -3.0",
     r"controller\.max_frequency"),
    ("design_modes = 1", "design_modes = 1\nslew_duration = -2.0", r"controller\.slew_duration"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 9.0\nslew_shape = "sine"',
     r"controller\.slew_shape"),
    ("design_modes = 1", 'design_modes = 1\nslew_shape = "poly7"', r"needs controller\.slew_duration"),
], ids=["no hub_angle", "no torque", "negative weight", "string weight",
        "zero noise", "no design modes", "unknown key",
        "negative cut-off", "negative slew duration", "unknown slew shape",
        "a shape without a duration"])
def test_a_bad_lq_loop_is_refused_by_its_key(tmp_path, old, new, pattern):
    assert old in SCENE
    path = tmp_path / "loop.toml"
    path.write_text(SCENE.replace(old, new, 1))
    with pytest.raises(InputError, match=pattern):
        load_scene(path)


def test_an_lqg_scene_follows_an_eigenaxis_slew(tmp_path):
    """``slew_duration``: the law follows a 12 s eigenaxis slew instead of a step, and
    excites the arrays less."""
    peaks = {}
    for name, extra in (("step", ""), ("eigenaxis", "\nslew_duration = 12.0")):
        path = tmp_path / f"{name}.toml"
        path.write_text(SCENE.replace("design_modes = 1", "design_modes = 1" + extra))
        out = tmp_path / name
        assert main(["run", str(path), "--out", str(out), "--set", "simulation.t_final=20",
                     "--set", "model.modes=1"]) == 0
        summary = json.loads((out / "summary.json").read_text())
        peaks[name] = summary["peak_tip_deflection"]
        assert _final_error(out) < 1e-3
    print(peaks)
    assert peaks["eigenaxis"] < 0.5 * peaks["step"]
