"""Rest-to-rest slews by trajectory optimisation (CasADi Opti + IPOPT), and their tracking.

:func:`solve_slew` turns a :class:`SlewProblem` into a :class:`SlewSolution`: the hub torque,
held constant on each of ``K`` intervals, that slews the hub of a :class:`~flexctl.Model`
by ``angle`` from rest to rest with every flexible state back at zero, at minimum effort over
a given duration or in minimum time. :class:`controllers.feedback.tracking.TrajectoryTracker`
follows
such a solution on a plant that differs from the design model.

Notes
-----
Symbols: ``N`` design modes, ``n = 2 N + 2`` states in the order of
:attr:`flexctl.Model.state_names`, ``K`` intervals (``problem.n_intervals``) of length
``h = T / K``, ``m`` collocation elements per hold (collocation only; ``m = 1`` otherwise),
``d = 3`` collocation points per element, ``x_f`` the target ``[angle, 0 .. 0]``. The decision
variables, in this order::

    X   (n, m K + 1) states at the element boundaries t_j = j h / m, j = 0 .. m K; the hold
                     boundaries t_k = k h are its columns k m (multiple shooting: m = 1)
    Xc  (n, d m K)   states at the collocation points, element j in columns j d .. j d + d - 1
                     (collocation only)
    U   (1, K)       torque held on [t_k, t_k+1), N m
    T   scalar       duration, s (minimum time only)

The constraints, in this order (the order of ``opti.g`` and of
:attr:`SlewSolution.multipliers`)::

    X[:, 0] = 0                                         n
    dynamics: multiple shooting  X[:, k+1] = F(X[:, k], U[k], h)          n K
              collocation        Z_j C = (h/m) f(Xc_j, U[j // m]), Z_j = [X_j, Xc_j]   n d m K
                                 X[:, j+1] = Z_j D                        n m K
    X[:, m K] = x_f                                     n
    -u_max <= U[k] <= u_max                             K
    -r h <= U[k] - U[k-1] <= r h, k = 0 .. K, U[-1] = U[K] = 0   (K + 1, rate bound only)
    -y_max <= tip @ q <= y_max at X[:, 1:m K] (and Xc)  m K - 1 (+ d m K)  (tip bound only)
    -w_max <= Omega(X[:, j]) <= w_max, j = 1 .. m K (and Xc)   m K (+ d m K)  (reaction wheel)
    -V_max <= V(U, rate at each element's start), then at its end <= V_max    2 m K  (DC motor)
    T_min <= T <= T_max                                 2  (minimum time only)

``F`` is ``substeps`` RK4 steps or a CVODES integrator; ``C`` and ``D`` come from
``casadi.collocation_coeff`` on Legendre or Radau points. ``substeps`` and ``m`` follow from
the design model's fastest mode (:func:`slew_discretisation`). The states are scaled for IPOPT
(``opti.set_linear_scale``) by their physical sizes; values and multipliers stay in SI units.
The rate bound treats the torque as zero before and after the slew, so the first and last
holds are limited to ``r h``. With an ``actuator`` (:mod:`controllers.design.actuator_limits`),
``u_max``
is the torque bound and a reaction wheel's torque limit; ``Omega(x)`` is the wheel's speed
relative to the hub, ``w_max`` its speed limit less
:data:`~controllers.design.actuator_limits.SPEED_MARGIN`; ``V(u, rate)`` the voltage a DC motor
needs
for the hub torque ``u`` at the hub rate.

Before anything is built, :func:`solve_slew` refuses a slew whose holds cannot reach its
true optimum (:mod:`controllers.design.hold_grid`): fewer holds than terminal conditions, or holds
that alias a design mode so that stopping it costs more than
:attr:`SlewProblem.effort_tolerance` (default
:data:`~controllers.design.hold_grid.HOLD_EFFORT_TOLERANCE`) above the converged effort; and a slew
the actuator cannot give (:func:`controllers.design.actuator_limits.refuse_infeasible`).
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass, field

import numpy as np

from flexctl.model import DCMotor, Model, ReactionWheel
from flexctl.model.actuators import as_actuator
from flexctl.model.checks import KeywordOnly, check_choice, check_integer, check_real
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.layout import StateLayout
from flexctl.sim.maneuvers import rigid_slew_duration

from ..design.actuator_limits import (check_design_model, demand, hub_torque_bound,
                                      minimum_duration, refuse_infeasible, speed_bound)
from ..design.hold_grid import HOLD_EFFORT_TOLERANCE, MAX_SUBSTEPS
from ..design.plant_state import DEFAULT_LAYOUT, resized
from .slew_checks import refuse_unsolvable
from ..spec import OBJECTIVES, TRANSCRIPTIONS
from .slew_nlp import (MAX_INTERVALS, Discretisation, Transcribed, discretisation, rk4_substeps,
                       transcribe, transcription_for)

__all__ = ["SlewProblem", "SlewSolution", "TrajectoryOptimizationError", "HoldTorque",
           "Discretisation", "solve_slew", "rigid_minimum_time", "rk4_substeps",
           "slew_discretisation", "transcription_for"]

INTEGRATORS = ("rk4", "cvodes")
COLLOCATION_SCHEMES = ("radau", "legendre")
#: Default upper bound on the free final time, in rigid-body minimum times.
MAX_TIME_FACTOR = 10.0
#: Factor by which a free-time guess is slowed until the actuator can give it.
GUESS_STRETCH = 1.1
_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


class TrajectoryOptimizationError(RuntimeError):
    """IPOPT failed to solve a slew problem; ``return_status`` holds its status.

    Parameters
    ----------
    message : str
        What failed, for the reader.
    return_status : str
        IPOPT's return status (e.g. ``"Infeasible_Problem_Detected"``).
    iterations : int
        Iterations IPOPT took before it stopped.
    """

    def __init__(self, message: str, return_status: str, iterations: int):
        super().__init__(message)
        self.return_status = return_status
        self.iterations = iterations


def checked_number(name, value, *, positive=True, optional=False):
    """``value`` as a finite float (:func:`~flexctl.model.checks.check_real`), errors naming
    ``name`` alone.

    Parameters
    ----------
    name : str
        The argument named in the error message.
    value : float or None
        The number to check.
    positive : bool, optional
        Require ``value > 0``. Default True.
    optional : bool, optional
        Let ``None`` pass (returned as is). Default False.
    """
    return check_real("", name, value, minimum=0.0 if positive else None, strict=positive,
                      optional=optional)


def _choice(name, value, choices):
    return check_choice("", name, value, choices)


def _integer(name, value, minimum, maximum):
    return check_integer("", name, value, minimum=minimum, maximum=maximum)


def rigid_minimum_time(angle: float, inertia: float, torque_bound: float) -> float:
    """Bang-bang minimum time ``2 sqrt(|angle| J / u_max)`` of a rigid body, s.

    A lower bound for any rest-to-rest slew of the flexible first_order model too: its total
    angular momentum obeys ``d/dt (J_0 theta_dot + m_tf^T q_dot) = torque``.

    Parameters
    ----------
    angle : float
        Slew angle, rad.
    inertia : float
        Rigid inertia ``J``, kg m^2 (> 0).
    torque_bound : float
        Bound ``u_max`` on ``|torque|``, N m (> 0).
    """
    return rigid_slew_duration(angle, inertia, torque_bound)


@dataclass(frozen=True, kw_only=True)
class SlewProblem(KeywordOnly):
    """A rest-to-rest slew to optimise.

    Parameters
    ----------
    angle : float
        Slew angle, rad (non-zero).
    duration : float or None
        Fixed duration ``T``, s; ``None`` for minimum time (then ``objective="time"``).
    torque_bound : float
        Bound ``u_max`` on ``|torque|``, N m.
    n_intervals : int, optional
        Number ``K`` of torque holds (>= 2). Default 40.
    torque_rate_bound : float, optional
        Bound ``r`` on the torque rate between holds, N m/s. Default none.
    tip_bound : float, optional
        Bound ``y_max`` on ``|tip deflection|``, m. Default none.
    objective : {"effort", "time"}, optional
        ``"effort"``: minimise the integral of torque^2 (N^2 m^2 s) at fixed ``duration``;
        ``"time"``: minimise the duration. Default ``"effort"``, or ``"time"`` when
        ``duration`` is None.
    transcription : {"multiple_shooting", "collocation"}, optional
        Default: by the design model (:func:`transcription_for`): collocation for the exact
        variant, whose dynamics are costly to differentiate (3 evaluations per hold, against 4
        per RK4 substep), multiple shooting for the others.
    integrator : {"rk4", "cvodes"}, optional
        Multiple shooting only: ``substeps`` fixed RK4 steps per hold, or CasADi's CVODES.
    substeps : int, optional
        RK4 steps per hold (>= 1). Default: chosen by :func:`rk4_substeps` from the design
        model's fastest mode, which they integrate over the slew within
        :data:`~controllers.design.hold_grid.PHASE_TOLERANCE` of its amplitude (and inside RK4's
        stability interval).
    collocation_scheme : {"radau", "legendre"}, optional
        Collocation only: the points (degree :attr:`degree`, 3) of each of the ``m`` elements
        per hold, ``m`` chosen from the design model's fastest mode
        (:func:`slew_discretisation`). Default ``"radau"``.
    max_duration : float, optional
        Upper bound on the free duration, s; default ``MAX_TIME_FACTOR`` times the rigid-body
        minimum time. Minimum time only.
    actuator : ReactionWheel or DCMotor, optional
        What gives the hub torque, whose limits the slew keeps
        (:mod:`controllers.design.actuator_limits`): a reaction wheel's torque limit (the hub torque
        within :attr:`hub_torque_bound`) and speed limit (less
        :data:`~controllers.design.actuator_limits.SPEED_MARGIN`, at every state of the grid, for a
        slew from rest with zero total momentum); a DC motor's voltage limit (the voltage for
        each hold's torque at the hub rate at both its ends, the motor's torque-speed line).
        The design model is the structure's (for a motor, with the rotor's reflected inertia:
        ``ActuatedModel.mechanical``). Default none: an ideal hub torque.
    effort_tolerance : float, optional
        Largest relative excess of the holds' least effort over the converged
        (continuous-torque) effort that a fixed-duration slew accepts (> 0; ``0.05`` accepts
        5 % more effort): holds that alias a design mode beyond it are refused before IPOPT
        runs (:class:`~controllers.design.hold_grid.HoldGrid`). Default
        :data:`~controllers.design.hold_grid.HOLD_EFFORT_TOLERANCE` (1 %).

    Examples
    --------
    >>> SlewProblem(angle=1.0, duration=2.0, torque_bound=5.0).objective
    'effort'
    >>> SlewProblem(angle=1.0, duration=None, torque_bound=5.0).objective
    'time'
    >>> SlewProblem(angle=1.0, duration=2.0, torque_bound=-5.0)
    Traceback (most recent call last):
    ...
    flexctl.model.errors.InputValueError: torque_bound must be finite and > 0; got -5.0
    """

    angle: float
    duration: float | None
    torque_bound: float
    n_intervals: int = 40
    torque_rate_bound: float | None = None
    tip_bound: float | None = None
    objective: str | None = None
    transcription: str | None = None
    integrator: str = "rk4"
    substeps: int | None = None
    collocation_scheme: str = "radau"
    max_duration: float | None = None
    actuator: ReactionWheel | DCMotor | None = None
    effort_tolerance: float = HOLD_EFFORT_TOLERANCE
    degree: int = field(default=3, init=False)

    def __post_init__(self):
        angle = checked_number("angle", self.angle, positive=False)
        if angle == 0.0:
            raise InputValueError("angle must be non-zero (rad); got 0.0")
        set_ = lambda name, v: object.__setattr__(self, name, v)  # noqa: E731
        set_("angle", angle)
        set_("duration", checked_number("duration", self.duration, optional=True))
        set_("torque_bound", checked_number("torque_bound", self.torque_bound))
        set_("n_intervals", _integer("n_intervals", self.n_intervals, 2, MAX_INTERVALS))
        for name in ("torque_rate_bound", "tip_bound", "max_duration"):
            set_(name, checked_number(name, getattr(self, name), optional=True))
        set_("effort_tolerance", checked_number("effort_tolerance", self.effort_tolerance))
        objective = ("time" if self.duration is None else "effort") if self.objective is None \
            else self.objective
        _choice("objective", objective, OBJECTIVES)
        set_("objective", objective)
        if objective == "time" and self.duration is not None:
            raise InputValueError(f"duration must be None for objective 'time' (the duration "
                                  f"is optimised); got {self.duration!r}")
        if objective == "effort" and self.duration is None:
            raise InputValueError("duration must be a positive time (s) for objective "
                                  "'effort'; got None")
        if self.max_duration is not None and objective != "time":
            raise InputValueError(f"max_duration applies to objective 'time' only; got "
                                  f"{self.max_duration!r}")
        for name, choices in (("transcription", TRANSCRIPTIONS), ("integrator", INTEGRATORS),
                              ("collocation_scheme", COLLOCATION_SCHEMES)):
            if name != "transcription" or self.transcription is not None:
                _choice(name, getattr(self, name), choices)
        if self.substeps is not None:
            set_("substeps", _integer("substeps", self.substeps, 1, MAX_SUBSTEPS))
        as_actuator(self.actuator)

    @property
    def hub_torque_bound(self) -> float:
        """The bound on ``|torque|`` the slew keeps, N m: :attr:`torque_bound`, and a reaction
        wheel's torque limit."""
        return hub_torque_bound(self.torque_bound, self.actuator)

    def target_state(self, layout) -> np.ndarray:
        """Final state ``x_f = [angle, 0 .. 0]``, shape (n_states,), of ``layout``: the design
        model's :class:`~flexctl.model.layout.StateLayout`, or a number of states (one
        appendage on a pinned hub); for a design model, its rest state at the angle (a free
        hub's centre where the turn about the centre of mass puts it).

        Parameters
        ----------
        layout : flexctl.Model, StateLayout or int
            A design model, the layout of its state, or the number of states ``2 N + 2`` of
            one appendage on a pinned hub.
        """
        if isinstance(layout, Model):
            return layout.rest_state(self.angle)
        if not isinstance(layout, StateLayout):
            n_states = check_integer("target_state", "n_states", layout, minimum=1)
            layout = resized(DEFAULT_LAYOUT, n_states)
            if layout is None:
                raise InputValueError("target_state.n_states must be 2 N + 2 for N >= 1 modes; "
                                      f"got {n_states}")
        return layout.join(theta=self.angle)


@dataclass(frozen=True, eq=False)
class HoldTorque:
    """Piecewise-constant torque (zero-order hold), callable as ``torque(t)``, N m.

    ``values[k]`` acts on ``[t[k], t[k+1])``; the torque is 0 before ``t[0]`` and from
    ``t[K]`` on. :attr:`breakpoints` (the hold boundaries ``t[1:]``) make
    :func:`flexctl.simulate` restart its integrator at every jump.

    Parameters
    ----------
    t : ndarray, shape (K+1,)
        The hold boundaries, s, ascending.
    values : ndarray, shape (K,)
        The torque held on each interval, N m.
    """

    t: np.ndarray
    values: np.ndarray
    breakpoints: tuple = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "breakpoints", tuple(float(b) for b in self.t[1:]))

    def __call__(self, t):
        if np.isscalar(t):               # the simulator's call: keep it cheap
            k = bisect.bisect_right(self.breakpoints, t)
            return float(self.values[k]) if self.t[0] <= t and k < self.values.size else 0.0
        t = np.asarray(t, dtype=float)
        k = np.searchsorted(self.t, t, side="right") - 1
        inside = (k >= 0) & (k < self.values.size)
        return np.where(inside, self.values[np.clip(k, 0, self.values.size - 1)], 0.0)

    def casadi(self, t):
        """The torque as a CasADi expression of the symbol ``t`` (exactly the held values).

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        import casadi as ca

        from flexctl.sim.compiled import piecewise_constant

        held = piecewise_constant(t, self.t[1:-1], self.values)
        return ca.if_else(ca.logic_or(t < self.t[0], t >= self.t[-1]), 0.0, held)


@dataclass(frozen=True, kw_only=True, eq=False)
class SlewSolution:
    """An optimal slew found by :func:`solve_slew`.

    Attributes
    ----------
    problem : SlewProblem
    model : flexctl.Model
        The design model the slew was optimised on.
    t : ndarray, shape (K+1,)
        Grid times, s, from 0 to :attr:`duration`.
    states : ndarray, shape (n, K+1)
        States at the grid times (order of :attr:`flexctl.Model.state_names`).
    torque : ndarray, shape (K,)
        Torque held on each interval, N m.
    duration : float
        s.
    cost : float
        Objective value: integral of torque^2 (N^2 m^2 s) or the duration (s).
    solve_time_s : float
        Wall time of the solve, s, building the derivatives included.
    ipopt_time_s : float
        IPOPT's own wall time (``t_wall_total``), s.
    iterations : int
        IPOPT iterations.
    return_status : str
        IPOPT's return status.
    multipliers : ndarray
        Constraint multipliers in the order of the module Notes (for warm starts).
    discretisation : Discretisation
        How the holds were integrated.
    """

    problem: SlewProblem
    model: Model = field(repr=False)
    t: np.ndarray = field(repr=False)
    states: np.ndarray = field(repr=False)
    torque: np.ndarray = field(repr=False)
    duration: float
    cost: float
    solve_time_s: float
    ipopt_time_s: float
    iterations: int
    return_status: str
    multipliers: np.ndarray = field(repr=False)
    discretisation: Discretisation | None = None
    _hermite: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        x0, x1, u = self.states[:, :-1], self.states[:, 1:], self.torque
        h = np.diff(self.t)
        m0 = h * self.model.dynamics(0.0, x0, u)        # h f(x_k, u_k)
        m1 = h * self.model.dynamics(0.0, x1, u)        # h f(x_k+1, u_k): same hold
        coef = np.stack((x0, m0, 3 * (x1 - x0) - 2 * m0 - m1, 2 * (x0 - x1) + m0 + m1))
        object.__setattr__(self, "_hermite", np.ascontiguousarray(coef.transpose(2, 0, 1)))

    @property
    def tip_deflection(self) -> np.ndarray:
        """Tip deflection at the grid times, m, shape (K+1,) (several appendages: the largest
        in magnitude over them at each time)."""
        tips = self.model.tip_matrix @ self.model.layout.modal(self.states)
        pick = np.argmax(np.abs(tips), axis=0)
        return np.take_along_axis(tips, pick[None], 0)[0]

    @property
    def actuator_demand(self) -> np.ndarray | None:
        """What the plan asks of ``problem.actuator``: the wheel speed relative to the hub at
        the grid times, rad/s, shape (K+1,); or the motor voltage at the start (row 0) and end
        (row 1) of each hold, V, shape (2, K); ``None`` without an actuator.
        (:func:`controllers.design.actuator_limits.demand`, from :attr:`states` and
        :attr:`torque`.)"""
        return demand(self.model, self.problem.actuator, self.states, self.torque)

    @property
    def actuator_peak(self) -> float | None:
        """The largest ``|wheel speed|`` (rad/s) or ``|voltage|`` (V) of
        :attr:`actuator_demand`; ``None`` without an actuator."""
        needed = self.actuator_demand
        return None if needed is None else float(np.max(np.abs(needed)))

    def torque_function(self) -> HoldTorque:
        """The torque as a callable ``torque(t)`` (N m) with ``breakpoints`` at the holds."""
        return HoldTorque(self.t, self.torque)

    def state_at(self, t) -> np.ndarray:
        """Design-model state at time(s) ``t``, shape (n,) or (n, P).

        Cubic Hermite interpolation on each hold, with the slopes ``f(x, u_k)`` of that hold
        at both ends (fourth order in ``h``). Before 0 the start state, after
        :attr:`duration` the final state.

        Parameters
        ----------
        t : float or array_like, shape (P,)
            Time(s), s.
        """
        if np.isscalar(t):               # the tracker's call: keep it cheap
            k = min(max(bisect.bisect_right(self.t, t) - 1, 0), self.torque.size - 1)
            s = min(max((t - self.t[k]) / (self.t[k + 1] - self.t[k]), 0.0), 1.0)
            c = self._hermite[k]
            return c[0] + s * (c[1] + s * (c[2] + s * c[3]))
        t = np.asarray(t, dtype=float)
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.torque.size - 1)
        s = np.clip((t - self.t[k]) / (self.t[k + 1] - self.t[k]), 0.0, 1.0)
        c = self._hermite[k].T                             # (n, 4) or (n, 4, P)
        return c[:, 0] + s * (c[:, 1] + s * (c[:, 2] + s * c[:, 3]))

    def __repr__(self):
        return (f"SlewSolution(angle={self.problem.angle:.6g} rad, duration={self.duration:.6g}"
                f" s, cost={self.cost:.6g}, objective={self.problem.objective!r}, "
                f"status={self.return_status!r}, iterations={self.iterations}, "
                f"solve_time_s={self.solve_time_s:.3g}, model={self.model!r})")


# ---------------------------------------------------------------------------- guesses
def _smooth_guess(model: Model, problem: SlewProblem, duration: float):
    """Rigid-body quintic rest-to-rest profile: grid states (n, K+1) and holds (K,)."""
    layout, K = model.layout, problem.n_intervals
    s = np.linspace(0.0, 1.0, K + 1)
    states = np.zeros((layout.n_states, K + 1))
    states[layout.theta] = problem.angle * (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5)
    states[layout.theta_dot] = problem.angle * 30 * (s ** 2 - 2 * s ** 3 + s ** 4) / duration
    mid = 0.5 * (s[1:] + s[:-1])
    acc = problem.angle * 60 * (mid - 3 * mid ** 2 + 2 * mid ** 3) / duration ** 2
    bound = problem.hub_torque_bound
    torque = np.clip(model.rigid_inertia * acc, -bound, bound)
    return states, torque


def _resample_guess(guess, model: Model, problem: SlewProblem):
    """``(duration, states (n, K+1), torque (K,))`` from a solution or ``(t, states, torque)``."""
    if isinstance(guess, SlewSolution):
        t, states, torque = guess.t, guess.states, guess.torque
    else:
        try:
            t, states, torque = (np.asarray(a, dtype=float) for a in guess)
        except (TypeError, ValueError):
            raise InputTypeError("initial_guess must be a SlewSolution or a tuple (t, states, "
                                 f"torque) of arrays; got {type(guess).__name__}") from None
    m = t.size - 1
    if t.ndim != 1 or m < 1 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0) \
            or t[0] != 0.0 \
            or states.shape != (model.n_states, m + 1) or torque.shape != (m,) \
            or not (np.all(np.isfinite(states)) and np.all(np.isfinite(torque))):
        raise InputValueError(f"initial_guess must hold t (M+1,) increasing from 0, states "
                              f"({model.n_states}, M+1) and torque (M,), finite; got shapes "
                              f"{t.shape}, {states.shape}, {torque.shape}")
    s_new = np.linspace(0.0, 1.0, problem.n_intervals + 1)
    s_old = t / t[-1]
    x = np.vstack([np.interp(s_new, s_old, row) for row in states])
    mid = 0.5 * (s_new[1:] + s_new[:-1])
    u = np.asarray(HoldTorque(s_old, torque)(mid))
    return float(t[-1]), x, u


# ---------------------------------------------------------------------------- discretisation
def slew_discretisation(problem: SlewProblem, model: Model,
                        duration: float | None = None) -> Discretisation:
    """The discretisation :func:`solve_slew` uses for ``problem`` on ``model``.

    RK4 substeps and collocation elements are chosen from the design model's fastest mode
    (:func:`controllers.design.hold_grid.steps_per_hold`): every scheme integrates it over the slew
    within :data:`~controllers.design.hold_grid.PHASE_TOLERANCE` of its amplitude.

    Parameters
    ----------
    problem : SlewProblem
        The slew.
    model : flexctl.Model
        The design model, whose fastest mode sets the steps.
    duration : float, optional
        Duration a free-time problem is sized for, s (overrides the default; collocation
        only: multiple shooting is sized for the longest free duration).

    Examples
    --------
    >>> import flexctl
    >>> model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=4)
    >>> problem = SlewProblem(angle=1.57, duration=2.0, torque_bound=6.0, n_intervals=60)
    >>> slew_discretisation(problem, model)          # omega_max h = 134.6 * 2 / 60 = 4.5
    Discretisation(transcription='multiple_shooting', method='rk4', steps_per_hold=12, \
sized_for=2.0)
    """
    return discretisation(problem, model, *_time_bounds(model, problem), duration)


# ---------------------------------------------------------------------------- refusals
def _refuse_before_solving(model: Model, problem: SlewProblem) -> None:
    """Raise on a slew that cannot be solved to its optimum, before anything is built.

    Too few holds for the terminal conditions, a slew the actuator cannot give, a duration
    below the rigid-body minimum time, and holds whose least effort exceeds the converged one
    by more than :attr:`SlewProblem.effort_tolerance` (fixed duration only).
    """
    n, N, K = model.n_states, model.n_modes, problem.n_intervals
    if K < n:
        raise InputValueError(f"n_intervals must be at least the {n} terminal conditions of a "
                              f"rest-to-rest slew of a {N}-mode design model (2 N + 2 torque "
                              f"holds); got {K}")
    _refuse_for_actuator(model, problem)
    umax = problem.torque_bound
    t_rigid = rigid_minimum_time(problem.angle, model.rigid_inertia, umax)
    if problem.duration is not None and problem.duration < t_rigid:
        # the structure's angular momentum obeys J_0 d(mean angle)/dt^2 = torque, so no torque
        # within the bound brings it to rest at the angle sooner than the rigid body
        raise TrajectoryOptimizationError(
            f"the duration {problem.duration:g} s is below the rigid-body minimum time "
            f"{t_rigid:.4g} s for angle {problem.angle:g} rad and torque_bound {umax:g} N m, so "
            "no torque within the bound can complete the slew: lengthen maneuver.duration or "
            "raise maneuver.torque_bound (found before the optimiser ran)",
            "Infeasible_Duration", 0)
    if problem.max_duration is not None and problem.max_duration < t_rigid:
        raise InputValueError(
            f"max_duration must be at least the rigid-body minimum time {t_rigid:.4g} s for "
            f"angle {problem.angle:g} rad and torque_bound {umax:g} N m (no torque within the "
            f"bound completes the slew sooner); got {problem.max_duration!r}")
    refuse_unsolvable(model, problem, *_time_bounds(model, problem))


def _refuse_for_actuator(model: Model, problem: SlewProblem) -> None:
    """Raise on a design model the actuator cannot drive, or a slew it cannot give
    (:func:`controllers.design.actuator_limits.refuse_infeasible`)."""
    actuator = check_design_model(model, problem.actuator)
    if actuator is None:
        return
    if problem.duration is not None:
        refuse_infeasible(model, actuator, problem.angle, problem.duration,
                          problem.torque_bound)
        return
    shortest = minimum_duration(model, actuator, problem.angle, problem.torque_bound)
    if problem.max_duration is not None and problem.max_duration < shortest:
        raise InputValueError(
            f"max_duration must be at least {shortest:.4g} s, the least a rigid body needs "
            f"for angle {problem.angle:g} rad within torque_bound {problem.torque_bound:g} N m "
            f"and the limits of the {actuator.kind} (actuator); got {problem.max_duration!r}")


_FEASIBILITY = ("lengthen maneuver.duration, raise maneuver.torque_bound, or loosen tip_bound "
                "or torque_rate_bound")
_CONVERGENCE = "start from initial_guess (a nearby solution) or raise the limit"
#: What an IPOPT ending without a solution means for a slew, and what to change.
_ENDINGS = {
    "Infeasible_Problem_Detected": ("found no torque within the bounds that meets the "
                                    "terminal conditions", _FEASIBILITY),
    "Restoration_Failed": ("could not find a torque that meets the terminal conditions",
                           _FEASIBILITY),
    "Maximum_Iterations_Exceeded": ("reached its iteration limit (ipopt_options max_iter)",
                                    _CONVERGENCE),
    "Maximum_CpuTime_Exceeded": ("reached its time limit (ipopt_options max_cpu_time)",
                                 _CONVERGENCE),
    "Maximum_WallTime_Exceeded": ("reached its time limit (ipopt_options max_wall_time)",
                                  _CONVERGENCE),
    "Invalid_Number_Detected": ("met a non-finite value of the dynamics", _FEASIBILITY),
}
_NUMERICAL_TROUBLE = ("stopped without converging (numerical trouble)",
                      "start from initial_guess, or " + _FEASIBILITY)


def _failure(status: str, iterations: int, problem: SlewProblem) -> TrajectoryOptimizationError:
    """The error for an optimiser that ended without a solution: what happened, what to do.

    IPOPT's own status stays in :attr:`TrajectoryOptimizationError.return_status`."""
    what, remedy = _ENDINGS.get(status, _NUMERICAL_TROUBLE)
    if problem.objective == "time" and remedy != _CONVERGENCE:
        remedy += ", or raise max_duration (the free duration's upper bound)"
    if problem.actuator is not None and remedy != _CONVERGENCE:
        remedy += f", or relax the {problem.actuator.kind}'s " + (
            "actuator.voltage_limit" if isinstance(problem.actuator, DCMotor)
            else "actuator.speed_limit or actuator.torque_limit")
    duration = (f"{problem.duration:g} s" if problem.duration is not None
                else "a free duration")
    return TrajectoryOptimizationError(
        f"the trajectory optimiser {what} after {iterations} iterations "
        f"({problem.n_intervals} holds over {duration}): {remedy}", status, iterations)


def _time_bounds(model: Model, problem: SlewProblem) -> tuple:
    """``(rigid-body minimum time, longest free duration)``, s: within the actuator's limits
    too (:func:`controllers.design.actuator_limits.minimum_duration`)."""
    t_rigid = rigid_minimum_time(problem.angle, model.rigid_inertia, problem.torque_bound)
    if problem.actuator is not None:
        t_rigid = max(t_rigid, minimum_duration(model, problem.actuator, problem.angle,
                                                problem.torque_bound))
    return t_rigid, problem.max_duration or MAX_TIME_FACTOR * t_rigid


def _guess(model: Model, problem: SlewProblem, initial_guess) -> tuple:
    """``(duration, states (n, K+1), torque (K,))`` to start from."""
    if initial_guess is not None:
        return _resample_guess(initial_guess, model, problem)
    t_rigid, longest = _time_bounds(model, problem)
    if problem.duration is not None:
        return (problem.duration, *_smooth_guess(model, problem, problem.duration))
    duration = math.sqrt(1.5) * t_rigid               # quintic peak torque = u_max
    states, torque = _smooth_guess(model, problem, duration)
    while duration < longest and not _within_actuator(model, problem, states, torque):
        # slower, until the actuator can give it (the rigid bound ignores the quintic's shape)
        duration = min(GUESS_STRETCH * duration, longest)
        states, torque = _smooth_guess(model, problem, duration)
    return duration, states, torque


def _within_actuator(model: Model, problem: SlewProblem, states, torque) -> bool:
    """Whether a plan keeps the actuator's speed or voltage limit (none: True)."""
    needed = demand(model, problem.actuator, states, torque)
    if needed is None:
        return True
    limit = (problem.actuator.voltage_limit if isinstance(problem.actuator, DCMotor)
             else speed_bound(problem.actuator))
    return bool(np.max(np.abs(needed)) <= limit)


def _solve(nlp: Transcribed, problem: SlewProblem, disc: Discretisation, initial_guess,
           ipopt_options: dict | None):
    """Run IPOPT; ``(stats, wall time s)``, or raise the failure."""
    opti = nlp.opti
    # mumps_pivtol: IPOPT's default (1e-6) lets MUMPS pick pivots that misjudge the inertia
    # of the KKT matrix of fine collocation grids: IPOPT then regularises a convex problem and
    # crawls, or stops in "Error_In_Step_Computation" (slew-90 on 4 modes with 6 elements per
    # hold, say). acceptable_*: an "acceptable" ending must still meet the constraints (in
    # state-scale units) and complementarity, not only IPOPT's default 1e-2 of them
    ipopt = {"print_level": 0, "sb": "yes", "tol": 1e-9, "max_iter": 1000,
             "mumps_pivtol": 1e-4, "acceptable_constr_viol_tol": 1e-8,
             "acceptable_compl_inf_tol": 1e-6}
    if isinstance(initial_guess, SlewSolution) \
            and initial_guess.problem.n_intervals == problem.n_intervals \
            and initial_guess.multipliers.size == opti.ng \
            and initial_guess.discretisation == disc:
        opti.set_initial(opti.lam_g, initial_guess.multipliers)
        ipopt.update(warm_start_init_point="yes", mu_init=1e-6,
                     warm_start_bound_push=1e-8, warm_start_mult_bound_push=1e-8)
    ipopt.update(ipopt_options or {})
    # expand=False: the mapped SX interval functions are faster to differentiate than the
    # expanded NLP (0.1 s against 0.8 s for 40 RK4 holds), and CVODES cannot be expanded.
    opti.solver("ipopt", {"expand": False, "print_time": False, "record_time": True}, ipopt)
    start = time.perf_counter()
    try:
        opti.solve_limited()
        failed = False
    except RuntimeError:             # CasADi raises on any status that is not a success
        failed = True
    wall = time.perf_counter() - start
    try:
        stats = opti.stats()
    except RuntimeError:             # pragma: no cover - no stats when the solver never ran
        stats = {"return_status": "CasADi_Error"}
    status, iterations = str(stats.get("return_status")), int(stats.get("iter_count", 0))
    if failed or status not in _SUCCESS:
        raise _failure(status, iterations, problem)
    return stats, wall


def solve_slew(model: Model, problem: SlewProblem, initial_guess=None,
               ipopt_options: dict | None = None) -> SlewSolution:
    """Optimise a rest-to-rest slew of ``model`` with CasADi Opti and IPOPT.

    Before anything is built, a slew that cannot be solved to its optimum is refused
    (``ValueError`` naming the setting and a value that works): fewer holds than terminal
    conditions; holds too coarse for the design modes, whose least effort exceeds the
    converged (continuous-torque) effort by more than :attr:`SlewProblem.effort_tolerance`
    (:mod:`controllers.design.hold_grid`); or
    an exact design model whose derivatives would take minutes
    (:data:`~controllers.slew.slew_checks.MAX_EXACT_WORK`). Each hold is integrated with the steps
    the
    fastest design mode needs (:func:`slew_discretisation`).

    Parameters
    ----------
    model : flexctl.Model
        Design model; its dynamics enter through :meth:`flexctl.Model.casadi`, for the exact
        variant compiled with their derivatives (:mod:`controllers.design.native_dynamics`).
    problem : SlewProblem
        The slew: angle, duration or minimum time, bounds, holds and discretisation.
    initial_guess : SlewSolution or tuple (t, states, torque), optional
        Warm start: a previous solution (any grid; resampled in normalised time) or arrays
        ``t`` (M+1,) s, ``states`` (n, M+1), ``torque`` (M,) N m. A solution of the same
        problem layout also passes its multipliers to IPOPT. Default: a rigid-body quintic
        profile with the flexible states at 0.
    ipopt_options : dict, optional
        IPOPT options, e.g. ``{"max_iter": 200, "print_level": 5}``; IPOPT's output is
        silenced unless ``print_level`` is given.

    Returns
    -------
    SlewSolution

    Raises
    ------
    ValueError
        A slew refused before solving, naming the setting to change and a value that works.
    TrajectoryOptimizationError
        No solution (e.g. an infeasible problem): the message says what happened and what
        to change; ``return_status`` holds IPOPT's status. No partial result is returned.

    Examples
    --------
    >>> import numpy as np, flexctl
    >>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=1)
    >>> problem = SlewProblem(angle=np.pi / 4, duration=3.0, torque_bound=5.0, n_intervals=20)
    >>> solution = solve_slew(model, problem)
    >>> solution.return_status, solution.states.shape, solution.torque.shape
    ('Solve_Succeeded', (4, 21), (20,))
    >>> bool(abs(solution.states[0, -1] - np.pi / 4) < 1e-8)
    True
    """
    if not isinstance(model, Model):
        raise InputTypeError(f"model must be a flexctl Model; got {type(model).__name__}")
    if not isinstance(problem, SlewProblem):
        raise InputTypeError(f"problem must be a SlewProblem; got {type(problem).__name__}")
    if ipopt_options is not None and not isinstance(ipopt_options, dict):
        raise InputValueError(f"ipopt_options must be a dict of IPOPT options; got "
                              f"{type(ipopt_options).__name__}")
    _refuse_before_solving(model, problem)
    disc = slew_discretisation(problem, model)
    guess = _guess(model, problem, initial_guess)
    start = time.perf_counter()
    nlp = transcribe(model, problem, disc, guess, *_time_bounds(model, problem))
    stats, _ = _solve(nlp, problem, disc, initial_guess, ipopt_options)
    duration = float(nlp.opti.value(nlp.T)) if problem.objective == "time" else problem.duration
    if duration > disc.sized_for * (1 + 1e-9):
        # a free duration longer than the collocation elements were chosen for: again, with
        # the elements of the duration found, from the solution found
        first = _solution(nlp, model, problem, disc, stats, start)
        disc = slew_discretisation(problem, model, duration * 1.05)
        nlp = transcribe(model, problem, disc, _resample_guess(first, model, problem),
                         *_time_bounds(model, problem))
        stats, _ = _solve(nlp, problem, disc, None, ipopt_options)
    return _solution(nlp, model, problem, disc, stats, start)


def _solution(nlp: Transcribed, model: Model, problem: SlewProblem, disc: Discretisation,
              stats: dict, start: float) -> SlewSolution:
    opti, K, n = nlp.opti, problem.n_intervals, model.n_states
    duration = float(opti.value(nlp.T)) if problem.objective == "time" else problem.duration
    torque = np.asarray(opti.value(nlp.U), dtype=float).reshape(K)
    cost = duration if problem.objective == "time" \
        else float(duration / K * np.sum(torque ** 2))
    return SlewSolution(
        problem=problem, model=model, t=np.linspace(0.0, duration, K + 1),
        states=np.asarray(opti.value(nlp.X), dtype=float).reshape(n, K + 1), torque=torque,
        duration=duration, cost=cost, solve_time_s=time.perf_counter() - start,
        ipopt_time_s=float(stats.get("t_wall_total", np.nan)),
        iterations=int(stats.get("iter_count", 0)), return_status=str(stats["return_status"]),
        multipliers=np.asarray(opti.value(opti.lam_g), dtype=float).reshape(-1),
        discretisation=disc)
