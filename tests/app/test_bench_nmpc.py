"""benchmarks/bench_nmpc.py in a tiny configuration: a closed-loop row and its table line, and
python-control solving the same MPC problem as flexctl (same plan, same cost)."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import flexctl

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_nmpc.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_nmpc", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module                # its dataclass looks its module up
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def test_closed_loop_row_and_its_table_line(bench):
    scene = flexctl.load_scene(bench.SCENE)
    plant = flexctl.build_model(scene.system, n_modes=3, variant="first_order")
    design = flexctl.build_model(scene.design_system, n_modes=2, variant="first_order")
    reference, intervals = bench.solve_reference(design, scene.maneuver)
    assert intervals >= 40
    cfg = bench.Config("first_order", 2, 20, 0.05)
    row = bench.closed_loop_row(cfg, scene, plant, reference, replays=1, t_final=0.5)
    report = row["report"]
    assert row["status"] == "ok" and row["samples"] == 10 == report["samples"]
    assert report["failed_steps"] == 0
    assert 0 < report["solve_time_median_s"] <= report["solve_time_p99_s"] \
        <= report["solve_time_max_s"]
    assert row["cpu"].shape == (10,) and np.all(row["cpu"] >= 0)
    # a replay repeats the same problems: the same torques (qrqp keeps no memory)
    (walls, cpus, worst), = row["replays"]
    assert walls.shape == cpus.shape == (10,) and worst < 1e-9
    (line,) = bench.timing_rows([row])
    assert line[:5] == ["first_order", 2, 20, "50", "qrqp"]
    assert line[-1].startswith(("PASS", "MISS")) and "<= 1 / 3" in line[-1]
    failed = bench.timing_rows([{"cfg": cfg, "error": "RuntimeError: x"}])[0]
    assert failed[-1] == "failed: RuntimeError: x"


def test_python_control_solves_the_same_problem(bench, capsys):
    out = bench.python_control_case(steps_linear=1, steps_nonlinear=1, samples_iosystem=1,
                                    horizon=4, sample_time=0.05, t_final=0.2)
    text = capsys.readouterr().out
    assert "| python-control solve_ocp, linear (RK4 hold at rest)" in text
    assert out["flexctl_median"] > 0
    for key in ("linear", "nonlinear"):
        assert all(out[key]["ok"]) and out[key]["times"].size == 1
        assert out[key]["variables"] == 5          # 4 torques and the last, unused one
        # python-control's optimum and flexctl's plan cost the same (one SQP step from rest
        # solves the problem on the linear model; nearly so on the nonlinear one)
        assert abs(out[key]["cost_gap"][0]) < 1e-4
    assert out["iosystem"]["times"].size == 1
    assert abs(out["iosystem"]["torques"][0] - out["linear"]["plans"][0][0]) < 1e-3
