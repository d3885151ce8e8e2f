"""A cluster of reaction wheels on a hub that turns about any axis: conservation, the
distribution law, each motor's limits, friction and lag against their closed forms."""

import math

import numpy as np
import pytest
from spatial_craft import INERTIA, WING

from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.spatial_structure import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.wheel_cluster import SPEED_LIMIT_BAND, Wheel, WheelCluster
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial

#: A hub so heavy that it hardly turns: the wheels' own equations in closed form.
HEAVY = 1e7


def craft(inertia=INERTIA, support="pinned"):
    hub = SpatialHub(inertia=inertia, radius=0.06, mass=2.0 if support == "free" else 0.0,
                     support=support)
    return SpatialStructure(hub=hub, appendages=(SpatialAppendage(**WING),))


def hold(times, values):
    return VectorTorque(times, values, interpolation="hold")


def axial_momentum(result):
    """``h_k = J_k (g_k . w + Omega_k)`` of every wheel, N m s, shape (n, P)."""
    cluster = result.equations.cluster
    return cluster.inertias[:, None] * (cluster.axes.T @ result.angular_velocity
                                        + result.wheel_speeds)


def test_a_pyramid_has_its_angle_and_an_isotropic_capacity_at_the_magic_angle():
    cluster = WheelCluster.pyramid(angle=math.degrees(math.acos(1 / math.sqrt(3))),
                                   pyramid_axis=(1, 1, 0), inertia=0.01, torque_limit=0.2,
                                   speed_limit=300.0)
    axis = np.array([1, 1, 0]) / math.sqrt(2)
    np.testing.assert_allclose(cluster.axes.T @ axis, 1 / math.sqrt(3), rtol=1e-12)
    np.testing.assert_allclose(cluster.axes @ cluster.axes.T, 4 / 3 * np.eye(3), atol=1e-12)
    null = cluster.axes @ np.linalg.svd(cluster.axes)[2][-1]
    np.testing.assert_allclose(null, 0.0, atol=1e-12)


def test_momentum_is_conserved_whatever_the_wheels_do():
    """Motors, Coulomb, viscous and Stribeck friction, lags, saturation and the speed limit
    are internal: the craft's angular momentum (structure plus rotors) stays what it was,
    on a pinned and on a free hub, while the hub turns and the wheels spin."""
    wheels = tuple(Wheel(axis=axis, inertia=0.01, torque_limit=0.05, speed_limit=40.0,
                         time_constant=lag, coulomb_friction=2e-3, viscous_friction=2e-5,
                         static_friction=3e-3 if lag else 0.0, stribeck_speed=0.5 if lag else 0)
                   for axis, lag in (((1, 0, 0), 0.0), ((0, 1, 0), 0.05), ((0, 0, 1), 0.0),
                                     ((1, 1, 1), 0.1)))
    cluster = WheelCluster(wheels=wheels)
    command = hold([0.0, 0.4, 0.8, 1.2], [[0.2, -0.1, 0.15], [-0.2, 0.1, -0.15],
                                          [0.05, 0.05, 0.05], [0.0, 0.0, 0.0]])
    for support in ("pinned", "free"):
        result = simulate_spatial(craft(support=support), 1.5, command, n_modes=1,
                                  wheels=cluster, wheel_speeds=[5.0, -3.0, 0.0, 1.0],
                                  angular_velocity=(0.1, -0.05, 0.2), output_step=0.01,
                                  check_accuracy=False, rtol=1e-10)
        assert result.ok, result.message
        angular, linear = result.momentum()
        drift = np.abs(angular - angular[:, :1]).max() / np.linalg.norm(angular[:, 0])
        turned = np.abs(result.angular_velocity - result.angular_velocity[:, :1]).max()
        print(support, f"momentum drift {drift:.1e}, hub rate change {turned:.2f} rad/s")
        assert drift < 1e-8 and turned > 0.01
        if support == "free":
            assert np.abs(linear - linear[:, :1]).max() < 1e-12


def test_the_pseudo_inverse_gives_the_hub_the_commanded_torque_and_the_rotors_its_impulse():
    """No friction, no lag, within the limits: the motor torques ``u`` satisfy
    ``-G u = command`` and each rotor's axial momentum grows by ``u t`` exactly (the
    torque is held), here on the pyramid (a redundant cluster, the minimum-norm split)."""
    cluster = WheelCluster.pyramid(angle=54.7356, inertia=0.01, torque_limit=1.0,
                                   speed_limit=1000.0)
    command = hold([0.0, 0.5, 1.0], [[0.1, -0.2, 0.05], [-0.05, 0.1, 0.2], [0.0, 0.0, 0.0]])
    result = simulate_spatial(craft(), 1.0, command, n_modes=1, wheels=cluster,
                              output_step=0.05, check_accuracy=False, rtol=1e-10)
    assert result.ok, result.message
    torques = result.wheel_torques
    np.testing.assert_allclose(-cluster.axes @ torques, result.torque, atol=1e-12)
    np.testing.assert_allclose(torques, np.linalg.pinv(-cluster.axes) @ result.torque,
                               atol=1e-12)
    h = axial_momentum(result)
    expected = np.cumsum(np.hstack([np.zeros((4, 1)), torques[:, :-1] * 0.05]), axis=1)
    np.testing.assert_allclose(h, expected, atol=1e-9)


def test_the_speed_limit_stops_the_spin_up_at_the_rated_speed():
    """A saturating command against Coulomb and viscous friction: the wheel reaches its
    rated speed and stays within the fade band below it (less the friction's share)."""
    wheel = Wheel(axis=(0, 0, 1), inertia=0.01, torque_limit=0.2, speed_limit=20.0,
                  coulomb_friction=2e-3, viscous_friction=2e-5)
    result = simulate_spatial(craft(np.eye(3) * HEAVY), 2.0, [0.0, 0.0, -1.0], n_modes=1,
                              wheels=WheelCluster(wheels=(wheel,)), output_step=0.01,
                              check_accuracy=False)
    assert result.ok, result.message
    speed = result.wheel_speeds[0]
    assert np.max(speed) <= 20.0
    assert speed[-1] > 20.0 * (1 - SPEED_LIMIT_BAND)
    assert np.ptp(speed[-50:]) < 20.0 * SPEED_LIMIT_BAND
    # before the limit, the torque limit less the friction spins it up
    early = result.t <= 0.5
    rate = (0.2 - 2e-3) / 0.01
    np.testing.assert_allclose(speed[early][result.t[early] > 0.1],
                               rate * result.t[early][result.t[early] > 0.1], rtol=1e-3)


def test_friction_spins_a_free_wheel_down_as_coulomb_and_viscous_friction_say():
    """No command, a heavy hub: ``J Omega_t = -c - b Omega`` until the wheel stops, so
    ``Omega(t) = (Omega_0 + c / b) exp(-b t / J) - c / b``; the Stribeck law, far above
    its speed, is the same."""
    j, c, b, omega0 = 0.01, 2e-3, 2e-5, 30.0
    for extra in ({}, {"static_friction": 3e-3, "stribeck_speed": 0.5}):
        wheel = Wheel(axis=(1, 0, 0), inertia=j, torque_limit=0.2, speed_limit=100.0,
                      coulomb_friction=c, viscous_friction=b, **extra)
        result = simulate_spatial(craft(np.eye(3) * HEAVY), 1.0, None, n_modes=1,
                                  wheels=WheelCluster(wheels=(wheel,)), wheel_speeds=[omega0],
                                  output_step=0.05, check_accuracy=False, rtol=1e-10)
        assert result.ok, result.message
        expected = (omega0 + c / b) * np.exp(-b * result.t / j) - c / b
        np.testing.assert_allclose(result.wheel_speeds[0], expected, rtol=1e-6)


def test_a_lagged_motor_follows_its_command_as_a_first_order_lag():
    """A step command through a lag ``tau``: ``u = u_c (1 - exp(-t / tau))``; a dead band
    above a command leaves the wheel still; a power limit caps ``|u Omega|``."""
    tau = 0.05
    lagged = Wheel(axis=(0, 1, 0), inertia=0.01, torque_limit=0.2, speed_limit=500.0,
                   time_constant=tau)
    result = simulate_spatial(craft(np.eye(3) * HEAVY), 0.3, [0.0, -0.1, 0.0], n_modes=1,
                              wheels=WheelCluster(wheels=(lagged,)), output_step=0.01,
                              check_accuracy=False, rtol=1e-10)
    assert result.ok, result.message
    np.testing.assert_allclose(result.wheel_torques[0], 0.1 * (1 - np.exp(-result.t / tau)),
                               atol=1e-8)
    dead = Wheel(axis=(0, 1, 0), inertia=0.01, torque_limit=0.2, speed_limit=500.0,
                 dead_band=0.15)
    limited = Wheel(axis=(1, 0, 0), inertia=0.01, torque_limit=0.2, speed_limit=500.0,
                    power_limit=0.5)
    result = simulate_spatial(craft(np.eye(3) * HEAVY), 0.5, [-0.2, -0.1, 0.0], n_modes=1,
                              wheels=WheelCluster(wheels=(dead, limited)), output_step=0.01,
                              check_accuracy=False, rtol=1e-10)
    assert result.ok, result.message
    assert np.all(result.wheel_speeds[0] == 0.0) and np.all(result.wheel_torques[0] == 0.0)
    power = np.abs(result.wheel_torques[1] * result.wheel_speeds[1])
    assert power.max() <= 0.5 * (1 + 1e-9) and power.max() > 0.49
    np.testing.assert_allclose(result.wheel_power, power, rtol=1e-12)


def test_null_motion_moves_the_speeds_to_the_bias_without_turning_the_hub():
    """From rest, no command: the null-space torques (saturated at first) spin the four
    wheels up to the bias speed, alternately signed, and the hub feels none of it."""
    cluster = WheelCluster.pyramid(angle=54.7356, inertia=0.01, torque_limit=0.2,
                                   speed_limit=300.0, distribution="null_motion",
                                   null_gain=2.0, bias_speed=50.0)
    result = simulate_spatial(craft(), 6.0, None, n_modes=1, wheels=cluster,
                              output_step=0.05, check_accuracy=False, rtol=1e-10)
    assert result.ok, result.message
    np.testing.assert_allclose(np.abs(result.wheel_speeds[:, -1]), 50.0, rtol=1e-3)
    assert np.abs(result.angular_velocity).max() < 1e-9


def test_bad_wheels_are_refused_by_name():
    good = dict(axis=(0, 0, 1), inertia=0.01, torque_limit=0.2, speed_limit=300.0)
    for change, words in (({"axis": (0, 0, 0)}, "wheel.axis"),
                          ({"inertia": -1.0}, "wheel.inertia"),
                          ({"time_constant": 1e-9}, "wheel.time_constant"),
                          ({"coulomb_friction": 0.3}, "wheel.coulomb_friction"),
                          ({"static_friction": 1e-3, "coulomb_friction": 2e-3},
                           "wheel.static_friction"),
                          ({"static_friction": 3e-3}, "wheel.stribeck_speed"),
                          ({"speed_limit": float("nan")}, "wheel.speed_limit"),
                          ({"power_limit": 0.0}, "wheel.power_limit")):
        with pytest.raises(InputValueError, match=words.replace(".", r"\.")):
            Wheel(**{**good, **change})
    with pytest.raises(InputTypeError, match="wheels.wheels"):
        WheelCluster(wheels=Wheel(**good))
    shared = {k: v for k, v in good.items() if k != "axis"}
    with pytest.raises(InputValueError, match="null space"):
        WheelCluster(wheels=WheelCluster.orthogonal(**shared).wheels,
                     distribution="null_motion")
    with pytest.raises(InputTypeError, match="arrangement"):
        WheelCluster.orthogonal(**good)
    with pytest.raises(InputValueError, match="wheel_speeds"):
        simulate_spatial(craft(), 1.0, None, n_modes=1, wheels=WheelCluster(
            wheels=(Wheel(**good),)), wheel_speeds=[400.0])
    with pytest.raises(InputTypeError, match="WheelCluster"):
        simulate_spatial(craft(), 1.0, None, n_modes=1, wheels=Wheel(**good))


def test_directions_of_any_length_keep_their_direction():
    """An axis of 1e308 entries (whose norm overflows) or of 1e-300 (whose norm underflows)
    is the same direction, for a wheel, an appendage and a pyramid."""
    half = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    for scale in (1e308, 1e-300):
        wheel = Wheel(axis=scale * np.array([1.0, 1.0, 0.0]), inertia=0.01, torque_limit=0.2,
                      speed_limit=300.0)
        np.testing.assert_allclose(wheel.axis, half, rtol=1e-15)
        wing = SpatialAppendage(**{**WING, "direction": (0.0, scale, 0.0),
                                   "normal": (0.0, 0.0, scale)})
        np.testing.assert_array_equal(wing.direction, [0.0, 1.0, 0.0])
        cluster = WheelCluster.pyramid(angle=45.0, pyramid_axis=(0.0, 0.0, scale),
                                       inertia=0.01, torque_limit=0.2, speed_limit=300.0)
        np.testing.assert_allclose(cluster.axes[2], math.sqrt(0.5), rtol=1e-15)


def test_an_imbalanced_wheel_shakes_the_hub_at_its_spin_rate():
    """A wheel spinning at 20 rad/s about z with a dynamic imbalance ``U_d`` (and a static
    one off the centre) on a heavy hub: the hub's rate across the spin axis oscillates at the
    wheel's speed with the amplitude ``|(U_d, |r| U_s)| Omega^2 / (J Omega)`` of a rigid hub
    of inertia ``J`` (the structure's, about that axis), its spin angle a state. On a free
    hub the jitter is refused."""
    u_d, u_s, lever, omega = 1e-6, 2e-6, 0.3, 20.0
    wheel = Wheel(axis=(0, 0, 1), inertia=0.01, torque_limit=0.2, speed_limit=100.0,
                  dynamic_imbalance=u_d, static_imbalance=u_s, position=(0.0, 0.0, lever))
    structure = craft(np.eye(3) * 1e3)
    result = simulate_spatial(structure, 1.0, None, n_modes=1,
                              wheels=WheelCluster(wheels=(wheel,)), wheel_speeds=[omega],
                              output_step=0.002, check_accuracy=False, rtol=1e-10)
    assert result.ok, result.message
    assert result.layout.state_names[-1] == "wheel1.angle"
    np.testing.assert_allclose(result.states[-1], omega * result.t, rtol=1e-6)
    inertia = structure.rigid_inertia
    across = result.angular_velocity[:2]
    amplitude = 0.5 * np.ptp(across, axis=1)
    # the static imbalance's torque r x F is a quarter turn from the dynamic one's
    expected = np.hypot(u_d, lever * u_s) * omega / np.diag(inertia)[:2]
    print("amplitude", amplitude, "expected", expected)
    np.testing.assert_allclose(amplitude, expected, rtol=0.05)
    with pytest.raises(InputValueError, match="pinned hub"):
        simulate_spatial(craft(support="free"), 1.0, None, n_modes=1,
                         wheels=WheelCluster(wheels=(wheel,)))
