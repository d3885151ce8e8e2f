"""Controllers that know the actuator between them and the hub.

A law designed for an ideal hub torque runs on a plant with an actuator
(:class:`flexctl.model.actuated.ActuatedModel`) as follows:

- a reaction wheel's command *is* a hub torque (:mod:`flexctl.model.actuators`), so the law
  drives it as it is; :func:`design_wheel_lqr` designs the LQR on the structure augmented with
  the wheel's first-order motor lag, its gain reading the wheel torque too;
- a DC motor takes a voltage: :class:`MotorVoltage` turns the law's hub torque into the
  voltage that gives it at the present hub rate, the exact inverse of the motor's algebraic
  torque-speed line (back-EMF, resistance, gear and friction); the plant clips the voltage,
  so the torque available falls with speed as on the real motor.

:func:`through_actuator` picks the wrapper a plant needs.

Notes
-----
Wheel-augmented LQR (:func:`design_wheel_lqr`): with the design model's ``x_m`` (``n``
states), the hub torque ``T_m`` (the wheel's lagged motor torque) and the command ``u``::

    d/dt [x_m; T_m] = [[A_m, B_m], [0, -1/tau]] [x_m; T_m] + [0; 1/tau] u
    u = sat(-K_m (x_m - x_ref) - k_a (T_m - J acc_ref) + J acc_ref)

The wheel's speed is left out of the design: it stores the momentum the structure gives up
(total angular momentum is conserved, a mode the command cannot move), and its friction is a
disturbance to the loop.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from flexctl.model.errors import InputTypeError, InputValueError

from ..design.actuator_limits import SPEED_MARGIN, hub_torque_bound, speed_bound
from ..design.controllable import controllable_part, design_failure, state_gain
from .lqr import LQR, LQRWeights, casadi_reference_state, design_lqr, lqr_weight_matrices, \
    reference_state
from ..slew.reference import casadi_saturate, saturate

__all__ = ["MotorVoltage", "LaggedLQR", "design_wheel_lqr", "through_actuator"]


def _actuator(plant):
    return getattr(plant, "actuator", None)


@dataclass(frozen=True, eq=False)
class MotorVoltage:
    """A hub-torque law driving a DC motor: the voltage that gives its torque at the hub rate.

    Parameters
    ----------
    law : object
        A flexctl controller whose output is a hub torque, N m: a static or stateful
        :class:`flexctl.Controller`, or a sampled one (``sample_time`` and ``start``).
    plant : ActuatedModel
        The motor-driven plant (its motor and the index of its hub rate).
    """

    law: object
    plant: object

    def __post_init__(self):
        actuator = _actuator(self.plant)
        if actuator is None or actuator.kind != "dc_motor":
            raise InputValueError("MotorVoltage.plant must be driven by a dc_motor; got "
                                  f"{type(actuator).__name__ if actuator else 'no actuator'}")
        if not (callable(getattr(self.law, "torque", None)) or callable(
                getattr(self.law, "start", None))):
            raise InputTypeError("MotorVoltage.law must be a flexctl controller; got "
                                 f"{type(self.law).__name__}")

    @property
    def motor(self):
        """The plant's :class:`~flexctl.model.actuators.DCMotor`."""
        return self.plant.actuator

    def _voltage(self, torque, x):
        return self.motor.voltage_for(torque, x[self.plant.layout.theta_dot])

    # ---- the Controller protocol, passed through the law
    @property
    def n_states(self) -> int:
        """The law's internal states."""
        return int(getattr(self.law, "n_states", 0) or 0)

    @property
    def breakpoints(self) -> tuple:
        """The law's times of non-smoothness, s."""
        return tuple(getattr(self.law, "breakpoints", ()) or ())

    @property
    def has_casadi_form(self) -> bool:
        """True when the law has a CasADi form."""
        return callable(getattr(self.law, "casadi_torque", None)) and bool(
            getattr(self.law, "has_casadi_form", True))

    @property
    def casadi_parameters(self):
        """The law's parameters (its compiled runs share integrators)."""
        return getattr(self.law, "casadi_parameters", None)

    @property
    def plant_layout(self):
        """The plant layout the law reads."""
        return getattr(self.law, "plant_layout", self.plant.layout)

    def for_plant(self, model):
        """The law bound to ``model`` (the plant).

        Parameters
        ----------
        model : ActuatedModel
            The motor-driven plant the law runs on.
        """
        law = self.law.for_plant(model) if hasattr(self.law, "for_plant") else self.law
        return replace(self, law=law, plant=model)

    def initial_state(self, x0):
        """The law's internal state at ``t = 0``.

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Initial state of the motor-driven plant.
        """
        return self.law.initial_state(x0)

    def derivative(self, t, x, z=None):
        """The law's ``dz/dt``.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            State of the motor-driven plant, in the order of ``plant.layout``.
        z : array_like, shape (n_states,), optional
            The law's internal state.
        """
        return self.law.derivative(t, x, z)

    def casadi_derivative(self, t, x, z):
        """The law's ``dz/dt`` (CasADi).

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            State of the motor-driven plant.
        z : CasADi column, shape (n_states, 1)
            The law's internal state.
        """
        return self.law.casadi_derivative(t, x, z)

    def torque(self, t, x, z=None) -> float:
        """Voltage, V, for the law's hub torque at time ``t`` and plant state ``x``.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            State of the motor-driven plant, in the order of ``plant.layout``.
        z : array_like, shape (n_states,), optional
            The law's internal state.
        """
        return float(self._voltage(self.law.torque(t, x, z), np.asarray(x, dtype=float)))

    def casadi_torque(self, t, x, extra=None):
        """:meth:`torque` as a CasADi expression.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            State of the motor-driven plant.
        extra : CasADi column, optional
            The law's internal state or parameters, as the law's ``casadi_torque`` takes
            them. Default: none passed.
        """
        args = (t, x) if extra is None else (t, x, extra)
        return self._voltage(self.law.casadi_torque(*args), x)

    # ---- a sampled law
    @property
    def sample_time(self):
        """The law's sample time, s (None for a continuous law)."""
        return getattr(self.law, "sample_time", None)

    def start(self, model, x0):
        """A session of the sampled law whose torques become voltages.

        Parameters
        ----------
        model : flexctl.Model
            The plant of the run.
        x0 : array_like, shape (n,)
            Plant state at the start of the run.
        """
        return _VoltageSession(self.law.start(model, x0), self)

    @property
    def measures(self) -> bool:
        """True when the law reads sensors rather than the state."""
        return bool(getattr(self.law, "measures", False))


@dataclass(frozen=True, eq=False)
class _VoltageSession:
    inner: object
    owner: MotorVoltage

    def step(self, t, x):
        return float(self.owner._voltage(self.inner.step(t, x), np.asarray(x, dtype=float)))

    def report(self):
        return self.inner.report()


@dataclass(frozen=True, kw_only=True, eq=False)
class LaggedLQR:
    """LQR on a structure turned through a lagging wheel (see the module Notes).

    Parameters
    ----------
    lqr : LQR
        The structure's part: gain ``K_m``, reference, feedforward inertia ``J``; its torque
        limit is not used (the saturation is this law's).
    actuator_gain : float
        ``k_a``, on the wheel's motor torque (dimensionless).
    torque_limit : float, optional
        Saturation of the command, N m. Default: none.
    plant_layout : StateLayout, optional
        The plant state's layout, set by :meth:`for_plant` (the wheel torque is read through
        it). Default None.
    """

    lqr: LQR
    actuator_gain: float
    torque_limit: float | None = None
    plant_layout: object = None

    n_states = 0
    owner = "lqr"
    #: Its loop closes through the wheel's states (:func:`controllers.design.stability.check_loop`).
    reads_actuator = True

    def for_plant(self, model):
        """The law reading ``model``'s states (the wheel torque among them).

        Parameters
        ----------
        model : ActuatedModel
            A plant turned by a reaction wheel (a state named ``wheel_torque``).
        """
        if _actuator(model) is None or "wheel_torque" not in model.state_names:
            raise InputValueError("LaggedLQR needs a plant turned by a reaction wheel; got "
                                  f"states {model.state_names}")
        return replace(self, lqr=self.lqr.for_plant(model), plant_layout=model.layout)

    def plant_gain(self, plant, spin_rate: float = 0.0) -> np.ndarray:
        """``K`` on the actuated ``plant``'s state: the structure's gain and ``k_a`` on the
        wheel torque, shape (1, n).

        Parameters
        ----------
        plant : ActuatedModel
            The wheel-driven plant (a state named ``wheel_torque``).
        spin_rate : float, optional
            Steady hub rate, rad/s (not read: the gain is fixed). Default 0.
        """
        names = tuple(getattr(plant, "state_names", ()))
        if "wheel_torque" not in names:
            raise InputValueError(
                "LaggedLQR.plant_gain plant must carry the reaction wheel the law commands (a "
                "state named 'wheel_torque': flexctl.build_model(..., actuator=wheel)); got "
                f"a plant without one, states {', '.join(names[:4])}"
                f"{', ...' if len(names) > 4 else ''}")
        gain = np.array(self.lqr.state_gain(plant.layout), dtype=float).reshape(1, -1)
        gain[0, names.index("wheel_torque")] += self.actuator_gain
        return gain

    def _lag_index(self, size: int) -> int:
        if self.plant_layout is None or self.plant_layout.n_states != size:
            raise InputValueError("LaggedLQR reads the wheel torque of its plant: bind it with "
                                  "for_plant(model) (flexctl.simulate does)")
        return self.plant_layout.names.index("wheel_torque")

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the reference is not smooth."""
        return self.lqr.breakpoints

    @property
    def has_casadi_form(self) -> bool:
        """True when the reference has a CasADi form."""
        return self.lqr.has_casadi_form

    def _feedforward(self, acceleration):
        inertia = self.lqr.feedforward_inertia
        return 0.0 if inertia is None else inertia * acceleration

    def initial_state(self, x0):
        """No internal state: shape (0,).

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Initial plant state (not read).
        """
        return np.zeros(0)

    def derivative(self, t, x, z=None):
        """No internal state.

        Parameters
        ----------
        t : float
            Time, s (not read).
        x : array_like, shape (n,)
            Plant state (not read).
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        return np.zeros(0)

    def torque(self, t: float, x, z=None) -> float:
        """Command, N m.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            State of the wheel-driven plant (the wheel torque among it), in the order of
            the bound ``plant_layout``.
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        x = np.asarray(x, dtype=float)
        lqr = self.lqr
        x_ref, acc = reference_state(lqr.reference, t, lqr.layout, lqr.deflection_gain)
        ff = self._feedforward(acc)
        u = -float(lqr.gain[0] @ (lqr._design_state(x) - x_ref)) \
            - self.actuator_gain * (x[self._lag_index(x.size)] - ff) + ff
        return saturate(u, self.torque_limit)

    def casadi_torque(self, t, x, z=None):
        """:meth:`torque` as a CasADi expression.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            State of the wheel-driven plant, in the order of the bound ``plant_layout``.
        z : CasADi column, optional
            Internal state (none; not read).
        """
        import casadi as ca

        lqr = self.lqr
        x_ref, acc = casadi_reference_state(lqr.reference, t, lqr.layout, lqr.deflection_gain)
        ff = self._feedforward(acc)
        u = -ca.dot(ca.DM(lqr.gain[0]), lqr._casadi_design_state(x) - x_ref) \
            - self.actuator_gain * (x[self._lag_index(x.numel())] - ff) + ff
        return u if self.torque_limit is None else casadi_saturate(u, self.torque_limit)


def design_wheel_lqr(design, wheel, weights: LQRWeights, *, reference=None,
                     feedforward: bool = True, torque_limit: float | None = None,
                     flexible_reference: bool = True,
                     sample_time: float | None = None) -> LaggedLQR:
    """LQR on the design model augmented with the wheel's motor lag (module Notes).

    Parameters
    ----------
    design : flexctl.Model
        The structure's design model (hub-torque input).
    wheel : ReactionWheel
        The wheel: its motor time constant ``tau`` (s) and torque limit (N m).
    weights : LQRWeights
        Weights of the structure's states and the command
        (:func:`~controllers.feedback.lqr.lqr_weight_matrices`).
    reference : object, optional
        Hub reference, as for :func:`controllers.feedback.lqr.design_lqr`.
    feedforward : bool, optional
        Add ``J0 acc_ref``, as for :func:`controllers.feedback.lqr.design_lqr`. Default True.
    torque_limit : float, optional
        Saturation of the command, N m; at most the wheel's torque limit, its default.
    flexible_reference : bool, optional
        As for :func:`controllers.feedback.lqr.design_lqr`. Default True.
    sample_time : float, optional
        For a law run sampled with a zero-order hold (s): the discrete LQR of the augmented
        plant held over ``sample_time`` (weights ``Q T`` and ``R T``, the continuous cost's
        rectangle rule), so that a hold slow against the lag keeps the loop stable. Default:
        the continuous LQR.

    Returns
    -------
    LaggedLQR
    """
    if getattr(wheel, "kind", None) != "reaction_wheel":
        raise InputTypeError(f"wheel must be a ReactionWheel; got {type(wheel).__name__}")
    limit = wheel.torque_limit if torque_limit is None else min(torque_limit, wheel.torque_limit)
    base = design_lqr(design, weights, reference=reference, feedforward=feedforward,
                      flexible_reference=flexible_reference)
    a_m, b_m = design.linear_matrices(0.0)
    n, tau = a_m.shape[0], wheel.time_constant
    a = np.block([[a_m, b_m], [np.zeros((1, n)), -np.ones((1, 1)) / tau]])
    b = np.vstack((np.zeros((n, 1)), [[1.0 / tau]]))
    q_m, r = lqr_weight_matrices(design, weights)
    part = controllable_part(design, 0.0)
    basis = np.block([[part.basis, np.zeros((n, 1))], [np.zeros((1, part.basis.shape[1])),
                                                       np.ones((1, 1))]])
    projector = np.block([[part.projector, np.zeros((part.projector.shape[0], 1))],
                          [np.zeros((1, n)), np.ones((1, 1))]])
    q = np.zeros((n + 1, n + 1))
    q[:n, :n] = q_m
    q_r = basis.T @ q @ basis
    a_r, b_r, q_r = projector @ a @ basis, projector @ b, 0.5 * (q_r + q_r.T)
    with design_failure("reaction-wheel lqr", "design_wheel_lqr", design, weights=weights,
                        time_constant=tau, sample_time=sample_time,
                        solving="the LQR Riccati equation of the structure with the motor lag"):
        gain = state_gain(a_r, b_r, q_r, r, sample_time) @ projector
    lqr = replace(base, gain=gain[:, :n], poles=np.linalg.eigvals(a - b @ gain))
    return LaggedLQR(lqr=lqr, actuator_gain=float(gain[0, n]), torque_limit=limit)


def through_actuator(controller, plant):
    """``controller`` (its output a hub torque) as the plant's actuator takes it: unchanged
    for an ideal torque or a reaction wheel, a :class:`MotorVoltage` for a DC motor.

    Parameters
    ----------
    controller : object
        A flexctl controller whose output is a hub torque, N m (continuous or sampled).
    plant : flexctl.Model
        The plant the controller runs on (an ``ActuatedModel`` carries its actuator).
    """
    actuator = _actuator(plant)
    if actuator is None or actuator.kind != "dc_motor" or isinstance(controller, MotorVoltage):
        return controller
    return MotorVoltage(controller, plant)


#: Points at which a reference's actuator demand is checked over its duration.
_CHECK_POINTS = 801


def actuator_torque_bound(actuator, torque_bound: float | None) -> float | None:
    """The hub-torque bound a design may use: the manoeuvre's, within what the actuator gives
    (a wheel's torque limit, a motor's stall torque at its voltage limit), N m.

    Parameters
    ----------
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque; None: an ideal torque.
    torque_bound : float or None
        The manoeuvre's bound on the hub torque, N m; None: the actuator's alone.
    """
    if actuator is None:
        return torque_bound
    if actuator.kind == "reaction_wheel":
        return actuator.torque_limit if torque_bound is None else \
            hub_torque_bound(float(torque_bound), actuator)
    # a motor gives its stall torque from rest (more while braking: its voltage line,
    # which trajectory optimisation and NMPC take as such)
    return actuator.stall_torque if torque_bound is None else \
        min(float(torque_bound), actuator.stall_torque)


def check_reference_fits(actuator, inertia: float, reference) -> dict:
    """Refuse a reference slew the actuator cannot follow; return what it needs.

    A rest-to-rest reference of the rigid structure (``inertia`` ``J``) needs the hub
    torque ``J acc(t)`` and, on a wheel, the momentum ``J rate(t)`` that the wheel takes up
    (its speed ``J rate / J_w`` relative to the hub, nearly); on a DC motor, the voltage
    ``voltage_for(J acc, rate)`` of its torque-speed line.

    Parameters
    ----------
    actuator : ReactionWheel, DCMotor or None
        What gives the hub torque; None: nothing to check.
    inertia : float
        Rigid inertia ``J`` of the structure, kg m^2.
    reference : object or None
        A rest-to-rest hub reference starting at 0 s with ``duration`` (s), ``rate(t)``
        (rad/s) and ``acceleration(t)`` (rad/s^2), e.g. a
        :class:`~controllers.slew.reference.SlewProfile`; None: nothing to check.

    Returns
    -------
    dict
        ``peak_wheel_speed`` (rad/s) or ``peak_voltage`` (V) the reference needs.

    Raises
    ------
    InputValueError
        Naming the limit (``actuator.speed_limit``, ``actuator.voltage_limit``) the reference
        passes, with the numbers.
    """
    if actuator is None or reference is None:
        return {}
    t = np.linspace(0.0, float(reference.duration), _CHECK_POINTS)
    rate = np.array([reference.rate(s) for s in t], dtype=float)
    acc = np.array([reference.acceleration(s) for s in t], dtype=float)
    if actuator.kind == "reaction_wheel":
        speed = float(np.max(np.abs(inertia * rate / actuator.inertia + rate)))
        allowed = speed_bound(actuator)
        if speed > allowed:
            raise InputValueError(
                f"actuator.speed_limit {actuator.speed_limit:g} rad/s: the slew's peak rate "
                f"{np.max(np.abs(rate)):.4g} rad/s puts {inertia * np.max(np.abs(rate)):.4g} "
                f"N m s into the wheel, which would spin at {speed:.4g} rad/s (more than "
                f"{allowed:.4g} rad/s, {1 - SPEED_MARGIN:.0%} of its limit; it stores "
                f"{actuator.momentum_capacity:.4g} N m s there); lengthen maneuver.duration")
        return {"peak_wheel_speed": speed}
    volts = float(np.max(np.abs(actuator.voltage_for(inertia * acc, rate))))
    if volts > actuator.voltage_limit:
        raise InputValueError(
            f"actuator.voltage_limit {actuator.voltage_limit:g} V: the slew needs "
            f"{volts:.4g} V (the torque J acc plus the back-EMF and friction at its rate; the "
            f"motor's no-load speed is {actuator.no_load_speed:.4g} rad/s at the hub); "
            "lengthen maneuver.duration")
    return {"peak_voltage": volts}
