"""Slew scenes: every controller kind built from a scene, run in closed loop on the nonlinear
first_order plant with more modes than its design model, and the CLI's slew metrics."""

import json

import numpy as np
import pytest

from controllers import OpenLoop, from_spec, solve_slew, SlewProblem
from controllers.slew.shaping import bang_bang, design_shaper, shape
from flexctl import SceneError, build_model, load_scene, run_scene, simulate
from flexctl.app.cli import main
from flexctl.sim.metrics import slew_metrics

#: Final hub angle error of a slew, as a fraction of the angle.
FINAL_ANGLE_FRACTION = 0.03
#: Margin of the torque bound for saturated controllers (the bound itself is exact).
TORQUE_BOUND_SLACK = 1e-9

KINDS = ["pd", "lqr", "lqg", "scheduled", "trajopt", "trajopt+lqr", "bang_bang", "zv", "zvd"]


@pytest.fixture(scope="module")
def slew_scene():
    return load_scene("slew-90")


def test_slew_90_is_the_issue_scene(slew_scene):
    hbm = load_scene("hub-beam-mass")
    assert slew_scene.system == hbm.system
    assert slew_scene.maneuver.angle == pytest.approx(np.pi / 2)
    assert slew_scene.maneuver.duration == 2.0
    assert slew_scene.maneuver.torque_bound == 6.0
    assert slew_scene.model.modes == 6
    assert slew_scene.model.design_modes < slew_scene.model.modes


@pytest.mark.parametrize("kind", KINDS, ids=KINDS)
def test_every_controller_kind_slews_within_the_torque_bound(slew_scene, kind):
    scene = load_scene("slew-90", overrides={"controller.kind": kind,
                                             "simulation.t_final": 8.0})
    built = from_spec(scene)
    result = run_scene(scene, controller=built.controller)
    assert result.status == "ok", result.message
    metrics = slew_metrics(result, scene.maneuver.angle, built.maneuver_end)
    assert abs(metrics.final_error) < FINAL_ANGLE_FRACTION * scene.maneuver.angle
    assert metrics.peak_torque <= scene.maneuver.torque_bound * (1 + TORQUE_BOUND_SLACK)
    assert np.all(np.isfinite(result.states))


def test_trajopt_leaves_less_residual_than_zvd_at_the_same_slew_time(slew_scene):
    """ZVD shaping of a rigid bang-bang and the optimal slew, both ending at the same time."""
    plant = build_model(slew_scene.system, n_modes=8)
    design = build_model(slew_scene.system, n_modes=2)
    angle = slew_scene.maneuver.angle
    shaper = design_shaper(design, "zvd")
    delay = float(max(shaper.times))
    total = 3.0
    base = bang_bang(design, angle, duration=total - delay)
    zvd = shape(base, shaper)
    solution = solve_slew(design, SlewProblem(angle=angle, duration=total, torque_bound=6.0))
    residual = {}
    for name, torque in (("zvd", zvd), ("trajopt", solution.torque_function())):
        result = simulate(plant, total + 3.0, controller=OpenLoop(torque), rtol=1e-9)
        residual[name] = slew_metrics(result, angle, total).residual_vibration
    assert residual["trajopt"] < residual["zvd"], residual


def test_open_loop_keeps_the_breakpoints_of_its_torque():
    design_scene = load_scene("slew-90", overrides={"controller.kind": "trajopt"})
    built = from_spec(design_scene)
    assert isinstance(built.controller, OpenLoop)
    assert len(built.controller.breakpoints) >= 40
    assert built.info["ipopt_status"] == "Solve_Succeeded"


@pytest.mark.parametrize("overrides, match", [
    ({"controller.kind": "fuzzy"}, "controller.kind"),
    ({"controller.gain": 3}, "controller.gain"),
    ({"controller.kind": "pd", "controller.bandwidth": -1.0}, "bandwidth"),
    ({"model.design_modes": 9}, "design_modes"),
    ({"maneuver.duration": 0.5, "controller.kind": "bang_bang"}, "duration"),
    ({"maneuver.duration": 0.5}, "trajectory optimisation failed"),
], ids=["unknown-kind", "unknown-setting", "negative-bandwidth", "design-modes-above-plant",
        "duration-below-rigid-minimum", "infeasible-trajopt"])
def test_bad_controller_settings_are_scene_errors(overrides, match):
    with pytest.raises(SceneError, match=match):
        scene = load_scene("slew-90", overrides=overrides)
        from_spec(scene)


def test_slew_scene_without_controller_is_refused():
    scene = load_scene("slew-90")
    with pytest.raises(SceneError, match="controller"):
        run_scene(scene)


def test_cli_slew_run_reports_slew_metrics(tmp_path, capsys):
    code = main(["run", "slew-90", "--out", str(tmp_path)])
    assert code == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    slew = summary["slew"]
    for key in ("settling_time", "overshoot", "peak_torque", "peak_tip_deflection",
                "residual_vibration", "solve_time_s"):
        assert key in slew
    assert slew["peak_torque"] <= 6.0 * (1 + TORQUE_BOUND_SLACK)
    assert slew["settling_time"] is not None and slew["settling_time"] < 6.0
    assert "residual tip vibration" in capsys.readouterr().out


def test_flexible_reference_leaves_less_vibration_than_a_straight_beam_reference(slew_scene):
    """Tracking the quasi-static deflection the commanded acceleration needs, instead of
    holding the beam straight against it, leaves the beam stiller after the slew."""
    from controllers import LQRWeights, SlewProfile, design_lqr, minimum_slew_duration

    design = build_model(slew_scene.system, n_modes=2)
    plant = build_model(slew_scene.system, n_modes=6)
    angle = slew_scene.maneuver.angle
    duration = 1.05 * minimum_slew_duration(angle, design.matrices.J0, 6.0)
    profile = SlewProfile(slew_angle=angle, duration=duration)
    weights = LQRWeights(hub_angle=0.05, hub_rate=0.02, tip_deflection=0.01, torque=1.0)
    residual = {}
    for flexible in (False, True):
        lqr = design_lqr(design, weights, reference=profile, torque_limit=6.0,
                         flexible_reference=flexible)
        result = simulate(plant, duration + 3.0, controller=lqr, output_step=0.01)
        residual[flexible] = slew_metrics(result, angle, duration).residual_vibration
    assert residual[True] < 0.6 * residual[False], residual
