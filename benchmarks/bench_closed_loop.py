"""Benchmark: closed-loop simulation, compiled (CVODES) against SciPy and a bare CVODES loop.

Case A, the closed loop of issue 9: ``slew-90``'s 6-mode plant, first_order, under
``controllers.PD(kp=12, kd=8, torque_limit=6)``, from 90 deg off target (``theta(0) = -pi/2``,
regulated to 0) to rest, 6 s, on the scene's 0.005 s output grid. Tools:

- ``flexctl.simulate(controller=pd)`` on its default path, now compiled (the PD law has a
  CasADi form): *cold*, a new controller object per run so that nothing built before is reused
  (integrator construction, the run, the accuracy check, outputs); *warm*, the same objects
  again (the integrators built for them are reused); and without the accuracy check;
- the same call forced onto SciPy's DOP853 (``method="DOP853"``), the path every closed loop
  took before the controllers had CasADi forms;
- a bare CasADi CVODES integration of the same closed loop built on ``model.casadi()``
  (``f(x, u)``, the saturated PD written with ``fmin``/``fmax``), construction included.

Every tool runs at the largest relative tolerance (quarter decades from 1e-4 down) whose tip
deflection is within 1e-6 of a reference, relative to the peak, as ``bench_speed.py`` does. The
reference is DOP853 at rtol 1e-12 through ``flexctl.simulate`` (a different integrator from the
compiled ones timed). The bare run takes ``atol = rtol * 1e-3`` (metres and radians); flexctl
scales its own.

Case B, the demo's controller comparison (:func:`flexctl.app.demo.slew_comparison`): every
controller kind on ``slew-90`` through :func:`flexctl.app.sweep.sweep`, run serially here,
on the default path and with ``simulation.method = "DOP853"``. Wall time per kind (design and
simulation, as the sweep reports it) and the whole sweep; on the first_order plant of issue 9's
measurement, and on the scene's own plant when that is another variant.

Case C, repeated runs (issue 9, item 4): slews of case A whose PD gains are dispersed by
+-30 %, at one tolerance: ``flexctl.simulate`` (the PD numbers are parameters of one compiled
right-hand side, so its integrators are built once) against the sum of the bare CVODES
integration times (and construction, which the bare loop repeats per gain pair).

Targets (issue 9): A, flexctl within 2x of the bare CVODES loop; B, the comparison at least 5x
faster than on the SciPy path; C, at most 3x the sum of the bare integration times. Nothing
here is asserted: the script prints what it measures.

Run: ``python benchmarks/bench_closed_loop.py`` (a few minutes: the DOP853 runs dominate).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import casadi as ca                                   # noqa: E402
import equal_error                                     # noqa: E402
from equal_error import TARGET, measure  # noqa: E402

from controllers import PD, from_spec                 # noqa: E402
from controllers.spec import CONTROLLER_KEYS          # noqa: E402
from flexctl import build_model, load_scene, simulate  # noqa: E402
from flexctl.app.sweep import SceneTask, SweepError, sweep  # noqa: E402

REFERENCE_RTOL = 1e-12
ATOL_SCALE = 1e-3                    # bare run: atol = rtol * 1e-3 (m, rad)
T_FINAL = 6.0                        # s
GAINS = {"kp": 12.0, "kd": 8.0, "torque_limit": 6.0}
REPEATS = 7                          # compiled runs (tens of ms each)
REPEATS_SLOW = 3                     # DOP853 runs (seconds each)
SWEEP_SLEWS = 200                    # case C (issue 9 asks about 1000: the cost is linear)
SWEEP_RTOL = 1e-6


# ---------------------------------------------------------------------------- case A
def flexctl_tip(model, x0, step, fresh=True, method="auto", check_accuracy=True):
    """``rtol -> tip``; ``fresh``: a new PD per run, so that no cached integrator applies."""
    kept = PD(**GAINS)

    def run(rtol):
        pd = PD(**GAINS) if fresh else kept
        result = simulate(model, T_FINAL, controller=pd, x0=x0, rtol=rtol, output_step=step,
                          method=method, check_accuracy=check_accuracy)
        assert result.ok and (method != "auto" or
                              result.method in ("cvodes", "RK45", "dop853")), \
            result.message
        return result.tip_deflection
    return run


def bare_cvodes_tip(model, x0, grid, multistep="bdf"):
    """CVODES on ``model.casadi()`` closed by the saturated PD law, written directly, with its
    default BDF or with Adams (``multistep``)."""
    n, tip = model.n_modes, model.mode_tips
    dynamics = model.casadi()

    def run(rtol):
        x = ca.SX.sym("x", model.n_states)
        u = GAINS["kp"] * (0.0 - x[0]) + GAINS["kd"] * (0.0 - x[n + 1])
        u = ca.fmin(ca.fmax(u, -GAINS["torque_limit"]), GAINS["torque_limit"])
        integrator = ca.integrator("bare", "cvodes", {"x": x, "ode": dynamics(x, u)}, 0.0,
                                   list(grid[1:]), {"reltol": rtol, "abstol": rtol * ATOL_SCALE,
                                                    "max_num_steps": 10 ** 7,
                                                    "linear_multistep_method": multistep})
        xf = np.array(integrator(x0=x0)["xf"])
        return np.concatenate(([tip @ x0[1:n + 1]], tip @ xf[1:n + 1]))
    return run


def slew_case():
    """slew-90's plant on first_order, 90 deg off target at rest, its output grid and step."""
    scene = load_scene("slew-90")
    model = build_model(scene.system, n_modes=scene.model.modes, variant="first_order")
    step = scene.simulation.output_step
    x0 = np.zeros(model.n_states)
    x0[0] = -np.pi / 2
    grid = np.arange(0.0, T_FINAL + 0.5 * step, step)
    grid = grid[grid <= T_FINAL]
    return model, x0, grid, step


def closed_loop_case():
    model, x0, grid, step = slew_case()
    print(f"\n== A. slew-90 plant ({model.variant}, {model.n_modes} modes) under "
          f"PD({', '.join(f'{k}={v:g}' for k, v in GAINS.items())}), 90 deg to rest, "
          f"{T_FINAL:g} s; target relative tip error {TARGET:g}")
    start = time.perf_counter()
    reference = flexctl_tip(model, x0, step, method="DOP853")(REFERENCE_RTOL)
    print(f"   reference: DOP853 at rtol {REFERENCE_RTOL:g} ({time.perf_counter() - start:.1f} s)")
    tools = {
        "flexctl.simulate, cold": (flexctl_tip(model, x0, step), REPEATS),
        "flexctl.simulate, warm": (flexctl_tip(model, x0, step, fresh=False), REPEATS),
        "flexctl, cold, no check": (flexctl_tip(model, x0, step, check_accuracy=False),
                                    REPEATS),
        "flexctl, DOP853 (SciPy)": (flexctl_tip(model, x0, step, method="DOP853"),
                                    REPEATS_SLOW),
        "bare casadi CVODES": (bare_cvodes_tip(model, x0, grid), REPEATS),
        "bare CVODES, Adams": (bare_cvodes_tip(model, x0, grid, "adams"), REPEATS),
    }
    times = measure(tools, reference, width=26)
    bare = times["bare casadi CVODES"]
    for label in ("flexctl.simulate, cold", "flexctl.simulate, warm", "flexctl, cold, no check"):
        ratio = times[label] / bare
        print(f"   {label} / bare CVODES = {ratio:.2f} (target <= 2: "
              f"{'met' if ratio <= 2 else 'missed'}); / bare CVODES with Adams "
              f"{times[label] / times['bare CVODES, Adams']:.2f}")
    cpu = equal_error.CPU_TIMES
    print("   CPU time (every thread) / bare CVODES: " + ", ".join(
        f"{label} {cpu[label] / cpu['bare casadi CVODES']:.2f}" for label in
        ("flexctl.simulate, cold", "flexctl.simulate, warm", "flexctl, cold, no check"))
        + " (the accuracy check runs beside the run on a spare core)")
    print(f"   DOP853 path / compiled path (cold) = "
          f"{times['flexctl, DOP853 (SciPy)'] / times['flexctl.simulate, cold']:.1f}")
    return times


# ---------------------------------------------------------------------------- case C
def dispersed_gains(count, seed=9):
    """``count`` PD gain pairs within +-30 % of the nominal ones."""
    rng = np.random.default_rng(seed)
    return GAINS["kp"] * rng.uniform(0.7, 1.3, count), GAINS["kd"] * rng.uniform(0.7, 1.3, count)


def gain_sweep_case(count=SWEEP_SLEWS, rtol=SWEEP_RTOL):
    """Slews with dispersed PD gains: flexctl (integrators shared through the gains as
    parameters) against the sum of bare CVODES integration times."""
    model, x0, grid, step = slew_case()
    kps, kds = dispersed_gains(count)
    print(f"\n== C. {count} slews of case A with PD gains dispersed by +-30 %, rtol {rtol:g}")
    totals = {}
    for label, check in (("flexctl.simulate", True), ("flexctl, no check", False)):
        start = time.perf_counter()
        for kp, kd in zip(kps, kds):
            pd = PD(kp=kp, kd=kd, torque_limit=GAINS["torque_limit"])
            simulate(model, T_FINAL, controller=pd, x0=x0, rtol=rtol, output_step=step,
                     check_accuracy=check)
        totals[label] = time.perf_counter() - start
    build_total = run_total = 0.0
    dynamics = model.casadi()
    for kp, kd in zip(kps, kds):
        start = time.perf_counter()
        x = ca.SX.sym("x", model.n_states)
        u = kp * (0.0 - x[0]) + kd * (0.0 - x[model.n_modes + 1])
        u = ca.fmin(ca.fmax(u, -GAINS["torque_limit"]), GAINS["torque_limit"])
        integrator = ca.integrator("bare", "cvodes", {"x": x, "ode": dynamics(x, u)}, 0.0,
                                   list(grid[1:]), {"reltol": rtol, "abstol": rtol * ATOL_SCALE,
                                                    "max_num_steps": 10 ** 7})
        built = time.perf_counter()
        integrator(x0=x0)
        build_total += built - start
        run_total += time.perf_counter() - built
    print(f"   bare CVODES: integration {run_total:.2f} s, construction {build_total:.2f} s "
          f"(sums over the {count} slews)")
    for label, total in totals.items():
        ratio = total / run_total
        print(f"   {label:<18} {total:.2f} s = {ratio:.2f} x the bare integration times "
              f"(target <= 3: {'met' if ratio <= 3 else 'missed'}), "
              f"{total / (run_total + build_total):.2f} x bare built and run")


# ---------------------------------------------------------------------------- case B
def comparison(method, variant):
    """The demo's sweep, one controller kind at a time: ``{kind: (wall time, row or the
    failure)}``. A kind that fails is reported, not fatal."""
    runs = {}
    for kind in CONTROLLER_KEYS:
        point = {"controller.kind": kind}
        if method is not None:
            point["simulation.method"] = method
        if variant is not None:
            point["model.variant"] = variant
        start = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")       # model-validity notes, not timings
                row = list(sweep(SceneTask(scene="slew-90", controller_factory=from_spec,
                                           keep_result=True), [point], progress=False))[0]
        except SweepError as exc:
            row = f"failed: {exc.__cause__ or exc}"
        if isinstance(row, dict) and "result" not in row:       # a refused point
            row = f"refused: {row.get('failure', 'no result')}"
        runs[kind] = (time.perf_counter() - start, row)
    return runs


def demo_case(variant=None):
    plant = load_scene("slew-90").model.variant if variant is None else variant
    print(f"\n== B. the demo's controller comparison on slew-90 (every kind, serial), "
          f"{plant} plant{' (the scene as the demo runs it)' if variant is None else ''}")
    fast, slow = comparison(None, variant), comparison("DOP853", variant)
    print(f"   {'kind':<13} {'method':>7} {'compiled: all, run (s)':>23} "
          f"{'DOP853: all, run (s)':>21} {'ratios':>11}")
    totals = np.zeros(4)
    for kind in fast:
        (t_fast, row), (t_slow, row_slow) = fast[kind], slow[kind]
        if isinstance(row, str) or isinstance(row_slow, str):
            print(f"   {kind:<13} {(row if isinstance(row, str) else row_slow)[:110]}")
            continue
        times = np.array([t_fast, row["result"].wall_time, t_slow, row_slow["result"].wall_time])
        totals += times
        print(f"   {kind:<13} {row['result'].method:>7} {times[0]:>12.3f} {times[1]:>10.3f} "
              f"{times[2]:>10.3f} {times[3]:>10.3f} {times[2] / times[0]:>5.1f} "
              f"{times[3] / times[1]:>5.1f}")
    ratio = totals[2] / totals[0]
    print(f"   whole comparison (kinds that ran both ways): {totals[0]:.2f} s compiled, "
          f"{totals[2]:.2f} s on DOP853: {ratio:.1f}x faster (target >= 5: "
          f"{'met' if ratio >= 5 else 'missed'}); the simulations alone {totals[1]:.2f} s and "
          f"{totals[3]:.2f} s: {totals[3] / totals[1]:.1f}x. 'all' includes the design "
          "(trajectory optimisation) and the scene run's model-validity estimate")


def main():
    import control                    # noqa: F401  imported here, not in the first LQR design

    print(f"flexctl closed-loop benchmark (casadi {ca.__version__}); times are medians, "
          "end to end")
    closed_loop_case()
    gain_sweep_case()
    demo_case("first_order")            # the plant of issue 9's measurement
    if load_scene("slew-90").model.variant != "first_order":
        demo_case()


if __name__ == "__main__":
    main()
