"""Sensors are a set the user chooses: which signals exist, and each one's noise model.

- a root gauge or a tip accelerometer exists only when asked for (its noise, or the
  ``signals`` list); a setting of a sensor the set does not hold is refused by name;
- the attitude sensor with white noise and a constant bias: the readings' mean is the truth
  plus that run's bias, their spread the white noise, the bias the same at every sample and
  drawn from a stream of its own (the gyro reads the same numbers with or without it);
- the filter's covariance gives the attitude reading its whole error variance;
- a scene's ``[sensors]`` table takes the same settings, and the Kalman filter built for a
  scene, and the C step exported from it, read exactly the signals it lists.
"""

import math

import numpy as np
import pytest

import flexctl
from flexctl.model.errors import InputValueError
from flexctl.sim.sensors import Sensors, measurement_matrix, noise_covariance, sensor_names

SAMPLE_TIME = 0.01
#: Allowed deviation of a sample statistic from its expectation, in standard errors.
STANDARD_ERRORS = 4.0


@pytest.fixture(scope="module")
def model():
    return flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)


def test_the_attitude_sensor_reads_truth_plus_a_run_bias_plus_white_noise(model):
    noise, bias, count, theta = 2e-4, 1e-3, 4000, 0.3
    sensors = Sensors(attitude_noise=noise, attitude_bias=bias, seed=5)
    session = sensors.start(model, SAMPLE_TIME)
    x = model.layout.join(theta=theta)
    readings = np.array([session.read(x)[0] for _ in range(count)])
    offset = session.attitude_offset
    assert offset != 0.0 and abs(offset) < 5.0 * bias
    assert abs(readings.mean() - theta - offset) < STANDARD_ERRORS * noise / math.sqrt(count)
    assert readings.std() == pytest.approx(noise, rel=STANDARD_ERRORS / math.sqrt(2 * count))
    # the bias of another run is another draw; the gyro's draws do not see it
    assert Sensors(attitude_bias=bias, seed=6).start(model, SAMPLE_TIME).attitude_offset \
        != offset
    gyro = Sensors(gyro_noise=1e-3, seed=5)
    with_bias = Sensors(gyro_noise=1e-3, attitude_bias=bias, seed=5)
    a, b = gyro.start(model, SAMPLE_TIME), with_bias.start(model, SAMPLE_TIME)
    for _ in range(5):
        assert a.read(x)[1] == b.read(x)[1]


def test_the_filter_gives_the_attitude_its_whole_error_variance(model):
    sensors = Sensors(encoder_resolution=1e-3, attitude_noise=2e-4, attitude_bias=1e-4)
    r = noise_covariance(model, sensors, SAMPLE_TIME)
    assert r[0, 0] == pytest.approx(1e-6 / 12 + 4e-8 + 1e-8, rel=1e-12)


def test_only_the_chosen_signals_are_read(model):
    sensors = Sensors(signals=["gyro"], gyro_noise=1e-4)
    assert sensor_names(model, sensors) == ("theta_dot",)
    c, d = measurement_matrix(model, sensors)
    assert c.shape == (1, model.n_states) and c[0, model.layout.theta_dot] == 1.0
    reading = sensors.start(model, SAMPLE_TIME).read(model.layout.join(theta_dot=0.2))
    assert reading.shape == (1,)


@pytest.mark.parametrize("settings,named", [
    ({"signals": ["attitude"], "gyro_noise": 1e-4}, "sensors.gyro_noise"),
    ({"signals": ["attitude", "gyro"], "root_moment_noise": 1e-3}, "sensors.root_moment_noise"),
    ({"signals": ["gyro"], "attitude_noise": 1e-4}, "sensors.attitude_noise"),
    ({"signals": ["attitude", "compass"]}, "sensors.signals must list each of"),
    ({"signals": []}, "sensors.signals must be a non-empty list"),
], ids=["gyro", "root-moment", "attitude", "unknown", "empty"])
def test_a_setting_of_a_sensor_not_in_the_set_is_refused(settings, named):
    with pytest.raises(InputValueError, match=named):
        Sensors(**settings)


def test_a_scene_reads_exactly_the_sensors_it_lists():
    from controllers import from_spec
    from flexctl.app.scenes import SceneError

    overrides = {"model.modes": 2, "model.design_modes": 1,
                 "sensors.signals": ["attitude", "gyro"], "sensors.root_moment_noise": None}
    with pytest.raises(SceneError, match="sensors.root_moment_noise is a setting of the "
                                         "root_moment sensor"):
        flexctl.load_scene("wheel-slew", overrides={**overrides,
                                                    "sensors.root_moment_noise": 1e-4})
    scene = flexctl.load_scene("wheel-slew", overrides=overrides)
    plant = scene.build_model()
    session = from_spec(scene, plant).controller.start(plant, np.zeros(plant.n_states))
    assert session.names == ("theta", "theta_dot")
    assert session.matrices.C.shape[0] == 2
    # the exported C step reads the same two readings, in the same order
    from controllers.codegen.laws import program_for

    program = program_for(from_spec(scene, plant).controller, plant)
    assert program.input_kind == "measurement"
    assert tuple(program.input_names) == ("theta", "theta_dot")
