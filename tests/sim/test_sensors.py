"""Noisy sampled sensors (flexctl.sim.sensors) and the Kalman estimator that reads them
(controllers.feedback.observer): the statistics of each reading, the tip accelerometer's physics,
and
the estimate's convergence on an exactly discretised plant.

The closed loops here are run on the linear plant discretised exactly (zero-order hold), not by
``flexctl.simulate``: they test the estimator, not the simulation core.
"""

import json
import math
import types

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

import flexctl
from controllers import PD
from controllers.feedback.observer import Observed, kalman_step
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.sensors import (VARIANCE_FLOOR, Sensors, measurement_matrix,
                                 noise_covariance, sensor_names)

SAMPLE_TIME = 0.01
#: Allowed deviation of a sample statistic from its expectation, in standard errors.
STANDARD_ERRORS = 4.0


@pytest.fixture(scope="module")
def model():
    return flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)


@pytest.fixture(scope="module")
def two_arrays():
    return flexctl.build_model(flexctl.load_scene("two-array-free").system, n_modes=2)


def _state(model, theta=0.3, theta_dot=0.2, q=(0.01, -0.002), q_dot=(0.05, 0.01)):
    return model.layout.join(theta=theta, theta_dot=theta_dot, q=np.array(q),
                             q_dot=np.array(q_dot))


# ---------------------------------------------------------------------- statistics
def test_encoder_reading_is_a_multiple_of_the_step_within_half_a_step(model, rng):
    step, count = 1e-3, 20000
    session = Sensors(encoder_resolution=step).start(model, SAMPLE_TIME)
    angles = rng.uniform(-math.pi, math.pi, count)
    readings = np.array([session.read(model.layout.join(theta=a))[0] for a in angles])
    counts = readings / step
    assert np.allclose(counts, np.round(counts), rtol=0, atol=1e-9)
    error = readings - angles
    assert np.max(np.abs(error)) <= step / 2 + 1e-12
    # uniform on [-a, a]: variance a^2/3, and the sample variance's standard error
    # sqrt(4 a^4 / 45 / N)
    half = step / 2
    standard_error = math.sqrt(4 * half ** 4 / 45 / count)
    assert abs(np.mean(error ** 2) - step ** 2 / 12) < STANDARD_ERRORS * standard_error


def test_gyro_white_noise_has_the_angle_random_walk_variance_over_a_sample(model):
    arw, count = 2e-3, 20000
    session = Sensors(gyro_noise=arw, seed=7).start(model, SAMPLE_TIME)
    x = _state(model)
    error = np.array([session.read(x)[1] for _ in range(count)]) - x[model.layout.theta_dot]
    expected = arw ** 2 / SAMPLE_TIME
    # the sample variance of a Gaussian has relative standard error sqrt(2 / N)
    assert abs(np.var(error) / expected - 1) < STANDARD_ERRORS * math.sqrt(2 / count)
    assert abs(np.mean(error)) < STANDARD_ERRORS * math.sqrt(expected / count)


def test_gyro_bias_is_gauss_markov_of_the_stated_spread_and_correlation(model):
    sigma, tau, count = 1e-3, 0.1, 40000
    session = Sensors(gyro_bias_instability=sigma, gyro_bias_time=tau, seed=11).start(
        model, SAMPLE_TIME)
    x = _state(model)
    bias = np.array([session.read(x)[1] for _ in range(count)]) - x[model.layout.theta_dot]
    decay = math.exp(-SAMPLE_TIME / tau)
    # about N (1 - a) / (1 + a) independent samples over 4000 correlation times
    effective = count * (1 - decay) / (1 + decay)
    assert abs(np.std(bias) / sigma - 1) < STANDARD_ERRORS * math.sqrt(1 / (2 * effective))
    lag_one = np.corrcoef(bias[:-1], bias[1:])[0, 1]
    assert abs(lag_one - decay) < STANDARD_ERRORS * math.sqrt((1 - decay ** 2) / count)


def test_root_moment_noise_has_the_stated_standard_deviation(model):
    sigma, count = 0.05, 20000
    session = Sensors(root_moment_noise=sigma, seed=5).start(model, SAMPLE_TIME)
    x = _state(model)
    truth = model.outputs(x)[model.output_names.index("root_moment")]
    error = np.array([session.read(x)[2] for _ in range(count)]) - truth
    assert abs(np.std(error) / sigma - 1) < STANDARD_ERRORS * math.sqrt(1 / (2 * count))
    # exact sensors elsewhere: theta and theta_dot read true
    y = session.read(x)
    assert y[0] == x[0] and y[1] == x[model.layout.theta_dot]


# ---------------------------------------------------------------------- tip accelerometers
def _tip_positions(model, x):
    """Inertial position of every tip (K, 2), small-deflection geometry."""
    layout, structure = model.layout, model.structure
    theta = x[layout.theta]
    hub = np.zeros(2) if layout.hub_position is None else x[layout.hub_position]
    turn = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    w = model.tip_matrix @ layout.modal(x)
    return np.array([hub + turn @ ((structure.root_radius(app) + app.beam.length)
                                   * app.direction + w[k] * app.normal)
                     for k, app in enumerate(structure.appendages)])


@pytest.mark.parametrize("which", ["hub-beam-mass", "two-array-free"])
def test_tip_acceleration_is_the_second_derivative_of_the_tip_position(which, model,
                                                                       two_arrays):
    plant = model if which == "hub-beam-mass" else two_arrays
    torque, h = 0.7, 2e-3
    # an instant at which nothing moves: the tip's transverse acceleration is then exactly
    # the second derivative of its position along its normal, with no rate products
    x0 = plant.layout.zeros()
    x0[plant.layout.theta] = 0.4
    x0[plant.layout.q] = 0.01 * np.arange(1, plant.layout.n_modes + 1)
    session = Sensors(tip_acceleration_noise=0.0).start(plant, SAMPLE_TIME)
    reading = session.read(x0, plant.dynamics(0.0, x0, torque))
    names = sensor_names(plant, Sensors(tip_acceleration_noise=0.0))
    tips = reading[[k for k, n in enumerate(names) if n.endswith("tip_acceleration")]]

    def state_at(t):
        return scipy.integrate.solve_ivp(lambda s, y: plant.dynamics(s, y, torque), (0.0, t),
                                         x0, method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]

    def second_difference(step):
        return (_tip_positions(plant, state_at(step)) - 2 * _tip_positions(plant, x0)
                + _tip_positions(plant, state_at(-step))) / step ** 2

    # Richardson: the O(h^2) error of the second difference cancels
    second = (4 * second_difference(h / 2) - second_difference(h)) / 3
    theta = x0[plant.layout.theta]
    turn = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    normals = np.array([turn @ app.normal for app in plant.structure.appendages])
    expected = np.sum(second * normals, axis=1)
    assert np.allclose(tips, expected, rtol=1e-6, atol=0), (tips, expected)


def test_tip_acceleration_reads_the_model_dynamics_and_needs_them(model, rng):
    session = Sensors(tip_acceleration_noise=0.0).start(model, SAMPLE_TIME)
    layout = model.layout
    reach = model.structure.hub.radius + model.structure.appendages[0].beam.length
    for _ in range(5):
        x = _state(model, *rng.normal(0, 0.1, 2), rng.normal(0, 0.01, 2), rng.normal(0, .1, 2))
        xdot = model.dynamics(0.0, x, rng.normal())
        expected = reach * xdot[layout.theta_dot] + model.tip_matrix[0] @ xdot[layout.q_dot]
        assert session.read(x, xdot)[-1] == pytest.approx(expected, rel=1e-12, abs=1e-12)
    with pytest.raises(InputValueError, match="sensors.read xdot must be given"):
        session.read(x)


@pytest.mark.parametrize("which", ["hub-beam-mass", "two-array-free"])
def test_measurement_matrix_is_the_readings_at_rest(which, model, two_arrays, rng):
    plant = model if which == "hub-beam-mass" else two_arrays
    sensors = Sensors(tip_acceleration_noise=0.0)
    c, d = measurement_matrix(plant, sensors)
    session = sensors.start(plant, SAMPLE_TIME)
    assert c.shape == (len(session.names), plant.n_states) and d.shape == (c.shape[0], 1)
    for _ in range(3):
        # small deflections, no hub rate, hub angle 0: the readings are linear there up to
        # terms of the deflection's relative size, 1e-6
        x = plant.layout.zeros()
        x[plant.layout.q] = rng.normal(0.0, 1e-6, plant.layout.n_modes)
        x[plant.layout.q_dot] = rng.normal(0.0, 5e-6, plant.layout.n_modes)
        u = 1e-4 * rng.normal()
        truth = session.true_values(x, plant.dynamics(0.0, x, u))
        linear = c @ x + d[:, 0] * u
        assert np.allclose(linear, truth, rtol=1e-6, atol=1e-6 * np.max(np.abs(truth)))


# ---------------------------------------------------------------------- contracts
@pytest.mark.parametrize("scene, variant", [("hub-beam-mass", "first_order"),
                                            ("hub-beam-mass", "exact"),
                                            ("two-array-free", "exact"),
                                            ("wheel-slew", None), ("flexible-link", None)])
def test_root_moments_are_read_as_the_models_outputs(scene, variant, rng):
    # the sensors read the root moments by rows over the state: they must be the model's own
    # outputs, for every variant and at deflections far from small (a wheel's or a motor's
    # states in the layout too)
    from flexctl.app.scenes import load_scene
    from flexctl.sim.sensors import _root_outputs, _root_rows

    loaded = load_scene(scene)
    plant = (loaded.build_model() if variant is None
             else flexctl.build_model(loaded.system, n_modes=3, variant=variant))
    rows = _root_rows(plant)
    for _ in range(5):
        x = rng.normal(size=plant.n_states)
        x[plant.layout.q] *= 0.2 * float(np.min(plant.lengths))
        expected = np.asarray(plant.outputs(x))[_root_outputs(plant)]
        np.testing.assert_allclose(rows @ x, expected, rtol=1e-12,
                                   atol=1e-12 * np.max(np.abs(expected)))


def test_sensor_names_follow_the_outputs(two_arrays, model):
    assert sensor_names(two_arrays, Sensors(tip_acceleration_noise=0.1,
                                            root_moment_noise=0.0)) == (
        "theta", "theta_dot", "wing_a.root_moment", "wing_b.root_moment",
        "wing_a.tip_acceleration", "wing_b.tip_acceleration")
    # a gauge exists when asked for: by its noise, or in the signals
    assert sensor_names(model, Sensors()) == ("theta", "theta_dot")
    assert sensor_names(two_arrays, Sensors(tip_acceleration_noise=0.1)) == (
        "theta", "theta_dot", "wing_a.tip_acceleration", "wing_b.tip_acceleration")
    assert sensor_names(model, Sensors(signals=["root_moment", "attitude"])) == (
        "theta", "root_moment")


def test_noise_covariance_diagonal_and_floor(model):
    sensors = Sensors(encoder_resolution=1e-3, gyro_noise=1e-3, gyro_bias_instability=2e-3,
                      root_moment_noise=0.1, tip_acceleration_noise=0.0)
    r = noise_covariance(model, sensors, 0.02)
    assert np.allclose(np.diag(r), [1e-6 / 12, 1e-6 / 0.02 + 4e-6, 0.01, VARIANCE_FLOOR],
                       rtol=1e-12, atol=0)
    assert np.count_nonzero(r - np.diag(np.diag(r))) == 0
    assert noise_covariance(model, sensors, 0.02, with_bias=True)[1, 1] == \
        pytest.approx(1e-6 / 0.02, rel=1e-12)
    assert np.all(np.diag(noise_covariance(model, Sensors(), 0.02)) == VARIANCE_FLOOR)


def test_same_seed_same_readings_other_seed_other_readings(model):
    noisy = dict(encoder_resolution=1e-3, gyro_noise=1e-3, gyro_bias_instability=1e-3,
                 root_moment_noise=0.1, tip_acceleration_noise=0.1)
    x = _state(model)
    xdot = model.dynamics(0.0, x, 0.5)

    def readings(seed):
        session = Sensors(seed=seed, **noisy).start(model, SAMPLE_TIME)
        return np.array([session.read(x, xdot) for _ in range(50)])

    assert np.array_equal(readings(3), readings(3))
    assert not np.allclose(readings(3)[:, 1:], readings(4)[:, 1:])


@pytest.mark.parametrize("field, value, error, match", [
    ("gyro_noise", -1e-3, InputValueError, r"sensors\.gyro_noise must be finite and >= 0"),
    ("encoder_resolution", math.nan, InputValueError, r"sensors\.encoder_resolution .*nan"),
    ("root_moment_noise", math.inf, InputValueError, r"sensors\.root_moment_noise .*inf"),
    ("gyro_bias_instability", "1e-3", InputTypeError,
     r"sensors\.gyro_bias_instability must be a real number"),
    ("gyro_bias_time", 0.0, InputValueError, r"sensors\.gyro_bias_time must be finite and > 0"),
    ("tip_acceleration_noise", -0.1, InputValueError, r"sensors\.tip_acceleration_noise"),
    ("delay", -0.01, InputValueError, r"sensors\.delay must be finite and >= 0 and <= 10"),
    ("delay", 60.0, InputValueError, r"sensors\.delay .*got 60\.0"),
    ("sample_time", 0.0, InputValueError, r"sensors\.sample_time must be finite and > 0"),
    ("seed", True, InputTypeError, r"sensors\.seed must be an integer >= 0; got True"),
    ("seed", -1, InputValueError, r"sensors\.seed must be an integer >= 0; got -1"),
    ("seed", 1.5, InputTypeError, r"sensors\.seed must be an integer"),
    # the filter squares a noise level into a variance: 1e300 overflowed it
    ("gyro_noise", 1e300, InputValueError, r"sensors\.gyro_noise must be .*<= 1e\+100"),
    ("tip_acceleration_noise", 1e200, InputValueError, r"sensors\.tip_acceleration_noise"),
], ids=lambda v: str(v)[:24])
def test_bad_sensor_settings_raise_naming_the_field(field, value, error, match):
    with pytest.raises(error, match=match):
        Sensors(**{field: value})


def test_reprs_are_readable(model):
    sensors = Sensors(encoder_resolution=1e-4, gyro_noise=1e-4, delay=0.002)
    assert repr(sensors).startswith("Sensors(attitude step 0.0001 rad, gyro ARW 0.0001 "
                                    "rad/sqrt(s)")
    assert "delay 0.002 s" in repr(sensors) and "root moment" not in repr(sensors)
    assert "2 readings every 0.01 s" in repr(sensors.start(model, SAMPLE_TIME))
    assert "sample_time=0.01 s" in repr(Observed(PD(kp=1.0, kd=1.0), sensors, SAMPLE_TIME))


# ---------------------------------------------------------------------- the estimator
class _ExactPlant:
    """The linear plant stepped exactly (zero-order hold), read by a SensorSession through the
    sensors' delay: the truth an estimator is measured against."""

    def __init__(self, model, sensors, x0):
        self.model, self.sensors = model, sensors
        self.a, self.b = model.linear_matrices(0.0)
        self.reader = sensors.start(model, SAMPLE_TIME)
        self.states, self.commands = [np.array(x0, dtype=float)], []

    def hold(self, h):
        n = self.a.shape[0]
        block = np.zeros((n + 1, n + 1))
        block[:n, :n], block[:n, n:] = self.a, self.b
        e = scipy.linalg.expm(block * h)
        return e[:n, :n], e[:n, n]

    def delayed(self, k):
        """State at ``t_k - delay`` and the command held just before then."""
        epoch = k * SAMPLE_TIME - self.sensors.delay
        if epoch <= 0.0:
            return self.states[0], 0.0
        j = int(math.floor(epoch / SAMPLE_TIME + 1e-9))
        rest = epoch - j * SAMPLE_TIME
        if rest < 1e-12:
            return self.states[j], self.commands[j - 1] if j else 0.0
        phi, gam = self.hold(rest)
        return phi @ self.states[j] + gam * self.commands[j], self.commands[j]

    def read(self, k):
        x, u = self.delayed(k)
        return self.reader.read(x, self.a @ x + self.b[:, 0] * u)

    def apply(self, u):
        phi, gam = self.hold(SAMPLE_TIME)
        self.commands.append(u)
        self.states.append(phi @ self.states[-1] + gam * u)


def _run(model, observed, samples, x0=None, filter_x0=None):
    x0 = model.layout.zeros() if x0 is None else x0
    plant = _ExactPlant(model, observed.sensors, x0)
    session = observed.start(model, x0 if filter_x0 is None else filter_x0)
    for k in range(samples):
        plant.apply(session.step(k * SAMPLE_TIME, plant.read(k)))
    return plant, session, np.array(plant.states[:samples])


NOISY = dict(seed=3, encoder_resolution=1e-4, gyro_noise=1e-4, gyro_bias_instability=2e-3,
             gyro_bias_time=100.0, root_moment_noise=0.02)


def _open_loop(t):
    return 0.5 * math.sin(1.3 * t)


@pytest.mark.parametrize("accelerometers", [None, 0.01], ids=["no-accelerometers",
                                                              "accelerometers"])
def test_estimate_converges_and_finds_the_gyro_bias(model, accelerometers):
    sensors = Sensors(tip_acceleration_noise=accelerometers, **NOISY)
    plant, session, truth = _run(model, Observed(_open_loop, sensors, SAMPLE_TIME), 1000)
    late = slice(500, None)                  # after 5 s
    error = session.estimates[late] - truth[late]
    layout = model.layout
    # the estimate beats each raw reading: the encoder's quantisation error (step / sqrt 12)
    # and the gyro's white noise per sample (its bias, 2e-3 rad/s, removed)
    encoder = 1e-4 / math.sqrt(12)
    gyro = 1e-4 / math.sqrt(SAMPLE_TIME)
    assert np.sqrt(np.mean(error[:, layout.theta] ** 2)) < encoder
    assert np.sqrt(np.mean(error[:, layout.theta_dot] ** 2)) < gyro
    # the bias found within the filter's own 4 sigma, which is far below the bias's spread
    bias_std = math.sqrt(session.covariance[layout.n_states, layout.n_states])
    assert bias_std < 0.2 * sensors.gyro_bias_instability
    assert abs(session.bias_estimates[-1] - plant.reader.bias) < 4 * bias_std
    report = session.report()
    json.dumps(report)
    assert report["samples"] == 1000 and report["gyro_bias"] == session.bias_estimates[-1]
    assert report["largest_normalised_innovation"] < 6.0


@pytest.mark.parametrize("delay", [0.004, 0.025], ids=["under-a-sample", "two-and-a-half"])
def test_delay_is_compensated_by_extrapolating_over_the_held_commands(model, delay):
    sensors = Sensors(delay=delay, **NOISY)
    _, session, truth = _run(model, Observed(_open_loop, sensors, SAMPLE_TIME), 800)
    late = slice(400, None)
    theta = model.layout.theta
    compensated = np.abs(session.estimates[late, theta] - truth[late, theta])
    at_epoch = np.abs(session.filtered[late, theta] - truth[late, theta])
    # the estimate at the sample time is as good as without delay; the filter's own
    # estimate, at the reading epoch, lags the hub by about rate * delay
    assert np.sqrt(np.mean(compensated ** 2)) < 3e-5
    rate = np.abs(truth[late, model.layout.theta_dot])
    assert np.mean(at_epoch) > 0.5 * delay * np.mean(rate) > 10 * np.mean(compensated)


def test_session_is_a_loop_of_the_pure_kalman_step(model):
    sensors = Sensors(tip_acceleration_noise=0.01, **NOISY)
    plant = _ExactPlant(model, sensors, model.layout.zeros())
    session = Observed(_open_loop, sensors, SAMPLE_TIME).start(model, model.layout.zeros())
    mats, readings = session.matrices, []
    for k in range(200):
        readings.append(plant.read(k))
        plant.apply(session.step(k * SAMPLE_TIME, readings[-1]))
    x_hat = np.append(model.layout.zeros(), 0.0)
    p, held = session.matrices.Q + VARIANCE_FLOOR * np.eye(x_hat.size), 0.0
    p[-1, -1] = sensors.gyro_bias_instability ** 2
    for k, (y, u) in enumerate(zip(readings, plant.commands)):
        x_plus, _, x_hat, p = kalman_step(x_hat, p, y, u, mats.Ad, mats.Bd, mats.C, mats.D,
                                          mats.Q, mats.R, u_held=held)
        held = u
        assert np.allclose(x_plus, session.filtered[k], rtol=1e-9, atol=1e-12)


def test_clipped_command_is_returned_and_predicted_with(model):
    limited = types.SimpleNamespace(**{name: getattr(model, name) for name in (
        "layout", "n_states", "output_names", "output_matrix", "structure", "outputs",
        "linear_matrices", "tip_matrix")})
    limited.actuator = types.SimpleNamespace(command_limit=0.1)
    observed = Observed(lambda t, x: 1.0, Sensors(**NOISY), SAMPLE_TIME)
    plant = _ExactPlant(model, observed.sensors, model.layout.zeros())
    session = observed.start(limited, model.layout.zeros())
    for k in range(100):
        u = session.step(k * SAMPLE_TIME, plant.read(k))
        assert u == 0.1
        plant.apply(u)
    # the plant got 0.1 N m, and so did the filter: its estimate follows the plant
    assert abs(session.estimates[-1][0] - plant.states[99][0]) < 1e-4
    assert session.report()["clipped_samples"] == 100


def test_pd_on_the_estimate_regulates_the_hub(model):
    x0 = model.layout.join(theta=0.1)
    observed = Observed(PD(kp=9.0, kd=8.0), Sensors(**NOISY), SAMPLE_TIME)
    _, session, truth = _run(model, observed, 800, x0=x0)
    assert np.max(np.abs(truth[-100:, model.layout.theta])) < 0.01
    assert np.all(np.isfinite(session.estimates))


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(sample_time=-0.01), InputValueError, r"observed\.sample_time must be finite and > 0"),
    (dict(process_noise=-1.0), InputValueError, r"observed\.process_noise"),
    (dict(sensors="noisy"), InputTypeError, r"observed\.sensors must be a Sensors"),
    (dict(sensors=Sensors(sample_time=0.02)), InputValueError,
     r"observed\.sample_time must equal sensors\.sample_time"),
    (dict(law=42), InputTypeError, r"observed\.law must be a static flexctl Controller"),
], ids=["sample-time", "process-noise", "sensors-type", "two-rates", "law-type"])
def test_bad_observed_settings_raise(kwargs, error, match):
    settings = dict(law=_open_loop, sensors=Sensors(), sample_time=SAMPLE_TIME) | kwargs
    with pytest.raises(error, match=match):
        Observed(**settings)


@pytest.mark.parametrize("sensors, t_final, match", [
    (Sensors(delay=9.0), 4.0, r"sensors\.delay 9 s must be shorter than the run"),
    (Sensors(sample_time=5.0), 4.0, r"sample time 5 s must be shorter than the run"),
], ids=["delay-past-the-end", "one-reading"])
def test_sensors_that_cannot_see_the_run_are_refused_before_it(model, sensors, t_final, match):
    # a 9 s delay in a 4 s run, or one reading in the whole run, ended "ok" with the hub unmoved
    observed = Observed(PD(kp=9.0, kd=8.0), sensors,
                        sensors.sample_time or SAMPLE_TIME)
    with pytest.raises(InputValueError, match=match):
        flexctl.simulate(model, t_final, controller=observed, sensors=sensors,
                         x0=model.layout.join(theta=0.1))

