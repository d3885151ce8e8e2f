"""Command line, run files, demo report and plots.

Facts checked: the spacecraft response of paper 001 (sec. 3.2), the cantilever frequencies in
closed form, the zero_order divergence above the first clamped frequency, and the contracts of
the command line (files, exit status, one-line errors).
"""

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import flexctl
from flexctl import builtin_scenes, build_model, load_scene
from flexctl.app.cli import EXIT_BAD_INPUT, EXIT_OK, EXIT_STOPPED, main, parse_overrides
from flexctl.app.plotting import plot_frequencies_vs_spin, plot_mode_shapes, plot_response

#: Paper 001, sec. 3.2: peak tip deflection of the spacecraft under 50 N m for 2 s, 0.42 m,
#: read off the paper's figure.
PAPER_PEAK_TIP_DEFLECTION = 0.42
PAPER_TOLERANCE = 0.05
#: Roots of cos z cosh z + 1 = 0 (Blevins, Formulas for natural frequency and mode shape).
CANTILEVER_ROOTS = (1.87510407, 4.69409113)
ROOT_DIGITS_RTOL = 1e-7
#: Closed forms against the assembled model (exact up to quadrature and round-off).
FREQUENCY_RTOL = 1e-6
#: timeseries.csv keeps 12 significant digits.
CSV_RTOL = 1e-10
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
BUILTINS = ("kane-spinup", "spacecraft-torque", "hub-beam-mass")


def _read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


def _cantilever_frequencies(beam):
    """omega_i = z_i^2 sqrt(EI / (rho A l^4)), rad/s."""
    scale = np.sqrt(beam.youngs_modulus * beam.second_moment
                    / (beam.density * beam.area * beam.length ** 4))
    return np.array(CANTILEVER_ROOTS) ** 2 * scale


@pytest.fixture(scope="module")
def spacecraft_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("spacecraft") / "out"
    code = main(["run", "spacecraft-torque", "--out", str(out)])
    return code, out, json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def zero_order_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("zero_order") / "out"
    code = main(["run", "kane-spinup", "--set", "model.variant=zero_order", "--out", str(out)])
    return code, out, json.loads((out / "summary.json").read_text())


# ---------------------------------------------------------------------------- run
def test_spacecraft_run_reaches_paper_peak(spacecraft_run):
    code, out, summary = spacecraft_run
    assert code == EXIT_OK
    assert summary["status"] == "ok"
    assert summary["scene"] == "spacecraft-torque"
    assert summary["peak_tip_deflection"] == pytest.approx(PAPER_PEAK_TIP_DEFLECTION,
                                                           rel=PAPER_TOLERANCE)
    assert summary["t_end"] == pytest.approx(load_scene("spacecraft-torque").simulation.t_final)
    for name in ("timeseries.csv", "summary.json", "response.png"):
        assert (out / name).is_file()
    assert (out / "response.png").read_bytes()[:8] == PNG_MAGIC


def test_summary_has_required_keys(spacecraft_run):
    _, _, summary = spacecraft_run
    scene = load_scene("spacecraft-torque")
    required = {"scene", "variant", "n_modes", "status", "message", "peak_tip_deflection",
                "t_end", "wall_time_s", "overrides", "clamped_frequencies"}
    assert required <= set(summary)
    assert summary["variant"] == scene.model.variant
    assert summary["n_modes"] == scene.model.modes
    assert summary["overrides"] == {}
    assert summary["wall_time_s"] >= 0.0


def test_summary_frequencies_are_the_cantilever_frequencies(spacecraft_run):
    # No point masses: the clamped frequencies at rest are those of a uniform cantilever.
    _, _, summary = spacecraft_run
    expected = _cantilever_frequencies(load_scene("spacecraft-torque").system.beam)
    np.testing.assert_allclose(summary["clamped_frequencies"][:len(expected)], expected,
                               rtol=max(FREQUENCY_RTOL, 2 * ROOT_DIGITS_RTOL))


def test_timeseries_header_and_columns(spacecraft_run):
    _, out, summary = spacecraft_run
    n = summary["n_modes"]
    header, data = _read_csv(out / "timeseries.csv")
    assert header == ["t", "theta", "theta_dot", "torque", "tip_deflection",
                      *(f"q{i}" for i in range(1, n + 1)), "root_moment", "tip_angle"]
    assert data.shape[1] == 7 + n
    assert data[0, 0] == 0.0
    assert np.all(np.diff(data[:, 0]) > 0)
    assert data[-1, 0] == pytest.approx(summary["t_end"], rel=CSV_RTOL)
    assert np.max(np.abs(data[:, 4])) == pytest.approx(summary["peak_tip_deflection"],
                                                       rel=CSV_RTOL)


def test_timeseries_torque_is_the_scene_maneuver(spacecraft_run):
    _, out, _ = spacecraft_run
    maneuver = load_scene("spacecraft-torque").maneuver
    _, data = _read_csv(out / "timeseries.csv")
    t, torque = data[:, 0], data[:, 3]
    np.testing.assert_allclose(torque, maneuver(t), rtol=CSV_RTOL,
                               atol=CSV_RTOL * maneuver.peak_torque)


def test_zero_order_spinup_diverges(zero_order_run, capsys):
    code, out, summary = zero_order_run
    assert code == EXIT_STOPPED
    assert summary["status"] == "diverged"
    assert summary["variant"] == "zero_order"
    assert summary["overrides"] == {"model.variant": "zero_order"}
    assert re.search(r"clamped frequency", summary["message"])
    assert re.search(r"stiffening", summary["message"])
    assert summary["t_end"] < load_scene("kane-spinup").simulation.t_final
    for name in ("timeseries.csv", "summary.json", "response.png"):
        assert (out / name).is_file()
    _, data = _read_csv(out / "timeseries.csv")
    assert data[-1, 0] == pytest.approx(summary["t_end"], rel=CSV_RTOL)


def test_zero_order_diverges_only_above_first_clamped_frequency(zero_order_run):
    # zero_order beam stiffness K - Omega^2 M: it is lost when the hub rate passes omega_1.
    _, out, summary = zero_order_run
    omega_1 = _cantilever_frequencies(load_scene("kane-spinup").system.beam)[0]
    _, data = _read_csv(out / "timeseries.csv")
    assert data[-1, 2] > omega_1
    # At a steady spin Omega its clamped eigenvalues are omega_i^2 - Omega^2 exactly.
    spin = summary["spin_rate"]
    assert spin > omega_1
    assert summary["clamped_frequencies_at_spin"][0] == pytest.approx(
        -np.sqrt(spin ** 2 - summary["clamped_frequencies"][0] ** 2), rel=FREQUENCY_RTOL)


def test_run_default_output_directory(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = main(["run", "kane-spinup", "--set", "model.variant=zero_order"])
    assert code == EXIT_STOPPED
    out = tmp_path / "flexctl-out" / "kane-spinup"
    assert sorted(p.name for p in out.iterdir()) == ["response.png", "summary.json",
                                                     "timeseries.csv"]
    printed = capsys.readouterr().out
    assert "diverged" in printed and "kane-spinup" in printed


def test_run_scene_file_with_override(tmp_path, capsys):
    source = tmp_path / "short.toml"
    source.write_text(
        (Path(flexctl.__file__).parent / "app" / "builtin_scenes" / "kane-spinup.toml").read_text())
    out = tmp_path / "out"
    code = main(["run", str(source), "--set", "simulation.t_final=2", "--out", str(out)])
    assert code == EXIT_OK
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scene"] == "short"
    assert summary["t_end"] == pytest.approx(2.0)
    assert summary["overrides"] == {"simulation.t_final": "2"}


# ---------------------------------------------------------------------------- bad input
BAD_INPUTS = [
    pytest.param(["run", "no-such-scene"], "no-such-scene", id="unknown-scene"),
    pytest.param(["run", "missing-file.toml"], "missing-file.toml", id="missing-file"),
    pytest.param(["run", "kane-spinup", "--set", "beam.lenght=3"], "beam.lenght",
                 id="unknown-key"),
    pytest.param(["run", "kane-spinup", "--set", "beam.length=-1"], "beam.length",
                 id="negative-length"),
    pytest.param(["run", "kane-spinup", "--set", "beam.length"], "=", id="set-without-equals"),
    pytest.param(["run", "kane-spinup", "--set", "model.variant=fourth_order"],
                 "model.variant", id="unknown-variant"),
    pytest.param(["frobnicate"], "frobnicate", id="unknown-command"),
]


@pytest.mark.parametrize(("argv", "named"), BAD_INPUTS)
def test_bad_input_is_one_line_and_exit_2(argv, named, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    captured = capsys.readouterr()
    assert code == EXIT_BAD_INPUT
    lines = captured.err.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("flexctl: error: ")
    assert named in lines[0]
    assert "Traceback" not in captured.err
    assert captured.out == ""
    assert not (tmp_path / "flexctl-out").exists()


def test_unwritable_output_is_one_line(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    code = main(["run", "kane-spinup", "--set", "simulation.t_final=1",
                 "--out", str(blocker / "sub")])
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT
    assert err.count("\n") == 1 and err.startswith("flexctl: error: cannot write")


def test_parse_overrides_requires_equals():
    assert parse_overrides(["a.b=c=d"]) == {"a.b": "c=d"}
    with pytest.raises(ValueError, match="key=value.*'beam'"):
        parse_overrides(["beam"])


def test_installed_script_reports_bad_input_without_traceback(tmp_path):
    script = Path(sys.executable).parent / "flexctl"
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run([str(script), "run", "kane-spinup", "--set", "beam.lenght=3"],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert proc.returncode == EXIT_BAD_INPUT
    assert proc.stderr.startswith("flexctl: error: ") and proc.stderr.count("\n") == 1
    assert "beam.lenght" in proc.stderr and "Traceback" not in proc.stderr

    proc = subprocess.run([str(script), "--version"], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == EXIT_OK
    assert proc.stdout.strip() == f"flexctl {flexctl.__version__}"


# ---------------------------------------------------------------------------- scenes, demo
def test_scenes_lists_builtins_with_descriptions(capsys):
    assert main(["scenes"]) == EXIT_OK
    printed = capsys.readouterr().out
    listed = {line.split()[0] for line in printed.splitlines() if line.strip()}
    assert set(BUILTINS) <= listed
    for name, description in builtin_scenes().items():
        assert description in printed


def _assert_hardware_rows(report: str):
    """The demo's actuator-and-sensor table: the limits hold, a wheel far from its limits
    leaves the LQR slew as it was, noisy readings do not."""
    from flexctl.app.demo_hardware import SETUPS

    cells = [[c.strip() for c in line.strip("|").split("|")] for line in report.splitlines()
             if line.startswith("| wheel-slew: ") or line.startswith("| flexible-link: ")]
    table = {(c[0], c[1]): c for c in cells}
    assert len(table) == 12 and all(c[2] == "ok" for c in cells)
    ideal, wheel, sensed = (table[("wheel-slew: lqr", setup)] for setup in SETUPS)
    assert float(wheel[-1].split()[0]) <= load_scene("wheel-slew").actuator.speed_limit
    assert float(wheel[3]) <= 2 * float(ideal[3]) and float(sensed[3]) > 2 * float(ideal[3])
    limit = load_scene("flexible-link").actuator.voltage_limit
    for (case, setup), c in table.items():
        if case.startswith("flexible-link") and setup != SETUPS[0]:
            assert float(c[-1].split()[0]) <= limit


@pytest.mark.slow
def test_demo_writes_report_and_plots(tmp_path, capsys, monkeypatch):
    # a run cache of its own: the first demo computes every run, the second replays them
    monkeypatch.setenv("FLEXCTL_RUN_CACHE_DIR", str(tmp_path / "runs"))
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == EXIT_OK
    assert str(out / "report.md") in capsys.readouterr().out
    report = (out / "report.md").read_text()
    remembered = sorted((tmp_path / "runs").iterdir())
    assert len(remembered) >= len(BUILTINS)
    again = tmp_path / "again"
    assert main(["demo", "--out", str(again)]) == EXIT_OK
    assert sorted((tmp_path / "runs").iterdir()) == remembered
    assert (again / "report.md").read_text() == report
    for path in out.rglob("*"):
        if path.is_file():
            assert (again / path.relative_to(out)).read_bytes() == path.read_bytes(), path

    links = re.findall(r"\]\(([^)]+\.png)\)", report)
    assert "frequencies-vs-spin.png" in links
    for name in BUILTINS:
        assert f"{name}/response.png" in links
    for link in set(links):
        assert (out / link).read_bytes()[:8] == PNG_MAGIC

    rows = {cells[0]: cells for cells in
            ([c.strip() for c in line.strip("|").split("|")] for line in report.splitlines()
             if line.startswith("| ") and not line.startswith("| run "))}
    for name in BUILTINS:
        assert rows[name][4] == "ok"
        assert json.loads((out / name / "summary.json").read_text())["status"] == "ok"
    _assert_hardware_rows(report)
    # the three-axis control section: every kind flies; the plan-followers end the slew
    # nearer the target than the eigenaxis LQR, the step law is still turning
    assert "## Three-axis control: every controller kind on the same slew" in report
    control = {label: cells for label, cells in rows.items() if "(state)" in label
               or "(sensors, filter)" in label}
    assert len(control) == 5 and all(cells[1] == "ok" for cells in control.values())
    at_end = {label: float(cells[2]) for label, cells in control.items()}
    assert at_end["LQR, optimal slew (state)"] < 0.3 * at_end["LQR, eigenaxis slew (state)"]
    assert at_end["NMPC, optimal slew (state)"] < 0.3 * at_end["LQR, eigenaxis slew (state)"]
    assert at_end["quaternion feedback, step (sensors, filter)"] > 1e-2
    # the three-axis section: its table, figure and animation
    assert "## Three axes: what a planar model misses" in report
    assert (out / "spatial-tilted-slew.gif").read_bytes()[:6] == b"GIF89a"
    assert "three_axes.png" in links
    zero = [cells for cells in rows.values() if cells[2] == "zero_order"]
    assert len(zero) == 1 and zero[0][1] == "kane-spinup" and zero[0][4] == "diverged"
    zero_summary = json.loads((out / zero[0][0] / "summary.json").read_text())
    assert zero_summary["message"] in report


# ---------------------------------------------------------------------------- plots
def test_frequency_plot_keeps_lost_stiffness_negative():
    system = load_scene("kane-spinup").system
    omega_1 = _cantilever_frequencies(system.beam)[0]
    spin = np.linspace(0.0, 2.0 * omega_1, 41)
    fig = plot_frequencies_vs_spin(system, spin, n_modes=3, n_frequencies=1)
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    zero = lines["zero_order mode 1"].get_ydata()
    # eig(K - Omega^2 M, M) = omega_1^2 - Omega^2: negative above omega_1, drawn as such.
    # Compared squared: near Omega = omega_1 the square root magnifies round-off.
    np.testing.assert_allclose(np.sign(zero) * zero ** 2, omega_1 ** 2 - spin ** 2,
                               rtol=FREQUENCY_RTOL, atol=FREQUENCY_RTOL * omega_1 ** 2)
    assert np.all(zero[spin > omega_1 * (1 + FREQUENCY_RTOL)] < 0)
    stiffened = lines["first_order mode 1"].get_ydata()
    assert np.all(stiffened > 0) and np.all(np.diff(stiffened) > 0)
    assert any("stiffness lost" in text.get_text() for text in fig.axes[0].texts)


def test_response_plot_marks_stop():
    scene = load_scene("kane-spinup", overrides={"model.variant": "zero_order"})
    result = flexctl.run_scene(scene)
    fig = plot_response(result)
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert {"hub angle (rad)", "hub rate (rad/s)", "torque (N m)",
            "tip deflection (m)"} <= set(labels)
    notes = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any(note.startswith("diverged at t =") for note in notes)


def _labelled_lines(ax) -> dict:
    return {line.get_label(): line for line in ax.get_lines()
            if not line.get_label().startswith("_")}


def test_slew_response_plot_draws_reference_and_torque_bound(tmp_path, monkeypatch):
    """``flexctl run slew-90`` draws on response.png the reference the tracker follows (it
    ends at the 90 degree target) and the 6 N m torque bound at +-6 N m."""
    from flexctl.app import plotting

    drawn = []

    def recorded(*args, **kwargs):
        drawn.append(plot_response(*args, **kwargs))
        return drawn[-1]

    monkeypatch.setattr(plotting, "plot_response", recorded)
    assert main(["run", "slew-90", "--out", str(tmp_path / "out")]) == EXIT_OK
    assert (tmp_path / "out" / "response.png").read_bytes()[:8] == PNG_MAGIC
    (fig,) = drawn
    angle_ax, torque_ax = fig.axes[0], fig.axes[1]
    maneuver = load_scene("slew-90").maneuver
    reference = _labelled_lines(angle_ax)["reference"]
    assert reference.get_linestyle() == "--"
    assert reference.get_ydata()[0] == pytest.approx(0.0, abs=1e-9)
    assert reference.get_ydata()[-1] == pytest.approx(maneuver.angle)
    assert "reference" in [t.get_text() for t in angle_ax.get_legend().get_texts()]
    bounds = sorted(line.get_ydata()[0] for line in torque_ax.get_lines()
                    if line.get_label().lstrip("_") == "torque bound")
    assert bounds == pytest.approx([-maneuver.torque_bound, maneuver.torque_bound])
    assert "torque bound" in _labelled_lines(torque_ax)


def test_slew_response_plot_without_reference_draws_the_target():
    # 10 degrees: inside the first_order model's small-deflection range
    scene = load_scene("slew-90", {"controller.kind": "bang_bang", "model.variant": "first_order",
                                   "model.modes": 2, "maneuver.angle_deg": 10.0})
    from flexctl.app.runner import execute

    result, _, reference = execute(scene)
    assert reference is None
    fig = plot_response(result, reference=reference, target_angle=scene.maneuver.angle,
                        torque_bound=scene.maneuver.torque_bound)
    target = _labelled_lines(fig.axes[0])["target"]
    assert list(target.get_ydata()) == [scene.maneuver.angle] * 2
    assert "reference" not in _labelled_lines(fig.axes[0])
    # Nothing of a slew is drawn on a run that is not one.
    plain = plot_response(result)
    assert set(_labelled_lines(plain.axes[0])) == {"hub angle"}
    assert not _labelled_lines(plain.axes[1])


def test_mode_shapes_plot_is_tip_normalised():
    model = build_model(load_scene("hub-beam-mass").system, n_modes=3)
    fig = plot_mode_shapes(model)
    shapes = [line for line in fig.axes[0].get_lines() if line.get_label().startswith("mode")]
    assert len(shapes) == 3
    for line in shapes:
        assert line.get_xdata()[-1] == pytest.approx(model.system.beam.length)
        assert abs(line.get_ydata()[-1]) == pytest.approx(2.0)


@pytest.mark.parametrize(("call", "match"), [
    pytest.param(lambda m: plot_frequencies_vs_spin(m, [1.0]), "spin_rates", id="one-rate"),
    pytest.param(lambda m: plot_frequencies_vs_spin(m, [0, 1], n_frequencies=9),
                 "n_frequencies", id="too-many-frequencies"),
    pytest.param(lambda m: plot_frequencies_vs_spin("beam", [0, 1]), "models", id="not-model"),
    pytest.param(lambda m: plot_mode_shapes(m, n_shapes=0), "n_shapes", id="no-shapes"),
])
def test_plots_reject_bad_arguments(call, match):
    model = build_model(load_scene("kane-spinup").system, n_modes=2)
    with pytest.raises((ValueError, TypeError), match=match):
        call(model)


def test_warnings_outside_a_held_run_are_one_line_each_once(monkeypatch, capsys):
    import warnings

    from flexctl.app import cli

    class StudyWarning(UserWarning):
        pass

    def noisy(args):
        for _ in range(3):
            warnings.warn("the tip\n    bends far", StudyWarning)
        warnings.warn("another", StudyWarning)
        return 0

    monkeypatch.setattr(cli, "_cmd_scenes", noisy)
    assert cli.main(["scenes"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err == ["flexctl: warning: StudyWarning: the tip bends far",
                   "flexctl: warning: StudyWarning: another"]
