"""Scenes: built-ins match MODEL.md, overrides, strict validation of keys and values."""

import dataclasses

import pytest

import flexctl
from flexctl import Beam, Hub, SceneError, builtin_scenes, load_scene, run_scene
from flexctl.sim.maneuvers import SineTorque, SpinUp

BUILTINS = ("hub-beam-mass", "kane-spinup", "slew-90", "slew-90-model-error", "spacecraft-torque",
            "two-array-free", "single-wing-free", "two-array-slew", "wheel-slew",
            "flexible-link", "bus-slew")
#: The built-in spatial scenes (a 3 x 3 hub inertia).
SPATIAL_BUILTINS = ("spatial-tilted-slew", "spatial-spin")
#: The built-in spatial scene flown by a controller (the demo's three-axis control section).
LOOP_BUILTINS = ("spatial-pyramid-slew",)

#: MODEL.md section 6, written out independently of the scene files.
KANE_BEAM = Beam(length=8.0, youngs_modulus=6.8952e10, area=7.2968e-5,
                 second_moment=8.2189e-9, density=2766.67)
SPACECRAFT_BEAM = Beam(length=5.0, area=4e-4, second_moment=1.333e-8, density=2766.7,
                       youngs_modulus=6.8952e10)
PAPER000_HUB = Hub(inertia=1.16, radius=0.06)
PAPER000_BEAM = Beam(length=1.8, area=2.5e-4, second_moment=1.3021e-10, density=2766.0,
                     youngs_modulus=6.9e10)
#: Paper figures, a few percent (MODEL.md section 6).
PAPER_RTOL = 0.05

SCENE_TOML = """\
description = "test scene"

[hub]
inertia = 2.0
radius = 0.1

[beam]
length = 1.5
density = 2700.0
area = 3e-4
second_moment = 2e-10
youngs_modulus = 7e10
damping_ratio = 0.01

[[masses]]
mass = 0.1
position = 1.2

[[masses]]
mass = 0.05
position = 0.3

[model]
variant = "consistent"
modes = 3

[maneuver]
kind = "sine_torque"
peak_torque = 1.0
duration = 1.5

[simulation]
t_final = 2.0
output_step = 0.05
"""


def test_builtin_scenes_are_listed_with_descriptions():
    scenes = builtin_scenes()
    assert set(scenes) == set(BUILTINS) | set(SPATIAL_BUILTINS) | set(LOOP_BUILTINS)
    for name, description in scenes.items():
        assert isinstance(description, str) and description, name


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_scenes_load(name):
    scene = load_scene(name)
    assert isinstance(scene, flexctl.Scene)
    assert scene.name == name
    assert isinstance(scene.system, (flexctl.HubBeam, flexctl.Structure))
    assert scene.model.variant in flexctl.VARIANTS
    model = scene.build_model()
    assert set(model.modes) == {scene.model.modes} and model.variant == scene.model.variant


@pytest.mark.parametrize("name", SPATIAL_BUILTINS)
def test_builtin_spatial_scenes_load_and_lie_in_the_plane_of_their_planar_counterpart(name):
    from flexctl.app.spatial_scene import SpatialScene

    scene = load_scene(name)
    assert isinstance(scene, SpatialScene) and scene.name == name
    planar = scene.structure.to_planar()
    assert planar.names == scene.structure.names
    assert planar.hub.inertia == scene.structure.hub.inertia[2, 2]


def test_kane_scene_is_the_kane_case():
    scene = load_scene("kane-spinup")
    assert scene.system.beam == KANE_BEAM
    assert scene.system.hub.radius == 0.0   # Southwell coefficients are quoted at b = 0
    assert scene.maneuver == SpinUp(spin_rate=4.0, ramp_time=15.0)


def test_spacecraft_scene_is_paper_001_case():
    scene = load_scene("spacecraft-torque")
    assert scene.system.beam == SPACECRAFT_BEAM
    assert scene.system.hub == Hub(inertia=0.0, radius=0.0)
    assert scene.system.masses == ()
    assert scene.maneuver == SineTorque(peak_torque=50.0, duration=2.0)


def test_hub_beam_mass_scene_is_paper_000_case():
    scene = load_scene("hub-beam-mass")
    assert scene.system.hub == PAPER000_HUB
    assert scene.system.beam == PAPER000_BEAM
    (mass,) = scene.system.masses
    assert mass.mass == 0.085
    assert mass.position == pytest.approx(0.9 * 1.8, rel=1e-12)
    assert scene.maneuver == SineTorque(peak_torque=2.0, duration=2.0)


@pytest.mark.parametrize("key, value, check", [
    ("maneuver.spin_rate", "10", lambda s: s.maneuver.spin_rate == 10.0),
    ("maneuver.spin_rate", 10, lambda s: s.maneuver.spin_rate == 10.0),
    ("maneuver.ramp_time", "7.5", lambda s: s.maneuver.ramp_time == 7.5),
    ("model.variant", "zero_order", lambda s: s.model.variant == "zero_order"),
    ("model.modes", "6", lambda s: s.model.modes == 6),
    ("hub.inertia", "0.5", lambda s: s.system.hub.inertia == 0.5),
    ("simulation.t_final", "5", lambda s: s.simulation.t_final == 5.0),
    ("beam.damping_ratio", "0.02", lambda s: s.system.beam.damping_ratio == 0.02),
], ids=["spin_rate-string", "spin_rate-int", "ramp_time", "variant", "modes", "hub.inertia",
        "t_final", "damping_ratio"])
def test_overrides_by_dotted_path(key, value, check):
    scene = load_scene("kane-spinup", overrides={key: value})
    assert check(scene)


def test_override_of_a_mass_in_the_list():
    scene = load_scene("hub-beam-mass", overrides={"masses.0.mass": "0.1"})
    assert scene.system.masses[0].mass == 0.1
    assert scene.system.masses[0].position == pytest.approx(1.62)


def test_overrides_do_not_leak_into_the_next_load():
    load_scene("kane-spinup", overrides={"maneuver.spin_rate": "10"})
    assert load_scene("kane-spinup").maneuver.spin_rate == 4.0


@pytest.mark.parametrize("scene, overrides, pattern", [
    ("kane-spinup", {"colour": "blue"}, r"colour"),
    ("kane-spinup", {"beam.colour": "1"}, r"beam\.colour"),
    ("kane-spinup", {"maneuver.colour": "1"}, r"maneuver\.colour"),
    ("hub-beam-mass", {"masses.0.colour": "1"}, r"masses\.0\.colour"),
    ("kane-spinup", {"simulation.colour": "1"}, r"simulation\.colour"),
    ("hub-beam-mass", {"maneuver.spin_rate": "3"}, r"maneuver\.spin_rate"),
], ids=["top-level", "beam", "maneuver", "masses", "simulation", "wrong-kind"])
def test_unknown_keys_are_rejected_by_name(scene, overrides, pattern):
    with pytest.raises(SceneError, match=pattern):
        load_scene(scene, overrides=overrides)


@pytest.mark.parametrize("overrides, pattern", [
    ({"beam.length": "-1"}, r"beam\.length"),
    ({"beam.density": "0"}, r"beam\.density"),
    ({"hub.inertia": "'heavy'"}, r"hub\.inertia"),
    ({"hub.radius": "nan"}, r"hub\.radius"),
    ({"masses.0.position": "5.0"}, r"masses\.0\.position"),
    ({"masses.0.mass": "-0.1"}, r"masses\.0\.mass"),
    ({"model.variant": "second_order"}, r"model\.variant"),
    ({"model.modes": "0"}, r"model\.modes"),
    ({"model.modes": "2.5"}, r"model\.modes"),
    ({"maneuver.kind": "kick"}, r"maneuver\.kind"),
    ({"maneuver.duration": "-2"}, r"maneuver\.duration"),
    ({"simulation.t_final": "-1"}, r"simulation\.t_final"),
    ({"simulation.rtol": "2"}, r"simulation\.rtol"),
    ({"simulation.method": "'euler'"}, r"simulation\.method"),
    ({"masses.3.mass": "0.1"}, r"masses\.3"),
], ids=["beam.length", "beam.density", "hub.inertia-string", "hub.radius-nan",
        "mass-past-tip", "mass-negative", "variant", "modes-zero", "modes-float",
        "maneuver.kind", "duration", "t_final", "rtol", "method", "mass-index"])
def test_bad_values_are_rejected_by_name(overrides, pattern):
    with pytest.raises(SceneError, match=pattern):
        load_scene("hub-beam-mass", overrides=overrides)


def test_scene_error_is_a_value_error():
    assert issubclass(SceneError, ValueError)


def test_scene_from_a_toml_file(tmp_path):
    path = tmp_path / "my-scene.toml"
    path.write_text(SCENE_TOML)
    scene = load_scene(path)
    assert scene.name == "my-scene"
    assert scene.description == "test scene"
    assert scene.system.hub == Hub(inertia=2.0, radius=0.1)
    assert scene.system.beam == Beam(length=1.5, density=2700.0, area=3e-4,
                                     second_moment=2e-10, youngs_modulus=7e10,
                                     damping_ratio=0.01)
    assert [(m.mass, m.position) for m in scene.system.masses] == [(0.05, 0.3), (0.1, 1.2)]
    assert (scene.model.variant, scene.model.modes) == ("consistent", 3)
    assert scene.maneuver == SineTorque(peak_torque=1.0, duration=1.5)
    assert scene.simulation.t_final == 2.0 and scene.simulation.output_step == 0.05
    # a string path works too, and overrides apply to files as to built-ins
    assert load_scene(str(path), overrides={"model.modes": "2"}).model.modes == 2


@pytest.mark.parametrize("edit, pattern", [
    (lambda text: text.replace("[beam]", "[beam]\ncolour = 1"), r"beam\.colour"),
    (lambda text: "colour = 1\n" + text, r"colour"),
    (lambda text: text.replace("kind = \"sine_torque\"", "kind = \"sine_torque\"\nfoo = 1"),
     r"maneuver\.foo"),
    (lambda text: text.replace("length = 1.5", "length = -1.5"), r"beam\.length"),
    (lambda text: text.replace("duration = 1.5\n", ""), r"maneuver\.duration"),
    (lambda text: text.replace("t_final = 2.0", ""), r"simulation\.t_final"),
    (lambda text: text.split("[beam]")[0] + "[model]" + text.split("[model]")[1],
     r"\[beam\]"),
    (lambda text: text + "\n[[[not toml", r"TOML"),
], ids=["unknown-beam-key", "unknown-top-level-key", "unknown-maneuver-key", "bad-value",
        "missing-maneuver-key", "missing-t_final", "missing-table", "invalid-toml"])
def test_bad_toml_files_are_rejected_by_name(tmp_path, edit, pattern):
    path = tmp_path / "bad.toml"
    path.write_text(edit(SCENE_TOML))
    with pytest.raises(SceneError, match=pattern):
        load_scene(path)


def _as_appendage(data: dict) -> None:
    """The one-beam form of ``data`` rewritten as one [[appendages]] entry, in place."""
    data["appendages"] = [{"name": "arm", **data.pop("beam"), "masses": data.pop("masses")}]


@pytest.mark.parametrize("edit, pattern", [
    (lambda d: d["masses"][0].pop("position"),
     r"^masses\.0\.position is required: distance d_k from the beam root, m"),
    (lambda d: d["masses"][1].pop("mass"), r"^masses\.1\.mass is required: mass m_k, kg"),
    (lambda d: d["hub"].pop("inertia"), r"^hub\.inertia is required: moment of inertia .*kg m\^2"),
    (lambda d: d["beam"].pop("area"), r"^beam\.area is required: cross-section area A, m\^2"),
    (lambda d: (_as_appendage(d), d["appendages"][0].pop("length")),
     r"^appendages\.0\.length is required: length l, m"),
    (lambda d: (_as_appendage(d), d["appendages"][0]["masses"][0].pop("position")),
     r"^appendages\.0\.masses\.0\.position is required: distance d_k from the beam root"),
    (lambda d: d.update(actuator={"kind": "reaction_wheel", "inertia": 0.02,
                                  "torque_limit": 0.2, "time_constant": 0.05}),
     r"^actuator\.speed_limit is required: largest wheel speed .*rad/s"),
    (lambda d: d.update(actuator={"kind": "dc_motor", "resistance": 2.6, "torque_constant": 0.008,
                                  "back_emf_constant": 0.008, "gear_ratio": 70.0}),
     r"^actuator\.voltage_limit is required: V_max, V"),
], ids=["mass-position", "mass-mass", "hub-inertia", "beam-area", "appendage-length",
        "appendage-mass-position", "wheel-speed-limit", "motor-voltage-limit"])
def test_a_missing_table_key_is_named_with_its_meaning_not_a_signature(edit, pattern):
    import tomllib

    from flexctl.app.scenes import parse_scene

    data = tomllib.loads(SCENE_TOML)
    edit(data)
    with pytest.raises(SceneError, match=pattern) as caught:
        parse_scene(data)
    message = str(caught.value)
    assert "__init__" not in message and "argument" not in message, message


def test_missing_file_and_unknown_name_are_rejected(tmp_path):
    with pytest.raises(SceneError, match="does not exist"):
        load_scene(tmp_path / "nowhere.toml")
    with pytest.raises(SceneError, match="no-such-scene"):
        load_scene("no-such-scene")


def test_scene_data_round_trips_through_parse(tmp_path):
    scene = load_scene("hub-beam-mass", overrides={"maneuver.peak_torque": "3"})
    again = flexctl.app.scenes.parse_scene(scene.data, name="copy")
    assert again.system == scene.system
    assert again.maneuver == scene.maneuver == SineTorque(peak_torque=3.0, duration=2.0)


def test_run_scene_hub_beam_mass():
    result = run_scene(load_scene("hub-beam-mass"))
    assert result.status == "ok", result.message
    assert result.t[-1] == 20.0
    assert result.peak_tip_deflection == pytest.approx(0.263, rel=PAPER_RTOL)


def test_run_scene_prescribed_spinup_reaches_the_final_rate():
    scene = load_scene("kane-spinup", overrides={"simulation.t_final": "20"})
    result = run_scene(scene)
    assert result.status == "ok", result.message
    assert result.theta_dot[-1] == pytest.approx(scene.maneuver.spin_rate, rel=1e-12)


def test_scenes_are_frozen():
    scene = load_scene("hub-beam-mass")
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.name = "other"


def test_scene_file_that_is_not_utf8_is_named(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes('description = "caf\xe9"\n'.encode("latin-1"))
    with pytest.raises(flexctl.SceneError, match=r"latin1\.toml.*UTF-8"):
        flexctl.load_scene(path)


def test_exact_mode_limit_names_the_scene_key():
    from flexctl.app.scenes import SceneError, load_scene as load

    with pytest.raises(SceneError, match="model.modes"):
        load("slew-90", overrides={"model.modes": 30}).build_model()


def test_an_override_under_both_names_of_a_setting_is_refused():
    with pytest.raises(SceneError, match="set the same setting controller.hub_angle"):
        load_scene("slew-90", {"controller.kind": "lqr", "controller.hub_angle": 0.05,
                               "controller.angle_error": 0.01})


def test_run_slew_designs_the_scene_controller_by_default():
    from flexctl import run_slew

    result, built, metrics = run_slew(load_scene("slew-90", {"controller.kind": "pd",
                                                             "model.variant": "first_order",
                                                             "model.modes": 2}))
    assert result.ok and built.kind == "pd" and metrics.final_error == pytest.approx(0, abs=1e-2)


def test_a_slew_angle_is_reported_in_the_degrees_it_was_written_in():
    from flexctl.app.report import _maneuver_table

    table = _maneuver_table(load_scene("slew-90", {"maneuver.angle_deg": 60.0}).maneuver)
    assert table["angle_deg"] == 60.0
