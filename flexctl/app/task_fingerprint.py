"""A sweep task's fingerprint: what it computes, as a SHA-256 that every process agrees on.

A sweep store (:mod:`flexctl.app.sweep_store`) keeps the fingerprint of the task that wrote
it and refuses to resume with another: two lambdas, or a function redefined under the same
name, share a name but not a fingerprint.

What counts, for each kind of task:

- a function (a lambda too): its module and qualified name; its code (bytecode, constants
  with nested code objects, the names and local variable names it uses, argument counts); its
  default arguments; the contents of its closure cells; and the values of the globals it
  names (see below);
- a callable object (a frozen dataclass such as :class:`~flexctl.app.sweep.SceneTask`): its
  class's module and qualified name, the fingerprint of the class's ``__call__`` and the
  values of its fields (``dataclasses.fields``; the public attributes of other objects);
- a ``functools.partial``: its function, arguments and keywords; a bound method: its function
  and the object it is bound to.

Values are taken whole: numbers, strings and bytes by value, tuples, lists, dicts and sets
item by item (sets and dicts in a sorted order), NumPy arrays by dtype, shape and bytes,
dataclasses by their fields, functions by their code, classes and modules by name. A global
the task names counts by value when it cannot change under it (a number, a string, a tuple or
frozenset of them, a frozen dataclass, an array, a function, a class, a module) and by its
type alone otherwise (a dict or list a task may fill as a cache would otherwise change the
fingerprint of the same task). A global function of the task's own module is fingerprinted
with its code (a helper the task calls), one of another module by its name only: the
fingerprint sees the task and its module, not the library code it calls.

Notes
-----
The digest is built from a canonical encoding (type tags and lengths before every item), never
from ``id()``, ``hash()`` or memory addresses (`` at 0x...`` is removed from a repr), so the
same task gives the same fingerprint in any process. The bytecode is that of the running
Python: a resume under another Python minor version sees another fingerprint, and so does a
task whose docstring changed (a function's docstring is one of its constants).

Examples
--------
>>> fingerprint = task_fingerprint(lambda x: {"y": 2 * x})
>>> len(fingerprint), fingerprint == task_fingerprint(lambda x: {"y": 3 * x})
(64, False)
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import re
import types

import numpy as np

from ..model.errors import InputTypeError

__all__ = ["task_fingerprint"]

#: Nesting depth past which a value counts by its type alone (deep object graphs).
MAX_DEPTH = 12
#: The part of a default repr that differs between processes.
_ADDRESS = re.compile(r"\s+at 0x[0-9a-fA-F]+")
_SCALARS = (type(None), bool, int, float, complex, str, bytes)


def task_fingerprint(task, *inputs) -> str:
    """The SHA-256 of what ``task`` computes (see the module docstring).

    Parameters
    ----------
    task : callable
        A function, lambda, callable object, ``functools.partial`` or bound method.
    *inputs : object
        Further values the task's results depend on that the task does not hold (settings
        passed to it separately), taken whole like its fields.

    Returns
    -------
    str
        64 hexadecimal digits; equal for the same code and inputs in any process.

    Raises
    ------
    InputTypeError
        When ``task`` is not callable.
    """
    if not callable(task):
        raise InputTypeError(f"task_fingerprint task must be callable; got "
                             f"{type(task).__name__}")
    digest = hashlib.sha256()
    encoder = _Encoder(digest)
    encoder.value(task, 0)
    encoder.value(inputs, 0)
    return digest.hexdigest()


def _qualified(obj) -> str:
    return f"{getattr(obj, '__module__', None)}.{getattr(obj, '__qualname__', None)}"


def _stable_repr(value) -> str:
    """``repr(value)`` without memory addresses; the type's name when repr fails."""
    try:
        text = repr(value)
    except Exception:
        return f"<{_qualified(type(value))}>"
    return _ADDRESS.sub("", text)


def _code_objects(code: types.CodeType):
    """``code`` and the code objects nested in its constants (inner functions, lambdas)."""
    yield code
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            yield from _code_objects(const)


def _class_call(kind: type):
    """The ``__call__`` a class defines in Python (from its MRO), or None."""
    for klass in kind.__mro__:
        call = vars(klass).get("__call__")
        if call is not None:
            return call if isinstance(call, types.FunctionType) else None
    return None


def _is_constant_global(value) -> bool:
    """True for a global whose value cannot change under a task that names it."""
    if isinstance(value, _SCALARS + (np.ndarray, np.generic, types.FunctionType,
                                     types.BuiltinFunctionType, types.ModuleType, type)):
        return True
    if isinstance(value, (tuple, frozenset)):
        return all(_is_constant_global(v) for v in value)
    return (dataclasses.is_dataclass(value)
            and type(value).__dataclass_params__.frozen)


class _Encoder:
    """Feeds the canonical encoding of values to a hash (one per fingerprint)."""

    def __init__(self, digest):
        self.digest = digest
        self.functions = set()       # ids of the functions whose code is in already
        self.active = set()          # ids of the containers on the current path (cycles)

    def put(self, tag: str, payload) -> None:
        data = payload if isinstance(payload, bytes) else str(payload).encode("utf-8",
                                                                             "surrogatepass")
        self.digest.update(f"{tag}:{len(data)}:".encode())
        self.digest.update(data)

    def value(self, value, depth: int) -> None:
        """Encode any value (the dispatch of the module docstring)."""
        if isinstance(value, _SCALARS):
            self.put(type(value).__name__, value if isinstance(value, bytes) else repr(value))
        elif isinstance(value, (np.ndarray, np.generic)):
            self.array(np.asarray(value), depth)
        elif isinstance(value, types.CodeType):
            self.code(value)
        elif isinstance(value, enum.Enum):
            self.put("enum", f"{_qualified(type(value))}.{value.name}")
        elif isinstance(value, types.ModuleType):
            self.put("module", value.__name__)
        elif isinstance(value, type):
            self.put("class", _qualified(value))
        elif isinstance(value, types.FunctionType):
            self.function(value, depth)
        elif depth >= MAX_DEPTH or id(value) in self.active:
            self.put("deep", _qualified(type(value)))
        else:
            self.active.add(id(value))
            try:
                self.compound(value, depth + 1)
            finally:
                self.active.discard(id(value))

    def compound(self, value, depth: int) -> None:
        """Containers, partials, methods and objects (``depth`` already counts this one)."""
        if isinstance(value, (tuple, list)):
            self.put(type(value).__name__, len(value))
            for item in value:
                self.value(item, depth)
        elif isinstance(value, dict):
            self.put("dict", len(value))
            for key, item in sorted(value.items(), key=lambda kv: self.sub(kv[0], depth)):
                self.value(key, depth)
                self.value(item, depth)
        elif isinstance(value, (set, frozenset)):
            self.put(type(value).__name__, "".join(sorted(self.sub(v, depth) for v in value)))
        elif isinstance(value, functools.partial):
            self.put("partial", _qualified(type(value)))
            self.value((value.func, value.args, value.keywords), depth)
        elif isinstance(value, types.MethodType):
            self.put("method", value.__func__.__name__)
            self.value((value.__func__, value.__self__), depth)
        else:
            self.instance(value, depth)

    def sub(self, value, depth: int) -> str:
        """The digest of one value alone (to sort the items of sets and dicts)."""
        inner = _Encoder(hashlib.sha256())
        inner.functions, inner.active = self.functions.copy(), self.active
        inner.value(value, depth)
        return inner.digest.hexdigest()

    def array(self, array: np.ndarray, depth: int) -> None:
        self.put("ndarray", f"{array.dtype.str}{array.shape}")
        if array.dtype.hasobject:             # its bytes are pointers: take the items
            for item in array.ravel().tolist():
                self.value(item, depth + 1)
        else:
            self.put("bytes", np.ascontiguousarray(array).tobytes())

    def instance(self, obj, depth: int) -> None:
        """An object: its class, its class's ``__call__`` and its fields or attributes."""
        kind = type(obj)
        self.put("object", _qualified(kind))
        call = _class_call(kind)
        if call is not None:
            self.function(call, depth)
        if dataclasses.is_dataclass(obj):
            fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
        elif isinstance(getattr(obj, "__dict__", None), dict):
            fields = {name: item for name, item in vars(obj).items()
                      if not name.startswith("_")
                      and not isinstance(getattr(kind, name, None), functools.cached_property)}
        else:
            self.put("repr", _stable_repr(obj))
            return
        self.put("fields", len(fields))
        for name in sorted(fields):
            self.put("field", name)
            self.value(fields[name], depth)

    def function(self, fn: types.FunctionType, depth: int) -> None:
        """A function: its name, and (the first time it is met) its code, defaults, closure
        and the globals it names."""
        self.put("function", _qualified(fn))
        if id(fn) in self.functions:          # its code is in already (recursion, reuse)
            return
        self.functions.add(id(fn))
        self.code(fn.__code__)
        self.value((fn.__defaults__, fn.__kwdefaults__), depth)
        cells = []
        for cell in fn.__closure__ or ():
            try:
                cells.append(cell.cell_contents)
            except ValueError:                # a cell not yet filled
                cells.append("<empty cell>")
        self.value(tuple(cells), depth)
        self.globals(fn, depth)

    def globals(self, fn: types.FunctionType, depth: int) -> None:
        """The globals ``fn`` (and the code nested in it) names, by value or by type."""
        names = sorted({name for code in _code_objects(fn.__code__) for name in code.co_names
                        if name in fn.__globals__})
        for name in names:
            value = fn.__globals__[name]
            self.put("global", name)
            if isinstance(value, types.FunctionType) and value.__module__ != fn.__module__:
                self.put("function", _qualified(value))      # library code: its name
            elif _is_constant_global(value):
                self.value(value, depth)
            else:
                self.put("mutable", _qualified(type(value)))

    def code(self, code: types.CodeType) -> None:
        """Bytecode, constants (nested code included), names and argument counts."""
        self.put("code", code.co_code)
        self.put("names", ",".join(code.co_names))
        self.put("varnames", ",".join(code.co_varnames))
        self.put("counts", f"{code.co_argcount},{code.co_posonlyargcount},"
                           f"{code.co_kwonlyargcount}")
        self.put("consts", len(code.co_consts))
        for const in code.co_consts:
            self.value(const, 0)
