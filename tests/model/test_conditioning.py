"""Conditioning: parameter ratios that make the model numerically meaningless are refused with
an error naming the ratio, and the effective hub inertia is computed without cancellation."""

import dataclasses

import numpy as np
import pytest

from flexctl import Beam, PointMass, build_model
from flexctl.model.errors import InputValueError
from flexctl.model.matrices import assemble, condensed_hub_inertia
from flexctl.model.parameters import MASS_RATIO_LIMIT

#: The condensed inertia and the textbook Schur complement agree this well where the latter is
#: well conditioned (a light tip mass).
AGREEMENT = 1e-12
#: Relative spread of the effective inertia over tip masses whose effect has converged.
CONVERGED = 1e-8


def _with_tip_mass(system, mass, position=None):
    position = system.beam.length if position is None else position
    return dataclasses.replace(system, masses=(PointMass(mass=mass, position=position),))


@pytest.mark.parametrize("n_modes", [1, 3, 6], ids=lambda n: f"{n}modes")
def test_condensed_inertia_is_the_schur_complement(hub_beam_mass_system, n_modes):
    mat = assemble(hub_beam_mass_system, n_modes)
    schur = mat.J0 - mat.m_tf @ np.linalg.solve(mat.M_ff, mat.m_tf)
    assert condensed_hub_inertia(hub_beam_mass_system, n_modes) == pytest.approx(
        schur, rel=AGREEMENT)


def test_heavy_tip_mass_keeps_the_effective_hub_inertia(hub_beam_mass_system):
    """A tip mass a million times the beam pins the tip: the effective inertia converges to the
    hub's plus the part of the beam rotation the modes cannot follow, far below J_0 (the
    subtraction J_0 - m_tf^T M_ff^-1 m_tf gave 30 times the hub inertia at 1e8 kg)."""
    beam_mass = hub_beam_mass_system.beam.mass
    values = []
    for ratio in (1e4, 1e5, 0.99 * MASS_RATIO_LIMIT):
        model = build_model(_with_tip_mass(hub_beam_mass_system, ratio * beam_mass), n_modes=6)
        j_eff = float(model.effective_hub_inertia(np.zeros(model.n_states)))
        hub = hub_beam_mass_system.hub.inertia
        beam_rigid = hub_beam_mass_system.rigid_inertia - hub - 0.085 * 1.68 ** 2
        assert hub <= j_eff <= hub + beam_rigid
        values.append(j_eff)
    assert np.ptp(values) <= 1e3 * CONVERGED * values[-1]


def test_mass_ratio_beyond_the_limit_is_refused(hub_beam_mass_system):
    with pytest.raises(InputValueError, match=r"ratio of the point masses to the beam mass.*"
                       r"<= 1e\+06.*got 8\.03\d*e\+07"):
        _with_tip_mass(hub_beam_mass_system, 1e8)


@pytest.mark.parametrize("changes, name", [
    ({"density": 1e-300, "area": 1e-300}, r"beam\.density \* beam\.area"),
    ({"youngs_modulus": 1e-200, "second_moment": 1e-200},
     r"beam\.youngs_modulus \* beam\.second_moment"),
    ({"density": 1e80, "area": 1e30}, r"beam\.density \* beam\.area"),
    ({"youngs_modulus": 1e90, "density": 1e-20}, r"ratio EI / \(rho A l\^4\)"),
], ids=["underflowing-mass", "underflowing-stiffness", "overflowing-mass", "stiffness-ratio"])
def test_beam_products_out_of_floating_point_range_are_refused(hub_beam_mass_system, changes,
                                                               name):
    with pytest.raises(InputValueError, match=name + r".*must lie in.*got"):
        dataclasses.replace(hub_beam_mass_system.beam, **changes)


def test_extreme_but_representable_beam_is_accepted():
    beam = Beam(length=1.0, density=1e-20, area=1e-20, second_moment=1e-20, youngs_modulus=1e-20)
    assert beam.linear_density == pytest.approx(1e-40)
