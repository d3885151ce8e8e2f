"""Compiled integration: the whole right-hand side in CasADi, integrated by SUNDIALS CVODES.

When every input of a run can be written as a CasADi expression (the built-in manoeuvres, and
controllers that offer ``casadi_torque``), the integration runs inside CVODES (variable-order BDF
with Newton iterations on the exact, symbolically derived Jacobian), with no Python call per step.
:func:`flexctl.simulate` uses this path by default and falls back to SciPy for Python inputs and
to locate the exact time at which a run stops.

States are scaled by their physical size before integration, so one absolute tolerance serves
angles, rates and modal coordinates alike.
"""

from __future__ import annotations

import numpy as np

from ..model.exports import _symbolic_beam_dynamics, _symbolic_dynamics

__all__ = ["is_symbolic", "SegmentIntegrator", "integrate_segments"]


def is_symbolic(torque=None, hub_motion=None, controller=None) -> bool:
    """True when every given input offers a CasADi form (``casadi`` / ``casadi_torque``)."""
    if torque is not None and not callable(getattr(torque, "casadi", None)):
        return False
    if hub_motion is not None and not callable(getattr(hub_motion, "casadi", None)):
        return False
    if controller is not None and (getattr(controller, "n_states", 0)
                                   or not callable(getattr(controller, "casadi_torque", None))):
        return False
    return True


class SegmentIntegrator:
    """CVODES integration of a model over one smooth segment, onto given output times.

    Parameters
    ----------
    model : Model
    t_start : float
        Segment start, s.
    t_out : ndarray, shape (K,)
        Output times in ``(t_start, t_end]``, ascending, s.
    scale : ndarray, shape (m,)
        Physical size of each integrated state; ``m = n`` (torque-driven) or ``2 N``
        (prescribed hub motion: ``[q, q_dot]``).
    rtol : float
        Relative tolerance; the absolute tolerance is ``rtol * scale``.
    torque, hub_motion, controller :
        As in :func:`flexctl.simulate`; each must pass :func:`is_symbolic`.
    solver : {"cvodes", "idas"}
        SUNDIALS solver; both are variable-order BDF.
    max_order : int, optional
        Highest BDF order (honoured by IDAS). Order 2 is A-stable: it never amplifies an
        undamped oscillation, where orders 3 to 5 can for steps near the oscillation period.
    """

    def __init__(self, model, t_start, t_out, scale, rtol, torque=None, hub_motion=None,
                 controller=None, max_steps=1_000_000, solver="cvodes", max_order=None):
        import casadi as ca

        scale = np.asarray(scale, dtype=float)
        ys = ca.SX.sym("ys", scale.size)
        t = ca.SX.sym("t")
        y = ys * ca.DM(scale)
        if hub_motion is not None:
            rate, acceleration = hub_motion.casadi(t)
            dy = _symbolic_beam_dynamics(model, y, rate, acceleration)
        else:
            u = 0.0
            if torque is not None:
                u = u + torque.casadi(t)
            if controller is not None:
                u = u + controller.casadi_torque(t, y)
            dy = _symbolic_dynamics(model, y, ca.vertcat(u))
        opts = {"reltol": float(rtol), "abstol": float(rtol), "max_num_steps": int(max_steps),
                "disable_internal_warnings": True}
        if solver == "cvodes":
            # a step this small means a singularity, not accuracy: fail fast and let the
            # caller locate it
            opts["min_step_size"] = 1e-12 * max(1.0, float(t_out[-1]))
        if max_order is not None:
            opts["max_multistep_order"] = int(max_order)
        self._scale = scale
        self._f = ca.integrator(f"flexctl_{solver}", solver,
                                {"x": ys, "t": t, "ode": dy / ca.DM(scale)},
                                float(t_start), [float(v) for v in t_out], opts)

    def __call__(self, y0) -> np.ndarray:
        """States at the output times, shape (m, K); raises ``RuntimeError`` if CVODES fails."""
        out = self._f(x0=np.asarray(y0, dtype=float) / self._scale)
        return np.array(out["xf"]) * self._scale[:, None]

    @property
    def n_evaluations(self) -> int:
        """Right-hand-side evaluations of the last call."""
        stats = self._f.stats()
        return int(stats.get("nfevals", 0)) if isinstance(stats, dict) else 0


def integrate_segments(model, segments, y0, scale, rtol, **options):
    """Integrate over consecutive smooth segments, each onto its output times.

    Parameters
    ----------
    model : Model
    segments : list of (float, ndarray)
        ``(t_start, t_out)`` per segment, as for :class:`SegmentIntegrator`; each segment starts
        where the previous one's outputs end.
    y0 : ndarray, shape (m,)
        State at the first segment's start.
    scale, rtol, **options :
        As for :class:`SegmentIntegrator` (``torque``, ``hub_motion``, ``controller``,
        ``solver``, ``max_order``).

    Returns
    -------
    states : ndarray, shape (m, K)
        At every output time of every segment, in order.
    n_evaluations : int

    Raises
    ------
    RuntimeError
        If the solver fails on a segment.
    """
    blocks, n_eval, y = [], 0, np.asarray(y0, dtype=float)
    for t_start, t_out in segments:
        integ = SegmentIntegrator(model, t_start, t_out, scale, rtol, **options)
        block = integ(y)
        n_eval += integ.n_evaluations
        blocks.append(block)
        y = block[:, -1]
    return np.concatenate(blocks, axis=1), n_eval


#: The accuracy check re-runs at this many times the tolerance ...
CHECK_FACTOR = 10.0
#: ... onto at most this many output times per segment.
CHECK_POINTS = 200
#: A disagreement this many times ``rtol`` (relative to the peak tip deflection) ...
ALARM_FACTOR = 1e4
#: ... with the run taking this many times the evaluations of the check run means the
#: integration went wrong rather than merely inexact: a healthy BDF run at 10x the tolerance
#: costs 1.5 to 3 times fewer steps, while a run that follows spurious ringing of undamped
#: high-frequency modes costs hundreds of times more.
EFFORT_FACTOR = 20.0


def _subsample(segments):
    """At most ``CHECK_POINTS`` output times per segment (its end always kept), and the
    indices of those times among all the segments' outputs."""
    check, picks, offset = [], [], 0
    for t_start, t_out in segments:
        k = len(t_out)
        keep = np.unique(np.r_[np.arange(0, k, max(1, k // CHECK_POINTS)), k - 1])
        check.append((t_start, np.asarray(t_out)[keep]))
        picks.append(offset + keep)
        offset += k
    return check, np.concatenate(picks)


def verify_accuracy(model, segments, y0, scale, rtol, y_main, tip_map, n_main, **options):
    """Estimate the integration error of a compiled run, and mend a run that went wrong.

    The run is repeated at ``CHECK_FACTOR`` times the tolerance, onto at most
    ``CHECK_POINTS`` of each segment's output times; the largest difference in tip deflection
    there is the error estimate (conservative: it is the error of the looser run). If the
    two disagree by more than ``ALARM_FACTOR * rtol`` of the peak while the run took more than
    ``EFFORT_FACTOR`` times the evaluations of the check, high-order BDF has amplified an
    undamped high-frequency mode, and the run is redone with A-stable BDF2 (IDAS).

    Parameters
    ----------
    model, segments, y0, scale, rtol, **options :
        As for :func:`integrate_segments`.
    y_main : ndarray, shape (m, K)
        The run to check, at the segments' output times.
    tip_map : ndarray, shape (m,)
        ``tip = tip_map @ y``.
    n_main : int
        Right-hand-side evaluations of the run to check.

    Returns
    -------
    states : ndarray, shape (m, K)
        ``y_main``, or the BDF2 run that replaces it.
    error : float or None
        Estimated largest tip error, m (None if the check could not run).
    note : str
        Empty, or what was found and done.
    n_evaluations : int
    """
    tip_main = tip_map @ y_main
    check_segments, picks = _subsample(segments)
    try:
        y_check, n_eval = integrate_segments(model, check_segments, y0, scale,
                                             CHECK_FACTOR * rtol, **options)
    except RuntimeError:
        return y_main, None, "accuracy check could not run (the check integration failed)", 0
    error = float(np.max(np.abs(tip_main[picks] - tip_map @ y_check)))
    peak = max(float(np.max(np.abs(tip_main))), float(abs(tip_map) @ scale) * 1e-3)
    if error <= ALARM_FACTOR * rtol * peak or n_main <= EFFORT_FACTOR * max(n_eval, 1):
        return y_main, error, "", n_eval
    found = (f"accuracy check: CVODES and a check run at {CHECK_FACTOR:g}x the tolerance "
             f"disagreed by {error:.3g} m at the tip, the mark of undamped high-frequency "
             "modes that BDF orders 3 to 5 amplify")
    try:
        options = {**options, "solver": "idas", "max_order": 2}
        y_fixed, n_fixed = integrate_segments(model, segments, y0, scale, rtol, **options)
        y_fixed_check, n_check = integrate_segments(model, check_segments, y0, scale,
                                                    CHECK_FACTOR * rtol, **options)
    except RuntimeError:
        return y_main, error, found + "; the A-stable re-run failed, result kept", n_eval
    error = float(np.max(np.abs(tip_map @ (y_fixed[:, picks] - y_fixed_check))))
    return (y_fixed, error, found + "; re-integrated with A-stable BDF2 (IDAS)",
            n_eval + n_fixed + n_check)
