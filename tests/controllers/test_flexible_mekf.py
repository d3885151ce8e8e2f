"""The attitude filter with the appendages' modes (:mod:`controllers.feedback.flexible_mekf`):
consistent over Monte Carlo runs where the structure moves as its model says, tracking the
arrays' modes, and flying in the sampled loop."""

import numpy as np
import pytest

from controllers.feedback.flexible_mekf import EstimatedStateLaw, FlexibleAttitudeFilter
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure, VectorTorque, simulate_spatial
from flexctl.model.errors import InputError
from flexctl.sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker
from flexctl.sim.quaternions import conjugate, error_angles, product, rotation_vector


def _array(name, direction):
    return SpatialAppendage(name=name, direction=direction, normal=(0.0, 0.0, 1.0), length=1.8,
                            density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
                            shear_modulus=2.6e10, torsion_constant=1.0e-9, damping_ratio=0.005)


CRAFT = SpatialStructure(hub=SpatialHub(inertia=[[1.30, 0.05, 0.0], [0.05, 1.20, 0.0],
                                                 [0.0, 0.0, 1.40]], radius=0.06),
                         appendages=(_array("wing_a", (0.0, 1.0, 0.0)),
                                     _array("wing_b", (0.0, -1.0, 0.0))))
STEP, SIGMA = 0.1, 1e-4
SENSORS = AttitudeSensors(star_tracker=StarTracker(cross_noise=2e-5, boresight_noise=1e-4,
                                                   sample_time=0.5),
                          gyro=Gyro(angle_random_walk=3e-5, rate_random_walk=1e-6),
                          gyro_sample_time=STEP)


def _filtered(seed, t_final=20.0):
    """A run under a known torque plus a disturbance held over each gyro sample (the filter's
    model of it), read by the sensors and filtered: per sample after the first, the
    estimation errors of the attitude and of the filtered modal part and the filter's
    covariance of them; the out-of-plane bending of ``wing_a``, its estimate and the
    estimate's standard deviation."""
    times = np.arange(0.0, t_final + STEP / 2, STEP)
    known = np.array([0.01 * np.sin(0.7 * times), 0.008 * np.cos(1.3 * times),
                      0.006 * np.sin(0.4 * times + 1.0)]).T
    disturbance = SIGMA * np.random.default_rng(100 + seed).standard_normal(known.shape)
    run = simulate_spatial(CRAFT, t_final, VectorTorque(times, known + disturbance,
                                                        interpolation="hold"),
                           n_modes=1, variant="first_order", rtol=1e-10, output_step=STEP)
    assert run.ok
    readings = SENSORS.start(seed)
    estimator = FlexibleAttitudeFilter(SENSORS, CRAFT, run.quaternion[:, 0], 1e-3,
                                       torque_sigma=SIGMA)
    rows, part = estimator.model.full_rows, estimator.part
    bending = estimator.names.index("wing_a.qn1")
    errors, covariances, tracked = [], [], []
    for k in range(1, run.t.size):
        turned = rotation_vector(product(conjugate(run.quaternion[:, k - 1]),
                                         run.quaternion[:, k]))
        estimator.propagate(readings.gyro(turned / STEP), known[k - 1])
        if k % SENSORS.tracker_every == 0:
            estimator.update(readings.star_tracker(run.quaternion[:, k]))
        modal = part.projector @ run.states[rows, k]
        errors.append(np.concatenate([error_angles(estimator.attitude, run.quaternion[:, k]),
                                      modal - estimator.x]))
        keep = np.r_[0:3, 6:estimator.P.shape[0]]
        covariances.append(estimator.covariance[np.ix_(keep, keep)])
        spread = part.basis @ estimator.P[6:, 6:] @ part.basis.T
        tracked.append((run.states[rows, k][bending], estimator.flexible_state[bending],
                        np.sqrt(spread[bending, bending])))
    return np.array(errors), np.array(covariances), np.array(tracked)


@pytest.mark.slow
def test_it_is_consistent_over_monte_carlo_runs():
    """The normalised estimation error squared of the attitude and the filtered modal part,
    averaged over 8 runs, within its two-sided 95 % chi-square bounds at most samples after
    the first 5 s, and its mean within 15 % of the dimension."""
    from scipy.stats import chi2

    runs = [_filtered(seed) for seed in range(8)]
    nees = np.array([[e @ np.linalg.solve(p, e) for e, p in zip(errors, covariances)]
                     for errors, covariances, _ in runs])
    late = nees[:, 50:]
    dof, count = runs[0][0].shape[1], len(runs)
    low, high = chi2.ppf([0.025, 0.975], dof * count) / count
    average = late.mean(axis=0)
    inside = float(np.mean((average >= low) & (average <= high)))
    print(f"dimension {dof}, mean NEES {late.mean():.2f}, bounds [{low:.2f}, {high:.2f}], "
          f"{100 * inside:.0f} % of samples inside")
    assert abs(late.mean() / dof - 1.0) < 0.15
    assert inside > 0.85


def test_it_tracks_the_arrays_modes():
    """The modes the gyro and the star tracker see through the hub: after the first 5 s the
    estimate of the arrays' out-of-plane bending follows the truth to a fraction of its
    motion, its error within its own standard deviations (the attitude filter has none)."""
    tracked = _filtered(0)[2][50:]
    truth, estimate, sigma = tracked.T
    error = estimate - truth
    print(f"wing_a.qn1: rms {np.sqrt(np.mean(truth ** 2)):.3e}, error rms "
          f"{np.sqrt(np.mean(error ** 2)):.3e}, sigma {sigma.mean():.3e}")
    assert np.sqrt(np.mean(error ** 2)) < 0.15 * np.sqrt(np.mean(truth ** 2))
    assert np.max(np.abs(error) / sigma) < 5.0


def test_bad_arguments_are_refused_by_name():
    with pytest.raises(InputError, match=r"flexible_mekf\.torque_sigma"):
        FlexibleAttitudeFilter(SENSORS, CRAFT, (1, 0, 0, 0), 1e-3, torque_sigma=0.0)
    with pytest.raises(InputError, match=r"flexible_mekf\.mode_sigma"):
        FlexibleAttitudeFilter(SENSORS, CRAFT, (1, 0, 0, 0), 1e-3, mode_sigma=np.nan)
    estimator = FlexibleAttitudeFilter(SENSORS, CRAFT, (1, 0, 0, 0), 1e-3)
    with pytest.raises(InputError, match=r"flexible_mekf\.torque"):
        estimator.propagate(np.zeros(3), (0.0, np.inf, 0.0))
    with pytest.raises(InputError, match=r"flexible_mekf\.wheel_momentum"):
        estimator.propagate(np.zeros(3), np.zeros(3), (0.0, np.nan, 0.0))
    with pytest.raises(InputError, match=r"flexible_mekf\.wheel_momentum"):
        estimator.propagate(np.zeros(3), np.zeros(3), np.zeros(4))
    with pytest.raises(InputError, match=r"flexible_mekf\.gyro_reading"):
        estimator.propagate(np.zeros(2))
    with pytest.raises(InputError, match=r"flexible_mekf\.gyro_reading must be at most"):
        estimator.propagate((1e300, 0.0, 0.0))
    with pytest.raises(InputError, match="the estimate left the finite numbers"):
        estimator.propagate(np.zeros(3), (1e300, 0.0, 0.0))
    from controllers.feedback.mekf import AttitudeFilter

    with pytest.raises(InputError, match=r"mekf\.gyro_reading must be at most"):
        AttitudeFilter(SENSORS, (1, 0, 0, 0), 1e-3).propagate((2e3, 0.0, 0.0))


def test_it_flies_in_the_loop():
    """Handed the command held over each sample, the filter flies an LQG's slew as the
    attitude filter does (the same pointing to its noise); the LQG's regulator reading the
    filter's modal estimates (``EstimatedStateLaw``) ends the slew closer and the arrays
    stiller than the LQG."""
    from controllers.feedback.lqr import LQRWeights
    from controllers.feedback.mekf import AttitudeFilter
    from controllers.feedback.spatial_lqr import design_spatial_lqg
    from flexctl.sim.quaternions import from_rotation_vector
    from flexctl.sim.spatial_loop import simulate_spatial_loop

    target = from_rotation_vector([0.05, -0.03, 0.08])
    law = design_spatial_lqg(CRAFT, LQRWeights(hub_angle=0.05, hub_rate=0.05,
                                               tip_deflection=0.005, torque=0.1),
                             target, STEP, n_modes=1, variant="first_order", torque_limit=0.1)
    pointing = {}
    for name, estimator in (
            ("attitude filter", AttitudeFilter(SENSORS, (1, 0, 0, 0), 1e-3)),
            ("with the modes", FlexibleAttitudeFilter(SENSORS, CRAFT, (1, 0, 0, 0), 1e-3))):
        loop = simulate_spatial_loop(CRAFT, 15.0, law, n_modes=1, variant="first_order",
                                     sensors=SENSORS, estimator=estimator, seed=4)
        assert loop.ok
        pointing[name] = float(np.linalg.norm(error_angles(target,
                                                           loop.result.quaternion[:, -1])))
    print(pointing)
    assert pointing["with the modes"] < 2.0 * pointing["attitude filter"] + 1e-5
    # the LQG's regulator on the filter's modal estimates instead of its own filter's
    regulated = {}
    estimator = FlexibleAttitudeFilter(SENSORS, CRAFT, (1, 0, 0, 0), 1e-3)
    for name, flown, reading in (
            ("lqg", law, AttitudeFilter(SENSORS, (1, 0, 0, 0), 1e-3)),
            ("lqr on the filter", EstimatedStateLaw(law.regulator, estimator), estimator)):
        run = simulate_spatial_loop(CRAFT, 15.0, flown, n_modes=1, variant="first_order",
                                    sensors=SENSORS, estimator=reading, seed=4).result
        late = run.t > 10.0
        regulated[name] = (float(np.linalg.norm(error_angles(target, run.quaternion[:, -1]))),
                           max(float(np.max(np.abs(tip[:, late]))) for tip in run.tips.values()))
    print(regulated)
    assert regulated["lqr on the filter"][0] < regulated["lqg"][0]
    assert regulated["lqr on the filter"][1] < regulated["lqg"][1]
    with pytest.raises(InputError, match="the law's design state is not the filter's"):
        EstimatedStateLaw(design_spatial_lqg(CRAFT, LQRWeights(hub_angle=0.05, torque=0.1),
                                             target, STEP, n_modes=2,
                                             variant="first_order").regulator, estimator)
    with pytest.raises(InputError, match=r"estimated_state_law\.estimator"):
        EstimatedStateLaw(law.regulator, AttitudeFilter(SENSORS, (1, 0, 0, 0), 1e-3))


class _Recorded(FlexibleAttitudeFilter):
    """The filter recording its estimate after each sample; with ``momentum_known`` False it
    is not told the wheels' momentum (their gyroscopic torque left out of its model)."""

    momentum_known = True

    def __init__(self, *args, **options):
        super().__init__(*args, **options)
        self.log = []

    def propagate(self, gyro_reading, torque=(0.0, 0.0, 0.0), wheel_momentum=None):
        super().propagate(gyro_reading, torque,
                          wheel_momentum if self.momentum_known else None)
        self.log.append((self.q.copy(), self.x.copy(), self.P.copy()))


def test_through_wheels_it_reads_their_speeds_and_stays_consistent():
    """Through a pyramid of four biased wheels (1 to 1.5 N m s each, with a motor lag and
    friction) the loop hands the filter the motors' torque from the wheels' speeds and their
    momentum, whose gyroscopic torque the filter adds from its rate estimate: flying the LQG's
    slew, its normalised estimation error squared of the attitude and the filtered modes
    stays near its dimension after 5 s (measured 5.7 of 8) and its modal estimate follows the
    truth (error rms 13 % of the motion's); told nothing of the momentum, the same filter is
    inconsistent (measured 226) and the slew ends farther (8.3e-4 rad against 1.3e-4)."""
    from controllers.feedback.lqr import LQRWeights
    from controllers.feedback.spatial_lqr import design_spatial_lqg
    from flexctl.model.wheel_cluster import WheelCluster
    from flexctl.sim.quaternions import from_rotation_vector
    from flexctl.sim.spatial_loop import simulate_spatial_loop

    target = from_rotation_vector([0.05, -0.03, 0.08])
    law = design_spatial_lqg(CRAFT, LQRWeights(hub_angle=0.05, hub_rate=0.05,
                                               tip_deflection=0.005, torque=0.1),
                             target, STEP, n_modes=1, variant="first_order", torque_limit=0.1)
    wheels = WheelCluster.pyramid(angle=54.7356, inertia=0.01, torque_limit=0.1,
                                  speed_limit=300.0, coulomb_friction=1e-3,
                                  viscous_friction=1e-5, time_constant=0.02)
    measured = {}
    for known in (True, False):
        estimator = _Recorded(SENSORS, CRAFT, (1, 0, 0, 0), 1e-3)
        estimator.momentum_known = known
        run = simulate_spatial_loop(CRAFT, 20.0, law, n_modes=1, variant="first_order",
                                    sensors=SENSORS, estimator=estimator, seed=4,
                                    wheels=wheels,
                                    wheel_speeds=(150.0, -100.0, 120.0, -80.0)).result
        assert run.ok
        rows, part = estimator.model.full_rows, estimator.part
        bending = estimator.names.index("wing_a.qn1")
        nees, errors, truth = [], [], []
        for k in range(51, run.t.size):
            q, x, covariance = estimator.log[k - 1]
            error = np.concatenate([error_angles(q, run.quaternion[:, k]),
                                    part.projector @ run.states[rows, k] - x])
            keep = np.r_[0:3, 6:covariance.shape[0]]
            nees.append(error @ np.linalg.solve(covariance[np.ix_(keep, keep)], error))
            errors.append((part.basis @ x)[bending] - run.states[rows, k][bending])
            truth.append(run.states[rows, k][bending])
        measured[known] = (float(np.mean(nees)) / error.size,
                           float(np.sqrt(np.mean(np.square(errors)) / np.mean(np.square(truth)))),
                           float(np.linalg.norm(error_angles(target, run.quaternion[:, -1]))))
    print(measured)
    nees, modal, pointing = measured[True]
    assert 0.4 < nees < 1.6 and modal < 0.25
    assert measured[False][0] > 10.0 and measured[False][2] > 3.0 * pointing


@pytest.mark.slow
def test_as_c_it_estimates_as_python_through_wheels_in_double_and_in_float(tmp_path):
    """The filter with the modes as C (its model's remainder written out, the tracker's
    latency replayed) flies the LQG's slew through the biased wheels with the same estimates
    as the Python filter, sample by sample (the tracker 0.2 s late: two gyro samples replayed
    at each update): in double within 1e-11, in float within 1e-6 rad and 1e-7 rad/s."""
    import dataclasses

    from controllers.codegen import export_c
    from controllers.codegen.filter_program import (FLEXIBLE_FILTER_INPUTS,
                                                    compiled_attitude_filter, filter_program)
    from controllers.feedback.lqr import LQRWeights
    from controllers.feedback.spatial_lqr import design_spatial_lqg
    from flexctl.model.wheel_cluster import WheelCluster
    from flexctl.sim.quaternions import from_rotation_vector
    from flexctl.sim.spatial_loop import simulate_spatial_loop

    law = design_spatial_lqg(CRAFT, LQRWeights(hub_angle=0.05, hub_rate=0.05,
                                               tip_deflection=0.005, torque=0.1),
                             from_rotation_vector([0.05, -0.03, 0.08]), STEP, n_modes=1,
                             variant="first_order", torque_limit=0.1)
    wheels = WheelCluster.pyramid(angle=54.7356, inertia=0.01, torque_limit=0.1,
                                  speed_limit=300.0, coulomb_friction=1e-3, time_constant=0.02)

    late = dataclasses.replace(SENSORS, star_tracker=dataclasses.replace(
        SENSORS.star_tracker, latency=0.2))

    def flown(estimator):
        return simulate_spatial_loop(CRAFT, 10.0, law, n_modes=1, variant="first_order",
                                     sensors=late, estimator=estimator, seed=4,
                                     wheels=wheels, wheel_speeds=(150.0, -100.0, 120.0, -80.0))

    def fresh():
        return FlexibleAttitudeFilter(late, CRAFT, (1, 0, 0, 0), 1e-3)

    program = filter_program(fresh())
    assert program.kind == "flexible_mekf" and program.input_names == FLEXIBLE_FILTER_INPUTS
    assert program.n_out == 7 + len(fresh().names)
    assert program.info["latency_samples"] == 2
    python = flown(fresh())
    assert python.ok
    differences = {}
    for precision in ("double", "float"):
        compiled = export_c(fresh(), None, tmp_path / precision,
                            precision=precision).compile()
        estimator = compiled_attitude_filter(compiled)
        assert estimator.takes_torque
        run = flown(estimator)
        assert run.ok
        differences[precision] = (
            np.max(np.abs(run.attitude_estimates - python.attitude_estimates)),
            np.max(np.abs(run.bias_estimates - python.bias_estimates)))
        if precision == "double":
            reference = fresh()
            reference.propagate((1e-3, 0.0, 0.0), (0.01, 0.0, 0.0), (0.5, 0.2, 0.0))
            fresh_c = compiled_attitude_filter(compiled)
            fresh_c.propagate((1e-3, 0.0, 0.0), (0.01, 0.0, 0.0), (0.5, 0.2, 0.0))
            np.testing.assert_allclose(fresh_c.flexible_state, reference.flexible_state,
                                       rtol=1e-9, atol=1e-14)
    print({k: f"{a:.1e} rad, {b:.1e} rad/s" for k, (a, b) in differences.items()})
    assert differences["double"][0] < 1e-11 and differences["double"][1] < 1e-11
    assert differences["float"][0] < 1e-6 and differences["float"][1] < 1e-7
