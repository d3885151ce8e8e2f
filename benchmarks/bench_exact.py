"""Cost of exact geometry: the exact variant against first_order on the same scene, modes and
tolerance, for simulation and for trajectory optimisation; and what ``variant = "auto"`` pays.

Run: ``python benchmarks/bench_exact.py`` (prints measured wall times and ratios; the best of
``REPEATS`` runs, each model built and its exact quadrature chosen before timing).
"""

from __future__ import annotations

import time
import warnings

import flexctl
from flexctl import SineTorque, SpinUp, build_model, simulate
from flexctl.sim.validity import choose_variant

REPEATS = 3
RTOL = 1e-8


def best_of(func, repeats=REPEATS):
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = func()
        times.append(time.perf_counter() - start)
    return min(times), value


def simulation_rows():
    cases = [
        ("kane-spinup 10 rad/s", "kane-spinup", 20.0,
         {"hub_motion": SpinUp(spin_rate=10.0, ramp_time=15.0)}),
        ("spacecraft (massless hub)", "spacecraft-torque", 6.0,
         {"torque": SineTorque(peak_torque=50.0, duration=2.0)}),
        ("hub-beam-mass", "hub-beam-mass", 6.0,
         {"torque": SineTorque(peak_torque=2.0, duration=2.0)}),
    ]
    print(f"\nSimulation, rtol {RTOL:g}, compiled path with its accuracy check (best of "
          f"{REPEATS}):")
    print(f"{'case':28s} {'modes':>5s} {'first_order s':>14s} {'exact s':>9s} {'ratio':>6s} "
          f"{'peak fo m':>10s} {'peak ex m':>10s}")
    for label, scene, t_final, drive in cases:
        system = flexctl.load_scene(scene).system
        for n_modes in (2, 4, 6):
            walls, peaks = {}, {}
            for variant in ("first_order", "exact"):
                model = build_model(system, n_modes, variant)
                if model.geometry is not None:
                    model.geometry                 # quadrature chosen before timing
                wall, result = best_of(lambda: simulate(model, t_final, rtol=RTOL, **drive))
                walls[variant], peaks[variant] = wall, result.peak_tip_deflection
            print(f"{label:28s} {n_modes:5d} {walls['first_order']:14.3f} {walls['exact']:9.3f} "
                  f"{walls['exact'] / walls['first_order']:6.1f} {peaks['first_order']:10.5f} "
                  f"{peaks['exact']:10.5f}")


def trajopt_rows():
    from controllers.slew.trajopt import SlewProblem, solve_slew, transcription_for

    scene = flexctl.load_scene("slew-90")
    slew = scene.maneuver
    problem = SlewProblem(angle=slew.angle, duration=slew.duration,
                          torque_bound=slew.torque_bound)
    print("\nTrajectory optimisation of slew-90 (40 holds, IPOPT, each variant's default "
          f"transcription), best of {REPEATS}:")
    walls = {}
    for n_modes in (1, 2):
        for variant in ("first_order", "exact"):
            model = build_model(scene.system, n_modes, variant)
            wall, solution = best_of(lambda: solve_slew(model, problem))
            walls[variant] = wall
            print(f"  {variant:12s} {n_modes} modes, {transcription_for(problem, model)}: "
                  f"{wall:6.2f} s, {solution.iterations} "
                  f"iterations, cost {solution.cost:.5g}, {solution.return_status}")
        print(f"  ratio exact / first_order at {n_modes} modes: "
              f"{walls['exact'] / walls['first_order']:.1f}")


def auto_rows():
    print("\nvariant = \"auto\" (the 2-mode first_order/exact comparison it runs):")
    for label, scene, drive, t_final in (
            ("hub-beam-mass, 0.2 N m", "hub-beam-mass", SineTorque(peak_torque=0.2, duration=2),
             6.0),
            ("hub-beam-mass, 2 N m", "hub-beam-mass", SineTorque(peak_torque=2.0, duration=2),
             6.0),
            ("slew-90 rigid torque", "slew-90", None, 6.0)):
        sc = flexctl.load_scene(scene)
        maneuver = drive or sc.maneuver
        start = time.perf_counter()
        choice = choose_variant(sc.system, maneuver, 1e-2, t_final=t_final)
        print(f"  {label:24s} -> {choice.variant:11s} in {time.perf_counter() - start:5.2f} s: "
              f"{choice.explanation}")


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    simulation_rows()
    trajopt_rows()
    auto_rows()
