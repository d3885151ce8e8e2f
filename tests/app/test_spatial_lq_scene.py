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
    ("design_modes = 1", 'design_modes = 1\nshaper = "zv"', r"controller\.shaper needs"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 9.0\nshaper = "zvdd"',
     r"controller\.shaper must be 'zv' or 'zvd'"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 9.0\nshaped_modes = 2',
     r"controller\.shaped_modes needs controller\.shaper"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 9.0\nshaper = "zv"\n'
     'shaped_modes = 0', r"controller\.shaped_modes must be an integer >= 1"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 9.0\nshaper = "zv"\n'
     'shaped_modes = 40', r"controller\.shaped_modes must be at most 3: a torque about"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 9.0\nshaper = "zv"\n'
     'shaped_modes = 1.5', r"controller\.shaped_modes"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 12.05\nslew_shape = "optimal"',
     r"controller\.slew_duration must be a multiple of controller\.sample_time"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 12.0\nslew_intervals = 40',
     r"controller\.slew_intervals is for slew_shape = 'optimal'"),
    ("design_modes = 1", 'design_modes = 1\nslew_intervals = 40',
     r"controller\.slew_intervals needs controller\.slew_duration"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 12.0\nslew_shape = "optimal"\n'
     'shaper = "zv"', r"controller\.shaper shapes a slew_shape"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 12.0\nslew_shape = "optimal"\n'
     'slew_intervals = 1', r"controller\.slew_intervals"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 0.5\nslew_shape = "optimal"',
     r"controller\.slew_duration must be at least [\d.]+ s"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 12.0\nslew_smoothness = 1.0',
     r"controller\.slew_smoothness is for slew_shape = 'optimal'"),
    ("design_modes = 1", 'design_modes = 1\nslew_duration = 12.0\nslew_shape = "optimal"\n'
     'slew_smoothness = -1.0', r"controller\.slew_smoothness"),
], ids=["no hub_angle", "no torque", "negative weight", "string weight",
        "zero noise", "no design modes", "unknown key",
        "negative cut-off", "negative slew duration", "unknown slew shape",
        "a shape without a duration", "a shaper without a duration", "unknown shaper",
        "shaped modes without a shaper", "no shaped modes", "more shaped modes than moved",
        "fractional shaped modes", "an optimal slew off the samples",
        "holds without an optimal slew", "holds without a duration", "a shaped optimal slew",
        "one hold", "an optimal slew too short", "smoothness without a plan",
        "negative smoothness"])
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


def _short_slew(extra: str) -> str:
    """The LQR on the whole state, the arrays' modes in its design, a 1 s cycloidal slew with
    no torque limit and no wheels: the profile itself rings the arrays."""
    text = _lqr_scene(sensors=False)
    text = "\n".join(line for line in text.splitlines() if not line.startswith("torque_limit"))
    text = text[:text.index("[actuator]")] + text[text.index("[controller]"):]
    return text.replace("design_modes = 1", "design_modes = 1\nslew_duration = 1.0\n"
                        'slew_shape = "cycloidal"\n' + extra)


@pytest.mark.slow
def test_a_shaped_eigenaxis_slew_leaves_less_vibration(tmp_path):
    """``shaper``: the profile convolved with a ZV or ZVD shaper of the mode a torque about
    the axis moves first; the arrays ring less after the slew than under the same law on the
    unshaped profile (measured 4.3e-3 m unshaped, 9.8e-4 ZV, 1.8e-4 ZVD)."""
    residual = {}
    for name, extra in (("none", ""), ("zv", 'shaper = "zv"'), ("zvd", 'shaper = "zvd"')):
        path = tmp_path / f"{name}.toml"
        path.write_text(_short_slew(extra))
        out = tmp_path / name
        assert main(["run", str(path), "--out", str(out), "--set", "simulation.t_final=6",
                     "--set", "model.modes=2", "--set", "controller.sample_time=0.01"]) == 0
        rows = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
        late = rows["t"] > 2.0                       # the slew and the shaper's delay are over
        residual[name] = max(np.max(np.abs(rows[c][late])) for c in rows.dtype.names
                             if ".tip_" in c or "tip_d" in c)
        assert _final_error(out) < 2e-3            # 20 degrees turned, settling 5 s after
    print(residual)
    assert residual["zv"] < 0.4 * residual["none"]
    assert residual["zvd"] < 0.25 * residual["zv"]


@pytest.mark.slow
def test_an_lqr_follows_an_optimal_slew_planned_within_the_wheels_limits(tmp_path):
    """``slew_shape = "optimal"``: the slew planned on the design modes within the wheels'
    limits, one hold per sample; on the exact plant the law ends the slew on target, where
    the rigid seventh-order profile of the same 12 s leaves it behind (measured 1.7e-6 rad
    against 2.0e-3 rad at the slew's end, residual tip 6.0e-6 m against 2.3e-5 m)."""
    target = from_rotation_vector(np.radians(20.0) * np.array([0.6, 0.0, 0.8]))
    found = {}
    for shape in ("poly7", "optimal"):
        path = tmp_path / f"{shape}.toml"
        path.write_text(_lqr_scene(sensors=False).replace(
            "design_modes = 1", f'design_modes = 1\nslew_duration = 12.0\nslew_shape = "{shape}"'))
        out = tmp_path / shape
        assert main(["run", str(path), "--out", str(out), "--set", "simulation.t_final=20",
                     "--set", "model.modes=2"]) == 0
        rows = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
        end = int(np.argmin(np.abs(rows["t"] - 12.0)))
        found[shape] = (
            float(np.linalg.norm(error_angles(target, [rows[k][end] for k in
                                                       ("qw", "qx", "qy", "qz")]))),
            max(np.max(np.abs(rows[c][rows["t"] > 12.0])) for c in rows.dtype.names
                if "tip_" in c),
            max(np.max(np.abs(rows[c])) for c in rows.dtype.names
                if c.startswith("wheel") and c.endswith("torque")))
    print(found)
    assert found["optimal"][0] < 0.01 * found["poly7"][0]
    assert found["optimal"][1] < 0.5 * found["poly7"][1]
    assert found["optimal"][2] <= 0.1 + 1e-9


def _nmpc_scene(extra: str = "", sensors: bool = False) -> str:
    return _lqr_scene(sensors).replace('kind = "lqr"', 'kind = "nmpc"').replace(
        "design_modes = 1", "design_modes = 1\n" + extra)


def test_an_nmpc_scene_slews_within_the_wheels_and_reports_its_linear_law(tmp_path):
    """``kind = "nmpc"``: the three-axis NMPC through the scene's wheels; the summary's
    margins are those of its held gain about rest at the target."""
    path = tmp_path / "nmpc.toml"
    path.write_text(_nmpc_scene())
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--set", "simulation.t_final=20",
                 "--set", "model.modes=2"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    margins = summary["loop_margins"]
    assert margins["closed_loop_stable"] and margins["held_at"] == 0.1
    assert "NMPC" in margins["design_note"] and min(margins["gain_margin_db"]) > 6.0
    assert _final_error(out) < 1e-4
    rows = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    assert max(np.max(np.abs(rows[c])) for c in rows.dtype.names
               if c.startswith("wheel") and c.endswith("torque")) <= 0.1 + 1e-9


@pytest.mark.parametrize("extra, sensors, pattern", [
    ("", True, r"controller\.kind = 'nmpc' feeds back the plant's whole state"),
    ("slew_duration = 12.0", False, r"controller\.kind = 'nmpc' follows slew_shape = 'optimal'"),
    ("horizon = 1", False, r"controller\.horizon"),
    ('qp_solver = "hpipm"', False, r"controller\.qp_solver"),
    ("shaper = \"zv\"", False, r"controller\.shaper"),
    ("max_frequency = 10.0", False, r"controller\.max_frequency"),
], ids=["with sensors", "an eigenaxis slew", "a horizon of one", "a stage-structured QP solver",
        "a shaper", "a cut-off"])
def test_a_bad_nmpc_scene_is_refused_by_its_key(tmp_path, extra, sensors, pattern):
    path = tmp_path / "nmpc.toml"
    path.write_text(_nmpc_scene(extra, sensors))
    with pytest.raises(InputError, match=pattern):
        load_scene(path)


def test_exporting_a_spatial_lqg_scene_writes_its_law_and_refuses_what_it_cannot(tmp_path,
                                                                                   capsys):
    """The LQG's C from the scene (its own filter inside: the scene's star tracker and gyro
    feed it through the attitude filter, written beside it in ``filter/``)."""
    out = tmp_path / "c"
    assert main(["export", str(EXAMPLE), "--out", str(out), "--no-compile"]) == 0
    summary = json.loads((out / "export.json").read_text())
    assert summary["controller"] == "SpatialLQG" and summary["compiled"] is False
    assert summary["input_names"] == ["qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    assert "#define FLEXCTL_NU 3" in (out / "flexctl_ctrl.h").read_text()
    assert summary["filter"]["input_names"][-1] == "tracked"
    assert "#define FLEXCTL_NU 7" in (out / "filter" / "flexctl_ctrl.h").read_text()
    single = tmp_path / "float"
    assert main(["export", str(EXAMPLE), "--out", str(single), "--no-compile",
                 "--precision", "float"]) == 0
    summary = json.loads((single / "export.json").read_text())
    assert summary["precision"] == "float" and summary["filter"]["precision"] == "float"
    assert isinstance(summary["float_conditioning"], list)
    assert isinstance(summary["filter"]["float_conditioning"], list)
    assert "float" in (single / "filter" / "flexctl_ctrl.h").read_text()
    capsys.readouterr()
    bad = tmp_path / "bad"
    assert main(["export", str(EXAMPLE), "--out", str(bad), "--no-compile",
                 "--sample-time", "0.2"]) != 0
    error = capsys.readouterr().err
    assert "keeps its own sample time (0.1 s)" in error and "Traceback" not in error
    assert not bad.exists()
    nmpc, written = tmp_path / "nmpc.toml", tmp_path / "nmpc"
    nmpc.write_text(_nmpc_scene())
    assert main(["export", str(nmpc), "--out", str(written), "--no-compile"]) == 0
    summary = json.loads((written / "export.json").read_text())
    assert summary["controller"] == "SpatialNMPC" and "qrqp" in summary["description"]
    assert summary["input_names"][:4] == ["qw", "qx", "qy", "qz"]
    assert summary["input_names"][-1] == "wheel3.speed"


@pytest.mark.slow
def test_a_spatial_export_flies_its_c_law_and_filter_in_the_scene_loop(tmp_path, capsys):
    """The built-in pyramid slew (quaternion feedback with integral action through the
    attitude filter, 0.2 s tracker latency) exported, compiled, checked step by step against
    its programs and flown for 4 s in the scene's loop in double and in float."""
    out = tmp_path / "c"
    assert main(["export", "spatial-pyramid-slew", "--out", str(out), "--loop-check",
                 "--set", "simulation.t_final=4"]) == 0
    printed = capsys.readouterr().out
    assert "in the loop, float: ok" in printed and "filter: multiplicative" in printed
    summary = json.loads((out / "export.json").read_text())
    assert summary["controller"] == "QuaternionFeedback" and summary["compiled"]
    assert summary["check_max_difference"] < 1e-12
    assert summary["filter"]["check_max_difference"] < 1e-12
    double, single = (summary["precision_in_the_loop"][p] for p in ("double", "float"))
    print(double, single)
    assert double["max_command_difference"] < 1e-9 and double["max_attitude_difference"] < 1e-9
    assert single["max_command_difference"] < 1e-4 and single["max_attitude_difference"] < 1e-5
    assert double["final_pointing_error"] == pytest.approx(
        double["python_final_pointing_error"], rel=1e-6)
    assert sorted(p.name for p in out.iterdir()) == ["Makefile", "export.json", "filter",
                                                     "flexctl_ctrl.c", "flexctl_ctrl.h",
                                                     "main.c"]

def _modes_filter_scene(wheels: bool, choice: str = "modes") -> str:
    text = SCENE.replace("[sensors]\n", f'[sensors]\nfilter = "{choice}"\n')
    return text if wheels else text[:text.index("[actuator]")] + text[text.index("[controller]"):]


def test_a_scene_flies_the_filter_with_the_modes_without_wheels(tmp_path):
    """``[sensors] filter = "modes"``: the LQG reads the attitude filter with the arrays'
    modes, handed the hub torque; another filter is refused by key."""
    path = tmp_path / "modes.toml"
    path.write_text(_modes_filter_scene(wheels=False))
    from controllers.feedback.flexible_mekf import FlexibleAttitudeFilter

    scene = load_scene(path)
    assert isinstance(scene.loop.estimator(scene.quaternion), FlexibleAttitudeFilter)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--set", "simulation.t_final=20",
                 "--set", "model.modes=1"]) == 0
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"
    assert _final_error(out) < 1e-3
    path.write_text(_modes_filter_scene(False, "kalman"))
    with pytest.raises(InputError, match=r"sensors\.filter must be one of attitude, modes"):
        load_scene(path)


def test_a_scene_flies_the_filter_with_the_modes_through_wheels(tmp_path):
    """The example's LQG through its three wheels, reading the filter with the modes (which
    reads the wheels' speeds): the slew ends as the attitude filter's does, to the sensors'
    noise; the export writes that filter as C."""
    path = tmp_path / "modes.toml"
    path.write_text(_modes_filter_scene(wheels=True))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--set", "simulation.t_final=20",
                 "--set", "model.modes=1"]) == 0
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"
    error = _final_error(out)
    print(f"final pointing error {error:.1e} rad")
    assert error < 1e-3
    written = tmp_path / "c"                 # its filter as C beside the law
    assert main(["export", str(path), "--out", str(written), "--no-compile"]) == 0
    summary = json.loads((written / "export.json").read_text())
    assert "modal states of the structure" in summary["filter"]["description"]
    assert summary["filter"]["input_names"][3:9] == ["tx", "ty", "tz", "hx", "hy", "hz"]
