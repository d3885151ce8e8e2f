"""Physics of the actuators in the plant (flexctl.model.actuators, flexctl.model.actuated):
momentum exchanged between wheel and structure, the wheel's torque and speed limits, the DC
motor's no-load speed and stall torque, and the plant's views agreeing with each other."""

import math

import numpy as np
import pytest

from flexctl import (Appendage, Beam, DCMotor, Hub, HubBeam, PointMass, ReactionWheel,
                     SineTorque, Structure, build_model, simulate)
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.digital import ZeroOrderHold

PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
             youngs_modulus=6.9e10)
TIP = (PointMass(mass=0.085, position=1.62),)
#: Relative drift of a conserved quantity over a run at rtol 1e-10.
CONSERVATION = 1e-7


def wheel(**changes):
    settings = dict(inertia=0.02, torque_limit=0.2, speed_limit=600.0, time_constant=0.05)
    settings.update(changes)
    return ReactionWheel(**settings)


def motor(**changes):
    settings = dict(resistance=2.6, torque_constant=7.68e-3, back_emf_constant=7.68e-3,
                    gear_ratio=70.0, voltage_limit=10.0, gear_efficiency=0.9,
                    rotor_inertia=3.9e-7)
    settings.update(changes)
    return DCMotor(**settings)


def spacecraft(support="free"):
    return Structure(hub=Hub(inertia=1.16, radius=0.06, mass=3.0, support=support),
                     appendages=(Appendage(name="wing_a", beam=PANEL, masses=TIP),
                                 Appendage(name="wing_b", beam=PANEL, masses=TIP,
                                           angle=math.radians(150.0))))


def one_beam():
    return HubBeam(hub=Hub(inertia=1.16, radius=0.06), beam=PANEL, masses=TIP)


@pytest.mark.parametrize("support", ["pinned", "free"])
@pytest.mark.parametrize("variant", ["consistent", "exact"])
def test_wheel_and_structure_conserve_angular_momentum(support, variant):
    """Friction off, no external torque: whatever the wheel's motor does (here a sine command
    that saturates), hub, beams and wheel keep their angular momentum, and the consistent
    and exact variants their energy less the motor's work."""
    model = build_model(spacecraft(support), 2, variant, actuator=wheel())
    x0 = model.rest_state()
    x0[model.layout.theta_dot], x0[model.layout.block("actuator")][0] = 0.05, -30.0
    command = SineTorque(peak_torque=0.4, duration=3.0)
    result = simulate(model, 4.0, torque=command, x0=x0, rtol=1e-10)
    assert result.ok, result.message
    h = model.angular_momentum(result.states)
    assert np.ptp(h) <= CONSERVATION * np.max(np.abs(h))
    # the wheel did trade momentum: the structure's own changed by much more than the drift
    h_structure = model.mechanical.angular_momentum(model.mechanical_states(result.states))
    assert np.ptp(h_structure) > 1e4 * np.ptp(h)
    if support == "free":
        p = model.linear_momentum(result.states)
        assert np.max(np.abs(p - p[:, :1])) <= 1e-9


def test_wheel_friction_is_internal_and_dissipates():
    """With friction on and no command, the wheel's spin decays into the structure: momentum
    kept, energy lost."""
    model = build_model(spacecraft("free"), 2, "consistent",
                        actuator=wheel(viscous_friction=1e-4, coulomb_friction=2e-3))
    x0 = model.rest_state()
    x0[model.layout.block("actuator")][0] = 200.0
    result = simulate(model, 20.0, x0=x0, rtol=1e-10)
    h, e = model.angular_momentum(result.states), model.energy(result.states)
    assert np.ptp(h) <= CONSERVATION * np.max(np.abs(h))
    assert np.all(np.diff(e) <= 1e-9 * e[0]) and e[-1] < 0.9 * e[0]


def test_wheel_respects_its_torque_and_speed_limits():
    """A hub-angle loop asking for ten times the torque limit: the motor torque never exceeds
    the limit, and the wheel's speed stops at its limit (the hub keeps the momentum it got)."""
    act = wheel(speed_limit=40.0, viscous_friction=1e-5, coulomb_friction=1e-3)
    model = build_model(spacecraft("pinned"), 2, "first_order", actuator=act)
    law = ZeroOrderHold(lambda t, x: 2.0, sample_time=0.05)   # always 2 N m: 10 x the limit
    result = simulate(model, 30.0, controller=law, rtol=1e-8)
    signals = result.actuator_signals
    assert np.max(np.abs(signals["wheel_torque"])) <= act.torque_limit * (1 + 1e-9)
    assert np.max(np.abs(result.torque)) <= act.torque_limit + act.coulomb_friction + 1e-3
    speed = signals["wheel_speed"]
    assert np.max(np.abs(speed)) <= act.speed_limit * (1 + 1e-3)
    assert np.max(np.abs(speed)) >= act.speed_limit * (1 - 2 * 0.01)   # it got there
    # once at the limit no motor torque is left in that direction
    at_limit = np.abs(speed) >= act.speed_limit * (1 - 1e-4)
    assert at_limit.any() and np.max(np.abs(signals["wheel_torque"][at_limit])) <= 1e-2 * \
        act.torque_limit


def test_wheel_lag_is_first_order():
    """A step command: the wheel torque follows 1 - exp(-t / tau)."""
    act = wheel(time_constant=0.1)
    model = build_model(one_beam(), 2, "first_order", actuator=act)
    result = simulate(model, 0.5, torque=lambda t: 0.1, rtol=1e-10, method="DOP853")
    expected = 0.1 * (1.0 - np.exp(-result.t / act.time_constant))
    assert np.max(np.abs(result.actuator_signals["wheel_torque"] - expected)) <= 1e-7


def test_dc_motor_no_load_speed_and_stall_torque():
    """b = 0 and a frictionless hub: a constant voltage V drives the hub to V / (k_b N)
    (V / k_b at the motor), and at standstill the hub torque is eta N k_t V / R (the motor's
    k_t V / R through the gear)."""
    act = motor(viscous_friction=0.0)
    model = build_model(one_beam(), 2, "first_order", actuator=act)
    volts = 6.0
    stall = model.applied_torque(model.rest_state(), volts)
    assert stall == pytest.approx(act.efficiency * act.gear_ratio * act.torque_constant
                                  * volts / act.resistance, rel=1e-12)
    time_constant = model.rigid_inertia / act.damping
    result = simulate(model, 12.0 * time_constant, torque=lambda t: volts, rtol=1e-10)
    # the beam still rings about the steady spin (its modes are lightly damped by the
    # back-EMF): average over two periods of the first one
    period = 2.0 * np.pi / model.natural_frequencies(0.0, hub="free")[0]
    last = result.t >= result.t[-1] - 2.0 * period
    assert np.mean(result.theta_dot[last]) * act.gear_ratio == pytest.approx(
        volts / act.back_emf_constant, rel=1e-5)
    current = result.actuator_signals["motor_current"]
    assert current[0] == pytest.approx(volts / act.resistance, rel=1e-12)
    assert abs(np.mean(current[last])) <= 1e-5 * volts / act.resistance


def test_dc_motor_voltage_is_clipped_and_the_rotor_inertia_reflected():
    act = motor(viscous_friction=0.015)
    model = build_model(one_beam(), 2, "first_order", actuator=act)
    assert model.system.hub.inertia == pytest.approx(1.16 + 70.0 ** 2 * 3.9e-7)
    signals = model.actuator_signals(model.rest_state(), 25.0)
    assert signals["motor_voltage"] == pytest.approx(act.voltage_limit)
    # the rigid pole of the voltage-driven plant: back-EMF and friction over the inertia
    poles = np.linalg.eigvals(model.linear_matrices()[0])
    rigid = poles[np.argmin(np.abs(poles.imag) + np.abs(poles.real + act.damping
                                                         / model.rigid_inertia))]
    assert rigid.real == pytest.approx(-act.damping / model.rigid_inertia, rel=0.05)


@pytest.mark.parametrize("make", [wheel, motor], ids=["wheel", "motor"])
def test_plant_views_agree(make):
    """dynamics, the CasADi function, the python-control system and the linearisation are
    one plant: the linear plant is the Jacobian of the nonlinear one at rest."""
    model = build_model(one_beam(), 2, "first_order", actuator=make())
    rng = np.random.default_rng(3)
    x = model.rest_state() + 1e-3 * rng.normal(size=model.n_states)
    u = 0.05
    xdot = model.dynamics(0.0, x, u)
    assert np.allclose(np.array(model.casadi()(x, u)).ravel(), xdot, rtol=1e-12, atol=1e-12)
    system = model.nonlinear()
    assert np.allclose(system._rhs(0.0, x, [u]), xdot, rtol=1e-12, atol=1e-12)
    a, b = model.linear_matrices()
    x0, step = model.rest_state(), 1e-6
    numeric = np.column_stack([(model.dynamics(0.0, x0 + step * e, 0.0)
                                - model.dynamics(0.0, x0 - step * e, 0.0)) / (2 * step)
                               for e in np.eye(model.n_states)])
    assert np.allclose(a, numeric, rtol=1e-5, atol=1e-6 * np.max(np.abs(a)))
    plant = model.linearize()
    assert list(plant.input_labels) == [make().input_name]
    assert plant.nstates == model.n_states and np.allclose(plant.B, b)


def test_results_without_an_actuator_have_no_command():
    model = build_model(one_beam(), 2)
    result = simulate(model, 1.0, torque=SineTorque(peak_torque=1.0, duration=1.0))
    assert result.command is None and result.actuator_signals == {}


@pytest.mark.parametrize("changes, match", [
    (dict(inertia=0.0), "actuator.inertia"),
    (dict(torque_limit=-1.0), "actuator.torque_limit"),
    (dict(speed_limit=float("nan")), "actuator.speed_limit"),
    (dict(time_constant=0.0), "actuator.time_constant"),
    (dict(coulomb_friction=0.5), "actuator.coulomb_friction must be below"),
    (dict(viscous_friction=-1e-3), "actuator.viscous_friction"),
    (dict(speed_limit=1e9), "actuator.speed_limit must be finite and > 0 and <= 100000"),
    (dict(time_constant=1e-9), "actuator.time_constant must be finite and >= 1e-06"),
])
def test_bad_wheels_are_refused(changes, match):
    with pytest.raises(InputValueError, match=match):
        wheel(**changes)


@pytest.mark.parametrize("changes, match", [
    (dict(resistance=0.0), "actuator.resistance"),
    (dict(gear_efficiency=1.5), "actuator.gear_efficiency"),
    (dict(voltage_limit=float("inf")), "actuator.voltage_limit"),
    (dict(gear_ratio=1e12), "actuator.gear_ratio must be finite and > 0 and <= 1e"),
    (dict(torque_constant=1e-12), "actuator.torque_constant must be within"),
])
def test_bad_motors_are_refused(changes, match):
    with pytest.raises(InputValueError, match=match):
        motor(**changes)


def test_motor_on_a_free_hub_and_wrong_types_are_refused():
    with pytest.raises(InputValueError, match="dc_motor .* needs a pinned hub"):
        build_model(spacecraft("free"), 2, actuator=motor())
    with pytest.raises(InputTypeError, match="actuator must be a ReactionWheel"):
        build_model(one_beam(), 2, actuator="wheel")
    with pytest.raises(InputTypeError, match="actuator.inertia must be a real number"):
        wheel(inertia="big")
