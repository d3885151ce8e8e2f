"""Cost of several appendages: a two-appendage structure against one beam carrying the same
total number of modes, for every variant, on a pinned and on a free hub.

The one-beam model is the hub-beam-mass beam with ``2 N`` modes on a pinned hub; the structure
carries two such beams at 0 and 120 degrees with ``N`` modes each (pinned, then free). Both
are driven by the same one-period sine torque. The target: the structure within 1.5 times the
one-beam run.

Run: ``python benchmarks/bench_structures.py`` (prints measured wall times and ratios; the
best of ``REPEATS`` runs, each model built and compiled before timing).
"""

from __future__ import annotations

import math
import warnings

from bench_exact import REPEATS, best_of
from flexctl import (Appendage, Beam, Hub, HubBeam, PointMass, SineTorque, Structure,
                     build_model, simulate)

RTOL = 1e-8
T_FINAL = 6.0
PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
             youngs_modulus=6.9e10)
TIP = (PointMass(mass=0.085, position=1.62),)


def structure(support: str) -> Structure:
    hub = Hub(inertia=1.16, radius=0.06, mass=3.0, support=support)
    return Structure(hub=hub, appendages=(
        Appendage(name="wing_a", beam=PANEL, masses=TIP),
        Appendage(name="wing_b", beam=PANEL, masses=TIP, angle=2.0 * math.pi / 3.0)))


def run(model):
    torque = SineTorque(peak_torque=2.0, duration=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(model, T_FINAL, torque=torque, rtol=RTOL, output_step=0.01)


def main():
    one = HubBeam(hub=Hub(inertia=1.16, radius=0.06), beam=PANEL, masses=TIP)
    print(f"Simulation of {T_FINAL:g} s, rtol {RTOL:g}, compiled path with its accuracy check "
          f"(best of {REPEATS}); ratio = structure / one beam with the same total modes")
    print(f"{'variant':12s} {'modes':>5s} {'one beam':>10s} {'pinned x2':>10s} "
          f"{'ratio':>6s} {'free x2':>10s} {'ratio':>6s}")
    for variant in ("first_order", "consistent", "exact"):
        for per in (2, 3):
            models = [build_model(one, 2 * per, variant),
                      build_model(structure("pinned"), per, variant),
                      build_model(structure("free"), per, variant)]
            for model in models:
                run(model)                       # build and compile before timing
            times = [best_of(lambda m=m: run(m))[0] for m in models]
            print(f"{variant:12s} {2 * per:5d} {times[0]:10.3f} {times[1]:10.3f} "
                  f"{times[1] / times[0]:6.2f} {times[2]:10.3f} {times[2] / times[0]:6.2f}")


if __name__ == "__main__":
    main()
