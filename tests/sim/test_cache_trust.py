"""A damaged compile cache never crashes a run or changes an answer.

Every file the cache reads back is checked against the digest written with it: a library
truncated, zeroed or altered is never mapped (mapping one crashed with SIGBUS or SIGSEGV),
altered constants are never used (they gave a wrong answer that ended "ok"), and the run
rebuilds what it needs, says why on one warning line, and gives the clean run's numbers bit
for bit. ``flexctl cache clear`` reports what it removed and what it could not.
"""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexctl.sim import compile_cache
from flexctl.sim.cache_files import (SEAL, DamagedEntry, clear_folder, read_sealed,
                                     verify_library, write_digest, write_sealed)

ROOT = Path(__file__).resolve().parents[2]

needs_compiler = pytest.mark.skipif(compile_cache.compiler() is None, reason="no C compiler")

#: A run that reads every kind of cache entry: the built-in scene hub-beam-mass as
#: ``flexctl run`` runs it (compiled integrators, the validity estimate's lifted exact model
#: with its index, its constants and structure files). It prints the SHA-256 of its time and state arrays, its peak tip deflection and the counters.
RUN = """
import hashlib, json, warnings
import numpy as np
import flexctl
from flexctl.sim.compile_cache import STATS

with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    result = flexctl.run_scene(flexctl.load_scene("hub-beam-mass"))
digest = hashlib.sha256(np.ascontiguousarray(result.t).tobytes()
                        + np.ascontiguousarray(result.states).tobytes()).hexdigest()
print(json.dumps({"status": str(result.status), "digest": digest,
                  "peak_tip": float(np.max(np.abs(result.tip_deflection))),
                  "stats": STATS, "warnings": [str(w.message) for w in caught]}))
"""

#: A small worker: a lifted, compiled function of three inputs.
SMALL = """
import json, warnings
import casadi as ca
from flexctl.sim.compile_cache import compiled, STATS
from flexctl.sim.lifted_constants import lift_constants

x = ca.SX.sym("x", 3)
f = ca.Function("trust_small", [x], [ca.sin(x) * x[0] * 1.25 + 0.5])
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    lifted, constants = lift_constants(f)
    g = compiled(lifted)
    value = g([1.0, 2.0, 3.0], constants).full().ravel()
print(json.dumps({"value": value.tobytes().hex(), "constants": constants.tobytes().hex(),
                  "external": g.is_a("External"), "stats": STATS,
                  "warnings": [str(w.message) for w in caught]}))
"""


def run(script: str, cache: Path) -> dict:
    env = {**os.environ, "FLEXCTL_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT),
           "MPLBACKEND": "Agg"}
    env.pop("FLEXCTL_COMPILE", None)
    process = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                             text=True, timeout=600)
    assert process.returncode == 0, f"exit {process.returncode}: {process.stderr[-2000:]}"
    return json.loads(process.stdout.strip().splitlines()[-1])


def entries(cache: Path, pattern: str) -> list:
    return sorted((cache / "compiled").glob(pattern))


# ----------------------------------------------------------------------------- the files


def test_sealed_file_round_trip_and_every_kind_of_damage(tmp_path):
    path = tmp_path / "entry"
    content = bytes(range(256)) * 4
    write_sealed(path, content)
    assert read_sealed(path) == content
    whole = path.read_bytes()
    damaged = {
        "truncated": whole[:len(whole) // 2],
        "empty": b"",
        "zeroed middle": whole[:100] + bytes(200) + whole[300:],
        "one bit": whole[:-1] + bytes([whole[-1] ^ 1]),
        "header zeroed": bytes(len(SEAL)) + whole[len(SEAL):],
        "no header": content,
    }
    for what, data in damaged.items():
        path.write_bytes(data)
        with pytest.raises(DamagedEntry):
            read_sealed(path)
    with pytest.raises(FileNotFoundError):
        read_sealed(tmp_path / "absent")


def test_a_library_is_trusted_only_with_its_digest(tmp_path):
    library = tmp_path / "lib-0.so"
    built = tmp_path / ".build.so"
    built.write_bytes(os.urandom(4096))
    write_digest(built, library)
    assert verify_library(built) is not None          # the digest is recorded for `library`
    os.replace(built, library)
    assert verify_library(library) is None
    good = library.read_bytes()
    for damaged in (good[:1000], good[:2000] + bytes(1000) + good[3000:],
                    good[:10] + bytes([good[10] ^ 0x40]) + good[11:]):
        library.write_bytes(damaged)
        assert "digest" in verify_library(library)
    library.write_bytes(good)
    Path(str(library) + ".sha256").unlink()
    assert verify_library(library) == "no digest is recorded for it"


def test_clear_reports_what_it_could_not_remove(tmp_path, monkeypatch):
    folder = tmp_path / "compiled"
    folder.mkdir()
    for name in ("a-1.so", "a-1.so.sha256", "b-2.so", "b-2.so.sha256", "x.index"):
        (folder / name).write_bytes(b"data")
    real_unlink = Path.unlink

    def read_only(self, *args, **kwargs):
        if self.name.startswith("b-2.so"):
            raise PermissionError(13, "Read-only file system")
        return real_unlink(self, *args, **kwargs)

    monkeypatch.setattr(Path, "unlink", read_only)
    report = clear_folder(folder, ".so")
    assert (report.libraries, report.files) == (1, 3)
    assert sorted(p.name for p, _ in report.failed) == ["b-2.so", "b-2.so.sha256"]
    assert all("Read-only" in reason for _, reason in report.failed)
    assert "could not remove" in str(report) and "removed 1 compiled functions" in str(report)
    assert sorted(p.name for p in folder.iterdir()) == ["b-2.so", "b-2.so.sha256"]


@needs_compiler
def test_cli_clear_on_a_read_only_cache_says_what_stayed(tmp_path, monkeypatch, capsys):
    from flexctl.app.cli import main

    cache = tmp_path / "cache"
    monkeypatch.setenv("FLEXCTL_CACHE_DIR", str(cache))
    run(SMALL, cache)
    kept = sorted(p.name for p in (cache / "compiled").iterdir())
    assert kept
    monkeypatch.setattr(Path, "unlink", _refuse)
    assert main(["cache", "clear"]) == 2
    captured = capsys.readouterr()
    assert "removed 0 compiled functions (0 files)" in captured.out
    assert captured.out.count("could not remove") == len(kept)
    (line,) = captured.err.strip().splitlines()
    assert line.startswith("flexctl: error: could not remove") and str(cache) in line
    assert sorted(p.name for p in (cache / "compiled").iterdir()) == kept


def _refuse(self, *args, **kwargs):
    raise PermissionError(13, "Permission denied")


# ------------------------------------------------------------------ a run on a damaged cache


def _truncate(path: Path) -> None:
    with open(path, "r+b") as handle:           # in place, as a crashed writer would leave it
        handle.truncate(path.stat().st_size // 3)


def _zero_middle(path: Path) -> None:
    size = path.stat().st_size
    with open(path, "r+b") as handle:
        handle.seek(size // 3)
        handle.write(bytes(size // 3))


def _alter_constants(path: Path) -> None:
    data = bytearray(path.read_bytes())
    values = np.frombuffer(bytes(data[-64:]), dtype="<f8") * 0.25   # a quarter of the numbers
    data[-64:] = values.tobytes()
    path.write_bytes(bytes(data))


def _nan_constants(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[-64:] = np.full(8, np.nan).tobytes()
    path.write_bytes(bytes(data))


def _flip_last(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[-2] ^= 0x01
    path.write_bytes(bytes(data))


#: What is damaged, and how.
DAMAGE = {
    "library truncated": ("*.so", _truncate),
    "library middle zeroed": ("*.so", _zero_middle),
    "library digest removed": ("*.so.sha256", Path.unlink),
    "constants altered": ("lifted-*.constants", _alter_constants),
    "constants set to NaN": ("lifted-*.constants", _nan_constants),
    "lifted function altered": ("lifted-*.casadi", _flip_last),
    "index altered": ("*.key", _flip_last),
}


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    cache = tmp_path_factory.mktemp("clean") / "cache"
    first = run(RUN, cache)
    assert first["status"] == "ok" and first["stats"]["compiles"] >= 1
    return cache, first


@pytest.mark.slow
@needs_compiler
@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_a_damaged_entry_is_rebuilt_and_the_answer_is_the_same(damage, clean_run, tmp_path):
    import shutil

    clean_cache, clean = clean_run
    cache = tmp_path / "cache"
    shutil.copytree(clean_cache, cache)
    pattern, spoil = DAMAGE[damage]
    targets = entries(cache, pattern)
    assert targets, f"the run left no {pattern} entry"
    for path in targets:
        spoil(path)
    again = run(RUN, cache)
    assert again["status"] == "ok"
    assert again["digest"] == clean["digest"], "a damaged cache changed the answer"
    assert again["peak_tip"] == clean["peak_tip"]
    assert any("is not used" in w for w in again["warnings"]), again["warnings"]
    healed = run(RUN, cache)            # what was rebuilt is trusted again: no warning
    assert healed["digest"] == clean["digest"]
    assert not any("is not used" in w for w in healed["warnings"]), healed["warnings"]


# ------------------------------------------------------------- random damage, every format

#: Random damages tried (a fixed seed: the same cases on every run).
RANDOM_CASES = 12


def _random_damage(rng, files: list) -> str:
    path = files[rng.integers(len(files))]
    data = bytearray(path.read_bytes())
    kind = ("truncate", "zero", "flip", "garbage")[rng.integers(4)]
    if kind == "truncate":
        data = data[:rng.integers(len(data))]
    elif kind == "zero" and data:
        start = int(rng.integers(len(data)))
        stop = min(len(data), start + int(rng.integers(1, 512)))
        data[start:stop] = bytes(stop - start)
    elif kind == "flip" and data:
        where = int(rng.integers(len(data)))
        data[where] ^= 1 << int(rng.integers(8))
    else:
        data = bytearray(rng.integers(0, 256, size=int(rng.integers(1, 2048)), dtype=np.uint8))
    path.write_bytes(bytes(data))
    return f"{kind} {path.name}"


@pytest.mark.slow
@needs_compiler
def test_random_damage_never_crashes_or_changes_the_answer(tmp_path):
    """Each of :data:`RANDOM_CASES` cases damages one file of the cache at random (truncated,
    zeroed, a bit flipped, replaced by garbage); the next process gives the clean value bit
    for bit."""
    import shutil

    clean_cache = tmp_path / "clean"
    clean = run(SMALL, clean_cache)
    assert clean["external"]
    rng = np.random.default_rng(47)
    for case in range(RANDOM_CASES):
        cache = tmp_path / f"case{case}"
        shutil.copytree(clean_cache, cache)
        files = sorted(p for p in (cache / "compiled").iterdir()
                       if p.is_file() and not p.name.endswith(".lock"))
        what = _random_damage(rng, files)
        again = run(SMALL, cache)
        assert again["value"] == clean["value"], what
        assert again["constants"] == clean["constants"], what
        assert again["external"], what


def test_sealed_digest_is_the_sha256_of_the_content(tmp_path):
    path = tmp_path / "entry"
    write_sealed(path, b"abc")
    head, content = path.read_bytes().split(b"\n", 1)
    assert head == SEAL + hashlib.sha256(b"abc").hexdigest().encode("ascii")
    assert content == b"abc"
