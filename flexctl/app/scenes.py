"""Scenes: a system, a model choice, a manoeuvre and simulation settings in one TOML file.

Format (every table but ``[[masses]]`` and ``[maneuver]`` keys is required as shown)::

    description = "free text"            # optional

    [hub]                                # Hub fields
    inertia = 1.16
    radius = 0.06
    friction = 0.0                       # optional

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

    [model]
    variant = "first_order"              # first_order | zero_order | consistent | exact, or
                                         # "auto": first_order where its geometric error meets
                                         # the tolerance, else exact (flexctl.sim.validity)
    modes = 4                            # or "auto": as few as the manoeuvre needs, see
                                         # flexctl.sim.fidelity.choose_modes
    # tolerance = 1e-2                   # optional: relative tip error for the "auto" choices
                                         # and for the model-validity warning
    design_modes = 2                     # optional: modes of a controller's design model
    # design_variant = "exact"           # optional: variant of the design model; default
                                         # exact on an exact plant, else first_order

    [maneuver]
    kind = "sine_torque"                 # peak_torque, duration
    # kind = "spin_up"                   # spin_rate, ramp_time
    # kind = "slew"                      # angle_deg, duration (s or "free"), torque_bound

    [controller]                         # slew scenes only: kind and its settings
    kind = "trajopt+lqr"                 # see controllers.factory for kinds and settings

    [simulation]
    t_final = 20.0
    output_step = 0.01                   # optional
    rtol = 1e-8                          # optional
    method = "auto"                      # optional: auto | cvodes | a solve_ivp method

Unknown keys and bad values raise :class:`SceneError` naming the key.

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
import json
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

# the controller kinds and their settings belong to the controllers package
from controllers.spec import (CONTROLLER_KEYS, ControllerSpec, SceneError, current_name,
                              current_names)

from ..sim.fidelity import DEFAULT_TOLERANCE, ModeChoice, choose_modes
from ..sim.maneuvers import SineTorque, Slew, SpinUp
from ..sim.metrics import slew_metrics
from ..model import VARIANTS, Model, build_model
from ..model.variants import EXACT_MAX_MODES
from ..model.errors import InputTypeError, InputValueError
from ..model.parameters import Beam, Hub, HubBeam, PointMass
from ..sim.simulation import METHODS, MIN_T_FINAL, SimulationResult, simulate
from ..sim.validity import VariantChoice, assess, choose_variant

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


_MANEUVERS = {"spin_up": SpinUp, "sine_torque": SineTorque, "slew": _slew}
_SCHEMA = {
    "description": None,
    "hub": {"inertia", "radius", "friction"},
    "beam": {"length", "density", "area", "second_moment", "youngs_modulus", "damping_ratio"},
    "masses": {"mass", "position"},
    "model": {"variant", "modes", "design_modes", "design_variant", "tolerance",
              "design_stiffness_factor", "design_mass_factor"},
    "maneuver": {"kind", "spin_rate", "ramp_time", "peak_torque", "duration", "angle_deg",
                 "torque_bound"},
    "simulation": {"t_final", "output_step", "rtol", "method"},
    "controller": None,
}
_MANEUVER_KEYS = {"spin_up": {"spin_rate", "ramp_time"},
                  "sine_torque": {"peak_torque", "duration"},
                  "slew": {"angle_deg", "duration", "torque_bound"}}
_MANEUVER_OPTIONAL = {"slew": {"duration", "torque_bound"}}

@dataclass(frozen=True, kw_only=True)
class ModelSpec:
    """Which model a scene uses: ``variant`` and number of modes ``modes``.

    ``modes`` may be ``"auto"``: as few modes as the scene's manoeuvre needs for a relative tip
    error ``tolerance`` in (0, 1) (default 1e-2; :func:`flexctl.sim.fidelity.choose_modes`).
    ``variant`` may be ``"auto"``: first_order where its estimated geometric error meets
    ``tolerance``, exact otherwise (:func:`flexctl.sim.validity.choose_variant`). The same
    ``tolerance`` decides when a run warns that its model was used out of range.

    ``design_modes`` and ``design_variant`` describe the model a controller is designed on
    (default 2 modes; the exact variant on an exact plant, first_order otherwise; used by slew
    scenes). ``design_stiffness_factor`` and ``design_mass_factor`` (default 1, in [0.1, 10])
    scale the beam's bending stiffness ``EI`` and every point mass of the design model only:
    a controller designed on a model that is off, run against the true plant.
    """

    variant: str = "first_order"
    modes: int | str = 4
    design_modes: int = 2
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
        if isinstance(self.design_modes, bool) or not isinstance(self.design_modes, int) \
                or not 1 <= self.design_modes <= 200:
            raise SceneError("model.design_modes must be an integer in [1, 200]; got "
                             f"{self.design_modes!r}")
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
        if self.modes == "auto":
            return
        if isinstance(self.modes, bool) or not isinstance(self.modes, int) \
                or not 1 <= self.modes <= 200:
            raise SceneError("model.modes must be an integer in [1, 200] or \"auto\"; "
                             f"got {self.modes!r}")

    @property
    def auto(self) -> bool:
        """True when the number of modes is chosen from the manoeuvre."""
        return self.modes == "auto"


@dataclass(frozen=True, kw_only=True)
class SimulationSpec:
    """Simulation settings of a scene (see :func:`flexctl.simulate`)."""

    t_final: float
    output_step: float | None = None
    rtol: float = 1e-8
    method: str = "auto"

    def __post_init__(self):
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
    system : HubBeam
    model : ModelSpec
    maneuver : SpinUp, SineTorque or Slew
    simulation : SimulationSpec
    controller : ControllerSpec or None
    description : str
    data : dict
        The scene's table form (after overrides), as it would be written to TOML.
    """

    name: str
    system: HubBeam
    model: ModelSpec
    maneuver: object
    simulation: SimulationSpec
    controller: ControllerSpec | None = None
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
    def design_system(self) -> HubBeam:
        """The system a controller is designed on: :attr:`system` with the beam's ``EI`` and
        the point masses scaled by ``model.design_stiffness_factor`` and
        ``model.design_mass_factor``."""
        stiffness, mass = self.model.design_stiffness_factor, self.model.design_mass_factor
        if stiffness == 1.0 and mass == 1.0:
            return self.system
        beam = dataclasses.replace(self.system.beam, youngs_modulus=self.system.beam
                                   .youngs_modulus * stiffness)
        masses = tuple(dataclasses.replace(m, mass=m.mass * mass) for m in self.system.masses)
        return dataclasses.replace(self.system, beam=beam, masses=masses)

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
        """The model this scene asks for (variant and number of modes chosen when ``"auto"``)."""
        choice = self.mode_choice()
        n_modes = choice.n_modes if choice is not None else self.model.modes
        if self.variant == "exact" and n_modes > EXACT_MAX_MODES:
            raise SceneError(f"model.modes must be at most {EXACT_MAX_MODES} for the exact "
                             "variant (its geometry grows as the square of the modes; converge "
                             f"the higher ones on first_order); got {n_modes}")
        return build_model(self.system, n_modes=n_modes, variant=self.variant)


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
                if key not in _SCHEMA or key == "description":
                    raise SceneError(f"override key {path!r}: unknown table {key!r}")
                node[key] = [] if key == "masses" else {}
            node = node[key]
    last = parts[-1]
    if isinstance(node, list):
        raise SceneError(f"override key {path!r} must index an item of the list, "
                         f"e.g. masses.0.mass")
    if not isinstance(node, dict):
        raise SceneError(f"override key {path!r}: {'.'.join(parts[:-1])} is a "
                         f"{type(node).__name__} value, not a table")
    node[last] = value


def _table(data: dict, name: str, required: bool = True) -> dict:
    table = data.get(name)
    if table is None:
        if required:
            raise SceneError(f"scene is missing the [{name}] table")
        return {}
    if not isinstance(table, dict):
        raise SceneError(f"scene key {name!r} must be a table; got {type(table).__name__}")
    return table


def _construct(cls, key: str, kwargs: dict):
    try:
        return cls(**kwargs)
    except SceneError:
        raise
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        for prefix in ("hub.", "beam.", "mass.", "maneuver."):
            if msg.startswith(prefix):
                msg = msg[len(prefix):]
        raise SceneError(f"{key}.{msg}") from None


def parse_scene(data: dict, name: str = "scene") -> Scene:
    """Validate a scene given as nested dictionaries (the TOML tables).

    Raises
    ------
    SceneError
        On an unknown key, a missing table or key, or a bad value; the message names the key.
    """
    data = copy.deepcopy(data)
    for key in data:
        if key not in _SCHEMA:
            raise SceneError(f"unknown scene key {key!r}; expected one of "
                             f"{', '.join(sorted(_SCHEMA))}")
    for key, allowed in _SCHEMA.items():
        if allowed is None or key not in data:
            continue
        items = data[key]
        if key == "masses":
            if not isinstance(items, list):
                raise SceneError("scene key 'masses' must be an array of tables [[masses]]")
            tables = [(f"masses.{k}", t) for k, t in enumerate(items)]
        else:
            tables = [(key, _table(data, key))]
        for where, table in tables:
            if not isinstance(table, dict):
                raise SceneError(f"scene key {where!r} must be a table")
            for sub in table:
                if sub not in allowed:
                    raise SceneError(f"unknown scene key '{where}.{sub}'; expected one of "
                                     f"{', '.join(sorted(allowed))}")

    hub = _construct(Hub, "hub", _table(data, "hub"))
    beam = _construct(Beam, "beam", _table(data, "beam"))
    masses = [_construct(PointMass, f"masses.{k}", t) for k, t in
              enumerate(data.get("masses", []))]
    for k, m in enumerate(masses):
        if m.position > beam.length:
            raise SceneError(f"masses.{k}.position must lie in [0, beam.length = "
                             f"{beam.length:g}]; got {m.position!r}")
    system = HubBeam(hub=hub, beam=beam, masses=masses)
    model = _construct(ModelSpec, "model", _table(data, "model", required=False))

    maneuver_table = dict(_table(data, "maneuver"))
    kind = maneuver_table.pop("kind", None)
    if not isinstance(kind, str) or kind not in _MANEUVERS:
        raise SceneError(f"maneuver.kind must be one of {', '.join(_MANEUVERS)}; got {kind!r}")
    for key in maneuver_table:
        if key not in _MANEUVER_KEYS[kind]:
            raise SceneError(f"maneuver.{key} does not apply to kind {kind!r}; expected "
                             f"{', '.join(sorted(_MANEUVER_KEYS[kind]))}")
    missing = _MANEUVER_KEYS[kind] - _MANEUVER_OPTIONAL.get(kind, set()) - set(maneuver_table)
    if missing:
        raise SceneError(f"maneuver.{sorted(missing)[0]} is required for kind {kind!r}")
    maneuver = _construct(_MANEUVERS[kind], "maneuver", maneuver_table)

    sim_table = _table(data, "simulation")
    if "t_final" not in sim_table:
        raise SceneError("simulation.t_final is required")
    simulation = _construct(SimulationSpec, "simulation", sim_table)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SceneError(f"description must be a string; got {description!r}")
    controller = None
    if "controller" in data:
        # the table as written to summary.json's scene_table carries the current names
        table = current_names(_table(data, "controller"))
        data["controller"] = dict(table)
        controller = ControllerSpec(kind=table.pop("kind", None), settings=table)
    if isinstance(maneuver, Slew) and controller is None:
        raise SceneError("maneuver.kind 'slew' needs a [controller] table")
    if controller is not None and not isinstance(maneuver, Slew):
        raise SceneError(f"a [controller] table needs maneuver.kind 'slew'; got {kind!r}")
    return Scene(name=name, system=system, model=model, maneuver=maneuver,
                 simulation=simulation, controller=controller, description=description,
                 data=data)


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
    if path.suffix == ".json":
        data, name = _summary_scene(path)
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
        name = path.stem
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
    for key, value in (overrides or {}).items():
        _set_dotted(data, key, value)
    return parse_scene(data, name=name)


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
    controller : optional
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
    elif isinstance(scene.maneuver, SpinUp):
        drive = {"hub_motion": scene.maneuver}
    else:
        drive = {"torque": scene.maneuver}
    result = simulate(model, sim.t_final, rtol=sim.rtol, method=sim.method,
                      output_step=sim.output_step, progress=progress, **drive)
    validity = assess(result, tolerance=scene.model.tolerance, **drive)
    return dataclasses.replace(result, validity=validity)


def run_slew(scene: Scene, controller_factory, *, progress=None):
    """Design a slew scene's controller, run it against the scene's plant, measure the slew.

    Parameters
    ----------
    scene : Scene
        A slew scene (``maneuver.kind = "slew"`` with a ``[controller]`` table).
    controller_factory : callable
        ``factory(scene, plant)`` returning an object with ``controller`` and
        ``maneuver_end`` (``controllers.from_spec``), passed in so that a caller can
        give another factory.
    progress : bool or callable, optional
        As for :func:`flexctl.simulate` (the closed-loop run).

    Returns
    -------
    result : SimulationResult
    built : object
        What the factory returned.
    metrics : SlewMetrics
        Residual vibration measured after ``built.maneuver_end``.
    """
    if not isinstance(scene.maneuver, Slew):
        raise SceneError(f"scene {scene.name!r} is not a slew; got maneuver "
                         f"{type(scene.maneuver).__name__}")
    plant = scene.build_model()
    built = controller_factory(scene, plant)
    _check_slew_fits(scene, built)
    result = run_scene(scene, controller=built.controller, model=plant, progress=progress)
    return result, built, slew_metrics(result, scene.maneuver.angle, built.maneuver_end)


def _check_slew_fits(scene: Scene, built) -> None:
    """A slew that ends after ``t_final`` (e.g. a reference stretched to what a small torque
    bound allows) would report a hub that never got there as a finished run: refuse it."""
    t_final, end = scene.simulation.t_final, float(built.maneuver_end)
    if end > t_final:
        why = built.info.get("note") if isinstance(getattr(built, "info", None), dict) else None
        raise SceneError(f"simulation.t_final must be at least the {end:.4g} s the "
                         f"{getattr(built, 'kind', 'controller')} slew needs"
                         f"{f' ({why})' if why else ''}; got {t_final:g} s")
