"""Files written whole or not at all.

:func:`write_atomic` and :func:`atomic_file` write one file through a temporary file in its
folder, moved over the file's name with ``os.replace`` once it is complete: a reader, or a
later run after a crash, sees the old file or the new one, never half of one.

:func:`staged_folder` does the same for a folder of files (an export, a run's report): they
are written into a temporary folder, and moved into the destination only once the block that
writes them has finished; a failure (an exception, a Ctrl-C) removes the temporary folder and
leaves the destination as it was.

- **Where.** A destination that does not exist yet is staged beside it (same parent) and
  renamed into place in one step; the parents made for it are removed again on failure. An
  existing destination is staged in a hidden folder inside it (same file system, whatever is
  mounted where), and each file is moved over its name with ``os.replace``: files of other
  names in the destination are kept.
- **Refusals.** A folder where a file is to go, or a file where a folder is to go, is refused
  with :class:`~flexctl.model.errors.InputValueError` naming the path, before anything is
  moved (and, for the names given up front, before anything is written).
- **Moving several files.** Should a move fail part way, the files moved so far are put back
  (the replaced ones from hard links taken before), so the destination is left as it was.
- **Names.** Temporary files and folders are hidden and start with :data:`TEMPORARY_PREFIX`;
  a temporary file keeps the name's suffix (``savefig`` and ``to_csv`` go by it).

Imports nothing of flexctl but its errors: :mod:`controllers.codegen` and :mod:`flexctl.app`
both write through it.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from flexctl.sim.atomic_files import staged_folder, write_atomic
>>> out = Path(tempfile.mkdtemp()) / "report"
>>> with staged_folder(out, names=("a.txt",)) as stage:
...     _ = write_atomic(stage / "a.txt", "first\\n")
...     _ = (stage / "b.txt").write_text("second\\n")
>>> sorted(p.name for p in out.iterdir())
['a.txt', 'b.txt']
"""

from __future__ import annotations

import contextlib
import functools
import os
import secrets
import shutil
from pathlib import Path

from ..model.errors import InputTypeError, InputValueError

__all__ = ["write_atomic", "atomic_file", "staged_folder", "TEMPORARY_PREFIX"]

#: Start of the name of every temporary file and folder written here (hidden).
TEMPORARY_PREFIX = ".partial-"


def _path(value, what: str) -> Path:
    """``value`` as a :class:`~pathlib.Path`, or a clear error naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, (str, os.PathLike)) \
            or not str(value).strip():
        raise InputTypeError(f"{what} must be a path; got {value!r}"[:200])
    return Path(value)


def _temporary(folder: Path, name: str) -> Path:
    """A fresh hidden name in ``folder`` that ends with ``name``."""
    return folder / f"{TEMPORARY_PREFIX}{secrets.token_hex(6)}-{name}"


def _refuse_folder_in_the_way(path: Path) -> None:
    if path.is_dir():
        raise InputValueError(f"output file {str(path)!r} is a folder: a file is written "
                              "there (move or remove the folder, or choose another output)")


def _refuse_file_in_the_way(path: Path) -> None:
    if path.exists() and not path.is_dir():
        raise InputValueError(f"output folder {str(path)!r} is a file: a folder of files is "
                              "written there (move or remove the file, or choose another "
                              "output)")


@contextlib.contextmanager
def atomic_file(path):
    """A temporary path to write ``path``'s content to; moved over ``path`` when the block
    ends without an exception, removed otherwise.

    Parameters
    ----------
    path : str or path-like
        The file; its folder must exist.

    Yields
    ------
    pathlib.Path
        A hidden name beside ``path``, ending with ``path``'s name (same suffix).

    Raises
    ------
    flexctl.model.errors.InputValueError
        If ``path`` is a folder (before the block runs).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> target = Path(tempfile.mkdtemp()) / "table.csv"
    >>> with atomic_file(target) as partial:
    ...     _ = partial.write_text("a,b\\n1,2\\n")
    >>> target.read_text()
    'a,b\\n1,2\\n'
    """
    path = _path(path, "atomic_file: path")
    _refuse_folder_in_the_way(path)
    partial = _temporary(path.parent, path.name)
    try:
        yield partial
        os.replace(partial, path)
    finally:
        with contextlib.suppress(OSError):
            partial.unlink()


def write_atomic(path, data) -> Path:
    """Write ``data`` to ``path`` whole or not at all (:func:`atomic_file`).

    Parameters
    ----------
    path : str or path-like
        The file; its folder must exist.
    data : str or bytes
        The content: text is written as UTF-8.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    flexctl.model.errors.InputTypeError
        If ``data`` is neither text nor bytes.
    flexctl.model.errors.InputValueError
        If ``path`` is a folder.
    """
    if not isinstance(data, (str, bytes, bytearray)):
        raise InputTypeError(f"write_atomic: data must be str or bytes; got "
                             f"{type(data).__name__}")
    path = _path(path, "write_atomic: path")
    with atomic_file(path) as partial:
        if isinstance(data, str):
            partial.write_text(data, encoding="utf-8")
        else:
            partial.write_bytes(bytes(data))
    return path


def _refuse_blocked(destination: Path, names) -> None:
    """Refuse a file named ``destination``, a folder at one of ``names`` (relative file paths
    under it), or a file at one of their folders."""
    _refuse_file_in_the_way(destination)
    for name in names:
        relative = Path(name)
        if relative.is_absolute() or ".." in relative.parts or not relative.parts:
            raise InputValueError(f"staged_folder: names must be relative paths inside the "
                                  f"folder; got {str(name)!r}")
        for depth in range(1, len(relative.parts)):
            _refuse_file_in_the_way(destination.joinpath(*relative.parts[:depth]))
        _refuse_folder_in_the_way(destination / relative)


def _make_folders(folder: Path) -> list:
    """Make ``folder`` and its missing parents; return those made, the deepest last."""
    missing = []
    while not folder.exists() and not folder.is_symlink() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    made = []
    try:
        for each in reversed(missing):
            each.mkdir()
            made.append(each)
    except BaseException:
        _remove_empty(made)
        raise
    return made


def _remove_empty(folders) -> None:
    """Remove ``folders`` (the deepest last in the list) where they are empty."""
    for folder in reversed(folders):
        with contextlib.suppress(OSError):
            folder.rmdir()


def _staged_files(stage: Path) -> list:
    """Paths of every file (and link) under ``stage``, relative to it, sorted."""
    return sorted(path.relative_to(stage) for path in stage.rglob("*")
                  if path.is_symlink() or not path.is_dir())


def _keep_copy(target: Path, copy: Path) -> None:
    """``copy`` holds ``target``'s content (a hard link where the file system allows)."""
    copy.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(target, copy, follow_symlinks=False)
    except OSError:
        shutil.copy2(target, copy, follow_symlinks=False)


def _move_files(stage: Path, destination: Path, files: list) -> None:
    """Move ``files`` from ``stage`` over their names in ``destination``; on a failure put
    back what was moved (the replaced files from copies kept in ``stage``) and re-raise."""
    undo = []
    kept = _temporary(stage, "previous")
    try:
        for relative in files:
            target = destination / relative
            undo += [functools.partial(os.rmdir, made)
                     for made in _make_folders(target.parent)]
            if target.exists() or target.is_symlink():
                _keep_copy(target, kept / relative)
                os.replace(stage / relative, target)
                undo.append(functools.partial(os.replace, kept / relative, target))
            else:
                os.replace(stage / relative, target)
                undo.append(functools.partial(os.unlink, target))
    except BaseException:
        for step in reversed(undo):
            with contextlib.suppress(OSError):
                step()
        raise


def _commit(stage: Path, destination: Path, beside: bool) -> None:
    """Move what ``stage`` holds into ``destination`` (see :func:`staged_folder`)."""
    files = _staged_files(stage)
    _refuse_blocked(destination, files)
    if beside and not destination.exists() and not destination.is_symlink():
        try:
            os.rename(stage, destination)       # the whole folder in one step
            return
        except OSError:                         # made meanwhile: move file by file
            pass
    made = _make_folders(destination)
    try:
        _move_files(stage, destination, files)
    except BaseException:
        _remove_empty(made)
        raise


@contextlib.contextmanager
def staged_folder(destination, names=()):
    """A temporary folder whose files are moved into ``destination`` when the block ends
    without an exception; on an exception it is removed and ``destination`` is left as it
    was.

    Parameters
    ----------
    destination : str or path-like
        The folder; made (with its parents) if missing. Files of other names in it are kept.
    names : sequence of str, optional
        Files (relative paths) the block will write: refused before the block runs if a
        folder stands at one of them. Whatever the block writes is checked the same way
        before anything is moved.

    Yields
    ------
    pathlib.Path
        The folder to write into (hidden, beside ``destination`` or inside it).

    Raises
    ------
    flexctl.model.errors.InputValueError
        If ``destination`` is a file, or a folder stands where a file is written (or a file
        where a folder is): the message names the path.
    OSError
        If the folders cannot be made or the files moved (``destination`` unchanged).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> out = Path(tempfile.mkdtemp())
    >>> (out / "mine.txt").write_text("kept")
    4
    >>> try:
    ...     with staged_folder(out) as stage:
    ...         _ = (stage / "half.txt").write_text("half")
    ...         raise RuntimeError("the writer failed")
    ... except RuntimeError:
    ...     pass
    >>> sorted(p.name for p in out.iterdir())
    ['mine.txt']
    """
    destination = _path(destination, "staged_folder: destination")
    if isinstance(names, (str, bytes)):
        raise InputTypeError(f"staged_folder: names must be a sequence of file names; got "
                             f"{names!r}"[:200])
    _refuse_blocked(destination, names)
    beside = not destination.is_dir()
    made = _make_folders(destination.parent) if beside else []
    home = destination.parent if beside else destination
    stage, done = _temporary(home, destination.name or "output"), False
    try:
        stage.mkdir()
        yield stage
        _commit(stage, destination, beside)
        done = True
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if not done:
            _remove_empty(made)
