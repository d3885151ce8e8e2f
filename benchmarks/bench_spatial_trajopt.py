"""The three-axis slew planned by :func:`controllers.slew.spatial_trajopt.solve_spatial_slew`
against python-control's ``solve_ocp`` on the same problem.

Case: two damped arrays on a pinned hub (the structure of ``examples/scenes/spatial-lqg-slew.toml``),
one mode per field (six modes, 18 design states and the quaternion), slewed 20 degrees about
(0.6, 0, 0.8) in 12 s, ``|torque| <= 0.08`` N m per axis, least effort ``sum h |tau|^2``, rest at
the target at the end, the same ``--holds`` holds for both. python-control gets the same
discrete-time model: a ``NonlinearIOSystem`` with ``dt`` the hold whose update is the plan's own
hold map (a compiled CasADi function), the same cost, the input bounds and the terminal state as
a constraint, and the same first guess (the rigid seventh-order eigenaxis slew); it solves by
shooting with SLSQP and finite-difference gradients (python-control 0.10's default for a
discrete-time system).

Each torque is judged the same way: its cost, and flown open loop (held) on the first_order
spatial model (CVODES, 1e-10) the pointing error and the largest tip deflection after the slew.

Run: ``python benchmarks/bench_spatial_trajopt.py [--holds 20]`` (python-control dominates).
"""

from __future__ import annotations

import argparse
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from controllers.slew import spatial_trajopt as st  # noqa: E402
from flexctl.app.spatial_scene import parse_spatial_scene  # noqa: E402
from flexctl.sim.quaternions import conjugate, error_angles, from_rotation_vector, product  # noqa: E402
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial  # noqa: E402

DURATION, LIMIT = 12.0, 0.08


def _judge(structure, target, torques, holds):
    times = np.linspace(0.0, DURATION, holds + 1)
    run = simulate_spatial(structure, DURATION + 4.0,
                           VectorTorque(times, np.vstack([torques, np.zeros((1, 3))]), "hold"),
                           n_modes=1, variant="first_order", rtol=1e-10, output_step=0.01,
                           check_accuracy=False)
    end = int(np.argmin(np.abs(run.t - DURATION)))
    late = run.t > DURATION
    return (float(np.linalg.norm(error_angles(target, run.quaternion[:, end]))),
            max(float(np.max(np.abs(tip[:, late]))) for tip in run.tips.values()))


def _python_control(structure, problem, holds):
    import control
    import control.optimal as opt
    from scipy.optimize import NonlinearConstraint

    model = st.spatial_hold_model(structure, 1, "first_order", DURATION / holds)
    step = st.hold_functions(model, None)
    n = model.a.shape[0]

    def update(t, x, u, params):
        nxt = step.advance(x[:n], x[n:], np.zeros(0), u)
        return np.concatenate([np.asarray(nxt[0]).ravel(), np.asarray(nxt[1]).ravel()])

    system = control.nlsys(update, None, states=n + 4, inputs=3, outputs=n + 4,
                           dt=DURATION / holds)
    x0 = np.concatenate([np.zeros(n), problem.start])
    target_state = np.concatenate([np.zeros(n), problem.target])

    def terminal(x, u):
        miss = product(conjugate(problem.target), x[n:])
        return np.concatenate([x[:n], miss[1:4]])

    torque, xs, qs, _ = st._rigid_guess(problem, model, step)
    h = DURATION / holds
    cost = lambda x, u: h * float(u @ u)                       # noqa: E731
    timepts = np.linspace(0.0, DURATION, holds + 1)
    guess = np.hstack([torque.T, torque[-1:].T])
    began = time.perf_counter()
    result = opt.solve_ocp(
        system, timepts, x0, cost, [opt.input_range_constraint(system, [-LIMIT] * 3,
                                                               [LIMIT] * 3)],
        terminal_constraints=[(NonlinearConstraint, terminal, np.zeros(n + 3),
                               np.zeros(n + 3))],
        initial_guess=guess, minimize_method="SLSQP",
        minimize_options={"maxiter": 2000})
    elapsed = time.perf_counter() - began
    del target_state
    return result, elapsed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--holds", type=int, default=20)
    args = parser.parse_args(argv)
    scene = tomllib.loads((ROOT / "examples/scenes/spatial-lqg-slew.toml").read_text())
    structure = parse_spatial_scene(scene).structure
    target = from_rotation_vector(np.radians(20.0) * np.array([0.6, 0.0, 0.8]))
    problem = st.SpatialSlewProblem(target=target, duration=DURATION, n_intervals=args.holds,
                                    torque_limit=LIMIT, torque_margin=1.0)
    began = time.perf_counter()
    st.solve_spatial_slew(structure, problem, n_modes=1)    # builds the remainder once
    first = time.perf_counter() - began
    began = time.perf_counter()
    plan = st.solve_spatial_slew(structure, problem, n_modes=1)
    ours = time.perf_counter() - began
    result, theirs = _python_control(structure, problem, args.holds)
    h = DURATION / args.holds
    their_torque = np.asarray(result.inputs).T[:args.holds]
    rows = [("solve_spatial_slew", ours, plan.cost, plan.return_status, plan.torque),
            ("control.optimal.solve_ocp", theirs, h * float(np.sum(their_torque ** 2)),
             f"success={result.success}", their_torque)]
    print(f"{args.holds} holds of {h:g} s, |torque| <= {LIMIT} N m, one mode per field")
    print(f"{'solver':28s} {'wall s':>8s} {'cost':>10s} {'pointing rad':>13s} "
          f"{'residual m':>11s}  status")
    for name, wall, cost, status, torque in rows:
        pointing, residual = _judge(structure, target, torque, args.holds)
        print(f"{name:28s} {wall:8.3f} {cost:10.6f} {pointing:13.2e} {residual:11.2e}  {status}")
    print(f"python-control / flexctl wall time: {theirs / ours:.0f} (flexctl's first call, "
          f"which builds the model's remainder and loads its compiled library: {first:.2f} s, "
          f"ratio {theirs / first:.0f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
