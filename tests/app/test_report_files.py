"""Reports are written whole or not at all: a run's folder, a bench scene's pages and the demo
folder are left as they were when writing fails part way (hidden temporary files included)."""

from pathlib import Path
from types import SimpleNamespace

import pytest

import flexctl
import flexctl.app.plotting as plotting
from flexctl.app import bench_report, demo
from flexctl.app.report import RESPONSE_PLOT, SUMMARY, TIMESERIES, write_run
from flexctl.app.runner import execute
from flexctl.app.section import Section
from flexctl.model.errors import InputValueError
from flexctl.sim.atomic_files import write_atomic
from tests.sim.test_atomic_files import listing

RUN_FILES = (TIMESERIES, SUMMARY, RESPONSE_PLOT)


@pytest.fixture(scope="module")
def quick_run():
    """A run of well under a second: one mode, one second."""
    scene = flexctl.load_scene("hub-beam-mass", {"model.modes": 1, "simulation.t_final": 1})
    result, extra, reference = execute(scene)
    return scene, result, extra


def _previous(out: Path, names) -> None:
    out.mkdir(parents=True)
    for name in names:
        (out / name).write_text("previous")
    (out / "notes.txt").write_text("mine")


def _broken_plot(*args, **kwargs):
    raise RuntimeError("the plot failed")


@pytest.mark.parametrize("existing", [False, True], ids=["new-folder", "previous-run"])
def test_a_run_whose_plot_fails_leaves_no_partial_folder(existing, quick_run, tmp_path,
                                                         monkeypatch):
    """The CSV and the summary are written before the plot: neither may be left."""
    scene, result, extra = quick_run
    out = tmp_path / "runs" / "out"
    if existing:
        _previous(out, RUN_FILES)
    before = listing(tmp_path)
    monkeypatch.setattr(plotting, "plot_response", _broken_plot)
    with pytest.raises(RuntimeError, match="the plot failed"):
        write_run(scene, result, out, extra=extra)
    assert listing(tmp_path) == before


def test_a_run_is_written_whole_beside_other_files(quick_run, tmp_path):
    scene, result, extra = quick_run
    out = tmp_path / "out"
    _previous(out, RUN_FILES)
    summary = write_run(scene, result, out, extra=extra)
    found = listing(tmp_path)
    assert set(found) == {"out", "out/notes.txt", *(f"out/{name}" for name in RUN_FILES)}
    assert all(found[f"out/{name}"] != b"previous" for name in RUN_FILES)
    assert summary["files"]["summary"] == str(out / SUMMARY)
    (out / SUMMARY).unlink()
    (out / SUMMARY).mkdir()
    before = listing(tmp_path)
    with pytest.raises(InputValueError, match=f"'{out / SUMMARY}' is a folder"):
        write_run(scene, result, out, extra=extra)
    assert listing(tmp_path) == before


def test_a_bench_scene_whose_plot_fails_leaves_its_pages_as_they_were(tmp_path, monkeypatch):
    bench = SimpleNamespace(scene=SimpleNamespace(name="kane-spinup"), rows=[])
    names = ("kane-spinup.csv", "kane-spinup.md", "kane-spinup-pareto.png")
    _previous(tmp_path / "bench", names)
    before = listing(tmp_path)
    monkeypatch.setattr(bench_report, "plot_speed_error", _broken_plot)
    with pytest.raises(RuntimeError, match="the plot failed"):
        bench_report.write_scene(bench, tmp_path / "bench")
    assert listing(tmp_path) == before


def _small_demo(monkeypatch, frequency_plot):
    """The demo reduced to one section writing a CSV and one run, with ``frequency_plot``."""
    def section(out):
        return Section(title="a section", files=(write_atomic(out / "a.csv", "a\n1\n"),))

    def run_one(source, overrides, out_dir):
        out_dir.mkdir(parents=True)
        (out_dir / "summary.json").write_text("{}")
        return {"status": "ok", "peak_tip_deflection": 0.1, "t_end": 1.0, "wall_time_s": 0.1,
                "scene": source, "variant": "first_order", "n_modes": 1, "message": "",
                "files": {"response_plot": str(out_dir / RESPONSE_PLOT)}}

    monkeypatch.setattr(demo, "SECTIONS", (("a section", section),))
    monkeypatch.setattr(demo, "SECTION_ORDER", ("a section",))
    monkeypatch.setattr(demo, "DEMO_COMPARISONS", ())
    monkeypatch.setattr(demo, "builtin_scenes", lambda: {"one-scene": "a scene"})
    monkeypatch.setattr(demo, "frequency_plot", frequency_plot)
    return run_one


@pytest.mark.parametrize("existing", [False, True], ids=["new-folder", "previous-demo"])
def test_a_demo_that_fails_at_the_end_leaves_no_partial_folder(existing, tmp_path, monkeypatch):
    out = tmp_path / "demo"
    if existing:
        _previous(out, ("report.md", "a.csv"))
    before = listing(tmp_path)
    run_one = _small_demo(monkeypatch, _broken_plot)
    with pytest.raises(RuntimeError, match="the plot failed"):
        demo.run_demo(out, run_one, workers=1, progress=lambda line: None)
    assert listing(tmp_path) == before


def test_a_demo_appears_whole(tmp_path, monkeypatch):
    out = tmp_path / "demo"
    _previous(out, ("report.md",))
    run_one = _small_demo(monkeypatch, lambda out: write_atomic(out / "f.png", b"png"))
    report, surprises = demo.run_demo(out, run_one, workers=1, progress=lambda line: None)
    assert report == out / "report.md" and surprises == []
    assert set(listing(tmp_path)) == {"demo", "demo/notes.txt", "demo/report.md", "demo/a.csv",
                                      "demo/f.png", "demo/one-scene",
                                      "demo/one-scene/summary.json"}
    text = report.read_text()
    assert "(one-scene/response.png)" in text and "(f.png)" in text
