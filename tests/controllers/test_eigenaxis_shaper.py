"""Input shaping per mode of a slew about an axis (:func:`controllers.slew.eigenaxis.eigenaxis_shaper`):
the modes a torque about the axis moves, at the linear plant's frequencies and damping."""

import numpy as np
import pytest

from controllers.slew.eigenaxis import eigenaxis_modes, eigenaxis_shaper
from controllers.slew.shaping import convolve, zv_shaper, zvd_shaper
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.errors import InputError
from flexctl.model.spatial_plant import linearize_spatial


def _wing(name, direction, zeta=0.005):
    return SpatialAppendage(name=name, direction=direction, normal=(0, 0, 1), length=1.8,
                            density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
                            shear_modulus=2.6e10, torsion_constant=1.0e-9,
                            damping_ratio=zeta)


CRAFT = SpatialStructure(hub=SpatialHub(inertia=np.diag([1.3, 1.2, 1.4]), radius=0.06),
                         appendages=(_wing("a", (0, 1, 0)), _wing("b", (0, -1, 0))))


def _residual(shaper, frequency, zeta):
    """|sum_i A_i exp(-zeta w (t_n - t_i)) e^{i w_d t_i}|: what the impulse train leaves of
    a mode of ``frequency`` and ``zeta``."""
    wd = frequency * np.sqrt(1 - zeta ** 2)
    t_end = shaper.times[-1]
    return abs(sum(a * np.exp(-zeta * frequency * (t_end - t)) * np.exp(1j * wd * t)
                   for t, a in zip(shaper.times, shaper.amplitudes)))


def test_the_modes_are_poles_of_the_plant_that_the_axis_torque_moves():
    """Each mode is a pole of the linear plant (frequency and damping ratio), moved by the
    torque about the axis (the plant's response to it has that pole), lowest first."""
    axis = np.array([0.6, 0.0, 0.8])
    modes = eigenaxis_modes(CRAFT, axis, n_shaped=3, n_modes=2)
    plant = linearize_spatial(CRAFT, 2)
    poles = np.linalg.eigvals(plant.A)
    assert [m[0] for m in modes] == sorted(m[0] for m in modes)
    for frequency, zeta in modes:
        pole = -zeta * frequency + 1j * frequency * np.sqrt(1 - zeta ** 2)
        assert np.min(np.abs(poles - pole)) < 1e-6 * frequency
        assert 0.0 < zeta < 0.02
    # the arrays bending against each other along z (7.8 rad/s) is not moved by any torque:
    # the lowest mode shaped is the symmetric one above it
    assert modes[0][0] > 10.0


def test_a_torque_about_z_does_not_move_the_out_of_plane_modes():
    """About z the arrays bend in plane only: the modes moved differ from those about x."""
    about_z = eigenaxis_modes(CRAFT, (0, 0, 1), n_shaped=1, n_modes=2)
    about_x = eigenaxis_modes(CRAFT, (1, 0, 0), n_shaped=1, n_modes=2)
    assert abs(about_z[0][0] - about_x[0][0]) > 1.0


@pytest.mark.parametrize("kind, maker", [("zv", zv_shaper), ("zvd", zvd_shaper)])
def test_the_shaper_cancels_each_mode_it_names(kind, maker):
    axis = (0.6, 0.0, 0.8)
    modes = eigenaxis_modes(CRAFT, axis, n_shaped=2)
    shaper = eigenaxis_shaper(CRAFT, axis, kind, n_shaped=2)
    expected = convolve(maker(*modes[0]), maker(*modes[1]))
    assert np.allclose(shaper.times, expected.times) and np.allclose(shaper.amplitudes,
                                                                     expected.amplitudes)
    assert np.isclose(sum(shaper.amplitudes), 1.0)
    for frequency, zeta in modes:
        assert _residual(shaper, frequency, zeta) < 1e-9
    # a mode it does not name is not cancelled
    assert _residual(shaper, 0.5 * (modes[0][0] + modes[1][0]), 0.0) > 1e-3


@pytest.mark.parametrize("kwargs, pattern", [
    ({"kind": "zvdd"}, r"eigenaxis_shaper\.kind must be 'zv' or 'zvd'"),
    ({"kind": ["zv"]}, r"eigenaxis_shaper\.kind must be 'zv' or 'zvd'"),
    ({"n_shaped": 0}, r"eigenaxis_shaper\.n_shaped must be an integer >= 1"),
    ({"n_shaped": 2.0}, r"eigenaxis_shaper\.n_shaped"),
    ({"n_shaped": 50}, r"eigenaxis_shaper\.n_shaped must be at most \d+: a torque about"),
    ({"axis": (0, 0, 0)}, r"eigenaxis_shaper\.axis"),
    ({"axis": (np.nan, 0, 1)}, r"eigenaxis_shaper\.axis"),
    ({"n_modes": 0}, r"n_modes"),
])
def test_bad_arguments_are_refused_by_name(kwargs, pattern):
    arguments = {"structure": CRAFT, "axis": (1, 0, 0), **kwargs}
    with pytest.raises(InputError, match=pattern):
        eigenaxis_shaper(**arguments)


@pytest.mark.parametrize("through_wheels", [True, False], ids=["wheels", "hub torque"])
def test_the_feedforward_turns_the_rigid_craft_to_the_target(through_wheels):
    """Flown open loop on the craft, the feedforward alone ends the slew on target: through
    wheels from rest (zero momentum: ``J alpha``, their gyroscopic torque turns the hub's
    momentum) and as a torque on the hub (``J alpha + w x J w``). The other form misses by
    the gyroscopic torque counted twice or left out."""
    from controllers.slew.eigenaxis import EigenaxisSlew
    from controllers.slew.reference import SlewProfile
    from flexctl import VectorTorque, simulate_spatial
    from flexctl.model.wheel_cluster import WheelCluster
    from flexctl.sim.quaternions import error_angles

    rigid = CRAFT
    wheels = WheelCluster.orthogonal(inertia=0.01, torque_limit=10.0, speed_limit=1e4) \
        if through_wheels else None
    axis = np.array([0.6, 0.0, 0.8])
    misses = {}
    for momentum in (np.zeros(3), None):
        slew = EigenaxisSlew(axis=axis, profile=SlewProfile(slew_angle=1.0, duration=8.0),
                             inertia=rigid.rigid_inertia, momentum=momentum)
        times = np.linspace(0.0, 8.0, 4001)
        torque = VectorTorque(times, np.array([slew.at(t)[2] for t in times]))
        run = simulate_spatial(rigid, 8.0, torque, n_modes=1, wheels=wheels, rtol=1e-9)
        assert run.ok
        misses[momentum is None] = np.linalg.norm(error_angles(slew.target,
                                                               run.quaternion[:, -1]))
    right, wrong = misses[not through_wheels], misses[through_wheels]
    print(f"through wheels {through_wheels}: miss {right:.2e} rad, other form {wrong:.2e} rad")
    assert wrong > 5 * right
