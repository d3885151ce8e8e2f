"""The compile cache's files, each checked before it is trusted.

Every file the cache reads back carries a SHA-256 digest written with it, and is used only
when its content matches; a file that does not match (truncated, zeroed, altered, a NaN
written into it, left half-written by a crash) is reported with its reason and built again,
so that a damaged cache never crashes a run or changes an answer.

- **Libraries** (``<name>-<key>.so``): their digest is kept beside them in
  ``<name>-<key>.so.sha256``, written before the library is moved into place. A library is
  mapped into the process (``dlopen``) only after its bytes have been hashed and found equal
  to the digest: a truncated or zeroed library is never mapped (mapping one is what crashed
  with SIGBUS or SIGSEGV), and a library still being written is never seen (it is written to
  a temporary name and moved into place whole).
- **Sealed files** (the index of a function's library, the lifted functions and their
  constants): one header line ``flexctl-sealed 1 <sha256 of the rest>``, then the content.

:func:`clear_folder` removes a folder's files and reports what it removed and what it could
not (a read-only cache).

Examples
--------
>>> import tempfile, pathlib
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> write_sealed(folder / "entry", b"numbers")
>>> read_sealed(folder / "entry")
b'numbers'
>>> _ = (folder / "entry").write_bytes(b"flexctl-sealed 1 " + b"0" * 64 + b"\\nnumbers")
>>> read_sealed(folder / "entry")
Traceback (most recent call last):
...
flexctl.sim.cache_files.DamagedEntry: its content does not match its digest
"""

from __future__ import annotations

import contextlib
import hashlib
import shutil
from dataclasses import dataclass
from pathlib import Path

__all__ = ["DamagedEntry", "atomic_write", "write_sealed", "read_sealed", "digest_path",
           "write_digest", "verify_library", "ClearReport", "clear_folder", "SEAL"]

#: First bytes of a sealed file, before the digest of the rest.
SEAL = b"flexctl-sealed 1 "
_DIGEST_HEX = 64
_CHUNK = 1 << 20


class DamagedEntry(Exception):
    """A cache file that cannot be trusted; its message says why."""


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in its folder, moved into place
    with ``os.replace``: a reader sees the old file, the new one or none, never a part.

    Parameters
    ----------
    path : pathlib.Path
        Where the file goes (its folder is created if needed).
    data : bytes
        The whole content.
    """
    from .atomic_files import write_atomic

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_dir():               # an OSError, as the cache's other failures are
        raise IsADirectoryError(21, "a folder stands at a cache entry's name", str(path))
    write_atomic(path, data)


def write_sealed(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` (atomically) behind a header holding its SHA-256.

    Parameters
    ----------
    path : pathlib.Path
        Where the file goes.
    data : bytes
        The content to seal.
    """
    atomic_write(path, SEAL + hashlib.sha256(data).hexdigest().encode("ascii") + b"\n" + data)


def read_sealed(path: Path) -> bytes:
    """The content of a file written by :func:`write_sealed`, after checking its digest.

    Parameters
    ----------
    path : pathlib.Path
        The sealed file.

    Returns
    -------
    bytes
        The content, exactly as written.

    Raises
    ------
    FileNotFoundError
        When there is no such file (not damage: an entry never written).
    DamagedEntry
        When the file has no header or its content does not match the digest.
    """
    data = Path(path).read_bytes()
    head = len(SEAL) + _DIGEST_HEX
    if not data.startswith(SEAL) or data[head:head + 1] != b"\n":
        raise DamagedEntry("it has no digest header (written by another version, or damaged)")
    content = data[head + 1:]
    if hashlib.sha256(content).hexdigest().encode("ascii") != data[len(SEAL):head]:
        raise DamagedEntry("its content does not match its digest")
    return content


def digest_path(library: Path) -> Path:
    """The file holding the digest of ``library``: its name with ``.sha256`` added.

    Parameters
    ----------
    library : pathlib.Path
        A library in the cache.

    Returns
    -------
    pathlib.Path
    """
    return library.with_name(library.name + ".sha256")


def _file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(_CHUNK), b""):
            digest.update(block)
    return digest.hexdigest()


def write_digest(built: Path, library: Path) -> None:
    """Record the digest of ``built`` (a library just compiled, still at its temporary name)
    as the digest of ``library``, where it will be moved.

    Parameters
    ----------
    built : pathlib.Path
        The library as the compiler wrote it.
    library : pathlib.Path
        Its place in the cache.
    """
    atomic_write(digest_path(library), _file_digest(built).encode("ascii") + b"\n")


def verify_library(library: Path) -> str | None:
    """Why ``library`` cannot be trusted, or None when its bytes match its recorded digest.

    Parameters
    ----------
    library : pathlib.Path
        A library in the cache (present).

    Returns
    -------
    str or None
        The reason (no digest recorded, a digest that does not match, an unreadable file).
    """
    try:
        recorded = digest_path(library).read_text(encoding="ascii").strip()
    except FileNotFoundError:
        return "no digest is recorded for it"
    except (OSError, UnicodeDecodeError):
        return "its digest file cannot be read"
    try:
        actual = _file_digest(library)
    except OSError as exc:
        return f"it cannot be read ({exc.strerror or exc})"
    if actual != recorded:
        return "its bytes do not match their recorded digest (truncated or altered)"
    return None


@dataclass(frozen=True)
class ClearReport:
    """What :func:`clear_folder` did.

    Attributes
    ----------
    folder : pathlib.Path
        The folder cleared.
    libraries : int
        Compiled libraries removed.
    files : int
        Files removed in all (libraries, their digests, indexes, lifted functions, leftovers).
    failed : tuple of (pathlib.Path, str)
        Files that could not be removed, with the reason.
    """

    folder: Path
    libraries: int
    files: int
    failed: tuple = ()

    def __str__(self):
        lines = [f"removed {self.libraries} compiled functions ({self.files} files) from "
                 f"{self.folder}"]
        lines += [f"could not remove {path}: {reason}" for path, reason in self.failed]
        return "\n".join(lines)


def clear_folder(folder: Path, library_suffix: str) -> ClearReport:
    """Remove every file in ``folder`` (and the folder, once empty), counting what went.

    Parameters
    ----------
    folder : pathlib.Path
        The cache's folder of compiled functions.
    library_suffix : str
        The suffix of a library (``".so"``), to count them apart.

    Returns
    -------
    ClearReport
        What was removed and what could not be, with the reason.
    """
    folder = Path(folder)
    libraries = files = 0
    failed = []
    if not folder.is_dir():
        return ClearReport(folder=folder, libraries=0, files=0)
    for path in sorted(folder.iterdir()):
        try:
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
        except FileNotFoundError:
            continue                    # another process removed it meanwhile
        except OSError as exc:
            failed.append((path, exc.strerror or str(exc)))
            continue
        files += 1
        libraries += path.name.endswith(library_suffix)
    with contextlib.suppress(OSError):
        folder.rmdir()
    return ClearReport(folder=folder, libraries=libraries, files=files, failed=tuple(failed))
