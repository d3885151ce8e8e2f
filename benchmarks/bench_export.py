"""Benchmark: controllers exported as C (``controllers.codegen``): size, memory, time per step.

For each law of ``slew-90`` (and the two hardware scenes' laws on their Kalman filters): the
export and compile times (system C compiler, ``controllers.codegen.C_FLAGS``), the code and
constant data of the object (``size``'s text column), the caller's struct
(``flexctl_ctrl_size()``), and the time per ``flexctl_ctrl_step`` called through ``ctypes`` on
the states of the Python law's own closed loop (the fastest of three passes per sample, so the
machine's other work stays out; the ``ctypes`` call itself costs about a microsecond), against
the Python law's step on the same states.

Target (issue 24): the compiled NMPC step with 2 design modes and 20 steps at most 0.3 ms.
Nothing here is asserted: the script prints what it measures.

Run: ``python benchmarks/bench_export.py`` (about a minute: the NMPC exports compile 4 to 8 s).
"""

from __future__ import annotations

import tempfile
import time

import numpy as np

import flexctl
from controllers import from_spec
from controllers.codegen import export_c
from controllers.feedback.lqg_sampled import SampledLQG

CASES = (
    ("slew-90", {"controller.kind": "pd"}),
    ("slew-90", {"controller.kind": "lqr"}),
    ("slew-90", {"controller.kind": "scheduled"}),
    ("slew-90", {"controller.kind": "trajopt+lqr"}),
    ("slew-90", {"controller.kind": "lqg"}),
    ("slew-90", {"controller.kind": "nmpc", "model.design_variant": "first_order"}),
    ("slew-90", {"controller.kind": "nmpc"}),
    ("flexible-link", {}),
    ("wheel-slew", {}),
)
LQG_SAMPLE_TIME = 0.01
PASSES = 3


def _python_law(controller, kind):
    return SampledLQG(controller, LQG_SAMPLE_TIME) if kind == "lqg" else controller


def _inputs(program, plant, result, period):
    """The law's inputs along the Python loop, at its samples (or 200 times)."""
    times = (np.arange(0.0, result.t[-1] - 1e-9, period) if period
             else np.linspace(0.0, result.t[-1], 200))
    states = np.array([np.interp(times, result.t, row) for row in result.states]).T
    if program.input_kind == "state":
        return times, states
    if program.measurement_matrix is not None:
        return times, states @ program.measurement_matrix.T
    return times, None                       # the sensors' readings: see _readings


def _readings(scene, plant, times, states):
    session = scene.sensors.noiseless().start(plant, times[1] - times[0])
    return np.array([session.read(x) for x in states])


def _time_steps(law, times, inputs) -> np.ndarray:
    best = np.full(times.size, np.inf)
    for _ in range(PASSES):
        law.init()
        for k, (t, v) in enumerate(zip(times, inputs)):
            started = time.perf_counter()
            law.step(t, v)
            best[k] = min(best[k], time.perf_counter() - started)
    return best


def _python_steps(python, plant, times, states, inputs, program) -> np.ndarray:
    """Time per step of the Python law on the same samples (one pass)."""
    out = np.zeros(times.size)
    if hasattr(python, "start"):
        session = python.start(plant, np.zeros(plant.n_states))
        feed = inputs if getattr(python, "measures", False) else states
        for k, (t, v) in enumerate(zip(times, feed)):
            started = time.perf_counter()
            session.step(t, v)
            out[k] = time.perf_counter() - started
        return out
    law = python.for_plant(plant) if hasattr(python, "for_plant") else python
    for k, (t, x) in enumerate(zip(times, states)):
        started = time.perf_counter()
        law.torque(t, x, np.zeros(0))
        out[k] = time.perf_counter() - started
    return out


def run_case(name, overrides) -> dict:
    scene = flexctl.load_scene(name, overrides)
    plant = scene.build_model()
    built = from_spec(scene, plant)
    kind = built.kind
    started = time.perf_counter()
    exported = export_c(built.controller, plant, tempfile.mkdtemp(),
                        sample_time=LQG_SAMPLE_TIME if kind == "lqg" else None)
    export_s = time.perf_counter() - started
    law = exported.compile()
    python = _python_law(built.controller, kind)
    sensors = {"sensors": scene.sensors} if getattr(python, "measures", False) else {}
    result = flexctl.simulate(plant, scene.simulation.t_final, controller=python, **sensors)
    program = exported.program
    times, inputs = _inputs(program, plant, result, program.sample_time)
    states = np.array([np.interp(times, result.t, row) for row in result.states]).T
    if inputs is None:
        inputs = _readings(scene, plant, times, states)
    steps = _time_steps(law, times, inputs)
    py = _python_steps(python, plant, times, states, inputs, program)
    return {"case": f"{name} {kind}" + (" (" + overrides.get("model.design_variant", "")
                                         + ")" if "model.design_variant" in overrides else ""),
            "export_s": export_s, "compile_s": law.compile_time_s, "code_bytes": law.code_bytes,
            "struct_bytes": law.struct_bytes, "median_us": 1e6 * np.median(steps),
            "p99_us": 1e6 * np.percentile(steps, 99), "max_us": 1e6 * steps.max(),
            "python_median_us": 1e6 * np.median(py)}


def main():
    print(f"{'case':<34} {'export':>7} {'compile':>8} {'code':>9} {'struct':>9} "
          f"{'median':>9} {'p99':>9} {'max':>9} {'python':>9}  ratio")
    print(f"{'':<34} {'s':>7} {'s':>8} {'bytes':>9} {'bytes':>9} {'us':>9} {'us':>9} "
          f"{'us':>9} {'us':>9}")
    for name, overrides in CASES:
        row = run_case(name, overrides)
        print(f"{row['case']:<34} {row['export_s']:7.2f} {row['compile_s']:8.2f} "
              f"{row['code_bytes']:9d} {row['struct_bytes']:9d} {row['median_us']:9.1f} "
              f"{row['p99_us']:9.1f} {row['max_us']:9.1f} {row['python_median_us']:9.1f}  "
              f"{row['python_median_us'] / row['median_us']:5.1f}x", flush=True)


if __name__ == "__main__":
    main()
