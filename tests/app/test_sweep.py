"""Sweeps: the executor contract, the tidy table, the paper-000 tasks, and a Dask cluster.

The sweep engine is checked against plain loops (the same task called directly), the tasks
against the physics of paper 000 and the closed form of a bare beam, and the table against its
own CSV form.
"""

import csv
import dataclasses
import io
import math
import pickle
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

import flexctl
from flexctl.app.sweep import (PointMassAmplitudes, SceneTask, SweepError, SweepResult,
                           parameter_grid, pareto_front, response_amplitudes, sweep)

#: Short runs keep the sweeps cheap; the torque acts for 2 s, so 6 s leaves two periods of
#: the first flexible mode (5.5 rad/s) for the residual.
SHORT = 6.0
#: Paper 000 numbers (MODEL.md section 6), read off plots: a few percent.
PAPER_TOLERANCE = 0.03


def square(x, offset=0.0):
    """Module-level task (picklable)."""
    return {"square": x * x + offset}


def scalar_task(x):
    return 2 * x


def failing(x):
    if x == 2:
        raise ArithmeticError("no twos")
    return {"x2": 2 * x}


@pytest.fixture(scope="module")
def short_task():
    return PointMassAmplitudes.from_scene("hub-beam-mass", t_final=SHORT)


# ---------------------------------------------------------------------------- grids
def test_parameter_grid_is_the_cartesian_product_first_axis_slowest():
    grid = parameter_grid(a=[1, 2], b=np.array([0.5, 1.5, 2.5]))
    assert len(grid) == 6
    assert grid[0] == {"a": 1, "b": 0.5} and grid[1] == {"a": 1, "b": 1.5}
    assert grid[-1] == {"a": 2, "b": 2.5}
    assert all(type(p["b"]) is float for p in grid)       # NumPy scalars made plain


@pytest.mark.parametrize("call, error, match", [
    pytest.param(lambda: parameter_grid(), ValueError, "at least one axis", id="no-axes"),
    pytest.param(lambda: parameter_grid(a=[]), ValueError, "axis 'a'", id="empty-axis"),
    pytest.param(lambda: parameter_grid(a="abc"), TypeError, "axis 'a'", id="string-axis"),
    pytest.param(lambda: sweep(square, 5), TypeError, "parameter_grid", id="bad-grid"),
    pytest.param(lambda: sweep(square, [{"x": 1}, 3]), TypeError, r"parameter_grid\[1\]",
                 id="bad-point"),
    pytest.param(lambda: sweep(square, []), ValueError, "at least one point", id="no-points"),
    pytest.param(lambda: sweep(3, {"x": [1]}), TypeError, "task", id="not-callable"),
    pytest.param(lambda: sweep(square, {"x": [1]}, executor=object()), TypeError,
                 "executor", id="bad-executor"),
])
def test_bad_arguments_name_the_parameter(call, error, match):
    with pytest.raises(error, match=match):
        call()


# ---------------------------------------------------------------------------- engine
def test_serial_sweep_equals_direct_calls_in_grid_order():
    table = sweep(square, {"x": [3.0, 1.0, 2.0], "offset": [0.0, 10.0]}, progress=False)
    assert table.parameters == ("x", "offset") and table.outputs == ("square",)
    assert len(table) == 6
    for row in table:
        assert row["square"] == square(row["x"], row["offset"])["square"]
    assert table.column("x").tolist() == [3.0, 3.0, 1.0, 1.0, 2.0, 2.0]


def test_scalar_outputs_go_to_a_value_column():
    table = sweep(scalar_task, [{"x": 1}, {"x": 4}], progress=False)
    assert table.columns == ("x", "value")
    assert table.column("value").tolist() == [2.0, 8.0]


@pytest.mark.parametrize("make_pool", [
    pytest.param(lambda: ThreadPoolExecutor(max_workers=2), id="threads"),
    pytest.param(lambda: ProcessPoolExecutor(max_workers=2), id="processes"),
])
def test_pool_sweep_keeps_grid_order_and_matches_serial(make_pool):
    grid = {"x": np.arange(12.0)}
    serial = sweep(square, grid, progress=False)
    with make_pool() as pool:
        pooled = sweep(square, grid, executor=pool, progress=False)
        # The sweep does not own the executor: it is still usable afterwards.
        assert pool.submit(square, 2.0).result() == {"square": 4.0}
    assert pooled.rows == serial.rows


class _InOrderExecutor:
    """An executor whose futures are not concurrent.futures.Future (duck-typed)."""

    class _Done:
        def __init__(self, value):
            self.value = value

        def result(self):
            return self.value

        def cancel(self):
            return False

    def submit(self, fn, *args):
        return self._Done(fn(*args))


def test_any_object_with_submit_is_an_executor():
    table = sweep(square, {"x": [1.0, 2.0]}, executor=_InOrderExecutor(), progress=False)
    assert table.column("square").tolist() == [1.0, 4.0]


@pytest.mark.parametrize("with_pool", [False, True], ids=["serial", "threads"])
def test_failing_point_is_named_and_chained(with_pool):
    pool = ThreadPoolExecutor(max_workers=2) if with_pool else None
    try:
        with pytest.raises(SweepError, match=r"failing failed at point 2 \{'x': 2\}") as info:
            sweep(failing, {"x": [0, 1, 2, 3]}, executor=pool, progress=False,
                  on_error="raise")
    finally:
        if pool is not None:
            pool.shutdown()
    assert isinstance(info.value.__cause__, ArithmeticError)


@pytest.mark.parametrize("with_pool", [False, True], ids=["serial", "processes"])
def test_failing_point_is_recorded_and_the_others_finish(with_pool):
    pool = ProcessPoolExecutor(max_workers=2) if with_pool else None
    try:
        with pytest.warns(RuntimeWarning, match=r"1 of 4 points failed.*point 2: "
                          r"ArithmeticError: no twos"):
            table = sweep(failing, {"x": [0, 1, 2, 3]}, executor=pool, progress=False)
    finally:
        if pool is not None:
            pool.shutdown()
    assert table.failed == (2,)
    assert table.rows[2] == {"x": 2, "failure": "ArithmeticError: no twos"}
    assert [table.rows[k]["x2"] for k in (0, 1, 3)] == [0, 2, 6]
    assert np.isnan(table.column("x2")[2])


def test_progress_bar_reports_every_point(capsys):
    sweep(square, {"x": [1.0, 2.0, 3.0]}, progress=True, description="squares")
    err = capsys.readouterr().err
    assert "squares" in err and "3/3" in err


# ---------------------------------------------------------------------------- table
def test_csv_round_trip_is_lossless():
    table = sweep(square, {"x": [0.1, 1.0 / 3.0], "offset": [2.0]}, progress=False)
    rows = list(csv.DictReader(io.StringIO(table.to_csv())))
    assert [float(r["square"]) for r in rows] == table.column("square").tolist()
    assert list(rows[0]) == list(table.columns)


def test_csv_leaves_out_object_columns_and_writes_a_file(tmp_path):
    table = SweepResult(rows=({"a": 1, "obj": object()}, {"a": 2, "obj": object()}),
                        parameters=("a",), outputs=("obj",))
    path = tmp_path / "table.csv"
    text = table.to_csv(path)
    assert text.splitlines()[0] == "a" and path.read_text() == text


def test_column_where_and_missing_values():
    table = SweepResult(rows=({"v": "x", "y": 1.0}, {"v": "z"}, {"v": "x", "y": 3.0}),
                        parameters=("v",), outputs=("y",))
    y = table.column("y")
    assert y[0] == 1.0 and math.isnan(y[1])
    assert table.column("v").dtype == object
    assert table.where(v="x").column("y").tolist() == [1.0, 3.0]
    with pytest.raises(KeyError, match="column must be one of v, y"):
        table.column("nope")
    with pytest.raises(KeyError, match="where"):
        table.where(nope=1)


def test_to_pandas_or_a_clear_import_error():
    table = sweep(square, {"x": [1.0, 2.0]}, progress=False)
    try:
        import pandas  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="pip install pandas"):
            table.to_pandas()
    else:
        frame = table.to_pandas()
        assert list(frame.columns) == ["x", "square"] and frame["square"].tolist() == [1.0, 4.0]


def test_pareto_front_keeps_only_non_dominated_points():
    time = [1.0, 2.0, 3.0, 2.5, np.nan, 1.0]
    error = [3.0, 1.0, 0.5, 2.0, 0.1, 3.0]
    assert pareto_front(time, error).tolist() == [True, True, True, False, False, True]
    with pytest.raises(ValueError, match="two objectives"):
        pareto_front([1.0])


# ---------------------------------------------------------------------------- tasks
def test_tasks_are_picklable(short_task):
    for task in (short_task, SceneTask(scene="kane-spinup")):
        assert pickle.loads(pickle.dumps(task)) == task


def test_response_amplitudes_split_at_the_torque_end(spacecraft_system):
    model = flexctl.build_model(spacecraft_system, n_modes=4)
    result = flexctl.simulate(model, SHORT, torque=flexctl.SineTorque(peak_torque=50.0,
                                                                      duration=2.0))
    peak, residual = response_amplitudes(result, 2.0)
    tip = np.abs(result.tip_deflection)
    assert peak == tip[result.t <= 2.0].max() and residual == tip[result.t > 2.0].max()
    assert max(peak, residual) == pytest.approx(result.peak_tip_deflection)
    assert math.isnan(response_amplitudes(result, 100.0)[1])


def test_point_mass_task_reproduces_paper_000_with_and_without_mass(short_task):
    with_mass = short_task()                       # the scene's 0.085 kg at 0.9 l
    without = short_task(mass_ratio=0.0)
    assert with_mass["mass"] == pytest.approx(0.085)
    assert with_mass["position"] == pytest.approx(0.9 * 1.8)
    for out, (peak, residual) in ((with_mass, (0.263, 0.141)), (without, (0.223, 0.081))):
        assert out["status"] == "ok"
        assert out["peak_amplitude"] == pytest.approx(peak, rel=PAPER_TOLERANCE)
        assert out["residual_amplitude"] == pytest.approx(residual, rel=PAPER_TOLERANCE)


def test_point_mass_task_at_zero_ratio_is_the_bare_beam(short_task, bare_hub_beam_system):
    bare = flexctl.build_model(bare_hub_beam_system, n_modes=short_task.n_modes)
    out = short_task(mass_ratio=0.0)
    assert out["mass"] == 0.0
    assert out["first_frequency"] == pytest.approx(bare.natural_frequencies(hub="free")[0],
                                                   rel=1e-12)
    # A mass at the root adds no modal mass, only m b^2 to the hub inertia (3e-4 kg m^2 on
    # about 3.5): the amplitudes of the bare beam within 1e-3.
    at_root = short_task(mass_position_ratio=0.0)
    assert at_root["peak_amplitude"] == pytest.approx(out["peak_amplitude"], rel=1e-3)
    assert at_root["first_frequency"] == pytest.approx(out["first_frequency"], rel=1e-3)


@pytest.mark.parametrize("kwargs, match", [
    pytest.param({"mass_ratio": 1.5}, "mass_ratio must be a number in", id="ratio>1"),
    pytest.param({"mass_position_ratio": -0.1}, "mass_position_ratio", id="position<0"),
])
def test_point_mass_task_rejects_ratios_outside_0_1(short_task, kwargs, match):
    with pytest.raises(ValueError, match=match):
        short_task(**kwargs)


def test_point_mass_task_validates_its_settings(hub_beam_mass_system):
    push = flexctl.SineTorque(peak_torque=2.0, duration=2.0)
    with pytest.raises(ValueError, match="t_final must exceed the torque duration 2 s"):
        PointMassAmplitudes(system=hub_beam_mass_system, torque=push, t_final=1.0)
    with pytest.raises(TypeError, match="system must be a HubBeam"):
        PointMassAmplitudes(system="beam", torque=push)
    with pytest.raises(ValueError, match="sine_torque scene"):
        PointMassAmplitudes.from_scene("kane-spinup")


def test_mass_softening_trends_of_paper_000(short_task):
    """Negligible for d/l <= 0.3, growing above; growing with the mass ratio."""
    with ProcessPoolExecutor(max_workers=2) as pool:
        by_position = sweep(short_task, {"mass_position_ratio": [0.0, 0.15, 0.3, 0.6, 0.9]},
                            executor=pool, progress=False)
        by_mass = sweep(short_task, {"mass_ratio": [0.0, 0.25, 0.5, 1.0]}, executor=pool,
                        progress=False)
    for column in ("peak_amplitude", "residual_amplitude"):
        d = by_position.column(column)
        assert np.all(np.abs(d[:3] / d[0] - 1) < 0.02), column
        assert d[2] < d[3] < d[4] and d[4] > 1.15 * d[0], column
        m = by_mass.column(column)
        assert np.all(np.diff(m) > 0), column


def test_scene_task_sweeps_overrides(kane_system):
    table = sweep(SceneTask(scene="kane-spinup", keep_result=True),
                  {"model.variant": ["first_order", "zero_order"], "maneuver.spin_rate": [4.0]},
                  progress=False)
    first, zero = table.rows
    assert first["status"] == "ok" and zero["status"] == "diverged"
    assert zero["t_end"] < first["t_end"] == 30.0
    assert first["result"].model.variant == "first_order"
    assert zero["result"].peak_tip_deflection == pytest.approx(zero["peak_tip_deflection"])
    assert "result" not in table.scalar_columns()


def test_scene_task_needs_a_controller_factory_for_slews():
    with pytest.raises(flexctl.SceneError, match="controller_factory"):
        SceneTask(scene="slew-90")()


def test_scene_task_runs_a_slew_with_the_controllers_factory():
    from controllers import from_spec

    out = SceneTask(scene="slew-90", controller_factory=from_spec)(
        **{"controller.kind": "zvd", "model.modes": 2, "simulation.t_final": 4.0})
    assert out["status"] == "ok"
    assert out["peak_torque"] <= 6.0 + 1e-9
    assert abs(out["final_error"]) < 0.01 and out["maneuver_end"] > 2.0


# ---------------------------------------------------------------------------- Dask
def test_sweep_on_a_dask_local_cluster(short_task):
    distributed = pytest.importorskip("distributed")
    grid = {"mass_ratio": [0.0, 0.5]}
    expected = sweep(short_task, grid, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        table = sweep(short_task, grid, executor=client.get_executor(), progress=False)
        # The work ran on the cluster's worker processes, not here.
        assert len(client.scheduler_info()["workers"]) == 2
    assert table.parameters == expected.parameters
    for got, want in zip(table.rows, expected.rows):
        assert got["peak_amplitude"] == pytest.approx(want["peak_amplitude"], rel=1e-9)
        assert got["residual_amplitude"] == pytest.approx(want["residual_amplitude"], rel=1e-9)
    assert table.column("peak_amplitude")[1] > table.column("peak_amplitude")[0]


def test_dataclass_replace_keeps_task_settings(short_task):
    longer = dataclasses.replace(short_task, t_final=8.0)
    assert longer.t_final == 8.0 and longer.torque == short_task.torque
