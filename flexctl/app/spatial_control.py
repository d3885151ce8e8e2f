"""A spatial scene's attitude loop: its ``[controller]`` and ``[sensors]`` tables.

- ``[controller]``: ``kind = "quaternion_feedback"``
  (:class:`controllers.feedback.quaternion.QuaternionFeedback`), ``sample_time`` (s), the
  target as ``slew_axis`` (hub frame) and ``slew_angle`` (degrees) from the initial attitude
  or as ``target`` (a quaternion, hub to inertial, scalar first), ``bandwidth`` (rad/s; the
  gains from the structure's rigid inertia), and optional ``damping`` (0.7),
  ``integral_time`` (s) and ``torque_limit`` (N m per axis). The scene's manoeuvre is then
  ``none``: the law commands the hub torque (of the wheels, with an ``[actuator]``).
- ``[sensors]`` (optional, with a controller): ``[sensors.star_tracker]`` and
  ``[sensors.gyro]`` (the fields of :class:`~flexctl.sim.attitude_sensors.StarTracker` and
  :class:`~flexctl.sim.attitude_sensors.Gyro`), ``seed``, and the attitude filter's initial
  uncertainty ``attitude_sigma`` (rad, default 1e-3) and ``bias_sigma`` (rad/s, default
  1e-4). The gyro reads at the controller's sample time; the law reads the filter
  (:class:`controllers.feedback.mekf.AttitudeFilter`), which starts at the scene's initial
  attitude.

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

__all__ = ["SpatialLoop", "spatial_loop"]

_CONTROLLER_KEYS = {"kind", "sample_time", "slew_axis", "slew_angle", "target", "bandwidth",
                    "damping", "integral_time", "torque_limit"}
_SENSOR_KEYS = {"star_tracker", "gyro", "seed", "attitude_sigma", "bias_sigma"}


@dataclass(frozen=True)
class SpatialLoop:
    """A spatial scene's law, sample time and sensors.

    Attributes
    ----------
    law : QuaternionFeedback
    sample_time : float
        s.
    sensors : AttitudeSensors or None
    attitude_sigma, bias_sigma : float
        The filter's initial uncertainty (rad, rad/s).
    """

    law: object
    sample_time: float
    sensors: AttitudeSensors | None
    attitude_sigma: float = 1e-3
    bias_sigma: float = 1e-4

    def estimator(self, attitude):
        """The attitude filter of a run from ``attitude`` (None without sensors).

        Parameters
        ----------
        attitude : array_like, shape (4,)
            The filter's initial attitude.
        """
        if self.sensors is None:
            return None
        from controllers.feedback.mekf import AttitudeFilter

        return AttitudeFilter(self.sensors, attitude=attitude,
                              attitude_sigma=self.attitude_sigma, bias_sigma=self.bias_sigma)


def _checked(check, *args, **limits):
    """``check(*args, **limits)``, its error a :class:`SceneError`."""
    try:
        return check(*args, **limits)
    except (ValueError, TypeError) as exc:
        raise SceneError(str(exc)) from None


def spatial_loop(controller: dict, sensors: dict, structure, quaternion) -> SpatialLoop | None:
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

    Returns
    -------
    SpatialLoop or None
    """
    from controllers.feedback.quaternion import QuaternionFeedback

    if not controller:
        if sensors:
            raise SceneError("[sensors] of a spatial scene are read by a [controller]; this "
                             "scene has none")
        return None
    check_table_keys("controller", controller, _CONTROLLER_KEYS)
    if controller.get("kind") != "quaternion_feedback":
        raise SceneError(f"controller.kind must be 'quaternion_feedback' for a spatial scene; "
                         f"got {controller.get('kind')!r:.80}")
    for key in ("sample_time", "bandwidth"):
        if key not in controller:
            raise SceneError(f"controller.{key} is required")
    step = _checked(check_real, "controller", "sample_time", controller["sample_time"],
                    minimum=1e-4, maximum=100.0)
    target = _target(controller, quaternion)
    try:
        law = QuaternionFeedback.design(
            structure.rigid_inertia, controller["bandwidth"], target,
            damping=controller.get("damping", 0.7),
            integral_time=controller.get("integral_time"),
            torque_limit=controller.get("torque_limit"))
    except (ValueError, TypeError) as exc:
        raise SceneError(str(exc).replace("quaternion_feedback.", "controller.")) from None
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
    setup = construct(AttitudeSensors, "sensors", {**parts, "gyro_sample_time": step,
                                                   "seed": sensors.get("seed", 0)})
    sigmas = {key: _checked(check_real, "sensors", key, sensors.get(key, default),
                            minimum=0.0, strict=True, maximum=1.0)
              for key, default in (("attitude_sigma", 1e-3), ("bias_sigma", 1e-4))}
    loop = SpatialLoop(law=law, sample_time=step, sensors=setup, **sigmas)
    _checked(loop.estimator, quaternion)
    return loop


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
