"""Benchmark: the persistent compiled-function cache (issue 21, deliverables 1, 3 and 5).

A. Compile time per model and time per right-hand-side evaluation: ``model.casadi()`` of
   ``hub-beam-mass`` (first_order and exact, 2, 4 and 6 modes, and the exact model's
   vectorized form ``model.vectorized_rhs()``, which CVODES evaluates) compiled through
   :func:`flexctl.sim.compile_cache.compiled` with the cache cold (a fresh directory: generate,
   compile, load) and warm (generate, hash, load the library), and one evaluation on CasADi's
   virtual machine against the compiled code (the mean over a ``map`` of 1000 evaluations, best
   of 20), with the ratio exact / first_order.
B. A 10-point sweep of PD slews over the angle (0.3 to 1.6 rad, durations 4.0 to 4.9 s, 8 s
   each, slew-90's system, 2 modes) with ``method="rk4"`` and with the default method: the code
   before the cache (``--before DIR``, a checkout of it; skipped if not given) against this one
   with the cache cold and warm, each in a fresh process (model built before timing). Also the
   issue's example: a PD slew of 30 then of 45 degrees.
C. Simulation of the exact model against first_order on the same scene and modes (the goals
   table's first row), before and after, each in a fresh process.
D. NMPC real-time iteration on slew-90's exact 2-mode design model: build time and solve time
   per step (median, 99th percentile), before and after, cache cold and warm.
E. Trajectory optimisation (``--trajopt``) on the exact design models of ``slew-90`` and
   ``two-array-slew`` against first_order: compiled (cache cold and warm) and on the virtual
   machine (``FLEXCTL_COMPILE=0``).
F. Compiler flags (``--flags``): compile time and evaluation time of the exact design models'
   dynamics, Jacobian and Lagrangian Hessian at ``-Og`` and ``-O2``.
G. Many modes and sample loops (``--loops``), before (``--before DIR``) and this code, each
   in a fresh process with the cache cold and then warm: ``simulate`` on ``hub-beam-mass``
   with 40 and 200 modes under the 2 N m sine torque for 0.05 s (the issue's example), and
   ``run_slew`` of ``wheel-slew`` (a sampled LQR with observer and noisy sensors on the
   free-hub structure with a reaction wheel, 1800 samples, and its reference run).

Run: ``python benchmarks/bench_compile.py [--before /path/to/old/checkout]`` (the code the
runs execute imports the laws from the top-level ``controllers``, where every release has
them). Nothing is
asserted; the script prints what it measures (the machine's two cores are shared).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MAP = 1000
REPEATS = 20

#: One process of case B: prints JSON with each point's wall time and the compile counters.
SWEEP = r"""
import json, sys, time, warnings
import numpy as np
warnings.simplefilter("ignore")
import flexctl
from controllers import design_pd
from controllers import SlewProfile
method = sys.argv[1]
model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2)
angles = [float(a) for a in sys.argv[2].split(",")]
walls = []
for k, angle in enumerate(angles):
    pd = design_pd(model, bandwidth=2.0, damping_ratio=0.9, torque_limit=20.0,
                   reference=SlewProfile(slew_angle=angle, duration=4.0 + 0.1 * k))
    start = time.perf_counter()
    result = flexctl.simulate(model, 8.0, controller=pd, method=method)
    walls.append(time.perf_counter() - start)
    assert result.status == "ok"
try:
    from flexctl.sim.compile_cache import STATS
except ImportError:
    STATS = {}
print(json.dumps({"walls": walls, "stats": STATS}))
"""


def case_a() -> None:
    import casadi as ca

    import flexctl
    from flexctl.sim import compile_cache

    system = flexctl.load_scene("hub-beam-mass").system
    print("## A. Compile time per model and time per right-hand-side evaluation\n")
    print(f"compiler: {compile_cache.cache_info().compiler}; flags "
          f"{' '.join(compile_cache.FLAGS)}; CasADi {ca.__version__}\n")
    print("| modes | variant | C (kB) | cold compile (s) | warm load (s) | VM eval (us) | "
          "compiled eval (us) | VM / compiled |")
    print("|---|---|---|---|---|---|---|---|")
    evals = {}
    for n_modes in (2, 4, 6):
        for variant in ("first_order", "exact", "exact vectorized"):
            model = flexctl.build_model(system, n_modes, variant.split()[0])
            f = model.casadi() if variant != "exact vectorized" \
                else model.vectorized_rhs()
            many = f.map(MAP, "serial")
            size = len(compile_cache._source(f)) // 1024
            start = time.perf_counter()
            fast = compile_cache.compiled(f)
            cold = time.perf_counter() - start
            compile_cache._LOADED.clear()
            start = time.perf_counter()
            compile_cache.compiled(f)
            warm = time.perf_counter() - start
            fast_many = compile_cache.compiled(many)
            vm = per_evaluation(many, f)
            machine = per_evaluation(fast_many, f)
            evals[n_modes, variant] = (vm, machine)
            print(f"| {n_modes} | {variant} | {size} | {cold:.2f} | {warm:.3f} | "
                  f"{vm * 1e6:.2f} | {machine * 1e6:.3f} | {vm / machine:.0f} |")
        for variant in ("exact", "exact vectorized"):
            vm_ratio = evals[n_modes, variant][0] / evals[n_modes, "first_order"][0]
            c_ratio = evals[n_modes, variant][1] / evals[n_modes, "first_order"][1]
            print(f"| {n_modes} | {variant} / first_order | | | | {vm_ratio:.1f} | "
                  f"{c_ratio:.1f} | |")

#: One process of case C: best-of-3 wall time of each variant's run, as JSON.
EXACT = r"""
import json, sys, time, warnings
warnings.simplefilter("ignore")
import numpy as np
import flexctl
from flexctl import SineTorque
from flexctl.sim.compile_cache import compiled
system = flexctl.load_scene("hub-beam-mass").system
out = {}
for n_modes in (2, 4, 6):
    for variant in ("first_order", "exact"):
        model = flexctl.build_model(system, n_modes, variant)
        if model.geometry is not None:
            model.geometry
        walls = []
        for _ in range(4):
            start = time.perf_counter()
            # without the validity estimate, which only the small-deflection variants run
            result = flexctl.simulate(model, 6.0, SineTorque(peak_torque=2.0, duration=2.0),
                                      rtol=1e-8, check_validity=False)
            walls.append(time.perf_counter() - start)
        out[f"{variant}{n_modes}"] = min(walls[1:])
        out[f"{variant}{n_modes}_first"] = walls[0]
        out[f"{variant}{n_modes}_how"] = f"{result.method}, {result.n_evaluations}"
        # the run's own evaluations (its accuracy check runs beside it, on the other core)
        # times one compiled evaluation of the model alone (the mean over a map of 1000, best
        # of 20): the least an integrator taking as many could spend
        alone = flexctl.simulate(model, 6.0, SineTorque(peak_torque=2.0, duration=2.0),
                                 rtol=1e-8, check_validity=False, check_accuracy=False)
        many = compiled(model.casadi().map(1000, "serial"))
        x, u = np.full((model.n_states, 1000), 1e-3), np.full((1, 1000), 0.1)
        many(x, u)
        each = []
        for _ in range(20):
            start = time.perf_counter()
            many(x, u)
            each.append((time.perf_counter() - start) / 1000)
        out[f"{variant}{n_modes}_floor"] = alone.n_evaluations * min(each)
print(json.dumps(out))
"""


def case_c(before: Path | None) -> None:
    print("\n## C. Simulation exact / first_order, hub-beam-mass, sine torque 2 N m, 6 s, "
          "rtol 1e-8 (method auto: the compiled pair, CVODES, the compiled BDF or Adams; with the "
          "accuracy check, no validity estimate; best of the 2nd to 4th run, and the first "
          "run, which builds "
          "and, cold, compiles; the last run's method and right-hand-side evaluations, the "
          "accuracy check's included; the floor: the exact run's evaluations without its "
          "check, which runs on the other core, times one compiled evaluation of its "
          "right-hand side, over first_order's whole run)\n")
    print("| code | cache | modes | first_order (s) | exact (s) | ratio | exact first run (s) | "
          "first_order: method, evaluations | exact: method, evaluations | floor (s) | "
          "floor / first_order |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for label, state, walls in fresh_processes(before, EXACT):
        for n_modes in (2, 4, 6):
            fo, ex = walls[f"first_order{n_modes}"], walls[f"exact{n_modes}"]
            how = [walls.get(f"{variant}{n_modes}_how", "-")
                   for variant in ("first_order", "exact")]
            floor = walls.get(f"exact{n_modes}_floor", float("nan"))
            print(f"| {label} | {state} | {n_modes} | {fo:.3f} | {ex:.3f} | "
                  f"{ex / fo:.2f} | {walls[f'exact{n_modes}_first']:.2f} | {how[0]} | "
                  f"{how[1]} | {floor:.4f} | {floor / fo:.2f} |")


def fresh_processes(before: Path | None, script: str, before_states=("cold", "warm")):
    """``(code, cache state, JSON)`` of ``script`` run in a fresh process per cache state
    (one empty cache directory per code), on the code ``before`` if given and on this one."""
    for label, tree in ([("before", before)] if before else []) + [("this", ROOT)]:
        with tempfile.TemporaryDirectory() as cache:
            for state in (("cold", "warm") if label == "this" else before_states):
                env = {**os.environ, "PYTHONPATH": str(tree), "FLEXCTL_CACHE_DIR": cache}
                out = subprocess.run([sys.executable, "-c", script], env=env, cwd=tree,
                                     capture_output=True, text=True, timeout=1800)
                yield label, state, json.loads(out.stdout.strip().splitlines()[-1])


#: One process of case D: NMPC build time and per-step solve times, as JSON.
NMPC = r"""
import json, time, warnings
import numpy as np
warnings.simplefilter("ignore")
import flexctl
from controllers import NMPC
system = flexctl.load_scene("slew-90").system
plant = flexctl.build_model(system, 4, "first_order")
design = flexctl.build_model(system, 2, "exact")
design.geometry
mpc = NMPC(model=design, target=np.pi / 2, torque_limit=6.0, sample_time=0.02, horizon=20)
start = time.perf_counter()
mpc.prepare()
build = time.perf_counter() - start
report = flexctl.simulate(plant, 4.0, controller=mpc, check_accuracy=False).controller_report
print(json.dumps({"build": build, "median": report["solve_time_median_s"],
                  "p99": report["solve_time_p99_s"]}))
"""


def case_d(before: Path | None) -> None:
    print("\n## D. NMPC real-time iteration, slew-90, exact 2-mode design model, horizon 20, "
          "0.02 s samples, 4-mode first_order plant, 4 s (in-loop wall time per step)\n")
    print("| code | cache | build (s) | median (ms) | p99 (ms) |")
    print("|---|---|---|---|---|")
    for label, state, found in fresh_processes(before, NMPC, before_states=("-",)):
        print(f"| {label} | {state} | {found['build']:.2f} | "
              f"{found['median'] * 1e3:.2f} | {found['p99'] * 1e3:.2f} |")


#: One process of case E: solve_slew on a scene's design model, first run and best of 3 later
#: runs, with IPOPT's iterations, as JSON.
TRAJOPT = r"""
import json, sys, time, warnings
warnings.simplefilter("ignore")
import flexctl
from controllers import SlewProblem, solve_slew
scene = flexctl.load_scene(sys.argv[1])
slew = scene.maneuver
model = flexctl.build_model(scene.system, scene.model.design_modes, sys.argv[2])
problem = SlewProblem(angle=slew.angle, duration=slew.duration, torque_bound=slew.torque_bound)
walls, iterations = [], []
for _ in range(4):
    start = time.perf_counter()
    solution = solve_slew(model, problem)
    walls.append(time.perf_counter() - start)
    iterations.append(solution.iterations)
print(json.dumps({"first": walls[0], "best": min(walls[1:]), "iterations": iterations[-1],
                  "cost": solution.cost}))
"""


def case_e() -> None:
    print("\n## E. Trajectory optimisation, exact / first_order design model (40 holds, each "
          "variant's default transcription; first run, and best of the next 3), each in a "
          "fresh process\n")
    print("| scene | design | compiled | cache | first run (s) | best (s) | iterations | cost |")
    print("|---|---|---|---|---|---|---|---|")
    for name in ("slew-90", "two-array-slew"):
        rows = {}
        for variant, setting in (("first_order", "1"), ("exact", "0"), ("exact", "1")):
            with tempfile.TemporaryDirectory() as cache:
                states = ("cold", "warm") if (variant, setting) == ("exact", "1") else ("-",)
                for state in states:
                    env = {**os.environ, "PYTHONPATH": str(ROOT), "FLEXCTL_CACHE_DIR": cache,
                           "FLEXCTL_COMPILE": setting}
                    out = subprocess.run([sys.executable, "-c", TRAJOPT, name, variant],
                                         env=env, capture_output=True, text=True,
                                         timeout=1800, cwd=ROOT)
                    found = json.loads(out.stdout.strip().splitlines()[-1])
                    rows[variant, setting, state] = found
                    print(f"| {name} | {variant} | {'yes' if setting == '1' else 'no'} | "
                          f"{state} | {found['first']:.2f} | {found['best']:.3f} | "
                          f"{found['iterations']} | {found['cost']:.6g} |")
        base = rows["first_order", "1", "-"]["best"]
        print(f"\n{name}: exact / first_order, best runs: compiled "
              f"{rows['exact', '1', 'warm']['best'] / base:.1f}x (cold cache, first run "
              f"{rows['exact', '1', 'cold']['first'] / base:.0f}x), virtual machine "
              f"{rows['exact', '0', '-']['best'] / base:.1f}x\n")


def case_f() -> None:
    """Compile time and evaluation time per point of the exact design models' dynamics,
    Jacobian and Lagrangian Hessian, at -Og and -O2 (lifted constants, a map of 300 points)."""
    import casadi as ca

    import flexctl
    from flexctl.sim.compile_cache import _source, compiler, lift_constants

    print("\n## F. Compiler flags: the exact design models' dynamics and derivatives\n")
    print("| scene | function | instructions | C (kB) | flags | compile (s) | compiled (us) | "
          "virtual machine (us) |")
    print("|---|---|---|---|---|---|---|---|")
    points = 300
    for name in ("slew-90", "two-array-slew"):
        scene = flexctl.load_scene(name)
        model = flexctl.build_model(scene.system, scene.model.design_modes, "exact")
        f = model.casadi()
        x, u, lam = (ca.SX.sym("x", model.n_states), ca.SX.sym("u"),
                     ca.SX.sym("lam", model.n_states))
        xdot, z = f(x, u), ca.vertcat(x, u)
        functions = (f, ca.Function("jacobian", [x, u], [ca.jacobian(xdot, z)]),
                     ca.Function("hessian", [x, u, lam],
                                 [ca.hessian(ca.dot(lam, xdot), z)[0]]))
        for function in functions:
            lifted, constants = lift_constants(function)
            source = _source(lifted)
            args = [np.full((function.size1_in(k), points), 0.01) for k in range(function.n_in())]
            on_vm = best_time(lambda: function.map(points)(*args)) / points
            with tempfile.TemporaryDirectory() as folder:
                c_file = Path(folder) / "f.c"
                c_file.write_text(source)
                for flags in ("-Og", "-O2"):
                    library = Path(folder) / f"f{flags}.so"
                    start = time.perf_counter()
                    subprocess.run([compiler()[0], flags, "-fPIC", "-shared", str(c_file),
                                    "-o", str(library), "-lm"], check=True)
                    took = time.perf_counter() - start
                    native = ca.external(lifted.name(), str(library)).map(
                        "many", "serial", points, [function.n_in()], [])
                    run = best_time(lambda: native(*args, constants)) / points
                    print(f"| {name} | {function.name()} | {function.n_instructions()} | "
                          f"{len(source) // 1024} | {flags} | {took:.2f} | {run * 1e6:.2f} | "
                          f"{on_vm * 1e6:.2f} |")


def best_time(call, repeats: int = 5) -> float:
    call()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)


def per_evaluation(many, f) -> float:
    """Seconds per evaluation of ``f(x, u)`` at a small state, from ``many``, its map of MAP
    (on the virtual machine or compiled), best of REPEATS."""
    x = np.full((f.size1_in(0), MAP), 1e-3)
    u = np.full((1, MAP), 0.1)
    many(x, u)
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        many(x, u)
        times.append(time.perf_counter() - start)
    return min(times) / MAP


def sweep(tree: Path, method: str, angles, cache: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "FLEXCTL_CACHE_DIR": cache,
           "MPLBACKEND": "Agg"}
    out = subprocess.run([sys.executable, "-c", SWEEP, method, ",".join(map(str, angles))],
                         env=env, capture_output=True, text=True, timeout=1800, cwd=tree)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-2000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def case_b(before: Path | None) -> None:
    angles = np.linspace(0.3, 1.6, 10).round(6)
    print("\n## B. 10-point PD slew-angle sweep, slew-90 system, 2 modes, 8 s each\n")
    print("| code | method | cache | first point (s) | other 9 (s, total) | sweep (s) | "
          "compiles |")
    print("|---|---|---|---|---|---|---|")
    trees = ([("before", before)] if before else []) + [("this", ROOT)]
    for label, tree in trees:
        for method in ("rk4", "auto"):
            with tempfile.TemporaryDirectory() as cache:
                states = ("cold", "warm") if label == "this" else ("-",)
                for state in states:
                    found = sweep(tree, method, angles, cache)
                    walls = found["walls"]
                    print(f"| {label} | {method} | {state} | {walls[0]:.3f} | "
                          f"{sum(walls[1:]):.3f} | {sum(walls):.3f} | "
                          f"{found['stats'].get('compiles', '-')} |")
    print("\nThe issue's example, a PD slew of 30 then of 45 degrees (s each):\n")
    for label, tree in trees:
        for method in ("rk4", "auto"):
            with tempfile.TemporaryDirectory() as cache:
                walls = sweep(tree, method, np.radians([30.0, 45.0]), cache)["walls"]
            print(f"- {label}, {method}: {walls[0]:.3f} then {walls[1]:.3f}")


#: One process of case G: wall times of the many-mode runs and of the wheel slew, as JSON.
LOOPS = r"""
import json, time, warnings
warnings.simplefilter("ignore")
import flexctl
from flexctl.app.scenes import run_slew
system = flexctl.load_scene("hub-beam-mass").system
walls = {}
for n_modes in (40, 200):
    model = flexctl.build_model(system, n_modes)
    start = time.perf_counter()
    result = flexctl.simulate(model, 0.05, torque=flexctl.SineTorque(peak_torque=2.0,
                                                                      duration=2.0))
    walls[f"modes{n_modes}"] = time.perf_counter() - start
    assert result.status == "ok", result.message
start = time.perf_counter()
result = run_slew(flexctl.load_scene("wheel-slew"))[0]
walls["wheel"] = time.perf_counter() - start
walls["wheel_error"] = result.integration_error
print(json.dumps(walls))
"""


def case_g(before: Path | None) -> None:
    print("\n## G. Many modes and sample loops, each in a fresh process (wall time, s)\n")
    print("| code | cache | 40 modes, 0.05 s | 200 modes, 0.05 s | wheel-slew run_slew | "
          "its integration error (m) |")
    print("|---|---|---|---|---|---|")
    for label, state, walls in fresh_processes(before, LOOPS):
        print(f"| {label} | {state} | {walls['modes40']:.2f} | {walls['modes200']:.2f} "
              f"| {walls['wheel']:.2f} | {walls['wheel_error']:.3g} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, default=None,
                        help="a checkout of the code before the cache, for case B")
    parser.add_argument("--skip-a", action="store_true", help="case B only")
    parser.add_argument("--skip-b", action="store_true", help="case A only")
    parser.add_argument("--only-c", action="store_true", help="case C only")
    parser.add_argument("--trajopt", action="store_true", help="case E only")
    parser.add_argument("--flags", action="store_true", help="case F only")
    parser.add_argument("--loops", action="store_true", help="case G only")
    parser.add_argument("--nmpc", action="store_true", help="case D only")
    args = parser.parse_args()
    if args.nmpc:
        case_d(args.before)
        return
    if args.only_c or args.loops:
        (case_c if args.only_c else case_g)(args.before)
        return
    if args.trajopt or args.flags:
        (case_e if args.trajopt else case_f)()
        return
    with tempfile.TemporaryDirectory() as cache:
        os.environ["FLEXCTL_CACHE_DIR"] = cache
        if not args.skip_a:
            case_a()
    if not args.skip_b:
        case_b(args.before)
    case_c(args.before)
    case_d(args.before)
    case_g(args.before)


if __name__ == "__main__":
    main()
