"""Three-axis LQR and LQG on the linear flexible spacecraft (issue 44, item 4), and the part of
a linear plant its inputs move (controllers.design.controllable.input_part)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.design.controllable import held, input_part
from controllers.feedback.lqr import LQRWeights
from controllers.feedback.spatial_lqr import (SpatialLQG, design_spatial_lqg,
                                              design_spatial_lqr, spatial_weight_matrices)
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.errors import InputValueError
from flexctl.model.spatial_plant import linearize_spatial
from flexctl.sim.quaternions import conjugate, from_rotation_vector, product, rotation_vector
from flexctl.sim.spatial_loop import simulate_spatial_loop

WEIGHTS = LQRWeights(hub_angle=0.05, hub_rate=0.05, torque=0.1, tip_deflection=0.005)
TARGET = from_rotation_vector(np.radians(20.0) * np.array([0.6, 0.0, 0.8]))


def _wing(name, direction, damping=0.005):
    return SpatialAppendage(name=name, direction=direction, normal=(0, 0, 1), length=1.8,
                            density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=5.2e-10, second_moment_lateral=5.2e-8,
                            shear_modulus=2.6e10, torsion_constant=1e-9,
                            damping_ratio=damping)


def _craft(support="pinned", damping=0.005):
    """Two identical arrays on opposite sides: their modes bending against each other are
    out of the torque's reach."""
    extra = {"support": "free", "mass": 20.0} if support == "free" else {}
    hub = SpatialHub(inertia=[[1.3, 0.05, 0.0], [0.05, 1.2, 0.0], [0.0, 0.0, 1.4]],
                     radius=0.06, **extra)
    return SpatialStructure(hub=hub, appendages=(_wing("a", (0, 1, 0), damping),
                                                 _wing("b", (0, -1, 0), damping)))


def _pointing(result):
    q = result.states[0:4]
    return np.array([np.linalg.norm(rotation_vector(product(conjugate(TARGET), q[:, k])))
                     for k in range(q.shape[1])])


# ------------------------------------------------------------------ the part the inputs move
def test_input_part_leaves_out_what_the_torque_cannot_move_and_keeps_its_poles():
    plant = linearize_spatial(_craft(damping=0.0), 1)
    a, b = plant.A, plant.B
    part = input_part(a, b)
    # the arrays bending against each other out of plane, in plane and in torsion: one pole
    # pair each, at a frequency of one array clamped (the hub does not move)
    assert len(part.dropped) == 3
    assert part.basis.shape[1] == a.shape[0] - 6
    assert np.allclose(part.projector @ part.basis, np.eye(part.basis.shape[1]), atol=1e-10)
    clamped = linearize_spatial(SpatialStructure(hub=SpatialHub(inertia=np.eye(3) * 1e12,
                                                                radius=0.06),
                                                 appendages=(_wing("a", (0, 1, 0), 0.0),)), 1)
    one_array = np.abs(np.linalg.eigvals(clamped.A).imag)
    for w in part.dropped:
        assert np.min(np.abs(one_array - w)) < 1e-6 * w
    # a gain on the part moves its poles and leaves the others where they were
    a_r, b_r = part.projector @ a @ part.basis, part.projector @ b
    rng = np.random.default_rng(1)
    gain = rng.normal(size=(3, a_r.shape[0])) @ part.projector
    closed = np.linalg.eigvals(a - b @ gain)
    expected = np.concatenate([np.linalg.eigvals(a_r - b_r @ (gain @ part.basis)),
                               1j * np.array(part.dropped), -1j * np.array(part.dropped)])
    for pole in expected:
        assert np.min(np.abs(closed - pole)) < 1e-6 * max(1.0, abs(pole))


def test_input_part_drops_a_free_hubs_momentum_and_the_fast_modes():
    plant = linearize_spatial(_craft("free"), 2)
    part = input_part(plant.A, plant.B, max_frequency=30.0)
    assert part.dropped.count(0.0) == 3                    # the linear momentum
    assert max(part.dropped) > 300.0                       # torsion, lateral bending
    assert "faster than 30 rad/s" in part.note and "conserved momentum" in part.note
    # what is kept is the right-invariant subspace of the slow poles: a rigid rotation is in it
    rotation = np.zeros(plant.nstates)
    rotation[0:3] = (0.1, -0.2, 0.3)
    assert np.allclose(part.basis @ (part.projector @ rotation), rotation, atol=1e-12)


@pytest.mark.parametrize("a, b, match", [
    (np.eye(2), np.zeros((2, 1)), "input matrix B is zero"),
    (np.full((2, 2), np.nan), np.ones((2, 1)), "input_part.a must be finite"),
    (np.eye(3), np.ones((2, 1)), "input_part.b must have 3 rows"),
    (np.ones(3), np.ones((3, 1)), "input_part.a must be a square matrix"),
])
def test_input_part_refuses_what_is_no_plant(a, b, match):
    with pytest.raises(InputValueError, match=match):
        input_part(a, b)


def test_a_cut_off_below_every_mode_leaves_the_rigid_design():
    law = design_spatial_lqr(_craft(), WEIGHTS, TARGET, n_modes=1, max_frequency=1e-300)
    assert law.part.basis.shape[1] == 6 and law.poles.real.max() < 0


def test_a_target_of_huge_entries_is_the_same_attitude():
    law = design_spatial_lqr(_craft(), WEIGHTS, 1e308 * np.asarray(TARGET), n_modes=1)
    np.testing.assert_allclose(law.target, TARGET, rtol=1e-15)


# ------------------------------------------------------------------ designs
def test_weights_are_brysons_per_axis():
    plant = linearize_spatial(_craft(), 1)
    q_mat, r_mat = spatial_weight_matrices(plant, LQRWeights(hub_angle=0.1, torque=2.0))
    assert np.allclose(np.diag(q_mat)[0:3], 100.0) and np.allclose(r_mat, np.eye(3) / 4.0)
    assert np.count_nonzero(q_mat) == 3
    with pytest.raises(InputValueError, match="modal_energy"):
        spatial_weight_matrices(plant, LQRWeights(hub_angle=0.1, torque=2.0, modal_energy=1.0))


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_lqr_is_stable_on_a_plant_with_more_modes_than_its_design(support):
    craft = _craft(support)
    truth = linearize_spatial(craft, 3)
    for sample_time in (None, 0.1):
        law = design_spatial_lqr(craft, WEIGHTS, TARGET, n_modes=1, sample_time=sample_time)
        poles = law.loop_poles(truth)
        # damped modes decay; the free hub's momentum stays at zero
        assert poles.real.max() <= 1e-9 * np.abs(poles).max()
        assert law.poles.real.max() < -0.05                # the designed part is damped


def test_lqr_slews_the_flexible_spacecraft_and_stops_its_vibration():
    craft = _craft()
    law = design_spatial_lqr(craft, WEIGHTS, TARGET, n_modes=1, sample_time=0.1,
                             torque_limit=0.1)
    run = simulate_spatial_loop(craft, 30.0, law, sample_time=0.1, n_modes=2, rtol=1e-6,
                                variant="first_order")
    assert run.ok
    error = _pointing(run.result)
    assert error[0] == pytest.approx(np.radians(20.0))
    assert error[-1] < 1e-6
    assert np.max(np.abs(run.result.torque)) <= 0.1 + 1e-15
    tips = np.array(list(run.result.tips.values()))
    late = run.result.t > 25.0
    assert np.max(np.abs(tips[..., late])) < 1e-3 * np.max(np.abs(tips))


def test_lqg_reads_attitude_and_rate_only_and_settles_as_the_lqr():
    craft = _craft()
    law = design_spatial_lqg(craft, WEIGHTS, TARGET, 0.1, n_modes=1, torque_limit=0.1)
    assert isinstance(law, SpatialLQG) and not law.state_feedback
    assert law.estimator_poles.real.max() < 0
    assert law.loop_poles(linearize_spatial(craft, 3)).real.max() < 0
    run = simulate_spatial_loop(craft, 30.0, law, sample_time=0.1, n_modes=2, rtol=1e-6,
                                variant="first_order")
    assert run.ok
    assert _pointing(run.result)[-1] < 1e-5


def test_lqg_sees_spillover_of_undamped_modes_the_lqr_does_not():
    """Undamped modes outside the design reach the filter through the readings and are
    driven by the commands: the held LQG loop on the plant with them grows, while the LQR,
    which reads the design part exactly, leaves them where they were."""
    craft = _craft(damping=0.0)
    truth = linearize_spatial(craft, 2)
    lqg = design_spatial_lqg(craft, WEIGHTS, TARGET, 0.1, n_modes=2, process_torque=1e-2)
    lqr = lqg.regulator
    scale = np.abs(lqr.loop_poles(truth)).max()
    assert lqr.loop_poles(truth).real.max() <= 1e-9 * scale
    assert lqg.loop_poles(truth).real.max() > 1e-6


def test_the_discrete_lqr_is_the_held_plants():
    craft = _craft()
    law = design_spatial_lqr(craft, WEIGHTS, TARGET, n_modes=1, sample_time=0.2)
    part = law.part
    a_d, b_d = held(part.projector @ law.plant.A @ part.basis, part.projector @ law.plant.B,
                    0.2)
    z = np.linalg.eigvals(a_d - b_d @ (law.gain @ part.basis))
    assert np.allclose(np.sort_complex(np.log(z) / 0.2), np.sort_complex(law.poles))


# ------------------------------------------------------------------ refusals
def test_a_state_feedback_law_is_refused_with_sensors_and_on_a_smaller_plant():
    from flexctl.sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker
    from controllers.feedback.mekf import AttitudeFilter

    craft = _craft()
    law = design_spatial_lqr(craft, WEIGHTS, TARGET, n_modes=2, sample_time=0.1)
    sensors = AttitudeSensors(star_tracker=StarTracker(cross_noise=1e-5, boresight_noise=1e-4,
                                                       sample_time=0.5),
                              gyro=Gyro(angle_random_walk=1e-5), gyro_sample_time=0.1)
    with pytest.raises(InputValueError, match="whole state"):
        simulate_spatial_loop(craft, 1.0, law, n_modes=2, sensors=sensors,
                              estimator=AttitudeFilter(sensors, TARGET, attitude_sigma=1e-3))
    with pytest.raises(InputValueError, match="at least its modes"):
        simulate_spatial_loop(craft, 1.0, law, sample_time=0.1, n_modes=1)
    with pytest.raises(InputValueError, match="at least its modes"):
        law.loop_poles(linearize_spatial(craft, 1))


@pytest.mark.parametrize("change, match", [
    ({"target": (0, 0, 0, 0)}, "non-zero quaternion"),
    ({"target": (1, 0, 0)}, "target"),
    ({"sample_time": -0.1}, "sample_time"),
    ({"sample_time": float("nan")}, "sample_time"),
    ({"torque_limit": 0.0}, "torque_limit"),
    ({"max_frequency": -1.0}, "max_frequency"),
    ({"n_modes": 0}, "n_modes|modes"),
    ({"variant": "consistent"}, "design_spatial_lqr.variant"),
])
def test_design_refuses_bad_inputs_by_name(change, match):
    args = {"target": TARGET, "n_modes": 1, "sample_time": 0.1}
    args.update(change)
    target = args.pop("target")
    with pytest.raises((InputValueError, TypeError, ValueError), match=match):
        design_spatial_lqr(_craft(), WEIGHTS, target, **args)


@pytest.mark.parametrize("name, value", [("angle_noise", 0.0), ("rate_noise", -1.0),
                                         ("process_torque", float("inf"))])
def test_lqg_refuses_bad_noise_by_name(name, value):
    with pytest.raises(InputValueError, match=name):
        design_spatial_lqg(_craft(), WEIGHTS, TARGET, 0.1, n_modes=1, **{name: value})


def test_lqg_is_refused_a_different_hold():
    law = design_spatial_lqg(_craft(), WEIGHTS, TARGET, 0.1, n_modes=1)
    session = law.start()
    session(0.0, TARGET, np.zeros(3))
    with pytest.raises(InputValueError, match="0.1 s hold"):
        session(0.25, TARGET, np.zeros(3))


# ------------------------------------------------------------------ loops and margins
def test_the_continuous_lqr_keeps_kalmans_margins_on_all_axes_at_once():
    """Kalman's inequality: with ``R`` a multiple of the identity, ``sigma_max(S) <= 1`` at
    every frequency, so the sensitivity disk (skew 1) of all three inputs at once is at
    least 1: gains from 1/2 to infinity, 60 degrees of phase."""
    from controllers.analysis.spatial_loops import loop_disk_margins, lq_loop

    law = design_spatial_lqr(_craft(), WEIGHTS, TARGET, n_modes=2)
    margins = loop_disk_margins(lq_loop(law, law.plant), skew=1.0)
    assert margins.closed_loop_stable
    assert margins.multiloop[0] >= 1.0 - 1e-6
    assert np.all(margins.disk_margin >= 1.0 - 1e-6)


@pytest.mark.parametrize("kind", ["lqr", "lqg"])
def test_the_held_loop_is_the_one_the_law_closes(kind):
    from controllers.analysis.spatial_loops import loop_disk_margins, lq_loop

    craft = _craft()
    law = (design_spatial_lqr(craft, WEIGHTS, TARGET, n_modes=1, sample_time=0.1)
           if kind == "lqr" else design_spatial_lqg(craft, WEIGHTS, TARGET, 0.1, n_modes=1))
    truth = linearize_spatial(craft, 3)
    loop = lq_loop(law, truth)
    assert loop.dt == 0.1
    margins = loop_disk_margins(loop)
    assert margins.spectral_abscissa == pytest.approx(law.loop_poles(truth).real.max(),
                                                      rel=1e-6)
    assert margins.closed_loop_stable and np.all(margins.gain_margin_db > 6.0)
    assert np.all(margins.frequency < np.pi / 0.1)
    with pytest.raises(InputValueError, match="SpatialLQR, SpatialLQG or ScheduledSpatialLQR"):
        lq_loop(object(), truth)
    with pytest.raises(InputValueError, match=r"lq_loop\.spin is for a ScheduledSpatialLQR"):
        lq_loop(law, truth, spin=1.0)


# ------------------------------------------------------------------ eigenaxis slews
def _eigenaxis(profile=None):
    from controllers import SlewProfile
    from controllers.slew.eigenaxis import EigenaxisSlew

    profile = profile or SlewProfile(slew_angle=np.radians(20.0), duration=12.0)
    return EigenaxisSlew(axis=(0.6, 0.0, 0.8), profile=profile, inertia=_craft().rigid_inertia)


def test_an_eigenaxis_slew_is_a_rotation_about_its_axis_to_the_target():
    from flexctl.sim.quaternions import from_rotation_vector

    slew = _eigenaxis()
    np.testing.assert_allclose(slew.target, TARGET, atol=1e-15)
    axis = np.array([0.6, 0.0, 0.8])
    for t in (0.0, 3.0, 6.0, 11.0, 12.0, 20.0):
        error, rate, torque = slew.at(t)
        angle, speed, acceleration = (float(f(t)) for f in (slew.profile.angle,
                                                             slew.profile.rate,
                                                             slew.profile.acceleration))
        # the attitude error of the reference from the target, exactly, about a fixed axis
        attitude = from_rotation_vector(angle * axis)
        np.testing.assert_allclose(rotation_vector(product(conjugate(TARGET), attitude)),
                                   error, atol=1e-14)
        np.testing.assert_allclose(rate, speed * axis, atol=1e-15)
        inertia = _craft().rigid_inertia
        np.testing.assert_allclose(torque, acceleration * inertia @ axis
                                   + np.cross(rate, inertia @ rate), atol=1e-15)
    assert np.allclose(slew.at(0.0)[0], -np.radians(20.0) * axis)
    assert np.allclose(slew.at(12.0)[0], 0.0) and np.allclose(slew.at(12.0)[1], 0.0)


def test_following_an_eigenaxis_slew_excites_the_arrays_less_than_a_step():
    craft = _craft()
    runs = {}
    for name, reference in (("step", None), ("eigenaxis", _eigenaxis())):
        law = design_spatial_lqr(craft, WEIGHTS, None if reference else TARGET, n_modes=1,
                                 sample_time=0.1, torque_limit=0.1, reference=reference)
        runs[name] = simulate_spatial_loop(craft, 30.0, law, sample_time=0.1, n_modes=2,
                                           rtol=1e-7, variant="first_order").result
    peak = {k: max(np.max(np.abs(v)) for v in r.tips.values()) for k, r in runs.items()}
    print(f"peak tip: step {peak['step']:.3g} m, eigenaxis {peak['eigenaxis']:.3g} m")
    assert peak["eigenaxis"] < 0.5 * peak["step"]
    assert np.max(np.abs(runs["eigenaxis"].torque)) < 0.1           # never saturated
    assert _pointing(runs["eigenaxis"])[-1] < 1e-6


def test_an_eigenaxis_slew_takes_a_shaped_profile_and_the_lqg_follows_it():
    from controllers import SlewProfile, shape, zvd_shaper

    profile = shape(SlewProfile(slew_angle=np.radians(20.0), duration=10.0),
                    zvd_shaper(13.6, 0.005))
    slew = _eigenaxis(profile)
    assert slew.end_time == pytest.approx(max(profile.breakpoints))
    law = design_spatial_lqg(_craft(), WEIGHTS, None, 0.1, n_modes=1, torque_limit=0.1,
                             reference=slew)
    run = simulate_spatial_loop(_craft(), 30.0, law, sample_time=0.1, n_modes=2, rtol=1e-7,
                                variant="first_order")
    assert run.ok and _pointing(run.result)[-1] < 1e-5


def test_an_eigenaxis_slew_refuses_what_is_no_slew(tmp_path):
    from controllers import SlewProfile
    from controllers.codegen import export_c
    from controllers.slew.eigenaxis import EigenaxisSlew
    from flexctl.model.errors import InputTypeError

    profile = SlewProfile(slew_angle=0.3, duration=5.0)
    with pytest.raises(InputValueError, match="axis"):
        EigenaxisSlew(axis=(0, 0, 0), profile=profile, inertia=np.eye(3))
    with pytest.raises(InputValueError, match="positive definite"):
        EigenaxisSlew(axis=(0, 0, 1), profile=profile, inertia=-np.eye(3))
    with pytest.raises(InputTypeError, match="profile"):
        EigenaxisSlew(axis=(0, 0, 1), profile=None, inertia=np.eye(3))
    with pytest.raises(InputTypeError, match="angle"):
        EigenaxisSlew(axis=(0, 0, 1), profile=object(), inertia=np.eye(3))
    with pytest.raises(InputValueError, match=r"eigenaxis_slew\.momentum must be finite"):
        EigenaxisSlew(axis=(0, 0, 1), profile=profile, inertia=np.eye(3),
                      momentum=(np.nan, 0.0, 0.0))
    with pytest.raises(InputValueError, match=r"eigenaxis_slew\.momentum must have shape"):
        EigenaxisSlew(axis=(0, 0, 1), profile=profile, inertia=np.eye(3), momentum=(1.0, 2.0))
    slew = _eigenaxis()
    with pytest.raises(InputValueError, match="reference's end"):
        design_spatial_lqr(_craft(), WEIGHTS, (1.0, 0.0, 0.0, 0.0), reference=slew)
    with pytest.raises(InputTypeError, match="reference"):
        design_spatial_lqr(_craft(), WEIGHTS, TARGET, reference="slew")
    law = design_spatial_lqr(_craft(), WEIGHTS, None, n_modes=1, reference=slew)
    # an eigenaxis slew's law is written as C (its profile in CasADi form), a plan's is not
    assert "following an eigenaxis slew" in export_c(law, None, tmp_path).program.description
