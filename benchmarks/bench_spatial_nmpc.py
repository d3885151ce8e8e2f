"""The three-axis NMPC's step (:mod:`controllers.mpc.spatial_nmpc`) in a closed-loop slew.

Case: the two damped arrays of ``examples/scenes/spatial-lqg-slew.toml`` through its three
orthogonal wheels, a 20 degree step about (0.6, 0, 0.8) (or a planned 12 s slew with
``--planned``), the NMPC at 0.1 s with a horizon of 20 on ``--modes`` modes per field, flown on
the exact rod with two modes per field for 20 s. Prints the median and largest step (wall time
of the session's call), the failed steps, the pointing error and the residual vibration.

Run: ``python benchmarks/bench_spatial_nmpc.py [--modes 1] [--planned]``.
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

from controllers.feedback.lqr import LQRWeights  # noqa: E402
from controllers.mpc.spatial_nmpc import design_spatial_nmpc  # noqa: E402
from controllers.slew.spatial_trajopt import SpatialSlewProblem, solve_spatial_slew  # noqa: E402
from flexctl.app.spatial_scene import parse_spatial_scene  # noqa: E402
from flexctl.sim.quaternions import error_angles, from_rotation_vector  # noqa: E402
from flexctl.sim.spatial_loop import simulate_spatial_loop  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=int, default=1)
    parser.add_argument("--horizon", type=int, default=20)
    parser.add_argument("--planned", action="store_true")
    args = parser.parse_args(argv)
    scene = parse_spatial_scene(tomllib.loads(
        (ROOT / "examples/scenes/spatial-lqg-slew.toml").read_text()))
    target = from_rotation_vector(np.radians(20.0) * np.array([0.6, 0.0, 0.8]))
    weights = LQRWeights(hub_angle=0.05, hub_rate=0.05, tip_deflection=0.005, torque=0.1)
    plan = None
    if args.planned:
        plan = solve_spatial_slew(scene.structure, SpatialSlewProblem(
            target=target, duration=12.0, n_intervals=120, wheels=scene.wheels),
            n_modes=args.modes)
    began = time.perf_counter()
    law = design_spatial_nmpc(scene.structure, weights, None if plan else target, 0.1,
                              horizon=args.horizon, n_modes=args.modes, wheels=scene.wheels,
                              reference=plan)
    design = time.perf_counter() - began
    began = time.perf_counter()
    loop = simulate_spatial_loop(scene.structure, 20.0, law, sample_time=0.1, n_modes=2,
                                 variant="exact", wheels=scene.wheels, rtol=1e-8)
    flight = time.perf_counter() - began
    run, steps = loop.result, 1e3 * np.array(loop.session.step_times)
    end = int(np.argmin(np.abs(run.t - 12.0)))
    late = run.t > 12.0
    print(f"modes per field {args.modes}, horizon {args.horizon}, "
          f"{'planned 12 s slew' if plan else 'step'}; design {design:.2f} s, flight "
          f"{flight:.1f} s ({loop.ok and 'ok'})")
    print(f"step median {np.median(steps):.2f} ms, largest {steps.max():.2f} ms, "
          f"failed {loop.session.failed_steps} of {steps.size}")
    print(f"pointing at 12 s {np.linalg.norm(error_angles(target, run.quaternion[:, end])):.2e} "
          f"rad, at 20 s {np.linalg.norm(error_angles(target, run.quaternion[:, -1])):.2e} rad; "
          f"residual tip after 12 s "
          f"{max(np.max(np.abs(t[:, late])) for t in run.tips.values()):.2e} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
