"""Timing at equal error, shared by the benchmarks: each tool runs at the loosest tolerance of
``RTOL_GRID`` whose tip deflection is within ``TARGET`` (relative to the peak) of a reference."""

from __future__ import annotations

import statistics
import time

import numpy as np

TARGET = 1e-6                        # relative tip error asked of every tool
RTOL_GRID = 10.0 ** (-4.0 - 0.25 * np.arange(29))     # 1e-4 .. 1e-11


def relative_error(tip, reference):
    return float(np.max(np.abs(tip - reference)) / np.max(np.abs(reference)))


def median_time(run, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def tune(run, reference):
    """Largest rtol of RTOL_GRID whose tip is within TARGET of the reference: (rtol, error)."""
    for rtol in RTOL_GRID:
        error = relative_error(run(rtol), reference)
        if error <= TARGET:
            return float(rtol), error
    raise RuntimeError(f"no rtol down to {RTOL_GRID[-1]:g} reaches {TARGET:g}")
