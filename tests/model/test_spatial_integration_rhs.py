"""The spatial exact model's right-hand side as the integrators evaluate it
(``SpatialEquations.integration_rhs``): each appendage's terms a call of one function shared by
the appendages of one rod, the same numbers as ``rhs``, and its numbers lifted with the calls
kept (one library for every structure of the same shape)."""

import hashlib

import numpy as np
import pytest

from flexctl.model.parameters import PointMass
from flexctl.model.spatial_dynamics import spatial_equations
from flexctl.model.spatial_structure import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.sim.lifted_constants import lift_constants

INERTIA = [[1.3, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]]


def _rod(name, direction, normal, length=1.2, masses=(), density=2766.0):
    return SpatialAppendage(name=name, direction=direction, normal=normal, length=length,
                            density=density, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=5.2e-10, second_moment_lateral=5.2e-8,
                            shear_modulus=2.6e10, torsion_constant=1.9e-9, masses=masses)


def _craft(support="pinned", density=2766.0):
    tip = (PointMass(mass=0.1, position=1.0),)
    return SpatialStructure(
        hub=SpatialHub(inertia=INERTIA, radius=0.06, mass=3.0, support=support),
        appendages=(_rod("a", (0, 1, 0), (0, 0, 1), masses=tip, density=density),
                    _rod("b", (0, -1, 0), (0, 0, 1), masses=tip, density=density),
                    _rod("c", (1, 0, 0), (0, 1, 0), length=0.8, density=density)))


def _states(equations, count=3, seed=1):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        x = 0.05 * rng.normal(size=equations.layout.n_states)   # deflected, turning
        x[0:4] /= np.linalg.norm(x[0:4])
        yield x, rng.normal(size=3)


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_the_integration_rhs_is_the_rhs_with_one_function_per_rod(support):
    equations = spatial_equations(_craft(support), (3, 3, 2))
    shared = equations.integration_rhs
    # the two arrays are one rod (their frames and roots are inputs): one function, and the
    # boom another; each calls one node recursion and one section function of its size
    names = sorted(f.name() for f in shared.find_functions())
    assert names == ["rod_chain_step_6", "rod_chain_step_9", "rod_section_6",
                     "rod_section_9", "spatial_appendage_0", "spatial_appendage_2"]
    assert shared.n_instructions() < equations.rhs.n_instructions() / 3
    for x, torque in _states(equations):
        whole = equations.rhs(x, torque).full()
        np.testing.assert_allclose(shared(x, torque).full(), whole, rtol=0,
                                   atol=1e-14 * np.max(np.abs(whole)))


def test_the_expanded_variants_integrate_their_rhs():
    equations = spatial_equations(_craft(), 2, "first_order")
    assert equations.integration_rhs is equations.rhs


def test_lifting_keeps_the_calls_and_lifts_their_numbers():
    """The lifted function calls lifted functions; a structure that differs only in numbers
    (a denser rod, on the same quadrature) lifts to the same function (one library) with
    other constants."""
    lifted = []
    for density in (2766.0, 2766.0 * 1.01):
        equations = spatial_equations(_craft(density=density), 2)
        function, constants = lift_constants(equations.integration_rhs)
        assert all(f.name().endswith("_lifted") for f in function.find_functions())
        for x, torque in _states(equations, 2):
            whole = equations.rhs(x, torque).full()
            np.testing.assert_allclose(function(x, torque, constants).full(), whole, rtol=0,
                                       atol=1e-14 * np.max(np.abs(whole)))
        lifted.append((hashlib.sha256(function.serialize().encode()).hexdigest(), constants))
    assert lifted[0][0] == lifted[1][0]
    assert lifted[0][1].shape == lifted[1][1].shape
    assert not np.array_equal(lifted[0][1], lifted[1][1])
