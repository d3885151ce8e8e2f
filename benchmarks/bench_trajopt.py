"""Benchmarks of :func:`controllers.slew.trajopt.solve_slew` on ``slew-90``.

1. ``--grid``: robustness to fast modes. Every design-mode count 1 to 8 and interval count
   (20, 30, 40, 60, 80, 120, 200) of the slew-90 system, on the first_order and exact design
   variants: each cell either solves, with its cost compared to the converged value (the same
   design model solved on :data:`REFERENCE_INTERVALS` holds, where holds no longer cost
   effort), or is refused before IPOPT runs. Prints, per variant, a table of cost, error
   against the converged value, wall and CPU time and status, then the refusals in full.
   ``python benchmarks/bench_trajopt.py --grid`` (an hour or so; ``--variants``, ``--modes``
   and ``--intervals`` narrow it).
2. Default: against python-control on one case.

Case of 2: the hub-beam-mass system on 2 modes (first_order), a 90 degree rest-to-rest slew in
2 s, ``|torque| <= 6 N m``, minimum effort (integral of torque^2), the same horizon and the
same 40 intervals for both solvers:

- ``solve_slew``: CasADi Opti + IPOPT, multiple shooting with RK4, torque held on each
  interval (zero-order hold), exact derivatives;
- ``control.optimal.solve_ocp``: python-control 0.10 on ``model.nonlinear()``, its default
  trapezoidal collocation for continuous-time systems, torque values at the 41 grid points
  (linearly interpolated), SLSQP with finite-difference gradients.

Both start from the same rigid-body quintic guess. Each torque is then judged the same way:
the integral of torque^2 of the signal as applied (exact for a hold and for a linear ramp),
the state it reaches when played into the 2-mode design model by flexctl's error-controlled
integrator, and the residual tip vibration it leaves in the 6-mode nonlinear plant.

Run: ``python benchmarks/bench_trajopt.py`` (about a minute; python-control dominates).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import control                                    # noqa: E402
import control.optimal as opt                     # noqa: E402

import flexctl                                    # noqa: E402
from flexctl import build_model                   # noqa: E402
from controllers.slew.trajopt import (HoldTorque, SlewProblem, TrajectoryOptimizationError,  # noqa: E402
                                      solve_slew)

ANGLE = math.radians(90.0)       # rad
DURATION = 2.0                   # s
TORQUE_BOUND = 6.0               # N m
N_INTERVALS = 40
DESIGN_MODES, PLANT_MODES = 2, 6
SETTLE = 5.0                     # s of coasting after the slew for the residual vibration
TERMINAL_TOL = 1e-3              # rad, m, rad/s, m/s: "met the terminal conditions"
REPEATS = 3                      # solve_slew is timed as the median of this many solves


class RampTorque:
    """Linear interpolation of torque values at grid points; 0 after the last point, N m."""

    def __init__(self, t, values):
        self.t, self.values = np.asarray(t, float), np.asarray(values, float)
        self.breakpoints = tuple(self.t[1:])

    def __call__(self, t):
        inside = (t >= self.t[0]) & (t <= self.t[-1])
        return np.where(inside, np.interp(t, self.t, self.values), 0.0)


def effort_hold(t, values):
    """Exact integral of a held torque squared, N^2 m^2 s."""
    return float(np.sum(np.diff(t) * values ** 2))


def effort_ramp(t, values):
    """Exact integral of a linearly interpolated torque squared, N^2 m^2 s."""
    a, b = values[:-1], values[1:]
    return float(np.sum(np.diff(t) * (a * a + a * b + b * b) / 3.0))


def quintic_guess(model, timepts):
    """The rigid-body quintic profile both solvers start from: states and torque."""
    s = timepts / DURATION
    n = model.n_modes
    states = np.zeros((model.n_states, timepts.size))
    states[0] = ANGLE * (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5)
    states[n + 1] = ANGLE * 30 * (s ** 2 - 2 * s ** 3 + s ** 4) / DURATION
    torque = model.matrices.J0 * ANGLE * 60 * (s - 3 * s ** 2 + 2 * s ** 3) / DURATION ** 2
    return states, np.clip(torque, -TORQUE_BOUND, TORQUE_BOUND)[None, :]


def judge(name, torque, design, plant, target):
    """Play ``torque`` into the design model and the larger plant; print what it reaches."""
    reached = flexctl.simulate(design, DURATION, torque=torque, rtol=1e-10)
    error = reached.states[:, -1] - target
    met = bool(np.all(np.abs(error) < TERMINAL_TOL))
    truth = flexctl.simulate(plant, DURATION + SETTLE, torque=torque, rtol=1e-8)
    after = truth.t >= DURATION
    residual = float(np.max(np.abs(truth.tip_deflection[after])))
    worst = int(np.argmax(np.abs(error)))
    tip_error = design.mode_tips @ error[1:design.n_modes + 1]
    print(f"  {name}: re-simulated on the {design.n_modes}-mode design model, "
          f"|x(T) - x_f| max {np.max(np.abs(error)):.3e} ({design.state_names[worst]}; "
          f"theta {error[0]:+.2e} rad, tip {tip_error:+.2e}"
          f" m) -> terminal conditions met (tol {TERMINAL_TOL:g}): {met}")
    print(f"  {name}: residual tip vibration in the {plant.n_modes}-mode nonlinear plant "
          f"{residual * 1e3:.3f} mm (peak during slew "
          f"{np.max(np.abs(truth.tip_deflection[~after])) * 1e3:.1f} mm), final theta "
          f"{math.degrees(truth.theta[-1]):.4f} deg")
    return met, residual


def main():
    system = flexctl.load_scene("hub-beam-mass").system
    design = flexctl.build_model(system, DESIGN_MODES)
    plant = flexctl.build_model(system, PLANT_MODES)
    target = np.eye(design.n_states)[0] * ANGLE
    timepts = np.linspace(0.0, DURATION, N_INTERVALS + 1)
    print(f"slew-90: hub-beam-mass, {DESIGN_MODES} modes ({design!r}), {math.degrees(ANGLE):g} deg"
          f" in {DURATION:g} s, |torque| <= {TORQUE_BOUND:g} N m, {N_INTERVALS} intervals; "
          f"rigid minimum effort {12 * ANGLE ** 2 * design.matrices.J0 ** 2 / DURATION ** 3:.4f}"
          f" N^2 m^2 s")

    # ---- solve_slew (CasADi + IPOPT)
    problem = SlewProblem(angle=ANGLE, duration=DURATION, torque_bound=TORQUE_BOUND,
                          n_intervals=N_INTERVALS)
    times, solution = [], None
    for _ in range(REPEATS):
        start = time.perf_counter()
        solution = solve_slew(design, problem)
        times.append(time.perf_counter() - start)
    t_casadi = float(np.median(times))
    cost_casadi = effort_hold(solution.t, solution.torque)
    disc = solution.discretisation
    print(f"\nsolve_slew (CasADi Opti + IPOPT, {disc.transcription} {disc.method}, "
          f"{disc.steps_per_hold} steps per hold):")
    print(f"  wall time {t_casadi:.3f} s (median of {REPEATS}: "
          f"{', '.join(f'{t:.3f}' for t in times)}), IPOPT {solution.ipopt_time_s:.3f} s, "
          f"{solution.iterations} iterations, status {solution.return_status}")
    print(f"  integral of torque^2 {cost_casadi:.4f} N^2 m^2 s (its own objective "
          f"{solution.cost:.4f}); peak |torque| {np.max(np.abs(solution.torque)):.3f} N m")
    print(f"  its own final state error {np.max(np.abs(solution.states[:, -1] - target)):.2e}")

    # ---- python-control solve_ocp
    sys_nl = design.nonlinear()
    cost = opt.quadratic_cost(sys_nl, None, np.array([[1.0]]))
    constraints = [opt.input_range_constraint(sys_nl, [-TORQUE_BOUND], [TORQUE_BOUND])]
    terminal = [opt.state_range_constraint(sys_nl, target, target)]
    guess = quintic_guess(design, timepts)
    start = time.perf_counter()
    result = opt.solve_ocp(sys_nl, timepts, np.zeros(design.n_states), cost, constraints,
                           terminal_constraints=terminal, initial_guess=guess,
                           print_summary=False)
    t_control = time.perf_counter() - start
    u_control = np.asarray(result.inputs, dtype=float).reshape(-1)
    x_control = np.asarray(result.states, dtype=float).reshape(design.n_states, -1)
    cost_control = effort_ramp(timepts, u_control)
    method = result.problem.minimize_kwargs.get("method") or "default (SLSQP, constrained)"
    print(f"\ncontrol.optimal.solve_ocp (python-control {control.__version__}, "
          f"{result.problem.collocation and 'trapezoidal collocation' or 'shooting'}, "
          f"scipy.optimize.minimize {method}):")
    print(f"  wall time {t_control:.3f} s, success {result.success}, "
          f"{getattr(result, 'nit', '?')} iterations, message {result.message!r}")
    print(f"  integral of torque^2 {cost_control:.4f} N^2 m^2 s (its own trapezoid "
          f"{result.cost:.4f}); peak |torque| {np.max(np.abs(u_control)):.3f} N m")
    print(f"  its own final state error {np.max(np.abs(x_control[:, -1] - target)):.2e}")

    # ---- the same yardsticks for both
    print(f"\nratio of wall times solve_ocp / solve_slew: {t_control / t_casadi:.1f}")
    print(f"ratio of efforts solve_ocp / solve_slew: {cost_control / cost_casadi:.4f}")
    print("\nplayed back (flexctl.simulate, error-controlled):")
    judge("solve_slew", solution.torque_function(), design, plant, target)
    judge("solve_ocp ", RampTorque(timepts, u_control), design, plant, target)
    u_bang = 4.0 * ANGLE * design.matrices.J0 / DURATION ** 2
    judge("rigid bang-bang (reference)",
          HoldTorque(np.array([0.0, DURATION / 2, DURATION]), np.array([u_bang, -u_bang])),
          design, plant, target)


# ---------------------------------------------------------------------------- the grid
GRID_MODES = tuple(range(1, 9))
GRID_INTERVALS = (20, 30, 40, 60, 80, 120, 200)
GRID_VARIANTS = ("first_order", "exact")
#: Holds of the converged reference, the first that is not refused: their least effort is
#: within 0.006 % (400) or 0.02 % (240, for 5 exact modes, whose 400 holds would take
#: minutes) of a continuous torque's (``controllers.design.hold_grid.hold_effort_excess``).
REFERENCE_INTERVALS = (400, 240)
COST_TOLERANCE = 0.01            # relative error of a solved cell against the converged value
END_STATE_TOL = 1e-3             # end state of the re-simulated torque / motion of its kind
REFUSAL_BUDGET = 1.0             # s: a refusal must come sooner
TIME_LIMIT = 900.0               # s of IPOPT per cell (max_wall_time)


def slew_problem(n_intervals):
    slew = flexctl.load_scene("slew-90").maneuver
    return SlewProblem(angle=slew.angle, duration=slew.duration,
                       torque_bound=slew.torque_bound, n_intervals=n_intervals)


def run_cell(model, n_intervals):
    """Solve one cell: a dict with status, cost, wall and CPU time and the message."""
    start, cpu = time.perf_counter(), time.process_time()
    try:
        solution = solve_slew(model, slew_problem(n_intervals),
                              ipopt_options={"max_wall_time": TIME_LIMIT})
    except (ValueError, TrajectoryOptimizationError) as exc:
        kind = "refused" if isinstance(exc, ValueError) or exc.iterations == 0 else "failed"
        return {"status": kind, "message": str(exc), "wall": time.perf_counter() - start,
                "cpu": time.process_time() - cpu}
    return {"status": solution.return_status, "cost": solution.cost,
            "wall": time.perf_counter() - start, "cpu": time.process_time() - cpu,
            "iterations": solution.iterations,
            "steps": solution.discretisation.steps_per_hold,
            "method": solution.discretisation.method, "end_error": end_state_error(solution)}


def end_state_error(solution):
    """Largest error of the state the torque reaches, played into the design model by
    flexctl's error-controlled integrator, relative to the largest motion of its kind
    (angle, modal deflection, hub rate, modal rate) along the optimum."""
    model, n = solution.model, solution.model.n_modes
    reached = flexctl.simulate(model, solution.duration, torque=solution.torque_function(),
                               rtol=1e-10).states[:, -1]
    peak = np.max(np.abs(solution.states), axis=1)
    kinds = [slice(0, 1), slice(1, n + 1), slice(n + 1, n + 2), slice(n + 2, 2 * n + 2)]
    scale = np.concatenate([np.full(k.stop - k.start, peak[k].max()) for k in kinds])
    target = solution.problem.target_state(model.n_states)
    return float(np.max(np.abs(reached - target) / scale))


def converged_cost(model):
    """``(cost, cell)`` on the first of REFERENCE_INTERVALS that is not refused (cost None
    when all are)."""
    for count in REFERENCE_INTERVALS:
        cell = run_cell(model, count)
        if cell["status"] != "refused":
            break
    return cell.get("cost"), cell


def cell_verdict(cell, reference):
    """'ok' (within COST_TOLERANCE of the converged value, or refused within
    REFUSAL_BUDGET), or what is wrong."""
    if cell["status"] == "refused":
        return "ok" if cell["wall"] < REFUSAL_BUDGET else "SLOW REFUSAL"
    if "cost" not in cell:
        return "FAILED"
    if cell["end_error"] > END_STATE_TOL:
        return "END STATE OFF"
    if reference is None:
        return "no reference"
    return "ok" if abs(cell["cost"] / reference - 1) <= COST_TOLERANCE else "OFF OPTIMUM"


def format_cell(cell, reference):
    if cell["status"] == "refused":
        return f"refused {cell['wall']:.2f}s"
    if "cost" not in cell:
        return f"FAILED {cell['wall']:.0f}s"
    error = "" if reference is None else f" {100 * (cell['cost'] / reference - 1):+.2f}%"
    acceptable = "*" if cell["status"] == "Solved_To_Acceptable_Level" else ""
    return f"{cell['cost']:.3f}{acceptable}{error} {cell['wall']:.1f}s/{cell['cpu']:.1f}"


def grid(variants, modes, intervals):
    system = flexctl.load_scene("slew-90").system
    problems = []
    for variant in variants:
        references = " or ".join(map(str, REFERENCE_INTERVALS))
        print(f"\nslew-90 on {variant} design models: cost (N^2 m^2 s), error against the "
              f"converged value ({references} holds), wall/CPU time (s); 'refused' = refused "
              "before IPOPT ran", flush=True)
        print(f"{'modes':>5} {'converged':>14} " + " ".join(f"{k:>25}" for k in intervals))
        refusals, end_errors = [], []
        for n_modes in modes:
            model = build_model(system, n_modes=n_modes, variant=variant)
            reference, ref_cell = converged_cost(model)
            cells = {k: run_cell(model, k) for k in intervals}
            ref_text = f"{reference:.4f}" if reference is not None else ref_cell["status"]
            print(f"{n_modes:>5} {ref_text:>14} " + " ".join(
                f"{format_cell(cells[k], reference):>25}" for k in intervals), flush=True)
            for k in intervals:
                verdict = cell_verdict(cells[k], reference)
                if "end_error" in cells[k]:
                    end_errors.append((cells[k]["end_error"], n_modes, k))
                if cells[k]["status"] == "refused":
                    refusals.append(f"  {n_modes} modes, {k} holds: {cells[k]['message']}")
                if verdict != "ok":
                    problems.append(f"  {variant}, {n_modes} modes, {k} holds: {verdict} "
                                    f"{cells[k]}")
        if end_errors:
            worst = max(end_errors)
            print(f"largest end-state error of the re-simulated torques: {worst[0]:.2e} of the "
                  f"motion of its kind ({worst[1]} modes, {worst[2]} holds); * = IPOPT "
                  "ended 'acceptable'")
        print("refusals:")
        print("\n".join(refusals) or "  none")
    print("\ncells neither within "
          f"{100 * COST_TOLERANCE:g} % of the converged value nor refused within "
          f"{REFUSAL_BUDGET:g} s:")
    print("\n".join(problems) or "  none")


def parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", action="store_true", help="robustness grid (see above)")
    parser.add_argument("--variants", nargs="+", default=list(GRID_VARIANTS))
    parser.add_argument("--modes", nargs="+", type=int, default=list(GRID_MODES))
    parser.add_argument("--intervals", nargs="+", type=int, default=list(GRID_INTERVALS))
    return parser.parse_args(argv)


if __name__ == "__main__":
    args = parse()
    if args.grid:
        grid(args.variants, args.modes, args.intervals)
    else:
        main()
