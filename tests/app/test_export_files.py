"""``flexctl export`` writes its folder whole or not at all: a folder in the way is refused by
its path, a compiler that fails is named with its status and messages in one error line, a
failure part way leaves the folder as it was, and a damaged export is rebuilt identical."""

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

import flexctl
from controllers.codegen import C_FILES, CompileError, export_c
from flexctl.app.cli import EXIT_BAD_INPUT, EXIT_OK, main
from flexctl.app.export import SUMMARY_FILE, export_scene
from flexctl.model.errors import InputError
from flexctl.sim import compile_cache
from tests.sim.test_atomic_files import listing

#: A law designed in well under a second (the default, trajopt+lqr, takes seconds).
PD = ["--set", "controller.kind=pd"]
EXPORT_FILES = (*C_FILES, SUMMARY_FILE)
needs_compiler = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                    reason="no C compiler")


@pytest.fixture(scope="module")
def pd_scene():
    return flexctl.load_scene("slew-90", {"controller.kind": "pd"})


@pytest.fixture
def cache_warns_again(monkeypatch):
    """The compile cache with no memory of its warnings: a CC that fails warns again."""
    monkeypatch.setattr(compile_cache, "_WARNED", set())
    monkeypatch.setattr(compile_cache, "_COMPILER", {})


def _previous_export(out: Path) -> None:
    out.mkdir(parents=True)
    for name in EXPORT_FILES:
        (out / name).write_text("previous export")
    (out / "notes.txt").write_text("mine")


def _assert_one_error_line(code, captured, *named) -> str:
    assert code == EXIT_BAD_INPUT
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("flexctl: error: ")
    for text in named:
        assert text in lines[0], lines[0]
    assert captured.out == ""
    return lines[0]


@pytest.mark.parametrize("blocked", EXPORT_FILES)
def test_a_folder_where_a_file_goes_is_refused_by_its_path(blocked, tmp_path, capfd):
    out = tmp_path / "out"
    _previous_export(out)
    (out / blocked).unlink()
    (out / blocked).mkdir()
    (out / blocked / "inside.txt").write_text("theirs")
    before = listing(tmp_path)
    code = main(["export", "slew-90", *PD, "--out", str(out)])
    _assert_one_error_line(code, capfd.readouterr(), f"'{out / blocked}' is a folder")
    assert listing(tmp_path) == before


@pytest.mark.skipif(shutil.which("false") is None, reason="no 'false' program")
@pytest.mark.parametrize("existing", [False, True], ids=["new-folder", "previous-export"])
def test_a_compiler_that_fails_silently_is_named_alone_and_nothing_is_written(
        existing, tmp_path, monkeypatch, capfd, cache_warns_again):
    """CC=false: the compiler's name and status, no empty 'failed:', no warning line before
    the error (the design's warnings are held and dropped), the folder as it was."""
    monkeypatch.setenv("CC", "false")
    out = tmp_path / "parent" / "out"
    if existing:
        _previous_export(out)
    before = listing(tmp_path)
    code = main(["export", "slew-90", *PD, "--out", str(out)])
    line = _assert_one_error_line(
        code, capfd.readouterr(), "the C compiler 'false' exited with status 1 and printed "
        "nothing", f"nothing written to {out}")
    assert not line.rstrip().endswith(":")
    assert listing(tmp_path) == before


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("false") is None, reason="no 'false' program")
def test_the_default_slew_export_with_a_failing_compiler_is_one_line(tmp_path, monkeypatch,
                                                                    capfd, cache_warns_again):
    """The issue's case: slew-90's own controller (whose design compiles through the cache,
    which warns when CC does not run)."""
    monkeypatch.setenv("CC", "false")
    out = tmp_path / "out"
    code = main(["export", "slew-90", "--out", str(out)])
    _assert_one_error_line(code, capfd.readouterr(), "'false' exited with status 1")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("via", ["export_scene", "cli"])
def test_a_failure_after_the_first_file_leaves_the_folder_as_it_was(via, pd_scene, tmp_path,
                                                                    monkeypatch, capfd):
    out = tmp_path / "out"
    _previous_export(out)
    before = listing(tmp_path)
    real, written = Path.write_text, []

    def full_after_the_first(self, *args, **kwargs):
        if written:
            raise OSError(28, "No space left on device", str(self))
        written.append(self.name)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full_after_the_first)
    if via == "cli":
        code = main(["export", "slew-90", *PD, "--no-compile", "--out", str(out)])
        _assert_one_error_line(code, capfd.readouterr(), f"cannot write the export to {out}",
                               "No space left on device")
    else:
        with pytest.raises(OSError, match="No space"):
            export_scene(pd_scene, out, compile=False)
    monkeypatch.undo()
    assert written == [C_FILES[0]]
    assert listing(tmp_path) == before


def test_an_export_keeps_other_files_and_leaves_no_temporary_ones(tmp_path, capfd):
    out = tmp_path / "out"
    _previous_export(out)
    assert main(["export", "slew-90", *PD, "--out", str(out)]) == EXIT_OK
    found = listing(tmp_path)
    assert set(found) == {"out", "out/notes.txt", *(f"out/{name}" for name in EXPORT_FILES)}
    assert found["out/notes.txt"] == b"mine"
    assert all(found[f"out/{name}"] != b"previous export" for name in EXPORT_FILES)


@needs_compiler
def test_compiling_writes_nothing_into_the_export(pd_scene, tmp_path):
    from controllers import from_spec

    plant = pd_scene.build_model()
    exported = export_c(from_spec(pd_scene, plant).controller, plant, tmp_path / "c")
    before = listing(tmp_path)
    law = exported.compile()
    assert listing(tmp_path) == before
    assert law.step(0.0, [0.0] * plant.n_states)[1] == 0


@needs_compiler
@pytest.mark.parametrize("errors", [1, 120], ids=["short", "long"])
def test_the_compilers_messages_are_shown(errors, pd_scene, tmp_path):
    """A short message whole; a long one its first lines and its last 40, never an empty
    tail."""
    from controllers import from_spec

    plant = pd_scene.build_model()
    exported = export_c(from_spec(pd_scene, plant).controller, plant, tmp_path)
    unused = "".join(f"\n  int unused_{k};" for k in range(errors))
    exported.source.write_text(exported.source.read_text().replace(
        "size_t flexctl_ctrl_size(void) {", "size_t flexctl_ctrl_size(void) {" + unused))
    with pytest.raises(CompileError) as raised:
        exported.compile()
    message = str(raised.value)
    first, *rest = message.splitlines()
    assert first.startswith("the C compiler ") and "exited with status" in first
    assert first.endswith("-Werror:") and rest
    assert "flexctl_ctrl.c:" in message and "unused_0" in message
    assert f"unused_{errors - 1}" in message             # the last error is there
    assert str(tmp_path) not in message                    # the file named as the user knows it
    assert ("lines left out" in message) == (errors > 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(C_FILES)


#: Ways an export folder is damaged, between two exports into it.
DAMAGE = ("delete", "truncate", "flip", "append", "empty", "read-only", "link", "leftover",
          "folder", "folder-is-a-file")


def _damage(out: Path, name: str, how: str, where: float, byte: int) -> None:
    """Damage ``out / name`` (or ``out`` itself) as ``how`` says."""
    path = out / name
    data = path.read_bytes()
    at = int(where * (len(data) - 1))
    if how == "delete":
        path.unlink()
    elif how == "truncate":
        path.write_bytes(data[:at])
    elif how == "flip":
        path.write_bytes(data[:at] + bytes([data[at] ^ byte]) + data[at + 1:])
    elif how == "append":
        path.write_bytes(data + bytes([byte]) * 3)
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "read-only":
        path.write_bytes(data[:at])
        path.chmod(0o444)
    elif how == "link":                    # someone else's file, which must stay untouched
        path.unlink()
        path.symlink_to(out.parent / "theirs.txt")
    elif how == "leftover":                # what a killed writer might have left
        (out / f".partial-dead-{name}").write_bytes(data[:at])
        path.write_bytes(data[:at])
    elif how == "folder":
        path.unlink()
        path.mkdir()
        (path / "inside.txt").write_bytes(data)
    else:
        shutil.rmtree(out)
        out.write_bytes(data)


def _damage_cases(seed: int = 20261128, per_kind: int = 2) -> list:
    """``per_kind`` damages of every kind of :data:`DAMAGE`, each to a file, at a place and
    with a byte drawn from a fixed seed: 20 cases."""
    rng = np.random.default_rng(seed)
    return [pytest.param(str(rng.choice(EXPORT_FILES)), how, float(rng.uniform()),
                         int(rng.integers(1, 256)), id=f"{how}-{k}")
            for how in DAMAGE for k in range(per_kind)]


@pytest.mark.parametrize(("name", "how", "where", "byte"), _damage_cases())
def test_a_damaged_export_is_rebuilt_identical_or_refused_by_its_path(pd_scene, name, how,
                                                                     where, byte):
    with tempfile.TemporaryDirectory() as root:
        root = Path(root)
        out = root / "out"
        (root / "theirs.txt").write_text("theirs")
        export_scene(pd_scene, out, compile=False)
        clean = listing(root)
        _damage(out, name, how, where, byte)
        damaged = listing(root)
        try:
            export_scene(pd_scene, out, compile=False)
        except InputError as exc:
            assert how in ("folder", "folder-is-a-file"), exc
            assert f"'{out / name if how == 'folder' else out}' is a " in str(exc)
            assert listing(root) == damaged
            return
        rebuilt = listing(root)
        extra = {k: v for k, v in rebuilt.items() if k not in clean}
        assert {k: rebuilt[k] for k in clean} == clean
        assert extra == ({f"out/.partial-dead-{name}": damaged[f"out/.partial-dead-{name}"]}
                         if how == "leftover" else {})
        assert not os.path.islink(out / name)
