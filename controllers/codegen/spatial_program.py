"""The three-axis LQR and LQG (:mod:`controllers.feedback.spatial_lqr`) as CasADi step
functions, and their compiled C flown in the spatial loop.

- **LQR.** Input ``v``: the plant state entries the law reads, by name (``qw qx qy qz``, the
  design's modal coordinates, ``wx wy wz``, a free hub's velocity, the modal rates); no memory.
  The step forms the attitude error (the rotation vector of ``target^-1 (x) q``, the short way
  round) and commands ``clip(-K x, +-torque_limit)``, three torques in the hub frame. One
  following an eigenaxis slew regulates the deviation from it (its profile in CasADi form)
  and adds its feedforward; one following a planned slew
  (:class:`~controllers.slew.spatial_trajopt.SpatialSlewSolution`), sampled at the plan's
  holds, reads the plan's design state and held torque from tables at the holds' ends (an
  LQG following one likewise).
- **LQG.** Input ``v``: the readings ``qw qx qy qz wx wy wz`` (the attitude, normalised in the
  step, and the rate); memory ``[started, z]``, the filter's prediction on the design part and
  whether it has one. The first step starts the filter from the reading, the structure at
  rest; every step takes the reading, commands, and predicts the next sample with the
  clipped command and the attitude's kinematics, as
  :class:`~controllers.feedback.spatial_lqr.SpatialLQG`'s session does. The caller calls it
  once per sample of the design's hold.

- **Scheduled LQR** (:class:`~controllers.feedback.spatial_scheduling.ScheduledSpatialLQR`).
  As the LQR, its attitude error from the spinning reference ``q_0 (x) exp(theta(t) a / 2)``
  and its gains interpolated in ``a . w`` between the design spins (clamped at the ends).
- **Quaternion feedback.** Input ``v``: the readings ``qw qx qy qz wx wy wz``; memory
  ``[started, t_last, integral (3)]``; the step is
  :class:`~controllers.feedback.quaternion.QuaternionFeedbackSession`'s call (the integral by
  the rectangle rule between calls, held while the command saturates).

:func:`compiled_spatial_law` turns a compiled export of a law back into a law for
:func:`flexctl.sim.spatial_loop.simulate_spatial_loop` (the attitude filters' programs are
:mod:`controllers.codegen.filter_program`'s): this is how the C is checked against Python in
the loop.
"""

from __future__ import annotations

import numpy as np

from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.quaternions import (symbolic_from_rotation_vector, symbolic_product,
                                     symbolic_rotation_vector)

from ..slew.reference import casadi_evaluate
from .program import ControllerProgram, ExportRefused

__all__ = ["spatial_program", "compiled_spatial_law", "attitude_error"]

READINGS = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")


def _rotation_vector(ca, q):
    """CasADi: the rotation vector of a quaternion (normalised here), the short way round."""
    q = q / ca.norm_2(q)
    sign = ca.if_else(q[0] < 0, -1.0, 1.0)
    w, v = sign * q[0], sign * q[1:4]
    s = ca.norm_2(v)
    # 2 atan2(s, w) / s, and its series below 1e-6 (where atan2(s, w) / s -> 1 / w)
    factor = ca.if_else(s > 1e-6, 2.0 * ca.atan2(s, w) / ca.fmax(s, 1e-300),
                        2.0 / w * (1.0 - s * s / (3.0 * w * w)))
    return factor * v


def attitude_error(ca, target, q):
    """CasADi: the attitude error ``target^-1 (x) q`` as a rotation vector, the short way round.

    Parameters
    ----------
    ca : module
        ``casadi``.
    target : array_like, shape (4,)
        The target attitude, scalar first.
    q : casadi.SX or casadi.MX, shape (4, 1)
        The attitude.

    Returns
    -------
    casadi.SX or casadi.MX, shape (3, 1)
        rad.
    """
    t0, tv = float(target[0]), ca.DM(-np.asarray(target[1:], dtype=float))
    qv = q[1:4]
    scalar = t0 * q[0] - ca.dot(tv, qv)
    vector = t0 * qv + q[0] * tv + ca.cross(tv, qv)
    return _rotation_vector(ca, ca.vertcat(scalar, vector))


def _limited(ca, u, limit):
    return u if limit is None else ca.fmin(ca.fmax(u, -limit), limit)


def _kinematics(ca, e, w):
    """CasADi: what the rotation vector's rate adds to ``e_t = w`` (as the session)."""
    angle = ca.norm_2(e)
    safe = ca.fmax(angle, 1e-4)
    factor = ca.if_else(angle < 1e-4, 1.0 / 12.0 + angle * angle / 720.0,
                        (1.0 - 0.5 * safe / ca.tan(0.5 * safe)) / (safe * safe))
    cross = ca.cross(e, w)
    return 0.5 * cross + factor * ca.cross(e, cross)


def _planned(ca, plan, t, state, law):
    """CasADi: the command following a planned slew at its holds' ends: its design state and
    held torque tabulated there (linear interpolants, read at the nodes the law samples;
    after the end, the final state and no torque)."""
    times = np.asarray(plan.times, dtype=float)
    nodes = np.array([plan.state_at(t_k) for t_k in times])            # (N + 1, n)
    torques = np.vstack([plan.torque, np.zeros((1, 3))])               # (N + 1, 3)
    reference = ca.interpolant("planned_state", "linear", [times],
                               nodes.T.ravel(order="F"))
    feedforward = ca.interpolant("planned_torque", "linear", [times],
                                 torques.T.ravel(order="F"))
    clamped = ca.fmin(ca.fmax(t, times[0]), times[-1])
    return _limited(ca, -ca.mtimes(ca.DM(law.gain), state - reference(clamped))
                    + feedforward(clamped), law.torque_limit)


def _regulated(ca, law, t, state):
    """CasADi: :meth:`SpatialLQR.command <controllers.feedback.spatial_lqr.SpatialLQR.command>`
    of the design state, an eigenaxis slew's or a planned slew's reference and feedforward
    included."""
    slew = law.reference
    if slew is None:
        return _limited(ca, -ca.mtimes(ca.DM(law.gain), state), law.torque_limit)
    if hasattr(slew, "state_at"):
        return _planned(ca, slew, t, state, law)
    angle, rate, acceleration = casadi_evaluate(slew.profile, t)
    axis = ca.DM(slew.axis)
    spin = rate * axis
    torque = slew.feedforward(angle, rate, acceleration)
    deviation = ca.vertcat(state[0:3] - (angle - slew.final_angle) * axis,
                           state[3:law.rate_at], state[law.rate_at:law.rate_at + 3] - spin,
                           state[law.rate_at + 3:])
    return _limited(ca, -ca.mtimes(ca.DM(law.gain), deviation) + torque, law.torque_limit)


def _lqr_program(law) -> ControllerProgram:
    import casadi as ca

    names = ("qw", "qx", "qy", "qz") + tuple(law.state_names[3:])
    kind = ca.MX if hasattr(law.reference, "state_at") else ca.SX     # tables want MX
    t, v, m = kind.sym("t"), kind.sym("v", len(names)), kind.sym("m", 0)
    state = ca.vertcat(attitude_error(ca, law.target, v[0:4]), v[4:])
    u = _regulated(ca, law, t, state)
    step = ca.Function("step", [t, v, m], [u, kind.zeros(0)], ["t", "v", "m"],
                       ["u", "m_next"])
    held = "continuous" if law.sample_time is None else f"held over {law.sample_time:g} s"
    if law.reference is not None:
        held += (", following a planned slew" if hasattr(law.reference, "state_at")
                 else ", following an eigenaxis slew")
    return ControllerProgram(
        kind="spatial_lqr", step=step, recover=None, input_names=names, input_kind="state",
        output_name="torque", output_unit="N m, hub frame", memory_init=np.zeros(0),
        sample_time=float(law.sample_time or 0.0),
        description=f"three-axis LQR on {len(law.state_names) - 3} design states, {held}",
        info={"design_states": len(law.state_names) - 3})


def _scheduled_program(law) -> ControllerProgram:
    import casadi as ca

    names = ("qw", "qx", "qy", "qz") + tuple(law.state_names[3:])
    t, v, m = ca.SX.sym("t"), ca.SX.sym("v", len(names)), ca.SX.sym("m", 0)
    angle, rate, acceleration = casadi_evaluate(law.profile, t)
    axis, inertia = ca.DM(law.spin_axis), ca.DM(law.inertia)
    start = ca.DM(law.start_attitude)
    reference = symbolic_product(start, symbolic_from_rotation_vector(angle * axis))
    error = symbolic_rotation_vector(symbolic_product(
        ca.vertcat(reference[0], -reference[1:4]), v[0:4]))
    at = law.rate_at + 1                                  # the rates in v (after qw..qz)
    spin = rate * axis
    design = ca.vertcat(error, v[4:at], v[at:at + 3] - spin, v[at + 3:])
    # K(a . w): the gains linear between the design spins, the end gains outside
    measured = ca.dot(axis, v[at:at + 3])
    rates, gains = law.spin_rates, law.gains
    gain = ca.DM(gains[0])
    for k in range(rates.size - 1):
        weight = ca.fmin(ca.fmax((measured - rates[k]) / (rates[k + 1] - rates[k]), 0.0), 1.0)
        gain = gain + weight * ca.DM(gains[k + 1] - gains[k])
    torque = acceleration * ca.mtimes(inertia, axis) + ca.cross(spin, ca.mtimes(inertia, spin))
    u = _limited(ca, torque - ca.mtimes(gain, design), law.torque_limit)
    step = ca.Function("step", [t, v, m], [u, ca.SX.zeros(0)], ["t", "v", "m"],
                       ["u", "m_next"])
    held = "continuous" if law.sample_time is None else f"held over {law.sample_time:g} s"
    return ControllerProgram(
        kind="spatial_lqr", step=step, recover=None, input_names=names, input_kind="state",
        output_name="torque", output_unit="N m, hub frame", memory_init=np.zeros(0),
        sample_time=float(law.sample_time or 0.0),
        description=(f"three-axis LQR scheduled over {rates.size} spins about "
                     f"{np.round(law.spin_axis, 6).tolist()}, {held}"),
        info={"design_states": len(law.state_names) - 3, "design_spins": rates.size})


def _lqg_program(law) -> ControllerProgram:
    import casadi as ca

    regulator, part = law.regulator, law.regulator.part
    size = part.basis.shape[1]
    rate_at = regulator.state_names.index("wx")
    kind = ca.MX if hasattr(regulator.reference, "state_at") else ca.SX   # tables want MX
    t, v, m = kind.sym("t"), kind.sym("v", len(READINGS)), kind.sym("m", 1 + size)
    y = ca.vertcat(attitude_error(ca, regulator.target, v[0:4]), v[4:7])
    rows = part.basis.shape[0]
    start = ca.vertcat(y[0:3], kind.zeros(rate_at - 3), y[3:6], kind.zeros(rows - rate_at - 3))
    predicted = ca.if_else(m[0] > 0.5, m[1:], ca.mtimes(ca.DM(part.projector), start))
    estimate = predicted + ca.mtimes(ca.DM(law.filter_gain),
                                     y - ca.mtimes(ca.DM(law.measured), predicted))
    state = ca.mtimes(ca.DM(part.basis), estimate)
    u = _regulated(ca, regulator, t, state)
    turned = _kinematics(ca, state[0:3], state[rate_at:rate_at + 3]) * law.sample_time
    following = (ca.mtimes(ca.DM(law.a_held), estimate) + ca.mtimes(ca.DM(law.b_held), u)
                 + ca.mtimes(ca.DM(part.projector[:, 0:3]), turned))
    step = ca.Function("step", [t, v, m], [u, ca.vertcat(1.0, following)], ["t", "v", "m"],
                       ["u", "m_next"])
    return ControllerProgram(
        kind="spatial_lqg", step=step, recover=None, input_names=READINGS,
        input_kind="measurement", output_name="torque", output_unit="N m, hub frame",
        memory_init=np.zeros(1 + size), sample_time=float(law.sample_time),
        description=(f"three-axis LQG, its filter on {size} states of the design part, "
                     f"{law.sample_time:g} s"
                     + (", following a planned slew" if kind is ca.MX else "")),
        info={"estimate_states": size})


def _quaternion_program(law) -> ControllerProgram:
    import casadi as ca

    t, v, m = ca.SX.sym("t"), ca.SX.sym("v", len(READINGS)), ca.SX.sym("m", 5)
    dq = symbolic_product(ca.vertcat(law.target[0], -ca.DM(law.target[1:])), v[0:4])
    error = 2.0 * dq[1:4] * ca.if_else(dq[0] >= 0, 1.0, -1.0)
    kp, kd, ki = (ca.DM(getattr(law, name)) for name in ("kp", "kd", "ki"))
    feedback = -ca.mtimes(kp, error) - ca.mtimes(kd, v[4:7] - ca.DM(law.target_rate))
    started, integral = m[0] > 0.5, m[2:5]
    grown = integral + error * (t - m[1])
    command = feedback - ca.mtimes(ki, grown)
    within = (1 if law.torque_limit is None
              else ca.mmax(ca.fabs(command)) <= law.torque_limit)
    kept = ca.if_else(ca.logic_and(started, within), grown, integral)
    u = _limited(ca, feedback - ca.mtimes(ki, kept), law.torque_limit)
    step = ca.Function("step", [t, v, m], [u, ca.vertcat(1.0, t, kept)], ["t", "v", "m"],
                       ["u", "m_next"])
    integral_action = bool(np.any(law.ki))
    return ControllerProgram(
        kind="quaternion_feedback", step=step, recover=None, input_names=READINGS,
        input_kind="measurement", output_name="torque", output_unit="N m, hub frame",
        memory_init=np.zeros(5), sample_time=0.0,
        description="quaternion feedback" + (" with integral action" if integral_action
                                             else "") + ", called once per sample",
        info={"integral_action": integral_action})


def spatial_program(law) -> ControllerProgram:
    """The :class:`~controllers.codegen.program.ControllerProgram` of a three-axis law
    (module description).

    Parameters
    ----------
    law : SpatialLQR, SpatialLQG, QuaternionFeedback or ScheduledSpatialLQR
        The designed law.

    Returns
    -------
    ControllerProgram
        Its step: three torques (N m, hub frame) from the state entries or the readings.
    """
    from ..feedback.quaternion import QuaternionFeedback
    from ..feedback.spatial_lqr import SpatialLQG, SpatialLQR
    from ..feedback.spatial_scheduling import ScheduledSpatialLQR

    if isinstance(law, QuaternionFeedback):
        return _quaternion_program(law)
    if isinstance(law, ScheduledSpatialLQR):
        if not callable(getattr(law.profile, "casadi_reference", None)):
            raise ExportRefused(f"export: the scheduled law's spin profile "
                                f"({type(law.profile).__name__}) has no CasADi form (a "
                                "SpinUp, a SteadySpin or a SlewProfile has)")
        return _scheduled_program(law)
    from ..slew.eigenaxis import EigenaxisSlew
    from ..slew.spatial_trajopt import SpatialSlewSolution

    regulator = getattr(law, "regulator", law)
    slew = getattr(regulator, "reference", None)
    if isinstance(slew, SpatialSlewSolution) and isinstance(law, (SpatialLQR, SpatialLQG)):
        hold = float(slew.model.hold)
        if regulator.sample_time is None or abs(regulator.sample_time - hold) > 1e-9 * hold:
            raise ExportRefused(
                f"export: a law following a planned slew is written as C when it samples at "
                f"the plan's holds ({hold:g} s; the C reads the plan at their ends); this one "
                f"samples at {regulator.sample_time!r} s: plan with n_intervals = duration / "
                "sample_time")
        return _lqg_program(law) if isinstance(law, SpatialLQG) else _lqr_program(law)
    if slew is not None and not isinstance(slew, EigenaxisSlew):
        raise ExportRefused(f"export: a three-axis law that follows a "
                            f"{type(slew).__name__} is not written as C; follow an "
                            "EigenaxisSlew or a planned slew (SpatialSlewSolution)")
    if slew is not None and not callable(getattr(slew.profile, "casadi_reference", None)):
        raise ExportRefused(f"export: the eigenaxis slew's profile "
                            f"({type(slew.profile).__name__}) has no CasADi form (a "
                            "SlewProfile, or a shaped one, has)")
    if isinstance(law, SpatialLQR):
        return _lqr_program(law)
    if isinstance(law, SpatialLQG):
        return _lqg_program(law)
    raise InputTypeError(f"spatial_program takes a SpatialLQR, SpatialLQG, QuaternionFeedback "
                         f"or ScheduledSpatialLQR; got {type(law).__name__}")


class _CompiledStateLaw:
    """A compiled LQR as a state-feedback law of the spatial loop."""

    state_feedback = True

    def __init__(self, compiled):
        self.compiled = compiled

    def start(self, state_names):
        names = self.compiled.program.input_names
        index = {name: k for k, name in enumerate(state_names)}
        missing = [name for name in names if name not in index]
        if missing:
            raise InputValueError(f"the plant has no state {missing[0]!r} that the compiled "
                                  "law reads")
        rows = np.array([index[name] for name in names], dtype=int)
        self.compiled.init()

        def session(t, attitude, rate, state):
            return _checked(self.compiled, t, np.asarray(state, dtype=float)[rows])
        return session


class _CompiledReadingLaw:
    """A compiled LQG as a law of the spatial loop that reads the attitude and the rate."""

    state_feedback = False

    def __init__(self, compiled):
        self.compiled = compiled

    def start(self):
        self.compiled.init()

        def session(t, attitude, rate):
            return _checked(self.compiled, t, np.concatenate([attitude, rate]))
        return session


def _checked(compiled, t, v) -> np.ndarray:
    u, code = compiled.step(t, v)
    if code != 0:
        raise RuntimeError(f"compiled law at t = {t:g} s returned code {code}")
    return u


def compiled_spatial_law(compiled):
    """A compiled three-axis law (:meth:`controllers.codegen.export.CExport.compile` of a
    :func:`spatial_program`) as a law of :func:`flexctl.sim.spatial_loop.simulate_spatial_loop`.

    Parameters
    ----------
    compiled : CompiledLaw
        The compiled export.

    Returns
    -------
    object
        A law with ``start``: an LQR's reads the plant state by name, an LQG's and a
        quaternion feedback's the attitude and rate.
    """
    kind = getattr(getattr(compiled, "program", None), "kind", None)
    if kind in ("spatial_lqr", "spatial_nmpc"):
        return _CompiledStateLaw(compiled)
    if kind in ("spatial_lqg", "quaternion_feedback"):
        return _CompiledReadingLaw(compiled)
    raise InputTypeError(f"compiled_spatial_law takes a compiled three-axis law; got "
                         f"{kind or type(compiled).__name__}")
