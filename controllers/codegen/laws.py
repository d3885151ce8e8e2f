"""The :class:`~controllers.codegen.program.ControllerProgram` of each built-in law.

:func:`program_for` builds the program of a designed law bound to its plant, or refuses with
the reason: a law with no CasADi form (a Python callable), an NMPC that is not a real-time
iteration with ``qrqp`` (IPOPT and the osqp / qpOASES / HPIPM plugins are libraries CasADi
calls, not code it writes), a continuous estimator with no sample time to discretise it at.
The static laws (PD, LQR, scheduled LQR, the tracker, an open-loop torque) and a DC motor's
voltage are here; the NMPC, LQG and Observed programs have a module each.
"""

from __future__ import annotations

import numpy as np

from flexctl.model.checks import check_array
from flexctl.model.errors import InputTypeError
from flexctl.sim.digital import ZeroOrderHold, is_sampled

from .precision import check_precision
from .program import ControllerProgram, ExportRefused, plant_output

__all__ = ["program_for", "filtered_program"]


def program_for(controller, plant, *, sample_time: float | None = None,
                initial_state=None, precision: str = "double") -> ControllerProgram:
    """The :class:`ControllerProgram` of a designed ``controller`` run on ``plant``.

    Parameters
    ----------
    controller : object
        A flexctl feedback law: PD, LQR, ScheduledLQR, TrajectoryTracker, LQG, NMPC, one of
        them sampled (:class:`~flexctl.sim.digital.ZeroOrderHold`) or driving an actuator
        (:class:`~controllers.feedback.actuated.MotorVoltage`,
        :class:`~controllers.feedback.actuated.LaggedLQR`).
    plant : flexctl.Model
        The plant the law reads (its state order, sensors and actuator).
    sample_time : float, optional
        Sample time, s: the rate a continuous estimator (LQG) is discretised at, or a static
        law sampled at. A law that samples itself keeps its own and refuses another.
    initial_state : array_like, optional
        Plant state at the start, shape (n,): where an estimator's estimate starts (default:
        at rest, zero).
    precision : {"double", "float"}, optional
        The precision the program will be written in: it sets an NMPC's QP tolerances
        (:func:`~controllers.codegen.precision.qp_options`). Default ``"double"``.

    Raises
    ------
    ExportRefused
        For a law that cannot be written as C, with the reason.
    """
    from flexctl.model import Model

    if not isinstance(plant, Model):
        raise InputTypeError(f"export plant must be a flexctl Model; got {type(plant).__name__}")
    if sample_time is not None:
        from flexctl.sim.digital import check_sample_time
        sample_time = check_sample_time("export", sample_time)
    x0 = np.zeros(plant.n_states) if initial_state is None else check_array(
        "export", "initial_state", initial_state, shape=(plant.n_states,))
    return _dispatch(controller, plant, sample_time, x0, check_precision(precision))


def _dispatch(controller, plant, sample_time, x0, precision):
    from controllers.feedback.actuated import MotorVoltage
    from controllers.feedback.lqg import LQG
    from controllers.mpc.nmpc import NMPC
    from controllers.feedback.observer import Observed
    from controllers.feedback.structural_filters import Filtered

    if isinstance(controller, MotorVoltage):
        return _voltage_program(controller, plant, sample_time, x0, precision)
    if isinstance(controller, ZeroOrderHold):
        own = controller.sample_time
        if sample_time is not None and abs(sample_time - own) > 1e-12 * own:
            raise ExportRefused(f"export sample_time {sample_time:g} s differs from the "
                                f"law's own {own:g} s")
        return _static_program(controller.law, plant, own)
    if isinstance(controller, NMPC):
        _same_rate(controller, sample_time)
        from .nmpc_program import nmpc_program
        return nmpc_program(controller, plant, x0, precision)
    if isinstance(controller, LQG):
        from .lqg_program import lqg_program
        return lqg_program(controller, plant, sample_time, x0)
    if isinstance(controller, Observed):
        _same_rate(controller, sample_time)
        from .observed_program import observed_program
        inner = program_for(controller.law, plant, initial_state=x0, precision=precision)
        return observed_program(controller, plant, x0, inner)
    if isinstance(controller, Filtered):
        _same_rate(controller, sample_time)
        inner = _dispatch(controller.law, plant, None, x0, precision)
        return filtered_program(inner, controller.cascade, controller.torque_limit)
    if is_sampled(controller):
        raise ExportRefused(f"export: the sampled controller {type(controller).__name__} has "
                            "no C form (built-in laws only)")
    return _static_program(controller, plant, sample_time or 0.0)


def filtered_program(inner: ControllerProgram, cascade, torque_limit=None) -> ControllerProgram:
    """``inner``'s program with its command passed through structural filters: the memory
    gains the filters' states (after the law's), the command is the filtered one (bounded by
    ``torque_limit``, N m, if given).

    Parameters
    ----------
    inner : ControllerProgram
        A sampled law's program, at the filters' sample time.
    cascade : controllers.feedback.structural_filters.FilterCascade
        The filters, discretised at that sample time.
    torque_limit : float, optional
        Bound on the filtered command, N m.
    """
    import casadi as ca

    if inner.n_out != 1 or abs(inner.sample_time - cascade.sample_time) > \
            1e-12 * cascade.sample_time:
        raise ExportRefused(f"export: structural filters need a one-input law sampled every "
                            f"{cascade.sample_time:g} s; got {inner.kind} with {inner.n_out} "
                            f"commands every {inner.sample_time:g} s")
    t, v = ca.SX.sym("t"), ca.SX.sym("v", inner.n_in)
    m_law, x_f = ca.SX.sym("m", inner.n_memory), ca.SX.sym("f", cascade.order)
    m = ca.vertcat(m_law, x_f)

    def filtered(function):
        u, m_next = function(t, v, m_law)
        y = ca.mtimes(ca.DM(cascade.c), x_f) + float(cascade.d[0, 0]) * u
        if torque_limit is not None:
            y = ca.fmin(ca.fmax(y, -torque_limit), torque_limit)
        x_next = ca.mtimes(ca.DM(cascade.a), x_f) + ca.DM(cascade.b) * u
        return ca.Function(function.name(), [t, v, m], [y, ca.vertcat(m_next, x_next)],
                           ["t", "v", "m"], ["u", "m_next"])

    names = ", ".join(type(item).__name__ for item in cascade.filters)
    return ControllerProgram(
        kind=inner.kind, step=filtered(inner.step),
        recover=None if inner.recover is None else filtered(inner.recover),
        input_names=inner.input_names, input_kind=inner.input_kind,
        output_name=inner.output_name, output_unit=inner.output_unit,
        memory_init=np.concatenate((inner.memory_init, np.zeros(cascade.order))),
        sample_time=inner.sample_time, measurement_matrix=inner.measurement_matrix,
        description=f"{inner.description}, its command through {names}",
        info={**inner.info, "structural_filters": len(cascade.filters)})


def _same_rate(controller, sample_time):
    own = controller.sample_time
    if sample_time is not None and abs(sample_time - own) > 1e-12 * own:
        raise ExportRefused(f"export sample_time {sample_time:g} s differs from the "
                            f"{type(controller).__name__}'s own {own:g} s")


def _static_kind(controller) -> str | None:
    """The kind of a built-in static law (subclasses included), or None."""
    from controllers.feedback.actuated import LaggedLQR
    from controllers.factory import OpenLoop
    from controllers.feedback.lqr import LQR
    from controllers.feedback.pd import PD
    from controllers.feedback.scheduling import ScheduledLQR
    from controllers.feedback.tracking import TrajectoryTracker

    kinds = ((PD, "pd"), (LQR, "lqr"), (ScheduledLQR, "scheduled_lqr"),
             (TrajectoryTracker, "tracker"), (LaggedLQR, "lqr_wheel"), (OpenLoop, "open_loop"))
    return next((kind for cls, kind in kinds if isinstance(controller, cls)), None)


def bound(law, plant):
    """``law`` reading ``plant``'s states (``for_plant``), whatever plant it was bound to.

    Parameters
    ----------
    law : object
        A flexctl feedback law; one without ``for_plant`` is returned as it is.
    plant : flexctl.Model
        The plant the law reads (its state order, sensors and actuator).
    """
    return law.for_plant(plant) if callable(getattr(law, "for_plant", None)) else law


def _static_law_expression(controller, plant, owner="export"):
    """``(t, x, u)``: SX symbols of time and plant state, and the law's command."""
    import casadi as ca

    kind = _static_kind(controller)
    if kind is None or not callable(getattr(controller, "casadi_torque", None)):
        name = getattr(controller, "__name__", type(controller).__name__)
        raise ExportRefused(f"{owner}: {name} has no CasADi form to write as C; the built-in "
                            "laws (PD, LQR, ScheduledLQR, TrajectoryTracker, LQG, NMPC) do")
    if getattr(controller, "n_states", 0):
        raise ExportRefused(f"{owner}: {type(controller).__name__} has internal states")
    if not getattr(controller, "has_casadi_form", True):
        raise ExportRefused(f"{owner}: {type(controller).__name__}'s reference has no CasADi "
                            "form (a SlewProfile or a SlewSolution has)")
    law = bound(controller, plant)
    t, x = ca.SX.sym("t"), ca.SX.sym("x", plant.n_states)
    if kind == "tracker":
        return kind, law, t, x, _tracker_torque(law, t, x)
    return kind, law, t, x, ca.SX(law.casadi_torque(t, x))


def _tracker_torque(tracker, t, x):
    """The tracker's torque in the order of its numpy form, ``ff(t) - K (x - x_opt(t))``:
    the state error first (its simulation form folds ``K`` into the Hermite coefficients,
    which rounds differently where the error is small against ``K x``)."""
    import casadi as ca

    from .nmpc_program import hermite_rows

    solution, hold = tracker.solution, tracker._feedforward
    optimal = hermite_rows(t, np.asarray(solution.t, dtype=float),
                            np.asarray(solution._hermite))
    rows = tracker._rows(x.numel())
    if rows is None:
        from controllers.feedback.lqr import casadi_truncate_state
        design = casadi_truncate_state(x, solution.model.layout)
    else:
        design = x[rows.tolist()]
    outside = ca.logic_or(t < hold.t[0], t >= hold.t[-1])
    feedforward = ca.if_else(outside, 0.0, hold.casadi(t))
    u = feedforward - ca.dot(ca.DM(tracker.gain), design - optimal)
    if tracker.torque_limit is not None:
        u = ca.fmin(ca.fmax(u, -tracker.torque_limit), tracker.torque_limit)
    return u



def _static_program(controller, plant, sample_time) -> ControllerProgram:
    import casadi as ca

    kind, law, t, x, u = _static_law_expression(controller, plant)
    m = ca.SX.sym("m", 0)
    step = ca.Function("step", [t, x, m], [u, m], ["t", "v", "m"], ["u", "m_next"])
    name, unit = plant_output(plant)
    return ControllerProgram(
        kind=kind, step=step, recover=None, input_names=tuple(plant.state_names),
        input_kind="state", output_name=name, output_unit=unit, memory_init=np.zeros(0),
        sample_time=float(sample_time), description=_describe(law, sample_time),
        info={"design_modes": _design_modes(law),
              **(_switches(law) if kind == "tracker" else {})})


def _switches(tracker) -> dict:
    """``switch_times``: the times (s) the tracker's held feedforward jumps."""
    times = tuple(float(t) for t in getattr(tracker, "breakpoints", ()) or ())
    return {"switch_times": times} if times else {}


def _describe(law, sample_time) -> str:
    modes = _design_modes(law)
    limit = getattr(law, "torque_limit", None)
    return (f"{type(law).__name__}" + (f" on {modes} design modes" if modes else "")
            + (f", command limited to {limit:g} N m" if limit else "")
            + (f", sampled every {sample_time:g} s" if sample_time else ""))


def _design_modes(law) -> int | None:
    for owner in (law, getattr(law, "lqr", None), getattr(getattr(law, "solution", None),
                                                          "model", None)):
        modes = getattr(owner, "n_modes", None)
        if isinstance(modes, (int, np.integer)):
            return int(modes)
    return None


def _voltage_program(controller, plant, sample_time, x0, precision) -> ControllerProgram:
    """A DC motor's voltage for the torque of the inner law's program: ``V(u, hub rate)``."""
    import casadi as ca

    inner = program_for(controller.law, plant, sample_time=sample_time, initial_state=x0,
                        precision=precision)
    if inner.input_kind != "state":
        raise ExportRefused("export: a DC motor's voltage needs the hub rate; the law inside "
                            f"MotorVoltage ({inner.kind}) reads sensors, not the state")
    motor, rate_index = controller.motor, plant.layout.theta_dot

    def wrap(function):
        if function is None:
            return None
        t, v, m = (ca.MX.sym(n, function.size_in(i)) for i, n in enumerate(("t", "v", "m")))
        u, m_next = function(t, v, m)
        volts = motor.voltage_for(u, v[rate_index])
        return ca.Function(function.name(), [t, v, m], [volts, m_next], ["t", "v", "m"],
                           ["u", "m_next"])

    return ControllerProgram(
        kind=inner.kind, step=wrap(inner.step), recover=wrap(inner.recover),
        input_names=inner.input_names, input_kind="state", output_name="voltage",
        output_unit="V", memory_init=inner.memory_init, sample_time=inner.sample_time,
        description=f"{inner.description}, through the DC motor's voltage",
        info=dict(inner.info))
