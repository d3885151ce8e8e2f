"""Integration by embedded Runge-Kutta pairs: Dormand-Prince 5(4) from sample to sample, and
5(4) or 8(5,3) over continuous runs.

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

A continuous run (:class:`EmbeddedRun`) makes :data:`ATTEMPTS` steps of a pair per compiled
call, accepted or rejected inside it, and reads its output times from the pair's continuous
extension: Dormand-Prince 5(4) (``method="RK45"``) or 8(5,3) (``method="dop853"``, the
scheme of Hairer's DOP853 and SciPy's ``DOP853``, which ``method="auto"`` takes), each a
:class:`PairScheme`.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from .compiled import (CHECK_FACTOR, cached_build, input_key, drive_size, input_numbers,
                       is_symbolic)
from .compile_cache import compiled
from .lifted_constants import lift_constants
from .buffers import InPlace, borrow, give_back
from .step_chain import skippable, step_chain
from . import fixed_step
from .fixed_step import (END_INSIDE, STEP_CACHE, STEP_CACHE_SIZE, drive_symbols, jit_compiled,
                         step_function)
from .native_rhs import MAX_INSTRUCTIONS
from ..model.checks import check_array, check_instance, check_integer, check_real
from ..model.errors import InputValueError

__all__ = ["EmbeddedHold", "EmbeddedRun", "CompiledRun", "PairScheme", "checked_run_arguments",
           "choose_hold", "DORMAND_PRINCE", "DENSE_OUTPUT", "STIFF_SAMPLE", "SAFETY", "ATTEMPTS",
           "PAIR_OMEGA_H", "DOP853_OMEGA_H"]

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
#: The coefficients of Dormand-Prince's continuous extension of order 4 (Hairer, Norsett
#: and Wanner's DOPRI5; also SciPy's ``RK45`` interpolant), one per stage: with
#: ``dy = y5 - y``, ``b = h k1 - dy``, ``r4 = dy - h k7 - b`` and ``r5 = h sum(d_i k_i)``,
#: ``y(t + theta h) = y + theta (dy + (1 - theta) (b + theta (r4 + (1 - theta) r5)))``.
DENSE_OUTPUT = (-12715105075 / 11282082432, 0.0, 87487479700 / 32700410799,
                -10690763975 / 1880347072, 701980252875 / 199316789632,
                -1453857185 / 822651844, 69997945 / 29380423)
#: Longest step of a continuous run, in radians of its fastest pole. The pair's stability
#: function stays within ``1 + 1.4e-6`` on the imaginary axis up to ``|h lambda| = 1`` and
#: grows past it (1.03 at 2, 1.44 at 3): an undamped fast mode whose error the control does
#: not see (a loose ``rtol``, a large ``atol``) must not be stepped past 1, or it grows step
#: after step. The run takes at most half that, so that its accuracy check, replayed with
#: twice the longest step, is still stable and still a different run. At the usual
#: tolerances the error control keeps the steps about this short anyway (``omega h`` of 0.49
#: on slew-90's 6-mode plant at rtol 1e-6).
PAIR_OMEGA_H = 0.5
#: Longest step of a continuous run by Dormand-Prince 8(5,3), in radians of its fastest pole:
#: its stability function stays within the unit circle on the imaginary axis up to
#: ``|h lambda| = 5.96`` (and damps past 2: 0.99997 at 2, 0.9985 at 3, 0.83 at 5), where
#: 5(4)'s leaves it at 0.997, so the run takes at most 2.5 and its accuracy check, replayed
#: with twice the longest step, 5.
DOP853_OMEGA_H = 2.5
#: Step attempts per compiled call of a continuous run (:class:`EmbeddedRun`): the calls'
#: Python overhead is paid once for this many steps; the attempts left once a segment is done
#: change nothing.
ATTEMPTS = 128
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
class HeldTorque:
    """The held torque as a parametric static controller: one compiled right-hand side and
    one integrator (or step) serve every sample of every hold, the torque entering as a
    number.

    Parameters
    ----------
    value : float
        The torque held, N m (an actuated model's command, in its unit).
    """

    value: float
    n_states = 0

    def torque(self, t, x, z=None):
        """The held torque, N m, whatever the time and state.

        Parameters
        ----------
        t : float
            Time, s; not used.
        x : ndarray, shape (n,)
            Plant state; not used.
        z : ndarray, optional
            Internal state; not used (there is none).
        """
        return self.value

    @property
    def casadi_parameters(self) -> tuple:
        return ("held",), (self.value,)

    def casadi_torque(self, t, x, parameters=None):
        """The held torque as a CasADi expression: its number, taken as a symbol.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s; not used.
        x : casadi.SX or casadi.MX
            Plant state; not used.
        parameters : casadi.SX or casadi.MX, shape (1, 1)
            The held torque's number as a symbol (its part of
            :func:`~flexctl.sim.compiled.split_numbers`), N m. Required despite its default.
        """
        return parameters[0]


def _dopri5_step(f, t, y, h, atol, rtol) -> tuple:
    """One Dormand-Prince step of ``y' = f(time, y)`` from ``y`` at ``t``, as CasADi
    expressions: ``(stages, y5, norm)``, the seven stage derivatives, the fifth-order solution
    and the weighted RMS norm of the embedded error estimate (CVODES's weights,
    ``atol + rtol max(|y|, |y5|)``)."""
    import casadi as ca

    tableau, ks = DORMAND_PRINCE, []
    for node, row in zip(tableau["c"], tableau["a"]):
        stage = y
        for a, k in zip(row, ks):
            if a != 0.0:
                stage = stage + h * a * k
        # a stage at the step's end sees the held input from the left, as RK4's does
        ks.append(f(t + h * (node if node < 1.0 else 1.0 - END_INSIDE), stage))
    y5 = y + h * sum(b * k for b, k in zip(tableau["b"], ks) if b != 0.0)
    error = h * sum(e * k for e, k in zip(tableau["e"], ks) if e != 0.0)
    weight = atol + rtol * ca.fmax(ca.fabs(y), ca.fabs(y5))
    return ks, y5, ca.sqrt(ca.sumsqr(error / weight) / y.numel())


class _DormandPrince:
    """The scheme for :func:`~flexctl.sim.fixed_step.step_function`: one Dormand-Prince step
    and the weighted norm of its error estimate."""

    name, label = "dopri5", "Dormand-Prince"

    def __init__(self, ny: int):
        self.inputs = (("atol", ny), ("rtol", 1))

    def __call__(self, f, t, y, h, extra):
        _, y5, norm = _dopri5_step(f, t, y, h, *extra)
        return y5, norm


def _dop853_tableau() -> dict:
    """Dormand and Prince's 8(5,3) pair (Hairer, Norsett and Wanner's DOP853; the
    coefficients of SciPy's ``DOP853``): twelve stages, the derivative at the step's end, and
    three more for the continuous extension of order 7."""
    from scipy.integrate._ivp import dop853_coefficients as dop853

    return {"a": dop853.A, "b": dop853.B, "c": dop853.C, "e3": dop853.E3, "e5": dop853.E5,
            "d": dop853.D, "stages": dop853.N_STAGES}


class PairScheme:
    """An embedded Runge-Kutta pair as compiled continuous runs use it
    (:class:`EmbeddedRun`): one attempted step as CasADi expressions, the exponent of its step
    control and its continuous extension.

    Parameters
    ----------
    name : {"dopri5", "dop853"}
        Dormand-Prince 5(4) (SciPy's ``RK45``) or 8(5,3) (SciPy's ``DOP853``).

    Attributes
    ----------
    evaluations : int
        Right-hand side evaluations of one attempt, its continuous extension included.
    dense_rows : int
        Vectors of the continuous extension per step (the start state first).
    exponent : float
        ``-1 / (q + 1)``, ``q`` the order of the error estimate: the step control's
        ``h_new = h * SAFETY * norm ** exponent``.
    omega_h : float
        Longest step of a run, in radians of its fastest pole (:data:`PAIR_OMEGA_H` for
        Dormand-Prince 5(4), :data:`DOP853_OMEGA_H` for 8(5,3)).
    """

    def __init__(self, name: str):
        if name not in ("dopri5", "dop853"):
            raise InputValueError(f"PairScheme name must be 'dopri5' or 'dop853'; got {name!r}")
        self.name = name
        self.label = "Dormand-Prince 5(4)" if name == "dopri5" else "Dormand-Prince 8(5,3)"
        self.evaluations = 7 if name == "dopri5" else 16
        self.dense_rows = 5 if name == "dopri5" else 8
        self.exponent = -0.2 if name == "dopri5" else -0.125
        self.omega_h = PAIR_OMEGA_H if name == "dopri5" else DOP853_OMEGA_H

    def attempt(self, f, t, y, h, atol, rtol) -> tuple:
        """``(y_new, norm, dense)`` of one step of length ``h`` from ``y`` at ``t``: the
        solution, the weighted RMS norm of its error estimate (CVODES's weights, ``atol +
        rtol max(|y|, |y_new|)``) and the rows of its continuous extension (``dense_rows``
        vectors stacked), all CasADi expressions.

        Parameters
        ----------
        f : callable
            ``f(time, state)``, the derivative as a CasADi expression (shape (m, 1)).
        t : casadi.SX or casadi.MX or float
            Start of the step, s.
        y : casadi.SX or casadi.MX, shape (m, 1)
            State at ``t``.
        h : casadi.SX or casadi.MX or float
            Length of the step, s.
        atol : casadi.SX or casadi.MX or float or array_like
            Absolute tolerance, one or one per state.
        rtol : casadi.SX or casadi.MX or float
            Relative tolerance.
        """
        import casadi as ca

        if self.name == "dopri5":
            ks, y5, norm = _dopri5_step(f, t, y, h, atol, rtol)
            dy = y5 - y
            spline = h * ks[0] - dy
            dense = ca.vertcat(y, dy, spline, dy - h * ks[6] - spline,
                               h * sum(d * k for d, k in zip(DENSE_OUTPUT, ks) if d != 0.0))
            return y5, norm, dense
        tab = _dop853_tableau()
        n_stages = tab["stages"]

        def stages(count, ks):
            for row in range(len(ks), count):
                stage = y
                for a, k in zip(tab["a"][row][:row], ks):
                    if a != 0.0:
                        stage = stage + h * float(a) * k
                node = float(tab["c"][row])
                ks.append(f(t + h * (node if node < 1.0 else 1.0 - END_INSIDE), stage))
            return ks

        ks = stages(n_stages, [])
        y_new = y + h * sum(float(b) * k for b, k in zip(tab["b"], ks) if b != 0.0)
        # the derivative at the step's end: the error estimate's last stage and the
        # continuous extension's
        ks.append(f(t + h * (1.0 - END_INSIDE), y_new))
        weight = atol + rtol * ca.fmax(ca.fabs(y), ca.fabs(y_new))
        err5 = sum(float(e) * k for e, k in zip(tab["e5"], ks) if e != 0.0) / weight
        err3 = sum(float(e) * k for e, k in zip(tab["e3"], ks) if e != 0.0) / weight
        n5, n3 = ca.sumsqr(err5), ca.sumsqr(err3)
        denominator = n5 + 0.01 * n3
        norm = ca.if_else(denominator > 0.0,
                          ca.fabs(h) * n5 / ca.sqrt(ca.fmax(denominator, 1e-300) * y.numel()),
                          0.0)
        ks = stages(tab["a"].shape[0], ks)
        dy = y_new - y
        rows = [y, dy, h * ks[0] - dy, 2.0 * dy - h * (ks[n_stages] + ks[0])]
        rows += [h * sum(float(d) * k for d, k in zip(tab["d"][i], ks) if d != 0.0)
                 for i in range(tab["d"].shape[0])]
        return y_new, norm, ca.vertcat(*rows)

    def interpolate(self, p, theta):
        """States at fractions of their steps from the steps' continuous extensions: shape
        (K, m).

        Parameters
        ----------
        p : ndarray, shape (K, dense_rows, m)
            Each output's step: the ``dense`` rows of :meth:`attempt`.
        theta : ndarray, shape (K, 1)
            Each output's fraction of its step, in [0, 1].
        """
        if self.name == "dopri5":
            return p[:, 0] + theta * (p[:, 1] + (1.0 - theta) * (
                p[:, 2] + theta * (p[:, 3] + (1.0 - theta) * p[:, 4])))
        value = p[:, 7]
        for k, row in enumerate((6, 5, 4, 3, 2, 1)):
            value = p[:, row] + (1.0 - theta if k % 2 else theta) * value
        return p[:, 0] + theta * value


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
        key = input_key(model, (torque, None, None), np.array([1.0]))
        ny = self.scale.size

        def build():
            step = step_function(model, torque, None, HeldTorque(0.0), n_numbers,
                                  scheme=_DormandPrince(ny))[0]
            return jit_compiled(step, model)

        step = cached_build(STEP_CACHE, STEP_CACHE_SIZE,
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
    ``"cvodes"``.

    Parameters
    ----------
    model : Model
        The plant, its actuator included.
    sample_time : float
        The controller's sample interval, s (> 0).
    spin_frequency : float, optional
        Fastest beam frequency at the initial hub rate, rad/s (its magnitude is taken).
        Default 0.
    """
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


def _attempt_chain(model, inputs, n_numbers: int, attempts: int = ATTEMPTS,
                   scheme: PairScheme | None = None):
    """``(run, lifted numbers or None)``: the compiled ``run(s, t_end, h_max, c, atol, rtol[,
    numbers]) -> (s_end, info, dense)`` (``numbers``: the model's numbers, lifted out of its
    code, :func:`~flexctl.sim.lifted_constants.lift_constants`) of ``attempts`` Dormand-Prince
    step attempts of the drive of ``inputs = (torque, hub_motion, controller)`` from
    ``s = [t; h; y]`` towards ``t_end``, each accepted or rejected by the error control
    inside the call.

    ``info`` (4, attempts) holds for each attempt whether it was accepted, its start time,
    its length and its error norm; ``dense`` (5 ny, attempts) the step's start state and the
    four vectors of the continuous extension (:data:`DENSE_OUTPUT`). Once ``t = t_end`` the
    remaining attempts change nothing."""
    import casadi as ca

    torque, hub_motion, controller = inputs
    drive = drive_symbols(model, torque, hub_motion, controller, n_numbers)
    ny, c, numbers, f = (drive[k] for k in ("ny", "c", "numbers", "f"))
    values = drive["lifted_values"]
    if drive["sym"] is ca.SX:
        # the drive's derivative as one scalar function, its numbers (the model's matrices)
        # lifted into an input: the step calls it seven times, so that its code is written
        # once, and models that differ only in numbers share one library
        ts, ys = ca.SX.sym("t"), ca.SX.sym("y", ny)
        rate = ca.Function("flexctl_drive_rate", [ts, ys, c], [f(ts, ys)])
        lifted = lift_constants(rate, MAX_INSTRUCTIONS)
        if lifted is not None:
            rate, values = lifted
        # called, not inlined, by the step's scalar code
        inputs = rate.sx_in()
        rate = ca.Function(rate.name(), inputs, [rate(*inputs)], {"never_inline": True})
        numbers = None if values is None else ca.SX.sym("numbers", values.size)
        extra = [] if numbers is None else [numbers]

        def f(time, state):
            return rate(time, state, c, *extra)
    sym = drive["sym"]
    s, t_end, h_max = sym.sym("s", ny + 2), sym.sym("t_end"), sym.sym("h_max")
    atol, rtol = sym.sym("atol", ny), sym.sym("rtol")
    t, h, y = s[0], s[1], s[2:]
    left = t_end - t
    live = left > 0.0
    h_try = ca.fmin(h, h_max)
    # the last step of a segment ends on it (and is not left a sliver)
    last = left <= 1.1 * h_try
    step = ca.if_else(last, left, h_try)
    scheme = scheme or PairScheme("dopri5")
    y5, norm, dense = scheme.attempt(f, t, y, step, atol, rtol)
    accepted = ca.logic_and(norm <= 1.0, live)            # a NaN norm never is
    change = SAFETY * norm ** scheme.exponent
    grown = ca.fmin(GROWTH, change) * step
    h_next = ca.if_else(live, ca.if_else(accepted, ca.if_else(last, ca.fmax(h, grown), grown),
                                         ca.fmax(SHRINK, change) * step), h)
    t_next = ca.if_else(accepted, ca.if_else(last, t_end, t + step), t)
    args = [s, t_end, h_max, c, atol, rtol] + ([] if numbers is None else [numbers])
    name = f"flexctl_{scheme.name}"
    attempt = ca.Function(f"{name}_attempt", args,
                          [ca.vertcat(t_next, h_next, ca.if_else(accepted, y5, y)),
                           ca.vertcat(accepted, t, step, norm), dense])
    # an attempt after the segment's end is skipped: the state passes through, unchanged
    body = skippable(attempt, lambda s, t_end, *rest: s[0] >= t_end,
                     lambda s, *rest: [s, ca.vertcat(0.0, s[0], 0.0, 0.0),
                                       ca.MX.zeros(scheme.dense_rows * ny)], name)
    # the input numbers and the model's are passed by reference to every attempt
    chain = step_chain(body, attempts, f"{name}_chain")
    call = [ca.MX.sym(body.name_in(k), body.sparsity_in(k)) for k in range(body.n_in())]
    ends, info, dense_all = chain(*call)
    run = ca.Function(f"{name}_run{attempts}", call,
                      [ends[:, -1], info, dense_all])
    label = f"the {model.variant} model's {scheme.label} steps"
    return (compiled(run, label=label) if fixed_step.USE_JIT else run), values


def checked_run_arguments(owner: str, model, inputs, scale, rtol, max_steps, h_first,
                          max_step) -> tuple:
    """The arguments of a continuous run's compiled steps (:class:`EmbeddedRun`,
    :class:`~flexctl.sim.compiled_bdf.BdfRun`) checked, each refused by name:
    ``(m, scale, rtol, max_steps, h_first, max_step)``, ``m`` the drive's size and
    ``max_step`` ``inf`` when None.

    Parameters
    ----------
    owner : str
        The class to name in an error.
    model : Model
        The model integrated (any :class:`~flexctl.model.variants.Model`).
    inputs : tuple
        ``(torque, hub_motion, controller)``, each None or an input with a CasADi form.
    scale : array_like, shape (m,)
        Physical size of each integrated state (> 0).
    rtol : float
        Relative tolerance, in (0, 1].
    max_steps : int
        Most step attempts between two output times (>= 1).
    h_first : float
        The first step tried, s (> 0).
    max_step : float or None
        Longest step, s (> 0); None or ``inf``: none.
    """
    from ..model import Model

    check_instance(owner, "model", model, Model)
    torque, hub_motion, controller = inputs
    if not is_symbolic(torque=torque, hub_motion=hub_motion, controller=controller):
        raise InputValueError(f"{owner} inputs must each have a CasADi form (casadi(t), "
                              "casadi_torque); got a Python callable")
    m = drive_size(model, hub_motion, controller)
    scale = check_array(owner, "scale", scale, shape=(m,))
    if np.any(scale <= 0.0):
        raise InputValueError(f"{owner} scale must be positive (the states' sizes); got a "
                              f"smallest entry of {float(np.min(scale))!r}")
    rtol = check_real(owner, "rtol", rtol, minimum=0.0, strict=True, maximum=1.0)
    max_steps = check_integer(owner, "max_steps", max_steps, minimum=1)
    h_first = check_real(owner, "h_first", h_first, minimum=0.0, strict=True)
    if max_step is None or (isinstance(max_step, float) and max_step == math.inf):
        max_step = math.inf
    else:
        max_step = check_real(owner, "max_step", max_step, minimum=0.0, strict=True)
    return m, scale, rtol, max_steps, h_first, max_step


class CompiledRun:
    """A continuous run's segments by one compiled function on buffers of its own
    (``self._run``, an :class:`~flexctl.sim.buffers.InPlace`): the call that
    :class:`EmbeddedRun` and :class:`~flexctl.sim.compiled_bdf.BdfRun` share; each has its
    ``_segment``."""

    def __call__(self, lo, t_out, y, stop=None) -> tuple:
        """States at ``t_out`` from ``y`` at ``lo``: ``(states (m, K), evaluations)``.
        ``stop(states)``, if given, is asked after each call about the states it added (the
        index of the first that ends the run, or None): the states end after that call's,
        fewer than ``K``, rather than integrating a run that has ended."""
        run = self._run
        if run is None:
            raise RuntimeError(f"{type(self).__name__} was released: its buffers serve "
                               "another run")
        with run._lock:        # its buffers are this run's: written and read here directly
            return self._segment(run, float(lo), np.asarray(t_out, dtype=float),
                                 np.asarray(y, dtype=float), stop)

    def release(self) -> None:
        """Give the buffers back for the next run of the same compiled function
        (:func:`~flexctl.sim.buffers.give_back`; also done when this run is let go); the
        run is not called after."""
        release = getattr(self, "_release", None)
        if release is not None:
            release()
            self._run = None


class EmbeddedRun(CompiledRun):
    """A continuous run's segments by Dormand-Prince 5(4) or 8(5,3) steps with error control
    (:class:`PairScheme`), the step size carried from segment to segment, :data:`ATTEMPTS`
    attempts per compiled call and the output times read from the pair's continuous
    extension.

    Parameters
    ----------
    model : Model
        The model integrated.
    torque, hub_motion, controller : object or None, optional
        The run's inputs, each with a CasADi form (:func:`~flexctl.sim.compiled.is_symbolic`).
    scale : ndarray, shape (m,)
        Physical size of each integrated state (the drive's: plant and controller states, or
        ``[q, q_dot]`` under a prescribed hub motion); the absolute tolerance is
        ``rtol * scale``.
    rtol : float
        Relative tolerance of each step's local error (weighted RMS norm, as CVODES).
    max_steps : int
        Most step attempts between two output times (as CVODES's ``max_num_steps``).
    h_first : float
        The first step tried, s.
    max_step : float, optional
        Longest step, s (an input's own bound). Default: none.
    scheme : {"dopri5", "dop853"}, optional
        The pair (:class:`PairScheme`): Dormand-Prince 5(4), the default, or 8(5,3).

    Notes
    -----
    ``run(lo, t_out, y, stop=None) -> (states (m, K), evaluations)`` integrates from ``y`` at
    ``lo`` onto the output times ``t_out`` (ascending, after ``lo``; the last is the segment's
    end, where an input may jump). ``RuntimeError`` when a step cannot be taken: a non-finite
    state, the step budget, a step too short.
    """

    def __init__(self, model, torque=None, hub_motion=None, controller=None, *, scale,
                 rtol: float, max_steps: int, h_first: float, max_step: float | None = None,
                 scheme: str = "dopri5"):
        inputs = (torque, hub_motion, controller)
        m, scale, rtol, self.max_steps, self.h, max_step = checked_run_arguments(
            "EmbeddedRun", model, inputs, scale, rtol, max_steps, h_first, max_step)
        if scheme not in ("dopri5", "dop853"):
            raise InputValueError(f"EmbeddedRun scheme must be 'dopri5' or 'dop853'; got "
                                  f"{scheme!r}")
        self.scheme = pair = PairScheme(scheme)
        numbers = input_numbers(inputs)
        key = input_key(model, inputs, np.array([1.0]))
        run, model_numbers = cached_build(STEP_CACHE, STEP_CACHE_SIZE,
                                     None if key is None else (f"{scheme}-run", key),
                                     (model, *inputs),
                                     lambda: _attempt_chain(model, inputs, numbers.size,
                                                            scheme=pair))
        self._run, self._size = borrow(run), m
        # the buffers go back to the pool when this run is let go (a replay beside the run
        # holds it until it ends)
        self._release = weakref.finalize(self, give_back, self._run)
        # the buffers keep every input but the carry and the segment's end, set per call
        fixed = [max_step, numbers, rtol * scale, rtol]
        if model_numbers is not None:
            fixed.append(model_numbers)
        for k, value in enumerate(fixed, start=2):
            self._run.args[k][:] = value

    def _segment(self, run, lo, t_out, y, stop):
        m, attempts, pair = self._size, 0, self.scheme
        # the carry: time, step size, then the drive's state
        carry, end = run.args[0], float(t_out[-1])
        run.args[1][0] = end
        carry[0], carry[1], carry[2:] = lo, self.h, y
        out, done = np.empty((m, t_out.size)), 0
        budget = self.max_steps * t_out.size
        while carry[0] < end:
            run.evaluate()
            final, info, dense = run.results
            info = info.reshape(-1, 4)
            live = info[:, 1] < end
            attempts += int(np.count_nonzero(live))
            taken = info[:, 0] > 0.5
            t_now = float(final[0])
            if not math.isfinite(t_now) or not np.all(np.isfinite(final[2:])):
                raise RuntimeError(f"non-finite state after t = {carry[0]:.6g} s")
            reached = int(np.searchsorted(t_out, t_now, side="right"))
            if reached > done:
                starts, lengths = info[taken, 1], info[taken, 2]
                parts = dense.reshape(-1, pair.dense_rows, m)[taken]
                which = np.searchsorted(starts, t_out[done:reached], side="right") - 1
                theta = ((t_out[done:reached] - starts[which]) / lengths[which])[:, None]
                out[:, done:reached] = pair.interpolate(parts[which], theta).T
                if stop is not None and stop(out[:, done:reached]) is not None:
                    return out[:, :reached], pair.evaluations * attempts
                done = reached
            h = float(final[1])
            carry[:] = final
            if attempts > budget:
                raise RuntimeError(f"more than {budget} steps before t = {end:.6g} s")
            if not h >= MIN_STEP * max(1.0, abs(t_now)):
                raise RuntimeError(f"step size {h:.3g} s at t = {t_now:.6g} s")
        out[:, -1] = carry[2:]
        self.h = float(carry[1])
        return out, pair.evaluations * attempts
