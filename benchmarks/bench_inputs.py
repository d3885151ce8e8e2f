"""Benchmark: sampled torques and traced Python torque functions against python-control.

Issue 9, item 2: a torque given as samples, or as a Python function CasADi can trace, runs on
the compiled CVODES path; the goal is ``flexctl.simulate`` at least 30 times faster than
python-control's ``control.input_output_response`` on ``model.nonlinear()`` at equal error.
Issue 45, item 1: a function CasADi cannot trace is sampled onto the compiled path; the goals
are 20 times python-control with the checks on and 40 times with them off (cases B and C).

Scene ``hub-beam-mass`` (20 s; the scene's push, one period of a 2 N m sine over 2 s), on
first_order models of 2 and 4 modes. Three inputs:

A. **Samples** ``(T, U)``: the push sampled every 0.01 s (2001 samples), the arrays a
   python-control user hands to ``input_output_response(sys, T, U)``. Both tools integrate the
   same piecewise-linear torque (python-control interpolates ``U`` linearly, and so does
   ``simulate(torque=(T, U))``). Also timed: the design not taken, restarting the integration
   at every sample instead of bounding the step by the sample interval.
B. **A Python function** ``torque(t) = where(t <= 2, 2 sin(pi t), 0)``. flexctl traces it;
   python-control needs samples, fine enough (every 2e-4 s, as in ``bench_speed.py``) that their
   interpolation error (~1e-7 of the peak) stays below the accuracy asked for. flexctl's
   SciPy path (``method="DOP853"``, the function called at every step: the path Python
   functions took before tracing) is timed too. Judged against issue 9's goal (30) with the
   checks on and without the accuracy check, and against issue 45's (40) with both checks
   off.

C. **A Python function with a branch**, ``2 sin(pi t) if t <= 2 else 0``, which CasADi cannot
   trace: flexctl samples it into a piecewise cubic (:mod:`flexctl.sim.function_samples`)
   and counts the sampling's error; python-control gets it sampled as in B. Timed at the
   default settings (the accuracy check and the validity estimate on), with both off, and on
   SciPy's DOP853 calling the function at every step (the path it took before sampling).

Every tool runs at the largest relative tolerance of ``equal_error.RTOL_GRID`` whose tip
deflection, on the 0.01 s output grid, is within 1e-6 of the peak of a reference: flexctl's
DOP853 at rtol 1e-13 on the same input (restarted at every sample for A). Absolute
tolerances: flexctl scales its own per state; python-control takes ``rtol * 1e-3``.
python-control runs with SciPy's RK45 (its default), DOP853 and LSODA; the fastest counts.

Times are medians, end to end: for flexctl the ``simulate`` call from the user's arrays or
function (sampled torque built, function traced, integrator built, run, accuracy check,
outputs); "reused" passes one ``SampledTorque`` object, whose compiled integrators flexctl keeps
between runs (equal arrays give the same object, so the pair hits the same caches); "no
accuracy check" skips the run at 10x the tolerance that gives ``integration_error``, which
python-control does not make. For python-control the ``input_output_response`` call.

Measured with ``--cases branching function --modes 2 4`` on two shared cores (ratios to
python-control's fastest method, with the checks / without): case C on 4 modes 17.5 / 40.9
(flexctl 53.6 / 22.9 ms; 7.2 / 19.8 before ``method="auto"`` took the compiled 8(5,3) pair,
its accuracy check the looser sampling and its runs kept their buffers), on 2 modes 7.5 /
20.2; case B 29.3 / 34.2 on 4 modes, 24.9 / 30.2 on 2. On 2 modes python-control's runs are
short (0.33 s) and flexctl's fixed costs (the sampling's 1 100 calls of the function, the
validity estimate's two runs) weigh more. Since the validity estimate replays the run's
sampling (``function_samples.recorded_sampling``), two runs of ``--cases branching --modes 4
2``: case C on 4 modes 17.4 / 34.5 (55.8 / 28.2 ms against LSODA's 0.972 s) and 16.7 / 32.4
(37.3 / 19.3 ms against LSODA's 0.625 s), on 2 modes 12.9 / 31.4 (36.8 / 15.1 ms against
0.473 s): python-control's fastest time moved as much as flexctl's from one process to the
next. With the checks on, the validity estimate's two runs on 2 modes (first_order on the
8(5,3) pair, exact on the compiled BDF: some 10 and 6 ms, 3 to 4 ms of each fixed) cost
about as much as the run. Case C on 4 modes, one run of ``--cases branching --modes 4``
before and two of ``--modes 4 2`` after the estimate's exact run was started beside the
variant's (``runs.start_states_run``) and the sampling's and a run's fixed costs were cut:
before 20.0 / 39.4 (15.6 / 7.9 ms against LSODA's 0.311 s); after 23.2 / 46.5 (13.7 / 6.8 ms
against 0.317 s) and 21.9 / 45.1 (14.3 / 7.0 ms against 0.314 s). On 2 modes 18.0 / 42.7
(9.7 / 4.1 ms against 0.175 s) and 16.8 / 40.7 (10.3 / 4.3 ms against 0.173 s): there
python-control's run is short and the estimate's two runs were each about as long as the run
itself. Since a run that is itself the estimate's run of its variant stands for it (2 modes,
rtol tightened to 1e-6 on the 8(5,3) pair: only the exact model is run), one more run: 4
modes 21.4 / 46.8 (14.7 / 6.7 ms against 0.314 s), 2 modes 19.9 / 41.3 (8.7 / 4.2 ms against
0.173 s). With the validity estimate's runs started while the run integrates (queued
behind the accuracy check for the spare core) and the step loops no longer copying the
sampled torque's table for every step attempt (``step_chain``), one run of ``--cases
branching --modes 4 2 --methods LSODA``: 4 modes 27.1 / 62.2 (11.6 / 5.0 ms against LSODA's
0.313 s), 2 modes 26.6 / 56.5 (6.4 / 3.0 ms against 0.172 s). In one process each, the
session's base (1f7b619) and its end: 4 modes 20.8 / 43.6 before, 31.9 / 65.6 after (15.0 /
7.1 ms and 9.9 / 4.8 ms against LSODA's 0.311 and 0.317 s); 2 modes 17.8 / 39.8 before,
23.8 / 55.3 after (9.7 / 4.3 and 7.2 / 3.1 ms against 0.172 s). Case B, ``--cases function
--modes 4 2`` (python-control's three methods, LSODA the fastest), checks on / no accuracy
check / both off: 4 modes 34.9 / 41.6 / 84.8 (9.1 / 7.7 / 3.8 ms against 0.319 s), 2 modes
25.6 / 33.2 / 72.8 (6.8 / 5.3 / 2.4 ms against 0.175 s).

Run: ``python benchmarks/bench_inputs.py`` (some 10 to 30 minutes, python-control dominates;
``--modes 2`` for one model, ``--methods RK45`` for python-control's default only).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import casadi as ca                                   # noqa: E402
import control                                        # noqa: E402
from equal_error import TARGET, measure, python_control_tip  # noqa: E402

from flexctl import build_model, load_scene, simulate  # noqa: E402
from flexctl.sim.inputs import SampledTorque          # noqa: E402

SCENE = "hub-beam-mass"
REFERENCE_RTOL = 1e-13
OUTPUT_STEP = 0.01               # s, output grid and the samples of case A
FINE_INPUT_STEP = 2e-4           # s, samples of the function handed to python-control (B)
REPEATS = 5                      # flexctl runs (tens to hundreds of ms)
REPEATS_SLOW = 3                 # python-control runs (seconds each)
PYTHON_CONTROL_METHODS = ("RK45", "DOP853", "LSODA")
GOAL = 30.0
#: Issue 45's goals for a Python function (B, C): with the checks on, and with both off.
GOALS_CALLABLE = (20.0, 40.0)


def time_grid(t_final, step):
    grid = np.arange(0.0, t_final + 0.5 * step, step)
    grid[-1] = t_final
    return grid


def push(t):
    """The scene's push as a Python function (traceable: numpy only, no branch on t)."""
    return np.where(t <= 2.0, 2.0 * np.sin(np.pi * t), 0.0)


# ---------------------------------------------------------------------------- the tools
def branching_push(t):
    """The scene's push as a user writes it first: a branch on ``t``, which CasADi cannot
    trace (flexctl samples it, :mod:`flexctl.sim.function_samples`)."""
    return 2.0 * np.sin(np.pi * t) if t <= 2.0 else 0.0


def flexctl_tip(model, t_final, torque, method="auto", check_accuracy=True,
                check_validity=True):
    """``rtol -> tip`` of ``simulate``; ``torque`` is a zero-argument factory, so each run
    starts from the user's arrays or function."""
    def run(rtol):
        result = simulate(model, t_final, torque=torque(), rtol=rtol, output_step=OUTPUT_STEP,
                          method=method, check_accuracy=check_accuracy,
                          check_validity=check_validity)
        # "auto" takes a compiled method (CVODES, a Dormand-Prince pair, BDF or Adams)
        compiled = ("cvodes", "dop853", "RK45", "BDF", "Adams", "rk4")
        assert result.ok and result.method in ((method,) if method != "auto" else compiled), \
            f"{result.method}: {result.message}"
        return result.tip_deflection
    return run


# ---------------------------------------------------------------------------- cases
def python_control_tools(model, t_final, t_in, u, methods):
    grid = time_grid(t_final, OUTPUT_STEP)
    return {f"python-control {m}": (python_control_tip(model, t_in, u, grid, m), REPEATS_SLOW)
            for m in methods}


def report(times, flexctl_labels, baselines=(), goals=None):
    """Print and return fastest python-control / each flexctl tool; the goal (``goals``, one
    per compiled tool; default :data:`GOAL`) is judged for the compiled tools, not for
    ``baselines`` (the paths they replace)."""
    pc = {k: v for k, v in times.items() if k.startswith("python-control")}
    fastest = min(pc, key=pc.get)
    goal_of = dict(zip(flexctl_labels, goals or [GOAL] * len(flexctl_labels)))
    ratios = {}
    for label in (*flexctl_labels, *baselines):
        ratios[label] = pc[fastest] / times[label]
        default = (f"; against its default RK45: {pc['python-control RK45'] / times[label]:.0f}"
                   if "python-control RK45" in pc else "")
        goal = goal_of.get(label)
        verdict = ("baseline" if label in baselines else
                   f"goal >= {goal:g}: {'met' if ratios[label] >= goal else 'missed'}")
        print(f"   fastest python-control ({fastest.split()[-1]}) / {label} = "
              f"{ratios[label]:.1f} ({verdict}){default}")
    return ratios


class RestartingTorque(SampledTorque):
    """The alternative not taken: restart the integration at every sample, no step bound."""

    max_step = None

    @property
    def breakpoints(self):
        return tuple(self.times.tolist())


def case_samples(model, t_final, methods):
    grid = time_grid(t_final, OUTPUT_STEP)
    t_in, u = grid, np.asarray(push(grid), dtype=float)
    sampled = SampledTorque(t_in, u)
    start = time.perf_counter()
    reference = flexctl_tip(model, t_final, lambda: sampled, "DOP853")(REFERENCE_RTOL)
    print(f"   A. samples (T, U), {t_in.size} of them, linear: reference DOP853 at "
          f"{REFERENCE_RTOL:g} ({time.perf_counter() - start:.1f} s)")
    restarting = RestartingTorque(t_in, u)
    tools = {"flexctl.simulate(torque=(T, U))": (
                 flexctl_tip(model, t_final, lambda: (t_in, u)), REPEATS),
             "flexctl, one SampledTorque reused": (
                 flexctl_tip(model, t_final, lambda: sampled), REPEATS),
             "flexctl, (T, U), no accuracy check": (
                 flexctl_tip(model, t_final, lambda: (t_in, u), check_accuracy=False), REPEATS),
             "flexctl, restart at every sample": (
                 flexctl_tip(model, t_final, lambda: restarting), REPEATS_SLOW)}
    tools.update(python_control_tools(model, t_final, t_in, u, methods))
    times = measure(tools, reference)
    print(f"   restarting at every sample / bounding the step: "
          f"{times[list(tools)[3]] / times[list(tools)[1]]:.1f}x the time")
    return report(times, list(tools)[:3], baselines=list(tools)[3:4])


def _function_case(model, t_final, methods, function, title, tools, what, goals=None):
    """Time ``tools`` (the flexctl runs: the compiled ones, one per goal of ``goals``, or two,
    then the SciPy path) and python-control on ``function`` sampled finely, against a DOP853
    reference."""
    start = time.perf_counter()
    reference = flexctl_tip(model, t_final, lambda: function, "DOP853")(REFERENCE_RTOL)
    print(f"   {title}: reference DOP853 at {REFERENCE_RTOL:g} "
          f"({time.perf_counter() - start:.1f} s)")
    t_in = time_grid(t_final, FINE_INPUT_STEP)
    tools.update(python_control_tools(model, t_final, t_in,
                                      np.array([float(function(t)) for t in t_in]), methods))
    times = measure(tools, reference)
    names, compiled = list(tools), 2 if goals is None else len(goals)
    print(f"   {what} / SciPy path for the same function: "
          f"{times[names[compiled]] / times[names[0]]:.1f}x faster")
    return report(times, names[:compiled], baselines=names[compiled:compiled + 1],
                  goals=goals)


def case_function(model, t_final, methods):
    tools = {"flexctl.simulate(torque=push), traced": (
                 flexctl_tip(model, t_final, lambda: push), REPEATS),
             "flexctl, traced, no accuracy check": (
                 flexctl_tip(model, t_final, lambda: push, check_accuracy=False), REPEATS),
             "flexctl, traced, no checks": (
                 flexctl_tip(model, t_final, lambda: push, check_accuracy=False,
                             check_validity=False), REPEATS),
             "flexctl, push on SciPy DOP853 (untraced)": (
                 flexctl_tip(model, t_final, lambda: push, "DOP853"), REPEATS_SLOW)}
    return _function_case(model, t_final, methods, push, "B. Python function", tools,
                          "tracing", goals=(GOAL, GOAL, GOALS_CALLABLE[1]))


def case_branching(model, t_final, methods):
    def fresh():
        # a new function object each run: its sampling is made again, not found remembered
        return lambda t: branching_push(t)
    tools = {"flexctl.simulate(torque=branch), sampled": (
                 flexctl_tip(model, t_final, fresh), REPEATS),
             "flexctl, sampled, no checks": (
                 flexctl_tip(model, t_final, fresh, check_accuracy=False,
                             check_validity=False), REPEATS),
             "flexctl, branch on SciPy DOP853 (default checks)": (
                 flexctl_tip(model, t_final, lambda: branching_push, "DOP853"), REPEATS_SLOW)}
    return _function_case(model, t_final, methods, branching_push,
                          "C. Python function with a branch (untraceable)", tools, "sampling",
                          goals=GOALS_CALLABLE)


CASES = {"samples": case_samples, "function": case_function, "branching": case_branching}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, nargs="+", default=[2, 4])
    parser.add_argument("--methods", nargs="+", default=list(PYTHON_CONTROL_METHODS),
                        choices=PYTHON_CONTROL_METHODS)
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    args = parser.parse_args(argv)
    scene = load_scene(SCENE)
    t_final = scene.simulation.t_final
    print(f"flexctl sampled and traced inputs against python-control (casadi {ca.__version__}, "
          f"python-control {control.__version__}); {SCENE}, {t_final:g} s, target relative "
          f"tip error {TARGET:g}; times are medians, end to end")
    ratios = {}
    for n_modes in args.modes:
        model = build_model(scene.system, n_modes=n_modes)
        print(f"\n== {n_modes} modes ({model.variant})")
        for case in args.cases:
            for label, ratio in CASES[case](model, t_final, args.methods).items():
                ratios[(n_modes, label)] = ratio
    print("\nsummary: fastest python-control / flexctl")
    for (n_modes, label), ratio in ratios.items():
        print(f"   {n_modes} modes  {label:<40} {ratio:>7.1f}")
    return ratios


if __name__ == "__main__":
    main()
