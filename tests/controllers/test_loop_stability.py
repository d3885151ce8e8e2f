"""Designs checked on the plant they run on (controllers.design.stability), and LQG without
spillover.

The facts checked: a loop's reported growth rates are the eigenvalues of the closed loop
built independently here; a held law's discrete check tends to the continuous one as the
sample time shrinks; the filter that models only the design modes destabilises the undamped
modes above them (observation spillover) and the built-in one does not, over a long run on
the nonlinear exact plant; a reference the torque limit cannot follow warns by name.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import flexctl
from controllers import (LQRWeights, NoiseLevels, SlewProfile, design_lqg, design_lqr,
                         design_pd, from_spec)
from controllers.factory import _design_model, _lqr_weights, _noise
from controllers.design.stability import (NEARLY_UNSTABLE_RATE, LoopStability, LoopStabilityWarning,
                                          check_loop)
from flexctl.model.errors import InputTypeError
from flexctl.sim.digital import ZeroOrderHold

#: Relative agreement of a growth rate with an independently formed eigenvalue.
RATE_TOLERANCE = 1e-6


@pytest.fixture(scope="module")
def slew90():
    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": "lqg"})
    plant = scene.build_model()
    return scene, plant, _design_model(scene, plant)


def _spillover_lqg(scene, plant, design, **common):
    """The filter of the design modes only (the pre-fix design)."""
    return design_lqg(design, _lqr_weights(scene.controller), _noise(scene.controller),
                      plant=plant, estimate_plant_modes=False, check_stability=False,
                      **common)


def test_filter_of_the_design_modes_only_is_reported_unstable_by_mode(slew90):
    scene, plant, design = slew90
    old = _spillover_lqg(scene, plant, design)
    check = check_loop(plant, old)
    poles = old.closed_loop_poles(plant)            # the LQG's own closed-loop matrix
    assert not check.stable
    assert check.spectral_abscissa == pytest.approx(poles.real.max(), rel=RATE_TOLERANCE)
    worst = check.poles[0]
    frequencies = np.sort(np.abs(np.linalg.eigvals(plant.linear_matrices(0.0)[0]).imag))
    flexible = np.unique(np.round(frequencies[frequencies > 1e-6], 6))
    # the growing pole lies on the third flexible mode, the first one the design left out
    assert worst.mode == design.n_modes + 1
    assert worst.frequency == pytest.approx(flexible[design.n_modes], rel=1e-2)
    assert worst.growth_rate > 0
    assert f"mode {worst.mode}" in check.message() and "grows" in check.message()
    with pytest.warns(LoopStabilityWarning, match=r"LQG is unstable .* mode 3 at"):
        design_lqg(design, _lqr_weights(scene.controller), _noise(scene.controller),
                   plant=plant, estimate_plant_modes=False)


def test_builtin_lqg_filter_models_every_plant_mode_and_is_stable(slew90):
    scene, plant, design = slew90
    with warnings.catch_warnings():
        warnings.simplefilter("error", LoopStabilityWarning)
        built = from_spec(scene, plant)
    lqg = built.controller
    assert lqg.n_states == plant.n_states
    assert lqg.closed_loop_poles(plant).real.max() < 0.0
    report = built.info["loop_stability"]
    assert report["closed_loop_stable"] and not report["nearly_unstable"]
    assert report["plant_modes"] == plant.n_modes and report["plant_variant"] == "exact"


@pytest.mark.slow
def test_builtin_lqg_decays_over_a_long_run_where_the_spillover_filter_grows(slew90):
    """200 s on the nonlinear exact 6-mode plant: the tip keeps decaying with the built-in
    filter; with the design-modes filter the third mode (0.024 1/s) has grown by e^3."""
    scene, plant, design = slew90
    long = flexctl.load_scene("slew-90", overrides={"controller.kind": "lqg",
                                                    "simulation.t_final": 200.0,
                                                    "simulation.output_step": 0.05})
    result, built, metrics = flexctl.run_slew(long, from_spec)
    assert result.status == "ok"
    tip, t = np.abs(result.tip_deflection), result.t
    early = tip[(t >= 10.0) & (t <= 30.0)].max()
    late = tip[t >= 180.0].max()
    assert late < 1e-3 * early
    short = flexctl.load_scene("slew-90", overrides={"controller.kind": "lqg"})
    _, _, short_metrics = flexctl.run_slew(short, from_spec)
    # the slew itself is the same: the residual vibration of the 6 s run is kept
    assert metrics.residual_vibration == pytest.approx(short_metrics.residual_vibration,
                                                       rel=0.05)
    old = _spillover_lqg(scene, plant, design, reference=built.controller.reference,
                         torque_limit=built.controller.torque_limit)
    run = flexctl.simulate(plant, 200.0, controller=old, output_step=0.05, rtol=1e-8)
    tip_old = np.abs(run.tip_deflection)
    grown = tip_old[run.t >= 180.0].max() / tip_old[(run.t >= 10.0) & (run.t <= 30.0)].max()
    assert grown > 5.0


def test_held_law_check_tends_to_the_continuous_one(slew90):
    _, plant, design = slew90
    lqr = design_lqr(design, LQRWeights(hub_angle=0.05, torque=1.0))
    continuous = check_loop(plant, lqr)
    fine = check_loop(plant, ZeroOrderHold(lqr, 1e-5))
    assert fine.sample_time == 1e-5 and continuous.sample_time is None
    assert fine.spectral_abscissa == pytest.approx(continuous.spectral_abscissa, rel=1e-2)


def test_a_stable_loop_reports_no_slow_pole_and_dicts_are_plain():
    system = flexctl.load_scene("hub-beam-mass").system
    plant, design = flexctl.build_model(system, 4), flexctl.build_model(system, 2)
    check = check_loop(plant, design_pd(design, bandwidth=2.0, damping_ratio=0.9))
    assert isinstance(check, LoopStability) and check.ok and check.poles == ()
    assert check.spectral_abscissa < -NEARLY_UNSTABLE_RATE
    assert check.as_dict()["worst_mode"] is None and "stable" in check.message()


def test_undamped_mode_the_law_does_not_touch_is_nearly_unstable():
    """A gain of zero leaves the plant's undamped flexible poles on the axis."""
    system = flexctl.load_scene("hub-beam-mass").system
    plant = flexctl.build_model(system, 2)
    gain = np.zeros((1, plant.n_states))
    gain[0, 0], gain[0, plant.n_states // 2] = 1.0, 2.0       # theta and theta_dot only
    check = check_loop(plant, gain)
    # the hub PD moves the beam through the coupling: every mode damped, none growing
    assert check.stable
    free = check_loop(plant, np.zeros((1, plant.n_states)))
    assert free.nearly_unstable or not free.stable
    assert all(abs(p.growth_rate) < 1e-9 for p in free.poles)


@pytest.mark.parametrize("bad", [object(), "lqr", 3.0], ids=["object", "string", "number"])
def test_check_loop_refuses_what_has_no_linear_loop(bad, slew90):
    _, plant, _ = slew90
    with pytest.raises(InputTypeError, match="check_loop.controller"):
        check_loop(plant, bad)


def test_check_loop_refuses_a_bad_spin_rate(slew90):
    _, plant, design = slew90
    lqr = design_lqr(design, LQRWeights(hub_angle=0.05, torque=1.0))
    for value in (math.nan, math.inf, "fast"):
        with pytest.raises((TypeError, ValueError), match="spin_rate"):
            check_loop(plant, lqr, spin_rate=value)


def test_reference_beyond_the_torque_limit_warns_with_the_shortest_duration():
    system = flexctl.load_scene("slew-90").system
    design = flexctl.build_model(system, 2)
    reference = SlewProfile(slew_angle=math.radians(60.0), duration=3.0)
    needed = design.rigid_inertia * reference.peak_acceleration
    with pytest.warns(UserWarning, match=rf"needs {needed:.3g} N m .* torque_limit = 1 N m"):
        design_lqr(design, LQRWeights(hub_angle=0.05, torque=1.0), reference=reference,
                   torque_limit=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        design_pd(design, 2.0, reference=reference, torque_limit=1.01 * needed)


def test_robustness_rows_name_the_least_damped_mode(slew90):
    from controllers import RobustnessTask

    scene, plant, design = slew90
    old = _spillover_lqg(scene, plant, design)
    row = RobustnessTask(system=scene.system, controller=old, n_modes=6)(
        youngs_modulus_scale=1.0, point_mass_scale=1.0, hub_inertia_scale=1.0)
    check = check_loop(plant, old)
    assert row["closed_loop_stable"] is False
    assert row["worst_mode"] == check.poles[0].mode == 3
    assert row["worst_growth_rate"] == pytest.approx(check.poles[0].growth_rate, rel=1e-6)
