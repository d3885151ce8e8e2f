"""What :func:`flexctl.simulate` is given: its arguments checked, its inputs' values checked,
and a torque given as samples (:class:`SampledTorque`).

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
import weakref
from collections import OrderedDict
from dataclasses import KW_ONLY, dataclass
from functools import cached_property
from numbers import Real

import numpy as np

from ..model.errors import InputError, InputTypeError, InputValueError

__all__ = ["MAX_OUTPUT_SAMPLES", "check_time", "check_rtol", "check_method", "as_vector",
           "output_grid", "input_value", "time_function", "jacobian_frequency",
           "INTERPOLATIONS", "UNIFORM_RATIO", "SampledTorque", "sampled_torque",
           "interval_index", "lookup_grid", "check_breakpoints"]

#: Most output samples a run may ask for (t_final / output_step + 1): 1e6 samples of a 6-mode
#: model are 100 MB of states and a 300 MB CSV file; beyond that the grid is a mistake.
MAX_OUTPUT_SAMPLES = 1_000_000


def _type_error(name, value, what):
    return InputTypeError(f"{name} must be {what}; got {value!r} of type {type(value).__name__}")


def check_time(name: str, value, *, allow_inf: bool = False) -> float:
    """``value`` as a positive time in s (finite unless ``allow_inf``).

    Parameters
    ----------
    name : str
        The argument's name, for an error.
    value : float
        The time, s (a bool is refused).
    allow_inf : bool, optional
        Accept ``inf``. Default False.
    """
    if isinstance(value, bool) or not isinstance(value, Real):
        raise _type_error(name, value, "a real number (s)")
    value = float(value)
    if not (value > 0.0 and (math.isfinite(value) or allow_inf)):
        rule = "positive" if allow_inf else "a positive finite time (s)"
        raise InputValueError(f"{name} must be {rule}; got {value!r}")
    return value


def check_rtol(value) -> float:
    """A relative tolerance in [1e-14, 1).

    Parameters
    ----------
    value : float
        The ``rtol`` given.
    """
    if isinstance(value, bool) or not isinstance(value, Real):
        raise _type_error("rtol", value, "a real number")
    value = float(value)
    if not (math.isfinite(value) and 1e-14 <= value < 1.0):
        raise InputValueError(f"rtol must lie in [1e-14, 1); got {value!r}")
    return value


def check_method(value, methods) -> str:
    """One of ``methods``.

    Parameters
    ----------
    value : str
        The method asked for.
    methods : sequence of str
        The methods allowed (e.g. :data:`flexctl.sim.request.METHODS`).
    """
    if not isinstance(value, str):
        raise _type_error("method", value, f"one of {', '.join(methods)}")
    if value not in methods:
        raise InputValueError(f"method must be one of {', '.join(methods)}; got {value!r}")
    return value


def as_vector(name: str, value, what: str) -> np.ndarray:
    """``value`` as a float array (any shape); a ``TypeError`` naming it if it is not numbers.

    Parameters
    ----------
    name : str
        The argument's name, for an error.
    value : array_like
        Real numbers (not strings, not complex, not ragged).
    what : str
        What the argument must be, for an error (e.g. ``"an array of sample times (s)"``).
    """
    if isinstance(value, (str, bytes)):
        raise _type_error(name, value, what)
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):      # ragged nesting
        raise _type_error(name, value, what) from None
    if raw.dtype.kind == "c":            # float() would drop the imaginary part, and warn
        raise _type_error(name, value, what + " (real, not complex)")
    try:
        return np.array(raw, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise _type_error(name, value, what) from None


def output_grid(t_final: float, step: float) -> np.ndarray:
    """Output times ``0, step, 2 step, ... , t_final``, s; refused before allocating when
    there would be more than :data:`MAX_OUTPUT_SAMPLES`.

    Parameters
    ----------
    t_final : float
        End time, s (> 0); always the last output time.
    step : float
        Spacing of the output times, s (> 0).

    Returns
    -------
    ndarray, shape (P,)
    """
    with np.errstate(divide="ignore", over="ignore"):
        n_samples = np.float64(t_final) / np.float64(step) + 1.0 if step > 0.0 else np.inf
    if not n_samples <= MAX_OUTPUT_SAMPLES:     # inf for a subnormal step
        raise InputValueError(
            f"output_step {step:g} s over t_final {t_final:g} s asks for {n_samples:.3g} "
            f"output samples, more than the limit {MAX_OUTPUT_SAMPLES:.3g}: raise output_step "
            "or shorten t_final")
    grid = np.arange(0.0, t_final + 0.5 * step, step)
    grid = grid[grid <= t_final]
    return grid if grid[-1] >= t_final else np.append(grid, t_final)


def input_value(name: str, value, t: float, unit: str = "N m") -> float:
    """The value an input function returned, as one finite float; else an error naming it.

    Parameters
    ----------
    name : str
        The input, for an error (e.g. ``"torque"``, ``"hub_motion.rate"``).
    value : object
        What it returned: a real number or an array of one.
    t : float
        The time at which it was evaluated, s, for an error.
    unit : str, optional
        The value's unit, for an error. Default ``"N m"``.
    """
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


#: The signatures read, by the function's identity: ``{id: (weak reference, parameters)}``.
_SIGNATURES: dict = {}
_SIGNATURES_KEPT = 64


def _parameters(func):
    """The parameters of ``func``'s signature, a tuple, or None when it cannot be read; kept
    while the function object lives (a run reads its inputs' signatures several times)."""
    entry = _SIGNATURES.get(id(func))
    if entry is not None and entry[0]() is func:
        return entry[1]
    try:
        params = tuple(inspect.signature(func).parameters.values())
    except (TypeError, ValueError):
        params = None
    try:
        reference = weakref.ref(func)
    except TypeError:                   # not weakly referable: read again next time
        return params
    if len(_SIGNATURES) >= _SIGNATURES_KEPT:
        _SIGNATURES.clear()
    _SIGNATURES[id(func)] = (reference, params)
    return params


def required_positional(func) -> int | None:
    """Number of arguments ``func`` needs, or None when its signature cannot be read (-1
    when it needs a keyword-only argument).

    Parameters
    ----------
    func : callable
        A torque, hub motion or controller function.
    """
    params = _parameters(func)
    if params is None:
        return None
    if any(p.kind is p.KEYWORD_ONLY and p.default is p.empty for p in params):
        return -1
    return sum(1 for p in params if p.default is p.empty
               and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD))


def time_function(func, name: str):
    """Wrap ``func(t)`` or ``func(t, x)`` as ``g(t, x)`` whose value is checked
    (:func:`input_value`).

    Parameters
    ----------
    func : callable
        ``func(t)`` or ``func(t, x)``: ``t`` in s, ``x`` the plant state, shape (n,); it returns
        a number in N m. Its exceptions are raised as an ``InputValueError`` naming it and the
        time.
    name : str
        The input's name, for an error (e.g. ``"torque"``).
    """
    if not callable(func):
        raise InputTypeError(f"{name} must be callable as {name}(t) or {name}(t, x); "
                             f"got {type(func).__name__}")
    n_required = required_positional(func)
    if n_required is not None and not 0 <= n_required <= 2 or _takes_no_time(func):
        what = ("a required keyword-only argument" if n_required is not None and n_required < 0
                else "no argument" if n_required == 0
                else f"{n_required} required arguments")
        raise InputTypeError(f"{name} must be callable as {name}(t) or {name}(t, x); "
                             f"got {getattr(func, '__name__', type(func).__name__)} with {what}")
    if n_required == 2:
        return lambda t, x: input_value(name, _call(func, name, t, t, x), t)
    return lambda t, x: input_value(name, _call(func, name, t, t), t)


def _takes_no_time(func) -> bool:
    """True when ``func`` can take no positional argument at all (``lambda: 1.0``)."""
    params = _parameters(func)
    if params is None:
        return False
    return not any(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD, p.VAR_POSITIONAL)
                   for p in params)


def _call(func, name: str, t: float, *args):
    """``func(*args)``, its exceptions reported as the input's (naming it and the time) and
    numpy's floating-point warnings silenced: a value they would warn about is NaN or
    infinite, which :func:`input_value` names."""
    try:
        with np.errstate(all="ignore"):
            return func(*args)
    except InputError:
        raise
    except Exception as exc:        # whatever the user's function raised
        raise InputValueError(f"{name} raised {type(exc).__name__} at t = {t:.6g} s: "
                              f"{exc}") from exc


def jacobian_frequency(rhs, t: float, y: np.ndarray, scale: np.ndarray) -> float:
    """Largest ``|eigenvalue|`` of ``d rhs / d y`` at ``(t, y)``, 1/s (finite differences).

    For a closed loop this is the fastest pole a controller's gains make, which bounds the
    step of an explicit method as the plant's fastest mode does.

    Parameters
    ----------
    rhs : callable
        ``rhs(t, y) -> dy/dt``, shape (m,): a drive's right-hand side.
    t : float
        Time, s.
    y : ndarray, shape (m,)
        State at which the Jacobian is taken.
    scale : ndarray, shape (m,)
        Each state's physical size: state ``k`` is perturbed by ``1e-6 scale[k]``.

    Returns
    -------
    float
        ``inf`` where the Jacobian is not finite; 0 for an empty state.
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


# ---- a torque given as samples ---------------------------------------------------------
#: How a :class:`SampledTorque` fills the time between its samples, and the fewest samples
#: each needs (CasADi's cubic spline is not-a-knot, which takes four).
INTERPOLATIONS = {"hold": 2, "linear": 2, "spline": 4}
#: A sample grid counts as near-uniform, and bounds the integration step by its shortest
#: interval, when that interval is at least the mean one divided by this: then the bound
#: costs at most this many steps per sample.
UNIFORM_RATIO = 4.0


@dataclass(frozen=True, eq=False)
class SampledTorque:
    """Hub torque given as samples ``(times, values)``, as python-control users pass ``T``
    and ``U`` to ``input_output_response``.

    :func:`flexctl.simulate` takes the pair itself (``torque=(times, values)``, linear
    interpolation, python-control's) or this class for another interpolation. The torque has a
    CasADi form (:meth:`casadi`), so it runs on the compiled path.

    Parameters
    ----------
    times : array_like, shape (K,)
        Sample times, s: finite and strictly increasing.
    values : array_like, shape (K,) or (1, K)
        Torque at each sample time, N m: finite.
    interpolation : {"linear", "hold", "spline"}, keyword-only
        ``"linear"`` (default): straight lines between samples, as python-control does.
        ``"hold"``: each value held until the next sample time (a zero-order hold,
        right-continuous: ``values[k]`` on ``[times[k], times[k+1])``). ``"spline"``: the
        not-a-knot cubic spline through the samples (``casadi.interpolant("bspline")``, equal
        to ``scipy.interpolate.CubicSpline(times, values)``); needs 4 samples.

    Notes
    -----
    Outside ``[times[0], times[-1]]`` the torque is the first or last value (the time is
    clamped into the sampled range). :func:`flexctl.simulate` does not rely on this: it refuses
    samples that do not cover the run, ``times[0] <= 0`` and ``times[-1] >= t_final`` (a
    shortfall of rounding size, at most ``1e-9 t_final``, is allowed and holds the last value).

    The numpy form (``__call__``) is exactly the CasADi form, bit for bit: the same lookup
    and the same arithmetic for ``"hold"`` and ``"linear"``, the CasADi function itself for
    ``"spline"``.

    No integrator may step over a sample: a pulse one sample long after a quiet start would
    go unseen by steps grown long at rest. Every jump of a hold is a breakpoint
    (:attr:`breakpoints`): a step across it is wrong to first order in its length whatever
    the tolerance (the fixed-step RK4 missed by 3e-4 m on ``hub-beam-mass`` with three
    samples, CVODES by 50 times its tolerance). A line on a near-uniform grid (the shortest
    interval at least ``1 / UNIFORM_RATIO`` of the mean one) bounds every step by its
    shortest interval (:attr:`max_step`) and the integration goes straight through its kinks,
    resolving them by error control; otherwise it restarts at every sample. On the 2001
    samples of ``hub-beam-mass``'s 20 s push, restarting at every sample made a run 20 to 40
    times as long for the same error as the bounded step did (2 and 4 modes,
    ``benchmarks/bench_inputs.py``): each restart begins again at order 1 with a tiny step.

    Examples
    --------
    >>> from flexctl.sim.inputs import SampledTorque
    >>> push = SampledTorque([0.0, 1.0, 2.0], [0.0, 2.0, 0.0])
    >>> float(push(0.25)), float(push(5.0))
    (0.5, 0.0)
    >>> float(SampledTorque([0.0, 1.0, 2.0], [0.0, 2.0, 0.0], interpolation="hold")(1.5))
    2.0
    >>> SampledTorque([0.0, 1.0, 1.0], [0.0, 2.0, 0.0])
    Traceback (most recent call last):
    ...
    flexctl.model.errors.InputValueError: torque samples: times must be strictly increasing (s); got times[2] = 1.0 after times[1] = 1.0
    """

    times: np.ndarray
    values: np.ndarray
    _: KW_ONLY
    interpolation: str = "linear"

    def __post_init__(self):
        interpolation = self.interpolation
        if not isinstance(interpolation, str):
            raise _type_error("torque samples: interpolation", interpolation,
                              f"one of {', '.join(map(repr, INTERPOLATIONS))}")
        if interpolation not in INTERPOLATIONS:
            raise InputValueError(f"torque samples: interpolation must be one of "
                                  f"{', '.join(map(repr, INTERPOLATIONS))}; got "
                                  f"{interpolation!r}")
        times, values = _checked_samples(self.times, self.values, interpolation)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)

    # the CasADi functions are built once, on first use, and not pickled
    def __getstate__(self):
        return {"times": self.times, "values": self.values,
                "interpolation": self.interpolation}

    def __setstate__(self, state):
        for name, value in state.items():
            object.__setattr__(self, name, value)

    def __repr__(self):
        return (f"SampledTorque({self.times.size} samples over [{self.times[0]:g}, "
                f"{self.times[-1]:g}] s, interpolation={self.interpolation!r})")

    @property
    def max_step(self) -> float | None:
        """Longest step an integrator may take, s: the shortest sample interval, for a line or
        a spline on a near-uniform grid; None (restart at every sample instead) for a hold,
        whose jumps no step may straddle, and on an uneven grid."""
        if self.interpolation == "hold":
            return None
        shortest = float(np.min(np.diff(self.times)))
        span = float(self.times[-1] - self.times[0])
        return shortest if span <= UNIFORM_RATIO * (self.times.size - 1) * shortest else None

    @property
    def breakpoints(self) -> tuple:
        """Times (s) at which the integration restarts: the ends of the sampled range (where
        the clamping starts), every sample of a hold (its jumps) and, on a grid too uneven for
        :attr:`max_step`, every sample of a line (its kinks)."""
        if self.interpolation == "spline" or self.max_step is not None:
            return (float(self.times[0]), float(self.times[-1]))
        return tuple(self.times.tolist())

    @cached_property
    def _function(self):
        """CasADi ``Function`` ``t -> torque`` (SX, scalar ``t``)."""
        import casadi as ca

        t = ca.SX.sym("t")
        inside = ca.fmin(ca.fmax(t, float(self.times[0])), float(self.times[-1]))
        grid, values = [self.times.tolist()], self.values.tolist()
        if self.interpolation == "linear":
            torque = ca.interpolant("torque_linear", "linear", grid, values)(inside)
        elif self.interpolation == "spline":
            torque = ca.interpolant("torque_spline", "bspline", grid, values)(inside)
        else:
            torque = self._hold_form(inside)
        return ca.Function("sampled_torque", [t], [torque])

    def _hold_form(self, inside):
        """``values[k]`` for ``times[k] <= inside < times[k+1]``, exactly, in O(log K)
        (:func:`interval_index`): a linear interpolant of the values over the indices returns
        ``values[k]`` exactly at the integer ``k``."""
        import casadi as ca

        by_index = ca.interpolant("torque_hold_value", "linear",
                                  [np.arange(self.times.size, dtype=float).tolist()],
                                  self.values.tolist())
        return by_index(interval_index(self.times, inside))

    def casadi(self, t):
        """The torque as a CasADi expression of the time symbol ``t`` (SX or MX), N m.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        return self._function(t)

    def __call__(self, t):
        """Torque at time(s) ``t``, N m: an array of the shape of ``t``, equal to
        :meth:`casadi` bit for bit."""
        t = np.asarray(t, dtype=float)
        inside = np.clip(t, self.times[0], self.times[-1])
        if self.interpolation == "hold":
            k = np.searchsorted(self.times, inside, side="right") - 1
            return self.values[np.clip(k, 0, self.times.size - 1)]
        if self.interpolation == "linear":
            # CasADi's arithmetic: the interval k with times[k] <= t < times[k+1] (the last
            # one for t = times[-1]), the fraction a along it, (1 - a) v_k + a v_{k+1}
            k = np.clip(np.searchsorted(self.times, inside, side="right") - 1, 0,
                        self.times.size - 2)
            t_k, t_next = self.times[k], self.times[k + 1]
            a = (inside - t_k) / (t_next - t_k)
            return (1.0 - a) * self.values[k] + a * self.values[k + 1]
        if inside.ndim == 0:
            return np.asarray(float(self._function(float(inside))))
        flat = inside.reshape(1, -1)
        return np.array(self._function.map(flat.shape[1])(flat)).reshape(t.shape)


def check_breakpoints(func, name: str) -> tuple:
    """The times an input function declares in its ``breakpoints`` attribute, checked: a
    sequence of finite numbers (s), or none; else an error naming ``<name>.breakpoints``.

    Parameters
    ----------
    func : object
        The input (a torque function).
    name : str
        The input's name, for an error (e.g. ``"torque"``).
    """
    declared = getattr(func, "breakpoints", None)
    if declared is None:
        return ()
    if isinstance(declared, (str, bytes)) or not hasattr(declared, "__iter__"):
        raise InputTypeError(f"{name}.breakpoints must be a sequence of times (s); got "
                             f"{type(declared).__name__}")
    times = []
    for value in declared:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (Real, np.number)) \
                or not math.isfinite(float(value)):
            raise InputValueError(f"{name}.breakpoints must be a sequence of finite times (s); "
                                  f"got {value!r}")
        times.append(float(value))
    return tuple(times)


def lookup_grid(times) -> tuple:
    """``(grid, index)`` of a linear interpolant that is constant between ``times``: each time
    ``t_k`` preceded by its float predecessor ``t_k^-`` (no float lies between the two), the
    index ``k - 1`` at ``t_k^-`` and ``k`` at ``t_k``. Rounded to the nearest integer, the
    interpolant at ``t`` is the ``k`` with ``times[k] <= t < times[k+1]``, exactly, in
    O(log K) (:func:`interval_index`).

    Parameters
    ----------
    times : array_like, shape (K,)
        Strictly increasing times, s.

    Returns
    -------
    grid, index : ndarray, shape (G,)
    """
    times = np.asarray(times, dtype=float).reshape(-1)
    after = times[1:]
    before = np.nextafter(after, -np.inf)
    k = np.arange(1.0, times.size)
    # each time after the first: its predecessor where a float lies between the two times
    # (index k - 1), then the time itself (index k)
    kept = np.column_stack([before > times[:-1], np.ones(after.size, dtype=bool)]).ravel()
    grid = np.column_stack([before, after]).ravel()[kept]
    index = np.column_stack([k - 1.0, k]).ravel()[kept]
    return np.concatenate([times[:1], grid]), np.concatenate([[0.0], index])


def interval_index(times, inside):
    """The index ``k`` with ``times[k] <= inside < times[k+1]`` as a CasADi expression of
    ``inside``, exactly, in O(log K) (the last index at and past ``times[-1]``;
    :func:`lookup_grid`).

    Parameters
    ----------
    times : ndarray, shape (K,)
        Strictly increasing times, s (K >= 2).
    inside : casadi.SX or casadi.MX
        Scalar time within ``[times[0], times[-1]]``, s.
    """
    import casadi as ca

    grid, index = lookup_grid(times)
    which = ca.interpolant("interval_index", "linear", [grid.tolist()], index.tolist())(inside)
    return ca.floor(which + 0.5)


def _checked_samples(times, values, interpolation):
    """``(times, values)`` as read-only float arrays of shape (K,), or an error naming the
    rule broken."""
    times = as_vector("torque samples: times", times, "an array of sample times (s)")
    values = as_vector("torque samples: values", values, "an array of torques (N m)")
    if times.ndim != 1:
        raise InputValueError(f"torque samples: times must be one-dimensional, shape (K,); "
                              f"got shape {times.shape}")
    if values.shape in ((1, times.size), (times.size, 1)):
        values = values.reshape(-1)
    if values.shape != times.shape:
        raise InputValueError(f"torque samples: values must hold one torque per sample time, "
                              f"shape ({times.size},) or (1, {times.size}); got shape "
                              f"{values.shape}")
    fewest = INTERPOLATIONS[interpolation]
    if times.size < fewest:
        raise InputValueError(f"torque samples: interpolation {interpolation!r} needs at "
                              f"least {fewest} samples; got {times.size}")
    for name, array, unit in (("times", times, "s"), ("values", values, "N m")):
        bad = np.flatnonzero(~np.isfinite(array))
        if bad.size:
            raise InputValueError(f"torque samples: {name} must be finite ({unit}); got "
                                  f"{name}[{bad[0]}] = {float(array[bad[0]])!r}")
    step = np.diff(times)
    if np.any(step <= 0.0):
        k = int(np.argmax(step <= 0.0)) + 1
        raise InputValueError(f"torque samples: times must be strictly increasing (s); got "
                              f"times[{k}] = {float(times[k])!r} after times[{k - 1}] = "
                              f"{float(times[k - 1])!r}")
    times, values = times.copy(), values.copy()
    times.flags.writeable = values.flags.writeable = False
    return times, values


#: Sampled torques made from pairs, kept by content (up to this many samples each), so that
#: the same arrays passed again reuse the compiled integrators built for them
#: (:mod:`flexctl.sim.compiled` keys those by the input's identity).
SAMPLES_CACHE_SIZE = 16
SAMPLES_CACHE_LIMIT = 100_000
_SAMPLED: OrderedDict = OrderedDict()


def sampled_torque(torque, t_final: float) -> SampledTorque:
    """``torque`` given as samples, a pair ``(times, values)`` or a :class:`SampledTorque`, as
    a :class:`SampledTorque` covering ``[0, t_final]``; else an error naming the rule broken.

    A pair equal, sample for sample, to one seen before gives the same object.

    Parameters
    ----------
    torque : (times, values) or SampledTorque
        Sample times, s, and torques, N m, shape (K,) each.
    t_final : float
        End of the run, s: the samples must reach it (within ``1e-9 t_final``).
    """
    if not isinstance(torque, SampledTorque):
        if len(torque) != 2:
            raise InputTypeError(f"torque samples must be a pair (times, values); got a "
                                 f"{type(torque).__name__} of {len(torque)} items")
        torque = _remembered(SampledTorque(*torque))
    first, last = float(torque.times[0]), float(torque.times[-1])
    if first > 0.0:
        raise InputValueError(f"torque samples must start at or before t = 0 s; got times[0] "
                              f"= {first!r}")
    if last < t_final * (1.0 - 1e-9):
        raise InputValueError(f"torque samples must cover the run up to t_final = "
                              f"{t_final:g} s; got times[-1] = {last!r} (add samples or "
                              "shorten t_final)")
    return torque


def _remembered(torque: SampledTorque) -> SampledTorque:
    """The sampled torque made before from the same samples, else ``torque``, remembered."""
    if torque.times.size > SAMPLES_CACHE_LIMIT:
        return torque
    key = (torque.interpolation, torque.times.tobytes(), torque.values.tobytes())
    if key in _SAMPLED:
        _SAMPLED.move_to_end(key)
        return _SAMPLED[key]
    _SAMPLED[key] = torque
    while len(_SAMPLED) > SAMPLES_CACHE_SIZE:
        _SAMPLED.popitem(last=False)
    return torque
