"""Actuators that turn the hub: a reaction wheel, or a geared DC motor driven by a voltage.

An actuator sits between the controller's command and the hub: it owns its states (appended to
the plant's state, :mod:`flexctl.model.actuated`), its input (the command) and the torque it
puts on the structure. Without one, the plant's input is an ideal hub torque.

Notes
-----
**Reaction wheel** (:class:`ReactionWheel`): a rotor of axial inertia ``J_w`` spinning at
``Omega`` (rad/s) *relative to the hub* about the hub's axis; its mass and transverse inertia
belong to the hub, so ``Hub.inertia`` is that of the body without the rotor's spin inertia.
States ``[wheel_speed Omega, wheel_torque T_m]``, input ``torque_command u`` (N m: the torque
asked of the wheel *on the hub*, so that a law designed for an ideal hub torque commands it as
it is)::

    T_m_dot = (sat(u) - T_m) / tau                      first-order motor lag, |sat(u)| <= T_max
    T_a     = g(Omega, T_m) T_m                          the motor torque on the hub
    f       = b Omega + c tanh(Omega / omega_s)          bearing friction on the rotor
    T_hub   = T_a + f                                    the torque on the structure
    J_w (theta_tt + Omega_dot) = -T_a - f                the rotor: Omega_dot = -T_hub / J_w - theta_tt

The speed limit ``Omega_max``: the gate ``g`` is 1 except where the motor torque on the rotor
(``-T_m``) would drive ``|Omega|`` further up, where it falls linearly from 1 to 0 over the
last :data:`SPEED_LIMIT_BAND` of ``Omega_max`` (Lipschitz, so that error-controlled
integrators keep their order; at ``|Omega| = Omega_max`` the motor gives no more torque in that
direction). Coulomb friction is smoothed by ``tanh(Omega / omega_s)``: within ``omega_s`` of
standstill it is a steep viscous friction of slope ``c / omega_s`` instead of a jump (no
stiction is modelled), which keeps the right-hand side smooth. Hub, beams and wheel conserve
their angular momentum ``H_structure + J_w (theta_dot + Omega)``: wheel friction is internal.

**Geared DC motor** (:class:`DCMotor`): armature resistance ``R``, torque constant ``k_t``,
back-EMF constant ``k_b``, gear ratio ``N`` (motor turns per hub turn), gear efficiency
``eta``, rotor inertia ``J_m`` and viscous friction ``b`` at the output shaft, voltage limit
``V_max``; the winding inductance is neglected (its time constant ``L / R`` is far below the
mechanical ones), so the motor adds no state. Input ``voltage`` (V)::

    V_a   = sat(u),  |V_a| <= V_max
    i     = (V_a - k_b N theta_dot) / R                  motor current, A
    T_hub = eta N k_t i - b theta_dot

and the rotor inertia reflected through the gear, ``N^2 J_m``, adds to the hub inertia (the
rotor's kinetic energy ``1/2 J_m (N theta_dot)^2``). Stall torque ``eta N k_t V / R``, no-load
speed ``V / (k_b N)`` at the hub (``V / k_b`` at the motor) when ``b = 0``. The stator is fixed
to the ground: a free-floating hub is turned by a reaction wheel instead.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .checks import KeywordOnly, check_real
from .errors import InputTypeError, InputValueError

__all__ = ["ReactionWheel", "DCMotor", "ACTUATOR_KINDS", "SPEED_LIMIT_BAND", "as_actuator"]

#: Fraction of the speed limit over which the wheel's motor torque fades to zero.
SPEED_LIMIT_BAND = 0.01
#: Default speed over which Coulomb friction is smoothed, rad/s (about 10 rpm).
FRICTION_SMOOTHING = 1.0
#: Smallest motor lag (s) and friction smoothing speed (rad/s) a wheel takes.
MIN_SCALE = 1e-6


@dataclass(frozen=True, kw_only=True)
class ReactionWheel(KeywordOnly):
    """A reaction wheel on the hub's axis (see the module Notes for its equations).

    Parameters
    ----------
    inertia : float
        Axial inertia of the rotor ``J_w``, kg m^2 (> 0).
    torque_limit : float
        Largest motor torque ``T_max``, N m (> 0).
    speed_limit : float
        Largest wheel speed relative to the hub ``Omega_max``, rad/s (> 0).
    time_constant : float
        Motor torque lag ``tau``, s (> 0).
    viscous_friction : float
        ``b``, N m s (>= 0). Default 0.
    coulomb_friction : float
        ``c``, N m (>= 0, below the torque limit). Default 0.
    friction_smoothing : float
        ``omega_s``, rad/s (> 0): the speed over which the Coulomb friction reaches its level.
        Default :data:`FRICTION_SMOOTHING`.
    """

    inertia: float
    torque_limit: float
    speed_limit: float
    time_constant: float
    viscous_friction: float = 0.0
    coulomb_friction: float = 0.0
    friction_smoothing: float = FRICTION_SMOOTHING

    kind = "reaction_wheel"
    input_name = "torque_command"
    input_unit = "N m"
    state_names = ("wheel_speed", "wheel_torque")
    signal_names = ("wheel_speed", "wheel_torque")

    def __post_init__(self):
        owner = "actuator"
        for name, most in (("inertia", 1e6), ("torque_limit", 1e9), ("speed_limit", 1e5)):
            # beyond any wheel built (1e5 rad/s is a million rpm): the tolerances scale on them
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, strict=True, maximum=most))
        # a lag or a friction knee far below anything the structure does only makes the
        # equations stiff (time constant, s; smoothing speed, rad/s)
        for name in ("time_constant", "friction_smoothing"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=MIN_SCALE, maximum=1e6))
        for name in ("viscous_friction", "coulomb_friction"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, maximum=1e9))
        if self.coulomb_friction >= self.torque_limit:
            raise InputValueError(
                f"actuator.coulomb_friction must be below the torque_limit "
                f"{self.torque_limit:g} N m (the motor could not turn the wheel); got "
                f"{self.coulomb_friction!r}")

    @property
    def command_limit(self) -> float:
        """Largest command magnitude the wheel takes, N m (its torque limit)."""
        return self.torque_limit

    @property
    def momentum_capacity(self) -> float:
        """Angular momentum the wheel stores at its speed limit, N m s."""
        return self.inertia * self.speed_limit

    def mechanical_hub(self, hub):
        """The hub the structure's equations carry: unchanged (the rotor spins by itself).

        Parameters
        ----------
        hub : Hub
            The structure's hub.
        """
        return hub

    def state_scale(self) -> np.ndarray:
        """Physical size of each state (rad/s, N m) for integration tolerances."""
        return np.array([1e-3 * self.speed_limit, 1e-3 * self.torque_limit])

    # ------------------------------------------------------------------ equations
    def _gate(self, speed, motor):
        import casadi as ca

        band = SPEED_LIMIT_BAND * self.speed_limit
        room = ca.fmin(ca.fmax((self.speed_limit - ca.fabs(speed)) / band, 0.0), 1.0)
        # the torque on the rotor is -motor: it speeds the wheel up where -motor * speed > 0
        return ca.if_else(motor * speed < 0.0, room, 1.0)

    def friction(self, speed):
        """Bearing friction on the rotor ``f(Omega)``, N m (CasADi or numpy).

        Parameters
        ----------
        speed : float, ndarray or casadi.SX
            Wheel speed relative to the hub ``Omega``, rad/s.
        """
        tanh = np.tanh if isinstance(speed, (float, np.ndarray)) else __import__("casadi").tanh
        return (self.viscous_friction * speed
                + self.coulomb_friction * tanh(speed / self.friction_smoothing))

    def hub_torque(self, states, rate, u):
        """Torque on the structure ``T_hub`` (CasADi), N m.

        Parameters
        ----------
        states : casadi.SX, shape (2,)
            The wheel's states ``[wheel_speed Omega (rad/s), wheel_torque T_m (N m)]``.
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s (not read).
        u : casadi.SX
            Torque command, N m (not read: it reaches the hub through the motor lag,
            :meth:`derivative`).
        """
        speed, motor = states[0], states[1]
        return self._gate(speed, motor) * motor + self.friction(speed)

    def derivative(self, states, rate, theta_tt, u, hub_torque):
        """``d[Omega, T_m]/dt`` (CasADi) given the hub acceleration and the hub torque.

        Parameters
        ----------
        states : casadi.SX, shape (2,)
            The wheel's states ``[wheel_speed Omega (rad/s), wheel_torque T_m (N m)]``.
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s (not read).
        theta_tt : casadi.SX
            Hub angular acceleration, rad/s^2.
        u : casadi.SX
            Torque command, N m; saturated at the torque limit ``T_max``.
        hub_torque : casadi.SX
            Torque on the structure ``T_hub`` (:meth:`hub_torque`), N m.
        """
        import casadi as ca

        command = ca.fmin(ca.fmax(u, -self.torque_limit), self.torque_limit)
        return ca.vertcat(-hub_torque / self.inertia - theta_tt,
                          (command - states[1]) / self.time_constant)

    def signals(self, states, rate, u):
        """``[wheel_speed, wheel_torque]`` (CasADi): the wheel's speed and the motor torque
        on the hub after the speed limit, rad/s and N m.

        Parameters
        ----------
        states : casadi.SX, shape (2,)
            The wheel's states ``[wheel_speed Omega (rad/s), wheel_torque T_m (N m)]``.
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s (not read).
        u : casadi.SX
            Torque command, N m (not read).
        """
        import casadi as ca

        return ca.vertcat(states[0], self._gate(states[0], states[1]) * states[1])

    def outputs(self, states):
        """Outputs that are states: ``[wheel_speed, wheel_torque]`` (CasADi).

        Parameters
        ----------
        states : casadi.SX, shape (2,)
            The wheel's states ``[wheel_speed Omega (rad/s), wheel_torque T_m (N m)]``.
        """
        import casadi as ca

        return ca.vertcat(states[0], states[1])

    def energy(self, states, rate):
        """Kinetic energy of the rotor's spin, J (CasADi).

        Parameters
        ----------
        states : casadi.SX, shape (2,)
            The wheel's states ``[wheel_speed Omega (rad/s), wheel_torque T_m (N m)]``.
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s: the rotor spins at ``theta_dot + Omega``.
        """
        return 0.5 * self.inertia * (rate + states[0]) ** 2

    def momentum(self, states, rate):
        """Axial angular momentum of the rotor, kg m^2/s (CasADi).

        Parameters
        ----------
        states : casadi.SX, shape (2,)
            The wheel's states ``[wheel_speed Omega (rad/s), wheel_torque T_m (N m)]``.
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s: the rotor spins at ``theta_dot + Omega``.
        """
        return self.inertia * (rate + states[0])

    def torque_bounds(self):
        """Bounds of the torque on the hub the wheel can give, N m: ``(-T_max, T_max)``."""
        return -self.torque_limit, self.torque_limit


@dataclass(frozen=True, kw_only=True)
class DCMotor(KeywordOnly):
    """A geared DC motor whose output shaft is the hub (see the module Notes).

    Parameters
    ----------
    resistance : float
        Armature resistance ``R``, ohm (> 0).
    torque_constant : float
        ``k_t``, N m / A (> 0).
    back_emf_constant : float
        ``k_b``, V s / rad (> 0).
    gear_ratio : float
        ``N``, motor turns per hub turn (> 0; 1 for a direct drive).
    voltage_limit : float
        ``V_max``, V (> 0).
    gear_efficiency : float
        ``eta_g`` in (0, 1]. Default 1.
    motor_efficiency : float
        ``eta_m`` in (0, 1] (a datasheet's motor efficiency, applied to the torque as
        Quanser's SRV02 model does). Default 1.
    rotor_inertia : float
        ``J_m`` at the motor shaft, kg m^2 (>= 0). Default 0.
    viscous_friction : float
        ``b`` at the output shaft, N m s (>= 0). Default 0.
    """

    resistance: float
    torque_constant: float
    back_emf_constant: float
    gear_ratio: float
    voltage_limit: float
    gear_efficiency: float = 1.0
    motor_efficiency: float = 1.0
    rotor_inertia: float = 0.0
    viscous_friction: float = 0.0

    kind = "dc_motor"
    input_name = "voltage"
    input_unit = "V"
    state_names = ()
    signal_names = ("motor_voltage", "motor_current")

    def __post_init__(self):
        owner = "actuator"
        for name in ("resistance", "torque_constant", "back_emf_constant", "gear_ratio",
                     "voltage_limit"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, strict=True, maximum=1e9))
        for name in ("rotor_inertia", "viscous_friction"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, maximum=1e9))
        for name in ("gear_efficiency", "motor_efficiency"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, strict=True, maximum=1.0))
        for name in ("resistance", "torque_constant", "back_emf_constant", "gear_ratio"):
            if not 1e-9 <= getattr(self, name) <= 1e9:
                raise InputValueError(f"actuator.{name} must be within 1e-9 and 1e9; got "
                                      f"{getattr(self, name)!r}")

    @property
    def command_limit(self) -> float:
        """Largest command magnitude, V (the voltage limit)."""
        return self.voltage_limit

    @property
    def reflected_inertia(self) -> float:
        """Rotor inertia seen at the hub, ``N^2 J_m``, kg m^2."""
        return self.gear_ratio ** 2 * self.rotor_inertia

    @property
    def efficiency(self) -> float:
        """``eta = eta_g eta_m``."""
        return self.gear_efficiency * self.motor_efficiency

    @property
    def torque_gain(self) -> float:
        """Hub torque per volt at standstill, ``eta N k_t / R``, N m / V."""
        return self.efficiency * self.gear_ratio * self.torque_constant / self.resistance

    @property
    def damping(self) -> float:
        """Hub torque per hub rate at a fixed voltage (back-EMF and friction),
        ``eta N^2 k_t k_b / R + b``, N m s."""
        return self.torque_gain * self.back_emf_constant * self.gear_ratio \
            + self.viscous_friction

    @property
    def stall_torque(self) -> float:
        """Hub torque at standstill under the voltage limit, N m."""
        return self.torque_gain * self.voltage_limit

    @property
    def no_load_speed(self) -> float:
        """Hub rate at which the voltage limit gives no torque, rad/s."""
        return self.torque_gain * self.voltage_limit / self.damping

    def mechanical_hub(self, hub):
        """The hub with the rotor's reflected inertia added.

        Parameters
        ----------
        hub : Hub
            The structure's hub; its ``inertia`` grows by :attr:`reflected_inertia`.
        """
        return dataclasses.replace(hub, inertia=hub.inertia + self.reflected_inertia)

    def state_scale(self) -> np.ndarray:
        """No states."""
        return np.zeros(0)

    def voltage(self, u):
        """The voltage applied, ``sat(u)`` (CasADi or numpy), V.

        Parameters
        ----------
        u : float, ndarray or casadi.SX
            Voltage command, V; clipped to ``[-V_max, V_max]``.
        """
        if isinstance(u, (float, int, np.ndarray, np.floating)):
            return np.clip(u, -self.voltage_limit, self.voltage_limit)
        import casadi as ca
        return ca.fmin(ca.fmax(u, -self.voltage_limit), self.voltage_limit)

    def current(self, u, rate):
        """Motor current, A.

        Parameters
        ----------
        u : float, ndarray or casadi.SX
            Voltage command, V; saturated at the voltage limit ``V_max`` (:meth:`voltage`).
        rate : float, ndarray or casadi.SX
            Hub rate ``theta_dot``, rad/s (the back-EMF).
        """
        return (self.voltage(u) - self.back_emf_constant * self.gear_ratio * rate) \
            / self.resistance

    def hub_torque(self, states, rate, u):
        """Torque on the hub, N m.

        Parameters
        ----------
        states : casadi.SX, shape (0,)
            The motor's states: none (not read).
        rate : float, ndarray or casadi.SX
            Hub rate ``theta_dot``, rad/s.
        u : float, ndarray or casadi.SX
            Voltage command, V; saturated at the voltage limit ``V_max``.
        """
        return (self.efficiency * self.gear_ratio * self.torque_constant
                * self.current(u, rate) - self.viscous_friction * rate)

    def derivative(self, states, rate, theta_tt, u, hub_torque):
        """No states.

        Parameters
        ----------
        states : casadi.SX, shape (0,)
            The motor's states: none (not read).
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s (not read).
        theta_tt : casadi.SX
            Hub angular acceleration, rad/s^2 (not read).
        u : casadi.SX
            Voltage command, V (not read).
        hub_torque : casadi.SX
            Torque on the hub, N m (not read).
        """
        import casadi as ca
        return ca.DM.zeros(0)

    def signals(self, states, rate, u):
        """``[motor_voltage, motor_current]`` (V, A).

        Parameters
        ----------
        states : casadi.SX, shape (0,)
            The motor's states: none (not read).
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s.
        u : casadi.SX
            Voltage command, V; saturated at the voltage limit ``V_max``.
        """
        import casadi as ca
        return ca.vertcat(self.voltage(u), self.current(u, rate))

    def outputs(self, states):
        """No outputs that are states: an empty CasADi column.

        Parameters
        ----------
        states : casadi.SX, shape (0,)
            The motor's states: none (not read).
        """
        import casadi as ca
        return ca.DM.zeros(0)

    def energy(self, states, rate):
        """The rotor's energy is in the hub's (reflected inertia).

        Parameters
        ----------
        states : casadi.SX, shape (0,)
            The motor's states: none (not read).
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s (not read).
        """
        return 0.0

    def momentum(self, states, rate):
        """The rotor's momentum is in the hub's (reflected inertia).

        Parameters
        ----------
        states : casadi.SX, shape (0,)
            The motor's states: none (not read).
        rate : casadi.SX
            Hub rate ``theta_dot``, rad/s (not read).
        """
        return 0.0

    def voltage_for(self, torque, rate):
        """The voltage that gives the hub ``torque`` at hub ``rate``, V (unsaturated: the
        inverse of :meth:`hub_torque`).

        Parameters
        ----------
        torque : float or ndarray
            Torque on the hub, N m.
        rate : float or ndarray
            Hub rate ``theta_dot``, rad/s; broadcast against ``torque``.
        """
        return ((torque + self.viscous_friction * rate) / self.torque_gain
                + self.back_emf_constant * self.gear_ratio * rate)


ACTUATOR_KINDS = {"reaction_wheel": ReactionWheel, "dc_motor": DCMotor}


def as_actuator(actuator):
    """``actuator`` checked: ``None`` (ideal torque), a :class:`ReactionWheel` or a
    :class:`DCMotor`.

    Parameters
    ----------
    actuator : ReactionWheel, DCMotor or None
        What turns the hub; anything else raises ``InputTypeError``.
    """
    if actuator is None or isinstance(actuator, tuple(ACTUATOR_KINDS.values())):
        return actuator
    raise InputTypeError("actuator must be a ReactionWheel, a DCMotor or None (an ideal "
                         f"torque); got {type(actuator).__name__}")
