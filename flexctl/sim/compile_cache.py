"""A persistent cache of CasADi functions compiled to machine code.

:func:`compiled` turns a CasADi ``Function`` into one that runs as machine code: its C source
(CasADi's code generator) is compiled once into a shared library in the cache directory and
loaded with ``casadi.external``; later calls, in this process or any other, load the library
without compiling again.

- **Key.** A library's name is the SHA-256 of the generated C, the CasADi version, the
  compiler (its path and ``--version`` line) and the flags: any change to the function (its
  structure; the numbers that are parameters do not appear in it), to CasADi or to the
  compiler makes a new entry, and an unchanged function is never compiled twice. For an SX
  function a small index file beside the library names it by the SHA-256 of the function's
  CasADi serialisation (and of the same CasADi, compiler and flags), so that a later process
  finds it without generating the C again: serialising costs a third to a tenth of that.
- **Lifted constants.** :func:`~flexctl.sim.lifted_constants.lift_constants` keeps what it
  made in the same folder (see :mod:`flexctl.sim.lifted_constants`).
- **Location.** ``$FLEXCTL_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/flexctl``, else
  ``~/.cache/flexctl``; a ``compiled/`` folder in it holds ``<name>-<hash>.so`` files.
- **Atomicity.** The source and the library are written to temporary names in the cache
  directory and moved into place with ``os.replace``: a reader sees a whole library or none.
  Workers of a sweep that want the same function at once take turns on a lock file, so one
  compiles and the others load its library (without ``fcntl`` each compiles, still safely).
- **Fallback.** Without a C compiler (``$CC``, else ``cc``, ``gcc`` or ``clang`` on the path),
  or where compiling fails, the function runs on CasADi's virtual machine as before, and one
  warning line says so, once per process. ``FLEXCTL_COMPILE=0`` turns compiling off.
- **Progress.** A compile that takes more than :data:`PROGRESS_AFTER` seconds says so on one
  whole stderr line, written in one call (workers of a sweep that compile at once print
  whole lines, never parts of each other's); :data:`STATS` adds up the seconds spent.
- **Trust.** Every file is checked before it is used (:mod:`flexctl.sim.cache_files`): a
  library is mapped only when its bytes match the SHA-256 digest written with it, an index
  only when its sealed digest matches. A file that does not match (truncated, zeroed,
  altered) or a library that does not load (foreign) is built again, with one
  :class:`CompileCacheWarning` line naming it and saying why: a damaged cache costs time,
  never a crash or another answer.

:func:`cache_info` and :func:`clear_cache` back ``flexctl cache info`` and
``flexctl cache clear``; :data:`STATS` counts compiles, loads and in-process hits.

Examples
--------
>>> import casadi as ca
>>> from flexctl.sim.compile_cache import compiled
>>> x = ca.SX.sym("x")
>>> f = compiled(ca.Function("doc_square", [x], [x ** 2]))
>>> float(f(3.0))
9.0
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

from .cache_files import (ClearReport, DamagedEntry, clear_folder, read_sealed, verify_library,
                          write_digest, write_sealed)

__all__ = ["compiled", "compiled_source", "entry_point", "cache_dir", "cache_info",
           "clear_cache", "compiler", "compiling_enabled", "same_signature", "warn_damaged",
           "CacheInfo", "ClearReport", "CompileCacheWarning", "STATS", "FLAGS", "LOOP_FLAGS",
           "PROGRESS_AFTER", "SUBDIR", "FORMAT"]

#: Compiler flags of every library (part of the key). ``-Og`` runs the generated straight-line
#: code about as fast as ``-O2`` (within 6 % on the exact model's right-hand side and its
#: derivatives) and compiles it up to 14 times sooner: the register allocation of ``-O1`` and
#: above grows faster than linearly with a function's length (``benchmarks/bench_compile.py
#: --flags``).
FLAGS = ("-Og", "-fPIC", "-shared")
#: Flags of hand-written C (:func:`compiled_source` with ``loops=True``): the compiled
#: multistep integrators' loops over the states and the history run faster at ``-O2``
#: (hub-beam-mass's exact 6-mode model under a sine torque, compiled Adams-Moulton at rtol
#: 1e-8: 15.4 ms a run against 17.4 ms at ``-Og``), and their libraries are small.
LOOP_FLAGS = ("-O2", "-fPIC", "-shared")
#: Version of the cache's file layout, part of every key: entries of another layout (an
#: earlier flexctl's, without digests) are never looked up, and ``flexctl cache clear``
#: removes them.
FORMAT = "2"
#: A compile longer than this (s) reports itself on stderr.
PROGRESS_AFTER = 1.0
#: Where libraries go, under the cache directory.
SUBDIR = "compiled"
_SUFFIX = ".so" if sys.platform != "win32" else ".dll"

#: Counts since the process started: ``compiles`` (libraries built), ``loads`` (libraries
#: loaded from disk), ``hits`` (functions found already loaded), ``fallbacks`` (functions left
#: on the virtual machine) and ``compile_seconds`` (wall time of the builds).
STATS = {"compiles": 0, "loads": 0, "hits": 0, "fallbacks": 0, "compile_seconds": 0.0}

_LOADED: dict = {}
#: The library and C name of each function loaded from the cache, by the function's id (the
#: function kept with them, so that the id is not reused).
_ORIGIN: dict = {}
_WARNED: set = set()
_COMPILER: dict = {}


class CompileCacheWarning(RuntimeWarning):
    """Compiled functions are not available: they run on CasADi's virtual machine."""


def cache_dir() -> Path:
    """The cache directory: ``$FLEXCTL_CACHE_DIR``, ``$XDG_CACHE_HOME/flexctl`` or
    ``~/.cache/flexctl`` (not created here)."""
    override = os.environ.get("FLEXCTL_CACHE_DIR")
    if override:
        return Path(override).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join("~", ".cache")
    return Path(base).expanduser() / "flexctl"


def compiler() -> tuple | None:
    """``(path, version line)`` of the C compiler: ``$CC`` if set (a program name or path),
    else the first of ``cc``, ``gcc``, ``clang`` on the path; None when there is none."""
    wanted = os.environ.get("CC") or None
    names = (wanted,) if wanted else ("cc", "gcc", "clang")
    memo_key = (names, os.environ.get("PATH", ""))
    if memo_key not in _COMPILER:
        found = None
        for name in names:
            path = shutil.which(name)
            if path is None:
                continue
            try:
                out = subprocess.run([path, "--version"], capture_output=True, text=True,
                                     timeout=30)
            except (OSError, subprocess.SubprocessError):
                continue
            if out.returncode == 0:
                found = (path, (out.stdout.splitlines() or [""])[0].strip())
                break
        _COMPILER[memo_key] = found
    return _COMPILER[memo_key]


def compiling_enabled() -> bool:
    """False when ``FLEXCTL_COMPILE`` turns compiling off (``0``, ``no``, ``false``, ``off``)."""
    return os.environ.get("FLEXCTL_COMPILE", "1").strip().lower() not in ("0", "no", "false",
                                                                           "off")


def _tool() -> tuple | None:
    """The compiler (:func:`compiler`) where compiling is on and one is found; None
    otherwise (counted, and one warning when there is none)."""
    if not compiling_enabled():
        return None
    tool = compiler()
    if tool is None:
        STATS["fallbacks"] += 1
        _warn_once("no C compiler found (set CC or put cc on the PATH)")
    return tool


def warn_damaged(path: Path, reason: str) -> None:
    """Say, once per file and process, that the cache entry ``path`` is not trusted and why
    (it is then built again: the answer does not change, only the time).

    Parameters
    ----------
    path : pathlib.Path
        The damaged file.
    reason : str
        Why it is not trusted.
    """
    if ("damaged", str(path)) not in _WARNED:
        _WARNED.add(("damaged", str(path)))
        warnings.warn(f"compile cache entry {path} is not used: {reason}; built again",
                      CompileCacheWarning, stacklevel=3)


def _warn_once(reason: str) -> None:
    if reason not in _WARNED:
        _WARNED.add(reason)
        warnings.warn(f"{reason}: CasADi functions run on the virtual machine (correct, "
                      "several times slower)", CompileCacheWarning, stacklevel=3)


def _source(function, companions=()) -> str:
    """The C source of ``function`` and its ``companions`` (their sub-functions included)."""
    import casadi as ca

    generator = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
    for each in (function, *companions):
        generator.add(each)
    return generator.dump()


def _key(source: str, tool: tuple, flags: tuple = FLAGS) -> str:
    import casadi as ca

    digest = hashlib.sha256()
    for part in (source, ca.__version__, FORMAT, tool[0], tool[1], " ".join(flags)):
        digest.update(part.encode("utf-8"))
        digest.update(b"\0")
    return digest.hexdigest()[:32]


def compiled(function, *, label: str | None = None, companions=(), options=None):
    """``function`` as machine code from the persistent cache, else ``function`` itself.

    Parameters
    ----------
    function : casadi.Function
        Any function CasADi can generate C for (SX or MX; no external calls inside).
    label : str, optional
        What to call it in a progress line. Default: its name.
    companions : sequence of casadi.Function, optional
        Functions compiled into the same library. ``casadi.external`` takes the ones named
        ``jac_<name>``, ``adj1_<name>`` and ``jac_adj1_<name>`` (the signatures of CasADi's
        ``jacobian()``, ``reverse(1)`` and ``reverse(1).jacobian()``) as the derivatives of
        ``<name>``: see :func:`with_derivatives`.
    options : dict, optional
        Options of ``casadi.external`` (e.g. ``{"jac_penalty": -1}``).

    Returns
    -------
    casadi.Function
        A ``casadi.external`` of the same name, inputs and outputs (differentiable only
        through its companions: take other derivatives of ``function`` before compiling), or
        ``function`` where compiling is off, impossible (one warning) or failed (one warning).
    """
    import casadi as ca

    from ..model.errors import InputTypeError

    companions = tuple(companions) if isinstance(companions, (list, tuple)) else companions
    if not isinstance(companions, tuple) or not all(isinstance(c, ca.Function)
                                                    for c in companions):
        raise InputTypeError(f"compiled: companions must be a sequence of casadi.Function; got "
                             f"{companions!r}"[:200])
    if options is not None and not isinstance(options, dict):
        raise InputTypeError(f"compiled: options must be a dict; got {type(options).__name__}")
    tool = _tool()
    if tool is None:
        return function
    name = function.name()
    # SX functions serialise in a third to a tenth of the time their C takes to generate, and
    # are looked up by their serialisation; MX ones (loops of calls) take longer to serialise
    # than to generate, and are looked up by their C
    indexed = all(f.is_a("SXFunction") for f in (function, *companions))
    try:
        if indexed:
            memo = fingerprint = _fingerprint((function, *companions), tool)
        else:
            source = _source(function, companions)  # CasADi refuses what it cannot generate
            memo = _key(source, tool)
        if (name, memo) in _LOADED:
            STATS["hits"] += 1
            return _LOADED[(name, memo)]
        # a library built before for this very function is found without generating its C
        key = _read_index(name, fingerprint) if indexed else memo
        loaded = None if key is None else _try_load(name, _library(name, key), options or {})
        if loaded is not None and not same_signature(loaded, function):
            loaded = None               # an index naming another function's library
        if loaded is None:
            if indexed:
                source = _source(function, companions)
                key = _key(source, tool)
            loaded = _load_or_build(name, key, source, tool, label or name, options or {})
            if indexed:
                _write_index(name, fingerprint, key)
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        STATS["fallbacks"] += 1
        _warn_once(f"compiling {name} failed ({' '.join(str(exc).split())[:200]})")
        return function
    _LOADED[(name, memo)] = loaded
    return loaded


def same_signature(found, function, extra_inputs: int = 0) -> bool:
    """Whether ``found`` has ``function``'s outputs and inputs (and ``extra_inputs`` more),
    their names and sparsity.

    Parameters
    ----------
    found : casadi.Function
        A function read back from the cache.
    function : casadi.Function
        The function it should stand for.
    extra_inputs : int, optional
        Inputs ``found`` has after ``function``'s (a lifted function's constants). Default 0.

    Returns
    -------
    bool
    """
    n_in = function.n_in()
    return (found.n_in() == n_in + extra_inputs and found.n_out() == function.n_out()
            and found.name_in()[:n_in] == function.name_in()
            and found.name_out() == function.name_out()
            and all(found.sparsity_in(k) == function.sparsity_in(k) for k in range(n_in))
            and all(found.sparsity_out(k) == function.sparsity_out(k)
                    for k in range(function.n_out())))


def _fingerprint(functions, tool: tuple) -> str:
    """SHA-256 of the functions' CasADi serialisations (their whole definition: operations,
    numbers, sparsity, names; the same from one process to the next), the CasADi version, the
    compiler and the flags."""
    import casadi as ca

    digest = hashlib.sha256()
    for part in (*(f.serialize() for f in functions), ca.__version__, FORMAT, tool[0], tool[1],
                 " ".join(FLAGS)):
        digest.update(part.encode("utf-8"))
        digest.update(b"\0")
    return digest.hexdigest()[:32]


def _library(name: str, key: str) -> Path:
    return cache_dir() / SUBDIR / f"{name}-{key}{_SUFFIX}"


def _index(name: str, fingerprint: str) -> Path:
    return cache_dir() / SUBDIR / f"{name}-{fingerprint}.key"


def _read_index(name: str, fingerprint: str) -> str | None:
    """The key of the library once built for the function of ``fingerprint``, if recorded
    (a damaged index is reported and ignored)."""
    path = _index(name, fingerprint)
    try:
        key = read_sealed(path).decode("ascii").strip()
    except FileNotFoundError:
        return None
    except (OSError, DamagedEntry, UnicodeDecodeError) as exc:
        warn_damaged(path, str(exc) or type(exc).__name__)
        return None
    if len(key) == 32 and all(c in "0123456789abcdef" for c in key):
        return key
    warn_damaged(path, "it does not hold a library's key")
    return None


def _write_index(name: str, fingerprint: str, key: str) -> None:
    """Record (atomically, sealed) that the function of ``fingerprint`` compiles to library
    ``key``; where that fails (the cache cleared meanwhile, a full disk), the library is
    still good and the next process generates the C once more."""
    with contextlib.suppress(OSError):
        write_sealed(_index(name, fingerprint), key.encode("ascii"))


def compiled_source(name: str, source: str, *, label: str | None = None, loops: bool = False):
    """A function written in C (CasADi's external interface: ``<name>``, ``<name>_n_in``,
    ``<name>_sparsity_in``, ``<name>_work``, ...) from the persistent cache, or None.

    Parameters
    ----------
    name : str
        The function's C name.
    source : str
        The whole C file (generated CasADi code it calls included); its hash is the key.
    label : str, optional
        What to call it in a progress line. Default: ``name``.
    loops : bool, optional
        Hand-written loops: compiled with :data:`LOOP_FLAGS` rather than :data:`FLAGS`
        (part of the key). Default False.

    Returns
    -------
    casadi.Function or None
        ``casadi.external(name, library)``; None where compiling is off, impossible (one
        warning) or failed (one warning): there is no virtual machine for hand-written C.
    """
    from ..model.errors import InputTypeError

    if not isinstance(name, str) or not name.isidentifier():
        raise InputTypeError(f"compiled_source: name must be a C identifier; got {name!r}"[:200])
    if not isinstance(source, str) or not source:
        raise InputTypeError("compiled_source: source must be the C file as a non-empty str; "
                             f"got {type(source).__name__}")
    if not isinstance(loops, bool):
        raise InputTypeError(f"compiled_source: loops must be True or False; got {loops!r}"[:200])
    tool = _tool()
    if tool is None:
        return None
    flags = LOOP_FLAGS if loops else FLAGS
    key = _key(source, tool, flags)
    if (name, key) in _LOADED:
        STATS["hits"] += 1
        return _LOADED[(name, key)]
    try:
        loaded = _load_or_build(name, key, source, tool, label or name, {}, flags)
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        STATS["fallbacks"] += 1
        _warn_once(f"compiling {name} failed ({' '.join(str(exc).split())[:200]})")
        return None
    _LOADED[(name, key)] = loaded
    return loaded


def _load_or_build(name: str, key: str, source: str, tool: tuple, label: str,
                   options: dict, flags: tuple = FLAGS):
    """Load ``<name>-<key>`` from the cache directory, compiling it first if absent or bad."""
    library = _library(name, key)
    library.parent.mkdir(parents=True, exist_ok=True)
    loaded = _try_load(name, library, options)
    if loaded is not None:
        return loaded
    with _lock(library.with_suffix(".lock")):
        loaded = _try_load(name, library, options)  # another worker may have built it meanwhile
        if loaded is None:
            _build(library, source, tool, label, flags)
            loaded = _try_load(name, library, options)
    if loaded is None:
        raise RuntimeError(f"the library compiled for {name} does not load")
    return loaded


def _try_load(name: str, library: Path, options: dict | None = None):
    """The function in ``library``, or None when the file is absent, is not what was built
    (its bytes do not match their recorded digest: it is never mapped) or does not load; a
    present library that is not used is reported, and compiled again by the caller."""
    import casadi as ca

    if not library.is_file():
        return None
    reason = verify_library(library)
    if reason is not None:
        warn_damaged(library, reason)
        return None
    try:
        function = ca.external(name, str(library), options or {})
    except RuntimeError as exc:
        warn_damaged(library, f"it does not load ({' '.join(str(exc).split())[:160]})")
        return None
    STATS["loads"] += 1
    _ORIGIN[id(function)] = (function, library, name)
    return function


def entry_point(function, symbol: str | None = None):
    """``(address, keep)`` of a C function in the library of a function loaded from the cache
    (:func:`compiled`, :func:`compiled_source`), or None for a function not loaded from it.

    Parameters
    ----------
    function : casadi.Function
        A function this module loaded.
    symbol : str, optional
        The C name; default the function's own entry point (CasADi's signature ``int
        f(const double **arg, double **res, casadi_int *iw, double *w, int mem)``).

    Returns
    -------
    tuple or None
        ``(address, keep)``: the address (an int) and an object to keep alive as long as the
        address is used (the library, as CasADi has it open: the same copy).
    """
    import ctypes

    origin = _ORIGIN.get(id(function))
    if origin is None or origin[0] is not function:
        return None
    try:
        library = ctypes.CDLL(str(origin[1]))
        return (ctypes.cast(getattr(library, symbol or origin[2]), ctypes.c_void_p).value,
                library)
    except (OSError, AttributeError):
        return None


@contextlib.contextmanager
def _lock(path: Path):
    """An exclusive lock on ``path`` among processes (a no-op without ``fcntl``)."""
    try:
        import fcntl
    except ImportError:         # pragma: no cover - Windows: atomic replace alone
        yield
        return
    with open(path, "a+b") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _build(library: Path, source: str, tool: tuple, label: str, flags: tuple = FLAGS) -> None:
    """Compile ``source`` into ``library`` through temporary files in the same directory."""
    folder = library.parent
    fd, c_path = tempfile.mkstemp(prefix=".build-", suffix=".c", dir=folder)
    out_path = c_path[:-2] + _SUFFIX
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(source)
        command = [tool[0], *flags, c_path, "-o", out_path, "-lm"]
        start = time.perf_counter()
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True)
        try:
            _, errors = process.communicate(timeout=PROGRESS_AFTER)
        except subprocess.TimeoutExpired:
            sys.stderr.write(f"flexctl: compiling {label} ({len(source) // 1024} kB of C; "
                             f"once, kept in {folder})\n")
            sys.stderr.flush()
            _, errors = process.communicate()
        if process.returncode != 0:
            raise RuntimeError(f"{tool[0]} exited with {process.returncode}: "
                               f"{errors.strip()[-300:]}")
        write_digest(Path(out_path), library)
        os.replace(out_path, library)
        STATS["compiles"] += 1
        STATS["compile_seconds"] += time.perf_counter() - start
    finally:
        for path in (c_path, out_path):
            with contextlib.suppress(OSError):
                os.unlink(path)


@dataclass(frozen=True)
class CacheInfo:
    """What the cache holds.

    Attributes
    ----------
    directory : pathlib.Path
    entries : int
        Compiled libraries.
    size : int
        Total size of the cache's files, bytes: the libraries, their index files and the
        lifted functions kept beside them.
    compiler : str
        The compiler's version line, or why there is none.
    """

    directory: Path
    entries: int
    size: int
    compiler: str

    def __str__(self):
        return (f"directory: {self.directory}\nentries: {self.entries}\n"
                f"size: {self.size / 1e6:.1f} MB\ncompiler: {self.compiler}")


def _libraries() -> list:
    folder = cache_dir() / SUBDIR
    return sorted(folder.glob(f"*{_SUFFIX}")) if folder.is_dir() else []


def cache_info() -> CacheInfo:
    """The cache directory, its number of libraries, their size and the compiler."""
    files = _libraries()
    tool = compiler()
    if not compiling_enabled():
        what = "compiling off (FLEXCTL_COMPILE=0)"
    else:
        what = "none found (functions run on CasADi's virtual machine)" if tool is None \
            else f"{tool[1]} ({tool[0]})"
    folder = cache_dir() / SUBDIR
    every = [f for f in folder.iterdir() if f.is_file()] if folder.is_dir() else []
    return CacheInfo(directory=cache_dir(), entries=len(files),
                     size=sum(_size(f) for f in every), compiler=what)


def _size(path: Path) -> int:
    """Bytes of ``path``, 0 if another process removed it meanwhile."""
    try:
        return path.stat().st_size
    except OSError:
        return 0


def clear_cache() -> ClearReport:
    """Remove every compiled library and the files kept beside them (digests, indexes,
    lifted functions, leftover build and lock files). Functions already loaded in this
    process stay usable.

    Returns
    -------
    ClearReport
        How many libraries and files were removed, and which files could not be (a read-only
        cache), with the reason; ``str()`` of it is what ``flexctl cache clear`` prints.
    """
    report = clear_folder(cache_dir() / SUBDIR, _SUFFIX)
    _LOADED.clear()
    return report

