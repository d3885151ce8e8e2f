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
- **Lifted constants.** :func:`lift_constants` keeps what it made in the same folder, by the
  SHA-256 of the serialisation of the function it lifted and the CasADi version: the lifted
  function once per structure, the constants once per model (the :data:`LIFTED_KEEP` most
  recently used). Reading them back costs a fifth of lifting.
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
  stderr line, finished with its duration.
- **Damage.** A library that does not load (truncated, foreign) is compiled again.

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
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

__all__ = ["compiled", "compiled_source", "entry_point", "lift_constants", "with_derivatives", "jacobian_companion", "cache_dir",
           "cache_info", "clear_cache", "compiler", "compiling_enabled", "CacheInfo",
           "CompileCacheWarning", "STATS", "FLAGS", "LOOP_FLAGS", "PROGRESS_AFTER", "LIFTED_KEEP"]

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
#: A compile longer than this (s) reports itself on stderr.
PROGRESS_AFTER = 1.0
#: Where libraries go, under the cache directory.
_SUBDIR = "compiled"
_SUFFIX = ".so" if sys.platform != "win32" else ".dll"

#: Counts since the process started: ``compiles`` (libraries built), ``loads`` (libraries
#: loaded from disk), ``hits`` (functions found already loaded), ``fallbacks`` (functions left
#: on the virtual machine).
STATS = {"compiles": 0, "loads": 0, "hits": 0, "fallbacks": 0}

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
    for part in (source, ca.__version__, tool[0], tool[1], " ".join(flags)):
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
        if loaded is not None and not _same_signature(loaded, function):
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


def _same_signature(found, function, extra_inputs: int = 0) -> bool:
    """Whether ``found`` has ``function``'s outputs and inputs (and ``extra_inputs`` more),
    their names and sparsity."""
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
    for part in (*(f.serialize() for f in functions), ca.__version__, tool[0], tool[1],
                 " ".join(FLAGS)):
        digest.update(part.encode("utf-8"))
        digest.update(b"\0")
    return digest.hexdigest()[:32]


def _library(name: str, key: str) -> Path:
    return cache_dir() / _SUBDIR / f"{name}-{key}{_SUFFIX}"


def _index(name: str, fingerprint: str) -> Path:
    return cache_dir() / _SUBDIR / f"{name}-{fingerprint}.key"


def _read_index(name: str, fingerprint: str) -> str | None:
    """The key of the library once built for the function of ``fingerprint``, if recorded."""
    try:
        key = _index(name, fingerprint).read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return key if len(key) == 32 and all(c in "0123456789abcdef" for c in key) else None


def _write_index(name: str, fingerprint: str, key: str) -> None:
    """Record (atomically) that the function of ``fingerprint`` compiles to library ``key``;
    where that fails (the cache cleared meanwhile, a full disk), the library is still good
    and the next process generates the C once more."""
    with contextlib.suppress(OSError):
        _atomic_write(_index(name, fingerprint), key.encode("ascii"))


def _atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in its directory
    (:func:`~flexctl.sim.atomic_files.atomic_file`; a folder in the way is an ``OSError``
    here, as the cache's other failures are)."""
    from .atomic_files import atomic_file

    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_dir():
        raise IsADirectoryError(21, "a folder stands at a cache entry's name", str(path))
    with atomic_file(path) as partial:
        partial.write_bytes(data)


def lift_constants(function, max_instructions: int | None = None):
    """``function`` with its numbers moved into a last input, so that its code, and the key of
    its library, depend on its structure alone.

    An SX function's constants (a model's matrices, quadrature weights, mode shapes) are
    written into its generated C, so two models that differ only in numbers (a Monte Carlo
    sample, another beam length) would each compile. The lifted function ``g(*inputs, c)``
    computes the same operations in the same order with the constants read from ``c``: one
    library serves every such model.

    Parameters
    ----------
    function : casadi.Function
        An SX function without calls to other functions.
    max_instructions : int, optional
        Return None for a larger function (too slow to lift and compile).

    Returns
    -------
    (casadi.Function, ndarray) or None
        The lifted function (named ``<name>_lifted``) and the constants ``c`` it takes, or
        None when ``function`` is not an SX function, calls others or is too large.

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> x = ca.SX.sym("x")
    >>> g, c = lift_constants(ca.Function("doc_affine", [x], [3.0 * x + 2.5]))
    >>> c.tolist(), float(g(2.0, c))
    ([3.0, 2.5], 8.5)
    """
    import casadi as ca

    from ..model.checks import check_integer

    if max_instructions is not None:
        max_instructions = check_integer("lift_constants", "max_instructions",
                                         max_instructions, minimum=0)
    if not isinstance(function, ca.Function) or not function.is_a("SXFunction"):
        return None
    if max_instructions is not None and function.n_instructions() > max_instructions:
        return None
    try:
        fingerprint = hashlib.sha256((function.serialize() + "\0" + ca.__version__)
                                     .encode("utf-8")).hexdigest()[:32]
    except RuntimeError:                # pragma: no cover - every SX function serialises
        return _lift(function)
    with _LIFTED_LOCK:
        found = _LIFTED.get(fingerprint, _MISSING)
    if found is _MISSING:
        found = _read_lifted(fingerprint)
        if found is not None and not (
                found[0].name() == f"{function.name()}_lifted"
                and _same_signature(found[0], function, extra_inputs=1)
                and found[0].nnz_in(function.n_in()) == found[1].size):
            found = None                # not what lifting this function makes: lift again
        if found is None:
            found = _lift(function)
            if found is not None:
                _write_lifted(fingerprint, *found)
        with _LIFTED_LOCK:
            _LIFTED[fingerprint] = found
            while len(_LIFTED) > _LIFTED_SIZE:
                _LIFTED.pop(next(iter(_LIFTED)))
    return None if found is None else (found[0], found[1].copy())


#: Lifted functions made or read in this process, by fingerprint of the function lifted
#: (the oldest dropped beyond :data:`_LIFTED_SIZE`).
_LIFTED: dict = {}
_LIFTED_SIZE = 64
_LIFTED_LOCK = threading.Lock()
_MISSING = object()


#: Most files of lifted constants kept (one per model lifted: a Monte Carlo sample, another
#: beam length); beyond it the least recently used go. The lifted functions themselves are
#: one per structure.
LIFTED_KEEP = 512
#: Lifted functions read in this process, by the hash of their serialisation.
_STRUCTURES: dict = {}


def _constants_path(fingerprint: str) -> Path:
    return cache_dir() / _SUBDIR / f"lifted-{fingerprint}.constants"


def _structure_path(structure: str) -> Path:
    return cache_dir() / _SUBDIR / f"lifted-{structure}.casadi"


def _read_lifted(fingerprint: str):
    """``(lifted function, constants)`` stored for the function of ``fingerprint`` in the
    cache directory (where compiling is on), else None.

    A ``.constants`` file holds the hash of the lifted function (one ``.casadi`` file per
    structure, shared by every model of it) on its first line, then the constants as
    float64."""
    import casadi as ca
    import numpy as np

    if not compiling_enabled() or compiler() is None:
        return None
    path = _constants_path(fingerprint)
    try:
        data = path.read_bytes()
        structure, values = data[:32].decode("ascii"), data[33:]
        if data[32:33] != b"\n" or len(values) % 8:
            return None
        with _LIFTED_LOCK:
            lifted = _STRUCTURES.get(structure)
        if lifted is None:
            lifted = ca.StringDeserializer(
                _structure_path(structure).read_text(encoding="ascii")).unpack()
            if not isinstance(lifted, ca.Function):
                return None
            with _LIFTED_LOCK:
                _STRUCTURES[structure] = lifted
                while len(_STRUCTURES) > _LIFTED_SIZE:
                    _STRUCTURES.pop(next(iter(_STRUCTURES)))
        os.utime(path)                  # recently used: kept by _prune_constants
    except (OSError, UnicodeDecodeError, RuntimeError):
        return None
    return lifted, np.frombuffer(values, dtype="<f8").astype(float)


def _write_lifted(fingerprint: str, lifted, values) -> None:
    """Store a lifted function (once per structure) and its constants (per model) beside the
    libraries, where compiling is on: reading them back costs a fifth of lifting again."""
    import casadi as ca
    import numpy as np

    if not compiling_enabled() or compiler() is None:
        return
    text = lifted.serialize()
    structure = hashlib.sha256((text + "\0" + ca.__version__).encode("utf-8")).hexdigest()[:32]
    with contextlib.suppress(OSError):
        if not _structure_path(structure).is_file():
            writer = ca.StringSerializer()
            writer.pack(lifted)
            _atomic_write(_structure_path(structure), writer.encode().encode("ascii"))
        _atomic_write(_constants_path(fingerprint), structure.encode("ascii") + b"\n"
                      + np.asarray(values, dtype="<f8").tobytes())
        _prune_constants()


def _prune_constants() -> None:
    """Remove the least recently used constants files beyond :data:`LIFTED_KEEP`."""
    folder = cache_dir() / _SUBDIR
    files = list(folder.glob("lifted-*.constants"))
    if len(files) <= LIFTED_KEEP:
        return
    aged = sorted(files, key=_mtime)
    for path in aged[:len(files) - LIFTED_KEEP]:
        with contextlib.suppress(OSError):
            path.unlink()


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:
        return 0.0


def _lift(function):
    """:func:`lift_constants`' work: ``(lifted, constants)`` or None (a call inside)."""
    import casadi as ca
    import numpy as np

    inputs = function.sx_in()
    outputs = [ca.SX.zeros(function.sparsity_out(k)) for k in range(function.n_out())]
    work, values, symbols = [None] * function.sz_w(), [], []
    for k in range(function.n_instructions()):
        op = function.instruction_id(k)
        out, arg = function.instruction_output(k), function.instruction_input(k)
        if op == ca.OP_CONST:
            symbols.append(ca.SX.sym(f"c{len(values)}"))
            values.append(function.instruction_constant(k))
            work[out[0]] = symbols[-1]
        elif op == ca.OP_INPUT:
            work[out[0]] = inputs[arg[0]].nz[arg[1]]
        elif op == ca.OP_OUTPUT:
            outputs[out[0]].nz[out[1]] = work[arg[0]]
        elif op == ca.OP_CALL:
            return None
        elif len(arg) > 1 and arg[1] >= 0:
            work[out[0]] = ca.SX.binary(op, work[arg[0]], work[arg[1]])
        else:
            work[out[0]] = ca.SX.unary(op, work[arg[0]])
    lifted = ca.Function(f"{function.name()}_lifted", [*inputs, ca.vertcat(*symbols)],
                         outputs, [*function.name_in(), "constants"], function.name_out())
    return lifted, np.array(values, dtype=float)


def with_derivatives(function, fixed=()):
    """The companions of ``function`` that give its compiled form first and second
    derivatives (see :func:`compiled`).

    Built in SX like CasADi's own ``jacobian()``, ``reverse(1)`` and
    ``reverse(1).jacobian()``, except that the inputs listed in ``fixed`` (the constants of
    :func:`lift_constants`, say) are not differentiated: their blocks are structurally zero,
    which spares the Jacobians thousands of columns that no caller asks for.

    Parameters
    ----------
    function : casadi.Function
        An SX function with dense inputs.
    fixed : sequence of int, optional
        Inputs held constant.

    Returns
    -------
    tuple of casadi.Function
        ``(jac_<name>, adj1_<name>, jac_adj1_<name>)``. With these in its library, a compiled
        function's forward derivatives come from ``jac_<name>``, its reverse ones from
        ``adj1_<name>`` (with the option ``jac_penalty = -1``), and the derivatives of those
        (an optimiser's exact Hessian) from ``jac_adj1_<name>``.

    Examples
    --------
    >>> import casadi as ca
    >>> x, c = ca.SX.sym("x", 2), ca.SX.sym("c")
    >>> f = ca.Function("doc_f", [x, c], [c * x[0] * x[1]], ["x", "c"], ["y"])
    >>> [g.name() for g in with_derivatives(f, fixed=(1,))]
    ['jac_doc_f', 'adj1_doc_f', 'jac_adj1_doc_f']
    """
    import casadi as ca
    import numpy as np

    free = _free_inputs(function, fixed)
    name, n_in = function.name(), function.n_in()
    jac, inputs, outs, z, stacked, jz = _jacobian_parts(function, free)
    out_names = [f"out_{o}" for o in function.name_out()]
    seeds = [ca.SX.sym(f"adj_{o}", function.sparsity_out(k))
             for k, o in enumerate(function.name_out())]
    weighted = ca.dot(ca.vertcat(*[ca.vec(seed) for seed in seeds]), stacked)
    gradient = ca.gradient(weighted, z)                  # reverse mode: one sweep
    offsets = np.cumsum([0] + [inputs[k].numel() for k in free])
    span = dict(zip(free, zip(offsets[:-1], offsets[1:])))
    sensitivities = [ca.reshape(ca.densify(gradient[int(span[k][0]):int(span[k][1])]),
                                inputs[k].shape) if k in free else ca.SX.zeros(inputs[k].shape)
                     for k in range(n_in)]
    adj_in = inputs + outs + seeds
    adj_in_names = function.name_in() + out_names + [f"adj_{o}" for o in function.name_out()]
    adj_out_names = [f"adj_{i}" for i in function.name_in()]
    adj = ca.Function(f"adj1_{name}", adj_in, sensitivities, adj_in_names, adj_out_names,
                      {"cse": True})
    # the sensitivities' Jacobian: the Lagrangian's Hessian in the free inputs, and the
    # transposed Jacobian in the seeds (the same expressions as jac_<name>'s)
    hessian, columns = ca.hessian(weighted, z)[0], z.numel() + stacked.numel()
    rows = [ca.horzcat(hessian[int(span[k][0]):int(span[k][1]), :],
                       jz.T[int(span[k][0]):int(span[k][1]), :]) if k in free
            else ca.SX(inputs[k].numel(), columns) for k in range(n_in)]
    adj_outs = [ca.SX.sym(f"out_{o}", adj.sparsity_out(k)) for k, o in enumerate(adj_out_names)]
    jac_adj = _jacobian_function(
        f"jac_adj1_{name}", adj_in + adj_outs, adj_in_names + [f"out_{o}" for o in adj_out_names],
        adj_out_names, free + [len(inputs) + len(outs) + j for j in range(len(seeds))],
        ca.vertcat(*rows), [inputs[k].numel() for k in range(n_in)])
    return jac, adj, jac_adj


def jacobian_companion(function, fixed=()):
    """``jac_<name>``, the first companion of :func:`with_derivatives` alone: enough for a
    compiled function whose callers take first derivatives only (an integrator's Newton
    iterations).

    Parameters
    ----------
    function : casadi.Function
        An SX function with dense inputs.
    fixed : sequence of int, optional
        Inputs held constant: their Jacobian blocks are structurally zero. Default none.

    Returns
    -------
    casadi.Function
        ``jac_<name>``, with CasADi's ``jacobian()`` signature.

    Examples
    --------
    >>> import casadi as ca
    >>> x, c = ca.SX.sym("x", 2), ca.SX.sym("c")
    >>> f = ca.Function("doc_g", [x, c], [c * x[0] * x[1]], ["x", "c"], ["y"])
    >>> jacobian_companion(f, fixed=(1,)).name_out()
    ['jac_y_x', 'jac_y_c']
    """
    return _jacobian_parts(function, _free_inputs(function, fixed, "jacobian_companion"))[0]


def _jacobian_parts(function, free: list) -> tuple:
    """``jac_<name>`` of ``function`` in its ``free`` inputs, with what it is made of: the
    symbolic inputs, the nominal outputs' symbols, the stacked free inputs, the stacked
    outputs and their Jacobian."""
    import casadi as ca

    inputs = function.sx_in()
    outputs = function.call(inputs)
    out_names = [f"out_{o}" for o in function.name_out()]
    outs = [ca.SX.sym(o, function.sparsity_out(k)) for k, o in enumerate(out_names)]
    z = ca.vertcat(*[ca.vec(inputs[k]) for k in free])
    stacked = ca.vertcat(*[ca.vec(o) for o in outputs])
    jz = ca.jacobian(stacked, z)
    jac = _jacobian_function(f"jac_{function.name()}", inputs + outs,
                             function.name_in() + out_names, function.name_out(), free, jz,
                             [o.numel() for o in outputs])
    return jac, inputs, outs, z, stacked, jz


def _free_inputs(function, fixed, owner: str = "with_derivatives") -> list:
    """The inputs of ``function`` that :func:`with_derivatives` (or ``owner``)
    differentiates: all but ``fixed``, after checking both."""
    import casadi as ca

    from ..model.checks import check_integer
    from ..model.errors import InputTypeError, InputValueError

    if not isinstance(function, ca.Function) or not function.is_a("SXFunction"):
        raise InputTypeError(f"{owner}: function must be an SX casadi.Function; got "
                             f"{type(function).__name__}")
    n_in = function.n_in()
    if not all(function.sparsity_in(k).is_dense() for k in range(n_in)):
        raise InputValueError(f"{owner}: every input of function must be dense")
    if isinstance(fixed, (str, bytes)) or not hasattr(fixed, "__iter__"):
        raise InputTypeError(f"{owner}: fixed must be a sequence of input indices; "
                             f"got {fixed!r}")
    held = {check_integer(owner, "fixed", k, minimum=0, maximum=n_in - 1)
            for k in fixed}
    return [k for k in range(n_in) if k not in held]


def _jacobian_function(name: str, inputs: list, in_names: list, out_names: list, free: list,
                       whole, heights: list):
    """``name(*inputs) -> jac_<o>_<i>`` for every output ``o`` (of ``heights`` entries) and
    every input ``i`` but the trailing nominal outputs (CasADi's Jacobian signature): the
    blocks of ``whole``, the Jacobian of the stacked outputs in the stacked ``free`` inputs,
    and structurally zero in the other inputs."""
    import casadi as ca
    import numpy as np

    differentiated = len(inputs) - len(out_names)        # the rest are the nominal outputs
    rows = np.cumsum([0] + list(heights))
    columns = dict(zip(free, np.cumsum([0] + [inputs[k].numel() for k in free])))
    blocks, names = [], []
    for j, out_name in enumerate(out_names):
        for k, in_name in enumerate(in_names[:differentiated]):
            width = inputs[k].numel()
            blocks.append(whole[int(rows[j]):int(rows[j + 1]),
                                int(columns[k]):int(columns[k]) + width] if k in free
                          else ca.SX(int(rows[j + 1] - rows[j]), width))
            names.append(f"jac_{out_name}_{in_name}")
    # common subexpressions eliminated: a fifth fewer instructions in the exact model's
    # Lagrangian Hessian, whose forward-over-reverse sweeps repeat many products
    return ca.Function(name, inputs, blocks, in_names, names, {"cse": True})


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
    """The function in ``library``, or None when the file is absent or does not load (it is
    then removed, to be compiled again)."""
    import casadi as ca

    if not library.is_file():
        return None
    try:
        function = ca.external(name, str(library), options or {})
    except RuntimeError:
        with contextlib.suppress(OSError):
            library.unlink()
        return None
    STATS["loads"] += 1
    _ORIGIN[id(function)] = (function, library, name)
    return function


def entry_point(function):
    """``(address, keep)`` of a function loaded from the cache (:func:`compiled`): the
    address of its C entry point (CasADi's signature ``int f(const double **arg, double
    **res, casadi_int *iw, double *w, int mem)``) and an object to keep alive as long as
    the address is used; None for a function not loaded from the cache."""
    import ctypes

    origin = _ORIGIN.get(id(function))
    if origin is None or origin[0] is not function:
        return None
    try:                # the library CasADi has open: the same copy
        library = ctypes.CDLL(str(origin[1]))
        return ctypes.cast(getattr(library, origin[2]), ctypes.c_void_p).value, library
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
            print(f"flexctl: compiling {label} ({len(source) // 1024} kB of C; once, kept in "
                  f"{folder}) ...", end="", file=sys.stderr, flush=True)
            _, errors = process.communicate()
            print(f" {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
        if process.returncode != 0:
            raise RuntimeError(f"{tool[0]} exited with {process.returncode}: "
                               f"{errors.strip()[-300:]}")
        os.replace(out_path, library)
        STATS["compiles"] += 1
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
    folder = cache_dir() / _SUBDIR
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
    folder = cache_dir() / _SUBDIR
    every = [f for f in folder.iterdir() if f.is_file()] if folder.is_dir() else []
    return CacheInfo(directory=cache_dir(), entries=len(files),
                     size=sum(_size(f) for f in every), compiler=what)


def _size(path: Path) -> int:
    """Bytes of ``path``, 0 if another process removed it meanwhile."""
    try:
        return path.stat().st_size
    except OSError:
        return 0


def clear_cache() -> int:
    """Remove every compiled library (and leftover build and lock files); return how many
    libraries were removed. Functions already loaded in this process stay usable."""
    folder = cache_dir() / _SUBDIR
    removed = len(_libraries())
    if folder.is_dir():
        shutil.rmtree(folder, ignore_errors=True)
    _LOADED.clear()
    return removed
