"""Benchmark: ``flexctl.simulate`` against a bare CasADi CVODES integration and python-control.

Cases, all on 4-mode first_order models:

A. ``kane-spinup`` (30 s, prescribed spin-up to 4 rad/s): ``flexctl.simulate`` (method "auto",
   which takes compiled Dormand-Prince steps on these cheap 4-mode models, CVODES on costlier
   ones: :func:`flexctl.sim.request.choose_continuous`) against a bare CVODES integration of the same beam
   equations, ``M_ff q'' + (K_ff - theta_t^2 D) q = -m_tf theta_tt``, written below with casadi
   from ``model.matrices``.
B. ``hub-beam-mass`` (20 s, one period of 2 N m sine torque): the same two, and python-control's
   ``control.input_output_response`` on ``model.nonlinear()``. python-control systems are driven
   by inputs and cannot take a prescribed hub motion, hence a torque-driven scene for it.

Every tool runs at the largest relative tolerance (quarter decades from 1e-4 down) whose tip
deflection is within 1e-6 of a reference, relative to the peak: ``max |tip - tip_ref| /
max |tip_ref|`` on the 0.01 s output grid. The reference is SciPy's DOP853 at rtol 1e-13 through
``flexctl.simulate`` (a different integrator from all those timed). Absolute tolerances: flexctl
scales its own per state; the bare and python-control runs take ``rtol * 1e-3`` (metres and
radians).

Times are end to end and the median of several repeats: for CVODES the construction of the
integrator (symbolic expression, ``casadi.integrator``) plus the run and the tip output; for
python-control the call of ``input_output_response``. python-control interpolates its input
linearly between samples, so the torque is sampled every 2e-4 s (on the 0.01 s output grid alone
the interpolation error of the sine, ~1e-4, would exceed the accuracy asked for); it is run with
SciPy's RK45 (its default), DOP853 and LSODA, and the fastest is compared.

flexctl runs with its checks (``check_accuracy``, the run at 10x the tolerance behind
``integration_error``; ``check_validity``, the geometric error of a small-deflection model
from two 2-mode runs), with the accuracy check alone, and with neither.

Targets: flexctl <= 2x the bare CVODES time; python-control >= 10x the flexctl time.

Run: ``python benchmarks/bench_speed.py`` (a few minutes; python-control dominates).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import casadi as ca                               # noqa: E402
from equal_error import (ATOL_SCALE, CPU_TIMES, TARGET, measure,  # noqa: E402
                         python_control_tip, relative_error)
import control                                    # noqa: E402

from flexctl import SpinUp, load_scene, simulate  # noqa: E402

REFERENCE_RTOL = 1e-13
OUTPUT_STEP = 0.01               # s
INPUT_STEP = 2e-4                # s, torque samples handed to python-control
REPEATS = 7                      # CVODES runs (tens of ms each)
REPEATS_SLOW = 3                 # python-control runs (seconds each)
PYTHON_CONTROL_METHODS = ("RK45", "DOP853", "LSODA")


def output_grid(t_final):
    grid = np.arange(0.0, t_final + 0.5 * OUTPUT_STEP, OUTPUT_STEP)
    grid[-1] = t_final
    return grid


# ---------------------------------------------------------------------------- the tools
def flexctl_tip(model, scene, t_final, check_accuracy=True, check_validity=True):
    drive = ({"hub_motion": scene.maneuver} if isinstance(scene.maneuver, SpinUp)
             else {"torque": scene.maneuver})

    def run(rtol, method="auto"):
        result = simulate(model, t_final, rtol=rtol, output_step=OUTPUT_STEP, method=method,
                          check_accuracy=check_accuracy, check_validity=check_validity,
                          **drive)
        assert result.ok, result.message
        return result.tip_deflection
    return run


def bare_cvodes_tip(model, scene, t_final, multistep="bdf"):
    """CVODES on the model's equations written directly with casadi (no flexctl code), with
    its default BDF or with Adams (``multistep``)."""
    mat, n = model.matrices, model.n_modes
    grid = output_grid(t_final)
    prescribed = isinstance(scene.maneuver, SpinUp)

    def run(rtol):
        t = ca.SX.sym("t")
        if prescribed:
            x = ca.SX.sym("x", 2 * n)
            q, qd = x[:n], x[n:]
            rate, acceleration = scene.maneuver.casadi(t)
            force = (-ca.mtimes(ca.DM(mat.K_ff), q) + rate ** 2 * ca.mtimes(ca.DM(mat.D), q)
                     - ca.DM(mat.m_tf) * acceleration)
            ode = ca.vertcat(qd, ca.mtimes(ca.DM(np.linalg.inv(mat.M_ff)), force))
        else:
            x = ca.SX.sym("x", 2 * n + 2)
            q, w, qd = x[1:n + 1], x[n + 1], x[n + 2:]
            mass = np.block([[np.array([[mat.J0]]), mat.m_tf[None, :]],
                             [mat.m_tf[:, None], mat.M_ff]])
            force = ca.vertcat(scene.maneuver.casadi(t),
                               -ca.mtimes(ca.DM(mat.K_ff), q)
                               + w ** 2 * ca.mtimes(ca.DM(mat.D), q))
            ode = ca.vertcat(w, qd, ca.mtimes(ca.DM(np.linalg.inv(mass)), force))
        integrator = ca.integrator("bare", "cvodes", {"x": x, "t": t, "ode": ode}, 0.0,
                                   list(grid[1:]), {"reltol": rtol,
                                                    "abstol": rtol * ATOL_SCALE,
                                                    "max_num_steps": 10 ** 7,
                                                    "linear_multistep_method": multistep})
        xf = np.array(integrator(x0=np.zeros(x.numel()))["xf"])
        q_out = xf[:n] if prescribed else xf[1:n + 1]
        return np.concatenate(([0.0], model.mode_tips @ q_out))
    return run


def python_control_run(model, scene, t_final, method):
    t_in = np.arange(0.0, t_final + 0.5 * INPUT_STEP, INPUT_STEP)
    t_in[-1] = t_final
    return python_control_tip(model, t_in, scene.maneuver(t_in), output_grid(t_final), method)


# ---------------------------------------------------------------------------- cases
def compare(name, with_python_control):
    scene = load_scene(name)
    model = scene.build_model()
    t_final = scene.simulation.t_final
    print(f"\n== {name}: {scene.description}")
    print(f"   {model.variant}, {model.n_modes} modes, {t_final:g} s; target relative tip "
          f"error {TARGET:g}")
    start = time.perf_counter()
    flex = flexctl_tip(model, scene, t_final)
    reference = flex(REFERENCE_RTOL, method="DOP853")
    check = relative_error(flex(1e-12), reference)
    print(f"   reference: DOP853 at rtol {REFERENCE_RTOL:g} ({time.perf_counter() - start:.1f} s);"
          f" flexctl cvodes at 1e-12 differs from it by {check:.2g}")

    tools = {"flexctl.simulate (auto)": (flex, REPEATS),
             "flexctl, no validity estimate": (
                 flexctl_tip(model, scene, t_final, check_validity=False), REPEATS),
             "flexctl, no checks": (flexctl_tip(model, scene, t_final, False, False), REPEATS),
             "bare casadi CVODES": (bare_cvodes_tip(model, scene, t_final), REPEATS),
             "bare casadi CVODES, Adams": (bare_cvodes_tip(model, scene, t_final, "adams"),
                                           REPEATS)}
    if with_python_control:
        for method in PYTHON_CONTROL_METHODS:
            tools[f"python-control {method}"] = (
                python_control_run(model, scene, t_final, method), REPEATS_SLOW)
    times = measure(tools, reference, width=28)
    flex_time = times["flexctl.simulate (auto)"]
    ratio = flex_time / times["bare casadi CVODES"]
    print(f"   flexctl / bare CVODES = {ratio:.2f} (target <= 2: "
          f"{'met' if ratio <= 2 else 'missed'}); without its accuracy check (the run at 10x "
          f"the tolerance that gives integration_error): "
          f"{times['flexctl, no checks'] / times['bare casadi CVODES']:.2f} (nor the validity "
          f"estimate); with the "
          f"accuracy check, without the validity estimate (the geometric error of the "
          f"small-deflection model, two 2-mode runs): "
          f"{times['flexctl, no validity estimate'] / times['bare casadi CVODES']:.2f}")
    adams = times["bare casadi CVODES, Adams"]
    print(f"   against bare CVODES with Adams (flexctl's choice for these undamped models): "
          f"flexctl {flex_time / adams:.2f}, without the validity estimate "
          f"{times['flexctl, no validity estimate'] / adams:.2f}, no checks "
          f"{times['flexctl, no checks'] / adams:.2f}")
    cpu, bare_cpu = CPU_TIMES, CPU_TIMES["bare casadi CVODES"]
    print(f"   CPU time (every thread) against bare CVODES: flexctl "
          f"{cpu['flexctl.simulate (auto)'] / bare_cpu:.2f}, without the validity estimate "
          f"{cpu['flexctl, no validity estimate'] / bare_cpu:.2f}, no checks "
          f"{cpu['flexctl, no checks'] / bare_cpu:.2f} (the accuracy check runs beside the run "
          f"on a spare core: wall time counts the longer of the two, CPU time both)")
    if with_python_control:
        pc = {k: v for k, v in times.items() if k.startswith("python-control")}
        fastest = min(pc, key=pc.get)
        speedup = pc[fastest] / flex_time
        print(f"   fastest python-control ({fastest.split()[-1]}) / flexctl = {speedup:.0f} "
              f"(target >= 10: {'met' if speedup >= 10 else 'missed'}); with its default RK45: "
              f"{pc['python-control RK45'] / flex_time:.0f}")
    return times


def main():
    print(f"flexctl speed benchmark (casadi {ca.__version__}, python-control "
          f"{control.__version__}); times are medians, end to end")
    compare("kane-spinup", with_python_control=False)
    compare("hub-beam-mass", with_python_control=True)


if __name__ == "__main__":
    main()
