"""Loop requirements verified on the loop as it flies and over the uncertainty.

- The rigid-body phase margin is python-control's at the same crossing.
- A notch at the second mode turns it from phase-stabilised (its peak above 0 dB) to
  gain-stabilised (below -6 dB).
- A roll-off whose lag turns the fourth mode unstable fails the loop's stability and that
  mode's requirement.
- No point of a dense Monte Carlo over the uncertainty box (each mode's frequency and damping
  on its own, the structure's stiffness, masses and hub inertia) is worse than the reported
  worst case of any requirement; the worst over the box is no better than over the common
  frequency factor.
"""

import numpy as np
import pytest

import flexctl
from controllers import Filtered, LQRWeights, Notch, RollOff, design_lqr, loop_margins
from controllers.analysis.requirements import (MODE_WINDOW, Requirements, _point, _Search,
                                               monte_carlo_requirements, verify_requirements)
from flexctl.model.errors import InputError
from flexctl.sim.digital import ZeroOrderHold

SYSTEM = flexctl.load_scene("hub-beam-mass").system
NOTCH = Notch(frequency=23.8, depth_db=20.0)


@pytest.fixture(scope="module")
def held():
    design = flexctl.build_model(SYSTEM, n_modes=1)
    return ZeroOrderHold(design_lqr(design, LQRWeights(hub_angle=0.05, torque=1.0)), 0.01)


def _plant(n_modes):
    return flexctl.build_model(SYSTEM, n_modes=n_modes)


def test_the_rigid_phase_margin_is_python_controls(held):
    report = verify_requirements(_plant(3), Filtered(law=held, filters=[NOTCH]),
                                 Requirements())
    flexible = [m.frequency for m in report.modes]
    rigid = [m for kind, w, m in loop_margins(report.loop).crossings if kind == "gain"
             and all(abs(w / f - 1.0) > MODE_WINDOW for f in flexible)]
    check = {c.name: c for c in report.checks}["phase_margin_deg"]
    assert check.nominal == pytest.approx(min(rigid), abs=1e-3)
    assert check.passed and report.passed


def test_a_notch_turns_the_second_mode_gain_stabilised(held):
    plant = _plant(3)
    bare = verify_requirements(plant, held, Requirements())
    notched = verify_requirements(plant, Filtered(law=held, filters=[NOTCH]), Requirements())
    assert bare.modes[1].kind == "phase" and bare.modes[1].peak_db > 0.0
    assert notched.modes[1].kind == "gain" and notched.modes[1].peak_db < -6.0
    assert [m.kind for m in notched.modes] == ["phase", "gain", "gain"]


def test_a_roll_off_that_destabilises_a_mode_fails(held):
    """Undamped (as check_loop judges it), the roll-off's lag turns mode 4 unstable; with
    0.1 % damping the same loop is stable."""
    law = Filtered(law=held, filters=[NOTCH, RollOff(frequency=60.0)])
    damped = verify_requirements(_plant(4), law, Requirements())
    assert {c.name: c for c in damped.checks}["closed_loop_stable"].passed
    report = verify_requirements(_plant(4), law, Requirements(damping_range=(0.0, 0.0)))
    checks = {c.name: c for c in report.checks}
    assert not checks["closed_loop_stable"].passed and not report.passed
    entry = checks["closed_loop_stable"].as_dict()
    assert set(entry) >= {"name", "required", "nominal", "worst", "pass"}
    assert entry["pass"] is False


@pytest.mark.slow
def test_no_monte_carlo_point_is_worse_than_the_reported_worst(held):
    """Every modal frequency on its own within +-20 %, every damping ratio 0.001 to 0.01,
    stiffness, point mass and hub inertia within +-10 %: 300 random plants (another seed than
    the search's own draws) find no worse case of any requirement than the one reported, and
    the reported worst plant gives the reported worst value."""
    plant = _plant(3)
    law = Filtered(law=held, filters=[NOTCH])
    req = Requirements(frequency_uncertainty=0.2, stiffness_uncertainty=0.1,
                       mass_uncertainty=0.1, hub_inertia_uncertainty=0.1)
    report = verify_requirements(plant, law, req)
    sampled = monte_carlo_requirements(plant, law, req, 300, seed=7)
    search = _Search(plant, law, req, 0.0)
    for check in report.checks:
        value, point = sampled[check.name]
        slack = 1e-9 * (1.0 if np.isinf(check.worst) else max(1.0, abs(check.worst)))
        assert not value < check.worst - slack, (check.name, point.describe(), value,
                                                 check.worst)
        assert search.value(check.worst_at, check.name) == pytest.approx(check.worst,
                                                                         rel=1e-12)
    assert not {c.name: c for c in report.checks}["flexible mode 3"].worst_at.describe() \
        == "the nominal plant"


def test_a_mode_on_its_own_is_worse_than_all_modes_together(held):
    """The common frequency factor is one line through the box of independent factors: the
    worst case over the box is no better than the worst of 41 common factors at either end
    of the damping range."""
    plant = _plant(3)
    law = Filtered(law=held, filters=[NOTCH])
    report = verify_requirements(plant, law, Requirements(frequency_uncertainty=0.2))
    search = _Search(plant, law, Requirements(frequency_uncertainty=0.2), 0.0)
    common = {}
    for f in np.linspace(0.8, 1.2, 41):
        for z in (0.001, 0.01):
            point = _point(factors=(f,) * 3, dampings=(z,) * 3)
            for check in report.checks:
                value = search.value(point, check.name)
                common[check.name] = min(common.get(check.name, np.inf), value)
    for check in report.checks:
        assert check.worst <= common[check.name] + 1e-9, check.name


@pytest.mark.parametrize("make, pattern", [
    (lambda: Requirements(gain_margin_db=0.0), "requirements.gain_margin_db"),
    (lambda: Requirements(phase_margin_deg=200.0), "requirements.phase_margin_deg"),
    (lambda: Requirements(frequency_uncertainty=0.8), "requirements.frequency_uncertainty"),
    (lambda: Requirements(damping_range=(0.1,)), "requirements.damping_range"),
    (lambda: Requirements(damping_range=(float("nan"), 0.1)), "requirements.damping_range"),
    (lambda: Requirements(delay_margin=-1.0), "requirements.delay_margin"),
    (lambda: Requirements(bandwidth="fast"), "requirements.bandwidth"),
], ids=["gain", "phase", "uncertainty", "short-range", "nan-damping", "delay", "bandwidth"])
def test_bad_requirements_are_refused_by_name(make, pattern):
    with pytest.raises(InputError, match=pattern):
        make()


# ------------------------------------------------------------------ the scene's table
SCENE = {"model.variant": "first_order", "model.design_variant": "first_order",
         "model.modes": "3", "controller.kind": "lqr", "controller.sample_time": "0.01",
         "controller.filters": '[{kind = "notch", frequency = 23.8, depth_db = 20}]',
         "requirements.gain_margin_db": "6", "requirements.phase_margin_deg": "30",
         "requirements.damping_range": "[0.001, 0.01]"}


@pytest.mark.filterwarnings("ignore::flexctl.sim.validity.ModelValidityWarning")
def test_a_scene_writes_its_requirements_and_a_nichols_chart(tmp_path):
    import json

    from flexctl.app.runner import execute, write_complete

    scene = flexctl.load_scene("slew-90", overrides=SCENE)
    result, extra, reference = execute(scene)
    summary = write_complete(scene, result, tmp_path / "run", SCENE, extra, reference)
    written = json.loads((tmp_path / "run" / "summary.json").read_text())
    entries = written["requirements"]
    assert [e["name"] for e in entries][:3] == ["closed_loop_stable", "gain_margin_db",
                                                "phase_margin_deg"]
    assert all(set(e) >= {"name", "required", "nominal", "worst", "pass"} for e in entries)
    assert written["requirements_passed"] == all(e["pass"] for e in entries)
    modes = written["flexible_modes"]
    assert len(modes) == 3 and {m["stabilised_by"] for m in modes} <= {"gain", "phase"}
    assert [m["mode"] for m in modes] == [1, 2, 3]
    assert (tmp_path / "run" / "nichols.png").stat().st_size > 10_000
    assert (tmp_path / "run" / "bode.png").stat().st_size > 10_000
    assert summary["files"]["nichols_plot"].endswith("nichols.png")
    assert flexctl.load_scene(tmp_path / "run" / "summary.json").requirements \
        == scene.requirements


@pytest.mark.parametrize("kind", ["trajopt", "nmpc"])
def test_requirements_need_a_linear_feedback_loop(kind):
    from flexctl import SceneError

    with pytest.raises(SceneError, match=r"\[requirements\] are verified on a linear feedback"):
        flexctl.load_scene("slew-90", overrides={"controller.kind": kind,
                                                 "requirements.gain_margin_db": "6"})


def test_design_filters_notches_the_modes_it_can_and_names_the_one_it_cannot(held):
    """Phase margins of 170 deg leave attenuation as the only way for a mode to pass: the
    second and third modes can be notched to 12 dB below unit gain, the first (inside the
    loop's bandwidth) cannot, and the design says so with its worst ratio."""
    from controllers.analysis.filter_design import design_filters

    plant = _plant(3)
    req = Requirements(flexible_attenuation_db=12.0, flexible_phase_margin_deg=170.0)
    before = {c.name: c for c in verify_requirements(plant, held, req).checks}
    assert not any(before[f"flexible mode {k}"].passed for k in (1, 2, 3))
    design = design_filters(plant, held, req)
    assert not design.met and [name for name, _, _ in design.unmet] == ["flexible mode 1"]
    after = {c.name: c for c in design.verification.checks}
    assert after["flexible mode 2"].passed and after["flexible mode 3"].passed
    assert after["phase_margin_deg"].passed and after["closed_loop_stable"].passed
    assert all(isinstance(f, Notch) for f in design.added)
    assert design.controller.filters == design.added
    again = verify_requirements(plant, design.controller, req)
    assert [c.worst for c in again.checks] == [c.worst for c in design.verification.checks]


@pytest.mark.parametrize("call, pattern", [
    (lambda held: verify_requirements("plant", held, Requirements()), "plant must be a planar"),
    (lambda held: verify_requirements(_plant(2), held, {"gain_margin_db": 6.0}),
     "requirements must be a Requirements"),
    (lambda held: verify_requirements(_plant(2), held, Requirements(), spin_rate=float("nan")),
     "spin_rate"),
    (lambda held: verify_requirements(_plant(2), object(), Requirements()),
     "loop_transfer.controller"),
], ids=["plant", "requirements", "spin", "controller"])
def test_bad_verification_inputs_are_refused_by_name(held, call, pattern):
    with pytest.raises(InputError, match=pattern):
        call(held)


@pytest.mark.parametrize("value", [0, -1, "3", True, 2.5, 11])
def test_design_filters_refuses_a_bad_filter_count(held, value):
    from controllers.analysis.filter_design import design_filters

    with pytest.raises(InputError, match="design_filters.max_filters"):
        design_filters(_plant(2), held, Requirements(), max_filters=value)
