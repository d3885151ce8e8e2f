"""Scenes of several appendages on a pinned or free hub, and torque given as samples.

Contracts of the ``[[appendages]]`` form (what it builds, every bad input refused by a
:class:`SceneError` naming its key, overrides, round trips through the scene's table and
``summary.json``), of :class:`~flexctl.sim.maneuvers.TorqueSamples` (values at and between the
samples, its CasADi form equal to its numpy form, its breakpoints, the simulation on the
compiled and SciPy paths against a smooth reference) and of the ``timeseries.csv`` columns of
a structure. The one-beam form is pinned unchanged beside them.
"""

import copy
import dataclasses
import inspect
import json
import math
import pickle
import tomllib

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import flexctl
from flexctl import (Appendage, Beam, Hub, HubBeam, PointMass, SceneError, Structure,
                     build_model, load_scene, run_scene, simulate)
from flexctl.app import scenes
from flexctl.app.report import json_safe, structure_columns, timeseries_columns, write_run
from flexctl.app.scenes import parse_scene
from clear_errors import assert_clear_error
from flexctl.model.errors import InputError, InputTypeError, InputValueError
from flexctl.sim.maneuvers import (MAX_TORQUE_SAMPLES, SineTorque, Slew, TorqueSamples)

#: The paper-000 panel and tip fitting (MODEL.md section 6), written out independently.
PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
             youngs_modulus=6.9e10)
FITTING = PointMass(mass=0.085, position=1.62)
FREE_HUB = Hub(inertia=1.16, radius=0.06, mass=3.0, support="free")
NEW_BUILTINS = ("two-array-free", "single-wing-free", "two-array-slew")
#: Relative tip error of a sampled torque against the smooth one it samples (second order in
#: the sample interval: 1.1e-4 at 201 samples of a 2 s period, measured; 5x margin).
SAMPLED_TIP_TOLERANCE = 5e-4
#: Halving the sample interval divides that error by at least this (4 for second order).
SAMPLED_CONVERGENCE_RATIO = 3.0
#: The compiled and SciPy paths agree to their integration tolerance (rtol 1e-8), m.
PATH_AGREEMENT = 1e-6
#: Symmetric structures stay symmetric to rounding of the integrator, m.
SYMMETRY_TOLERANCE = 1e-9
#: Generated inputs per property.
MAX_EXAMPLES = {"overrides": 150, "samples": 80}
PROPERTY_SETTINGS = {"deadline": None, "derandomize": True,
                     "suppress_health_check": [HealthCheck.too_slow]}

TWO_ARRAYS = """\
description = "two arrays"

[hub]
inertia = 1.16
radius = 0.06
mass = 3.0
support = "free"

[[appendages]]
name = "wing_a"
angle_deg = 0.0
length = 1.8
density = 2766.0
area = 2.5e-4
second_moment = 1.3021e-10
youngs_modulus = 6.9e10

[[appendages.masses]]
mass = 0.085
position = 1.62

[[appendages]]
name = "wing_b"
angle_deg = 180.0
radius = 0.1
length = 1.8
density = 2766.0
area = 2.5e-4
second_moment = 1.3021e-10
youngs_modulus = 6.9e10
damping_ratio = 0.01

[[appendages.masses]]
mass = 0.085
position = 1.62

[model]
variant = "first_order"
modes = {wing_a = 4, wing_b = 2}

[maneuver]
kind = "sine_torque"
peak_torque = 1.0
duration = 2.0

[simulation]
t_final = 1.0
output_step = 0.01
"""

SAMPLES_SCENE = """\
[hub]
inertia = 1.16
radius = 0.06

[beam]
length = 1.8
density = 2766.0
area = 2.5e-4
second_moment = 1.3021e-10
youngs_modulus = 6.9e10

[model]
variant = "first_order"
modes = 2

[maneuver]
kind = "torque_samples"
{maneuver}

[simulation]
t_final = 1.0
output_step = 0.01
"""


def two_arrays() -> dict:
    return tomllib.loads(TWO_ARRAYS)


def _samples_scene(tmp_path, maneuver: str, name: str = "pushed.toml"):
    path = tmp_path / name
    path.write_text(SAMPLES_SCENE.format(maneuver=maneuver))
    return path


# ----------------------------------------------------------------- the general form
def test_appendages_build_the_structure_they_describe():
    scene = parse_scene(two_arrays(), name="two")
    assert isinstance(scene.system, Structure)
    assert scene.system.hub == FREE_HUB
    wing_a, wing_b = scene.system.appendages
    assert wing_a == Appendage(name="wing_a", beam=PANEL, masses=(FITTING,), angle=0.0)
    assert wing_b.beam == dataclasses.replace(PANEL, damping_ratio=0.01)
    assert wing_b.angle == pytest.approx(math.pi, rel=1e-15)
    assert (wing_a.radius, wing_b.radius) == (None, 0.1)
    assert scene.system.root_radius(wing_a) == 0.06      # default: the hub radius
    assert scene.model.modes == {"wing_a": 4, "wing_b": 2}
    assert scene.description == "two arrays"


@pytest.mark.parametrize("name", NEW_BUILTINS)
def test_new_builtin_scenes_are_structures_on_a_free_hub(name):
    scene = load_scene(name)
    assert name in flexctl.builtin_scenes() and flexctl.builtin_scenes()[name]
    assert isinstance(scene.system, Structure)
    assert scene.system.hub == FREE_HUB
    for appendage in scene.system.appendages:
        assert appendage.beam == PANEL and appendage.masses == (FITTING,)
    assert (scene.model.variant, scene.model.modes) == ("exact", 3)


def test_two_array_scenes_are_symmetric():
    for name in ("two-array-free", "two-array-slew"):
        system = load_scene(name).system
        assert system.names == ("wing_a", "wing_b")
        assert [a.angle for a in system.appendages] == [0.0, pytest.approx(math.pi)]
    assert load_scene("single-wing-free").system.names == ("wing_a",)
    assert isinstance(load_scene("two-array-free").maneuver, SineTorque)
    slew = load_scene("two-array-slew")
    assert isinstance(slew.maneuver, Slew) and slew.controller.kind == "trajopt+lqr"
    assert slew.model.design_modes < slew.model.modes


def test_the_one_beam_form_is_unchanged():
    scene = load_scene("hub-beam-mass")
    assert type(scene.system) is HubBeam
    assert scene.system.hub == Hub(inertia=1.16, radius=0.06)
    assert scene.system.hub.support == "pinned" and scene.system.hub.mass == 0.0


def test_the_one_beam_form_on_a_free_hub_is_its_one_appendage_structure():
    scene = load_scene("hub-beam-mass", overrides={"hub.support": "free", "hub.mass": "3.0"})
    pinned = load_scene("hub-beam-mass").system
    expected = Structure.from_hub_beam(dataclasses.replace(pinned, hub=FREE_HUB))
    assert scene.system == expected and scene.system.names == ("",)


def test_a_pinned_hub_needs_no_mass_and_keeps_one():
    data = two_arrays()
    data["hub"] = {"inertia": 1.16, "radius": 0.06}
    assert parse_scene(data).system.hub == Hub(inertia=1.16, radius=0.06)
    data["hub"]["mass"] = 2.0
    assert parse_scene(data).system.hub.mass == 2.0


def _edit(path, value):
    """A copy of the two-array tables with ``value`` set at ``path`` (a tuple of keys and
    indices); ``value`` DELETE removes the key."""
    data = two_arrays()
    node = data
    for key in path[:-1]:
        node = node[key]
    if value is DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


DELETE = object()
BAD_STRUCTURES = {
    "beam-and-appendages": (("beam",), dict(PANEL.__dict__), r"either \[beam\].*got both"),
    "masses-and-appendages": (("masses",), [{"mass": 0.1, "position": 1.0}],
                              r"either \[beam\].*got both"),
    "free-without-mass": (("hub", "mass"), DELETE, r"hub\.mass is required.*free"),
    "support": (("hub", "support"), "floating", r"hub\.support must be one of"),
    "support-type": (("hub", "support"), 1, r"hub\.support"),
    "hub-mass": (("hub", "mass"), -1.0, r"hub\.mass must be"),
    "no-appendages": (("appendages",), [], r"appendages must hold 1 to 32"),
    "too-many": (("appendages",), [{"name": f"a{k}", **PANEL.__dict__} for k in range(33)],
                 r"appendages must hold 1 to 32.*got 33"),
    "appendages-table": (("appendages",), {"name": "x"}, r"'appendages' must be an array"),
    "appendage-not-table": (("appendages", 1), 3, r"'appendages\.1' must be a table"),
    "unknown-key": (("appendages", 1, "colour"), "red", r"appendages\.1\.colour"),
    "unknown-mass-key": (("appendages", 0, "masses", 0, "colour"), 1,
                         r"appendages\.0\.masses\.0\.colour"),
    "missing-name": (("appendages", 1, "name"), DELETE, r"appendages\.1\.name is required"),
    "name-digit": (("appendages", 1, "name"), "1wing", r"appendages\.1\.name must be an "
                                                       r"identifier"),
    "name-space": (("appendages", 1, "name"), "wing b", r"appendages\.1\.name must be an "
                                                        r"identifier"),
    "name-empty": (("appendages", 1, "name"), "", r"appendages\.1\.name must be an identifier"),
    "name-int": (("appendages", 1, "name"), 3, r"appendages\.1\.name must be a string"),
    "name-duplicate": (("appendages", 1, "name"), "wing_a",
                       r"appendages\.1\.name must be unique; 'wing_a' is already the name "
                       r"of appendages\.0"),
    "angle-nan": (("appendages", 1, "angle_deg"), math.nan, r"appendages\.1\.angle_deg must "
                                                            r"be finite"),
    "angle-inf": (("appendages", 1, "angle_deg"), math.inf, r"appendages\.1\.angle_deg"),
    "angle-string": (("appendages", 1, "angle_deg"), "east", r"appendages\.1\.angle_deg must "
                                                             r"be a real number"),
    "angle-bool": (("appendages", 1, "angle_deg"), True, r"appendages\.1\.angle_deg"),
    "angle-huge": (("appendages", 1, "angle_deg"), 1e5, r"appendages\.1\.angle_deg must be "
                                                        r"at most 1440 degrees"),
    "angle-10e400": (("appendages", 1, "angle_deg"), 10 ** 400, r"appendages\.1\.angle_deg"),
    "length": (("appendages", 1, "length"), -1.0, r"appendages\.1\.length must be"),
    "length-missing": (("appendages", 1, "length"), DELETE, r"appendages\.1\.length is "
                                                            r"required"),
    "length-string": (("appendages", 0, "length"), "long", r"appendages\.0\.length"),
    "stiffness-ratio": (("appendages", 0, "youngs_modulus"), 1e-300,
                        r"appendages\.0\.youngs_modulus"),
    "radius": (("appendages", 1, "radius"), -0.1, r"appendages\.1\.radius must be"),
    "radius-far": (("appendages", 1, "radius"), 1e8, r"appendages\.1\.radius must be at most"),
    "hub-radius-far": (("hub", "radius"), 1e8, r"hub\.radius must be at most"),
    "masses-table": (("appendages", 0, "masses"), {"mass": 1.0}, r"appendages\.0\.masses"),
    "mass-past-tip": (("appendages", 1, "masses", 0, "position"), 2.0,
                      r"appendages\.1\.masses\.0\.position must lie in \[0, appendages\.1"
                      r"\.length = 1\.8\]"),
    "mass-negative": (("appendages", 0, "masses", 0, "mass"), -0.1,
                      r"appendages\.0\.masses\.0\.mass"),
    "mass-missing-position": (("appendages", 0, "masses", 0, "position"), DELETE,
                              r"appendages\.0\.masses\.0\.position is required"),
    "mass-ratio": (("appendages", 0, "masses", 0, "mass"), 1e8, r"of appendages\.0 must be"),
    "modes-missing-name": (("model", "modes"), {"wing_a": 4},
                           r"model\.modes\.wing_b is missing"),
    "modes-unknown-name": (("model", "modes"), {"wing_a": 4, "wing_b": 2, "wing_c": 1},
                           r"model\.modes\.wing_c names no appendage; expected wing_a, wing_b"),
    "modes-zero": (("model", "modes", "wing_a"), 0, r"model\.modes\.wing_a must be an "
                                                    r"integer in \[1, 200\]"),
    "modes-float": (("model", "modes", "wing_b"), 2.5, r"model\.modes\.wing_b"),
    "modes-bool": (("model", "modes", "wing_b"), True, r"model\.modes\.wing_b"),
    "modes-201": (("model", "modes", "wing_b"), 201, r"model\.modes\.wing_b"),
    "modes-empty": (("model", "modes"), {}, r"model\.modes must give the modes of every"),
    "modes-list": (("model", "modes"), [4, 2], r"model\.modes must be an integer"),
}


@pytest.mark.parametrize("case", sorted(BAD_STRUCTURES))
def test_bad_structures_are_refused_by_key(case):
    path, value, pattern = BAD_STRUCTURES[case]
    with pytest.raises(SceneError, match=pattern):
        parse_scene(_edit(path, value))


@pytest.mark.parametrize("modes, pattern", [
    (25, r"model\.modes must be at most 24 for the exact variant"),
    ({"wing_a": 2, "wing_b": 25}, r"model\.modes\.wing_b must be at most 24 for the exact"),
], ids=["number", "table"])
def test_the_exact_limit_applies_to_each_appendage(modes, pattern):
    data = two_arrays()
    data["model"] = {"variant": "exact", "modes": modes}
    with pytest.raises(SceneError, match=pattern):
        parse_scene(data)
    data["model"]["variant"] = "first_order"
    assert parse_scene(data).model.modes == modes
    data["model"]["modes"] = 24
    data["model"]["variant"] = "exact"
    assert parse_scene(data).model.modes == 24


def test_a_modes_table_needs_appendages():
    with pytest.raises(SceneError, match=r"model\.modes may be a table .* only with "
                                         r"\[\[appendages\]\]"):
        load_scene("hub-beam-mass", overrides={"model.modes": "{beam = 2}"})


def test_scene_files_of_the_general_form_load(tmp_path):
    path = tmp_path / "two.toml"
    path.write_text(TWO_ARRAYS)
    assert load_scene(path) == parse_scene(two_arrays(), name="two")
    path.write_text(TWO_ARRAYS.replace("[[appendages]]", "[beam]\nlength = 1.0\n\n"
                                       "[[appendages]]", 1))
    with pytest.raises(SceneError, match=r"got both"):
        load_scene(path)


def test_schema_keys_reach_their_constructors():
    beam_fields = {f.name for f in dataclasses.fields(Beam)}
    appendage_fields = {f.name for f in dataclasses.fields(Appendage)}
    # angle_deg sets Appendage.angle in degrees (as maneuver.angle_deg sets Slew.angle)
    assert scenes._APPENDAGE_KEYS - {"angle_deg"} <= beam_fields | appendage_fields
    assert scenes._SCHEMA["hub"] <= {f.name for f in dataclasses.fields(Hub)}
    samples = scenes._MANEUVER_KEYS["torque_samples"]
    assert samples <= set(inspect.signature(scenes._torque_samples).parameters)
    assert samples - {"file"} == {f.name for f in dataclasses.fields(TorqueSamples)}


# ------------------------------------------------------------------ overrides
@pytest.mark.parametrize("key, value, check", [
    ("appendages.0.length", "2.0", lambda s: s.system.appendages[0].beam.length == 2.0),
    ("appendages[1].masses[0].mass", "0.1",
     lambda s: s.system.appendages[1].masses[0].mass == 0.1),
    ("appendages.1.angle_deg", "90", lambda s: s.system.appendages[1].angle == math.pi / 2),
    ("appendages.0.radius", "0.2", lambda s: s.system.appendages[0].radius == 0.2),
    ("model.modes.wing_a", "5", lambda s: s.model.modes == {"wing_a": 5, "wing_b": 3}),
    ("model.modes", "{wing_a = 1, wing_b = 2}",
     lambda s: s.model.modes == {"wing_a": 1, "wing_b": 2}),
    ("model.design_modes.wing_b", "1",
     lambda s: s.model.design_modes == {"wing_a": 2, "wing_b": 1}),
    ("model.design_modes", "{wing_a = 1, wing_b = 3}",
     lambda s: s.model.design_modes == {"wing_a": 1, "wing_b": 3}),
    ("hub.support", "pinned", lambda s: not s.system.free and s.system.hub.mass == 3.0),
    ("hub.mass", "0", lambda s: s.system.hub.mass == 0.0),
], ids=["length", "mass-bracketed", "angle", "radius", "modes-by-name", "modes-table",
        "design-modes-by-name", "design-modes-table", "support", "hub-mass"])
def test_overrides_reach_the_new_tables(key, value, check):
    scene = load_scene("two-array-free", overrides={key: value})
    assert check(scene)
    assert load_scene("two-array-free") == load_scene("two-array-free")   # nothing leaked
    assert load_scene("two-array-free").model.modes == 3


@pytest.mark.parametrize("key, value, pattern", [
    ("appendages.2.length", "1", r"appendages\.2 is not an index of a list of 2"),
    ("appendages.0.colour", "1", r"appendages\.0\.colour"),
    ("appendages.0.masses.0.colour", "1", r"appendages\.0\.masses\.0\.colour"),
    ("appendages.0", "1", r"must index an item of the list"),
    ("model.modes.wing_c", "2", r"model\.modes\.wing_c names no appendage"),
    ("model.modes.wing_a", "0", r"model\.modes\.wing_a must be an integer"),
    ("model.design_modes.wing_c", "2", r"model\.design_modes\.wing_c names no appendage"),
    ("model.design_modes", "{wing_a = 2}", r"model\.design_modes\.wing_b is missing"),
    ("model.design_modes.wing_a", "true", r"model\.design_modes\.wing_a must be an integer"),
    ("model.design_modes", "{}", r"model\.design_modes must give the modes of every"),
    ("hub.support", "'orbit'", r"hub\.support must be one of"),
    ("appendages.1.name", "wing_a", r"appendages\.1\.name must be unique"),
    ("beam.length", "1", r"either \[beam\]"),
], ids=["index", "unknown", "unknown-mass-key", "list-item", "modes-name", "modes-zero",
        "design-modes-name", "design-modes-missing", "design-modes-bool", "design-modes-empty",
        "support", "duplicate", "beam-too"])
def test_bad_overrides_of_the_new_tables_are_refused_by_key(key, value, pattern):
    with pytest.raises(SceneError, match=pattern):
        load_scene("two-array-free", overrides={key: value})


def test_modes_by_name_on_the_one_beam_form_are_refused():
    with pytest.raises(SceneError, match=r"model\.modes is a int value, not a table"):
        load_scene("hub-beam-mass", overrides={"model.modes.beam": "2"})
    with pytest.raises(SceneError, match=r"model\.design_modes may be a table .* only with"):
        load_scene("hub-beam-mass", overrides={"model.design_modes": "{beam = 2}"})


@pytest.mark.parametrize("design_modes, expected", [
    ("{wing_a = 3, wing_b = 1}", {"wing_a": 3, "wing_b": 1}), ("2", {"wing_a": 2, "wing_b": 2})])
def test_the_design_model_has_the_design_modes_of_each_appendage(design_modes, expected):
    from controllers.factory import _design_model

    scene = load_scene("two-array-slew", overrides={"model.variant": "first_order",
                                                    "model.design_modes": design_modes})
    design = _design_model(scene, scene.build_model())
    assert dict(zip(design.structure.names, design.modes)) == expected


@pytest.mark.parametrize("design_modes, pattern", [
    ("4", r"model\.design_modes must be <= model\.modes = 3 \(the plant's modes of wing_a\); "
          "got 4"),
    ("{wing_a = 1, wing_b = 4}", r"model\.design_modes\.wing_b must be <= model\.modes = 3"),
])
def test_design_modes_beyond_the_plants_are_refused_per_appendage(design_modes, pattern):
    from controllers.factory import _design_model

    scene = load_scene("two-array-slew", overrides={"model.variant": "first_order",
                                                    "model.design_modes": design_modes})
    with pytest.raises(SceneError, match=pattern):
        _design_model(scene, scene.build_model())


# ------------------------------------------------------- models and design models
def test_build_model_gets_the_modes_of_each_appendage_by_name(monkeypatch):
    calls = []
    monkeypatch.setattr(scenes, "build_model",
                        lambda system, n_modes, variant: calls.append((system, n_modes,
                                                                       variant)))
    load_scene("two-array-free").build_model()
    load_scene("two-array-free", overrides={"model.modes.wing_b": "2"}).build_model()
    load_scene("hub-beam-mass").build_model()
    assert [c[1] for c in calls] == [{"wing_a": 3, "wing_b": 3}, {"wing_a": 3, "wing_b": 2}, 4]
    assert isinstance(calls[0][0], Structure) and calls[0][2] == "exact"


def test_the_design_system_scales_every_appendage():
    scene = load_scene("two-array-free", overrides={"model.design_stiffness_factor": "1.2",
                                                    "model.design_mass_factor": "0.5"})
    design = scene.design_system
    assert isinstance(design, Structure) and design.hub == scene.system.hub
    for true, off in zip(scene.system.appendages, design.appendages):
        assert (off.name, off.angle, off.radius) == (true.name, true.angle, true.radius)
        assert off.beam.bending_stiffness == pytest.approx(1.2 * true.beam.bending_stiffness)
        assert off.beam.linear_density == true.beam.linear_density
        assert [m.mass for m in off.masses] == [0.5 * m.mass for m in true.masses]
    base = load_scene("two-array-free")
    assert base.design_system is base.system


def test_the_one_beam_design_system_is_unchanged():
    scene = load_scene("hub-beam-mass", overrides={"model.design_stiffness_factor": "2"})
    assert type(scene.design_system) is HubBeam
    assert scene.design_system.beam.youngs_modulus == 2.0 * scene.system.beam.youngs_modulus
    assert scene.design_system.masses == scene.system.masses


# ------------------------------------------------------------------ round trips
@pytest.mark.parametrize("source, overrides", [
    ("two-array-free", {"model.modes.wing_a": "4", "appendages.1.angle_deg": "170"}),
    ("single-wing-free", {}),
    ("two-array-slew", {"controller.n_intervals": "30"}),
    ("hub-beam-mass", {"hub.support": "free", "hub.mass": "2.5"}),
], ids=["two-array", "single-wing", "slew", "one-beam-free"])
def test_the_scene_table_round_trips_through_json(tmp_path, source, overrides):
    scene = load_scene(source, overrides=overrides)
    assert parse_scene(scene.data, name=scene.name) == scene
    summary = tmp_path / "run" / "summary.json"
    summary.parent.mkdir()
    summary.write_text(json.dumps(json_safe({"scene": scene.name,
                                             "scene_table": scene.data})))
    again = load_scene(summary)
    assert again == scene and again.data == scene.data and again.name == scene.name


# ------------------------------------------------------------- TorqueSamples
def test_hold_values_at_and_between_samples():
    push = TorqueSamples(times=[0.5, 1.0, 2.0], values=[3.0, -1.0, 2.0])
    t = [0.0, 0.4999, 0.5, 0.75, 0.999, 1.0, 1.5, 2.0, 10.0]
    np.testing.assert_array_equal(push(t), [0, 0, 3, 3, 3, -1, -1, 2, 2])
    assert push.interpolation == "hold"


def test_linear_values_at_and_between_samples():
    ramp = TorqueSamples(times=(0.5, 1.0, 3.0), values=(2.0, 4.0, 0.0), interpolation="linear")
    t = np.array([0.0, 0.4999, 0.5, 0.75, 1.0, 2.0, 3.0, 3.5, 1e6])
    np.testing.assert_array_equal(ramp(t), [0, 0, 2, 3, 4, 2, 0, 0, 0])
    np.testing.assert_array_equal(ramp(t.reshape(3, 3)), ramp(t).reshape(3, 3))


def test_a_single_sample_is_a_step():
    step = TorqueSamples(times=[0.25], values=[1.5])
    np.testing.assert_array_equal(step([0.0, 0.2499, 0.25, 7.0]), [0, 0, 1.5, 1.5])
    assert step.breakpoints == (0.25,)


@pytest.mark.parametrize("interpolation", ["hold", "linear"])
def test_breakpoints_are_every_sample_time(interpolation):
    times = [0.0, 0.1, 0.35, 2.0]
    assert TorqueSamples(times=times, values=[1, 2, 3, 4],
                         interpolation=interpolation).breakpoints == tuple(times)


@pytest.mark.parametrize("symbol", [ca.SX, ca.MX], ids=["SX", "MX"])
@pytest.mark.parametrize("interpolation, n_samples", [
    ("hold", 1), ("hold", 2), ("hold", 7), ("hold", 20_000),
    ("linear", 2), ("linear", 7), ("linear", 20_000)])
def test_casadi_form_equals_the_numpy_form(rng, symbol, interpolation, n_samples):
    times = 0.2 + np.cumsum(rng.uniform(1e-4, 1e-2, n_samples))
    samples = TorqueSamples(times=times, values=rng.normal(size=n_samples),
                            interpolation=interpolation)
    t = symbol.sym("t")
    torque = ca.Function("torque", [t], [samples.casadi(t)])
    probes = np.concatenate([times, np.nextafter(times, -np.inf), np.nextafter(times, np.inf),
                             rng.uniform(0.0, times[-1] + 1.0, 3000), [0.0, 0.2, 1e9]])
    got = np.array(torque.map(probes.size)(probes.reshape(1, -1))).reshape(-1)
    np.testing.assert_array_equal(got, samples(probes))


def test_many_samples_make_a_small_casadi_expression(rng):
    # a lookup, not a chain of if_else as deep as the samples
    times = np.arange(50_000) * 1e-3
    for interpolation in ("hold", "linear"):
        samples = TorqueSamples(times=times, values=rng.normal(size=times.size),
                                interpolation=interpolation)
        t = ca.SX.sym("t")
        assert ca.Function("torque", [t], [samples.casadi(t)]).n_instructions() < 50


def test_torque_samples_are_frozen_read_only_equal_by_content_and_picklable():
    push = TorqueSamples(times=[0, 1], values=np.array([1, 2]))
    assert push.times.dtype == float and push.values.dtype == float
    with pytest.raises(dataclasses.FrozenInstanceError):
        push.interpolation = "linear"
    with pytest.raises(ValueError):
        push.values[0] = 5.0
    same = TorqueSamples(times=(0.0, 1.0), values=[1.0, 2.0])
    assert same == push and hash(same) == hash(push) and len({push, same}) == 1
    assert push != TorqueSamples(times=[0, 1], values=[1, 2], interpolation="linear")
    assert push != TorqueSamples(times=[0, 1], values=[1, 3])
    again = pickle.loads(pickle.dumps(push))
    assert again == push and not again.times.flags.writeable
    assert copy.deepcopy(push) == push
    assert "2 samples" in repr(push)


def test_caller_arrays_are_copied():
    times = np.array([0.0, 1.0])
    push = TorqueSamples(times=times, values=[1.0, 2.0])
    times[1] = 5.0
    assert push.times[1] == 1.0


BAD_SAMPLES = {
    "empty": (dict(times=[], values=[]), InputValueError, r"maneuver\.times must hold at "
                                                         r"least 1 sample"),
    "linear-one": (dict(times=[0.0], values=[1.0], interpolation="linear"), InputValueError,
                   r"maneuver\.times must hold at least 2 samples for interpolation "
                   r"'linear'; got 1"),
    "sizes": (dict(times=[0, 1], values=[1.0]), InputValueError,
              r"maneuver\.values must hold one torque per sample time \(2\); got 1"),
    "equal-times": (dict(times=[0, 1, 1], values=[1, 2, 3]), InputValueError,
                    r"maneuver\.times must be strictly increasing.*times\[2\] = 1\.0"),
    "decreasing": (dict(times=[0, 2, 1], values=[1, 2, 3]), InputValueError,
                   r"maneuver\.times must be strictly increasing"),
    "negative": (dict(times=[-1, 1], values=[1, 2]), InputValueError,
                 r"maneuver\.times must be >= 0 s.*-1\.0"),
    "nan-time": (dict(times=[0, math.nan], values=[1, 2]), InputValueError,
                 r"maneuver\.times must be finite; got times\[1\] = nan"),
    "inf-value": (dict(times=[0, 1], values=[1, math.inf]), InputValueError,
                  r"maneuver\.values must be finite; got values\[1\] = inf"),
    "strings": (dict(times=["0", "1"], values=[1, 2]), InputTypeError, r"maneuver\.times"),
    "string": (dict(times="0, 1", values=[1, 2]), InputTypeError, r"maneuver\.times"),
    "none": (dict(times=None, values=[1]), InputTypeError, r"maneuver\.times"),
    "dict": (dict(times=[0], values={"a": 1}), InputTypeError, r"maneuver\.values"),
    "nested": (dict(times=[[0, 1]], values=[[1, 2]]), InputValueError,
               r"maneuver\.times must be one-dimensional"),
    "ragged": (dict(times=[0, [1, 2]], values=[1, 2]), InputTypeError, r"maneuver\.times"),
    "scalar": (dict(times=0.0, values=1.0), InputValueError,
               r"maneuver\.times must be one-dimensional"),
    "bools": (dict(times=[0, 1], values=[True, False]), InputTypeError,
              r"maneuver\.values must be an array of real numbers.*\(booleans\)"),
    "bool-among-numbers": (dict(times=[0, 1], values=[1.0, True]), InputTypeError,
                           r"maneuver\.values.*\(booleans\)"),
    "bool-array": (dict(times=np.array([False, True]), values=[1, 2]), InputTypeError,
                   r"maneuver\.times"),
    "complex": (dict(times=[0, 1j], values=[1, 2]), InputTypeError, r"maneuver\.times"),
    "huge-int": (dict(times=[0, 10 ** 400], values=[1, 2]), InputTypeError,
                 r"maneuver\.times"),
    "interpolation": (dict(times=[0], values=[1], interpolation="spline"), InputValueError,
                      r"maneuver\.interpolation must be one of 'hold', 'linear'"),
    "interpolation-type": (dict(times=[0], values=[1], interpolation=1), InputTypeError,
                           r"maneuver\.interpolation"),
}


@pytest.mark.parametrize("case", sorted(BAD_SAMPLES))
def test_bad_torque_samples_are_refused_by_name(case):
    kwargs, error, pattern = BAD_SAMPLES[case]
    with pytest.raises(error, match=pattern):
        TorqueSamples(**kwargs)


def test_too_many_samples_are_refused():
    with pytest.raises(InputValueError, match=r"maneuver\.times must hold at most 1000000 "
                                              r"samples; got 1000001"):
        TorqueSamples(times=np.arange(MAX_TORQUE_SAMPLES + 1.0), values=[0.0])


# --------------------------------------------------------- simulating samples
@pytest.fixture(scope="module")
def small_model(hub_beam_mass_system):
    return build_model(hub_beam_mass_system, n_modes=2)


@pytest.fixture(scope="module")
def smooth_push():
    return SineTorque(peak_torque=2.0, duration=2.0)


@pytest.fixture(scope="module")
def smooth_run(small_model, smooth_push):
    return simulate(small_model, 3.0, torque=smooth_push, output_step=0.01)


def _sampled(push, n_samples, interpolation):
    """The smooth push sampled on ``n_samples`` times over its period: at the times for a
    line, at the midpoints of the intervals for a hold (second order, as the line is)."""
    edges = np.linspace(0.0, push.duration, n_samples)
    if interpolation == "linear":
        return TorqueSamples(times=edges, values=push(edges), interpolation="linear")
    middles = 0.5 * (edges[:-1] + edges[1:])
    return TorqueSamples(times=edges, values=np.append(push(middles), 0.0))


@pytest.mark.parametrize("method", ["auto", "DOP853"], ids=["compiled", "scipy"])
@pytest.mark.parametrize("interpolation", ["hold", "linear"])
def test_sampled_torque_converges_to_the_torque_it_samples(small_model, smooth_push,
                                                           smooth_run, method, interpolation):
    errors = []
    for n_samples in (201, 401):
        result = simulate(small_model, 3.0, torque=_sampled(smooth_push, n_samples,
                                                            interpolation),
                          output_step=0.01, method=method)
        assert result.status == "ok", result.message
        assert (result.method in ("cvodes", "RK45", "dop853")) == (method == "auto")
        errors.append(np.max(np.abs(result.tip_deflection - smooth_run.tip_deflection))
                      / smooth_run.peak_tip_deflection)
    assert errors[0] < SAMPLED_TIP_TOLERANCE
    assert errors[0] / errors[1] > SAMPLED_CONVERGENCE_RATIO


def test_compiled_and_scipy_paths_agree_on_jumps(small_model, rng):
    jumps = TorqueSamples(times=np.sort(rng.uniform(0.1, 1.5, 12)),
                          values=rng.uniform(-2.0, 2.0, 12))
    compiled = simulate(small_model, 2.0, torque=jumps, output_step=0.01, method="cvodes")
    scipy_run = simulate(small_model, 2.0, torque=jumps, output_step=0.01, method="DOP853")
    np.testing.assert_allclose(compiled.tip_deflection, scipy_run.tip_deflection, rtol=0,
                               atol=PATH_AGREEMENT)
    np.testing.assert_array_equal(compiled.torque, jumps(compiled.t))


def test_nothing_moves_before_the_first_sample(small_model):
    late = TorqueSamples(times=[0.5, 0.8], values=[1.0, -1.0])
    result = simulate(small_model, 1.0, torque=late, output_step=0.01)
    before = result.t < 0.5
    assert np.all(result.states[:, before] == 0.0)      # at rest under no torque: exactly
    assert np.all(result.torque[before] == 0.0) and result.theta[-1] != 0.0


# ------------------------------------------------------------ torque_samples scenes
def test_inline_samples_make_the_manoeuvre(tmp_path):
    scene = load_scene(_samples_scene(tmp_path, "times = [0.0, 0.5]\nvalues = [1, -1]"))
    assert scene.maneuver == TorqueSamples(times=[0.0, 0.5], values=[1.0, -1.0])
    scene = load_scene(_samples_scene(tmp_path, "times = [0.0, 0.5]\nvalues = [1, -1]"),
                       overrides={"maneuver.interpolation": "linear",
                                  "maneuver.values": "[2, 3]"})
    assert scene.maneuver == TorqueSamples(times=[0, 0.5], values=[2, 3], interpolation="linear")
    assert parse_scene(scene.data, name=scene.name) == scene


def test_a_torque_file_is_read_from_the_scene_directory(tmp_path, monkeypatch):
    folder = tmp_path / "scenes"
    folder.mkdir()
    (folder / "torque.csv").write_text("\ufefft, torque\n0.0, 1.5\n0.25,-2\n\n0.5 ,0\n")
    path = _samples_scene(folder, 'file = "torque.csv"\ninterpolation = "linear"')
    monkeypatch.chdir(tmp_path)          # not the scene's directory
    scene = load_scene(path)
    assert scene.maneuver == TorqueSamples(times=[0, 0.25, 0.5], values=[1.5, -2, 0],
                                           interpolation="linear")
    # the scene's table keeps the samples, not the file: it runs without it
    assert scene.data["maneuver"] == {"kind": "torque_samples", "times": [0.0, 0.25, 0.5],
                                      "values": [1.5, -2.0, 0.0], "interpolation": "linear"}
    (folder / "torque.csv").unlink()
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"scene": scene.name, "scene_table": scene.data}))
    assert load_scene(summary) == scene


def test_an_absolute_torque_file_path_is_read(tmp_path):
    csv = tmp_path / "data" / "push.csv"
    csv.parent.mkdir()
    csv.write_text("T,Torque\n0,1\n")
    scene = load_scene(_samples_scene(tmp_path, f"file = {json.dumps(str(csv))}"))
    assert scene.maneuver == TorqueSamples(times=[0.0], values=[1.0])


BAD_FILES = {
    "missing": (None, r"maneuver\.file 'torque\.csv' does not exist"),
    "no-header": ("0,1\n1,2\n", r"maneuver\.file 'torque\.csv' must start with the header "
                                r"line 't, torque'; got '0,1'"),
    "wrong-header": ("time,torque\n0,1\n", r"header line"),
    "empty": ("", r"header line.*got ''"),
    "header-only": ("t,torque\n", r"maneuver\.file 'torque\.csv' holds no samples"),
    "word": ("t,torque\n0,1\n1,abc\n", r"maneuver\.file 'torque\.csv' line 3 must hold two "
                                       r"numbers t, torque; got '1,abc'"),
    "three-columns": ("t,torque\n0,1,2\n", r"line 2 must hold two numbers"),
    "one-column": ("t,torque\n0\n", r"line 2 must hold two numbers"),
    "nan": ("t,torque\n0,nan\n", r"line 2: t and torque must be finite"),
    "inf-time": ("t,torque\n0,1\ninf,1\n", r"line 3: t and torque must be finite"),
    "decreasing": ("t,torque\n0,1\n2,1\n1,1\n", r"line 4: t must increase strictly \(after "
                                                r"2\.0 s\); got 1\.0"),
    "repeated": ("t,torque\n0,1\n0,2\n", r"line 3: t must increase strictly"),
    "negative": ("t,torque\n-1,1\n", r"line 2: t must be >= 0 s; got -1\.0"),
    "latin-1": ("t,torque\n0,1 caf\xe9\n".encode("latin-1"), r"must be UTF-8 text"),
    "directory": ("<dir>", r"does not exist"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_torque_files_are_refused_by_key(tmp_path, case):
    content, pattern = BAD_FILES[case]
    target = tmp_path / "torque.csv"
    if content == "<dir>":
        target.mkdir()
    elif isinstance(content, bytes):
        target.write_bytes(content)
    elif content is not None:
        target.write_text(content)
    with pytest.raises(SceneError, match=pattern):
        load_scene(_samples_scene(tmp_path, 'file = "torque.csv"'))


@pytest.mark.parametrize("maneuver, pattern", [
    ('file = "t.csv"\ntimes = [0]', r"maneuver\.file and maneuver\.times exclude each other"),
    ('file = "t.csv"\nvalues = [0]', r"maneuver\.file and maneuver\.values exclude"),
    ("values = [0]", r"maneuver\.times is required for kind 'torque_samples'"),
    ("times = [0]", r"maneuver\.values is required"),
    ("", r"maneuver\.times is required"),
    ("file = 3", r"maneuver\.file must be the path of a CSV file"),
    ('file = ""', r"maneuver\.file must be the path"),
    ("times = [0, 1]\nvalues = [1, 2]\ninterpolation = \"cubic\"",
     r"maneuver\.interpolation must be one of"),
    ("times = [0, 1]\nvalues = [1, \"x\"]", r"maneuver\.values"),
    ("times = [1, 0]\nvalues = [1, 2]", r"maneuver\.times must be strictly increasing"),
    ("times = []\nvalues = []", r"maneuver\.times must hold at least 1"),
    ("times = [0]\nvalues = [1]\npeak_torque = 2.0", r"maneuver\.peak_torque does not apply "
                                                    r"to kind 'torque_samples'"),
], ids=["file-and-times", "file-and-values", "no-times", "no-values", "nothing", "file-int",
        "file-empty", "interpolation", "value-string", "order", "empty", "foreign-key"])
def test_bad_torque_samples_tables_are_refused_by_key(tmp_path, maneuver, pattern):
    with pytest.raises(SceneError, match=pattern):
        load_scene(_samples_scene(tmp_path, maneuver))


# ------------------------------------------------------------------ properties
ODD_VALUES = st.one_of(
    st.sampled_from(["{a = 1}", "{wing_a = 2, wing_b = 3}", "[1, 2]", "[]", "{}", "true",
                     "nan", "inf", "-inf", "1e400", "1e-400", "0", "-1", "2", "\"x\"",
                     "\"wing_a\"", "free", "pinned", "1979-05-27", "99999999999999999999",
                     "", "[{name = \"w\"}]"]),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10 ** 30, 10 ** 30),
    st.text(max_size=6))
ODD_KEYS = st.sampled_from([
    "appendages.0.length", "appendages[1].masses[0].mass", "appendages.1.masses.0.position",
    "appendages.0.angle_deg", "appendages.1.name", "appendages.0.radius", "appendages.0",
    "appendages", "appendages.2.length", "appendages[-1].length", "appendages.0.masses",
    "appendages.0.masses.3.mass", "model.modes.wing_a", "model.modes.wing_c", "model.modes",
    "model.variant", "hub.support", "hub.mass", "hub.radius", "beam.length", "masses.0.mass",
    "appendages.0.damping_ratio", "appendages.0.colour"])


#: Overrides that load, so that a good part of the examples reach a scene.
GOOD_OVERRIDES = st.one_of(
    st.fixed_dictionaries({}, optional={
        "appendages.0.length": st.floats(0.5, 3.0).map(repr),
        "appendages[1].angle_deg": st.floats(-720.0, 720.0).map(repr),
        "model.modes.wing_a": st.integers(1, 8).map(str),
        "hub.support": st.sampled_from(["pinned", "free"]),
        "appendages.1.masses.0.mass": st.floats(0.0, 1.0).map(repr)}))


@settings(max_examples=MAX_EXAMPLES["overrides"], **PROPERTY_SETTINGS)
@given(overrides=st.one_of(GOOD_OVERRIDES,
                           st.dictionaries(ODD_KEYS, ODD_VALUES, min_size=1, max_size=3)))
def test_structure_overrides_give_a_clear_error_naming_the_key_or_a_scene(overrides):
    try:
        loaded = load_scene("two-array-free", overrides=overrides)
    except (TypeError, ValueError) as exc:
        tables = {k.split(".")[0].split("[")[0] for k in overrides}
        assert_clear_error(exc, "override key", "scene key", *tables,
                           "[beam]", "the ratio")
        return
    event("loaded")
    assert isinstance(loaded.system, Structure)
    assert all(math.isfinite(a.angle) for a in loaded.system.appendages)


SAMPLE_NUMBERS = st.one_of(st.floats(-1.0, 3.0), st.floats(allow_nan=True, allow_infinity=True),
                           st.sampled_from([0, 1, True, "1", None, 10 ** 400, 1j]))


@st.composite
def sample_pairs(draw):
    """``(times, values)``: valid pairs about half the time, anything else otherwise."""
    if draw(st.booleans()):
        times = sorted(draw(st.lists(st.floats(0.0, 3.0), min_size=1, max_size=6,
                                     unique=True)))
        return times, draw(st.lists(st.floats(-5.0, 5.0), min_size=len(times),
                                    max_size=len(times)))
    return (draw(st.one_of(st.lists(SAMPLE_NUMBERS, max_size=5),
                           st.sampled_from(["t", None, 1.0, [[0.0]]]))),
            draw(st.lists(SAMPLE_NUMBERS, max_size=6)))


@settings(max_examples=MAX_EXAMPLES["samples"], **PROPERTY_SETTINGS)
@given(pair=sample_pairs(), interpolation=st.sampled_from(["hold", "linear", "spline", None]))
def test_torque_samples_give_a_clear_error_or_an_exact_casadi_form(pair, interpolation):
    times, values = pair
    try:
        samples = TorqueSamples(times=times, values=values, interpolation=interpolation)
    except (TypeError, ValueError) as exc:
        assert_clear_error(exc, "maneuver.times", "maneuver.values", "maneuver.interpolation")
        return
    event("built")
    t = ca.SX.sym("t")
    torque = ca.Function("torque", [t], [samples.casadi(t)])
    probes = np.concatenate([samples.times, np.linspace(0.0, 4.0, 41)])
    got = np.array(torque.map(probes.size)(probes.reshape(1, -1))).reshape(-1)
    np.testing.assert_array_equal(got, samples(probes))
    assert np.all(np.isfinite(got))


def test_every_refusal_is_a_scene_error_and_an_input_error():
    assert issubclass(SceneError, InputError) and issubclass(SceneError, ValueError)


# ------------------------------------------------------------ reports
def test_timeseries_columns_of_structures():
    assert structure_columns(load_scene("two-array-free").system) == [
        "t", "theta", "theta_dot", "torque", "hub_x", "hub_y", "wing_a.tip_deflection",
        "wing_b.tip_deflection"]
    pinned = load_scene("two-array-free", overrides={"hub.support": "pinned"}).system
    assert "hub_x" not in structure_columns(pinned)
    assert timeseries_columns(2) == ["t", "theta", "theta_dot", "torque", "tip_deflection",
                                     "q1", "q2"]


def test_a_one_beam_run_writes_the_same_csv_as_before(tmp_path):
    scene = load_scene("hub-beam-mass", overrides={"simulation.t_final": "0.5",
                                                   "model.modes": "2"})
    result = run_scene(scene)
    write_run(scene, result, tmp_path)
    lines = (tmp_path / "timeseries.csv").read_text().splitlines()
    # the columns of before, then the other named outputs
    assert lines[0] == "t,theta,theta_dot,torque,tip_deflection,q1,q2,root_moment,tip_angle"
    table = np.loadtxt(tmp_path / "timeseries.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 4], result.tip_deflection, rtol=1e-11, atol=1e-15)
    np.testing.assert_allclose(table[:, 7], result.outputs["root_moment"], rtol=1e-11,
                               atol=1e-15)


def test_a_torque_samples_run_writes_its_manoeuvre_under_the_scene_keys(tmp_path):
    scene = load_scene(_samples_scene(tmp_path, "times = [0.0, 0.5]\nvalues = [1.0, -1.0]"))
    summary = write_run(scene, run_scene(scene), tmp_path / "run")
    assert summary["maneuver"] == {"kind": "torque_samples", "times": [0.0, 0.5],
                                   "values": [1.0, -1.0], "interpolation": "hold"}
    assert parse_scene({**scene.data, "maneuver": summary["maneuver"]},
                       name=scene.name) == scene
    assert load_scene(tmp_path / "run" / "summary.json") == scene


@pytest.fixture(scope="module")
def two_array_run():
    scene = load_scene("two-array-free", overrides={"simulation.t_final": "1.0"})
    return scene, run_scene(scene)


def test_a_structure_run_writes_its_named_outputs(tmp_path, two_array_run):
    scene, result = two_array_run
    assert result.status == "ok", result.message
    summary = write_run(scene, result, tmp_path)
    header = (tmp_path / "timeseries.csv").read_text().splitlines()[0]
    columns = structure_columns(scene.system)
    assert header.split(",")[:len(columns)] == columns
    assert set(header.split(",")[len(columns):]) == \
        set(result.model.output_names) - set(columns)
    table = np.loadtxt(tmp_path / "timeseries.csv", delimiter=",", skiprows=1)
    for k, name in enumerate(header.split(",")):
        want = {"t": result.t, "torque": result.torque}.get(name, result.outputs.get(name))
        np.testing.assert_allclose(table[:, k], want, rtol=1e-11, atol=1e-15, err_msg=name)
    assert summary["scene_table"] == scene.data
    assert load_scene(tmp_path / "summary.json") == scene


def test_symmetric_arrays_bend_alike_and_keep_the_hub_centred(two_array_run):
    _, result = two_array_run
    out = result.outputs
    assert np.max(np.abs(out["wing_a.tip_deflection"])) > 1e-3
    np.testing.assert_allclose(out["wing_a.tip_deflection"], out["wing_b.tip_deflection"],
                               rtol=0, atol=SYMMETRY_TOLERANCE)
    assert np.max(np.abs(out["hub_x"])) < SYMMETRY_TOLERANCE
    assert np.max(np.abs(out["hub_y"])) < SYMMETRY_TOLERANCE


def test_a_single_wing_pushes_its_free_hub_about():
    scene = load_scene("single-wing-free", overrides={"simulation.t_final": "1.0"})
    result = run_scene(scene)
    assert result.status == "ok", result.message
    assert np.max(np.abs(result.outputs["hub_y"])) > 1e-4


@pytest.mark.slow
def test_the_two_array_slew_reaches_its_angle():
    from controllers import from_spec

    scene = load_scene("two-array-slew")
    result, built, metrics = flexctl.run_slew(scene, from_spec)
    assert result.status == "ok", result.message
    assert abs(metrics.final_error) < 0.03 * scene.maneuver.angle
    assert metrics.peak_torque <= scene.maneuver.torque_bound * (1 + 1e-9)
