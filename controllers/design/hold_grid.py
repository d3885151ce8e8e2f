"""What a grid of torque holds can do for a slew: resolution and effort of each design mode.

:func:`controllers.solve_slew` holds the torque constant on ``K`` intervals of length
``h = T / K`` and brings every design mode to rest at ``T``. Two facts about that grid decide,
before IPOPT runs, whether a slew can be solved to its true optimum:

- **Resolution.** Each hold is integrated by ``s`` RK4 substeps or ``m`` collocation elements.
  :func:`steps_per_hold` picks the smallest count that integrates every design mode over the
  whole slew within its tolerance (:func:`mode_tolerances`): ``omega T / (omega dt)`` steps,
  each off by ``|R(i omega dt) - exp(i omega dt)|`` (``R`` the scheme's stability function;
  exact for a linear oscillator).
- **Aliasing.** Seen through holds of length ``h``, a mode of frequency ``omega`` above the
  hold Nyquist frequency ``pi / h`` behaves like one at its alias ``|omega - 2 pi j / h|``,
  and stopping a mode aliased near zero fights the slew's own torque (with ``omega h`` a
  multiple of ``pi``, the holds move the mode along a single direction only).
  :func:`hold_effort_excess` measures the effect on the linearisation at rest: the least
  effort of ``K`` holds that reach the target, against the least effort of a continuous
  torque (the converged value).

Notes
-----
The excess is computed in the modal coordinates of the linearisation ``(A, B)`` at rest,
``z = [omega_j eta_j, eta_dot_j]`` per mode (``omega_0 = 1`` for the rigid-body mode), where
``A`` is nearly skew and both the hold map and the controllability Gramian are well conditioned:

- ``K`` holds: ``x(T) = G u``, ``G[:, k] = Phi^(K-1-k) Gamma`` with ``Phi = exp(A h)`` and
  ``Gamma = int_0^h exp(A s) B ds``; least effort ``h min |u|^2 = h z_f^T (G G^T)^-1 z_f``.
- continuous: ``z_f^T W^-1 z_f`` with ``W = int_0^T exp(A s) B B^T exp(A^T s) ds`` (Van Loan).

Honouring only the rigid-body mode and the first ``j`` flexible modes keeps their rows; the
first ``j`` whose excess passes the tolerance names the mode that the holds cannot stop
cheaply.
"""

from __future__ import annotations

import functools
import math
import weakref
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from flexctl.model.errors import InputValueError
from flexctl.model.layout import StateLayout

__all__ = ["PHASE_TOLERANCE", "END_STATE_TOLERANCE", "MAX_SUBSTEPS", "HOLD_EFFORT_TOLERANCE",
           "step_error", "steps_per_hold", "largest_step", "mode_tolerances", "HoldEffort",
           "HoldGrid", "hold_effort_excess"]

#: Error that integrating a design mode over the whole slew may leave, relative to that
#: mode's own amplitude. Measured on slew-90 (``benchmarks/bench_trajopt.py``): a mode
#: integrated with errors near 1 is a different mode, and stopping it can cost over 1 % more
#: effort; 0.2 leaves the effort within 0.05 % of the converged discretisation.
PHASE_TOLERANCE = 0.05
#: Error the integration may leave in the end state, relative to the largest motion of its
#: kind (modal deflection or modal rate): a mode that carries a share ``w`` of that motion is
#: held to ``END_STATE_TOLERANCE / w`` of its own amplitude (at most PHASE_TOLERANCE), so the
#: slowest mode is integrated finely and a fast one that hardly moves only to PHASE_TOLERANCE.
END_STATE_TOLERANCE = 1e-3
#: More RK4 substeps per hold than this means design modes far faster than the holds can shape:
#: fewer design modes or more intervals is the remedy.
MAX_SUBSTEPS = 100
#: Largest relative excess of the least effort of the holds over the converged (continuous
#: torque) effort that a slew accepts; above it the holds are refused, naming the interval
#: counts and design-mode counts that stay within it.
HOLD_EFFORT_TOLERANCE = 0.01
#: A design mode that turns less than this over the slew (``omega T``, rad) hardly moves: the
#: hub torque cannot stop it apart from the rigid body, and the hold analysis is singular.
SLOW_MODE_PHASE = 1e-2
#: Largest ``omega_max dt`` per step: RK4 is stable up to 2.83 on the imaginary axis; a
#: collocation element spans at most half a period of the fastest mode.
LARGEST_STEP = {"rk4": 2.5, "radau": math.pi, "legendre": math.pi}
SCHEMES = ("rk4", "radau", "legendre")


@functools.lru_cache(maxsize=None)
def _butcher(scheme: str, degree: int):
    """Butcher ``A`` (d, d) and ``b`` (d,) of the collocation method on CasADi's points."""
    import casadi as ca
    from numpy.polynomial import polynomial as P

    tau = np.asarray(ca.collocation_points(degree, scheme), dtype=float)
    a, b = np.zeros((degree, degree)), np.zeros(degree)
    for j in range(degree):
        basis = np.array([1.0])
        for k in range(degree):
            if k != j:
                basis = P.polymul(basis, np.array([-tau[k], 1.0]) / (tau[j] - tau[k]))
        integral = P.polyint(basis)
        a[:, j] = P.polyval(tau, integral)
        b[j] = P.polyval(1.0, integral)
    return a, b


def step_error(scheme: str, omega_dt: float, degree: int = 3) -> float:
    """``|R(i omega dt) - exp(i omega dt)|``: one step's error on an undamped oscillator.

    ``R`` is the scheme's stability function: RK4's Taylor polynomial, or
    ``1 + z b^T (I - z A)^-1 1`` of the collocation method. The error is relative to the
    mode's amplitude.

    Parameters
    ----------
    scheme : {"rk4", "radau", "legendre"}
        One RK4 step, or one collocation element on CasADi's points of that name.
    omega_dt : float
        The step times the mode's frequency, ``omega dt``, rad.
    degree : int, optional
        Collocation points per element (not read for ``"rk4"``). Default 3.

    Examples
    --------
    >>> round(step_error("rk4", 0.3), 7)              # (0.3)^5 / 120
    2.02e-05
    >>> step_error("legendre", 1.0) < step_error("radau", 1.0) < step_error("rk4", 1.0)
    True
    """
    z = 1j * omega_dt
    if scheme == "rk4":
        r = 1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24
    else:
        a, b = _butcher(scheme, degree)
        r = 1 + z * b @ np.linalg.solve(np.eye(degree) - z * a, np.ones(degree))
    return float(abs(r - np.exp(z)))


def steps_per_hold(scheme: str, omega, hold: float, duration: float, degree: int = 3,
                   tolerance=PHASE_TOLERANCE) -> int:
    """Fewest steps per hold that integrate each frequency in ``omega`` over ``duration``
    within its ``tolerance`` of its amplitude.

    Parameters
    ----------
    scheme : {"rk4", "radau", "legendre"}
        RK4 substeps or collocation elements (``degree`` points each).
    omega : float or array_like, shape (N,)
        Design frequencies, rad/s.
    hold : float
        Hold length ``h``, s.
    duration : float
        Time over which the errors add up (the slew), s.
    degree : int, optional
        Collocation points per element (not read for ``"rk4"``). Default 3.
    tolerance : float or array_like, shape (N,)
        Error allowed for each frequency over ``duration``, relative to its amplitude
        (:func:`mode_tolerances`).

    Examples
    --------
    >>> steps_per_hold("rk4", 100.0, 0.05, 2.0)      # omega h = 5, omega T = 200
    13
    >>> steps_per_hold("radau", 100.0, 0.05, 2.0), steps_per_hold("legendre", 100.0, 0.05, 2.0)
    (5, 3)
    >>> steps_per_hold("rk4", [5.0, 100.0], 0.05, 2.0, tolerance=[1e-3, 0.05])
    13
    """
    omega, tolerance = np.broadcast_arrays(np.atleast_1d(np.asarray(omega, dtype=float)),
                                           np.asarray(tolerance, dtype=float))
    steps = 1
    for w, tol in zip(np.abs(omega), tolerance):
        if w * hold > 0.0:
            largest = largest_step(scheme, w, max(duration, hold), degree, tol)
            steps = max(steps, math.ceil(w * hold / largest))
    return steps


def largest_step(scheme: str, omega: float, duration: float, degree: int = 3,
                 tolerance: float = PHASE_TOLERANCE) -> float:
    """Largest ``omega dt`` of one step that integrates ``omega`` over ``duration`` within
    ``tolerance`` of its amplitude; ``omega duration`` divided by it is the fewest steps a
    slew can take.

    Parameters
    ----------
    scheme : {"rk4", "radau", "legendre"}
        RK4 substeps or collocation elements (``degree`` points each).
    omega : float
        The mode's frequency, rad/s (> 0).
    duration : float
        Time over which the errors add up (the slew), s (> 0).
    degree : int, optional
        Collocation points per element (not read for ``"rk4"``). Default 3.
    tolerance : float, optional
        Error allowed over ``duration``, relative to the mode's amplitude. Default
        :data:`PHASE_TOLERANCE`.

    Raises
    ------
    InputValueError
        If ``scheme`` is not one of the three.

    Examples
    --------
    >>> round(largest_step("rk4", 100.0, 2.0), 3)       # (omega dt)^4 / 120 = 0.05 / 200
    0.416
    """
    if scheme not in SCHEMES:
        raise InputValueError(f"scheme must be one of {', '.join(map(repr, SCHEMES))}; "
                         f"got {scheme!r}")
    return _largest_step(scheme, degree, float(tolerance) / (omega * duration))


@functools.lru_cache(maxsize=4096)
def _largest_step(scheme: str, degree: int, per_radian: float) -> float:
    """Largest ``omega dt`` whose error per radian is within ``per_radian`` (bisection: the
    error per radian grows with the step)."""
    low, high = 0.0, LARGEST_STEP[scheme]
    if step_error(scheme, high, degree) / high <= per_radian:
        return high
    for _ in range(50):
        mid = 0.5 * (low + high)
        if step_error(scheme, mid, degree) / mid <= per_radian:
            low = mid
        else:
            high = mid
    return max(low, 1e-6)


def mode_tolerances(model):
    """Hub-free frequencies (rad/s) and the error each mode may keep over a slew.

    Mode ``i`` of the linearisation at rest, driven quasi-statically by the torque, moves the
    beam's modal coordinates by ``d_i = max|V[q, i]| |beta_i| / omega_i^2`` (per unit torque;
    ``V`` the mode shapes, ``q`` their modal rows, ``beta`` their modal input) and their rates
    by ``omega_i d_i``. Its share
    of the larger motion of either kind, ``w_i``, sets its tolerance
    ``min(PHASE_TOLERANCE, END_STATE_TOLERANCE / w_i)``.

    Parameters
    ----------
    model : flexctl.Model
        The design model; computed once per model and kept while it lives.

    Returns
    -------
    omega, tolerance : ndarray, shape (N,)

    Examples
    --------
    >>> import flexctl
    >>> model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=3)
    >>> omega, tolerance = mode_tolerances(model)
    >>> omega.round(1).tolist(), tolerance.round(4).tolist()
    ([5.5, 24.3, 68.5], [0.001, 0.0253, 0.05])
    """
    if model not in _TOLERANCES:
        _TOLERANCES[model] = _mode_tolerances(model)
    return _TOLERANCES[model]


_TOLERANCES = weakref.WeakKeyDictionary()       # per model: computed once, read-only


def _linear_form(model):
    """``(A, B, layout, P)``: the linearisation at rest on the modes the torque moves.

    For one beam every mode: the model's own ``A``, ``B`` and layout, ``P`` None. With modes
    the torque cannot move (symmetric appendages, a free hub's translation), the
    :class:`~controllers.design.controllable.ControllablePart` in its modal coordinates ``z = P x``,
    ordered as a one-beam layout's (the rigid rotation first)."""
    from .controllable import controllable_part

    linear = _linearisation_model(model)
    a, b = linear.linear_matrices(0.0)
    if len(linear.modes) == 1 and linear.layout.hub_position is None:
        return a, b, linear.layout, None
    part = controllable_part(linear)
    if not part.dropped:
        return a, b, linear.layout, None
    a_r, b_r = part.reduce(a, b)
    return a_r, b_r, StateLayout.single(a_r.shape[0] // 2 - 1), part.projector


def _mode_tolerances(model):
    a, b, layout, _ = _linear_form(model)
    lam, vec = np.linalg.eig(-a[layout.velocities, layout.coordinates])     # M^-1 K
    order = np.argsort(lam.real)[1:]                       # the rigid-body mode left out
    omega = np.sqrt(np.abs(lam.real[order]))
    vec = vec.real[:, order]                               # mode shapes in the coordinates
    beta = np.linalg.lstsq(vec, b[layout.velocities, 0], rcond=None)[0]
    deflection = np.max(np.abs(vec[layout.q]), axis=0) * np.abs(beta) / omega ** 2
    share = np.maximum(deflection / deflection.max(),
                       omega * deflection / (omega * deflection).max())
    tolerance = np.minimum(PHASE_TOLERANCE, END_STATE_TOLERANCE / share)
    omega.setflags(write=False)
    tolerance.setflags(write=False)
    return omega, tolerance


@dataclass(frozen=True)
class HoldEffort:
    """Least effort of ``n_intervals`` holds against a continuous torque, per honoured mode.

    Attributes
    ----------
    n_intervals : int
    excess : ndarray, shape (N + 1,)
        ``excess[j]``: relative excess of the holds' least effort over the continuous one
        when the rigid-body mode and the first ``j`` flexible modes must end at rest
        (``inf`` when the holds cannot stop them).
    frequencies : ndarray, shape (N,)
        Hub-free natural frequencies, rad/s, ascending.
    """

    n_intervals: int
    excess: np.ndarray
    frequencies: np.ndarray

    @property
    def worst(self) -> float:
        """Excess with every design mode honoured."""
        return float(self.excess[-1])

    def culprit(self, tolerance: float) -> int:
        """The first design mode (1-based) whose honouring takes the excess above
        ``tolerance`` (0: the rigid-body slew alone; N + 1: none).

        Parameters
        ----------
        tolerance : float
            Largest relative excess of effort accepted (e.g.
            :data:`HOLD_EFFORT_TOLERANCE`).
        """
        above = np.flatnonzero(self.excess > tolerance)
        return int(above[0]) if above.size else self.excess.size

    def modes_within(self, tolerance: float) -> int:
        """Most design modes, counted from the slowest, whose excess is within ``tolerance``.

        Parameters
        ----------
        tolerance : float
            Largest relative excess of effort accepted (e.g.
            :data:`HOLD_EFFORT_TOLERANCE`).
        """
        return max(self.culprit(tolerance) - 1, 0)


def _modal_form(a: np.ndarray, b: np.ndarray, layout):
    """``(A_z, B_z, T_z, omega)``: the linearisation (states of ``layout``) in scaled modal
    coordinates ``z = T_z x``, ``z = [omega_j eta_j, eta_dot_j]``."""
    coordinates, velocities = layout.coordinates, layout.velocities
    stiffness = -a[velocities, coordinates]        # M^-1 K, similar to a symmetric matrix
    lam, vec = np.linalg.eig(stiffness)
    order = np.argsort(lam.real)
    lam, vec = lam.real[order], vec.real[:, order]
    omega = np.sqrt(np.clip(lam, 0.0, None))
    omega[0] = 1.0                                 # the rigid-body mode: no stiffness
    inv = np.linalg.inv(vec)
    t_z = np.zeros_like(a)
    t_z[coordinates, coordinates] = omega[:, None] * inv
    t_z[velocities, velocities] = inv
    a_z = t_z @ a @ np.linalg.inv(t_z)
    return a_z, t_z @ b, t_z, omega


def _hold_map(a_z: np.ndarray, b_z: np.ndarray, duration: float, n_intervals: int):
    """``G`` (n, K): the end state reached from rest by unit torque on each hold."""
    n, h = a_z.shape[0], duration / n_intervals
    block = np.zeros((n + 1, n + 1))
    block[:n, :n], block[:n, n] = a_z * h, b_z[:, 0] * h
    e = scipy.linalg.expm(block)
    cols, power = e[:n, n:], e[:n, :n]              # Phi^k Gamma for k = 0, by doubling
    while cols.shape[1] < n_intervals:
        cols = np.hstack((cols, power @ cols))
        power = power @ power
    return cols[:, :n_intervals][:, ::-1]


def _gramian(a_z: np.ndarray, b_z: np.ndarray, duration: float) -> np.ndarray:
    n = a_z.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n], block[:n, n:], block[n:, n:] = -a_z, b_z @ b_z.T, a_z.T
    e = scipy.linalg.expm(block * duration)
    return e[n:, n:].T @ e[:n, n:]


class HoldGrid:
    """Torque holds over one rest-to-rest slew of a model's linearisation at rest.

    Built once per model, duration and angle (the modal form and the continuous least
    efforts, about 10 ms); :meth:`effort` and :meth:`reason` then cost a few milliseconds per
    interval count. The exact variant is analysed on its first_order twin, which has the same
    linearisation at rest and builds in milliseconds.

    Parameters
    ----------
    model : flexctl.Model
        The design model (the exact variant is analysed on its first_order twin).
    duration : float
        Slew duration ``T``, s.
    angle : float, optional
        Slew angle, rad (the excess does not depend on it). Default 1.
    """

    def __init__(self, model, duration: float, angle: float = 1.0):
        a, b, layout, projector = _linear_form(model)
        self.n_dof = layout.n_coordinates
        self.frequencies, self.duration = np.sqrt(np.abs(np.sort(
            np.linalg.eigvals(-a[layout.velocities, layout.coordinates]).real)[1:])), duration
        self.rows = [self._rows(j) for j in range(self.n_dof)]
        # The excess is a ratio of efforts, which both scale as |B|^-2: a unit input keeps a
        # tiny rigid inertia J0 (B ~ 1 / J0) from overflowing the Van Loan exponential
        with np.errstate(all="ignore"):
            try:
                self.a_z, b_z, t_z, omega = _modal_form(a, b, layout)
                self.b_z = b_z / np.linalg.norm(b_z)
                self.frequencies = omega[1:]
                target = (layout.join(theta=angle) if projector is None
                          else projector @ model.layout.join(theta=angle))
                self.target = t_z @ target
                gramian = _gramian(self.a_z, self.b_z, duration)
                self.continuous = np.array([self.target[r] @ np.linalg.solve(
                    gramian[np.ix_(r, r)], self.target[r]) for r in self.rows])
            except np.linalg.LinAlgError:
                self.continuous = np.full(self.n_dof, np.nan)
        if not (np.all(np.isfinite(self.continuous)) and np.all(self.continuous > 0.0)):
            raise InputValueError(self._unresolved())

    def _unresolved(self) -> str:
        """Why the holds of this slew cannot be analysed: the physical scales involved."""
        w, T = self.frequencies, self.duration
        what = (f"the design model's linearisation at rest cannot be analysed over the "
                f"{T:.4g} s slew in floating point: its {w.size} design mode"
                f"{'s span' if w.size > 1 else ' is at'} {w[0]:.4g}"
                f"{f' to {w[-1]:.4g}' if w.size > 1 else ''} rad/s (omega T = {w[0] * T:.3g}"
                f"{f' to {w[-1] * T:.3g}' if w.size > 1 else ''} rad)")
        if w[0] * T < SLOW_MODE_PHASE:
            return (f"{what}; design mode 1 hardly moves during the slew, so the hub torque "
                    f"cannot bring the beam to rest with it: lengthen the duration towards its "
                    f"period {2 * math.pi / w[0]:.3g} s or stiffen the beam "
                    "(beam.youngs_modulus)")
        return (f"{what}; use fewer design modes (model.design_modes), a duration nearer the "
                "rigid-body minimum time, or check the beam and hub parameters")

    def _rows(self, honoured: int) -> np.ndarray:
        """Modal states of the rigid-body mode and the first ``honoured`` modes."""
        keep = np.arange(honoured + 1)
        return np.concatenate((keep, self.n_dof + keep))

    def excess(self, n_intervals: int, honoured: int | None = None) -> np.ndarray:
        """Excess of the holds' least effort for 0 .. N honoured modes, shape (N + 1,) (or for
        ``honoured`` modes only, shape (1,)).

        Parameters
        ----------
        n_intervals : int
            Number of holds ``K`` over the slew (each ``duration / K`` s).
        honoured : int, optional
            Number of flexible modes, from the slowest, that must end at rest with the
            rigid-body mode. Default: every count from 0 to N.

        Raises
        ------
        InputValueError
            If the hold map cannot be evaluated in floating point.
        """
        h = self.duration / n_intervals
        counts = range(self.n_dof) if honoured is None else [honoured]
        excess = np.full(len(counts), np.nan)
        with np.errstate(all="ignore"):
            g = _hold_map(self.a_z, self.b_z, self.duration, n_intervals)
            for i, count in enumerate(counts):
                rows = self.rows[count]
                z, gj = self.target[rows], g[rows]
                if not np.all(np.isfinite(gj)):
                    break
                try:
                    u, *_ = np.linalg.lstsq(gj, z, rcond=None)
                except np.linalg.LinAlgError:
                    break
                miss = np.linalg.norm(gj @ u - z) / np.linalg.norm(z)
                excess[i] = np.inf if miss > 1e-6 \
                    else h * (u @ u) / self.continuous[count] - 1.0
        if np.any(np.isnan(excess)):
            raise InputValueError(self._unresolved())
        return excess

    def effort(self, n_intervals: int) -> HoldEffort:
        """The excess of ``n_intervals`` holds for every honoured-mode count.

        Parameters
        ----------
        n_intervals : int
            Number of holds ``K`` over the slew (each ``duration / K`` s).
        """
        return HoldEffort(n_intervals, self.excess(n_intervals), self.frequencies)

    def passes(self, n_intervals: int, tolerance: float = HOLD_EFFORT_TOLERANCE) -> bool:
        """Whether ``n_intervals`` holds keep the excess within ``tolerance`` with every
        design mode honoured.

        Parameters
        ----------
        n_intervals : int
            Number of holds ``K`` over the slew (each ``duration / K`` s).
        tolerance : float, optional
            Largest relative excess of effort accepted. Default
            :data:`HOLD_EFFORT_TOLERANCE`.
        """
        return bool(self.excess(n_intervals, self.n_dof - 1)[0] <= tolerance)

    def reason(self, n_intervals: int, tolerance: float = HOLD_EFFORT_TOLERANCE) -> str | None:
        """Why ``n_intervals`` holds are too coarse for the design modes, or None.

        Parameters
        ----------
        n_intervals : int
            Number of holds ``K`` over the slew (each ``duration / K`` s).
        tolerance : float, optional
            Largest relative excess of effort accepted. Default
            :data:`HOLD_EFFORT_TOLERANCE`.

        Examples
        --------
        >>> import flexctl
        >>> model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=4)
        >>> print(HoldGrid(model, 2.0).reason(40))  # doctest: +NORMALIZE_WHITESPACE
        holds of 0.05 s see design mode 4 (134.6 rad/s) at its alias 8.92 rad/s, and stopping
        it costs 5.15 % more effort than the converged slew (limit 1 %)
        >>> HoldGrid(model, 2.0).reason(60) is None
        True
        """
        effort = self.effort(n_intervals)
        if effort.worst <= tolerance:
            return None
        if effort.excess[0] > tolerance:
            return (f"{n_intervals} holds shape even the rigid-body slew with "
                    f"{100 * effort.excess[0]:.3g} % more effort than a continuous torque "
                    f"(limit {100 * tolerance:g} %)")
        return _aliasing_reason(effort, effort.culprit(tolerance),
                                self.duration / n_intervals, tolerance)


def hold_effort_excess(model, duration: float, n_intervals: int,
                       angle: float = 1.0) -> HoldEffort:
    """Excess effort of ``n_intervals`` torque holds over a continuous torque, per mode.

    The least-effort rest-to-rest slew of ``model``'s linearisation at rest, without the
    torque bound (:class:`HoldGrid`).

    Parameters
    ----------
    model : flexctl.Model
        The design model (the exact variant is analysed on its first_order twin).
    duration : float
        Slew duration ``T``, s.
    n_intervals : int
        Number of holds ``K`` (each ``T / K`` s).
    angle : float, optional
        Slew angle, rad (the excess does not depend on it). Default 1.

    Examples
    --------
    >>> import flexctl
    >>> model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=4)
    >>> effort = hold_effort_excess(model, 2.0, 40)      # mode 4: 134.6 rad/s, h = 0.05 s
    >>> effort.culprit(HOLD_EFFORT_TOLERANCE), bool(effort.worst > 0.04)
    (4, True)
    >>> bool(hold_effort_excess(model, 2.0, 60).worst < HOLD_EFFORT_TOLERANCE)
    True
    """
    return HoldGrid(model, duration, angle).effort(n_intervals)


def _linearisation_model(model):
    """A model with ``model``'s linearisation at rest that is cheap to build: the exact
    variant's equals first_order's there, and building its geometry takes seconds."""
    if not model.variant.exact:
        return model
    from flexctl.model import build_model

    return build_model(model.system, n_modes=model.mode_spec, variant="first_order")


def _aliasing_reason(effort: HoldEffort, culprit: int, h: float, tolerance: float) -> str:
    omega = effort.frequencies[culprit - 1]
    if math.isinf(effort.excess[culprit]):
        return f"holds of {h:.3g} s cannot stop design mode {culprit} ({omega:.4g} rad/s)"
    alias = abs(omega - 2 * math.pi / h * round(omega * h / (2 * math.pi)))
    total = "" if culprit == effort.excess.size - 1 else \
        f", and stopping all {effort.excess.size - 1} modes {100 * effort.worst:.3g} %"
    return (f"holds of {h:.3g} s see design mode {culprit} ({omega:.4g} rad/s) at its alias "
            f"{alias:.3g} rad/s, and stopping it costs {100 * effort.excess[culprit]:.3g} % "
            f"more effort than the converged slew{total} (limit "
            f"{100 * tolerance:g} %)")
