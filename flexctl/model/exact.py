"""Geometrically exact kinematics of the hub-beam-mass system (:ref:`section 4.5 of the model
<sec-exact>`).

The beam is inextensible and described by its slope angle in the hub frame,
``psi(s, t) = sum_i q_i phi_i'(s)`` on the same cantilever modes as the other variants, so that
``q`` means the same thing and the variants agree to first order. Positions are exact,

    p(s) = ( b + int_0^s cos psi,  int_0^s sin psi ),

and the equations of motion follow from the principle of virtual work with the exact inertial
acceleration of every beam point and point mass,

    a = p_tt + theta_tt e_z x p + 2 theta_t e_z x p_t - theta_t^2 p,
    p_t = J(s) q_t,   p_tt = J(s) q_tt + (-int_0^s cos psi psi_t^2, -int_0^s sin psi psi_t^2),

with ``J(s) = dp/dq`` (2 x N). Bending energy ``EI/2 int psi_s^2 = 1/2 q^T K_ff q`` is exact on
these modes. The result is ``M(q) [theta_tt; q_tt] = [T_h - c_h theta_t - b_theta;
-K_ff q - C_ff q_t - b_q]``, with::

    M_theta_theta = J_h + int rhoA |p|^2 + sum_k m_k |p_k|^2
    M_theta_q     = int rhoA (p_x J_y - p_y J_x) + sum_k ...
    M_qq          = int rhoA (J_x^T J_x + J_y^T J_y) + sum_k ...

``M(q)`` is the kinetic-energy metric of the whole structure, positive definite for any hub
inertia (``J_h = 0`` included): the beam carries inertia. Expanded to second order in ``q`` the
equations are those of the consistent variant; linearised about a steady spin they are
first_order's (the tests pin both).

The inner integrals ``int_0^s`` and the outer ones ``int_0^l`` use Gauss-Legendre panels
(:class:`PanelRule`): the beam is cut into equal panels of ``P`` Gauss points each; inside a
panel the cumulative integral is that of the interpolating polynomial, and whole panels before
it add their Gauss sums. Every integral then costs ``O(n P)`` operations for ``n`` points
instead of the ``O(n^2)`` of one global polynomial, at the same accuracy. The rule (points per
panel and panels, a :class:`Quadrature`) is chosen per model (:func:`choose_rule`): the one of
fewest operations whose accelerations at two strongly deflected, fast test states agree with
those of a converged reference rule to :data:`PANEL_TOLERANCE`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import NamedTuple

import numpy as np

from .checks import check_instance, check_integer, check_real
from .errors import InputTypeError, InputValueError
from .layout import StateLayout
from .modes import mode_shapes
from .parameters import HubBeam

__all__ = ["EXACT_MAX_MODES", "PanelRule", "Quadrature", "choose_rule",
           "appendage_terms", "vectorized_rhs", "symmetric_solve",
           "VELOCITY_FROM_JACOBIAN", "PANEL_TOLERANCE", "POINT_CANDIDATES", "PANEL_CANDIDATES",
           "REFERENCE_POINTS", "reference_rule"]

#: Most modes the exact variant takes (20 modes: a 445k-instruction right-hand side, 4 s to build).
EXACT_MAX_MODES = 24
#: Largest difference of a chosen rule's accelerations from the reference rule's at each test
#: state, relative to their largest entry. The rule's error is part of the model's, so it is
#: held far below the error of truncating the beam to its modes: with rules chosen at 1e-5
#: rather than 1e-6, the tip deflection of hub-beam-mass (sine torques of 2, 8 and 20 N m,
#: peaks of up to 80 % of the length), slew-90 under a PD law, Kane's spin-up and
#: spacecraft-torque on 4, 6 and 8 modes moved by at most 8e-9 of its peak (2e-6 on
#: spacecraft-torque), where going from 6 to 8 modes moved it by 1.7e-5 to 4.3e-3; the rule
#: for 6 modes then has 28 nodes rather than 33, and a quarter fewer operations.
PANEL_TOLERANCE = 1e-5
#: Candidate Gauss points per panel.
POINT_CANDIDATES = tuple(range(4, 17))
#: Most Gauss points per panel and most panels of a :class:`PanelRule`.
MAX_POINTS, MAX_PANELS = 64, 1024
#: Candidate panel counts.
PANEL_CANDIDATES = (1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64)
#: Most modes for which the scalar form computes the beam's velocities as ``J q_t`` rather
#: than integrating them along the beam.
VELOCITY_FROM_JACOBIAN = 8
#: Tip deflection of the test state on which the panel count is chosen, relative to the length.
TEST_DEFLECTION = 0.4


class Quadrature(NamedTuple):
    """Size of a :class:`PanelRule`: Gauss points per panel and equal panels along the beam.

    Parameters
    ----------
    points : int
        Gauss-Legendre points per panel (1 to :data:`MAX_POINTS`).
    panels : int
        Equal panels along the beam (1 to :data:`MAX_PANELS`).
    """

    points: int
    panels: int

    @classmethod
    def checked(cls, owner: str, value) -> "Quadrature":
        """``value`` as a Quadrature, or a clear error naming ``owner``.

        Parameters
        ----------
        owner : str
            Who takes the rule: the messages name ``owner.quadrature``.
        value : tuple of (int, int)
            ``(points, panels)``: Gauss points per panel (1 to :data:`MAX_POINTS`) and equal panels
            (1 to :data:`MAX_PANELS`).
        """
        if not isinstance(value, tuple) or len(value) != 2:
            raise InputTypeError(f"{owner}.quadrature must be a Quadrature(points, panels); "
                                 f"got {value!r} of type {type(value).__name__}"[:300])
        return cls(check_integer(owner, "quadrature.points", value[0], minimum=1,
                                 maximum=MAX_POINTS),
                   check_integer(owner, "quadrature.panels", value[1], minimum=1,
                                 maximum=MAX_PANELS))


#: Gauss points per panel of the rule every candidate is compared with, on
#: :func:`reference_rule` panels.
REFERENCE_POINTS = 12


def reference_rule(n_modes: int) -> Quadrature:
    """The rule the candidates on ``n_modes`` modes are compared with: some 36 points per half
    wave of the fastest mode's slope (``3 N`` panels of :data:`REFERENCE_POINTS`, at least 4
    and at most 64), converged far below :data:`PANEL_TOLERANCE`.

    Parameters
    ----------
    n_modes : int
        Cantilever modes of the beam, ``N``.
    """
    return Quadrature(REFERENCE_POINTS, min(64, max(4, 3 * n_modes)))


@dataclass(frozen=True, eq=False)
class PanelRule:
    """Composite Gauss-Legendre rule on ``[0, length]`` that also integrates from the root.

    Inside a panel the integral from the panel's start to each node is that of the
    polynomial through the panel's values. The nodes lie in mirror pairs about the panel's
    centre (and one at the centre for odd ``points``), so the polynomial is split into its even
    part, whose integral from the centre is odd, and its odd part, whose integral is even:
    each half is a matrix of half the size, on the pair sums ``E`` and differences ``O``
    (:meth:`integrate`), about half the operations of the full matrix. Vectorized (MX)
    expressions take the whole-matrix form instead (``local``, ``panel_sums``,
    ``before``): one sparse product each, where the pairs' gathers would add operations.

    Attributes
    ----------
    n_panels : int
    length : float
        Beam length, m.
    points : int
        Gauss points per panel.
    nodes : ndarray, shape (n,)
        Gauss points, ascending, m (``n = n_panels * points``).
    weights : ndarray, shape (n,)
        Weights of ``int_0^l``, m.
    left, right : ndarray of int, shape (n_pairs,)
        Each pair's node before the panel's centre and its mirror image.
    centre : ndarray of int, shape (n_panels,) or (0,)
        The node at each panel's centre (odd ``points``).
    even, odd : ndarray, shape (n_half, n_half_e), (n_half, n_pairs)
        From ``E`` (the pair sums, then the centre values) and ``O`` (the pair differences) to
        the integrals from the panel's start at the left nodes and the centres
        (``n_half = n_pairs + centre.size``): ``even @ E + odd @ O``.
    sums : ndarray, shape (n_panels, n_half_e)
        Gauss sum of each whole panel from ``E``.
    before_half, upto_right : ndarray, shape (n_half, n_panels), (n_pairs, n_panels)
        1 on the whole panels before each left or centre node; on the panels up to and
        including each right node's own.
    order : ndarray of int, shape (n,)
        Where each node's integral lies in ``[left and centre nodes; right nodes]``.
    """

    n_panels: int
    length: float
    points: int
    nodes: np.ndarray
    weights: np.ndarray
    left: np.ndarray
    right: np.ndarray
    centre: np.ndarray
    even: np.ndarray
    odd: np.ndarray
    sums: np.ndarray
    before_half: np.ndarray
    upto_right: np.ndarray
    order: np.ndarray

    @classmethod
    def build(cls, n_panels: int, length: float, points: int) -> "PanelRule":
        """The rule of ``n_panels`` equal panels of ``points`` Gauss points on
        ``[0, length]``, built once per size (cached).

        Parameters
        ----------
        n_panels : int
            Number of equal panels, 1 to :data:`MAX_PANELS`.
        length : float
            Beam length, m (> 0).
        points : int
            Gauss points per panel, 1 to :data:`MAX_POINTS`.
        """
        owner = "PanelRule.build"
        return cls._build(check_integer(owner, "n_panels", n_panels, minimum=1,
                                        maximum=MAX_PANELS),
                          check_real(owner, "length", length, minimum=0.0, strict=True),
                          check_integer(owner, "points", points, minimum=1, maximum=MAX_POINTS))

    @classmethod
    @lru_cache(maxsize=256)
    def _build(cls, n_panels: int, length: float, points: int) -> "PanelRule":
        g, w = np.polynomial.legendre.leggauss(points)
        half = 0.5 * length / n_panels
        nodes = np.concatenate([(2 * p + 1 + g) * half for p in range(n_panels)])
        n, h = n_panels * points, points // 2
        starts = points * np.arange(n_panels)
        left = (starts[:, None] + np.arange(h)[None, :]).ravel()
        right = (starts[:, None] + points - 1 - np.arange(h)[None, :]).ravel()
        centre = starts + h if points % 2 else np.zeros(0, dtype=int)
        # E = [f(left) + f(right); f(centre)], O = f(left) - f(right); from_e, from_o give f
        # from them for an even and an odd f
        from_e = np.zeros((n, left.size + centre.size))
        from_o = np.zeros((n, left.size))
        pairs = np.arange(left.size)
        from_e[left, pairs] = from_e[right, pairs] = 0.5
        from_e[centre, left.size + np.arange(centre.size)] = 1.0
        from_o[left, pairs], from_o[right, pairs] = 0.5, -0.5
        whole = np.kron(np.eye(n_panels), _local(points, half))
        first = np.concatenate([left, centre])
        panel = np.arange(n) // points
        below = panel[:, None] > np.arange(n_panels)[None, :]
        arrays = dict(nodes=nodes, weights=np.tile(half * w, n_panels), left=left, right=right,
                      centre=centre, even=(whole @ from_e)[first], odd=(whole @ from_o)[first],
                      sums=np.kron(np.eye(n_panels), half * w[None, :]) @ from_e,
                      before_half=below[first].astype(float),
                      upto_right=(panel[right][:, None] >= np.arange(n_panels)[None, :]
                                  ).astype(float),
                      order=np.argsort(np.concatenate([first, right])))
        for a in arrays.values():             # shared by every caller of the cached rule
            a.setflags(write=False)
        return cls(n_panels=n_panels, length=length, points=points, **arrays)

    def integrate(self, f):
        """``(F, S)``: ``F`` (n, c) the integrals from the root to every node of the columns
        of ``f`` (n, c; CasADi or numpy), ``S`` (n_panels, c) their whole-panel sums.

        Parameters
        ----------
        f : casadi.SX, casadi.MX or ndarray, shape (n, c)
            Values of ``c`` integrands at the :attr:`nodes`, in their own unit; the integrals
            are in that unit times m. An MX ``f`` takes the whole-matrix form.
        """
        import casadi as ca

        if isinstance(f, ca.MX):
            sums = ca.mtimes(self.sparse('panel_sums'), f)
            return (ca.mtimes(self.sparse('local'), f)
                    + ca.mtimes(self.sparse('before'), sums), sums)
        left, right = list(map(int, self.left)), list(map(int, self.right))
        pair_sums = f[left, :] + f[right, :]
        e = ca.vertcat(pair_sums, f[list(map(int, self.centre)), :]) if self.centre.size \
            else pair_sums
        o = f[left, :] - f[right, :]
        sums = ca.mtimes(self.sparse('sums'), e)
        from_even = ca.mtimes(self.sparse('even'), e)
        from_odd = ca.mtimes(self.sparse('odd'), o)
        n_pairs = len(left)
        first = from_even + from_odd + ca.mtimes(self.sparse('before_half'), sums)
        second = ca.mtimes(self.sparse('upto_right'), sums) - from_even[:n_pairs, :] \
            + from_odd[:n_pairs, :]
        return ca.vertcat(first, second)[list(map(int, self.order)), :], sums

    def sparse(self, name: str):
        """The matrix attribute ``name`` as a sparse CasADi ``DM`` (converted once).

        Parameters
        ----------
        name : str
            A matrix attribute or property of the rule: ``"even"``, ``"odd"``, ``"sums"``,
            ``"before_half"``, ``"upto_right"``, ``"local"``, ``"panel_sums"`` or
            ``"before"``.
        """
        key = ("sparse", name)
        if key not in self._converted:
            self._converted[key] = _sparse(getattr(self, name))
        return self._converted[key]

    def slopes(self, n_modes: int):
        """``phi_i'(s)`` of the first ``n_modes`` cantilever modes at the nodes, a CasADi
        ``DM`` (n, n_modes), 1/m (computed once).

        Parameters
        ----------
        n_modes : int
            Cantilever modes, ``N``, of a beam of the rule's length.
        """
        import casadi as ca

        key = ("slopes", n_modes)
        if key not in self._converted:
            self._converted[key] = ca.DM(mode_shapes(n_modes, self.nodes / self.length,
                                                     derivative=1, length=self.length).T)
        return self._converted[key]

    @cached_property
    def _converted(self) -> dict:
        """What :meth:`sparse` and :meth:`slopes` computed, kept with the (shared) rule."""
        return {}

    @cached_property
    def local(self) -> np.ndarray:
        """Block diagonal (n, n): ``(local @ f)[j]`` integrates ``f`` from the start of the
        panel of ``nodes[j]`` to ``nodes[j]``."""
        return np.kron(np.eye(self.n_panels),
                       _local(self.points, 0.5 * self.length / self.n_panels))

    @cached_property
    def panel_sums(self) -> np.ndarray:
        """Gauss sum of each whole panel from the nodes' values, shape (n_panels, n)."""
        return np.kron(np.eye(self.n_panels), np.reshape(self.weights[:self.points], (1, -1)))

    @cached_property
    def before(self) -> np.ndarray:
        """1 where the panel lies wholly before ``nodes[j]``, shape (n, n_panels)."""
        panel = np.arange(self.nodes.size) // self.points
        return (panel[:, None] > np.arange(self.n_panels)[None, :]).astype(float)

    def at(self, positions) -> tuple:
        """``(local, before)``: ``local @ f + before @ S`` (``S`` from :meth:`integrate`)
        integrates ``f`` from the root to each position (m); ``local`` (P, n) holds the
        position's own panel only, ``before`` (P, n_panels) is 1 on the whole panels before
        it.

        Parameters
        ----------
        positions : sequence of float, length P
            Distances from the root, m, in ``[0, length]``.
        """
        leg = np.polynomial.legendre
        h = self.length / self.n_panels
        local = np.zeros((len(positions), self.nodes.size))
        before = np.zeros((len(positions), self.n_panels))
        for k, s in enumerate(positions):
            p = min(int(s // h), self.n_panels - 1)
            xi = 2.0 * (s - p * h) / h - 1.0
            block = slice(p * self.points, (p + 1) * self.points)
            local[k, block] = 0.5 * h * leg.legvander(np.array([xi]), self.points) \
                @ _integrated(self.points)
            before[k, :p] = 1.0
        return local, before


@lru_cache(maxsize=64)
def _local_unit(points: int) -> np.ndarray:
    """``_local`` on a panel of half-width 1 (read-only)."""
    leg = np.polynomial.legendre
    local = leg.legvander(leg.leggauss(points)[0], points) @ _integrated(points)
    local.setflags(write=False)
    return local


def _local(points: int, half: float) -> np.ndarray:
    """(points, points): the integrals from a panel's start (of half-width ``half``, m) to
    each of its Gauss points of the polynomial through the values there."""
    return half * _local_unit(points)


@lru_cache(maxsize=64)
def _integrated(points: int) -> np.ndarray:
    """Legendre coefficients (rows, degree 0 to ``points``) of the integral from -1 of the
    polynomial through the values at ``points`` Gauss points (columns; read-only)."""
    leg = np.polynomial.legendre
    g = leg.leggauss(points)[0]
    out = leg.legint(np.linalg.inv(leg.legvander(g, points - 1)), lbnd=-1.0, axis=0)
    out.setflags(write=False)
    return out


def _sparse(a):
    import casadi as ca
    return ca.sparsify(ca.DM(a))


def appendage_terms(system, n_modes, quadrature, q, q_dot, rate) -> dict:
    """One beam's share of the exact equations in its own frame, as CasADi expressions.

    The frame is the beam's: its root at ``(b, 0)``, its axis along ``x``. Keys: ``m_tt``
    (scalar), ``m_tq`` (1, N), ``m_qq`` (N, N), ``b_t``, ``b_q`` (N,): the mass-matrix blocks
    and velocity terms of the pinned-hub equations; ``first`` (2,): the first moment
    ``int p dm``; ``first_q`` (2, N): its Jacobian ``int J dm``; ``first_acc`` (2,):
    ``int (p_tt at q_tt = 0) dm``; ``tip`` (2,): the tip position.

    Parameters
    ----------
    system : HubBeam
        The beam, its point masses and its root radius ``b`` (the hub's radius); the hub's
        inertia is left out: the caller adds it.
    n_modes : int
        Number of modes ``N``.
    quadrature : Quadrature
        Gauss points per panel and panels (:func:`choose_rule`).
    q, q_dot : casadi.SX, casadi.MX or casadi.DM, shape (N,)
        Modal coordinates (m) and their rates (m/s).
    rate : casadi.SX, casadi.MX or casadi.DM
        Hub rate ``theta_dot``, rad/s.
    """
    import casadi as ca

    b, l = system.hub.radius, system.beam.length
    quadrature = Quadrature.checked("appendage_terms", quadrature)
    rule = PanelRule.build(quadrature.panels, l, quadrature.points)
    slope_shapes = rule.slopes(n_modes)
    psi = ca.mtimes(slope_shapes, q)
    psi_t = ca.mtimes(slope_shapes, q_dot)
    cos, sin = ca.cos(psi), ca.sin(psi)
    # scalar form: the velocities as J q_t (2 N - 1 operations a point) where that is cheaper
    # than integrating their own integrands
    velocities_from_jacobian = isinstance(q, ca.SX) and n_modes <= VELOCITY_FROM_JACOBIAN
    # integrands of p_x - b, p_y, [p_x_t, p_y_t,] and of the q_t^2 part of p_tt
    integrands = ca.horzcat(cos, sin, -cos * psi_t ** 2, -sin * psi_t ** 2,
                            *(() if velocities_from_jacobian else (-sin * psi_t, cos * psi_t)))
    jac_x = -ca.repmat(sin, 1, n_modes) * slope_shapes
    jac_y = ca.repmat(cos, 1, n_modes) * slope_shapes
    # every integrand's integrals from the root and whole-panel sums, the latter shared by the
    # point masses and the tip
    along = [rule.integrate(f) for f in (integrands, jac_x, jac_y)]
    tip = ca.vertcat(b + ca.sum1(along[0][1][:, 0]), ca.sum1(along[0][1][:, 1]))
    mass_local, mass_before = (_sparse(a) for a in rule.at([m.position for m in system.masses]))

    def at_masses(f, f_sums):
        return ca.mtimes(mass_local, f) + ca.mtimes(mass_before, f_sums)

    # (weights, integral from the root) of the beam's points and of the point masses
    points = [(system.beam.linear_density * rule.weights, [f for f, _ in along])]
    if system.masses:
        points.append((np.array([m.mass for m in system.masses]),
                       [at_masses(f, f_sums) for f, (_, f_sums) in
                        zip((integrands, jac_x, jac_y), along)]))
    out = dict.fromkeys(("m_tt", "m_tq", "m_qq", "b_t", "b_q"), 0.0)
    out.update(first=ca.DM.zeros(2), first_q=ca.DM.zeros(2, n_modes), first_acc=ca.DM.zeros(2),
               tip=tip)
    for weights, (p, jx, jy) in points:
        w = ca.DM(weights)
        px, py, ax, ay = (p[:, k] for k in range(4))
        px = px + b
        if velocities_from_jacobian:
            pxt, pyt = ca.mtimes(jx, q_dot), ca.mtimes(jy, q_dot)
        else:
            pxt, pyt = p[:, 4], p[:, 5]
        wjx, wjy = ca.repmat(w, 1, n_modes) * jx, ca.repmat(w, 1, n_modes) * jy
        out["m_tt"] = out["m_tt"] + ca.dot(w, px ** 2 + py ** 2)
        out["m_tq"] = out["m_tq"] + ca.mtimes(px.T, wjy) - ca.mtimes(py.T, wjx)
        out["m_qq"] = out["m_qq"] + _gram(jx, wjx, jy, wjy)
        # velocity terms of the inertial acceleration: p_tt(q_tt = 0), Coriolis, centripetal
        gx = ax - 2.0 * rate * pyt - rate ** 2 * px
        gy = ay + 2.0 * rate * pxt - rate ** 2 * py
        out["b_t"] = out["b_t"] + ca.dot(w, px * gy - py * gx)
        out["b_q"] = out["b_q"] + ca.mtimes(wjx.T, gx) + ca.mtimes(wjy.T, gy)
        out["first"] = out["first"] + ca.vertcat(ca.dot(w, px), ca.dot(w, py))
        out["first_q"] = out["first_q"] + ca.vertcat(ca.sum1(wjx), ca.sum1(wjy))
        out["first_acc"] = out["first_acc"] + ca.vertcat(ca.dot(w, ax), ca.dot(w, ay))
    return out


def _gram(jx, wjx, jy, wjy):
    """``jx^T wjx + jy^T wjy``, symmetric: in scalar form (SX) each pair of modes once."""
    import casadi as ca

    if not isinstance(jx, ca.SX):
        return ca.mtimes(jx.T, wjx) + ca.mtimes(jy.T, wjy)
    n = jx.shape[1]
    entries = {(i, j): ca.dot(jx[:, i], wjx[:, j]) + ca.dot(jy[:, i], wjy[:, j])
               for i in range(n) for j in range(i, n)}
    return ca.blockcat([[entries[min(i, j), max(i, j)] for j in range(n)] for i in range(n)])


def symmetric_solve(matrix, rhs):
    """``matrix^-1 rhs`` by an ``L D L^T`` factorisation written out (about a third of the
    operations of CasADi's general symbolic solve).

    Parameters
    ----------
    matrix : casadi.SX, shape (n, n)
        Symmetric positive definite; only its upper triangle is read.
    rhs : casadi.SX, shape (n, 1)
        Right-hand side.

    Returns
    -------
    casadi.SX, shape (n, 1)
    """
    import casadi as ca

    n = matrix.shape[0]
    if matrix.shape != (n, n) or rhs.shape != (n, 1):
        raise InputValueError(f"symmetric_solve needs a square matrix and a right-hand side of "
                              f"its size; got shapes {matrix.shape} and {rhs.shape}")
    lower, diag = {}, []
    for j in range(n):
        d = matrix[j, j]
        for k in range(j):
            d = d - lower[j, k] * lower[j, k] * diag[k]
        diag.append(d)
        for i in range(j + 1, n):
            v = matrix[j, i]
            for k in range(j):
                v = v - lower[i, k] * lower[j, k] * diag[k]
            lower[i, j] = v / d
    y = []
    for i in range(n):
        v = rhs[i]
        for k in range(i):
            v = v - lower[i, k] * y[k]
        y.append(v)
    x = [None] * n
    for i in reversed(range(n)):
        v = y[i] / diag[i]
        for k in range(i + 1, n):
            v = v - lower[k, i] * x[k]
        x[i] = v
    return ca.vertcat(*x)


def _terms(system, n_modes, quadrature, q, q_dot, rate):
    """Mass matrix ``M(q)``, bias ``[b_theta; b_q]`` and tip position, as CasADi expressions."""
    import casadi as ca

    t = appendage_terms(system, n_modes, quadrature, q, q_dot, rate)
    mass = ca.blockcat([[system.hub.inertia + t["m_tt"], t["m_tq"]], [t["m_tq"].T, t["m_qq"]]])
    return mass, ca.vertcat(t["b_t"], t["b_q"]), t["tip"]


def _equations(system: HubBeam, matrices, quadrature, x, u):
    """``M(q)``, the generalized forces ``f`` of ``M(q) [theta_tt; q_tt] = f``, the velocity
    terms ``[b_theta; b_q]`` in them and the tip position at state ``x`` and torque ``u``:
    CasADi expressions of symbols or numbers."""
    import casadi as ca

    _, q, rate, q_dot = StateLayout.single(matrices.n_modes).split(x)
    mass, bias, tip = _terms(system, matrices.n_modes, quadrature, q, q_dot, rate)
    elastic = -ca.mtimes(ca.DM(matrices.K_ff), q) - ca.mtimes(ca.DM(matrices.C_ff), q_dot)
    return mass, ca.vertcat(u - system.hub.friction * rate, elastic) - bias, bias, tip


def _rhs(system: HubBeam, n_modes: int, quadrature, matrices, vectorized: bool = False):
    """``(x, u) -> xdot`` and the symbols and terms it was built from: SX (every node's
    arithmetic written out) or, ``vectorized``, MX (one operation per vector of nodes)."""
    import casadi as ca

    n, layout = n_modes, StateLayout.single(n_modes)
    sym = ca.MX if vectorized else ca.SX
    x = sym.sym("x", layout.n_states)
    u = sym.sym("u")
    mass, generalized, bias, tip = _equations(system, matrices, quadrature, x, u)
    if vectorized:
        # the small dense solve as scalar code (an MX solve needs a linear solver plugin)
        m_sym, g_sym = ca.SX.sym("M", n + 1, n + 1), ca.SX.sym("g", n + 1)
        solve = ca.Function(f"flexctl_exact_solve_N{n}", [m_sym, g_sym],
                            [symmetric_solve(m_sym, g_sym)])
        acc = solve(mass, generalized)
    else:
        acc = symmetric_solve(mass, generalized)
    name = f"flexctl_exact_{'vec_' if vectorized else ''}N{n}"
    rhs = ca.Function(name, [x, u], [ca.vertcat(x[layout.velocities], acc)],
                      ["x", "u"], ["xdot"], {} if vectorized else {"cse": True})
    return rhs, x, mass, bias, tip


def vectorized_rhs(system: HubBeam, n_modes: int, quadrature, matrices):
    """The exact right-hand side ``(x, u) -> xdot`` as an MX function of whole-vector
    operations: the nodes' slopes, integrands and Jacobian rows as vectors and matrices, the
    integrals as products with the constant (sparse) quadrature matrices, the mass-matrix
    blocks as matrix products. Its operation count, and so its generated code, does not depend
    on the number of quadrature nodes (only the constant tables grow with them).

    Parameters
    ----------
    system : HubBeam
        The hub, beam and point masses.
    n_modes : int
        Number of modes ``N``.
    quadrature : Quadrature
        Gauss points per panel and panels (:func:`choose_rule`).
    matrices : ModalMatrices
        The system's matrices on ``n_modes`` modes (:func:`~flexctl.model.matrices.assemble`),
        whose modal stiffness ``K_ff`` and damping ``C_ff`` the equations take.
    """
    quadrature = Quadrature.checked("vectorized_rhs", quadrature)
    return _rhs(system, n_modes, quadrature, matrices, vectorized=True)[0]


def _test_states(system: HubBeam, matrices) -> list:
    """Two strongly deflected, fast states: modal amplitudes falling as ``1 / i^4`` (as a
    static load spreads over the modes) with the hub turning at the first beam frequency, and
    as ``1 / i^2`` (the higher modes rung up) with the hub at three times it; each mode's tip
    deflection is ``TEST_DEFLECTION * l`` over that power of ``i``, its rate its amplitude
    times its own frequency."""
    n = matrices.n_modes
    i = np.arange(1, n + 1)
    omega = matrices.beam_frequencies
    states = []
    for power, spin in ((4, 1.0), (2, 3.0)):
        q = TEST_DEFLECTION * system.beam.length / np.abs(matrices.tip) / i ** power
        states.append(StateLayout.single(n).join(q=q, theta_dot=spin * omega[0],
                                                 q_dot=omega * q))
    return states


def choose_rule(system: HubBeam, matrices) -> Quadrature:
    """The quadrature of fewest operations that resolves the exact model on its modes.

    Candidates (:data:`POINT_CANDIDATES` points per panel times :data:`PANEL_CANDIDATES`
    panels) are tried in the order of their operation count (``_operations``); the first
    whose accelerations at each test state (``_test_states``) agree with those of
    :func:`reference_rule` within :data:`PANEL_TOLERANCE` (relative to the largest) is taken.
    A candidate with no more points per panel and no more panels than one that failed is
    skipped: it is no more accurate. The choice is kept per system and mode count (the
    appendages of a structure are often alike).

    Parameters
    ----------
    system : HubBeam
        The hub, beam and point masses modelled.
    matrices : ModalMatrices
        The system's assembled matrices (:func:`~flexctl.model.matrices.assemble`).
    """
    from .matrices import ModalMatrices

    check_instance("choose_rule", "system", system, HubBeam)
    check_instance("choose_rule", "matrices", matrices, ModalMatrices)
    if matrices.system != system:
        raise InputValueError("choose_rule.matrices must be assembled from choose_rule.system; "
                              "they describe another system")
    return _chosen(system, matrices.n_modes)


@lru_cache(maxsize=256)
def _chosen(system: HubBeam, n_modes: int) -> Quadrature:
    """:func:`choose_rule`'s search, once per ``(system, n_modes)``."""
    from .matrices import assemble

    matrices = assemble(system, n_modes)
    states = _test_states(system, matrices)
    reference = [_test_accelerations(system, matrices, reference_rule(matrices.n_modes), x)
                 for x in states]
    candidates = sorted((_operations(Quadrature(p, k), matrices.n_modes, len(system.masses)),
                         Quadrature(p, k)) for p in POINT_CANDIDATES for k in PANEL_CANDIDATES)
    failed: list = []
    for _, rule in candidates:
        if any(rule.points <= p and rule.panels <= k for p, k in failed):
            continue
        if all(_agrees(_test_accelerations(system, matrices, rule, x), r)
               for x, r in zip(states, reference)):
            return rule
        failed.append(rule)
    return reference_rule(matrices.n_modes)


def _agrees(accelerations, reference) -> bool:
    """Within :data:`PANEL_TOLERANCE` of ``reference``'s largest entry (False on NaN)."""
    scale = max(float(np.max(np.abs(reference))), np.finfo(float).tiny)
    return bool(np.max(np.abs(accelerations - reference)) <= PANEL_TOLERANCE * scale)


def _test_accelerations(system, matrices, quadrature, x) -> np.ndarray:
    """Accelerations ``[theta_tt, q_tt]`` at state ``x`` with the torque 1 N m on
    ``quadrature``, computed on numbers (no function is built); NaN where too few points make
    the mass matrix singular."""
    import casadi as ca

    mass, generalized, _, _ = _equations(system, matrices, quadrature, ca.DM(x), 1.0)
    try:
        return np.linalg.solve(np.array(mass), np.array(generalized).ravel())
    except np.linalg.LinAlgError:
        return np.full(matrices.n_modes + 1, np.nan)


def _operations(quadrature: Quadrature, n_modes: int, n_masses: int) -> float:
    """Estimated scalar operations of one right-hand side on ``quadrature``: the integrals
    from the root of every integrand (``2 N + 4`` of them: the two half-size local matrices
    of :meth:`PanelRule.integrate`, the panels before) and their values at the masses, and
    the per-point products."""
    points, panels = quadrature
    n = points * panels
    columns = 2 * n_modes + 4 + (2 if n_modes > VELOCITY_FROM_JACOBIAN else 0)
    integrals = columns * (n * (points + 3 + 0.5 * (panels - 1))
                           + n_masses * (2 * points + panels))
    return integrals + n * (2 * n_modes ** 2 + 16 * n_modes + 30)
