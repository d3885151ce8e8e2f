"""A CasADi function's numbers moved into an input, kept in the compile cache.

An SX function's constants (a model's matrices, quadrature weights, mode shapes) are written
into its generated C, so two models that differ only in numbers would compile two libraries.
:func:`lift_constants` moves them into a last input: the lifted function depends on the
structure alone and compiles once (:func:`flexctl.sim.compile_cache.compiled`); the
constants are passed at each call.

What it made is kept in the cache directory, by the SHA-256 of the serialisation of the
function it lifted and the CasADi version: the lifted function once per structure
(``lifted-<hash>.casadi``), the constants once per model (``lifted-<hash>.constants``, the
:data:`LIFTED_KEEP` most recently used). Reading them back costs a fifth of lifting. Both
are sealed files (:mod:`flexctl.sim.cache_files`): one whose digest does not match,, is lifted again, with one warning line saying why.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import threading
from pathlib import Path

from .cache_files import DamagedEntry, read_sealed, write_sealed
from .compile_cache import (FORMAT, SUBDIR, cache_dir, compiler, compiling_enabled, same_signature,
                            warn_damaged)

__all__ = ["lift_constants", "LIFTED_KEEP"]


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
        An SX function; the functions it calls (``never_inline``) are lifted too and stay
        calls, their constants in the same last input.
    max_instructions : int, optional
        Return None for a larger function (too slow to lift and compile).

    Returns
    -------
    (casadi.Function, ndarray) or None
        The lifted function (named ``<name>_lifted``) and the constants ``c`` it takes, or
        None when ``function`` is not an SX function, calls one that cannot be lifted or is
        too large.

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
        fingerprint = hashlib.sha256((function.serialize() + "\0" + ca.__version__ + FORMAT)
                                     .encode("utf-8")).hexdigest()[:32]
    except RuntimeError:                # pragma: no cover - every SX function serialises
        return _lift(function)
    with _LIFTED_LOCK:
        found = _LIFTED.get(fingerprint, _MISSING)
    if found is _MISSING:
        found = _read_lifted(fingerprint)
        if found is not None and not (
                found[0].name() == f"{function.name()}_lifted"
                and same_signature(found[0], function, extra_inputs=1)
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
#: (the oldest dropped beyond ``_LIFTED_SIZE``).
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
    return cache_dir() / SUBDIR / f"lifted-{fingerprint}.constants"


def _structure_path(structure: str) -> Path:
    return cache_dir() / SUBDIR / f"lifted-{structure}.casadi"


def _read_lifted(fingerprint: str):
    """``(lifted function, constants)`` stored for the function of ``fingerprint`` in the
    cache directory (where compiling is on), else None (absent, or damaged: one warning).

    A ``.constants`` file (sealed) holds the hash of the lifted function (one sealed
    ``.casadi`` file per structure, shared by every model of it) on its first line, then the
    constants as little-endian float64."""
    import numpy as np

    if not compiling_enabled() or compiler() is None:
        return None
    path = _constants_path(fingerprint)
    try:
        data = read_sealed(path)
        structure, values = data[:32].decode("ascii"), data[33:]
        if data[32:33] != b"\n" or len(values) % 8 or not structure.isalnum():
            raise DamagedEntry("its layout is not a structure's hash and float64 constants")
        lifted = _read_structure(structure)
        os.utime(path)                  # recently used: kept by _prune_constants
    except FileNotFoundError:
        return None
    except DamagedEntry as exc:
        warn_damaged(path, str(exc))
        return None
    except (OSError, UnicodeDecodeError) as exc:
        warn_damaged(path, f"it cannot be read ({exc})")
        return None
    if lifted is None:
        return None
    return lifted, np.frombuffer(values, dtype="<f8").astype(float)


def _read_structure(structure: str):
    """The lifted function stored under ``structure``, from this process's memory or its
    sealed file; None when absent or damaged (one warning)."""
    import casadi as ca

    with _LIFTED_LOCK:
        lifted = _STRUCTURES.get(structure)
    if lifted is not None:
        return lifted
    path = _structure_path(structure)
    try:
        lifted = ca.StringDeserializer(read_sealed(path).decode("ascii")).unpack()
        if not isinstance(lifted, ca.Function):
            raise DamagedEntry("it does not hold a CasADi function")
    except FileNotFoundError:
        return None
    except (DamagedEntry, UnicodeDecodeError, RuntimeError, OSError) as exc:
        warn_damaged(path, str(exc) or type(exc).__name__)
        return None
    with _LIFTED_LOCK:
        _STRUCTURES[structure] = lifted
        while len(_STRUCTURES) > _LIFTED_SIZE:
            _STRUCTURES.pop(next(iter(_STRUCTURES)))
    return lifted


def _write_lifted(fingerprint: str, lifted, values) -> None:
    """Store a lifted function (once per structure) and its constants (per model) beside the
    libraries, where compiling is on: reading them back costs a fifth of lifting again."""
    import casadi as ca
    import numpy as np

    if not compiling_enabled() or compiler() is None:
        return
    text = lifted.serialize()
    structure = hashlib.sha256((text + "\0" + ca.__version__ + FORMAT).encode("utf-8")
                               ).hexdigest()[:32]
    with contextlib.suppress(OSError):
        try:
            read_sealed(_structure_path(structure))
        except (OSError, DamagedEntry):      # absent or damaged: written (again)
            writer = ca.StringSerializer()
            writer.pack(lifted)
            write_sealed(_structure_path(structure), writer.encode().encode("ascii"))
        write_sealed(_constants_path(fingerprint), structure.encode("ascii") + b"\n"
                     + np.asarray(values, dtype="<f8").tobytes())
        _prune_constants()


def _prune_constants() -> None:
    """Remove the least recently used constants files beyond :data:`LIFTED_KEEP`."""
    folder = cache_dir() / SUBDIR
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
    """:func:`lift_constants`' work: ``(lifted, constants)`` or None (a call that cannot be
    lifted inside)."""
    import casadi as ca
    import numpy as np

    inputs = function.sx_in()
    outputs = [ca.SX.zeros(function.sparsity_out(k)) for k in range(function.n_out())]
    work, values, symbols = [None] * function.sz_w(), [], []
    calls, callees = None, {}
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
            calls = function.instructions_sx() if calls is None else calls
            callee = _lifted_callee(calls[k].which_function(), callees, symbols, values)
            if callee is None:
                return None
            _call(callee, work, arg, out)
        elif len(arg) > 1 and arg[1] >= 0:
            work[out[0]] = ca.SX.binary(op, work[arg[0]], work[arg[1]])
        else:
            work[out[0]] = ca.SX.unary(op, work[arg[0]])
    lifted = ca.Function(f"{function.name()}_lifted", [*inputs, ca.vertcat(*symbols)],
                         outputs, [*function.name_in(), "constants"], function.name_out())
    return lifted, np.array(values, dtype=float)


def _lifted_callee(callee, callees: dict, symbols: list, values: list):
    """``(function, constant symbols)``: a called function (``never_inline``) lifted, kept as a
    call, its constants appended to the caller's (once per callee, ``callees``), or None
    where it cannot be lifted."""
    import casadi as ca

    key = callee.serialize()
    if key not in callees:
        lifted = lift_constants(callee)
        if lifted is None:
            return None
        function, numbers = lifted
        args = function.sx_in()
        kept = ca.Function(function.name(), args, function(*args), function.name_in(),
                           function.name_out(), {"never_inline": True})
        own = [ca.SX.sym(f"c{len(values) + i}") for i in range(numbers.size)]
        symbols.extend(own)
        values.extend(float(v) for v in numbers)
        callees[key] = (kept, ca.vertcat(*own) if own else ca.SX(0, 1))
    return callees[key]


def _call(callee: tuple, work: list, arg, out) -> None:
    """The call of a lifted ``callee`` (``(function, constant symbols)``) on the work
    entries ``arg`` (every input's nonzeros in turn), its outputs' nonzeros into ``out``'s."""
    import casadi as ca

    function, constants = callee
    args, position = [], 0
    for i in range(function.n_in() - 1):
        count = function.nnz_in(i)
        entries = [work[j] if j >= 0 else ca.SX(0) for j in arg[position:position + count]]
        args.append(ca.SX(function.sparsity_in(i), ca.vertcat(*entries) if entries
                          else ca.SX(0, 1)))
        position += count
    results, position = function(*args, constants), 0
    for i, result in enumerate(results if isinstance(results, (list, tuple)) else [results]):
        for j in range(function.nnz_out(i)):
            if out[position + j] >= 0:
                work[out[position + j]] = result.nz[j]
        position += function.nnz_out(i)
