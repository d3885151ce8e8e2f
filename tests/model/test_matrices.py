"""Modal matrices (MODEL.md section 3) against independent quadrature and closed forms."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import quad

from conftest import gauss_legendre
from flexctl import PointMass
from flexctl.model.matrices import assemble
from flexctl.model.modes import cantilever_roots, mode_shapes

#: Southwell coefficients K_g[i,i]/M_ff[i,i] at b = 0, MODEL.md section 6 (as printed).
SOUTHWELL = [(0, 1.1933, 5e-5), (1, 6.478, 5e-4)]   # (index, value, half a unit in last digit)
#: Matrices against independent quadrature of smooth integrands.
QUAD_RTOL = 1e-10
#: Matrices against exact closed forms (round-off only).
EXACT_RTOL = 1e-11
#: Ritz monotonicity: allowed increase of an eigenvalue with N (round-off of the eigensolver).
RITZ_SLACK = 1e-10


def _tension(system, x):
    """n(x) of MODEL.md section 2, written from the formula (not from flexctl)."""
    b, l, rho_a = system.hub.radius, system.beam.length, system.beam.linear_density
    n = rho_a * (b * (l - x) + 0.5 * (l ** 2 - x ** 2))
    return n + sum(m.mass * (b + m.position) * (m.position > x) for m in system.masses)


@pytest.mark.parametrize("index, expected, atol", SOUTHWELL, ids=["mode-1", "mode-2"])
def test_southwell_coefficients_of_the_kane_beam(kane_system, index, expected, atol):
    system = dataclasses.replace(kane_system, hub=dataclasses.replace(kane_system.hub,
                                                                       radius=0.0))
    mat = assemble(system, 4)
    assert mat.K_g[index, index] / mat.M_ff[index, index] == pytest.approx(expected, abs=atol)


def test_bare_beam_modal_mass_is_rhoA_l_identity(kane_system):
    n = 12
    mat = assemble(kane_system, n)
    beam = kane_system.beam
    np.testing.assert_allclose(mat.M_ff, beam.linear_density * beam.length * np.eye(n),
                               rtol=0, atol=QUAD_RTOL * beam.mass)


def test_bending_stiffness_is_EI_integral_of_curvature_products(kane_system):
    """K_ff = EI int phi'' phi''^T dx by our own quadrature (diagonal rhoA l omega_i^2)."""
    n = 12
    beam = kane_system.beam
    l = beam.length
    x, w = gauss_legendre(0.0, l)
    curv = mode_shapes(n, x / l, derivative=2, length=l)
    expected = beam.bending_stiffness * (curv * w) @ curv.T
    mat = assemble(kane_system, n)
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    np.testing.assert_allclose(mat.K_ff / scale, expected / scale, rtol=0, atol=QUAD_RTOL)


def test_beam_frequencies_and_stiffness_follow_the_closed_form(kane_system):
    n = 6
    beam = kane_system.beam
    z = cantilever_roots(n)
    omega = z ** 2 * np.sqrt(beam.bending_stiffness / (beam.linear_density * beam.length ** 4))
    mat = assemble(kane_system, n)
    np.testing.assert_allclose(mat.beam_frequencies, omega, rtol=EXACT_RTOL)
    np.testing.assert_allclose(np.diag(mat.K_ff), beam.mass * omega ** 2, rtol=EXACT_RTOL)


def _three_masses(system):
    l = system.beam.length
    return dataclasses.replace(system, masses=(
        PointMass(mass=0.05, position=0.0),
        PointMass(mass=0.085, position=0.37 * l),
        PointMass(mass=0.2, position=l)))


def test_point_masses_add_rank_one_terms_to_the_modal_mass(hub_beam_mass_system):
    """M_ff = rhoA l I + sum_k m_k phi(d_k) phi(d_k)^T."""
    n = 6
    system = _three_masses(hub_beam_mass_system)
    beam = system.beam
    expected = beam.mass * np.eye(n)
    for m in system.masses:
        phi = mode_shapes(n, [m.position / beam.length])[:, 0]
        expected += m.mass * np.outer(phi, phi)
    mat = assemble(system, n)
    np.testing.assert_allclose(mat.M_ff, expected, rtol=0, atol=QUAD_RTOL * beam.mass)


def test_coupling_vector_and_rigid_inertia(hub_beam_mass_system):
    """m_tf = rhoA int (b+x) phi dx + sum m_k (b+d_k) phi(d_k); J_0 of MODEL.md section 2."""
    n = 4
    system = _three_masses(hub_beam_mass_system)
    b, l, rho_a = system.hub.radius, system.beam.length, system.beam.linear_density
    expected = np.empty(n)
    for i in range(n):
        def integrand(x, i=i):
            return rho_a * (b + x) * mode_shapes(n, [x / l])[i, 0]
        expected[i] = quad(integrand, 0.0, l, epsabs=1e-15, epsrel=1e-12, limit=200)[0]
    for m in system.masses:
        expected += m.mass * (b + m.position) * mode_shapes(n, [m.position / l])[:, 0]
    mat = assemble(system, n)
    np.testing.assert_allclose(mat.m_tf, expected, rtol=QUAD_RTOL, atol=0)
    j0 = (system.hub.inertia + rho_a * ((b + l) ** 3 - b ** 3) / 3
          + sum(m.mass * (b + m.position) ** 2 for m in system.masses))
    assert mat.J0 == pytest.approx(j0, rel=EXACT_RTOL)


def test_geometric_stiffness_is_piecewise_exact_at_an_awkward_mass_position(
        hub_beam_mass_system):
    """K_g = int n(x) phi' phi'^T dx with n stepping at a mass at 0.37 l (not a Gauss node).

    The reference integrates each piece separately with adaptive quadrature, so a method
    that integrated across the step would miss it by far more than the tolerance.
    """
    n = 3
    l = hub_beam_mass_system.beam.length
    system = dataclasses.replace(hub_beam_mass_system,
                                 masses=(PointMass(mass=0.3, position=0.37 * l),))
    d = system.masses[0].position
    expected = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            def integrand(x, i=i, j=j):
                slope = mode_shapes(n, [x / l], derivative=1, length=l)[:, 0]
                return _tension(system, x) * slope[i] * slope[j]
            expected[i, j] = sum(quad(integrand, lo, hi, epsabs=0, epsrel=1e-13, limit=200)[0]
                                 for lo, hi in ((0.0, d), (d, l)))
    mat = assemble(system, n)
    np.testing.assert_allclose(mat.K_g, expected, rtol=QUAD_RTOL, atol=0)


@pytest.mark.parametrize("n_modes", [2, 8, 20], ids=["N2", "N8", "N20"])
def test_matrices_are_symmetric_and_definite(hub_beam_mass_system, n_modes):
    mat = assemble(_three_masses(hub_beam_mass_system), n_modes)
    for name in ("M_ff", "K_ff", "K_g"):
        a = getattr(mat, name)
        np.testing.assert_array_equal(a, a.T, err_msg=name)
        # positive tension and positive masses make all three positive definite
        assert np.linalg.eigvalsh(a)[0] > 0, name


@pytest.mark.parametrize("spin_rate", [0.0, 3.0, 6.0], ids=["spin-0", "spin-3", "spin-6"])
def test_ritz_frequencies_decrease_with_more_modes(hub_beam_mass_system, spin_rate):
    """Rayleigh-Ritz on nested bases: each eigenvalue of (K_ff - W^2 D, M_ff) never rises."""
    counts = [1, 2, 3, 4, 6, 8, 12, 16]
    eig = {}
    for n in counts:
        mat = assemble(hub_beam_mass_system, n)
        eig[n] = scipy.linalg.eigh(mat.K_ff - spin_rate ** 2 * mat.D, mat.M_ff,
                                   eigvals_only=True)
    for coarse, fine in zip(counts[:-1], counts[1:]):
        lo, hi = eig[fine][:coarse], eig[coarse]
        assert np.all(lo <= hi + RITZ_SLACK * np.abs(hi)), (coarse, fine)
    # and they converge; only algebraically here, since the point mass puts a kink in the
    # slope that smooth modes resolve slowly: the first eigenvalue has settled to 1e-5.
    assert eig[16][0] == pytest.approx(eig[12][0], rel=1e-5)


def test_modal_damping_gives_each_clamped_mode_the_damping_ratio(hub_beam_mass_system):
    zeta = 0.03
    system = dataclasses.replace(hub_beam_mass_system,
                                 beam=dataclasses.replace(hub_beam_mass_system.beam,
                                                          damping_ratio=zeta))
    n = 4
    mat = assemble(system, n)
    m_inv = np.linalg.inv(mat.M_ff)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-m_inv @ mat.K_ff, -m_inv @ mat.C_ff]])
    poles = np.linalg.eigvals(a)
    np.testing.assert_allclose(-poles.real / np.abs(poles), zeta, rtol=1e-9)
    undamped = assemble(hub_beam_mass_system, n)
    np.testing.assert_array_equal(undamped.C_ff, np.zeros((n, n)))


def test_tip_and_root_output_vectors(hub_beam_mass_system):
    """phi_i(l) = 2 (-1)^(i+1); root moment EI phi_i''(0) = 2 EI (z_i / l)^2."""
    n = 5
    mat = assemble(hub_beam_mass_system, n)
    beam = hub_beam_mass_system.beam
    i = np.arange(1, n + 1)
    z = cantilever_roots(n)
    np.testing.assert_allclose(mat.tip, 2.0 * (-1.0) ** (i + 1), rtol=EXACT_RTOL)
    np.testing.assert_allclose(mat.root, 2.0 * beam.bending_stiffness * (z / beam.length) ** 2,
                               rtol=EXACT_RTOL)
    np.testing.assert_allclose(mat.deflection_vector(beam.length), mat.tip, rtol=EXACT_RTOL)
    np.testing.assert_allclose(mat.deflection_vector(0.0), 0.0, atol=1e-12)


def test_matrices_are_read_only(hub_beam_mass_system):
    mat = assemble(hub_beam_mass_system, 3)
    with pytest.raises(ValueError):
        mat.M_ff[0, 0] = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        mat.J0 = 0.0


@pytest.mark.parametrize("system, n_modes, exc, pattern", [
    ("not a system", 3, TypeError, "system"),
    (None, 0, ValueError, "n_modes"),
    (None, 2.0, TypeError, "n_modes"),
    (None, True, TypeError, "n_modes"),
], ids=["bad-system", "zero-modes", "float-modes", "bool-modes"])
def test_assemble_rejects_bad_input(hub_beam_mass_system, system, n_modes, exc, pattern):
    # Assemble the valid neighbour first: a cached result for n_modes = 1 or 2 must not make
    # True or 2.0 (which hash equal) acceptable.
    assemble(hub_beam_mass_system, 1)
    assemble(hub_beam_mass_system, 2)
    with pytest.raises(exc, match=pattern):
        assemble(hub_beam_mass_system if system is None else system, n_modes)


@pytest.mark.parametrize("position", [-0.1, 2.0], ids=["before-root", "past-tip"])
def test_deflection_vector_rejects_positions_off_the_beam(hub_beam_mass_system, position):
    mat = assemble(hub_beam_mass_system, 3)
    with pytest.raises(ValueError, match="position"):
        mat.deflection_vector(position)
