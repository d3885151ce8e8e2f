"""A state law on the sensors' discrete Kalman filter
(:class:`controllers.feedback.observer.Observed`)
as a CasADi step function.

The step is :meth:`controllers.feedback.observer.ObservedSession.step` for a law called every
``sample_time`` (the flight computer's fixed rate): with the transport delay
``d = m T + r`` (``0 <= r < T``), the filter's epochs ``t_k - d`` and the command switches
between them fall at the same offsets every sample, so each propagation is a fixed chain of
holds (of ``r``, ``T - r`` or ``T`` seconds) with the commands of fixed earlier samples, a hold
before the first sample left out. The memory holds, in order: the filter state ``z``, its
covariance ``P`` (column-major), the commands of the last ``m`` plus two samples (newest first),
the samples taken, and the inner law's memory.
"""

from __future__ import annotations

import numpy as np

from .program import ControllerProgram, ExportRefused, plant_output

__all__ = ["observed_program"]


def _pieces(sample_time: float, delay: float) -> tuple:
    """``(m, r)``: whole samples and the remainder of the delay (r snapped to 0 within
    1e-9 of a sample)."""
    whole = int(np.floor(delay / sample_time + 1e-9))
    rest = delay - whole * sample_time
    if rest < 1e-9 * sample_time:
        rest = 0.0
    return whole, rest


def _update(z, p, y, mats, offset):
    """:func:`controllers.feedback.observer.kalman_update` (Joseph form) on CasADi expressions."""
    import casadi as ca

    c_mat, r_mat = ca.DM(mats.C), ca.DM(mats.R)
    innovation = y - ca.mtimes(c_mat, z) - offset
    s = ca.mtimes([c_mat, p, c_mat.T]) + r_mat
    gain = ca.solve(s, ca.mtimes(c_mat, p), "qr").T
    keep = ca.DM.eye(z.numel()) - ca.mtimes(gain, c_mat)
    p_plus = ca.mtimes([keep, p, keep.T]) + ca.mtimes([gain, r_mat, gain.T])
    return z + ca.mtimes(gain, innovation), 0.5 * (p_plus + p_plus.T)


def observed_program(observed, plant, x0, inner: ControllerProgram) -> ControllerProgram:
    """The program of ``observed`` on ``plant`` started at ``x0``, its law's program
    ``inner`` (reading the state).

    Parameters
    ----------
    observed : Observed
        The law on the sensors' Kalman filter (:class:`controllers.feedback.observer.Observed`).
    plant : flexctl.Model
        The plant the filter is built on (its linearisation at rest and its sensors).
    x0 : array_like, shape (n,)
        Plant state at the start: the filter's initial estimate.
    inner : ControllerProgram
        The program of ``observed.law`` (its ``input_kind`` must be ``"state"``).

    Raises
    ------
    ExportRefused
        If ``inner`` reads sensors rather than the state.
    """
    import casadi as ca

    from controllers.feedback.observer import ObservedSession

    if inner.input_kind != "state":
        raise ExportRefused("export: the law inside Observed must read the state")
    session = ObservedSession(observed, plant, np.asarray(x0, dtype=float))
    mats, n = session.matrices, plant.n_states
    n_f, n_y = mats.C.shape[1], mats.C.shape[0]
    period = observed.sample_time
    whole, rest = _pieces(period, observed.sensors.delay)
    history = whole + 2
    n_mem = n_f + n_f * n_f + history + 1 + inner.n_memory

    t, y, mem = ca.MX.sym("t"), ca.MX.sym("v", n_y), ca.MX.sym("m", n_mem)
    z, p = mem[:n_f], ca.reshape(mem[n_f:n_f + n_f * n_f], n_f, n_f)
    commands = mem[n_f + n_f * n_f:n_f + n_f * n_f + history]
    count = mem[n_f + n_f * n_f + history]
    inner_memory = mem[n_f + n_f * n_f + history + 1:]

    def command(i):
        """``(c_{k-i}, exists)``: the command of ``i`` samples ago."""
        return commands[i - 1], count >= i

    def predict(z, p, length, i):
        phi, gam, q = (ca.DM(v) for v in session._holds(length))
        u, on = command(i)
        p_new = ca.mtimes([phi, p, phi.T]) + q
        return (ca.if_else(on, ca.mtimes(phi, z) + gam * u, z),
                ca.if_else(on, 0.5 * (p_new + p_new.T), p))

    chain = ([(rest, whole + 2), (period - rest, whole + 1)] if rest > 0.0
             else [(period, whole + 1)])
    for length, i in chain:
        z, p = predict(z, p, length, i)
    held, on = command(whole + 1)
    offset = ca.DM(mats.D[:, 0]) * ca.if_else(on, held, 0.0)
    z, p = _update(z, p, y, mats, offset)
    # the estimate extrapolated from the epoch to now, the state alone
    x_now = z[:n]
    extrapolation = ([(rest, whole + 1)] if rest > 0.0 else []) + [
        (period, i) for i in range(whole, 0, -1)]
    for length, i in extrapolation:
        phi, gam, _ = session._holds(length)
        u, on = command(i)
        x_now = ca.if_else(on, ca.mtimes(ca.DM(phi[:n, :n]), x_now) + ca.DM(gam[:n, 0]) * u,
                           x_now)

    limit = session._limit

    def finish(function, name):
        u, inner_next = function(t, x_now, inner_memory)
        if limit is not None:
            u = ca.fmin(ca.fmax(u, -limit), limit)
        m_next = ca.vertcat(z, ca.vec(p), u, commands[:history - 1],
                            ca.fmin(count + 1, history), inner_next)
        return ca.Function(name, [t, y, mem], [u, m_next], ["t", "v", "m"], ["u", "m_next"])

    memory = np.concatenate((session._z, session._p.reshape(-1, order="F"), np.zeros(history),
                             [0.0], inner.memory_init))
    name, unit = (inner.output_name, inner.output_unit) if inner.output_name == "voltage" \
        else plant_output(plant)
    return ControllerProgram(
        kind=inner.kind, step=finish(inner.step, "step"),
        recover=None if inner.recover is None else finish(inner.recover, "recover"),
        input_names=tuple(session.names), input_kind="measurement", output_name=name,
        output_unit=unit, memory_init=memory, sample_time=float(period),
        description=(f"{inner.description}, on a discrete Kalman filter of the sensors "
                     f"({n_f} filter states, delay {observed.sensors.delay:g} s)"),
        info={**inner.info, "filter_states": n_f, "readings": n_y})
