"""The three-axis LQR and LQG (:mod:`controllers.feedback.spatial_lqr`) as CasADi step
functions, and their compiled C flown in the spatial loop.

- **LQR.** Input ``v``: the plant state entries the law reads, by name (``qw qx qy qz``, the
  design's modal coordinates, ``wx wy wz``, a free hub's velocity, the modal rates); no memory.
  The step forms the attitude error (the rotation vector of ``target^-1 (x) q``, the short way
  round) and commands ``clip(-K x, +-torque_limit)``, three torques in the hub frame.
- **LQG.** Input ``v``: the readings ``qw qx qy qz wx wy wz`` (the attitude, normalised in the
  step, and the rate); memory ``[started, z]``, the filter's prediction on the design part and
  whether it has one. The first step starts the filter from the reading, the structure at
  rest; every step takes the reading, commands, and predicts the next sample with the
  clipped command and the attitude's kinematics, as
  :class:`~controllers.feedback.spatial_lqr.SpatialLQG`'s session does. The caller calls it
  once per sample of the design's hold.

:func:`compiled_spatial_law` turns a compiled export of one of them back into a law for
:func:`flexctl.sim.spatial_loop.simulate_spatial_loop`, which is how the C is checked against
Python in the loop.
"""

from __future__ import annotations

import numpy as np

from flexctl.model.errors import InputTypeError, InputValueError

from .program import ControllerProgram, ExportRefused

__all__ = ["spatial_program", "compiled_spatial_law"]

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


def _error(ca, target, q):
    """CasADi: the attitude error ``target^-1 (x) q`` as a rotation vector."""
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


def _lqr_program(law) -> ControllerProgram:
    import casadi as ca

    names = ("qw", "qx", "qy", "qz") + tuple(law.state_names[3:])
    t, v, m = ca.SX.sym("t"), ca.SX.sym("v", len(names)), ca.SX.sym("m", 0)
    state = ca.vertcat(_error(ca, law.target, v[0:4]), v[4:])
    u = _limited(ca, -ca.mtimes(ca.DM(law.gain), state), law.torque_limit)
    step = ca.Function("step", [t, v, m], [u, ca.SX.zeros(0)], ["t", "v", "m"],
                       ["u", "m_next"])
    held = "continuous" if law.sample_time is None else f"held over {law.sample_time:g} s"
    return ControllerProgram(
        kind="spatial_lqr", step=step, recover=None, input_names=names, input_kind="state",
        output_name="torque", output_unit="N m, hub frame", memory_init=np.zeros(0),
        sample_time=float(law.sample_time or 0.0),
        description=f"three-axis LQR on {len(law.state_names) - 3} design states, {held}",
        info={"design_states": len(law.state_names) - 3})


def _lqg_program(law) -> ControllerProgram:
    import casadi as ca

    regulator, part = law.regulator, law.regulator.part
    size = part.basis.shape[1]
    rate_at = regulator.state_names.index("wx")
    t, v, m = ca.SX.sym("t"), ca.SX.sym("v", len(READINGS)), ca.SX.sym("m", 1 + size)
    y = ca.vertcat(_error(ca, regulator.target, v[0:4]), v[4:7])
    start = ca.SX.zeros(part.basis.shape[0])
    start[0:3] = y[0:3]
    start[rate_at:rate_at + 3] = y[3:6]
    predicted = ca.if_else(m[0] > 0.5, m[1:], ca.mtimes(ca.DM(part.projector), start))
    estimate = predicted + ca.mtimes(ca.DM(law.filter_gain),
                                     y - ca.mtimes(ca.DM(law.measured), predicted))
    state = ca.mtimes(ca.DM(part.basis), estimate)
    u = _limited(ca, -ca.mtimes(ca.DM(regulator.gain), state), regulator.torque_limit)
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
                     f"{law.sample_time:g} s"),
        info={"estimate_states": size})


def spatial_program(law) -> ControllerProgram:
    """The :class:`~controllers.codegen.program.ControllerProgram` of a three-axis LQR or LQG
    (module description).

    Parameters
    ----------
    law : SpatialLQR or SpatialLQG
        The designed law.

    Returns
    -------
    ControllerProgram
        Its step: three torques (N m, hub frame) from the state entries or the readings.
    """
    from ..feedback.spatial_lqr import SpatialLQG, SpatialLQR

    regulator = getattr(law, "regulator", law)
    if getattr(regulator, "reference", None) is not None:
        raise ExportRefused("export: a three-axis law that follows a reference slew is not "
                            "written as C yet; export the regulator (design it without "
                            "reference) and feed its state the reference's deviation")
    if isinstance(law, SpatialLQR):
        return _lqr_program(law)
    if isinstance(law, SpatialLQG):
        return _lqg_program(law)
    raise InputTypeError(f"spatial_program takes a SpatialLQR or SpatialLQG; got "
                         f"{type(law).__name__}")


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
        A law with ``start``: an LQR's reads the plant state by name, an LQG's the attitude
        and rate.
    """
    kind = getattr(getattr(compiled, "program", None), "kind", None)
    if kind == "spatial_lqr":
        return _CompiledStateLaw(compiled)
    if kind == "spatial_lqg":
        return _CompiledReadingLaw(compiled)
    raise InputTypeError(f"compiled_spatial_law takes a compiled three-axis law; got "
                         f"{kind or type(compiled).__name__}")
