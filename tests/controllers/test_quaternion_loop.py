"""Quaternion feedback flown in a sampled loop on the spatial exact model: rest-to-rest slews
about a tilted axis, the short way round, through a wheel pyramid with a star tracker, a gyro
and the attitude filter."""

import numpy as np
import pytest
from spatial_craft import INERTIA, WING

from controllers.feedback.mekf import AttitudeFilter
from controllers.feedback.quaternion import QuaternionFeedback
from flexctl.model.errors import InputValueError
from flexctl.model.spatial_structure import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.wheel_cluster import WheelCluster
from flexctl.sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker
from flexctl.sim.quaternions import error_angles, from_rotation_vector
from flexctl.sim.spatial_loop import simulate_spatial_loop

AXIS = np.array([0.6, 0.0, 0.8])


def craft():
    return SpatialStructure(hub=SpatialHub(inertia=INERTIA, radius=0.06),
                            appendages=(SpatialAppendage(**WING),))


def test_a_rest_to_rest_slew_about_a_tilted_axis_settles_on_the_flexible_craft():
    """0.5 rad about (0.6, 0, 0.8), bandwidth 0.5 rad/s (the array's first mode near
    8 rad/s), 10 Hz: the attitude error falls below 1e-4 rad by 25 s, the rotation stays
    about the slew's axis, and the array's bending along its normal settles."""
    structure = craft()
    target = from_rotation_vector(0.5 * AXIS)
    law = QuaternionFeedback.design(structure.rigid_inertia, 0.5, target, damping=0.9)
    loop = simulate_spatial_loop(structure, 25.0, law, sample_time=0.1, n_modes=1)
    assert loop.ok, loop.result.message
    run = loop.result
    errors = np.array([np.linalg.norm(error_angles(target, q)) for q in run.quaternion.T])
    tip = run.tips["wing_a"]
    print(f"final error {errors[-1]:.1e} rad, peak tip {np.abs(tip).max():.2e} m, "
          f"final tip {np.abs(tip[:, -1]).max():.1e} m")
    assert errors[0] == pytest.approx(0.5, rel=1e-3) and errors[-1] < 1e-4
    halfway = from_rotation_vector(0.25 * AXIS)
    closest = min(np.linalg.norm(error_angles(halfway, q)) for q in run.quaternion.T)
    assert closest < 0.02                  # it passed near the eigenaxis path's midpoint
    # the bending along the normal settles with the hub; the lateral plane (100 times stiffer,
    # undamped: the model has no structural damping) rings on at about 1 % of the peak
    assert abs(tip[2, -1]) < 1e-3 * np.abs(tip[2]).max()
    assert np.abs(tip[0, -50:]).max() < 0.05 * np.abs(tip).max()


def test_the_error_is_taken_the_short_way_round():
    """A target 350 degrees about z is 10 degrees the other way: the hub turns by -10."""
    structure = craft()
    target = from_rotation_vector(np.radians(350.0) * np.array([0.0, 0.0, 1.0]))
    law = QuaternionFeedback.design(structure.rigid_inertia, 0.5, target)
    run = simulate_spatial_loop(structure, 12.0, law, sample_time=0.1, n_modes=1).result
    yaw = run.euler_angles()[0]
    assert yaw.min() > np.radians(-11.5) and yaw.max() < np.radians(0.5)
    assert yaw[-1] == pytest.approx(np.radians(-10.0), abs=np.radians(0.2))


@pytest.mark.slow
def test_a_slew_through_wheels_and_sensors_settles_on_the_estimated_attitude():
    """The same slew asked of a four-wheel pyramid (torque and speed limits, Coulomb and
    viscous friction, a motor lag), the law (with integral action) reading a star tracker at
    1 Hz (0.2 s late) and a gyro at 10 Hz through the attitude filter. The filter's attitude
    is within 5e-4 rad of the truth after 30 s and its bias estimate reaches the gyro's; the wheels'
    friction, a disturbance the law does not know (its Coulomb part jumps as a wheel's speed
    changes sign), is what the integral works against: measured, at most 4.5e-3 rad after
    45 s (5.2e-4 at 50 s, 1.9e-3 at 60 s), the filter within 1.3e-4 rad after 30 s. The
    craft's momentum stays in the wheels."""
    structure = craft()
    target = from_rotation_vector(0.5 * AXIS)
    law = QuaternionFeedback.design(structure.rigid_inertia, 0.5, target, damping=0.9,
                                    integral_time=8.0, torque_limit=0.1)
    wheels = WheelCluster.pyramid(angle=54.7356, inertia=0.01, torque_limit=0.1,
                                  speed_limit=300.0, time_constant=0.05,
                                  coulomb_friction=1e-3, viscous_friction=1e-5)
    sensors = AttitudeSensors(
        star_tracker=StarTracker(cross_noise=2e-5, boresight_noise=1e-4, sample_time=1.0,
                                 latency=0.2),
        gyro=Gyro(angle_random_walk=3e-5, rate_random_walk=1e-6,
                  initial_bias=(2e-4, -1e-4, 1e-4)),
        gyro_sample_time=0.1, seed=5)
    estimator = AttitudeFilter(sensors, attitude=[1, 0, 0, 0], attitude_sigma=1e-3,
                               bias_sigma=5e-4)
    loop = simulate_spatial_loop(structure, 60.0, law, n_modes=1, wheels=wheels,
                                 sensors=sensors, estimator=estimator)
    assert loop.ok, loop.result.message
    run = loop.result
    errors = np.array([np.linalg.norm(error_angles(target, q)) for q in run.quaternion.T])
    known = np.array([np.linalg.norm(error_angles(a, q)) for a, q in
                      zip(loop.attitude_estimates.T, run.quaternion.T)])
    late = run.t > 45.0
    print(f"pointing error after 45 s: {errors[late].max():.1e} rad, filter error after "
          f"30 s {known[run.t > 30.0].max():.1e} rad; final bias estimate {loop.bias_estimates[:, -1]}")
    print(f"at 50 s {errors[np.argmin(abs(run.t - 50))]:.1e} rad, at 60 s {errors[-1]:.1e}")
    assert errors[late].max() < 1e-2 and errors[-1] < errors[0] / 100
    assert known[run.t > 30.0].max() < 5e-4
    np.testing.assert_allclose(loop.bias_estimates[:, -1], [2e-4, -1e-4, 1e-4], atol=5e-5)
    angular, _ = run.momentum()
    assert np.abs(angular - angular[:, :1]).max() < 1e-8
    assert np.abs(run.wheel_speeds[:, -1]).max() > 0.1


def test_bad_loops_are_refused():
    structure = craft()
    with pytest.raises(InputValueError, match="3 finite numbers"):
        simulate_spatial_loop(structure, 1.0, lambda t, q, w: [np.nan, 0, 0],
                              sample_time=0.1, n_modes=1)
    with pytest.raises(InputValueError, match="sample_time is required"):
        simulate_spatial_loop(structure, 1.0, lambda t, q, w: np.zeros(3), n_modes=1)
    with pytest.raises(InputValueError, match="come together"):
        simulate_spatial_loop(structure, 1.0, lambda t, q, w: np.zeros(3), sample_time=0.1,
                              sensors=object())
    with pytest.raises(InputValueError, match=r"quaternion_feedback\.kp"):
        QuaternionFeedback(target=[1, 0, 0, 0], kp=np.ones((2, 2)), kd=1.0)
