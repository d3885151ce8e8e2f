"""Cost of the spatial (3-axis) exact model: a motion in one plane against the planar exact
model on the same modes, and a two-array structure slewed about a tilted axis.

(a) Two panels (the two-array scene's, as planar beams at +-90 degrees on a 1.45 kg m^2
    hub) under one period of a 0.5 N m sine torque over 6 s, 10 s simulated: the planar exact
    model (``flexctl.simulate``) and the same structure as a spatial one
    (``SpatialStructure.from_planar``, torque about the hub's z axis) at the same modes per
    field, tolerance and output grid, both with their accuracy checks. Printed: the wall
    times and their ratio (target: the spatial run within 2 times the planar one), the planar
    run at its own default ``atol`` (each state's physical size times rtol: 1.8e-3 m for a
    modal coordinate, that times the first clamped frequency for a rate) and at the spatial
    model's (``rtol * 1e-3`` for every state), the like-for-like comparison.
(b) The two arrays of ``examples/scenes/spatial-two-arrays.toml`` (its hub, with products of
    inertia; 4 modes per field: 27 speeds, torsion and lateral modes up to 3.6e3 rad/s)
    slewed about the tilted axis (0.6, 0, 0.8) by one period of a 0.5 N m sine over 6 s given
    as 1001 torque samples (0.01 s apart, interpolated linearly, as a scene's
    ``torque_samples``), 10 s simulated, on the exact rod and its first_order expansion, each
    on the exponential steps that such a stiff run now takes (:mod:`flexctl.sim.exponential`)
    and on Adams-Moulton (``spatial_run.EXPONENTIAL = False``). Printed: the wall time of the
    run with and without its accuracy check, its integration steps and right-hand-side
    evaluations, its error estimate, and its tip error against a reference run at rtol 1e-11
    (each tip component relative to its own peak, the largest: the definition of
    ``integration_error``). Target: under 1 s.

Every wall time excludes the one-time work: the spatial equations' construction and the
compiling of their right-hand side (some 25 s for (b), kept in the compile cache) happen in
a first run before timing. rtol 1e-8, ``atol`` each model's default.

Measured on two cores shared with other work (load 4 to 6: wall times are noisy, so the
processor times are printed too; ratios repeat within some 20 %):

- Before (Adams-Moulton with functional iteration on the whole model for every run, the
  check after the run): (a) ratio 18.5 on 2 modes, 37.9 on 4 (13 336 evaluations, the
  planar model's compiled Adams-Moulton some 3 500); (b) 18.9 s alone, 33.7 s with the
  check (1.78 times), 110 357 steps, 207 597 evaluations, estimate 7.1e-7, error 6.6e-7.
- After: (a) ratio 3.5 on 2 and on 4 modes, wall and processor alike (2 073 and 6 265
  evaluations: the equations restricted to the plane, ``flexctl.sim.spatial_plane``, with
  Newton's iterations); the whole model on the same motion (``PLANE_MOTION = False``) 10.4
  and 34, the cache's lookup of the compiled right-hand side (0.5 s a run) no longer
  repeated. (b) unchanged: 110 357 steps, 207 597 evaluations, 19.8 s of processor time
  alone, 1.96 times that with the check (it runs beside the run only on a free core, which
  this machine did not have), estimate 7.1e-7, error 6.6e-7. The target of (a) is missed by
  1.75 times, that of (b) by some 20 times.

Measured for (a) with the restriction on the compiled Adams-Moulton steps
(:mod:`flexctl.sim.spatial_adams`), its tips taken on the plane for the check (best of 3):
2 modes, 8 ms against the planar model's 5 ms at its own ``atol`` and 6 ms at the same
(ratios 1.66 and 1.38); 4 modes, 39 ms against 16 and 23 ms (ratios 2.49 and 1.66); another
run of the benchmark: 9 ms against 4 and 5 (2.02 and 1.85), 38 ms against 14 and 22 (2.62 and
1.76): on 2 modes the fixed costs of a run (its plan, the check's tips) weigh. At the
same tolerances the target is met: the runs alone take as many evaluations (4 modes: 5 414
and 5 433), each of the restriction's 1.4 times the planar one's (4.7 against 3.3 us; 17 142
operations against 11 165: rotations in three dimensions along the rod). At its own ``atol``,
1.8 times the spatial one for a modal coordinate and 14 times for a modal rate, the planar
run alone takes 3 374. Before, on CVODES: 27 ms and 90 to 127 ms (ratios 6 and 5 to 9).

Measured for (b) with the exponential steps (rtol 1e-8, the run alone, the best of 2):

- exact: 1.35 s wall (4 329 steps, 18 759 evaluations of some 60 us), error 4.0e-7 (its
  estimate 4.1e-7); with its check 2.54 s wall. Adams-Moulton: 10.65 s (102 655 steps,
  193 939 evaluations), error 6.4e-7 (estimate 7.0e-7). 7.9 times faster, as accurate; the
  target is missed by 1.35 times: the evaluations alone take 1.1 s.
- first_order: **0.67 s** wall (5 621 steps, 24 482 evaluations), error 3.1e-9 (estimate
  2.4e-9); with its check 1.48 s. Adams-Moulton: 2.36 s (100 502 steps), error 6.3e-7.

Then the exact rod's evaluations on ``SpatialEquations.integration_rhs`` (each appendage's
terms one function shared by the two arrays, each node's recursion and section one function:
a library of 0.78 MB against 1.6 MB, which no longer runs from the third-level cache; 30 us
an evaluation against 53, the same numbers to the last bit): exact **0.93 s** wall (0.88 s in
a run of its own), the same 4 329 steps, 18 759 evaluations and error 4.0e-7 (estimate
4.1e-7); with its check 1.84 s. Adams-Moulton 6.48 s. first_order (its own right-hand side,
unchanged) 0.76 s on this run of the benchmark, error 1.3e-8 against its reference (estimate
2.4e-9). In a run of its own (0.88 s) the chains of steps took 0.72 s, of which their 17 316
evaluations some 0.51 s (29.6 us each), the rest their matrix products (14 of 55 x 55 a
step) and the virtual machine's calls; the 13 Jacobians 1 430 evaluations.

Why Adams-Moulton costs what it does on (b): with functional iteration it is held to
``h omega = 0.33`` on the fastest mode (3 609 rad/s, the fourth torsion mode) by the
iteration's convergence: the same 108 000 to 113 000 steps at rtol 1e-4, 1e-6, 1e-8 and
1e-11, at 66 to 117 us an evaluation (134 000 operations). What was measured on it before the
exponential steps, and not kept:

- CVODES's BDF with Newton's iterations on CasADi's Jacobian (finite differences of the
  compiled right-hand side): 69 301 steps, 84 304 evaluations and 7 771 Jacobians, 2 to 4
  times slower, error 6.6e-7; the out-of-plane tolerances loosened 1e4 times: still 54 000 to
  73 000 steps (its orders 3 to 5 amplify the undamped modes they step over), error up to
  5.1e-6; with a Jacobian held over the run: 70 335 steps, 1.6 times less processor time.
- Adams-Moulton with Newton's iterations: 42 178 steps, 50 801 evaluations, but 4 402
  Jacobians of 56 evaluations (slower); with a Jacobian held over the run 39 000 to 44 000
  steps, 2.7 to 3.3 times less processor time, but an error of 1.2e-6 to 1.55e-6.
- SciPy's Radau on the compiled right-hand side with a finite-difference Jacobian: 32 942,
  78 153 and 142 581 evaluations at rtol 1e-6, 1e-7 and 1e-8; SciPy's RK45: 283 514
  evaluations at rtol 1e-8 (stability-bound); DOP853: 119 993.
- ``-O1`` or ``-O2`` for the right-hand side: 67.8 and 68.9 us an evaluation against 66.2 at
  ``-Og`` (best of 6), compiled in 48 and 79 s against 36 s.
- Fewer quadrature nodes per rod: 2 panels of 7 or 6 points instead of 9 take 24 % and 35 %
  fewer operations, tips 1.7e-8 and 8.2e-8 of their peaks from 4 panels of 9 (the rule used:
  1.7e-8), but the rule is the planar exact model's, so that a motion in one plane is that
  model's to round-off (``tests/model/test_spatial_model.py``): kept.

On the exponential steps, measured and not kept: the error estimate of the embedded
third-order solution (6 560 steps, error 7e-8 on (b), but 3.8e-5 on a free-hub rod at rtol
1e-8 where Adams-Moulton gave 1.1e-6: it missed the true local error by 1e4 to 1e5); step
doubling (11 evaluations for two steps; with the modal rates weighed by their frequency
1.17 s but an error of 1.5e-5, by its square root 1.85 s and 6.7e-7); CVODES's plain weights
(24 375 steps, 106 158 evaluations, 8.0 s, error 3.7e-8: a torsion mode's rate, moving some
1e-9 rad/s, held the steps); the Jacobian every 64, 128 or 1 024 steps instead of 256
(4 187, 4 280 and 4 798 steps: the same time).

(c) Three-axis slews through wheels, sensors and filters at 10 Hz: the 60 s slew of
    ``examples/scenes/spatial-lqg-slew.toml`` (two damped arrays, exact model on 2 modes per
    field, three wheels, star tracker, gyro, attitude filter), flown by each controller kind
    of a spatial scene: quaternion feedback (bandwidth 0.5 rad/s, damping 0.9, with the
    sensors), the LQR (on the true state: no sensors) and the LQG (with the sensors), all
    limited to 0.1 N m per axis. Printed per kind: the wall time of the run (target: under
    5 s), the pointing error at the end, the residual vibration (the largest tip displacement
    over the last 30 s), the peak wheel speed and power, and the torque used
    (``int |u|_1 dt``); each metric's error is its change when the run's tolerance is
    divided by 100.

Run: ``python benchmarks/bench_spatial.py [--loops-only]`` (prints measured wall times and
ratios; the best of ``REPEATS`` runs, of 2 for the long runs of (b)).
"""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path

import numpy as np

from bench_exact import REPEATS
import flexctl
from flexctl import Appendage, Beam, Hub, SineTorque, Structure, build_model, simulate
from flexctl.app.spatial_scene import SpatialSine
from flexctl.model.spatial_structure import SpatialStructure
from flexctl.sim import spatial_run
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial

RTOL = 1e-8
T_FINAL = 10.0
STEP = 0.01
PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=5.2083e-10,
             youngs_modulus=6.9e10)
AXIS = np.array([0.6, 0.0, 0.8])
SCENE = Path(__file__).resolve().parent.parent / "examples" / "scenes" / "spatial-two-arrays.toml"
REFERENCE_RTOL = 1e-11


def timed(func, repeats=REPEATS):
    """``(wall, cpu, value)``: the least wall and processor times (s) of ``repeats`` calls
    (processor time counts every thread of the process: an accuracy check beside the run
    included) and the last call's value."""
    walls, cpus, value = [], [], None
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        value = func()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus), value


def planar_rows():
    planar = Structure(hub=Hub(inertia=1.45, radius=0.06), appendages=(
        Appendage(name="wing_a", beam=PANEL, angle=math.pi / 2),
        Appendage(name="wing_b", beam=PANEL, angle=-math.pi / 2)))
    spatial = SpatialStructure.from_planar(planar)
    print(f"(a) motion in one plane, {T_FINAL:g} s, rtol {RTOL:g}, with accuracy checks "
          f"(best of {REPEATS}; wall and processor time, s): the planar model at its own "
          f"default atol (each state's physical size) and at the spatial model's "
          f"(rtol * 1e-3 for every state)")
    print(f"{'':5s} {'planar (own atol)':>20s} | {'planar (same atol)':>20s} | "
          f"{'spatial (in its plane)':>34s} | {'spatial (whole model)':>27s} |")
    print(f"{'modes':>5s} {'wall':>6s} {'cpu':>6s} {'evals':>6s} | {'wall':>6s} {'cpu':>6s} "
          f"{'evals':>6s} | {'wall':>6s} {'cpu':>6s} {'evals':>6s} {'ratio':>6s} {'same':>6s} | "
          f"{'wall':>6s} {'cpu':>6s} {'ratio':>6s} {'evals':>6s} | {'tip diff':>9s}")
    for n_modes in (2, 4):
        model = build_model(planar, n_modes, "exact")
        model.geometry                                # quadrature chosen before timing

        def run_planar(atol=None, model=model):
            return simulate(model, T_FINAL, torque=SineTorque(peak_torque=0.5, duration=6.0),
                            rtol=RTOL, atol=atol, output_step=STEP)

        def run_spatial(n_modes=n_modes):
            return simulate_spatial(spatial, T_FINAL, SpatialSine([0.0, 0.0, 0.5], 6.0),
                                    n_modes=n_modes, rtol=RTOL, output_step=STEP)

        run_planar(), run_planar(RTOL * 1e-3)         # build and compile before timing
        times = {"planar": timed(run_planar), "same": timed(lambda: run_planar(RTOL * 1e-3))}
        for restricted in (True, False):
            spatial_run.PLANE_MOTION = restricted
            run_spatial()
            times[restricted] = timed(run_spatial)
        spatial_run.PLANE_MOTION = True
        planar_result, spatial_result = times["planar"][2], times[True][2]
        # wing_a's tip deflection along its normal, the hub's -x
        tip_s = -spatial_result.tips["wing_a"][0]
        tip_p = planar_result.tip_deflections["wing_a"]
        assert np.allclose(spatial_result.t, planar_result.t, rtol=0.0, atol=1e-12)
        difference = float(np.max(np.abs(tip_s - tip_p)) / np.max(np.abs(tip_p)))
        row = f"{n_modes:5d}"
        for key in ("planar", "same"):
            wall, cpu, result = times[key]
            row += f" {wall:6.3f} {cpu:6.3f} {result.n_evaluations:6d} |"
        wall, cpu, result = times[True]
        row += (f" {wall:6.3f} {cpu:6.3f} {result.n_evaluations:6d} "
                f"{wall / times['planar'][0]:6.2f} {wall / times['same'][0]:6.2f} |")
        wall, cpu, result = times[False]
        row += (f" {wall:6.3f} {cpu:6.3f} {wall / times['planar'][0]:6.1f} "
                f"{result.n_evaluations:6d} |")
        print(row + f" {difference:9.2e}")
    print("  (ratio, same: the spatial run's wall time to the planar run's at its own and at the "
          "same atol; evals: the planar model's count its check's too, the spatial model's the "
          "run's alone; tip diff: wing_a's deflection in the plane from the planar model's, "
          "relative to its peak)")


def slew_torque() -> VectorTorque:
    times = np.linspace(0.0, T_FINAL, round(T_FINAL / STEP) + 1)
    magnitude = np.where(times < 6.0, 0.5 * np.sin(2.0 * np.pi * times / 6.0), 0.0)
    return VectorTorque(times, np.outer(magnitude, AXIS / np.linalg.norm(AXIS)))


def relative_tip_error(result, reference) -> float:
    """Largest tip difference, each component relative to its own peak."""
    worst = 0.0
    for name, tips in reference.tips.items():
        peaks = np.maximum(np.max(np.abs(tips), axis=1), 1e-12)
        worst = max(worst, float(np.max(np.max(np.abs(result.tips[name] - tips), axis=1)
                                        / peaks)))
    return worst


def slew_rows():
    scene = flexctl.load_scene(SCENE)
    arrays = SpatialStructure(hub=scene.structure.hub, appendages=scene.structure.appendages[:2])
    torque = slew_torque()
    print(f"\n(b) two arrays, 4 modes per field, {T_FINAL:g} s tilted slew from "
          f"{torque.times.size} torque samples (best of 2; wall and processor time, s; error: "
          f"each tip component's largest difference from a run at rtol {REFERENCE_RTOL:g}, "
          f"relative to its peak):")
    for variant in ("exact", "first_order"):
        def run(check, rtol=RTOL, variant=variant):
            return simulate_spatial(arrays, T_FINAL, torque, n_modes=4, rtol=rtol,
                                    output_step=STEP, check_accuracy=check, variant=variant)

        run(False)                                    # build and compile before timing
        reference = run(False, REFERENCE_RTOL)
        for exponential in (True, False):
            spatial_run.EXPONENTIAL = exponential
            wall_bare, cpu_bare, bare = timed(lambda: run(False), 2)
            wall_check, cpu_check, checked = timed(lambda: run(True), 2)
            label = "exponential steps" if exponential else "Adams-Moulton"
            print(f"  {variant:11s} {label:17s} rtol {RTOL:g}: alone {wall_bare:6.2f} wall "
                  f"{cpu_bare:6.2f} cpu, with its check {wall_check:6.2f} wall "
                  f"{cpu_check:6.2f} cpu; steps {bare.n_steps:7d}, evaluations "
                  f"{bare.n_evaluations:7d}; estimate {checked.integration_error:.2e}, error "
                  f"{relative_tip_error(bare, reference):.2e} (target: under 1 s alone)",
                  flush=True)
        spatial_run.EXPONENTIAL = True


LOOP_SCENE = SCENE.parent / "spatial-lqg-slew.toml"
LOOP_KINDS = {
    "quaternion feedback": {"controller": {"kind": "quaternion_feedback", "sample_time": 0.1,
                                           "slew_axis": [0.6, 0.0, 0.8], "slew_angle": 20.0,
                                           "bandwidth": 0.5, "damping": 0.9,
                                           "torque_limit": 0.1}},
    "LQR (true state)": {"drop_sensors": True},
    "LQG": {},
}


def _loop_metrics(result, target) -> dict:
    from flexctl.sim.quaternions import error_angles

    tips = np.array([np.linalg.norm(v, axis=0) for v in result.tips.values()])
    late = result.t >= result.t[-1] - 30.0
    step = np.diff(result.t, prepend=result.t[0])
    return {"pointing (rad)": float(np.linalg.norm(error_angles(target,
                                                               result.states[0:4, -1]))),
            "residual (mm)": 1e3 * float(np.max(tips[:, late])),
            "wheel speed (rad/s)": float(np.max(np.abs(result.wheel_speeds))),
            "wheel power (W)": float(np.max(result.wheel_power)),
            "torque used (N m s)": float(np.sum(np.abs(result.torque) * step))}


def _loop_scene(base: dict, label: str, change: dict):
    import copy

    from flexctl.app.spatial_scene import parse_spatial_scene

    data = copy.deepcopy(base)
    if change.get("drop_sensors"):
        data.pop("sensors")
        data["controller"]["kind"] = "lqr"
        for key in ("angle_noise", "rate_noise", "process_torque"):
            data["controller"].pop(key)
    data.update({k: v for k, v in change.items() if k != "drop_sensors"})
    return parse_spatial_scene(data, name=label, base_dir=LOOP_SCENE.parent)


def loop_rows():
    import dataclasses
    import tomllib

    from flexctl.app.spatial_report import run_spatial_scene
    from flexctl.sim.quaternions import from_rotation_vector, product

    base = tomllib.loads(LOOP_SCENE.read_text())
    base["simulation"]["t_final"] = 60.0
    print("\n(c) 60 s three-axis slew (20 deg about (0.6, 0, 0.8)) at 10 Hz through three "
          "wheels, exact model, 2 modes per field; metric (error: its change at rtol / 100)")
    for label, change in LOOP_KINDS.items():
        scene = _loop_scene(base, label, change)
        target = product(scene.quaternion,
                         from_rotation_vector(np.radians(20.0) * AXIS / np.linalg.norm(AXIS)))
        run_spatial_scene(scene)                          # compile before timing
        wall, _, result = timed(lambda: run_spatial_scene(scene), 2)
        tight = run_spatial_scene(dataclasses.replace(scene, rtol=scene.rtol / 100))
        metrics, errors = _loop_metrics(result, target), _loop_metrics(tight, target)
        cells = ", ".join(f"{k} {v:.3g} (+-{abs(v - errors[k]):.1g})"
                          for k, v in metrics.items())
        print(f"  {label:22s} {result.status}, {wall:5.2f} s wall (target 5 s): {cells}",
              flush=True)


if __name__ == "__main__":
    import sys

    warnings.simplefilter("ignore")
    start = time.perf_counter()
    if "--loops-only" in sys.argv[1:]:
        loop_rows()
        raise SystemExit(0)
    planar_rows()
    slew_rows()
    loop_rows()
    print(f"\n(benchmark took {time.perf_counter() - start:.0f} s)")
