"""Equations of motion of a spatial structure (MODEL.md section 8), as CasADi expressions.

Coordinates and speeds (:class:`SpatialLayout`): the hub's attitude quaternion ``q`` (hub to
inertial, scalar first), for a free hub its centre's position ``r`` (inertial frame), and per
appendage the modal coordinates of its three fields (bending along the normal ``qn``, along
the lateral direction ``ql``, twist ``qt``); the speeds are the hub's angular velocity ``w``
(hub frame), a free hub's centre velocity ``v`` (hub frame), and the modal rates.

**Exact rod** (the variant ``exact``). Each appendage is an inextensible rod whose section
rotation ``R(s)`` (relative to its root frame ``[e1 e2 e3]``) solves ``R_s = R [k]x`` with the
curvature vector ``k = (tau, -kappa_n, kappa_l)``: the bending curvatures are modal fields on
the cantilever slope shapes, ``kappa_n = sum_i qn_i phi_i''``, the twist
``tau = sum_k qt_k chi_k'`` on the clamped-free torsion shapes
``chi_k = sqrt(2) sin((2 k - 1) pi s / (2 l))``. Between consecutive nodes of the quadrature the
rotation advances by the exponential of the exact integral of ``k`` plus the fourth-order
Magnus correction ``h^2 / 12 (k_a x k_b)`` (zero when the rod bends in one plane, so that the
planar exact model is reproduced to round-off); the centreline ``p(s) = r_a + int R e1`` is
integrated on the same Gauss-Legendre panels as the planar model's
(:class:`~flexctl.model.exact.PanelRule`).

**Kane's equations.** Every node of the quadrature (mass ``rhoA`` times its weight) and every
point mass moves with the inertial velocity ``v = v_h + w x p + P q_t`` (hub frame, ``P`` the
Jacobian of ``p`` in the modal coordinates); its partial velocities ``[-[p]x, I, P]`` give the
mass matrix ``M = sum m V^T V`` and its acceleration at ``u_t = 0``,
``w x v_h + 2 w x P q_t + (P_t) q_t + w x (w x p)``, the velocity terms ``b = sum m V^T a``. Each
section's twist carries the polar inertia ``rho I_p`` about its tangent ``t``: angular velocity
``w_s = w + vee(R_t R^T)`` (in the root frame, turned into the hub's), inertia force
``J t (t . alpha) + J (t . w_s) (w_s x t)``. The hub adds ``J_h`` and ``w x J_h w``, a free hub
its mass. Then ``M u_t = F - b`` with ``F`` the hub torque (hub frame) on ``w``, the elastic
and damping forces ``-K q - C q_t`` on the modes. ``M`` is the kinetic-energy metric of the
whole structure: positive definite for any hub inertia, a massless hub included.

Quaternion kinematics ``q_t = 1/2 q (0, w) + QUATERNION_GAIN (1 - |q|^2) q`` keep ``|q| = 1``
an attracting invariant (the added term is zero on it), so that the norm does not drift.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .spatial_structure import SpatialAppendage, SpatialStructure

__all__ = ["SpatialLayout", "SpatialEquations", "spatial_equations", "rod_shapes",
           "QUATERNION_GAIN", "FAMILIES", "skew"]

#: Rate at which the quaternion's norm returns to 1, 1/s (zero effect on a unit quaternion).
QUATERNION_GAIN = 1.0
#: The modal fields of an appendage, in the order of its coordinates.
FAMILIES = ("qn", "ql", "qt")


@dataclass(frozen=True)
class SpatialLayout:
    """Where each coordinate and speed lies in the state of a spatial structure.

    State ``x = [q (4); r (3, free hub); eta (M); w (3); v (3, free hub); eta_t (M)]`` with
    ``eta`` every appendage's ``[qn (N), ql (N), qt (N)]`` in turn (``M = 3 N A``).

    Attributes
    ----------
    names : tuple of str
        The appendages' names.
    n_modes : int
        Modes per field (``N``).
    free : bool
        Whether the hub floats free.
    """

    names: tuple
    n_modes: int
    free: bool

    @property
    def n_elastic(self) -> int:
        """``M``: modal coordinates in all."""
        return 3 * self.n_modes * len(self.names)

    @property
    def n_coordinates(self) -> int:
        """Coordinates: quaternion, position (free hub), modal."""
        return 4 + (3 if self.free else 0) + self.n_elastic

    @property
    def n_speeds(self) -> int:
        """Speeds: angular velocity, velocity (free hub), modal rates."""
        return 3 + (3 if self.free else 0) + self.n_elastic

    @property
    def n_states(self) -> int:
        """Length of the state vector."""
        return self.n_coordinates + self.n_speeds

    def modal(self, k: int, family: str) -> slice:
        """Slice of appendage ``k``'s field ``family`` (``"qn"``, ``"ql"``, ``"qt"``) in ``eta``.

        Parameters
        ----------
        k : int
            Appendage index.
        family : str
            One of :data:`FAMILIES`.
        """
        start = (3 * k + FAMILIES.index(family)) * self.n_modes
        return slice(start, start + self.n_modes)

    @property
    def state_names(self) -> tuple:
        """Name of every state: ``qw qx qy qz``, ``hub_x hub_y hub_z`` (free),
        ``<name>.qn1 ...``, ``wx wy wz``, ``hub_vx hub_vy hub_vz`` (free, hub frame),
        ``<name>.qn1_dot ...``."""
        modal = [f"{a}.{f}{i + 1}" for a in self.names for f in FAMILIES
                 for i in range(self.n_modes)]
        position = ["hub_x", "hub_y", "hub_z"] if self.free else []
        velocity = ["hub_vx", "hub_vy", "hub_vz"] if self.free else []
        return tuple(["qw", "qx", "qy", "qz", *position, *modal, "wx", "wy", "wz", *velocity,
                      *[f"{m}_dot" for m in modal]])

    def split(self, x):
        """``(quaternion, position or None, eta, w, v or None, eta_t)`` of a state ``x``.

        Parameters
        ----------
        x : casadi.SX or ndarray, shape (n_states,) or (n_states, P)
        """
        c = 4
        position = x[c:c + 3] if self.free else None
        c += 3 if self.free else 0
        eta = x[c:c + self.n_elastic]
        c += self.n_elastic
        w = x[c:c + 3]
        c += 3
        v = x[c:c + 3] if self.free else None
        c += 3 if self.free else 0
        return x[0:4], position, eta, w, v, x[c:c + self.n_elastic]


def skew(a):
    """``[a]x``, the cross-product matrix of a 3-vector (CasADi).

    Parameters
    ----------
    a : casadi.SX, shape (3, 1)

    Returns
    -------
    casadi.SX, shape (3, 3)
    """
    import casadi as ca

    return ca.vertcat(ca.horzcat(0, -a[2], a[1]), ca.horzcat(a[2], 0, -a[0]),
                      ca.horzcat(-a[1], a[0], 0))


def _vee(m):
    """The vector of the skew part of a 3 x 3 matrix."""
    import casadi as ca

    return 0.5 * ca.vertcat(m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1])


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


@dataclass(frozen=True, eq=False)
class _Rod:
    """One appendage's exact kinematics on its quadrature: node rotations, positions."""

    appendage: SpatialAppendage
    rule: object
    n_modes: int
    root: np.ndarray

    def chain(self, eta, eta_t):
        """The section rotations ``R_j`` (relative to the root frame) at every node, with
        their variations in the body form ``R_j^-1 dR_j / deta_a = [delta_j,a]x``: the
        recursion ``delta_j = E_j^T delta_(j-1) + T(Omega_j) dOmega_j / deta`` of the product
        ``R_j = R_(j-1) E_j``, ``E_j = exp([Omega_j]x)`` (CasADi).

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
            factor = _exp(step)
            right, right_t = _right_jacobian_and_rate()(step, step_t)
            turn = ca.mtimes(right, step_t)                # E^-1 E_t = [turn]x
            rotation = ca.mtimes(rotation, factor)
            delta = ca.mtimes(factor.T, delta) + ca.mtimes(right, ca.jacobian(step, eta))
            # d_j = E^T d_(j-1) + T step_t and its rate at u_t = 0 (E_t^T = -[turn]x E^T)
            carried = ca.mtimes(factor.T, rate)
            accel = -ca.cross(turn, carried) + ca.mtimes(factor.T, accel) \
                + ca.mtimes(right_t, step_t) + ca.mtimes(right, step_tt)
            rate = carried + turn
            rotations.append(rotation)
            deltas.append(delta)
            rates.append(rate)
            accels.append(accel)
        return rotations, deltas, rates, accels

    def integrate(self, values):
        """The integrals from the root to every node and then every point mass of ``values``
        (n, c) at the nodes, (n + K, c): the Gauss-Legendre panels' cumulative form, within
        the panel and over the whole panels before (sparse: a third of the dense product's
        operations on 2 panels)."""
        import casadi as ca

        rule = self.rule
        local, before = rule.local, rule.before
        if self.appendage.masses:
            at_local, at_before = rule.at([m.position for m in self.appendage.masses])
            local, before = np.vstack([local, at_local]), np.vstack([before, at_before])
        sums = ca.mtimes(ca.sparsify(ca.DM(rule.panel_sums)), values)
        return ca.mtimes(ca.sparsify(ca.DM(local)), values) \
            + ca.mtimes(ca.sparsify(ca.DM(before)), sums)

    def motion(self, eta, eta_t) -> dict:
        """Positions and their derivatives of every node and point mass, and the sections'
        rotations with theirs, for the appendage's modal coordinates ``eta`` ``[qn; ql; qt]``
        and rates ``eta_t`` (CasADi).

        With ``R^-1 dR = [delta]x``: the tangent ``R e1`` varies by ``R (delta x e1)``, its
        rate is ``R (d x e1)`` with ``d = delta eta_t``, its acceleration at ``u_t = 0``
        ``R (d x (d x e1) + d_t x e1)``; the section's angular velocity relative to the root
        frame is ``R d`` and its rate ``R d_t`` (``d_t``: the rate of ``d`` at ``u_t = 0``,
        one forward sweep).

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
        frame = ca.DM(self.appendage.frame)
        tangent, tangent_jac, tangent_rate, tangent_accel = [], [], [], []
        spin_jac, spin, spin_rate = [], [], []
        for j, (r, delta, d) in enumerate(zip(rotations, deltas, rates)):
            d_t = accelerations[j]
            hub_r = ca.mtimes(frame, r)                                  # section in hub frame
            tangent.append(hub_r[:, 0])
            # delta x e1 = (0, delta_3, -delta_2)
            tangent_jac.append(ca.mtimes(hub_r[:, 1], delta[2, :])
                               - ca.mtimes(hub_r[:, 2], delta[1, :]))     # (3, N)
            tangent_rate.append(hub_r[:, 1] * d[2] - hub_r[:, 2] * d[1])
            local = ca.cross(d, ca.vertcat(0, d[2], -d[1])) + ca.vertcat(0, d_t[2], -d_t[1])
            tangent_accel.append(ca.mtimes(hub_r, local))
            spin_jac.append(ca.mtimes(hub_r, delta))
            spin.append(ca.mtimes(hub_r, d))
            spin_rate.append(ca.mtimes(hub_r, d_t))
        tangents = ca.horzcat(*tangent)                                  # (3, n)
        root = ca.DM(self.root)
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


@dataclass(frozen=True, eq=False)
class SpatialEquations:
    """The spatial model's CasADi functions.

    Attributes
    ----------
    layout : SpatialLayout
    rhs : casadi.Function
        ``(x (n_states), torque (3)) -> x_t``: the state's rate, torque in the hub frame, N m.
    tips : casadi.Function
        ``x -> (3, A)``: each tip's displacement from the undeformed tip, hub frame, m.
    energy : casadi.Function
        ``x -> (kinetic, elastic)``, J.
    momentum : casadi.Function
        ``x -> (angular (3), linear (3))`` in the inertial frame: the angular momentum about
        the hub's centre (pinned) or the structure's centre of mass (free), N m s; the linear
        momentum, N s.
    mass_matrix : casadi.Function
        ``x -> M`` (n_speeds, n_speeds).
    """

    structure: SpatialStructure
    layout: SpatialLayout
    rhs: object
    tips: object
    energy: object
    momentum: object
    mass_matrix: object


def _rule(appendage: SpatialAppendage, hub, n_modes: int):
    """The planar exact model's quadrature for the rod bending along its softer plane."""
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


def _elastic(appendage: SpatialAppendage, n_modes: int) -> tuple:
    """``(K, C)`` of one appendage's ``[qn; ql; qt]`` (3N, 3N): bending stiffness and modal
    damping of each plane as the planar model's (masses included), torsion's on the
    clamped-free shapes."""
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


def spatial_equations(structure: SpatialStructure, n_modes: int) -> SpatialEquations:
    """Build the exact spatial model's functions (cached per structure and mode count).

    Parameters
    ----------
    structure : SpatialStructure
    n_modes : int
        Modes per field of every appendage (1 to 12).

    Returns
    -------
    SpatialEquations
    """
    from .checks import check_instance, check_integer

    check_instance("spatial_equations", "structure", structure, SpatialStructure)
    n_modes = check_integer("spatial_equations", "n_modes", n_modes, minimum=1, maximum=12)
    return _built(structure, n_modes)


@lru_cache(maxsize=16)
def _built(structure: SpatialStructure, n_modes: int) -> SpatialEquations:
    import casadi as ca

    from .exact import symmetric_solve

    layout = SpatialLayout(names=structure.names, n_modes=n_modes, free=structure.hub.free)
    x = ca.SX.sym("x", layout.n_states)
    torque = ca.SX.sym("torque", 3)
    quaternion, position, eta, w, v, eta_t = layout.split(x)
    hub = structure.hub
    n_u = layout.n_speeds
    mass = ca.SX.zeros(n_u, n_u)
    bias = ca.SX.zeros(n_u, 1)
    forces = ca.SX.zeros(n_u, 1)
    forces[0:3] = torque
    mass[0:3, 0:3] += ca.DM(hub.inertia)
    bias[0:3] += ca.cross(w, ca.mtimes(ca.DM(hub.inertia), w))
    e = 6 if layout.free else 3                    # first modal speed
    if layout.free:
        mass[3:6, 3:6] += hub.mass * ca.DM.eye(3)
        bias[3:6] += hub.mass * ca.cross(w, v)
    velocity_h = v if layout.free else ca.SX.zeros(3, 1)
    tips, elastic_energy = [], 0
    linear = hub.mass * velocity_h
    moment = ca.SX.zeros(3, 1)
    angular = ca.mtimes(ca.DM(hub.inertia), w)
    for k, appendage in enumerate(structure.appendages):
        rod = _Rod(appendage, _rule(appendage, hub, n_modes), n_modes, appendage.root_point(hub))
        block = slice(3 * k * n_modes, 3 * (k + 1) * n_modes)
        motion = rod.motion(eta[block], eta_t[block])
        tips.append(motion["tip"] - ca.DM(rod.root + appendage.length * appendage.direction))
        point_mass = np.concatenate([appendage.linear_density * np.asarray(rod.rule.weights),
                                     [m.mass for m in appendage.masses]])
        kinetic = _particles(motion, point_mass, w, velocity_h, layout.free)
        cols = list(range(0, 6 if layout.free else 3)) + list(range(e + block.start,
                                                                      e + block.stop))
        mass, bias = _place(mass, bias, kinetic[0], kinetic[1], cols)
        linear += kinetic[2]
        angular += kinetic[3]
        moment += kinetic[4]
        polar = _sections(motion, appendage, rod.rule, w)
        mass, bias = _place(mass, bias, polar[0], polar[1],
                            [0, 1, 2] + list(range(e + block.start, e + block.stop)))
        angular += polar[2]
        stiffness, damping = _elastic(appendage, n_modes)
        local, local_t = eta[block], eta_t[block]
        forces[e + block.start:e + block.stop] -= ca.mtimes(ca.DM(stiffness), local) \
            + ca.mtimes(ca.DM(damping), local_t)
        elastic_energy += 0.5 * ca.dot(local, ca.mtimes(ca.DM(stiffness), local))
    speeds = x[layout.n_coordinates:]
    accelerations = symmetric_solve(mass, forces - bias)
    rate = ca.vertcat(_quaternion_rate(quaternion, w),
                      *([ca.mtimes(_rotation(quaternion), v)] if layout.free else []),
                      eta_t, accelerations)
    rotation = _rotation(quaternion)
    kinetic_energy = 0.5 * ca.dot(speeds, ca.mtimes(mass, speeds))
    if layout.free:     # about the centre of mass: H_O - r_c x L (all in the hub frame)
        angular = angular - ca.cross(moment / structure.total_mass, linear)
    return SpatialEquations(
        structure=structure, layout=layout,
        rhs=ca.Function("spatial_rhs", [x, torque], [rate], ["x", "torque"], ["x_dot"],
                        {"cse": True}),
        tips=ca.Function("spatial_tips", [x], [ca.horzcat(*tips)], ["x"], ["tips"]),
        energy=ca.Function("spatial_energy", [x], [kinetic_energy, elastic_energy], ["x"],
                           ["kinetic", "elastic"]),
        momentum=ca.Function("spatial_momentum", [x], [ca.mtimes(rotation, angular),
                                                       ca.mtimes(rotation, linear)],
                             ["x"], ["angular", "linear"]),
        mass_matrix=ca.Function("spatial_mass", [x], [mass], ["x"], ["M"]))


def _place(mass, bias, local_mass, local_bias, cols: list) -> tuple:
    """Add an appendage's blocks (on its speeds ``cols``) into the whole mass matrix and
    velocity terms."""
    import casadi as ca

    n_u = mass.shape[0]
    pick = ca.DM.zeros(len(cols), n_u)
    for a, c in enumerate(cols):
        pick[a, c] = 1.0
    pick = ca.sparsify(pick)
    return (mass + ca.mtimes([pick.T, local_mass, pick]),
            bias + ca.mtimes(pick.T, local_bias))


def _particles(motion: dict, masses, w, v, free: bool) -> tuple:
    """Mass matrix and velocity terms on the appendage's speeds (``[w; v (free); eta_t of
    the appendage]``), linear and angular momentum (hub frame, about the centre) and first
    moment of mass of its nodes and point masses (``masses`` (M,), kg)."""
    import casadi as ca

    points, rel = motion["points"], motion["rel"]
    n = points.shape[1]
    m = ca.DM(np.asarray(masses, dtype=float))
    wide_w = ca.repmat(w, 1, n)
    velocity = ca.repmat(v, 1, n) + _cross_columns(wide_w, points) + rel
    accel = ca.repmat(ca.cross(w, v), 1, n) + 2 * _cross_columns(wide_w, rel) \
        + motion["conv"] + _cross_columns(wide_w, _cross_columns(wide_w, points))
    zero = ca.SX.zeros(n, 1)
    px, py, pz = points[0, :].T, points[1, :].T, points[2, :].T
    # partial velocities, component by component: -[p]x, I (free), P
    spin_rows = [ca.horzcat(zero, pz, -py), ca.horzcat(-pz, zero, px),
                 ca.horzcat(py, -px, zero)]
    partials, weighted = [], []
    for c in range(3):
        parts = [spin_rows[c]]
        if free:
            unit = np.zeros((n, 3))
            unit[:, c] = 1.0
            parts.append(ca.DM(unit))
        parts.append(motion["jac"][c])
        partials.append(ca.horzcat(*parts))                           # (M, speeds)
        weighted.append(partials[-1] * ca.repmat(m, 1, partials[-1].shape[1]))
    partial, weighted = ca.vertcat(*partials), ca.vertcat(*weighted)
    local_mass = _gram(partial, weighted)
    local_bias = ca.mtimes(weighted.T, ca.vec(accel.T))
    linear = ca.mtimes(velocity, m)
    angular = ca.mtimes(_cross_columns(points, velocity), m)
    moment = ca.mtimes(points, m)
    return local_mass, local_bias, linear, angular, moment


def _gram(partial, weighted):
    """``partial^T weighted``, symmetric: each pair of columns once (half the products of
    the full product)."""
    import casadi as ca

    n = partial.shape[1]
    entries = {(i, j): ca.dot(partial[:, i], weighted[:, j])
               for i in range(n) for j in range(i, n)}
    return ca.blockcat([[entries[min(i, j), max(i, j)] for j in range(n)] for i in range(n)])


def _cross_columns(a, b):
    """Column-wise cross products of two (3, n) matrices (CasADi)."""
    import casadi as ca

    return ca.vertcat(a[1, :] * b[2, :] - a[2, :] * b[1, :],
                      a[2, :] * b[0, :] - a[0, :] * b[2, :],
                      a[0, :] * b[1, :] - a[1, :] * b[0, :])


def _sections(motion: dict, appendage, rule, w) -> tuple:
    """Mass matrix and velocity terms on ``[w; eta_t of the appendage]`` and angular
    momentum of the sections' polar inertia ``rho I_p`` about their tangents ``t``: angular
    velocity ``w_s = w + spin``, inertia force ``J t (t . alpha) + J (t . w_s) (w_s x t)``
    with ``alpha = spin_rate + w x w_s`` at ``u_t = 0``."""
    import casadi as ca

    tangents, spin_jac = motion["tangents"], motion["spin_jac"]
    n = tangents.shape[1]
    omega = ca.repmat(w, 1, n) + motion["spin"]
    alpha_bias = motion["spin_rate"] + _cross_columns(ca.repmat(w, 1, n), omega)
    gyro = _cross_columns(omega, tangents)                           # w_s x t, (3, n)
    along = ca.vertcat(*[ca.horzcat(tangents[:, j].T, ca.mtimes(tangents[:, j].T, spin_jac[j]))
                         for j in range(n)])                         # (n, 3 + N)
    partial_gyro = ca.vertcat(*[ca.horzcat(gyro[:, j].T, ca.mtimes(gyro[:, j].T, spin_jac[j]))
                                for j in range(n)])
    js = ca.DM(appendage.polar_density * np.asarray(rule.weights))
    polar_rate = ca.sum1(tangents * omega).T                         # t . w_s, (n,)
    polar_accel = ca.sum1(tangents * alpha_bias).T                   # t . alpha_b, (n,)
    local_mass = _gram(along, along * ca.repmat(js, 1, along.shape[1]))
    local_bias = ca.mtimes(along.T, js * polar_accel) \
        + ca.mtimes(partial_gyro.T, js * polar_rate)
    angular = ca.mtimes(tangents, js * polar_rate)
    return local_mass, local_bias, angular


def _quaternion_rate(q, w):
    """``1/2 q (0, w) + QUATERNION_GAIN (1 - |q|^2) q``."""
    import casadi as ca

    qw, qv = q[0], q[1:4]
    product = ca.vertcat(-ca.dot(qv, w), qw * w + ca.cross(qv, w))
    return 0.5 * product + QUATERNION_GAIN * (1 - ca.dot(q, q)) * q


def _rotation(q):
    """The rotation matrix of a unit quaternion (hub to inertial), CasADi."""
    import casadi as ca

    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)),
        ca.horzcat(2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)),
        ca.horzcat(2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)))
