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


#: CPU time (s, every thread of the process) of the last :func:`median_time` per label of
#: :func:`measure`: flexctl's accuracy check runs on a second core beside its run, so wall
#: time and CPU time differ.
CPU_TIMES: dict = {}


def median_time(run, repeats, cpu=False):
    """Median wall time of ``repeats`` calls of ``run``, s; with ``cpu``, ``(wall, cpu)``."""
    times, cpus = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        run()
        times.append(time.perf_counter() - start)
        cpus.append(time.process_time() - start_cpu)
    if cpu:
        return statistics.median(times), statistics.median(cpus)
    return statistics.median(times)


def tune(run, reference):
    """Largest rtol of RTOL_GRID whose tip is within TARGET of the reference: (rtol, error)."""
    for rtol in RTOL_GRID:
        error = relative_error(run(rtol), reference)
        if error <= TARGET:
            return float(rtol), error
    raise RuntimeError(f"no rtol down to {RTOL_GRID[-1]:g} reaches {TARGET:g}")


#: python-control's runs: atol = rtol * ATOL_SCALE (m, rad).
ATOL_SCALE = 1e-3


def python_control_tip(model, t_in, u, grid, method):
    """A run ``rtol -> tip deflection on grid`` of python-control's ``input_output_response``
    on ``model.nonlinear()`` with the torque samples ``(t_in, u)``, by SciPy's ``method``."""
    import control

    system = model.nonlinear()
    tip_row = list(model.output_names).index("tip_deflection")

    def run(rtol):
        response = control.input_output_response(
            system, t_in, u, np.zeros(model.n_states), evaluation_times=grid,
            solve_ivp_method=method, solve_ivp_kwargs={"rtol": rtol,
                                                       "atol": rtol * ATOL_SCALE})
        return np.asarray(response.outputs)[tip_row]
    return run


def measure(tools, reference, width=40):
    """Tune and time each tool of ``{label: (run, repeats)}``: ``{label: seconds}``, printing
    a table row per tool."""
    times = {}
    print(f"   {'tool':<{width}} {'rtol':>9} {'error':>9} {'median time':>12} {'CPU time':>10}")
    for label, (run, repeats) in tools.items():
        rtol, error = tune(run, reference)
        times[label], CPU_TIMES[label] = median_time(lambda: run(rtol), repeats, cpu=True)
        print(f"   {label:<{width}} {rtol:>9.2g} {error:>9.2g} {times[label]:>10.4f} s "
              f"{CPU_TIMES[label]:>8.4f} s", flush=True)
    return times
