"""Star tracker, gyro and the multiplicative extended Kalman filter: the sensors' statistics,
and the filter's consistency (normalised estimation errors within their chi-square bounds over
Monte Carlo runs), with a late star tracker and an outage."""

import numpy as np
import pytest
from scipy.stats import chi2

from controllers.feedback.mekf import AttitudeFilter
from flexctl.model.errors import InputValueError
from flexctl.sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker
from flexctl.sim.quaternions import error_angles, from_rotation_vector, product

GYRO_STEP = 0.1
DURATION = 60.0


def rate(t):
    """A tumbling hub's angular velocity, rad/s, hub frame."""
    return np.array([0.05 * np.sin(0.3 * t), 0.03 * np.cos(0.2 * t), 0.02 + 0.01 * t / 60])


def truth(steps_per_sample=20):
    """The attitude at every gyro sample and the mean rate over each sample (rates
    integrated by the midpoint rule on a fine grid)."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    count = int(round(DURATION / GYRO_STEP))
    attitudes, rates = [q], []
    h = GYRO_STEP / steps_per_sample
    for k in range(count):
        mean = np.zeros(3)
        for j in range(steps_per_sample):
            w = rate(k * GYRO_STEP + (j + 0.5) * h)
            q = product(q, from_rotation_vector(w * h))
            mean += w / steps_per_sample
        attitudes.append(q / np.linalg.norm(q))
        rates.append(mean)
    return np.array(attitudes), np.array(rates)


def sensors(latency=0.0, outages=()):
    return AttitudeSensors(
        star_tracker=StarTracker(cross_noise=2e-5, boresight_noise=1e-4, sample_time=1.0,
                                 boresight=(1.0, 1.0, 0.0), latency=latency, outages=outages),
        gyro=Gyro(angle_random_walk=3e-5, rate_random_walk=2e-6,
                  initial_bias=(1e-4, -2e-4, 5e-5)),
        gyro_sample_time=GYRO_STEP, seed=7)


def fly(setup, seed, attitudes, rates):
    """One run: the normalised estimation error squared at every star tracker sample, and
    the trace of the attitude covariance."""
    session = setup.start(seed)
    q0 = product(attitudes[0], from_rotation_vector(np.random.default_rng(seed).normal(
        0.0, 1e-3, 3)))
    estimator = AttitudeFilter(setup, attitude=q0, attitude_sigma=1e-3, bias_sigma=3e-4)
    every, lag = setup.tracker_every, estimator.lag
    nees, spread = [], []
    for k in range(len(rates)):
        bias = session.bias
        estimator.propagate(session.gyro(rates[k]))
        now = k + 1
        if now % every == 0 and now - lag >= 0 and setup.star_tracker.available(now * GYRO_STEP):
            estimator.update(session.star_tracker(attitudes[now - lag]))
        if now % every == 0:
            error = np.concatenate([error_angles(estimator.attitude, attitudes[now]),
                                    session.bias - estimator.bias])
            nees.append(error @ np.linalg.solve(estimator.covariance, error))
            spread.append(np.trace(estimator.covariance[:3, :3]))
        del bias
    return np.array(nees), np.array(spread)


@pytest.mark.parametrize("latency, outages", [(0.0, ()), (0.3, ((20.0, 32.0),))],
                         ids=["on time", "late, with an outage"])
def test_the_filter_is_consistent_over_monte_carlo_runs(latency, outages):
    """30 runs of 60 s: the average normalised estimation error squared (6 states) lies
    within its two-sided 99 % chi-square bounds at nearly every star tracker sample after
    the first ten seconds, and the attitude covariance grows during an outage and shrinks
    after it."""
    attitudes, rates = truth()
    setup = sensors(latency, outages)
    runs = [fly(setup, seed, attitudes, rates) for seed in range(30)]
    nees = np.mean([r[0] for r in runs], axis=0)
    low, high = chi2.ppf([0.005, 0.995], 6 * 30) / 30
    settled = nees[10:]
    inside = np.mean((settled > low) & (settled < high))
    print(f"mean NEES {settled.mean():.2f} (6 expected), bounds [{low:.2f}, {high:.2f}], "
          f"{inside:.0%} of the samples inside")
    assert inside >= 0.9
    assert 6 * 0.8 < settled.mean() < 6 * 1.2
    if outages:
        spread = runs[0][1]
        print(f"attitude variance: before the outage {spread[18]:.2e}, at its end {spread[30]:.2e}, "
              f"after {spread[40]:.2e} rad^2")
        assert spread[30] > 3 * spread[18] and spread[40] < spread[30] / 3


def test_the_sensors_have_the_statistics_they_are_given():
    """The gyro's white noise and the tracker's noise across and about the boresight, from
    many readings of a still hub; the same seed gives the same readings."""
    setup = AttitudeSensors(
        star_tracker=StarTracker(cross_noise=2e-5, boresight_noise=1e-4, sample_time=0.1,
                                 boresight=(0.0, 1.0, 0.0)),
        gyro=Gyro(angle_random_walk=3e-5, misalignment=[[0, 1e-3, 0], [0, 0, 0], [0, 0, 0]],
                  scale_factor=(1e-3, 0, 0)),
        gyro_sample_time=0.1, seed=3)
    session = setup.start()
    still = np.array([1.0, 0.0, 0.0, 0.0])
    readings = np.array([session.gyro(np.zeros(3)) for _ in range(20000)])
    np.testing.assert_allclose(readings.std(axis=0), 3e-5 / np.sqrt(0.1), rtol=0.03)
    errors = np.array([error_angles(still, session.star_tracker(still)) for _ in range(20000)])
    np.testing.assert_allclose(errors.std(axis=0), [2e-5, 1e-4, 2e-5], rtol=0.03)
    spinning = setup.start().gyro([0.0, 1.0, 0.0])
    np.testing.assert_allclose(spinning, [1e-3, 1.0, 0.0], atol=5 * 3e-5 / np.sqrt(0.1))
    again = setup.start()
    assert np.array_equal(again.gyro(np.zeros(3)), setup.start().gyro(np.zeros(3)))


def test_bad_sensor_settings_are_refused_by_name():
    with pytest.raises(InputValueError, match=r"star_tracker\.outages\[0\]"):
        StarTracker(cross_noise=1e-5, boresight_noise=1e-5, sample_time=1.0,
                    outages=((5.0, 2.0),))
    with pytest.raises(InputValueError, match=r"gyro\.misalignment"):
        Gyro(angle_random_walk=1e-5, misalignment=np.eye(3) * 1e-3)
    with pytest.raises(InputValueError, match="whole multiple"):
        AttitudeSensors(star_tracker=StarTracker(cross_noise=1e-5, boresight_noise=1e-5,
                                                 sample_time=0.25),
                        gyro=Gyro(angle_random_walk=1e-5), gyro_sample_time=0.1)
    setup = AttitudeSensors(star_tracker=StarTracker(cross_noise=1e-5, boresight_noise=1e-5,
                                                     sample_time=1.0, latency=0.25),
                            gyro=Gyro(angle_random_walk=1e-5), gyro_sample_time=0.1)
    with pytest.raises(InputValueError, match="whole number of gyro samples"):
        AttitudeFilter(setup, attitude=[1, 0, 0, 0], attitude_sigma=1e-3)
