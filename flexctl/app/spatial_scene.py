"""Scenes of structures that turn about any axis (a ``[hub]`` whose inertia is a 3 x 3 matrix).

A scene is spatial when ``hub.inertia`` is a 3 x 3 array; :func:`parse_spatial_scene` reads it
into a :class:`SpatialScene`. The tables (every key is checked, every error names it):

- ``[hub]``: ``inertia`` (3 x 3, kg m^2, hub frame, about the centre), ``radius`` (m),
  ``mass`` (kg; needed when ``support = "free"``), ``support`` (``"pinned"`` or ``"free"``).
- ``[[appendages]]``: ``name``, ``direction`` and ``normal`` (3-vectors, hub frame), ``root``
  (optional 3-vector, m; default ``radius * direction``), ``length``, ``density``, ``area``,
  ``youngs_modulus``, ``second_moment`` (bending along the normal), ``second_moment_lateral``,
  ``shear_modulus``, ``torsion_constant``, optional ``polar_moment`` and ``damping_ratio``;
  ``[[appendages.masses]]`` with ``mass`` and ``position``.
- ``[model]``: ``variant``, ``"exact"`` (the default: the geometrically exact rod),
  ``"first_order"`` or ``"zero_order"`` (its equations to first order in the deflections, with
  or without the centrifugal stiffening; :data:`~flexctl.model.spatial_dynamics.SPATIAL_VARIANTS`),
  and ``modes``, per field (bending along the normal, along the lateral direction, torsion):
  an integer for every appendage, a table of one integer per appendage by name, or
  ``"auto"`` (:func:`~flexctl.sim.spatial_fidelity.choose_spatial_modes`: as few as the
  manoeuvre needs for the relative tip error ``tolerance``, default 1e-2).
- ``[initial]``: ``angular_velocity`` (rad/s, hub frame) and ``quaternion`` (hub to inertial,
  scalar first); the structure starts straight and at rest relative to its hub.
- ``[maneuver]``: ``kind = "torque_samples"`` with ``times`` and ``values`` (rows ``tx, ty,
  tz``, N m, hub frame) or ``file`` (a CSV with the header ``t, tx, ty, tz``), and
  ``interpolation`` (``"linear"``, the default, or ``"hold"``); ``kind = "sine_torque"`` with
  ``peak_torque`` (a 3-vector) and ``duration`` (one period of ``sin(2 pi t / duration)``,
  then none); ``kind = "none"`` (a free motion from the initial state).
- ``[simulation]``: ``t_final`` (s), ``output_step`` (s), ``rtol``.
- ``[actuator]`` (optional): ``kind = "wheels"``, a cluster of reaction wheels
  (:mod:`flexctl.model.wheel_cluster`) that the manoeuvre's torque is commanded of, distributed
  by ``distribution`` (``"pseudo_inverse"``, the default, or ``"null_motion"`` with
  ``null_gain`` 1/s and ``bias_speed`` rad/s). The wheels are ``[[actuator.wheels]]`` tables
  (``axis``, ``inertia``, ``torque_limit``, ``speed_limit``, and optional ``time_constant``,
  ``coulomb_friction``, ``viscous_friction``, ``static_friction``, ``stribeck_speed``,
  ``friction_smoothing``, ``dead_band``, ``power_limit``: the fields of
  :class:`~flexctl.model.wheel_cluster.Wheel`), or ``arrangement = "orthogonal"`` (three
  wheels along ``x``, ``y``, ``z``) or ``"pyramid"`` (four, ``pyramid_angle`` degrees from
  ``pyramid_axis``, default ``z``) with one ``[actuator.wheel]`` table of the fields they
  share. ``[initial] wheel_speeds`` gives their initial speeds (rad/s, relative to the hub).
- ``[controller]`` and ``[sensors]`` (optional): an attitude loop
  (:mod:`flexctl.app.spatial_control`).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, fields

import numpy as np

from controllers.spec import SceneError
from ..model.checks import check_real
from ..model.parameters import PointMass
from ..model.spatial_structure import SpatialAppendage, SpatialHub, SpatialStructure
from ..model.spatial_dynamics import MAX_SPATIAL_MODES, SPATIAL_VARIANTS, spatial_modes
from ..model.wheel_cluster import Wheel, WheelCluster
from ..sim.spatial_run import DEFAULT_RTOL, MAX_SPIN, MAX_T_FINAL, VectorTorque
from .scene_tables import check_table_keys, construct, read_table_file
from .scene_tables import table_of as _table

__all__ = ["SpatialScene", "SpatialSine", "is_spatial", "parse_spatial_scene",
           "SPATIAL_TORQUE_COLUMNS"]

#: Header of a spatial torque file.
SPATIAL_TORQUE_COLUMNS = ("t", "tx", "ty", "tz")
#: Largest torque file read, bytes.
MAX_FILE_BYTES = 64 * 2 ** 20

_KEYS = {
    "description": None,
    "hub": {"inertia", "radius", "mass", "support"},
    "appendages": None,
    "model": {"variant", "modes", "tolerance"},
    "initial": {"angular_velocity", "quaternion", "wheel_speeds"},
    "controller": None,
    "sensors": None,
    "actuator": {"kind", "distribution", "null_gain", "bias_speed", "wheels", "arrangement",
                 "pyramid_angle", "pyramid_axis", "wheel"},
    "maneuver": {"kind", "times", "values", "interpolation", "file", "peak_torque",
                 "duration"},
    "simulation": {"t_final", "output_step", "rtol"},
}
_APPENDAGE_KEYS = {"name", "direction", "normal", "root", "length", "density", "area",
                   "youngs_modulus", "second_moment", "second_moment_lateral",
                   "shear_modulus", "torsion_constant", "polar_moment", "damping_ratio",
                   "masses"}
_REQUIRED = ("direction", "normal", "length", "density", "area", "youngs_modulus",
             "second_moment", "second_moment_lateral", "shear_modulus", "torsion_constant")
_MANEUVER_KEYS = {"torque_samples": {"times", "values", "interpolation", "file"},
                  "sine_torque": {"peak_torque", "duration"}, "none": set()}


@dataclass(frozen=True)
class SpatialSine:
    """One period of a sine torque about a fixed axis of the hub frame, then none.

    Parameters
    ----------
    peak_torque : array_like, shape (3,)
        Peak of each component, N m, hub frame.
    duration : float
        The period, s (> 0).
    """

    peak_torque: np.ndarray
    duration: float

    def __post_init__(self):
        from ..model.checks import check_array

        peak = check_array("maneuver", "peak_torque", self.peak_torque, shape=(3,))
        if np.max(np.abs(peak)) > 1e150:
            raise SceneError("maneuver.peak_torque must be at most 1e150 N m in magnitude")
        object.__setattr__(self, "peak_torque", peak)
        object.__setattr__(self, "duration", check_real("maneuver", "duration", self.duration,
                                                        minimum=0.0, strict=True))

    def __call__(self, t) -> np.ndarray:
        """The torque at ``t`` (s), N m, shape (3,).

        Parameters
        ----------
        t : float
        """
        t = float(t)
        if not 0.0 <= t <= self.duration:
            return np.zeros(3)
        return np.asarray(self.peak_torque) * math.sin(2 * math.pi * t / self.duration)

    def at(self, times) -> np.ndarray:
        """The torque at each of ``times``, N m, shape (3, P): as ``self(t)`` for each.

        Parameters
        ----------
        times : array_like, shape (P,)
            Times, s: finite.
        """
        from ..model.checks import check_array

        times = check_array("SpatialSine.at", "times", times, shape=(None,))
        inside = (times >= 0.0) & (times <= self.duration)
        wave = np.where(inside, np.sin(2 * math.pi * times / self.duration), 0.0)
        return np.outer(np.asarray(self.peak_torque), wave)

    @property
    def breakpoints(self) -> np.ndarray:
        """The end of the period, s."""
        return np.array([self.duration])

    def segment_form(self, a: float, b: float) -> np.ndarray:
        """The torque on ``[a, b]`` as the 11 numbers of
        ``p[0:3] + p[3:6] t + p[6:9] sin(p[9] (p[10] + t))`` (see
        :mod:`flexctl.sim.spatial_run`).

        Parameters
        ----------
        a, b : float
            The segment, s: inside the period or after it.
        """
        inside = b <= self.duration + 1e-12 * max(1.0, self.duration)
        peak = np.asarray(self.peak_torque) if inside else np.zeros(3)
        return np.concatenate([np.zeros(6), peak, [2 * math.pi / self.duration, a]])


@dataclass(frozen=True)
class SpatialScene:
    """A validated spatial scene.

    Attributes
    ----------
    name : str
    structure : SpatialStructure
    n_modes : int or tuple of int
        Modes per field: of every appendage, or of each.
    variant : str
        The model: one of :data:`~flexctl.model.spatial_dynamics.SPATIAL_VARIANTS`.
    angular_velocity, quaternion : ndarray
        Initial hub angular velocity (rad/s, hub frame) and attitude.
    maneuver : VectorTorque, SpatialSine or None
    t_final, output_step, rtol : float
    description : str
    data : dict
        The scene's tables as read (a torque file's samples inline).
    wheels : WheelCluster or None
        The reaction wheels the manoeuvre's torque is commanded of (``[actuator]``).
    wheel_speeds : ndarray or None
        Their initial speeds relative to the hub, rad/s.
    mode_choice : SpatialModeChoice or None
        With ``modes = "auto"``, how the counts were chosen.
    loop : SpatialLoop or None
        The attitude loop of ``[controller]`` and ``[sensors]``.
    """

    name: str
    structure: SpatialStructure
    n_modes: int
    angular_velocity: np.ndarray
    quaternion: np.ndarray
    maneuver: object
    t_final: float
    output_step: float
    rtol: float
    variant: str = "exact"
    description: str = ""
    data: dict = field(default_factory=dict, repr=False)
    wheels: WheelCluster | None = None
    wheel_speeds: np.ndarray | None = None
    mode_choice: object = None
    loop: object = None


def is_spatial(data: dict) -> bool:
    """Whether the scene tables ``data`` describe a spatial structure (a 3 x 3 hub inertia).

    Parameters
    ----------
    data : dict
        The scene's tables as read from TOML.
    """
    hub = data.get("hub")
    return isinstance(hub, dict) and isinstance(hub.get("inertia"), (list, tuple))


def parse_spatial_scene(data: dict, name: str = "scene", base_dir=None) -> SpatialScene:
    """Validate a spatial scene given as nested dictionaries (the TOML tables).

    Parameters
    ----------
    data : dict
        The scene's tables.
    name : str, optional
        The scene's name.
    base_dir : str or path-like, optional
        Directory a relative ``maneuver.file`` is read from.

    Returns
    -------
    SpatialScene

    Raises
    ------
    SceneError
        On an unknown key, a missing table or key, or a bad value; the message names the key.
    """
    data = copy.deepcopy(data)
    for key in data:
        if key not in _KEYS:
            raise SceneError(f"unknown scene key {key!r} of a spatial scene; expected one of "
                             f"{', '.join(sorted(_KEYS))}")
    for key, allowed in _KEYS.items():
        if allowed is not None and key in data:
            check_table_keys(key, _table(data, key), allowed)
    hub = construct(SpatialHub, "hub", _table(data, "hub"))
    structure = _structure(hub, data.get("appendages"))
    model = _table(data, "model", required=False)
    initial = _table(data, "initial", required=False)
    from ..model.checks import check_array
    try:
        spin = check_array("initial", "angular_velocity",
                           initial.get("angular_velocity", [0.0, 0.0, 0.0]), shape=(3,))
        quaternion = np.array(check_array("initial", "quaternion",
                                          initial.get("quaternion", [1.0, 0.0, 0.0, 0.0]),
                                          shape=(4,)))
    except (ValueError, TypeError) as exc:
        raise SceneError(str(exc)) from None
    if not np.linalg.norm(quaternion) > 0:
        raise SceneError("initial.quaternion must be non-zero")
    if np.max(np.abs(spin)) > MAX_SPIN:
        raise SceneError(f"initial.angular_velocity must be at most {MAX_SPIN:g} rad/s in "
                         f"magnitude; got {spin.tolist()}")
    maneuver = _maneuver(data, base_dir)
    wheels = _wheels(_table(data, "actuator", required=False))
    wheel_speeds = None
    if "wheel_speeds" in initial:
        if wheels is None:
            raise SceneError("initial.wheel_speeds needs an [actuator] of kind 'wheels'")
        try:
            wheel_speeds = check_array("initial", "wheel_speeds", initial["wheel_speeds"],
                                       shape=(wheels.count,))
        except (ValueError, TypeError) as exc:
            raise SceneError(str(exc)) from None
        for k, (speed, wheel) in enumerate(zip(wheel_speeds, wheels.wheels)):
            if abs(speed) > wheel.speed_limit:
                raise SceneError(f"initial.wheel_speeds[{k}] must be within wheel {k + 1}'s "
                                 f"speed_limit ({wheel.speed_limit:g} rad/s); got {speed!r}")
    t_final, output_step, rtol = _simulation(_table(data, "simulation"))
    n_modes, variant, choice = _model(model, structure, maneuver, t_final, spin)
    from .spatial_control import spatial_loop

    loop = spatial_loop(_table(data, "controller", required=False),
                        _table(data, "sensors", required=False), structure,
                        quaternion / np.linalg.norm(quaternion), wheels, wheel_speeds, spin,
                        variant)
    if loop is not None and maneuver is not None:
        raise SceneError("a spatial scene with a [controller] takes maneuver.kind = 'none' "
                         "(the law commands the torque)")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SceneError(f"description must be a string; got {description!r:.80}")
    return SpatialScene(name=name, structure=structure, n_modes=n_modes,
                        angular_velocity=spin, quaternion=quaternion / np.linalg.norm(quaternion),
                        maneuver=maneuver, t_final=t_final, output_step=output_step, rtol=rtol,
                        variant=variant, description=description, data=data, wheels=wheels,
                        wheel_speeds=wheel_speeds, mode_choice=choice, loop=loop)


_WHEEL_KEYS = {f.name for f in fields(Wheel)}


def _wheels(table: dict) -> WheelCluster | None:
    """The ``[actuator]`` table's wheel cluster (None without the table)."""
    if not table:
        return None
    if table.get("kind") != "wheels":
        raise SceneError(f"actuator.kind must be 'wheels' for a spatial scene (a cluster of "
                         f"reaction wheels); got {table.get('kind')!r:.80}")
    law = {key: table[key] for key in ("distribution", "null_gain", "bias_speed")
           if key in table}
    arrangement = table.get("arrangement")
    if ("wheels" in table) == (arrangement is not None):
        raise SceneError("actuator needs either [[actuator.wheels]] tables (one per wheel) or "
                         "an arrangement ('orthogonal' or 'pyramid') with one [actuator.wheel] "
                         "table, not both")
    if arrangement is None:
        items = table["wheels"]
        if not isinstance(items, list) or not items:
            raise SceneError("actuator.wheels must be an array of tables, one per wheel")
        wheels = [construct(Wheel, "wheel", item, rename=where)
                  for where, item in _tables("actuator.wheels", items, _WHEEL_KEYS)]
        for key in ("pyramid_angle", "pyramid_axis", "wheel"):
            if key in table:
                raise SceneError(f"actuator.{key} belongs to an arrangement; these wheels are "
                                 "listed one by one")
        return construct(WheelCluster, "wheels", {"wheels": tuple(wheels), **law},
                         rename="actuator")
    shared = table.get("wheel")
    if not isinstance(shared, dict):
        raise SceneError("actuator.wheel must be a table of the fields the arrangement's "
                         "wheels share (inertia, torque_limit, speed_limit, ...)")
    check_table_keys("actuator.wheel", shared, _WHEEL_KEYS - {"axis"})
    # the shared fields checked once, on a wheel of any axis
    construct(Wheel, "wheel", {"axis": (0.0, 0.0, 1.0), **shared}, rename="actuator.wheel")
    if arrangement == "orthogonal":
        for key in ("pyramid_angle", "pyramid_axis"):
            if key in table:
                raise SceneError(f"actuator.{key} belongs to arrangement 'pyramid'")
        return construct(WheelCluster, "wheels", {"wheels": tuple(
            Wheel(axis=axis, **shared) for axis in np.eye(3)), **law}, rename="actuator")
    if arrangement == "pyramid":
        if "pyramid_angle" not in table:
            raise SceneError("actuator.pyramid_angle is required for arrangement 'pyramid': "
                             "the angle between each spin axis and the pyramid's axis, degrees")
        pyramid = {"angle": table["pyramid_angle"], **law, **shared}
        if "pyramid_axis" in table:
            pyramid["pyramid_axis"] = table["pyramid_axis"]
        try:
            return WheelCluster.pyramid(**pyramid)
        except (ValueError, TypeError) as exc:
            raise SceneError(str(exc).replace("wheels.", "actuator.")) from None
    raise SceneError(f"actuator.arrangement must be 'orthogonal' or 'pyramid'; got "
                     f"{arrangement!r:.80}")


def _tables(key: str, items: list, allowed) -> list:
    """``[(where, table)]`` of an array of tables, each a table of ``allowed`` keys."""
    out = []
    for k, item in enumerate(items):
        where = f"{key}.{k}"
        if not isinstance(item, dict):
            raise SceneError(f"{where} must be a table; got {type(item).__name__}")
        check_table_keys(where, item, allowed)
        out.append((where, item))
    return out


def _structure(hub: SpatialHub, items) -> SpatialStructure:
    if not isinstance(items, list) or not items:
        raise SceneError("a spatial scene needs [[appendages]] tables (one per appendage)")
    appendages = []
    for k, (where, table) in enumerate(_tables("appendages", items, _APPENDAGE_KEYS)):
        fields = {key: value for key, value in table.items() if key != "masses"}
        masses = table.get("masses", [])
        if not isinstance(masses, list):
            raise SceneError(f"{where}.masses must be an array of tables; got "
                             f"{type(masses).__name__}")
        points = []
        for j, m in enumerate(masses):
            if not isinstance(m, dict):
                raise SceneError(f"{where}.masses.{j} must be a table")
            check_table_keys(f"{where}.masses.{j}", m, {"mass", "position"})
            points.append(construct(PointMass, f"{where}.masses.{j}", m))
        fields["masses"] = tuple(points)
        if "name" not in fields:
            fields["name"] = f"appendage{k}"
        missing = [f for f in _REQUIRED if f not in fields]
        if missing:
            raise SceneError(f"{where}.{missing[0]} is required for a spatial appendage")
        try:
            appendage = SpatialAppendage(**fields)
        except (ValueError, TypeError) as exc:
            name = fields["name"]
            message = str(exc).replace(f"appendage {name!r}", where)
            raise SceneError(message if message.startswith(where) else f"{where}: {message}") \
                from None
        appendages.append(appendage)
    try:
        return SpatialStructure(hub=hub, appendages=tuple(appendages))
    except (ValueError, TypeError) as exc:
        message = str(exc)
        for k, a in enumerate(appendages):
            message = message.replace(f"appendage {a.name!r}", f"appendages.{k}")
            message = message.replace(f"appendages[{k}]", f"appendages.{k}")
        raise SceneError(message) from None


def _model(table: dict, structure: SpatialStructure, maneuver, t_final: float,
           spin) -> tuple:
    """``(modes, variant, choice)`` of a spatial scene's ``[model]`` table (``choice``: the
    :class:`~flexctl.sim.spatial_fidelity.SpatialModeChoice` of ``modes = "auto"``)."""
    variant = table.get("variant", "exact")
    if not isinstance(variant, str) or variant not in SPATIAL_VARIANTS:
        raise SceneError(f"model.variant must be one of {', '.join(map(repr, SPATIAL_VARIANTS))} "
                         f"for a spatial scene (the planar 'consistent' has no spatial form); "
                         f"got {variant!r:.80}")
    modes = table.get("modes", 4)
    tolerance = table.get("tolerance")
    if tolerance is not None and modes != "auto":
        raise SceneError("model.tolerance is the relative tip error of modes = 'auto'; these "
                         f"modes are given ({modes!r:.80})")
    if modes == "auto":
        from ..sim.fidelity import DEFAULT_TOLERANCE, check_tolerance
        from ..sim.spatial_fidelity import choose_spatial_modes

        tolerance = DEFAULT_TOLERANCE if tolerance is None else tolerance
        try:
            check_tolerance(tolerance)
        except (ValueError, TypeError) as exc:
            raise SceneError(f"model.tolerance: {exc}") from None
        choice = choose_spatial_modes(structure, maneuver, t_final, tolerance, spin)
        return choice.n_modes, variant, choice
    if isinstance(modes, dict):
        bad = next((name for name, n in modes.items() if isinstance(n, bool)
                    or not isinstance(n, int) or not 1 <= n <= MAX_SPATIAL_MODES), None)
        if bad is not None:
            raise SceneError(f"model.modes.{bad} must be an integer from 1 to "
                             f"{MAX_SPATIAL_MODES} (modes per field); got {modes[bad]!r:.80}")
        try:
            return spatial_modes("model", structure, modes), variant, None
        except (ValueError, TypeError) as exc:
            raise SceneError(str(exc).replace("model.n_modes", "model.modes")) from None
    if isinstance(modes, bool) or not isinstance(modes, int) or not \
            1 <= modes <= MAX_SPATIAL_MODES:
        raise SceneError(f"model.modes must be an integer from 1 to {MAX_SPATIAL_MODES} (modes "
                         f"per field: each bending plane and torsion), a table of one per "
                         f"appendage, or 'auto'; got {modes!r:.80}")
    return modes, variant, None


def _maneuver(data: dict, base_dir):
    table = dict(_table(data, "maneuver", required=False)) or {"kind": "none"}
    kind = table.pop("kind", None)
    if kind not in _MANEUVER_KEYS:
        raise SceneError(f"maneuver.kind must be one of {', '.join(sorted(_MANEUVER_KEYS))} "
                         f"for a spatial scene; got {kind!r:.80}")
    check_table_keys("maneuver", table, _MANEUVER_KEYS[kind])
    if kind == "none":
        return None
    if kind == "sine_torque":
        return construct(SpatialSine, "maneuver", table)
    if "file" in table:
        if "times" in table or "values" in table:
            raise SceneError("maneuver.file and maneuver.times/values exclude each other")
        times, values = _read_file(table.pop("file"), base_dir)
        data["maneuver"].pop("file", None)
        data["maneuver"].update(times=times.tolist(), values=values.tolist())
        table.update(times=times, values=values)
    for key in ("times", "values"):
        if key not in table:
            raise SceneError(f"maneuver.{key} is required for kind 'torque_samples' (or "
                             "maneuver.file, a CSV file of columns t, tx, ty, tz)")
    return construct(VectorTorque, "maneuver", table)


def _read_file(file, base_dir) -> tuple:
    """``(times (K,), values (K, 3))`` of a spatial torque file."""
    where, lines = read_table_file(file, base_dir, SPATIAL_TORQUE_COLUMNS, MAX_FILE_BYTES)
    rows = []
    for number, line in lines:
        try:
            row = [float(c) for c in line.split(",")]
        except ValueError:
            row = []
        if len(row) != 4 or not all(math.isfinite(v) for v in row):
            raise SceneError(f"{where} line {number} must hold four finite numbers t, tx, ty, "
                             f"tz; got {line[:80]!r}")
        rows.append(row)
    if not rows:
        raise SceneError(f"{where} holds no samples")
    table = np.array(rows)
    return table[:, 0], table[:, 1:]


def _simulation(table: dict) -> tuple:
    if "t_final" not in table:
        raise SceneError("simulation.t_final is required")
    try:
        t_final = check_real("simulation", "t_final", table["t_final"], minimum=0.0,
                             strict=True, maximum=MAX_T_FINAL)
        step = check_real("simulation", "output_step",
                          table.get("output_step", t_final / 1000), minimum=0.0, strict=True)
        rtol = check_real("simulation", "rtol", table.get("rtol", DEFAULT_RTOL),
                          minimum=1e-13, maximum=1e-2)
    except (ValueError, TypeError) as exc:
        raise SceneError(str(exc)) from None
    if step > t_final:
        raise SceneError(f"simulation.output_step must be at most t_final = {t_final:g} s; "
                         f"got {step:g}")
    if t_final / step > 1_000_000:
        raise SceneError(f"simulation.output_step {step:g} s gives more than 10^6 samples")
    return t_final, step, rtol
