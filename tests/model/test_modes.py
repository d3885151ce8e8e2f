"""Cantilever modes (MODEL.md section 3): roots, normalisation, boundary conditions, ODE."""

import numpy as np
import pytest

from conftest import gauss_legendre
from flexctl.model.modes import cantilever_roots, mode_shapes

#: Roots of cos z cosh z + 1 = 0 as tabulated in MODEL.md section 3 (7 decimals).
TABULATED_ROOTS = np.array([1.8751041, 4.6940911, 7.8547574, 10.9955407, 14.1371684])
#: Half a unit in the 7th decimal of the table.
TABLE_ATOL = 5e-8
#: Orthonormality and normalisation: MODEL.md promises ~1e-12 for 40 modes; we ask 1e-10.
ORTHO_ATOL = 1e-10
#: Boundary conditions, relative to the natural scale (z/l)^k of the k-th derivative.
BC_ATOL = 1e-10
#: Finite differences: step and tolerance (truncation ~ (z h)^2 / 12 for the modes checked).
FD_STEP = 1e-4
FD_STEP_SECOND = 1e-3
FD_RTOL = 1e-4

N_ORTHO = 40
LENGTH = 2.5   # any length: it must only scale the derivatives


def test_first_roots_match_the_table():
    np.testing.assert_allclose(cantilever_roots(5), TABULATED_ROOTS, rtol=0, atol=TABLE_ATOL)


def test_roots_solve_the_frequency_equation():
    """cos z cosh z + 1 = 0, written as cos z + sech z = 0 to stay well scaled."""
    z = cantilever_roots(N_ORTHO)
    np.testing.assert_allclose(np.cos(z) + 1.0 / np.cosh(z), 0.0, atol=1e-13)
    assert np.all(np.diff(z) > 0)


def test_higher_roots_approach_odd_multiples_of_half_pi():
    z = cantilever_roots(N_ORTHO)
    i = np.arange(1, N_ORTHO + 1)
    # cos z = -sech z ~ -2 e^-z, so z - (2i-1) pi/2 = O(e^-z)
    gap = np.abs(z - (2 * i - 1) * np.pi / 2)
    assert np.all(gap[5:] < 3.0 * np.exp(-z[5:]) + 1e-13)


def test_roots_of_a_larger_set_extend_a_smaller_set():
    np.testing.assert_array_equal(cantilever_roots(40)[:7], cantilever_roots(7))


def test_modes_are_orthonormal():
    """int_0^1 phi_i phi_j dxi = delta_ij for 40 modes, by independent quadrature."""
    xi, w = gauss_legendre(0.0, 1.0, n_panels=16, n_points=80)
    phi = mode_shapes(N_ORTHO, xi)
    gram = (phi * w) @ phi.T
    np.testing.assert_allclose(gram, np.eye(N_ORTHO), rtol=0, atol=ORTHO_ATOL)


def test_tip_values_alternate_in_sign():
    i = np.arange(1, N_ORTHO + 1)
    tip = mode_shapes(N_ORTHO, [1.0])[:, 0]
    np.testing.assert_allclose(tip, 2.0 * (-1.0) ** (i + 1), rtol=0, atol=ORTHO_ATOL)


@pytest.mark.parametrize("xi, derivative", [(0.0, 0), (0.0, 1), (1.0, 2), (1.0, 3)],
                         ids=["root-deflection", "root-slope", "tip-moment", "tip-shear"])
def test_clamped_free_boundary_conditions(xi, derivative):
    """phi(0) = phi'(0) = 0 (clamped), phi''(l) = phi'''(l) = 0 (free end)."""
    z = cantilever_roots(N_ORTHO)
    value = mode_shapes(N_ORTHO, [xi], derivative=derivative, length=LENGTH)[:, 0]
    np.testing.assert_allclose(value / (z / LENGTH) ** derivative, 0.0, atol=BC_ATOL)


@pytest.mark.parametrize("derivative", [0, 1, 2], ids=["phi", "phi'", "phi''"])
def test_derivative_orders_are_consistent(derivative):
    """Central difference of the k-th derivative equals the (k+1)-th (in x, length scaling)."""
    n = 8
    z = cantilever_roots(n)[:, None]
    xi = np.linspace(0.05, 0.95, 19)
    hx = FD_STEP  # in xi
    up = mode_shapes(n, xi + hx, derivative=derivative, length=LENGTH)
    down = mode_shapes(n, xi - hx, derivative=derivative, length=LENGTH)
    fd = (up - down) / (2 * hx * LENGTH)
    exact = mode_shapes(n, xi, derivative=derivative + 1, length=LENGTH)
    scale = 2.0 * (z / LENGTH) ** (derivative + 1)
    np.testing.assert_allclose(fd / scale, exact / scale, rtol=0, atol=FD_RTOL)


def test_modes_satisfy_the_beam_equation():
    """phi'''' = (z/l)^4 phi, the free-vibration equation EI y'''' = rhoA omega^2 y."""
    n = 8
    z = cantilever_roots(n)[:, None]
    xi = np.linspace(0.05, 0.95, 19)
    h = FD_STEP_SECOND
    second = [mode_shapes(n, xi + s * h, derivative=2, length=LENGTH) for s in (-1, 0, 1)]
    fourth = (second[0] - 2 * second[1] + second[2]) / (h * LENGTH) ** 2
    expected = (z / LENGTH) ** 4 * mode_shapes(n, xi)
    scale = 2.0 * (z / LENGTH) ** 4
    np.testing.assert_allclose(fourth / scale, expected / scale, rtol=0, atol=FD_RTOL)


def test_mode_shapes_shape_and_scalar_input():
    assert mode_shapes(3, 0.5).shape == (3, 1)
    assert mode_shapes(3, np.linspace(0, 1, 7), derivative=2).shape == (3, 7)


@pytest.mark.parametrize("kwargs, pattern", [
    ({"n_modes": 3, "xi": [0.5], "derivative": 4}, "derivative"),
    ({"n_modes": 3, "xi": [1.1]}, "xi"),
    ({"n_modes": 3, "xi": [-0.1]}, "xi"),
    ({"n_modes": 0, "xi": [0.5]}, "n_modes"),
], ids=["derivative-4", "xi-above-1", "xi-below-0", "zero-modes"])
def test_mode_shapes_reject_bad_input(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        mode_shapes(**kwargs)


@pytest.mark.parametrize("n_modes, exc", [(0, ValueError), (-1, ValueError), (2.5, TypeError),
                                          (True, TypeError)],
                         ids=["zero", "negative", "float", "bool"])
def test_cantilever_roots_reject_bad_count(n_modes, exc):
    with pytest.raises(exc, match="n_modes"):
        cantilever_roots(n_modes)
