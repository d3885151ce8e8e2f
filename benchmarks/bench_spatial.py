"""Cost of the spatial (3-axis) exact model: a motion in one plane against the planar exact
model on the same modes, and a two-array structure slewed about a tilted axis.

(a) Two panels (the two-array scene's, as planar beams at +-90 degrees on a 1.45 kg m^2
    hub) under one period of a 0.5 N m sine torque over 6 s, 10 s simulated: the planar exact
    model (``flexctl.simulate``) and the same structure as a spatial one
    (``SpatialStructure.from_planar``, torque about the hub's z axis) at the same modes per
    field, tolerance and output grid, both with their accuracy checks. Printed: the wall
    times and their ratio (target: the spatial run within 2 times the planar one).
(b) The two arrays of ``examples/scenes/spatial-two-arrays.toml`` (its hub, with products of
    inertia; 4 modes per field: 27 speeds, torsion and lateral modes up to 3.6e3 rad/s)
    slewed about the tilted axis (0.6, 0, 0.8) by one period of a 0.5 N m sine over 6 s given
    as 1001 torque samples (0.01 s apart, interpolated linearly, as a scene's
    ``torque_samples``), 10 s simulated. Printed: the wall time of the run with and without
    its accuracy check, its integration steps and right-hand-side evaluations, its error
    estimate, and its tip error against a reference run at rtol 1e-11 (each tip component
    relative to its own peak, the largest: the definition of ``integration_error``).
    Target: under 1 s.

Every wall time excludes the one-time work: the spatial equations' construction and the
compiling of their right-hand side (some 25 s for (b), kept in the compile cache) happen in
a first run before timing. rtol 1e-8, ``atol`` each model's default.

Measured (two shared cores, so wall times are noisy; CVODES Adams-Moulton with functional
iteration on the whole spatial model): (a) ratio 18.5 on 2 modes, 37.9 on 4 (13 336
evaluations against the planar model's compiled Adams-Moulton's some 3 500); (b) 18.9 s
alone, 33.7 s with the check (1.78 times), 110 357 steps, 207 597 evaluations, estimate
7.1e-7, error 6.6e-7: the steps are bounded by the stability of the Adams steps on the
torsion and lateral modes (the same 108 000 to 113 000 steps at rtol 1e-4 and 1e-6).

Run: ``python benchmarks/bench_spatial.py`` (prints measured wall times and ratios; the best
of ``REPEATS`` runs, of 2 for the long runs of (b)).
"""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path

import numpy as np

from bench_exact import REPEATS, best_of
import flexctl
from flexctl import Appendage, Beam, Hub, SineTorque, Structure, build_model, simulate
from flexctl.app.spatial_scene import SpatialSine
from flexctl.model.spatial_structure import SpatialStructure
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial

RTOL = 1e-8
T_FINAL = 10.0
STEP = 0.01
PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=5.2083e-10,
             youngs_modulus=6.9e10)
AXIS = np.array([0.6, 0.0, 0.8])
SCENE = Path(__file__).resolve().parent.parent / "examples" / "scenes" / "spatial-two-arrays.toml"
REFERENCE_RTOL = 1e-11


def planar_rows():
    planar = Structure(hub=Hub(inertia=1.45, radius=0.06), appendages=(
        Appendage(name="wing_a", beam=PANEL, angle=math.pi / 2),
        Appendage(name="wing_b", beam=PANEL, angle=-math.pi / 2)))
    spatial = SpatialStructure.from_planar(planar)
    print(f"(a) motion in one plane, {T_FINAL:g} s, rtol {RTOL:g}, with accuracy checks "
          f"(best of {REPEATS}):")
    print(f"{'modes':>5s} {'planar s':>9s} {'spatial s':>10s} {'ratio':>6s} "
          f"{'spatial evals':>13s} {'tip difference':>15s}")
    for n_modes in (2, 4):
        model = build_model(planar, n_modes, "exact")
        model.geometry                                # quadrature chosen before timing

        def run_planar(model=model):
            return simulate(model, T_FINAL, torque=SineTorque(peak_torque=0.5, duration=6.0),
                            rtol=RTOL, output_step=STEP)

        def run_spatial(n_modes=n_modes):
            return simulate_spatial(spatial, T_FINAL, SpatialSine([0.0, 0.0, 0.5], 6.0),
                                    n_modes=n_modes, rtol=RTOL, output_step=STEP)

        run_planar(), run_spatial()                   # build and compile before timing
        wall_p, planar_result = best_of(run_planar)
        wall_s, spatial_result = best_of(run_spatial)
        # wing_a's tip deflection along its normal, the hub's -x
        tip_s = -spatial_result.tips["wing_a"][0]
        tip_p = planar_result.tip_deflections["wing_a"]
        assert np.allclose(spatial_result.t, planar_result.t, rtol=0.0, atol=1e-12)
        difference = float(np.max(np.abs(tip_s - tip_p)) / np.max(np.abs(tip_p)))
        print(f"{n_modes:5d} {wall_p:9.3f} {wall_s:10.3f} {wall_s / wall_p:6.1f} "
              f"{spatial_result.n_evaluations:13d} {difference:15.2e}")


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

    def run(check, rtol=RTOL):
        return simulate_spatial(arrays, T_FINAL, torque, n_modes=4, rtol=rtol,
                                output_step=STEP, check_accuracy=check)

    run(False)                                        # build and compile before timing
    reference = run(False, REFERENCE_RTOL)
    wall_bare, bare = best_of(lambda: run(False), 2)
    wall_check, checked = best_of(lambda: run(True), 2)
    print(f"\n(b) two arrays, 4 modes per field, {T_FINAL:g} s tilted slew from "
          f"{torque.times.size} torque samples, rtol {RTOL:g} (best of 2):")
    print(f"  run alone            {wall_bare:8.2f} s   steps {bare.n_steps:7d}   "
          f"evaluations {bare.n_evaluations:7d}")
    print(f"  with accuracy check  {wall_check:8.2f} s   (ratio {wall_check / wall_bare:.2f} to "
          f"the run alone)")
    print(f"  error estimate {checked.integration_error:.2e}, error against rtol "
          f"{REFERENCE_RTOL:g}: {relative_tip_error(bare, reference):.2e} of each component's "
          f"peak")


if __name__ == "__main__":
    warnings.simplefilter("ignore")
    start = time.perf_counter()
    planar_rows()
    slew_rows()
    print(f"\n(benchmark took {time.perf_counter() - start:.0f} s)")
