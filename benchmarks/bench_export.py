"""Benchmark: controllers exported as C (``controllers.codegen``): size, memory, time per step.

For each law of ``slew-90`` (and the two hardware scenes' laws on their Kalman filters): the
export and compile times (system C compiler, ``controllers.codegen.C_FLAGS``), the code and
constant data of the object (``size``'s text column), the caller's struct
(``flexctl_ctrl_size()``), and the time per ``flexctl_ctrl_step`` called through ``ctypes`` on
the states of the Python law's own closed loop (the fastest of three passes per sample, so the
machine's other work stays out; the ``ctypes`` call itself costs about a microsecond), against
the Python law's step on the same states.

Target (issue 24): the compiled NMPC step with 2 design modes and 20 steps at most 0.3 ms;
(issue 48) the exact 2-mode design's at most 0.2 ms on the host and the first_order one's at
most 400,000 instructions on the Cortex-M7. Measured (``host`` and ``targets``): the exact
design's step 72.6 us on the host (103.4 before its condensing was written in scalars), the
first_order design's 23.3 us (36.9); on the Cortex-M7 381,800 instructions a step in double
and 393,826 in float (721,934 and 751,508 before), the exact design's 939,310 in double.

``targets`` (issue 48): each law exported in double and in float, built freestanding for the
Cortex-M4F and the Cortex-M7 (``controllers.codegen.targets``: code, constants, the caller's
struct, the deepest stack of a step, whether double runs in software), and run under QEMU on
the same recorded inputs (``controllers.codegen.pil``, at most :data:`PIL_STEPS` samples):
instructions per step from ``-icount`` (QEMU's deterministic count, not cycles) and the time
they would take at the stated clock, one instruction a cycle, with the largest difference of
the emulated commands from the host build's. ``precision``: the slew flown with the law
compiled in double and in float on the scene's plant
(``flexctl.app.export_precision.compare_precisions``).
Nothing here is asserted: the script prints what it measures.

Run: ``python benchmarks/bench_export.py [host] [targets] [precision]`` (all three by default;
host about a minute, targets several minutes: the NMPC compiles 8 to 10 s for each target).
"""

from __future__ import annotations

import sys
import tempfile
import time
import warnings

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
#: Samples of the recorded inputs run under QEMU per law.
PIL_STEPS = 100


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


def _recorded(name, overrides):
    """The scene's law, its export, and the law's inputs along the Python loop."""
    scene = flexctl.load_scene(name, overrides)
    plant = scene.build_model()
    built = from_spec(scene, plant)
    kind = built.kind
    started = time.perf_counter()
    exported = export_c(built.controller, plant, tempfile.mkdtemp(),
                        sample_time=LQG_SAMPLE_TIME if kind == "lqg" else None)
    export_s = time.perf_counter() - started
    python = _python_law(built.controller, kind)
    sensors = {"sensors": scene.sensors} if getattr(python, "measures", False) else {}
    result = flexctl.simulate(plant, scene.simulation.t_final, controller=python, **sensors)
    program = exported.program
    times, inputs = _inputs(program, plant, result, program.sample_time)
    states = np.array([np.interp(times, result.t, row) for row in result.states]).T
    if inputs is None:
        inputs = _readings(scene, plant, times, states)
    label = f"{name} {kind}" + (" (" + overrides.get("model.design_variant", "") + ")"
                                 if "model.design_variant" in overrides else "")
    return {"scene": scene, "plant": plant, "built": built, "python": python,
            "exported": exported, "export_s": export_s, "times": times, "inputs": inputs,
            "states": states, "label": label}


def run_case(name, overrides) -> dict:
    case = _recorded(name, overrides)
    exported, times, inputs = case["exported"], case["times"], case["inputs"]
    law = exported.compile()
    steps = _time_steps(law, times, inputs)
    py = _python_steps(case["python"], case["plant"], times, case["states"], inputs,
                       exported.program)
    return {"case": case["label"], "export_s": case["export_s"],
            "compile_s": law.compile_time_s, "code_bytes": law.code_bytes,
            "struct_bytes": law.struct_bytes, "median_us": 1e6 * np.median(steps),
            "p99_us": 1e6 * np.percentile(steps, 99), "max_us": 1e6 * steps.max(),
            "python_median_us": 1e6 * np.median(py)}


def host():
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


def _target_rows(case):
    """Sizes and instruction counts of ``case``'s law per precision and target."""
    from controllers.codegen.pil import run_on_target
    from controllers.codegen.targets import build_for_target

    built, plant = case["built"], case["plant"]
    times, inputs = case["times"][:PIL_STEPS], case["inputs"][:PIL_STEPS]
    for precision in ("double", "float"):
        exported = export_c(built.controller, plant, tempfile.mkdtemp(), precision=precision,
                            sample_time=LQG_SAMPLE_TIME if built.kind == "lqg" else None)
        host_law = exported.compile()
        on_host = np.array([host_law.step(t, v)[0] for t, v in zip(times, inputs)])
        for target in ("cortex-m4", "cortex-m7"):
            build = build_for_target(exported, target)
            run = run_on_target(exported, times, inputs, target)
            summary = run.summary()
            yield {"case": case["label"], "precision": precision, "target": target,
                   "code": build.code_bytes, "constants": build.constant_bytes,
                   "struct": build.struct_bytes, "stack": build.stack_bytes,
                   "soft_double": build.software_double,
                   "instructions": summary["instructions_median"],
                   "instructions_max": summary["instructions_max"],
                   "ms": 1e3 * summary["time_estimate_median_s"], "clock": run.clock_hz,
                   "recovered": int(np.sum(run.codes == 1)),
                   "vs_host": float(np.max(np.abs(run.commands - on_host)))}


def targets():
    print(f"\n{'case':<34} {'prec':<6} {'target':<9} {'code':>8} {'const':>7} {'struct':>7} "
          f"{'stack':>6} {'instr/step':>11} {'max':>10} {'est. ms':>8} {'at MHz':>6} "
          f"{'|C - host|':>10}")
    for name, overrides in CASES:
        case = _recorded(name, overrides)
        for row in _target_rows(case):
            print(f"{row['case']:<34} {row['precision']:<6} {row['target']:<9} "
                  f"{row['code']:8d} {row['constants']:7d} {row['struct']:7d} "
                  f"{row['stack']:6d} {row['instructions']:11.0f} {row['instructions_max']:10d} "
                  f"{row['ms']:8.3f} {row['clock'] / 1e6:6.0f} {row['vs_host']:10.2e}"
                  + ("  software double" if row["soft_double"] else "")
                  + (f"  {row['recovered']} recovered" if row["recovered"] else ""),
                  flush=True)
    print("instructions: QEMU's -icount count on the MPS2 board (AN386 for the M4, AN500 for "
          "the M7), not cycles; est. ms assumes one instruction a cycle at the clock shown")


def precision():
    from flexctl.app.export_precision import compare_precisions

    print(f"\n{'case':<34} {'res. vib. double':>16} {'float - double':>15} "
          f"{'pointing double':>16} {'float - double':>15} {'max |du|':>10}")
    for name, overrides in CASES:
        scene = flexctl.load_scene(name, overrides)
        kind = scene.controller.kind
        built = from_spec(scene, scene.build_model())
        if kind != "lqg" and not getattr(built.controller, "sample_time", None):
            continue        # continuous laws: the loop calls ctypes at every integrator step
        out = compare_precisions(scene, sample_time=LQG_SAMPLE_TIME if kind == "lqg" else None,
                                 built=built)
        d, diff = out["double"], out["difference"]
        label = f"{name} {kind}" + (f" ({overrides['model.design_variant']})"
                                    if "model.design_variant" in overrides else "")
        print(f"{label:<34} {d['residual_vibration']:16.6e} {diff['residual_vibration']:+15.3e} "
              f"{d['pointing_error']:16.6e} {diff['pointing_error']:+15.3e} "
              f"{diff['max_command']:10.3e}", flush=True)
    print("residual vibration in m, pointing error (largest |theta - angle| after the "
          "manoeuvre) in rad, max |du| in the law's output unit")


def main(argv=None):
    sections = {"host": host, "targets": targets, "precision": precision}
    chosen = (argv if argv is not None else sys.argv[1:]) or list(sections)
    warnings.simplefilter("ignore")
    for name in chosen:
        sections[name]()


if __name__ == "__main__":
    main()
