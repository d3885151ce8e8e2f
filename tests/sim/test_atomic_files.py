"""Files written whole or not at all (flexctl.sim.atomic_files): a folder's files appear
together or not at all, a failure at any point leaves the destination as it was (hidden
temporary files included), and what stands in the way is refused by its path."""

import os
import stat
from pathlib import Path

import pytest

from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim import atomic_files
from flexctl.sim.atomic_files import (TEMPORARY_PREFIX, atomic_file, staged_folder,
                                      write_atomic)


def listing(root: Path) -> dict:
    """Every entry under ``root``, hidden ones too: relative path -> bytes, or the target of
    a link, or ``"folder"``."""
    found = {}
    for path in sorted(root.rglob("*")):
        key = path.relative_to(root).as_posix()
        if path.is_symlink():
            found[key] = f"link to {os.readlink(path)}"
        elif path.is_dir():
            found[key] = "folder"
        else:
            found[key] = path.read_bytes()
    return found


def _previous(out: Path) -> None:
    out.mkdir(parents=True)
    (out / "a.txt").write_text("previous a")
    (out / "notes.txt").write_text("mine")


def _write_two(stage: Path) -> None:
    (stage / "a.txt").write_text("new a")
    (stage / "b.txt").write_text("new b")


def test_files_appear_together_and_others_are_kept(tmp_path):
    out = tmp_path / "out"
    _previous(out)
    with staged_folder(out, names=("a.txt", "b.txt")) as stage:
        _write_two(stage)
        assert listing(out)["a.txt"] == b"previous a"       # nothing moved yet
        assert stage.name.startswith(TEMPORARY_PREFIX)
    assert listing(tmp_path) == {"out": "folder", "out/a.txt": b"new a", "out/b.txt": b"new b",
                                 "out/notes.txt": b"mine"}


def test_a_new_folder_and_its_parents_appear_in_one_step(tmp_path):
    out = tmp_path / "a" / "b" / "out"
    with staged_folder(out) as stage:
        _write_two(stage)
        (stage / "sub").mkdir()
        (stage / "sub" / "c.txt").write_text("c")
        assert not out.exists()
    assert listing(tmp_path / "a" / "b") == {"out": "folder", "out/a.txt": b"new a",
                                             "out/b.txt": b"new b", "out/sub": "folder",
                                             "out/sub/c.txt": b"c"}


def test_folders_and_files_get_the_modes_of_a_plain_write(tmp_path):
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "a.txt").write_text("a")
    with staged_folder(tmp_path / "out") as stage:
        (stage / "a.txt").write_text("a")
    write_atomic(tmp_path / "single.txt", "a")
    mode = stat.S_IMODE
    assert mode((tmp_path / "out").stat().st_mode) == mode(plain.stat().st_mode)
    for written in (tmp_path / "out" / "a.txt", tmp_path / "single.txt"):
        assert mode(written.stat().st_mode) == mode((plain / "a.txt").stat().st_mode)


@pytest.mark.parametrize("failure", [RuntimeError("the writer failed"), KeyboardInterrupt()],
                         ids=["exception", "ctrl-c"])
@pytest.mark.parametrize("existing", [False, True], ids=["new-folder", "existing-folder"])
def test_a_failure_in_the_block_leaves_everything_as_it_was(failure, existing, tmp_path):
    out = tmp_path / "parent" / "out"
    if existing:
        _previous(out)
    before = listing(tmp_path)
    with pytest.raises(type(failure)):
        with staged_folder(out) as stage:
            _write_two(stage)
            raise failure
    assert listing(tmp_path) == before


def test_a_move_that_fails_part_way_puts_everything_back(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _previous(out)
    (out / "sub").mkdir()
    before = listing(tmp_path)
    real, calls = os.replace, []

    def third_move_fails(source, target):
        calls.append(Path(target).name)
        if len(calls) == 3:
            raise OSError(28, "No space left on device", str(target))
        return real(source, target)

    monkeypatch.setattr(atomic_files.os, "replace", third_move_fails)
    with pytest.raises(OSError, match="No space"):
        with staged_folder(out) as stage:
            _write_two(stage)
            (stage / "sub" / "deeper").mkdir(parents=True)
            (stage / "sub" / "deeper" / "c.txt").write_text("c")
    monkeypatch.undo()
    assert calls[:3] == ["a.txt", "b.txt", "c.txt"]
    assert listing(tmp_path) == before


@pytest.mark.parametrize("declared", [True, False], ids=["named-up-front", "found-at-the-end"])
def test_a_folder_where_a_file_goes_is_refused_by_its_path(declared, tmp_path):
    out = tmp_path / "out"
    _previous(out)
    (out / "b.txt").mkdir()
    (out / "b.txt" / "inside").write_text("theirs")
    before, entered = listing(tmp_path), []
    with pytest.raises(InputValueError, match="'.*b.txt' is a folder"):
        with staged_folder(out, names=("a.txt", "b.txt") if declared else ()) as stage:
            entered.append(True)
            _write_two(stage)
    assert entered == ([] if declared else [True])      # named: refused before any writing
    assert listing(tmp_path) == before


def test_a_file_where_a_folder_goes_is_refused_by_its_path(tmp_path):
    out = tmp_path / "out"
    _previous(out)
    (out / "sub").write_text("a file")
    before = listing(tmp_path)
    with pytest.raises(InputValueError, match="'.*sub' is a file"):
        with staged_folder(out, names=("sub/c.txt",)):
            pass
    with pytest.raises(InputValueError, match="folder '.*a.txt' is a file"):
        with staged_folder(out / "a.txt"):
            pass
    assert listing(tmp_path) == before


@pytest.mark.parametrize(("call", "error", "match"), [
    (lambda: staged_folder(3).__enter__(), InputTypeError, "destination must be a path"),
    (lambda: staged_folder("x", names="a.txt").__enter__(), InputTypeError, "names"),
    (lambda: staged_folder("x", names=("../a",)).__enter__(), InputValueError, "'../a'"),
    (lambda: write_atomic("x", 3.0), InputTypeError, "data must be str or bytes"),
    (lambda: write_atomic(None, "a"), InputTypeError, "path must be a path"),
], ids=["destination", "names-a-string", "names-outside", "data", "path"])
def test_bad_arguments_are_refused_by_name(call, error, match, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(error, match=match):
        call()
    assert list(tmp_path.iterdir()) == []


def test_one_file_is_replaced_whole_or_kept(tmp_path):
    target = tmp_path / "table.csv"
    write_atomic(target, "a,b\n1,2\n")
    with pytest.raises(RuntimeError):
        with atomic_file(target) as partial:
            assert partial.suffix == ".csv" and partial.name.startswith(TEMPORARY_PREFIX)
            partial.write_text("a,b\n3")
            raise RuntimeError("the writer failed")
    assert listing(tmp_path) == {"table.csv": b"a,b\n1,2\n"}
    write_atomic(target, b"\x00\x01")
    assert listing(tmp_path) == {"table.csv": b"\x00\x01"}
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(InputValueError, match="folder.csv' is a folder"):
        write_atomic(tmp_path / "folder.csv", "a")
