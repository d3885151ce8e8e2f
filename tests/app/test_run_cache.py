"""Demo jobs remembered by their inputs: a job found under its key is replayed (its files and
its value), any other input runs it, and a damaged or unkeepable entry only costs a run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from flexctl.app import run_cache
from flexctl.app.cli import main
from flexctl.app.run_cache import job_key, remembered, run_cache_info
from flexctl.app.section import Section


@pytest.fixture(autouse=True)
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXCTL_RUN_CACHE_DIR", str(tmp_path / "runs"))
    monkeypatch.delenv("FLEXCTL_RUN_CACHE", raising=False)


class Job:
    """A job that counts its runs and writes a figure, a data file and a subfolder."""

    def __init__(self):
        self.runs = 0

    def __call__(self, folder: Path):
        self.runs += 1
        (folder / "figure.png").write_bytes(b"\x89PNG fake")
        (folder / "sub").mkdir()
        (folder / "sub" / "data.csv").write_text("t,x\n0,1\n")
        return Section(title="a section", paragraphs=(f"written in {folder}",),
                       table=(("a", "b"), (("1", "2"),)),
                       images=(("caption", folder / "figure.png"),),
                       files=(folder / "sub" / "data.csv",))


def test_a_job_is_replayed_with_its_files_and_its_value(tmp_path):
    job = Job()
    first = remembered("section", ["one"], tmp_path / "a", job)
    second = remembered("section", ["one"], tmp_path / "b", job)
    assert job.runs == 1
    for out, value in ((tmp_path / "a", first), (tmp_path / "b", second)):
        assert value.images == (("caption", out / "figure.png"),)
        assert value.files == (out / "sub" / "data.csv",)
        assert value.paragraphs == (f"written in {out}",)
        assert (out / "sub" / "data.csv").read_text() == "t,x\n0,1\n"
        assert not list(out.glob(".job-*"))
    assert second.table == first.table and isinstance(second.table[1][0], tuple)
    assert run_cache_info().entries == 1


def test_another_input_or_turning_it_off_runs_the_job(tmp_path, monkeypatch):
    job = Job()
    remembered("section", ["one"], tmp_path / "a", job)
    remembered("section", ["two"], tmp_path / "b", job)
    remembered("scene", ["one"], tmp_path / "c", job)
    assert job.runs == 3
    monkeypatch.setenv("FLEXCTL_RUN_CACHE", "0")
    remembered("section", ["one"], tmp_path / "d", job)
    assert job.runs == 4 and (tmp_path / "d" / "figure.png").exists()


def test_the_key_follows_the_code_and_the_compile_switch(monkeypatch):
    key = job_key("scene", ["slew-90", {}])
    monkeypatch.setenv("FLEXCTL_COMPILE", "0")
    assert job_key("scene", ["slew-90", {}]) != key
    monkeypatch.delenv("FLEXCTL_COMPILE")
    monkeypatch.setattr(run_cache, "code_version", lambda: "another version")
    assert job_key("scene", ["slew-90", {}]) != key


@pytest.mark.parametrize("damage", ["truncated", "not json", "unknown kind", "missing"])
def test_a_damaged_entry_runs_the_job_again(tmp_path, damage):
    job = Job()
    remembered("section", ["one"], tmp_path / "a", job)
    entry = run_cache.runs_dir() / job_key("section", ["one"])
    value = entry / "value.json"
    if damage == "truncated":
        value.write_text(value.read_text()[:40])
    elif damage == "not json":
        value.write_bytes(b"\x00\xff")
    elif damage == "unknown kind":
        value.write_text(json.dumps({"pickle": "cos\nsystem\n"}))
    else:
        value.unlink()
    again = remembered("section", ["one"], tmp_path / "b", job)
    assert job.runs == 2 and again.images == (("caption", tmp_path / "b" / "figure.png"),)


def test_a_value_that_cannot_be_kept_is_returned_and_not_kept(tmp_path):
    calls = []

    def job(folder):
        calls.append(folder)
        return {"callable": print}
    assert remembered("scene", ["x"], tmp_path / "a", job) == {"callable": print}
    remembered("scene", ["x"], tmp_path / "b", job)
    assert len(calls) == 2 and run_cache_info().entries == 0


def test_flexctl_cache_lists_and_clears_the_remembered_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("FLEXCTL_CACHE_DIR", str(tmp_path / "compiled"))
    remembered("section", ["one"], tmp_path / "a", Job())
    assert main(["cache", "info"]) == 0
    assert "remembered runs: 1 " in capsys.readouterr().out
    assert main(["cache", "clear"]) == 0
    assert "removed 1 remembered runs" in capsys.readouterr().out
    assert run_cache_info().entries == 0


def test_a_cache_that_cannot_be_written_only_costs_the_replay(tmp_path, monkeypatch):
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the cache's folder would be")
    monkeypatch.setenv("FLEXCTL_RUN_CACHE_DIR", str(blocked / "runs"))
    job = Job()
    first = remembered("section", ["one"], tmp_path / "a", job)
    remembered("section", ["one"], tmp_path / "b", job)
    assert job.runs == 2 and first.images == (("caption", tmp_path / "a" / "figure.png"),)
    assert (tmp_path / "b" / "sub" / "data.csv").exists()
