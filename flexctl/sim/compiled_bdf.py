"""Compiled multistep methods (variable-order BDF, Adams-Moulton): a continuous run's
segments integrated in machine code.

CVODES takes few steps on these models (its BDF reaches order 5 and its Newton iterations
converge in about one evaluation a step), but through CasADi's interface each step costs
some 3 to 5 us of its own: vector operations, callbacks for each evaluation, linear solve
and Jacobian. On the exact model that is as much again as its right-hand side. Here the
same family of formulas (the numerical differentiation formulas of orders 1 to 5 of SciPy's
``BDF``, Shampine and Reichelt 1997, with CVODES's choice of step and order and its test
that accepts a Newton iteration by the convergence rate of the steps before) is written in C
(``bdf.c``) and compiled with the drive's right-hand side and its Newton Jacobian, generated
by CasADi: a step costs its evaluations and a few hundred operations of its own. The same
template holds the Adams-Moulton methods of orders 1 to 12 (``family="adams"``) in LSODE's
Nordsieck form (Hindmarsh 1983; Radhakrishnan and Hindmarsh 1993): its coefficients, Newton
test, and choice of step and order (its biases raised by 0.2). On lightly damped beams they
take some 40 % fewer steps than the BDF, whose orders 3 to 5 damp and amplify the
oscillations they must follow (hub-beam-mass's exact 6-mode model under a sine torque at
rtol 1e-8, 6 s: 4 394 steps against 7 120), at one evaluation a step too.

- **Jacobian.** The other variants' own (CasADi's, compiled into the library); the exact
  model's by forward differences of its compiled right-hand side (N + 1 evaluations), which
  costs less than building and compiling its symbolic Jacobian. first_order's, which CVODES
  takes for the exact model (:meth:`flexctl.Model.integration_rhs`), is too far from it at
  large deflection: a heavy tip mass on a massless hub took 162 000 to 250 000 evaluations
  with it against 7 189 on the Dormand-Prince pair. Evaluated at a segment's start and where
  Newton's iterations fail to converge, and carried from call to call.
- **Library.** The model's numbers (and first_order's, for the Jacobian) are inputs
  (:func:`~flexctl.sim.lifted_constants.lift_constants`): one library per structure and
  inputs' form, kept in the persistent cache (:func:`~flexctl.sim.compile_cache.compiled_source`).
  The exact model's right-hand side is not in it: the library holds the drive's own part
  (torque and controller, or the hub's motion) and calls the model's compiled right-hand side,
  one library per structure shared with CVODES's, whose entry point is handed to the
  integrator's with each call as a C function pointer
  (:func:`~flexctl.sim.compile_cache.entry_point`). Its libraries are then some 40 kB of C,
  compiled in a fraction of a second, where one holding the model took 400 to 800 kB and 2 to
  4 s for each controller.
- **Calls.** One call integrates onto at most :data:`OUTPUTS` output times and hands back
  the integrator's whole state, so that the next call goes on where it stopped; each
  segment (between the inputs' breakpoints) starts again at order 1.

:class:`BdfRun` has the interface of :class:`~flexctl.sim.embedded_rk.EmbeddedRun`.
:func:`bdf_available` says whether a run can have it (a CasADi form of every input, a C
compiler, a drive small enough to compile).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .buffers import InPlace
from .compiled import cached_build, input_key, input_numbers, is_symbolic
from .compile_cache import compiled_source, compiling_enabled, compiler
from .lifted_constants import lift_constants
from .embedded_rk import CompiledRun, checked_run_arguments
from .fixed_step import STEP_CACHE, STEP_CACHE_SIZE, drive_symbols
from .native_rhs import MAX_DAE_INSTRUCTIONS, MAX_INSTRUCTIONS
from ..model.errors import InputValueError

__all__ = ["BdfRun", "bdf_available", "bdf_possible", "NoCompiledIntegrator", "OUTPUTS",
           "CALL_STEPS", "assembled", "NEWTON_TOLERANCE", "STATUS", "FAMILIES"]

#: Output times per compiled call (the states handed back after each, for a run's stops).
OUTPUTS = 128
#: Most step attempts per compiled call: a call returns within some milliseconds, so that
#: a run's stops are looked at and an abandoned accuracy check ends soon (a thread still in
#: a compiled call when the interpreter exits aborts the process).
CALL_STEPS = 2000
#: Newton iterations stop once the correction left is estimated below this, in the weighted
#: norm of the error test (where 1 is the tolerance); the BDF's (the Adams-Moulton methods
#: take LSODE's test, on the order's error constant).
NEWTON_TOLERANCE = 0.03
#: What the library's status codes mean.
STATUS = {1: "step budget spent", 2: "step too short", 3: "state or derivative not finite",
          4: "output count out of range", 5: "no model right-hand side"}
_TEMPLATE = Path(__file__).with_name("bdf.c")
#: The families of formulas the template holds, by the name a run gives them.
FAMILIES = {"bdf": "BDF", "adams": "Adams"}


def _functions(model, inputs, n_numbers: int) -> dict | None:
    """The pieces of a drive's integrator library, or None where the drive has none: ``F``,
    the drive's derivative ``F(t, y, c, numbers)`` (its numbers lifted) or, for the exact
    model, its own part ``F(t, y, c)`` (torque and controller's derivative, or the hub's rate
    and acceleration) beside ``core``, the model's compiled right-hand side (``address``,
    ``keep``: :func:`~flexctl.sim.compile_cache.entry_point`); ``J(t, y, c, numbers)``, the
    dense Newton Jacobian (None for the exact model, whose Jacobian the C code takes by
    differences); the numbers ``f_values``, ``j_values``; ``defines`` of the C template."""
    import casadi as ca

    from .compiled import drive_terms, split_numbers, hub_motion_casadi
    from .compile_cache import compiled, entry_point
    from .fixed_step import lifted_core

    torque, hub_motion, controller = inputs
    drive = drive_symbols(model, torque, hub_motion, controller, n_numbers)
    ny, c = drive["ny"], drive["c"]
    ts, ys = ca.SX.sym("t"), ca.SX.sym("y", ny)
    out = {"defines": {}, "address": None, "keep": None}
    if drive["sym"] is ca.SX:
        rate = ca.Function("flexctl_bdf_rate", [ts, ys, c], [drive["f"](ts, ys)])
        lifted = lift_constants(rate, MAX_INSTRUCTIONS)
        if lifted is None:
            return None
        f_function, f_values = lifted
        twin = drive
    else:
        lifted = lifted_core(model, hub_motion)
        core = None if lifted is None else compiled(lifted[0], label=lifted[0].name())
        point = None if core is None else entry_point(core)
        if point is None:
            return None
        cs = ca.SX.sym("c", n_numbers)
        if hub_motion is not None:
            own = ca.vertcat(*hub_motion_casadi(hub_motion, ts,
                                                split_numbers(inputs, cs)[1]))
        else:
            u, dz = drive_terms(model, ts, ys, torque, controller, cs)
            own = ca.vertcat(u, *(() if dz is None else (dz,)))
        f_function, f_values = ca.Function("flexctl_bdf_own", [ts, ys, cs], [own]), lifted[1]
        out.update(address=point[0], keep=(core, point[1]))
        out["defines"] = {"BDF_CORE": 1, "BDF_MOTION": int(hub_motion is not None),
                          "BDF_NX": model.n_states, "BDF_NQ": ny // 2,
                          "BDF_NPRE": own.numel(), "BDF_CORE_ARG": core.sz_arg(),
                          "BDF_CORE_RES": core.sz_res(), "BDF_CORE_IW": core.sz_iw(),
                          "BDF_CORE_W": core.sz_w()}
    # fixed C names for the integrator's code
    f_args = f_function.sx_in()
    out.update(F=ca.Function("flexctl_bdf_f", f_args, [f_function(*f_args)]), J=None,
               f_values=np.asarray(f_values, dtype=float).ravel(), j_values=np.zeros(0))
    if drive["sym"] is not ca.SX:
        return out                      # the exact model's Jacobian: by differences, in C
    jacobian = ca.Function("flexctl_bdf_jacobian", [ts, ys, twin["c"]],
                           [ca.densify(ca.jacobian(twin["f"](ts, ys), ys))], {"cse": True})
    lifted = lift_constants(jacobian, MAX_DAE_INSTRUCTIONS)
    if lifted is None:
        return None
    j_function, j_values = lifted
    j_args = j_function.sx_in()
    out.update(J=ca.Function("flexctl_bdf_j", j_args, [j_function(*j_args)]),
               j_values=np.asarray(j_values, dtype=float).ravel())
    return out


def _library(model, inputs, n_numbers: int, family: str = "bdf"):
    """``(external, pieces)`` of the compiled integrator of ``family`` (``"bdf"`` or
    ``"adams"``) for this drive (``pieces`` from ``_functions``), or None."""
    pieces = _functions(model, inputs, n_numbers)
    if pieces is None:
        return None
    return assembled(pieces, n_numbers, family,
                     f"the {model.variant} model's {FAMILIES[family]} integrator")


def assembled(pieces: dict, n_numbers: int, family: str, label: str):
    """``(external, pieces)``: the integrator library of ``family`` around a drive's
    ``pieces`` (as ``_functions`` gives them), from the compile cache, or None where it
    cannot be compiled.

    Parameters
    ----------
    pieces : dict
        ``F`` (the drive's rate, or with a core its own part ``(t, y, c) -> pre``), ``J``
        (its Newton Jacobian, or None: by differences, in C), ``f_values``, ``j_values``
        (their lifted numbers), ``defines`` (of the C template; ``BDF_CORE`` and the core's
        work sizes where a compiled right-hand side is called through its address),
        ``address`` and ``keep`` (that right-hand side's entry point).
    n_numbers : int
        Length of the input ``c`` (the inputs' numbers).
    family : {"bdf", "adams"}
        The formulas (:data:`FAMILIES`).
    label : str
        What to call the library in a progress line.
    """
    import casadi as ca

    generator = ca.CodeGenerator("flexctl_bdf.c", {"with_header": False})
    generator.add(pieces["F"])
    if pieces["J"] is not None:
        generator.add(pieces["J"])
    ny = pieces["F"].size1_in(1)
    defines = {"BDF_NAME": "flexctl_bdf", "BDF_F": "flexctl_bdf_f", "BDF_J": "flexctl_bdf_j",
               "BDF_N": ny, "BDF_K": OUTPUTS, "BDF_NCIN": max(1, n_numbers),
               "BDF_NFNUM": max(1, pieces["f_values"].size),
               "BDF_NJNUM": max(1, pieces["j_values"].size),
               "BDF_ADAMS": int(family == "adams"), **pieces["defines"]}
    for tag in ("F", "J") if pieces["J"] is not None else ("F",):
        function = pieces[tag]
        defines.update({f"BDF_{tag}_ARG": function.sz_arg(), f"BDF_{tag}_RES": function.sz_res(),
                        f"BDF_{tag}_IW": function.sz_iw(), f"BDF_{tag}_W": function.sz_w()})
    source = (generator.dump() + "\n"
              + "".join(f"#define {k} {v}\n" for k, v in defines.items())
              + _TEMPLATE.read_text(encoding="utf-8"))
    external = compiled_source("flexctl_bdf", source, label=label, loops=True)
    if external is None:
        return None
    return external, pieces


class NoCompiledIntegrator(InputValueError):
    """The drive's compiled integrator cannot be built (compiling off, no C compiler, the
    consistent variant, or a drive too large to compile)."""


def bdf_possible(model, torque=None, hub_motion=None, controller=None) -> bool:
    """Whether :class:`BdfRun` may integrate this drive, decided without building anything:
    every input with a CasADi form, compiling on, a C compiler, not the consistent variant.
    A drive too large to compile is found only when it is built (:class:`BdfRun` then raises
    :class:`NoCompiledIntegrator`).

    Parameters
    ----------
    model : Model
        The plant.
    torque, hub_motion, controller : object or None, optional
        The run's inputs, as :func:`flexctl.simulate` takes them.
    """
    return (is_symbolic(torque=torque, hub_motion=hub_motion, controller=controller)
            and compiling_enabled() and compiler() is not None
            and not model.variant.quadratic_inertia)


def bdf_available(model, torque=None, hub_motion=None, controller=None,
                  family: str = "bdf") -> bool:
    """Whether :class:`BdfRun` can integrate this drive with ``family``: every input with a
    CasADi form, compiling on, a C compiler, and a drive whose right-hand side and Jacobian
    are small enough to compile (built, and compiled, here if not yet).

    Parameters
    ----------
    model : Model
        The plant; the consistent variant never has a compiled integrator.
    torque, hub_motion, controller : object or None, optional
        The run's inputs, as :func:`flexctl.simulate` takes them.
    family : {"bdf", "adams"}, optional
        The formulas (:data:`FAMILIES`). Default ``"bdf"``.
    """
    if not is_symbolic(torque=torque, hub_motion=hub_motion, controller=controller):
        return False
    return _built(model, (torque, hub_motion, controller), family) is not None


def _built(model, inputs, family: str = "bdf"):
    """``_library`` of the drive, kept by model and inputs; None where compiling is off,
    there is no compiler, the model is the consistent variant or the drive has no form."""
    if family not in FAMILIES:
        raise InputValueError(f"family must be one of {sorted(FAMILIES)}; got {family!r}"[:300])
    if not compiling_enabled() or compiler() is None or model.variant.quadratic_inertia:
        return None
    numbers = input_numbers(inputs)
    key = input_key(model, inputs, np.array([1.0]))
    return cached_build(STEP_CACHE, STEP_CACHE_SIZE, None if key is None else (family, key),
                   (model, *inputs), lambda: _library(model, inputs, numbers.size, family))


class _Entry(InPlace):
    """The integrator library's ``flexctl_bdf_with_core`` on the buffers of an
    :class:`~flexctl.sim.buffers.InPlace` and CasADi's work arrays: the model's compiled
    right-hand side, where the drive calls one, is passed as a C function pointer (``core``,
    an address; None: a null pointer). ``evaluate()`` makes the call (without Python's lock,
    as ctypes calls C); a status other than 0 is in ``results[2]``."""

    def __init__(self, external, core: int | None):
        import ctypes

        from .compile_cache import entry_point

        super().__init__(external)
        point = entry_point(external, "flexctl_bdf_with_core")
        if point is None:
            raise InputValueError("BdfRun: the integrator's library has no entry "
                                  "flexctl_bdf_with_core")
        pointer = ctypes.c_void_p
        function = ctypes.CFUNCTYPE(ctypes.c_int, pointer, pointer, pointer, pointer,
                                    pointer)(point[0])
        iw = np.zeros(external.sz_iw(), dtype=np.int64)    # casadi_int: long long
        w = np.zeros(external.sz_w())
        arg = (pointer * external.sz_arg())(*(a.ctypes.data for a in self.args))
        res = (pointer * external.sz_res())(*(r.ctypes.data for r in self.results))
        self._keep = (point[1], iw, w, arg, res)
        call = (core, ctypes.addressof(arg), ctypes.addressof(res), iw.ctypes.data,
                w.ctypes.data)
        self.evaluate = lambda: function(*call)


class BdfRun(CompiledRun):
    """A continuous run's segments by compiled variable-order BDF or Adams-Moulton steps with
    error control, each segment from order 1 and the step size carried from the segment
    before.

    Parameters
    ----------
    model : Model
        The model integrated.
    torque, hub_motion, controller : object or None, optional
        The run's inputs, each with a CasADi form.
    scale : ndarray, shape (m,)
        Physical size of each integrated state: the absolute tolerance is ``rtol * scale``.
    rtol : float
        Relative tolerance of each step's local error (weighted RMS norm).
    max_steps : int
        Most step attempts between two output times (as CVODES's ``max_num_steps``).
    h_first : float
        The first step tried, s.
    max_step : float, optional
        Longest step, s. Default: none.
    family : {"bdf", "adams"}, optional
        The formulas (:data:`FAMILIES`). Default ``"bdf"``.

    Notes
    -----
    ``run(lo, t_out, y, stop=None) -> (states (m, K), evaluations)`` integrates from ``y`` at
    ``lo`` onto the output times ``t_out`` (ascending, after ``lo``; the last is the segment's
    end, which no step passes). ``RuntimeError`` when a step cannot be taken (the step
    budget, a step too short, a state that is not finite). ``ValueError`` where the drive
    has no compiled integrator (:func:`bdf_available`).
    """

    def __init__(self, model, torque=None, hub_motion=None, controller=None, *, scale,
                 rtol: float, max_steps: int, h_first: float, max_step: float | None = None,
                 family: str = "bdf"):
        inputs = (torque, hub_motion, controller)
        m, scale, self.rtol, self.max_steps, self.h, self.max_step = checked_run_arguments(
            "BdfRun", model, inputs, scale, rtol, max_steps, h_first, max_step)
        built = _built(model, inputs, family)
        self.family = family
        if built is None:
            raise NoCompiledIntegrator("BdfRun: this drive has no compiled integrator (compiling "
                                  "off, no C compiler, the consistent variant, or a drive too "
                                  "large to compile); use CVODES")
        self._start(built, m, self.rtol * scale, input_numbers(inputs))

    @classmethod
    def on_library(cls, built, n_states: int, atol, numbers, *, rtol: float, max_steps: int,
                   h_first: float, family: str = "adams") -> "BdfRun":
        """A run on a library assembled elsewhere (:func:`assembled`: a spatial model's right-
        hand side, :mod:`flexctl.sim.spatial_adams`), its arguments checked by its caller.

        Parameters
        ----------
        built : tuple
            ``(external, pieces)``, as :func:`assembled` gives them.
        n_states : int
            States integrated.
        atol : ndarray, shape (n_states,)
            Absolute tolerance of each state.
        numbers : ndarray
            The library's input ``c`` (the drive's numbers; its size the library's).
        rtol : float
            Relative tolerance.
        max_steps : int
            Most step attempts between two output times.
        h_first : float
            The first step tried, s.
        family : {"bdf", "adams"}, optional
            The library's formulas. Default ``"adams"``.
        """
        run = cls.__new__(cls)
        run.rtol, run.max_steps, run.h, run.max_step = rtol, max_steps, h_first, math.inf
        run.family = family
        run._start(built, n_states, atol, np.asarray(numbers, dtype=float))
        return run

    def _start(self, built, m: int, atol, numbers) -> None:
        """This run's buffers on the library ``built`` (``(external, pieces)``), ``m``
        states, their absolute tolerances ``atol`` and the inputs' ``numbers``."""
        external, pieces = built
        self._run, self._size = _Entry(external, pieces["address"]), m
        self._keep = pieces["keep"]
        args = self._run.args
        args[4][:] = atol
        args[5][:numbers.size] = numbers
        args[6][:pieces["f_values"].size] = pieces["f_values"]
        args[7][:pieces["j_values"].size] = pieces["j_values"]
        self.last_stats = {}

    def _segment(self, run, lo, t_out, y, stop):
        m, end = self._size, float(t_out[-1])
        if not (np.all(np.isfinite(t_out)) and t_out[0] > lo and np.all(np.diff(t_out) > 0)):
            raise InputValueError(f"BdfRun output times must be finite, ascending and after "
                                  f"lo = {lo!r}")
        carry, y0, times, settings = run.args[0], run.args[1], run.args[2], run.args[3]
        carry[:] = 0.0                  # a fresh start at order 1
        y0[:] = y
        out, done, evaluations = np.empty((m, t_out.size)), 0, 0
        stats = {"steps": 0, "evaluations": 0, "jacobians": 0, "factorisations": 0,
                 "rejected": 0}
        since = 0.0                     # steps since an output was last reached
        while done < t_out.size:
            chunk = t_out[done:done + OUTPUTS]
            times[:chunk.size] = chunk
            times[chunk.size:] = chunk[-1]
            settings[:] = (chunk.size, self.rtol, self.h, self.max_step,
                           min(CALL_STEPS, self.max_steps - since), end, NEWTON_TOLERANCE,
                           lo)
            run.evaluate()
            carry[:] = run.results[0]
            info = run.results[2]
            states = run.results[1].reshape(OUTPUTS, m).T
            reached = int(info[1])
            for key, k in (("steps", 2), ("evaluations", 3), ("jacobians", 4),
                           ("factorisations", 5), ("rejected", 7)):
                stats[key] += int(info[k])
            evaluations += int(info[3])
            since = 0.0 if reached else since + info[2]
            out[:, done:done + reached] = states[:, :reached]
            # asked after every call, also one that reached no output (a cancelled replay
            # ends within a call)
            if stop is not None:
                bad = stop(out[:, done:done + reached])
                if bad is not None:
                    self.last_stats = stats
                    return out[:, :done + reached], evaluations
            done += reached
            status = int(info[0])
            if status == 1 and since < self.max_steps:
                continue                # this call's share of the budget: the next goes on
            if status != 0:
                self.last_stats = stats
                raise RuntimeError(f"{FAMILIES[self.family]}: {STATUS.get(status, status)} "
                                   f"at t = {info[6]:.6g} s")
        self.h = float(carry[1]) if carry[1] > 0.0 else self.h
        self.last_stats = stats
        return out, evaluations
