"""Integration strategies: one per method family, each a small object with one ``run``.

- :class:`CvodesSegments`: the compiled right-hand side integrated by CVODES segment by
  segment (between the inputs' breakpoints); where a segment fails or passes a stopping
  condition, SciPy locates the stop from the last good sample on a bounded budget.
- :class:`EmbeddedSegments`: the same segments by compiled Dormand-Prince 5(4) steps with
  error control (:class:`~flexctl.sim.embedded_rk.EmbeddedRun`), the output times read from
  the pair's continuous extension; SciPy locates a stop as behind CVODES.
- :class:`BdfSegments`: the same segments by compiled variable-order BDF or Adams-Moulton
  steps (:class:`~flexctl.sim.compiled_bdf.BdfRun`), the output times read from their
  interpolants.
- :class:`FixedStepRK4`: the compiled fixed-step loop of :mod:`flexctl.sim.fixed_step`, one
  call for the whole run, its step halved until a step-doubling estimate meets ``rtol``.
- :class:`ScipyIVP`: ``scipy.integrate.solve_ivp`` segment by segment, with the stopping
  conditions as terminal events.

Each hands back a :class:`Trajectory`: the samples it integrated and why it stopped. The
accuracy check of an error-controlled compiled run is its own step, which the strategy
starts beside the run (``start_check``) and completes once the run reaches its end
(``finish_check``): :func:`check_run_accuracy` for CVODES, :func:`check_embedded_accuracy`
for the pair and the compiled BDF.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .background import Beside
from .compiled import (CHECK_FACTOR, SegmentIntegrator, numeric_rhs, start_check,
                       verify_accuracy)
from .compiled_bdf import BdfRun
from .embedded_rk import DOP853_OMEGA_H, PAIR_OMEGA_H, EmbeddedRun
from .fixed_step import MAX_HALVINGS, RK4_FIRST_OMEGA_H, RK4_OMEGA_H, integrate_fixed_step
from .inputs import jacobian_frequency
from .progress import Progress
from .stops import StopReason, tip_rows
from ..model import SingularMassMatrixError
from ..model.errors import InputValueError

__all__ = ["Trajectory", "CvodesSegments", "EmbeddedSegments", "BdfSegments", "FixedStepRK4",
           "ScipyIVP",
           "strategy_for",
           "check_run_accuracy", "start_accuracy_check", "planned_segments",
           "rk4_accuracy_note", "AccuracyWarning", "FALLBACK_EVALUATIONS",
           "check_embedded_accuracy", "start_embedded_check", "replay_error", "replay_steps"]

#: Where a compiled segment fails, SciPy locates the stop with at most this many evaluations
#: of the right-hand side (1 to 5 s of DOP853 steps); a state so stiff that they do not
#: reach it ends the run as an integrator failure, with its stiffness named. The 3e4 kg
#: tip-mass divergence of first_order took 7.5e4.
FALLBACK_EVALUATIONS = 200_000


def _solve_ivp():
    """``scipy.integrate.solve_ivp``, imported where a run needs it: the compiled methods do
    not, and ``scipy.integrate`` takes longer to import than a short run."""
    from scipy.integrate import solve_ivp

    return solve_ivp


class AccuracyWarning(RuntimeWarning):
    """The accuracy check of a compiled run found it wrong and what was done about it."""


@dataclass
class Trajectory:
    """What an integration hands back: samples, effort, and why it stopped.

    Attributes
    ----------
    ts : list of ndarray
        Sample times of each piece of the run, s, in order.
    ys : list of ndarray
        The integrated states at those times, shape (m, K) per piece.
    reason : StopReason
        Why the run ended. Default: it reached its end.
    message : str
        What happened, with the time; empty for a run that reached its end.
    found : bool
        True when a stopping condition ended the run and its physical reason is still to be
        named from the last state (:meth:`StopConditions.message`).
    n_eval : int
        Right-hand-side evaluations so far.
    compiled_segments : list of tuple
        ``(t_start, t_out)`` of each segment a compiled strategy integrated, for its accuracy
        check.
    integration_error : float or None
        Estimated largest tip-deflection error, m; None where no check ran.
    accuracy_note : str
        What the accuracy check found and did; empty when nothing.
    check_torque_taken : bool
        The accuracy check ran on a torque of its own (a sampled function sampled more
        loosely, :func:`flexctl.sim.runs.run_once`).
    """

    ts: list
    ys: list
    reason: StopReason = StopReason.REACHED_END
    message: str = ""
    found: bool = False
    n_eval: int = 0
    compiled_segments: list = field(default_factory=list)
    integration_error: float | None = None
    accuracy_note: str = ""
    check_torque_taken: bool = False

    def add(self, t, y):
        """Append samples ``t`` (K,) and ``y`` (m, K).

        Parameters
        ----------
        t : ndarray, shape (K,)
            Times, s.
        y : ndarray, shape (m, K)
            The integrated state at those times.
        """
        self.ts.append(t)
        self.ys.append(y)

    def stop(self, reason: StopReason, message: str = "", found: bool = False):
        """End the run for ``reason``.

        Parameters
        ----------
        reason : StopReason
            Why the run ended.
        message : str, optional
            What happened, with the time. Default "" (a ``found`` stop is named later from the
            last state, :meth:`StopConditions.message`).
        found : bool, optional
            A stopping condition ended the run and its physical reason is still to be named from
            the last state. Default False.
        """
        self.reason, self.message, self.found = reason, message, found


class _BudgetSpent(Exception):
    """The fallback integrator spent its evaluations at time ``t`` in state ``y``."""

    def __init__(self, t, y):
        super().__init__(f"evaluation budget spent at t = {t:.6g} s")
        self.t, self.y = float(t), np.array(y, dtype=float)


class _Budgeted:
    """A right-hand side that raises ``_BudgetSpent`` past ``budget`` evaluations."""

    def __init__(self, rhs, budget: int):
        self.rhs, self.left = rhs, int(budget)

    def __call__(self, t, y):
        self.left -= 1
        if self.left < 0:
            raise _BudgetSpent(t, y)
        return self.rhs(t, y)


class _Segments:
    """The segment loop shared by the error-controlled strategies: each segment between two
    cuts is integrated onto the output times inside it, restarting at every cut.

    ``check_request`` is the request the accuracy check integrates: the run's, or where
    ``checks_beside`` (a replay started beside the run with inputs of its own) the run's with
    another torque set by the caller before :meth:`start_check`."""

    #: The accuracy check is a replay started by :meth:`start_check` from ``check_request``.
    checks_beside = False

    def __init__(self, request, plan, drive, stops):
        self.request, self.plan, self.drive, self.stops = request, plan, drive, stops
        self.check_request = request
        self.start = time.perf_counter()

    @property
    def compiled_steps(self):
        """The compiled steps that integrate every segment (``steps(lo, t_out, y, stop)``,
        an :class:`~flexctl.sim.embedded_rk.EmbeddedRun` or
        :class:`~flexctl.sim.compiled_bdf.BdfRun`), or None for the other strategies."""
        return getattr(self, "_steps", None)

    def release(self) -> None:
        """Give back the compiled steps' buffers once the run has ended (a no-op but for the
        compiled pairs and multistep methods)."""
        steps = self.compiled_steps
        if steps is not None:
            steps.release()

    def run(self) -> Trajectory:
        """Integrate every segment until the end or a stop."""
        drive = self.drive
        traj = Trajectory(ts=[np.array([0.0])], ys=[drive.y_init[:, None]])
        y = drive.y_init
        for lo, t_eval in planned_segments(self.plan, self.request.grid):
            hi = float(t_eval[-1])
            drive.segment_end = np.nextafter(hi, lo)
            y = self.segment(traj, lo, hi, t_eval, y)
            if y is None:
                break
            self.report(hi)
        return traj

    def report(self, t_reached, note: str = ""):
        """Progress to the reporter, if any."""
        if self.request.report is not None:
            self.request.report(Progress(t_reached, self.request.t_final,
                                         time.perf_counter() - self.start, *((note,) if note
                                                                            else ())))

    def segment(self, traj, lo, hi, t_eval, y):
        """Integrate ``[lo, hi]`` from ``y``: the state at ``hi``, or None after a stop."""
        return self.solve_ivp(traj, lo, hi, t_eval, y, self.drive.rhs)

    def start_check(self):
        """The accuracy check of a compiled run, started beside it (None: no check)."""
        return None

    def finish_check(self, traj, check) -> None:
        """Complete ``traj`` (reached its end) with the result of :meth:`start_check`."""

    def solve_ivp(self, traj, lo, hi, t_eval, y, rhs):
        """``solve_ivp`` over ``[lo, hi]`` with the stops as terminal events."""
        plan, request = self.plan, self.request
        try:
            with np.errstate(over="raise", invalid="raise"):
                sol = _solve_ivp()(rhs, (lo, hi), y, method=plan.fallback, t_eval=t_eval,
                                rtol=plan.rtol, atol=plan.atol, events=self.stops.events(),
                                max_step=request.max_step)
        except _BudgetSpent as spent:
            traj.stop(StopReason.INTEGRATOR_FAILED, self._budget_message(lo, spent))
            return None
        except SingularMassMatrixError as exc:
            # named again from the state, with J_eff
            traj.stop(StopReason.SINGULAR_MASS, str(exc), found="effective" in str(exc))
            return None
        except FloatingPointError as exc:
            hint = ""
            if plan.fallback in ("BDF", "LSODA"):
                # orders 3 to 5 are not stable on the imaginary axis: undamped modes grow
                hint = (f"; SciPy's {plan.fallback} steps at orders 3 to 5, whose formulas "
                        "amplify undamped oscillations, so this may be the method's growth "
                        "and not the model's: method 'auto', 'Adams' or 'Radau' keeps them")
            traj.stop(StopReason.STATE_OVERFLOW,
                      f"the state overflowed between t = {lo:.6g} s and {hi:.6g} s "
                      f"({exc}){hint}")
            return None
        traj.n_eval += sol.nfev
        return self._take(traj, sol, y.size)

    def _take(self, traj, sol, size):
        """Keep ``sol``'s samples up to its first event; the last state, or None."""
        # (solve_ivp hands back lists when an event fires before the first output time)
        t_seg = np.asarray(sol.t, dtype=float)
        y_seg = np.asarray(sol.y, dtype=float).reshape(size, t_seg.size)
        hits = [(float(te[0]), k, ye[0]) for k, (te, ye) in
                enumerate(zip(sol.t_events, sol.y_events)) if te.size]
        if hits:
            stop_time, kind, y_stop = min(hits, key=lambda h: h[0])
            before = t_seg < stop_time
            traj.add(np.append(t_seg[before], stop_time),
                     np.column_stack((y_seg[:, before], y_stop)))
            traj.stop(self.stops.reason_of_event(kind), found=True)
            return None
        if t_seg.size:
            traj.add(t_seg, y_seg)
        if sol.status != 0:
            traj.stop(StopReason.INTEGRATOR_FAILED,
                      f"integration failed at t = {sol.t[-1]:.6g} s: {sol.message}")
            return None
        return sol.y[:, -1]

    def _budget_message(self, lo, spent) -> str:
        """The integrator failure of a stop search that spent its budget, with the stiffness
        of the state it reached."""
        try:                    # a diagnosis only: any failure of it leaves it unknown
            with np.errstate(all="ignore"):
                w = jacobian_frequency(self.fallback_rhs or self.drive.rhs, spent.t, spent.y,
                                       self.plan.scale)
        except (ArithmeticError, ValueError, SingularMassMatrixError):
            w = math.inf
        return (f"integration failed at t = {lo:.6g} s: the compiled integrator could not pass "
                f"it and {FALLBACK_EVALUATIONS:.3g} evaluations of {self.plan.fallback} from "
                f"there reached only t = {spent.t:.6g} s; the state had become stiff (fastest "
                f"rate {w:.3g} 1/s against the fastest mode at rest, "
                f"{self.plan.omega_plant:.3g} rad/s)")

    fallback_rhs = None


class ScipyIVP(_Segments):
    """``scipy.integrate.solve_ivp`` on the drive's Python right-hand side; its accuracy check
    is the run replayed at :data:`~flexctl.sim.compiled.CHECK_FACTOR` times the tolerance, as
    a compiled run's (:func:`replay_error`).

    Its place: the runs nothing compiles (a torque function that can be neither traced nor
    sampled, a controller without a CasADi form, compiling off) and the SciPy methods asked
    for by name. ``benchmarks/bench_inputs.py`` measures what it costs: a torque function
    called at every step of DOP853 ran at 0.7 of python-control's fastest method, the same
    function sampled onto the compiled path at 23 to 29 times it (2026-11-29).

    Parameters
    ----------
    request : RunRequest
        The checked arguments of the run.
    plan : IntegrationPlan
        How it is integrated: the method, the tolerances and the segment cuts.
    drive : PrescribedDrive or TorqueDrive
        What is integrated: its right-hand side and initial state.
    stops : StopConditions
        The run's stopping conditions.
    """

    def segment(self, traj, lo, hi, t_eval, y):
        """Integrate ``[lo, hi]`` from ``y``: the state at ``hi``, or None after a stop; a segment
        that reaches its end is kept for the replay (:func:`replay_error`).

        Parameters
        ----------
        traj : Trajectory
            Gets the segment's samples, or the stop.
        lo, hi : float
            Start and end of the segment, s.
        t_eval : ndarray, shape (K,)
            Output times in ``(lo, hi]``, s, the last ``hi``.
        y : ndarray, shape (m,)
            The integrated state at ``lo``.
        """
        y_end = super().segment(traj, lo, hi, t_eval, y)
        if y_end is not None:
            traj.compiled_segments.append((lo, t_eval))
        return y_end

    def start_check(self):
        # the replay needs the run's segments: it runs once the run has reached its end
        return Beside(lambda: None, beside=False)

    def finish_check(self, traj, check) -> None:
        """Complete ``traj`` (reached its end) with its replay at
        :data:`~flexctl.sim.compiled.CHECK_FACTOR` times the tolerance (:func:`replay_error`),
        made now: it needs the run's segments.

        Parameters
        ----------
        traj : Trajectory
            The run; gets ``integration_error``, the replay's evaluations and any note.
        check : Beside
            The placeholder of :meth:`start_check`; not used.
        """
        self.report(self.request.t_final, "checking accuracy")
        traj.integration_error, n_check, note = replay_error(self, traj)
        traj.n_eval += n_check
        if note:
            traj.accuracy_note = note


def replay_error(strategy, traj) -> tuple:
    """``(error, evaluations, note)``: the largest tip difference (m) between a SciPy run
    ``traj`` that reached its end and the same segments integrated again at
    :data:`~flexctl.sim.compiled.CHECK_FACTOR` times its tolerances (conservative: it is the
    error of the looser run); ``None`` with the reason where the replay fails.

    Parameters
    ----------
    strategy : ScipyIVP
        The strategy that made the run: its request, plan and drive.
    traj : Trajectory
        The run, with its ``compiled_segments`` (``(t_start, t_out)`` of each segment).
    """
    request, plan, drive = strategy.request, strategy.plan, strategy.drive
    y, states, evaluations = drive.y_init, [], 0
    try:
        with np.errstate(over="raise", invalid="raise"):
            for lo, t_eval in traj.compiled_segments:
                hi = float(t_eval[-1])
                drive.segment_end = np.nextafter(hi, lo)
                sol = _solve_ivp()(drive.rhs, (lo, hi), y, method=plan.fallback, t_eval=t_eval,
                                rtol=min(CHECK_FACTOR * request.rtol, 0.1),
                                atol=CHECK_FACTOR * np.asarray(plan.atol),
                                max_step=request.max_step)
                evaluations += sol.nfev
                if sol.status != 0 or sol.y.shape[1] != t_eval.size:
                    raise ArithmeticError(sol.message)
                states.append(sol.y)
                y = sol.y[:, -1]
    except (ArithmeticError, SingularMassMatrixError) as exc:
        return None, evaluations, f"accuracy check not run: its replay at {CHECK_FACTOR:g} " \
            f"times the tolerance failed ({exc})"
    tip_map = tip_rows(request.model, drive.layout)
    run = np.concatenate(traj.ys[1:], axis=1)
    replayed = np.concatenate(states, axis=1)
    return float(np.max(np.abs(tip_map @ (run - replayed)))), evaluations, ""


class CvodesSegments(_Segments):
    """CVODES on the compiled right-hand side; SciPy locates a stop within a segment.

    Its place: ``method="auto"`` on models whose steps times instructions pass the compiled
    pair's work bound (many modes), behind a fast actuator, and wherever a compiled method
    cannot be built. ``benchmarks/bench_multistep.py`` (its second table, rtol 1e-6 with the
    check): hub-beam-mass on 30 first_order modes, auto took CVODES, 71 to 116 ms, error
    6e-6 (the compiled BDF cannot be built there; the pair 65 ms). Its multistep family is
    :func:`~flexctl.sim.request.choose_multistep`'s.

    Parameters
    ----------
    request : RunRequest
        The checked arguments of the run.
    plan : IntegrationPlan
        How it is integrated: the method, the tolerances and the segment cuts.
    drive : PrescribedDrive or TorqueDrive
        What is integrated: its right-hand side and initial state.
    stops : StopConditions
        The run's stopping conditions.
    """

    def __init__(self, request, plan, drive, stops):
        super().__init__(request, plan, drive, stops)
        self._compiled_rhs = None
        # consistent keeps the Python right-hand side to locate a stop, which names a
        # singular mass matrix
        if not request.model.variant.quadratic_inertia:
            self.fallback_rhs = self._compiled_fallback

    def _compiled_fallback(self, t, y):
        """The compiled right-hand side for SciPy, built on first use (most runs never need
        it)."""
        if self._compiled_rhs is None:
            r = self.request
            self._compiled_rhs = numeric_rhs(r.model, r.torque, r.hub_motion, r.controller)
        dy = self._compiled_rhs(t, y, self.drive.segment_end)
        if not np.all(np.isfinite(dy)):
            raise FloatingPointError("the state derivative is not finite")
        return dy

    checks_beside = True

    def start_check(self):
        return start_accuracy_check(self.check_request, self.plan, self.drive)

    def finish_check(self, traj, check) -> None:
        """Complete ``traj`` (reached its end) with the result of :meth:`start_check`
        (:func:`check_run_accuracy`).

        Parameters
        ----------
        traj : Trajectory
            The run; gets ``integration_error`` and any note, and its states are replaced where
            the check redoes the run.
        check : Beside
            The check run started by :meth:`start_check`.
        """
        check_run_accuracy(self.request, self.plan, self.drive, traj, reporter=self,
                           check=check)

    def integrate(self, lo, t_eval, y) -> tuple:
        """``(states at t_eval, evaluations)`` of one segment from ``y`` at ``lo``;
        ``RuntimeError`` where the integrator fails.

        Parameters
        ----------
        lo : float
            Start of the segment, s.
        t_eval : ndarray, shape (K,)
            Output times after ``lo``, s, ascending; the last is the segment's end.
        y : ndarray, shape (m,)
            The integrated state at ``lo``.

        Returns
        -------
        states : ndarray, shape (m, K)
        evaluations : int
        """
        request, plan = self.request, self.plan
        integ = SegmentIntegrator(request.model, lo, t_eval, plan.scale, request.rtol,
                                  torque=request.torque, hub_motion=request.hub_motion,
                                  controller=request.controller,
                                  max_steps=plan.cvodes_steps, max_step=plan.cvodes_step,
                                  multistep=plan.cvodes_multistep)
        return integ(y), integ.n_evaluations

    def segment(self, traj, lo, hi, t_eval, y):
        """Integrate ``[lo, hi]`` from ``y`` by CVODES: the state at ``hi``, or None after a stop.
        Where the segment fails or passes a stopping condition, SciPy locates the stop from the
        last good sample, on a budget of :data:`FALLBACK_EVALUATIONS` evaluations.

        Parameters
        ----------
        traj : Trajectory
            Gets the segment's samples, or the stop.
        lo, hi : float
            Start and end of the segment, s.
        t_eval : ndarray, shape (K,)
            Output times in ``(lo, hi]``, s, the last ``hi``.
        y : ndarray, shape (m,)
            The integrated state at ``lo``.
        """
        try:
            y_seg, n_eval = self.integrate(lo, t_eval, y)
            traj.n_eval += n_eval
            bad = self.stops.first_bad(y_seg)
        except RuntimeError:
            y_seg, bad = None, 0
        if bad is None:
            traj.add(t_eval, y_seg)
            traj.compiled_segments.append((lo, t_eval))
            return y_seg[:, -1]
        # Something stops the run in this segment: find where, exactly, with SciPy from the
        # last good sample.
        if bad > 0:
            traj.add(t_eval[:bad], y_seg[:, :bad])
            lo, y = float(t_eval[bad - 1]), y_seg[:, bad - 1]
        locate = _Budgeted(self.fallback_rhs or self.drive.rhs, FALLBACK_EVALUATIONS)
        return self.solve_ivp(traj, lo, hi, t_eval[bad:], y, locate)


def _embedded_run(request, plan, rtol: float, looser: bool = False) -> EmbeddedRun:
    """The compiled Dormand-Prince run of ``request`` at ``rtol``: its first step a radian of
    the fastest pole it meets (mode, loop, spin), its steps at most
    :data:`~flexctl.sim.embedded_rk.PAIR_OMEGA_H` radians of it and the inputs' own bound.
    ``looser``: the accuracy check's replay, whose longest step is twice the run's, so that a
    run whose steps are all bound is not replayed step for step."""
    omega = max(plan.fastest_pole, request.spin_frequency)
    scheme = "dop853" if plan.method == "dop853" else "dopri5"
    cap = DOP853_OMEGA_H if scheme == "dop853" else PAIR_OMEGA_H
    bound = min(cap / omega if omega > 0.0 else math.inf,
                math.inf if plan.cvodes_step is None else plan.cvodes_step)
    if looser:
        bound *= 2.0
    return EmbeddedRun(request.model, request.torque, request.hub_motion, request.controller,
                       scale=plan.scale, rtol=rtol, max_steps=plan.cvodes_steps,
                       h_first=min(1.0 / omega if omega > 0.0 else math.inf, request.step,
                                   bound),
                       max_step=bound, scheme=scheme)


def _bdf_run(request, plan, rtol: float) -> BdfRun:
    """The compiled multistep run of ``request`` at ``rtol`` (Adams-Moulton where the plan's
    method is ``"Adams"``, else BDF): its first step a hundredth of a
    radian of the fastest pole it meets (mode, loop, spin; order 1 grows it as the accuracy
    allows) or, with no finite pole, the output step; no longest step but the inputs' own
    bound."""
    omega = max(plan.fastest_pole, request.spin_frequency)
    return BdfRun(request.model, request.torque, request.hub_motion, request.controller,
                  family="adams" if plan.method == "Adams" else "bdf",
                  scale=plan.scale, rtol=rtol, max_steps=plan.cvodes_steps,
                  h_first=min(0.01 / omega if 0.0 < omega < math.inf else math.inf,
                              request.step),
                  max_step=math.inf if plan.cvodes_step is None else plan.cvodes_step)


class EmbeddedSegments(CvodesSegments):
    """The segments by compiled Dormand-Prince 5(4) steps with error control
    (:class:`~flexctl.sim.embedded_rk.EmbeddedRun`), the step size carried from one segment
    to the next; SciPy locates a stop within a segment, as behind CVODES.

    Its place: ``method="auto"`` on the small-deflection models whose work it bounds
    (:func:`~flexctl.sim.request.choose_continuous`). ``benchmarks/bench_multistep.py``
    (second table, rtol 1e-6 with the check, ms): the Kane spin-up on 4 first_order modes
    14.7 against CVODES's 21.6; hub-beam-mass on 12 modes over 20 s 275 against 484;
    spacecraft-torque on 6 modes 209 against 341. The compiled Adams-Moulton measured faster
    still on these three rows (8.1, 159, 86) but is not on auto's path for these variants.

    Parameters
    ----------
    request : RunRequest
        The checked arguments of the run.
    plan : IntegrationPlan
        How it is integrated: the method, the tolerances and the segment cuts.
    drive : PrescribedDrive or TorqueDrive
        What is integrated: its right-hand side and initial state.
    stops : StopConditions
        The run's stopping conditions.
    """

    def __init__(self, request, plan, drive, stops):
        super().__init__(request, plan, drive, stops)
        self._steps = _embedded_run(request, plan, plan.rtol)

    def start_check(self):
        return start_embedded_check(self.check_request, self.plan, self.drive, self.stops)

    def finish_check(self, traj, check) -> None:
        """Complete ``traj`` (reached its end) with the replay started by :meth:`start_check`
        (:func:`check_embedded_accuracy`).

        Parameters
        ----------
        traj : Trajectory
            The run; gets ``integration_error`` or a note.
        check : Beside
            The replay started by :meth:`start_check`.
        """
        check_embedded_accuracy(self.request, self.drive, traj, check, reporter=self)

    def integrate(self, lo, t_eval, y) -> tuple:
        """``(states at t_eval, evaluations)`` of one segment from ``y`` at ``lo`` by the compiled
        steps; a run that passes a stopping condition ends there, with fewer states than
        ``t_eval``; ``RuntimeError`` where a step cannot be taken.

        Parameters
        ----------
        lo : float
            Start of the segment, s.
        t_eval : ndarray, shape (K,)
            Output times after ``lo``, s, ascending; the last is the segment's end.
        y : ndarray, shape (m,)
            The integrated state at ``lo``.

        Returns
        -------
        states : ndarray, shape (m, K) or (m, K') with K' < K
        evaluations : int
        """
        return self._steps(lo, t_eval, y, stop=self.stops.first_bad)


class BdfSegments(EmbeddedSegments):
    """The segments by compiled variable-order BDF or Adams-Moulton steps
    (:class:`~flexctl.sim.compiled_bdf.BdfRun`), each segment from order 1; the accuracy
    check replays them at :data:`~flexctl.sim.compiled.CHECK_FACTOR` times the tolerance
    beside the run; SciPy locates a stop within a segment, as behind CVODES.

    Its place: ``method="auto"`` on the exact variant
    (:data:`~flexctl.sim.request.BDF_REPLACES`). ``benchmarks/bench_multistep.py`` (second
    table, rtol 1e-6 with the check, ms): slew-90's saturated PD on 4 and 6 exact modes,
    Adams 20 and 40 against CVODES's 34 and 89 and the pair's 73 and 223; the Kane spin-up
    on 4 exact modes 47 to 57 against CVODES's 85.

    Parameters
    ----------
    request : RunRequest
        The checked arguments of the run.
    plan : IntegrationPlan
        How it is integrated: the method, the tolerances and the segment cuts.
    drive : PrescribedDrive or TorqueDrive
        What is integrated: its right-hand side and initial state.
    stops : StopConditions
        The run's stopping conditions.
    """

    def __init__(self, request, plan, drive, stops):
        CvodesSegments.__init__(self, request, plan, drive, stops)
        self._steps = _bdf_run(request, plan, plan.rtol)

    def start_check(self):
        import threading

        # at a tolerance so loose that ten times it is no tolerance, the replay is tighter:
        # a replay at the run's own tolerance would be the run, and its difference nothing
        rtol = self.plan.rtol
        check = CHECK_FACTOR * rtol if CHECK_FACTOR * rtol <= 0.5 else rtol / CHECK_FACTOR
        steps = _bdf_run(self.check_request, self.plan, check)
        return Beside(replay_steps, steps, planned_segments(self.plan, self.request.grid),
                      self.drive.y_init, self.stops.first_bad, cancelled=threading.Event())


def replay_steps(steps, segments, y0, stop, cancelled):
    """The states of compiled steps over a run's segments, and their evaluations: the run's
    integration alone, safe to start on another thread (the steps are built, and let go of
    Python's lock while they integrate).

    Parameters
    ----------
    steps : EmbeddedRun or BdfRun
        The compiled steps, ``steps(lo, t_out, y, stop) -> (states, evaluations)``; released
        at the end (they are the replay's own).
    segments : list of (float, ndarray)
        ``(t_start, t_out)`` per segment (:func:`planned_segments`).
    y0 : ndarray, shape (m,)
        The integrated state at the first segment's start.
    stop : callable
        ``stop(states) -> int or None``, the run's stopping conditions (the first bad
        column, as :meth:`StopConditions.first_bad`).
    cancelled : threading.Event
        Looked at after every compiled call: once set, the replay ends.

    Returns
    -------
    tuple of (ndarray, int) or None
        ``(states (m, K), evaluations)`` at every segment's output times, or None when a step
        fails, a state passes a stop or the replay is cancelled.
    """
    def ended(states):
        return 0 if cancelled.is_set() else stop(states)

    states, evaluations, y = [], 0, y0
    try:
        for lo, t_out in segments:
            try:
                part, n_eval = steps(lo, t_out, y, stop=ended)
            except RuntimeError:
                return None
            if part.shape[1] < len(t_out):
                return None
            states.append(part)
            evaluations += n_eval
            y = part[:, -1]
    finally:
        # the replay's steps are its own
        steps.release()
    return np.concatenate(states, axis=1), evaluations


def start_embedded_check(request, plan, drive, stops):
    """The replay of a Dormand-Prince run at :data:`~flexctl.sim.compiled.CHECK_FACTOR` times
    its tolerance and twice its longest step, with a step size of its own, started beside the
    run on a spare core (its compiled steps let go of Python's lock): give it to
    :func:`check_embedded_accuracy`, or ``abandon()`` it if the run stops early, which ends it
    within a compiled call. A replay that passes one of the run's ``stops`` ends there.

    Parameters
    ----------
    request : RunRequest
        The checked run: model, inputs, tolerance, output grid.
    plan : IntegrationPlan
        Its segments, tolerances per state and step bounds.
    drive : PrescribedDrive or TorqueDrive
        Gives the initial state.
    stops : StopConditions
        The run's stopping conditions.

    Returns
    -------
    Beside
        Its ``result()`` is ``(states (m, K), evaluations)``, or None where the replay failed
        or stopped.
    """
    import threading

    steps = _embedded_run(request, plan, min(CHECK_FACTOR * plan.rtol, 1.0), looser=True)
    return Beside(replay_steps, steps, planned_segments(plan, request.grid),
                  drive.y_init, stops.first_bad, cancelled=threading.Event())


def check_embedded_accuracy(request, drive, traj: Trajectory, check, reporter=None):
    """``traj.integration_error`` of a Dormand-Prince run that reached its end: the largest
    tip difference from its replay at 10 times the tolerance (conservative: the error of the
    looser run), at every output time.

    Parameters
    ----------
    request : RunRequest
        The checked run.
    drive : PrescribedDrive or TorqueDrive
        Gives the layout of the integrated state (for the tip rows).
    traj : Trajectory
        The run; gets ``integration_error`` and the replay's evaluations, or a note where the
        replay failed.
    check : Beside
        The replay (:func:`start_embedded_check`, or the compiled BDF's own).
    reporter : object, optional
        A strategy whose ``report(t, note)`` says that the check runs. Default none.
    """
    if reporter is not None:
        reporter.report(request.t_final, "checking accuracy")
    found = check.result()
    if found is None:
        traj.accuracy_note = "accuracy check could not run (the check integration failed)"
        return
    y_check, n_check = found
    tip_map = tip_rows(request.model, drive.layout)
    y_main = np.concatenate(traj.ys[1:], axis=1)
    traj.integration_error = float(np.max(np.abs(tip_map @ (y_main - y_check))))
    traj.n_eval += n_check


class FixedStepRK4(_Segments):
    """Compiled fixed-step RK4 over the whole run in one call (:mod:`flexctl.sim.fixed_step`);
    where an output sample is past a stopping condition, SciPy locates the stop from the
    sample before it, as behind CVODES.

    Its place: no default path; ``method="rk4"`` for sweeps and design loops where a fixed
    step and about 1 % are enough. ``benchmarks/bench_multistep.py`` (second table): the Kane
    spin-up on 4 first_order modes in 3.9 ms (error 3e-8) against auto's 14.7 ms;
    ``benchmarks/bench_fixed_step.py`` case A: 2 modes within 0.38 % in 7 to 11 ms.

    Parameters
    ----------
    request : RunRequest
        The checked arguments of the run.
    plan : IntegrationPlan
        How it is integrated: the method, the tolerances and the segment cuts.
    drive : PrescribedDrive or TorqueDrive
        What is integrated: its right-hand side and initial state.
    stops : StopConditions
        The run's stopping conditions.
    """

    def start_check(self):
        """None: the run's step-doubling pair is its own accuracy check."""
        return None

    def _step_bounds(self) -> tuple:
        """The first returned run's step and the resolved step, s: :data:`RK4_FIRST_OMEGA_H`
        and :data:`RK4_OMEGA_H` over the fastest frequency the run meets (the plant's, the
        loop's, the initial spin's, a prescribed spin's)."""
        request, plan = self.request, self.plan
        omega_max = max(plan.fastest_pole, request.spin_frequency)
        if request.prescribed:
            rates = np.asarray(request.hub_motion.rate(request.grid), dtype=float)
            spin_max = float(np.max(np.abs(rates))) if rates.size else 0.0
            if np.isfinite(spin_max) and spin_max > 0.0:
                omega_max = max(omega_max, float(request.model.natural_frequencies(
                    spin_max, hub="clamped")[-1]))
        return (min(RK4_FIRST_OMEGA_H / omega_max, 0.5 * request.max_step),
                min(RK4_OMEGA_H / omega_max, 0.5 * request.max_step))

    def run(self) -> Trajectory:
        request, drive, stops = self.request, self.drive, self.stops
        tip_map = tip_rows(request.model, drive.layout)
        h_first, h_resolved = self._step_bounds()
        try:
            fixed = integrate_fixed_step(request.model, np.array(self.plan.cuts), request.grid,
                                         drive.y_init, tip_map, h_first,
                                         request.rtol, torque=request.torque,
                                         hub_motion=request.hub_motion,
                                         controller=request.controller, h_resolved=h_resolved)
        except ValueError as exc:
            raise InputValueError(f"method 'rk4': {exc}; use method 'cvodes'") from None
        traj = Trajectory(ts=[np.array([0.0])], ys=[drive.y_init[:, None]],
                          n_eval=fixed.evaluations)
        t_fixed, y_fixed = request.grid, fixed.states
        bad = stops.first_bad(y_fixed)
        if bad is not None:
            return self._stopped(traj, t_fixed, y_fixed, bad)
        else:
            traj.integration_error = fixed.error
            traj.accuracy_note = rk4_accuracy_note(
                fixed.error, tip_map @ y_fixed, request.rtol,
                f" after {MAX_HALVINGS} step halvings (step {fixed.h:.3g} s)", stacklevel=3)
        traj.add(t_fixed, y_fixed)
        return traj


    def _stopped(self, traj, t, y, bad) -> Trajectory:
        """The run up to its first output sample ``bad`` past a stopping condition, the stop
        located by SciPy from the sample before it; at that sample where SciPy, on its
        bounded budget, finds none before it."""
        traj.add(t[:bad], y[:, :bad])
        if bad > 0:
            lo, hi = float(t[bad - 1]), float(t[bad])
            # the torque of the segment the stop lies in (its end: the first cut from hi on)
            end = next((c for c in self.plan.cuts if c >= hi), hi)
            self.drive.segment_end = np.nextafter(end, lo)
            located = _Budgeted(self.drive.rhs, FALLBACK_EVALUATIONS)
            if self.solve_ivp(traj, lo, hi, np.array([hi]), y[:, bad - 1], located) is None:
                if traj.reason is not StopReason.INTEGRATOR_FAILED:
                    return traj
            else:
                # SciPy reached the sample without a stop: the sample it added gives way to
                # the one past the stopping condition
                traj.ts.pop()
                traj.ys.pop()
        traj.add(t[bad:bad + 1], y[:, bad:bad + 1])
        traj.stop(self.stops.reason_of_sample(y[:, bad]), found=True)
        return traj


def rk4_accuracy_note(error, tip, rtol: float, detail: str = "", stacklevel: int = 2) -> str:
    """The note, and an :class:`AccuracyWarning`, of an rk4 run whose step-doubling estimate
    ``error`` (m) stays above ``rtol`` of the peak of ``tip`` (m); "" otherwise.

    Parameters
    ----------
    error : float or None
        The step-doubling estimate of the largest tip error, m; None: no note.
    tip : ndarray, shape (K, P)
        Each appendage's tip deflection over the run, m.
    rtol : float
        The run's tolerance, relative to the peak tip deflection.
    detail : str, optional
        Appended to the note's first clause (e.g. the halvings made and the step). Default "".
    stacklevel : int, optional
        ``stacklevel`` of the warning, counted from the caller. Default 2.
    """
    peak = float(np.max(np.abs(tip))) if np.size(tip) else 0.0
    if error is None or error <= rtol * max(peak, 1e-12):
        return ""
    note = (f"rk4: the estimated tip error {error:.3g} m is above rtol {rtol:g} of the peak "
            f"{peak:.3g} m{detail}; use method 'cvodes' for this accuracy")
    warnings.warn(note, AccuracyWarning, stacklevel=stacklevel + 1)
    return note


def planned_segments(plan, grid) -> list:
    """``(t_start, t_out)`` of every segment between two of ``plan.drive_cuts``: the output
    times of ``grid`` inside it, and its end.

    Parameters
    ----------
    plan : IntegrationPlan
        Gives the segment boundaries ``drive_cuts``, s.
    grid : ndarray, shape (P,)
        Output times, s.

    Returns
    -------
    list of (float, ndarray)
        Each segment's start, s, and its output times in ``(t_start, t_end]``, s, the last
        ``t_end``.
    """
    segments, cuts = [], plan.drive_cuts
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        t_eval = grid[(grid > lo) & (grid <= hi)]
        if t_eval.size == 0 or t_eval[-1] < hi:
            t_eval = np.append(t_eval, hi)
        segments.append((lo, t_eval))
    return segments


def _check_options(request, plan) -> dict:
    """The check's integrator options: the run's inputs, largest step, step budget and
    multistep family."""
    return dict(torque=request.torque, hub_motion=request.hub_motion,
                controller=request.controller, max_step=plan.cvodes_step,
                max_steps=plan.cvodes_steps, multistep=plan.cvodes_multistep)


def start_accuracy_check(request, plan, drive):
    """The accuracy check of a CVODES run (:func:`~flexctl.sim.compiled.check_run`), started
    beside the run on a spare core before the run starts: it needs only the plan. Hand it
    to :func:`check_run_accuracy`, or ``abandon()`` it if the run stops early.

    Parameters
    ----------
    request : RunRequest
        The checked run: model, inputs, tolerance, output grid.
    plan : IntegrationPlan
        Its segments, tolerances per state, step bounds and multistep family.
    drive : PrescribedDrive or TorqueDrive
        Gives the initial state.

    Returns
    -------
    Beside
    """
    return start_check(request.model, planned_segments(plan, request.grid), drive.y_init,
                       plan.scale, request.rtol, **_check_options(request, plan))


def strategy_for(plan, symbolic: bool = False):
    """The strategy class of a plan's method: ``RK45`` the compiled pair when the inputs have
    a CasADi form, SciPy's otherwise; ``BDF`` and ``Adams`` the compiled multistep methods
    where the plan compiles them (:attr:`~flexctl.sim.request.IntegrationPlan.compiled`),
    ``BDF`` SciPy's otherwise.

    Parameters
    ----------
    plan : IntegrationPlan
        The run's plan (:func:`~flexctl.sim.request.plan_integration`).
    symbolic : bool, optional
        Every input has a CasADi form. Default False.
    """
    method = plan.method
    if method in ("RK45", "dop853") and symbolic:
        return EmbeddedSegments
    if method in ("Adams", "BDF") and plan.compiled:
        return BdfSegments
    return {"cvodes": CvodesSegments, "rk4": FixedStepRK4}.get(method, ScipyIVP)


def check_run_accuracy(request, plan, drive, traj: Trajectory, reporter=None, check=None):
    """Repeat a compiled run that reached its end at 10 times the tolerance
    (:func:`flexctl.sim.compiled.verify_accuracy`): ``traj.integration_error``, and the run
    redone with BDF2 where the two disagree grossly (with an :class:`AccuracyWarning`).

    Parameters
    ----------
    request : RunRequest
        The checked run.
    plan : IntegrationPlan
        Its tolerances per state, step bounds and multistep family.
    drive : PrescribedDrive or TorqueDrive
        Gives the initial state and the layout of the integrated state.
    traj : Trajectory
        The run, with its ``compiled_segments``; gets ``integration_error``, any note and the
        check's evaluations, and its states are replaced where the run is redone.
    reporter : object, optional
        A strategy whose ``report(t, note)`` says that the check runs. Default none.
    check : Beside, optional
        The check run already started (:func:`start_accuracy_check`); default: run it now.
    """
    if reporter is not None:
        reporter.report(request.t_final, "checking accuracy")
    tip_map = tip_rows(request.model, drive.layout)
    y_checked, traj.integration_error, traj.accuracy_note, n_check = verify_accuracy(
        request.model, traj.compiled_segments, drive.y_init, plan.scale, request.rtol,
        np.concatenate(traj.ys[1:], axis=1), tip_map, traj.n_eval, check=check,
        **_check_options(request, plan))
    traj.n_eval += n_check
    traj.ys = [traj.ys[0], y_checked]
    if traj.accuracy_note:
        warnings.warn(traj.accuracy_note, AccuracyWarning, stacklevel=3)
