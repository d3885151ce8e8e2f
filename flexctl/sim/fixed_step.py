"""Compiled fixed-step integration (classical RK4) with a step-doubling error estimate.

For "fast, and 1 % is enough" (sweeps, Monte Carlo, design loops): the whole run is one
compiled loop of an RK4 step (:func:`~flexctl.sim.step_chain.step_chain`), evaluated in one
call, with no step-size control to pay for. The step is chosen from the fastest retained mode (and the closed loop's fastest pole),
``omega_max h <= RK4_OMEGA_H``, well inside RK4's stability interval on the imaginary axis
(``2 sqrt 2``); every output time and every breakpoint of the inputs is a step boundary.

The error is estimated by step doubling: the run is repeated with half the step, and the
largest difference of the two tip-deflection histories (at the coarse run's step boundaries)
is the estimate. It is the error of the coarser run, so it bounds the error of the finer run
that is returned; Richardson's division by ``2^4 - 1 = 15`` would hold only where RK4 is in
its asymptotic range for every mode, which a fast mode at ``omega h`` near 1 is not (measured
on slew-90 under a sampled PD law: the error fell 4.6 times, not 16, when the step was
halved). While the estimate exceeds ``rtol`` times the peak tip deflection, the step is halved
again (at most ``MAX_HALVINGS`` times).
"""

from __future__ import annotations

import weakref
from collections import OrderedDict

import numpy as np

from .compiled import (cached_build, closed_loop_dynamics, input_key, split_numbers,
                       drive_size, hub_motion_casadi, input_numbers)
from .buffers import InPlace
from .compile_cache import compiled
from .lifted_constants import lift_constants
from .step_chain import step_chain
from .native_rhs import MAX_INSTRUCTIONS
from ..model.exports import symbolic_beam_dynamics
from ..model.discrete import rk4_step

__all__ = ["RK4_OMEGA_H", "RK4_FIRST_OMEGA_H", "RK4_STABILITY", "MAX_HALVINGS", "step_times",
           "FixedStepRun", "integrate_fixed_step"]

#: ``omega_max h`` of a resolved step: the fastest mode takes about 13 steps a period. The
#: sampled path steps at most this; a continuous run whose states are not finite at a longer
#: step is refined down to it before its divergence is reported.
RK4_OMEGA_H = 0.5
#: ``omega_max h`` of a continuous run's first returned run (the first, coarser run of the
#: step-doubling pair has twice as much, still inside RK4's stability interval); halvings
#: follow until the estimated error meets the tolerance. At the default ``rtol`` of 1e-2
#: the first pair is usually enough: a fast mode that the inputs do not excite needs
#: stability, not resolution.
RK4_FIRST_OMEGA_H = 1.0
#: RK4's stability interval on the imaginary axis: ``|R(i y)| <= 1`` for ``|y| <= 2 sqrt 2``.
RK4_STABILITY = 2.0 * np.sqrt(2.0)
#: Most step halvings made to meet the tolerance.
MAX_HALVINGS = 5
#: Most RK4 steps a run may take (each a few microseconds compiled).
MAX_STEPS = 20_000_000
#: Stage times stop this fraction of a step short of its end, so that an input that jumps at
#: a step boundary (a breakpoint) is seen from the left inside the step, as by the other paths.
END_INSIDE = 1e-9

#: Compile the loops to machine code (:mod:`flexctl.sim.compile_cache`, kept across runs and
#: processes) where a compiler is present: about 6 times faster per step than CasADi's virtual
#: machine, once the 0.2 to 0.5 s compile is paid, once. The exact variant, whose quadrature
#: takes seconds to compile, compiles its step alone (``_exact_step``).
USE_JIT = True
#: Steps per call of a compiled loop, largest first: a segment takes the largest that fits,
#: then smaller ones, the last padded with steps of length 0 (which change nothing) where
#: that wastes fewer steps than it makes. The loops do not depend on the number of steps, so
#: runs of other lengths, steps or segments reuse them.
CHUNKS = (4096, 256, 16)

STEP_CACHE: OrderedDict = OrderedDict()
#: Each exact model's lifted step dynamics (:func:`lifted_core`).
_LIFTED: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
STEP_CACHE_SIZE = 64


def drive_symbols(model, torque, hub_motion, controller, n_numbers: int) -> dict:
    """The symbols of a drive's compiled step: ``sym`` (SX, or MX for the exact model), ``ny``
    (the drive's state size), ``c`` (the inputs' numbers, ``n_numbers`` rows), ``numbers``
    (the exact model's lifted numbers as a symbol, else None) with their values
    ``lifted_values``, and ``f(time, state)``, the drive's derivative (plant and controller
    states, or ``[q, q_dot]`` under a prescribed hub motion) on them.

    Parameters
    ----------
    model : Model
        The model of the run.
    torque, hub_motion, controller : object or None
        The run's inputs, each with a CasADi form (:func:`~flexctl.sim.compiled.is_symbolic`).
    n_numbers : int
        Rows of ``c``: the size of the inputs' numbers
        (:func:`~flexctl.sim.compiled.input_numbers`), plus any the caller appends (a sampled
        hold's torque).
    """
    import casadi as ca

    sym = ca.MX if model.variant.exact else ca.SX
    ny = drive_size(model, hub_motion, controller)
    c = sym.sym("c", n_numbers)
    lifted = lifted_core(model, hub_motion)
    numbers = None if lifted is None else sym.sym("numbers", lifted[1].size)

    def f(time, state, model_numbers=numbers):
        if hub_motion is not None:
            rate, acceleration = hub_motion_casadi(
                hub_motion, time, split_numbers((torque, hub_motion, controller), c)[1])
            if model_numbers is None:
                return symbolic_beam_dynamics(model, state, rate, acceleration)
            beam = model.layout.without_rotation()
            q, q_dot = beam.modal(state), beam.modal_rates(state)
            return ca.vertcat(q_dot, lifted[0](q, q_dot, rate, acceleration, model_numbers))
        rhs = None if model_numbers is None else (lambda x, u: lifted[0](x, u, model_numbers))
        return closed_loop_dynamics(model, time, state, torque, controller, c, rhs=rhs)

    return {"sym": sym, "ny": ny, "c": c, "numbers": numbers, "f": f,
            "lifted_values": None if lifted is None else lifted[1]}


def step_function(model, torque, hub_motion, controller, n_numbers: int, scheme=None):
    """CasADi ``step([y; t], h, c) -> ([y_next; t + h], f(t, y))``: one RK4 step of the drive
    (plant and controller states, or ``[q, q_dot]`` under a prescribed hub motion), time
    carried with the state, and the derivative at the step's start for dense output; and
    ``rate(y, t, c) -> f`` alone. The exact model's step is compiled on its own
    (``_exact_step``). The last stage sees a held input from inside the step (at
    ``t + h (1 - END_INSIDE)``), never the value it jumps to at the step's end.

    Parameters
    ----------
    model : Model
        The model of the run.
    torque, hub_motion, controller : object or None
        The run's inputs, each with a CasADi form (:func:`~flexctl.sim.compiled.is_symbolic`).
    n_numbers : int
        Rows of ``c``, as for :func:`drive_symbols`.
    scheme : callable, optional
        ``scheme(f, t, y, h, extra)`` in place of RK4: it returns the step's outputs after
        ``[y_next; t + h]``, given the drive's ``f(time, state)``; ``extra`` are the step's
        further inputs (``scheme.inputs``: ``(name, rows)`` pairs) as symbols (the sampled
        loop's Dormand-Prince steps, :class:`~flexctl.sim.embedded_rk.EmbeddedHold`).

    Returns
    -------
    step, rate : casadi.Function
    """
    import casadi as ca

    drive = drive_symbols(model, torque, hub_motion, controller, n_numbers)
    sym, ny, c, numbers, f = (drive[k] for k in ("sym", "ny", "c", "numbers", "f"))
    yt, h = sym.sym("yt", ny + 1), sym.sym("h")
    y, t = yt[:ny], yt[ny]
    ys, ts = sym.sym("y", ny), sym.sym("t")
    rate = ca.Function("flexctl_rate", [ys, ts, c], [f(ts, ys, None)])
    extra = [] if scheme is None else [sym.sym(name, rows) for name, rows in scheme.inputs]
    if scheme is None:
        y_next, k1 = rk4_step(f, t, y, h, end=1.0 - END_INSIDE)
        outputs, name = [k1], "rk4"
    else:
        y_next, *outputs = scheme(f, t, y, h, extra)
        name = scheme.name
    args = [yt, h, c, *extra]
    if numbers is None:
        return (ca.Function(f"flexctl_{name}_step", args,
                            [ca.vertcat(y_next, t + h), *outputs]), rate)
    step = ca.Function(f"flexctl_exact_{name}_step", args + [numbers],
                       [ca.vertcat(y_next, t + h), *outputs])
    return (_exact_step(step, drive["lifted_values"],
                        "RK4" if scheme is None else scheme.label), rate)


def lifted_core(model, hub_motion):
    """``_exact_core`` with its numbers lifted (``(function, numbers)``,
    :func:`~flexctl.sim.lifted_constants.lift_constants`), kept with the model: a sampled loop
    builds a step for each count of steps per sample. None where there is no core or it is
    too long to compile.

    Parameters
    ----------
    model : Model
        The model of the run (only the exact variant has a core).
    hub_motion : object or None
        Only whether there is one matters: the beam's function under a prescribed hub motion,
        the right-hand side under a torque.
    """
    kind = "prescribed" if hub_motion is not None else "torque"
    kept = _LIFTED.setdefault(model, {})
    if kind not in kept:
        core = _exact_core(model, hub_motion)
        kept[kind] = None if core is None else lift_constants(core, MAX_INSTRUCTIONS)
    return kept[kind]


def _exact_core(model, hub_motion):
    """The exact model's scalar function that its RK4 step calls: its beam under a prescribed
    hub motion (a pinned hub), its right-hand side under a torque; None for the other
    variants (written out in the step)."""
    if not model.variant.exact:
        return None
    if hub_motion is not None:
        return None if model.structure.free else model.functions.beam
    return model.casadi()


def _exact_step(step, numbers, label: str = "RK4"):
    """The exact model's ``label`` ``step`` (``[y; t], h, c, ..., model numbers``) as machine
    code from the persistent cache (:mod:`flexctl.sim.compile_cache`), called with the model's
    ``numbers``: ``([y; t], h, c, ...) -> ...``. The model's numbers are an input, so that one
    library serves every model of a structure (a Monte Carlo over the beam compiles once). The
    other variants' loops are compiled whole; the exact model's quadrature would be written
    into each of them, several compilations of seconds each, so its loops (on CasADi's
    virtual machine) call this step instead: some microseconds of arithmetic a step against
    well under one for the call."""
    import casadi as ca

    built = compiled(step, label=f"the exact model's {label} step") if USE_JIT else step
    args = [ca.MX.sym(step.name_in(k), step.sparsity_in(k)) for k in range(step.n_in() - 1)]
    return ca.Function(step.name().replace("_exact", ""), args,
                       built(*args, ca.DM(numbers)))


class _ChunkRuns(dict):
    """Compiled loops ``run_k([y; t], h, c) -> (Y, F)`` of ``k`` steps, ``k`` in
    :data:`CHUNKS`, each built (and compiled) when first used: ``h`` the step lengths, shape
    (1, k), ``Y`` the states with time after each step, ``F`` the derivatives at each step's
    start."""

    def __init__(self, step, model):
        super().__init__()
        self.step, self.model = step, model

    def __missing__(self, k: int):
        import casadi as ca

        chain = step_chain(self.step, k, f"flexctl_rk4_chain{k}", stacked=[1])
        yt, hs = ca.MX.sym("yt", self.step.size1_in(0)), ca.MX.sym("h", 1, k)
        c = ca.MX.sym("c", self.step.size1_in(2))
        ys, fs = chain(yt, hs, c)
        self[k] = InPlace(jit_compiled(ca.Function(f"flexctl_rk4_run{k}", [yt, hs, c],
                                            [ca.densify(ys), ca.densify(fs)]), self.model))
        return self[k]


def _chunk_runs(step, model) -> dict:
    """The compiled loops of ``step`` (``_ChunkRuns``), built on first use."""
    return _ChunkRuns(step, model)


def run_steps(runs: dict, yt, h: float, count: int, numbers) -> tuple:
    """``count`` RK4 steps of length ``h`` from ``yt = [y; t]`` by the loops of
    ``_chunk_runs``: ``(Y, F)`` of shapes (m + 1, count) and (m, count).

    Parameters
    ----------
    runs : dict
        The compiled loops of ``_chunk_runs``, by number of steps (:data:`CHUNKS`).
    yt : ndarray, shape (m + 1,)
        The drive's state, then the time, s.
    h : float
        Step length, s.
    count : int
        Number of steps (>= 1).
    numbers : ndarray, shape (C,)
        The inputs' numbers ``c`` (:func:`~flexctl.sim.compiled.input_numbers`).
    """
    ys, fs, done = [], [], 0
    while done < count:
        left = count - done
        # one padded call where it wastes no more steps than it makes, else the largest
        # loop that fits
        k = min((k for k in CHUNKS if k >= left), default=None)
        if k is None or k - left > left:
            k = next((k for k in CHUNKS if k <= left), CHUNKS[-1])
        used = min(k, left)
        steps = np.zeros((1, k))
        steps[0, :used] = h
        y_k, f_k = runs[k](yt, steps, numbers)
        ys.append(y_k[:, :used])           # the loops hand out arrays of their own
        fs.append(f_k[:, :used])
        yt = ys[-1][:, -1]
        done += used
    return np.concatenate(ys, axis=1), np.concatenate(fs, axis=1)


def hermite(t, starts, sizes, y, f) -> np.ndarray:
    """Cubic Hermite dense output of a fixed-step run (fourth-order accurate, as RK4).

    Parameters
    ----------
    t : ndarray, shape (P,)
        Output times within the run, s.
    starts, sizes : ndarray, shape (S,)
        Each step's start and length, s.
    y, f : ndarray, shape (m, S + 1)
        States and derivatives at the step boundaries.

    Returns
    -------
    ndarray, shape (m, P)
    """
    k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, starts.size - 1)
    s = np.clip((t - starts[k]) / sizes[k], 0.0, 1.0)
    # per step, y(s) = y_0 + s (h f_0 + s (c_2 + s c_3)) in Horner form
    hf0, hf1 = sizes * f[:, :-1], sizes * f[:, 1:]
    dy = y[:, 1:] - y[:, :-1]
    c2, c3 = 3.0 * dy - 2.0 * hf0 - hf1, hf0 + hf1 - 2.0 * dy
    return y[:, k] + s * (hf0[:, k] + s * (c2[:, k] + s * c3[:, k]))


def jit_compiled(function, model, any_variant: bool = False):
    """``function`` compiled to machine code where allowed and possible, else itself (the
    exact variant's only with ``any_variant``: for functions built on its vectorized
    right-hand side, which compile in about a second).

    Parameters
    ----------
    function : casadi.Function
        The function to compile.
    model : Model
        Its variant decides: the exact model's functions stay uncompiled unless
        ``any_variant``.
    any_variant : bool, optional
        Compile the exact model's too. Default False.
    """
    if not USE_JIT or (model.variant.exact and not any_variant):
        return function
    return compiled(function)


def step_times(edges, h_max: float, refine: int = 1) -> tuple:
    """Fixed steps covering consecutive intervals.

    Parameters
    ----------
    edges : array_like, shape (E,)
        Ascending times, s: every output time and breakpoint, from the start.
    h_max : float
        Largest step, s.
    refine : int
        Each interval takes ``refine`` times its base number of steps.

    Returns
    -------
    starts, sizes : ndarray, shape (S,)
        Start time and length of each step, s.
    ends : ndarray of int, shape (E - 1,)
        Index of the step that ends at each of ``edges[1:]``.
    """
    edges = np.asarray(edges, dtype=float)
    widths = np.diff(edges)
    counts = np.maximum(1, np.ceil(widths / h_max * (1.0 - 1e-12))).astype(int) * int(refine)
    sizes = np.repeat(widths / counts, counts)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    local = np.arange(offsets[-1]) - np.repeat(offsets[:-1], counts)
    starts = np.repeat(edges[:-1], counts) + local * sizes
    return starts, sizes, offsets[1:] - 1


class FixedStepRun:
    """Outcome of :func:`integrate_fixed_step`.

    Parameters
    ----------
    states : ndarray, shape (m, E - 1)
        Integrated states at ``edges[1:]``.
    error : float
        Estimated largest tip-deflection error of ``states``, m.
    steps : int
        RK4 steps of the returned run.
    evaluations : int
        Right-hand-side evaluations of every run made (4 per step).
    h : float
        Largest step of the returned run, s.
    """

    def __init__(self, states, error, steps, evaluations, h):
        self.states, self.error, self.steps = states, error, steps
        self.evaluations, self.h = evaluations, h


def integrate_fixed_step(model, edges, t_out, y0, tip_map, h_max: float, rtol: float, *,
                         torque=None, hub_motion=None, controller=None,
                         h_resolved: float = 0.0) -> FixedStepRun:
    """RK4 over ``edges`` with step doubling until the estimated tip error meets ``rtol``.

    Parameters
    ----------
    model : Model
        The model integrated.
    edges : array_like, shape (E,)
        Start time, breakpoints of the inputs and end time, ascending, s: step boundaries.
    t_out : array_like, shape (P,)
        Output times within ``[edges[0], edges[-1]]``, s (cubic Hermite dense output).
    y0 : ndarray, shape (m,)
        The drive's state at ``edges[0]`` (plant and controller states, or ``[q, q_dot]``
        under a prescribed hub motion).
    tip_map : ndarray, shape (K, m)
        ``tips = tip_map @ y`` (m), one row per appendage.
    h_max : float
        Largest step of the returned run before any halving, s (the first, coarser run of
        the pair takes twice as long steps).
    rtol : float
        Target error relative to the peak tip deflection.
    torque, hub_motion, controller : object or None, optional
        As for :func:`flexctl.simulate`, each with a CasADi form.
    h_resolved : float, optional
        A run whose states are not finite is refined, not returned, while its step is
        longer than this, s: it may be the integrator's instability, not the model's.
        Default 0.

    Returns
    -------
    FixedStepRun
        The finest run made, at ``t_out``; its ``error`` may exceed ``rtol`` times the peak
        after ``MAX_HALVINGS`` halvings (the caller warns).
    """
    runner = _RK4Runner(model, edges, y0, tip_map, h_max, (torque, hub_motion, controller))
    coarse = runner.step_end_tips(1)
    evaluations = 4 * int(runner.base.sum())
    refine = 1
    while True:
        refine *= 2
        found = runner.states(refine)
        steps = int(runner.base.sum()) * refine
        evaluations += 4 * steps
        fine = runner.tip_map @ found[0]
        finite = bool(np.all(np.isfinite(found[0])))
        error = None
        if finite:
            # the coarse run's step ends are every other one of the fine run's
            error = float(np.max(np.abs(fine[:, 2::2] - coarse)))
            peak = float(np.max(np.abs(fine)))
        h = float(np.max(runner.widths / (runner.base * refine)))
        unstable = not finite and h > h_resolved * (1.0 + 1e-9)
        if (not finite and not unstable) or (finite and error <= rtol * max(peak, 1e-12)) \
                or refine >= 2 ** MAX_HALVINGS:
            return FixedStepRun(runner.dense(found, t_out), error, steps, evaluations, h)
        coarse = fine[:, 1:]


class _RK4Runner:
    """RK4 runs of one drive over fixed step boundaries at a given refinement: the compiled
    loops (shared by every step count), the tip at the step ends, the states for dense output."""

    def __init__(self, model, edges, y0, tip_map, h_max, inputs):
        self.model, self.inputs = model, inputs
        self.numbers = input_numbers(inputs)
        self.base_key = input_key(model, inputs, np.array([self.numbers.size], dtype=float))
        self.step, self.rate = cached_build(
            STEP_CACHE, STEP_CACHE_SIZE,
            None if self.base_key is None else ("rk4", self.base_key), (model, *inputs),
            lambda: step_function(model, *inputs, self.numbers.size))
        self.tip_map = np.atleast_2d(np.asarray(tip_map, dtype=float))
        self.y0 = np.asarray(y0, dtype=float)
        self.edges = np.asarray(edges, dtype=float)
        self.widths = np.diff(self.edges)
        self.base = np.maximum(1, np.ceil(self.widths / (2.0 * h_max)
                                          * (1.0 - 1e-12))).astype(int)
        if 2 ** MAX_HALVINGS * 2 * int(self.base.sum()) > MAX_STEPS:
            raise ValueError(f"the fixed-step run may need "
                             f"{2 ** (MAX_HALVINGS + 1) * self.base.sum()} RK4 steps, more "
                             f"than the limit {MAX_STEPS}")

    def runs(self) -> dict:
        """The compiled loops of ``_chunk_runs``."""
        key = None if self.base_key is None else ("rk4-runs", self.base_key)
        return cached_build(STEP_CACHE, STEP_CACHE_SIZE, key, (self.model, *self.inputs),
                       lambda: _chunk_runs(self.step, self.model))

    def step_end_tips(self, refine) -> np.ndarray:
        """Each appendage's tip at every step end, m, shape (K, steps)."""
        ny = self.y0.size
        return self.tip_map @ self.states(refine)[0][:ny, 1:]

    def states(self, refine):
        """States at the step ends, derivatives, step starts and sizes, for dense output."""
        yt = np.append(self.y0, self.edges[0])
        blocks, derivatives, starts, sizes = [], [], [], []
        runs = self.runs()
        with np.errstate(invalid="ignore", over="ignore"):
            for lo, width, count in zip(self.edges[:-1], self.widths, self.base * refine):
                count = int(count)
                h = width / count
                ys, fs = run_steps(runs, yt, h, count, self.numbers)
                blocks.append(ys)
                derivatives.append(fs)
                starts.append(lo + h * np.arange(count))
                sizes.append(np.full(count, h))
                yt = ys[:, -1]
                yt[-1] = lo + width          # time exactly at the segment's end
        ny = self.y0.size
        y_all = np.column_stack([self.y0] + [b[:ny] for b in blocks])
        return y_all, np.concatenate(derivatives, axis=1), np.concatenate(starts), \
            np.concatenate(sizes)

    def dense(self, found, t_out) -> np.ndarray:
        """Cubic Hermite interpolation of a run of :meth:`states` at ``t_out``."""
        y_all, fs, starts, sizes = found
        with np.errstate(invalid="ignore", over="ignore"):
            f_end = np.array(self.rate(y_all[:, -1], self.edges[-1] * (1.0 - 1e-15),
                                       self.numbers))
            return hermite(np.asarray(t_out, dtype=float), starts, sizes, y_all,
                           np.column_stack((fs, f_end)))
