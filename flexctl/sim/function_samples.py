"""Python torque functions that CasADi cannot trace, sampled adaptively onto a compiled form.

A torque function of time that branches on its argument (``2 sin(pi t) if t <= 2 else 0``)
cannot be traced (:mod:`flexctl.sim.tracing`): a CasADi symbol has no truth value. Instead of
calling it at every step of a SciPy integration (and again in the accuracy check and the
validity estimate's runs), :func:`flexctl.simulate` samples it once, before the run, into a
piecewise cubic (:class:`SampledFunction`) that runs on the compiled path, and counts the
sampling's error in the run's ``integration_error``.

The sampling (:func:`sample_function`):

- The run ``[0, t_final]`` starts as :data:`START_INTERVALS` equal intervals (and the
  function's own ``breakpoints`` attribute, if it declares one, as more interval ends).
- On each interval ``[a, b]`` the cubic through the function at ``a``, ``a + h/3``,
  ``a + 2h/3`` and ``b`` (``h = b - a``) is compared with the function at ``a + h/6``,
  ``a + h/2`` and ``a + 5h/6``. It is kept when every difference is within the tolerance,
  else the interval is halved (the halves reuse the parent's points, so that each half costs
  three calls).
- An interval that reaches :data:`JUMP_FRACTION` of the run (at least of a second) and still
  misses holds a jump: the jump is placed at its start, which becomes a breakpoint of the run
  (every integrator restarts there), and the interval holds the value at its end.
- The tolerance is :data:`SAMPLE_FRACTION` of the run's ``rtol`` times the largest torque
  seen on the start intervals (not below :data:`TOLERANCE_FLOOR` of it, the rounding of the
  function's own arithmetic).

The error of the sampling in the response is measured, not assumed: the run's accuracy
check, its replay at :data:`~flexctl.sim.compiled.CHECK_FACTOR` times the tolerance, runs on
the function sampled at that many times the tolerance too, so that its difference from the
run (the run's ``integration_error``) counts the sampling's error with the integration's;
where the check cannot take another torque (a sampled loop, SciPy's methods, ``"rk4"``) the
run is repeated on the looser sampling and the largest tip difference is added
(:func:`flexctl.sim.runs.run_once`). The cubic's error falls as the fourth power of the
interval, so the looser sampling's difference bounds the run's.

The limits, as for tracing: the function must be pure (the torque a function of ``t`` alone;
it is called some hundreds to thousands of times before the run and never during it), and a
feature shorter than about a sixth of a start interval (``t_final / 1536``) that lies between
the points looked at goes unseen, as it would by an integrator whose steps have grown at rest:
declare such times in a ``breakpoints`` attribute of the function. A function that raises or
returns anything but a finite number, or that needs more than :data:`MAX_EVALUATIONS` calls
(noise, a chirp faster than the tolerance can follow), is not sampled: the run calls it at
every step on SciPy's path, which reports a bad value with its time.

Examples
--------
>>> import numpy as np
>>> from flexctl.sim.function_samples import sample_function
>>> samples, reason = sample_function(lambda t: 2.0 * np.sin(np.pi * t) if t <= 2.0 else 0.0,
...                                   t_final=10.0, tolerance=1e-9)
>>> reason, samples.jumps
('', ())
>>> bool(abs(float(samples(0.25)) - 2.0 * np.sin(np.pi * 0.25)) < 1e-9)
True
>>> step, _ = sample_function(lambda t: 1.0 if t < 1.0 else -1.0, t_final=3.0, tolerance=1e-9)
>>> round(step.jumps[0], 9), round(float(step(0.5)), 12), float(step(1.5))
(1.0, 1.0, -1.0)
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np

from ..model.checks import check_real
from ..model.errors import InputTypeError
from .inputs import input_value, lookup_grid

__all__ = ["SampledFunction", "sample_function", "sampled_for_run", "recorded_sampling",
           "START_INTERVALS", "SAMPLE_FRACTION", "TOLERANCE_FLOOR", "JUMP_FRACTION",
           "MAX_EVALUATIONS"]

#: Equal intervals the run starts with.
START_INTERVALS = 256
#: The interpolation error allowed, as a fraction of the run's ``rtol`` times the torque's
#: size: the sampled torque is ten times closer to the function than the integration is to
#: the exact response.
SAMPLE_FRACTION = 0.1
#: Smallest interpolation error asked for, relative to the torque's size: about the rounding
#: of a function's own arithmetic, below which halving would never end.
TOLERANCE_FLOOR = 1e-13
#: Shortest interval, as a fraction of ``max(1, t_final)`` s: a miss on an interval this short
#: is a jump, located to it.
JUMP_FRACTION = 1e-12
#: Most calls of the function a sampling may make.
MAX_EVALUATIONS = 200_000
#: Samplings kept, so that the same function at the same tolerance (the accuracy check's and
#: the validity estimate's runs) is sampled once and its compiled integrators are reused.
CACHE_SIZE = 16
_CACHE: OrderedDict = OrderedDict()
#: The values of the last functions sampled, by identity (``_known_values``).
_VALUES: OrderedDict = OrderedDict()

#: The types of value taken as they are (others go through :func:`input_value`).
_FLOATS = frozenset((float, np.float64))
_FIT = np.array([0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0])
_CHECK = np.array([1.0 / 6.0, 0.5, 5.0 / 6.0])
#: Power-basis coefficients in ``u = (t - a) / h`` from the values at ``_FIT``.
_FROM_VALUES = np.linalg.inv(np.vander(_FIT, 4, increasing=True))


@dataclass(frozen=True, eq=False)
class SampledFunction:
    """A torque function of time as a piecewise cubic (:func:`sample_function`).

    Attributes
    ----------
    function : callable
        The Python function ``function(t)``, N m.
    knots : ndarray, shape (P + 1,)
        Interval ends, s: ``0`` to ``t_final``.
    coefficients : ndarray, shape (P, 4)
        Each interval's cubic ``c0 + c1 u + c2 u^2 + c3 u^3`` in ``u = (t - knots[k]) / h_k``,
        N m.
    jumps : tuple of float
        Located jumps, s: breakpoints of the run.
    tolerance : float
        The interpolation error asked for, N m.
    evaluations : int
        Calls of the function made.
    """

    function: object
    knots: np.ndarray
    coefficients: np.ndarray
    jumps: tuple
    tolerance: float
    evaluations: int
    #: :meth:`casadi` takes the time alone (:func:`flexctl.sim.compiled.is_symbolic`)
    state_dependent: ClassVar[bool] = False

    def __repr__(self):
        name = getattr(self.function, "__name__", type(self.function).__name__)
        return (f"SampledFunction({name}: {self.coefficients.shape[0]} cubic pieces over "
                f"[0, {self.knots[-1]:g}] s, {len(self.jumps)} jumps)")

    @property
    def breakpoints(self) -> tuple:
        """The jumps located, s (every integrator restarts there)."""
        return self.jumps

    @property
    def table(self) -> np.ndarray:
        """Each interval's start, inverse length and cubic coefficients, shape (P, 6)."""
        starts = self.knots[:-1]
        return np.column_stack([starts, 1.0 / np.diff(self.knots), self.coefficients])

    @property
    def size_class(self) -> int:
        """Intervals the compiled form holds: the next power of two (at least
        :data:`START_INTERVALS`), so that samplings of one size class share a library."""
        return max(START_INTERVALS, 1 << int(self.coefficients.shape[0] - 1).bit_length())

    @cached_property
    def casadi_parameters(self) -> tuple:
        """``(structure, values)``: the size class shapes :meth:`casadi`; the numbers are the
        run's end, the interval lookup's grid and indices and the padded :attr:`table`
        (compiled runs of any sampled function of one size class share one function)."""
        grid, index = lookup_grid(self.knots[:-1])
        q = self.size_class
        end = float(self.knots[-1])
        # the end closes the last interval, so that no time of the run is extrapolated to;
        # padding past it is never reached (the time is clamped to [0, t_final])
        extra = 2 * q - 1 - grid.size
        grid = np.concatenate([grid, [end], end + 1.0 + np.arange(extra)])
        index = np.concatenate([index, np.full(extra + 1, index[-1])])
        table = np.vstack([self.table, np.repeat(self.table[-1:], q - self.table.shape[0], 0)])
        return (q,), np.concatenate([[float(self.knots[0]), end], grid, index, table.ravel()])

    def casadi(self, t, parameters=None):
        """The torque as a CasADi expression of the time symbol ``t`` (SX or MX), N m; its
        numbers are symbols when ``parameters`` (laid out as :attr:`casadi_parameters`) is
        given.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        parameters : casadi.SX or casadi.MX, optional
            The numbers of :attr:`casadi_parameters` as symbols; None: this sampling's.
        """
        import casadi as ca

        q = self.size_class
        numbers = parameters if parameters is not None else ca.DM(self.casadi_parameters[1])
        g = 2 * q
        grid, index = numbers[2:2 + g], numbers[2 + g:2 + 2 * g]
        table = numbers[2 + 2 * g:2 + 2 * g + 6 * q]
        inside = ca.fmin(ca.fmax(t, numbers[0]), numbers[1])
        which = ca.interpolant("sampled_function_index", "linear", [g], 1)(inside, grid, index)
        piece = ca.interpolant("sampled_function_piece", "linear",
                               [np.arange(q, dtype=float).tolist()], 6)
        start, inverse, c0, c1, c2, c3 = ca.vertsplit(piece(ca.floor(which + 0.5), table))
        u = (inside - start) * inverse
        return ((c3 * u + c2) * u + c1) * u + c0

    def __call__(self, t):
        """Torque at time(s) ``t``, N m: an array of the shape of ``t`` (the time clamped into
        ``[0, t_final]``)."""
        t = np.asarray(t, dtype=float)
        inside = np.clip(t, self.knots[0], self.knots[-1])
        k = np.clip(np.searchsorted(self.knots[:-1], inside, side="right") - 1, 0,
                    self.coefficients.shape[0] - 1)
        rows = self.table[k]
        u = (inside - rows[..., 0]) * rows[..., 1]
        c0, c1, c2, c3 = (rows[..., j] for j in range(2, 6))
        return ((c3 * u + c2) * u + c1) * u + c0


class _Unsampled(Exception):
    """Why a function could not be sampled."""


class _Values:
    """The function's values, each time asked once; a bad value, an exception or more than
    :data:`MAX_EVALUATIONS` calls end the sampling.

    The start intervals' points are kept as an array (:meth:`start_points`, the same for
    every sampling of one run length), the halves' points by their times (:meth:`many`).
    """

    def __init__(self, function):
        self.function, self.known, self.calls, self.start = function, {}, 0, None

    def _call(self, times: list) -> np.ndarray:
        """The function's values at ``times`` (a list), called in that order."""
        if self.calls + len(times) > MAX_EVALUATIONS:
            raise _Unsampled(f"it needed more than {MAX_EVALUATIONS} calls")
        function, got = self.function, []
        try:
            for t in times:
                got.append(function(t))
        except Exception as exc:                # noqa: BLE001 - any failure keeps SciPy's path
            raise _Unsampled(_raised(times[len(got)], exc)) from None
        finally:
            self.calls += len(got)
        if not (_FLOATS.issuperset(map(type, got)) and np.all(np.isfinite(got))):
            # a value to convert, or one that is bad
            got = [self._checked(value, t) for t, value in zip(times, got)]
        return np.array(got, dtype=float)

    def start_points(self, knots: np.ndarray) -> np.ndarray:
        """The values at the seven points (:data:`_POINTS`) of each start interval between
        ``knots``, shape (I, 7)."""
        if self.start is not None and np.array_equal(self.start[0], knots):
            return self.start[1]
        starts, ends = knots[:-1], knots[1:]
        inner = starts[:, None] + _POINTS[1:-1] * (ends - starts)[:, None]
        got = self._call(np.concatenate([knots, inner.reshape(-1)]).tolist())
        at_ends, inner = got[:knots.size], got[knots.size:].reshape(-1, 5)
        points = np.column_stack([at_ends[:-1], inner, at_ends[1:]])
        self.start = (knots.copy(), points)
        return points

    def many(self, times: np.ndarray) -> np.ndarray:
        """The values at ``times`` (any shape), an array of that shape (the function called
        once at each time not asked before, in increasing time)."""
        flat = times.reshape(-1).tolist()
        known = self.known
        new = sorted(set(flat).difference(known))
        if new:
            known.update(zip(new, self._call(new).tolist()))
        return np.fromiter(map(known.__getitem__, flat), dtype=float,
                           count=len(flat)).reshape(times.shape)

    @staticmethod
    def _checked(value, t: float) -> float:
        """``value`` as a finite float, or :class:`_Unsampled` with the reason."""
        try:
            return input_value("torque", value, t)
        except Exception as exc:                # noqa: BLE001 - any failure keeps SciPy's path
            raise _Unsampled(_raised(t, exc)) from None


def _raised(t: float, exc: Exception) -> str:
    """Why a sampling ended: the call at ``t`` raised ``exc`` (or its value did)."""
    return f"calling it at t = {t:.6g} s raised {type(exc).__name__}: {exc}"[:300]


def _start_knots(function, t_final: float) -> np.ndarray:
    """The start intervals' ends: equal ones and the function's declared breakpoints."""
    knots = set(np.linspace(0.0, t_final, START_INTERVALS + 1).tolist())
    declared = getattr(function, "breakpoints", ()) or ()
    try:
        knots.update(float(b) for b in declared if 0.0 < float(b) < t_final)
    except (TypeError, ValueError):
        raise _Unsampled("its breakpoints attribute is not a sequence of times") from None
    return np.array(sorted(knots))


#: The cubic's values at ``_CHECK`` from its power coefficients.
_AT_CHECKS = np.vander(_CHECK, 4, increasing=True)


#: The seven points of an interval looked at, in ``u = (t - a) / h``: the fit's at rows
#: :data:`_FIT_ROWS` (``0, 1/3, 2/3, 1``) and the check's at :data:`_CHECK_ROWS` (``1/6, 1/2,
#: 5/6``). A half's fit points are four of its parent's (every other row of its half), its
#: checks the three new ones between them.
_POINTS = np.arange(7.0) / 6.0
_FIT_ROWS = [0, 2, 4, 6]
_CHECK_ROWS = [1, 3, 5]
#: The new points of the left and right halves, in the parent's ``u``.
_HALF_CHECKS = np.array([[1.0, 3.0, 5.0], [7.0, 9.0, 11.0]]) / 12.0
#: The cubic's power coefficients from an interval's seven values (shape (7, 4)), and its
#: differences from the values at the checks (shape (7, 3)).
_COEFFICIENTS = np.zeros((7, 4))
_COEFFICIENTS[_FIT_ROWS] = _FROM_VALUES.T
_CHECK_MISS = _COEFFICIENTS @ _AT_CHECKS.T
_CHECK_MISS[_CHECK_ROWS, np.arange(3)] -= 1.0


def _halves(values, starts: np.ndarray, ends: np.ndarray, points: np.ndarray) -> tuple:
    """``(starts, ends, points)`` of the two halves of each interval: their fit values are
    the parent's, their checks three new calls each."""
    h = ends - starts
    middles = starts + 0.5 * h
    fresh = values.many(starts[:, None, None] + _HALF_CHECKS * h[:, None, None])
    halves = np.empty((2,) + points.shape)
    halves[0][:, _FIT_ROWS], halves[1][:, _FIT_ROWS] = points[:, :4], points[:, 3:]
    halves[0][:, _CHECK_ROWS], halves[1][:, _CHECK_ROWS] = fresh[:, 0], fresh[:, 1]
    return (np.concatenate([starts, middles]), np.concatenate([middles, ends]),
            halves.reshape(-1, 7))


def _refine(values, knots: np.ndarray, tolerance: float, shortest: float):
    """The accepted intervals' starts and coefficients, left to right, and the jumps: the
    intervals are halved level by level until their cubics pass."""
    starts, ends = knots[:-1].copy(), knots[1:].copy()
    points = values.start_points(knots)
    kept_starts, kept_points, jumps, held = [], [], [], []
    while True:
        # each cubic's largest difference from the function at its checks
        failed = np.max(np.abs(points @ _CHECK_MISS), axis=1) > tolerance
        if not np.all(failed):
            kept_starts.append(starts[~failed])
            kept_points.append(points[~failed])
        if not np.any(failed):
            break
        starts, ends, points = starts[failed], ends[failed], points[failed]
        middles = starts + 0.5 * (ends - starts)
        # a miss on an interval too short to halve: a jump inside it, placed at its start,
        # the interval holding the value at its end
        jump = (ends - starts <= shortest) | ~((starts < middles) & (middles < ends))
        if np.any(jump):
            jumps.extend(starts[jump].tolist())
            held.extend(points[jump, -1].tolist())
            starts, ends, points = starts[~jump], ends[~jump], points[~jump]
            if not starts.size:
                break
        starts, ends, points = _halves(values, starts, ends, points)
    coefficients = np.concatenate(kept_points) @ _COEFFICIENTS if kept_points \
        else np.zeros((0, 4))
    constant = np.zeros((len(held), 4))
    constant[:, 0] = held
    starts = np.concatenate(kept_starts + [np.array(jumps)])
    order = np.argsort(starts, kind="stable")
    return starts[order], np.concatenate([coefficients, constant])[order], tuple(sorted(jumps))


def sample_function(function, t_final: float, tolerance: float, *, reuse: bool = False):
    """Sample ``function(t)`` into a :class:`SampledFunction` within ``tolerance``.

    Parameters
    ----------
    function : callable
        ``function(t) -> torque``, N m: pure, of the time alone.
    t_final : float
        End of the run, s (> 0, finite).
    tolerance : float
        Largest difference between the cubic and the function at the checks, N m (>= 0).
    reuse : bool, optional
        Call the function only at times it was not called at by an earlier sampling of the
        same function object (its values are kept for the last few functions: a pure
        function of time). Default False.

    Returns
    -------
    samples : SampledFunction or None
        None when the function cannot be sampled.
    reason : str
        Why not; empty when it was sampled.
    """
    if not callable(function):
        raise InputTypeError(f"sample_function function must be callable as function(t); got "
                             f"{type(function).__name__}")
    t_final = check_real("sample_function", "t_final", t_final, minimum=0.0, strict=True)
    tolerance = check_real("sample_function", "tolerance", tolerance, minimum=0.0)
    return _sampled(function, t_final, tolerance,
                    _known_values(function) if reuse else _Values(function))


def _sampled(function, t_final: float, tolerance: float, values: "_Values") -> tuple:
    """:func:`sample_function` with the function's values asked of ``values`` (which may
    know some already: the calls counted are the new ones)."""
    calls = values.calls
    try:
        knots = _start_knots(function, t_final)
        starts, coefficients, jumps = _refine(values, knots, tolerance,
                                              JUMP_FRACTION * max(1.0, t_final))
    except _Unsampled as exc:
        return None, str(exc)
    return SampledFunction(function=function, knots=np.append(starts, t_final),
                           coefficients=coefficients, jumps=jumps, tolerance=tolerance,
                           evaluations=values.calls - calls), ""


def _known_values(function) -> _Values:
    """The values of ``function`` asked so far, kept for the same function object (a pure
    function of time: the accuracy check's looser sampling and the torque's size then call
    it only where the run's sampling did not)."""
    ident = id(function)
    entry = _VALUES.get(ident)
    if entry is None or entry.function is not function:
        entry = _VALUES[ident] = _Values(function)
    _VALUES.move_to_end(ident)
    while len(_VALUES) > CACHE_SIZE:
        _VALUES.popitem(last=False)
    return entry


def _torque_size(function, t_final: float, values: _Values):
    """The largest ``|function|`` at the start intervals' ends and first checks, N m (None
    if it fails)."""
    try:
        points = values.start_points(_start_knots(function, t_final))
        return float(max(np.max(np.abs(points[:, :2])), abs(points[-1, -1]))), ""
    except _Unsampled as exc:
        return None, str(exc)


def sampled_for_run(function, t_final: float, rtol: float, factor: float = 1.0):
    """``function`` sampled for a run at ``rtol`` (and, with ``factor``, at ``factor`` times
    its tolerance: the accuracy check's), remembered for the same function, run and tolerance.

    Parameters
    ----------
    function : callable
        ``function(t)``, N m.
    t_final : float
        End of the run, s.
    rtol : float
        The run's relative tolerance.
    factor : float, optional
        Multiple of the tolerance :data:`SAMPLE_FRACTION` ``* rtol`` times the torque's size.
        Default 1.

    Returns
    -------
    samples : SampledFunction or None
    reason : str
        Why it could not be sampled; empty when it was.
    """
    relative = factor * max(SAMPLE_FRACTION * float(rtol), TOLERANCE_FLOOR)
    # one made at this tolerance or a tighter one serves, found before the function is
    # called again
    found = _remembered(function, float(t_final), relative)
    if found is not None:
        _CACHE.move_to_end(found)
        return _CACHE[found]
    values = _known_values(function)
    size, reason = _torque_size(function, t_final, values)
    if size is None:
        return None, reason
    made = _sampled(function, t_final, relative * size, values)
    _CACHE[(id(function), float(t_final), relative)] = made
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return made


def recorded_sampling(function, t_final: float):
    """The last sampling :func:`sampled_for_run` made of ``function`` for a run ending at
    ``t_final``, or ``function`` itself when there is none (not a function, traced, never
    sampled, or forgotten).

    A run's input as recorded, for computations whose result does not depend on the
    sampling's small error to first order, such as the difference of two models' responses
    to the same input (the validity estimate: :func:`flexctl.sim.validity.geometric_error`),
    so that they do not call the function again.

    Parameters
    ----------
    function : object
        A run's ``torque``.
    t_final : float
        End of the run, s (> 0, finite).

    Returns
    -------
    SampledFunction or object
    """
    t_final = check_real("recorded_sampling", "t_final", t_final, minimum=0.0, strict=True)
    if not callable(function) or isinstance(function, SampledFunction):
        return function
    found = _remembered(function, t_final)
    return function if found is None else _CACHE[found][0]


def _remembered(function, t_final: float, loosest: float = float("inf")):
    """The key in ``_CACHE`` of the last sampling of ``function`` for a run ending at
    ``t_final`` made at a relative tolerance of at most ``loosest``, or None."""
    for key, made in reversed(_CACHE.items()):
        ident, end, made_at = key
        if (ident, end) == (id(function), t_final) and made_at <= loosest \
                and made[0] is not None and made[0].function is function:
            return key
    return None
