"""What :func:`flexctl.simulate` is given: its arguments checked, its inputs' values checked.

Every check raises :class:`~flexctl.model.errors.InputTypeError` (a ``TypeError``) for a wrong
type and :class:`~flexctl.model.errors.InputValueError` (a ``ValueError``) for a wrong value,
naming the argument, the rule and the value received. The torque, controller and hub-motion
functions are wrapped so that a value they return is checked where it is used: one real, finite
number, or an error naming the function and the time (never a NaN deep inside the integrator).

Examples
--------
>>> from flexctl.sim.inputs import check_time, time_function
>>> check_time("t_final", 3)
3.0
>>> check_time("t_final", "3")
Traceback (most recent call last):
...
flexctl.model.errors.InputTypeError: t_final must be a real number (s); got '3' of type str
>>> torque = time_function(lambda t: float("nan"), "torque")
>>> torque(0.5, None)
Traceback (most recent call last):
...
flexctl.model.errors.InputValueError: torque returned nan at t = 0.5 s; it must be finite (N m)
"""

from __future__ import annotations

import inspect
import math
from numbers import Real

import numpy as np

from ..model.errors import InputTypeError, InputValueError

__all__ = ["MAX_OUTPUT_SAMPLES", "check_time", "check_rtol", "check_method", "as_vector",
           "output_grid", "input_value", "time_function", "jacobian_frequency"]

#: Most output samples a run may ask for (t_final / output_step + 1): 1e6 samples of a 6-mode
#: model are 100 MB of states and a 300 MB CSV file; beyond that the grid is a mistake.
MAX_OUTPUT_SAMPLES = 1_000_000


def _type_error(name, value, what):
    return InputTypeError(f"{name} must be {what}; got {value!r} of type {type(value).__name__}")


def check_time(name: str, value, *, allow_inf: bool = False) -> float:
    """``value`` as a positive time in s (finite unless ``allow_inf``)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise _type_error(name, value, "a real number (s)")
    value = float(value)
    if not (value > 0.0 and (math.isfinite(value) or allow_inf)):
        rule = "positive" if allow_inf else "a positive finite time (s)"
        raise InputValueError(f"{name} must be {rule}; got {value!r}")
    return value


def check_rtol(value) -> float:
    """A relative tolerance in [1e-14, 1)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise _type_error("rtol", value, "a real number")
    value = float(value)
    if not (math.isfinite(value) and 1e-14 <= value < 1.0):
        raise InputValueError(f"rtol must lie in [1e-14, 1); got {value!r}")
    return value


def check_method(value, methods) -> str:
    """One of ``methods``."""
    if not isinstance(value, str):
        raise _type_error("method", value, f"one of {', '.join(methods)}")
    if value not in methods:
        raise InputValueError(f"method must be one of {', '.join(methods)}; got {value!r}")
    return value


def as_vector(name: str, value, what: str) -> np.ndarray:
    """``value`` as a float array (any shape); a ``TypeError`` naming it if it is not numbers."""
    if isinstance(value, (str, bytes)):
        raise _type_error(name, value, what)
    try:
        return np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise _type_error(name, value, what) from None


def output_grid(t_final: float, step: float) -> np.ndarray:
    """Output times ``0, step, 2 step, ... , t_final``, s; refused before allocating when
    there would be more than :data:`MAX_OUTPUT_SAMPLES`."""
    n_samples = t_final / step + 1.0
    if not n_samples <= MAX_OUTPUT_SAMPLES:     # inf for a subnormal step
        raise InputValueError(
            f"output_step {step:g} s over t_final {t_final:g} s asks for {n_samples:.3g} "
            f"output samples, more than the limit {MAX_OUTPUT_SAMPLES:.3g}: raise output_step "
            "or shorten t_final")
    grid = np.arange(0.0, t_final + 0.5 * step, step)
    grid = grid[grid <= t_final]
    return grid if grid[-1] >= t_final else np.append(grid, t_final)


def input_value(name: str, value, t: float, unit: str = "N m") -> float:
    """The value an input function returned, as one finite float; else an error naming it."""
    if type(value) is not float:
        if value is None or isinstance(value, (bool, np.bool_, str, bytes)):
            raise InputTypeError(f"{name} must return a real number ({unit}); got {value!r} "
                                 f"at t = {t:.6g} s")
        if isinstance(value, Real):
            value = float(value)
        else:
            try:
                array = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise InputTypeError(f"{name} must return a real number ({unit}); got "
                                     f"{type(value).__name__} at t = {t:.6g} s") from None
            if array.size != 1:
                raise InputTypeError(f"{name} must return one real number ({unit}); got an "
                                     f"array of shape {array.shape} at t = {t:.6g} s")
            value = float(array.reshape(()))
    if not math.isfinite(value):
        raise InputValueError(f"{name} returned {value!r} at t = {t:.6g} s; it must be finite "
                              f"({unit})")
    return value


def _required_positional(func) -> int | None:
    """Number of arguments ``func`` needs, or None when its signature cannot be read."""
    try:
        params = inspect.signature(func).parameters.values()
    except (TypeError, ValueError):
        return None
    if any(p.kind is p.KEYWORD_ONLY and p.default is p.empty for p in params):
        return -1
    return sum(1 for p in params if p.default is p.empty
               and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD))


def time_function(func, name: str):
    """Wrap ``func(t)`` or ``func(t, x)`` as ``g(t, x)`` whose value is checked
    (:func:`input_value`)."""
    if not callable(func):
        raise InputTypeError(f"{name} must be callable as {name}(t) or {name}(t, x); "
                             f"got {type(func).__name__}")
    n_required = _required_positional(func)
    if n_required is not None and not 0 <= n_required <= 2:
        what = ("a required keyword-only argument" if n_required < 0
                else f"{n_required} required arguments")
        raise InputTypeError(f"{name} must be callable as {name}(t) or {name}(t, x); "
                             f"got {getattr(func, '__name__', type(func).__name__)} with {what}")
    if n_required == 2:
        return lambda t, x: input_value(name, func(t, x), t)
    return lambda t, x: input_value(name, func(t), t)


def jacobian_frequency(rhs, t: float, y: np.ndarray, scale: np.ndarray) -> float:
    """Largest ``|eigenvalue|`` of ``d rhs / d y`` at ``(t, y)``, 1/s (finite differences).

    For a closed loop this is the fastest pole a controller's gains make, which bounds the
    step of an explicit method as the plant's fastest mode does.
    """
    y = np.asarray(y, dtype=float)
    f0 = np.asarray(rhs(t, y), dtype=float)
    jac = np.empty((f0.size, y.size))
    for k in range(y.size):
        h = 1e-6 * float(scale[k])
        shifted = y.copy()
        shifted[k] += h
        jac[:, k] = (np.asarray(rhs(t, shifted), dtype=float) - f0) / h
    if not np.all(np.isfinite(jac)):
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(jac)))) if jac.size else 0.0
