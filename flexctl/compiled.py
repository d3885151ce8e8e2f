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

from .exports import _symbolic_beam_dynamics, _symbolic_dynamics

__all__ = ["is_symbolic", "SegmentIntegrator"]


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
    """

    def __init__(self, model, t_start, t_out, scale, rtol, torque=None, hub_motion=None,
                 controller=None, max_steps=1_000_000):
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
                "disable_internal_warnings": True,
                # a step this small means a singularity, not accuracy: fail fast and let the
                # caller locate it
                "min_step_size": 1e-12 * max(1.0, float(t_out[-1]))}
        self._scale = scale
        self._f = ca.integrator("flexctl_cvodes", "cvodes",
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
