"""Controllers exported as C99: compiled at -Werror, loaded by ctypes, checked against Python."""

import ctypes
import dataclasses
import json
import re
import shutil
import subprocess

import numpy as np
import pytest

import flexctl
from controllers import from_spec
from controllers.codegen import (C_FLAGS, CompileError, ExportRefused, export_c,
                                 program_for)
from controllers.feedback.lqg_sampled import SampledLQG
from flexctl.app.cli import main
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.digital import ZeroOrderHold
from flexctl.sim.metrics import slew_metrics

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")


def _scene(kind, **overrides):
    return flexctl.load_scene("slew-90", {"controller.kind": kind, **overrides})


def _design(scene):
    plant = scene.build_model()
    return plant, from_spec(scene, plant)


@pytest.fixture(scope="module")
def designs():
    """The slew-90 laws that read the state, each designed once."""
    out = {}
    for kind in ("pd", "lqr", "scheduled", "trajopt+lqr"):
        out[kind] = _design(_scene(kind))
    return out


def _recorded_states(plant, controller, n=40):
    """States of a closed-loop run of the Python law, at ``n`` times through the slew."""
    result = flexctl.simulate(plant, 4.0, controller=controller)
    picks = np.linspace(0, result.t.size - 1, n).astype(int)
    return result.t[picks], result.states[:, picks].T


@pytest.mark.parametrize("kind", ["pd", "lqr", "scheduled", "trajopt+lqr"])
def test_static_law_matches_python_to_1e12(designs, kind, tmp_path):
    plant, built = designs[kind]
    law = built.controller.for_plant(plant)
    compiled = export_c(built.controller, plant, tmp_path).compile()
    rng = np.random.default_rng(3)
    times, states = _recorded_states(plant, built.controller)
    random_t = rng.uniform(-0.5, 5.0, 60)
    random_x = rng.normal(scale=0.05, size=(60, plant.n_states))
    worst = 0.0
    for t, x in zip(np.concatenate((times, random_t)), np.vstack((states, random_x))):
        expected = law.torque(t, x, np.zeros(0))
        got, code = compiled.step(t, x)
        assert code == 0
        worst = max(worst, abs(got - expected) / max(abs(expected), 1e-3))
    assert worst <= 1e-12, f"{kind}: relative difference {worst:.2e}"
    # the struct is the only memory: fixed, small for a static law
    assert compiled.struct_bytes < 4096


def test_exported_source_is_self_contained(designs, tmp_path):
    plant, built = designs["trajopt+lqr"]
    exported = export_c(built.controller, plant, tmp_path)
    source = exported.source.read_text()
    for call in ("malloc", "calloc", "realloc", "free("):
        assert call not in source, call
    includes = set(re.findall(r"#include\s*<([^>]+)>", source))
    assert includes <= {"math.h", "string.h", "stddef.h", "stdio.h", "stdarg.h"}, includes
    # nothing at file scope that could change: every static object is const
    for line in source.splitlines():
        if line.startswith("static") and "(" not in line.split("=")[0]:
            assert "const" in line, line
    header = exported.header.read_text()
    for name in ("FLEXCTL_NX", "FLEXCTL_SAMPLE_TIME", "flexctl_ctrl_size",
                 "flexctl_ctrl_init", "flexctl_ctrl_step", "typedef struct flexctl_ctrl"):
        assert name in header
    assert f"#define FLEXCTL_NX {plant.n_states}" in header


def test_werror_is_enforced(designs, tmp_path):
    """The checking flags are live: an unused variable in the source fails the build."""
    assert {"-std=c99", "-Wall", "-Wextra", "-Werror"} <= set(C_FLAGS)
    plant, built = designs["pd"]
    exported = export_c(built.controller, plant, tmp_path)
    text = exported.source.read_text()
    exported.source.write_text(text.replace("size_t flexctl_ctrl_size(void) {",
                                            "size_t flexctl_ctrl_size(void) {\n  int unused;"))
    with pytest.raises(CompileError, match="unused"):
        exported.compile()


def test_return_codes_and_bad_input(designs, tmp_path):
    plant, built = designs["lqr"]
    compiled = export_c(built.controller, plant, tmp_path).compile()
    x = np.full(plant.n_states, 0.01)
    reference, _ = compiled.step(0.3, x)
    bad = x.copy()
    bad[2] = np.nan
    assert compiled.step(0.3, bad) == (0.0, 2)
    assert compiled.step(np.inf, x) == (0.0, 2)
    assert compiled.step(0.3, x) == (reference, 0)
    lib = compiled._lib
    u = ctypes.c_double(7.0)
    data = (ctypes.c_double * plant.n_states)(*x)
    assert lib.flexctl_ctrl_step(None, 0.0, data, ctypes.byref(u)) == 4
    assert u.value == 7.0
    assert lib.flexctl_ctrl_init(None) == 4
    blank = np.zeros(compiled.struct_bytes // 8 + 1)         # never initialised
    assert lib.flexctl_ctrl_step(blank.ctypes.data, 0.0, data, ctypes.byref(u)) == 4
    with pytest.raises(InputValueError, match="entries"):
        compiled.step(0.0, x[:-1])


def test_lqg_estimator_discretised_matches_sampled_python(tmp_path):
    plant, built = _design(_scene("lqg"))
    lqg = built.controller
    with pytest.raises(ExportRefused, match="sample_time"):
        export_c(lqg, plant, tmp_path)
    exported = export_c(lqg, plant, tmp_path, sample_time=0.01)
    assert exported.program.input_kind == "measurement"
    assert exported.program.input_names == ("theta", "root_moment")
    compiled = exported.compile()
    session = SampledLQG(lqg, 0.01).start(plant, np.zeros(plant.n_states))
    rng = np.random.default_rng(5)
    for k in range(200):
        y = rng.normal(scale=[0.05, 0.5])
        expected = session.step_readings(0.01 * k, y)
        got, code = compiled.step(0.01 * k, y)
        assert code == 0
        assert abs(got - expected) <= 1e-12 * max(abs(expected), 1e-3)
    # in the loop: the compiled law and the Python one leave the same vibration
    runs = [flexctl.simulate(plant, 6.0, controller=c)
            for c in (SampledLQG(lqg, 0.01), compiled.controller())]
    assert all(r.status == "ok" for r in runs)
    np.testing.assert_allclose(runs[1].torque, runs[0].torque, rtol=0, atol=1e-9)
    vib = [slew_metrics(r, np.pi / 2, built.maneuver_end).residual_vibration for r in runs]
    assert vib[1] == pytest.approx(vib[0], rel=1e-6)


def test_sampled_static_law(designs, tmp_path):
    plant, built = designs["pd"]
    held = ZeroOrderHold(built.controller, 0.01)
    exported = export_c(held, plant, tmp_path)
    assert exported.program.sample_time == 0.01
    assert "#define FLEXCTL_SAMPLE_TIME 0.01" in exported.header.read_text()
    compiled = exported.compile()
    runs = [flexctl.simulate(plant, 3.0, controller=c) for c in (held, compiled.controller())]
    np.testing.assert_allclose(runs[1].torque, runs[0].torque, rtol=1e-12, atol=1e-12)
    with pytest.raises(ExportRefused, match="differs"):
        export_c(held, plant, tmp_path, sample_time=0.02)


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["state", "kalman"])
def test_nmpc_rti_matches_python_and_closes_the_loop(estimator, tmp_path):
    scene = _scene("nmpc", **{"model.design_variant": "first_order",
                              "controller.estimator": estimator})
    plant, built = _design(scene)
    mpc = built.controller
    exported = export_c(mpc, plant, tmp_path)
    program = exported.program
    assert program.input_kind == ("state" if estimator == "state" else "measurement")
    compiled = exported.compile()
    # step by step on the states of the Python loop
    result = flexctl.simulate(plant, 6.0, controller=mpc)
    assert result.controller_report["fallback_steps"] == 0
    session = mpc.start(plant, np.zeros(plant.n_states))
    compiled.init()
    samples = np.arange(0, 6.0 - 1e-9, mpc.sample_time)
    states = np.array([np.interp(samples, result.t, row) for row in result.states]).T
    worst = 0.0
    for t, x in zip(samples, states):
        expected = session.step(t, x)
        v = x if estimator == "state" else program.measurement_matrix @ x
        got, code = compiled.step(t, v)
        assert code == 0
        worst = max(worst, abs(got - expected) / max(abs(expected), 1.0))
    assert worst <= 1e-9
    # in the loop, same residual vibration
    loop = flexctl.simulate(plant, 6.0, controller=compiled.controller())
    end = built.maneuver_end
    vib = [slew_metrics(r, np.pi / 2, end).residual_vibration for r in (result, loop)]
    assert vib[1] == pytest.approx(vib[0], rel=1e-6, abs=1e-9)
    report = loop.controller_report
    print(f"\ncompiled NMPC ({estimator}, 2 first_order design modes, horizon {mpc.horizon}): "
          f"code {compiled.code_bytes} bytes, struct {compiled.struct_bytes} bytes, CPU per "
          f"step median {report['cpu_time_median_s'] * 1e3:.3f} ms, p99 "
          f"{report['cpu_time_p99_s'] * 1e3:.3f} ms; Python "
          f"{result.controller_report['solve_time_median_s'] * 1e3:.3f} ms")


def test_failed_qp_applies_the_shifted_plan_and_says_so(tmp_path):
    """Rest at 1 rad within 5 samples of 0.01 N m is out of reach: every QP is infeasible;
    the C step returns FLEXCTL_STEP_RECOVERED with the torque the Python law applies."""
    from controllers import NMPC

    plant = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2,
                                variant="first_order")
    mpc = NMPC(model=plant, target=1.0, torque_limit=0.01, terminal="rest", horizon=5)
    compiled = export_c(mpc, plant, tmp_path).compile()
    session = mpc.start(plant, np.zeros(plant.n_states))
    x = np.zeros(plant.n_states)
    for k in range(4):
        expected = session.step(0.02 * k, x)
        assert compiled.step(0.02 * k, x) == (pytest.approx(expected, abs=1e-12), 1)
    assert session.report()["failed_steps"] == 4


@pytest.mark.slow
def test_nmpc_on_a_hardware_scene_matches(tmp_path):
    """flexible-link's NMPC: the DC motor's voltage constraints in the QP, the voltage out,
    the sensors' Kalman filter in front, 500 Hz."""
    from controllers.spec import ControllerSpec
    from flexctl.app.scenes import run_slew

    scene = flexctl.load_scene("flexible-link")
    scene = dataclasses.replace(scene, controller=ControllerSpec(
        kind="nmpc", settings={"sample_time": scene.sensors.sample_time}))
    plant, built = _design(scene)
    exported = export_c(built.controller, plant, tmp_path)
    assert exported.program.info["qp_constraints"] > 0
    assert exported.program.output_name == "voltage"
    compiled = exported.compile()
    runs = [run_slew(scene, lambda s, p, c=c: dataclasses.replace(built, controller=c))
            for c in (built.controller, compiled.controller())]
    (r_py, _, m_py), (r_c, _, m_c) = runs
    assert r_c.controller_report["recovered_steps"] == 0
    np.testing.assert_allclose(r_c.torque, r_py.torque, rtol=0, atol=1e-9)
    assert m_c.residual_vibration == pytest.approx(m_py.residual_vibration, rel=1e-9)


def test_observed_law_of_a_hardware_scene_matches(tmp_path):
    """flexible-link: LQR through a DC motor on the sensors' Kalman filter, 500 Hz, with a
    transport delay of half a sample."""
    from flexctl.app.scenes import run_slew

    scene = flexctl.load_scene("flexible-link")
    plant, built = _design(scene)
    exported = export_c(built.controller, plant, tmp_path)
    program = exported.program
    assert program.input_kind == "measurement" and program.output_name == "voltage"
    compiled = exported.compile()
    runs = [run_slew(scene, lambda s, p, c=c: dataclasses.replace(built, controller=c))
            for c in (built.controller, compiled.controller())]
    (r_py, _, m_py), (r_c, _, m_c) = runs
    np.testing.assert_allclose(r_c.torque, r_py.torque, rtol=0, atol=1e-9)
    assert m_c.residual_vibration == pytest.approx(m_py.residual_vibration, rel=1e-9)


def test_refusals_name_the_reason(tmp_path):
    plant = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2)
    with pytest.raises(ExportRefused, match="CasADi form"):
        export_c(lambda t, x: -x[0], plant, tmp_path)
    from controllers import NMPC
    converged = NMPC(model=plant, target=1.0, torque_limit=5.0, mode="converged")
    with pytest.raises(ExportRefused, match="IPOPT"):
        program_for(converged, plant)
    osqp = NMPC(model=plant, target=1.0, torque_limit=5.0, qp_solver="osqp")
    with pytest.raises(ExportRefused, match="osqp"):
        program_for(osqp, plant)
    pd = from_spec(_scene("pd"), plant).controller
    with pytest.raises(InputTypeError, match="Model"):
        program_for(pd, "plant")
    for bad in (np.nan, -1.0, 0.0, "fast", True):
        with pytest.raises((InputTypeError, InputValueError), match="sample_time"):
            program_for(pd, plant, sample_time=bad)
    with pytest.raises(InputValueError, match="initial_state"):
        program_for(pd, plant, initial_state=[0.0, 1.0])
    with pytest.raises(InputValueError, match="initial_state"):
        program_for(pd, plant, initial_state=np.full(plant.n_states, np.nan))
    afile = tmp_path / "file"
    afile.write_text("x")
    with pytest.raises(InputValueError, match="is a file"):
        export_c(pd, plant, afile)
    with pytest.raises(InputTypeError, match="path"):
        export_c(pd, plant, 3)


def test_cli_export_writes_compiles_and_checks(tmp_path, capsys):
    out = tmp_path / "ctrl"
    assert main(["export", "slew-90", "--out", str(out)]) == 0
    summary = json.loads((out / "export.json").read_text())
    assert summary["compiled"] is True
    assert summary["check_max_difference"] <= 1e-12
    assert summary["kind"] == "tracker" and summary["input"] == "state"
    assert "struct" in capsys.readouterr().out
    assert main(["export", "slew-90", "--set", "controller.kind=nmpc", "--set",
                 'controller.mode="converged"', "--out", str(tmp_path / "x")]) == 2
    assert "IPOPT" in capsys.readouterr().err
    assert main(["export", "slew-90", "--sample-time", "-1"]) == 2
    if shutil.which("make"):
        subprocess.run(["make", "-s", "-C", str(out)], check=True, capture_output=True)
        run = subprocess.run([str(out / "flexctl_ctrl_demo"), "0.1"], check=True,
                             capture_output=True, text=True)
        assert run.stdout.count("(code 0)") == 10


def test_a_compiled_state_law_runs_where_the_validity_estimate_runs(tmp_path):
    """The run's validity estimate flies the law on the plant's system again: a compiled law
    reads exactly the exported plant's state, so the estimate keeps the plant's modes (it
    asked the law to start on 2 modes and stopped the run with an error)."""
    from controllers import LQRWeights, design_lqr

    system = flexctl.load_scene("hub-beam-mass").system
    plant = flexctl.build_model(system, n_modes=4)
    held = ZeroOrderHold(design_lqr(flexctl.build_model(system, n_modes=1),
                                    LQRWeights(hub_angle=0.05, torque=1.0)), 0.01)
    compiled = export_c(held, plant, tmp_path).compile()
    x0 = plant.layout.join(theta=0.3)
    runs = [flexctl.simulate(plant, 2.0, controller=c, x0=x0)
            for c in (held, compiled.controller())]
    assert all(r.status == "ok" and r.validity is not None for r in runs)
    assert runs[1].validity.geometric_error > 0.0
    np.testing.assert_allclose(runs[1].torque, runs[0].torque, rtol=1e-12, atol=1e-12)
