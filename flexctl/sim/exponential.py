"""Exponential Runge-Kutta integration of a stiff spatial model: its linear part integrated
exactly, the rest by Krogstad's fourth-order scheme.

A spatial structure's torsion and stiff-plane bending modes reach thousands of rad/s
(``examples/scenes/spatial-two-arrays.toml``'s arrays on 4 modes per field: 3 609 rad/s) while
a slew and the modes it moves live below 100 rad/s. Adams-Moulton with functional iteration is
held to steps of a fraction of the fastest period however little those modes move
(``benchmarks/bench_spatial.py`` (b): 102 655 steps for 10 s). Written as

``x_t = L x + N(x, t)``

with ``L`` the Jacobian of the rate at a recent state, the linear flow ``exp(h L)`` carries
every mode, fast or slow, exactly, and only the remainder ``N`` (the torque, the gyroscopic
and centrifugal terms, the change of the mass matrix with the deflection) is integrated by
quadrature: the steps are set by how fast ``N`` changes, not by the fastest mode.

- **The scheme** (Krogstad 2005, "Generalized integrating factor methods for stiff PDEs",
  J. Comput. Phys. 203), with ``phi_k`` the functions of :func:`phi_functions`,
  ``e(s) = exp(s L)`` and ``N_u = N(x, t)``::

      a  = e(h/2) x + h/2 phi_1(hL/2) N_u
      b  = a + h phi_2(hL/2) (N_a - N_u)
      c  = e(h) x + h phi_1(hL) N_u + 2 h phi_2(hL) (N_b - N_u)
      x+ = e(h) x + h [(phi_1 - 3 phi_2 + 4 phi_3) N_u + (2 phi_2 - 4 phi_3) (N_a + N_b)
                       + (4 phi_3 - phi_2) N_c]

  (``N_a = N(a, t + h/2)``, ``N_b = N(b, t + h/2)``, ``N_c = N(c, t + h)``, ``phi_k`` at
  ``hL`` where not written): of order four, exact for a linear model under a torque linear in
  time. The rate at ``x+`` is the next step's ``N_u``: four evaluations a step.
- **Its error estimate** is the difference from the second-order solution on the same nodes,
  ``e(h) x + h [(phi_1 - phi_2) N_u + phi_2 N_c]``: ``h (2 phi_2 - 4 phi_3) (N_a + N_b - N_u
  - N_c)``, of order ``h^3``, so the next step is ``h min(5, max(0.2, 0.9 e^(-1/3)))``. The
  embedded third-order solutions of the same stages (``N_b`` for ``N_a``, the new rate for
  ``N_c``; or Cox and Matthews' third-order scheme) were measured first and left: their
  difference from the fourth-order solution came 1e4 to 1e5 times below its true local error
  on the free-hub test of ``tests/model/test_spatial_planar.py`` and on the two arrays (the
  error of ``a``, a first-order stage, is common to them all), and step doubling, which
  estimates it well, costs 11 evaluations for two steps.
- **The weights** of the error's RMS norm are CVODES's, ``atol + rtol max(|x|, |x+|)``, but
  for each modal rate: its ``atol`` is multiplied by the mode's frequency (the root of the
  rate's Jacobian's stiffness entry at the run's start, at least 1 rad/s), so that a rate's
  error is weighed as the displacement it makes over a radian of its mode, an energy norm.
  With CVODES's plain weights, the torsion modes' rates, moving some 1e-9 rad/s, held the two
  arrays' slew to 106 000 evaluations (the tips' error 3.7e-8); weighed so, 18 800 (4.0e-7,
  against Adams-Moulton's 6.4e-7 from 194 000).
- **Steps** end on every output time and every breakpoint of the torque (each sample of a
  line), so a step never crosses a kink: the interval between two such times is cut into equal
  steps, and a run of steps of one length (every interval of a uniform grid) is one call of
  up to :data:`CHAIN` steps (:func:`~flexctl.sim.step_chain.step_chain` on CasADi's virtual
  machine; the right-hand side is the compiled one; a rejected step ends the call's work). The
  coefficient matrices of each step length are computed once per Jacobian.
- **The Jacobian** (central differences of the compiled rate, ``2 n`` evaluations) is taken at
  the run's start and again every :data:`REFRESH` steps, so that ``L`` follows the hub's rate
  (gyroscopic coupling) and the attitude; any ``L`` gives the same order, the one at hand only
  the longest steps.

- **Where they cost more.** The error estimate can hold the steps far below what the fastest
  mode would ask of an explicit method: 1 000 N m on the two arrays (on 3 modes) spins the hub
  to 67 rad/s in 0.2 s, and the steps fell to some 2e-6 s (88 352 of them, 30 s) where
  Adams-Moulton takes 11 000. With a ``floor`` (the caller's: a radian of the fastest mode),
  :data:`HELD` calls in a row below it raise :class:`Abandoned`, and the spatial run takes
  the segment again, from its start, on Adams-Moulton (1.6 s for that run).

:class:`~flexctl.sim.spatial_run.SpatialSegments` (Adams-Moulton) stays the integrator of a
model that is not stiff on the run's grid (:data:`~flexctl.sim.spatial_run.STIFF_SPACING`),
of the equations restricted to a plane, of structures with reaction wheels (whose speed
limit switches the motor torque off within a band: exponential steps passed the rated speed by
0.4 %, ``tests/model/test_wheel_cluster.py``) and of sampled loops.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.checks import check_array, check_integer, check_real
from ..model.errors import InputValueError

__all__ = ["phi_functions", "central_jacobian", "sample_bound", "segment_torque",
           "ExponentialSegments", "SegmentFailed", "Abandoned", "CHAIN", "REFRESH", "EXPONENT"]

#: Steps of one length per compiled call.
CHAIN = 128
#: Accepted steps between two Jacobians of the rate.
REFRESH = 256
#: Calls in a row whose next step is below the floor before the segment is abandoned.
HELD = 3
#: Step-size control: safety factor, and the largest and smallest change of a step.
SAFETY, GROWTH, SHRINK = 0.9, 5.0, 0.2
#: The step control's exponent, ``-1 / 3``: the error estimate is that of a second-order
#: solution, ``O(h^3)``.
EXPONENT = -1.0 / 3.0
#: A step shorter than this fraction of the time reached (or of 1 s) ends the run.
MIN_STEP = 1e-12
#: Relative distance below which a sample of a line and an output time are one breakpoint.
MERGE = 1e-9
#: Coefficient sets (one per step length) kept per Jacobian.
CACHE_SIZE = 32
#: Largest 1-norm of the scaled matrix whose Taylor series :func:`phi_functions` sums.
TAYLOR_NORM = 0.25
#: Terms of that series: the first left out is below ``0.25^18 / 18!``, 1e-27.
TAYLOR_TERMS = 18


def phi_functions(matrix, order: int = 3) -> tuple:
    """``exp(A)`` and the functions ``phi_k(A) = sum_j A^j / (j + k)!`` for ``k = 1 ..
    order``: the coefficients of exponential integrators (``phi_0 = exp``, ``phi_k(0) = I /
    k!``, ``phi_k(A) A = phi_(k-1)(A) - I / (k-1)!``).

    Computed by scaling and doubling: the Taylor series of each ``phi_k(A / 2^s)``, with
    ``||A / 2^s||_1 <= 1/4``, then ``s`` times ``exp(2A) = exp(A)^2`` and
    ``phi_k(2A) = 2^-k [exp(A) phi_k(A) + sum_(j=1..k) phi_j(A) / (k-j)!]``: ``order + 1``
    matrix products a doubling, where the exponential of the block matrix that holds them
    all (``(order + 1) n`` square) costs ``(order + 1)^3`` times more.

    Parameters
    ----------
    matrix : array_like, shape (n, n)
        ``A``: finite, square.
    order : int, optional
        Highest ``k`` (1 to 6). Default 3.

    Returns
    -------
    tuple of ndarray, each shape (n, n)
        ``(exp(A), phi_1(A), ..., phi_order(A))``.

    Raises
    ------
    TypeError, ValueError
        If ``matrix`` is not a finite square array of numbers, or ``order`` is not an integer
        from 1 to 6.

    Examples
    --------
    >>> e, phi1 = phi_functions([[0.0, 1.0], [0.0, 0.0]], order=1)
    >>> e.tolist(), phi1.tolist()
    ([[1.0, 1.0], [0.0, 1.0]], [[1.0, 0.5], [0.0, 1.0]])
    """
    a = check_array("phi_functions", "matrix", matrix, shape=(None, None))
    if a.shape[0] != a.shape[1]:
        raise ValueError(f"phi_functions: matrix must be square; got shape {a.shape}")
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) \
            or not 1 <= order <= 6:
        raise ValueError(f"phi_functions: order must be an integer from 1 to 6; got {order!r}")
    n, order = a.shape[0], int(order)
    norm = float(np.max(np.sum(np.abs(a), axis=0), initial=0.0))
    if norm > 1e300:
        raise ValueError(f"phi_functions: matrix's 1-norm, {norm:.3g}, is too large for its "
                         "exponential")
    doublings = max(0, math.ceil(math.log2(norm / TAYLOR_NORM))) if norm > 0.0 else 0
    x = a / 2.0 ** doublings
    powers = [np.eye(n)]
    for _ in range(TAYLOR_TERMS):
        powers.append(powers[-1] @ x)
    funcs = []
    for k in range(order + 1):
        total = np.zeros((n, n))
        for j in range(TAYLOR_TERMS, -1, -1):      # the smallest terms first
            total += powers[j] / math.factorial(j + k)
        funcs.append(total)
    for _ in range(doublings):
        funcs = _doubled(funcs)
    return tuple(funcs)


class SegmentFailed(Exception):
    """An integration that could not continue (the message says why)."""


class Abandoned(Exception):
    """Exponential steps held below their ``floor`` (:class:`ExponentialSegments`): another
    integrator would take the segment for less."""


def sample_bound(times, a: float, wanted, max_steps: int):
    """Why a run along a line through samples, each step ending at or before the next sample,
    runs out of steps between two output times, if the samples are the reason, else None.

    Parameters
    ----------
    times : array_like, shape (K,)
        The samples' times, s (ascending).
    a : float
        The segment's start, s.
    wanted : array_like
        Its output times, s.
    max_steps : int
        The step budget between two output times.

    Returns
    -------
    str or None
    """
    gap = float(np.max(np.diff(np.concatenate([[a], np.asarray(wanted, dtype=float)]))))
    interval = float(np.min(np.diff(times)))
    if gap / interval > max_steps / 2:
        return (f"the torque samples' shortest interval, {interval:.3g} s, bounds every step, "
                f"and an output interval of {gap:.3g} s needs {gap / interval:.3g} of them; a "
                f"shorter output_step would let it finish")
    return None


def central_jacobian(mapped, x, torque) -> np.ndarray:
    """A right-hand side's Jacobian (n, n) at ``x`` under ``torque`` by central differences
    (steps of ``6e-6 max(|x_i|, 1)``: an error near ``eps^(2/3)`` of the entries).

    Parameters
    ----------
    mapped : casadi.Function
        The right-hand side ``(x, torque) -> x_t`` mapped over ``2 n`` columns.
    x : array_like, shape (n,)
        The state.
    torque : array_like, shape (3,)
        The hub torque, N m.

    Returns
    -------
    ndarray, shape (n, n)

    Raises
    ------
    TypeError, ValueError
        If ``x`` or ``torque`` is not a finite vector of its size, or ``mapped`` not such a
        function.
    """
    import casadi as ca

    x = check_array("central_jacobian", "x", x, shape=(None,))
    torque = check_array("central_jacobian", "torque", torque, shape=(3,))
    n = x.size
    if not isinstance(mapped, ca.Function) or mapped.n_in() != 2 \
            or mapped.size_in(0) != (n, 2 * n):
        raise ValueError(f"central_jacobian: mapped must be a casadi.Function of (x, torque) "
                         f"over {2 * n} columns of {n} states; got {mapped!r:.80}")
    steps = 6e-6 * np.maximum(np.abs(x), 1.0)
    points = np.tile(x[:, None], (1, 2 * n))
    points[np.arange(n), np.arange(n)] += steps
    points[np.arange(n), n + np.arange(n)] -= steps
    torques = np.tile(np.asarray(torque, dtype=float)[:, None], (1, 2 * n))
    rates = mapped(points, torques).full()
    return (rates[:, :n] - rates[:, n:]) / (2.0 * steps)


def _doubled(funcs: list) -> list:
    """``[exp(2A), phi_1(2A), ...]`` from ``[exp(A), phi_1(A), ...]``."""
    e = funcs[0]
    out = [e @ e]
    for k in range(1, len(funcs)):
        value = e @ funcs[k]
        for j in range(1, k + 1):
            value = value + funcs[j] / math.factorial(k - j)
        out.append(value / 2.0 ** k)
    return out


def _coefficients(jacobian: np.ndarray, h: float) -> list:
    """The step's matrices for length ``h`` (s): ``[[e(h/2); e(h)] (2n, n),
    [h/2 phi_1(hL/2); h phi_1(hL); h (phi_1 - 3 phi_2 + 4 phi_3)] (3n, n), h phi_2(hL/2),
    2 h phi_2(hL), h (2 phi_2 - 4 phi_3), h (4 phi_3 - phi_2)]``, each in column-major order
    as one vector."""
    half = phi_functions(0.5 * h * jacobian, 3)
    e, p1, p2, p3 = _doubled(list(half))
    blocks = [np.vstack([half[0], e]),
              np.vstack([0.5 * h * half[1], h * p1, h * (p1 - 3.0 * p2 + 4.0 * p3)]),
              h * half[2], 2.0 * h * p2, h * (2.0 * p2 - 4.0 * p3), h * (4.0 * p3 - p2)]
    return [block.ravel(order="F") for block in blocks]


def segment_torque(form, tau):
    """The torque of an 11-number segment form, ``form[0:3] + form[3:6] tau + form[6:9]
    sin(form[9] (form[10] + tau))``, N m (CasADi).

    Parameters
    ----------
    form : casadi.MX or casadi.SX, shape (11,) or longer
        The form's numbers (those after the eleventh are not read).
    tau : casadi.MX or casadi.SX or float
        Time from the segment's (or step's) start, s.
    """
    import casadi as ca

    return form[0:3] + form[3:6] * tau + form[6:9] * ca.sin(form[9] * (form[10] + tau))


def _chain(rhs, n: int):
    """``chain(carry, form (12, CHAIN), atol, rtol, h, L, coefficients...) -> (carries (2n+1,
    CHAIN), errors (1, CHAIN))``: up to :data:`CHAIN` steps of one length ``h``, the carry
    ``[x; N(x); stopped]``; a rejected step sets ``stopped`` and leaves the state, and the
    steps after it, and those whose ``form[11]`` is 0, pass it through."""
    import casadi as ca

    from .step_chain import skippable, step_chain

    carry, form = ca.MX.sym("carry", 2 * n + 1), ca.MX.sym("form", 12)
    atol, rtol = ca.MX.sym("atol", n), ca.MX.sym("rtol")
    jac = ca.MX.sym("L", n * n)
    sizes = (2 * n * n, 3 * n * n, n * n, n * n, n * n, n * n)
    blocks = [ca.MX.sym(f"c{k}", size) for k, size in enumerate(sizes)]
    h = ca.MX.sym("h")
    shared = [atol, rtol, h, jac] + blocks
    matrix = ca.reshape(jac, n, n)
    ex, en, p2h, p2, f2, f3 = (ca.reshape(block, rows, n) for block, rows in
                               zip(blocks, (2 * n, 3 * n, n, n, n, n)))
    x, nu = carry[0:n], carry[n:2 * n]

    def remainder(state, tau):
        return rhs(state, segment_torque(form, tau)) - ca.mtimes(matrix, state)

    exps, terms = ca.mtimes(ex, x), ca.mtimes(en, nu)
    half, whole = exps[0:n], exps[n:2 * n]
    na = remainder(half + terms[0:n], 0.5 * h)
    nb = remainder(half + terms[0:n] + ca.mtimes(p2h, na - nu), 0.5 * h)
    nc = remainder(whole + terms[n:2 * n] + ca.mtimes(p2, nb - nu), h)
    new = whole + terms[2 * n:3 * n] + ca.mtimes(f2, na + nb) + ca.mtimes(f3, nc)
    nn = remainder(new, h)
    # the difference from the second-order solution on the same nodes
    error = ca.mtimes(f2, na + nb - nu - nc)
    weight = atol + rtol * ca.fmax(ca.fabs(x), ca.fabs(new))
    norm = ca.sqrt(ca.sumsqr(error / weight) / n)
    accepted = norm <= 1.0                         # a NaN norm never is
    out = ca.if_else(accepted, ca.vertcat(new, nn, 0.0), ca.vertcat(x, nu, 1.0))
    step = ca.Function("flexctl_exponential_step", [carry, form] + shared, [out, norm])
    # a step after a rejected one, or past the run's steps (form[11] = 0), is skipped
    body = skippable(step, lambda carry, form, *rest: ca.logic_or(carry[2 * n] > 0.5,
                                                                  form[11] < 0.5),
                     lambda carry, *rest: [carry, ca.MX(0.0)], "flexctl_exponential")
    return step_chain(body, CHAIN, "flexctl_exponential_chain", stacked=(1,))


class ExponentialSegments:
    """Krogstad's exponential fourth-order steps with error control (module docstring) from
    breakpoint to breakpoint: the interface of :class:`~flexctl.sim.spatial_run.SpatialSegments`
    (``form``, ``count``, ``build``, ``advance``, ``steps``, ``evaluations``) for a torque with
    a segment form.

    Parameters
    ----------
    rhs : casadi.Function
        ``(x, torque) -> x_t``.
    n_states : int
        Length of ``x``.
    drive : callable
        The torque, ``t -> (3,)``, with ``segment_form(a, b)`` (its 11 parameters on a
        segment with no breakpoint inside) and, for a line, ``times``.
    rtol, atol : float
        Relative and absolute tolerance of each step's error (weighted RMS norm).
    line : bool
        A line through many samples, integrated in one segment: its samples are then
        breakpoints of the steps.
    max_steps : int
        Most steps between two output times.
    modal : tuple of ndarray, optional
        ``(coordinates, rates)``: the indices of the modal coordinates and of their rates, in
        the same order (their rates' ``atol`` is scaled by each mode's frequency). Default
        none.
    jacobian : ndarray, shape (n_states, n_states), optional
        The rate's Jacobian at the run's start (by :func:`central_jacobian`), where the
        caller has it. Default: taken at the first segment.
    floor : float, optional
        A step length, s: when :data:`HELD` calls in a row end with the next step below it,
        :meth:`advance` raises :class:`Abandoned` (the caller's cue to take the segment on
        another integrator). Default 0: never.
    """

    def __init__(self, rhs, n_states: int, drive, rtol: float, atol: float, line: bool,
                 max_steps: int, modal=(), jacobian=None, floor: float = 0.0):
        owner = "ExponentialSegments"
        self.floor, self.held = check_real(owner, "floor", floor, minimum=0.0), 0
        self.n = check_integer(owner, "n_states", n_states, minimum=1)
        self.rhs, self.drive = rhs, drive
        self.rtol = check_real(owner, "rtol", rtol, minimum=0.0, strict=True, maximum=1.0)
        self.atol = np.full(self.n, check_real(owner, "atol", atol, minimum=0.0, strict=True))
        self.line = bool(line)
        self.max_steps = check_integer(owner, "max_steps", max_steps, minimum=1)
        if not callable(getattr(drive, "segment_form", None)):
            raise InputValueError(f"{owner} drive must have a segment_form(a, b); got "
                                  f"{type(drive).__name__}")
        self.modal = (np.asarray(modal[0], dtype=int), np.asarray(modal[1], dtype=int)) \
            if len(modal) else (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
        if self.modal[0].shape != self.modal[1].shape or np.any(
                (np.concatenate(self.modal) < 0) | (np.concatenate(self.modal) >= self.n)):
            raise InputValueError(f"{owner} modal must be two index arrays of one length "
                                  f"within the {self.n} states")
        self.weights = None
        self.form = getattr(drive, "segment_form", None)
        self.steps = self.evaluations = 0
        # built here, in the caller's thread (CasADi's symbolic work is not thread-safe)
        self.differences = rhs.map(2 * self.n)
        self.chain = None
        self.jacobian, self.since, self.cache = None, 0, {}
        self.h = None
        if jacobian is not None:
            self._take(np.array(jacobian, dtype=float))
            self.evaluations += 2 * self.n

    def count(self, pieces) -> int:
        """Integrators the run needs built ahead (one compiled chain for every segment).

        Parameters
        ----------
        pieces : list of tuple
            ``(a, b, wanted)`` each: a segment's ends (s) and its output times.
        """
        return 1

    def build(self, a: float, b: float, wanted):
        """The chain of steps, built once (every segment shares it).

        Parameters
        ----------
        a, b : float
            The segment's ends, s.
        wanted : array_like
            Output times in ``(a, b]``, s.
        """
        if self.chain is None:
            self.chain = _chain(self.rhs, self.n)
        return self.chain

    def _remainder(self, x, t) -> np.ndarray:
        self.evaluations += 1
        return self.rhs(x, self.drive(t)).full().ravel() - self.jacobian @ x

    def _refresh(self, x, t) -> None:
        jacobian = central_jacobian(self.differences, x, self.drive(t))
        self.evaluations += 2 * self.n
        if not np.all(np.isfinite(jacobian)):
            raise SegmentFailed(f"the rate's Jacobian at t = {t:g} s is not finite: the "
                                f"state has left the model's domain")
        self._take(jacobian)

    def _take(self, jacobian: np.ndarray) -> None:
        self.jacobian, self.since, self.cache = jacobian, 0, {}
        if self.weights is None:
            # each modal rate's error in its mode's displacement units: divided by the mode's
            # frequency, the root of its stiffness over its mass at the run's start
            coordinates, rates = self.modal
            stiffness = -jacobian[rates, coordinates]
            self.weights = self.atol.copy()
            self.weights[rates] *= np.sqrt(np.maximum(stiffness, 1.0))

    def _coefficients(self, key: float) -> list:
        if key not in self.cache:
            if len(self.cache) >= CACHE_SIZE:
                self.cache.pop(next(iter(self.cache)))
            self.cache[key] = _coefficients(self.jacobian, key)
        return self.cache[key]

    def _events(self, a: float, b: float, wanted) -> np.ndarray:
        """The ends of the steps' intervals on ``(a, b]``: the output times and, for a line,
        its samples (a sample within :data:`MERGE` of an output time or of ``a`` is that
        time: the steps never leave a sliver)."""
        events = np.asarray(wanted, dtype=float)
        if not self.line:
            return events
        samples = self.drive.times
        samples = samples[(samples > a) & (samples < b)]
        ends = np.concatenate([[a], events])
        near = np.searchsorted(ends, samples)
        gap = np.minimum(np.abs(samples - ends[np.maximum(near - 1, 0)]),
                         np.abs(ends[np.minimum(near, ends.size - 1)] - samples))
        keep = gap > MERGE * np.maximum(1.0, np.abs(samples))
        return np.union1d(events, samples[keep])

    def _forms(self, a: float, b: float, starts: np.ndarray, gaps: np.ndarray,
               lows: np.ndarray) -> np.ndarray:
        """(12, CHAIN): each step's torque form in its own time (``starts`` the steps'
        starts, ``gaps`` their intervals' indices, ``lows`` the intervals' starts), and 1
        for the steps to take."""
        if self.line:
            bases = {g: self.form(lows[g], lows[g + 1]) for g in np.unique(gaps)}
            base = np.column_stack([bases[g] for g in gaps])
            offset = starts - lows[gaps]
        else:
            base = np.repeat(self.form(a, b)[:, None], starts.size, axis=1)
            offset = starts - a
        forms = np.zeros((12, CHAIN))
        forms[0:11, :starts.size] = base
        forms[0:3, :starts.size] += base[3:6] * offset
        forms[10, :starts.size] += offset
        forms[11, :starts.size] = 1.0
        return forms

    def _plan(self, events: np.ndarray, gap: int, t: float) -> tuple:
        """The next call's steps, all of one length: the rest of interval ``gap`` from ``t``,
        then the whole intervals after it that the same length divides (at most
        :data:`CHAIN`). ``(h, starts, intervals, ends)``: the length (s), each step's start
        and interval, and ``{step index: the interval it ends}``."""
        end = events[gap]
        count = max(1, math.ceil((end - t) / self.h - 1e-9))
        # to 12 digits, so that the intervals of a uniform grid share their coefficients
        h = float(f"{(end - t) / count:.12g}")
        if not h >= MIN_STEP * max(1.0, abs(t)):
            raise SegmentFailed(f"step size {h:.3g} s at t = {t:.6g} s: the error control "
                                f"found no step short enough")
        starts, owners = [t + h * np.arange(min(count, CHAIN))], [gap]
        size, ends = starts[0].size, {}
        if size == count:
            ends[size - 1] = gap
            following = gap + 1
            while size < CHAIN and following < events.size:
                length = events[following] - events[following - 1]
                fits = max(1, round(length / h))
                if abs(length / fits - h) > 1e-9 * h or size + fits > CHAIN:
                    break
                starts.append(events[following - 1] + h * np.arange(fits))
                owners.append(following)
                size += fits
                ends[size - 1] = following
                following += 1
        intervals = np.concatenate([np.full(s.size, g) for s, g in zip(starts, owners)])
        return h, np.concatenate(starts), intervals, ends

    def _control(self, h: float, norms: np.ndarray, accepted: int, size: int, t: float) -> bool:
        """The next step length from the call's error norms; False where a state could not be
        kept finite at the shortest step (the run ends there)."""
        if accepted < size:
            norm = float(norms[accepted])
            if not math.isfinite(norm):
                if h <= MIN_STEP * max(1.0, abs(t)) * 1e3:
                    return False
                self.h = SHRINK * h
            else:
                self.h = h * max(SHRINK, SAFETY * norm ** EXPONENT)
        else:
            worst = float(np.max(norms[:size]))
            self.h = h * (GROWTH if worst == 0.0 else min(GROWTH, SAFETY * worst ** EXPONENT))
        return True

    def advance(self, a: float, b: float, x, wanted) -> np.ndarray:
        """The states at ``wanted``, from ``x`` at ``a``.

        Parameters
        ----------
        a, b : float
            The segment's ends, s.
        x : ndarray, shape (n_states,)
            The state at ``a``.
        wanted : array_like
            Output times in ``(a, b]``, ascending, ending at ``b``, s.

        Returns
        -------
        ndarray, shape (n_states, len(wanted))
            NaN from the first time the state could not be kept finite.

        Raises
        ------
        SegmentFailed
            When the integration cannot go on (the message says why).
        """
        n, chain = self.n, self.build(a, b, wanted)
        wanted = np.asarray(wanted, dtype=float)
        events = self._events(a, b, wanted)
        lows = np.concatenate([[a], events])
        out = np.full((n, wanted.size), np.nan)
        y = np.array(x, dtype=float)
        if self.jacobian is None or self.since >= REFRESH:
            self._refresh(y, a)
        nu = self._remainder(y, a)
        if self.h is None:
            self.h = (b - a) / 10.0 if wanted.size < 10 else float(np.min(np.diff(lows)))
        gap, t, taken = 0, float(a), 0          # the interval, the time, steps since an output
        carry = np.zeros(2 * n + 1)
        while gap < events.size:
            if self.since >= REFRESH:
                self._refresh(y, t)
                nu = self._remainder(y, t)
            h, starts, intervals, ends = self._plan(events, gap, t)
            size = starts.size
            carry[0:n], carry[n:2 * n], carry[2 * n] = y, nu, 0.0
            states, norms = chain(carry, self._forms(a, b, starts, intervals, lows),
                                  self.weights, self.rtol, h, self.jacobian.ravel(order="F"),
                                  *self._coefficients(h))
            states, norms = states.full(), norms.full().ravel()
            stopped = states[2 * n, :size] > 0.5
            accepted = int(np.argmax(stopped)) if np.any(stopped) else size
            self.steps += min(accepted + 1, size)
            self.evaluations += 4 * min(accepted + 1, size)
            self.since += accepted
            taken += accepted
            if accepted:
                y, nu = states[0:n, accepted - 1].copy(), states[n:2 * n, accepted - 1].copy()
                for k in (k for k in ends if k < accepted):
                    index = int(np.searchsorted(wanted, events[ends[k]]))
                    if index < wanted.size and wanted[index] == events[ends[k]]:
                        out[:, index], taken = states[0:n, k], 0
                    gap = max(gap, ends[k] + 1)
                last = accepted - 1
                t = float(events[ends[last]]) if last in ends else float(starts[last] + h)
            if not self._control(h, norms, accepted, size, t):
                return out                    # NaN from here on: the caller reports it
            if taken > self.max_steps:
                raise SegmentFailed(self._budget(a, b, wanted, h))
            self.held = self.held + 1 if self.h < self.floor else 0
            if self.held >= HELD:
                raise Abandoned(f"steps near {self.h:.2g} s at t = {t:g} s, below "
                                f"{self.floor:.2g} s")
        return out

    def _budget(self, a: float, b: float, wanted, h: float) -> str:
        """Why the steps between two output times ran past the budget."""
        head = (f"the exponential steps took more than {self.max_steps:g} steps between two "
                f"output times in [{a:g}, {b:g}] s")
        bound = sample_bound(self.drive.times, a, wanted, self.max_steps) if self.line \
            else None
        if bound is not None:
            return f"{head}: {bound}"
        return (f"{head}: the error control held them near {h:.2g} s; a looser rtol or atol, "
                f"fewer modes per field or a shorter output_step would let it finish")
