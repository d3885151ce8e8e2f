"""The equations of several appendages on a pinned or free hub, as CasADi functions.

Every variant is written once in the accelerations ``(theta_tt, a, q_tt)``, ``a`` the hub
centre's acceleration in hub axes (free hub only), as ``docs/theory/free_hub.md`` section 3
derives them::

    M(q) [theta_tt; a; q_tt] = [T_h - c_h theta_t; 0; -K_ff q - C_ff q_t] - bias(q, v)

    M = [[ J(q)        (e_z x S)^T   M_tq ]      bias = [ b_theta                          ]
         [ e_z x S     m I_2         S_q  ]             [ S_acc + 2 theta_t e_z x S_q q_t  ]
         [ M_tq^T      S_q^T         M_qq ]]            [        - theta_t^2 S             ]
                                                        [ b_q                              ]

with ``S(q)`` the first moment of the appendages about the hub centre (hub axes) and ``S_q`` its
Jacobian. The pinned-hub blocks ``J, M_tq, M_qq, b_theta, b_q`` are those of :ref:`the model
<sec-continuous>`, appendage by appendage: for first_order, zero_order and consistent the modal
matrices (:mod:`flexctl.model.structure_matrices`) with ``S = S_0 + N q``; for exact each
appendage's geometry (:func:`flexctl.model.exact.appendage_terms`) rotated by its mounting
angle. A pinned hub drops the ``a`` row and column. The inertial hub acceleration is ``R(theta)
a``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .exact import appendage_terms, choose_rule, symmetric_solve

__all__ = ["StructureFunctions", "structure_functions", "output_function"]

_E = np.array([[0.0, -1.0], [1.0, 0.0]])        # e_z x


@dataclass(frozen=True, eq=False)
class StructureFunctions:
    """CasADi functions of one structure model (built by :func:`structure_functions`).

    Attributes
    ----------
    rhs : ``(x, u) -> xdot``
    mass : ``x -> M`` in the accelerations ``(theta_tt, [a], q_tt)``
    energy : ``x -> E``, J (the consistent energy for the small-deflection variants)
    momentum : ``x -> [H_O, P_x, P_y]``: angular momentum about the inertial origin, kg m^2/s,
        and linear momentum, kg m/s (zero for a pinned hub's structure is not reported: the
        pin's reaction carries it)
    center : ``x -> r_G``, the centre of mass in inertial axes, m
    outputs : ``x -> y`` in the model's output order
    beam : ``(q, q_dot, rate, acceleration) -> q_tt`` under a prescribed hub rotation
        (pinned hub)
    torque : ``(x, theta_tt, q_tt) -> T_h`` (pinned hub)
    rules : tuple of Quadrature
        Gauss-Legendre points per panel and panels of each appendage (exact variant), else ().
    hub_torque, signals : ``(x, u) -> T_hub``, ``(x, u) -> s``
        With an actuator (:mod:`flexctl.model.actuated`): the torque it puts on the structure
        and its signals; ``None`` otherwise.
    """

    rhs: object = field(repr=False)
    mass: object = field(repr=False)
    energy: object = field(repr=False)
    momentum: object = field(repr=False)
    center: object = field(repr=False)
    outputs: object = field(repr=False)
    beam: object = field(repr=False)
    torque: object = field(repr=False)
    rules: tuple = ()
    hub_torque: object = field(default=None, repr=False)
    signals: object = field(default=None, repr=False)


def _rotation(angle):
    import casadi as ca
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.blockcat([[c, -s], [s, c]])


def _small_blocks(mat, variant, q, q_dot, rate, for_energy=False):
    """Pinned-hub blocks and first moments of the small-deflection variants."""
    import casadi as ca

    dm = ca.DM
    d = dm(mat.D)
    j = mat.J0
    if variant.quadratic_inertia or for_energy:
        j = j + ca.dot(q, ca.mtimes(d, q))
    stiff_d = dm(variant.spin_matrix(mat))
    b_t = 2.0 * rate * ca.dot(q, ca.mtimes(d, q_dot)) if variant.quadratic_inertia else 0.0
    tips = []
    for k, app in enumerate(mat.system.appendages):
        block = mat.slices[k]
        reach = mat.system.root_radius(app) + app.beam.length
        tips.append(ca.vertcat(reach, ca.dot(dm(mat.tip[k, block]), q[block])))
    return dict(m_tt=j, m_tq=dm(mat.m_tf).T, m_qq=dm(mat.M_ff), b_t=b_t,
                b_q=-rate ** 2 * ca.mtimes(stiff_d, q),
                first=dm(mat.first) + ca.mtimes(dm(mat.first_q), q), first_q=dm(mat.first_q),
                first_acc=dm.zeros(2), tips=tips)


def _exact_blocks(mat, rules, q, q_dot, rate):
    """Pinned-hub blocks and first moments of the exact variant, appendage by appendage."""
    import casadi as ca

    n = mat.n_modes
    out = dict(m_tt=mat.system.hub.inertia, m_tq=ca.SX.zeros(1, n), m_qq=ca.SX.zeros(n, n),
               b_t=0.0, b_q=ca.SX.zeros(n), first=ca.SX.zeros(2), first_q=ca.SX.zeros(2, n),
               first_acc=ca.SX.zeros(2), tips=[])
    for k, (part, app) in enumerate(zip(mat.parts, mat.system.appendages)):
        block = mat.slices[k]
        t = appendage_terms(part.system, part.n_modes, rules[k], q[block], q_dot[block], rate)
        rot = ca.DM(np.array([[np.cos(app.angle), -np.sin(app.angle)],
                              [np.sin(app.angle), np.cos(app.angle)]]))
        out["m_tt"] = out["m_tt"] + t["m_tt"]
        out["m_tq"][0, block] = t["m_tq"]
        out["m_qq"][block, block] = t["m_qq"]
        out["b_t"] = out["b_t"] + t["b_t"]
        out["b_q"][block] = t["b_q"]
        out["first"] = out["first"] + ca.mtimes(rot, t["first"])
        out["first_q"][:, block] = ca.mtimes(rot, t["first_q"])
        out["first_acc"] = out["first_acc"] + ca.mtimes(rot, t["first_acc"])
        out["tips"].append(t["tip"])
    return out


def _assemble(blocks, mat, free, q_dot, rate):
    """Mass matrix and bias in the accelerations ``(theta_tt, [a], q_tt)``."""
    import casadi as ca

    if not free:
        mass = ca.blockcat([[blocks["m_tt"], blocks["m_tq"]], [blocks["m_tq"].T, blocks["m_qq"]]])
        return mass, ca.vertcat(blocks["b_t"], blocks["b_q"])
    e = ca.DM(_E)
    e_s, s_q = ca.mtimes(e, blocks["first"]), blocks["first_q"]
    mass = ca.blockcat([[blocks["m_tt"], e_s.T, blocks["m_tq"]],
                        [e_s, mat.mass * ca.DM.eye(2), s_q],
                        [blocks["m_tq"].T, s_q.T, blocks["m_qq"]]])
    b_a = (blocks["first_acc"] + 2.0 * rate * ca.mtimes(e, ca.mtimes(s_q, q_dot))
           - rate ** 2 * blocks["first"])
    return mass, ca.vertcat(blocks["b_t"], b_a, blocks["b_q"])


def _constant_inverse(mass):
    """The inverse of a constant CasADi matrix, symmetrised, as a ``DM``."""
    import casadi as ca

    inverse = np.linalg.inv(np.array(ca.DM(ca.evalf(mass))))
    return ca.DM(0.5 * (inverse + inverse.T))


def _solve(mass, rhs, variables, condensed=None):
    """``mass^-1 rhs``: through a numeric inverse where ``mass`` is constant, through the
    Schur complement of the hub rotation where only its row and column vary (the
    small-deflection variants: ``J(q)`` and ``e_z x S(q)``), else a symbolic solve.
    ``condensed = (J_0, J_0 - m_tf^T M_ff^-1 m_tf)`` of a pinned hub, the second computed
    without the cancelling subtraction, gives the Schur complement as it plus the varying
    part of ``J(q)`` (a heavy tip mass made the subtraction 30 times too large)."""
    import casadi as ca

    if not ca.depends_on(mass, variables):
        return ca.mtimes(_constant_inverse(mass), rhs)
    n = mass.size1()
    rest = mass[1:, 1:]
    if n == 1 or ca.depends_on(rest, variables):
        # the kinetic-energy metric is symmetric positive definite
        return symmetric_solve(mass, rhs) if isinstance(mass, ca.SX) else ca.solve(mass, rhs)
    inverse = _constant_inverse(rest)
    column = mass[1:, 0]
    g = ca.mtimes(inverse, column)
    schur = mass[0, 0] - ca.dot(column, g) if condensed is None \
        else condensed[1] + (mass[0, 0] - condensed[0])
    hub = (rhs[0] - ca.dot(g, rhs[1:])) / schur
    return ca.vertcat(hub, ca.mtimes(inverse, rhs[1:]) - g * hub)


def structure_functions(model) -> StructureFunctions:
    """Build the CasADi functions of a structure ``model`` (see the module docstring).

    Parameters
    ----------
    model : StructureModel
        The structure's model: its matrices, variant and state layout.
    """
    import casadi as ca

    mat, variant, layout = model.matrices, model.variant, model.layout
    free = mat.system.free
    rules = _rules(mat) if variant.exact else ()
    x, u = ca.SX.sym("x", layout.n_states), ca.SX.sym("u")
    theta, q, rate, q_dot = layout.split(x)

    def blocks(for_energy=False, qq=q, qd=q_dot, w=rate):
        if variant.exact:
            return _exact_blocks(mat, rules, qq, qd, w)
        return _small_blocks(mat, variant, qq, qd, w, for_energy)

    terms = blocks()
    mass, bias = _assemble(terms, mat, free, q_dot, rate)
    rot = _rotation(theta)
    v_hub = ca.mtimes(rot.T, x[layout.hub_velocity]) if free else None
    forces = ca.vertcat(u - mat.system.hub.friction * rate, ca.SX.zeros(2 if free else 0),
                        -ca.mtimes(ca.DM(mat.K_ff), q) - ca.mtimes(ca.DM(mat.C_ff), q_dot))
    condensed = None if free or variant.exact else (mat.J0, mat.condensed_inertia)
    acc = _solve(mass, forces - bias, x, condensed)
    n_q = mat.n_modes
    parts = dict(theta=rate, q=q_dot, theta_dot=acc[0], q_dot=acc[acc.size1() - n_q:])
    if free:
        parts.update(hub_position=x[layout.hub_velocity],
                     hub_velocity=ca.mtimes(rot, acc[1:3]))
    rhs = ca.Function(f"flexctl_{variant}_structure", [x, u], [layout.join(**parts)],
                      ["x", "u"], ["xdot"], {"cse": True})

    velocity = ca.vertcat(rate, v_hub, q_dot) if free else ca.vertcat(rate, q_dot)
    e_mass = mass if variant.exact else _assemble(blocks(True), mat, free, q_dot, rate)[0]
    energy = (0.5 * ca.dot(velocity, ca.mtimes(e_mass, velocity))
              + 0.5 * ca.dot(q, ca.mtimes(ca.DM(mat.K_ff), q)))
    generalized = ca.mtimes(mass, velocity)
    hub = x[layout.hub_position] if free else ca.DM.zeros(2)
    linear = ca.mtimes(rot, generalized[1:3]) if free else ca.DM.zeros(2)
    angular = generalized[0] + hub[0] * linear[1] - hub[1] * linear[0]
    center = hub + ca.mtimes(rot, terms["first"]) / mat.mass
    functions = dict(
        rhs=rhs,
        mass=ca.Function("structure_mass", [x], [mass], ["x"], ["M"]),
        energy=ca.Function("structure_energy", [x], [energy], ["x"], ["E"]),
        momentum=ca.Function("structure_momentum", [x], [ca.vertcat(angular, linear)],
                             ["x"], ["h"]),
        center=ca.Function("structure_center", [x], [center], ["x"], ["r_G"]),
        outputs=ca.Function("structure_outputs", [x], [_outputs(model, x, terms["tips"])],
                            ["x"], ["y"]))
    functions.update(_prescribed(model, blocks, free))
    return StructureFunctions(rules=rules, **functions)


def output_function(model):
    """The outputs (:attr:`Model.output_names`) of a small-deflection ``model`` as a CasADi
    function ``x -> y``, built alone: for many modes, the structure's whole set of functions
    takes seconds (1.7 s at 200 modes) where a run needs only its outputs' matrix. The same
    expressions as :attr:`StructureFunctions.outputs`.

    Parameters
    ----------
    model : Model
        A model of a small-deflection variant.

    Returns
    -------
    casadi.Function
    """
    import casadi as ca

    mat, variant, layout = model.matrices, model.variant, model.layout
    if variant.exact:
        raise ValueError("output_function: the exact variant's outputs need its quadrature; "
                         "take structure_functions(model).outputs")
    x = ca.SX.sym("x", layout.n_states)
    _, q, rate, q_dot = layout.split(x)
    tips = _small_blocks(mat, variant, q, q_dot, rate)["tips"]
    return ca.Function("structure_outputs", [x], [_outputs(model, x, tips)], ["x"], ["y"])


def _rules(mat) -> tuple:
    """Quadrature of each appendage: :func:`~flexctl.model.exact.choose_rule` on
    the appendage with the rest of the structure's inertia as its hub (the accelerations it
    compares depend on the hub it turns)."""
    from .matrices import assemble
    from .parameters import Hub

    out = []
    for k, part in enumerate(mat.parts):
        others = mat.J0 - part.J0
        system = dataclasses.replace(part.system, hub=Hub(inertia=others,
                                                          radius=part.system.hub.radius))
        out.append(choose_rule(system, assemble(system, part.n_modes)))
    return tuple(out)


def _outputs(model, x, tips):
    """Outputs in :attr:`Model.output_names` order."""
    import casadi as ca

    mat, layout = model.matrices, model.layout
    theta, q, rate, _ = layout.split(x)
    y = [theta, rate]
    if mat.system.free:
        y += [x[layout.hub_position][0], x[layout.hub_position][1]]
    for k, tip in enumerate(tips):
        block = mat.slices[k]
        root = ca.dot(ca.DM(mat.root[k, block]), q[block])
        if model.variant.exact:
            angle = theta + ca.atan2(tip[1], tip[0])
        else:
            angle = theta + tip[1] / tip[0]
        y += [tip[1], root, angle]
    return ca.vertcat(*y)


def _prescribed(model, blocks, free) -> dict:
    """The beam rows under a prescribed hub rotation and the hub row (pinned hub only)."""
    import casadi as ca

    if free:
        return dict(beam=None, torque=None)
    mat, layout = model.matrices, model.layout
    n = mat.n_modes
    qs, qds, w, acc_hub = (ca.SX.sym("q", n), ca.SX.sym("q_dot", n), ca.SX.sym("rate"),
                           ca.SX.sym("acceleration"))
    t = blocks(qq=qs, qd=qds, w=w)
    load = (-ca.mtimes(ca.DM(mat.K_ff), qs) - ca.mtimes(ca.DM(mat.C_ff), qds) - t["b_q"]
            - t["m_tq"].T * acc_hub)
    beam = ca.Function("structure_beam", [qs, qds, w, acc_hub],
                       [_solve(t["m_qq"], load, ca.vertcat(qs, qds, w, acc_hub))],
                       ["q", "q_dot", "rate", "acceleration"], ["q_tt"])
    x = ca.SX.sym("x", layout.n_states)
    theta_tt, q_tt = ca.SX.sym("theta_tt"), ca.SX.sym("q_tt", n)
    _, q, rate, q_dot = layout.split(x)
    t = blocks(qq=q, qd=q_dot, w=rate)
    row = (t["m_tt"] * theta_tt + ca.mtimes(t["m_tq"], q_tt) + t["b_t"]
           + mat.system.hub.friction * rate)
    torque = ca.Function("structure_torque", [x, theta_tt, q_tt], [row],
                         ["x", "theta_tt", "q_tt"], ["torque"])
    return dict(beam=beam, torque=torque)
