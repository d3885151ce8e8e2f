"""Python torque functions traced into CasADi, so that they run on the compiled path.

A torque function ``f(t)`` or ``f(t, x)`` that only does arithmetic and numpy's elementwise
functions on its arguments can be called with CasADi symbols instead of numbers: numpy hands
``np.sin(t)`` to CasADi's ``sin``, and the call returns the torque as an expression. Such a
function gets a CasADi form (:class:`TracedTorque`, :class:`TracedStateTorque`) and
:func:`flexctl.simulate` integrates it compiled; a function of time that cannot be traced is
sampled into a piecewise cubic instead (:mod:`flexctl.sim.function_samples`), and a function
of the state that cannot be traced keeps the SciPy path, the run's message saying why.

The rule, and why tracing never changes a result:

- A function is traced only when its form would be used: ``method`` ``"auto"``, ``"cvodes"`` or
  ``"rk4"``, no prescribed hub motion, and a controller (if any) with a CasADi form.
  ``method="DOP853"`` (or any SciPy method), or an attribute ``has_casadi_form = False`` on the
  function, keeps it off the compiled path.
- It is called once with the symbols: the time ``t`` (``casadi.SX``) and, for ``f(t, x)``, the
  state as a numpy array of ``n`` CasADi scalars (so that ``x[0]``, ``x[1:3]``, ``K @ x`` and
  ``len(x)`` work as on the numbers). The call must return one CasADi scalar or number. Any
  exception (``if t < 1:`` asks a symbol for its truth value; ``math.sin`` wants a float), any
  other result (an array of several values, a string) and any free symbol other than ``t``
  and ``x`` leave the function untraced.
- The trace is trusted only if it agrees with the function itself: both are evaluated at
  :data:`CHECK_FRACTIONS` of the run (times ``0`` to ``t_final``) and, for ``f(t, x)``, at
  states around the start drawn with a fixed seed at each state's physical scale, and every
  pair must agree within :data:`TRACE_RTOL` of the largest value. A function that reads a
  random number generator, a clock or a counter gives its trace a constant that the checks
  see differ; a function that returns NaN or raises at a check time keeps the SciPy path,
  which reports it with the time.
- Functions must be pure (the torque a function of its arguments alone). A function with side
  effects sees, before each run, one call with the symbols and 7 with numbers (21 for
  ``f(t, x)``: :data:`CHECK_STATES` states at each time) and, on the compiled path, none
  during it. A function passed again is traced and checked again; when its trace is the same,
  bit for bit, the compiled integrators built for it before are reused.

Examples
--------
>>> import numpy as np
>>> from flexctl.sim.tracing import trace_torque
>>> traced, reason = trace_torque(lambda t: 2.0 * np.sin(3.0 * t), t_final=5.0)
>>> traced.casadi(0.5), round(float(traced(0.5)), 6)
(DM(1.99499), 1.99499)
>>> traced, reason = trace_torque(lambda t: 1.0 if t < 1.0 else 0.0, t_final=5.0)
>>> traced is None, reason.startswith("calling it with a CasADi symbol raised RuntimeError")
(True, True)
"""

from __future__ import annotations

import warnings
from collections import OrderedDict
from dataclasses import dataclass
from numbers import Real
from typing import ClassVar

import numpy as np

from ..model.errors import InputTypeError
from .function_samples import sampled_for_run
from .inputs import (SampledTorque, check_breakpoints, required_positional, input_value,
                     sampled_torque, time_function)

__all__ = ["TRACE_RTOL", "CHECK_FRACTIONS", "TracedTorque", "TracedStateTorque", "trace_torque",
           "torque_input"]

#: A trace is trusted when it agrees with the Python function within this fraction of the
#: largest torque at the check points: rounding of reordered sums (``K @ x``) is a few units
#: of 1e-16; a function that changes between calls differs by far more.
TRACE_RTOL = 1e-12
#: Check times, as fractions of the run: its ends and irrational-looking points in between,
#: unlikely to sit on a switch of the function.
CHECK_FRACTIONS = (0.0, 0.1234567, 0.3090170, 0.5, 0.6180340, 0.8765432, 1.0)
#: States at which a state-dependent function is checked at each time: the start, and
#: random ones (fixed seed) at each state's physical scale.
CHECK_STATES = 3
_CHECK_SEED = 20240917
#: Traces kept, so that a function passed again with the same trace reuses the compiled
#: right-hand sides and integrators built for it (:mod:`flexctl.sim.compiled` keys them by
#: the input's identity); least recently used dropped first.
TRACE_CACHE_SIZE = 32
_TRACES: OrderedDict = OrderedDict()


@dataclass(frozen=True, eq=False)
class TracedTorque:
    """A Python torque function of time with the CasADi form its trace gave
    (:func:`trace_torque`).

    Attributes
    ----------
    function : callable
        The Python function ``function(t)``, N m.
    form : casadi.Function
        ``(t) -> torque`` (SX), equal to ``function`` at the checks.
    """

    function: object
    form: object
    #: :meth:`casadi` takes the time alone (:func:`flexctl.sim.compiled.is_symbolic`)
    state_dependent: ClassVar[bool] = False

    def __repr__(self):
        name = getattr(self.function, "__name__", type(self.function).__name__)
        return f"{type(self).__name__}({name})"

    @property
    def breakpoints(self) -> tuple:
        """The function's own ``breakpoints``, if it declares any, s."""
        return tuple(getattr(self.function, "breakpoints", ()) or ())

    def casadi(self, t):
        """The torque as a CasADi expression of the time symbol ``t``, N m.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        return self.form(t)

    def __call__(self, t):
        """Torque through the CasADi form at time(s) ``t``, N m: an array of their shape."""
        t = np.asarray(t, dtype=float)
        if t.ndim == 0:
            return np.asarray(float(self.form(float(t))))
        flat = t.reshape(1, -1)
        return np.array(self.form.map(flat.shape[1])(flat)).reshape(t.shape)


@dataclass(frozen=True, eq=False, repr=False)
class TracedStateTorque(TracedTorque):
    """A traced Python torque function of time and plant state, ``function(t, x)``; its
    ``form`` is ``(t, x) -> torque``.

    Attributes
    ----------
    function : callable
        The Python function ``function(t, x)``, N m.
    form : casadi.Function
        ``(t, x) -> torque`` (SX), equal to ``function`` at the checks.
    """

    state_dependent: ClassVar[bool] = True

    def casadi(self, t, x):
        """The torque as a CasADi expression of the time ``t`` and plant state ``x``, N m.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        x : casadi.SX or casadi.MX, shape (n, 1)
            Plant state, in the order of ``model.layout``.
        """
        return self.form(t, x)

    def __call__(self, t, x):
        """Torque through the CasADi form at time ``t`` (s) and plant state ``x``, N m."""
        return np.asarray(float(self.form(float(t), np.asarray(x, dtype=float))))


def _scalar_expression(value):
    """``value`` (what the function returned for the symbols) as a 1x1 ``casadi.SX``, or None
    when it is not one CasADi scalar or real number."""
    import casadi as ca

    if isinstance(value, np.ndarray):
        if value.size != 1:
            return None
        value = value.reshape(-1)[0]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (ca.SX, ca.DM, Real)):
        return None
    expression = ca.SX(value)
    return expression if expression.shape == (1, 1) else None


def _symbolic_form(function, n_states: int | None):
    """``(casadi.Function, '')`` of ``function`` called with symbols, or ``(None, reason)``.

    ``n_states`` is the plant state size for ``function(t, x)``, None for ``function(t)``.
    """
    import casadi as ca

    t = ca.SX.sym("t")
    inputs, args = [t], [t]
    if n_states is not None:
        x = ca.SX.sym("x", n_states)
        inputs.append(x)
        state = np.empty(n_states, dtype=object)
        for i in range(n_states):
            state[i] = x[i]
        args.append(state)
    try:
        # numpy warns that it hands a CasADi value to CasADi, and the function may warn or
        # overflow on a symbol: none of it concerns the user
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            value = function(*args)
    except Exception as exc:        # whatever a symbol makes the function raise
        return None, f"calling it with a CasADi symbol raised {type(exc).__name__}: {exc}"
    expression = _scalar_expression(value)
    if expression is None:
        return None, (f"called with a CasADi symbol it returned {type(value).__name__}, not one "
                      "CasADi scalar")
    try:
        return ca.Function("traced_torque", inputs, [expression]), ""
    except RuntimeError as exc:     # free symbols other than t and x
        return None, f"its trace is not a function of t and x alone ({exc})"


def _check_points(t_final: float, n_states: int | None, state_scale, x0):
    """``(times, states)`` at which a trace is checked; ``states`` is None for ``f(t)``."""
    times = [float(t_final) * f for f in CHECK_FRACTIONS]
    if n_states is None:
        return times, None
    rng = np.random.default_rng(_CHECK_SEED)
    start = np.zeros(n_states) if x0 is None else np.asarray(x0, dtype=float)
    scale = np.ones(n_states) if state_scale is None else np.asarray(state_scale, dtype=float)
    states = [start] + [start + scale * rng.standard_normal(n_states)
                        for _ in range(CHECK_STATES - 1)]
    return times, states


def _agrees(function, form, times, states) -> str:
    """Empty when ``form`` equals ``function`` at the check points, else how they differ."""
    own, traced = [], []
    try:
        for t in times:
            for x in (states if states is not None else [None]):
                args = (t,) if x is None else (t, x.copy())
                with warnings.catch_warnings(), np.errstate(all="ignore"):
                    warnings.simplefilter("ignore")
                    own.append(input_value("torque", function(*args), t))
                traced.append(float(form(*args)))
    except Exception as exc:        # the SciPy path will name it with its time
        return f"evaluating it at a check time raised {type(exc).__name__}: {exc}"
    own, traced = np.array(own), np.array(traced)
    tolerance = TRACE_RTOL * float(np.max(np.abs(own)))
    gap = np.abs(own - traced)
    if np.all(gap <= tolerance):    # False for NaN
        return ""
    k = int(np.argmax(~(gap <= tolerance)))
    return (f"its trace gives {traced[k]!r} where it gives {own[k]!r} (check {k}): it is not "
            "a pure function of its arguments, or the trace took another branch")


def trace_torque(function, *, t_final: float, n_states: int | None = None, state_scale=None,
                 x0=None):
    """Trace a Python torque function into CasADi, and check the trace against it.

    Parameters
    ----------
    function : callable
        ``function(t)`` or ``function(t, x)``, N m.
    t_final : float
        End of the run, s: the checks lie in ``[0, t_final]``.
    n_states : int, optional
        Plant state size; needed for ``function(t, x)``.
    state_scale : array_like, shape (n_states,), optional
        Physical size of each state: the checked states are drawn at this scale around
        ``x0`` (default zeros).
    x0 : array_like, shape (n_states,), optional
        The state the checked states are drawn around (the run's initial state). Default
        zeros.

    Returns
    -------
    traced : TracedTorque, TracedStateTorque or None
        None when the function cannot be traced, or its trace differs from it.
    reason : str
        Why it was not traced; empty when it was.
    """
    if getattr(function, "has_casadi_form", True) is False:
        return None, "it sets has_casadi_form = False"
    state_dependent = required_positional(function) == 2
    if state_dependent and n_states is None:
        return None, "it takes the state x, whose size was not given"
    form, reason = _symbolic_form(function, n_states if state_dependent else None)
    if form is None:
        return None, reason
    times, states = _check_points(t_final, n_states if state_dependent else None,
                                  state_scale, x0)
    reason = _agrees(function, form, times, states)
    if reason:
        return None, reason
    return _remembered(TracedStateTorque if state_dependent else TracedTorque, function,
                       form), ""


def _remembered(kind, function, form):
    """The traced torque made before from ``function`` with the same form, bit for bit (its
    serialisation: a closure whose numbers changed traces to another), else a new one."""
    key = (kind, id(function), form.serialize())
    traced = _TRACES.get(key)
    if traced is not None and traced.function is function:
        _TRACES.move_to_end(key)
        return traced
    traced = kind(function=function, form=form)
    _TRACES[key] = traced           # which keeps the function, and so its id, alive
    while len(_TRACES) > TRACE_CACHE_SIZE:
        _TRACES.popitem(last=False)
    return traced


def torque_input(torque, *, t_final: float, trace: bool, n_states: int, state_scale=None,
                 rtol: float | None = None):
    """The torque :func:`flexctl.simulate` integrates, why a function was not traced, and
    what the run says about it.

    Samples (a pair ``(times, values)`` or a :class:`~flexctl.sim.inputs.SampledTorque`)
    become a :class:`~flexctl.sim.inputs.SampledTorque` covering the run; a Python function
    without a CasADi form is traced when ``trace`` (:func:`trace_torque`), and a function of
    time that cannot be traced is sampled into a piecewise cubic when ``rtol`` is given
    (:mod:`flexctl.sim.function_samples`); anything else is returned as given.

    Parameters
    ----------
    torque : callable, (times, values), SampledTorque or None
        The ``torque`` argument of :func:`flexctl.simulate`, N m.
    t_final : float
        End of the run, s: samples must cover ``[0, t_final]``, a trace is checked inside it.
    trace : bool
        Trace a Python function (the rest of the run is compiled).
    n_states : int
        Plant state size ``n``, for a function ``torque(t, x)``.
    state_scale : array_like, shape (n,), optional
        Physical size of each plant state: a trace is checked at states of this size
        (:func:`trace_torque`).
    rtol : float, optional
        The run's relative tolerance: an untraced function of time is sampled at it
        (:func:`~flexctl.sim.function_samples.sampled_for_run`). Default None (not sampled).

    Returns
    -------
    torque : object or None
    reason : str
        Why a function stays a Python function on the run's path (not traced, nor sampled);
        empty otherwise.
    note : str
        What the run says about its torque function: sampled, or called at every step and
        why; empty for any other torque.
    """
    if torque is None:
        return None, "", ""
    if isinstance(torque, (SampledTorque, tuple, list)):
        return sampled_torque(torque, t_final), "", ""
    if not callable(torque):
        raise InputTypeError(f"torque must be callable as torque(t) or torque(t, x), or "
                             f"samples (times, values); got {type(torque).__name__}")
    time_function(torque, "torque")         # its signature, before any call
    check_breakpoints(torque, "torque")
    if callable(getattr(torque, "casadi", None)) or not trace:
        return torque, "", ""
    traced, reason = trace_torque(torque, t_final=t_final, n_states=n_states,
                                  state_scale=state_scale)
    if traced is not None:
        return traced, "", ""
    if rtol is None or required_positional(torque) == 2 or \
            getattr(torque, "has_casadi_form", True) is False:
        return torque, reason, (f"the torque function was called at every step: it could not "
                                f"be traced ({reason})")
    samples, why = sampled_for_run(torque, t_final, rtol)
    if samples is None:
        return torque, reason, (f"the torque function was called at every step: it could not "
                                f"be traced ({reason}) nor sampled ({why})")
    return samples, "", (f"the torque function could not be traced ({reason}): sampled into "
                         f"{samples.coefficients.shape[0]} cubic pieces from "
                         f"{samples.evaluations} calls, {len(samples.jumps)} jumps located, "
                         f"within {samples.tolerance:.3g} N m")
