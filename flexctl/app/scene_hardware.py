"""A scene's hardware tables: ``[actuator]`` (what turns the hub) and ``[sensors]`` (what the
controller reads).

::

    [actuator]
    kind = "reaction_wheel"      # or "dc_motor"; no table: an ideal hub torque
    inertia = 0.02               # wheel, kg m^2
    torque_limit = 0.2           # N m
    speed_limit = 600.0          # rad/s
    time_constant = 0.05         # s
    viscous_friction = 1e-5      # N m s
    coulomb_friction = 1e-3      # N m
    # dc_motor: resistance, torque_constant, back_emf_constant, gear_ratio, gear_efficiency,
    #           motor_efficiency, rotor_inertia, viscous_friction, voltage_limit

    [sensors]
    seed = 1
    signals = ["attitude", "gyro", "root_moment"]  # default: attitude and gyro, and the
                                 # root gauges or tip accelerometers when their noise is given
    encoder_resolution = 1e-4    # rad (attitude quantisation)
    attitude_noise = 0.0         # rad (attitude white noise)
    attitude_bias = 0.0          # rad (attitude bias, drawn once per run)
    gyro_noise = 1e-4            # rad/sqrt(s)
    gyro_bias_instability = 1e-5 # rad/s
    root_moment_noise = 1e-3     # N m
    delay = 0.002                # s

The keys are the fields of :class:`~flexctl.model.actuators.ReactionWheel`,
:class:`~flexctl.model.actuators.DCMotor` and :class:`~flexctl.sim.sensors.Sensors` (one name
for each quantity in Python and TOML). A scene with ``[sensors]`` runs its controller sampled,
at ``sensors.sample_time`` or the controller's ``sample_time``, else every
:data:`~flexctl.sim.sensors.DEFAULT_SAMPLE_TIME` seconds.
"""

from __future__ import annotations

import dataclasses

from controllers.spec import SceneError

from ..model.actuators import ACTUATOR_KINDS
from ..sim.sensors import DEFAULT_SAMPLE_TIME, Sensors
from .scene_tables import construct

__all__ = ["parse_actuator", "parse_sensors", "ACTUATOR_KEYS", "SENSOR_KEYS",
           "DEFAULT_SAMPLE_TIME"]

#: The keys of each actuator kind's table (besides ``kind``).
ACTUATOR_KEYS = {kind: tuple(f.name for f in dataclasses.fields(cls))
                 for kind, cls in ACTUATOR_KINDS.items()}
#: The keys of ``[sensors]``.
SENSOR_KEYS = tuple(f.name for f in dataclasses.fields(Sensors))


def parse_actuator(table) -> object:
    """The actuator of an ``[actuator]`` table (:mod:`flexctl.model.actuators`).

    Parameters
    ----------
    table : dict
        The table as parsed from TOML: ``kind`` (``"reaction_wheel"`` or ``"dc_motor"``)
        and the fields of that actuator (:data:`ACTUATOR_KEYS`), in SI units.
    """
    if not isinstance(table, dict):
        raise SceneError(f"scene key 'actuator' must be a table; got {type(table).__name__}")
    table = dict(table)
    kind = table.pop("kind", None)
    if kind not in ACTUATOR_KINDS:
        raise SceneError(f"actuator.kind must be one of {', '.join(ACTUATOR_KINDS)}; got "
                         f"{kind!r}")
    allowed = ACTUATOR_KEYS[kind]
    for key in table:
        if key not in allowed:
            raise SceneError(f"unknown key {key!r} in [actuator] of kind {kind!r}; expected "
                             f"one of {', '.join(('kind',) + allowed)}")
    return construct(ACTUATOR_KINDS[kind], "actuator", table)


def parse_sensors(table) -> Sensors:
    """The :class:`~flexctl.sim.sensors.Sensors` of a ``[sensors]`` table.

    Parameters
    ----------
    table : dict
        The table as parsed from TOML: fields of ``Sensors`` (:data:`SENSOR_KEYS`), in SI
        units.
    """
    if not isinstance(table, dict):
        raise SceneError(f"scene key 'sensors' must be a table; got {type(table).__name__}")
    for key in table:
        if key not in SENSOR_KEYS:
            raise SceneError(f"unknown key {key!r} in [sensors]; expected one of "
                             f"{', '.join(SENSOR_KEYS)}")
    return construct(Sensors, "sensors", table)
