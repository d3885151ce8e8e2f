"""Benchmark: CVODES's multistep families on flexctl's runs (``choose_multistep``).

Each case runs ``flexctl.simulate(..., method="cvodes", rtol=1e-6, check_validity=False)``
with the accuracy check, once with the family the rule chooses and once with the other one
(the rule replaced for that run), and prints the best of 5 wall times and each run's largest
tip error against a run at rtol 1e-11, relative to the peak.

Run: ``python benchmarks/bench_multistep.py``. Nothing is asserted.
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


def main():
    print(f"load average at start: {os.getloadavg()[0]:.2f} (2 cores)\n")
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
    print(f"\nload average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
