"""Equations of motion of a spatial structure (:doc:`the spatial model </guide/spatial>`), as
CasADi expressions.

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

**First order** (the variants ``first_order`` and ``zero_order``). The same equations, written
as the residual ``r = M u_t - (F - b)``, expanded to first order in the deflections: the modal
coordinates, rates and accelerations are scaled together by ``eps`` and
``r1 = r(0) + dr/deps(0)``, while the hub's motion (``w``, ``w_t``, ``v``, ``v_t``) and the
torque stay exact. ``r1`` is linear in the accelerations, ``M1 u_t = f1``: ``M1``'s modal
columns are the straight structure's mass matrix, its hub columns gain the terms linear in the
deflections (the inertia of the deformed structure about the hub: products of inertia), and
the products of two deflections (``q q_tt``, ``q_t^2``) drop. ``first_order`` keeps the rods'
kinematics to second order (exactly what ``r1`` needs: the foreshortening whose tension,
driven by the whole angular velocity and acceleration and a free hub's acceleration, stiffens
both bending planes), ``zero_order`` truncates positions and section rotations to first order
(no foreshortening: the centrifugal softening stays, the stiffening goes, :ref:`section 4 of the
model <variants>`). For a structure moving in one plane they are :ref:`section 4 <variants>`'s
first_order and zero_order (on the exact model's quadrature); linearised about the straight
structure in a steady turn, first_order is the exact model. Where the hub accelerates, the modal
accelerations of the straight structure are not small, and the dropped ``q q_tt`` products are
first order in ``q`` there: the twist of a bent rod, whose inertia is small, feels them most.
Their tips, energy and momentum are those of their kinematics (the tips to second and to first
order).

Quaternion kinematics ``q_t = 1/2 q (0, w) + QUATERNION_GAIN (1 - |q|^2) q`` keep ``|q| = 1``
an attracting invariant (the added term is zero on it), so that the norm does not drift.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from .spatial_rod import Rod, elastic_matrices, rod_rule
from .spatial_structure import SpatialStructure

__all__ = ["SpatialLayout", "SpatialEquations", "spatial_equations", "truncated_motion",
           "quaternion_rotation", "spatial_modes",
           "taylor", "QUATERNION_GAIN", "FAMILIES", "MAX_SPATIAL_MODES", "SPATIAL_VARIANTS",
           "KINEMATIC_ORDER"]

#: Rate at which the quaternion's norm returns to 1, 1/s (zero effect on a unit quaternion).
QUATERNION_GAIN = 1.0
#: Most modes per field of a spatial model.
MAX_SPATIAL_MODES = 12
#: The modal fields of an appendage, in the order of its coordinates.
FAMILIES = ("qn", "ql", "qt")
#: The spatial model's variants: the geometrically exact rod, and its equations to first order
#: in the deflections with dynamic stiffening (first_order) or without (zero_order).
SPATIAL_VARIANTS = ("exact", "first_order", "zero_order")
#: Degree in the deflections to which each variant keeps its rods' kinematics (positions and
#: section rotations): exact (None); to second order, the foreshortening that carries the
#: centrifugal stiffening; to first order, none.
KINEMATIC_ORDER = {"exact": None, "first_order": 2, "zero_order": 1}
#: The entries of :meth:`Rod.motion` that are Jacobians in the modal coordinates (one degree
#: less than the positions they differentiate).
_JACOBIANS = ("jac", "spin_jac")


@dataclass(frozen=True)
class SpatialLayout:
    """Where each coordinate and speed lies in the state of a spatial structure.

    State ``x = [q (4); r (3, free hub); eta (M); w (3); v (3, free hub); eta_t (M)]`` with
    ``eta`` every appendage's ``[qn (N_k), ql (N_k), qt (N_k)]`` in turn (``M = 3 sum N_k``).

    Attributes
    ----------
    names : tuple of str
        The appendages' names.
    n_modes : int or tuple of int
        Modes per field (``N_k``): one count for every appendage, or one per appendage.
    free : bool
        Whether the hub floats free.
    wheels : tuple of str
        Names of the states a wheel cluster appends after the structure's
        (:mod:`flexctl.model.wheel_cluster`); empty without one.
    """

    names: tuple
    n_modes: int | tuple
    free: bool
    wheels: tuple = ()

    @property
    def counts(self) -> tuple:
        """Modes per field of each appendage, ``(N_1, ...)``."""
        if isinstance(self.n_modes, tuple):
            return self.n_modes
        return (self.n_modes,) * len(self.names)

    def block(self, k: int) -> slice:
        """Slice of appendage ``k``'s coordinates ``[qn, ql, qt]`` in ``eta``.

        Parameters
        ----------
        k : int
            Appendage index.
        """
        start = 3 * sum(self.counts[:k])
        return slice(start, start + 3 * self.counts[k])

    @property
    def n_elastic(self) -> int:
        """``M``: modal coordinates in all."""
        return 3 * sum(self.counts)

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
        return self.n_coordinates + self.n_speeds + len(self.wheels)

    def modal(self, k: int, family: str) -> slice:
        """Slice of appendage ``k``'s field ``family`` (``"qn"``, ``"ql"``, ``"qt"``) in ``eta``.

        Parameters
        ----------
        k : int
            Appendage index.
        family : str
            One of :data:`FAMILIES`.
        """
        n = self.counts[k]
        start = self.block(k).start + FAMILIES.index(family) * n
        return slice(start, start + n)

    @property
    def modal_indices(self) -> tuple:
        """``(coordinates, rates)``: the state indices of every modal coordinate and of its
        rate, in the same order (ndarrays of ``M`` integers)."""
        start = 4 + (3 if self.free else 0)
        coordinates = np.arange(start, start + self.n_elastic)
        return coordinates, coordinates + self.n_coordinates + 3 + (3 if self.free else 0) \
            - start

    @property
    def state_names(self) -> tuple:
        """Name of every state: ``qw qx qy qz``, ``hub_x hub_y hub_z`` (free),
        ``<name>.qn1 ...``, ``wx wy wz``, ``hub_vx hub_vy hub_vz`` (free, hub frame),
        ``<name>.qn1_dot ...``."""
        modal = [f"{a}.{f}{i + 1}" for a, n in zip(self.names, self.counts) for f in FAMILIES
                 for i in range(n)]
        position = ["hub_x", "hub_y", "hub_z"] if self.free else []
        velocity = ["hub_vx", "hub_vy", "hub_vz"] if self.free else []
        return tuple(["qw", "qx", "qy", "qz", *position, *modal, "wx", "wy", "wz", *velocity,
                      *[f"{m}_dot" for m in modal], *self.wheels])

    def split(self, x):
        """``(quaternion, position or None, eta, w, v or None, eta_t)`` of a state ``x``.

        Parameters
        ----------
        x : casadi.SX or ndarray, shape (n_states,) or (n_states, P)
            State(s) in this layout's order.
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


@dataclass(frozen=True, eq=False)
class SpatialEquations:
    """The spatial model's CasADi functions.

    Attributes
    ----------
    structure : SpatialStructure
        The structure modelled.
    layout : SpatialLayout
        Where each coordinate and speed lies in the state.
    variant : str
        One of :data:`SPATIAL_VARIANTS`.
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
        ``x -> M`` (n_speeds, n_speeds): the matrix the accelerations are solved with
        (``M1`` of a first-order variant, not symmetric).
    cluster : WheelCluster or None
        The reaction wheels on the hub (:func:`~flexctl.model.wheel_cluster.with_wheels`);
        their states follow the structure's, and ``torque`` is the hub torque commanded of
        them.
    wheel_outputs : casadi.Function or None
        With a cluster, ``(x, torque) -> (motor torques (n), N m; power drawn, W)``.
    """

    structure: SpatialStructure
    layout: SpatialLayout
    variant: str
    rhs: object
    tips: object
    energy: object
    momentum: object
    mass_matrix: object
    cluster: object = None
    wheel_outputs: object = None

    @cached_property
    def integration_rhs(self):
        """:attr:`rhs` as the integrators evaluate it, ``(x, torque) -> x_t``: for the exact
        rod without wheels, each appendage's terms (its rod's kinematics, inertia and
        sections) a call of one function (``never_inline``) shared by the appendages of the
        same rod, and in it each node's recursion and section a call of one function
        (:class:`~flexctl.model.spatial_rod.Rod` ``shared``): the same numbers in half the
        machine code. A right-hand side longer than a processor's second-level cache runs
        from the third: the two arrays of ``spatial-two-arrays.toml`` on 4 modes took 53 us
        an evaluation in a library of 1.6 MB, 30 us in one of 0.78 MB. :attr:`rhs` itself
        for the expanded variants and with wheels."""
        if self.variant != "exact" or self.cluster is not None:
            return self.rhs
        return _shared_rhs(self.structure, self.layout.n_modes)


def spatial_modes(owner: str, structure: SpatialStructure, n_modes) -> int | tuple:
    """A checked mode count of a spatial structure: one integer, or one per appendage (a
    sequence in the appendages' order, or a mapping from their names).

    Parameters
    ----------
    owner : str
        Who takes it (named in errors).
    structure : SpatialStructure
        The structure whose appendages the counts are for.
    n_modes : int, sequence of int or mapping of str to int
        Modes per field, 1 to :data:`MAX_SPATIAL_MODES`.

    Returns
    -------
    int or tuple of int
        An integer when every appendage has the same count, else the tuple of counts.
    """
    from .checks import check_counts

    counts = check_counts(owner, structure.names, n_modes, MAX_SPATIAL_MODES)
    return counts[0] if len(set(counts)) == 1 else counts


def spatial_equations(structure: SpatialStructure, n_modes,
                      variant: str = "exact") -> SpatialEquations:
    """Build a spatial model's functions (cached per structure, mode count and variant).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, sequence of int or mapping of str to int
        Modes per field (1 to 12) of every appendage, or of each
        (:func:`spatial_modes`).
    variant : {"exact", "first_order", "zero_order"}, optional
        The geometrically exact rod (default), or its equations expanded to first order in the
        deflections with the rod's kinematics kept to second order (``first_order``: dynamic
        stiffening) or to first order (``zero_order``: none); see the module's description.

    Returns
    -------
    SpatialEquations
    """
    from .checks import check_choice, check_instance

    check_instance("spatial_equations", "structure", structure, SpatialStructure)
    n_modes = spatial_modes("spatial_equations", structure, n_modes)
    variant = check_choice("spatial_equations", "variant", variant, SPATIAL_VARIANTS)
    return _built(structure, n_modes, variant)


@dataclass(frozen=True, eq=False)
class _Terms:
    """Kane's equations ``mass u_t = forces - bias`` of a whole structure, with the outputs
    of its kinematics (CasADi expressions of the state and the torque)."""

    mass: object
    bias: object
    forces: object
    tips: object
    elastic_energy: object
    linear: object
    angular: object
    moment: object


@lru_cache(maxsize=16)
def _built(structure: SpatialStructure, n_modes: int, variant: str) -> SpatialEquations:
    import casadi as ca

    from .exact import symmetric_solve

    layout = SpatialLayout(names=structure.names, n_modes=n_modes, free=structure.hub.free)
    x = ca.SX.sym("x", layout.n_states)
    torque = ca.SX.sym("torque", 3)
    quaternion, _, _, w, v, eta_t = layout.split(x)
    terms = _kane(structure, layout, x, torque, KINEMATIC_ORDER[variant])
    if variant == "exact":
        mass = terms.mass
        accelerations = symmetric_solve(mass, terms.forces - terms.bias)
    else:
        mass, accelerations = _first_order(layout, x, terms)
    speeds = x[layout.n_coordinates:]
    rate = _rate(layout, x, accelerations)
    rotation = quaternion_rotation(quaternion)
    kinetic_energy = 0.5 * ca.dot(speeds, ca.mtimes(terms.mass, speeds))
    angular = terms.angular
    if layout.free:     # about the centre of mass: H_O - r_c x L (all in the hub frame)
        angular = angular - ca.cross(terms.moment / structure.total_mass, terms.linear)
    return SpatialEquations(
        structure=structure, layout=layout, variant=variant,
        rhs=ca.Function("spatial_rhs", [x, torque], [rate], ["x", "torque"], ["x_dot"],
                        {"cse": True}),
        tips=ca.Function("spatial_tips", [x], [terms.tips], ["x"], ["tips"]),
        energy=ca.Function("spatial_energy", [x], [kinetic_energy, terms.elastic_energy],
                           ["x"], ["kinetic", "elastic"]),
        momentum=ca.Function("spatial_momentum", [x], [ca.mtimes(rotation, angular),
                                                       ca.mtimes(rotation, terms.linear)],
                             ["x"], ["angular", "linear"]),
        mass_matrix=ca.Function("spatial_mass", [x], [mass], ["x"], ["M"]))


def _rate(layout: SpatialLayout, x, accelerations):
    """The state's rate: the quaternion's and a free hub's position's kinematics, the modal
    rates, the speeds' ``accelerations``."""
    import casadi as ca

    quaternion, _, _, w, v, eta_t = layout.split(x)
    return ca.vertcat(_quaternion_rate(quaternion, w),
                      *([ca.mtimes(quaternion_rotation(quaternion), v)] if layout.free else []),
                      eta_t, accelerations)


@lru_cache(maxsize=16)
def _shared_rhs(structure: SpatialStructure, n_modes) -> object:
    """The exact model's rate with each appendage's terms a call (:func:`_shared_terms`)."""
    import casadi as ca

    from .exact import symmetric_solve

    layout = SpatialLayout(names=structure.names, n_modes=n_modes, free=structure.hub.free)
    x = ca.SX.sym("x", layout.n_states)
    torque = ca.SX.sym("torque", 3)
    terms = _kane(structure, layout, x, torque, None, shared=True)
    rate = _rate(layout, x, symmetric_solve(terms.mass, terms.forces - terms.bias))
    return ca.Function("spatial_rhs_shared", [x, torque], [rate], ["x", "torque"], ["x_dot"],
                       {"cse": True})


def _kane(structure: SpatialStructure, layout: SpatialLayout, x, torque, order,
          shared: bool = False) -> _Terms:
    """Kane's equations of the whole structure at state ``x``, its rods' kinematics kept to
    ``order`` in the deflections (None: exact); with ``shared`` each appendage's terms are a
    call of one function per distinct rod (:func:`_shared_terms`)."""
    import casadi as ca

    _, _, eta, w, v, eta_t = layout.split(x)
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
    functions: dict = {}
    for k, appendage in enumerate(structure.appendages):
        n = layout.counts[k]
        rod = Rod(appendage, rod_rule(appendage, hub, n), n, appendage.root_point(hub),
                  shared)
        block = layout.block(k)
        if shared:
            function = _shared_terms(rod, layout.free, functions, k)
            terms = function(w, *([v] if layout.free else []), eta[block], eta_t[block],
                             ca.DM(appendage.frame), ca.DM(rod.root))
        else:
            terms = _appendage_terms(rod, w, velocity_h, eta[block], eta_t[block],
                                     layout.free, order)
        tip, kinetic, polar = terms[0], terms[1:6], terms[6:9]
        tips.append(tip)
        cols = list(range(0, e)) + list(range(e + block.start, e + block.stop))
        mass, bias = _place(mass, bias, kinetic[0], kinetic[1], cols)
        linear += kinetic[2]
        angular += kinetic[3]
        moment += kinetic[4]
        mass, bias = _place(mass, bias, polar[0], polar[1],
                            [0, 1, 2] + list(range(e + block.start, e + block.stop)))
        angular += polar[2]
        stiffness, damping = elastic_matrices(appendage, n)
        local, local_t = eta[block], eta_t[block]
        forces[e + block.start:e + block.stop] -= ca.mtimes(ca.DM(stiffness), local) \
            + ca.mtimes(ca.DM(damping), local_t)
        elastic_energy += 0.5 * ca.dot(local, ca.mtimes(ca.DM(stiffness), local))
    return _Terms(mass=mass, bias=bias, forces=forces, tips=ca.horzcat(*tips),
                  elastic_energy=elastic_energy, linear=linear, angular=angular,
                  moment=moment)


def _appendage_terms(rod: Rod, w, v, eta, eta_t, free: bool, order=None, frame=None,
                     root=None) -> tuple:
    """One appendage's terms of Kane's equations: ``(tip, mass, bias, linear, angular,
    moment, polar mass, polar bias, polar angular)`` (:func:`_particles`, :func:`_sections`;
    the tip's displacement from the undeformed tip), its root frame and point the
    appendage's numbers or symbols (``frame``, ``root``)."""
    import casadi as ca

    appendage = rod.appendage
    motion = truncated_motion(rod, eta, eta_t, order, frame, root)
    undeformed = ca.DM(rod.root + appendage.length * appendage.direction) if root is None \
        else root + appendage.length * frame[:, 0]
    point_mass = np.concatenate([appendage.linear_density * np.asarray(rod.rule.weights),
                                 [m.mass for m in appendage.masses]])
    return (motion["tip"] - undeformed, *_particles(motion, point_mass, w, v, free),
            *_sections(motion, appendage, rod.rule, w))


def _shared_terms(rod: Rod, free: bool, functions: dict, k: int):
    """:func:`_appendage_terms` of the exact rod as a function kept as a call
    (``never_inline``) of ``(w, v (free hub), eta, eta_t, frame (3, 3), root (3))``, the
    same function for every appendage of the structure whose function is the same
    (``functions``, by its serialisation: the appendages of one rod differ only in their
    frame and root)."""
    import casadi as ca

    n = 3 * rod.n_modes
    w, v = ca.SX.sym("w", 3), ca.SX.sym("v", 3)
    eta, eta_t = ca.SX.sym("eta", n), ca.SX.sym("eta_t", n)
    frame, root = ca.SX.sym("frame", 3, 3), ca.SX.sym("root", 3)
    inputs = [w, *([v] if free else []), eta, eta_t, frame, root]
    terms = _appendage_terms(rod, w, v if free else ca.SX.zeros(3, 1), eta, eta_t, free,
                             None, frame, root)
    plain = ca.Function("spatial_appendage", inputs, list(terms), {"cse": True})
    key = plain.serialize()
    if key not in functions:
        functions[key] = ca.Function(f"spatial_appendage_{k}", inputs, plain(*inputs),
                                     {"never_inline": True})
    return functions[key]


def truncated_motion(rod: Rod, eta, eta_t, order=None, frame=None, root=None) -> dict:
    """:meth:`Rod.motion` with the rod's kinematics kept to ``order`` in its deflections.

    Positions, tangents and section rotations are Taylor polynomials of degree ``order`` in
    ``(eta, eta_t)`` (the modal coordinates and their rates, scaled together by ``eps``);
    their Jacobians in ``eta`` (``jac``, ``spin_jac``) of degree ``order - 1``; the
    velocities and the convective accelerations are the same truncations of the exact ones
    (the rates of the truncated positions, to that degree).

    Parameters
    ----------
    rod : Rod
        The appendage's exact kinematics on its quadrature.
    eta, eta_t : casadi.SX, shape (3N,)
        The appendage's modal coordinates and rates.
    order : int or None, optional
        Degree kept (1 or 2); None (default) for the exact kinematics.
    frame, root : casadi.SX, optional
        The root frame and point as symbols (:meth:`Rod.motion`). Default the appendage's.

    Returns
    -------
    dict
        As :meth:`Rod.motion`.
    """
    import casadi as ca

    motion = rod.motion(eta, eta_t, frame, root)
    if order is None:
        return motion
    eps, both = ca.SX.sym("eps"), ca.vertcat(eta, eta_t)
    result = {}
    for degree, keys in ((order - 1, _JACOBIANS),
                         (order, [k for k in motion if k not in _JACOBIANS])):
        parts = [v for k in keys for v in (motion[k] if isinstance(motion[k], list)
                                            else [motion[k]])]
        flat = taylor(ca.substitute(ca.vertcat(*[ca.vec(p) for p in parts]), both, eps * both),
                      eps, degree)
        pieces = iter(ca.vertsplit(flat, np.cumsum([0] + [p.numel() for p in parts]).tolist()))
        for k in keys:
            shaped = [ca.reshape(next(pieces), p.shape) for p in (
                motion[k] if isinstance(motion[k], list) else [motion[k]])]
            result[k] = shaped if isinstance(motion[k], list) else shaped[0]
    return result


def taylor(expression, eps, order: int):
    """The Taylor polynomial of degree ``order`` of ``expression`` in ``eps`` about 0,
    evaluated at ``eps = 1`` (CasADi).

    Parameters
    ----------
    expression : casadi.SX
        Any shape.
    eps : casadi.SX
        A scalar symbol.
    order : int
        Degree (>= 0).

    Returns
    -------
    casadi.SX
        Same shape as ``expression``.
    """
    import casadi as ca

    total = ca.substitute(expression, eps, 0)
    term, factorial = expression, 1.0
    for k in range(1, order + 1):
        term = ca.reshape(ca.jacobian(ca.vec(term), eps), term.shape)
        factorial *= k
        total += ca.substitute(term, eps, 0) / factorial
    return total


def _first_order(layout: SpatialLayout, x, terms: _Terms) -> tuple:
    """``(M1, u_t)``: the residual ``mass u_t - (forces - bias)`` expanded to first order in
    the deflections (modal coordinates, rates and accelerations scaled together by ``eps``;
    the hub's motion and the torque exact), ``M1 u_t = f1``, solved.

    ``M1``'s modal columns are the straight structure's mass matrix (numbers): its hub
    columns gain the terms linear in the deflections (the deformed structure's inertia about
    the hub), the products of two deflections (``q q_tt``) drop. The solve eliminates the
    constant modal block (``_hub_schur_solve``)."""
    import casadi as ca

    n_u, h = layout.n_speeds, layout.n_speeds - layout.n_elastic
    eps = ca.SX.sym("eps")
    accel = ca.SX.sym("u_t", n_u)
    c, m = layout.n_coordinates, layout.n_elastic
    scaled_x = ca.vertcat(x[:c - m], eps * x[c - m:c], x[c:c + h], eps * x[c + h:])
    scaled_a = ca.vertcat(accel[:h], eps * accel[h:])
    residual = ca.mtimes(terms.mass, accel) - terms.forces + terms.bias
    residual = taylor(ca.substitute(residual, ca.vertcat(x, accel),
                                    ca.vertcat(scaled_x, scaled_a)), eps, 1)
    matrix = ca.jacobian(residual, accel)
    rest = -ca.substitute(residual, accel, ca.DM.zeros(n_u))
    modal = ca.evalf(matrix[:, h:]).full()         # numbers: the straight structure's
    return matrix, _hub_schur_solve(matrix[:h, :h], matrix[h:, :h], modal, rest, h,
                                    [layout.block(k) for k in range(len(layout.names))])


def _hub_schur_solve(a, c, modal: np.ndarray, rhs, h: int, blocks: list):
    """``[[a, b], [c, d]]^-1 rhs`` with the modal columns ``[b; d]`` (numbers) constant and
    ``d`` block diagonal (``blocks``: one slice per appendage): ``d^-1`` once, block by
    block, the Schur complement ``a - b d^-1 c`` (h x h) solved symbolically."""
    import casadi as ca
    from scipy.linalg import block_diag

    b, d = modal[:h], modal[h:]
    d_inv = block_diag(*[np.linalg.inv(d[k, k]) for k in blocks])
    through = ca.mtimes(ca.sparsify(ca.DM(d_inv)), ca.horzcat(c, rhs[h:]))   # d^-1 [c, f_e]
    hub = ca.solve(a - ca.mtimes(ca.DM(b), through[:, :h]),
                   rhs[:h] - ca.mtimes(ca.DM(b), through[:, h]))
    return ca.vertcat(hub, through[:, h] - ca.mtimes(through[:, :h], hub))


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


def quaternion_rotation(q):
    """The rotation matrix of a unit quaternion (hub to inertial), CasADi.

    Parameters
    ----------
    q : casadi.SX, shape (4,)
        Unit quaternion, scalar first.

    Returns
    -------
    casadi.SX, shape (3, 3)
        ``R(q)``: ``v_inertial = R v_hub``.
    """
    import casadi as ca

    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)),
        ca.horzcat(2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)),
        ca.horzcat(2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)))
