"""Scenes with an actuator and sensors, and the sampled loop that reads the sensors.

The ``[actuator]`` and ``[sensors]`` tables in the issue's form (every bad key refused by
name), the built-in scenes that use them, the files a run writes (``timeseries.csv`` with the
actuator's columns, ``summary.json`` with its peaks and the sensors' errors), and the readings
a controller saw: their noise, quantisation and delay against the settings, a closed loop on
noisy readings that settles, and the refusals of a loop that mixes sensors and exact states.
"""

import copy
import csv
import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import flexctl
from controllers import LQRWeights, Observed, design_lqr, from_spec
from flexctl import DCMotor, ReactionWheel, SceneError, build_model, load_scene, simulate
from flexctl.app.cli import EXIT_OK, main
from flexctl.app.scenes import parse_scene, run_slew
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.digital import ZeroOrderHold
from flexctl.sim.sensors import Sensors

#: The issue's tables, as an outside check writes them.
WHEEL_TABLE = {"kind": "reaction_wheel", "inertia": 0.02, "torque_limit": 0.2,
               "speed_limit": 600.0, "time_constant": 0.05, "viscous_friction": 1e-5,
               "coulomb_friction": 1e-3}
MOTOR_TABLE = {"kind": "dc_motor", "resistance": 2.6, "torque_constant": 7.68e-3,
               "back_emf_constant": 7.68e-3, "gear_ratio": 70.0, "gear_efficiency": 0.9,
               "rotor_inertia": 3.9e-7, "viscous_friction": 0.015, "voltage_limit": 10.0}
SENSOR_TABLE = {"seed": 1, "encoder_resolution": 1e-4, "gyro_noise": 1e-4,
                "gyro_bias_instability": 1e-5, "root_moment_noise": 1e-3, "delay": 0.002}
#: A short wheel slew of the two-array spacecraft: 10 degrees in 30 s at 10 Hz.
SHORT_WHEEL = {"maneuver.angle_deg": 10.0, "maneuver.duration": 30.0,
               "simulation.t_final": 40.0, "simulation.output_step": 0.1,
               "sensors.sample_time": 0.1}


def _one_beam_table(**tables):
    data = copy.deepcopy(load_scene("hub-beam-mass").data)
    data.update(tables)
    return data


def test_the_issue_tables_parse_into_the_hardware():
    scene = parse_scene(_one_beam_table(actuator=dict(WHEEL_TABLE)))
    assert scene.actuator == ReactionWheel(**{k: v for k, v in WHEEL_TABLE.items()
                                              if k != "kind"})
    model = scene.build_model()
    assert model.actuator is scene.actuator
    assert model.state_names[-2:] == ("wheel_speed", "wheel_torque")
    scene = parse_scene(_one_beam_table(actuator=dict(MOTOR_TABLE)))
    assert isinstance(scene.actuator, DCMotor) and scene.actuator.gear_ratio == 70.0
    data = copy.deepcopy(load_scene("slew-90").data)
    data["sensors"] = dict(SENSOR_TABLE)
    scene = parse_scene(data)
    assert scene.sensors == Sensors(**SENSOR_TABLE)


@pytest.mark.parametrize("tables, match", [
    (dict(actuator={"kind": "thruster"}), "actuator.kind must be one of"),
    (dict(actuator={**WHEEL_TABLE, "voltage_limit": 10.0}), "unknown key 'voltage_limit'"),
    (dict(actuator={k: v for k, v in WHEEL_TABLE.items() if k != "inertia"}),
     "actuator.inertia is required"),
    (dict(actuator={**WHEEL_TABLE, "speed_limit": -1.0}), "actuator.speed_limit must be"),
    (dict(actuator={**MOTOR_TABLE, "gear_efficiency": 2.0}), "actuator.gear_efficiency"),
    (dict(actuator="wheel"), "scene key 'actuator' must be a table"),
    (dict(sensors={"gyro_noise": 1e-4}), "needs? maneuver.kind 'slew'|are read by a "
                                         "controller"),
])
def test_bad_hardware_tables_are_refused_by_name(tables, match):
    with pytest.raises(SceneError, match=match):
        parse_scene(_one_beam_table(**tables))


def test_bad_sensor_keys_and_impossible_pairings_are_refused():
    slew = copy.deepcopy(load_scene("slew-90").data)
    with pytest.raises(SceneError, match="unknown key 'gyro_arw' in \\[sensors\\]"):
        parse_scene({**slew, "sensors": {"gyro_arw": 1.0}})
    with pytest.raises(SceneError, match="sensors.delay must be"):
        parse_scene({**slew, "sensors": {"delay": -1.0}})
    with pytest.raises(SceneError, match="sensors.seed"):
        parse_scene({**slew, "sensors": {"seed": True}})
    free = copy.deepcopy(load_scene("two-array-free").data)
    with pytest.raises(SceneError, match="dc_motor' turns the hub against the ground"):
        parse_scene({**free, "actuator": dict(MOTOR_TABLE)})
    spin = copy.deepcopy(load_scene("kane-spinup").data)
    with pytest.raises(SceneError, match="'spin_up' prescribes the hub's motion"):
        parse_scene({**spin, "actuator": dict(WHEEL_TABLE)})


@pytest.mark.parametrize("name, columns", [
    ("wheel-slew", ("wheel_speed", "wheel_torque")),
    ("flexible-link", ("motor_voltage", "motor_current")),
])
def test_hardware_scenes_write_their_columns_and_summary(tmp_path, name, columns):
    args = ["run", name, "--out", str(tmp_path)]
    for k, v in (SHORT_WHEEL.items() if name == "wheel-slew" else
                 {"simulation.t_final": 1.0}.items()):
        args += ["--set", f"{k}={v}"]
    assert main(args) == EXIT_OK
    with open(tmp_path / "timeseries.csv", newline="") as f:
        rows = list(csv.reader(f))
    header, table = rows[0], np.array(rows[1:], dtype=float)
    assert header[-2:] == list(columns) and np.all(np.isfinite(table))
    summary = json.loads((tmp_path / "summary.json").read_text())
    actuator = summary["actuator"]
    scene = load_scene(name)
    if name == "wheel-slew":
        assert actuator["peak_wheel_torque"] <= scene.actuator.torque_limit * (1 + 1e-9)
        assert actuator["peak_wheel_speed"] == pytest.approx(
            np.max(np.abs(table[:, header.index("wheel_speed")])), rel=1e-9)
    else:
        assert actuator["peak_motor_voltage"] <= scene.actuator.voltage_limit * (1 + 1e-12)
    errors = summary["sensors"]["largest_error"]
    assert errors["theta"] <= 0.5 * scene.sensors.encoder_resolution * (1 + 1e-9)
    assert summary["sensors"]["samples"] > 0 and summary["status"] == "ok"


def _sensed_run(sensors, t_final=4.0, sample_time=0.01, torque=0.5):
    """hub-beam-mass under a constant torque read through ``sensors`` by a filter whose law
    asks for that torque whatever it estimates: the plant's motion is known."""
    model = build_model(load_scene("hub-beam-mass").system, 2)
    law = Observed(law=lambda t, x: torque, sensors=sensors, sample_time=sample_time)
    return model, simulate(model, t_final, controller=law, sensors=sensors,
                           output_step=sample_time / 4)


def test_readings_carry_the_settings_noise():
    """Gyro white noise variance ARW^2 / T, root-moment noise std, encoder steps."""
    sample_time, arw, root_noise, step = 0.01, 2e-3, 0.05, 1e-3
    sensors = Sensors(seed=3, encoder_resolution=step, gyro_noise=arw,
                      root_moment_noise=root_noise)
    _, result = _sensed_run(sensors, t_final=40.0, sample_time=sample_time)
    seen, true = result.measurements, result.measurements["true"]
    count = seen["t"].size
    assert count == 4000
    rate_error = seen["theta_dot"] - true["theta_dot"]
    assert np.var(rate_error) == pytest.approx(arw ** 2 / sample_time,
                                               rel=4 * math.sqrt(2 / count))
    moment_error = seen["root_moment"] - true["root_moment"]
    assert np.std(moment_error) == pytest.approx(root_noise, rel=4 / math.sqrt(2 * count))
    steps = seen["theta"] / step
    assert np.allclose(steps, np.round(steps), atol=1e-6)
    assert np.max(np.abs(seen["theta"] - true["theta"])) <= 0.5 * step * (1 + 1e-9)


def test_readings_are_late_by_the_delay_and_reproducible():
    delay, sample_time = 0.013, 0.01       # more than one sample late
    model, result = _sensed_run(Sensors(seed=4, delay=delay), sample_time=sample_time)
    seen = result.measurements
    t_read = seen["t"] - delay
    late = t_read > 0
    # the true angle read at t_k is the plant's at t_k - delay (interpolated on a grid 4 x finer)
    theta = np.interp(t_read[late], result.t, result.theta)
    assert np.max(np.abs(seen["true"]["theta"][late] - theta)) <= 1e-5 * np.max(
        np.abs(result.theta))
    assert np.all(seen["true"]["theta"][~late] == result.theta[0])
    again = _sensed_run(Sensors(seed=4, delay=delay), sample_time=sample_time)[1]
    assert np.array_equal(again.measurements["theta_dot"], seen["theta_dot"])


def test_a_filtered_slew_on_noisy_readings_settles_within_the_noise():
    """The wheel slew read through its sensors by the Kalman filter: the hub ends within a few
    encoder steps of the target, the wheel gives its momentum back."""
    scene = load_scene("wheel-slew", SHORT_WHEEL)
    result, built, metrics = run_slew(scene, from_spec)
    assert result.ok and built.info["estimator"].startswith("kalman")
    last = result.t >= result.t[-1] - 5.0
    error = np.mean(result.theta[last]) - scene.maneuver.angle
    assert abs(error) <= 5 * scene.sensors.encoder_resolution
    speed = result.actuator_signals["wheel_speed"]
    assert abs(speed[-1]) <= 0.02 * np.max(np.abs(speed))
    assert result.controller_report["largest_normalised_innovation"] < 6.0


def test_sensors_and_exact_states_do_not_mix():
    model = build_model(load_scene("hub-beam-mass").system, 2)
    sensors = Sensors(gyro_noise=1e-4)
    pd = ZeroOrderHold(lambda t, x: -x[0], sample_time=0.01)
    with pytest.raises(InputValueError, match="reads the plant's exact state"):
        simulate(model, 1.0, controller=pd, sensors=sensors)
    observed = Observed(law=lambda t, x: 0.0, sensors=sensors, sample_time=0.01)
    with pytest.raises(InputValueError, match="pass sensors="):
        simulate(model, 1.0, controller=observed)
    with pytest.raises(InputTypeError, match="sensors must be a flexctl.sim.sensors.Sensors"):
        simulate(model, 1.0, controller=observed, sensors={"gyro_noise": 1e-4})
    with pytest.raises(InputValueError, match="sensors.sample_time 0.02 s must be"):
        simulate(model, 1.0, controller=observed, sensors=Sensors(sample_time=0.02))


def test_a_motor_scene_without_sensors_turns_torque_laws_into_voltages():
    scene = dataclasses.replace(load_scene("flexible-link"), sensors=None)
    result, built, metrics = run_slew(scene, from_spec)
    assert result.ok and metrics.settling_time < scene.simulation.t_final
    volts = result.actuator_signals["motor_voltage"]
    assert np.max(np.abs(volts)) <= scene.actuator.voltage_limit
    # the hub torque is the motor's line at the applied voltage and the hub rate
    motor = scene.actuator
    expected = motor.torque_gain * volts - motor.damping * result.theta_dot
    assert np.allclose(result.torque, expected, rtol=1e-9, atol=1e-12)


def test_a_reference_the_wheel_cannot_follow_is_refused_naming_the_limit():
    scene = load_scene("wheel-slew", {"maneuver.angle_deg": 170.0, "maneuver.duration": 60.0,
                                      "actuator.speed_limit": 150.0})
    with pytest.raises(SceneError, match="actuator.speed_limit 150 rad/s"):
        from_spec(scene)
    link = load_scene("flexible-link", {"maneuver.duration": 0.1})
    with pytest.raises(SceneError, match="actuator.voltage_limit 10 V"):
        from_spec(link)


@pytest.mark.parametrize("table", [
    {"kind": "pd", "bandwidth": 0.3}, {"kind": "lqr"}, {"kind": "lqr", "sample_time": 0.1},
    {"kind": "lqg"}, {"kind": "zv"},
], ids=["pd", "lqr", "lqr-sampled", "lqg", "zv"])
def test_laws_read_the_plant_through_its_actuator_states(table):
    """A frictionless wheel far from its limits, with a short lag: every law slews the
    actuated plant as it slews the ideal one (it reads the hub and the modes by the plant's
    layout, whose wheel states come last). With friction an open-loop slew drifts: the wheel
    drags the hub."""
    frictionless = {"actuator.coulomb_friction": 0.0, "actuator.viscous_friction": 0.0}
    scene = dataclasses.replace(load_scene("wheel-slew", {**SHORT_WHEEL, **frictionless,
                                                          "controller": table}), sensors=None)
    ideal = dataclasses.replace(scene, actuator=None)
    finals = []
    for case in (ideal, scene):
        result, _, metrics = run_slew(case, from_spec)
        assert result.ok
        finals.append(result.theta[-1])
    assert abs(finals[1] - finals[0]) <= 2e-3 * scene.maneuver.angle


_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10, 10 ** 6),
                    st.text(max_size=3), st.booleans(), st.none())


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["reaction_wheel", "dc_motor"]), data=st.data())
def test_any_actuator_table_gives_a_clear_error_or_a_finite_plant(kind, data):
    base = dict(WHEEL_TABLE if kind == "reaction_wheel" else MOTOR_TABLE)
    key = data.draw(st.sampled_from(sorted(k for k in base if k != "kind")))
    base[key] = data.draw(_VALUES)
    try:
        scene = parse_scene(_one_beam_table(actuator=base))
    except SceneError as exc:
        assert f"actuator.{key}" in str(exc) or "actuator" in str(exc)
        return
    model = scene.build_model()
    for command in (0.0, 1e3, -1e3):
        assert np.all(np.isfinite(model.dynamics(0.0, model.rest_state(), command)))


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_sensors_table_gives_a_clear_error_or_honest_readings(data):
    table = dict(SENSOR_TABLE)
    key = data.draw(st.sampled_from(sorted(table) + ["tip_acceleration_noise",
                                                     "sample_time", "gyro_bias_time"]))
    table[key] = data.draw(_VALUES)
    slew = copy.deepcopy(load_scene("slew-90").data)
    try:
        scene = parse_scene({**slew, "sensors": table})
    except SceneError as exc:
        assert f"sensors.{key}" in str(exc)
        return
    model = build_model(load_scene("hub-beam-mass").system, 2)
    session = scene.sensors.start(model, 0.01)
    x = model.layout.zeros()
    xdot = model.dynamics(0.0, x, 0.0)
    readings = [session.read(x, xdot) for _ in range(3)]
    assert all(np.all(np.isfinite(r)) for r in readings)


def test_lqg_on_a_motor_integrates_the_torque_the_motor_gives():
    """A 1 rad error on the flexible link: the voltage saturates. LQG that keeps its torque
    on the motor's voltage line at its estimated rate (anti-windup) estimates the hub angle
    and rate far better than one that integrates the torque it asked for."""
    from controllers import MotorVoltage, NoiseLevels, design_lqg

    scene = load_scene("flexible-link")
    plant = scene.build_model()
    design = build_model(scene.design_system, 2)
    weights = LQRWeights(hub_angle=0.01, hub_rate=1.0, tip_deflection=0.002, torque=0.2)
    base = design_lqg(design, weights, NoiseLevels(angle=1e-4, root_moment=1e-3, torque=0.1),
                      plant=plant)
    x0 = plant.rest_state()
    x0[plant.layout.theta] = -1.0
    rows = plant.layout.projection(base.layout)      # the estimate: the filter's modes
    errors = {}
    for motor in (None, scene.actuator):
        law = dataclasses.replace(base, motor=motor, initial_estimate=x0[rows])
        result = simulate(plant, 1.5, controller=MotorVoltage(law, plant), x0=x0)
        volts = result.actuator_signals["motor_voltage"]
        assert result.ok and np.max(np.abs(volts)) == scene.actuator.voltage_limit
        error = np.abs(result.controller_states - result.states[rows])
        errors[motor is not None] = (np.max(error[base.layout.theta]),
                                     np.max(error[base.layout.theta_dot]))
    assert errors[True][0] <= 0.2 * errors[False][0]
    assert errors[True][1] <= 0.2 * errors[False][1]


def test_the_response_plot_shows_the_actuator_demand_against_its_limit():
    from flexctl.app.plotting import plot_response

    model = build_model(load_scene("hub-beam-mass").system, 2,
                        actuator=ReactionWheel(**{k: v for k, v in WHEEL_TABLE.items()
                                                  if k != "kind"}))
    result = simulate(model, 2.0, torque=lambda t: 0.1)
    fig = plot_response(result)
    rows = [ax for ax in fig.axes if ax.get_ylabel().startswith("wheel speed")]
    assert len(rows) == 1
    lines = rows[0].get_lines()
    assert np.allclose(lines[0].get_ydata(), result.actuator_signals["wheel_speed"])
    assert {-600.0, 600.0} <= {float(line.get_ydata()[0]) for line in lines[1:]}


def test_a_controller_rate_other_than_the_sensors_is_refused():
    scene = load_scene("wheel-slew", {**SHORT_WHEEL, "controller.sample_time": 0.05})
    with pytest.raises(SceneError, match="controller.sample_time 0.05 s and sensors.sample_time"):
        from_spec(scene)
