"""Benchmark: the compiled fixed-step path (``method="rk4"``) and sampled controllers.

Case A, issue 9 item 5: the Kane spin-up (``kane-spinup``, 4 rad/s in 15 s, 30 s) on 2, 3 and
4 modes, end to end through ``flexctl.simulate`` from a built model, second and later runs
(the compiled loop is cached after the first). Error: largest difference of the tip deflection
from a converged reference (8 modes, CVODES at rtol 1e-10), relative to its peak; also the
run's own estimate (``integration_error``, step doubling) against its actual integration error
(the same model converged). Beside it CVODES at rtol 1e-4 and 1e-6 on the same model.
Target: 2 modes within 1 % of the converged history in at most 2.5 ms.

Case A2: the same spin-up on the exact variant with ``method="rk4"``, against first_order's,
without the validity estimate.

Case B, digital control (issue 9 item 3): ``slew-90``'s system, 6-mode first_order plant,
``PD(kp=12, kd=8, torque_limit=6)`` from 90 deg off target, 6 s, sampled at 100 Hz with a
zero-order hold (``ZeroOrderHold``): the CVODES sample-to-sample path against the
Dormand-Prince one (``RK45``, what ``method="auto"`` takes for this plant) and the rk4 one,
their wall time per sample and their error against a tight run.

Case C, sampled loops: CVODES from sample to sample against the Dormand-Prince pair
(``method="RK45"``, :mod:`flexctl.sim.embedded_rk`) on plants of 6 to 30 modes under a PD law
at 100 Hz, rtol 1e-8, no validity estimate: wall time per sample, and each run's error
against CVODES at rtol 1e-12 beside its own estimate.

Run: ``python benchmarks/bench_fixed_step.py [--repeats 20] [--only-c]``. Nothing is asserted; the script
prints what it measures (and the load of the machine, which shares its two cores).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controllers import PD                                   # noqa: E402
from flexctl import build_model, load_scene, simulate        # noqa: E402
from flexctl.sim.digital import ZeroOrderHold                # noqa: E402

TARGET_MS = 2.5


def timed(run, repeats):
    """``(result, best s, median s)`` of ``repeats`` calls after one warm-up call."""
    result = run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return result, min(times), float(np.median(times))


def case_a(repeats):
    scene = load_scene("kane-spinup")
    motion = scene.maneuver
    reference = simulate(build_model(scene.system, n_modes=8), 30.0, hub_motion=motion,
                         rtol=1e-10)
    peak = reference.peak_tip_deflection
    print("## A. Kane spin-up, 30 s, end to end from a built model (second and later runs)\n")
    print("| modes | method | rtol | best (ms) | median (ms) | error vs converged | "
          "estimated integration error | actual integration error |")
    print("|---|---|---|---|---|---|---|---|")
    verdict = None
    for n_modes in (2, 3, 4):
        model = build_model(scene.system, n_modes=n_modes)
        tight = simulate(model, 30.0, hub_motion=motion, rtol=1e-11)
        for method, rtol in (("rk4", None), ("cvodes", 1e-4), ("cvodes", 1e-6)):
            def run():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    return simulate(model, 30.0, hub_motion=motion, method=method, rtol=rtol)
            result, best, median = timed(run, repeats)
            error = np.max(np.abs(result.tip_deflection - reference.tip_deflection)) / peak
            actual = np.max(np.abs(result.tip_deflection - tight.tip_deflection)) / peak
            estimate = ("-" if result.integration_error is None
                        else f"{result.integration_error / peak:.2g}")
            print(f"| {n_modes} | {method} | {result.rtol:g} | {1e3 * best:.3g} | "
                  f"{1e3 * median:.3g} | {error:.2%} | {estimate} | {actual:.2g} |")
            if n_modes == 2 and method == "rk4":
                verdict = (error <= 0.01 and 1e3 * median <= TARGET_MS, error, median, best)
    ok, error, median, best = verdict
    print(f"\nTarget (2 modes, rk4, within 1 % in at most {TARGET_MS} ms): "
          f"{'PASS' if ok else 'MISS'} (error {error:.2%}, median {1e3 * median:.3g} ms, "
          f"best {1e3 * best:.3g} ms)\n")


def case_a_exact(repeats):
    """The same spin-up on the exact variant with ``method="rk4"`` (its RK4 step compiled,
    :func:`flexctl.sim.fixed_step._exact_step`) against first_order's, without the validity
    estimate (which the exact variant does not need), and its actual integration error
    against a tight CVODES run of the same model."""
    scene = load_scene("kane-spinup")
    motion = scene.maneuver
    print("## A2. Kane spin-up on the exact variant, method=\"rk4\", no validity estimate "
          "(second and later runs)\n")
    print("| modes | first_order median (ms) | exact median (ms) | ratio | exact: estimated "
          "integration error | actual |")
    print("|---|---|---|---|---|---|")
    for n_modes in (2, 3, 4):
        medians, runs = {}, {}
        for variant in ("first_order", "exact"):
            model = build_model(scene.system, n_modes=n_modes, variant=variant)

            def run():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    return simulate(model, 30.0, hub_motion=motion, method="rk4",
                                    check_validity=False)
            runs[variant], _, medians[variant] = timed(run, repeats)
        exact = runs["exact"]
        tight = simulate(exact.model, 30.0, hub_motion=motion, rtol=1e-11,
                         check_validity=False)
        peak = tight.peak_tip_deflection
        actual = np.max(np.abs(exact.tip_deflection - tight.tip_deflection)) / peak
        print(f"| {n_modes} | {1e3 * medians['first_order']:.3g} | "
              f"{1e3 * medians['exact']:.3g} | {medians['exact'] / medians['first_order']:.1f} "
              f"| {exact.integration_error / peak:.2g} | {actual:.2g} |")
    print()


def case_b(repeats):
    system = load_scene("slew-90").system
    model = build_model(system, n_modes=6, variant="first_order")
    x0 = np.zeros(model.n_states)
    x0[0] = -np.pi / 2
    law = ZeroOrderHold(PD(kp=12.0, kd=8.0, torque_limit=6.0), sample_time=0.01)
    tight = simulate(model, 6.0, controller=law, x0=x0, rtol=1e-12, output_step=0.01)
    print("## B. PD sampled at 100 Hz (zero-order hold), slew-90 system, 6-mode first_order "
          "plant, 6 s\n")
    print("| integration | best (ms) | median (ms) | per sample (us) | error vs tight | "
          "estimated |")
    print("|---|---|---|---|---|---|")
    for method in ("cvodes", "RK45", "rk4"):
        def run():
            return simulate(model, 6.0, controller=law, x0=x0, method=method,
                            output_step=0.01)
        best, median, per_sample, error, estimate = sampled_timing(run, tight,
                                                                   max(3, repeats // 4))[1:]
        print(f"| {method} | {1e3 * best:.3g} | {1e3 * median:.3g} | {per_sample:.3g} | "
              f"{error:.2g} | {estimate:.2g} |")
    print()


def sampled_timing(run, tight, repeats):
    """``(result, best s, median s, median us per sample, error, estimated error)`` of a
    sampled run (:func:`timed`), its errors relative to the peak of the ``tight`` run."""
    result, best, median = timed(run, repeats)
    peak = tight.peak_tip_deflection
    error = np.max(np.abs(result.tip_deflection - tight.tip_deflection)) / peak
    per_sample = 1e6 * median / result.controller_report["samples"]
    return result, best, median, per_sample, error, result.integration_error / peak


#: Case C's plants: (scene, modes, variant, PD gains, initial hub angle in rad, duration in s).
SAMPLED_PLANTS = (("slew-90", 6, "first_order", (12.0, 8.0, 6.0), -np.pi / 2, 6.0),
                  ("slew-90", 4, "exact", (12.0, 8.0, 6.0), -np.pi / 2, 6.0),
                  ("slew-90", 12, "first_order", (12.0, 8.0, 6.0), -np.pi / 2, 6.0),
                  ("hub-beam-mass", 30, "first_order", (20.0, 10.0, None), -0.5, 3.0))


def case_c(repeats):
    print("## C. Sampled PD at 100 Hz, rtol 1e-8, no validity estimate: CVODES against the "
          "Dormand-Prince pair\n")
    print("| plant | integration | per sample (us) | error vs tight | estimated |")
    print("|---|---|---|---|---|")
    for name, n_modes, variant, (kp, kd, limit), angle, t_final in SAMPLED_PLANTS:
        model = build_model(load_scene(name).system, n_modes=n_modes, variant=variant)
        x0 = model.rest_state(angle)
        law = ZeroOrderHold(PD(kp=kp, kd=kd, torque_limit=limit), sample_time=0.01)
        options = dict(controller=law, x0=x0, check_validity=False)
        tight = simulate(model, t_final, rtol=1e-12, method="cvodes", **options)
        for method in ("cvodes", "RK45"):
            result, _, _, per_sample, error, estimate = sampled_timing(
                lambda: simulate(model, t_final, method=method, **options), tight,
                max(2, repeats // 5))
            print(f"| {name}, {variant}, {n_modes} modes | {result.method} | "
                  f"{per_sample:.4g} | {error:.2g} | {estimate:.2g} |")
    print()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--only-c", action="store_true", help="case C only")
    args = parser.parse_args(argv)
    print(f"load average at start: {os.getloadavg()[0]:.2f} (2 cores)\n")
    if not args.only_c:
        case_a(args.repeats)
        case_a_exact(args.repeats)
        case_b(args.repeats)
    case_c(args.repeats)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
