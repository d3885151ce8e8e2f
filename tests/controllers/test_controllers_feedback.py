"""Feedback controllers and open-loop baselines on the hub-beam-mass plant of paper 000.

Every controller is designed on a 2-mode linear model and judged on the nonlinear first_order
plant with more modes (8 unless stated), which carries the modes the design left out.
"""

from __future__ import annotations

import dataclasses

import control
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import flexctl
from controllers import (LQG, LQR, PD, BangBang, LQRWeights, NoiseLevels, ScheduledLQR,
                         SlewProfile, SumOfSines, bang_bang, closed_loop_poles, design_lqg,
                         design_lqr, design_pd, design_scheduled_lqr, design_shaper,
                         estimator_gain, lqr_weight_matrices, minimum_slew_duration, pd_gains,
                         shape, truncate_state, truncation_matrix, zv_shaper, zvd_shaper)

DESIGN_MODES = 2
PLANT_MODES = 8
SLEW_ANGLE = np.pi / 2          # rad
SLEW_TIME = 2.0                 # s
#: closed-loop poles must have real part below -STABILITY_MARGIN, 1/s
STABILITY_MARGIN = 1e-5
#: the hub must end within this fraction of the commanded angle
ANGLE_TOLERANCE = 0.02
#: max |tip| in the last second over the peak |tip| of the run
VIBRATION_DECAY = 0.05
#: residual vibration of a shaped command over that of the unshaped bang-bang
SHAPING_RESIDUAL_RATIO = 0.1
#: estimation error at the end over the initial error
ESTIMATION_DECAY = 1e-3
GAIN_RTOL = 1e-9
PD_BANDWIDTH, PD_DAMPING = 2.0, 0.9
WEIGHTS = LQRWeights(hub_angle=0.05, hub_rate=0.02, tip_deflection=0.01, torque=1.0)
NOISE = NoiseLevels(angle=1e-3, root_moment=0.01, torque=1.0)


@pytest.fixture(scope="module")
def system():
    return flexctl.load_scene("hub-beam-mass").system


@pytest.fixture(scope="module")
def damped_system(system):
    """The same system with 1 % modal damping (the scene's beam is undamped)."""
    return dataclasses.replace(system, beam=dataclasses.replace(system.beam,
                                                                damping_ratio=0.01))


@pytest.fixture(scope="module")
def design(system):
    return flexctl.build_model(system, n_modes=DESIGN_MODES)


@pytest.fixture(scope="module")
def plant(system):
    return flexctl.build_model(system, n_modes=PLANT_MODES)


def _static_controllers(design, reference=None):
    return {
        "pd": design_pd(design, PD_BANDWIDTH, PD_DAMPING, reference=reference),
        "lqr": design_lqr(design, WEIGHTS, reference=reference),
        "scheduled": design_scheduled_lqr(design, WEIGHTS, [0.0, 1.0, 2.0],
                                          reference=reference),
    }


def _residual(result, start, stop=None):
    window = (result.t >= start) & (result.t <= (result.t[-1] if stop is None else stop))
    return float(np.max(np.abs(result.tip_deflection[window])))


# ----------------------------------------------------------------------------- reference
@pytest.mark.parametrize("shape_name", ["poly7", "cycloidal"])
def test_slew_profile_is_rest_to_rest_and_consistent(shape_name):
    slew = SlewProfile(slew_angle=-1.2, duration=1.5, start_time=0.5, shape=shape_name)
    t = np.linspace(0.0, 3.0, 30001)
    assert slew.angle(0.5) == 0.0 and slew.angle(2.0) == pytest.approx(-1.2, abs=1e-15)
    for end in (0.5, 2.0):
        assert slew.rate(end) == pytest.approx(0.0, abs=1e-15)
        assert slew.acceleration(end) == pytest.approx(0.0, abs=1e-12)
    # rate and acceleration are the derivatives of angle and rate (away from the ends, where
    # the cycloid's jerk steps and a central difference straddles the step)
    smooth = np.min(np.abs(t[:, None] - np.array(slew.breakpoints)), axis=1) > 1e-3
    np.testing.assert_allclose(np.gradient(slew.angle(t), t), slew.rate(t), atol=1e-6)
    np.testing.assert_allclose(np.gradient(slew.rate(t), t)[smooth],
                               slew.acceleration(t)[smooth], atol=1e-5)
    assert np.max(np.abs(slew.rate(t))) == pytest.approx(slew.peak_rate, rel=1e-6)
    assert np.max(np.abs(slew.acceleration(t))) == pytest.approx(slew.peak_acceleration,
                                                                 rel=1e-6)
    assert slew.breakpoints == (0.5, 2.0)
    # the one-time form a sampled law reads gives the same numbers as the array methods
    for time in (0.0, 0.5, 0.9, 1.25, 1.99, 2.0, 2.7):
        assert slew.at(time) == (float(slew.angle(time)), float(slew.rate(time)),
                                 float(slew.acceleration(time)))
    for bad, error in ((float("nan"), ValueError), (float("inf"), ValueError),
                       ("1.0", TypeError), (None, TypeError), (True, TypeError)):
        with pytest.raises(error, match="slew.at.t"):
            slew.at(bad)


def test_minimum_slew_duration_meets_torque_limit():
    inertia, limit = 2.88, 6.0
    duration = minimum_slew_duration(SLEW_ANGLE, inertia, limit)
    slew = SlewProfile(slew_angle=SLEW_ANGLE, duration=duration)
    assert inertia * slew.peak_acceleration == pytest.approx(limit, rel=1e-12)


# ----------------------------------------------------------------------------- PD
@pytest.mark.parametrize("bandwidth, damping", [(2.0, 0.9), (5.0, 0.5), (1.0, 1.0)],
                         ids=["w2-z0.9", "w5-z0.5", "w1-z1"])
def test_pd_gains_place_rigid_poles(design, bandwidth, damping):
    kp, kd = pd_gains(design, bandwidth, damping)
    poles = np.roots([design.matrices.J0, kd, kp])
    np.testing.assert_allclose(np.abs(poles), bandwidth, rtol=1e-6)
    np.testing.assert_allclose(-poles.real / np.abs(poles), damping, rtol=1e-6)


# ----------------------------------------------------------------------------- spillover
@pytest.mark.parametrize("name", ["pd", "lqr", "scheduled"])
def test_design_gain_is_stable_on_plant_with_more_modes(design, plant, name):
    controller = _static_controllers(design)[name]
    poles = closed_loop_poles(plant, controller.state_gain(PLANT_MODES))
    assert poles.size == plant.n_states
    assert poles.real.max() < -STABILITY_MARGIN


@pytest.mark.parametrize("name", ["pd", "lqr", "scheduled"])
def test_slew_on_nonlinear_plant_reaches_target_and_settles(design, plant, name):
    reference = SlewProfile(slew_angle=SLEW_ANGLE, duration=SLEW_TIME)
    controller = _static_controllers(design, reference)[name]
    assert isinstance(controller, flexctl.Controller)
    result = flexctl.simulate(plant, 8.0, controller=controller, rtol=1e-6)
    assert result.ok, result.message
    assert abs(result.theta[-1] / SLEW_ANGLE - 1.0) < ANGLE_TOLERANCE
    assert _residual(result, result.t[-1] - 1.0) < VIBRATION_DECAY * result.peak_tip_deflection


def test_torque_limit_saturates(design, plant):
    reference = SlewProfile(slew_angle=SLEW_ANGLE, duration=SLEW_TIME)
    limit = 6.0
    controller = design_pd(design, 3.0, 0.9, reference=reference, torque_limit=limit)
    result = flexctl.simulate(plant, 3.0, controller=controller, rtol=1e-6)
    assert np.max(np.abs(result.torque)) == pytest.approx(limit, rel=1e-12)


# ----------------------------------------------------------------------------- LQR
@pytest.mark.parametrize("spin_rate", [0.0, 1.5], ids=["rest", "spinning"])
def test_lqr_gain_equals_control_lqr(design, spin_rate):
    weights = LQRWeights(hub_angle=0.05, hub_rate=0.5, tip_deflection=0.02,
                         modal_energy=0.1, torque=3.0)
    n = design.n_modes
    tip_row = np.concatenate(([0.0], design.mode_tips, np.zeros(n + 1)))
    q_mat = np.outer(tip_row, tip_row) / 0.02 ** 2
    q_mat[0, 0] += 1 / 0.05 ** 2
    q_mat[n + 1, n + 1] += 1 / 0.5 ** 2
    q_mat[1:n + 1, 1:n + 1] += design.matrices.K_ff / (2 * 0.1)
    q_mat[n + 2:, n + 2:] += design.matrices.M_ff / (2 * 0.1)
    a, b = design.linear_matrices(spin_rate)
    expected, _, _ = control.lqr(a, b, q_mat, np.array([[1 / 3.0 ** 2]]))
    lqr = design_lqr(design, weights, spin_rate)
    np.testing.assert_allclose(lqr.gain, expected, rtol=GAIN_RTOL)
    np.testing.assert_allclose(np.sort_complex(lqr.poles),
                               np.sort_complex(np.linalg.eigvals(a - b @ expected)), rtol=1e-8)


def test_lqr_weights_are_physical_costs(design):
    """x^T Q x is the sum of the squared ratios to the largest acceptable values."""
    weights = LQRWeights(hub_angle=0.1, hub_rate=0.3, tip_deflection=0.05,
                         modal_energy=0.2, torque=4.0)
    q_mat, r_mat = lqr_weight_matrices(design, weights)
    x = np.random.default_rng(0).normal(size=design.n_states)
    theta, q, rate, q_dot = design.split(x)
    mat = design.matrices
    energy = 0.5 * q @ mat.K_ff @ q + 0.5 * q_dot @ mat.M_ff @ q_dot
    tip = mat.tip @ q
    expected = (theta / 0.1) ** 2 + (rate / 0.3) ** 2 + (tip / 0.05) ** 2 + energy / 0.2
    assert x @ q_mat @ x == pytest.approx(expected, rel=1e-12)
    assert r_mat[0, 0] == pytest.approx(1 / 16.0)


def test_truncation_picks_design_states():
    x = np.arange(2 * PLANT_MODES + 2, dtype=float)   # theta=0, q=1..8, theta_dot=9, ...
    expected = np.array([0.0, 1.0, 2.0, 9.0, 10.0, 11.0])
    np.testing.assert_array_equal(truncate_state(x, 2), expected)
    np.testing.assert_array_equal(truncation_matrix(PLANT_MODES, 2) @ x, expected)


# ----------------------------------------------------------------------------- LQG
def test_estimator_gain_equals_control_lqe(design):
    a, b = design.linear_matrices()
    c = design.output_matrix[[0, 3]]
    expected, _, _ = control.lqe(a, b, c, np.array([[NOISE.torque ** 2]]),
                                 np.diag([NOISE.angle ** 2, NOISE.root_moment ** 2]))
    gain, poles = estimator_gain(design, NOISE)
    np.testing.assert_allclose(gain, expected, rtol=GAIN_RTOL)
    assert poles.real.max() < 0


def test_lqg_separation_principle(design):
    """Closed-loop poles on the design model are the regulator's plus the estimator's."""
    lqg = design_lqg(design, WEIGHTS, NOISE)
    a, b = design.linear_matrices()
    expected = np.concatenate((np.linalg.eigvals(a - b @ lqg.gain),
                               np.linalg.eigvals(a - lqg.estimator_gain @ lqg.c)))
    np.testing.assert_allclose(np.sort_complex(lqg.closed_loop_poles(design)),
                               np.sort_complex(expected), rtol=1e-7, atol=1e-9)


def test_lqg_estimate_converges_from_theta_and_root_moment(design):
    """The filter, started at zero, finds an unknown initial angle and beam deflection."""
    lqg = design_lqg(design, WEIGHTS, NOISE)
    x0 = np.zeros(design.n_states)
    x0[0], x0[1], x0[DESIGN_MODES + 2] = 0.2, 0.05, -0.1          # rad, m, m/s
    result = flexctl.simulate(design, 10.0, controller=lqg, x0=x0, rtol=1e-8)
    assert result.ok
    z = result.controller_states
    tip_row = design.output_matrix[design.output_names.index("tip_deflection")]
    error_theta = np.abs(z[0] - result.theta)
    error_tip = np.abs(tip_row @ z - result.tip_deflection)
    for error in (error_theta, error_tip):
        assert error[0] > 0.05
        assert error[-1] < ESTIMATION_DECAY * error[0]


def test_lqg_with_deterministic_noise_on_larger_plant(damped_system, design):
    plant = flexctl.build_model(damped_system, n_modes=4)
    noise = SumOfSines.from_levels([NOISE.angle, NOISE.root_moment], bandwidth=30.0, seed=3)
    t = np.linspace(0.0, 200.0, 200001)
    samples = np.array([noise(tk) for tk in t[::10]])
    np.testing.assert_allclose(samples.std(axis=0), [NOISE.angle, NOISE.root_moment],
                               rtol=0.15)
    np.testing.assert_array_equal(noise(1.234), noise(1.234))
    quiet = design_lqg(design, WEIGHTS, NOISE, plant=plant)
    noisy = dataclasses.replace(quiet, measurement_noise=noise)
    x0 = np.zeros(plant.n_states)
    x0[0] = 0.1
    runs = [flexctl.simulate(plant, 3.0, controller=c, x0=x0, rtol=1e-7) for c in
            (quiet, noisy, noisy)]
    assert all(r.ok for r in runs)
    np.testing.assert_array_equal(runs[1].theta, runs[2].theta)    # reproducible
    assert not np.allclose(runs[0].theta, runs[1].theta, rtol=0, atol=1e-9)


def test_lqg_spillover_is_damped_by_structural_damping(damped_system, design):
    """Undamped left-out modes are what the root-moment feedback can destabilise; 1 %
    structural damping, a realistic value, is enough for this design."""
    plant = flexctl.build_model(damped_system, n_modes=PLANT_MODES)
    lqg = design_lqg(design, WEIGHTS, NoiseLevels(angle=1e-3, root_moment=0.1, torque=0.1))
    assert lqg.closed_loop_poles(plant).real.max() < -STABILITY_MARGIN


# ----------------------------------------------------------------------------- scheduling
def test_scheduled_gains_interpolate(design):
    rates = [0.0, 1.5, 3.0]
    sched = design_scheduled_lqr(design, WEIGHTS, rates)
    for rate in rates:
        expected = design_lqr(design, WEIGHTS, rate).gain
        np.testing.assert_allclose(sched.gain_at(rate), expected, rtol=GAIN_RTOL)
        np.testing.assert_allclose(sched.gain_at(-rate), expected, rtol=GAIN_RTOL)
    low, high = sched.gains[1], sched.gains[2]
    assert not np.allclose(low, high, rtol=1e-6)      # the schedule does something
    middle = sched.gain_at(2.25)[0]
    np.testing.assert_allclose(middle, 0.5 * (low + high), rtol=1e-12)
    assert np.all(middle >= np.minimum(low, high)) and np.all(middle <= np.maximum(low, high))
    np.testing.assert_array_equal(sched.gain_at(10.0)[0], high)
    # the torque uses the gain at the measured hub rate of the (larger) plant state
    x = np.random.default_rng(1).normal(size=2 * PLANT_MODES + 2)
    x[PLANT_MODES + 1] = -2.25
    expected = -float(middle @ truncate_state(x, DESIGN_MODES))
    assert sched.torque(0.0, x) == pytest.approx(expected, rel=1e-12)


def test_scheduled_lqr_stabilises_fast_slew(design, plant):
    rates = [0.0, 1.0, 2.0, 3.0, 4.0]
    reference = SlewProfile(slew_angle=SLEW_ANGLE, duration=1.0)     # peak rate 3.4 rad/s
    sched = design_scheduled_lqr(design, WEIGHTS, rates, reference=reference)
    for rate in rates:
        poles = closed_loop_poles(plant, sched.state_gain(PLANT_MODES, rate), rate)
        assert poles.real.max() < -STABILITY_MARGIN
    result = flexctl.simulate(plant, 8.0, controller=sched, rtol=1e-6)
    assert result.ok, result.message
    assert abs(result.theta[-1] / SLEW_ANGLE - 1.0) < ANGLE_TOLERANCE
    assert _residual(result, result.t[-1] - 1.0) < VIBRATION_DECAY * result.peak_tip_deflection


# ----------------------------------------------------------------------------- bang-bang
@pytest.mark.parametrize("make", [
    lambda j: bang_bang(j, SLEW_ANGLE, torque_limit=6.0),
    lambda j: bang_bang(j, -SLEW_ANGLE, duration=SLEW_TIME),
], ids=["torque-limit", "duration"])
def test_bang_bang_slews_a_rigid_hub(plant, make):
    bb = make(plant.matrices.J0)
    assert isinstance(bb, BangBang)

    def rigid(t, y):
        return [y[1], float(bb(t)) / bb.inertia]

    end = bb.breakpoints[-1]
    y, t0 = [0.0, 0.0], 0.0
    for t1 in bb.breakpoints[1:]:
        y = solve_ivp(rigid, (t0, t1), y, rtol=1e-12, atol=1e-14).y[:, -1]
        t0 = t1
    np.testing.assert_allclose(y, [bb.slew_angle, 0.0], atol=1e-9)
    assert bb.angle(end) == pytest.approx(bb.slew_angle, abs=1e-15)
    assert np.max(np.abs(bb(np.linspace(0.0, end, 1001)))) <= bb.peak_torque


def test_bang_bang_moves_the_rigid_body_mode_of_the_flexible_plant(plant):
    """The hub equation makes J0 theta + m_tf q a rigid double integrator of the torque."""
    bb = bang_bang(plant, SLEW_ANGLE, torque_limit=6.0)
    result = flexctl.simulate(plant, bb.duration + 0.5, torque=bb, rtol=1e-9)
    mat = plant.matrices
    rigid_angle = (mat.J0 * result.theta + mat.m_tf @ result.q) / mat.J0
    momentum = mat.J0 * result.theta_dot + mat.m_tf @ plant.split(result.states)[3]
    np.testing.assert_allclose(rigid_angle[-1], SLEW_ANGLE, rtol=1e-6)
    assert abs(momentum[-1]) < 1e-6 * mat.J0 * SLEW_ANGLE
    assert result.peak_tip_deflection > 0.1        # but the beam is left ringing


# ----------------------------------------------------------------------------- shaping
@pytest.mark.parametrize("maker, zeta", [(zv_shaper, 0.0), (zvd_shaper, 0.0),
                                         (zv_shaper, 0.05), (zvd_shaper, 0.05)],
                         ids=["zv", "zvd", "zv-damped", "zvd-damped"])
def test_shaper_cancels_its_mode(maker, zeta):
    """Residual vibration of a damped mode after the impulse train is zero."""
    w = 5.0
    shaper = maker(w, zeta)
    times, amps = np.array(shaper.times), np.array(shaper.amplitudes)
    wd = w * np.sqrt(1 - zeta ** 2)
    residual = np.sum(amps * np.exp(zeta * w * times) * np.exp(1j * wd * times))
    assert abs(residual) < 1e-12
    assert amps.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("kind", ["zv", "zvd"])
def test_shaping_reduces_residual_vibration(plant, kind):
    bb = bang_bang(plant, SLEW_ANGLE, torque_limit=6.0)
    shaped = shape(bb, design_shaper(plant, kind))
    end = shaped.breakpoints[-1]
    t_final = end + 1.5
    runs = [flexctl.simulate(plant, t_final, torque=u, rtol=1e-7) for u in (bb, shaped)]
    assert all(r.ok for r in runs)
    unshaped, with_shaper = (_residual(r, end + 0.5) for r in runs)
    assert with_shaper < SHAPING_RESIDUAL_RATIO * unshaped
    assert np.max(np.abs(runs[1].torque)) <= bb.peak_torque + 1e-12


# ----------------------------------------------------------------------------- protocol
def test_controllers_follow_the_protocol(design, plant):
    reference = SlewProfile(slew_angle=1.0, duration=2.0, start_time=0.5)
    controllers = list(_static_controllers(design, reference).values())
    controllers.append(design_lqg(design, WEIGHTS, NOISE, plant=plant, reference=reference))
    for c in controllers:
        assert isinstance(c, flexctl.Controller)
        assert c.breakpoints == (0.5, 2.5)
        z0 = c.initial_state(np.zeros(plant.n_states))
        assert z0.shape == (c.n_states,)
        assert c.derivative(0.0, np.zeros(plant.n_states), z0).shape == (c.n_states,)
        assert c.torque(0.0, np.zeros(plant.n_states), z0) == 0.0
    assert controllers[-1].n_states == plant.n_states      # the filter models every plant mode


# ----------------------------------------------------------------------------- bad input
BAD_SETTINGS = {
    "pd-negative-kp": (lambda m: PD(kp=-1.0, kd=1.0), r"pd\.kp .*-1\.0"),
    "pd-negative-kd": (lambda m: PD(kp=1.0, kd=-2.0), r"pd\.kd"),
    "pd-nan-kp": (lambda m: PD(kp=float("nan"), kd=1.0), r"pd\.kp .*nan"),
    "pd-zero-limit": (lambda m: PD(kp=1.0, kd=1.0, torque_limit=0.0), r"pd\.torque_limit"),
    "bandwidth-zero": (lambda m: pd_gains(m, 0.0, 0.7), r"pd_gains\.bandwidth"),
    "bandwidth-negative": (lambda m: pd_gains(m, -3.0, 0.7), r"pd_gains\.bandwidth"),
    "damping-zero": (lambda m: pd_gains(m, 3.0, 0.0), r"pd_gains\.damping_ratio"),
    "damping-above-one": (lambda m: pd_gains(m, 3.0, 1.2), r"pd_gains\.damping_ratio"),
    "inertia-negative": (lambda m: pd_gains(-1.0, 3.0, 0.7), r"pd_gains\.inertia"),
    "weight-angle-zero": (lambda m: LQRWeights(hub_angle=0.0, torque=1.0),
                          r"lqr_weights\.hub_angle"),
    "weight-torque-negative": (lambda m: LQRWeights(hub_angle=0.1, torque=-1.0),
                               r"lqr_weights\.torque"),
    "weight-tip-nan": (lambda m: LQRWeights(hub_angle=0.1, torque=1.0,
                                            tip_deflection=float("nan")),
                       r"lqr_weights\.tip_deflection"),
    "weight-energy-negative": (lambda m: LQRWeights(hub_angle=0.1, torque=1.0,
                                                    modal_energy=-0.1),
                               r"lqr_weights\.modal_energy"),
    "noise-zero": (lambda m: NoiseLevels(angle=0.0, root_moment=0.1, torque=1.0),
                   r"noise\.angle"),
    "design-modes-above-plant": (lambda m: truncation_matrix(2, 4),
                                 r"n_design_modes .*got 4"),
    "lqr-on-smaller-plant": (lambda m: design_lqr(m, WEIGHTS).torque(0.0, np.zeros(4)),
                             r"n_design_modes"),
    "lqg-on-smaller-plant": (lambda m: design_lqg(m, WEIGHTS, NOISE).for_plant(
        flexctl.build_model(m.system, n_modes=1)), r"plant .*n_modes = 1"),
    "lqr-nan-spin": (lambda m: design_lqr(m, WEIGHTS, float("nan")), r"spin_rate"),
    "schedule-decreasing": (lambda m: design_scheduled_lqr(m, WEIGHTS, [1.0, 0.5]),
                            r"spin_rates"),
    "schedule-negative": (lambda m: ScheduledLQR(spin_rates=[-1.0], gains=np.ones((1, 6))),
                          r"spin_rates"),
    "lqr-gain-shape": (lambda m: LQR(gain=np.ones((1, 5))), r"lqr\.gain"),
    "lqg-gain-shape": (lambda m: dataclasses.replace(design_lqg(m, WEIGHTS, NOISE),
                                                     gain=np.ones((1, 4))), r"lqg\.gain"),
    "slew-zero-duration": (lambda m: SlewProfile(slew_angle=1.0, duration=0.0),
                           r"slew\.duration"),
    "slew-nan-angle": (lambda m: SlewProfile(slew_angle=float("nan"), duration=1.0),
                       r"slew\.slew_angle"),
    "slew-shape": (lambda m: SlewProfile(slew_angle=1.0, duration=1.0, shape="cubic"),
                   r"slew\.shape"),
    "bang-bang-both": (lambda m: bang_bang(m, 1.0, torque_limit=1.0, duration=1.0),
                       r"torque_limit and duration"),
    "bang-bang-torque": (lambda m: BangBang(slew_angle=1.0, inertia=1.0, peak_torque=-1.0),
                         r"bang_bang\.peak_torque"),
    "shaper-frequency": (lambda m: zv_shaper(-5.0), r"zv_shaper\.frequency"),
    "shaper-damping": (lambda m: zvd_shaper(5.0, 1.0), r"zvd_shaper\.damping_ratio"),
    "shaper-kind": (lambda m: design_shaper(m, "zvdd"), r"design_shaper\.kind"),
}


@pytest.mark.parametrize("make, match", list(BAD_SETTINGS.values()), ids=list(BAD_SETTINGS))
def test_bad_settings_raise_value_error(design, make, match):
    with pytest.raises(ValueError, match=match):
        make(design)


def test_wrong_types_raise_type_error(design):
    with pytest.raises(TypeError, match=r"pd\.reference"):
        PD(kp=1.0, kd=1.0, reference=3.0)
    with pytest.raises(TypeError, match=r"design_lqr\.model"):
        design_lqr("model", WEIGHTS)
    with pytest.raises(TypeError, match=r"weights"):
        design_lqr(design, {"hub_angle": 0.1})
    with pytest.raises(TypeError, match=r"lqg\.measurement_noise"):
        dataclasses.replace(design_lqg(design, WEIGHTS, NOISE), measurement_noise=0.1)
    assert isinstance(design_lqg(design, WEIGHTS, NOISE), LQG)
