"""Benchmark: nonlinear MPC (:mod:`controllers.mpc.nmpc`) in the loop, its slews, and
python-control.

Issue 12, item 3 ("Targets"). Three cases, every number measured on this machine when run:

A. **Solve time in the closed loop.** ``slew-90``'s plant (the scene's own: exact, 6 modes, its
   CVODES tolerance and output step, 6 s) under :class:`controllers.NMPC` as a sampled
   controller (:func:`flexctl.simulate` with a zero-order hold), tracking the optimal slew (90
   deg in 2 s, 6 N m; :func:`controllers.solve_slew` on the first_order design model of the
   same modes, for every row: the exact 4-mode trajectory optimisation takes minutes). Design
   models first_order and exact with 2 modes and horizons 20 and 40, and 4 modes with 40;
   sample times 0.02 s (and 0.05 s); QP solvers ``qrqp`` and ``osqp``; and the converged mode
   (IPOPT) for one configuration. Per row: the controller's own report
   (``result.controller_report``: wall time of the whole ``step``, end to end per sample in the
   loop: median, 99th percentile, max; failed and fallback steps), the thread CPU time of the
   same calls (what other processes on the machine cannot inflate), and the same sequence of
   samples replayed through fresh sessions of the same controller (no plant integration in
   between; the torques are checked to repeat), the best of the replays. The accuracy check of
   :func:`flexctl.simulate` (a replay of the torques at a looser tolerance) is off: it does not
   call the controller. Targets (issue 12): real-time iteration at most 1 ms median and 3 ms
   at the 99th percentile with 2 design modes and 20 steps, 2 ms / 5 ms with 40 steps; 4
   modes reported. The verdict is on the in-loop wall time, as the issue defines it.

B. **Slew quality.** ``slew-90`` (nominal) and ``slew-90-model-error`` (design model's beam
   stiffness and point mass 20 % off) run through :func:`flexctl.app.scenes.run_slew` with
   :func:`controllers.factory.from_spec`, ``controller.kind`` set to ``trajopt+lqr`` and to
   ``nmpc`` (the scenes' other settings as they are): residual tip vibration after the 2 s
   slew, and the ratio. Targets: nominal within 2x of trajopt+lqr; with model error lower.

C. **python-control on the same problem.** The 2-mode first_order design model of ``slew-90``,
   regulation from rest to 90 deg at rest (a constant target, so that python-control's
   time-invariant quadratic cost is the same objective), horizon 20 samples of 0.02 s,
   ``Q, R`` of :func:`controllers.mpc.nmpc._default_weights`, terminal cost the discrete LQR
   Riccati matrix ``P``, ``|u| <= 6 N m``:

       min sum_{j<N} |x_j - r|_Q^2 + R u_j^2 + |x_N - r|_P^2,  x_{j+1} = F(x_j, u_j)

   flexctl: the real-time iteration (one Gauss-Newton SQP step, one condensed QP of 20
   torques, ``qrqp``) in a closed loop on the design model. python-control
   (``control.optimal``, discrete time, ``dt`` = the sample time, shooting over 21 inputs of
   which the last enters no cost, SLSQP with finite-difference gradients) on (i) the
   linearisation at rest of the very hold ``F`` the MPC predicts with (RK4, its substeps),
   (ii) that nonlinear hold itself (the CasADi function, compiled speed, as a python-control
   ``nlsys``: the problem the real-time iteration approximates with one SQP step), and (iii)
   ``create_mpc_iosystem`` on (i), one sample as its simulator evaluates it (output and
   update: two solves). python-control solves the states of flexctl's own closed loop, warm
   started by shifting its previous solution as ``create_mpc_iosystem`` does, so that both
   solve the same problems; the torques are compared. Target: flexctl at least 1000x faster
   per step.

The machine has 2 cores and is shared: the load average is printed with each case, and the
CPU-time columns show what contention adds to the wall times.

Run: ``python benchmarks/bench_nmpc.py`` (some 140 s of CPU: 2 to 3 minutes on an idle
machine, more on a loaded one; ``--quick`` for a small subset in about a minute, ``--full`` for
every combination of case A (the exact 4-mode rows take minutes each), ``--only A`` to run one
case).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import re
import shutil
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import casadi as ca                                      # noqa: E402
import control                                           # noqa: E402
import control.optimal as opt                            # noqa: E402

import flexctl                                           # noqa: E402
from controllers import NMPC, SlewProblem, solve_slew    # noqa: E402
from controllers.mpc.nmpc import _default_weights, hold_function  # noqa: E402
from flexctl.sim.metrics import slew_metrics             # noqa: E402

SCENE = "slew-90"
SIZES = ((2, 20), (2, 40), (4, 40))                      # (design modes, horizon)
SAMPLE_TIMES = (0.02, 0.05)                              # s
SOLVERS = ("qrqp", "osqp")
VARIANTS = ("first_order", "exact")
#: Issue 12: (median, 99th percentile) per sample in the loop, ms, by (design modes, horizon).
TARGETS = {(2, 20): (1.0, 3.0), (2, 40): (2.0, 5.0)}
REPLAYS = 2
#: A row is replayed only when its in-loop controller time was at most this, s.
REPLAY_BUDGET = 3.0
SPEEDUP_TARGET = 1000.0
PC_HORIZON, PC_SAMPLE_TIME = 20, 0.02
PC_LOOP_TIME = 3.0                                       # s of flexctl's closed loop in case C


@dataclass(frozen=True)
class Config:
    """One row of case A."""

    variant: str
    modes: int
    horizon: int
    sample_time: float
    qp_solver: str = "qrqp"
    mode: str = "rti"

    @property
    def solver_label(self) -> str:
        return "ipopt (converged)" if self.mode == "converged" else self.qp_solver


def quick_grid():
    return [Config("first_order", 2, 20, 0.02), Config("first_order", 2, 40, 0.02)]


def default_grid():
    rows = [Config("first_order", m, n, 0.02, qp) for m, n in SIZES for qp in SOLVERS]
    rows += [Config("exact", 2, 20, 0.02), Config("exact", 2, 40, 0.02)]
    rows += [Config("first_order", 2, 20, 0.05), Config("first_order", 2, 40, 0.05)]
    rows.append(Config("first_order", 2, 20, 0.02, mode="converged"))
    return rows


def full_grid():
    rows = [Config(v, m, n, t, qp) for t in SAMPLE_TIMES for v in VARIANTS for m, n in SIZES
            for qp in SOLVERS]
    rows += [Config(v, 2, 20, 0.02, mode="converged") for v in VARIANTS]
    return rows


# ---------------------------------------------------------------------------- helpers
def load() -> str:
    one, five, fifteen = os.getloadavg()
    return (f"load average {one:.2f} / {five:.2f} / {fifteen:.2f} (1/5/15 min, "
            f"{os.cpu_count()} cores)")


def table(headers, rows):
    """Print a Markdown table."""
    print("| " + " | ".join(headers) + " |")
    print("|" + "|".join("---" for _ in headers) + "|")
    for row in rows:
        print("| " + " | ".join(str(c) for c in row) + " |")


def ms(seconds) -> str:
    return "-" if seconds is None or not np.isfinite(seconds) else f"{seconds * 1e3:.3f}"


def percentile99(values) -> float:
    return float(np.percentile(values, 99))


def verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def git_state() -> str:
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "controllers/nmpc.py"],
                               cwd=ROOT, timeout=10).returncode != 0
        return f"commit {head or '?'}" + (", controllers/nmpc.py modified in the working tree"
                                          if dirty else ", controllers/nmpc.py as committed")
    except (OSError, subprocess.SubprocessError):
        return "git state unknown"


class Recorded:
    """A sampled controller that runs another one and records, per sample, the time, the
    measured state, the torque, and the thread CPU time of its ``step``."""

    def __init__(self, controller, plans=False):
        self.controller, self.keep_plans = controller, plans
        self.sample_time = controller.sample_time
        self.session, self.samples, self.cpu, self.plans = None, [], [], []

    def start(self, model, x0):
        self.session = self.controller.start(model, x0)
        self.samples, self.cpu, self.plans = [], [], []
        return self

    def step(self, t, x):
        started = time.thread_time()
        u = self.session.step(t, x)
        self.cpu.append(time.thread_time() - started)
        self.samples.append((float(t), np.array(x, dtype=float), float(u)))
        if self.keep_plans:
            # the planned torques over the horizon (NMPCSession internals: w, u_index)
            self.plans.append(np.array(self.session.w)[self.session.built["u_index"]])
        return u

    def report(self):
        return self.session.report()


def replay(mpc, plant, samples, repeats):
    """The recorded samples through fresh sessions of ``mpc``: per repeat the session's wall
    times and thread CPU times, and the largest torque difference to the record."""
    runs = []
    for _ in range(repeats):
        session = mpc.start(plant, samples[0][1])
        cpu, worst = [], 0.0
        for t, x, u in samples:
            started = time.thread_time()
            u_again = session.step(t, x)
            cpu.append(time.thread_time() - started)
            worst = max(worst, abs(u_again - u))
        runs.append((np.array(session.solve_times), np.array(cpu), worst))
    return runs


def solve_reference(design, slew):
    """The optimal slew on ``design``: 40 intervals, or the number the trajectory optimiser
    asks for when it refuses 40 for this many modes."""
    tried, n_intervals = [], 40
    for _ in range(8):
        problem = SlewProblem(angle=slew.angle, duration=slew.duration,
                              torque_bound=slew.torque_bound, n_intervals=n_intervals)
        try:
            return solve_slew(design, problem), n_intervals
        except ValueError as exc:
            tried.append(n_intervals)
            hint = re.search(r"n_intervals = (\d+)\b(?! is)", str(exc))
            suggested = int(hint.group(1)) if hint else 0
            n_intervals = suggested if suggested > n_intervals else n_intervals + 10
    raise RuntimeError(f"solve_slew refused n_intervals {tried}")


def compiled_pieces(mpc) -> str:
    """Whether the real-time iteration's shooting (forward) and Jacobian (linear) functions
    were compiled to machine code (the compile cache), from the built problem."""
    built = getattr(mpc, "_built", {})
    try:
        return "/".join("yes" if built[k].is_a("External") else "no"
                        for k in ("forward", "linear"))
    except (KeyError, AttributeError):
        return "?"


# ---------------------------------------------------------------------------- case A
def closed_loop_row(cfg: Config, scene, plant, reference, replays=REPLAYS, t_final=None):
    """One configuration in the closed loop on ``plant``: a dict of what it measured."""
    slew, sim = scene.maneuver, scene.simulation
    design = flexctl.build_model(scene.design_system, n_modes=cfg.modes, variant=cfg.variant)
    options = dict(model=design, target=slew.angle, torque_limit=slew.torque_bound,
                   sample_time=cfg.sample_time, horizon=cfg.horizon, reference=reference,
                   mode=cfg.mode)
    if cfg.mode == "rti":
        options["qp_solver"] = cfg.qp_solver
    started = time.perf_counter()
    mpc = NMPC(**options).prepare()
    build = time.perf_counter() - started
    recorded = Recorded(mpc)
    started = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                 # model-validity notes, not timings
        result = flexctl.simulate(plant, sim.t_final if t_final is None else t_final,
                                  controller=recorded, rtol=sim.rtol,
                                  output_step=sim.output_step, check_accuracy=False,
                                  check_validity=False)      # the recorder sees one run
    run = time.perf_counter() - started
    report = result.controller_report
    row = {"cfg": cfg, "substeps": mpc.substeps, "compiled": compiled_pieces(mpc),
           "build": build, "run": run, "status": result.status, "report": report,
           "samples": len(recorded.samples), "cpu": np.array(recorded.cpu),
           "residual": slew_metrics(result, slew.angle, reference.duration).residual_vibration,
           "replays": None}
    if replays and report["controller_time"] <= REPLAY_BUDGET:
        row["replays"] = replay(mpc, plant, recorded.samples, replays)
    return row


def timing_rows(rows):
    """Markdown rows of case A and the verdicts."""
    lines = []
    for row in rows:
        cfg = row["cfg"]
        if "error" in row:
            lines.append([cfg.variant, cfg.modes, cfg.horizon, f"{cfg.sample_time * 1e3:g}",
                          cfg.solver_label] + ["-"] * 13 + [f"failed: {row['error']}"])
            continue
        rep = row["report"]
        median, p99, peak = (rep["solve_time_median_s"], rep["solve_time_p99_s"],
                             rep["solve_time_max_s"])
        cpu = row["cpu"]
        if row["replays"]:
            best_median = min(float(np.median(w)) for w, _, _ in row["replays"])
            best_p99 = min(percentile99(w) for w, _, _ in row["replays"])
            best_cpu_p99 = min(percentile99(c) for _, c, _ in row["replays"])
            repeat = max(d for _, _, d in row["replays"])
            replayed = (f"{ms(best_median)} / {ms(best_p99)} / {ms(best_cpu_p99)}"
                        f" ({len(row['replays'])}x, du {repeat:.0e})")
        else:
            replayed = "-"
        target = TARGETS.get((cfg.modes, cfg.horizon)) if cfg.mode == "rti" else None
        if target is None:
            judged = "reported"
        else:
            on_cpu = (float(np.median(cpu)) * 1e3 <= target[0]
                      and percentile99(cpu) * 1e3 <= target[1])
            judged = (f"{verdict(median * 1e3 <= target[0] and p99 * 1e3 <= target[1])} "
                      f"(<= {target[0]:g} / {target[1]:g}; on CPU time: {verdict(on_cpu)})")
        lines.append([cfg.variant, cfg.modes, cfg.horizon, f"{cfg.sample_time * 1e3:g}",
                      cfg.solver_label, row["substeps"], row["compiled"], f"{row['build']:.1f}",
                      row["samples"], ms(median), ms(p99), ms(peak), ms(float(np.median(cpu))),
                      ms(percentile99(cpu)), replayed, rep["failed_steps"],
                      rep["fallback_steps"], f"{row['residual'] * 1e3:.3f}", judged])
    return lines


def timing_case(grid, replays):
    scene = flexctl.load_scene(SCENE)
    plant = scene.build_model()
    slew, sim = scene.maneuver, scene.simulation
    print(f"\n## A. Real-time iteration in the closed loop on {SCENE}\n")
    print(f"Plant: the scene's {plant.variant} model, {plant.n_modes} modes, CVODES rtol "
          f"{sim.rtol:g}, {sim.t_final:g} s; slew {np.degrees(slew.angle):g} deg in "
          f"{slew.duration:g} s, |u| <= {slew.torque_bound:g} N m. {load()} at the start.\n")
    references = {}
    for modes in sorted({cfg.modes for cfg in grid}):
        design = flexctl.build_model(scene.design_system, n_modes=modes, variant="first_order")
        started = time.perf_counter()
        solution, intervals = solve_reference(design, slew)
        references[modes] = solution
        print(f"- reference for {modes} design modes: solve_slew on first_order, {intervals} "
              f"intervals, {solution.return_status}, {time.perf_counter() - started:.1f} s")
    rows = []
    for cfg in grid:
        try:
            rows.append(closed_loop_row(cfg, scene, plant, references[cfg.modes], replays))
        except Exception as exc:                      # a failing row is reported, not fatal
            rows.append({"cfg": cfg, "error": f"{type(exc).__name__}: {exc}"[:200]})
    print()
    table(["design", "modes", "N", "T (ms)", "solver", "RK4 substeps", "compiled fwd/lin",
           "build (s)", "samples", "loop median (ms)", "loop p99 (ms)", "loop max (ms)",
           "CPU median (ms)", "CPU p99 (ms)", "replayed best median / p99 / CPU p99 (ms)",
           "failed", "fallback", "residual vib. (mm)", "target median / p99 (ms)"],
          timing_rows(rows))
    print(f"\nloop: wall time per sample of NMPCSession.step as its report gives it (median, "
          f"99th percentile, max over the run); CPU: thread CPU time of the same calls; "
          f"replayed: the run's samples through fresh sessions of the same controller, best of "
          f"the repeats (rows whose loop controller time was at most {REPLAY_BUDGET:g} s), du: "
          f"largest torque difference to the closed loop (N m). Residual vibration: largest "
          f"|tip deflection| after {slew.duration:g} s. Verdict on the loop wall times (the "
          f"issue's definition), and the same targets on the CPU times for comparison. "
          f"{load()} at the end.")
    return rows


# ---------------------------------------------------------------------------- case B
def timed_factory(scene, plant):
    """:func:`controllers.factory.from_spec`, the NMPC wrapped to record CPU times."""
    from controllers.factory import from_spec

    built = from_spec(scene, plant)
    if getattr(built, "kind", None) == "nmpc" and dataclasses.is_dataclass(built):
        built = dataclasses.replace(built, controller=Recorded(built.controller))
    return built


def quality_case():
    from flexctl.app.scenes import run_slew

    print(f"\n## B. Slew quality: nmpc against trajopt+lqr\n\n{load()} at the start.\n")
    residual, lines = {}, []
    for name in ("slew-90", "slew-90-model-error"):
        for kind in ("trajopt+lqr", "nmpc"):
            scene = flexctl.load_scene(name, overrides={"controller.kind": kind})
            started = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result, built, metrics = run_slew(scene, timed_factory)
            wall = time.perf_counter() - started
            residual[name, kind] = metrics.residual_vibration
            period = getattr(built.controller, "sample_time", None) \
                or built.info.get("sample_time")
            report = result.controller_report or {}
            timing = (f"{ms(report['solve_time_median_s'])} / {ms(report['solve_time_p99_s'])}"
                      f" / {ms(report['solve_time_max_s'])}"
                      if "solve_time_median_s" in report else "-")
            cpu = getattr(built.controller, "cpu", None)
            if cpu:
                timing += f" (CPU {ms(float(np.median(cpu)))} / {ms(percentile99(cpu))})"
            mspec = scene.model
            lines.append([name, f"{mspec.design_stiffness_factor:g} / "
                          f"{mspec.design_mass_factor:g}", kind,
                          f"sampled {period * 1e3:g} ms" if period else "continuous",
                          result.status, f"{metrics.residual_vibration * 1e3:.3f}",
                          f"{metrics.peak_tip_deflection * 1e3:.1f}",
                          f"{metrics.final_error * 1e3:+.3f}", timing,
                          report.get("failed_steps", "-"), f"{wall:.1f}"])
    table(["scene", "design stiffness / mass factor", "controller", "runs", "status",
           "residual vib. (mm)", "peak tip (mm)", "final hub error (mrad)",
           "NMPC step median / p99 / max (CPU median / p99) (ms)", "failed steps", "wall (s)"],
          lines)
    nominal = residual["slew-90", "nmpc"] / residual["slew-90", "trajopt+lqr"]
    error = residual["slew-90-model-error", "nmpc"] / residual["slew-90-model-error",
                                                                "trajopt+lqr"]
    print(f"\n- nominal (slew-90): nmpc / trajopt+lqr = {nominal:.3f} (target <= 2: "
          f"{verdict(nominal <= 2.0)})")
    print(f"- model error (slew-90-model-error): nmpc / trajopt+lqr = {error:.3f} (target < 1: "
          f"{verdict(error < 1.0)})")
    print(f"\nBoth scenes: {flexctl.load_scene('slew-90').model.variant} plant, "
          f"{flexctl.load_scene('slew-90').model.modes} modes; the design model of "
          f"{flexctl.load_scene('slew-90').model.design_modes} modes on the scene's design "
          "variant; each controller as controllers.factory.from_spec builds it (trajectory "
          "optimisation included in the wall time). Residual vibration: largest |tip deflection|"
          f" after the controller's maneuver end. {load()} at the end.")
    return residual


# ---------------------------------------------------------------------------- case C
def python_control_problem(design, horizon, sample_time, angle, bound, substeps):
    """python-control's discrete-time versions of the MPC problem: linear (the RK4 hold's
    Jacobians at rest) and nonlinear (the RK4 hold), cost, constraints and time points."""
    n = design.n_states
    hold = hold_function(design, sample_time, substeps)
    x, u = ca.SX.sym("x", n), ca.SX.sym("u")
    step = hold(x, u)
    jac = ca.Function("hold_jacobian", [x, u], [ca.jacobian(step, x), ca.jacobian(step, u)])
    a_d, b_d = (np.array(v) for v in jac(np.zeros(n), 0.0))
    q, r = _default_weights(design, angle, bound)
    _, p_mat, _ = control.dlqr(a_d, b_d, np.diag(q), np.array([[r]]))
    names = dict(states=list(design.state_names), inputs=["torque"])
    linear = control.ss(a_d, b_d, np.eye(n), np.zeros((n, 1)), dt=sample_time, **names)
    nonlinear = control.nlsys(lambda t, x, u, params: np.array(hold(x, u[0])).reshape(-1), None,
                              dt=sample_time, **names)
    target = np.zeros(n)
    target[0] = angle
    a_c, b_c = design.linear_matrices(0.0)
    zoh = control.c2d(control.ss(a_c, b_c, np.eye(n), np.zeros((n, 1))), sample_time, "zoh")
    zoh_gap = max(float(np.max(np.abs(zoh.A - a_d))), float(np.max(np.abs(zoh.B - b_d))))

    def parts(system):
        cost = opt.quadratic_cost(system, np.diag(q), np.array([[r]]), x0=target,
                                  u0=np.zeros(1))
        terminal = opt.quadratic_cost(system, p_mat, None, x0=target)
        constraints = [opt.input_range_constraint(system, [-bound], [bound])]
        return cost, constraints, terminal

    timepts = sample_time * np.arange(horizon + 1)
    return {"linear": linear, "nonlinear": nonlinear, "parts": parts, "timepts": timepts,
            "zoh_gap": zoh_gap}


def python_control_steps(system, problem, samples, count, flex_plans=None):
    """``OptimalControlProblem.compute_trajectory`` on the first ``count`` recorded states,
    warm started by shifting: wall times, plans, SLSQP iterations, successes; and, given
    flexctl's plans, python-control's own cost of its optimum relative to that of flexctl's
    plan, ``J(u_pc) / J(u_flexctl) - 1`` (negative: python-control's is lower)."""
    cost, constraints, terminal = problem["parts"](system)
    ocp = opt.OptimalControlProblem(system, problem["timepts"], cost, constraints,
                                    terminal_cost=terminal)
    times, torques, iterations, ok, guess, costs = [], [], [], [], None, []
    for k, (_, x, _) in enumerate(samples[:count]):
        started = time.perf_counter()
        res = ocp.compute_trajectory(x, initial_guess=guess, print_summary=False)
        times.append(time.perf_counter() - started)
        inputs = np.asarray(res.inputs, dtype=float).reshape(1, -1)
        guess = np.hstack((inputs[:, 1:], inputs[:, -1:]))
        torques.append(inputs[0, :-1])           # the plan; the last input enters no cost
        if flex_plans is not None:
            try:                                 # python-control's cost function (private)
                ocp.x = np.asarray(x, dtype=float)
                theirs = ocp._cost_function(inputs.reshape(-1))
                ours = ocp._cost_function(np.append(flex_plans[k], 0.0))
                costs.append(theirs / ours - 1.0)
            except Exception:                    # noqa: BLE001  an internal that changed
                costs.append(np.nan)
        iterations.append(int(getattr(res, "nit", -1)))
        ok.append(bool(res.success))
    return {"times": np.array(times), "plans": np.array(torques), "iterations": iterations,
            "cost_gap": np.array(costs),
            "ok": ok, "variables": ocp.timepts.size * system.ninputs,
            "method": ocp.minimize_kwargs.get("method") or "scipy default: SLSQP"}


def mpc_iosystem_samples(system, problem, samples, count):
    """``create_mpc_iosystem``: per sample its output and its update (each solves)."""
    cost, constraints, terminal = problem["parts"](system)
    ctrl = opt.create_mpc_iosystem(system, problem["timepts"], cost, constraints,
                                   terminal_cost=terminal)
    xc = np.zeros(ctrl.nstates)
    times, torques, plans = [], [], []
    for t, x, _ in samples[:count]:
        started = time.perf_counter()
        u = ctrl.output(t, xc, x)
        xc = ctrl.dynamics(t, xc, x)
        times.append(time.perf_counter() - started)
        torques.append(float(np.asarray(u).reshape(-1)[0]))
        plans.append(np.asarray(xc, dtype=float).reshape(-1)[:-1])   # the update's plan
    return {"times": np.array(times), "torques": np.array(torques), "plans": np.array(plans)}


def flexctl_loop(design, horizon, sample_time, angle, bound, t_final):
    """flexctl's real-time iteration regulating ``design`` from rest to ``angle``."""
    mpc = NMPC(model=design, target=angle, torque_limit=bound, sample_time=sample_time,
               horizon=horizon).prepare()
    recorded = Recorded(mpc, plans=True)
    result = flexctl.simulate(design, t_final, controller=recorded, check_accuracy=False)
    return mpc, recorded, result


def python_control_case(steps_linear=2, steps_nonlinear=1, samples_iosystem=1,
                        horizon=PC_HORIZON, sample_time=PC_SAMPLE_TIME, t_final=PC_LOOP_TIME):
    scene = flexctl.load_scene(SCENE)
    slew = scene.maneuver
    design = flexctl.build_model(scene.design_system, n_modes=2, variant="first_order")
    angle, bound = slew.angle, slew.torque_bound
    print(f"\n## C. One MPC step: flexctl against python-control {control.__version__}\n")
    print(f"{load()} at the start.\n")
    mpc, recorded, result = flexctl_loop(design, horizon, sample_time, angle, bound, t_final)
    report = result.controller_report
    flex_median = report["solve_time_median_s"]
    problem = python_control_problem(design, horizon, sample_time, angle, bound, mpc.substeps)
    u_flex = np.array([u for _, _, u in recorded.samples])
    print(f"Problem: {SCENE}'s system, design model {design.variant} with {design.n_modes} "
          f"modes ({design.n_states} states), regulation from rest to "
          f"{np.degrees(angle):g} deg at rest, horizon {horizon} x {sample_time:g} s, Q and R "
          f"of controllers.mpc.nmpc._default_weights, terminal cost the discrete LQR Riccati "
          f"matrix, |u| <= {bound:g} N m. Prediction: RK4 hold, {mpc.substeps} substep(s) per "
          f"sample (its linearisation at rest differs from control.c2d's zoh by at most "
          f"{problem['zoh_gap']:.1e} per entry). flexctl ran {len(u_flex)} samples "
          f"({t_final:g} s) in closed loop on the design model; python-control solved the "
          "first of those states.\n")
    lines = []
    flex_first = {}
    for count in {steps_linear, steps_nonlinear, samples_iosystem}:
        if count:
            flex_first[count] = float(np.median(
                [w for w in recorded.session.solve_times[:count]]))
    lines.append(["flexctl NMPC, real-time iteration (qrqp)",
                  f"nonlinear hold, one SQP step: condensed QP of {horizon} torques",
                  horizon, len(u_flex), ms(flex_median),
                  f"{ms(float(np.min(recorded.session.solve_times)))}", "1 (reference)", "-", "-",
                  f"failed steps {report['failed_steps']}"])
    results = {}
    runs = (("solve_ocp, linear (RK4 hold at rest)", "linear", steps_linear, "QP by SLSQP"),
            ("solve_ocp, nonlinear (the RK4 hold)", "nonlinear", steps_nonlinear,
             "NLP by SLSQP"))
    for label, key, count, kind in runs:
        if not count:
            continue
        out = python_control_steps(problem[key], problem, recorded.samples, count,
                                   recorded.plans)
        results[key] = out
        gap = float(np.max(np.abs(out["plans"] - np.array(recorded.plans[:count]))))
        ratio = float(np.median(out["times"])) / flex_median
        lines.append([f"python-control {label}",
                      f"{kind} ({out['method']}, finite differences), shooting, "
                      f"{out['variables']} inputs", horizon, count,
                      ms(float(np.median(out["times"]))), ms(float(np.min(out["times"]))),
                      f"{ratio:,.0f}x ({verdict(ratio >= SPEEDUP_TARGET)}); vs flexctl's same "
                      f"{count} steps {float(np.median(out['times'])) / flex_first[count]:,.0f}x",
                      f"{gap:.1e}", ", ".join(f"{g:+.1e}" for g in out["cost_gap"]),
                      f"{all(out['ok'])}, SLSQP iterations {out['iterations']}"])
    if samples_iosystem:
        out = mpc_iosystem_samples(problem["linear"], problem, recorded.samples,
                                   samples_iosystem)
        results["iosystem"] = out
        gap = float(np.max(np.abs(out["plans"] - np.array(recorded.plans[:samples_iosystem]))))
        ratio = float(np.median(out["times"])) / flex_median
        lines.append(["python-control create_mpc_iosystem, linear: output + update",
                      "two solve_ocp per sample (output from the stored inputs, update from "
                      "them shifted)", horizon, samples_iosystem,
                      ms(float(np.median(out["times"]))), ms(float(np.min(out["times"]))),
                      f"{ratio:,.0f}x ({verdict(ratio >= SPEEDUP_TARGET)})", f"{gap:.1e}", "-",
                      "-"])
    table(["solver", "what is solved", "N", "steps timed", "median per step (ms)",
           "best (ms)", "python-control / flexctl median (target >= 1000x)",
           "max plan difference to flexctl (N m)", "J(u_pc) / J(u_flexctl) - 1",
           "success"], lines)
    print(f"\nflexctl median per step over its whole closed loop {ms(flex_median)} ms "
          f"(p99 {ms(report['solve_time_p99_s'])} ms, failed steps {report['failed_steps']}); "
          "the ratios divide python-control's median by it, and by flexctl's median over the "
          "same first steps. Same problem: same states, weights, bounds, horizon and sample "
          "time; python-control converges each problem (SLSQP), flexctl does one SQP step "
          "(on the linear problem at rest one step is the solution). Plan difference: largest "
          "difference of the planned torques over the horizon, at the steps timed (the "
          f"iosystem row: the plan its update stores); J: python-control's own cost function "
          "at its optimum and at flexctl's plan, per step timed (negative: python-control's "
          f"plan costs less). {load()} at the end.")
    return {"flexctl_median": flex_median, **results}


# ---------------------------------------------------------------------------- main
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true",
                      help="2 rows of case A, no replays, 1 python-control step each")
    size.add_argument("--full", action="store_true",
                      help="every combination of case A (variants, sizes, sample times, "
                           "solvers; the exact 4-mode rows take minutes) and more "
                           "python-control steps")
    parser.add_argument("--only", action="append", choices=("A", "B", "C"),
                        help="run only this case (repeatable)")
    parser.add_argument("--replays", type=int, default=None,
                        help=f"replays per row of case A (default {REPLAYS}, 0 with --quick)")
    args = parser.parse_args(argv)
    cases = set(args.only or ("A", "B", "C"))
    grid = quick_grid() if args.quick else full_grid() if args.full else default_grid()
    replays = args.replays if args.replays is not None else (0 if args.quick else REPLAYS)

    started = time.perf_counter()
    print("# flexctl NMPC benchmark (issue 12, item 3)\n")
    print(f"- machine: {platform.machine()}, {os.cpu_count()} cores, {platform.system()} "
          f"{platform.release()}; {load()}")
    print(f"- python {platform.python_version()}, numpy {np.__version__}, casadi "
          f"{ca.__version__}, python-control {control.__version__}; C compiler for CasADi jit: "
          f"{shutil.which('gcc') or shutil.which('cc') or 'none'}")
    print(f"- code: {git_state()}")
    given = sys.argv[1:] if argv is None else list(argv)
    print(f"- command: python benchmarks/bench_nmpc.py {' '.join(given)}".rstrip())
    if "A" in cases:
        timing_case(grid, replays)
    if "B" in cases:
        quality_case()
    if "C" in cases:
        if args.quick:
            python_control_case(1, 1, 1)
        elif args.full:
            python_control_case(5, 3, 2)
        else:
            python_control_case()
    print(f"\nTotal wall time {time.perf_counter() - started:.0f} s (CPU time of this process "
          f"{time.process_time():.0f} s); {load()}.")


if __name__ == "__main__":
    main()
