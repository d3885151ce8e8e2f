"""Independent finite-element references for a planar hub carrying several beams.

This module deliberately does not import ``flexctl`` (only the mesh and sine torque of
``fe_reference``, which does not either): it is a second,
independent model of the structures of ``docs/theory/free_hub.md`` against which the toolbox is
checked. A hub, pinned at its centre C or floating free in the plane, carries any number of
uniform Euler-Bernoulli beams, each clamped radially at radius ``b_k`` and mounting angle
``alpha_k`` in the hub frame (axis ``e_k = (cos alpha_k, sin alpha_k)``, transverse direction
``n_k = (-sin alpha_k, cos alpha_k)``), with its own point masses. No gravity, no external
force; a torque ``T_h(t)`` on the hub only; no friction, no damping.

Two models
----------
:func:`linear_frequencies`
    Hermite cubic (Euler-Bernoulli) finite elements of every beam, rigidly clamped to the hub,
    linearised at rest. Generalized coordinates: the hub's translation ``(X, Y)`` (free hub
    only), its rotation ``theta`` (unless the hub is held), and the nodal deflections and
    slopes of every beam. A beam point at ``(b_k + x) e_k + w n_k`` moves by
    ``(dX, dY) + dtheta (b_k + x) n_k + w n_k`` to first order, so its transverse velocity is
    ``n_k . V + (b_k + x) theta_t + w_t`` and its axial velocity ``e_k . V`` (the beams are
    rigid axially: translation along ``e_k`` moves the whole beam and its point masses).
    Consistent element mass matrices, point masses lumped on nodes (a node is put at every
    mass), exact Gauss quadrature. The hub coordinates, which carry no stiffness, are
    eliminated exactly (``M_ww - M_wr M_rr^-1 M_rw``), which removes the rigid-body modes, and
    the eigenproblem is solved in the inverse form ``M v = K v / omega^2`` for accuracy of the
    lowest modes. Frequencies converge as ``h^4`` (round-off floor about 1e-9 relative): with
    40 elements per beam a bare cantilever's first three modes are within 3.2e-9, 1.3e-7 and
    1.0e-6 of the exact roots, and on the structures of ``tests/model/test_structure_fe.py`` the lowest
    two modes per beam change by at most 1.2e-7 from 40 to 80 elements (hub held or free).
    The rigid-element chain of :func:`simulate_multibody`, linearised at rest
    (:func:`chain_linear_frequencies`, 64 and 128 elements, Richardson) agrees with it to
    1e-6.

:func:`simulate_multibody`
    Geometrically exact rigid finite elements (the rigid-finite-element chain of
    ``tests/fe_reference.py``, rebuilt here): each beam of length ``l`` is meshed with nodes
    ``0 = x_0 < .. < x_n = l`` (point masses on nodes); segment ``i`` keeps its bending
    flexibility in a rotational spring ``EI / h_i`` at its midpoint, and the material between
    springs forms rigid, exactly inextensible links carrying the distributed mass and the point
    masses. Link 0 of every beam is rigid with the hub. Generalized coordinates: the hub centre
    ``(X, Y)`` (free hub only), the hub angle ``theta`` and the link angles ``psi_ki`` of every
    chain, ``psi_ki = beta_ki - alpha_k`` with ``beta_ki`` the link's inertial direction angle
    (so the rest state is all zeros and ``psi_k0 = theta``). Exact planar kinematics of a tree
    of rigid bodies, so foreshortening, centrifugal stiffening and softening, Coriolis forces
    and the translation-rotation coupling of a free hub all come out of the geometry.

    With the chain constants of beam ``k`` (link lengths ``L_i``, first moments
    ``g_i = int_link s dm + L_i m_beyond_i`` of the link and everything outboard of it about
    its start, and ``A_ij = L_i g_j`` for ``i < j``, ``A_ii = int_link s^2 dm + L_i^2
    m_beyond_i``), and ``u_a = (cos beta_a, sin beta_a)``, ``u_a^perp = (-sin, cos)``:

        T = 1/2 m |V|^2 + V . sum_a g_a beta_a_t u_a^perp + 1/2 J_h theta_t^2
            + 1/2 sum_k sum_ij A^k_ij cos(beta_i - beta_j) beta_i_t beta_j_t
        U = 1/2 sum_k sum_i EI_k / h_i (psi_ki - psi_k,i-1)^2

    (``m`` the total mass, ``V`` the hub centre's velocity). Lagrange's equations

        m V_t + sum_a g_a (u_a^perp beta_a_tt - u_a beta_a_t^2) = 0                 (free hub)
        g_a u_a^perp . V_t + sum_b A_ab (cos(b_a - b_b) beta_b_tt
                                         + sin(b_a - b_b) beta_b_t^2) + (K psi)_a = T_h [a = hub]

    (the hub angle collects the rows of every chain's link 0 plus ``J_h theta_tt``; for a
    pinned hub ``V = 0`` and the first row is dropped) are integrated with the fixed-step
    implicit midpoint rule, as in ``fe_reference``, with Newton iterations on the mass-matrix
    form of the step and an exact analytic Jacobian; the mass matrix and the iteration matrix
    are arrowheads (the beams couple only through the hub coordinates) and are inverted
    block by block. Second order in the element size (first clamped frequency error about
    ``0.23 / n^2``) and in the time step. Energy and linear and angular momentum are kept to
    O(dt^2), not exactly (they are not quadratic invariants): unforced, 20 % tip deflections,
    24 elements, 3 s: drifts 5e-7 (energy), 6e-8 (angular momentum), 3e-7 of the momentum.
    The time step needed depends on the torque: a smooth one (one-period sine) is converged to
    3e-5 of the tip peak with the default 1000 steps per first period, but the jumps of a
    bang-bang torque excite the chain's stiff modes and need about 4000 (1000 leave 3e-4).

Both models are checked in ``tests/model/test_structure_fe.py``: one beam on a pinned hub reproduces
``fe_reference`` to round-off (1e-12), at any mounting angle; energy and momenta are conserved
unforced; the angular momentum about the inertial origin equals the torque impulse; a free
hub's centre of mass stays at rest; a symmetric twin's tips move alike; the chain linearised
at rest has the Hermite model's frequencies (:func:`chain_linear_frequencies`); histories are
converged in elements (Richardson 32/64 against 16/32: 1e-4 of each tip's peak) and time step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

# the one-beam reference's mesh and sine torque (it, too, imports nothing from flexctl)
from fe_reference import _mesh, _midpoint, sine_torque  # noqa: F401  (sine_torque re-exported)
from scipy.linalg import eigh

__all__ = ["BeamSpec", "MultiSystem", "linear_frequencies", "simulate_multibody",
           "sine_torque", "bang_bang_torque", "torque_impulse",
           "clamped_first_frequency", "chain_linear_frequencies"]

SUPPORTS = ("pinned", "free")


@dataclass(frozen=True)
class BeamSpec:
    """One beam, SI units.

    Parameters
    ----------
    length : float
        Beam length ``l``, m.
    linear_density : float
        ``rhoA``, kg/m.
    bending_stiffness : float
        ``EI``, N m^2.
    angle : float
        Mounting angle ``alpha`` of the beam axis in the hub frame, rad.
    radius : float or None
        Radius ``b`` of the root from the hub centre, m; ``None``: the hub radius.
    masses : tuple of (float, float)
        Point masses as ``(mass, distance_from_root)`` pairs, distance in ``[0, l]``.
    """

    length: float
    linear_density: float
    bending_stiffness: float
    angle: float = 0.0
    radius: float | None = None
    masses: tuple = ()


@dataclass(frozen=True)
class MultiSystem:
    """A hub carrying several beams.

    Parameters
    ----------
    hub_inertia : float
        ``J_h`` about the hub centre, kg m^2 (may be 0).
    hub_radius : float
        Default root radius of the beams, m.
    hub_mass : float
        ``m_h``, kg; counts only for a free hub.
    support : {"pinned", "free"}
        Hub centre fixed, or free to translate in the plane.
    beams : tuple of BeamSpec
    """

    hub_inertia: float
    hub_radius: float
    hub_mass: float = 0.0
    support: str = "pinned"
    beams: tuple = ()

    def __post_init__(self):
        if self.support not in SUPPORTS:
            raise ValueError(f"support must be one of {SUPPORTS}; got {self.support!r}")
        if not self.beams:
            raise ValueError("at least one beam")
        for beam in self.beams:
            if min(beam.length, beam.linear_density, beam.bending_stiffness) <= 0:
                raise ValueError("length, linear_density and bending_stiffness must be > 0")
            for _, d in beam.masses:
                if not 0.0 <= d <= beam.length:
                    raise ValueError("point mass outside its beam")

    def root_radius(self, beam: BeamSpec) -> float:
        return float(self.hub_radius if beam.radius is None else beam.radius)

    @property
    def total_mass(self) -> float:
        return float(self.hub_mass) + sum(
            b.linear_density * b.length + sum(m for m, _ in b.masses) for b in self.beams)

    @property
    def reach(self) -> float:
        return max(self.root_radius(b) + b.length for b in self.beams)


# --------------------------------------------------------------------------------------------
# torques

def bang_bang_torque(amplitude: float, duration: float):
    """``+amplitude`` on ``[0, duration/2)``, ``-amplitude`` on ``[duration/2, duration)``, 0 after.

    The implicit midpoint rule samples the torque at step midpoints, so a switch inside a step
    is resolved to first order in the step only; pick ``dt`` dividing ``duration / 2``.
    """
    def torque(t):
        if t < 0.5 * duration:
            return amplitude
        if t < duration:
            return -amplitude
        return 0.0
    return torque


# --------------------------------------------------------------------------------------------
# meshing

# --------------------------------------------------------------------------------------------
# linear Hermite finite elements

_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(5)     # exact to degree 9


def _hermite(xi: np.ndarray, h: float):
    """Cubic Hermite shape functions and second derivatives on ``[0, h]``, ``xi in [0, 1]``.

    DOF order (w_1, w_1', w_2, w_2'). Returns arrays of shape (len(xi), 4).
    """
    n = np.column_stack([1 - 3 * xi ** 2 + 2 * xi ** 3, h * (xi - 2 * xi ** 2 + xi ** 3),
                         3 * xi ** 2 - 2 * xi ** 3, h * (-xi ** 2 + xi ** 3)])
    dd = np.column_stack([(-6 + 12 * xi) / h ** 2, (-4 + 6 * xi) / h,
                          (6 - 12 * xi) / h ** 2, (-2 + 6 * xi) / h])
    return n, dd


def _fe_matrices(system: MultiSystem, n_elements: int):
    """Mass and stiffness of the linearised structure.

    DOFs: ``[X, Y, theta]`` then, per beam, ``(w, w')`` at nodes 1..n (node 0 clamped).
    Returns ``M, K, beam_slices``.
    """
    meshes = [_mesh(beam, n_elements) for beam in system.beams]
    n_dof = 3 + sum(2 * (len(x) - 1) for x in meshes)
    m = np.zeros((n_dof, n_dof))
    k = np.zeros((n_dof, n_dof))
    m[0, 0] = m[1, 1] = float(system.hub_mass)
    m[2, 2] = float(system.hub_inertia)
    slices = []
    start = 3
    for beam, x in zip(system.beams, meshes):
        b = system.root_radius(beam)
        rho, ei = float(beam.linear_density), float(beam.bending_stiffness)
        a = float(beam.angle)
        e = np.array([np.cos(a), np.sin(a)])
        nrm = np.array([-np.sin(a), np.cos(a)])
        n_nodes = len(x)
        size = 2 * (n_nodes - 1)
        sl = slice(start, start + size)
        slices.append(sl)
        # local transverse field v = n.V + (b + s) theta + w(s); columns: [nV (1), theta, w...]
        # build the local basis matrix B(s) = [n_x, n_y, b + s, N(s) at DOFs] by quadrature
        loc = np.zeros((3 + size, 3 + size))      # local mass over [X, Y, theta, w..]
        kloc = np.zeros((size, size))
        for i in range(n_nodes - 1):
            h = x[i + 1] - x[i]
            xi = 0.5 * (_GAUSS_X + 1.0)
            wq = 0.5 * h * _GAUSS_W
            shp, dd = _hermite(xi, h)
            s = x[i] + h * xi
            # indices of the element DOFs in the local w block (node 0 is clamped)
            idx = np.arange(2 * (i - 1), 2 * (i + 1))
            keep = idx >= 0
            cols = np.concatenate([[0, 1, 2], 3 + idx[keep]])
            basis = np.column_stack([np.outer(np.ones_like(s), nrm), b + s, shp[:, keep]])
            loc[np.ix_(cols, cols)] += rho * (basis * wq[:, None]).T @ basis
            kloc[np.ix_(idx[keep], idx[keep])] += ei * ((dd[:, keep] * wq[:, None]).T
                                                        @ dd[:, keep])
        for mass, d in beam.masses:
            mass, d = float(mass), float(d)
            j = int(np.argmin(np.abs(x - d)))
            assert abs(x[j] - d) < 1e-12 * max(1.0, beam.length)
            vec = np.zeros(3 + size)
            vec[:2] = nrm
            vec[2] = b + d
            if j > 0:
                vec[3 + 2 * (j - 1)] = 1.0
            loc += mass * np.outer(vec, vec)
        # axial rigid translation: the whole beam with its masses moves with e . V
        beam_mass = rho * beam.length + sum(float(mm) for mm, _ in beam.masses)
        loc[:2, :2] += beam_mass * np.outer(e, e)
        glob = np.concatenate([[0, 1, 2], np.arange(sl.start, sl.stop)])
        m[np.ix_(glob, glob)] += loc
        k[sl, sl] += kloc
        start += size
    return m, k, slices


def linear_frequencies(system: MultiSystem, n_elements: int = 40, hub: str = "free"):
    """Natural frequencies of the structure linearised at rest (spin 0), Hermite cubic FE.

    Parameters
    ----------
    system : MultiSystem
    n_elements : int
        Elements per beam (a node is put at every point mass). Frequencies converge as
        ``h^4`` down to a round-off floor of about 1e-9 relative. Measured on a bare cantilever
        against its exact roots with 40 elements: relative errors 3.2e-9, 1.3e-7 and 1.0e-6 for
        the first three modes (20 elements: 5.4e-8, 2.1e-6, 1.6e-5); 40 against 80 elements on
        the structures of ``tests/model/test_structure_fe.py``: the lowest two modes per beam change
        by at most 1.2e-7, hub held or free.
    hub : {"clamped", "free"}
        ``"clamped"``: the hub is held (no rotation, no translation); the frequencies of each
        beam as a clamped-free cantilever, merged. ``"free"``: the hub rotates (pinned support)
        and also translates (free support) as ``system.support`` says; the rigid-body modes
        (1 or 3 zero frequencies) are left out.

    Returns
    -------
    numpy.ndarray
        Sorted nonzero frequencies, rad/s (all of the discretized model: only the lowest few
        per beam are converged).
    """
    if hub not in ("clamped", "free"):
        raise ValueError("hub must be 'clamped' or 'free'")
    m, k, _ = _fe_matrices(system, n_elements)
    w = np.arange(3, m.shape[0])
    m_ww, k_ww = m[np.ix_(w, w)], k[np.ix_(w, w)]
    if hub == "free":
        # the hub coordinates r carry no stiffness: M_rr r_tt + M_rw w_tt = 0 eliminates them
        # exactly (the rigid-body modes go with them)
        r = np.array([2]) if system.support == "pinned" else np.arange(3)
        m_ww = m_ww - m[np.ix_(w, r)] @ np.linalg.solve(m[np.ix_(r, r)], m[np.ix_(r, w)])
    # inverse form M v = mu K v: the lowest frequencies are the largest mu, computed to
    # round-off relative to themselves (K w v = lambda M v loses ~1e-8 at 80 elements)
    mu = eigh(m_ww, k_ww, eigvals_only=True)
    if mu[0] <= 0:
        raise RuntimeError("non-positive eigenvalue")
    return np.sort(1.0 / np.sqrt(mu))


# --------------------------------------------------------------------------------------------
# geometrically exact rigid finite elements

def _chain(beam: BeamSpec, b: float, n_elements: int):
    """Constants of one beam's rigid-link chain (link 0 from the hub centre)."""
    rho, ei = float(beam.linear_density), float(beam.bending_stiffness)
    x = _mesh(beam, n_elements)
    h = np.diff(x)
    n = len(h)
    springs = x[:-1] + h / 2.0
    starts = np.concatenate([[0.0], springs])
    ends = np.concatenate([springs, [x[-1]]])
    lengths = np.concatenate([[b + ends[0]], ends[1:] - starts[1:]])
    mass = rho * (ends - starts)
    first = np.empty(n + 1)
    second = np.empty(n + 1)
    first[0] = rho * ((b + ends[0]) ** 2 - b ** 2) / 2.0
    second[0] = rho * ((b + ends[0]) ** 3 - b ** 3) / 3.0
    first[1:] = mass[1:] * lengths[1:] / 2.0
    second[1:] = mass[1:] * lengths[1:] ** 2 / 3.0
    for mk, d in beam.masses:
        mk, d = float(mk), float(d)
        i = min(int(np.searchsorted(ends, d, side="left")) if d > 0 else 0, n)
        r = (b + d) if i == 0 else (d - starts[i])
        mass[i] += mk
        first[i] += mk * r
        second[i] += mk * r * r
    beyond = np.concatenate([np.cumsum(mass[::-1])[::-1][1:], [0.0]])
    g = first + lengths * beyond
    a = np.empty((n + 1, n + 1))
    for j in range(n + 1):
        a[j, j] = second[j] + lengths[j] ** 2 * beyond[j]
        kk = np.arange(j + 1, n + 1)
        a[j, kk] = lengths[j] * g[kk]
        a[kk, j] = a[j, kk]
    kmat = np.zeros((n + 1, n + 1))
    idx = np.arange(n)
    stiff = ei / h
    kmat[idx, idx] += stiff
    kmat[idx + 1, idx + 1] += stiff
    kmat[idx, idx + 1] -= stiff
    kmat[idx + 1, idx] -= stiff
    mids = 0.5 * (starts[1:] + ends[1:])
    return dict(n=n, a=a, k=kmat, g=g, lengths=lengths, mass=mass.sum(), mids=mids,
                b=b, l=float(beam.length))


class _Multibody:
    """Several rigid-link chains on one hub (internal).

    Extended coordinates ``z = [X, Y, beta_1 (chain 1 links), beta_2 ...]`` with ``beta`` the
    inertial link angles; generalized ``q = [X, Y (free only), theta, psi_11.. psi_1n1, ...]``
    and ``z = z_0 + Q q`` with ``z_0`` the mounting angles.
    """

    def __init__(self, system: MultiSystem, n_elements: int):
        self.system = system
        self.free = system.support == "free"
        self.chains = [_chain(beam, system.root_radius(beam), n_elements)
                       for beam in system.beams]
        n_phi = sum(c["n"] + 1 for c in self.chains)
        n_rigid = 3 if self.free else 1
        n_gen = n_rigid + sum(c["n"] for c in self.chains)
        i_theta = n_rigid - 1
        q_mat = np.zeros((2 + n_phi, n_gen))
        if self.free:
            q_mat[0, 0] = q_mat[1, 1] = 1.0
        alpha = np.zeros(n_phi)
        a = np.zeros((n_phi, n_phi))
        k = np.zeros((n_phi, n_phi))
        g = np.zeros(n_phi)
        blocks, gen_blocks = [], []
        row, col = 0, n_rigid
        for beam, c in zip(system.beams, self.chains):
            size = c["n"] + 1
            sl = slice(row, row + size)
            blocks.append(sl)
            gen_blocks.append(slice(col, col + c["n"]))
            alpha[sl] = float(beam.angle)
            a[sl, sl] = c["a"]
            k[sl, sl] = c["k"]
            g[sl] = c["g"]
            q_mat[2 + row, i_theta] = 1.0
            q_mat[2 + row + 1: 2 + row + size, col: col + c["n"]] = np.eye(c["n"])
            row += size
            col += c["n"]
        self.n_phi, self.n_gen, self.i_theta = n_phi, n_gen, i_theta
        self.q = q_mat
        self.q_phi = q_mat[2:]
        # Q has one 1 per row (none on a pinned hub's X, Y rows): products by index
        self.phi_gen = np.argmax(self.q_phi, axis=1)       # generalized index of each link
        self.ext_rep = np.argmax(q_mat, axis=0)            # one extended row per coordinate
        link0 = 2 + np.array([sl.start for sl in blocks])
        self.extra = link0[1:]                              # further rows mapped to theta
        self.alpha, self.a, self.k, self.g = alpha, a, k, g
        self.k_gen = self.q_phi.T @ k @ self.q_phi
        self.blocks, self.gen_blocks = blocks, gen_blocks
        self.total_mass = system.total_mass
        self.hub_inertia = float(system.hub_inertia)

    # -- mechanics --------------------------------------------------------------------------

    def parts(self, q, w):
        """Generalized mass matrix, force without the torque, and the pieces for the Jacobian."""
        beta = self.alpha + q[self.phi_gen]
        om = w[self.phi_gen]
        e = np.exp(1j * beta)
        c, s = e.real, e.imag
        cm = np.zeros((self.n_phi, self.n_phi))          # A_ab cos(beta_a - beta_b)
        sm = np.zeros((self.n_phi, self.n_phi))          # A_ab sin(beta_a - beta_b)
        for sl in self.blocks:                           # A is block diagonal
            both = self.a[sl, sl] * np.outer(e[sl], e[sl].conj())
            cm[sl, sl], sm[sl, sl] = both.real, both.imag
        gperp = np.vstack([-s, c]) * self.g              # columns g_a u_a^perp
        gu = np.vstack([c, s]) * self.g                  # columns g_a u_a
        m_ext = np.empty((2 + self.n_phi, 2 + self.n_phi))
        m_ext[:2, :2] = self.total_mass * np.eye(2)
        m_ext[:2, 2:] = gperp
        m_ext[2:, :2] = gperp.T
        m_ext[2:, 2:] = cm
        f_ext = np.concatenate([gu @ (om * om), -sm @ (om * om)])
        m_gen = self._rows(self._cols(m_ext))
        m_gen[self.i_theta, self.i_theta] += self.hub_inertia
        f_gen = self._rows(f_ext) - self.k_gen @ q
        return m_gen, f_gen, (cm, sm, gperp, gu, om)

    def jacobian(self, pieces, acc):
        """``d(f - M acc)/dq`` and ``d(f - M acc)/dw`` at the acceleration ``acc``."""
        cm, sm, gperp, gu, om = pieces
        ax = acc[:2] if self.free else np.zeros(2)
        a_ext = np.concatenate([ax, acc[self.phi_gen]])
        ax, aphi = a_ext[:2], a_ext[2:]
        om2 = om * om
        jp = np.empty((2 + self.n_phi, self.n_phi))          # d/d beta
        jp[:2] = gperp * om2 + gu * aphi
        ang = -self.k + cm * om2[None, :] - sm * aphi[None, :]
        ang[np.diag_indices_from(ang)] += -(cm @ om2) + sm @ aphi + ax @ gu
        jp[2:] = ang
        jw = np.empty((2 + self.n_phi, self.n_phi))
        jw[:2] = 2.0 * gu * om
        jw[2:] = -2.0 * sm * om[None, :]
        # f_gen holds -K_gen q; jp[2:] holds -K in the link angles, which projects to -K_gen
        return self._rows(self._cols(jp, 2)), self._rows(self._cols(jw, 2))

    def _rows(self, mat):
        """``Q^T mat``."""
        out = mat[self.ext_rep]
        out[self.i_theta] += mat[self.extra].sum(axis=0)
        return out

    def _cols(self, mat, offset=0):
        """``mat Q`` (``offset=0``) or ``mat Q_phi`` (``offset=2``)."""
        out = mat[:, self.ext_rep - offset]
        out[:, self.i_theta] += mat[:, self.extra - offset].sum(axis=1)
        return out

    def observe(self, q, w):
        """Outputs of one state."""
        m_gen, _, pieces = self.parts(q, w)
        beta = self.alpha + q[self.phi_gen]
        p_gen = m_gen @ w
        if self.free:
            rc, vc = q[:2], w[:2]
            momentum = p_gen[:2]
        else:
            rc, vc = np.zeros(2), np.zeros(2)
            _, _, gperp, _, om = pieces
            momentum = gperp @ om
        h_o = p_gen[self.i_theta:].sum() + (rc[0] * momentum[1] - rc[1] * momentum[0])
        energy = 0.5 * w @ p_gen + 0.5 * q @ self.k_gen @ q
        first = np.array([self.g @ np.cos(beta), self.g @ np.sin(beta)])
        com = rc + first / self.total_mass
        theta = q[self.i_theta]
        tips = []
        for beam, c, sl in zip(self.system.beams, self.chains, self.blocks):
            rel = beta[sl][1:] - beta[sl][0]
            ln = c["lengths"][1:]
            tips.append((c["lengths"][0] + ln @ np.cos(rel), ln @ np.sin(rel)))
        return dict(theta=theta, theta_dot=w[self.i_theta], x=rc[0], y=rc[1],
                    x_dot=vc[0], y_dot=vc[1], energy=energy, momentum=momentum,
                    angular_momentum=h_o, com=com, tips=tips)


def chain_linear_frequencies(system: MultiSystem, n_elements: int = 64, hub: str = "free"):
    """Frequencies of the rigid-finite-element chain model linearised at rest, rad/s.

    The mass matrix of :func:`simulate_multibody`'s model at the undeformed state and its
    spring stiffness; the hub coordinates are eliminated as in :func:`linear_frequencies`
    (``hub="free"``) or held (``"clamped"``). Converges as ``1 / n^2`` to the Hermite values:
    an independent check of both discretizations and of the free hub's coupling terms.
    """
    body = _Multibody(system, n_elements)
    m, _, _ = body.parts(np.zeros(body.n_gen), np.zeros(body.n_gen))
    # link angles relative to the hub (psi - theta): the springs then act on them only
    t = np.eye(body.n_gen)
    t[body.i_theta + 1:, body.i_theta] = 1.0
    m, k = t.T @ m @ t, t.T @ body.k_gen @ t
    r = np.arange(body.i_theta + 1)
    w = np.arange(body.i_theta + 1, body.n_gen)
    assert np.max(np.abs(k[np.ix_(r, r)])) < 1e-9 * np.max(np.abs(k))
    m_ww, k_ww = m[np.ix_(w, w)], k[np.ix_(w, w)]
    if hub == "free":
        m_ww = m_ww - m[np.ix_(w, r)] @ np.linalg.solve(m[np.ix_(r, r)], m[np.ix_(r, w)])
    elif hub != "clamped":
        raise ValueError("hub must be 'clamped' or 'free'")
    mu = eigh(m_ww, k_ww, eigvals_only=True)
    return np.sort(1.0 / np.sqrt(mu))


class _Arrow:
    """Inverse of an arrowhead matrix ``[[Z_rr, Z_rb], [Z_br, D]]``: the hub coordinates
    ``r`` couple to everything, each beam's block of ``D`` only to itself and to ``r`` (the
    structure of the mass matrix and of the Jacobians). Built from small per-beam inverses and
    the Schur complement ``S = Z_rr - Z_rb D^-1 Z_br``, which keeps it out of the multithreaded
    BLAS regime that crawls on a loaded machine; applied as one dense product."""

    def __init__(self, z, n_rigid, blocks):
        n = z.shape[0]
        r = slice(0, n_rigid)
        inv = np.zeros((n, n))
        y = np.empty((n - n_rigid, n_rigid))          # D^-1 Z_br
        w = np.empty((n_rigid, n - n_rigid))          # Z_rb D^-1
        for sl in blocks:
            dk = np.linalg.inv(z[sl, sl])
            inv[sl, sl] = dk
            y[sl.start - n_rigid: sl.stop - n_rigid] = dk @ z[sl, r]
            w[:, sl.start - n_rigid: sl.stop - n_rigid] = z[r, sl] @ dk
        si = np.linalg.inv(z[r, r] - z[r, n_rigid:] @ y)
        inv[r, r] = si
        inv[r, n_rigid:] = -si @ w
        inv[n_rigid:, r] = -y @ si
        inv[n_rigid:, n_rigid:] += y @ (si @ w)
        self.inv = inv

    def solve(self, v):
        return self.inv @ v


def clamped_first_frequency(beam: BeamSpec) -> float:
    """First clamped-free frequency of the bare beam, rad/s."""
    return 1.8751041 ** 2 * np.sqrt(beam.bending_stiffness
                                    / (beam.linear_density * beam.length ** 4))


def simulate_multibody(system: MultiSystem, t_final: float, *, torque=None, dt=None,
                       n_elements: int = 32, t_eval=None, tol: float = 1e-10,
                       initial_theta_dot: float = 0.0, initial_slopes=None) -> dict:
    """Simulate the geometrically exact rigid-finite-element model of the structure.

    Parameters
    ----------
    system : MultiSystem
    t_final : float
        End time, s.
    torque : callable, optional
        ``t -> T_h`` on the hub, N m. Default 0.
    dt : float, optional
        Time step of the implicit midpoint rule. Default ``T_1 / 1000`` with ``T_1`` the
        shortest first clamped period among the beams (phase error of the first mode about
        3e-6 per period); take ``T_1 / 4000`` for a torque with jumps, and make the jumps
        fall on step boundaries (the torque is sampled at step midpoints).
    n_elements : int
        Elements per beam (point masses on nodes). Errors fall as ``1 / n^2``; extrapolate two
        meshes (``fine + (fine - coarse) / 3`` for ``n`` and ``2n``) for a converged history.
        Measured on the 3 s manoeuvres of ``tests/model/test_structure_fe.py`` (tips bent 6-13 % of
        their length): 32 against 64 elements differ by 0.5e-3 to 1.5e-3 of each tip's peak;
        the extrapolations from (16, 32) and from (32, 64) differ by at most 1e-4 of the peak
        (0.25e-3 from 64 elements alone to the extrapolation).
    t_eval : array_like, optional
        Output times (outputs of the state interpolated linearly between steps: error about
        ``(omega dt)^2 / 8`` of an amplitude, 5e-6 with the default step); default every step.
    tol : float
        Newton tolerance, relative to the largest rate plus the first clamped frequency.
    initial_theta_dot : float
        Initial hub rate (the structure is otherwise at rest and undeformed unless
        ``initial_slopes`` is given; a free hub's centre starts at rest).
    initial_slopes : sequence of callables or None, optional
        Per beam ``s -> psi(s)`` (rad), the initial slope angle against arc length in the
        beam's mounting frame; ``None`` entries leave a beam straight.

    Returns
    -------
    dict
        ``'t'``, ``'theta'``, ``'theta_dot'``, ``'hub_x'``, ``'hub_y'`` (hub centre, m; zero
        for a pinned hub), ``'tip_deflection'`` (array (n_beams, P): each tip's transverse
        position in its own mounting frame, m), ``'tip_axial'`` (its axial position from the hub
        centre, m), ``'energy'`` (J), ``'momentum'`` ((2, P), kg m/s; for a pinned hub the
        momentum of the moving mass, i.e. the time integral of the support reaction),
        ``'angular_momentum'`` (about the inertial origin, kg m^2/s), ``'com'`` ((2, P),
        centre of mass, m), ``'torque'``, ``'n_elements'``, ``'dt'``, ``'cpu_time'``,
        ``'newton_iterations'``.
    """
    body = _Multibody(system, n_elements)
    drive = torque if torque is not None else (lambda t: 0.0)
    omega1 = max(clamped_first_frequency(b) for b in system.beams)
    if dt is None:
        dt = 2.0 * np.pi / omega1 / 1000.0
    q0 = np.zeros(body.n_gen)
    w0 = np.zeros(body.n_gen)
    w0[body.i_theta] = float(initial_theta_dot)
    if initial_slopes is not None:
        for c, gsl, slope in zip(body.chains, body.gen_blocks, initial_slopes):
            if slope is not None:
                q0[gsl] = [float(slope(s)) for s in c["mids"]]
    # the links' inertial rates equal the hub rate initially (no deformation rate)
    w0[body.i_theta + 1:] = float(initial_theta_dot)
    it = body.i_theta

    def factor(z):
        return _Arrow(z, it + 1, body.gen_blocks)

    def problem(t, q, w, with_jac):
        m_gen, f_gen, pieces = body.parts(q, w)
        f_gen[it] += drive(t)
        if not with_jac:
            return m_gen, f_gen
        jq, jw = body.jacobian(pieces, factor(m_gen).solve(f_gen))
        return m_gen, f_gen, jq, jw

    start = time.process_time()
    t_steps, qs, ws, n_it, _, dt = _midpoint(problem, q0, w0, t_final, dt, tol, omega1, factor)
    cpu = time.process_time() - start
    if t_eval is not None:          # outputs of the linearly interpolated state
        t = np.asarray(t_eval, dtype=float)
        qs = np.column_stack([np.interp(t, t_steps, col) for col in qs.T])
        ws = np.column_stack([np.interp(t, t_steps, col) for col in ws.T])
    else:
        t = t_steps
    obs = [body.observe(qs[j], ws[j]) for j in range(len(t))]
    out = {
        "t": t,
        "theta": np.array([o["theta"] for o in obs]),
        "theta_dot": np.array([o["theta_dot"] for o in obs]),
        "hub_x": np.array([o["x"] for o in obs]),
        "hub_y": np.array([o["y"] for o in obs]),
        "tip_deflection": np.array([[o["tips"][k][1] for o in obs]
                                    for k in range(len(system.beams))]),
        "tip_axial": np.array([[o["tips"][k][0] for o in obs]
                               for k in range(len(system.beams))]),
        "energy": np.array([o["energy"] for o in obs]),
        "momentum": np.array([o["momentum"] for o in obs]).T,
        "angular_momentum": np.array([o["angular_momentum"] for o in obs]),
        "com": np.array([o["com"] for o in obs]).T,
        "torque": np.array([drive(tt) for tt in t]),
    }
    out.update(n_elements=n_elements, dt=dt, cpu_time=cpu, newton_iterations=n_it)
    return out


def torque_impulse(t, torque_values):
    """Trapezoidal integral of sampled torque values (for momentum checks)."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (torque_values[1:] + torque_values[:-1])
                                            * np.diff(t))])
