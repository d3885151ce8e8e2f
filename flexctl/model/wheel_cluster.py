"""A cluster of reaction wheels on a hub that turns about any axis.

A :class:`WheelCluster` is any number of :class:`Wheel` objects, each a rotor of axial
inertia ``J_k`` spinning at ``Omega_k`` (rad/s) *relative to the hub* about its spin axis
``g_k`` (a unit vector in the hub frame), with a torque distribution law that turns the hub
torque a controller (or a scene's ``torque_samples``) commands into motor torques.
:func:`with_wheels` adds the cluster to a spatial model's equations
(:func:`~flexctl.model.spatial_dynamics.spatial_equations`).

Notes
-----
**Inertia.** The rotors' mass and transverse inertia belong to the hub: ``SpatialHub.inertia``
is that of the body without the rotors' spin inertias ``J_k g_k g_k^T`` (as for the planar
:class:`~flexctl.model.actuators.ReactionWheel`). Basilisk's balanced wheels take the hub's
inertia with them: its ``IHubPntBc_B`` is ``SpatialHub.inertia + sum_k J_k g_k g_k^T``.

**Equations** (``G = [g_1 ... g_n]``, ``h_k = J_k (g_k . w + Omega_k)`` the rotor's axial
angular momentum, ``u_k`` the motor torque on rotor ``k``, ``f_k`` its bearing friction)::

    J_k (g_k . w_t + Omega_k_t) = u_k + f_k                         rotor k
    torque on the structure     = -G (u + f) - w x (G h)            the hub's reaction

so that the structure's equations take the wheels as a hub torque, and the whole craft's
angular momentum (structure plus ``R G h``) is conserved whatever the motors do: they and
the friction are internal. The gyroscopic coupling is the ``w x (G h)`` term.

**The command** ``tau_c`` (3, N m) is the torque asked *on the hub*. The distribution gives
the motor torques ``u_c = -G^+ tau_c`` (``G^+`` the pseudo-inverse: the hub then receives
``tau_c`` where the axes span it, its least-squares part otherwise); ``"null_motion"`` adds
``-k_n P (J o (Omega - Omega_b))`` with ``P = I - G^+ G`` the projector on the null space
(motor torques the hub does not feel), ``k_n`` the :attr:`WheelCluster.null_gain` and
``Omega_b`` the :attr:`WheelCluster.bias_speed` times the first null vector of ``G`` scaled to
a largest entry of 1: the speeds move along the null space towards that bias, away from zero,
without a torque on the hub.

**Each motor** then, in this order (the order of Basilisk's ``ReactionWheelStateEffector``):

1. a dead band: ``|u_c| < dead_band`` gives no torque;
2. saturation at ``+-torque_limit``;
3. an optional first-order lag ``T_t = (u - T) / time_constant`` (a state; ``0``: none);
4. a power limit: ``|u Omega| <= power_limit``;
5. the speed limit: a torque that would drive ``|Omega|`` further up fades from full to none
   over the last :data:`SPEED_LIMIT_BAND` of ``speed_limit`` (Lipschitz, so that
   error-controlled integrators keep their order); the spin-up stops at the rated speed
   (within ``SPEED_LIMIT_BAND * speed_limit`` times the fraction of the torque the friction
   takes there).

**Friction** on the rotor, ``f = -F(Omega)``: ``F = c sign(Omega) + b Omega`` (Coulomb and
viscous), or with static friction ``f_s > c`` and a Stribeck speed ``beta``
``F = sqrt(2 e) (f_s - c) exp(-(Omega / beta)^2 / 2) Omega / (beta sqrt 2) + c tanh(10 Omega
/ beta) + b Omega`` (Basilisk's Stribeck law, here at every speed: it tends to Coulomb and
viscous friction beyond a few ``beta``); below ``friction_smoothing`` (Basilisk's
``omegaLimitCycle``) ``F`` is the straight line from zero to its value there.

**Power drawn**: ``sum_k max(u_k Omega_k, 0)`` W (no regeneration, electrical equal to
mechanical power).

**Imbalance jitter** (optional, Basilisk's ``JitterSimple``): a wheel with a static imbalance
``U_s`` (kg m) or a dynamic one ``U_d`` (kg m^2) has its spin angle ``theta_k`` as a state
(``theta_t = Omega``) and puts on the hub the torque ``r_k x F + U_d Omega^2 w2`` with ``F =
U_s Omega^2 w2``, ``w2 = cos(theta) w2_0 + sin(theta) w3_0`` turning about the spin axis
(``w2_0``, ``w3_0`` perpendicular to it at ``theta = 0``) and ``r_k`` the wheel's
``position``. Like Basilisk's simple model this is a disturbance from outside the
structure's dynamics (the momentum it adds is not taken from anywhere), and on a pinned hub
only: the force ``F`` itself would move a free hub, which this model's hub torque cannot.

Examples
--------
>>> from flexctl.model.wheel_cluster import WheelCluster
>>> cluster = WheelCluster.pyramid(angle=54.7356, inertia=0.01, torque_limit=0.2,
...                                speed_limit=314.16)
>>> cluster.count, cluster.axes.shape
(4, (3, 4))
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .checks import KeywordOnly, check_array, check_choice, check_direction, check_real
from .errors import InputTypeError, InputValueError

__all__ = ["Wheel", "WheelCluster", "with_wheels", "DISTRIBUTIONS", "SPEED_LIMIT_BAND",
           "MAX_WHEELS"]

#: Torque distribution laws.
DISTRIBUTIONS = ("pseudo_inverse", "null_motion")
#: Fraction of the speed limit over which a motor torque that spins a wheel up fades to none.
SPEED_LIMIT_BAND = 1e-4
#: Most wheels in one cluster.
MAX_WHEELS = 16
#: Basilisk's default ``omegaLimitCycle``, rad/s: the friction's straight line near standstill.
FRICTION_SMOOTHING = 1e-4


@dataclass(frozen=True, kw_only=True)
class Wheel(KeywordOnly):
    """One reaction wheel of a :class:`WheelCluster` (equations in the module Notes).

    Parameters
    ----------
    axis : array_like, shape (3,)
        Spin axis in the hub frame (normalised here; non-zero).
    inertia : float
        Rotor inertia about the spin axis ``J``, kg m^2 (> 0).
    torque_limit : float
        Largest motor torque, N m (> 0).
    speed_limit : float
        Rated speed relative to the hub, rad/s (> 0).
    time_constant : float, optional
        Motor lag, s (0: none, the default; else at least 1e-6).
    coulomb_friction : float, optional
        ``c``, N m (>= 0, below the torque limit). Default 0.
    viscous_friction : float, optional
        ``b``, N m s (>= 0). Default 0.
    static_friction : float, optional
        ``f_s``, N m: 0 (default, none) or at least ``coulomb_friction``, with a
        ``stribeck_speed``.
    stribeck_speed : float, optional
        ``beta``, rad/s (> 0 when ``static_friction`` is given). Default 0.
    friction_smoothing : float, optional
        Speed below which the friction is a straight line through zero, rad/s (> 0).
        Default :data:`FRICTION_SMOOTHING`.
    dead_band : float, optional
        Commands below this magnitude give no torque, N m (>= 0, below the torque limit).
        Default 0.
    power_limit : float or None, optional
        Largest mechanical power ``|u Omega|``, W (> 0); None (default): none.
    static_imbalance : float, optional
        ``U_s``, kg m (>= 0). Default 0.
    dynamic_imbalance : float, optional
        ``U_d``, kg m^2 (>= 0). Default 0.
    position : array_like, shape (3,), optional
        The wheel's centre in the hub frame, m (the lever of the static imbalance's force).
        Default the hub's centre.
    """

    axis: np.ndarray
    inertia: float
    torque_limit: float
    speed_limit: float
    time_constant: float = 0.0
    coulomb_friction: float = 0.0
    viscous_friction: float = 0.0
    static_friction: float = 0.0
    stribeck_speed: float = 0.0
    friction_smoothing: float = FRICTION_SMOOTHING
    dead_band: float = 0.0
    power_limit: float | None = None
    static_imbalance: float = 0.0
    dynamic_imbalance: float = 0.0
    position: np.ndarray = (0.0, 0.0, 0.0)

    def __post_init__(self):
        owner = "wheel"
        object.__setattr__(self, "axis", check_direction(owner, "axis", self.axis))
        # beyond any wheel built (1e5 rad/s is a million rpm)
        for name, most in (("inertia", 1e6), ("torque_limit", 1e9), ("speed_limit", 1e5)):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, strict=True, maximum=most))
        lag = check_real(owner, "time_constant", self.time_constant, minimum=0.0, maximum=1e6)
        if 0.0 < lag < 1e-6:
            raise InputValueError(f"wheel.time_constant must be 0 (no lag) or at least 1e-06 s; "
                                  f"got {lag!r}")
        object.__setattr__(self, "time_constant", lag)
        for name in ("coulomb_friction", "viscous_friction", "static_friction",
                     "stribeck_speed", "dead_band"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, maximum=1e9))
        object.__setattr__(self, "friction_smoothing", check_real(
            owner, "friction_smoothing", self.friction_smoothing, minimum=1e-9, maximum=1e3))
        for name in ("coulomb_friction", "static_friction", "dead_band"):
            if getattr(self, name) >= self.torque_limit:
                raise InputValueError(f"wheel.{name} must be below the torque_limit "
                                      f"({self.torque_limit:g} N m); got {getattr(self, name)!r}")
        if self.static_friction > 0:
            if self.static_friction < self.coulomb_friction:
                raise InputValueError(
                    f"wheel.static_friction must be at least the coulomb_friction "
                    f"({self.coulomb_friction:g} N m); got {self.static_friction!r}")
            if not self.stribeck_speed > 0:
                raise InputValueError("wheel.stribeck_speed must be positive when "
                                      "static_friction is given; got "
                                      f"{self.stribeck_speed!r}")
        if self.power_limit is not None:
            object.__setattr__(self, "power_limit", check_real(
                owner, "power_limit", self.power_limit, minimum=0.0, strict=True,
                maximum=1e12))
        for name in ("static_imbalance", "dynamic_imbalance"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, maximum=1e3))
        position = check_array(owner, "position", self.position, shape=(3,))
        if np.max(np.abs(position)) > 1e6:
            raise InputValueError(f"wheel.position must be within 1e6 m of the hub's centre; "
                                  f"got {position.tolist()}")
        object.__setattr__(self, "position", position)

    @property
    def jitters(self) -> bool:
        """Whether the wheel has an imbalance (and its spin angle a state)."""
        return self.static_imbalance > 0 or self.dynamic_imbalance > 0

    def __eq__(self, other):
        return isinstance(other, Wheel) and all(
            np.array_equal(getattr(self, n), getattr(other, n)) if n in ("axis", "position")
            else getattr(self, n) == getattr(other, n) for n in self.__dataclass_fields__)

    def __hash__(self):
        return hash(tuple(getattr(self, n).tobytes() if n in ("axis", "position")
                          else getattr(self, n) for n in self.__dataclass_fields__))

    def friction(self, speed):
        """The friction torque magnitude law ``F(Omega)`` (the rotor feels ``-F``).

        Parameters
        ----------
        speed : float, ndarray or casadi.SX
            Wheel speed relative to the hub, rad/s.

        Returns
        -------
        Same type as ``speed``
            ``F``, N m (odd in ``speed``).
        """
        import casadi as ca

        symbolic = isinstance(speed, (ca.SX, ca.MX))
        where, sign, tanh, exp = ((ca.if_else, ca.sign, ca.tanh, ca.exp) if symbolic else
                                  (np.where, np.sign, np.tanh, np.exp))
        c, b = self.coulomb_friction, self.viscous_friction
        fs, beta = self.static_friction, self.stribeck_speed

        def law(s):
            if fs > 0:
                return (math.sqrt(2 * math.e) * (fs - c) * exp(-(s / beta) ** 2 / 2) * s
                        / (beta * math.sqrt(2)) + c * tanh(10 * s / beta) + b * s)
            return c * sign(s) + b * s

        knee = self.friction_smoothing
        line = float(law(np.float64(knee))) / knee
        return where(abs(speed) < knee, line * speed, law(speed))


@dataclass(frozen=True, kw_only=True)
class WheelCluster(KeywordOnly):
    """Reaction wheels and the law that distributes a commanded hub torque among them.

    Parameters
    ----------
    wheels : tuple of Wheel
        One to :data:`MAX_WHEELS` wheels, numbered from 1 in that order (``wheel1``, ...).
    distribution : {"pseudo_inverse", "null_motion"}, optional
        The distribution law (module Notes). Default ``"pseudo_inverse"``.
    null_gain : float, optional
        ``k_n`` of ``"null_motion"``, 1/s (>= 0). Default 0.1.
    bias_speed : float, optional
        ``"null_motion"``'s bias speed, rad/s (>= 0, below every wheel's speed limit).
        Default 0.
    """

    wheels: tuple
    distribution: str = "pseudo_inverse"
    null_gain: float = 0.1
    bias_speed: float = 0.0

    def __post_init__(self):
        wheels = self.wheels
        if isinstance(wheels, Wheel) or not isinstance(wheels, (tuple, list)):
            raise InputTypeError(f"wheels.wheels must be a tuple of Wheel; got "
                                 f"{type(wheels).__name__}")
        if not 1 <= len(wheels) <= MAX_WHEELS:
            raise InputValueError(f"wheels.wheels must hold 1 to {MAX_WHEELS} wheels; got "
                                  f"{len(wheels)}")
        for k, wheel in enumerate(wheels):
            if not isinstance(wheel, Wheel):
                raise InputTypeError(f"wheels.wheels[{k}] must be a Wheel; got "
                                     f"{type(wheel).__name__}")
        object.__setattr__(self, "wheels", tuple(wheels))
        object.__setattr__(self, "distribution", check_choice(
            "wheels", "distribution", self.distribution, DISTRIBUTIONS))
        object.__setattr__(self, "null_gain", check_real("wheels", "null_gain", self.null_gain,
                                                         minimum=0.0, maximum=1e6))
        bias = check_real("wheels", "bias_speed", self.bias_speed, minimum=0.0, maximum=1e5)
        if bias >= min(w.speed_limit for w in wheels):
            raise InputValueError(f"wheels.bias_speed must be below every wheel's speed_limit; "
                                  f"got {bias!r}")
        object.__setattr__(self, "bias_speed", bias)
        if self.distribution == "null_motion" and self.count <= np.linalg.matrix_rank(
                self.axes, tol=1e-9):
            raise InputValueError(
                f"wheels.distribution 'null_motion' needs more wheels than the dimensions "
                f"their axes span (a null space); these {self.count} span "
                f"{np.linalg.matrix_rank(self.axes, tol=1e-9)}")

    @classmethod
    def orthogonal(cls, **wheel) -> "WheelCluster":
        """Three equal wheels along the hub's ``x``, ``y`` and ``z`` axes.

        Parameters
        ----------
        **wheel
            :class:`Wheel` fields but ``axis``, shared by the three.

        Returns
        -------
        WheelCluster
        """
        _no_axis(wheel)
        return cls(wheels=tuple(Wheel(axis=axis, **wheel) for axis in np.eye(3)))

    @classmethod
    def pyramid(cls, *, angle: float, pyramid_axis=(0.0, 0.0, 1.0), distribution: str =
                "pseudo_inverse", null_gain: float = 0.1, bias_speed: float = 0.0,
                **wheel) -> "WheelCluster":
        """Four equal wheels in a pyramid: each spin axis ``angle`` degrees from
        ``pyramid_axis``, at azimuths 0, 90, 180 and 270 degrees about it.

        The azimuth 0 is the hub's ``x`` axis projected on the pyramid's base (its ``y``
        axis when ``pyramid_axis`` is along ``x``). ``angle = 54.7356`` (``acos(1/sqrt 3)``)
        gives the same torque capacity about every axis.

        Parameters
        ----------
        angle : float
            Angle between each spin axis and the pyramid's axis, degrees, in ``(0, 90]``.
        pyramid_axis : array_like, shape (3,), optional
            The pyramid's axis in the hub frame. Default ``z``.
        distribution : {"pseudo_inverse", "null_motion"}, optional
            As in :class:`WheelCluster`.
        null_gain : float, optional
            As in :class:`WheelCluster`, 1/s.
        bias_speed : float, optional
            As in :class:`WheelCluster`, rad/s.
        **wheel
            :class:`Wheel` fields but ``axis``, shared by the four.

        Returns
        -------
        WheelCluster
        """
        _no_axis(wheel)
        angle = check_real("wheels", "pyramid_angle", angle, minimum=0.0, strict=True,
                           maximum=90.0)
        axis = check_direction("wheels", "pyramid_axis", pyramid_axis)
        first, second = _across(axis)
        a = math.radians(angle)
        axes = [math.cos(a) * axis + math.sin(a) * (math.cos(p) * first + math.sin(p) * second)
                for p in np.radians([0.0, 90.0, 180.0, 270.0])]
        return cls(wheels=tuple(Wheel(axis=g, **wheel) for g in axes),
                   distribution=distribution, null_gain=null_gain, bias_speed=bias_speed)

    @property
    def count(self) -> int:
        """Number of wheels."""
        return len(self.wheels)

    @property
    def axes(self) -> np.ndarray:
        """``G``: the spin axes as columns, shape (3, n)."""
        return np.column_stack([w.axis for w in self.wheels])

    @property
    def inertias(self) -> np.ndarray:
        """Rotor inertias, kg m^2, shape (n,)."""
        return np.array([w.inertia for w in self.wheels])

    @property
    def lagged(self) -> tuple:
        """Indices of the wheels with a motor lag (each adds a state)."""
        return tuple(k for k, w in enumerate(self.wheels) if w.time_constant > 0)

    @property
    def names(self) -> tuple:
        """``("wheel1", ...)``."""
        return tuple(f"wheel{k + 1}" for k in range(self.count))

    @property
    def state_names(self) -> tuple:
        """The cluster's states: ``wheel<k>.speed`` (rad/s, relative to the hub), then
        ``wheel<k>.motor_torque`` (N m) of each lagged wheel, then ``wheel<k>.angle`` (rad)
        of each wheel with an imbalance."""
        return tuple([f"{n}.speed" for n in self.names]
                     + [f"{self.names[k]}.motor_torque" for k in self.lagged]
                     + [f"{self.names[k]}.angle" for k in self.jittering])

    @property
    def jittering(self) -> tuple:
        """Indices of the wheels with an imbalance (each adds its spin angle, rad, as a
        state)."""
        return tuple(k for k, w in enumerate(self.wheels) if w.jitters)

    @property
    def null_target(self) -> np.ndarray:
        """``Omega_b``: the speeds ``"null_motion"`` moves towards, rad/s, shape (n,)."""
        if self.distribution != "null_motion":
            return np.zeros(self.count)
        vector = np.linalg.svd(self.axes)[2][-1]
        return self.bias_speed * vector / np.max(np.abs(vector))

    def motor_commands(self, command, speeds):
        """The motor torques the distribution asks for (before each motor's limits).

        Parameters
        ----------
        command : casadi.SX or ndarray, shape (3,)
            Commanded torque on the hub, hub frame, N m.
        speeds : casadi.SX or ndarray, shape (n,)
            Wheel speeds relative to the hub, rad/s.

        Returns
        -------
        Same type as ``command``, shape (n,)
            Motor torques on the rotors, N m.
        """
        import casadi as ca

        g = self.axes
        pinv = np.linalg.pinv(g)
        symbolic = isinstance(command, (ca.SX, ca.MX))
        times = ca.mtimes if symbolic else np.matmul
        asked = -times(ca.DM(pinv) if symbolic else pinv, command)
        if self.distribution == "null_motion":
            projector = np.eye(self.count) - pinv @ g
            weighted = self.inertias * (speeds - self.null_target) if not symbolic else \
                ca.DM(self.inertias) * (speeds - ca.DM(self.null_target))
            asked = asked - self.null_gain * times(
                ca.DM(projector) if symbolic else projector, weighted)
        return asked


def _across(axis) -> tuple:
    """Two unit vectors across a unit ``axis``, ``(first, axis x first)``: ``first`` the hub's
    ``x`` projected on the plane across it (its ``y`` when ``axis`` is near ``x``)."""
    reference = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    first = reference - (reference @ axis) * axis
    first /= np.linalg.norm(first)
    return first, np.cross(axis, first)


def _no_axis(wheel: dict):
    if "axis" in wheel:
        raise InputTypeError("wheel.axis is set by the arrangement; give the other fields of "
                             "the wheels it places")


def _delivered(wheel: Wheel, asked, speed, lag_state):
    """``(torque, lag rate or None)``: the motor torque on the rotor after the dead band,
    saturation, lag, power and speed limits (CasADi)."""
    import casadi as ca

    u = ca.if_else(ca.fabs(asked) < wheel.dead_band, 0, asked) if wheel.dead_band > 0 \
        else asked
    u = ca.fmin(ca.fmax(u, -wheel.torque_limit), wheel.torque_limit)
    rate = None
    if wheel.time_constant > 0:
        rate = (u - lag_state) / wheel.time_constant
        u = lag_state
    if wheel.power_limit is not None:
        most = wheel.power_limit / ca.fmax(ca.fabs(speed), 1e-300)
        u = ca.fmin(ca.fmax(u, -most), most)
    room = ca.fmin(ca.fmax((wheel.speed_limit - ca.fabs(speed))
                           / (SPEED_LIMIT_BAND * wheel.speed_limit), 0), 1)
    return ca.if_else(u * speed > 0, room * u, u), rate


def _jitter(cluster: WheelCluster, speeds, angles):
    """The imbalances' torque on the hub (module Notes), CasADi, shape (3,)."""
    import casadi as ca

    torque = ca.SX.zeros(3, 1)
    for j, k in enumerate(cluster.jittering):
        wheel = cluster.wheels[k]
        first, second = _across(wheel.axis)
        w2 = ca.cos(angles[j]) * ca.DM(first) + ca.sin(angles[j]) * ca.DM(second)
        square = speeds[k] ** 2
        torque += ca.cross(ca.DM(wheel.position), wheel.static_imbalance * square * w2) \
            + wheel.dynamic_imbalance * square * w2
    return torque


def with_wheels(equations, cluster: WheelCluster):
    """A spatial model's equations with a wheel cluster on its hub.

    The state is the structure's followed by the cluster's (:attr:`WheelCluster.state_names`);
    the torque input becomes the hub torque commanded of the cluster; the energy counts the
    rotors' kinetic energy and the angular momentum their spin.

    Parameters
    ----------
    equations : SpatialEquations
        The structure's (:func:`~flexctl.model.spatial_dynamics.spatial_equations`).
    cluster : WheelCluster
        The wheels.

    Returns
    -------
    SpatialEquations
        With ``cluster`` set and ``wheel_outputs``: ``(x, command) -> (motor torques (n) on
        the rotors, N m; power drawn, W)``.
    """
    import casadi as ca

    from .checks import check_instance
    from .spatial_dynamics import quaternion_rotation

    check_instance("with_wheels", "cluster", cluster, WheelCluster)
    if equations.cluster is not None:
        raise InputValueError("with_wheels: these equations already carry a wheel cluster")
    inner = equations.layout
    layout = dataclasses.replace(inner, wheels=cluster.state_names)
    n0, n = inner.n_states, cluster.count
    x = ca.SX.sym("x", layout.n_states)
    command = ca.SX.sym("torque", 3)
    if cluster.jittering and inner.free:
        raise InputValueError("wheel imbalance jitter is for a pinned hub: its force would "
                              "move a free hub, which the jitter model does not carry")
    structure, speeds = x[:n0], x[n0:n0 + n]
    n_lag = len(cluster.lagged)
    lag_states = x[n0 + n:n0 + n + n_lag]
    angles = x[n0 + n + n_lag:]
    c = inner.n_coordinates
    w = structure[c:c + 3]
    g = ca.DM(cluster.axes)
    inertia = ca.DM(cluster.inertias)
    asked = cluster.motor_commands(command, speeds)
    torques, lag_rates, lag_index = [], [], {k: i for i, k in enumerate(cluster.lagged)}
    for k, wheel in enumerate(cluster.wheels):
        state = lag_states[lag_index[k]] if k in lag_index else None
        u, rate = _delivered(wheel, asked[k], speeds[k], state)
        torques.append(u)
        if rate is not None:
            lag_rates.append(rate)
    motor = ca.vertcat(*torques)
    friction = -ca.vertcat(*[wheel.friction(speeds[k])
                             for k, wheel in enumerate(cluster.wheels)])
    spin = inertia * (ca.mtimes(g.T, w) + speeds)          # h_k, N m s
    hub_torque = -ca.mtimes(g, motor + friction) - ca.cross(w, ca.mtimes(g, spin)) \
        + _jitter(cluster, speeds, angles)
    rate = equations.rhs(structure, hub_torque)
    w_t = rate[c:c + 3]
    speeds_t = (motor + friction) / inertia - ca.mtimes(g.T, w_t)
    full_rate = ca.vertcat(rate, speeds_t, *lag_rates,
                           *[speeds[k] for k in cluster.jittering])
    kinetic, elastic = equations.energy(structure)
    angular, linear = equations.momentum(structure)
    quaternion = structure[0:4]
    power = ca.sum1(ca.fmax(motor * speeds, 0))
    return dataclasses.replace(
        equations, layout=layout, cluster=cluster,
        rhs=ca.Function("spatial_wheels_rhs", [x, command], [full_rate], ["x", "torque"],
                        ["x_dot"], {"cse": True}),
        tips=ca.Function("spatial_tips", [x], [equations.tips(structure)], ["x"], ["tips"]),
        energy=ca.Function("spatial_energy", [x],
                           [kinetic + 0.5 * ca.sum1(spin * spin / inertia), elastic],
                           ["x"], ["kinetic", "elastic"]),
        momentum=ca.Function("spatial_momentum", [x], [
            angular + ca.mtimes(quaternion_rotation(quaternion), ca.mtimes(g, spin)), linear],
            ["x"], ["angular", "linear"]),
        mass_matrix=ca.Function("spatial_mass", [x], [equations.mass_matrix(structure)],
                                ["x"], ["M"]),
        wheel_outputs=ca.Function("spatial_wheel_outputs", [x, command], [motor, power],
                                  ["x", "torque"], ["motor_torque", "power"]))
