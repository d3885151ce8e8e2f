"""A spatial scene's attitude loop: its ``[controller]`` and ``[sensors]`` tables.

- ``[controller]``: ``sample_time`` (s), the target as ``slew_axis`` (hub frame) and
  ``slew_angle`` (degrees) from the initial attitude or as ``target`` (a quaternion, hub to
  inertial, scalar first), optional ``torque_limit`` (N m per axis), and by ``kind``:

  - ``"quaternion_feedback"``
    (:class:`controllers.feedback.quaternion.QuaternionFeedback`): ``bandwidth`` (rad/s; the
    gains from the structure's rigid inertia), optional ``damping`` (0.7) and
    ``integral_time`` (s);
  - ``"lqr"`` (:func:`controllers.feedback.spatial_lqr.design_spatial_lqr`, held over the
    sample time; it feeds back the plant's whole state, so it takes no ``[sensors]``):
    the Bryson weights ``hub_angle`` (rad), ``torque`` (N m) and optional ``hub_rate``
    (rad/s) and ``tip_deflection`` (m), optional ``design_modes`` (per field, default 2) and
    ``max_frequency`` (rad/s); with ``slew_duration`` (s, and ``slew_shape``, ``"poly7"`` or
    ``"cycloidal"``) it follows an eigenaxis slew of that length
    (:class:`controllers.slew.eigenaxis.EigenaxisSlew`) instead of a step to the target,
    shaped against the modes a torque about the axis moves with ``shaper`` (``"zv"`` or
    ``"zvd"``) and ``shaped_modes`` (how many, from the lowest, default 1; from the model of
    ``design_modes``: :func:`controllers.slew.eigenaxis.eigenaxis_shaper`); ``slew_shape =
    "optimal"`` plans the least-effort slew on the design modes within the wheels' (or
    ``torque_limit``'s) limits instead, in ``slew_intervals`` holds (default: one per
    sample of the loop), its torque's jumps weighted by ``slew_smoothness`` (s^2, default 0;
    :func:`controllers.slew.spatial_trajopt.solve_spatial_slew`), and the law follows its
    whole state;
  - ``"lqg"`` (:func:`controllers.feedback.spatial_lqr.design_spatial_lqg`): those and the
    filter's ``angle_noise`` (rad), ``rate_noise`` (rad/s) and ``process_torque`` (N m); it
    reads the attitude and rate (the attitude filter's, with ``[sensors]``).

  - ``"nmpc"`` (:func:`controllers.mpc.spatial_nmpc.design_spatial_nmpc`, on the plant's
    whole state like the LQR): the LQR's weights, ``design_modes`` (default 1),
    ``horizon`` (default 20), ``qp_solver`` (``"qpoases"``, ``"qrqp"`` or ``"osqp"``); the
    wheels' torque and speed limits (or ``torque_limit``) are its constraints; with
    ``slew_duration`` it follows ``slew_shape = "optimal"``.
  - ``"scheduled_lqr"``
    (:func:`controllers.feedback.spatial_scheduling.design_scheduled_spatial_lqr`, on the
    plant's whole state): a spin about ``spin_axis`` (hub frame, a principal axis across or
    along every appendage) from the scene's initial attitude, to ``spin_rate`` (rad/s) over
    ``ramp_time`` (s; a :class:`~flexctl.sim.maneuvers.SpinUp`) or, without ``ramp_time``, a
    steady spin at ``spin_rate`` (start the scene spinning: ``initial.angular_velocity``);
    one LQR per design spin of ``spin_rates`` (rad/s, increasing, 1 to 50) on the scene's
    model variant, scheduled on the measured spin; the LQR's weights, ``design_modes``
    (default 2), ``max_frequency``; no target (``slew_axis``, ``slew_angle`` and ``target``
    are refused).

  The scene's manoeuvre is then ``none``: the law commands the hub torque (of the wheels,
  with an ``[actuator]``).
- ``[sensors]`` (optional, with a controller): ``[sensors.star_tracker]`` and
  ``[sensors.gyro]`` (the fields of :class:`~flexctl.sim.attitude_sensors.StarTracker` and
  :class:`~flexctl.sim.attitude_sensors.Gyro`), ``seed``, and the attitude filter's initial
  uncertainty ``attitude_sigma`` (rad, default 1e-3) and ``bias_sigma`` (rad/s, default
  1e-4). The gyro reads at the controller's sample time; the law reads the filter
  (:class:`controllers.feedback.mekf.AttitudeFilter`), which starts at the scene's initial
  attitude; ``filter = "modes"`` takes the one with the arrays' modes in it
  (:class:`controllers.feedback.flexible_mekf.FlexibleAttitudeFilter`, 1 mode per field,
  first_order; through wheels it reads their speeds); both export as C.

The loop's outputs are at its samples (``simulation.output_step`` does not apply).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from controllers.spec import SceneError
from ..model.checks import check_array, check_direction, check_real
from ..sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker
from ..sim.quaternions import from_rotation_vector, product
from .scene_tables import check_table_keys, construct

__all__ = ["SpatialLoop", "spatial_loop", "pointing_target"]

_COMMON_KEYS = {"kind", "sample_time", "slew_axis", "slew_angle", "target", "torque_limit"}
_CONTROLLER_KEYS = {
    "quaternion_feedback": _COMMON_KEYS | {"bandwidth", "damping", "integral_time"},
    "lqr": _COMMON_KEYS | {"hub_angle", "hub_rate", "tip_deflection", "torque", "design_modes",
                           "max_frequency", "slew_duration", "slew_shape", "shaper",
                           "shaped_modes", "slew_intervals", "slew_smoothness"},
}
_CONTROLLER_KEYS["lqg"] = _CONTROLLER_KEYS["lqr"] | {"angle_noise", "rate_noise",
                                                     "process_torque"}
_CONTROLLER_KEYS["nmpc"] = (_CONTROLLER_KEYS["lqr"] - {"max_frequency", "shaper", "shaped_modes"}) \
    | {"horizon", "qp_solver"}
_CONTROLLER_KEYS["scheduled_lqr"] = {"kind", "sample_time", "torque_limit", "hub_angle",
                                     "hub_rate", "tip_deflection", "torque", "design_modes",
                                     "max_frequency", "spin_axis", "spin_rates", "spin_rate",
                                     "ramp_time"}
#: The kinds that feed back the plant's whole state (no ``[sensors]``).
_FULL_STATE = ("lqr", "nmpc", "scheduled_lqr")
_REQUIRED = {"quaternion_feedback": ("sample_time", "bandwidth"),
             "lqr": ("sample_time", "hub_angle", "torque"),
             "lqg": ("sample_time", "hub_angle", "torque"),
             "nmpc": ("sample_time", "hub_angle", "torque"),
             "scheduled_lqr": ("sample_time", "hub_angle", "torque", "spin_axis",
                               "spin_rates", "spin_rate")}
_SENSOR_KEYS = {"star_tracker", "gyro", "seed", "attitude_sigma", "bias_sigma", "filter"}
#: ``[sensors] filter``: the attitude filter, or the one with the arrays' modes in it.
FILTERS = ("attitude", "modes")


@dataclass(frozen=True)
class SpatialLoop:
    """A spatial scene's law, sample time and sensors.

    Attributes
    ----------
    law : QuaternionFeedback, SpatialLQR, SpatialLQG, SpatialNMPC or ScheduledSpatialLQR
    sample_time : float
        s.
    sensors : AttitudeSensors or None
    attitude_sigma, bias_sigma : float
        The filter's initial uncertainty (rad, rad/s).
    modes : SpatialStructure or None
        With ``[sensors] filter = "modes"``: the structure whose modes the filter carries
        (:class:`~controllers.feedback.flexible_mekf.FlexibleAttitudeFilter`, 1 mode per field,
        first_order); None: the attitude filter.
    """

    law: object
    sample_time: float
    sensors: AttitudeSensors | None
    attitude_sigma: float = 1e-3
    bias_sigma: float = 1e-4
    modes: object = None

    def estimator(self, attitude):
        """The attitude filter of a run from ``attitude`` (None without sensors).

        Parameters
        ----------
        attitude : array_like, shape (4,)
            The filter's initial attitude.
        """
        if self.sensors is None:
            return None
        if self.modes is not None:
            from controllers.feedback.flexible_mekf import FlexibleAttitudeFilter

            return FlexibleAttitudeFilter(self.sensors, self.modes, attitude,
                                          self.attitude_sigma, bias_sigma=self.bias_sigma)
        from controllers.feedback.mekf import AttitudeFilter

        return AttitudeFilter(self.sensors, attitude=attitude,
                              attitude_sigma=self.attitude_sigma, bias_sigma=self.bias_sigma)


def _checked(check, *args, **limits):
    """``check(*args, **limits)``, its error a :class:`SceneError`."""
    try:
        return check(*args, **limits)
    except (ValueError, TypeError) as exc:
        raise SceneError(str(exc)) from None


def spatial_loop(controller: dict, sensors: dict, structure, quaternion, wheels=None,
                 wheel_speeds=None, angular_velocity=None,
                 variant: str = "exact") -> SpatialLoop | None:
    """The loop of a spatial scene's ``[controller]`` and ``[sensors]`` tables.

    Parameters
    ----------
    controller : dict
        The ``[controller]`` table (empty: no loop).
    sensors : dict
        The ``[sensors]`` table (empty: the law reads the truth).
    structure : SpatialStructure
        The structure (its rigid inertia sets the gains).
    quaternion : ndarray, shape (4,)
        The initial attitude (the slew's start).
    wheels : WheelCluster, optional
        The scene's wheels (their limits bound an optimal slew).
    wheel_speeds : ndarray, optional
        Their initial speeds, rad/s.
    angular_velocity : ndarray, shape (3,), optional
        The initial angular velocity, rad/s, hub frame (with the wheels' speeds, the
        momentum an eigenaxis slew's feedforward turns). Default at rest.
    variant : str, optional
        The scene's model variant (a scheduled LQR's designs linearise it). Default
        ``"exact"``.

    Returns
    -------
    SpatialLoop or None
    """
    if not controller:
        if sensors:
            raise SceneError("[sensors] of a spatial scene are read by a [controller]; this "
                             "scene has none")
        return None
    kind = controller.get("kind")
    if not isinstance(kind, str) or kind not in _CONTROLLER_KEYS:
        raise SceneError(f"controller.kind must be one of {sorted(_CONTROLLER_KEYS)} for a "
                         f"spatial scene; got {kind!r:.80}")
    check_table_keys("controller", controller, _CONTROLLER_KEYS[kind])
    for key in _REQUIRED[kind]:
        if key not in controller:
            raise SceneError(f"controller.{key} is required for controller.kind = {kind!r}")
    if kind in _FULL_STATE and sensors:
        raise SceneError(f"controller.kind = {kind!r} feeds back the plant's whole state, which "
                         "[sensors] do not give; with sensors take kind = 'lqg' (its filter "
                         "estimates the modes from the attitude and rate)")
    step = _checked(check_real, "controller", "sample_time", controller["sample_time"],
                    minimum=1e-4, maximum=100.0)
    try:
        if kind == "scheduled_lqr":
            law = _scheduled(controller, structure, quaternion, step, variant)
        else:
            law = _design(kind, controller, structure, _target(controller, quaternion), step,
                          (wheels, wheel_speeds, _momentum(structure, quaternion, wheels,
                                                           wheel_speeds, angular_velocity)))
    except SceneError:
        raise
    except (ValueError, TypeError) as exc:
        raise SceneError(_scene_message(str(exc))) from None
    if not sensors:
        return SpatialLoop(law=law, sample_time=step, sensors=None)
    check_table_keys("sensors", sensors, _SENSOR_KEYS)
    parts = {}
    for key, cls in (("star_tracker", StarTracker), ("gyro", Gyro)):
        table = sensors.get(key)
        if not isinstance(table, dict):
            raise SceneError(f"sensors.{key} must be a table of the {cls.__name__}'s fields")
        check_table_keys(f"sensors.{key}", table, {f.name for f in fields(cls)})
        parts[key] = construct(cls, key, table, rename=f"sensors.{key}")
    try:
        setup = construct(AttitudeSensors, "sensors", {**parts, "gyro_sample_time": step,
                                                       "seed": sensors.get("seed", 0)})
    except SceneError as exc:       # the gyro samples at the law's step: the scene's key
        raise SceneError(str(exc).replace("sensors.gyro_sample_time (", "the gyro's sample "
                                          "time, controller.sample_time (")) from None
    sigmas = {key: _checked(check_real, "sensors", key, sensors.get(key, default),
                            minimum=0.0, strict=True, maximum=1.0)
              for key, default in (("attitude_sigma", 1e-3), ("bias_sigma", 1e-4))}
    choice = sensors.get("filter", "attitude")
    if not isinstance(choice, str) or choice not in FILTERS:
        raise SceneError(f"sensors.filter must be one of {', '.join(FILTERS)}; got "
                         f"{choice!r:.80}")
    loop = SpatialLoop(law=law, sample_time=step, sensors=setup, **sigmas,
                       modes=structure if choice == "modes" else None)
    _checked(loop.estimator, quaternion)
    return loop


def _scene_message(message: str) -> str:
    """A design's error message with its parameters named as the ``[controller]`` keys."""
    for owner, name in (("slew.duration", "slew_duration"), ("slew.shape", "slew_shape"),
                        ("eigenaxis_shaper.kind", "shaper"),
                        ("eigenaxis_shaper.n_shaped", "shaped_modes"),
                        ("design_spatial_lqr.n_modes", "design_modes"),
                        ("spatial_slew.duration", "slew_duration"),
                        ("spatial_slew.n_intervals", "slew_intervals"),
                        ("spatial_slew.smoothness", "slew_smoothness"),
                        ("design_spatial_nmpc.n_modes", "design_modes"),
                        ("design_scheduled_spatial_lqr.n_modes", "design_modes"),
                        ("maneuver.spin_rate", "spin_rate"),
                        ("maneuver.ramp_time", "ramp_time"),
                        ("steady_spin.spin_rate", "spin_rate"),
                        ("design_scheduled_spatial_lqr: the design spin",
                         "spin_axis, spin_rates: the design spin")):
        message = message.replace(owner, f"controller.{name}")
    for owner in ("quaternion_feedback.", "design_spatial_lqr.", "design_spatial_lqg.",
                  "lqr_weights.", "eigenaxis_slew.", "spatial_slew.", "design_spatial_nmpc.",
                  "design_scheduled_spatial_lqr."):
        message = message.replace(owner, "controller.")
    return message


def _weights(controller: dict):
    """The Bryson weights of a ``[controller]`` table (an LQR's, LQG's, NMPC's or scheduled
    LQR's)."""
    from controllers.feedback.lqr import LQRWeights

    return LQRWeights(**{key: controller[key] for key in
                         ("hub_angle", "hub_rate", "tip_deflection", "torque")
                         if key in controller})


def _scheduled(controller: dict, structure, quaternion, step: float, variant: str):
    """The scheduled LQR of a ``[controller]`` table: a spin-up (or a steady spin) about
    its axis from the initial attitude."""
    from controllers.feedback.spatial_scheduling import design_scheduled_spatial_lqr
    from ..sim.maneuvers import SpinUp

    weights = _weights(controller)
    rate = _checked(check_real, "controller", "spin_rate", controller["spin_rate"],
                    minimum=-1e4, maximum=1e4)
    profile = (SpinUp(spin_rate=rate, ramp_time=controller["ramp_time"])
               if "ramp_time" in controller else rate)
    rates = controller["spin_rates"]
    if not isinstance(rates, (list, tuple)):
        raise SceneError(f"controller.spin_rates must be a list of design spin rates (rad/s); "
                         f"got {rates!r:.80}")
    return design_scheduled_spatial_lqr(
        structure, weights, controller["spin_axis"], rates, profile, start=quaternion,
        n_modes=controller.get("design_modes", 2), variant=variant, sample_time=step,
        torque_limit=controller.get("torque_limit"),
        max_frequency=controller.get("max_frequency"))


def pointing_target(law, t: float) -> np.ndarray:
    """The attitude a spatial scene's law points at, at time ``t``: its target, or a
    scheduled LQR's spin reference then.

    Parameters
    ----------
    law : object
        The scene's law.
    t : float
        Time, s.

    Returns
    -------
    ndarray, shape (4,)
        Hub to inertial, scalar first.
    """
    if hasattr(law, "reference_at"):
        return law.reference_at(t)[0]
    return law.target


def _momentum(structure, quaternion, cluster, speeds, angular_velocity):
    """The rigid structure and its wheels' angular momentum at the start, inertial frame,
    N m s (what an eigenaxis slew through the wheels turns); None without wheels."""
    if cluster is None:
        return None
    from flexctl.sim.quaternions import rotation_matrix

    spin = np.zeros(3) if angular_velocity is None else np.asarray(angular_velocity, float)
    speeds = np.zeros(cluster.count) if speeds is None else np.asarray(speeds, float)
    g = cluster.axes
    body = structure.rigid_inertia @ spin + g @ (cluster.inertias * (g.T @ spin + speeds))
    return rotation_matrix(quaternion) @ body


def _design(kind: str, controller: dict, structure, target, step: float, wheels: tuple):
    """The law of a ``[controller]`` table of ``kind`` (``wheels``: the cluster, its initial
    speeds and the momentum at the start, or Nones)."""
    if kind == "quaternion_feedback":
        from controllers.feedback.quaternion import QuaternionFeedback

        return QuaternionFeedback.design(
            structure.rigid_inertia, controller["bandwidth"], target,
            damping=controller.get("damping", 0.7),
            integral_time=controller.get("integral_time"),
            torque_limit=controller.get("torque_limit"))
    from controllers.feedback.spatial_lqr import design_spatial_lqg, design_spatial_lqr

    weights = _weights(controller)
    n_modes = controller.get("design_modes", 1 if kind == "nmpc" else 2)
    common = {"n_modes": n_modes,
              "torque_limit": controller.get("torque_limit"),
              "max_frequency": controller.get("max_frequency"),
              "reference": _eigenaxis(controller, structure, target, wheels, n_modes)}
    if kind == "nmpc":
        return _nmpc(controller, structure, target, step, weights, wheels, common["reference"])
    if kind == "lqr":
        return design_spatial_lqr(structure, weights, target, sample_time=step, **common)
    noise = {key: controller[key] for key in ("angle_noise", "rate_noise", "process_torque")
             if key in controller}
    return design_spatial_lqg(structure, weights, target, step, **noise, **common)


def _nmpc(controller: dict, structure, target, step: float, weights, wheels: tuple, reference):
    """The three-axis NMPC of a ``[controller]`` table (a planned slew as its reference)."""
    from controllers.mpc.spatial_nmpc import design_spatial_nmpc

    if reference is not None and not hasattr(reference, "state_at"):
        raise SceneError("controller.kind = 'nmpc' follows slew_shape = 'optimal' (a slew "
                         "planned on its modes) or steps to the target; got slew_shape = "
                         f"{controller.get('slew_shape', 'poly7')!r}")
    cluster = wheels[0]
    return design_spatial_nmpc(
        structure, weights, None if reference is not None else target, step,
        horizon=controller.get("horizon", 20), n_modes=controller.get("design_modes", 1),
        wheels=cluster, torque_limit=controller.get("torque_limit") if cluster is None
        else None, reference=reference, qp_solver=controller.get("qp_solver", "qpoases"))


def _eigenaxis(controller: dict, structure, target, wheels: tuple, n_modes):
    """The slew of ``slew_duration`` (and ``slew_shape``, shaped or optimal), or None for a
    step."""
    if "slew_duration" not in controller:
        for key in ("slew_shape", "shaper", "shaped_modes", "slew_intervals",
                    "slew_smoothness"):
            if key in controller:
                raise SceneError(f"controller.{key} needs controller.slew_duration (s)")
        return None
    if "shaped_modes" in controller and "shaper" not in controller:
        raise SceneError("controller.shaped_modes needs controller.shaper ('zv' or 'zvd')")
    if "slew_axis" not in controller:
        raise SceneError("controller.slew_duration needs the slew as slew_axis and slew_angle "
                         "(an eigenaxis slew), not a target quaternion")
    angle = np.radians(float(controller["slew_angle"]))
    start = product(target, from_rotation_vector(-angle * check_direction(
        "controller", "slew_axis", controller["slew_axis"])))
    from controllers.slew.reference import SHAPES

    shape = controller.get("slew_shape", "poly7")
    if not isinstance(shape, str) or shape not in (*SHAPES, "optimal"):
        raise SceneError(f"controller.slew_shape must be one of {', '.join(SHAPES)}, optimal; "
                         f"got {shape!r:.80}")
    if shape == "optimal":
        return _optimal(controller, structure, start, target, wheels, n_modes)
    for key in ("slew_intervals", "slew_smoothness"):
        if key in controller:
            raise SceneError(f"controller.{key} is for slew_shape = 'optimal'")
    from controllers.slew.eigenaxis import EigenaxisSlew
    from controllers.slew.reference import SlewProfile

    profile = SlewProfile(slew_angle=angle, duration=controller["slew_duration"], shape=shape)
    if "shaper" in controller:
        from controllers.slew.eigenaxis import eigenaxis_shaper
        from controllers.slew.shaping import shape

        profile = shape(profile, eigenaxis_shaper(
            structure, controller["slew_axis"], controller["shaper"],
            controller.get("shaped_modes", 1), n_modes))
    return EigenaxisSlew(axis=controller["slew_axis"], profile=profile,
                         inertia=structure.rigid_inertia, start=start, momentum=wheels[2])


def _optimal(controller: dict, structure, start, target, wheels: tuple, n_modes):
    """The least-effort slew planned on the design modes within the wheels' limits."""
    from controllers.slew.spatial_trajopt import SpatialSlewProblem, solve_spatial_slew

    if "shaper" in controller:
        raise SceneError("controller.shaper shapes a slew_shape of 'poly7' or 'cycloidal'; an "
                         "optimal slew is planned on the modes themselves")
    cluster, speeds = wheels[:2]
    limit = controller.get("torque_limit") if cluster is None else None
    duration = _checked(check_real, "controller", "slew_duration", controller["slew_duration"],
                        minimum=0.0, strict=True, maximum=1e5)
    step = float(controller["sample_time"])
    holds = controller.get("slew_intervals")
    if holds is None:                       # the plan's holds are the loop's samples
        holds = int(round(duration / step))
        if abs(holds * step - duration) > 1e-9 * duration or holds < 2:
            raise SceneError(
                f"controller.slew_duration must be a multiple of controller.sample_time "
                f"({step:g} s), at least two, for slew_shape = 'optimal' (its holds are the "
                f"loop's samples), or give controller.slew_intervals; got {duration!r}")
    problem = SpatialSlewProblem(start=start, target=target, duration=duration,
                                 n_intervals=holds,
                                 smoothness=controller.get("slew_smoothness", 0.0),
                                 torque_limit=limit, wheels=cluster,
                                 wheel_speeds=None if cluster is None else speeds)
    return solve_spatial_slew(structure, problem, n_modes=n_modes, variant="first_order")


def _target(controller: dict, quaternion) -> np.ndarray:
    """The law's target attitude from the ``[controller]`` table."""
    slew = ("slew_axis" in controller, "slew_angle" in controller)
    if "target" in controller:
        if any(slew):
            raise SceneError("controller.target and controller.slew_axis/slew_angle exclude "
                             "each other")
        target = _checked(check_array, "controller", "target", controller["target"],
                          shape=(4,))
        if not np.max(np.abs(target)) > 0:
            raise SceneError("controller.target must be a non-zero quaternion")
        return target / np.max(np.abs(target))
    if not all(slew):
        raise SceneError("controller needs a target: slew_axis (hub frame) and slew_angle "
                         "(degrees), or target (a quaternion)")
    axis = _checked(check_direction, "controller", "slew_axis", controller["slew_axis"])
    angle = _checked(check_real, "controller", "slew_angle", controller["slew_angle"],
                     minimum=-360.0, maximum=360.0)
    return product(quaternion, from_rotation_vector(np.radians(angle) * axis))
