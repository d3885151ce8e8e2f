"""The NMPC's real-time iteration as one CasADi step function (:mod:`controllers.codegen`).

The step is :meth:`controllers.mpc.nmpc.NMPCSession.step` in the ``"rti"`` mode, every operation
a CasADi expression, so that CasADi writes it as C with its QP solver (``qrqp``, an
active-set solver whose code CasADi generates):

1. the design state: the plant state's design rows, or the extended Kalman filter's update
   with the readings (an NMPC with ``noise``);
2. the reference over the horizon at ``t + j T`` (the rest target, or the optimal slew's
   Hermite cubics and the mean of its held torque over each sample);
3. the warm start: the previous plan shifted one sample, its last hold repeated (the first
   step: the reference, or the state held);
4. condense (the compiled pieces of ``controllers.mpc.nmpc.NMPC._condensed``), solve the QP,
   expand;
5. the first torque, clipped to the torque limit and, after the first step, to the torque-rate
   limit.

The memory is ``[w (the plan), u_prev, started, x_hat (EKF), P (EKF, column-major)]``. The
``recover`` function is the same step with the QP left out: the shifted previous plan.
"""

from __future__ import annotations

import numpy as np

from flexctl.model.errors import InputValueError

from .precision import qp_options
from .program import ControllerProgram, ExportRefused, plant_output

__all__ = ["nmpc_program"]


def _check(mpc, plant):
    if mpc.mode != "rti":
        raise ExportRefused("export: an NMPC solved to convergence runs IPOPT, which CasADi "
                            "cannot write as C; use mode='rti' (one QP a sample)")
    if mpc.qp_solver != "qrqp":
        raise ExportRefused(f"export: the NMPC's QP solver {mpc.qp_solver!r} is a library "
                            "CasADi calls, not code it writes; use qp_solver='qrqp'")
    if plant.n_modes < mpc.model.n_modes:
        raise InputValueError(f"export: the NMPC's design model has {mpc.model.n_modes} modes, "
                              f"more than the plant's {plant.n_modes}")


def _all_finite(v):
    """MX: 1 when every entry of ``v`` is finite, else 0: the sum of the magnitudes is below
    infinity (an infinite entry makes it infinite, a NaN makes it NaN; entries so large that
    their sum overflows count as not finite too)."""
    import casadi as ca

    return ca.sum1(ca.fabs(v)) < ca.inf


def hermite_rows(t, grid, coef):
    """``state_at(t)`` of a :class:`~controllers.slew.trajopt.SlewSolution`, shape (n, 1).

    Parameters
    ----------
    t : CasADi scalar
        Time, s (MX: the hold found by a binary search, SX: by a chain of ``if_else``).
    grid : ndarray, shape (K+1,)
        The solution's grid times, s (``SlewSolution.t``).
    coef : ndarray, shape (K, 4, n)
        Its Hermite coefficients on each hold (``SlewSolution._hermite``).
    """
    import casadi as ca

    from flexctl.sim.compiled import piecewise_constant

    k_holds, _, n = coef.shape
    table = np.column_stack((grid[:-1], grid[1:], coef.reshape(k_holds, 4 * n)))
    row = (_looked_up(t, grid, table) if isinstance(t, ca.MX)
           else piecewise_constant(t, grid[1:-1], table))
    s = ca.fmin(ca.fmax((t - row[0]) / (row[1] - row[0]), 0.0), 1.0)
    c = [row[2 + j * n:2 + (j + 1) * n] for j in range(4)]
    return c[0] + s * (c[1] + s * (c[2] + s * c[3]))


#: Most buckets per hold of ``_hold_index``'s table (a grid whose shortest hold is much
#: shorter than its mean is searched instead).
BUCKETS_PER_HOLD = 4


def _hold_index(t, grid):
    """MX: the hold ``k`` of ``grid`` (K + 1 ascending times) with ``grid[k] <= t <
    grid[k + 1]`` (the first and last holds extend to infinity), as a float, in a number of
    operations that does not grow with K; None where the grid's holds are too uneven.

    ``t`` falls in one of equal buckets no longer than the shortest hold; a table gives the
    hold one before the one at the bucket's start, and three comparisons with the grid's
    times (exact, so that a time on a node is in the hold it starts) step on from there: a
    bucket holds at most one node, and the bucket found may be one off by rounding."""
    import casadi as ca

    k_holds = grid.size - 1
    length = float(np.min(np.diff(grid)))
    buckets = int(np.ceil((grid[-1] - grid[0]) / length)) + 1
    if buckets > BUCKETS_PER_HOLD * k_holds:
        return None
    starts = grid[0] + length * np.arange(buckets)
    first = np.clip(np.searchsorted(grid, starts, side="right") - 2, 0, k_holds - 1)
    bucket = ca.fmin(ca.fmax(ca.floor((t - grid[0]) / length), 0.0), buckets - 1.0)
    k0 = ca.MX(ca.DM(first.astype(float)))[bucket]
    # past the last node: its time again, so that the count stops at the last hold
    nodes = ca.MX(ca.DM(np.concatenate([grid, np.full(3, grid[-1])])))
    k = k0
    for step in (1.0, 2.0, 3.0):
        k = k + (t >= nodes[k0 + step])
    return ca.fmin(k, k_holds - 1.0)


def _looked_up(t, grid, table):
    """MX: the row of ``table`` (K, m) of the hold ``grid[k] <= t < grid[k + 1]`` of ``grid``
    (K + 1 ascending times; the first and last holds extend to infinity): its index by
    :func:`_hold_index`, its row read from the table at that index; on an uneven grid by
    binary searches (CasADi's linear interpolants: ``t`` to its fractional hold index, then
    that index, floored, to its row, read exactly at a node)."""
    import casadi as ca

    k_holds, m = table.shape
    if k_holds == 1:
        return ca.DM(table[0])
    k = _hold_index(t, grid)
    if k is not None:
        return ca.MX(ca.DM(table.ravel()))[k * m + ca.DM(np.arange(float(m)))]
    index = ca.interpolant("hold_index", "linear", [grid], np.arange(k_holds + 1.0))
    rows = ca.interpolant("hold_row", "linear", [np.arange(float(k_holds))],
                          table.T.ravel(order="F"))
    clamped = ca.fmin(ca.fmax(t, grid[0]), grid[-1])
    k = ca.fmin(ca.floor(index(clamped)), k_holds - 1.0)
    return rows(k)


def _impulse_at(t, edges, impulse):
    """``np.interp(t, edges, impulse)`` (clamped at both ends)."""
    import casadi as ca

    if isinstance(t, ca.MX):
        clamped = ca.fmin(ca.fmax(t, edges[0]), edges[-1])
        k = _hold_index(clamped, edges) if edges.size > 2 else ca.MX(0.0)
        if k is None:
            line = ca.interpolant("impulse", "linear", [edges], impulse)
            return line(clamped)
        at, values = ca.MX(ca.DM(edges)), ca.MX(ca.DM(impulse))
        start, low = at[k], values[k]
        return low + (values[k + 1.0] - low) * (clamped - start) / (at[k + 1.0] - start)
    from flexctl.sim.compiled import piecewise_constant

    table = np.column_stack((edges[:-1], edges[1:], impulse[:-1], impulse[1:]))
    row = piecewise_constant(t, edges[1:-1], table)
    slope = (row[3] - row[2]) / (row[1] - row[0])
    inside = slope * (t - row[0]) + row[2]
    return ca.if_else(t <= edges[0], impulse[0], ca.if_else(t >= edges[-1], impulse[-1],
                                                             inside))


def _reference(mpc, t):
    """``[r_0, v_0, ..., r_{N-1}, v_{N-1}, r_N]`` at ``t + j T`` (MX column): one function
    of time holding the tables once, mapped over the horizon's times (a loop in C)."""
    import casadi as ca

    n, big_n, step = mpc.model.n_states, mpc.horizon, mpc.sample_time
    if mpc.reference is None:
        rest = ca.DM(mpc.model.rest_state(mpc.target))
        return ca.vertcat(*([ca.vertcat(rest, 0.0)] * big_n + [rest]))
    solution = mpc.reference
    grid, coef = np.asarray(solution.t, dtype=float), np.asarray(solution._hermite)
    edges, values = mpc._reference_holds()
    impulse = np.concatenate(([0.0], np.cumsum(values * np.diff(edges))))
    time = ca.MX.sym("t")
    held = (_impulse_at(time + step, edges, impulse) - _impulse_at(time, edges, impulse)) / step
    at = ca.Function("nmpc_reference", [time],
                     [ca.vertcat(hermite_rows(time, grid, coef), held)])
    stages = at.map(big_n + 1)(ca.repmat(t, 1, big_n + 1)
                               + ca.DM(step * np.arange(big_n + 1)).T)      # (n + 1, N + 1)
    return ca.vertcat(ca.vec(stages[:, :big_n]), stages[:n, big_n])


def _first_guess(mpc, built, x_design):
    """The plan before the first step (:class:`~controllers.mpc.nmpc.NMPCSession`'s start): the
    reference, or ``x_design`` held."""
    import casadi as ca

    from controllers.mpc.nmpc import state_slice

    n, big_n = built["n"], mpc.horizon
    if mpc.reference is not None:
        refs, torques = mpc.reference_at(mpc.sample_time * np.arange(big_n + 1))
        w = np.zeros(built["nw"])
        for j in range(big_n + 1):
            w[state_slice(n, j)] = refs[:, j]
        bound = mpc.hub_torque_limit
        w[built["u_index"]] = np.clip(torques[:big_n], -bound, bound)
        return ca.DM(w)
    parts = [ca.vertcat(x_design, 0.0)] * big_n + [x_design]
    return ca.vertcat(*parts)


def _shifted(w, n, hold):
    """The plan moved one sample on, its last hold repeated (the plan itself when that is
    not finite), as ``_shift``."""
    import casadi as ca

    width = n + 1
    last_x, last_u = w[w.numel() - n:], w[w.numel() - n - 1]
    shifted = ca.vertcat(w[width:], last_u, hold(last_x, last_u))
    # short-circuit: the plan copied once, rather than both selected entry by entry
    return _pick(_all_finite(shifted), shifted, w)


def _pick(condition, first, second):
    """MX: ``first`` where ``condition`` is 1, else ``second`` (of one shape), by a switch
    between two functions of both: one copy, rather than an entry-by-entry selection of
    both (``if_else``) or the chosen one's dependencies computed again in its branch (a
    short-circuit ``if_else``)."""
    import casadi as ca

    a, b = ca.MX.sym("a", first.sparsity()), ca.MX.sym("b", second.sparsity())
    switch = ca.Function.conditional(
        "nmpc_pick", [ca.Function("nmpc_pick_second", [a, b], [b])],
        ca.Function("nmpc_pick_first", [a, b], [a]))
    return switch(condition, first, second)


class _Filter:
    """The extended Kalman filter of ``controllers.mpc.nmpc._ExtendedKalman`` in CasADi."""

    def __init__(self, mpc, plant, x0_design):
        import casadi as ca

        from controllers.feedback.lqg import measurement_rows
        from controllers.mpc.nmpc import hold_function

        model = mpc.model
        n = model.n_states
        self.n = n
        self.plant_rows = measurement_rows(plant)
        self.rows = measurement_rows(model)
        x, u = ca.MX.sym("x", n), ca.MX.sym("u")
        lin = hold_function(mpc.linearisation_model, mpc.sample_time, mpc.substeps)(x, u)
        self.jacobians = ca.Function("nmpc_ekf_jac", [x, u], [ca.jacobian(lin, x),
                                                               ca.jacobian(lin, u)])
        self.r = np.asarray(mpc.noise.measurement_covariance, dtype=float)
        self.q = float(mpc.noise.process_covariance[0, 0]) / mpc.sample_time
        self.init = np.concatenate((x0_design, (np.eye(n) * 1e-8).reshape(-1, order="F")))

    def update(self, memory, y, u_prev, started, hold):
        """``(x_hat, P)`` after this sample's prediction (from the second step on) and
        update, as MX."""
        import casadi as ca

        n = self.n
        x_hat = memory[:n]
        p = ca.reshape(memory[n:n + n * n], n, n)
        a, b = self.jacobians(x_hat, u_prev)
        x_pred = ca.if_else(started, hold(x_hat, u_prev), x_hat)
        p_pred = ca.if_else(started, ca.mtimes([a, p, a.T]) + self.q * ca.mtimes(b, b.T), p)
        c = ca.DM(self.rows)
        s = ca.mtimes([c, p_pred, c.T]) + ca.DM(self.r)
        gain = ca.solve(s, ca.mtimes(c, p_pred), "qr").T
        x_new = x_pred + ca.mtimes(gain, y - ca.mtimes(c, x_pred))
        p_new = ca.mtimes(ca.DM.eye(n) - ca.mtimes(gain, c), p_pred)
        return x_new, p_new


def nmpc_program(mpc, plant, x0, precision: str = "double") -> ControllerProgram:
    """The :class:`~controllers.codegen.program.ControllerProgram` of ``mpc`` on ``plant``.

    Parameters
    ----------
    mpc : NMPC
        A real-time iteration with ``qp_solver="qrqp"`` (:class:`controllers.mpc.nmpc.NMPC`).
    plant : flexctl.Model
        The plant the law reads, with at least the design model's modes.
    x0 : array_like, shape (n,)
        Plant state at the start: where the extended Kalman filter starts (an NMPC with
        ``noise``).
    precision : {"double", "float"}, optional
        The precision the program will be written in: the QP's tolerances
        (:func:`~controllers.codegen.precision.qp_options`). Default ``"double"``.

    Raises
    ------
    ExportRefused
        For an NMPC solved to convergence or with another QP solver.
    InputValueError
        If the plant has fewer modes than the design model.
    """
    import casadi as ca

    from controllers.mpc.nmpc import conic_solver, input_index

    _check(mpc, plant)
    mpc._problem()          # validates and sets the sizes
    model, big_n = mpc.model, mpc.horizon
    n = model.n_states
    built = dict(mpc._built)
    from controllers.mpc.nmpc import hold_function

    hold = hold_function(model, mpc.sample_time, mpc.substeps)
    pieces = mpc._condensed(hold, mpc.state_weights, mpc.torque_weight,
                            mpc._terminal_weight(), compiled=False)
    qp = conic_solver("nmpc_qp", "qrqp", pieces["h_sparsity"], pieces["a_sparsity"],
                      options=qp_options(precision))
    nw = built["nw"]
    rows = plant.layout.projection(model.layout)
    ekf = None if mpc.noise is None else _Filter(mpc, plant, np.asarray(x0, dtype=float)[rows])
    n_in = plant.n_states if ekf is None else ekf.plant_rows.shape[0]
    n_mem = nw + 2 + (0 if ekf is None else n + n * n)

    t, v, m = ca.MX.sym("t"), ca.MX.sym("v", n_in), ca.MX.sym("m", n_mem)
    w, u_prev, started = m[:nw], m[nw], m[nw + 1]
    extra = []
    if ekf is None:
        x_design = v[rows.tolist()]
    else:
        x_hat, p_new = ekf.update(m[nw + 2:], v, u_prev, started, hold)
        x_design = x_hat
        extra = [x_hat, ca.reshape(p_new, n * n, 1)]
    par = ca.vertcat(x_design, u_prev, _reference(mpc, t))
    # the first plan holds the state read (an EKF's: the state it starts from)
    start = x_design if ekf is None else ca.DM(ekf.init[:n])
    guess = ca.if_else(started, _shifted(w, n, hold), _first_guess(mpc, built, start), True)
    guess = ca.vertcat(x_design, guess[n:])
    h, g, a, lba, uba, lbx, ubx, affine, gains = pieces["condense"](guess, par)
    solution = qp(h=h, g=g, a=a, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
    planned = pieces["expand"](guess, affine, gains, solution["x"])

    def finish(plan, name):
        bound = mpc.hub_torque_limit
        u = ca.fmin(ca.fmax(plan[input_index(n, 0)], -bound), bound)
        if mpc.torque_rate_limit is not None:
            step = mpc.torque_rate_limit * mpc.sample_time
            u = ca.if_else(started, ca.fmin(ca.fmax(u, u_prev - step), u_prev + step), u)
        m_next = ca.vertcat(plan, u, 1.0, *extra)
        return ca.Function(name, [t, v, m], [u, m_next], ["t", "v", "m"], ["u", "m_next"])

    memory = np.concatenate((np.zeros(nw), [0.0, 0.0], [] if ekf is None else ekf.init))
    if mpc.reference is not None:
        memory[:nw] = np.array(_first_guess(mpc, built, None)).reshape(-1)
    first = np.asarray(x0, dtype=float) if ekf is None else ekf.plant_rows @ np.asarray(
        x0, dtype=float)
    hessian = np.array(ca.Function("nmpc_hessian", [t, v, m], [h])(0.0, first, memory))
    if ekf is None:
        names, kind, matrix = tuple(plant.state_names), "state", None
    else:
        from controllers.feedback.lqg import measured_outputs
        names, kind, matrix = tuple(measured_outputs(plant)), "measurement", ekf.plant_rows
    out_name, unit = plant_output(plant)
    return ControllerProgram(
        kind="nmpc", step=finish(planned, "step"), recover=finish(guess, "recover"),
        input_names=names, input_kind=kind, output_name=out_name, output_unit=unit,
        memory_init=memory, sample_time=float(mpc.sample_time), measurement_matrix=matrix,
        description=(f"NMPC real-time iteration, {model.variant} design model with "
                     f"{model.n_modes} modes, horizon {big_n} x {mpc.sample_time:g} s, qrqp"
                     + (", extended Kalman filter" if ekf is not None else "")),
        info={"design_modes": model.n_modes, "horizon": big_n, "qp_variables": big_n,
              "qp_constraints": int(pieces["rows"]), "design_variant": model.variant,
              "qp_hessian_condition": float(np.linalg.cond(hessian)),
              **({} if ekf is None else {"ekf_states": n, "ekf_offset": nw + 2})})
