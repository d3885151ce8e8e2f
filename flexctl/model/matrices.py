"""Modal matrices of the hub-beam-mass system (:ref:`section 3 of the model <sec-modes>`).

Every integral is piecewise smooth: the tension ``n(x)`` steps at each point mass. The beam is
cut at the mass positions and each piece is integrated with its own Gauss-Legendre rule, with
enough points for the highest product of modes, so the steps cost no accuracy.

Notes
-----
With ``N`` modes:

========  =========  ==============================================================
name      shape      meaning
========  =========  ==============================================================
J0        scalar     inertia of the undeformed system about O, kg m^2
M_ff      (N, N)     modal mass, kg
K_ff      (N, N)     modal bending stiffness (diagonal ``rhoA l omega_i^2``), N/m
K_g       (N, N)     geometric stiffness per unit ``theta_t^2``, kg
m_tf      (N,)       rigid-flexible inertia coupling, kg m
C_ff      (N, N)     modal damping, N s/m
D         (N, N)     ``M_ff - K_g``, kg
tip       (N,)       ``phi_i(l)``, tip deflection per modal coordinate
root      (N,)       ``EI phi_i''(0)``, root bending moment per modal coordinate, N
========  =========  ==============================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .checks import check_integer
from .errors import InputTypeError, InputValueError
from .modes import cantilever_roots, mode_shapes
from .parameters import HubBeam

__all__ = ["ModalMatrices", "assemble", "tension"]


def tension(system: HubBeam, x) -> np.ndarray:
    """Centrifugal tension per unit ``theta_t^2``, ``n(x)``, kg m.

    Parameters
    ----------
    system : HubBeam
        The beam, its point masses and the hub radius ``b``.
    x : array_like
        Positions along the beam, m. At a mass position the tension just outboard of the
        mass is returned (the mass pulls on the part inboard of it).
    """
    x = np.asarray(x, dtype=float)
    b, l, rho_a = system.hub.radius, system.beam.length, system.beam.linear_density
    n = rho_a * (b * (l - x) + 0.5 * (l ** 2 - x ** 2))
    for m in system.masses:
        n = n + m.mass * (b + m.position) * (x < m.position)
    return n


def beam_quadrature(system: HubBeam, n_modes: int):
    """Gauss-Legendre nodes (m) and weights over the beam, cut at every mass position.

    Parameters
    ----------
    system : HubBeam
        The beam and its point masses.
    n_modes : int
        Number of modes ``N``: each piece's rule has enough points for products of two of them.
    """
    l = system.beam.length
    cuts = sorted({0.0, l, *(m.position for m in system.masses)})
    z_max = cantilever_roots(n_modes)[-1]
    nodes, weights = [], []
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        if hi - lo <= 1e-12 * l:
            continue
        # products of two modes oscillate at up to 2 z_max / l rad/m; the exponential
        # parts need a few extra points on short pieces.
        n_points = int(np.ceil(z_max * (hi - lo) / l)) + 24
        g, w = np.polynomial.legendre.leggauss(n_points)
        nodes.append(0.5 * (hi - lo) * g + 0.5 * (hi + lo))
        weights.append(0.5 * (hi - lo) * w)
    return np.concatenate(nodes), np.concatenate(weights)


def condensed_hub_inertia(system: HubBeam, n_modes: int) -> float:
    """Effective hub inertia at rest ``J_0 - m_tf^T M_ff^-1 m_tf``, kg m^2, without cancellation.

    The Schur complement is the hub inertia plus the inertia of the part of the rigid rotation
    ``r = b + x`` that the modes cannot represent: with the mass measure ``mu`` of the beam and
    its point masses, ``J_0 - m_tf^T M_ff^-1 m_tf = J_h + ||r - P r||_mu^2``, ``P`` the
    ``mu``-orthogonal projection onto the mode shapes. The residual norm is the last diagonal
    entry of the QR factor of ``sqrt(mu) [phi^T, r]`` (rows sorted heaviest first, which keeps
    Householder QR accurate under strong row scaling), so a heavy tip mass (1e8 kg on a 1 kg
    beam) no longer subtracts two nearly equal numbers of size ``J_0``.

    Parameters
    ----------
    system : HubBeam
        The hub, beam and point masses.
    n_modes : int
        Number of cantilever modes ``N`` (>= 1).

    Returns
    -------
    float
    """
    beam, b = system.beam, system.hub.radius
    l = beam.length
    x, w = beam_quadrature(system, n_modes)
    positions = np.concatenate((x, [m.position for m in system.masses]))
    weights = np.concatenate((beam.linear_density * w, [m.mass for m in system.masses]))
    keep = weights > 0.0
    root_w = np.sqrt(weights[keep])
    order = np.argsort(-root_w, kind="stable")
    phi = mode_shapes(n_modes, positions[keep] / l)
    rows = np.column_stack((phi.T * root_w[:, None], (b + positions[keep]) * root_w))[order]
    r_factor = np.linalg.qr(rows, mode="r")
    return float(system.hub.inertia + r_factor[n_modes, n_modes] ** 2)


@dataclass(frozen=True, eq=False)
class ModalMatrices:
    """Assembled modal matrices of a :class:`~flexctl.model.parameters.HubBeam` (read-only arrays).

    Build with :func:`assemble`; see the module Notes for the symbols and shapes.

    Attributes
    ----------
    system : HubBeam
        The system assembled.
    n_modes : int
        Number of cantilever modes ``N``.
    roots : ndarray, shape (N,)
        Cantilever eigenvalues ``z_i`` (``cos z cosh z = -1``), dimensionless.
    beam_frequencies : ndarray, shape (N,)
        Clamped frequencies of the bare beam, ``z_i^2 sqrt(EI / (rhoA l^4))``, rad/s.
    J0 : float
        Inertia of the undeformed system about O, kg m^2.
    M_ff : ndarray, shape (N, N)
        Modal mass, kg.
    K_ff : ndarray, shape (N, N)
        Modal bending stiffness, N/m.
    K_g : ndarray, shape (N, N)
        Geometric stiffness per unit ``theta_t^2``, kg.
    m_tf : ndarray, shape (N,)
        Rigid-flexible inertia coupling, kg m.
    C_ff : ndarray, shape (N, N)
        Modal damping, N s/m.
    tip : ndarray, shape (N,)
        ``phi_i(l)``, tip deflection per modal coordinate.
    root : ndarray, shape (N,)
        ``EI phi_i''(0)``, root bending moment per modal coordinate, N.
    """

    system: HubBeam
    n_modes: int
    roots: np.ndarray
    beam_frequencies: np.ndarray
    J0: float
    M_ff: np.ndarray
    K_ff: np.ndarray
    K_g: np.ndarray
    m_tf: np.ndarray
    C_ff: np.ndarray
    tip: np.ndarray
    root: np.ndarray

    @property
    def D(self) -> np.ndarray:
        """``M_ff - K_g``: net softening minus stiffening per unit ``theta_t^2``, kg."""
        return self.M_ff - self.K_g

    def deflection_vector(self, position: float) -> np.ndarray:
        """``phi_i(x)`` at ``position`` (m), so that ``y(x) = phi(x) @ q``. Shape (N,).

        Parameters
        ----------
        position : float
            Distance from the beam root, m, in ``[0, l]``.
        """
        l = self.system.beam.length
        if not 0.0 <= position <= l:
            raise InputValueError(f"position must lie in [0, beam.length = {l:g}]; "
                                  f"got {position!r}")
        return mode_shapes(self.n_modes, [position / l])[:, 0]


def _freeze(*arrays):
    for a in arrays:
        a.setflags(write=False)


def assemble(system: HubBeam, n_modes: int) -> ModalMatrices:
    """Assemble (cached) the modal matrices of ``system`` on ``n_modes`` cantilever modes.

    Parameters
    ----------
    system : HubBeam
        The hub, beam and point masses.
    n_modes : int
        Number of cantilever modes ``N`` (>= 1).

    Returns
    -------
    ModalMatrices
    """
    if not isinstance(system, HubBeam):
        raise InputTypeError(f"system must be a HubBeam; got {type(system).__name__}")
    return _assemble(system, check_integer("", "n_modes", n_modes, minimum=1))


@lru_cache(maxsize=64)
def _assemble(system: HubBeam, n_modes: int) -> ModalMatrices:
    beam, b = system.beam, system.hub.radius
    l, rho_a, ei = beam.length, beam.linear_density, beam.bending_stiffness
    z = cantilever_roots(n_modes)
    omega = z ** 2 * np.sqrt(ei / (rho_a * l ** 4))

    x, w = beam_quadrature(system, n_modes)
    phi = mode_shapes(n_modes, x / l)
    dphi = mode_shapes(n_modes, x / l, derivative=1, length=l)

    M_ff = rho_a * (phi * w) @ phi.T
    m_tf = rho_a * phi @ (w * (b + x))
    for m in system.masses:
        phi_k = mode_shapes(n_modes, [m.position / l])[:, 0]
        M_ff += m.mass * np.outer(phi_k, phi_k)
        m_tf += m.mass * (b + m.position) * phi_k
    K_g = (dphi * (w * tension(system, x))) @ dphi.T
    M_ff = 0.5 * (M_ff + M_ff.T)
    K_g = 0.5 * (K_g + K_g.T)
    # Exact: EI int phi_i'' phi_j'' dx = EI z_i^4 / l^3 delta_ij = rhoA l omega_i^2 delta_ij.
    K_ff = np.diag(rho_a * l * omega ** 2)

    # Modal damping: ratio zeta on every clamped mode of the beam with its masses,
    # C = M V diag(2 zeta w) V^T M with V the M-normalised eigenvectors of (K_ff, M_ff).
    zeta = beam.damping_ratio
    if zeta > 0.0:
        from scipy.linalg import eigh
        w2, vecs = eigh(K_ff, M_ff)
        mv = M_ff @ vecs
        C_ff = mv @ np.diag(2.0 * zeta * np.sqrt(np.maximum(w2, 0.0))) @ mv.T
        C_ff = 0.5 * (C_ff + C_ff.T)
    else:
        C_ff = np.zeros((n_modes, n_modes))

    tip = mode_shapes(n_modes, [1.0])[:, 0]
    root = ei * mode_shapes(n_modes, [0.0], derivative=2, length=l)[:, 0]
    _freeze(z, omega, M_ff, K_ff, K_g, m_tf, C_ff, tip, root)
    return ModalMatrices(system=system, n_modes=n_modes, roots=z, beam_frequencies=omega,
                         J0=system.rigid_inertia, M_ff=M_ff, K_ff=K_ff, K_g=K_g, m_tf=m_tf,
                         C_ff=C_ff, tip=tip, root=root)
