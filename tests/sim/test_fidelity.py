"""Model only what a scene needs: the mode-count estimate, the stiffening verdict, auto scenes."""

import json
import math
from importlib import resources

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from flexctl import SceneError, SineTorque, SpinUp, build_model, load_scene, simulate
from flexctl.app.cli import main
from flexctl.sim.fidelity import (DEFAULT_TOLERANCE, ModeChoice, choose_modes, largest_spin_rate,
                              rigid_slew_torque)
from flexctl.sim.maneuvers import Slew

#: The linear estimate against the tip error of the nonlinear N-mode runs: within a factor of
#: four either way (frozen spin at its largest value is conservative for a spin-up, ~3x).
ESTIMATE_FACTOR = 4.0
#: Converged nonlinear reference of the estimate checks: 12 modes at rtol 1e-10. Errors below
#: a few times its own distance from convergence are not compared.
REFERENCE_MODES = 12
#: The estimate must fall by this factor from 1 mode to 12 on every built-in scene.
CONVERGENCE_FACTOR = 100.0
#: Southwell: at a slow spin, stiffening raises omega_1^2 by S Omega^2 (S = 1.1933 for b = 0,
#: MODEL.md section 6) on top of the -Omega^2 softening both variants share, so the first
#: clamped frequency shifts by S Omega^2 / (2 omega_1^2) to first order.
SOUTHWELL_1 = 1.1933
SOUTHWELL_RTOL = 0.02
#: Rigid-body quantities computed on the estimate's time grid (trapezoid, >= 200 points).
GRID_RTOL = 1e-4


def _builtin_text(name):
    """The TOML text of a built-in scene."""
    return resources.files("flexctl.app.builtin_scenes").joinpath(f"{name}.toml").read_text()


def _drive(scene):
    return ({"hub_motion": scene.maneuver} if isinstance(scene.maneuver, SpinUp)
            else {"torque": scene.maneuver})


def _tip(scene, n_modes, rtol=1e-10):
    result = simulate(build_model(scene.system, n_modes), scene.simulation.t_final, rtol=rtol,
                      output_step=0.01, **_drive(scene))
    assert result.status == "ok", result.message
    return result.tip_deflection


@pytest.mark.parametrize("name, modes", [("kane-spinup", (1, 2, 3, 4)),
                                         ("hub-beam-mass", (1, 2, 4)),
                                         ("spacecraft-torque", (2, 4))],
                         ids=["kane-spinup", "hub-beam-mass", "spacecraft-torque"])
def test_estimate_tracks_the_nonlinear_truncation_error(name, modes):
    scene = load_scene(name)
    choice = choose_modes(scene.system, scene.maneuver, 1e-2, t_final=scene.simulation.t_final)
    reference = _tip(scene, REFERENCE_MODES, rtol=1e-9 if name == "spacecraft-torque" else 1e-10)
    peak = np.max(np.abs(reference))
    for n in modes:
        actual = np.max(np.abs(_tip(scene, n) - reference)) / peak
        estimate = choice.error_by_modes[n - 1]
        assert actual / ESTIMATE_FACTOR < estimate < actual * ESTIMATE_FACTOR, (n, estimate,
                                                                                 actual)


@pytest.mark.parametrize("name", ["kane-spinup", "hub-beam-mass", "spacecraft-torque",
                                  "slew-90"])
def test_choice_is_the_fewest_modes_within_tolerance(name):
    scene = load_scene(name)
    choice = choose_modes(scene.system, scene.maneuver, DEFAULT_TOLERANCE,
                          t_final=scene.simulation.t_final)
    errors = choice.error_by_modes
    assert len(errors) == 12
    assert errors[-1] * CONVERGENCE_FACTOR < errors[0]
    assert choice.meets_tolerance and choice.estimated_error == errors[choice.n_modes - 1]
    assert all(e > DEFAULT_TOLERANCE for e in errors[:choice.n_modes - 1])
    tighter = choose_modes(scene.system, scene.maneuver, DEFAULT_TOLERANCE / 10,
                           t_final=scene.simulation.t_final)
    assert tighter.n_modes >= choice.n_modes


def test_tolerance_out_of_reach_takes_every_mode_and_says_so(spacecraft_system):
    choice = choose_modes(spacecraft_system, SineTorque(peak_torque=50.0, duration=2.0), 1e-6,
                          max_modes=4, t_final=20.0)
    assert choice.n_modes == 4 and not choice.meets_tolerance
    assert "No model of up to 4 modes meets the tolerance" in choice.explanation


def test_stiffening_shift_at_a_slow_spin_is_southwells(kane_system):
    spin = SpinUp(spin_rate=0.2, ramp_time=15.0)
    choice = choose_modes(kane_system, spin, 1e-2, t_final=30.0)
    w1 = build_model(kane_system, 1).first_clamped_frequency
    expected = SOUTHWELL_1 * spin.spin_rate ** 2 / (2 * w1 ** 2)
    assert choice.max_spin_rate == pytest.approx(spin.spin_rate)
    assert choice.stiffening_effect == pytest.approx(expected, rel=SOUTHWELL_RTOL)
    assert not choice.stiffening_matters
    assert "does not matter" in choice.explanation


def test_spin_past_the_first_frequency_makes_stiffening_matter(kane_system):
    choice = choose_modes(kane_system, SpinUp(spin_rate=4.0, ramp_time=15.0), 1e-2,
                          t_final=30.0)
    assert choice.stiffening_matters
    assert choice.stiffening_effect > 1.0            # zero_order has no stiffness left
    assert "zero_order diverges" in choice.explanation


def test_zero_order_above_its_first_frequency_is_judged_on_the_stiffened_model(kane_system):
    spin = SpinUp(spin_rate=4.0, ramp_time=15.0)
    zero = choose_modes(kane_system, spin, 1e-2, variant="zero_order", t_final=30.0)
    first = choose_modes(kane_system, spin, 1e-2, variant="first_order", t_final=30.0)
    assert zero.n_modes == first.n_modes
    assert np.all(np.isfinite(zero.error_by_modes))
    assert "diverges whatever the number of modes" in zero.explanation


def test_largest_spin_of_a_torque_pulse_is_the_rigid_rate(spacecraft_system):
    """One period of sine torque: the rigid rate peaks at T_hm T_m / (pi J_0) at T_m / 2."""
    torque = SineTorque(peak_torque=50.0, duration=2.0)
    t = np.linspace(0.0, 20.0, 20001)
    expected = torque.peak_torque * torque.duration / (math.pi * spacecraft_system.rigid_inertia)
    assert largest_spin_rate(spacecraft_system, torque, t) == pytest.approx(expected,
                                                                             rel=GRID_RTOL)
    choice = choose_modes(spacecraft_system, torque, 1e-2, t_final=20.0)
    assert choice.max_spin_rate == pytest.approx(expected, rel=GRID_RTOL)


@pytest.mark.parametrize("slew", [Slew(angle=math.pi / 2, duration=2.0),
                                  Slew(angle=-1.0, torque_bound=6.0)],
                         ids=["fixed-duration", "free-duration"])
def test_rigid_slew_torque_is_rest_to_rest(hub_beam_mass_system, slew):
    torque = rigid_slew_torque(hub_beam_mass_system, slew)
    t = np.linspace(0.0, torque.duration, 20001)
    j0 = hub_beam_mass_system.rigid_inertia
    rate = cumulative_trapezoid(torque(t) / j0, t, initial=0.0)
    angle = cumulative_trapezoid(rate, t, initial=0.0)
    assert angle[-1] == pytest.approx(slew.angle, rel=GRID_RTOL)
    assert abs(rate[-1]) < GRID_RTOL * np.max(np.abs(rate))
    if slew.duration is None:
        assert abs(torque.peak_torque) == pytest.approx(slew.torque_bound)
    else:
        assert torque.duration == slew.duration


def _bad_choose_cases():
    spin = SpinUp(spin_rate=1.0, ramp_time=5.0)
    cases = [
        ({"tolerance": 0.0}, ValueError, "tolerance", "tolerance-zero"),
        ({"tolerance": 1.0}, ValueError, "tolerance", "tolerance-one"),
        ({"tolerance": math.nan}, ValueError, "tolerance", "tolerance-nan"),
        ({"tolerance": "0.1"}, ValueError, "tolerance", "tolerance-string"),
        ({"variant": "second_order"}, ValueError, "variant", "variant"),
        ({"max_modes": 0}, ValueError, "max_modes", "max_modes-zero"),
        ({"max_modes": 2.5}, ValueError, "max_modes", "max_modes-float"),
        ({"max_modes": 6, "reference_modes": 6}, ValueError, "reference_modes",
         "reference-not-larger"),
        ({"t_final": -1.0}, ValueError, "t_final", "t_final-negative"),
        ({"maneuver": object()}, TypeError, "maneuver", "maneuver-object"),
        ({"maneuver": Slew(angle=1.0)}, ValueError, "duration or a torque_bound",
         "slew-without-time-scale"),
    ]
    return [pytest.param(dict({"maneuver": spin}, **kw), exc, pattern, id=name)
            for kw, exc, pattern, name in cases]


@pytest.mark.parametrize("kwargs, exc, pattern", _bad_choose_cases())
def test_choose_modes_rejects_bad_input(kane_system, kwargs, exc, pattern):
    kwargs = dict(kwargs)
    maneuver = kwargs.pop("maneuver")
    with pytest.raises(exc, match=pattern):
        choose_modes(kane_system, maneuver, **kwargs)


def test_mode_choice_is_validated_cached_and_serialisable(kane_system):
    spin = SpinUp(spin_rate=1.0, ramp_time=5.0)
    choice = choose_modes(kane_system, spin, 1e-2, max_modes=4, t_final=10.0)
    assert choose_modes(kane_system, spin, 1e-2, max_modes=4, t_final=10.0) is choice
    data = json.loads(json.dumps(choice.to_dict()))
    assert data["n_modes"] == choice.n_modes and len(data["error_by_modes"]) == 4
    with pytest.raises(ValueError, match="n_modes"):
        ModeChoice(n_modes=5, estimated_error=0.0, tolerance=0.01, variant="first_order",
                   error_by_modes=(0.1, 0.0), reference_modes=8, t_final=1.0,
                   max_spin_rate=0.0, stiffening_effect=0.0, stiffening_matters=False)
    with pytest.raises(ValueError, match="error_by_modes"):
        ModeChoice(n_modes=1, estimated_error=0.0, tolerance=0.01, variant="first_order",
                   error_by_modes=(-0.1,), reference_modes=8, t_final=1.0,
                   max_spin_rate=0.0, stiffening_effect=0.0, stiffening_matters=False)


# ------------------------------------------------------------------ scenes with modes = "auto"
def test_auto_scene_builds_the_chosen_model():
    scene = load_scene("kane-spinup", overrides={"model.modes": "auto"})
    assert scene.model.modes == "auto" and scene.model.tolerance == DEFAULT_TOLERANCE
    choice = scene.mode_choice()
    assert choice.t_final == scene.simulation.t_final
    assert scene.build_model().n_modes == choice.n_modes
    assert load_scene("kane-spinup").mode_choice() is None


def test_auto_scene_from_a_file_with_its_tolerance(tmp_path):
    text = _builtin_text("hub-beam-mass").replace("modes = 4",
                                                    'modes = "auto"\ntolerance = 1e-5')
    path = tmp_path / "auto.toml"
    path.write_text(text)
    scene = load_scene(path)
    assert scene.model.tolerance == 1e-5
    choice = scene.mode_choice()
    assert choice.tolerance == 1e-5
    assert choice.n_modes > load_scene("hub-beam-mass", overrides={
        "model.modes": "auto"}).mode_choice().n_modes



@pytest.mark.parametrize("overrides, pattern", [
    ({"model.tolerance": "-0.01"}, r"model\.tolerance"),
    ({"model.modes": "auto", "model.tolerance": "0"}, r"model\.tolerance"),
    ({"model.modes": "auto", "model.tolerance": "1.5"}, r"model\.tolerance"),
    ({"model.modes": "auto", "model.tolerance": "'tight'"}, r"model\.tolerance"),
    ({"model.modes": "many"}, r"model\.modes.*auto"),
], ids=["tolerance-negative", "tolerance-zero", "tolerance-above-one", "tolerance-string",
        "modes-other-string"])
def test_auto_settings_are_checked_by_name(overrides, pattern):
    with pytest.raises(SceneError, match=pattern):
        load_scene("kane-spinup", overrides=overrides)


def test_tolerance_with_fixed_modes_sets_the_validity_warning():
    """With fixed modes the tolerance still decides when a run warns of its model's range."""
    assert load_scene("kane-spinup", overrides={"model.tolerance": "0.05"}).model.tolerance \
        == 0.05


def test_summary_reports_the_mode_choice(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "kane-spinup", "--set", "model.modes=auto", "--set",
                 "simulation.t_final=10", "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    entry = summary["mode_choice"]
    assert entry["n_modes"] == summary["n_modes"]
    assert entry["tolerance"] == DEFAULT_TOLERANCE
    assert entry["estimated_error"] <= entry["tolerance"] and entry["meets_tolerance"]
    assert entry["t_final"] == 10.0
    assert isinstance(entry["stiffening_matters"], bool) and entry["explanation"]
    assert "mode_choice" in summary["units"]
    fixed = tmp_path / "fixed"
    assert main(["run", "kane-spinup", "--set", "simulation.t_final=2", "--out",
                 str(fixed)]) == 0
    assert "mode_choice" not in json.loads((fixed / "summary.json").read_text())
