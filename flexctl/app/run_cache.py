"""The demo's runs remembered by their inputs, so that a second ``flexctl demo`` replays them.

A demo job (a built-in scene's run, a section's sweep and figures) is a function of its
inputs and of the code that computes it. :func:`remembered` keys a job by all of them
(:func:`job_key`): its name and inputs (the scene, its overrides), the SHA-256 of every source
file of the ``flexctl`` and ``controllers`` packages (the built-in scenes included), the
versions of Python and of the numerical packages, and ``FLEXCTL_COMPILE``. A job found under
its key is not run again: the files it wrote and the value it returned are copied back. Any
change of the code, a package or an input is another key.

- **Location.** ``$FLEXCTL_RUN_CACHE_DIR`` if set, else a ``runs/`` folder in the compiled
  functions' cache directory (:func:`flexctl.sim.compile_cache.cache_dir`): one folder per
  job, its files and a ``value.json``. ``flexctl cache info`` lists the jobs, ``flexctl cache clear`` removes them
  with the compiled functions. ``FLEXCTL_RUN_CACHE=0`` turns remembering off.
- **What is kept.** The files the job wrote into its own folder, and its value as JSON:
  numbers, strings, lists, tuples, dicts, paths (relative to the job's folder) and the demo's
  :class:`~flexctl.app.section.Section`. A value of any other kind is not remembered (the
  job simply runs every time). Nothing is unpickled: a file in the cache can at worst be a
  wrong number, never code.
- **Atomicity.** A job's entry is written into a temporary folder and renamed into place once
  whole; a reader sees an entry whole or not at all, and one that does not parse is run again.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import shutil
import sys
import tempfile
from functools import lru_cache
from pathlib import Path

from ..sim.cache_files import ClearReport, clear_folder
from ..sim.compile_cache import cache_dir
from .section import Section

__all__ = ["remembered", "job_key", "code_version", "runs_dir", "run_cache_info",
           "clear_run_cache", "RunCacheInfo", "SUBDIR", "LAYOUT"]

#: The folder of the remembered jobs in the cache directory.
SUBDIR = "runs"
#: The layout of an entry; part of every key, so that entries of another layout are never read.
LAYOUT = 1
#: Source files hashed into :func:`code_version`.
SOURCE_SUFFIXES = (".py", ".toml", ".c", ".h", ".json", ".csv")
_VALUE = "value.json"
_FILES = "files"
_PACKAGES = ("numpy", "scipy", "casadi", "control", "matplotlib")


@lru_cache(maxsize=1)
def code_version() -> str:
    """SHA-256 of every source file of the ``flexctl`` and ``controllers`` packages (path and
    bytes), of the Python version and of the numerical packages' versions."""
    import controllers

    import flexctl

    digest = hashlib.sha256()
    for package in (flexctl, controllers):
        root = Path(package.__file__).resolve().parent
        for path in sorted(p for p in root.rglob("*") if p.suffix in SOURCE_SUFFIXES):
            digest.update(path.relative_to(root.parent).as_posix().encode())
            digest.update(hashlib.sha256(path.read_bytes()).digest())
    digest.update(sys.version.encode())
    for name in _PACKAGES:
        module = sys.modules.get(name) or __import__(name)
        digest.update(f"{name}={getattr(module, '__version__', '?')}".encode())
    return digest.hexdigest()


def job_key(name: str, inputs) -> str:
    """The key of a job: SHA-256 of :data:`LAYOUT`, :func:`code_version`, ``FLEXCTL_COMPILE``,
    the job's ``name`` and its ``inputs`` (as JSON, sorted keys).

    Parameters
    ----------
    name : str
        What the job is (e.g. ``"scene"``, ``"section"``).
    inputs : object
        Its inputs: JSON-able (numbers, strings, lists, dicts); anything else enters by its
        ``repr``.
    """
    text = json.dumps([LAYOUT, code_version(), os.environ.get("FLEXCTL_COMPILE", ""), name,
                       inputs], sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


def remembered(name: str, inputs, out: Path, make, *, create: bool = True):
    """``make(out)``'s value, made once per key (:func:`job_key`) and replayed after.

    Parameters
    ----------
    name : str
        What the job is.
    inputs : object
        Its inputs (:func:`job_key`).
    out : Path
        The folder the job writes into (created if missing); its files are copied there on
        a replay.
    make : callable
        ``make(folder) -> value``: runs the job, writing its files into ``folder``.
    create : bool, optional
        Hand ``make`` an existing folder (True, default) or a path it creates itself.

    Returns
    -------
    object
        The value, its paths under ``out``.
    """
    out = Path(out)
    if os.environ.get("FLEXCTL_RUN_CACHE", "1") == "0":
        if create:
            out.mkdir(parents=True, exist_ok=True)
        return make(out)
    entry = runs_dir() / job_key(name, inputs)
    out.parent.mkdir(parents=True, exist_ok=True)
    # the job's own folder: inside ``out`` when it exists (a demo's stage), else beside it
    work = Path(tempfile.mkdtemp(prefix=".job-", dir=out if out.is_dir() else out.parent))
    private = work / out.name
    try:
        if create:
            private.mkdir()
        found = _replayed(entry, out)
        if found is not _MISSING:
            return found
        value = make(private)
        if private.is_dir():
            with contextlib.suppress(OSError):   # a cache it cannot write costs the replay only
                _keep(entry, private, value)
            out.mkdir(exist_ok=True)
            for path in private.iterdir():
                _move_into(path, out / path.name)
        return _reanchored(value, private, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def runs_dir() -> Path:
    """The folder of the remembered jobs: ``$FLEXCTL_RUN_CACHE_DIR``, else
    :data:`SUBDIR` in :func:`~flexctl.sim.compile_cache.cache_dir` (not created here)."""
    override = os.environ.get("FLEXCTL_RUN_CACHE_DIR")
    return Path(override).expanduser() if override else cache_dir() / SUBDIR


_MISSING = object()
_ANCHOR = "@flexctl-job@"


def _move_into(source: Path, target: Path) -> None:
    """``source`` moved to ``target``, replacing what is there."""
    if target.is_dir() and not target.is_symlink():
        shutil.rmtree(target)
    elif target.exists() or target.is_symlink():
        target.unlink()
    shutil.move(str(source), str(target))


def _replayed(entry: Path, out: Path):
    """The value kept in ``entry`` with its files copied into ``out``, or ``_MISSING``."""
    try:
        value = _decoded(json.loads((entry / _VALUE).read_text()))
    except (OSError, ValueError, KeyError, TypeError):
        return _MISSING
    files = entry / _FILES
    if files.is_dir():
        shutil.copytree(files, out, dirs_exist_ok=True)
    else:
        out.mkdir(parents=True, exist_ok=True)
    return _reanchored(value, Path(_ANCHOR), out)


def _keep(entry: Path, produced: Path, value) -> None:
    """Write ``entry`` (the files in ``produced`` and ``value``) whole, or not at all."""
    try:
        text = json.dumps(_encoded(_reanchored(value, produced, Path(_ANCHOR))))
    except TypeError:
        return                          # a value of another kind: not remembered
    entry.parent.mkdir(parents=True, exist_ok=True)
    partial = Path(tempfile.mkdtemp(prefix=".partial-", dir=entry.parent))
    try:
        shutil.copytree(produced, partial / _FILES)
        (partial / _VALUE).write_text(text)
        with contextlib.suppress(OSError):     # another process kept the same job first
            os.replace(partial, entry)
    finally:
        shutil.rmtree(partial, ignore_errors=True)


def _reanchored(value, old: Path, new: Path):
    """``value`` with every path (or string) under ``old`` moved under ``new``."""
    old_text, new_text = str(old), str(new)

    def move(text: str) -> str:
        # the job's own folder has a random name (or is the entry's anchor): only its paths
        # contain it
        return text.replace(old_text, new_text)

    def walk(item):
        if isinstance(item, Path):
            return Path(move(str(item)))
        if isinstance(item, str):
            return move(item)
        if isinstance(item, Section):
            return dataclasses.replace(item, **{f.name: walk(getattr(item, f.name))
                                                for f in dataclasses.fields(item)})
        if isinstance(item, dict):
            return {walk(k): walk(v) for k, v in item.items()}
        if isinstance(item, (list, tuple)):
            return type(item)(walk(v) for v in item)
        return item
    return walk(value)


def _encoded(item):
    """``item`` as JSON-able data that ``_decoded`` turns back; TypeError for a kind that
    is not kept."""
    if item is None or isinstance(item, (bool, int, float, str)):
        return item
    if isinstance(item, Path):
        return {"path": str(item)}
    if isinstance(item, Section):
        return {"section": {f.name: _encoded(getattr(item, f.name))
                            for f in dataclasses.fields(item)}}
    if isinstance(item, tuple):
        return {"tuple": [_encoded(v) for v in item]}
    if isinstance(item, list):
        return [_encoded(v) for v in item]
    if isinstance(item, dict):
        return {"dict": [[_encoded(k), _encoded(v)] for k, v in item.items()]}
    if type(item).__module__ == "numpy" and hasattr(item, "item") and getattr(
            item, "shape", None) == ():
        return _encoded(item.item())
    raise TypeError(f"a {type(item).__name__} is not kept")


def _decoded(item):
    """The value ``_encoded`` wrote."""
    if isinstance(item, list):
        return [_decoded(v) for v in item]
    if not isinstance(item, dict):
        return item
    (kind, data), = item.items()
    if kind == "path":
        return Path(data)
    if kind == "tuple":
        return tuple(_decoded(v) for v in data)
    if kind == "dict":
        return {_hashable(_decoded(k)): _decoded(v) for k, v in data}
    if kind == "section":
        return Section(**{name: _decoded(v) for name, v in data.items()})
    raise KeyError(kind)


def _hashable(key):
    return tuple(key) if isinstance(key, list) else key


@dataclasses.dataclass(frozen=True)
class RunCacheInfo:
    """The remembered jobs: their folder, how many and their size.

    Attributes
    ----------
    directory : pathlib.Path
    entries : int
    size : int
        Bytes.
    """

    directory: Path
    entries: int
    size: int

    def __str__(self):
        return f"remembered runs: {self.entries} ({self.size / 1e6:.1f} MB) in {self.directory}"


def run_cache_info() -> RunCacheInfo:
    """The folder of the remembered jobs, their number and size."""
    folder = runs_dir()
    entries = [p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")] \
        if folder.is_dir() else []
    size = sum(f.stat().st_size for e in entries for f in e.rglob("*") if f.is_file())
    return RunCacheInfo(directory=folder, entries=len(entries), size=size)


def clear_run_cache() -> ClearReport:
    """Remove every remembered job (:func:`~flexctl.sim.cache_files.clear_folder`)."""
    return clear_folder(runs_dir(), "")
