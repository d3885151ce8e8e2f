"""Scenes: a system, a model choice, a manoeuvre and simulation settings in one TOML file.

Format (every table but ``[[masses]]`` and ``[maneuver]`` keys is required as shown)::

    description = "free text"            # optional

    [hub]                                # Hub fields
    inertia = 1.16
    radius = 0.06
    friction = 0.0                       # optional
    # support = "free"                   # optional: "pinned" (default) or "free" (the hub
    # mass = 3.0                         # also translates); mass, kg, required when free

    [beam]                               # Beam fields
    length = 1.8
    density = 2766.0
    area = 2.5e-4
    second_moment = 1.3021e-10
    youngs_modulus = 6.9e10
    damping_ratio = 0.0                  # optional

    [[masses]]                           # any number, optional
    mass = 0.085
    position = 1.62

    # or, for any number of beams on one hub, [[appendages]] instead of [beam] and [[masses]]:
    # [[appendages]]
    # name = "wing_a"                    # an identifier, unique: it names the states and
    #                                    # outputs (wing_a.tip_deflection)
    # angle_deg = 0.0                    # optional: mounting angle in the hub frame, degrees
    # radius = 0.06                      # optional: root radius, m (default hub.radius)
    # length = 1.8                       # and the other [beam] fields
    # [[appendages.masses]]              # any number, optional; position from the root, m
    # mass = 0.085
    # position = 1.62

    [model]
    variant = "first_order"              # first_order | zero_order | consistent | exact, or
                                         # "auto": first_order where its geometric error meets
                                         # the tolerance, else exact (flexctl.sim.validity)
    modes = 4                            # or "auto": as few as the manoeuvre needs, see
                                         # flexctl.sim.fidelity.choose_modes; with
                                         # [[appendages]] per appendage, or a table
                                         # {wing_a = 4, wing_b = 2} naming each of them
    # tolerance = 1e-2                   # optional: relative tip error for the "auto" choices
                                         # and for the model-validity warning
    design_modes = 2                     # optional: modes of a controller's design model,
                                         # per appendage as for modes (no "auto")
    # design_variant = "exact"           # optional: variant of the design model; default
                                         # exact on an exact plant, else first_order

    [maneuver]
    kind = "sine_torque"                 # peak_torque, duration
    # kind = "spin_up"                   # spin_rate, ramp_time
    # kind = "slew"                      # angle_deg, duration (s or "free"), torque_bound
    # kind = "torque_samples"            # times (s), values (N m), interpolation ("hold" or
                                         # "linear"); or file = "torque.csv" (columns
                                         # t, torque after a header line; relative to the
                                         # scene file's directory) instead of times, values

    [controller]                         # slew scenes only: kind and its settings
    kind = "trajopt+lqr"                 # see controllers.factory for kinds and settings

    [simulation]
    t_final = 20.0
    output_step = 0.01                   # optional
    rtol = 1e-8                          # optional
    method = "auto"                      # optional: auto | cvodes | rk4 | a solve_ivp method

Unknown keys and bad values raise :class:`SceneError` naming the key. The one-beam form
(``[beam]``, ``[[masses]]``) gives :attr:`Scene.system` a :class:`~flexctl.model.HubBeam` on a
pinned hub; ``[[appendages]]``, or a free hub, a :class:`~flexctl.model.Structure`.

Examples
--------
>>> from flexctl import load_scene
>>> scene = load_scene("kane-spinup", overrides={"maneuver.spin_rate": "10"})
>>> scene.maneuver
SpinUp(spin_rate=10.0, ramp_time=15.0)
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

# the controller kinds and their settings belong to the controllers package
from controllers.spec import FORMER_NAMES
from controllers.spec import (ControllerSpec, SceneError, current_name,
                              current_names)

from ..sim.fidelity import DEFAULT_TOLERANCE, ModeChoice, choose_modes
from ..sim.maneuvers import MAX_TORQUE_SAMPLES, SineTorque, Slew, SpinUp, TorqueSamples
from ..sim.metrics import slew_metrics
from ..model import VARIANTS, Model, build_model
from ..model.variants import EXACT_MAX_MODES
from ..model.errors import InputTypeError, InputValueError
from ..model.checks import check_real
from ..model.parameters import Beam, Hub, HubBeam, PointMass
from ..model.structure import MAX_ANGLE, MAX_APPENDAGES, Appendage, Structure
from ..sim.simulation import METHODS, MIN_T_FINAL, SimulationResult, simulate
from ..sim.validity import VariantChoice, choose_variant, run_assessed
from .scene_hardware import parse_actuator, parse_sensors
from .scene_tables import construct as _construct
from .scene_tables import read_table_file
from .scene_tables import table_of as _table
from .scene_tables import check_table_keys as _check_table_keys

__all__ = ["Scene", "SceneError", "ModelSpec", "SimulationSpec", "ControllerSpec", "load_scene",
           "parse_scene",
           "builtin_scenes", "run_scene", "run_slew"]

def _slew(angle_deg, duration="free", torque_bound=None):
    if isinstance(duration, str):
        if duration != "free":
            raise InputValueError(f"maneuver.duration must be a positive time (s) or \"free\"; "
                                  f"got {duration!r}")
        duration = None
    if isinstance(angle_deg, bool) or not isinstance(angle_deg, (int, float)):
        raise InputValueError(f"maneuver.angle_deg must be a number (degrees); got {angle_deg!r}")
    return Slew(angle=math.radians(angle_deg), duration=duration, torque_bound=torque_bound)


def _torque_samples(times=None, values=None, interpolation="hold", file=None, *,
                    base_dir=None):
    """A ``torque_samples`` manoeuvre: its samples given inline, or read from the CSV ``file``
    (a relative path from ``base_dir``, the scene file's directory)."""
    if file is not None:
        given = [key for key, value in (("times", times), ("values", values)) if value is not None]
        if given:
            raise SceneError(f"maneuver.file and maneuver.{given[0]} exclude each other: give "
                             "the samples inline (times, values) or in a file; got both")
        times, values = _read_torque_file(file, base_dir)
    for key, value in (("times", times), ("values", values)):
        if value is None:
            raise SceneError(f"maneuver.{key} is required for kind 'torque_samples' (or "
                             "maneuver.file, a CSV file of columns t, torque)")
    return TorqueSamples(times=times, values=values, interpolation=interpolation)


#: Largest torque file read, bytes: 10^6 samples of two 20-digit numbers fit.
MAX_TORQUE_FILE_BYTES = 64 * 2 ** 20
#: The header line of a torque file.
TORQUE_FILE_COLUMNS = ("t", "torque")


def _read_torque_file(file, base_dir) -> tuple:
    """``(times, values)`` of a torque file: a header line ``t, torque``, then one line
    ``t, torque`` per sample (s, N m), times strictly increasing from 0 or later."""
    where, lines = read_table_file(file, base_dir, TORQUE_FILE_COLUMNS, MAX_TORQUE_FILE_BYTES)
    times, values = [], []
    for number, line in lines:
        _read_sample(f"{where} line {number}", line, times, values)
    if not times:
        raise SceneError(f"{where} holds no samples: after the header, one line t, torque per "
                         "sample")
    return times, values


def _read_sample(where: str, line: str, times: list, values: list) -> None:
    """Append the sample of one line of a torque file to ``times`` and ``values``."""
    cells = line.split(",")
    try:
        t, torque = (float(cell) for cell in cells) if len(cells) == 2 else (None, None)
    except ValueError:
        t = torque = None
    if t is None:
        raise SceneError(f"{where} must hold two numbers t, torque; got {line[:80]!r}")
    if not (math.isfinite(t) and math.isfinite(torque)):
        raise SceneError(f"{where}: t and torque must be finite; got {line[:80]!r}")
    if t < 0.0 if not times else t <= times[-1]:
        rule = "t must be >= 0 s" if not times else \
            f"t must increase strictly (after {times[-1]!r} s)"
        raise SceneError(f"{where}: {rule}; got {t!r}")
    if len(times) == MAX_TORQUE_SAMPLES:
        raise SceneError(f"{where}: a torque file holds at most {MAX_TORQUE_SAMPLES} samples")
    times.append(t)
    values.append(torque)


_MANEUVERS = {"spin_up": SpinUp, "sine_torque": SineTorque, "slew": _slew,
              "torque_samples": _torque_samples}
_SCHEMA = {
    "description": None,
    "hub": {"inertia", "radius", "friction", "mass", "support"},
    "beam": {"length", "density", "area", "second_moment", "youngs_modulus", "damping_ratio"},
    "masses": {"mass", "position"},
    "model": {"variant", "modes", "design_modes", "design_variant", "tolerance",
              "design_stiffness_factor", "design_mass_factor"},
    "maneuver": {"kind", "spin_rate", "ramp_time", "peak_torque", "duration", "angle_deg",
                 "torque_bound", "times", "values", "interpolation", "file"},
    "simulation": {"t_final", "output_step", "rtol", "method", "states"},
    "controller": None,
    # checked by their own parsers (flexctl.app.scene_hardware): the keys depend on the kind
    "actuator": None,
    "sensors": None,
    "requirements": {"gain_margin_db", "phase_margin_deg", "delay_margin", "bandwidth",
                     "flexible_attenuation_db", "flexible_phase_margin_deg",
                     "frequency_uncertainty", "damping_range", "stiffness_uncertainty",
                     "mass_uncertainty", "hub_inertia_uncertainty", "gain_stabilised_above"},
}
#: Keys of one [[appendages]] table: its name, mounting, beam fields and [[appendages.masses]]
#: (whose keys are those of [[masses]]); beside _SCHEMA, whose tables are the one-beam form's.
_APPENDAGE_KEYS = {"name", "angle_deg", "radius", "masses"} | _SCHEMA["beam"]
#: Top-level keys, and those that hold an array of tables.
_TOP_LEVEL = set(_SCHEMA) | {"appendages"}
_ARRAYS = ("masses", "appendages")
_MANEUVER_KEYS = {"spin_up": {"spin_rate", "ramp_time"},
                  "sine_torque": {"peak_torque", "duration"},
                  "slew": {"angle_deg", "duration", "torque_bound"},
                  "torque_samples": {"times", "values", "interpolation", "file"}}
_MANEUVER_OPTIONAL = {"slew": {"duration", "torque_bound"},
                      # times and values, or a file: _torque_samples says which is missing
                      "torque_samples": {"times", "values", "interpolation", "file"}}

@dataclass(frozen=True, kw_only=True)
class ModelSpec:
    """Which model a scene uses: ``variant`` and number of modes ``modes`` (the ``[model]``
    table).

    The design model is the one a controller is designed on (used by slew scenes); its
    factors make a controller designed on a model that is off, run against the true plant.

    Parameters
    ----------
    variant : str, optional
        ``"first_order"`` (default), ``"zero_order"``, ``"consistent"``, ``"exact"``, or
        ``"auto"``: first_order where its estimated geometric error meets ``tolerance``,
        exact otherwise (:func:`flexctl.sim.validity.choose_variant`).
    modes : int, dict or str, optional
        Modes per appendage (default 4); a dict ``{name: modes}`` gives each appendage of a
        ``[[appendages]]`` scene its own (every one named, :func:`parse_scene` checks the
        names); ``"auto"``: as few modes as the scene's manoeuvre needs for a relative tip
        error ``tolerance`` (:func:`flexctl.sim.fidelity.choose_modes`).
    design_modes : int or dict, optional
        Modes of the design model per appendage (1 to 200), in the forms of ``modes`` but
        ``"auto"``: one int for every appendage, or ``{name: modes}`` for each of a
        ``[[appendages]]`` scene; each at most the plant's. Default 2.
    design_variant : str, optional
        Variant of the design model. Default None: the exact variant on an exact plant,
        first_order otherwise.
    tolerance : float, optional
        Relative tip error in (0, 1) that ``"auto"`` modes and variant aim at; it also decides
        when a run warns that its model was used out of range. Default None: 1e-2.
    design_stiffness_factor : float, optional
        Scale of the design model's beam bending stiffness ``EI``, in [0.1, 10]. Default 1.
    design_mass_factor : float, optional
        Scale of every point mass of the design model, in [0.1, 10]. Default 1.
    """

    variant: str = "first_order"
    modes: int | str = 4
    design_modes: int | dict = 2
    design_variant: str | None = None
    tolerance: float | None = None
    design_stiffness_factor: float = 1.0
    design_mass_factor: float = 1.0

    def __post_init__(self):
        for key in ("design_stiffness_factor", "design_mass_factor"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not 0.1 <= value <= 10.0:
                raise SceneError(f"model.{key} must be a number in [0.1, 10]; got {value!r}")
            object.__setattr__(self, key, float(value))
        if isinstance(self.design_modes, dict):
            object.__setattr__(self, "design_modes",
                               _modes_table(self.design_modes, "design_modes"))
        elif isinstance(self.design_modes, bool) or not isinstance(self.design_modes, int) \
                or not 1 <= self.design_modes <= 200:
            raise SceneError("model.design_modes must be an integer in [1, 200] or a table "
                             f"{{appendage name = modes}}; got {self.design_modes!r}")
        if self.variant not in VARIANTS + ("auto",):
            raise SceneError(f"model.variant must be one of {', '.join(VARIANTS)} or auto; "
                             f"got {self.variant!r}")
        if self.design_variant is not None and self.design_variant not in VARIANTS:
            raise SceneError(f"model.design_variant must be one of {', '.join(VARIANTS)}; "
                             f"got {self.design_variant!r}")
        tolerance = DEFAULT_TOLERANCE if self.tolerance is None else self.tolerance
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) \
                or not 0.0 < tolerance < 1.0:
            raise SceneError("model.tolerance must be a relative tip error in (0, 1); "
                             f"got {tolerance!r}")
        object.__setattr__(self, "tolerance", float(tolerance))
        if isinstance(self.modes, dict):
            object.__setattr__(self, "modes", _modes_table(self.modes))
            return
        if isinstance(self.modes, str) and self.modes == "auto":
            return
        if isinstance(self.modes, bool) or not isinstance(self.modes, int) \
                or not 1 <= self.modes <= 200:
            raise SceneError("model.modes must be an integer in [1, 200], \"auto\" or a table "
                             f"{{appendage name = modes}}; got {self.modes!r}")

    @property
    def auto(self) -> bool:
        """True when the number of modes is chosen from the manoeuvre."""
        return isinstance(self.modes, str) and self.modes == "auto"


def _modes_table(table: dict, key: str = "modes") -> dict:
    """``model.<key>`` given per appendage, ``{name: modes}``, checked (not yet its names)."""
    if not table:
        raise SceneError(f"model.{key} must give the modes of every appendage, "
                         "{name = modes}; got an empty table")
    for name, n_modes in table.items():
        if isinstance(n_modes, bool) or not isinstance(n_modes, int) or not 1 <= n_modes <= 200:
            raise SceneError(f"model.{key}.{name} must be an integer in [1, 200]; got "
                             f"{n_modes!r}")
    return dict(table)


def _check_exact_modes(n_modes) -> None:
    """The exact variant's limit on the modes of each appendage (an int or ``{name: int}``)."""
    for name, count in (n_modes.items() if isinstance(n_modes, dict) else [("", n_modes)]):
        if count > EXACT_MAX_MODES:
            raise SceneError(f"model.modes{'.' + name if name else ''} must be at most "
                             f"{EXACT_MAX_MODES} for the exact variant (its geometry grows as "
                             "the square of the modes; converge the higher ones on "
                             f"first_order); got {count}")


@dataclass(frozen=True, kw_only=True)
class SimulationSpec:
    """Simulation settings of a scene (the ``[simulation]`` table; see
    :func:`flexctl.simulate`).

    Parameters
    ----------
    t_final : float
        End time, s (at least ``MIN_T_FINAL``).
    output_step : float, optional
        Spacing of the output times, s (> 0). Default: the run's own.
    rtol : float, optional
        Relative tolerance, in [1e-14, 1). Default 1e-8.
    method : str, optional
        Integrator, one of :data:`flexctl.sim.simulation.METHODS`. Default ``"auto"``.
    states : bool, optional
        ``timeseries.csv`` also carries every state (modal coordinates and rates, a free
        hub's velocity, an actuator's states), not only the named outputs. Default False.
    """

    t_final: float
    output_step: float | None = None
    rtol: float = 1e-8
    method: str = "auto"
    #: ``timeseries.csv`` also carries every state (modal coordinates and rates, a free hub's
    #: velocity, an actuator's states), not only the named outputs.
    states: bool = False

    def __post_init__(self):
        if not isinstance(self.states, bool):
            raise SceneError(f"simulation.states must be true or false; got {self.states!r}")
        for key in ("t_final", "output_step", "rtol"):
            value = getattr(self, key)
            if key == "output_step" and value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0 \
                    or value != value or value == float("inf"):
                raise SceneError(f"simulation.{key} must be a positive finite number; "
                                 f"got {value!r}")
        if not 1e-14 <= self.rtol < 1:
            raise SceneError(f"simulation.rtol must lie in [1e-14, 1); got {self.rtol!r}")
        if self.t_final < MIN_T_FINAL:
            raise SceneError(f"simulation.t_final must be at least {MIN_T_FINAL:g} s; "
                             f"got {self.t_final!r}")
        if self.method not in METHODS:
            raise SceneError(f"simulation.method must be one of {', '.join(METHODS)}; "
                             f"got {self.method!r}")


@dataclass(frozen=True, kw_only=True)
class Scene:
    """A validated scene.

    Attributes
    ----------
    name : str
    system : HubBeam or Structure
        A :class:`~flexctl.model.HubBeam` for the one-beam form on a pinned hub, a
        :class:`~flexctl.model.Structure` for ``[[appendages]]`` or a free hub.
    model : ModelSpec
    maneuver : SpinUp, SineTorque, Slew or TorqueSamples
    simulation : SimulationSpec
    controller : ControllerSpec or None
    actuator : ReactionWheel, DCMotor or None
        What turns the hub (``[actuator]``); ``None``: an ideal hub torque.
    sensors : Sensors or None
        What the controller reads (``[sensors]``); ``None``: the exact state.
    requirements : controllers.analysis.requirements.Requirements or None
        What the loop must meet (``[requirements]``), verified after the run
        (:func:`~controllers.analysis.requirements.verify_requirements`); slew scenes with a
        feedback controller only.
    description : str
    data : dict
        The scene's table form (after overrides), as it would be written to TOML.
    """

    name: str
    system: HubBeam | Structure
    model: ModelSpec
    maneuver: object
    simulation: SimulationSpec
    controller: ControllerSpec | None = None
    actuator: object = None
    sensors: object = None
    requirements: object = None
    description: str = ""
    data: dict = field(default_factory=dict, repr=False, compare=False)

    def variant_choice(self) -> VariantChoice | None:
        """Which variant ``variant = "auto"`` takes, and why (None for a named variant).

        Estimated over the scene's horizon (:func:`flexctl.sim.validity.choose_variant`,
        cached).
        """
        if self.model.variant != "auto":
            return None
        return choose_variant(self.system, self.maneuver, self.model.tolerance,
                              t_final=self.simulation.t_final)

    @property
    def variant(self) -> str:
        """The plant's variant (the choice when ``"auto"``)."""
        choice = self.variant_choice()
        return choice.variant if choice is not None else self.model.variant

    @property
    def design_variant(self) -> str:
        """Variant of a controller's design model: ``model.design_variant``, else exact on an
        exact plant and first_order otherwise."""
        if self.model.design_variant is not None:
            return self.model.design_variant
        return "exact" if self.variant == "exact" else "first_order"

    @property
    def design_system(self) -> HubBeam | Structure:
        """The system a controller is designed on: :attr:`system` with every beam's ``EI``
        and every point mass scaled by ``model.design_stiffness_factor`` and
        ``model.design_mass_factor``."""
        stiffness, mass = self.model.design_stiffness_factor, self.model.design_mass_factor
        if stiffness == 1.0 and mass == 1.0:
            return self._with_actuator_hub(self.system)

        def scaled(holder):       # a HubBeam or an Appendage: its beam and masses
            beam = dataclasses.replace(holder.beam, youngs_modulus=holder.beam.youngs_modulus
                                       * stiffness)
            return dataclasses.replace(holder, beam=beam, masses=tuple(
                dataclasses.replace(m, mass=m.mass * mass) for m in holder.masses))

        if isinstance(self.system, Structure):
            system = dataclasses.replace(self.system, appendages=tuple(
                scaled(a) for a in self.system.appendages))
        else:
            system = scaled(self.system)
        return self._with_actuator_hub(system)

    def _with_actuator_hub(self, system):
        """``system`` with the hub the actuator gives it (a DC motor's reflected rotor
        inertia), as the plant's equations carry it."""
        if self.actuator is None:
            return system
        hub = self.actuator.mechanical_hub(system.hub)
        return system if hub is system.hub else dataclasses.replace(system, hub=hub)

    def mode_choice(self) -> ModeChoice | None:
        """How many modes ``modes = "auto"`` takes, and why (None for a fixed number).

        Estimated over the scene's horizon for its manoeuvre and variant
        (:func:`flexctl.sim.fidelity.choose_modes`, cached).
        """
        if not self.model.auto:
            return None
        return choose_modes(self.system, self.maneuver, self.model.tolerance,
                            variant=self.variant, t_final=self.simulation.t_final)

    def build_model(self) -> Model:
        """The model this scene asks for (variant and number of modes chosen when ``"auto"``);
        a structure with named appendages gets its modes by name, ``{name: modes}``."""
        choice = self.mode_choice()
        n_modes = self._per_appendage(choice.n_modes if choice is not None
                                      else self.model.modes)
        if self.variant == "exact":
            _check_exact_modes(n_modes)
        hardware = {} if self.actuator is None else {"actuator": self.actuator}
        return build_model(self.system, n_modes=n_modes, variant=self.variant, **hardware)

    def _per_appendage(self, n_modes):
        """``n_modes`` (an int, ``{name: int}`` or one int per appendage) as ``build_model``
        gets it: by name for a structure with named appendages, else one int."""
        names = self.system.names if isinstance(self.system, Structure) else ("",)
        if not all(names):
            return n_modes
        if isinstance(n_modes, dict):
            return dict(n_modes)
        if isinstance(n_modes, (tuple, list)):
            return dict(zip(names, (int(n) for n in n_modes)))
        return dict.fromkeys(names, int(n_modes))


def builtin_scenes() -> dict:
    """Built-in scenes shipped with the package: ``{name: description}``."""
    out = {}
    for entry in sorted(resources.files("flexctl.app.builtin_scenes").iterdir(), key=str):
        if entry.name.endswith(".toml"):
            data = tomllib.loads(entry.read_text())
            out[entry.name[:-5]] = data.get("description", "")
    return out


#: A list item written ``name[k]`` in an override key.
_INDEX = re.compile(r"\[([^\[\]]*)\]")


def _set_dotted(data: dict, path: str, value):
    """Set ``data[a][b]... = value`` for the dotted ``path``; list items by index.

    A string ``value`` is read as a TOML value when it is one (``"10"`` -> 10).
    """
    if isinstance(path, str):
        path = _INDEX.sub(r".\1", path)      # masses[0].mass is masses.0.mass
    if not isinstance(path, str) or not path or any(not p for p in path.split(".")):
        raise SceneError(f"override key {path!r} is not a dotted path like maneuver.spin_rate")
    if isinstance(value, str):
        try:
            value = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            pass
    parts = path.split(".")
    if len(parts) == 2 and parts[0] == "controller":
        parts[1] = current_name(parts[1])       # a former name warns and takes the new one
    _spread_modes(data, parts)
    node = data
    for depth, key in enumerate(parts[:-1]):
        where = ".".join(parts[:depth + 1])
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                raise SceneError(f"override key {path!r}: {where} is not an index of a list of "
                                 f"{len(node)}")
            node = node[int(key)]
        elif not isinstance(node, dict):
            raise SceneError(f"override key {path!r}: {'.'.join(parts[:depth])} is a "
                             f"{type(node).__name__} value, not a table")
        else:
            if key not in node:
                if key not in _TOP_LEVEL or key == "description":
                    raise SceneError(f"override key {path!r}: unknown table {key!r}")
                node[key] = [] if key in _ARRAYS else {}
            node = node[key]
    last = parts[-1]
    if isinstance(node, list):
        raise SceneError(f"override key {path!r} must index an item of the list, "
                         f"e.g. masses.0.mass")
    if not isinstance(node, dict):
        raise SceneError(f"override key {path!r}: {'.'.join(parts[:-1])} is a "
                         f"{type(node).__name__} value, not a table")
    node[last] = value


def _spread_modes(data: dict, parts: list) -> None:
    """Before ``model.modes.<name>`` (or ``model.design_modes.<name>``) is set on a scene whose
    modes are one number: that number for every appendage, as the table of which one entry is
    then set."""
    if len(parts) != 3 or parts[0] != "model" or parts[1] not in ("modes", "design_modes"):
        return
    key = parts[1]
    model, appendages = data.get("model", {}), data.get("appendages")
    modes = model.get(key, getattr(ModelSpec, key)) if isinstance(model, dict) else None
    if isinstance(modes, bool) or not isinstance(modes, int) or not isinstance(appendages, list):
        return
    names = [a.get("name") if isinstance(a, dict) else None for a in appendages]
    if names and all(isinstance(n, str) for n in names):
        data["model"] = {**model, key: dict.fromkeys(names, modes)}


def parse_scene(data: dict, name: str = "scene", base_dir=None) -> Scene:
    """Validate a scene given as nested dictionaries (the TOML tables).

    Parameters
    ----------
    data : dict
        The scene's tables.
    name : str, optional
        The scene's name, used in messages and output names. Default ``"scene"``.
    base_dir : str or path-like, optional
        Directory a relative ``maneuver.file`` is read from (the scene file's); default the
        working directory. The samples read replace ``file`` in :attr:`Scene.data`, so that
        the scene's table runs without the file.

    Raises
    ------
    SceneError
        On an unknown key, a missing table or key, or a bad value; the message names the key.
    """
    data = copy.deepcopy(data)
    _check_keys(data)
    system = _system(data)
    model = _construct(ModelSpec, "model", _table(data, "model", required=False))
    _check_modes(model, system)
    maneuver = _maneuver(data, base_dir)
    sim_table = _table(data, "simulation")
    if "t_final" not in sim_table:
        raise SceneError("simulation.t_final is required")
    simulation = _construct(SimulationSpec, "simulation", sim_table)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SceneError(f"description must be a string; got {description!r}")
    actuator, sensors = _hardware(data, system, maneuver)
    controller = None
    if "controller" in data:
        # the table as written to summary.json's scene_table carries the current names
        table = current_names(_table(data, "controller"))
        data["controller"] = dict(table)
        controller = ControllerSpec(kind=table.pop("kind", None), settings=table)
    if isinstance(maneuver, Slew) and controller is None:
        raise SceneError("maneuver.kind 'slew' needs a [controller] table")
    if controller is not None and not isinstance(maneuver, Slew):
        raise SceneError("a [controller] table needs maneuver.kind 'slew'; got "
                         f"{data['maneuver'].get('kind')!r}")
    if sensors is not None and controller is None:
        raise SceneError("[sensors] are read by a controller: they need maneuver.kind 'slew' "
                         "with a [controller] table")
    return Scene(name=name, system=system, model=model, maneuver=maneuver,
                 simulation=simulation, controller=controller, actuator=actuator,
                 sensors=sensors, requirements=_requirements(data, controller),
                 description=description, data=data)


def _requirements(data: dict, controller):
    """The scene's ``[requirements]``, or None; a feedback controller's loop only."""
    if "requirements" not in data:
        return None
    from controllers.analysis.requirements import Requirements
    from controllers.spec import OPEN_LOOP_KINDS

    if controller is None or controller.kind in OPEN_LOOP_KINDS + ("nmpc",):
        raise SceneError("[requirements] are verified on a linear feedback loop: they need a "
                         "slew with controller.kind pd, lqr, lqg, scheduled or trajopt+lqr "
                         "(an NMPC's loop has no linear form); got "
                         f"{getattr(controller, 'kind', None)!r}")
    table = dict(_table(data, "requirements"))
    if isinstance(table.get("damping_range"), list):
        table["damping_range"] = tuple(table["damping_range"])
    return _construct(Requirements, "requirements", table)


def _hardware(data: dict, system, maneuver) -> tuple:
    """``(actuator, sensors)`` of the scene's ``[actuator]`` and ``[sensors]`` tables."""
    actuator = parse_actuator(data["actuator"]) if "actuator" in data else None
    sensors = parse_sensors(data["sensors"]) if "sensors" in data else None
    if actuator is not None:
        if isinstance(maneuver, SpinUp):
            raise SceneError("maneuver.kind 'spin_up' prescribes the hub's motion, which no "
                             "actuator drives; remove [actuator] or drive the hub by a torque")
        free = system.free if isinstance(system, Structure) else system.hub.free
        if actuator.kind == "dc_motor" and free:
            raise SceneError("actuator.kind 'dc_motor' turns the hub against the ground and "
                             "needs hub.support = \"pinned\"; a free hub is turned by a "
                             "reaction_wheel")
    return actuator, sensors


def _check_keys(data: dict) -> None:
    """Every key of the scene's tables (but [[appendages]], see ``_appendage``) known."""
    for key in data:
        if key not in _TOP_LEVEL:
            raise SceneError(f"unknown scene key {key!r}; expected one of "
                             f"{', '.join(sorted(_TOP_LEVEL))}")
    for key, allowed in _SCHEMA.items():
        if allowed is None or key not in data:
            continue
        if key == "masses":
            tables = _array_of_tables(data["masses"], "masses")
        else:
            tables = [(key, _table(data, key))]
        for where, table in tables:
            _check_table_keys(where, table, allowed)


def _array_of_tables(items, where: str) -> list:
    """``[(where.k, table)]`` of an array of tables ``[[where]]``."""
    if not isinstance(items, list):
        raise SceneError(f"scene key {where!r} must be an array of tables [[{where}]]")
    return [(f"{where}.{k}", t) for k, t in enumerate(items)]


def _system(data: dict) -> HubBeam | Structure:
    """The hub and what it carries: a HubBeam for the one-beam form on a pinned hub, else a
    Structure."""
    hub_table = _table(data, "hub")
    hub = _construct(Hub, "hub", hub_table)
    if hub.free and "mass" not in hub_table:
        raise SceneError("hub.mass is required when hub.support = \"free\" (the mass of the hub "
                         "alone, kg: it moves with the hub)")
    if "appendages" in data:
        if "beam" in data or "masses" in data:
            raise SceneError("a scene gives either [beam] and [[masses]] (one beam) or "
                             "[[appendages]]; got both (write the beam as one [[appendages]])")
        return _structure(hub, data["appendages"])
    if "beam" not in data:
        raise SceneError("scene is missing the [beam] table (or [[appendages]])")
    beam = _construct(Beam, "beam", _table(data, "beam"))
    masses = [_construct(PointMass, f"masses.{k}", t) for k, t in
              enumerate(data.get("masses", []))]
    for k, m in enumerate(masses):
        if m.position > beam.length:
            raise SceneError(f"masses.{k}.position must lie in [0, beam.length = "
                             f"{beam.length:g}]; got {m.position!r}")
    try:
        system = HubBeam(hub=hub, beam=beam, masses=masses)
    except (ValueError, TypeError) as exc:
        raise SceneError(str(exc)) from None
    return Structure.from_hub_beam(system) if hub.free else system


def _structure(hub: Hub, items) -> Structure:
    """The [[appendages]] on ``hub``."""
    tables = _array_of_tables(items, "appendages")
    if not 1 <= len(tables) <= MAX_APPENDAGES:
        raise SceneError(f"appendages must hold 1 to {MAX_APPENDAGES} [[appendages]] tables; "
                         f"got {len(tables)}")
    appendages, seen = [], {}
    for where, table in tables:
        appendage = _appendage(where, table)
        if appendage.name in seen:
            raise SceneError(f"{where}.name must be unique; {appendage.name!r} is already the "
                             f"name of appendages.{seen[appendage.name]}")
        seen[appendage.name] = where.rpartition(".")[2]
        appendages.append(appendage)
    try:
        return Structure(hub=hub, appendages=appendages)
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        for k, a in enumerate(appendages):
            if a.radius is None:        # its root is at the hub radius
                msg = msg.replace(f"appendage {a.name!r}.radius", "hub.radius")
            msg = msg.replace(f"appendage {a.name!r}.beam.", f"appendages.{k}.")
            msg = msg.replace(f"appendage {a.name!r}", f"appendages.{k}")
        raise SceneError(msg) from None


def _appendage(where: str, table) -> Appendage:
    """One [[appendages]] table: name, mounting angle (degrees) and radius, beam, masses."""
    _check_table_keys(where, table, _APPENDAGE_KEYS)
    if "name" not in table:
        raise SceneError(f"{where}.name is required: an identifier that names the appendage's "
                         "states and outputs")
    name = table["name"]
    if isinstance(name, str) and not name:
        raise SceneError(f"{where}.name must be an identifier (letters, digits and "
                         "underscores, not starting with a digit); got ''")
    try:
        angle = check_real(where, "angle_deg", table.get("angle_deg", 0.0))
    except (ValueError, TypeError) as exc:
        raise SceneError(f"{exc} (degrees)") from None
    if not abs(math.radians(angle)) <= MAX_ANGLE:
        raise SceneError(f"{where}.angle_deg must be at most {math.degrees(MAX_ANGLE):g} "
                         f"degrees in magnitude; got {angle!r}")
    beam = _construct(Beam, "beam", {k: v for k, v in table.items() if k in _SCHEMA["beam"]},
                      rename=where)
    masses = []
    for key, mass_table in _array_of_tables(table.get("masses", []), f"{where}.masses"):
        _check_table_keys(key, mass_table, _SCHEMA["masses"])
        masses.append(_construct(PointMass, key, mass_table))
    for k, m in enumerate(masses):
        if m.position > beam.length:
            raise SceneError(f"{where}.masses.{k}.position must lie in [0, {where}.length = "
                             f"{beam.length:g}]; got {m.position!r}")
    try:
        return Appendage(name=name, beam=beam, masses=masses, angle=math.radians(angle),
                         radius=table.get("radius"))
    except (ValueError, TypeError) as exc:
        msg = str(exc).replace("appendage.name", f"{where}.name")
        raise SceneError(msg.replace(f"appendage {name!r}", where)) from None


def _check_modes(model: ModelSpec, system) -> None:
    """A table of modes names exactly the appendages; the exact variant's limit."""
    names = system.names if isinstance(system, Structure) else ("",)
    for field_name in ("modes", "design_modes"):
        table = getattr(model, field_name)
        if not isinstance(table, dict):
            continue
        if not all(names):
            raise SceneError(f"model.{field_name} may be a table {{appendage name = modes}} "
                             f"only with [[appendages]]; got {table!r}")
        for key in table:
            if key not in names:
                raise SceneError(f"model.{field_name}.{key} names no appendage; expected "
                                 f"{', '.join(names)}")
        for key in names:
            if key not in table:
                raise SceneError(f"model.{field_name}.{key} is missing: a table of modes gives "
                                 f"every appendage ({', '.join(names)}); got "
                                 f"{', '.join(table)}")
    if model.variant == "exact" and not model.auto:
        _check_exact_modes(model.modes)


def _maneuver(data: dict, base_dir):
    """The [maneuver] table's manoeuvre; a torque file's samples replace ``file`` in
    ``data``."""
    table = dict(_table(data, "maneuver"))
    kind = table.pop("kind", None)
    if not isinstance(kind, str) or kind not in _MANEUVERS:
        raise SceneError(f"maneuver.kind must be one of {', '.join(_MANEUVERS)}; got {kind!r}")
    for key in table:
        if key not in _MANEUVER_KEYS[kind]:
            raise SceneError(f"maneuver.{key} does not apply to kind {kind!r}; expected "
                             f"{', '.join(sorted(_MANEUVER_KEYS[kind]))}")
    missing = _MANEUVER_KEYS[kind] - _MANEUVER_OPTIONAL.get(kind, set()) - set(table)
    if missing:
        raise SceneError(f"maneuver.{sorted(missing)[0]} is required for kind {kind!r}")
    make = _MANEUVERS[kind]
    if make is _torque_samples:
        make = functools.partial(make, base_dir=base_dir)
    maneuver = _construct(make, "maneuver", table)
    if isinstance(maneuver, TorqueSamples) and "file" in table:
        # the samples read stand in for the file: summary.json's scene_table runs without it
        data["maneuver"] = {"kind": kind, "times": maneuver.times.tolist(),
                            "values": maneuver.values.tolist(),
                            "interpolation": maneuver.interpolation}
    return maneuver


def load_scene(source, overrides: dict | None = None) -> Scene:
    """Load a scene from a TOML file or a built-in name, with optional overrides.

    Parameters
    ----------
    source : str or path-like
        A path to a ``.toml`` file, a run's ``summary.json`` (the scene as it was run, from
        its ``scene_table``), or the name of a built-in scene (:func:`builtin_scenes`).
    overrides : dict, optional
        ``{"dotted.key": value}``; string values are read as TOML values (``"10"`` -> 10,
        ``"zero_order"`` stays a string), e.g. ``{"maneuver.spin_rate": "10"}``.

    Returns
    -------
    Scene
    """
    if not isinstance(source, (str, os.PathLike)) or isinstance(source, bytes):
        raise InputTypeError(f"scene must be a path or a built-in scene name; got "
                             f"{type(source).__name__}")
    if overrides is not None and not isinstance(overrides, dict):
        raise InputTypeError("overrides must be a dict {\"dotted.key\": value}; got "
                             f"{type(overrides).__name__}")
    path = Path(source)
    if not str(source).strip() or "\0" in str(source):
        raise SceneError(f"scene must name a TOML file, a summary.json or a built-in scene; "
                         f"got {str(source)!r}")
    try:
        is_file = path.is_file()
    except OSError as exc:      # a name too long for the file system
        raise SceneError(f"scene {str(source)[:80]!r} cannot be read: "
                         f"{exc.strerror or exc}") from None
    base_dir = None
    if path.suffix == ".json":
        data, name = _summary_scene(path)
        base_dir = path.parent
    elif path.suffix == ".toml" or is_file:
        if not path.is_file():
            raise SceneError(f"scene file {str(path)!r} does not exist")
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as exc:
            raise SceneError(f"scene file {str(path)!r} is not valid TOML: {exc}") from None
        except UnicodeDecodeError as exc:
            raise SceneError(f"scene file {str(path)!r} must be UTF-8 text (TOML); byte "
                             f"{exc.object[exc.start]:#04x} at offset {exc.start} is not "
                             "UTF-8") from None
        except OSError as exc:
            raise SceneError(f"scene file {str(path)!r} cannot be read: "
                             f"{exc.strerror or exc}") from None
        name, base_dir = path.stem, path.parent
    else:
        names = builtin_scenes()
        if str(source) not in names:
            what = "a directory, not a scene file" if path.is_dir() else \
                "neither a file nor a built-in scene"
            raise SceneError(f"scene {str(source)[:200]!r} is {what} ({', '.join(names)})")
        name = str(source)
        data = tomllib.loads(
            resources.files("flexctl.app.builtin_scenes").joinpath(f"{name}.toml").read_text())
    if isinstance(data.get("controller"), dict):
        # former names first, so that an override under either name replaces the file's value
        data["controller"] = current_names(data["controller"])
    _check_setting_once(overrides or {})
    for key, value in (overrides or {}).items():
        _set_dotted(data, key, value)
    from .spatial_scene import is_spatial, parse_spatial_scene
    if is_spatial(data):            # a 3 x 3 hub inertia: a structure turning about any axis
        return parse_spatial_scene(data, name=name, base_dir=base_dir)
    return parse_scene(data, name=name, base_dir=base_dir)


def _check_setting_once(overrides: dict) -> None:
    """Refuse overrides that set one controller setting under its current and its former
    name (the later one would win unseen; a scene file giving both is refused too)."""
    seen = {}
    for key in overrides:
        if not isinstance(key, str) or not key.startswith("controller."):
            continue
        setting = key[len("controller."):]
        current = FORMER_NAMES.get(setting, setting)
        if current in seen and seen[current] != key:
            raise SceneError(f"override keys {seen[current]!r} and {key!r} set the same setting "
                             f"controller.{current} (one is its former name); give it once")
        seen[current] = key


def _summary_scene(path: Path) -> tuple:
    """The scene table and name recorded in a run's ``summary.json``."""
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SceneError(f"summary file {str(path)!r} cannot be read: "
                         f"{exc.strerror or exc}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SceneError(f"summary file {str(path)!r} is not valid JSON: {exc}") from None
    table = summary.get("scene_table") if isinstance(summary, dict) else None
    if not isinstance(table, dict):
        raise SceneError(f"summary file {str(path)!r} has no scene_table (a run's summary.json "
                         "records the scene it ran under that key)")
    name = summary.get("scene")
    return table, name if isinstance(name, str) and name else path.parent.name


def run_scene(scene: Scene, controller=None, model: Model | None = None, *,
              progress=None) -> SimulationResult:
    """Simulate a scene with the model and settings it names.

    Parameters
    ----------
    scene : Scene
        The scene: system, manoeuvre and simulation settings.
    controller : object, optional
        The controller built from ``scene.controller`` (``controllers.from_spec``); required
        for a slew scene, which is a goal for a controller rather than an input.
    model : Model, optional
        ``scene.build_model()`` when already built.
    progress : bool or callable, optional
        As for :func:`flexctl.simulate`.

    Returns
    -------
    SimulationResult
        With ``validity`` (:class:`flexctl.sim.validity.ModelValidity`): the deflection
        reached and the estimated geometric error of the model; a
        :class:`~flexctl.sim.validity.ModelValidityWarning` is issued when a small-deflection
        variant was used where that error is above ``model.tolerance``.
    """
    model = scene.build_model() if model is None else model
    sim = scene.simulation
    if isinstance(scene.maneuver, Slew):
        if controller is None:
            raise SceneError(f"scene {scene.name!r} is a slew: pass the controller built from "
                             "its [controller] table (controllers.from_spec)")
        drive = {"controller": controller}
        if getattr(controller, "measures", False):
            drive["sensors"] = scene.sensors
    elif isinstance(scene.maneuver, SpinUp):
        drive = {"hub_motion": scene.maneuver}
    elif getattr(model, "actuator", None) is not None and model.actuator.kind == "dc_motor":
        # the manoeuvre's hub torque, asked of the motor as the voltage that gives it
        from controllers.feedback.actuated import through_actuator
        from controllers.factory import OpenLoop
        drive = {"controller": through_actuator(OpenLoop(scene.maneuver), model)}
    else:
        drive = {"torque": scene.maneuver}
    # simulate's run, assessed with the scene's own tolerance
    return run_assessed(model, sim.t_final, rtol=sim.rtol, method=sim.method,
                        output_step=sim.output_step, progress=progress,
                        tolerance=scene.model.tolerance, **drive)


#: Modes added to each appendage of the plant for the reference run of the metrics' errors.
REFERENCE_EXTRA_MODES = 2


def run_slew(scene: Scene, controller_factory=None, *, progress=None,
             error_estimate: bool = True):
    """Design a slew scene's controller, run it against the scene's plant, measure the slew.

    Parameters
    ----------
    scene : Scene
        A slew scene (``maneuver.kind = "slew"`` with a ``[controller]`` table).
    controller_factory : callable, optional
        ``factory(scene, plant)`` returning an object with ``controller`` and
        ``maneuver_end``; default ``controllers.from_spec`` (the scene's ``[controller]``
        table).
    progress : bool or callable, optional
        As for :func:`flexctl.simulate` (the closed-loop run).
    error_estimate : bool, optional
        Give each metric its error (``metrics.errors``,
        :func:`flexctl.sim.metrics.metric_errors`): the same closed loop is run again on the
        plant with :data:`REFERENCE_EXTRA_MODES` more modes per appendage and exact geometry
        (mode truncation and geometry), and the run's accuracy check adds the integration error.
        Default True; False saves that run.

    Returns
    -------
    result : SimulationResult
    built : object
        What the factory returned.
    metrics : SlewMetrics
        Residual vibration measured after ``built.maneuver_end``; ``metrics.errors`` with
        ``error_estimate`` (None when the reference run stopped early).
    """
    if not isinstance(scene.maneuver, Slew):
        raise SceneError(f"scene {scene.name!r} is not a slew; got maneuver "
                         f"{type(scene.maneuver).__name__}")
    if controller_factory is None:
        from controllers import from_spec as controller_factory
    plant = scene.build_model()
    built = controller_factory(scene, plant)
    _check_slew_fits(scene, built)
    result = run_scene(scene, controller=built.controller, model=plant, progress=progress)
    metrics = slew_metrics(result, scene.maneuver.angle, built.maneuver_end)
    if error_estimate and result.status == "ok":
        errors = _metric_errors(scene, plant, built, result)
        metrics = dataclasses.replace(metrics, errors=errors)
    return result, built, metrics


def _reference_plant(plant: Model, validity) -> Model:
    """The plant with :data:`REFERENCE_EXTRA_MODES` more modes per appendage (within what the
    exact variant builds), and exact geometry unless the run's tip stayed in the range where
    its small-deflection variant's geometric error is bounded without runs
    (``validity.screened``)."""
    from ..model.build import rebuild

    spec = plant.mode_spec
    more = (min(spec + REFERENCE_EXTRA_MODES, EXACT_MAX_MODES) if isinstance(spec, int)
            else tuple(min(n + REFERENCE_EXTRA_MODES, EXACT_MAX_MODES) for n in spec))
    small = validity is not None and validity.screened
    return rebuild(plant, n_modes=more, variant=plant.variant if small else "exact")


def _metric_errors(scene: Scene, plant: Model, built, result):
    """:func:`~flexctl.sim.metrics.metric_errors` of a slew run, from its closed loop on
    ``_reference_plant``; None when that run does not finish."""
    import warnings

    from ..sim.metrics import metric_errors

    reference_plant = _reference_plant(plant, result.validity)
    law = built.controller
    if callable(getattr(law, "for_plant", None)):      # read the reference plant's sensors
        law = law.for_plant(reference_plant)
    drive = {"controller": law}
    if getattr(law, "measures", False):
        drive["sensors"] = scene.sensors
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # the run itself said what there is to say
        reference = simulate(reference_plant, scene.simulation.t_final,
                             rtol=scene.simulation.rtol, method=scene.simulation.method,
                             output_step=scene.simulation.output_step, check_accuracy=False,
                             check_validity=False, **drive)
    if reference.status != "ok" or reference.t.shape != result.t.shape:
        return None
    geometry = 0.0
    if not reference_plant.variant.exact:     # the screen's bound, as the validity states it
        geometry = result.validity.geometric_error * result.peak_tip_deflection
    return metric_errors(result, reference, scene.maneuver.angle, built.maneuver_end,
                         geometry=geometry)


def _check_slew_fits(scene: Scene, built) -> None:
    """A slew that ends after ``t_final`` (e.g. a reference stretched to what a small torque
    bound allows) would report a hub that never got there as a finished run: refuse it."""
    t_final, end = scene.simulation.t_final, float(built.maneuver_end)
    if end > t_final:
        why = built.info.get("note") if isinstance(getattr(built, "info", None), dict) else None
        raise SceneError(f"simulation.t_final must be at least the {end:.4g} s the "
                         f"{getattr(built, 'kind', 'controller')} slew needs"
                         f"{f' ({why})' if why else ''}; got {t_final:g} s")
