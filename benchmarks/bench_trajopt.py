"""Benchmark ``slew-90``: :func:`controllers.trajopt.solve_slew` against python-control.

Case: the hub-beam-mass system on 2 modes (first_order), a 90 degree rest-to-rest slew in
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

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import control                                    # noqa: E402
import control.optimal as opt                     # noqa: E402

import flexctl                                    # noqa: E402
from controllers.trajopt import HoldTorque, SlewProblem, solve_slew   # noqa: E402

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
    tip_error = design.matrices.tip @ error[1:design.n_modes + 1]
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
    print(f"\nsolve_slew (CasADi Opti + IPOPT, multiple shooting RK4, {problem.substeps or "auto"} substeps):")
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


if __name__ == "__main__":
    main()
