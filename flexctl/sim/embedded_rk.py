"""Sample-to-sample integration by an embedded Runge-Kutta pair (Dormand-Prince 5(4)).

A sampled loop integrates the plant over one sample at a time under a held torque. CVODES
starts every sample again from BDF order 1 and a step far below the one the plant allows: on
``wheel-slew``'s sensor loop (rtol 1e-8, 20 Hz) each 50 ms sample took some 46 steps, the
first of 0.2 ms and the last of 24 ms, with 13 Jacobian factorisations. A one-step method has
no history to rebuild: the Dormand-Prince pair (the scheme of SciPy's ``RK45``) carries its
step size from one sample to the next, so a sample of a smooth, non-stiff plant takes the few
steps its accuracy needs.

Each step is one compiled call, ``([y; t], h, [c; u], atol, rtol) -> ([y5; t + h], e)``: the
fifth-order solution and the weighted RMS norm of its difference from the embedded
fourth-order one, ``e = ||(y5 - y4) / (atol + rtol max(|y|, |y5|))||``, with the weights of
CVODES (``atol = rtol * scale``). A step with ``e <= 1`` is accepted (local extrapolation, as in
SciPy and Hairer's DOPRI5); the next is ``h * min(5, max(0.2, 0.9 e^(-1/5)))``. Steps end
exactly at the output times inside a sample (an output grid point, a sensor's read time).

:func:`choose_hold` picks this pair or CVODES for ``method="auto"``: the pair when the fastest
pole of the held plant (the largest eigenvalue of its linearisation at rest) allows a sample
in a few steps within the pair's stability region, CVODES for a stiff plant (many modes, a
fast actuator) whose explicit steps would be stability-bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .compiled import CHECK_FACTOR, _cached, _input_key, input_numbers, is_symbolic
from .buffers import InPlace
from .fixed_step import _END_INSIDE, _STEP_CACHE, _STEP_CACHE_SIZE, _jit, _step_function
from ..model.checks import check_array, check_instance, check_integer, check_real
from ..model.errors import InputValueError

__all__ = ["EmbeddedHold", "choose_hold", "DORMAND_PRINCE", "STIFF_SAMPLE", "SAFETY"]

#: The Dormand-Prince 5(4) tableau: nodes ``c``, stages ``a``, fifth-order weights ``b`` (also
#: the last stage's row) and the error weights ``e = b - b_hat`` (``b_hat`` of fourth order).
DORMAND_PRINCE = {
    "c": (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0),
    "a": ((),
          (1 / 5,),
          (3 / 40, 9 / 40),
          (44 / 45, -56 / 15, 32 / 9),
          (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
          (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
          (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84)),
    "b": (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0),
    "e": (71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40),
}
#: Largest ``omega_max T`` (fastest pole of the held plant times the sample time) for which
#: ``method="auto"`` takes the pair: the pair is stable up to ``|h lambda|`` of about 3.3 on
#: the imaginary axis, so a sample then needs at most some 30 stability-bound steps (7
#: evaluations each, no Jacobian), about what CVODES spends on its restart.
STIFF_SAMPLE = 100.0
#: Step-size control: safety factor, and the largest and smallest change of a step.
SAFETY, GROWTH, SHRINK = 0.9, 5.0, 0.2
#: A step shorter than this fraction of the time reached (or of 1 s) is a singularity, not
#: accuracy: the sample fails.
MIN_STEP = 1e-12



@dataclass(frozen=True)
class _Held:
    """The held torque as a parametric static controller: one compiled right-hand side and
    one integrator (or step) serve every sample of every hold, the torque entering as a
    number."""

    value: float
    n_states = 0

    def torque(self, t, x, z=None):
        return self.value

    @property
    def casadi_parameters(self) -> tuple:
        return ("held",), (self.value,)

    def casadi_torque(self, t, x, parameters=None):
        return parameters[0]


class _DormandPrince:
    """The scheme for :func:`~flexctl.sim.fixed_step._step_function`: one Dormand-Prince step
    and the weighted norm of its error estimate."""

    name, label = "dopri5", "Dormand-Prince"

    def __init__(self, ny: int):
        self.inputs = (("atol", ny), ("rtol", 1))

    def __call__(self, f, t, y, h, extra):
        import casadi as ca

        atol, rtol = extra
        tableau = DORMAND_PRINCE
        ks = []
        for c, row in zip(tableau["c"], tableau["a"]):
            stage = y
            for a, k in zip(row, ks):
                if a != 0.0:
                    stage = stage + h * a * k
            # a stage at the step's end sees the held input from the left, as RK4's does
            ks.append(f(t + h * (c if c < 1.0 else 1.0 - _END_INSIDE), stage))
        y5 = y + h * sum(b * k for b, k in zip(tableau["b"], ks) if b != 0.0)
        error = h * sum(e * k for e, k in zip(tableau["e"], ks) if e != 0.0)
        weight = atol + rtol * ca.fmax(ca.fabs(y), ca.fabs(y5))
        norm = ca.sqrt(ca.sumsqr(error / weight) / y.numel())
        return y5, norm


class EmbeddedHold:
    """One sample under a held torque by Dormand-Prince 5(4) steps with error control, the
    step size carried from sample to sample.

    Parameters
    ----------
    model : Model
        The plant (its actuator's states included).
    torque : object or None
        An additional torque with a CasADi form, applied continuously.
    scale : ndarray, shape (n,)
        Physical size of each state: the absolute tolerance is ``rtol * scale``.
    rtol : float
        Relative tolerance of each step's local error (weighted RMS norm, as CVODES).
    max_steps : int
        Most steps (accepted or not) of one sample; more raise ``RuntimeError``.
    h_first : float
        The first step tried, s (the error control shortens it as it must).

    Notes
    -----
    Called as the other holds of :func:`flexctl.sim.digital.run_sampled`:
    ``hold(lo, t_out, y, u, loose=False) -> (states (n, K), evaluations)``; ``loose`` runs at
    :data:`~flexctl.sim.compiled.CHECK_FACTOR` times the tolerance (the replay that estimates
    the run's integration error), with a step size of its own.
    """

    #: the looser replay's difference is taken as the error (conservative), as for CVODES
    error_divisor = 1.0

    def __init__(self, model, torque, scale, rtol: float, max_steps: int, h_first: float):
        from ..model import Model

        check_instance("EmbeddedHold", "model", model, Model)
        if torque is not None and not is_symbolic(torque=torque):
            raise InputValueError("EmbeddedHold torque must have a CasADi form (casadi(t)) or "
                                  f"be None; got {type(torque).__name__}")
        n = model.layout.n_states
        self.scale = check_array("EmbeddedHold", "scale", scale, shape=(n,))
        if np.any(self.scale <= 0.0):
            raise InputValueError(f"EmbeddedHold scale must be positive (the states' sizes); "
                                  f"got a smallest entry of {float(np.min(self.scale))!r}")
        self.rtol = check_real("EmbeddedHold", "rtol", rtol, minimum=0.0, strict=True,
                               maximum=1.0)
        self.max_steps = check_integer("EmbeddedHold", "max_steps", max_steps, minimum=1)
        h_first = check_real("EmbeddedHold", "h_first", h_first, minimum=0.0, strict=True)
        self.model, self.torque = model, torque
        self.torque_numbers = input_numbers((torque, None, None))
        n_numbers = self.torque_numbers.size + 1
        key = _input_key(model, (torque, None, None), np.array([1.0]))
        ny = self.scale.size

        def build():
            step = _step_function(model, torque, None, _Held(0.0), n_numbers,
                                  scheme=_DormandPrince(ny))[0]
            return _jit(step, model)

        step = _cached(_STEP_CACHE, _STEP_CACHE_SIZE,
                       None if key is None else ("dopri5", key), (model, torque), build)
        self._runs, self._h = {}, {}
        for loose in (False, True):
            tol = self.rtol * (CHECK_FACTOR if loose else 1.0)
            run = InPlace(step)
            # the tolerances stay in the buffers: calls pass [y; t], h and [c; u] only
            run.args[3][:] = tol * self.scale
            run.args[4][:] = tol
            self._runs[loose] = run
            self._h[loose] = float(h_first)

    def __call__(self, lo, t_out, y, u, loose=False):
        """States at ``t_out`` (ascending, after ``lo``, s) from ``y`` (n,) at ``lo`` under the
        held torque ``u`` (N m): ``(states (n, K), evaluations)``; ``RuntimeError`` when a step
        cannot be taken (a non-finite state, the step budget, a step too short)."""
        run = self._runs[bool(loose)]
        with run._lock:       # its buffers are this hold's: written and read here directly
            return self._sample(run, lo, t_out, y, u, loose)

    def _sample(self, run, lo, t_out, y, u, loose):
        state, length, numbers = run.args[0], run.args[1], run.args[2]
        stepped, error = run.results[0], run.results[1]
        numbers[:-1], numbers[-1] = self.torque_numbers, u
        state[:-1], state[-1] = y, lo
        t, h, attempts = float(lo), self._h[loose], 0
        out = np.empty((state.size - 1, len(t_out)))
        for j, end in enumerate(np.asarray(t_out, dtype=float)):
            while t < end:
                left = end - t
                # the last step of an output interval ends on it (and is not left a sliver)
                last = left <= 1.1 * h
                step = left if last else h
                length[0] = step
                run.evaluate()
                norm = float(error[0])
                attempts += 1
                if attempts > self.max_steps:
                    raise RuntimeError(f"more than {self.max_steps} steps in a sample")
                if norm <= 1.0:                          # accepted (NaN never is)
                    t = end if last else t + step
                    state[:] = stepped
                    state[-1] = t
                    grow = GROWTH if norm == 0.0 else min(GROWTH, SAFETY * norm ** -0.2)
                    # a step cut short to end on an output time does not shorten the next
                    h = max(h, step * grow) if last else step * grow
                else:
                    shrink = (max(SHRINK, SAFETY * norm ** -0.2) if math.isfinite(norm)
                              else SHRINK)
                    h = step * shrink
                    if h < MIN_STEP * max(1.0, abs(t)):
                        raise RuntimeError(f"step size {h:.3g} s at t = {t:.6g} s")
            out[:, j] = state[:-1]
        self._h[loose] = h
        if not np.all(np.isfinite(out)):
            raise RuntimeError("non-finite state")
        return out, 7 * attempts


def choose_hold(model, sample_time: float, spin_frequency: float = 0.0) -> tuple:
    """``(integrator, omega)`` for a sampled loop under ``method="auto"``: ``"RK45"`` (an
    :class:`EmbeddedHold`) when the fastest pole ``omega`` (1/s) of the plant under a held
    torque (the largest eigenvalue of its linearisation at rest, its actuator's included),
    or the spin frequency, times ``sample_time`` is at most :data:`STIFF_SAMPLE`; else
    ``"cvodes"``."""
    from ..model import Model

    check_instance("choose_hold", "model", model, Model)
    sample_time = check_real("choose_hold", "sample_time", sample_time, minimum=0.0,
                             strict=True)
    spin_frequency = abs(check_real("choose_hold", "spin_frequency", spin_frequency))
    a = np.asarray(model.linear_matrices(0.0)[0], dtype=float)
    omega = (float(np.max(np.abs(np.linalg.eigvals(a)))) if np.all(np.isfinite(a))
             else math.inf)
    omega = max(omega, spin_frequency)
    stiff = not math.isfinite(omega) or omega * sample_time > STIFF_SAMPLE
    return ("cvodes" if stiff else "RK45"), omega
