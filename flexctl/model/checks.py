"""The one vocabulary of argument checks, for flexctl and controllers alike.

Every check names the input as ``owner.name`` (e.g. ``lqr.gain``, ``nmpc.horizon``; the
scene's field path where the input comes from a scene), states the rule and shows the value,
and raises :class:`~flexctl.model.errors.InputTypeError` (a ``TypeError``) for an input of the
wrong type and :class:`~flexctl.model.errors.InputValueError` (a ``ValueError``) for a wrong
value. A NaN or an infinity is a wrong value unless a check says otherwise.

Examples
--------
>>> from flexctl.model.checks import check_integer, check_real
>>> check_real("pd", "kp", 2)
2.0
>>> check_integer("nmpc", "horizon", 2.5, minimum=1)
Traceback (most recent call last):
...
flexctl.model.errors.InputTypeError: nmpc.horizon must be an integer >= 1; got 2.5 of type float
"""

from __future__ import annotations

import dataclasses
import math
import reprlib
from numbers import Integral, Real

import numpy as np

from .errors import InputTypeError, InputValueError

__all__ = ["label", "check_real", "check_integer", "check_choice", "check_instance",
           "check_array", "check_direction", "check_quaternion", "check_counts", "KeywordOnly"]


def label(owner: str, name: str) -> str:
    """``owner.name``, or ``name`` alone for an empty owner.

    Parameters
    ----------
    owner : str
        Who takes the input (``"lqr"``, a scene table's key), or ``""``.
    name : str
        The input's name.
    """
    return f"{owner}.{name}" if owner else name


def check_real(owner: str, name: str, value, *, minimum: float | None = None,
               strict: bool = False, maximum: float | None = None,
               optional: bool = False, infinite: bool = False) -> float | None:
    """A finite real number within bounds, as float (``None`` passes when ``optional``;
    an infinity within the bounds when ``infinite``).

    Raises ``TypeError`` for a non-number (bool included) and ``ValueError`` naming
    ``owner.name``, the rule and the value for NaN, infinity or a value out of bounds.

    Parameters
    ----------
    owner : str
        Who takes the input (``"lqr"``, a scene table's key), or ``""``: the messages name the
        input ``owner.name``.
    name : str
        The input's name.
    value : object
        The value to check.
    minimum : float, optional
        Lower bound, inclusive unless ``strict``; default none.
    strict : bool, optional
        Make ``minimum`` exclusive. Default False.
    maximum : float, optional
        Upper bound, inclusive; default none.
    optional : bool, optional
        Let ``None`` pass (returned as ``None``). Default False.
    infinite : bool, optional
        Let an infinity within the bounds pass. Default False.
    """
    if value is None and optional:
        return None
    where = label(owner, name)
    if isinstance(value, bool) or not isinstance(value, Real):
        raise InputTypeError(f"{where} must be a real number; got {value!r} of type "
                             f"{type(value).__name__}")
    rule = "a number (infinity allowed)" if infinite else "finite"
    if minimum is not None:
        rule += f" and {'>' if strict else '>='} {minimum:g}"
    if maximum is not None:
        rule += f" and <= {maximum:g}"
    try:
        value = float(value)
    except OverflowError:       # an int beyond the float range, e.g. 10**400
        exponent = int(abs(int(value)).bit_length() * math.log10(2.0))
        raise InputValueError(f"{where} must be {rule}; got a number of about "
                              f"1e{exponent}, beyond the float range") from None
    ok = not math.isnan(value) if infinite else math.isfinite(value)
    if ok and minimum is not None:
        ok = value > minimum if strict else value >= minimum
    if ok and maximum is not None:
        ok = value <= maximum
    if not ok:
        raise InputValueError(f"{where} must be {rule}; got {value!r}")
    return value


def check_integer(owner: str, name: str, value, *, minimum: int | None = None,
                  maximum: int | None = None) -> int:
    """An integer (not a bool, not a float) within ``[minimum, maximum]``, as int.

    Parameters
    ----------
    owner : str
        Who takes the input (``"lqr"``, a scene table's key), or ``""``: the messages name the
        input ``owner.name``.
    name : str
        The input's name.
    value : object
        The value to check.
    minimum, maximum : int, optional
        Inclusive bounds; default none.
    """
    where = label(owner, name)
    rule = "an integer"
    if minimum is not None and maximum is not None:
        rule += f" in [{minimum}, {maximum}]"
    elif minimum is not None:
        rule += f" >= {minimum}"
    elif maximum is not None:
        rule += f" <= {maximum}"
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise InputTypeError(f"{where} must be {rule}; got {value!r} of type "
                             f"{type(value).__name__}")
    value = int(value)
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        shown = repr(value) if len(repr(value)) <= 30 else \
            f"an integer of {len(str(abs(value)))} digits"
        raise InputValueError(f"{where} must be {rule}; got {shown}")
    return value


def check_choice(owner: str, name: str, value, choices) -> str:
    """One of the strings ``choices``.

    Parameters
    ----------
    owner : str
        Who takes the input (``"lqr"``, a scene table's key), or ``""``: the messages name the
        input ``owner.name``.
    name : str
        The input's name.
    value : object
        The value to check.
    choices : sequence of str
        The strings allowed.
    """
    where, listed = label(owner, name), ", ".join(map(repr, choices))
    if not isinstance(value, str):
        raise InputTypeError(f"{where} must be one of {listed}; got {value!r} of type "
                             f"{type(value).__name__}")
    if value not in choices:
        raise InputValueError(f"{where} must be one of {listed}; got {value!r}")
    return value


def check_instance(owner: str, name: str, value, kind, what: str | None = None):
    """``value`` itself when it is an instance of ``kind``.

    Parameters
    ----------
    owner : str
        Who takes the input (``"lqr"``, a scene table's key), or ``""``: the messages name the
        input ``owner.name``.
    name : str
        The input's name.
    value : object
        The value to check.
    kind : type or tuple of type
        The types allowed.
    what : str, optional
        What the message calls the expected type; default the type names joined by ``or``.
    """
    if not isinstance(value, kind):
        what = what or (kind.__name__ if isinstance(kind, type)
                        else " or ".join(k.__name__ for k in kind))
        raise InputTypeError(f"{label(owner, name)} must be a {what}; got "
                             f"{type(value).__name__}")
    return value


def check_array(owner: str, name: str, value, *, shape: tuple | None = None,
                finite: bool = True, minimum: float | None = None) -> np.ndarray:
    """A read-only float array of the given ``shape``.

    Raises ``TypeError`` when ``value`` is not numbers (strings, objects, ragged lists) and
    ``ValueError`` for a wrong shape, a NaN or infinity (when ``finite``) or an entry below
    ``minimum``.

    Parameters
    ----------
    owner : str
        Who takes the input (``"lqr"``, a scene table's key), or ``""``: the messages name the
        input ``owner.name``.
    name : str
        The input's name.
    value : array_like
        The value to check.
    shape : tuple of (int or None), optional
        Shape required; a ``None`` entry matches any size. Default: any shape.
    finite : bool, optional
        Refuse NaN and infinities. Default True.
    minimum : float, optional
        Smallest entry allowed; default none.
    """
    where = label(owner, name)
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputTypeError(f"{where} must be an array of real numbers; got "
                             f"{type(value).__name__} {value!r:.80}") from None
    if shape is not None and (array.ndim != len(shape) or any(
            want is not None and want != got for want, got in zip(shape, array.shape))):
        wanted = "(" + ", ".join("any" if s is None else str(s) for s in shape) + \
            ("," if len(shape) == 1 else "") + ")"
        raise InputValueError(f"{where} must have shape {wanted}; got shape {array.shape}")
    if finite and not np.all(np.isfinite(array)):
        raise InputValueError(f"{where} must be finite; got {array!r:.120}")
    if minimum is not None and np.any(array < minimum):
        raise InputValueError(f"{where} must be >= {minimum:g}; got {array!r:.120}")
    array.setflags(write=False)
    return array


class KeywordOnly:
    """Base of the keyword-only parameter dataclasses (``Hub``, ``Beam``, ...): a positional
    call is refused with an :class:`~flexctl.model.errors.InputTypeError` that shows the
    keyword form, where Python would only say how many arguments it takes.

    ``__new__`` runs before the dataclass's generated ``__init__``, so the check sits in one
    place for every subclass and leaves the dataclass machinery (``dataclasses.replace``,
    copying, pickling, which call by keyword or with no arguments) as it is.

    Parameters
    ----------
    *args
        Positional arguments: refused (any one raises the ``InputTypeError``).
    **kwargs
        The subclass's fields by name, passed on to its dataclass ``__init__``.

    Examples
    --------
    >>> from flexctl import Hub
    >>> Hub(2.5, 0.1)
    Traceback (most recent call last):
    ...
    flexctl.model.errors.InputTypeError: Hub takes keyword arguments only: Hub(inertia=..., \
radius=..., friction=0.0, mass=0.0, support='pinned'); got 2 positional: 2.5, 0.1
    """

    __slots__ = ()

    def __new__(cls, *args, **kwargs):
        if args:
            raise InputTypeError(f"{cls.__name__} takes keyword arguments only: "
                                 f"{keyword_form(cls)}; got {len(args)} positional: "
                                 f"{', '.join(map(_short_repr, args))}")
        return super().__new__(cls)


def check_counts(owner: str, names: tuple, value, maximum: int) -> tuple:
    """One count per appendage from an int (each), a dict ``{name: int}`` or a sequence.

    Parameters
    ----------
    owner : str
        Who takes the counts, or ``""``: the messages name them ``owner.n_modes``.
    names : tuple of str
        The appendages' names, in order.
    value : int, dict or sequence of int
        One count for every appendage, one per appendage by name, or one per appendage in
        order.
    maximum : int
        The largest count.

    Returns
    -------
    tuple of int
    """
    where = label(owner, "n_modes")
    if isinstance(value, dict):
        unknown = [k for k in value if k not in names]
        if unknown:
            raise InputValueError(f"{where} names no appendage {unknown[0]!r}; the appendages "
                                  f"are {', '.join(map(repr, names))}")
        missing = [k for k in names if k not in value]
        if missing:
            raise InputValueError(f"{where} gives no count for appendage {missing[0]!r}: it "
                                  "must give the modes of every appendage")
        value = [value[k] for k in names]
    if isinstance(value, (list, tuple)):
        if len(value) != len(names):
            raise InputValueError(f"{where} must give one count per appendage ({len(names)}); "
                                  f"got {len(value)}")
        return tuple(check_integer(owner, f"n_modes[{name}]", v, minimum=1, maximum=maximum)
                     for name, v in zip(names, value))
    return (check_integer(owner, "n_modes", value, minimum=1, maximum=maximum),) * len(names)


def check_direction(owner: str, name: str, value) -> np.ndarray:
    """A read-only unit 3-vector along ``value`` (finite, not zero; scaled by its largest
    entry first, so that neither 1e308 nor 1e-300 entries lose the direction).

    Parameters
    ----------
    owner : str
        Who takes the input, or ``""``.
    name : str
        The input's name.
    value : array_like, shape (3,)
        The direction, any length.
    """
    vector = np.array(check_array(owner, name, value, shape=(3,)))
    largest = float(np.max(np.abs(vector)))
    if not largest > 0:
        raise InputValueError(f"{label(owner, name)} must be a non-zero 3-vector; got "
                              f"{vector.tolist()}")
    if not 1e-150 < largest < 1e150:        # its norm would overflow or underflow
        vector = vector / largest
    vector = vector / np.linalg.norm(vector)
    vector.setflags(write=False)
    return vector


def check_quaternion(owner: str, name: str, value) -> np.ndarray:
    """A read-only unit quaternion along ``value`` (scalar first; finite, not zero; scaled by
    its largest entry first, so that its norm neither overflows nor underflows).

    Parameters
    ----------
    owner : str
        Who takes the input, or ``""``.
    name : str
        The input's name.
    value : array_like, shape (4,)
        The quaternion, any length.
    """
    quaternion = np.array(check_array(owner, name, value, shape=(4,)))
    largest = float(np.max(np.abs(quaternion)))
    if not largest > 0:
        raise InputValueError(f"{label(owner, name)} must be a non-zero quaternion; got "
                              f"{quaternion.tolist()}")
    quaternion /= largest
    quaternion /= np.linalg.norm(quaternion)
    quaternion.setflags(write=False)
    return quaternion


def _short_repr(value) -> str:
    """``repr(value)`` cut to about 40 characters (an array, a long list)."""
    short = reprlib.Repr()
    short.maxstring = short.maxother = 40
    return short.repr(value)


def keyword_form(record) -> str:
    """``Name(required=..., optional=default, ...)``: how to call the dataclass ``record``
    (a default made by a factory shows as ``...`` too).

    Parameters
    ----------
    record : type
        A dataclass; its ``init`` fields without a leading underscore are shown, in order.
    """
    fields = [f for f in dataclasses.fields(record) if f.init and not f.name.startswith("_")]
    return f"{record.__name__}(" + ", ".join(
        f"{f.name}={'...' if f.default is dataclasses.MISSING else _short_repr(f.default)}"
        for f in fields) + ")"
