"""The three-axis NMPC's real-time iteration (:mod:`controllers.mpc.spatial_nmpc`) as one CasADi
step function, which CasADi writes as C with its QP solver (``qrqp``, an active-set solver
whose code it generates).

Input ``v``: the plant state entries the law reads, by name (``qw qx qy qz``, the design
model's ``x_l``, the wheels' speeds); memory ``[started, U]``, the previous plan's torques
(``3 N``, hold after hold). The step is :class:`~controllers.mpc.spatial_nmpc.SpatialNMPCSession`'s
call:

1. the reference over the horizon at ``t + j T`` (rest at the target, or a planned slew's design
   state and held torque, tabulated at its holds' ends and read at the law's samples, which
   are the plan's holds);
2. the warm start: the previous plan shifted one sample, the reference's torque appended (the
   first step: the reference's torques);
3. the rollout and each hold's exact Jacobians
   (:func:`~controllers.mpc.spatial_nmpc.hold_linearisation`, one function called ``N``
   times), the condensing onto the ``3 N`` torques and the wheels' rows as the session forms
   them, one QP (``qrqp``), the plan moved by its solution;
4. the first torque.

The ``recover`` function is the same step with the QP left out: the shifted plan, which the
Python session also commands when its QP fails. Where no limit binds, the session's step is
the QP's unconstrained minimiser and ``qrqp`` finds the same; where one binds, both solve the
same QP, ``qrqp`` to its own tolerance.
"""

from __future__ import annotations

import numpy as np

from .precision import qp_options
from .program import ControllerProgram, ExportRefused

__all__ = ["spatial_nmpc_program"]


def _tables(law):
    """CasADi interpolants of a planned slew's design state and held torque at its holds'
    ends (after the end: the final state, no torque), or None at rest."""
    import casadi as ca

    plan = law.reference
    if plan is None:
        return None
    hold = float(plan.model.hold)
    if abs(hold - law.sample_time) > 1e-9 * hold:
        raise ExportRefused(
            f"export: an NMPC following a planned slew is written as C when it samples at the "
            f"plan's holds ({hold:g} s; the C reads the plan at their ends); this one samples "
            f"at {law.sample_time:g} s: plan with n_intervals = duration / sample_time")
    times = np.asarray(plan.times, dtype=float)
    nodes = np.array([plan.state_at(t_k) for t_k in times])
    torques = np.vstack([plan.torque, np.zeros((1, 3))])
    state = ca.interpolant("nmpc_planned_state", "linear", [times],
                           nodes.T.ravel(order="F"))
    torque = ca.interpolant("nmpc_planned_torque", "linear", [times],
                            torques.T.ravel(order="F"))
    return times, state, torque


def _wanted(ca, law, tables, t):
    """``(r_j, v_j)`` for ``j = 0..N`` at ``t + j T``: design states (n + 3, N + 1) and torques
    (3, N + 1)."""
    horizon, n_design = law.horizon, len(law.state_names)
    if tables is None:
        return ca.MX.zeros(n_design, horizon + 1), ca.MX.zeros(3, horizon + 1)
    times, state, torque = tables
    states, torques = [], []
    for j in range(horizon + 1):
        at = ca.fmin(ca.fmax(t + j * law.sample_time, times[0]), times[-1])
        states.append(state(at))
        torques.append(torque(at))
    return ca.horzcat(*states), ca.horzcat(*torques)


def _condensed(ca, law, a_all, b_all, residuals, shifted, wanted_torques):
    """The session's condensing (``controllers.mpc.spatial_nmpc._solve``) in CasADi:
    the Hessian and gradient in the ``3 N`` torque moves and the speeds' rows."""
    n = law.model.a.shape[0]
    count = 0 if law.wheels is None else law.wheels.count
    horizon, m = law.horizon, n + 3 + count
    order = np.r_[n:n + 3, 0:n].tolist()
    r_mat = ca.DM(law.r_mat)
    hessian = ca.MX(ca.DM(np.kron(np.eye(horizon), law.r_mat)))
    gradient = ca.vec(ca.mtimes(r_mat, shifted - wanted_torques[:, :horizon]))
    sensitivity = ca.MX(m, 3 * horizon)
    speed_rows = []
    for j in range(horizon):
        sensitivity = ca.mtimes(a_all[j], sensitivity)
        sensitivity = sensitivity + ca.horzcat(ca.MX(m, 3 * j), b_all[j],
                                               ca.MX(m, 3 * (horizon - j - 1)))
        mapped = sensitivity[order, :]
        weighted = ca.mtimes(ca.DM(law.p_mat if j == horizon - 1 else law.q_mat), mapped)
        hessian = hessian + ca.mtimes(mapped.T, weighted)
        gradient = gradient + ca.mtimes(weighted.T, residuals[:, j])
        if count:
            speed_rows.append(sensitivity[n + 3:, :])
    return hessian, gradient, (ca.vertcat(*speed_rows) if count else None)


def _limits(ca, law, shifted, speed_rows, speed_starts, speeds):
    """The QP's rows and bounds as the session's ``_qp`` forms them: ``(a, lba, uba, lbx,
    ubx)``."""
    horizon = law.horizon
    flat = ca.vec(shifted)
    if law.wheels is None:
        limit = np.inf if law.torque_limit is None else law.torque_limit
        return (ca.MX(0, 3 * horizon), ca.MX(0, 1), ca.MX(0, 1), -limit - flat,
                limit - flat)
    wheels = law.wheels
    count = wheels.count
    limits = law.wheel_rows
    share, null = limits.share, limits.null
    torque_limits, speed_limits = limits.torque_limits, limits.speed_limits
    motor_now = ca.mtimes(ca.DM(share), shifted) + ca.mtimes(
        ca.DM(null), speed_starts - ca.DM(wheels.null_target))
    motor_rows = ca.MX(ca.DM(np.kron(np.eye(horizon), share)))
    if np.any(null):
        motor_rows = motor_rows + ca.vertcat(
            ca.MX(count, 3 * horizon),
            ca.mtimes(ca.DM(np.kron(np.eye(horizon - 1), null)), speed_rows[:-count, :]))
    rows = ca.vertcat(motor_rows, speed_rows)
    now = ca.vertcat(ca.vec(motor_now), ca.vec(speeds))
    bound = np.concatenate([np.tile(torque_limits, horizon), np.tile(speed_limits, horizon)])
    big = np.full(3 * horizon, np.inf)
    return rows, -bound - now, bound - now, -big, big


def spatial_nmpc_program(law, precision: str = "double") -> ControllerProgram:
    """The :class:`~controllers.codegen.program.ControllerProgram` of a three-axis NMPC
    (module description).

    Parameters
    ----------
    law : SpatialNMPC
        The designed NMPC (:func:`~controllers.mpc.spatial_nmpc.design_spatial_nmpc`).
    precision : {"double", "float"}, optional
        The precision the program will be written in: the QP's tolerances
        (:func:`~controllers.codegen.precision.qp_options`). Default ``"double"``.

    Returns
    -------
    ControllerProgram
        Its step: three torques commanded of the wheels (or on the hub), N m, hub frame.

    Raises
    ------
    ExportRefused
        For an NMPC following a planned slew at samples other than the plan's holds.
    """
    import casadi as ca

    from flexctl.model.checks import check_instance

    from controllers.mpc.nmpc import conic_solver
    from controllers.mpc.spatial_nmpc import SpatialNMPC, hold_linearisation

    from .precision import check_precision
    from .spatial_program import attitude_error

    check_instance("spatial_nmpc_program", "law", law, SpatialNMPC)
    precision = check_precision(precision)
    tables = _tables(law)
    model, horizon = law.model, law.horizon
    n = model.a.shape[0]
    count = 0 if law.wheels is None else law.wheels.count
    wheel_names = () if law.wheels is None else tuple(law.wheels.state_names[:count])
    names = ("qw", "qx", "qy", "qz") + tuple(law.state_names[3:]) + wheel_names
    t, v, memory = ca.MX.sym("t"), ca.MX.sym("v", len(names)), ca.MX.sym("m", 1 + 3 * horizon)
    q = v[0:4] / ca.norm_2(v[0:4])
    x, speeds = v[4:4 + n], v[4 + n:]
    started, previous = memory[0], ca.reshape(memory[1:], 3, horizon)
    states, torques = _wanted(ca, law, tables, t)
    shifted = ca.if_else(started > 0.5,
                         ca.horzcat(previous[:, 1:], torques[:, horizon - 1]),
                         torques[:, :horizon])
    hold = hold_linearisation(model, law.wheels)
    xs, qs, ss, a_all, b_all = [], [], [], [], []
    state = (x, q, speeds)
    for j in range(horizon):
        out = hold(*state, shifted[:, j])
        state = tuple(out[:3])
        xs.append(out[0])
        qs.append(out[1])
        ss.append(out[2])
        a_all.append(out[3])
        b_all.append(out[4])
    residuals = ca.horzcat(*[ca.vertcat(attitude_error(ca, law.target, qs[j]), xs[j])
                             for j in range(horizon)]) - states[:, 1:]
    hessian, gradient, speed_rows = _condensed(ca, law, a_all, b_all, residuals, shifted,
                                               torques)
    speed_starts = ca.horzcat(speeds, *ss[:-1]) if count else None
    rows, lba, uba, lbx, ubx = _limits(ca, law, shifted, speed_rows, speed_starts,
                                       ca.horzcat(*ss) if count else None)
    qp = conic_solver("spatial_nmpc_qp", "qrqp", ca.Sparsity.dense(3 * horizon, 3 * horizon),
                      ca.Sparsity.dense(rows.shape[0], 3 * horizon),
                      options=qp_options(precision))
    hessian = ca.densify(0.5 * (hessian + hessian.T))
    rows = ca.densify(rows)
    # the session's shortcut: the unconstrained minimiser where it meets every limit (the QP's
    # solution then), the QP solver only where it does not (a branch evaluated alone)
    free = -ca.solve(hessian, gradient, "ldl")
    meets = ca.logic_and(ca.mmin(free - lbx) >= 0, ca.mmin(ubx - free) >= 0)
    if rows.shape[0]:
        value = ca.mtimes(rows, free)
        meets = ca.logic_and(meets, ca.logic_and(ca.mmin(value - lba) >= 0,
                                                 ca.mmin(uba - value) >= 0))
    solved = qp(h=hessian, g=gradient, a=rows, lba=lba, uba=uba, lbx=lbx, ubx=ubx)["x"]
    move = ca.if_else(meets, free, solved, True)
    planned = shifted + ca.reshape(move, 3, horizon)

    def finish(plan, name):
        return ca.Function(name, [t, v, memory], [plan[:, 0], ca.vertcat(1.0, ca.vec(plan))],
                           ["t", "v", "m"], ["u", "m_next"])

    return ControllerProgram(
        kind="spatial_nmpc", step=finish(planned, "step"), recover=finish(shifted, "recover"),
        input_names=names, input_kind="state", output_name="torque",
        output_unit="N m, hub frame" + ("" if law.wheels is None else ", commanded of the wheels"),
        memory_init=np.zeros(1 + 3 * horizon), sample_time=float(law.sample_time),
        description=(f"three-axis NMPC real-time iteration, {model.equations.variant} design "
                     f"model on {n} states, horizon {horizon} x {law.sample_time:g} s, qrqp"
                     + ("" if law.reference is None else ", following a planned slew")),
        info={"design_states": n, "horizon": horizon, "qp_variables": 3 * horizon,
              "qp_constraints": int(rows.shape[0]), "wheels": count})
