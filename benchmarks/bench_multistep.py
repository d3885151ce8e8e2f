"""Benchmark: CVODES's multistep families on flexctl's runs (``choose_multistep``), and the
place of each integration method on ``method="auto"``'s paths.

1. Each case runs ``flexctl.simulate(..., method="cvodes", rtol=1e-6, check_validity=False)``
   with the accuracy check, once with the family the rule chooses and once with the other one
   (the rule replaced for that run), and prints the best of 5 wall times and each run's
   largest tip error against a run at rtol 1e-11, relative to the peak.
2. The same cases with ``method="auto"`` (the method it took is printed) against each
   compiled method asked for by name: ``"cvodes"``, the compiled Dormand-Prince pairs
   (``"dop853"``, ``"RK45"``), the compiled multistep methods (``"Adams"``, ``"BDF"``) and
   the fixed-step ``"rk4"``, at the same tolerance with the accuracy check, best of 3 (ms), each with its
   error as above. A method earns its place on a default path where ``auto`` takes it and it
   is the fastest of those within the tolerance.

Run: ``python benchmarks/bench_multistep.py [--place-only]``. Nothing is asserted.
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controllers import PD                                               # noqa: E402
from flexctl import SineTorque, build_model, load_scene, simulate        # noqa: E402
from flexctl.sim import request                                          # noqa: E402

RTOL = 1e-6
REPEATS = 5


def cases():
    """``(label, model, t_final, simulate keywords)``."""
    slew = load_scene("slew-90")
    for n_modes in (4, 6):
        model = build_model(slew.system, n_modes, "exact")
        yield (f"slew-90 saturated PD, exact, {n_modes} modes, 6 s", model, 6.0,
               dict(controller=PD(kp=12.0, kd=8.0, torque_limit=6.0),
                    x0=model.rest_state(-np.pi / 2)))
    hub = load_scene("hub-beam-mass")
    sine = SineTorque(peak_torque=2.0, duration=2.0)
    for n_modes, t_final in ((30, 2.0), (12, 20.0)):
        yield (f"hub-beam-mass sine, first_order, {n_modes} modes, {t_final:g} s",
               build_model(hub.system, n_modes), t_final, dict(torque=sine))
    spacecraft = load_scene("spacecraft-torque")
    yield ("spacecraft-torque, first_order, 6 modes, 20 s",
           build_model(spacecraft.system, 6), 20.0, dict(torque=spacecraft.maneuver))
    kane = load_scene("kane-spinup")
    for variant in ("first_order", "exact"):
        yield (f"Kane spin-up, {variant}, 4 modes, 30 s", build_model(kane.system, 4, variant),
               30.0, dict(hub_motion=kane.maneuver))


def run(model, t_final, options, rtol, family=None):
    """A compiled run, with ``family`` forced (None: the rule's choice)."""
    chosen = request.choose_multistep
    if family is not None:
        request.choose_multistep = lambda *args, **kwargs: family
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return simulate(model, t_final, method="cvodes", rtol=rtol, check_validity=False,
                            **options)
    finally:
        request.choose_multistep = chosen


PLACE_METHODS = ("auto", "cvodes", "dop853", "RK45", "Adams", "BDF", "rk4")
PLACE_REPEATS = 3


def timed(model, t_final, options, method):
    """``(best wall time s, result)`` of ``method`` at :data:`RTOL` (None where refused)."""
    best, result = float("inf"), None
    for _ in range(PLACE_REPEATS + 1):                   # the first compiles
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                result = simulate(model, t_final, method=method, rtol=RTOL,
                                  check_validity=False, **options)
            except (ValueError, TypeError) as exc:
                return None, str(exc)
        best = min(best, time.perf_counter() - start)
    return best, result


def place():
    """Table 2 of the module description."""
    print(f"\nEach method at rtol {RTOL:g} with its accuracy check, best of {PLACE_REPEATS} (ms), "
          "and its largest tip error against rtol 1e-11 relative to the peak; 'auto' names "
          "the method it took\n")
    print("| run | auto | " + " | ".join(PLACE_METHODS[1:]) + " |")
    print("|---|---|" + "---|" * (len(PLACE_METHODS) - 1))
    for label, model, t_final, options in cases():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tight = simulate(model, t_final, method="cvodes", rtol=1e-11,
                             check_validity=False, **options)
        cells = []
        for method in PLACE_METHODS:
            best, result = timed(model, t_final, options, method)
            if best is None or result.status not in ("ok", "stopped"):
                cells.append("refused" if best is None else result.status)
                continue
            error = np.max(np.abs(result.tip_deflection - tight.tip_deflection)) \
                / tight.peak_tip_deflection
            name = f"{result.method}: " if method == "auto" else ""
            cells.append(f"{name}{1e3 * best:.1f} ({error:.1g})")
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)


def main():
    print(f"load average at start: {os.getloadavg()[0]:.2f} (2 cores)\n")
    if "--place-only" in sys.argv[1:]:
        place()
        return
    print(f"CVODES at rtol {RTOL:g} with its accuracy check: best of {REPEATS} (ms) and the "
          "largest tip error against rtol 1e-11, relative to the peak\n")
    print("| run | the rule's choice | BDF (ms) | error | Adams (ms) | error |")
    print("|---|---|---|---|---|---|")
    for label, model, t_final, options in cases():
        omega = float(model.natural_frequencies(
            0.0, hub="clamped" if "hub_motion" in options else "free")[-1])
        choice = request.choose_multistep(model, omega, 0.0, t_final)
        tight = run(model, t_final, options, 1e-11)
        peak = tight.peak_tip_deflection
        cells = []
        for family in ("bdf", "adams"):
            result = run(model, t_final, options, RTOL, family)
            best = float("inf")
            for _ in range(REPEATS):
                start = time.perf_counter()
                result = run(model, t_final, options, RTOL, family)
                best = min(best, time.perf_counter() - start)
            error = np.max(np.abs(result.tip_deflection - tight.tip_deflection)) / peak
            cells += [f"{1e3 * best:.1f}", f"{error:.2g}"]
        print(f"| {label} | {choice} | " + " | ".join(cells) + " |", flush=True)
    place()
    print(f"\nload average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
