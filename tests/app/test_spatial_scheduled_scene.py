"""A spatial scene flown by the LQR scheduled on the spin rate (``[controller] kind =
"scheduled_lqr"``): the example spin-up run as written, its margins the worst design spin's,
exported and flown as C, and refused by key."""

import json
from pathlib import Path

import numpy as np
import pytest

from flexctl.app.cli import main
from flexctl.app.scenes import load_scene
from flexctl.app.spatial_control import pointing_target
from flexctl.model.errors import InputError
from flexctl.sim.quaternions import error_angles

EXAMPLE = (Path(__file__).resolve().parents[2] / "examples" / "scenes"
           / "spatial-scheduled-spin.toml")
SCENE = EXAMPLE.read_text()


def _rows(out):
    return np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)


def test_the_scheduled_example_spins_up_on_its_reference(tmp_path):
    """Spun up to 20 rad/s in 10 s from a small nutation, then 5 s at full spin: the craft
    follows the spinning reference (error under 1e-3 rad at the end), spins at 20 rad/s, and
    every design spin's held loop is stable on the plant with every mode of the run."""
    out = tmp_path / "out"
    assert main(["run", str(EXAMPLE), "--out", str(out), "--set",
                 "simulation.t_final=15"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok"
    margins = summary["loop_margins"]
    assert [entry["spin"] for entry in margins["per_spin"]] == [0.0, 5.0, 10.0, 15.0, 20.0]
    assert all(entry["closed_loop_stable"] for entry in margins["per_spin"])
    worst = min(entry["disk_margin"] for entry in margins["per_spin"])
    assert min(margins["disk_margin"]) == pytest.approx(worst)
    assert margins["at_spin"] in (0.0, 5.0, 10.0, 15.0, 20.0) and margins["held_at"] == 0.05
    rows = _rows(out)
    assert rows["wz"][-1] == pytest.approx(20.0, rel=1e-3)
    law = load_scene(EXAMPLE).loop.law
    final = [rows[k][-1] for k in ("qw", "qx", "qy", "qz")]
    error = float(np.linalg.norm(error_angles(pointing_target(law, rows["t"][-1]), final)))
    print(f"error from the spinning reference at 15 s: {error:.2e} rad; margins {margins}")
    assert error < 1e-3


def test_a_scheduled_scene_exports_its_law_and_flies_it_as_c(tmp_path):
    """The scheduled law's C from the scene, compiled and flown in the scene's loop for 3 s
    in double (equal to Python's to 1e-9) and in float."""
    out = tmp_path / "c"
    assert main(["export", str(EXAMPLE), "--out", str(out), "--loop-check",
                 "--set", "simulation.t_final=3"]) == 0
    summary = json.loads((out / "export.json").read_text())
    assert summary["controller"] == "ScheduledSpatialLQR" and summary["compiled"]
    double, single = (summary["precision_in_the_loop"][p] for p in ("double", "float"))
    print(double, single)
    assert double["max_command_difference"] < 1e-9
    assert single["max_command_difference"] < 1e-3
    assert double["final_pointing_error"] == pytest.approx(
        double["python_final_pointing_error"], rel=1e-6, abs=1e-12)


def _edited(old: str, new: str) -> str:
    assert old in SCENE, old
    return SCENE.replace(old, new, 1)


@pytest.mark.parametrize("old, new, pattern", [
    ("spin_axis = [0.0, 0.0, 1.0]\n", "", r"controller\.spin_axis is required"),
    ("spin_rates = [0.0, 5.0, 10.0, 15.0, 20.0]\n", "", r"controller\.spin_rates is required"),
    ("spin_rate = 20.0\n", "", r"controller\.spin_rate is required"),
    ("spin_rates = [0.0, 5.0, 10.0, 15.0, 20.0]", "spin_rates = 5.0",
     r"controller\.spin_rates must be a list"),
    ("spin_rates = [0.0, 5.0, 10.0, 15.0, 20.0]", "spin_rates = [5.0, 0.0]",
     r"controller\.spin_rates must be 1 to 50 strictly increasing"),
    ("spin_rates = [0.0, 5.0, 10.0, 15.0, 20.0]", 'spin_rates = ["fast"]',
     r"controller\.spin_rates"),
    ("spin_rate = 20.0", "spin_rate = 1e300", r"controller\.spin_rate"),
    ("spin_rate = 20.0", 'spin_rate = "fast"', r"controller\.spin_rate"),
    ("ramp_time = 10.0", "ramp_time = -1.0", r"controller\.ramp_time"),
    ("ramp_time = 10.0", "ramp_time = nan", r"controller\.ramp_time"),
    ("spin_axis = [0.0, 0.0, 1.0]", "spin_axis = [0.0, 0.0, 0.0]", r"controller\.spin_axis"),
    ("spin_axis = [0.0, 0.0, 1.0]", "spin_axis = [1.0, 0.0, 1.0]",
     r"controller\.spin_axis, spin_rates: the design spin 5 rad/s about "
     r"\[0.707107, 0.0, 0.707107\]: .* no steady turn"),
    ("hub_angle = 0.01", "hub_angle = -0.01", r"controller\.hub_angle"),
    ("design_modes = 1", "design_modes = 0", r"controller\.design_modes"),
    ("spin_rate = 20.0", "spin_rate = 20.0\nslew_angle = 10.0", r"controller"),
    ("spin_rate = 20.0", "spin_rate = 20.0\ntarget = [1.0, 0.0, 0.0, 0.0]", r"controller"),
    ("design_modes = 1\n", "design_modes = 1\n[sensors]\nseed = 1\n",
     r"controller\.kind = 'scheduled_lqr' feeds back the plant's whole state"),
])
def test_a_bad_scheduled_scene_is_refused_by_its_key(tmp_path, old, new, pattern):
    path = tmp_path / "scheduled.toml"
    path.write_text(_edited(old, new))
    with pytest.raises(InputError, match=pattern):
        load_scene(path)
