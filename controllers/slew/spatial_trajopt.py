"""An optimal rest-to-rest slew of a flexible spacecraft about any axis, within its wheels'
torque, speed and power limits.

:func:`solve_spatial_slew` finds the hub torque, held over ``n_intervals`` equal holds, that
turns a spatial structure from rest at ``start`` to rest at ``target`` in ``duration`` seconds
with the least torque effort ``sum_k h |tau_k|^2``, its modes at rest at the end: a slew that
leaves the design model's modes still, the wheels within their limits on the way. The
:class:`SpatialSlewSolution` it returns is also a reference that a three-axis LQR or LQG
follows (:func:`~controllers.feedback.spatial_lqr.design_spatial_lqr` with
``reference=solution``), as it follows an :class:`~controllers.slew.eigenaxis.EigenaxisSlew`.

Notes
-----
**Design model.** The spatial model (``variant``, ``n_modes`` per field) split into its linear
plant at rest (:func:`~flexctl.model.spatial_plant.linearize_spatial`) and the rest. In the
design state ``x = (e, x_l)`` (the attitude error ``e``; ``x_l`` the modal coordinates, the rate
``w``, a free hub's velocity and the modal rates) nothing depends on ``e`` at rest (its columns
of ``A`` are zero), so the attitude is carried by a quaternion instead. Over a hold of length
``h`` with torque ``tau_k`` the model is integrated as an exponential Euler step::

    x_l(k+1) = Phi x_l(k) + Gamma tau_k + Psi r_k
    q(k+1)   = q(k) (x) exp(1/2 int_hold w dt),   int_hold w dt = C_w (S_x x_l(k) + S_u tau_k + S_r r_k)

``Phi = exp(A_l h)``, ``Gamma``, ``Psi = int_0^h exp(A_l s) ds`` and the integrals ``S`` from
one matrix exponential (Van Loan): exact for the linear part, so no mode is too fast for it,
whatever its frequency. ``r_k = f(x_l(k), tau_k) - A_l x_l(k) - B_l tau_k`` is what the
model's right-hand side ``f`` adds to the linear plant (the rigid gyroscopic torque ``w x J w``,
the modes' Coriolis coupling, the dynamic stiffening), held at its value at the hold's start,
and with wheels ``tau_k`` carries their gyroscopic torque ``-w x (G h)`` (``h = J_w (G^T w +
Omega)``). The rotation increments within a hold are taken as commuting. Both errors are of
first order in ``h``: on two arrays slewed 20 degrees in 12 s, the plan flown open loop on the
same model ends 7e-5 rad from its target with 60 holds and 3e-5 rad with 120. The loop that
follows the slew corrects them.

**Wheels.** With a :class:`~flexctl.model.wheel_cluster.WheelCluster` the torque is the one
commanded of the cluster, distributed by its own law (``u = -G^+ tau``, the motor torques,
and a ``"null_motion"`` cluster's null-space torques at the speeds of the hold's start, which
the hub does not feel); the wheel speeds follow ``J_w (g . w_t + Omega_t) = u`` over each
hold, and
each wheel's ``|u_k| <= torque_margin * torque_limit``, ``|Omega_k| <= speed_margin *
speed_limit`` and (with a ``power_limit``) ``|u_k Omega_k| <= power_limit`` are constraints at
every hold's ends (the margins leave the loop room to correct). Friction, dead band and motor
lag are disturbances to the loop. Without wheels, ``torque_margin * torque_limit`` bounds each hub axis.

**NLP.** Multiple shooting in the holds' torques and the states at every hold's end (scaled by
the rigid guess's excursions), the terminal constraints ``vec(target^* (x) q_N) = 0``,
``x_l(N) = 0``; CasADi ``Opti`` hands it to IPOPT with exact second derivatives. The first guess
is the rigid eigenaxis slew (a seventh-order polynomial in angle) run through the design model.
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from flexctl.model.checks import (KeywordOnly, check_array, check_instance, check_integer,
                                  check_quaternion, check_real)
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.quaternions import (conjugate, error_angles, from_rotation_vector, product,
                                     symbolic_product)

from ..design.plant_state import spatial_design_plant

__all__ = ["SpatialSlewProblem", "SpatialSlewSolution", "solve_spatial_slew",
           "SpatialSlewError", "MAX_SPATIAL_INTERVALS", "SpatialHoldModel", "HoldFunctions",
           "spatial_hold_model", "hold_functions", "hold_expressions", "remainder_function",
           "remainder_expression"]

#: Most holds of a spatial slew (the NLP grows linearly with them).
MAX_SPATIAL_INTERVALS = 2000

#: The remainder function of each spatial model's equations (built and compiled once).
_REMAINDERS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


class SpatialSlewError(RuntimeError):
    """IPOPT did not find the slew.

    Parameters
    ----------
    message : str
        What happened and what to change.
    return_status : str
        IPOPT's.
    iterations : int
        IPOPT's iterations.
    """

    def __init__(self, message: str, return_status: str, iterations: int):
        super().__init__(message)
        self.return_status = return_status
        self.iterations = iterations


@dataclass(frozen=True, kw_only=True, eq=False)
class SpatialSlewProblem(KeywordOnly):
    """A rest-to-rest slew of a spatial structure (module description).

    Parameters
    ----------
    target : array_like, shape (4,)
        The attitude at the end, hub to inertial, scalar first.
    duration : float
        The slew's length, s (> 0).
    start : array_like, shape (4,), optional
        The attitude at the start. Default the identity.
    n_intervals : int, optional
        Torque holds over the slew (2 to :data:`MAX_SPATIAL_INTERVALS`). Default 100.
    torque_limit : float, optional
        Bound on each hub axis's torque, N m (without ``wheels``). Default none.
    wheels : WheelCluster, optional
        The wheels that deliver the torque; their limits bound the slew. Default none.
    wheel_speeds : array_like, shape (n_wheels,), optional
        The wheels' speeds at the start, rad/s. Default zero.
    speed_margin : float, optional
        Fraction of each wheel's ``speed_limit`` the plan may use, in ``(0, 1]``. Default 0.9.
    torque_margin : float, optional
        Fraction of each torque limit (a wheel's, or ``torque_limit``) the plan may use, in
        ``(0, 1]``: the rest is left to the loop that follows the slew. Default 0.8.
    smoothness : float, optional
        Weight ``s`` of the torque's jumps, s^2: the cost becomes ``sum_k h |tau_k|^2 + s
        sum_k |tau_k - tau_(k-1)|^2 / h`` (about ``int |tau|^2 + s |tau_t|^2 dt``), the torque
        starting from and ending at zero. A smoother torque excites less the modes the plan
        leaves out and suffers less from a motor's lag (on the demo's pyramid, ``s = 1``
        left a quarter of the residual vibration of ``s = 0`` at 18 % more effort). Default 0:
        the least effort.
    """

    target: np.ndarray
    duration: float
    start: np.ndarray = (1.0, 0.0, 0.0, 0.0)
    n_intervals: int = 100
    torque_limit: float | None = None
    wheels: object = None
    wheel_speeds: np.ndarray | None = None
    speed_margin: float = 0.9
    torque_margin: float = 0.8
    smoothness: float = 0.0

    def __post_init__(self):
        owner = "spatial_slew"
        set_ = object.__setattr__
        set_(self, "target", check_quaternion(owner, "target", self.target))
        set_(self, "start", check_quaternion(owner, "start", self.start))
        set_(self, "duration", check_real(owner, "duration", self.duration, minimum=0.0,
                                          strict=True, maximum=1e5))
        set_(self, "n_intervals", check_integer(owner, "n_intervals", self.n_intervals,
                                                minimum=2, maximum=MAX_SPATIAL_INTERVALS))
        if self.torque_limit is not None:
            if self.wheels is not None:
                raise InputValueError("spatial_slew.torque_limit bounds a hub torque without "
                                      "wheels; with wheels their own torque_limit does")
            set_(self, "torque_limit", check_real(owner, "torque_limit", self.torque_limit,
                                                  minimum=0.0, strict=True))
        for name in ("speed_margin", "torque_margin"):
            set_(self, name, check_real(owner, name, getattr(self, name), minimum=0.0,
                                        strict=True, maximum=1.0))
        set_(self, "smoothness", check_real(owner, "smoothness", self.smoothness, minimum=0.0,
                                            maximum=1e6))
        if self.wheels is None:
            if self.wheel_speeds is not None:
                raise InputValueError("spatial_slew.wheel_speeds needs wheels")
            return
        from flexctl.model.wheel_cluster import WheelCluster

        check_instance(owner, "wheels", self.wheels, WheelCluster)
        speeds = np.zeros(self.wheels.count) if self.wheel_speeds is None else np.array(
            check_array(owner, "wheel_speeds", self.wheel_speeds, shape=(self.wheels.count,)))
        limits = np.array([w.speed_limit for w in self.wheels.wheels])
        if np.any(np.abs(speeds) > self.speed_margin * limits):
            k = int(np.argmax(np.abs(speeds) - self.speed_margin * limits))
            raise InputValueError(
                f"spatial_slew.wheel_speeds[{k}] must be within speed_margin * speed_limit = "
                f"{self.speed_margin * limits[k]:.6g} rad/s; got {speeds[k]!r}")
        speeds.setflags(write=False)
        set_(self, "wheel_speeds", speeds)

    @property
    def eigenaxis(self) -> tuple:
        """``(axis, angle)`` of the shortest rotation from :attr:`start` to :attr:`target`
        (hub frame at the start; rad)."""
        vector = error_angles(self.start, self.target)
        angle = float(np.linalg.norm(vector))
        axis = vector / angle if angle > 0 else np.array([0.0, 0.0, 1.0])
        return axis, angle


@dataclass(frozen=True, eq=False)
class SpatialHoldModel:
    """The design model of a spatial structure over holds of :attr:`hold` seconds (module
    Notes), made by :func:`spatial_hold_model`.

    Attributes
    ----------
    names : tuple of str
        The design state's names: ``ex, ey, ez`` then ``x_l``'s.
    a, b : ndarray
        ``A_l`` (n, n) and ``B_l`` (n, 3) of the linear plant at rest.
    maps : tuple of ndarray
        ``Phi``, ``[Gamma, Psi]``, ``C_w S_x`` and ``C_w [S_u, S_r]`` over a hold.
    rate_at : int
        Where ``wx`` is in ``x_l``.
    hold : float
        Length of each hold, s.
    equations : SpatialEquations
        The spatial model's.
    full_rows : ndarray of int
        Where ``x_l`` sits in the spatial model's state.
    n_full : int
        The spatial model's state size.
    inertia : ndarray, shape (3, 3)
        The rigid structure's inertia, kg m^2.
    """

    names: tuple
    a: np.ndarray          # A_l
    b: np.ndarray          # B_l
    maps: tuple            # Phi, [Gamma, Psi], C_w S_x, C_w [S_u, S_r] over a hold
    rate_at: int           # where w starts in x_l
    hold: float
    equations: object      # the spatial model's (SpatialEquations)
    full_rows: np.ndarray  # where x_l sits in the spatial model's state
    n_full: int
    inertia: np.ndarray    # the rigid structure's, for the first guess


def _interval_maps(a, b, h: float) -> tuple:
    """``Phi, Gamma, S_x, S_u`` of ``x_t = A x + B u`` over ``h`` with ``u`` held: ``x(h) =
    Phi x + Gamma u`` and ``int_0^h x dt = S_x x + S_u u`` (Van Loan's exponential)."""
    n, m = b.shape
    big = np.zeros((2 * n + m, 2 * n + m))
    big[0:n, n:2 * n] = np.eye(n)
    big[n:2 * n, n:2 * n] = a
    big[n:2 * n, 2 * n:] = b
    e = expm(big * h)
    return e[n:2 * n, n:2 * n], e[n:2 * n, 2 * n:], e[0:n, n:2 * n], e[0:n, 2 * n:]


def _hold_maps(model_a, model_b, rate_at: int, h: float) -> tuple:
    """The maps of a hold of ``h`` for the torque and the remainder (module Notes)."""
    n = model_a.shape[0]
    phi, gamma, s_x, s_u = _interval_maps(model_a, np.hstack([model_b, np.eye(n)]), h)
    rows = slice(rate_at, rate_at + 3)
    return phi, gamma, s_x[rows], s_u[rows]


def spatial_hold_model(structure, n_modes, variant: str, hold: float,
                       owner: str = "spatial_hold_model") -> SpatialHoldModel:
    """The design model of ``structure`` over holds of ``hold`` seconds (module Notes).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, sequence of int or mapping
        Modes per field.
    variant : {"exact", "first_order", "zero_order"}
        The spatial model whose right-hand side gives the remainder.
    hold : float
        Length of each hold, s (> 0).
    owner : str, optional
        Who asks (named in errors). Default ``"spatial_hold_model"``.

    Returns
    -------
    SpatialHoldModel
    """
    from flexctl.model.spatial_dynamics import spatial_equations

    hold = check_real(owner, "hold", hold, minimum=0.0, strict=True, maximum=1e5)
    plant, names = spatial_design_plant(owner, structure, n_modes, variant)
    a, b = np.asarray(plant.A), np.asarray(plant.B)
    if np.max(np.abs(a[:, 0:3]), initial=0.0) > 1e-9 * max(1.0, np.max(np.abs(a))):
        raise AssertionError("the plant at rest depends on its attitude error")
    equations = spatial_equations(structure, n_modes, variant)
    layout = equations.layout
    c = layout.n_coordinates
    rows = np.r_[c - layout.n_elastic:c, c:c + layout.n_speeds]
    a_l, b_l = a[3:, 3:], b[3:, :]
    rate_at = names.index("wx", 3) - 3
    return SpatialHoldModel(names=names, a=a_l, b=b_l, maps=_hold_maps(a_l, b_l, rate_at, hold),
                        rate_at=rate_at, hold=hold, equations=equations, full_rows=rows,
                        n_full=layout.n_states,
                        inertia=np.asarray(structure.rigid_inertia, dtype=float))


def _exp_quaternion(theta):
    """``exp(theta / 2)`` as a quaternion, CasADi or numpy (smooth at zero)."""
    import casadi as ca

    half = 0.5 * ca.sqrt(ca.sumsqr(theta) + 1e-30)
    return ca.vertcat(ca.cos(half), theta * (0.5 * ca.sin(half) / half))


@dataclass(frozen=True, eq=False)
class HoldFunctions:
    """A :class:`SpatialHoldModel`'s hold as CasADi functions (:func:`hold_functions`).

    Attributes
    ----------
    advance : casadi.Function
        ``(x_l, q, speeds, tau) -> (x_l, q, speeds)`` one hold later (``tau`` the torque
        commanded of the cluster, or on the hub without wheels).
    motor : casadi.Function
        ``(tau, speeds) ->`` the wheels' motor torques (n_wheels; empty without wheels), N m,
        by the cluster's distribution (its null motion included).
    held : casadi.Function
        ``(x_l, speeds, tau) ->`` the hold's input ``[torque on the structure, remainder]``.
    """

    advance: object        # (x_l, q, speeds, tau) -> (x_l+, q+, speeds+)
    motor: object          # tau -> motor torques (n_wheels)
    held: object           # (x_l, speeds, tau) -> the hold's input (torque, remainder)


def remainder_expression(model: SpatialHoldModel, x, torque):
    """What the spatial model's right-hand side adds to ``A_l x_l + B_l torque`` (module
    Notes), at the identity attitude (the speeds' equations do not depend on it), as a CasADi
    SX expression of SX symbols ``x`` (n,) and ``torque`` (3,).

    Parameters
    ----------
    model : SpatialHoldModel
        The design model.
    x : casadi.SX, shape (n,)
        ``x_l``.
    torque : casadi.SX, shape (3,)
        The torque on the structure, N m.

    Returns
    -------
    casadi.SX, shape (n,)
    """
    import casadi as ca

    full = ca.SX.zeros(model.n_full)
    full[0] = 1.0
    for k, row in enumerate(model.full_rows):
        full[int(row)] = x[k]
    rate = model.equations.rhs(full, torque)[model.full_rows.tolist()]
    return rate - ca.mtimes(ca.DM(model.a), x) - ca.mtimes(ca.DM(model.b), torque)


def remainder_function(model: SpatialHoldModel):
    """``(x_l, torque) ->`` :func:`remainder_expression`, compiled with its derivatives where
    it can be (:func:`~controllers.design.native_dynamics.with_compiled_derivatives`), built
    once per model.

    Parameters
    ----------
    model : SpatialHoldModel
        The design model.

    Returns
    -------
    casadi.Function
        Inputs ``x`` (n,) and ``torque`` (3,), output ``remainder`` (n,).
    """
    import casadi as ca

    from ..design.native_dynamics import with_compiled_derivatives

    if model.equations in _REMAINDERS:
        return _REMAINDERS[model.equations]
    n = model.a.shape[0]
    x, torque = ca.SX.sym("x", n), ca.SX.sym("torque", 3)
    rest = remainder_expression(model, x, torque)
    built = with_compiled_derivatives(ca.Function("spatial_remainder", [x, torque], [rest],
                                                  ["x", "torque"], ["remainder"],
                                                  {"cse": True}))
    _REMAINDERS[model.equations] = built
    return built


def hold_expressions(model: SpatialHoldModel, wheels, x, q, speeds, tau, remainder) -> tuple:
    """One hold of ``model`` (module Notes) as CasADi expressions of the symbols given.

    Parameters
    ----------
    model : SpatialHoldModel
        The design model.
    wheels : WheelCluster or None
        The wheels ``tau`` is commanded of (a torque on the hub without them).
    x, q, speeds, tau : casadi.SX or casadi.MX
        ``x_l`` (n,), the attitude (4,), the wheel speeds (n_wheels,) and the torque (3,)
        at the hold's start.
    remainder : callable
        ``(x, torque) ->`` the remainder (:func:`remainder_expression` or
        :func:`remainder_function`).

    Returns
    -------
    tuple
        ``(x_next, q_next, speeds_next, motor, held)``: the state one hold later, the motor
        torques of the cluster's distribution and the hold's input ``[torque, remainder]``.
    """
    import casadi as ca

    w = x[model.rate_at:model.rate_at + 3]
    motor, torque = ca.DM(0, 1), tau
    if wheels is not None:
        g, j_w = ca.DM(wheels.axes), ca.DM(wheels.inertias)
        torque = tau - ca.cross(w, ca.mtimes(g, j_w * (ca.mtimes(g.T, w) + speeds)))
        motor = wheels.motor_commands(tau, speeds)      # the cluster's distribution
    held = ca.vertcat(torque, remainder(x, torque))
    phi, gamma, s_x, s_u = (ca.DM(m) for m in model.maps)
    x_next = ca.mtimes(phi, x) + ca.mtimes(gamma, held)
    q_next = symbolic_product(q, _exp_quaternion(ca.mtimes(s_x, x) + ca.mtimes(s_u, held)))
    speeds_next = speeds
    if wheels is not None:
        w_next = x_next[model.rate_at:model.rate_at + 3]
        speeds_next = speeds + model.hold * motor / ca.DM(wheels.inertias) \
            - ca.mtimes(ca.DM(wheels.axes).T, w_next - w)
    return x_next, q_next, speeds_next, motor, held


def hold_functions(model: SpatialHoldModel, wheels) -> HoldFunctions:
    """The hold of ``model`` as CasADi functions, with ``wheels`` or a torque on the hub.

    Parameters
    ----------
    model : SpatialHoldModel
        The design model.
    wheels : WheelCluster or None
        The wheels the torque is commanded of (pseudo-inverse distribution).

    Returns
    -------
    HoldFunctions
    """
    import casadi as ca

    n = model.a.shape[0]
    x, q, tau = ca.MX.sym("x", n), ca.MX.sym("q", 4), ca.MX.sym("tau", 3)
    count = 0 if wheels is None else wheels.count
    speeds = ca.MX.sym("speeds", count)
    x_next, q_next, speeds_next, motor, held = hold_expressions(
        model, wheels, x, q, speeds, tau, remainder_function(model))
    return HoldFunctions(advance=ca.Function("spatial_hold", [x, q, speeds, tau],
                                             [x_next, q_next, speeds_next]),
                         motor=ca.Function("motor", [tau, speeds], [motor]),
                         held=ca.Function("held", [x, speeds, tau], [held]))


def _rigid_guess(problem: SpatialSlewProblem, model: SpatialHoldModel, step: HoldFunctions) -> tuple:
    """The rigid eigenaxis slew's torques (poly7 in angle) and the design model's response."""
    axis, angle = problem.eigenaxis
    n_int = problem.n_intervals
    s = (np.arange(n_int) + 0.5) / n_int
    # the seventh-order rest-to-rest profile's acceleration, at each hold's middle
    acceleration = angle * 420.0 * s ** 2 * (1 - s) ** 2 * (1 - 2 * s) / problem.duration ** 2
    torque = acceleration[:, None] * (model.inertia @ axis)[None, :]
    x = np.zeros(model.a.shape[0])
    q = np.array(problem.start)
    speeds = np.zeros(0) if problem.wheels is None else np.array(problem.wheel_speeds)
    xs, qs, ws = [x], [q], [speeds]
    for k in range(n_int):
        x, q, speeds = (np.asarray(v).ravel() for v in step.advance(x, q, speeds, torque[k]))
        xs.append(x)
        qs.append(q)
        ws.append(speeds)
    return torque, np.array(xs), np.array(qs), np.array(ws)


def _available_torque(problem: SpatialSlewProblem, axis) -> float:
    """The largest torque about ``axis`` the limits allow (N m; inf without any)."""
    if problem.wheels is not None:
        share = np.abs(np.linalg.pinv(problem.wheels.axes) @ axis)
        limits = problem.torque_margin * np.array([w.torque_limit
                                                   for w in problem.wheels.wheels])
        return float(np.min(limits[share > 0] / share[share > 0]))
    if problem.torque_limit is not None:
        return problem.torque_margin * problem.torque_limit / float(np.max(np.abs(axis)))
    return float("inf")


def _refuse_before_solving(problem: SpatialSlewProblem, inertia) -> None:
    wheels = problem.wheels
    if wheels is not None:                  # the null motion's own torque at the start
        rest = np.asarray(wheels.motor_commands(np.zeros(3), problem.wheel_speeds), float)
        limits = problem.torque_margin * np.array([w.torque_limit for w in wheels.wheels])
        if np.any(np.abs(rest) > limits):
            k = int(np.argmax(np.abs(rest) - limits))
            raise InputValueError(
                f"spatial_slew.wheel_speeds: the cluster's null motion asks wheel {k + 1} for "
                f"{rest[k]:.4g} N m at the start (its speeds {np.round(problem.wheel_speeds, 6).tolist()} "
                f"against the null target {np.round(wheels.null_target, 6).tolist()}), beyond "
                f"torque_margin * torque_limit = {limits[k]:.4g} N m before any slew: start the "
                "wheels nearer their null target or lower the cluster's null_gain")
    axis, angle = problem.eigenaxis
    available = _available_torque(problem, axis)
    if angle == 0.0 or not np.isfinite(available):
        return
    shortest = 2.0 * np.sqrt(angle * float(axis @ inertia @ axis) / available)
    if problem.duration < shortest:
        raise InputValueError(
            f"spatial_slew.duration must be at least {shortest:.4g} s, the rigid structure's "
            f"bang-bang time for {np.degrees(angle):.4g} degrees about "
            f"{np.round(axis, 4).tolist()} with the {available:.4g} N m the limits allow about "
            f"it (torque_margin {problem.torque_margin:g} of them); got {problem.duration!r} (a "
            "flexible structure needs somewhat more)")


def _scales(guess: tuple) -> tuple:
    torque, xs, _, _ = guess
    x_scale = np.max(np.abs(xs), axis=0)
    x_scale = np.maximum(x_scale, 1e-6 * max(float(np.max(x_scale)), 1e-12))
    return float(max(np.max(np.abs(torque)), 1e-12)), x_scale


def _limit_constraints(opti, problem, step, torques, speeds) -> None:
    """The wheels' (or the hub axes') limits at every hold's ends."""
    if problem.wheels is None:
        if problem.torque_limit is not None:
            bound = problem.torque_margin * problem.torque_limit
            opti.subject_to(opti.bounded(-bound, torques, bound))
        return
    motor = step.motor.map(problem.n_intervals)(torques, speeds[:, :-1])
    for k, wheel in enumerate(problem.wheels.wheels):
        bound = problem.torque_margin * wheel.torque_limit
        opti.subject_to(opti.bounded(-bound, motor[k, :], bound))
        bound = problem.speed_margin * wheel.speed_limit
        opti.subject_to(opti.bounded(-bound, speeds[k, :], bound))
        if wheel.power_limit is not None:
            for ends in (speeds[k, :-1], speeds[k, 1:]):
                opti.subject_to(opti.bounded(-wheel.power_limit, motor[k, :] * ends,
                                             wheel.power_limit))


@dataclass(frozen=True, eq=False)
class _Transcribed:
    opti: object
    x: object              # scaled states (n, N + 1)
    q: object              # quaternions (4, N + 1)
    speeds: object         # wheel speeds (n_wheels, N + 1)
    torque: object         # scaled torques (3, N)
    torque_scale: float
    x_scale: np.ndarray


def _transcribe(problem: SpatialSlewProblem, model: SpatialHoldModel, step: HoldFunctions,
                guess: tuple) -> _Transcribed:
    import casadi as ca

    n_int, n = problem.n_intervals, model.a.shape[0]
    count = 0 if problem.wheels is None else problem.wheels.count
    torque_scale, x_scale = _scales(guess)
    opti = ca.Opti()
    x_var, qs = opti.variable(n, n_int + 1), opti.variable(4, n_int + 1)
    speeds, u_var = opti.variable(count, n_int + 1), opti.variable(3, n_int)
    xs, torques = ca.diag(ca.DM(x_scale)) @ x_var, torque_scale * u_var
    nxt = step.advance.map(n_int)(xs[:, :-1], qs[:, :-1], speeds[:, :-1], torques)
    opti.subject_to(x_var[:, 1:] - ca.diag(ca.DM(1.0 / x_scale)) @ nxt[0] == 0)
    opti.subject_to(qs[:, 1:] == nxt[1])
    opti.subject_to(x_var[:, 0] == 0)
    opti.subject_to(qs[:, 0] == ca.DM(problem.start))
    if count:
        opti.subject_to(speeds[:, 1:] == nxt[2])
        opti.subject_to(speeds[:, 0] == ca.DM(problem.wheel_speeds))
    opti.subject_to(x_var[:, -1] == 0)
    miss = symbolic_product(ca.DM(conjugate(problem.target)), qs[:, -1])
    opti.subject_to(miss[1:4] == 0)
    _limit_constraints(opti, problem, step, torques, speeds)
    jumps = ca.horzcat(u_var[:, 0], ca.diff(u_var, 1, 1), -u_var[:, -1])
    opti.minimize(model.hold * ca.sumsqr(u_var)
                  + problem.smoothness * ca.sumsqr(jumps) / model.hold)
    torque_g, xs_g, qs_g, ws_g = guess
    opti.set_initial(x_var, (xs_g / x_scale).T)
    opti.set_initial(qs, qs_g.T)
    opti.set_initial(u_var, torque_g.T / torque_scale)
    if count:
        opti.set_initial(speeds, ws_g.T)
    return _Transcribed(opti=opti, x=x_var, q=qs, speeds=speeds, torque=u_var,
                        torque_scale=torque_scale, x_scale=x_scale)


@dataclass(frozen=True, eq=False)
class SpatialSlewSolution:
    """An optimal spatial slew, and the reference a three-axis loop follows along it.

    Attributes
    ----------
    problem : SpatialSlewProblem
        The slew asked for.
    state_names : tuple of str
        The design state's names (``ex, ey, ez`` then the design model's), as
        :func:`~controllers.feedback.spatial_lqr.design_spatial_lqr` names them for the same
        structure and modes.
    times : ndarray, shape (N + 1,)
        The holds' ends, s.
    torque : ndarray, shape (N, 3)
        The torque held over each hold, N m, hub frame (the command of the wheel cluster).
    states : ndarray, shape (N + 1, n)
        The design state after the attitude error (``state_names[3:]``) at every hold's end.
    quaternions : ndarray, shape (N + 1, 4)
        The attitude at every hold's end, hub to inertial, scalar first.
    wheel_speeds : ndarray, shape (N + 1, n_wheels) or None
        The wheels' speeds at every hold's end, rad/s.
    motor_torques : ndarray, shape (N, n_wheels) or None
        Each wheel's motor torque over each hold, N m.
    cost : float
        The plan's cost, ``sum_k h |tau_k|^2`` (N^2 m^2 s) and with a ``smoothness`` its
        jumps' term.
    iterations : int
        IPOPT's iterations.
    solve_time : float
        Wall time of the solve (IPOPT and CasADi's functions), s.
    return_status : str
        IPOPT's.
    model : SpatialHoldModel
        The design model it was planned on.
    step : HoldFunctions
        Its hold.
    _maps : dict
        The hold maps of partial holds the reference has used (filled as it is read).
    """

    problem: SpatialSlewProblem
    state_names: tuple
    times: np.ndarray
    torque: np.ndarray
    states: np.ndarray
    quaternions: np.ndarray
    wheel_speeds: np.ndarray | None
    motor_torques: np.ndarray | None
    cost: float
    iterations: int
    solve_time: float
    return_status: str
    model: SpatialHoldModel
    step: HoldFunctions
    _maps: dict

    def __repr__(self):
        axis, angle = self.problem.eigenaxis
        return (f"SpatialSlewSolution({np.degrees(angle):.4g} deg in {self.end_time:.4g} s, "
                f"{self.problem.n_intervals} holds, cost {self.cost:.6g}, peak torque "
                f"{np.max(np.abs(self.torque)):.4g} N m, {self.return_status})")

    @property
    def target(self) -> np.ndarray:
        """The attitude at the end, hub to inertial, scalar first."""
        return self.problem.target

    @property
    def end_time(self) -> float:
        """When the slew ends, s."""
        return self.problem.duration

    @property
    def peak_power(self) -> float | None:
        """The largest power the wheels draw at a hold's ends, ``sum_k max(u_k Omega_k, 0)``,
        W (None without wheels)."""
        if self.motor_torques is None:
            return None
        ends = [np.sum(np.maximum(self.motor_torques * self.wheel_speeds[s], 0.0), axis=1)
                for s in (slice(0, -1), slice(1, None))]
        return float(np.max(np.maximum(*ends)))

    def torque_function(self):
        """The planned torque as held samples for :func:`flexctl.sim.spatial_run.simulate_spatial`
        (the command of the cluster with ``wheels``).

        Returns
        -------
        VectorTorque
        """
        from flexctl.sim.spatial_run import VectorTorque

        values = np.vstack([self.torque, np.zeros((1, 3))])
        return VectorTorque(self.times, values, interpolation="hold")

    def _within(self, t: float) -> tuple:
        """The design state and attitude at ``t`` (s) from the hold it falls in."""
        h, n_int = self.model.hold, self.problem.n_intervals
        if not t > 0.0:
            return self.states[0], self.quaternions[0], 0
        if t >= self.end_time:
            return self.states[-1], self.quaternions[-1], None
        k = min(int(np.floor(t / h + 1e-9)), n_int - 1)   # a hold's start is its own
        s = round(t - k * h, 12)
        if s <= 0.0:
            return self.states[k], self.quaternions[k], k
        if s not in self._maps:
            self._maps[s] = _hold_maps(self.model.a, self.model.b, self.model.rate_at, s)
        phi, gamma, s_x, s_u = self._maps[s]
        x = self.states[k]
        speeds = np.zeros(0) if self.wheel_speeds is None else self.wheel_speeds[k]
        held = np.asarray(self.step.held(x, speeds, self.torque[k])).ravel()
        return phi @ x + gamma @ held, product(self.quaternions[k],
                                               from_rotation_vector(s_x @ x + s_u @ held)), k

    def state_at(self, t: float) -> np.ndarray:
        """The design state on the slew at ``t`` (:attr:`state_names`: the attitude error from
        :attr:`target` first).

        Parameters
        ----------
        t : float
            Time, s.

        Returns
        -------
        ndarray, shape (n + 3,)
        """
        x, q, _ = self._within(float(t))
        return np.concatenate([error_angles(self.target, q), x])

    def at(self, t: float) -> tuple:
        """The reference at ``t``, as :meth:`EigenaxisSlew.at
        <controllers.slew.eigenaxis.EigenaxisSlew.at>` gives it.

        Parameters
        ----------
        t : float
            Time, s.

        Returns
        -------
        tuple
            ``(error, rate, torque)``: the rotation vector of ``target^-1 (x) q_ref(t)``
            (rad), the rate (rad/s, hub frame) and the planned torque (N m, hub frame).
        """
        x, q, k = self._within(float(t))
        torque = np.zeros(3) if k is None else self.torque[k]
        rate = x[self.model.rate_at:self.model.rate_at + 3]
        return error_angles(self.target, q), rate, torque


def solve_spatial_slew(structure, problem: SpatialSlewProblem, *, n_modes=2,
                       variant: str = "first_order", ipopt_options: dict | None = None
                       ) -> SpatialSlewSolution:
    """The least-effort rest-to-rest slew of ``problem`` on ``structure`` (module description).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    problem : SpatialSlewProblem
        The slew, its holds and its limits.
    n_modes : int, sequence of int or mapping, optional
        Modes per field of each appendage in the design model. Default 2.
    variant : {"exact", "first_order", "zero_order"}, optional
        The spatial model whose right-hand side gives the remainder (module Notes). Default
        ``"first_order"``: compiled with its derivatives, it keeps IPOPT's callbacks fast
        (the exact rod's is longer than
        :data:`~controllers.design.native_dynamics.MAX_INSTRUCTIONS` beyond one mode per
        field, and runs on CasADi's virtual machine, several times slower).
    ipopt_options : dict, optional
        IPOPT options over the defaults (``print_level`` 0, ``max_iter`` 500, ``tol`` 1e-8,
        ``mu_init`` 1e-3: the barrier starts near the limits a slew presses on).

    Returns
    -------
    SpatialSlewSolution

    Raises
    ------
    InputValueError
        When the duration is shorter than the rigid structure's bang-bang time the limits allow.
    SpatialSlewError
        When IPOPT does not converge (its status and iterations attached).

    Examples
    --------
    >>> import numpy as np
    >>> from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
    >>> from flexctl.sim.quaternions import from_rotation_vector
    >>> rod = SpatialAppendage(name="wing", direction=(0, 1, 0), normal=(0, 0, 1), length=1.8,
    ...                        density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
    ...                        second_moment=5.2e-10, second_moment_lateral=5.2e-8,
    ...                        shear_modulus=2.6e10, torsion_constant=1e-9)
    >>> craft = SpatialStructure(hub=SpatialHub(inertia=np.diag([1.3, 1.2, 1.4]),
    ...                                         radius=0.06), appendages=(rod,))
    >>> slew = solve_spatial_slew(craft, SpatialSlewProblem(
    ...     target=from_rotation_vector(np.radians(30) * np.array([0.6, 0, 0.8])),
    ...     duration=6.0, n_intervals=30, torque_limit=0.2), n_modes=1)
    >>> slew.return_status, bool(np.max(np.abs(slew.torque)) <= 0.2 + 1e-6)
    ('Solve_Succeeded', True)
    """
    check_instance("solve_spatial_slew", "problem", problem, SpatialSlewProblem)
    if ipopt_options is not None and not isinstance(ipopt_options, dict):
        raise InputTypeError("solve_spatial_slew.ipopt_options must be a dict of IPOPT "
                             f"options; got {type(ipopt_options).__name__}")
    model = spatial_hold_model(structure, n_modes, variant,
                               problem.duration / problem.n_intervals, "solve_spatial_slew")
    _refuse_before_solving(problem, model.inertia)
    step = hold_functions(model, problem.wheels)
    guess = _rigid_guess(problem, model, step)
    nlp = _transcribe(problem, model, step, guess)
    options = {"print_level": 0, "max_iter": 500, "tol": 1e-8, "mu_init": 1e-3, "sb": "yes",
               **(ipopt_options or {})}
    nlp.opti.solver("ipopt", {"expand": False, "print_time": False}, options)
    began = time.perf_counter()
    try:
        solved = nlp.opti.solve()
    except RuntimeError:
        stats = nlp.opti.stats()
        raise SpatialSlewError(
            f"solve_spatial_slew: IPOPT ended with {stats.get('return_status')} after "
            f"{stats.get('iter_count')} iterations; a longer duration, more holds or looser "
            "limits make the slew easier", str(stats.get("return_status")),
            int(stats.get("iter_count", 0))) from None
    elapsed = time.perf_counter() - began
    stats = solved.stats()
    torque = np.atleast_2d(solved.value(nlp.torque)).T * nlp.torque_scale
    states = np.atleast_2d(solved.value(nlp.x)).T * nlp.x_scale
    quaternions = np.atleast_2d(solved.value(nlp.q)).T
    speeds = motors = None
    if problem.wheels is not None:
        speeds = np.atleast_2d(solved.value(nlp.speeds)).T.reshape(-1, problem.wheels.count)
        motors = np.asarray(step.motor.map(problem.n_intervals)(torque.T, speeds[:-1].T)).T
    return SpatialSlewSolution(
        problem=problem, state_names=model.names,
        times=np.linspace(0.0, problem.duration, problem.n_intervals + 1), torque=torque,
        states=states, quaternions=quaternions / np.linalg.norm(quaternions, axis=1)[:, None],
        wheel_speeds=speeds, motor_torques=motors, cost=float(solved.value(nlp.opti.f)) * nlp.torque_scale ** 2,
        iterations=int(stats["iter_count"]), solve_time=elapsed,
        return_status=str(stats["return_status"]), model=model, step=step,
        _maps={})
