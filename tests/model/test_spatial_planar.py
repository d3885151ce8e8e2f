"""A spatial structure lying in the x-y plane as the planar structure turning about z
(flexctl.model.spatial_structure.SpatialStructure.to_planar)."""

import dataclasses

import numpy as np
import pytest

import flexctl
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.errors import InputError
from flexctl.model.parameters import PointMass
from flexctl.sim.inputs import SampledTorque
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial

ROD = SpatialAppendage(name="a", direction=(1.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), length=1.8,
                       density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                       second_moment=1.3e-10, second_moment_lateral=5.2e-8,
                       shear_modulus=2.6e10, torsion_constant=5e-10,
                       masses=(PointMass(mass=0.085, position=1.62),))


def _craft(**hub):
    boom = dataclasses.replace(ROD, name="b", direction=(-0.6, 0.8, 0.0), normal=(0.0, 0.0, 1.0),
                               masses=())
    return SpatialStructure(hub=SpatialHub(**{"inertia": np.diag([1.3, 1.16, 1.45]),
                                              "radius": 0.06, **hub}), appendages=(ROD, boom))


def test_each_rod_keeps_its_in_plane_stiffness_angle_and_masses():
    planar = _craft().to_planar()
    a, b = planar.appendages
    assert planar.hub.inertia == 1.45 and planar.hub.radius == 0.06
    assert a.beam.second_moment == 1.3e-10 and a.angle == 0.0 and a.masses == ROD.masses
    # the boom's normal is along z: its in-plane bending is the lateral one
    assert b.beam.second_moment == 5.2e-8 and np.isclose(b.angle, np.arctan2(0.8, -0.6))
    assert a.radius == b.radius == 0.06


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_in_plane_motion_is_the_planar_models(support):
    """Under a torque about z the spatial structure and its planar counterpart move alike:
    hub rate and every in-plane tip to 1e-7 of their peaks (two integrations at rtol 1e-10)."""
    craft = _craft(support=support, mass=3.0)
    times = [0.0, 0.4, 0.8, 1.2]
    values = [[0.0, 0.0, 0.6], [0.0, 0.0, -0.6], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    spatial = simulate_spatial(craft, 1.2, VectorTorque(times, values, "hold"), n_modes=2,
                               rtol=1e-10, output_step=0.01, check_accuracy=False)
    model = flexctl.build_model(craft.to_planar(), 2, "exact")
    planar = flexctl.simulate(model, 1.2, SampledTorque(times, [v[2] for v in values],
                                                        interpolation="hold"),
                              rtol=1e-10, output_step=0.01, check_validity=False,
                              check_accuracy=False)
    assert spatial.t.size == planar.t.size
    rate = planar.theta_dot
    np.testing.assert_allclose(spatial.angular_velocity[2], rate, atol=1e-7 * np.max(abs(rate)))
    for appendage in craft.appendages:
        across = np.cross([0.0, 0.0, 1.0], appendage.direction)
        flat = planar.tip_deflections[appendage.name]
        np.testing.assert_allclose(across @ spatial.tips[appendage.name], flat,
                                   atol=1e-7 * np.max(np.abs(flat)))


@pytest.mark.parametrize("change, match", [
    ({"direction": (0.6, 0.0, 0.8), "normal": (0.0, 1.0, 0.0)}, "x-y plane"),
    ({"root": (0.0, 0.06, 0.0)}, "own axis"),
    ({"normal": (0.0, 0.6, 0.8)}, "tilted section")])
def test_a_rod_out_of_the_plane_is_refused_by_name(change, match):
    craft = SpatialStructure(hub=SpatialHub(inertia=np.eye(3), radius=0.06),
                             appendages=(dataclasses.replace(ROD, **change),))
    with pytest.raises(InputError, match=match) as caught:
        craft.to_planar()
    assert "'a'" in str(caught.value)


def test_a_hub_whose_z_axis_is_not_principal_is_refused():
    craft = _craft(inertia=[[1.3, 0.0, 0.02], [0.0, 1.16, 0.0], [0.02, 0.0, 1.45]])
    with pytest.raises(InputError, match="principal"):
        craft.to_planar()
