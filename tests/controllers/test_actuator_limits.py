"""The actuator's limits in trajectory optimisation and NMPC (controllers/actuator_limits.py).

Contracts checked: the CasADi wheel speed agrees with the model's own angular momentum for
every variant; a slew planned with a reaction wheel keeps the wheel speed (computed from the
plan's states by momentum conservation) within the margin-reduced speed limit, at that limit
somewhere, while the same slew planned for an ideal torque exceeds it; the wheel-driven plant,
commanded with the plan, keeps its wheel below the band where its torque fades and ends at the
target; a slew planned with a DC motor needs no more than its voltage limit (the motor's
torque-speed line), at the limit somewhere, and the motor-driven plant follows it to the
target, while the plan for an ideal torque needs more and, the voltage clipped, misses; slews
no actuator can give are refused before the solver runs, naming the limit; NMPC keeps the
wheel speed and the voltage in its plans and in closed loop.
"""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import flexctl
from controllers import NMPC, SlewProblem, solve_slew
from controllers.design.actuator_limits import (SPEED_MARGIN, RigidLimits, minimum_duration,
                                                rigid_slew_time, wheel_speed_function)
from controllers.slew.trajopt import rigid_minimum_time
from flexctl import DCMotor, ReactionWheel
from flexctl.model.actuators import SPEED_LIMIT_BAND
from flexctl.model.errors import InputTypeError, InputValueError

SYSTEM = flexctl.load_scene("hub-beam-mass").system
ANGLE = math.pi / 2            # rad
TORQUE_BOUND = 6.0             # N m
DESIGN_MODES = 2
N_INTERVALS = 30
WHEEL_DURATION = 3.0           # s: an ideal-torque plan peaks at about 224 rad/s of a wheel...
WHEEL = ReactionWheel(inertia=0.01, torque_limit=10.0, speed_limit=200.0,  # ...this one's
                      time_constant=0.002)
MOTOR_DURATION = 2.0           # s: an ideal-torque plan needs about 4.5 V of...
MOTOR = DCMotor(resistance=1.0, torque_constant=0.05, back_emf_constant=0.05,  # ...this one
                gear_ratio=50.0, voltage_limit=4.0, rotor_inertia=1e-4)

BOUND_TOL = 1e-6               # relative excess over a bound that IPOPT may leave
ACTIVE_TOL = 1e-4              # relative distance below a bound that counts as reaching it
AGREEMENT_TOL = 1e-9           # CasADi against numpy momentum, relative to the speed scale
FOLLOW_TOL = 1e-3              # final angle error of a plan driven through its actuator, rel.
PREDICTION_TOL = 1e-4          # NMPC's RK4 prediction against the plant, relative
SIM_RTOL = 1e-8


def hub_rates(model, states):
    return np.asarray(states)[model.layout.theta_dot]


def wheel_speed(model, wheel, states):
    """Wheel speed relative to the hub, rad/s, by momentum conservation from rest:
    ``J_w (theta_dot + Omega) = -H_structure``."""
    return -model.angular_momentum(states) / wheel.inertia - hub_rates(model, states)


def hold_voltages(motor, torque, rates):
    """The voltage each hold needs at the hub rates at its start and end, V, shape (2, K):
    ``V = R i / 1 + k_b N rate`` with ``i`` the current that gives ``torque + b rate``."""
    current = lambda u, w: (u + motor.viscous_friction * w) / (  # noqa: E731
        motor.gear_efficiency * motor.gear_ratio * motor.torque_constant)
    volts = lambda u, w: (motor.resistance * current(u, w)  # noqa: E731
                          + motor.back_emf_constant * motor.gear_ratio * w)
    return np.stack((volts(torque, rates[:-1]), volts(torque, rates[1:])))


@pytest.fixture(scope="module")
def design():
    return flexctl.build_model(SYSTEM, DESIGN_MODES)


@pytest.fixture(scope="module")
def motor_plant():
    return flexctl.build_model(SYSTEM, DESIGN_MODES, actuator=MOTOR)


@pytest.fixture(scope="module")
def motor_design(motor_plant):
    """The structure with the rotor's reflected inertia: the motor plant's mechanical part."""
    return motor_plant.mechanical


def _problem(duration, actuator, **kwargs):
    return SlewProblem(angle=ANGLE, duration=duration, torque_bound=TORQUE_BOUND,
                       n_intervals=N_INTERVALS, actuator=actuator, **kwargs)


@pytest.fixture(scope="module")
def wheel_slews(design):
    return {name: solve_slew(design, _problem(WHEEL_DURATION, actuator))
            for name, actuator in (("wheel", WHEEL), ("ideal", None))}


@pytest.fixture(scope="module")
def motor_slews(motor_design):
    return {name: solve_slew(motor_design, _problem(MOTOR_DURATION, actuator))
            for name, actuator in (("motor", MOTOR), ("ideal", None))}


# ---------------------------------------------------------------------------- momentum
def _free_hub_model():
    free = dataclasses.replace(SYSTEM, hub=dataclasses.replace(SYSTEM.hub, support="free",
                                                               mass=3.0))
    return flexctl.build_model(free, DESIGN_MODES)


@pytest.mark.parametrize("build", [
    lambda: flexctl.build_model(SYSTEM, DESIGN_MODES, "first_order"),
    lambda: flexctl.build_model(SYSTEM, DESIGN_MODES, "zero_order"),
    lambda: flexctl.build_model(SYSTEM, DESIGN_MODES, "consistent"),
    lambda: flexctl.build_model(SYSTEM, DESIGN_MODES, "exact"),
    _free_hub_model,
], ids=["first_order", "zero_order", "consistent", "exact", "free_hub_structure"])
def test_casadi_wheel_speed_agrees_with_the_models_momentum(build):
    model = build()
    states = np.random.default_rng(1).normal(scale=0.2, size=(model.n_states, 7))
    casadi_speed = np.asarray(wheel_speed_function(model, WHEEL).map(7)(states)).ravel()
    expected = wheel_speed(model, WHEEL, states)
    assert np.max(np.abs(casadi_speed - expected)) \
        <= AGREEMENT_TOL * np.max(np.abs(expected))


# ---------------------------------------------------------------------------- reaction wheel
def test_wheel_speed_limit_binds_and_is_kept(design, wheel_slews):
    bound = (1 - SPEED_MARGIN) * WHEEL.speed_limit
    limited, ideal = wheel_slews["wheel"], wheel_slews["ideal"]
    assert limited.return_status == "Solve_Succeeded"
    speed = np.abs(wheel_speed(design, WHEEL, limited.states))
    assert speed.max() <= bound * (1 + BOUND_TOL)
    assert speed.max() >= bound * (1 - ACTIVE_TOL)                  # the constraint is active
    assert np.abs(wheel_speed(design, WHEEL, ideal.states)).max() > WHEEL.speed_limit
    assert limited.actuator_peak == pytest.approx(speed.max(), rel=1e-12)
    assert ideal.actuator_peak is None
    assert limited.cost > ideal.cost           # the limit costs effort: it binds
    np.testing.assert_allclose(limited.states[:, -1], design.rest_state(ANGLE), atol=1e-8)


def test_wheel_driven_plant_follows_the_plan_below_the_fade_band(wheel_slews):
    """The plant with the wheel (its motor lag, its torque fading near the speed limit),
    commanded with each plan: the wheel-aware one keeps the wheel out of the band where its
    torque fades and ends at the target; the ideal-torque one runs into it and misses."""
    plant = flexctl.build_model(SYSTEM, DESIGN_MODES, actuator=WHEEL)
    runs = {name: flexctl.simulate(plant, WHEEL_DURATION, torque=slew.torque_function(),
                                   rtol=SIM_RTOL)
            for name, slew in wheel_slews.items()}
    fade = (1 - SPEED_LIMIT_BAND) * WHEEL.speed_limit
    assert np.abs(runs["wheel"].actuator_signals["wheel_speed"]).max() < fade
    assert abs(runs["wheel"].theta[-1] - ANGLE) <= FOLLOW_TOL * ANGLE
    assert np.abs(runs["ideal"].actuator_signals["wheel_speed"]).max() > fade
    assert abs(runs["ideal"].theta[-1] - ANGLE) > 10 * FOLLOW_TOL * ANGLE


def test_wheel_torque_limit_bounds_the_hub_torque(design):
    wheel = dataclasses.replace(WHEEL, torque_limit=2.4, speed_limit=1000.0)   # 2.6 N m needed
    problem = _problem(WHEEL_DURATION, wheel)
    assert problem.hub_torque_bound == 2.4
    solution = solve_slew(design, problem)
    assert np.abs(solution.torque).max() <= 2.4 * (1 + BOUND_TOL)
    assert np.abs(solution.torque).max() >= 2.4 * (1 - ACTIVE_TOL)


def test_free_time_slew_keeps_the_wheel_and_the_lower_bound(design):
    solution = solve_slew(design, _problem(None, WHEEL))
    bound = (1 - SPEED_MARGIN) * WHEEL.speed_limit
    assert solution.duration >= minimum_duration(design, WHEEL, ANGLE, TORQUE_BOUND)
    speed = np.abs(wheel_speed(design, WHEEL, solution.states))
    assert bound * (1 - ACTIVE_TOL) <= speed.max() <= bound * (1 + BOUND_TOL)


# ---------------------------------------------------------------------------- DC motor
def test_motor_voltage_limit_binds_and_is_kept(motor_design, motor_slews):
    limited, ideal = motor_slews["motor"], motor_slews["ideal"]
    volts = np.abs(hold_voltages(MOTOR, limited.torque, hub_rates(motor_design,
                                                                   limited.states)))
    assert volts.max() <= MOTOR.voltage_limit * (1 + BOUND_TOL)
    assert volts.max() >= MOTOR.voltage_limit * (1 - ACTIVE_TOL)
    ideal_volts = hold_voltages(MOTOR, ideal.torque, hub_rates(motor_design, ideal.states))
    assert np.abs(ideal_volts).max() > MOTOR.voltage_limit
    assert limited.actuator_peak == pytest.approx(volts.max(), rel=1e-12)
    np.testing.assert_allclose(limited.states[:, -1], motor_design.rest_state(ANGLE),
                               atol=1e-8)


def test_motor_driven_plant_follows_the_plan(motor_plant, motor_slews):
    """Each plan driven through the motor plant, the voltage for its torque at the plant's
    hub rate: the voltage-aware plan needs no clipping and ends at the target; the
    ideal-torque plan is clipped at the voltage limit and misses."""
    rate = motor_plant.layout.theta_dot
    errors = {}
    for name, slew in motor_slews.items():
        hold = slew.torque_function()
        run = flexctl.simulate(motor_plant, MOTOR_DURATION, rtol=SIM_RTOL,
                               torque=lambda t, x, hold=hold: MOTOR.voltage_for(hold(t), x[rate]))
        assert run.ok
        errors[name] = abs(run.theta[-1] - ANGLE)
    assert errors["motor"] <= FOLLOW_TOL * ANGLE
    assert errors["ideal"] > 10 * FOLLOW_TOL * ANGLE


# ---------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("model_name, duration, actuator, match", [
    ("design", 2.0, WHEEL, r"actuator\.speed_limit 200 rad/s is too low .* momentum"),
    ("design", 2.0, dataclasses.replace(WHEEL, torque_limit=1.0, speed_limit=2000.0),
     r"actuator\.torque_limit 1 N m is too low"),
    ("motor_design", 0.9, MOTOR, r"actuator\.voltage_limit 4 V is too low .* no-load speed"),
    # stall torque 4 N m, no-load speed 3.2 rad/s: 1.9 s is above the 1.81 s of torque_bound
    ("motor_design", 1.9, dataclasses.replace(MOTOR, voltage_limit=1.6, back_emf_constant=0.01),
     r"actuator\.voltage_limit 1.6 V is too low .* stall torque"),
], ids=["wheel_momentum", "wheel_torque", "motor_no_load_speed", "motor_stall_torque"])
def test_slews_no_actuator_can_give_are_refused(request, model_name, duration, actuator,
                                                match):
    model = request.getfixturevalue(model_name)
    # InputValueError, not TrajectoryOptimizationError: refused before IPOPT ran
    with pytest.raises(InputValueError, match=match):
        solve_slew(model, _problem(duration, actuator))


def test_refusal_bounds_are_physical(design, motor_design):
    """The momentum refusal sits where the wheel's mean momentum reaches its capacity, the
    motor's where the mean hub rate reaches the no-load speed."""
    capacity = WHEEL.inertia * (1 - SPEED_MARGIN) * WHEEL.speed_limit
    shortest = (design.rigid_inertia + WHEEL.inertia) * ANGLE / capacity
    with pytest.raises(InputValueError, match="speed_limit"):
        solve_slew(design, _problem(0.999 * shortest, WHEEL))
    slow = dataclasses.replace(MOTOR, voltage_limit=1.0)        # no-load speed 0.4 rad/s
    with pytest.raises(InputValueError, match="no-load speed"):
        solve_slew(motor_design, _problem(0.999 * ANGLE / slow.no_load_speed, slow))
    with pytest.raises(InputValueError, match="max_duration"):
        solve_slew(design, _problem(None, WHEEL, max_duration=0.999 * shortest))


@pytest.mark.parametrize("make", [
    lambda: SlewProblem(angle=1.0, duration=2.0, torque_bound=1.0, actuator="wheel"),
    lambda: SlewProblem(angle=1.0, duration=2.0, torque_bound=1.0, actuator=WHEEL.inertia),
    lambda: NMPC(model=flexctl.build_model(SYSTEM, 1), torque_limit=1.0, actuator="motor"),
], ids=["slew_str", "slew_float", "nmpc_str"])
def test_bad_actuator_type_is_named(make):
    with pytest.raises(InputTypeError, match="actuator"):
        make()


def test_design_model_must_take_the_hub_torque(motor_plant, design):
    with pytest.raises(InputValueError, match="model.mechanical"):
        solve_slew(motor_plant, _problem(MOTOR_DURATION, MOTOR))
    with pytest.raises(InputValueError, match="pinned hub"):
        solve_slew(_free_hub_model(), _problem(MOTOR_DURATION, MOTOR))


@settings(max_examples=50, deadline=None)
@given(angle=st.floats(1e-3, 10.0), inertia=st.floats(1e-2, 1e2),
       accelerating=st.floats(0.1, 10.0), braking=st.floats(0.1, 10.0),
       rate=st.floats(1e-2, 10.0))
def test_rigid_slew_time_bounds(angle, inertia, accelerating, braking, rate):
    """A rate limit only slows a slew down, never below ``angle / rate``; accelerating and
    braking torques no stronger than ``u`` are no faster than bang-bang at ``u``, and equal to
    it when both are ``u``."""
    free = rigid_slew_time(angle, inertia, RigidLimits(accelerating, braking, math.inf))
    limited = rigid_slew_time(angle, inertia, RigidLimits(accelerating, braking, rate))
    assert limited >= free * (1 - 1e-12)
    assert limited >= angle / rate * (1 - 1e-12)
    strong = max(accelerating, braking)
    assert free >= rigid_minimum_time(angle, inertia, strong) * (1 - 1e-12)
    assert rigid_slew_time(angle, inertia, RigidLimits(strong, strong, math.inf)) \
        == pytest.approx(rigid_minimum_time(angle, inertia, strong), rel=1e-12)


# ---------------------------------------------------------------------------- NMPC
def _nmpc(model, actuator, **kwargs):
    return NMPC(model=model, target=ANGLE, torque_limit=TORQUE_BOUND, sample_time=0.05,
                horizon=20, actuator=actuator, **kwargs)


def _plan(mpc, model):
    """One converged solve from rest: predicted states (n, N+1) and torques (N,)."""
    session = mpc.start(model, model.rest_state())
    session.step(0.0, model.rest_state())
    n, w = model.n_states, session.w
    stages = w[:-n].reshape(mpc.horizon, n + 1)
    return np.column_stack((stages[:, :n].T, w[-n:])), stages[:, n]


def test_nmpc_plan_keeps_the_wheel(design):
    wheel = dataclasses.replace(WHEEL, speed_limit=100.0, torque_limit=5.0)
    mpc = _nmpc(design, wheel, mode="converged")
    assert mpc.hub_torque_limit == 5.0
    states, torque = _plan(mpc, design)
    bound = (1 - SPEED_MARGIN) * wheel.speed_limit
    speed = np.abs(wheel_speed(design, wheel, states))
    assert np.abs(torque).max() <= 5.0 * (1 + BOUND_TOL)
    assert bound * (1 - ACTIVE_TOL) <= speed.max() <= bound * (1 + BOUND_TOL)
    ideal_states, _ = _plan(_nmpc(design, None, mode="converged"), design)
    assert np.abs(wheel_speed(design, wheel, ideal_states)).max() > wheel.speed_limit


def test_nmpc_plan_keeps_the_motor_voltage(motor_design):
    slow = dataclasses.replace(MOTOR, voltage_limit=2.0)   # stall torque 5 N m < 6 N m
    states, torque = _plan(_nmpc(motor_design, slow, mode="converged"), motor_design)
    volts = np.abs(hold_voltages(slow, torque, hub_rates(motor_design, states)))
    assert slow.voltage_limit * (1 - ACTIVE_TOL) <= volts.max() \
        <= slow.voltage_limit * (1 + BOUND_TOL)


def test_nmpc_closed_loop_keeps_the_wheel(design):
    """Real-time iteration on the design model: the wheel speed of the closed loop (from its
    states) stays within the bound up to the RK4 prediction's error, and reaches it; without
    the wheel's limits the same loop exceeds its speed limit."""
    wheel = dataclasses.replace(WHEEL, speed_limit=150.0)
    bound = (1 - SPEED_MARGIN) * wheel.speed_limit
    peaks = {}
    for name, actuator in (("wheel", wheel), ("ideal", None)):
        result = flexctl.simulate(design, 4.0, controller=_nmpc(design, actuator))
        assert result.ok and result.controller_report["failed_steps"] == 0
        assert np.abs(result.torque).max() <= TORQUE_BOUND * (1 + BOUND_TOL)
        peaks[name] = np.abs(wheel_speed(design, wheel, result.states)).max()
    assert bound * (1 - ACTIVE_TOL) <= peaks["wheel"] <= bound * (1 + PREDICTION_TOL)
    assert peaks["ideal"] > wheel.speed_limit
