"""Exports built freestanding for Cortex-M4F and Cortex-M7, and run under QEMU in the loop.

These need Debian's cross tools (``gcc-arm-none-eabi``, ``libnewlib-arm-none-eabi``) and, for
the processor in the loop, ``qemu-system-arm``; each test says which is missing when it skips.
"""

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import flexctl
from controllers import from_spec
from controllers.codegen import CompileError, ExportRefused, export_c
from controllers.codegen.precision import EPSILON
from controllers.codegen.targets import (TARGETS, build_for_target, check_target,
                                         find_target_compiler)
from flexctl.app.cli import main
from flexctl.model.errors import InputValueError

CROSS = "arm-none-eabi-gcc"
needs_cross = pytest.mark.skipif(
    shutil.which(CROSS) is None,
    reason=f"{CROSS} not installed (Debian: gcc-arm-none-eabi libnewlib-arm-none-eabi)")
needs_qemu = pytest.mark.skipif(
    shutil.which("qemu-system-arm") is None,
    reason="qemu-system-arm not installed (Debian: qemu-system-arm)")
needs_host = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no host C compiler")


@pytest.fixture(scope="module")
def sampled_lqr():
    """slew-90's LQR sampled at 100 Hz, and the states of its slew at the samples."""
    scene = flexctl.load_scene("slew-90", {"controller.kind": "lqr",
                                           "controller.sample_time": 0.01})
    plant = scene.build_model()
    built = from_spec(scene, plant)
    result = flexctl.simulate(plant, 3.0, controller=built.controller)
    times = np.arange(0.0, 3.0 - 1e-9, 0.01)
    states = np.array([np.interp(times, result.t, row) for row in result.states]).T
    return scene, plant, built.controller, times, states


def test_targets_and_missing_tools_are_named():
    assert set(TARGETS) == {"host", "cortex-m4", "cortex-m7"}
    assert "-mfloat-abi=hard" in TARGETS["cortex-m4"].flags
    assert "-mfpu=fpv4-sp-d16" in TARGETS["cortex-m4"].flags
    assert not TARGETS["cortex-m4"].double_in_hardware and TARGETS["cortex-m7"].double_in_hardware
    with pytest.raises(InputValueError, match=r"target must be one of .*got 'cortex-a9'"):
        check_target("cortex-a9")
    with pytest.raises(CompileError, match="no-such-gcc not found.*gcc-arm-none-eabi"):
        find_target_compiler(TARGETS["cortex-m4"], cc="no-such-gcc")


@needs_cross
@pytest.mark.parametrize("target", ["cortex-m4", "cortex-m7"])
@pytest.mark.parametrize("precision", ["double", "float"])
def test_freestanding_build_sizes_and_stack(sampled_lqr, target, precision, tmp_path):
    _, plant, law, _, _ = sampled_lqr
    exported = export_c(law, plant, tmp_path, precision=precision)
    build = build_for_target(exported, target)
    assert {"-ffreestanding", "-Werror", "-mfloat-abi=hard"} <= set(build.flags)
    assert build.code_bytes > 0 and build.constant_bytes > 0
    assert build.static_ram_bytes == 0                   # nothing mutable at file scope
    real = 4 if precision == "float" else 8
    assert build.struct_bytes >= real * exported.sizes["work_reals"]
    assert build.stack_path[0] == "flexctl_ctrl_step" and build.stack_bytes > 0
    assert not {"malloc", "calloc", "realloc", "free"} & set(build.library_calls)
    # double on the M4's single-precision FPU runs in software, nowhere else
    assert build.software_double == (precision == "double" and target == "cortex-m4")


@needs_cross
def test_an_export_in_a_relative_folder_builds_for_the_target(sampled_lqr, tmp_path,
                                                              monkeypatch):
    """The cross build runs in a folder of its own: an export written to a relative path
    (``flexctl export ... --out out``) is found from there."""
    _, plant, law, _, _ = sampled_lqr
    monkeypatch.chdir(tmp_path)
    exported = export_c(law, plant, "relative")
    assert not Path(exported.source).is_absolute()
    assert build_for_target(exported, "cortex-m7").code_bytes > 0


@needs_cross
def test_allocation_and_recursion_are_refused(sampled_lqr, tmp_path):
    _, plant, law, _, _ = sampled_lqr
    exported = export_c(law, plant, tmp_path)
    text = exported.source.read_text()
    entry = "size_t flexctl_ctrl_size(void) {"
    exported.source.write_text(
        "#include <stdlib.h>\n" + text.replace(entry, entry + "\n  free(malloc(1));"))
    with pytest.raises(ExportRefused, match="malloc.*must not allocate"):
        build_for_target(exported, "cortex-m4")
    recursive = ("static int flexctl_depth(int n) { return n < 2 ? n : flexctl_depth(n - 1) "
                 "+ flexctl_depth(n - 2); }\n")
    step = "int flexctl_ctrl_step(flexctl_ctrl *c,"
    guard = "  if (!c || !x || !u"
    body = text.replace(step, recursive + step, 1).replace(
        guard, "  if (flexctl_depth((int)x[0]) > 3) return 9;\n" + guard, 1)
    exported.source.write_text(body)
    with pytest.raises(ExportRefused, match="recurses"):
        build_for_target(exported, "cortex-m4")


@needs_cross
@needs_host
def test_cli_target_reports_sizes_and_the_makefile_builds(tmp_path, capsys):
    out = tmp_path / "m7"
    assert main(["export", "slew-90", "--set", "controller.kind=pd", "--precision", "float",
                 "--target", "cortex-m7", "--out", str(out)]) == 0
    summary = json.loads((out / "export.json").read_text())
    build = summary["target_build"]
    assert build["target"] == "cortex-m7" and build["precision"] == "float"
    assert build["code_bytes"] > 0 and build["stack_bytes"] > 0
    assert "cortex-m7 (float): code" in capsys.readouterr().out
    if shutil.which("make"):
        subprocess.run(["make", "-s", "-C", str(out), "cortex-m4", "cortex-m7"], check=True,
                       capture_output=True)
        assert (out / "libflexctl_ctrl_cortex-m4.a").exists()
        assert (out / "flexctl_ctrl_cortex-m7.su").exists()


@needs_cross
@needs_qemu
@needs_host
@pytest.mark.parametrize("target, precision", [("cortex-m4", "float"),
                                               ("cortex-m7", "double")])
def test_processor_in_the_loop_matches_host_and_python(sampled_lqr, target, precision,
                                                       tmp_path):
    """The step under QEMU on the recorded states of a slew: the host build of the same C
    within the precision's rounding, the Python law within double's or float's; the timer
    counts instructions at 2**shift ns each, as -icount sets."""
    from controllers.codegen.pil import ICOUNT_SHIFT, run_on_target

    scene, plant, law, times, states = sampled_lqr
    exported = export_c(law, plant, tmp_path, precision=precision)
    run = run_on_target(exported, times, states, target)
    assert run.codes.tolist() == [0] * times.size
    host = exported.compile()
    on_host = np.array([host.step(t, x)[0] for t, x in zip(times, states)])
    session = exported.program.session()
    python = np.array([session.step(t, x) for t, x in zip(times, states)])
    eps, bound = EPSILON[precision], scene.maneuver.torque_bound
    np.testing.assert_allclose(run.commands, on_host, rtol=0, atol=8 * eps * bound)
    allowed = 1e-12 if precision == "double" else 1e-3     # float: the poly7's cancellation
    np.testing.assert_allclose(run.commands, python, rtol=0, atol=allowed * bound)
    # the boards' 25 MHz timer under -icount: 2**shift ns per instruction
    assert run.ticks_per_instruction == pytest.approx(2 ** ICOUNT_SHIFT * 25e6 / 1e9, rel=1e-3)
    assert np.all(run.instructions > 0)
    assert run.summary()["time_estimate_median_s"] == pytest.approx(
        np.median(run.instructions) / run.clock_hz)


@needs_cross
@needs_qemu
@needs_host
def test_processor_in_the_loop_reads_every_torque_of_a_three_axis_law(tmp_path):
    """A law of three outputs (a three-axis LQR) under QEMU: each sample's three torques,
    those of the host build of the same C, in float."""
    from controllers.codegen.pil import run_on_target
    from controllers.feedback.lqr import LQRWeights
    from controllers.feedback.spatial_lqr import design_spatial_lqr
    from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
    from flexctl.sim.quaternions import from_rotation_vector
    from flexctl.sim.spatial_loop import simulate_spatial_loop

    rod = SpatialAppendage(name="wing", direction=(0.0, 1.0, 0.0), normal=(0.0, 0.0, 1.0),
                           length=1.0, density=2700.0, area=2e-4, youngs_modulus=7e10,
                           second_moment=1e-9, second_moment_lateral=5e-8,
                           shear_modulus=2.6e10, torsion_constant=2e-9)
    craft = SpatialStructure(hub=SpatialHub(inertia=np.diag([1.2, 1.0, 1.4]), radius=0.05),
                             appendages=(rod,))
    target = from_rotation_vector([0.1, -0.05, 0.2])
    law = design_spatial_lqr(craft, LQRWeights(hub_angle=0.05, torque=0.1), target,
                             n_modes=1, sample_time=0.1, torque_limit=0.2)
    run = simulate_spatial_loop(craft, 2.0, law, sample_time=0.1, n_modes=1,
                                variant="first_order").result
    exported = export_c(law, None, tmp_path, precision="float")
    names = list(run.equations.layout.state_names)
    inputs = run.states[[names.index(n) for n in exported.program.input_names]].T
    emulated = run_on_target(exported, run.t, inputs, "cortex-m4")
    assert emulated.outputs.shape == (run.t.size, 3)
    host = exported.compile()
    on_host = np.array([host.step(t, v)[0] for t, v in zip(run.t, inputs)])
    np.testing.assert_allclose(emulated.outputs, on_host, rtol=0,
                               atol=8 * EPSILON["float"] * 0.2)
    assert np.max(np.abs(on_host)) > 0.01
    assert np.array_equal(emulated.commands, emulated.outputs[:, 0])


@needs_cross
@needs_qemu
def test_processor_in_the_loop_refuses_bad_input(sampled_lqr, tmp_path):
    from controllers.codegen.pil import run_on_target

    _, plant, law, times, states = sampled_lqr
    exported = export_c(law, plant, tmp_path)
    with pytest.raises(InputValueError, match="must be embedded"):
        run_on_target(exported, times, states, "host")
    with pytest.raises(InputValueError, match=f"must have {plant.n_states} columns"):
        run_on_target(exported, times[:3], states[:3, :-1], "cortex-m4")


@needs_host
@pytest.mark.parametrize("precision", ["double", "float"])
def test_the_guides_flight_loop_compiles(sampled_lqr, precision, tmp_path):
    """The sample main.c of docs/guide/c_export.md builds against an export at the checking
    flags (for the Cortex-M4 too where the cross compiler is installed)."""
    import re
    from pathlib import Path

    from controllers.codegen import C_FLAGS, find_compiler
    from controllers.codegen.precision import PRECISION_FLAGS

    guide = Path(__file__).resolve().parents[2] / "docs" / "guide" / "c_export.md"
    blocks = re.findall(r"```c\n(.*?)```", guide.read_text(encoding="utf-8"), re.DOTALL)
    loop = next(block for block in blocks if "int main(void)" in block)
    _, plant, law, _, _ = sampled_lqr
    export_c(law, plant, tmp_path, precision=precision)
    (tmp_path / "flight.c").write_text(loop, encoding="utf-8")
    compilers = [(find_compiler(), ())]
    if shutil.which(CROSS):
        compilers.append((CROSS, TARGETS["cortex-m4"].flags))
    for compiler, flags in compilers:
        subprocess.run([compiler, *C_FLAGS, *PRECISION_FLAGS[precision], *flags, "-c",
                        "flight.c", "-o", "flight.o"], cwd=tmp_path, check=True,
                       capture_output=True)


@needs_cross
@needs_qemu
@needs_host
def test_the_emulated_law_flies_the_slew_with_the_plant_on_the_host(sampled_lqr, tmp_path):
    """The plant integrated on the host, the float law on the emulated Cortex-M4 stepped over
    its UART each sample: the same commands as the host build of the same C, the same
    residual vibration, and the double Python law's within LOOP_FRACTION."""
    from controllers.codegen import EmulatedLaw
    from flexctl.sim.metrics import slew_metrics

    scene, plant, law, _, _ = sampled_lqr
    exported = export_c(law, plant, tmp_path, precision="float")
    with EmulatedLaw(exported, "cortex-m4") as emulated:
        on_target = flexctl.simulate(plant, 3.0, controller=emulated.controller())
        assert len(emulated.instructions) == 300 and min(emulated.instructions) > 0
    on_host = flexctl.simulate(plant, 3.0, controller=exported.compile().controller())
    python = flexctl.simulate(plant, 3.0, controller=law)
    assert on_target.status == "ok"
    np.testing.assert_allclose(on_target.torque, on_host.torque, rtol=0,
                               atol=8 * EPSILON["float"] * scene.maneuver.torque_bound)
    end = from_spec(scene, plant).maneuver_end
    vib = [slew_metrics(r, scene.maneuver.angle, end).residual_vibration
           for r in (on_target, on_host, python)]
    assert vib[0] == pytest.approx(vib[1], rel=1e-9)
    assert vib[0] == pytest.approx(vib[2], rel=1e-3)
