"""The registry of controller kinds (controllers.spec.CONTROLLER_KINDS) is the one owner of
each kind's settings: the scene parser checks names and values against it, the factory takes
its defaults from it, the factory's docstring table and the CLI help are rendered from it."""

import textwrap

import pytest

from controllers import factory, lqr, nmpc, reference, spec, trajopt
from controllers.spec import CONTROLLER_KEYS, CONTROLLER_KINDS, ControllerSpec, SceneError
from flexctl import load_scene
from flexctl.app import cli
from flexctl.app.cli import main


def test_factory_docstring_table_is_the_registry():
    # a literal block of the module's docstring, indented by four spaces
    assert textwrap.indent(spec.settings_table(), "    ", str.strip) in factory.__doc__


def test_choices_of_the_registry_are_the_modules_constants():
    # one owner: the modules act on the registry's own objects, not on copies
    assert reference.SHAPES is spec.SHAPES
    assert trajopt.OBJECTIVES is spec.OBJECTIVES
    assert trajopt.TRANSCRIPTIONS is spec.TRANSCRIPTIONS
    assert (nmpc.MODES, nmpc.QP_SOLVERS, nmpc.TERMINALS) == (spec.MODES, spec.QP_SOLVERS,
                                                             spec.TERMINALS)
    assert nmpc.QP_SOLVERS is spec.QP_SOLVERS and lqr.WEIGHT_RANGE is spec.WEIGHT_RANGE


def test_nmpc_defaults_agree_with_the_controller_class():
    fields = nmpc.NMPC.__dataclass_fields__
    kind = CONTROLLER_KINDS["nmpc"]
    for name in ("horizon", "mode", "qp_solver", "terminal", "sample_time"):
        assert kind.setting(name).default == fields[name].default, name


def test_trajopt_intervals_default_agrees_with_slew_problem():
    default = trajopt.SlewProblem.__dataclass_fields__["n_intervals"].default
    assert CONTROLLER_KINDS["trajopt"].setting("n_intervals").default == default


def test_controller_keys_derive_from_the_registry():
    assert set(CONTROLLER_KEYS) == set(CONTROLLER_KINDS) == {
        "pd", "lqr", "lqg", "scheduled", "trajopt", "trajopt+lqr", "bang_bang", "zv", "zvd",
        "nmpc"}
    for name, kind in CONTROLLER_KINDS.items():
        assert CONTROLLER_KEYS[name] == {item.name for item in kind.settings}
        # every kind but lqg (continuous estimator) may run sampled
        assert ("sample_time" in CONTROLLER_KEYS[name]) == (name != "lqg")
    assert "spin_rate" not in CONTROLLER_KEYS["scheduled"]


def test_defaults_meet_their_own_rules():
    for name, kind in CONTROLLER_KINDS.items():
        for item in kind.settings:
            if item.default is not None:
                value = list(item.default) if item.type is tuple else item.default
                assert item.check(name, value) == value


@pytest.mark.parametrize("kind, key, value, rule", [
    ("pd", "bandwidth", -1.0, "a number > 0"),
    ("pd", "bandwidth", "fast", "a number > 0"),
    ("pd", "feedforward", 1, "true or false"),
    ("lqr", "hub_angle", 1e20, r"a number in \[1e-12, 1e\+12\]"),
    ("lqr", "reference", "sine", 'one of "poly7", "cycloidal"'),
    ("trajopt", "n_intervals", 1, "an integer >= 2"),
    ("trajopt", "n_intervals", 40.5, "an integer >= 2"),
    ("nmpc", "horizon", 1000, r"an integer in \[2, 500\]"),
    ("nmpc", "estimator", "ukf", 'one of "state", "kalman"'),
    ("scheduled", "spin_rates", [-1.0, 1.0], "an array of numbers >= 0"),
    ("zv", "sample_time", 0.0, "a number > 0"),
], ids=lambda v: str(v))
def test_bad_values_name_key_rule_and_value(kind, key, value, rule):
    with pytest.raises(SceneError, match=rf"controller\.{key} \(kind '{kind}'\) must be "
                                         rf"{rule}; got "):
        ControllerSpec(kind=kind, settings={key: value})


@pytest.mark.parametrize("kind, key", [("scheduled", "spin_rate"), ("lqg", "sample_time"),
                                       ("bang_bang", "bandwidth")])
def test_keys_a_kind_does_not_take_are_refused(kind, key):
    with pytest.raises(SceneError, match=rf"unknown scene key 'controller\.{key}' for kind"):
        ControllerSpec(kind=kind, settings={key: 1.0})


def test_get_falls_back_to_the_registry_default():
    pd = ControllerSpec(kind="pd", settings={"bandwidth": 3.0})
    assert pd.get("bandwidth") == 3.0
    assert pd.get("damping_ratio") == CONTROLLER_KINDS["pd"].setting("damping_ratio").default


def test_scene_override_is_checked_against_the_registry():
    with pytest.raises(SceneError, match=r"controller\.n_intervals \(kind 'trajopt\+lqr'\)"):
        load_scene("slew-90", overrides={"controller.n_intervals": "-3"})


def test_cli_help_lists_every_kind_and_setting(capsys):
    assert main(["run", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for name, kind in CONTROLLER_KINDS.items():
        assert f"{name}:" in text
        for item in kind.settings:
            assert f"{item.name}=" in text
    assert cli.controller_help().split()[0] == "controller"


def test_user_guide_names_every_kind_of_the_registry():
    from pathlib import Path

    guide = Path(__file__).resolve().parents[2] / "docs" / "guide" / "controllers.md"
    text = guide.read_text()
    listed = text.split("--set controller.kind=", 1)[1].split("`", 1)[0].split("|")
    assert listed == list(CONTROLLER_KINDS)
