"""One run of :func:`flexctl.simulate`, without the assessment of its model's range.

:func:`run_once` validates the request (:mod:`~flexctl.sim.request`) and integrates it: a
continuous drive through its strategy, stops and accuracy check, or a sampled controller
(:mod:`~flexctl.sim.digital`). :func:`flexctl.simulate` adds the validity of the model
(:mod:`~flexctl.sim.validity`), whose estimates are themselves runs made here.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np

from ..model.errors import InputValueError
from .background import Beside
from .compiled import CHECK_FACTOR
from .compiled_bdf import NoCompiledIntegrator
from .function_samples import SampledFunction, sample_function
from .digital import run_sampled
from .drives import PrescribedDrive, TorqueDrive
from .request import check_atol, plan_integration, plan_sampled, run_request, state_scale
from .result import SimulationResult, output_samples, assemble_result, audit_energy
from .stops import StopConditions, StopReason, tip_rows
from .strategies import (Trajectory, replay_steps, planned_segments, rk4_accuracy_note,
                         strategy_for)

__all__ = ["run_once", "run_states", "start_states_run"]


def run_once(model, t_final: float, torque=None, hub_motion=None, controller=None, x0=None,
             *, alongside=None, **options) -> SimulationResult:
    """:func:`flexctl.simulate` without ``check_validity`` (``options``: its keywords).

    Parameters
    ----------
    model : Model
        The model to simulate.
    t_final : float
        End time, s.
    torque, hub_motion, controller : object, optional
        The run's inputs, as :func:`flexctl.simulate` takes them.
    x0 : array_like, shape (n,), optional
        Initial plant state; default rest at zero.
    alongside : callable, optional
        ``alongside(request, plan)``, called once with the run's checked request and
        integration plan (``flexctl.sim.request``) when its integrators are built and its
        accuracy check started, before its steps: work to start beside the run (the
        validity estimate's runs). Not called for a sampled controller's run.
    **options
        The keywords of :func:`flexctl.simulate` (``rtol``, ``atol``, ``method``,
        ``output_step``, ``max_step``, ``check_accuracy``, ``progress``, ``sensors``), but
        ``check_validity``.

    Returns
    -------
    SimulationResult
        With ``validity`` None (:func:`flexctl.simulate` adds it).
    """
    request = run_request(model, t_final, torque, hub_motion, controller, x0, **options)
    looser = _looser_sampling(request)
    if request.sampled:
        result, merged = _simulate_sampled(request), False
    else:
        result, merged = _simulate_continuous(request, looser, alongside)
    if not request.input_note:
        return result
    message = f"{result.message} ({request.input_note})"
    if merged:
        message = (f"{message} (integration_error includes the sampling's: the accuracy check "
                   f"ran on the function sampled at {CHECK_FACTOR:g} times the tolerance)")
    elif isinstance(request.torque, SampledFunction):
        error, note = _sampling_error(request, result, (model, t_final, hub_motion, controller,
                                                         x0), options, looser)
        result = replace(result, integration_error=error)
        message = f"{message} ({note})" if note else message
    return replace(result, message=message)


def _looser_sampling(request):
    """The run's sampled torque function sampled again at
    :data:`~flexctl.sim.compiled.CHECK_FACTOR` times its tolerance (the accuracy check's
    torque, so that the check counts the sampling's error with the integration's), or None:
    no check, no sampled function, or one the looser sampling could not make."""
    if not request.check_accuracy or not isinstance(request.torque, SampledFunction):
        return None
    samples = request.torque
    looser, _ = sample_function(samples.function, request.t_final,
                                CHECK_FACTOR * samples.tolerance, reuse=True)
    return looser


def _sampling_error(request, result, arguments, options, looser) -> tuple:
    """``(integration_error, note)`` of a run on a sampled torque function whose accuracy
    check could not take the looser sampling (a sampled loop, SciPy's methods, ``"rk4"``):
    the run's own estimate plus the largest tip difference from the same run on ``looser``,
    the function sampled at :data:`~flexctl.sim.compiled.CHECK_FACTOR` times the run's
    sampling tolerance (the sampling's error in the response, conservative: the looser
    sampling's), or None with the reason where that run cannot be compared."""
    error = result.integration_error
    if not request.check_accuracy or error is None or result.status != "ok":
        return error, ""
    model, t_final, hub_motion, controller, x0 = arguments
    rerun = None if looser is None else run_once(
        model, t_final, looser, hub_motion, controller, x0,
        **dict(options, check_accuracy=False, progress=None))
    if rerun is None or rerun.status != "ok" or rerun.t.shape != result.t.shape:
        return None, ("accuracy check not complete: the run on the torque sampled at "
                      f"{CHECK_FACTOR:g} times the tolerance did not reach its end")
    sampling = float(np.max(np.abs(rerun.tip_deflection - result.tip_deflection)))
    return float(error) + sampling, (f"integration_error includes the sampling's, {sampling:.3g} "
                                     "m at the tip")


def run_states(model, t_final: float, torque=None, hub_motion=None, controller=None,
               x0=None, **options) -> tuple:
    """``(ok, states)``: whether :func:`run_once` reaches ``t_final``, and its plant states
    on its output grid, without the result's outputs, torque history and energy audit (for
    runs whose states alone are wanted: the validity estimate's). ``states`` is None when
    the run stops early.

    Parameters
    ----------
    model : Model
        The model to simulate.
    t_final : float
        End time, s.
    torque, hub_motion, controller : object, optional
        The run's inputs, as :func:`flexctl.simulate` takes them.
    x0 : array_like, shape (n,), optional
        Initial plant state; default rest at zero.
    **options
        As for :func:`run_once`.

    Returns
    -------
    ok : bool
    states : ndarray, shape (n, P), or None
    """
    return _states_of(run_request(model, t_final, torque, hub_motion, controller, x0,
                                  **options))


def _states_of(request) -> tuple:
    """:func:`run_states` of a checked request."""
    if request.sampled:
        run = _simulate_sampled(request)
        return (True, run.states) if run.status == "ok" else (False, None)
    _, _, drive, _, traj = _integrate(request)
    return _plant_states(request, drive, traj)


def _plant_states(request, drive, traj) -> tuple:
    """``(ok, plant states on the output grid)`` of a trajectory (``(False, None)`` when it
    stopped early or holds a state that is not finite)."""
    if traj.reason is not StopReason.REACHED_END:
        return False, None
    states = np.asarray(drive.plant_state(*output_samples(request.grid, traj)), dtype=float)
    if not np.all(np.isfinite(states)):
        return False, None
    return True, states


def start_states_run(model, t_final: float, torque=None, hub_motion=None, controller=None,
                     x0=None, **options) -> Beside:
    """:func:`run_states`, started beside the caller on a spare core where its integration is
    compiled (:class:`~flexctl.sim.background.Beside`; queued for the first core given back
    where none is spare now).

    The run is checked and its integrator built here, in the caller's thread (CasADi's
    symbolic work is not thread-safe); only the compiled steps run beside, letting go of
    Python's lock. Where the beside integration fails or passes a stopping condition, or the
    run is not one of compiled steps (a sampled controller, CVODES, SciPy), ``result()``
    makes the run as :func:`run_states` does, in the caller's thread: the result is the same
    either way.

    Parameters
    ----------
    model : Model
        The model to simulate.
    t_final : float
        End time, s.
    torque, hub_motion, controller : object, optional
        The run's inputs, as :func:`flexctl.simulate` takes them.
    x0 : array_like, shape (n,), optional
        Initial plant state; default rest at zero.
    **options
        As for :func:`run_once`; ``check_accuracy`` must be False (the run has no accuracy
        check).

    Returns
    -------
    Beside
        Its ``result()`` is :func:`run_states`'s ``(ok, states)``; ``abandon()`` stops the
        steps beside within a compiled call.
    """
    request = run_request(model, t_final, torque, hub_motion, controller, x0, **options)
    if request.check_accuracy:
        raise InputValueError("start_states_run makes runs without an accuracy check; got "
                              "check_accuracy=True")
    if request.sampled:
        return Beside(_states_of, request, beside=False)
    plan, stops, drive, strategy = _strategy(request)
    steps = strategy.compiled_steps
    if steps is None:
        return Beside(_states_of, request, beside=False)
    # one event: abandoning the run abandons its steps beside
    segments, cancelled = planned_segments(plan, request.grid), threading.Event()
    replay = Beside(_replay_states, steps, segments, drive.y_init, stops.first_bad,
                    cancelled=cancelled, queue=True)
    return Beside(_states_after, request, drive, segments, replay, beside=False,
                  cancelled=cancelled)


def _replay_states(steps, segments, y0, stop, cancelled):
    """The compiled steps' states at every segment's output times (:func:`replay_steps`), or
    None where they failed, stopped or were abandoned."""
    done = replay_steps(steps, segments, y0, stop, cancelled)
    return None if done is None else done[0]


def _states_after(request, drive, segments, replay, cancelled) -> tuple:
    """:func:`run_states`'s result from the states of the steps started beside, or from the
    run made again where they failed or stopped (which names and locates the stop)."""
    states = replay.result()
    if cancelled.is_set():
        return False, None
    if states is None:
        return _states_of(request)
    traj = Trajectory(ts=[np.array([0.0]), *(t_out for _, t_out in segments)],
                      ys=[drive.y_init[:, None], states])
    traj.reason = StopReason.REACHED_END
    return _plant_states(request, drive, traj)


def _simulate_continuous(request, check_torque=None, alongside=None) -> tuple:
    """:func:`run_once` with a continuous drive: its strategy, stops and accuracy check, the
    check on ``check_torque`` where it is given and the strategy's check can take it, and
    ``alongside`` (:func:`run_once`'s) started before the steps. ``(result, whether the check
    took check_torque and gave the run's estimate)``."""
    plan, stops, drive, start, traj = _integrate(request, check_torque, alongside)
    result = assemble_result(request, plan, drive, stops, traj, time.perf_counter() - start)
    return result, traj.check_torque_taken and result.integration_error is not None


def _integrate(request, check_torque=None, alongside=None) -> tuple:
    """``(plan, stops, drive, start time, trajectory)`` of a continuous drive's run: its
    strategy, stops and accuracy check (on ``check_torque`` in place of the run's torque
    where given and where the strategy's check runs beside the run:
    ``trajectory.check_torque_taken``); ``alongside(request, plan)`` called after the check
    started, before the steps."""
    plan, stops, drive, strategy = _strategy(request)
    start = time.perf_counter()
    taken = check_torque is not None and strategy.checks_beside
    if taken:
        strategy.check_request = replace(request, torque=check_torque)
    # the check needs only the plan: it runs beside the run, on a spare core if there is one
    check = strategy.start_check() if request.check_accuracy else None
    try:
        if alongside is not None:
            alongside(request, plan)
        traj = strategy.run()
    except BaseException:
        if check is not None:
            check.abandon()
        raise
    finally:
        strategy.release()
    if check is not None and traj.reason is StopReason.REACHED_END and \
            len(traj.compiled_segments) == len(plan.drive_cuts) - 1:
        strategy.finish_check(traj, check)
    elif check is not None:
        check.abandon()
        if traj.reason is StopReason.REACHED_END and not traj.accuracy_note:
            # a segment the compiled integrator could not take went to SciPy: the replay
            # does not describe that run, and no estimate is better than a wrong one
            traj.accuracy_note = ("accuracy check not run: the compiled integrator failed on "
                                  "a segment, which SciPy integrated instead")
    traj.check_torque_taken = taken
    return plan, stops, drive, start, traj


def _strategy(request) -> tuple:
    """``(plan, stops, drive, strategy)`` of a continuous drive's run, its integrators built."""
    model, hub_motion = request.model, request.hub_motion
    drive = (PrescribedDrive(model, hub_motion, request.x_init) if request.prescribed
             else TorqueDrive(model, request.torque, request.controller, request.x_init))
    singular = model.variant.quadratic_inertia and not request.prescribed
    stops, plan = StopConditions(model, drive.layout, singular), plan_integration(request, drive)
    drive.check_inputs()
    try:
        strategy = strategy_for(plan, request.symbolic)(request, plan, drive, stops)
    except NoCompiledIntegrator:
        # the plan's compiled multistep method is built here, when the run starts: a drive
        # too large to compile takes the plan's method without it
        plan = plan.without_compiled()
        strategy = strategy_for(plan, request.symbolic)(request, plan, drive, stops)
    return plan, stops, drive, strategy


def _simulate_sampled(request) -> SimulationResult:
    """:func:`run_once` under a sampled controller (:mod:`flexctl.sim.digital`)."""
    model, rtol = request.model, request.rtol
    scale = state_scale(model, model.layout)
    if request.atol is not None:
        scale = check_atol(request.atol, scale, model.layout.names) / rtol
    stops = StopConditions(model, model.layout, singular=False)
    start = time.perf_counter()
    integrator, h_max = plan_sampled(request)
    run = run_sampled(model, request.t_final, request.controller, request.x_init,
                      torque=request.torque, output_step=request.step, scale=scale, rtol=rtol,
                      bad_sample=stops.first_bad, check_accuracy=request.check_accuracy,
                      integrator=integrator, h_max=h_max, sensors=request.sensors)
    wall = time.perf_counter() - start
    note = "" if integrator != "rk4" else rk4_accuracy_note(
        run.integration_error, tip_rows(model, model.layout) @ run.states, rtol, stacklevel=3)
    message = run.message
    if run.stop is None:
        reason = StopReason.REACHED_END
    elif run.stop == "integrator":
        reason = StopReason.INTEGRATOR_FAILED
    else:
        reason = stops.reason_of_sample(run.stop_state)
        message = stops.message(reason, float(run.t[-1]), run.states[:, -1])
    balance, message = audit_energy(model, (run.t, run.states, run.torque), reason, message, 4)
    if note:
        message = f"{message} ({note})"
    return SimulationResult.from_states(
        model, run.t, run.states, run.torque, status=reason.status, message=message,
        wall_time=wall, n_evaluations=run.n_evaluations, method=integrator, rtol=float(rtol),
        controller_states=np.zeros((0, run.t.size)),
        integration_error=run.integration_error,
        controller_report=dict(run.report, controller_time=run.controller_time),
        stop_reason=reason, energy_balance=balance, measurements=run.measurements)
