"""One rod of a spatial structure: its exact kinematics on the quadrature, its modal stiffness.

:class:`Rod` computes, for the modal coordinates of the three fields (bending along the normal
``qn``, along the lateral direction ``ql``, twist ``qt``), the section rotations along the rod
and their variations by recursion (``R_j^-1 dR_j = [delta_j]x``), the centreline's positions
and their derivatives at every node and point mass (:meth:`Rod.motion`): what
:mod:`flexctl.model.spatial_dynamics` assembles into Kane's equations. See that module for the
model.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .spatial_structure import SpatialAppendage

__all__ = ["Rod", "rod_shapes", "rod_rule", "elastic_matrices", "skew", "cross_matrix"]


def skew(a):
    """``[a]x``, the cross-product matrix of a 3-vector (CasADi).

    Parameters
    ----------
    a : casadi.SX, shape (3, 1)
        The vector ``a``: ``[a]x b = a x b``.

    Returns
    -------
    casadi.SX, shape (3, 3)
    """
    import casadi as ca

    return ca.vertcat(ca.horzcat(0, -a[2], a[1]), ca.horzcat(a[2], 0, -a[0]),
                      ca.horzcat(-a[1], a[0], 0))


def cross_matrix(a) -> np.ndarray:
    """``[a]x``, the cross-product matrix of a 3-vector, or of each of a stack of them (numpy
    form of :func:`skew`).

    Parameters
    ----------
    a : array_like, shape (..., 3)
        The vectors ``a``: ``[a]x b = a x b``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    a = np.asarray(a, dtype=float)
    out = np.zeros(a.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = a[..., 2], -a[..., 1], a[..., 0]
    return out


def _exp(omega):
    """Rodrigues' rotation ``exp([omega]x)``, regular at ``omega = 0`` (a Taylor form below
    ``|omega| = 1e-4``, where the closed form loses digits)."""
    import casadi as ca

    t2 = ca.dot(omega, omega)
    small = t2 < 1e-8
    # the closed form evaluated away from 0 where the Taylor form is taken: both branches of
    # an if_else and their derivatives are computed, and 0 * NaN would leak into the sum
    t = ca.sqrt(ca.if_else(small, 1.0, t2))
    a = ca.if_else(small, 1 - t2 / 6 + t2 * t2 / 120, ca.sin(t) / t)
    half = 0.5 * t
    b = ca.if_else(small, 0.5 - t2 / 24 + t2 * t2 / 720,
                   0.5 * (ca.sin(half) / half) ** 2)
    k = skew(omega)
    return ca.SX.eye(3) + a * k + b * ca.mtimes(k, k)


def _right_jacobian(omega):
    """``T(omega)`` with ``exp([omega]x)^-1 d exp([omega]x) = [T(omega) d omega]x``:
    ``I - b [omega]x + c [omega]x^2``, ``b = (1 - cos t) / t^2``, ``c = (t - sin t) / t^3``
    (Taylor forms below ``|omega| = 1e-4``)."""
    import casadi as ca

    t2 = ca.dot(omega, omega)
    small = t2 < 1e-8
    t = ca.sqrt(ca.if_else(small, 1.0, t2))
    half = 0.5 * t
    b = ca.if_else(small, 0.5 - t2 / 24 + t2 * t2 / 720, 0.5 * (ca.sin(half) / half) ** 2)
    c = ca.if_else(small, 1.0 / 6 - t2 / 120 + t2 * t2 / 5040, (t - ca.sin(t)) / (t * t2))
    k = skew(omega)
    return ca.SX.eye(3) - b * k + c * ca.mtimes(k, k)


@lru_cache(maxsize=1)
def _right_jacobian_and_rate():
    """``(omega, omega_t) -> (T(omega), dT/dt)`` as an SX function (its calls on SX
    arguments are written out inline)."""
    import casadi as ca

    omega, omega_t = ca.SX.sym("omega", 3), ca.SX.sym("omega_t", 3)
    right = _right_jacobian(omega)
    return ca.Function("right_jacobian", [omega, omega_t],
                       [right, ca.jtimes(right, omega, omega_t)])


@lru_cache(maxsize=64)
def rod_shapes(length: float, n_modes: int, nodes: tuple) -> dict:
    """The three fields' shapes at ``nodes`` (m, ascending, the root ``0`` first).

    Parameters
    ----------
    length : float
        Rod length, m.
    n_modes : int
        Modes per field.
    nodes : tuple of float
        Arc lengths, m.

    Returns
    -------
    dict
        ``slope`` and ``curvature`` (P, N): ``phi_i'`` and ``phi_i''`` of the cantilever modes
        (1/m, 1/m^2); ``twist`` and ``twist_rate`` (P, N): ``chi_k`` and ``chi_k'`` (1, 1/m).
    """
    from .modes import mode_shapes

    s = np.asarray(nodes, dtype=float)
    xi = np.clip(s / length, 0.0, 1.0)
    beta = (2 * np.arange(1, n_modes + 1) - 1) * np.pi / (2 * length)
    return {"slope": mode_shapes(n_modes, xi, derivative=1, length=length).T,
            "curvature": mode_shapes(n_modes, xi, derivative=2, length=length).T,
            "twist": np.sqrt(2.0) * np.sin(np.outer(s, beta)),
            "twist_rate": np.sqrt(2.0) * np.cos(np.outer(s, beta)) * beta}


def chain_step(rotation, delta, rate, accel, step, step_t, step_tt, step_jac) -> tuple:
    """One node of :meth:`Rod.chain`'s recursion: the product ``R_j = R_(j-1) E_j``,
    ``E_j = exp([Omega_j]x)``, the variations ``delta_j = E_j^T delta_(j-1) + T(Omega_j)
    dOmega_j / deta``, ``d_j = E^T d_(j-1) + T Omega_t`` and its rate at ``u_t = 0``
    (``E_t^T = -[turn]x E^T``) (CasADi).

    Parameters
    ----------
    rotation : casadi.SX, shape (3, 3)
        ``R_(j-1)``.
    delta : casadi.SX, shape (3, M)
        ``delta_(j-1)``.
    rate, accel : casadi.SX, shape (3, 1)
        ``d_(j-1)`` and its rate.
    step, step_t, step_tt : casadi.SX, shape (3, 1)
        ``Omega_j`` (the integrated curvature over the node's interval) and its first and
        second rates at ``u_t = 0``.
    step_jac : casadi.SX, shape (3, M)
        ``dOmega_j / deta``.

    Returns
    -------
    tuple
        ``(R_j, delta_j, d_j, d_t_j)``.
    """
    import casadi as ca

    factor = _exp(step)
    right, right_t = _right_jacobian_and_rate()(step, step_t)
    turn = ca.mtimes(right, step_t)                # E^-1 E_t = [turn]x
    carried = ca.mtimes(factor.T, rate)
    accel = -ca.cross(turn, carried) + ca.mtimes(factor.T, accel) \
        + ca.mtimes(right_t, step_t) + ca.mtimes(right, step_tt)
    return (ca.mtimes(rotation, factor), ca.mtimes(factor.T, delta) + ca.mtimes(right, step_jac),
            carried + turn, accel)


def section_motion(frame, rotation, delta, d, d_t) -> tuple:
    """One section's tangent and spin in the hub frame, their variations and rates, from its
    rotation ``R`` (relative to the root frame) and ``delta``, ``d``, ``d_t``
    (:meth:`Rod.chain`): ``R e1`` varies by ``R (delta x e1)``, its rate is ``R (d x e1)``,
    its acceleration at ``u_t = 0`` ``R (d x (d x e1) + d_t x e1)``; the section's angular
    velocity relative to the root frame is ``R d`` and its rate ``R d_t`` (CasADi).

    Parameters
    ----------
    frame : casadi.DM or SX, shape (3, 3)
        The root frame in the hub frame.
    rotation : casadi.SX, shape (3, 3)
        ``R``.
    delta : casadi.SX, shape (3, M)
        ``R^-1 dR / deta = [delta]x``, column by column.
    d, d_t : casadi.SX, shape (3, 1)
        ``delta eta_t`` and its rate at ``u_t = 0``.

    Returns
    -------
    tuple
        ``(tangent (3,), tangent_jac (3, M), tangent_rate (3,), tangent_accel (3,),
        spin_jac (3, M), spin (3,), spin_rate (3,))``, hub frame.
    """
    import casadi as ca

    hub_r = ca.mtimes(frame, rotation)                                # section in hub frame
    # delta x e1 = (0, delta_3, -delta_2)
    local = ca.cross(d, ca.vertcat(0, d[2], -d[1])) + ca.vertcat(0, d_t[2], -d_t[1])
    return (hub_r[:, 0],
            ca.mtimes(hub_r[:, 1], delta[2, :]) - ca.mtimes(hub_r[:, 2], delta[1, :]),
            hub_r[:, 1] * d[2] - hub_r[:, 2] * d[1], ca.mtimes(hub_r, local),
            ca.mtimes(hub_r, delta), ca.mtimes(hub_r, d), ca.mtimes(hub_r, d_t))


@lru_cache(maxsize=16)
def shared_chain_step(n_coordinates: int):
    """:func:`chain_step` as one CasADi function kept as a call (``never_inline``): its
    machine code once, however many nodes call it.

    Parameters
    ----------
    n_coordinates : int
        ``M``, the rod's modal coordinates.
    """
    import casadi as ca

    args = [ca.SX.sym("rotation", 3, 3), ca.SX.sym("delta", 3, n_coordinates),
            ca.SX.sym("rate", 3), ca.SX.sym("accel", 3), ca.SX.sym("step", 3),
            ca.SX.sym("step_t", 3), ca.SX.sym("step_tt", 3),
            ca.SX.sym("step_jac", 3, n_coordinates)]
    return ca.Function(f"rod_chain_step_{n_coordinates}", args, list(chain_step(*args)),
                       {"never_inline": True, "cse": True})


@lru_cache(maxsize=16)
def shared_section(n_coordinates: int):
    """:func:`section_motion` as one CasADi function kept as a call (``never_inline``).

    Parameters
    ----------
    n_coordinates : int
        ``M``, the rod's modal coordinates.
    """
    import casadi as ca

    args = [ca.SX.sym("frame", 3, 3), ca.SX.sym("rotation", 3, 3),
            ca.SX.sym("delta", 3, n_coordinates), ca.SX.sym("d", 3), ca.SX.sym("d_t", 3)]
    return ca.Function(f"rod_section_{n_coordinates}", args, list(section_motion(*args)),
                       {"never_inline": True, "cse": True})


@dataclass(frozen=True, eq=False)
class Rod:
    """One appendage's exact kinematics on its quadrature: node rotations, positions.

    Parameters
    ----------
    appendage : SpatialAppendage
        The rod, its masses and its mounting.
    rule : PanelRule
        The quadrature along the rod (:func:`rod_rule`).
    n_modes : int
        Modes per field ``N``.
    root : ndarray, shape (3,)
        The rod's root point in the hub frame, m.
    shared : bool, optional
        Each node's recursion and section as calls of one function
        (:func:`shared_chain_step`, :func:`shared_section`) rather than written out: the
        same values in a fraction of the machine code. Default False.
    """

    appendage: SpatialAppendage
    rule: object
    n_modes: int
    root: np.ndarray
    shared: bool = False

    def chain(self, eta, eta_t):
        """The section rotations ``R_j`` (relative to the root frame) at every node, with
        their variations in the body form ``R_j^-1 dR_j / deta_a = [delta_j,a]x``: the
        recursion ``delta_j = E_j^T delta_(j-1) + T(Omega_j) dOmega_j / deta`` of the product
        ``R_j = R_(j-1) E_j``, ``E_j = exp([Omega_j]x)`` (CasADi).

        Parameters
        ----------
        eta : casadi.SX, shape (3N,)
            The appendage's modal coordinates ``[qn; ql; qt]`` (m for bending, rad for twist,
            per unit of the mode shape).
        eta_t : casadi.SX, shape (3N,)
            Their rates.

        Returns
        -------
        tuple
            ``(rotations, deltas, rates, accelerations)``: lists of 3 x 3, 3 x N and
            3-vectors: ``d_j = delta_j eta_t`` and its rate at ``u_t = 0``.
        """
        import casadi as ca

        rule, a, n_modes = self.rule, self.appendage, self.n_modes
        qn, ql, qt = eta[0:n_modes], eta[n_modes:2 * n_modes], eta[2 * n_modes:]
        nodes = (0.0, *map(float, rule.nodes))
        shapes = rod_shapes(a.length, n_modes, nodes)
        # the integrated curvature (exact) and the curvature at every node, root first
        angle = ca.horzcat(ca.mtimes(ca.DM(shapes["twist"]), qt),
                           -ca.mtimes(ca.DM(shapes["slope"]), qn),
                           ca.mtimes(ca.DM(shapes["slope"]), ql)).T        # (3, n + 1)
        curvature = ca.horzcat(ca.mtimes(ca.DM(shapes["twist_rate"]), qt),
                               -ca.mtimes(ca.DM(shapes["curvature"]), qn),
                               ca.mtimes(ca.DM(shapes["curvature"]), ql)).T
        # the same fields at the rates: the curvature's rate, for the steps' rates
        angle_t = ca.horzcat(ca.mtimes(ca.DM(shapes["twist"]), eta_t[2 * n_modes:]),
                             -ca.mtimes(ca.DM(shapes["slope"]), eta_t[0:n_modes]),
                             ca.mtimes(ca.DM(shapes["slope"]), eta_t[n_modes:2 * n_modes])).T
        curvature_t = ca.horzcat(
            ca.mtimes(ca.DM(shapes["twist_rate"]), eta_t[2 * n_modes:]),
            -ca.mtimes(ca.DM(shapes["curvature"]), eta_t[0:n_modes]),
            ca.mtimes(ca.DM(shapes["curvature"]), eta_t[n_modes:2 * n_modes])).T
        advance = shared_chain_step(int(eta.shape[0])) if self.shared else chain_step
        rotation = ca.SX.eye(3)
        delta = ca.SX.zeros(3, eta.shape[0])
        rate, accel = ca.SX.zeros(3, 1), ca.SX.zeros(3, 1)
        rotations, deltas, rates, accels = [], [], [], []
        for j in range(1, len(nodes)):
            h2 = (nodes[j] - nodes[j - 1]) ** 2 / 12.0
            step = angle[:, j] - angle[:, j - 1] + h2 * ca.cross(curvature[:, j - 1],
                                                                  curvature[:, j])
            step_t = angle_t[:, j] - angle_t[:, j - 1] + h2 * (
                ca.cross(curvature_t[:, j - 1], curvature[:, j])
                + ca.cross(curvature[:, j - 1], curvature_t[:, j]))
            step_tt = 2 * h2 * ca.cross(curvature_t[:, j - 1], curvature_t[:, j])
            rotation, delta, rate, accel = advance(rotation, delta, rate, accel, step, step_t,
                                                   step_tt, ca.jacobian(step, eta))
            rotations.append(rotation)
            deltas.append(delta)
            rates.append(rate)
            accels.append(accel)
        return rotations, deltas, rates, accels

    def integrate(self, values):
        """The integrals from the root to every node and then every point mass of ``values``
        (n, c) at the nodes, (n + K, c): the Gauss-Legendre panels' cumulative form, within
        the panel and over the whole panels before.

        Parameters
        ----------
        values : casadi.SX, shape (n, c)
            A function's values at the nodes.

        Returns
        -------
        casadi.SX, shape (n + K, c)
        """
        import casadi as ca

        rule = self.rule
        local, before = rule.local, rule.before
        if self.appendage.masses:
            at_local, at_before = rule.at([m.position for m in self.appendage.masses])
            local, before = np.vstack([local, at_local]), np.vstack([before, at_before])
        sums = ca.mtimes(ca.sparsify(ca.DM(rule.panel_sums)), values)
        return ca.mtimes(ca.sparsify(ca.DM(local)), values) \
            + ca.mtimes(ca.sparsify(ca.DM(before)), sums)

    def motion(self, eta, eta_t, frame=None, root=None) -> dict:
        """Positions and their derivatives of every node and point mass, and the sections'
        rotations with theirs, for the appendage's modal coordinates ``eta`` ``[qn; ql; qt]``
        and rates ``eta_t`` (CasADi).

        With ``R^-1 dR = [delta]x``: the tangent ``R e1`` varies by ``R (delta x e1)``, its
        rate is ``R (d x e1)`` with ``d = delta eta_t``, its acceleration at ``u_t = 0``
        ``R (d x (d x e1) + d_t x e1)``; the section's angular velocity relative to the root
        frame is ``R d`` and its rate ``R d_t`` (``d_t``: the rate of ``d`` at ``u_t = 0``,
        one forward sweep).

        Parameters
        ----------
        eta : casadi.SX, shape (3N,)
            The appendage's modal coordinates ``[qn; ql; qt]`` (m for bending, rad for twist,
            per unit of the mode shape).
        eta_t : casadi.SX, shape (3N,)
            Their rates.
        frame, root : casadi.SX, optional
            The root frame (3, 3) and root point (3,) in the hub frame as symbols (one
            function for every appendage of the same rod, :mod:`flexctl.model.spatial_dynamics`).
            Default the appendage's numbers.

        Returns
        -------
        dict
            ``points`` (3, M): positions in the hub frame (the nodes, then the point masses);
            ``jac`` (list of 3 (M, N)): each component's Jacobian in ``eta``; ``rel`` and
            ``conv`` (3, M): ``P eta_t`` and ``(P_t) eta_t``; ``tangents`` (3, n);
            ``spin_jac`` (list of n (3, N)), ``spin`` and ``spin_rate`` (3, n): the sections'
            angular velocity relative to the hub, its coefficients and rate, all in the hub
            frame; ``tip`` (3,).
        """
        import casadi as ca

        rotations, deltas, rates, accelerations = self.chain(eta, eta_t)
        frame = ca.DM(self.appendage.frame) if frame is None else frame
        tangent, tangent_jac, tangent_rate, tangent_accel = [], [], [], []
        spin_jac, spin, spin_rate = [], [], []
        section = shared_section(int(eta.shape[0])) if self.shared else section_motion
        for r, delta, d, d_t in zip(rotations, deltas, rates, accelerations):
            parts = section(frame, r, delta, d, d_t)
            for kept, part in zip((tangent, tangent_jac, tangent_rate, tangent_accel, spin_jac,
                                   spin, spin_rate), parts):
                kept.append(part)
        tangents = ca.horzcat(*tangent)                                  # (3, n)
        root = ca.DM(self.root) if root is None else root
        points = self.integrate(tangents.T).T
        points = points + ca.repmat(root, 1, points.shape[1])
        jac = [self.integrate(ca.vertcat(*[t[c, :] for t in tangent_jac])) for c in range(3)]
        rel = self.integrate(ca.horzcat(*tangent_rate).T).T
        conv = self.integrate(ca.horzcat(*tangent_accel).T).T
        weights = ca.DM(self.rule.weights)
        tip = root + ca.mtimes(tangents, weights)
        return {"points": points, "jac": jac, "rel": rel, "conv": conv,
                "tangents": tangents, "spin_jac": spin_jac, "spin": ca.horzcat(*spin),
                "spin_rate": ca.horzcat(*spin_rate), "tip": tip}


def rod_rule(appendage: SpatialAppendage, hub, n_modes: int):
    """The planar exact model's quadrature for the rod bending along its softer plane.

    Parameters
    ----------
    appendage : SpatialAppendage
        The rod: its two bending planes' beams and its mounting.
    hub : SpatialHub
        Its hub (the planar model's hub inertia about the bending axis and root radius).
    n_modes : int
        Modes per field.

    Returns
    -------
    PanelRule
    """
    from .exact import PanelRule, choose_rule
    from .matrices import assemble
    from .parameters import Hub, HubBeam

    # the softer plane, about its bending axis (e2 for bending along the normal, e3 for the
    # lateral): a planar structure's rod gets exactly the planar model's rule
    beam, axis = min(((appendage.beam_normal, appendage.lateral),
                      (appendage.beam_lateral, appendage.normal)),
                     key=lambda pair: pair[0].bending_stiffness)
    system = HubBeam(hub=Hub(inertia=float(axis @ hub.inertia @ axis),
                             radius=float(np.linalg.norm(appendage.root_point(hub)))),
                     beam=beam, masses=appendage.masses)
    rule = choose_rule(system, assemble(system, n_modes))
    return PanelRule.build(rule.panels, appendage.length, rule.points)


def elastic_matrices(appendage: SpatialAppendage, n_modes: int) -> tuple:
    """``(K, C)`` of one appendage's ``[qn; ql; qt]`` (3N, 3N): bending stiffness and modal
    damping of each plane as the planar model's (masses included), torsion's on the
    clamped-free shapes.

    Parameters
    ----------
    appendage : SpatialAppendage
        The rod: its two bending planes' beams, its torsion and its point masses.
    n_modes : int
        Modes per field.

    Returns
    -------
    tuple of ndarray
        Stiffness (N m or N/m per modal unit) and damping, shape (3N, 3N) each.
    """
    from .matrices import assemble
    from .parameters import Hub, HubBeam

    hub = Hub(inertia=1.0, radius=0.0)
    blocks_k, blocks_c = [], []
    for beam in (appendage.beam_normal, appendage.beam_lateral):
        m = assemble(HubBeam(hub=hub, beam=beam, masses=appendage.masses), n_modes)
        blocks_k.append(m.K_ff)
        blocks_c.append(m.C_ff)
    k = np.arange(1, n_modes + 1)
    beta = (2 * k - 1) * np.pi / (2 * appendage.length)
    blocks_k.append(np.diag(appendage.torsional_stiffness * beta ** 2 * appendage.length))
    omega_t = np.array([appendage.torsion_frequency(int(i)) for i in k])
    blocks_c.append(np.diag(2 * appendage.damping_ratio * omega_t * appendage.polar_density
                            * appendage.length))
    from scipy.linalg import block_diag
    return block_diag(*blocks_k), block_diag(*blocks_c)
