"""The limits of the actuator that turns the hub, for controllers that plan the hub torque.

Trajectory optimisation (:mod:`controllers.slew.trajopt`) and NMPC (:mod:`controllers.mpc.nmpc`)
plan
the hub torque ``u`` on a design model whose input is that torque. The actuator
(:mod:`flexctl.model.actuators`) that must give it bounds the torque, and through the
structure's state, what it can give; this module writes those bounds once for both.

Notes
-----
**Reaction wheel** ``(J_w, T_max, Omega_max)``: ``|u| <= min(u_max, T_max)``, and the wheel
speed relative to the hub stays within its limit. Hub, beams and wheel start at rest and keep
their total angular momentum at 0 (wheel friction is internal; a pinned hub's own friction,
small, is neglected), so the rotor carries ``J_w (theta_dot + Omega) = -H(x)``::

    Omega(x) = -H(x) / J_w - theta_dot,      |Omega(x)| <= (1 - SPEED_MARGIN) Omega_max

with ``H(x)`` the angular momentum of the structure (hub and beams) about the inertial origin
(:func:`structure_momentum`). :data:`SPEED_MARGIN` keeps the plant's wheel off the last
:data:`~flexctl.model.actuators.SPEED_LIMIT_BAND` of its speed range, where its torque fades.

**Geared DC motor**: the voltage that gives the torque ``u`` at the hub rate ``theta_dot``,
``V = u / g + (D / g) theta_dot`` (:meth:`~flexctl.model.actuators.DCMotor.voltage_for`, ``g``
the torque gain, ``D`` the damping), stays within ``+-V_max`` at both ends of every hold: the
motor's torque-speed line ``-g V_max - D theta_dot <= u <= g V_max - D theta_dot``. The design
model carries the rotor's reflected inertia (``ActuatedModel.mechanical``, or the structure
built with it) and a pinned hub.

**What a rest-to-rest slew of angle ``a`` in ``T`` needs** (:func:`refuse_infeasible`):

- from the wheel, on average over the slew, ``J_w |Omega| >= (J + J_w) |a| / T``: the mean of
  ``H`` is ``J a / T`` (the structure starts and ends undeformed at rest), that of
  ``theta_dot`` is ``a / T``;
- from the motor, a mean hub rate ``|a| / T`` below the no-load speed ``g V_max / D``: the
  torque's integral is zero from rest to rest, and the line above bounds it by
  ``D (omega_0 T - |a|)``;
- a torque within the bounds that turns a rigid body of inertia ``J`` (the design model's
  :attr:`~flexctl.Model.rigid_inertia`) in ``T``: bang-bang at ``min(u_max, T_max)``; for a
  motor, accelerating with at most its stall torque and braking with at most twice it (back-EMF
  helps a braking motor: ``g V_max + D theta_dot``, ``theta_dot`` below the no-load speed).

:func:`minimum_duration` adds the hub's rate limit to the last (the wheel's holding
``J_w (1 - margin) Omega_max`` against ``J + J_w``; the motor's no-load speed): a rigid body's
bang-coast-bang time, the lower bound of a free duration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexctl.model import ActuatedModel, DCMotor, Model, ReactionWheel
from flexctl.model.actuators import as_actuator
from flexctl.model.errors import InputTypeError, InputValueError

__all__ = ["SPEED_MARGIN", "RigidLimits", "structure_momentum", "wheel_speed_function",
           "wheel_speeds", "hold_voltages", "demand", "hub_torque_bound", "speed_bound",
           "check_design_model", "rigid_limits", "rigid_slew_time", "minimum_duration",
           "refuse_infeasible", "horizon_rows", "horizon_constraints",
           "linearised_horizon_constraints"]

#: Fraction of the wheel's speed limit a plan keeps clear of: twice the band over which the
#: wheel's torque fades (:data:`flexctl.model.actuators.SPEED_LIMIT_BAND`), so that a plan at
#: its bound still gets the full torque from the plant.
SPEED_MARGIN = 0.02


def hub_torque_bound(torque_bound: float, actuator) -> float:
    """The bound on the hub torque, N m: ``torque_bound``, and a wheel's torque limit.

    Parameters
    ----------
    torque_bound : float
        The controller's own bound on the hub torque, N m (> 0).
    actuator : ReactionWheel, DCMotor or None
        What turns the hub; only a reaction wheel's torque limit lowers the bound.
    """
    if isinstance(actuator, ReactionWheel):
        return min(torque_bound, actuator.torque_limit)
    return torque_bound


def speed_bound(wheel: ReactionWheel) -> float:
    """The bound a plan keeps the wheel speed within, ``(1 - SPEED_MARGIN) Omega_max``, rad/s.

    Parameters
    ----------
    wheel : ReactionWheel
        The wheel; its speed limit ``Omega_max`` (rad/s) is read.
    """
    return (1.0 - SPEED_MARGIN) * wheel.speed_limit


def check_design_model(model, actuator):
    """``actuator`` checked (:func:`~flexctl.model.actuators.as_actuator`) against the design
    ``model``: a model with the hub torque as input, a pinned hub for a DC motor.

    Parameters
    ----------
    model : flexctl.Model
        The design model, whose input is the hub torque (not an ``ActuatedModel``).
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque; ``None`` for an ideal torque (returned as is).

    Raises
    ------
    InputTypeError
        If ``actuator`` is of another type, or ``model`` is not a flexctl Model.
    InputValueError
        If ``model`` is actuated, or a DC motor is asked to turn a free hub.
    """
    actuator = as_actuator(actuator)
    if actuator is None:
        return None
    if not isinstance(model, Model):
        raise InputTypeError(f"model must be a flexctl Model; got {type(model).__name__}")
    if isinstance(model, ActuatedModel):
        raise InputValueError("model must be the design model, whose input is the hub torque "
                              "(for an actuated plant, its model.mechanical); got a model "
                              f"driven through a {model.actuator.kind}")
    if isinstance(actuator, DCMotor) and model.layout.hub_position is not None:
        raise InputValueError("actuator: a dc_motor turns the hub against the ground and needs "
                              "a pinned hub; a free-floating hub is turned by a reaction_wheel")
    return actuator


# ---------------------------------------------------------------------------- momentum
def structure_momentum(model):
    """Angular momentum of hub and beams about the inertial origin, as a CasADi ``Function``
    ``x -> H`` (kg m^2/s) of the design state: the CasADi form of
    :meth:`flexctl.Model.angular_momentum`.

    ``J(q) theta_dot + m_tf^T q_dot`` for the one-beam small-deflection variants (``J(q) = J_0
    + q^T D q`` for consistent, ``J_0`` otherwise); the first row of the exact mass matrix
    times the velocities for exact; a structure model's own momentum function.

    Parameters
    ----------
    model : flexctl.Model
        The design model (hub-torque input; not an ``ActuatedModel``, whose momentum
        includes the actuator's).
    """
    import casadi as ca

    if isinstance(model, ActuatedModel):
        raise InputValueError("the structure's momentum is that of its model.mechanical (an "
                              "actuated model's momentum includes the actuator's)")
    x = ca.SX.sym("x", model.n_states)
    h = model.functions.momentum(x)[0]
    return ca.Function("structure_momentum", [x], [h], ["x"], ["H"])


def wheel_speed_function(model, wheel: ReactionWheel):
    """``Omega(x) = -H(x) / J_w - theta_dot`` (rad/s) as a CasADi ``Function`` ``x -> Omega``
    of the design state (zero total momentum).

    Parameters
    ----------
    model : flexctl.Model
        The design model (not actuated), whose state ``x`` (shape (n,)) the function takes.
    wheel : ReactionWheel
        The wheel: its inertia ``J_w``, kg m^2.
    """
    import casadi as ca

    x = ca.SX.sym("x", model.n_states)
    omega = -structure_momentum(model)(x) / wheel.inertia - x[model.layout.theta_dot]
    return ca.Function("wheel_speed", [x], [omega], ["x"], ["Omega"])


def wheel_speeds(model, wheel: ReactionWheel, states) -> np.ndarray:
    """The wheel speed relative to the hub (rad/s) at design state(s) ``states``, shape () or
    (P,), from :meth:`flexctl.Model.angular_momentum` (zero total momentum).

    Parameters
    ----------
    model : flexctl.Model
        The design model (not actuated).
    wheel : ReactionWheel
        The wheel: its inertia ``J_w``, kg m^2.
    states : array_like, shape (n,) or (n, P)
        Design states, in the order of ``model.layout``.
    """
    states = np.asarray(states, dtype=float)
    return -model.angular_momentum(states) / wheel.inertia - states[model.layout.theta_dot]


def hold_voltages(motor: DCMotor, torque, start_rates, end_rates) -> tuple:
    """The voltages (V) each hold's torque needs at the hub rates at its start and at its end:
    ``(V_start, V_end)`` (numpy or CasADi, linear in every argument).

    Parameters
    ----------
    motor : DCMotor
        The geared motor (:meth:`~flexctl.model.actuators.DCMotor.voltage_for`).
    torque : float, array_like, shape (K,), or CasADi column
        Each hold's hub torque, N m.
    start_rates, end_rates : float, array_like, shape (K,), or CasADi column
        Hub rate at the start and at the end of each hold, rad/s.
    """
    return motor.voltage_for(torque, start_rates), motor.voltage_for(torque, end_rates)


def demand(model, actuator, states, torque):
    """What a plan of hold torques asks of ``actuator``: the wheel speed at the grid states
    (rad/s, shape (K+1,)), or the motor voltage at the start and end of each hold (V, shape
    (2, K)); ``None`` without an actuator.

    Parameters
    ----------
    model : flexctl.Model
        The design model (not actuated).
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque.
    states : array_like, shape (n, K+1)
        Design states at the hold boundaries, in the order of ``model.layout``.
    torque : array_like, shape (K,)
        Torque of each hold, N m.
    """
    if isinstance(actuator, ReactionWheel):
        return wheel_speeds(model, actuator, states)
    if isinstance(actuator, DCMotor):
        rates = np.asarray(states, dtype=float)[model.layout.theta_dot]
        return np.stack(hold_voltages(actuator, np.asarray(torque, dtype=float), rates[:-1],
                                      rates[1:]))
    return None


# ---------------------------------------------------------------------------- horizons
def horizon_rows(actuator, horizon: int) -> int:
    """Rows of :func:`horizon_constraints` over ``horizon`` holds: the wheel speed at each
    state after the first; the voltage at the start, then at the end, of each hold.

    Parameters
    ----------
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque (no rows without one).
    horizon : int
        Number of holds ``N`` of the horizon.
    """
    if isinstance(actuator, ReactionWheel):
        return horizon
    if isinstance(actuator, DCMotor):
        return 2 * horizon
    return 0


def horizon_constraints(model, actuator, xs, us) -> tuple:
    """``(g, lower, upper)``: the actuator's limits on the states ``xs`` (``N + 1`` CasADi
    columns) and hold torques ``us`` (``N``) of a horizon, ``lower <= g <= upper``, in the
    order of :func:`horizon_rows` (empty without an actuator).

    Parameters
    ----------
    model : flexctl.Model
        The design model (not actuated).
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque.
    xs : sequence of CasADi column
        The ``N + 1`` design states of the horizon, each of shape (n, 1).
    us : sequence of CasADi scalar
        The ``N`` hold torques, N m.
    """
    import casadi as ca

    big_n = len(us)
    if isinstance(actuator, ReactionWheel):
        speed, bound = wheel_speed_function(model, actuator), speed_bound(actuator)
        g = ca.vertcat(*[speed(x) for x in xs[1:]])
        return g, np.full(big_n, -bound), np.full(big_n, bound)
    if isinstance(actuator, DCMotor):
        rates = [x[model.layout.theta_dot] for x in xs]
        start, end = hold_voltages(actuator, ca.vertcat(*us), ca.vertcat(*rates[:-1]),
                                   ca.vertcat(*rates[1:]))
        limit = np.full(2 * big_n, actuator.voltage_limit)
        return ca.vertcat(start, end), -limit, limit
    return ca.MX(0, 1), np.zeros(0), np.zeros(0)


def linearised_horizon_constraints(model, actuator, xs, us, e, g_mats) -> tuple:
    """``(A, lower, upper)`` of :func:`horizon_constraints` linearised in the torque steps
    ``du`` (``lower <= A du <= upper``), for state steps ``dx_j = e_j + G_j du`` about the
    guess ``xs``, ``us`` (a condensed Gauss-Newton step); the voltage is linear, so exact.

    Parameters
    ----------
    model : flexctl.Model
        The design model (not actuated).
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque (no rows without one).
    xs : sequence of CasADi column
        The ``N + 1`` guessed design states, each of shape (n, 1).
    us : CasADi column, shape (N, 1)
        The guessed hold torques, N m.
    e : sequence of CasADi column
        ``e_j`` (``j = 0..N``), each of shape (n, 1): the state steps at ``du = 0``.
    g_mats : sequence of CasADi matrix
        ``G_j`` (``j = 0..N``), each of shape (n, N): the state steps per torque step (state
        units per N m).
    """
    import casadi as ca

    big_n, n = us.numel(), model.n_states
    if isinstance(actuator, ReactionWheel):
        x = ca.SX.sym("x", n)
        omega = wheel_speed_function(model, actuator)(x)
        linear = ca.Function("wheel_speed_linear", [x], [omega, ca.jacobian(omega, x)])
        values, slopes = linear.map(big_n)(ca.horzcat(*xs[1:]))
        grads = [slopes[:, j * n:(j + 1) * n] for j in range(big_n)]
        rows = ca.vertcat(*[ca.mtimes(grads[j], g_mats[j + 1]) for j in range(big_n)])
        now = values.T + ca.vertcat(*[ca.mtimes(grads[j], e[j + 1]) for j in range(big_n)])
        bound = speed_bound(actuator)
        return rows, -bound - now, bound - now
    if isinstance(actuator, DCMotor):
        k = model.layout.theta_dot
        per_torque, per_rate = actuator.voltage_for(1.0, 0.0), actuator.voltage_for(0.0, 1.0)
        rates = [g[k, :] for g in g_mats]
        steps = [xs[j][k] + e[j][k] for j in range(big_n + 1)]
        eye = per_torque * ca.DM.eye(big_n)
        rows = ca.vertcat(eye + per_rate * ca.vertcat(*rates[:-1]),
                          eye + per_rate * ca.vertcat(*rates[1:]))
        now = ca.vertcat(*hold_voltages(actuator, us, ca.vertcat(*steps[:-1]),
                                        ca.vertcat(*steps[1:])))
        limit = actuator.voltage_limit
        return rows, -limit - now, limit - now
    return ca.MX(0, big_n), ca.MX(0, 1), ca.MX(0, 1)


# ---------------------------------------------------------------------------- rigid bounds
@dataclass(frozen=True)
class RigidLimits:
    """What a rest-to-rest slew of a rigid body may use (see the module Notes).

    Attributes
    ----------
    accelerating, braking : float
        Largest torque speeding the hub up and slowing it down, N m.
    rate : float
        Largest hub rate, rad/s (``inf`` without a limit).
    """

    accelerating: float
    braking: float
    rate: float


def rigid_limits(model, actuator, torque_bound: float) -> RigidLimits:
    """The :class:`RigidLimits` of ``actuator`` (or of ``torque_bound`` alone) on ``model``.

    Parameters
    ----------
    model : flexctl.Model
        The design model (its :attr:`~flexctl.Model.rigid_inertia`, kg m^2).
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque.
    torque_bound : float
        The controller's own bound on the hub torque, N m (> 0).
    """
    bound = hub_torque_bound(torque_bound, actuator)
    if isinstance(actuator, ReactionWheel):
        inertia = model.rigid_inertia
        rate = actuator.inertia * speed_bound(actuator) / (inertia + actuator.inertia)
        return RigidLimits(bound, bound, rate)
    if isinstance(actuator, DCMotor):
        stall = actuator.stall_torque
        return RigidLimits(min(bound, stall), min(bound, 2.0 * stall), actuator.no_load_speed)
    return RigidLimits(bound, bound, math.inf)


def rigid_slew_time(angle: float, inertia: float, limits: RigidLimits) -> float:
    """Least time (s) a rigid body of ``inertia`` takes to turn ``angle`` from rest to rest
    within ``limits``: bang-bang, or bang-coast-bang at the rate limit.

    Parameters
    ----------
    angle : float
        Slew angle, rad (its sign does not matter).
    inertia : float
        Inertia of the rigid body, kg m^2 (> 0).
    limits : RigidLimits
        Largest accelerating and braking torques (N m) and hub rate (rad/s).

    Examples
    --------
    >>> rigid_slew_time(1.0, 2.0, RigidLimits(2.0, 2.0, math.inf))     # 2 sqrt(a J / u)
    2.0
    >>> rigid_slew_time(1.0, 2.0, RigidLimits(2.0, 2.0, 0.5))         # a / w + w J / u
    2.5
    """
    per_rate = inertia / limits.accelerating + inertia / limits.braking    # s per rad/s
    peak = math.sqrt(2.0 * abs(angle) / per_rate)
    if peak <= limits.rate:
        return peak * per_rate
    return abs(angle) / limits.rate + 0.5 * limits.rate * per_rate


def minimum_duration(model, actuator, angle: float, torque_bound: float) -> float:
    """A lower bound on the duration (s) of a rest-to-rest slew of ``angle`` on ``model``
    within ``torque_bound`` and the limits of ``actuator``: the rigid body's
    (:func:`rigid_slew_time`).

    Parameters
    ----------
    model : flexctl.Model
        The design model (its :attr:`~flexctl.Model.rigid_inertia`, kg m^2).
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque.
    angle : float
        Slew angle, rad.
    torque_bound : float
        The controller's own bound on the hub torque, N m (> 0).
    """
    return rigid_slew_time(angle, model.rigid_inertia, rigid_limits(model, actuator,
                                                                     torque_bound))


# ---------------------------------------------------------------------------- refusals
def refuse_infeasible(model, actuator, angle: float, duration: float,
                      torque_bound: float) -> None:
    """Raise ``InputValueError`` naming the actuator's limit that a rest-to-rest slew of
    ``angle`` in ``duration`` cannot meet (module Notes); nothing without one.

    Parameters
    ----------
    model : flexctl.Model
        The design model (its :attr:`~flexctl.Model.rigid_inertia`, kg m^2).
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque (nothing is checked without one).
    angle : float
        Slew angle, rad.
    duration : float
        Slew duration, s (> 0).
    torque_bound : float
        The controller's own bound on the hub torque, N m (> 0).
    """
    if isinstance(actuator, ReactionWheel):
        _refuse_wheel(model, actuator, angle, duration, torque_bound)
    elif isinstance(actuator, DCMotor):
        _refuse_motor(model, actuator, angle, duration, torque_bound)


def _refuse_wheel(model, wheel: ReactionWheel, angle, duration, torque_bound) -> None:
    inertia, a = model.rigid_inertia, abs(angle)
    capacity = wheel.inertia * speed_bound(wheel)
    needed = (inertia + wheel.inertia) * a / duration
    if needed > capacity:
        raise InputValueError(
            f"actuator.speed_limit {wheel.speed_limit:g} rad/s is too low for a {angle:g} rad "
            f"slew in {duration:g} s: the wheel must hold on average (J + J_w) |angle| / T = "
            f"{needed:.4g} N m s of momentum (structure J = {inertia:.4g} kg m^2, wheel J_w = "
            f"{wheel.inertia:g} kg m^2), more than the {capacity:.4g} N m s it holds at "
            f"{1 - SPEED_MARGIN:.0%} of its speed limit: lengthen the duration to at least "
            f"{duration * needed / capacity:.4g} s, or raise actuator.speed_limit above "
            f"{wheel.speed_limit * needed / capacity:.4g} rad/s")
    shortest = minimum_duration(model, None, angle, min(torque_bound, wheel.torque_limit))
    if wheel.torque_limit < torque_bound and duration < shortest:
        raise InputValueError(
            f"actuator.torque_limit {wheel.torque_limit:g} N m is too low for a {angle:g} rad "
            f"slew in {duration:g} s: a rigid body of {inertia:.4g} kg m^2 needs at least "
            f"{shortest:.4g} s at that torque (bang-bang): lengthen the duration or raise "
            "actuator.torque_limit")


def _refuse_motor(model, motor: DCMotor, angle, duration, torque_bound) -> None:
    mean_rate, no_load = abs(angle) / duration, motor.no_load_speed
    if mean_rate >= no_load:
        raise InputValueError(
            f"actuator.voltage_limit {motor.voltage_limit:g} V is too low for a {angle:g} rad "
            f"slew in {duration:g} s: the hub must turn on average at |angle| / T = "
            f"{mean_rate:.4g} rad/s, at or above the motor's no-load speed {no_load:.4g} rad/s, "
            f"where its torque-speed line (stall torque {motor.stall_torque:.4g} N m, "
            f"{motor.damping:.4g} N m s per rad/s) leaves no torque: lengthen the duration "
            f"beyond {abs(angle) / no_load:.4g} s, or raise actuator.voltage_limit above "
            f"{motor.voltage_limit * mean_rate / no_load:.4g} V")
    limits = rigid_limits(model, motor, torque_bound)
    turning = RigidLimits(limits.accelerating, limits.braking, math.inf)
    shortest = rigid_slew_time(angle, model.rigid_inertia, turning)
    if limits.accelerating < torque_bound and duration < shortest:
        raise InputValueError(
            f"actuator.voltage_limit {motor.voltage_limit:g} V is too low for a {angle:g} rad "
            f"slew in {duration:g} s: with at most the stall torque "
            f"{limits.accelerating:.4g} N m to speed the hub up and {limits.braking:.4g} N m "
            f"to slow it down, a rigid body of {model.rigid_inertia:.4g} kg m^2 needs at least "
            f"{shortest:.4g} s: lengthen the duration or raise actuator.voltage_limit")
