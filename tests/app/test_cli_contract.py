"""The command line's contract: exit 0 ok, 2 bad input (one line on stderr and nothing else),
3 stopped, 1 a bug with its traceback; files complete in ``--out`` or not there at all."""

import pytest

import flexctl.app.runner as runner
from flexctl.app.cli import EXIT_BAD_INPUT, EXIT_BUG, EXIT_OK, main

#: A run that takes well under a second: one mode, one second.
QUICK = ["--set", "model.modes=1", "--set", "simulation.t_final=1"]
OUTPUT_FILES = {"timeseries.csv", "summary.json", "response.png"}


def _assert_one_error_line(code, captured, *named):
    assert code == EXIT_BAD_INPUT
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("flexctl: error: ")
    for text in named:
        assert text in lines[0]
    assert captured.out == ""


@pytest.mark.parametrize(("argv", "named"), [
    pytest.param(["run", "hub-beam-mass", "--out", ""], ("--out", "''"), id="empty-out"),
    pytest.param(["run", "slew-90", "--set", "controller.kind=lqr",
                  "--set", "controller.hub_angle=1e-200"],
                 ("controller.hub_angle", "1e-200"),
                 id="overflowing-lqr-weight"),
    pytest.param(["run", "slew-90", "--set", "controller.kind=pd",
                  "--set", "maneuver.torque_bound=1e-3"], ("simulation.t_final", "194 s", "6 s"),
                 id="stretched-reference-past-t_final"),
    pytest.param(["run", "hub-beam-mass", "--set", "masses.0.mass=1e8"],
                 ("ratio of the point masses", "8.034e+07"), id="heavy-tip-mass"),
    pytest.param(["run", "hub-beam-mass", "--set", "beam.density=1e-300",
                  "--set", "beam.area=1e-300"], ("beam.density * beam.area", "got 0.0"),
                 id="underflowing-density"),
    pytest.param(["run", "slew-90", "--set", "controller.kind=trajopt",
                  "--set", "maneuver.torque_bound=1e-3"], ("torque_bound", "0.001"),
                 id="infeasible-trajopt"),
])
def test_bad_input_leaves_one_line_on_stderr_and_no_files(argv, named, tmp_path, monkeypatch,
                                                          capfd):
    """capfd: CasADi and IPOPT print from C++, below sys.stderr; none of it may show."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    code = main(argv + (["--out", str(out)] if "--out" not in argv else []))
    _assert_one_error_line(code, capfd.readouterr(), *named)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_bug_exits_1_with_its_traceback(tmp_path, monkeypatch, capsys):
    def broken(scene, **options):
        raise ValueError("an internal inconsistency")
    monkeypatch.setattr(runner, "run_scene", broken)
    code = main(["run", "hub-beam-mass", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == EXIT_BUG
    assert "Traceback" in err and "ValueError: an internal inconsistency" in err
    assert "flexctl: error:" not in err
    assert not (tmp_path / "out").exists()


def _previous_run(out):
    out.mkdir()
    for name in OUTPUT_FILES:
        (out / name).write_text("previous run")
    (out / "notes.txt").write_text("mine")


@pytest.mark.parametrize("failure", ["write", "bug"])
def test_failed_run_leaves_the_output_directory_as_it_was(failure, tmp_path, monkeypatch,
                                                          capsys):
    out = tmp_path / "out"
    _previous_run(out)
    if failure == "write":
        real = runner.write_run

        def write_then_fail(scene, result, where, **kwargs):
            real(scene, result, where, **kwargs)
            raise OSError(28, "No space left on device")
        monkeypatch.setattr(runner, "write_run", write_then_fail)
        expected = EXIT_BAD_INPUT
    else:
        def broken(scene, **options):
            raise RuntimeError("boom")
        monkeypatch.setattr(runner, "run_scene", broken)
        expected = EXIT_BUG
    assert main(["run", "hub-beam-mass", *QUICK, "--out", str(out)]) == expected
    assert {p.name: p.read_text() for p in out.iterdir()} == {
        **{name: "previous run" for name in OUTPUT_FILES}, "notes.txt": "mine"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_complete_run_replaces_the_files_and_keeps_others(tmp_path, capsys):
    out = tmp_path / "out"
    _previous_run(out)
    assert main(["run", "hub-beam-mass", *QUICK, "--out", str(out)]) == EXIT_OK
    assert {p.name for p in out.iterdir()} == OUTPUT_FILES | {"notes.txt"}
    assert all((out / name).read_bytes() != b"previous run" for name in OUTPUT_FILES)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
