"""Every key a scene accepts sets a constructor argument, under the argument's own name unless
this file says why not; former names still work for one release, with a FutureWarning.

The tables of keys come from the scene parser (``flexctl.app.scenes``) and the controller
registry (``controllers.spec.CONTROLLER_KINDS``); the destinations are checked against the
constructors' signatures, so a new key without a destination fails here.
"""

import dataclasses
import inspect
import warnings
from importlib import resources

import pytest

from controllers import factory
from controllers.feedback.lqg import NoiseLevels, design_lqg
from controllers.feedback.lqr import LQRWeights, design_lqr
from controllers.mpc.nmpc import NMPC
from controllers.feedback.pd import design_pd
from controllers.slew.reference import SlewProfile
from controllers.feedback.scheduling import design_scheduled_lqr
from controllers.analysis.requirements import Requirements
from controllers.feedback.structural_filters import Filtered
from controllers.spec import CONTROLLER_KINDS, FORMER_NAMES
from controllers.slew.trajopt import SlewProblem
from flexctl import SceneError, load_scene
from flexctl.app import scenes
from flexctl.model import build_model
from flexctl.model.parameters import Beam, Hub, PointMass
from flexctl.sim.digital import ZeroOrderHold

#: Tables whose keys are the fields of a dataclass of the same names.
TABLE_CLASSES = {"hub": Hub, "beam": Beam, "masses": PointMass, "model": scenes.ModelSpec,
                 "simulation": scenes.SimulationSpec, "requirements": Requirements}

_LQR = {name: (LQRWeights, name) for name in
        ("hub_angle", "hub_rate", "tip_deflection", "modal_energy", "torque")}
_NOISE = {key: (NoiseLevels, field) for field, key in factory.NOISE_SETTINGS.items()}
_SLEW_PROBLEM = {name: (SlewProblem, name) for name in
                 ("n_intervals", "objective", "transcription", "torque_rate_bound", "tip_bound",
                  "effort_tolerance")}
_TRACKING = {"reference": (SlewProfile, "shape"), "sample_time": (ZeroOrderHold, "sample_time"),
             "filters": (Filtered, "filters")}

#: Where each setting of each controller kind goes: (constructor or design function, parameter).
CONTROLLER_DESTINATIONS = {
    "pd": {**_TRACKING, "bandwidth": (design_pd, "bandwidth"),
           "damping_ratio": (design_pd, "damping_ratio"),
           "feedforward": (design_pd, "feedforward")},
    "lqr": {**_TRACKING, **_LQR, "spin_rate": (design_lqr, "spin_rate")},
    "lqg": {"reference": (SlewProfile, "shape"), **_LQR, **_NOISE,
            "spin_rate": (design_lqg, "spin_rate"), "filters": (Filtered, "filters")},
    "scheduled": {**_TRACKING, **_LQR, "spin_rates": (design_scheduled_lqr, "spin_rates")},
    "trajopt": {**_SLEW_PROBLEM, "sample_time": (ZeroOrderHold, "sample_time")},
    "trajopt+lqr": {**_SLEW_PROBLEM, "sample_time": (ZeroOrderHold, "sample_time"),
                    "filters": (Filtered, "filters")},
    "bang_bang": {"sample_time": (ZeroOrderHold, "sample_time")},
    "zv": {"sample_time": (ZeroOrderHold, "sample_time")},
    "zvd": {"sample_time": (ZeroOrderHold, "sample_time")},
    "nmpc": {**_SLEW_PROBLEM, **_NOISE,
             **{name: (NMPC, name) for name in
                ("horizon", "mode", "qp_solver", "terminal", "sample_time")},
             "reference": (NMPC, "reference"),
             # NMPC's own names; controllers/nmpc.py keeps its *_limit spelling for now
             "torque_rate_bound": (NMPC, "torque_rate_limit"), "tip_bound": (NMPC, "tip_limit"),
             # "kalman" passes the noise levels, "state" none
             "estimator": (NMPC, "noise")},
}

#: Keys kept under a name other than their parameter's, and why.
KEPT_NAMES = {
    # the [controller] table is flat: the noise levels need a word to tell them from the LQR
    # weights (NoiseLevels.torque beside LQRWeights.torque, NoiseLevels.angle beside hub_angle)
    "angle_noise": "flat table", "moment_noise": "flat table", "process_torque": "flat table",
    # "reference" is what the loop tracks: a shape for the feedback laws, the optimal slew or
    # none for NMPC; one key for the one choice
    "reference": "what the loop tracks",
    # scenes bound quantities (maneuver.torque_bound, SlewProblem.*_bound); NMPC says *_limit
    "torque_rate_bound": "SlewProblem name", "tip_bound": "SlewProblem name",
    "estimator": "a choice of estimator, not the noise levels it passes",
    # model.modes and model.design_modes set ModelSpec fields (which also take "auto") and
    # reach build_model's n_modes; both keep the shorter names that pair up
    "modes": "ModelSpec.modes, may be auto",
}


def _parameters(target) -> set:
    if dataclasses.is_dataclass(target):
        return {f.name for f in dataclasses.fields(target) if f.init}
    return set(inspect.signature(target).parameters)


@pytest.mark.parametrize("table", sorted(TABLE_CLASSES))
def test_table_keys_are_dataclass_fields(table):
    keys = scenes._SCHEMA[table]
    assert keys <= _parameters(TABLE_CLASSES[table]), keys - _parameters(TABLE_CLASSES[table])


def test_every_table_of_the_schema_is_checked():
    assert set(scenes._SCHEMA) == {*TABLE_CLASSES, "maneuver", "controller", "description",
                                   "actuator", "sensors"}
    assert "description" in _parameters(scenes.Scene)


@pytest.mark.parametrize("kind", sorted(scenes._MANEUVER_KEYS))
def test_maneuver_keys_are_constructor_parameters(kind):
    keys = scenes._MANEUVER_KEYS[kind]
    assert keys <= _parameters(scenes._MANEUVERS[kind])
    assert set().union(*scenes._MANEUVER_KEYS.values()) | {"kind"} == scenes._SCHEMA["maneuver"]


def test_model_modes_reach_build_model():
    assert "n_modes" in _parameters(build_model)


@pytest.mark.parametrize("kind", sorted(CONTROLLER_KINDS))
def test_controller_settings_have_a_destination(kind):
    settings = CONTROLLER_KINDS[kind].names
    destinations = CONTROLLER_DESTINATIONS[kind]
    assert settings - set(destinations) == set(), "settings without a destination"
    assert set(destinations) - settings == set(), "destinations of settings that do not exist"
    for key, (target, parameter) in destinations.items():
        assert parameter in _parameters(target), \
            f"{kind}: {key} -> {target.__name__}.{parameter}"
        if key != parameter:
            assert key in KEPT_NAMES, f"controller.{key} sets {target.__name__}.{parameter}"


def test_every_kind_has_destinations():
    assert set(CONTROLLER_DESTINATIONS) == set(CONTROLLER_KINDS)


def test_former_names_now_name_the_parameter():
    assert FORMER_NAMES == {"angle_error": "hub_angle", "rate_error": "hub_rate",
                            "intervals": "n_intervals"}
    for new in FORMER_NAMES.values():
        assert any(new == parameter for kind in CONTROLLER_DESTINATIONS.values()
                   for key, (_, parameter) in kind.items() if key == new)


@pytest.mark.parametrize(("old", "new", "kind", "value"), [
    ("angle_error", "hub_angle", "lqr", 0.1), ("rate_error", "hub_rate", "lqg", 0.3),
    ("intervals", "n_intervals", "trajopt", 30)], ids=["angle_error", "rate_error", "intervals"])
def test_a_former_name_warns_and_takes_the_new_name(tmp_path, old, new, kind, value):
    base = load_scene("slew-90").data
    base["controller"] = {"kind": kind, old: value}
    with pytest.warns(FutureWarning, match=rf"controller\.{old} is deprecated.*"
                                           rf"controller\.{new}"):
        scene = scenes.parse_scene(base)
    assert scene.controller.settings == {new: value}
    assert scene.data["controller"] == {"kind": kind, new: value}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert scenes.parse_scene(scene.data) == scene


@pytest.mark.parametrize(("in_file", "in_override"), [("n_intervals", "intervals"),
                                                      ("intervals", "n_intervals")])
def test_an_override_under_either_name_replaces_the_files_value(tmp_path, in_file, in_override):
    text = resources.files("flexctl.app.builtin_scenes").joinpath("slew-90.toml").read_text()
    path = tmp_path / "slew.toml"
    kind = 'kind = "trajopt+lqr"'
    path.write_text(text.replace(kind, f"{kind}\n{in_file} = 50"))
    with pytest.warns(FutureWarning, match=r"controller\.intervals .*controller\.n_intervals"):
        scene = load_scene(path, overrides={f"controller.{in_override}": "25"})
    assert scene.controller.settings == {"n_intervals": 25}


def test_both_names_at_once_are_refused():
    base = load_scene("slew-90").data
    base["controller"] = {"kind": "lqr", "angle_error": 0.1, "hub_angle": 0.2}
    with pytest.raises(SceneError, match=r"controller\.angle_error is the former name of "
                                         r"controller\.hub_angle"):
        scenes.parse_scene(base)
