"""The frequency-domain view of the flexible loop (controllers.analysis.loops,
controllers.analysis.robustness,
flexctl.app.plotting_loops): physics and contracts.

Physics checked against independent facts, not numbers of the code itself:

- the plant's poles are the rigid double pole and +-j the hub-free frequencies, the hub-angle
  zeros +-j the clamped ones (at rest and spinning); the tip-angle channel is non-minimum
  phase;
- collocated PD is stable with an infinite gain margin for any positive gains, mode count and
  spin rate; tip feedback is unstable on an undamped beam and, on a damped one, has a finite
  gain margin;
- LQR on its own design model has Kalman's margins (phase >= 60 deg, gain up to infinity and
  down to 1/2, |1 + L| >= 1); LQG has finite ones;
- every gain margin is the gain at which the closed-loop eigenvalues cross the axis;
- the closed loop's poles equal those of controllers.feedback.lqr.closed_loop_poles and
  LQG.closed_loop_poles, built without python-control;
- a Young's modulus factor s scales every frequency by sqrt(s).
"""

import dataclasses
import math

import control
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import flexctl
from controllers import (PD, LQRWeights, NoiseLevels, closed_loop_poles, design_lqg,
                         design_lqr, design_pd, pd_gains)
from controllers.analysis.loops import (SENSORS, LoopMargins, loop_margins, loop_transfer,
                                        plant_channels, poles_vs_spin)
from controllers.analysis.robustness import (SCALES, Dispersion, RobustnessTask, disperse,
                                             robustness_summary)
from flexctl.model.errors import InputTypeError, InputValueError

from conftest import scene_system

#: Roots (1/s) agree to this fraction of the largest root magnitude.
ROOT_RTOL = 1e-7
#: The closed loop just inside and outside a gain margin: gain factors (1 -+ MARGIN_STEP).
MARGIN_STEP = 0.02
#: Kalman's LQR guarantees, less rounding.
KALMAN_PHASE_MARGIN = 60.0 - 1e-6
KALMAN_RETURN_DIFFERENCE = 1.0 - 1e-6


@pytest.fixture(scope="module")
def system():
    """slew-90's hub-beam-mass system (undamped beam, frictionless hub)."""
    return scene_system("slew-90")


def damped(system, zeta):
    return dataclasses.replace(system, beam=dataclasses.replace(system.beam,
                                                                damping_ratio=zeta))


@pytest.fixture(scope="module")
def lqr_weights():
    return LQRWeights(hub_angle=0.05, hub_rate=0.02, tip_deflection=0.01, torque=1.0)


def spectral_abscissa(loop, gain=1.0):
    return float(np.max(control.poles(control.feedback(gain * loop)).real))


def assert_same_roots(got, want, scale=None):
    """Two multisets of complex roots agree (each matched to its nearest partner)."""
    got, want = np.asarray(got, dtype=complex), np.asarray(want, dtype=complex)
    assert got.shape == want.shape
    scale = scale or max(1.0, np.max(np.abs(want)))
    remaining = list(got)
    for root in want:
        k = int(np.argmin(np.abs(np.array(remaining) - root)))
        assert abs(remaining.pop(k) - root) <= ROOT_RTOL * scale, (root, got)


def assert_margins_bound_stability(loop, margins):
    """The gain margins of a stable loop are where its eigenvalues cross the imaginary axis."""
    assert margins.closed_loop_stable
    for bound in (margins.gain_margin, margins.gain_reduction_margin):
        if 0.0 < bound < math.inf:
            inside = (1.0 - MARGIN_STEP) * bound if bound > 1.0 else (1.0 + MARGIN_STEP) * bound
            outside = (1.0 + MARGIN_STEP) * bound if bound > 1.0 else (1.0 - MARGIN_STEP) * bound
            assert spectral_abscissa(loop, inside) < 0.0, bound
            assert spectral_abscissa(loop, outside) > 0.0, bound


# --------------------------------------------------------------------------- plant channels
@pytest.mark.parametrize("n_modes", [1, 2, 4], ids=lambda n: f"N{n}")
@pytest.mark.parametrize("spin_rate", [0.0, 3.0], ids=["rest", "spin3"])
def test_plant_poles_and_hub_angle_zeros_are_the_hub_free_and_clamped_frequencies(
        system, n_modes, spin_rate):
    model = flexctl.build_model(system, n_modes)
    channels = plant_channels(model, spin_rate)
    free = model.natural_frequencies(spin_rate, hub="free")
    clamped = model.natural_frequencies(spin_rate, hub="clamped")
    assert_same_roots(control.poles(channels.hub_angle),
                      np.concatenate(([0.0, 0.0], 1j * free, -1j * free)))
    assert_same_roots(control.zeros(channels.hub_angle),
                      np.concatenate((1j * clamped, -1j * clamped)))
    np.testing.assert_array_equal(channels.natural_frequencies, free)
    np.testing.assert_array_equal(channels.clamped_frequencies, clamped)
    # poles and zeros interlace: a collocated pair, zero below pole, mode by mode
    assert np.all(clamped < free) and np.all(free[:-1] < clamped[1:])


def test_tip_angle_channel_is_non_minimum_phase_and_hub_angle_is_not(system):
    channels = plant_channels(flexctl.build_model(system, 3))
    scale = np.max(np.abs(control.poles(channels.hub_angle)))
    assert np.max(control.zeros(channels.tip_angle).real) > 1.0           # RHP zeros, 1/s
    assert np.max(np.abs(control.zeros(channels.hub_angle).real)) < ROOT_RTOL * scale
    assert channels.hub_angle.output_labels == ["theta"]
    assert channels.tip_deflection.output_labels == ["tip_deflection"]
    # the same rows as the model's output matrix
    model = flexctl.build_model(system, 3)
    np.testing.assert_array_equal(channels.tip_deflection.C[0], model.output_matrix[2])


def test_plant_channels_repr_is_one_short_line(system):
    channels = plant_channels(flexctl.build_model(system, 6), 2.0)
    text = repr(channels)
    assert "\n" not in text and len(text) < 200, text
    assert text.startswith("PlantChannels(")
    for identifying in ("theta", "tip_deflection", "tip_angle", "spin_rate=2 rad/s",
                        "14 states", "6 modes"):
        assert identifying in text, text


# --------------------------------------------------------------------------- collocated PD
@pytest.mark.parametrize("n_modes", [1, 2, 4, 8], ids=lambda n: f"N{n}")
@pytest.mark.parametrize("bandwidth,damping_ratio", [(0.5, 0.3), (2.0, 0.9), (10.0, 1.0)],
                         ids=["slow", "nominal", "fast"])
def test_collocated_pd_is_stable_with_infinite_gain_margin_for_any_mode_count(
        system, n_modes, bandwidth, damping_ratio):
    model = flexctl.build_model(system, n_modes)
    kp, kd = pd_gains(model, bandwidth, damping_ratio)
    loop = loop_transfer(model, PD(kp=kp, kd=kd))
    margins = loop_margins(loop)
    assert margins.closed_loop_stable
    assert margins.gain_margin == math.inf and margins.gain_reduction_margin == 0.0
    assert margins.phase_margin > 0.0
    for gain in np.logspace(-2, 2, 9):
        assert spectral_abscissa(loop, gain) < 0.0, gain


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(kp=st.floats(1e-2, 1e3), kd=st.floats(1e-2, 1e3), n_modes=st.integers(1, 4),
       spin_rate=st.floats(0.0, 5.0))
def test_collocated_pd_is_stable_for_any_positive_gains_and_spin(system, kp, kd, n_modes,
                                                                 spin_rate):
    model = flexctl.build_model(system, n_modes)
    margins = loop_margins(loop_transfer(model, PD(kp=kp, kd=kd), spin_rate))
    assert margins.closed_loop_stable and margins.gain_margin == math.inf


def test_collocated_pd_loop_is_the_state_feedback_of_its_state_gain(system):
    model = flexctl.build_model(system, 3)
    pd = design_pd(model, bandwidth=2.0)
    loop = loop_transfer(model, pd)
    assert_same_roots(control.poles(control.feedback(loop)),
                      closed_loop_poles(model, pd.state_gain(3)))


# --------------------------------------------------------------------------- tip feedback
@pytest.mark.parametrize("sensor", ["tip_angle", "tip_deflection"])
def test_tip_feedback_on_an_undamped_beam_is_unstable_at_every_gain(system, sensor):
    model = flexctl.build_model(system, 3)
    kp, kd = pd_gains(model, 2.0, 0.9)
    loop = loop_transfer(model, PD(kp=kp, kd=kd), sensor=sensor)
    assert not loop_margins(loop).closed_loop_stable
    for gain in np.logspace(-3, 2, 11):
        assert spectral_abscissa(loop, gain) >= 0.0, gain


@pytest.mark.parametrize("zeta", [0.005, 0.02])
def test_tip_angle_feedback_on_a_damped_beam_has_a_finite_gain_margin(system, zeta):
    model = flexctl.build_model(damped(system, zeta), 3)
    kp, kd = pd_gains(model, 2.0, 0.9)
    nominal = loop_margins(loop_transfer(model, PD(kp=kp, kd=kd), sensor="tip_angle"))
    assert not nominal.closed_loop_stable
    # turned down below where it loses stability, the tip loop is stable, but only just
    scale = 0.5 * nominal.gain_reduction_margin
    loop = loop_transfer(model, PD(kp=scale * kp, kd=scale * kd), sensor="tip_angle")
    margins = loop_margins(loop)
    assert margins.closed_loop_stable
    assert 1.0 < margins.gain_margin < 10.0
    assert_margins_bound_stability(loop, margins)
    # the nominal loop regains stability just below its gain-reduction margin
    nominal_loop = loop_transfer(model, PD(kp=kp, kd=kd), sensor="tip_angle")
    bound = nominal.gain_reduction_margin
    assert spectral_abscissa(nominal_loop, (1.0 - MARGIN_STEP) * bound) < 0.0
    assert spectral_abscissa(nominal_loop, (1.0 + MARGIN_STEP) * bound) > 0.0


# --------------------------------------------------------------------------- LQR and LQG
@pytest.mark.parametrize("n_modes,spin_rate", [(1, 0.0), (2, 0.0), (3, 0.0), (2, 2.0)],
                         ids=["N1", "N2", "N3", "N2-spin2"])
def test_lqr_on_its_design_model_has_kalmans_margins(system, lqr_weights, n_modes,
                                                     spin_rate):
    model = flexctl.build_model(system, n_modes)
    lqr = design_lqr(model, lqr_weights, spin_rate)
    loop = loop_transfer(model, lqr, spin_rate)
    margins = loop_margins(loop)
    assert margins.closed_loop_stable
    assert margins.gain_margin == math.inf
    assert margins.gain_reduction_margin <= 0.5
    assert abs(margins.phase_margin) >= KALMAN_PHASE_MARGIN
    assert margins.stability_margin >= KALMAN_RETURN_DIFFERENCE
    # |1 + L(jw)| >= 1 on a grid too, not only at python-control's minimum
    response = control.frequency_response(loop, np.logspace(-2, 3, 4000))
    assert np.min(np.abs(1.0 + response.complex.ravel())) >= KALMAN_RETURN_DIFFERENCE


def test_lqr_on_a_plant_with_more_modes_has_poles_of_closed_loop_poles(system, lqr_weights):
    lqr = design_lqr(flexctl.build_model(system, 2), lqr_weights)
    plant = flexctl.build_model(system, 5)
    loop = loop_transfer(plant, lqr)
    assert_same_roots(control.poles(control.feedback(loop)),
                      closed_loop_poles(plant, lqr.state_gain(5)))
    margins = loop_margins(loop)
    assert_margins_bound_stability(loop, margins)


@pytest.fixture(scope="module")
def lqg_on_design(system, lqr_weights):
    model = flexctl.build_model(system, 2)
    noise = NoiseLevels(angle=1e-3, root_moment=0.1, torque=0.1)
    return model, design_lqg(model, lqr_weights, noise)


def test_lqg_margins_are_finite_and_bound_its_stability(lqg_on_design):
    model, lqg = lqg_on_design
    loop = loop_transfer(model, lqg)
    margins = loop_margins(loop)
    assert margins.closed_loop_stable
    assert margins.gain_margin < math.inf or margins.gain_reduction_margin > 0.0
    assert margins.stability_margin < 1.0          # no Kalman guarantee for output feedback
    assert_margins_bound_stability(loop, margins)


@pytest.mark.parametrize("n_plant_modes", [2, 4])
def test_lqg_closed_loop_poles_from_the_loop_equal_lqg_closed_loop_poles(system, lqg_on_design,
                                                                        n_plant_modes):
    _, lqg = lqg_on_design
    plant = flexctl.build_model(system, n_plant_modes)
    loop = loop_transfer(plant, lqg)
    assert loop.nstates == plant.n_states + lqg.n_states
    assert_same_roots(control.poles(control.feedback(loop)), lqg.closed_loop_poles(plant))


def test_margins_follow_python_control_on_an_ordinary_loop():
    loop = control.ss(control.tf([4.0], [1.0, 3.0, 2.0, 0.0]))   # 4 / (s (s + 1) (s + 2))
    gm, pm, sm, wpc, wgc, wms = control.stability_margins(loop)
    margins = loop_margins(loop)
    assert margins.gain_margin == pytest.approx(gm) == pytest.approx(1.5)
    assert margins.phase_margin == pytest.approx(pm)
    assert margins.phase_crossover_frequency == pytest.approx(wpc) == pytest.approx(math.sqrt(2))
    assert margins.gain_crossover_frequency == pytest.approx(wgc)
    assert margins.stability_margin == pytest.approx(sm)
    assert margins.gain_margin_db == pytest.approx(20 * math.log10(1.5))
    assert_margins_bound_stability(loop, margins)


# --------------------------------------------------------------------------- against spin
def test_poles_vs_spin_at_rest_are_the_rigid_double_pole_and_hub_free_modes(system,
                                                                             lqr_weights):
    model = flexctl.build_model(system, 3)
    lqr = design_lqr(flexctl.build_model(system, 2), lqr_weights)
    rates = [0.0, 1.5, 4.0]
    table = poles_vs_spin(model, rates, lqr)
    assert table.plant_poles.shape == (3, 8) and table.hub_angle_zeros.shape == (3, 6)
    assert table.closed_loop_poles.shape == (3, 8)
    for k, rate in enumerate(rates):
        free = model.natural_frequencies(rate, hub="free")
        assert_same_roots(table.plant_poles[k],
                          np.concatenate(([0.0, 0.0], 1j * free, -1j * free)))
        np.testing.assert_allclose(table.natural_frequencies[k], free)
        clamped = model.natural_frequencies(rate)
        assert_same_roots(table.hub_angle_zeros[k], np.concatenate((1j * clamped,
                                                                    -1j * clamped)))
        assert_same_roots(table.closed_loop_poles[k],
                          closed_loop_poles(model, lqr.state_gain(3), rate))
    # centrifugal stiffening: every flexible frequency rises with the spin rate
    assert np.all(np.diff(table.natural_frequencies, axis=0) > 0.0)
    assert poles_vs_spin(model, [0.0]).closed_loop_poles is None


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("call,error,match", [
    (lambda m: loop_transfer("model", PD(kp=1.0, kd=1.0)), InputTypeError,
     "loop_transfer.model must be a flexctl Model; got str"),
    (lambda m: loop_transfer(m, PD(kp=1.0, kd=1.0), sensor="hub"), InputValueError,
     "loop_transfer.sensor must be one of theta, tip_angle, tip_deflection; got 'hub'"),
    (lambda m: loop_transfer(m, design_lqr(m, LQRWeights(hub_angle=0.1, torque=1.0)),
                             sensor="theta"), InputValueError, "applies to a PD law only"),
    (lambda m: loop_transfer(m, "pd"), InputTypeError,
     "loop_transfer.controller must be a PD, LQR.*got str"),
    (lambda m: loop_transfer(m, np.ones(3)), InputValueError,
     r"controller gain must be finite with shape \(1, 2 M \+ 2\).*got shape \(1, 3\)"),
    (lambda m: loop_transfer(m, np.ones(8)), InputValueError, "M <= the plant's 2 modes"),
    (lambda m: loop_transfer(m, PD(kp=1.0, kd=1.0), math.nan), InputValueError,
     "loop_transfer.spin_rate must be finite; got nan"),
    (lambda m: loop_transfer(m, PD(kp=1.0, kd=1.0), "1"), InputTypeError,
     "loop_transfer.spin_rate must be a real number; got '1'"),
    (lambda m: plant_channels(m, math.inf), InputValueError, "plant_channels.spin_rate"),
    (lambda m: loop_margins(m.linearize()), InputValueError,
     "loop_margins.loop must be a SISO system, continuous or with a sample time; got 5 x 1"),
    (lambda m: loop_margins(control.ss([[0.5]], [[1]], [[1]], [[0]], dt=True)),
     InputValueError, "continuous or with a sample time.*dt = True"),
    (lambda m: loop_margins("L"), InputTypeError, "loop_margins.loop must be a python-control"),
    (lambda m: loop_margins(control.tf([1], [1, 1]), tolerance=0.0), InputValueError,
     "loop_margins.tolerance must be finite and > 0"),
    (lambda m: poles_vs_spin(m, []), InputValueError, "spin_rates must be a non-empty 1-D"),
    (lambda m: poles_vs_spin(m, [0.0, math.nan]), InputValueError, "finite numbers"),
    (lambda m: poles_vs_spin(m, "0 1"), InputTypeError, "spin_rates must be a sequence"),
    (lambda m: poles_vs_spin(m, [[0.0, 1.0]]), InputValueError, "non-empty 1-D"),
], ids=["model", "sensor", "sensor-lqr", "controller", "gain-shape", "gain-modes", "spin-nan",
        "spin-str", "channels-spin", "margins-mimo", "margins-discrete", "margins-type",
        "margins-tolerance", "spin-empty", "spin-nan-list", "spin-str-list", "spin-2d"])
def test_bad_input_is_refused_naming_it(system, call, error, match):
    with pytest.raises(error, match=match):
        call(flexctl.build_model(system, 2))


def test_lqr_designed_on_more_modes_than_the_plant_is_refused(system, lqr_weights):
    lqr = design_lqr(flexctl.build_model(system, 3), lqr_weights)
    with pytest.raises(ValueError, match="n_design_modes must be <= n_plant_modes = 2"):
        loop_transfer(flexctl.build_model(system, 2), lqr)


@pytest.mark.parametrize("field,value,match", [
    ("gain_margin", 0.5, "loop_margins.gain_margin must be finite and >= 1; got 0.5"),
    ("gain_reduction_margin", 2.0, "gain_reduction_margin must be finite and >= 0 and <= 1"),
    ("phase_margin", 400.0, r"phase_margin must lie in \[-180, 180\] deg or be inf; got 400"),
    ("stability_margin", -1.0, "stability_margin must be >= 0; got -1.0"),
    ("gain_crossover_frequency", -2.0, "gain_crossover_frequency must be >= 0 rad/s or NaN"),
    ("closed_loop_stable", "yes", "closed_loop_stable must be a bool; got 'yes'"),
])
def test_loop_margins_are_validated_on_construction(field, value, match):
    good = dict(gain_margin=math.inf, gain_reduction_margin=0.0, phase_margin=60.0,
                stability_margin=0.8, phase_crossover_frequency=math.nan,
                gain_crossover_frequency=2.0, stability_margin_frequency=3.0,
                spectral_abscissa=-0.1, closed_loop_stable=True)
    LoopMargins(**good)
    with pytest.raises((InputValueError, InputTypeError), match=match):
        LoopMargins(**{**good, field: value})


# --------------------------------------------------------------------------- robustness
def test_dispersion_samples_lie_in_their_ranges_and_repeat_with_the_seed():
    dispersion = Dispersion(youngs_modulus=0.1, point_mass=0.3, hub_inertia=0.05)
    samples = dispersion.samples(400, seed=3)
    assert samples == dispersion.samples(400, seed=3) != dispersion.samples(400, seed=4)
    for name, spread in zip(SCALES, (0.1, 0.3, 0.05)):
        values = np.array([s[name] for s in samples])
        assert np.all(np.abs(values - 1.0) <= spread)
        assert abs(values.mean() - 1.0) < 0.2 * spread          # centred on the nominal
        assert values.std() == pytest.approx(spread / math.sqrt(3.0), rel=0.15)
    normal = Dispersion(youngs_modulus=0.1, distribution="normal").samples(400)
    values = np.array([s["youngs_modulus_scale"] for s in normal])
    assert values.std() == pytest.approx(0.1, rel=0.15) and values.min() >= 0.7


def test_a_youngs_modulus_factor_scales_every_frequency_by_its_square_root(system):
    nominal = flexctl.build_model(system, 4).natural_frequencies(hub="free")
    stiff = flexctl.build_model(disperse(system, youngs_modulus_scale=1.21), 4)
    np.testing.assert_allclose(stiff.natural_frequencies(hub="free"), 1.1 * nominal,
                               rtol=1e-10)
    heavy = disperse(system, point_mass_scale=2.0, hub_inertia_scale=0.5)
    assert heavy.masses[0].mass == 2.0 * system.masses[0].mass
    assert heavy.hub.inertia == 0.5 * system.hub.inertia
    assert heavy.beam == system.beam


def test_robustness_task_at_the_nominal_point_gives_the_nominal_margins(system, lqr_weights):
    lqr = design_lqr(flexctl.build_model(system, 2), lqr_weights)
    row = RobustnessTask(system=system, controller=lqr, n_modes=4)()
    nominal = loop_margins(loop_transfer(flexctl.build_model(system, 4), lqr))
    assert {k: row[k] for k in nominal.as_dict()} == pytest.approx(nominal.as_dict(),
                                                                    nan_ok=True)
    assert row["first_frequency"] == pytest.approx(
        flexctl.build_model(system, 4).natural_frequencies(hub="free")[0])


def test_collocated_pd_stays_stable_over_a_wide_dispersion(system):
    pd = design_pd(flexctl.build_model(system, 2), bandwidth=2.0, damping_ratio=0.9)
    task = RobustnessTask(system=system, controller=pd, n_modes=4)
    wide = Dispersion(youngs_modulus=0.5, point_mass=0.9, hub_inertia=0.9)
    summary = robustness_summary([task(**s) for s in wide.samples(25, seed=7)])
    assert summary.n_samples == summary.n_stable == 25
    assert summary.worst_gain_margin == math.inf and summary.worst_phase_margin > 30.0


def test_robustness_task_flies_the_slew_on_the_dispersed_plant(system):
    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": "pd"})
    from controllers import from_spec

    built = from_spec(scene, flexctl.build_model(system, 2))
    task = RobustnessTask(system=system, controller=built.controller, n_modes=2,
                          slew_time=built.maneuver_end + 2.0)
    row = task(youngs_modulus_scale=0.9)
    assert row["status"] == "ok"
    assert abs(row["final_error"]) < 0.02 * scene.maneuver.angle
    assert row["peak_torque"] <= scene.maneuver.torque_bound + 1e-9
    assert row["youngs_modulus_scale"] == 0.9 and row["closed_loop_stable"]


@pytest.mark.parametrize("make,match", [
    (lambda s, pd: Dispersion(youngs_modulus=1.0), "dispersion.youngs_modulus must be < 1"),
    (lambda s, pd: Dispersion(point_mass=0.4, distribution="normal"),
     "dispersion.point_mass must be < 0.3333 for a normal draw"),
    (lambda s, pd: Dispersion(distribution="beta"), "dispersion.distribution must be one of"),
    (lambda s, pd: Dispersion(hub_inertia=-0.1), "dispersion.hub_inertia must be finite and >= 0"),
    (lambda s, pd: Dispersion().samples(0), "n_samples must be an integer >= 1; got 0"),
    (lambda s, pd: disperse(s, youngs_modulus_scale=0.0),
     "disperse.youngs_modulus_scale must be finite and > 0; got 0.0"),
    (lambda s, pd: disperse("system"),
     "disperse.system must be a HubBeam or a Structure; got str"),
    (lambda s, pd: RobustnessTask(system=s, controller=pd, n_modes=0),
     "robustness_task.n_modes must be an integer in"),
    (lambda s, pd: RobustnessTask(system=s, controller=pd, variant="exactish"),
     "robustness_task.variant must be one of"),
    (lambda s, pd: RobustnessTask(system=s, controller=pd, slew_time=5.0),
     "slew_time needs a controller with a slew reference"),
    (lambda s, pd: RobustnessTask(system=s, controller=pd, sensor="hub"),
     "loop_transfer.sensor must be one of"),
    (lambda s, pd: RobustnessTask(system=s, controller=object()),
     "loop_transfer.controller must be"),
    (lambda s, pd: robustness_summary([]), "must hold at least one row"),
    (lambda s, pd: robustness_summary([{"gain_margin": 2.0}]),
     "row 0 must hold the columns closed_loop_stable"),
    (lambda s, pd: robustness_summary({"gain_margin": [2.0]}),
     "table must be a SweepResult or a sequence of row dicts; got dict"),
], ids=["dispersion-range", "dispersion-normal", "distribution", "dispersion-negative",
        "samples", "scale", "system", "modes", "variant", "slew-reference", "sensor",
        "controller", "summary-empty", "summary-columns", "summary-type"])
def test_robustness_bad_input_is_refused_naming_it(system, make, match):
    with pytest.raises((InputValueError, InputTypeError), match=match):
        make(system, PD(kp=1.0, kd=1.0))


def test_robustness_study_on_a_dask_local_cluster(system, lqr_weights):
    distributed = pytest.importorskip("distributed")
    from flexctl.app.sweep import sweep

    lqr = design_lqr(flexctl.build_model(system, 2), lqr_weights)
    task = RobustnessTask(system=system, controller=lqr, n_modes=3)
    samples = Dispersion().samples(6, seed=11)
    expected = sweep(task, samples, progress=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        table = sweep(task, samples, executor=client.get_executor(), progress=False)
        assert len(client.scheduler_info()["workers"]) == 1
    assert table.parameters == SCALES
    for got, want in zip(table.rows, expected.rows):
        assert got == pytest.approx(want, nan_ok=True)
    summary = robustness_summary(table)
    assert summary.n_samples == 6 and summary == robustness_summary(expected)


# --------------------------------------------------------------------------- figures
def test_loop_figures_mark_the_flexible_modes(system, lqr_weights):
    from flexctl.app.plotting_loops import (plot_bode, plot_frequencies_vs_spin,
                                            plot_pole_zero, plot_poles_vs_spin,
                                            plot_robustness)

    model = flexctl.build_model(system, 3)
    free = model.natural_frequencies(hub="free")
    lqr = design_lqr(flexctl.build_model(system, 2), lqr_weights)
    loops = {"PD": loop_transfer(model, design_pd(model, 2.0)), "LQR": loop_transfer(model, lqr)}
    fig = plot_bode(loops, natural_frequencies=free, omega_limits=(0.1, 300.0))
    magnitude, phase = fig.axes[:2]
    mode_lines = [line for line in magnitude.lines if line.get_linestyle() == ":"]
    assert sorted(line.get_xdata()[0] for line in mode_lines) == pytest.approx(sorted(free))
    assert len(magnitude.get_legend().get_texts()) == 2
    # one label per mode, or per group of near-equal modes: no two labels overprint
    labels = [t for t in magnitude.texts if "mode" in t.get_text()]
    spots = sorted(t.get_position()[0] for t in labels)
    assert len(labels) >= 1 and all(b > 1.15 * a for a, b in zip(spots, spots[1:]))
    import matplotlib.pyplot as plt

    from flexctl.app.plotting_loops import mark_modes
    fig_twins, ax = plt.subplots()
    mark_modes(ax, [4.2466, 4.2466, 24.8, 25.4, 68.7])
    assert [(t.get_position()[0], t.get_text().strip()) for t in ax.texts] == [
        (4.2466, "modes 1, 2"), (24.8, "modes 3, 4"), (68.7, "mode 5")]
    plt.close(fig_twins)
    channels = plant_channels(model)
    fig = plot_pole_zero({"hub angle": channels.hub_angle}, natural_frequencies=free)
    assert sum(line.get_linestyle() == ":" for line in fig.axes[0].lines) == 2 * free.size
    table = poles_vs_spin(model, [0.0, 2.0], lqr)
    assert len(plot_poles_vs_spin(table).axes) == 2                   # axes and colour bar
    assert len(plot_poles_vs_spin(table, which="plant").axes[0].collections) == 2
    assert len(plot_frequencies_vs_spin(table).axes[0].lines) == 2 * model.n_modes
    rows = [RobustnessTask(system=system, controller=lqr, n_modes=3)(**s)
            for s in Dispersion().samples(3)]
    assert plot_robustness(rows).axes[0].get_xlabel() == "youngs_modulus_scale"
    with pytest.raises(ValueError, match="needs a table built with a controller"):
        plot_poles_vs_spin(poles_vs_spin(model, [0.0]))
    with pytest.raises(TypeError, match="systems must be a python-control LTI system"):
        plot_bode([loops["PD"]])


def test_the_nichols_chart_marks_each_mode_where_the_loop_passes_it(system):
    import control
    from matplotlib.patches import Rectangle

    from flexctl.app.plotting_loops import plot_nichols

    model = flexctl.build_model(system, 3)
    free = model.natural_frequencies(hub="free")
    loop = loop_transfer(model, design_pd(model, 2.0))
    fig = plot_nichols({"PD": loop}, natural_frequencies=free, margins=(6.0, 30.0),
                       omega_limits=(0.1, 300.0))
    ax = fig.axes[0]
    assert ax.get_xlim() == (-360.0, 0.0)
    # each mode's dot is the loop's gain and phase at that frequency, the phase in [-360, 0)
    dots = [line for line in ax.lines if line.get_marker() == "o"]
    assert len(dots) == free.size
    for dot, w in zip(dots, free):
        response = control.frequency_response(loop, omega_limits=(0.1, 300.0), omega_num=3000)
        k = int(np.argmin(np.abs(np.log(np.asarray(response.omega) / w))))
        value = complex(np.asarray(response.complex).reshape(-1)[k])
        assert dot.get_ydata()[0] == pytest.approx(20 * np.log10(abs(value)))
        assert dot.get_xdata()[0] == pytest.approx(np.degrees(np.angle(value)) % 360 - 360)
    zones = [p for p in ax.patches if isinstance(p, Rectangle)]
    assert zones and all(p.get_width() == 60.0 and p.get_height() == 12.0 for p in zones)
    assert any(p.get_x() == -210.0 for p in zones)
    with pytest.raises(ValueError, match="margins"):
        plot_nichols(loop, margins=(6.0, 200.0))
    with pytest.raises(ValueError, match="SISO"):
        plot_nichols(control.ss(-np.eye(2), np.eye(2), np.eye(2), 0))


def test_sensors_are_the_models_position_outputs(system):
    model = flexctl.build_model(system, 2)
    a, b = model.linear_matrices()
    for sensor in SENSORS:
        row = model.output_matrix[model.output_names.index(sensor)]
        assert row @ b[:, 0] == 0.0          # the rate of the reading is c A x exactly
