"""Sweeps that keep going and resume: the store, lost workers, interrupts, per-task seeds.

Every interrupted, broken or redistributed sweep is compared with one uninterrupted serial run
of the same grid and seed, row for row and bit for bit (:func:`assert_same_rows`).
"""

import dataclasses
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import flexctl
from flexctl.app.sweep import PointMassAmplitudes, SweepError, sweep
from flexctl.app.sweep_store import StoreError, SweepStore, TaskOutcome, task_key, task_seed
from flexctl.app.task_fingerprint import task_fingerprint

GRID = {"x": list(range(12))}
SEED = 5
#: Wall-time bound on waiting for a subprocess to write its first rows, s (a guard against a
#: hang, not a measurement).
PATIENCE = 120.0


def noisy(x, seed):
    """A cheap seeded task: draws that depend on the seed it is given."""
    rng = np.random.default_rng(seed)
    return {"draw": x + float(rng.standard_normal()), "pair": tuple(rng.uniform(size=2))}


def slow_noisy(x, seed):
    """:func:`noisy`, slow enough to be interrupted mid-sweep."""
    time.sleep(0.1)
    return noisy(x, seed)


def unseeded(x):
    return {"y": 3 * x}


@dataclasses.dataclass(frozen=True)
class DieOnce:
    """:func:`noisy`, except that the first run at ``x == victim`` ends its process (a worker
    killed under its task: out of memory, SIGKILL); ``marker`` records that it happened."""

    marker: str
    victim: int = 3

    def __call__(self, x, seed):
        if x == self.victim and not os.path.exists(self.marker):
            Path(self.marker).touch()
            os._exit(1)
        return noisy(x, seed)


@dataclasses.dataclass(frozen=True)
class InterruptOnce:
    """:func:`noisy`, except that the first run at ``x == victim`` is a Ctrl-C."""

    marker: str
    victim: int = 5

    def __call__(self, x, seed):
        if x == self.victim and not os.path.exists(self.marker):
            Path(self.marker).touch()
            raise KeyboardInterrupt
        return noisy(x, seed)


def bits(value):
    """A value with every float as its IEEE bytes (NaN and -0.0 included)."""
    if isinstance(value, float):
        return np.float64(value).tobytes()
    if isinstance(value, (tuple, list)):
        return type(value)(bits(v) for v in value)
    if isinstance(value, dict):
        return {k: bits(v) for k, v in value.items()}
    return value


def assert_same_rows(got, want):
    """Same columns in the same order, same rows, floats bit for bit."""
    assert got.columns == want.columns
    assert [list(r) for r in got.rows] == [list(r) for r in want.rows]
    assert [bits(r) for r in got.rows] == [bits(r) for r in want.rows]


@pytest.fixture(scope="module")
def uninterrupted():
    return sweep(noisy, GRID, seed=SEED, progress=False)


def stored_keys(path) -> int:
    """Tasks committed to a store file, read as another process would."""
    try:
        with sqlite3.connect(path) as db:
            return db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
    except sqlite3.OperationalError:        # not created yet
        return 0


# ---------------------------------------------------------------------------- keys, seeds
def test_keys_are_canonical_and_seeds_depend_on_sweep_seed_and_key_only():
    assert task_key({"b": 1, "a": 0.1}) == task_key({"a": 0.1, "b": 1}) == '{"a":0.1,"b":1}'
    assert task_key({"a": np.float64(0.1)}) == task_key({"a": 0.1})
    assert task_key({"a": 1}) != task_key({"a": 1.0})
    key = task_key({"x": 3})
    assert task_seed(SEED, key) == task_seed(SEED, key)
    assert len({task_seed(SEED, key), task_seed(SEED + 1, key),
                task_seed(SEED, task_key({"x": 4}))}) == 3
    assert 0 <= task_seed(2**40, key) < 2**63
    with pytest.raises(TypeError, match="sweep point values must be numbers.*got object"):
        task_key({"a": object()})


@pytest.mark.parametrize("run", [
    pytest.param(lambda: sweep(noisy, GRID, seed=SEED, progress=False), id="serial"),
    pytest.param(lambda: sweep(noisy, {"x": GRID["x"][::-1]}, seed=SEED, progress=False),
                 id="reversed"),
    pytest.param(lambda: sweep(noisy, GRID, seed=SEED, progress=False,
                               executor=ThreadPoolExecutor(3)), id="threads-3"),
    pytest.param(lambda: sweep(noisy, GRID, seed=SEED, progress=False,
                               executor=lambda: ProcessPoolExecutor(2)), id="processes-2"),
])
def test_each_task_draws_from_its_own_seed_whatever_the_order_or_workers(run, uninterrupted):
    table = run()
    by_x = {row["x"]: row for row in table}
    assert [bits(by_x[row["x"]]) for row in uninterrupted] == [bits(r) for r in uninterrupted]
    draws = table.column("draw") - table.column("x")
    assert len(set(draws.tolist())) == len(draws)         # independent streams per point


def test_another_sweep_seed_gives_other_draws_and_a_point_seed_is_kept(uninterrupted):
    other = sweep(noisy, GRID, seed=SEED + 1, progress=False)
    assert not np.any(other.column("draw") == uninterrupted.column("draw"))
    given = sweep(noisy, [{"x": 1, "seed": 7}], progress=False)
    assert given.rows[0]["draw"] == noisy(1, 7)["draw"]


# ---------------------------------------------------------------------------- store, resume
def test_resume_runs_only_the_missing_tasks_and_equals_one_run(tmp_path, uninterrupted):
    store = tmp_path / "runs.sqlite"
    first = sweep(noisy, {"x": GRID["x"][:5]}, seed=SEED, store=store, progress=False)
    assert first.resumed == 0 and stored_keys(store) == 5
    whole = sweep(noisy, GRID, seed=SEED, store=store, resume=True, progress=False)
    assert whole.resumed == 5 and stored_keys(store) == len(GRID["x"])
    assert_same_rows(whole, uninterrupted)
    again = sweep(noisy, GRID, seed=SEED, store=store, resume=True, progress=False)
    assert again.resumed == len(GRID["x"])
    assert_same_rows(again, uninterrupted)


@pytest.mark.parametrize("call, error, match", [
    pytest.param(lambda s: sweep(noisy, GRID, seed=SEED, store=s, progress=False),
                 StoreError, "already holds 12 tasks: pass resume=True", id="no-resume"),
    pytest.param(lambda s: sweep(noisy, GRID, seed=SEED + 1, store=s, resume=True,
                                 progress=False),
                 StoreError, "with seed 5; this one has seed 6", id="other-seed"),
    pytest.param(lambda s: sweep(slow_noisy, GRID, seed=SEED, store=s, resume=True,
                                 progress=False),
                 StoreError, "holds results of task .*noisy.* but this sweep runs .*slow_noisy",
                 id="other-task"),
    pytest.param(lambda s: sweep(noisy, GRID, resume=True, progress=False),
                 ValueError, "resume=True needs a store", id="resume-no-store"),
    pytest.param(lambda s: sweep(noisy, GRID, on_error="skip", progress=False),
                 ValueError, "on_error must be one of record, raise; got 'skip'", id="on-error"),
    pytest.param(lambda s: sweep(noisy, GRID, retries=-1, progress=False),
                 ValueError, "retries must be an integer >= 0; got -1", id="retries"),
    pytest.param(lambda s: sweep(noisy, GRID, seed=-2, progress=False),
                 ValueError, "seed must be an integer >= 0; got -2", id="seed"),
])
def test_a_store_is_resumed_only_by_the_same_sweep(tmp_path, call, error, match):
    store = tmp_path / "runs.sqlite"
    sweep(noisy, GRID, seed=SEED, store=store, progress=False)
    with pytest.raises(error, match=match):
        call(store)
    assert stored_keys(store) == len(GRID["x"])         # nothing lost or overwritten


def test_a_file_that_is_not_a_store_is_refused_by_name(tmp_path):
    garbage = tmp_path / "notes.txt"
    garbage.write_text("not a database, but long enough to have a header page\n" * 40)
    with pytest.raises(StoreError, match="sweep store .*notes.txt.* is not an SQLite database"):
        sweep(noisy, GRID, store=garbage, progress=False)


def test_a_task_without_seed_is_resumed_whatever_the_sweep_seed(tmp_path):
    store = tmp_path / "runs.sqlite"
    sweep(unseeded, {"x": [1, 2]}, seed=1, store=store, progress=False)
    table = sweep(unseeded, {"x": [1, 2, 3]}, seed=2, store=store, resume=True, progress=False)
    assert table.resumed == 2 and table.column("y").tolist() == [3.0, 6.0, 9.0]


def test_failures_are_stored_with_their_error_and_can_be_run_again(tmp_path):
    store = tmp_path / "runs.sqlite"
    task = InterruptOnce(marker=str(tmp_path / "never"), victim=-1)
    grid = {"x": [0, 1, "two", 3]}                   # "two" + float raises TypeError
    with pytest.warns(RuntimeWarning, match="1 of 4 points failed"):
        table = sweep(task, grid, seed=SEED, store=store, progress=False)
    assert table.failed == (2,) and table.rows[2]["failure"].startswith("TypeError: ")
    assert "4 rows, 1 failed" in repr(table)
    assert table.where(x="two").failed == (0,) and table.where(x=3).failed == ()
    assert [r["x"] for r in table.without_failures()] == [0, 1, 3]
    with pytest.raises(StoreError, match="holds results of task .*InterruptOnce"):
        SweepStore(store, task="other", fingerprint=task_fingerprint(task), seed=SEED,
                   resume=True)
    with SweepStore(store, task=kept_task_name(task), fingerprint=task_fingerprint(task),
                    seed=SEED, resume=True) as kept:
        assert kept.failed_keys() == [task_key({"x": "two"})]
        outcome = kept.outcomes()[task_key({"x": "two"})]
        assert outcome.status == "failed" and outcome.error == table.rows[2]["failure"]
        assert outcome.seed == task_seed(SEED, task_key({"x": "two"}))
        assert kept.forget(kept.failed_keys()) == 1
    with pytest.warns(RuntimeWarning, match="1 of 4 points failed"):
        again = sweep(task, grid, seed=SEED, store=store, resume=True, progress=False)
    assert again.resumed == 3 and again.failed == (2,)
    with pytest.raises(SweepError, match=r"failed at point 2 \{'x': 'two'\}: TypeError"):
        sweep(task, grid, seed=SEED, store=store, resume=True, on_error="raise",
              progress=False)


def kept_task_name(task) -> str:
    return f"{type(task).__module__}.{type(task).__qualname__}"


def test_progress_shows_done_failed_and_remaining(capsys):
    with pytest.warns(RuntimeWarning):
        sweep(InterruptOnce(marker="/nonexistent/never", victim=-1), {"x": [0, "one"]},
              progress=True, description="mixed")
    err = capsys.readouterr().err
    assert "mixed" in err and "2/2" in err and "done 2, failed 1, remaining 0" in err


# ---------------------------------------------------------------------------- interrupts
def test_ctrl_c_in_a_serial_sweep_keeps_the_finished_rows_and_resumes(tmp_path, uninterrupted):
    store = tmp_path / "runs.sqlite"
    task = InterruptOnce(marker=str(tmp_path / "interrupted"))
    with pytest.raises(KeyboardInterrupt):
        sweep(task, GRID, seed=SEED, store=store, progress=False)
    assert stored_keys(store) == task.victim                  # every row before it committed
    table = sweep(task, GRID, seed=SEED, store=store, resume=True, progress=False)
    assert table.resumed == task.victim
    assert_same_rows(table, uninterrupted)


def test_sigint_to_a_process_pool_sweep_then_resume_equals_one_run(tmp_path):
    store = tmp_path / "runs.sqlite"
    grid = {"x": list(range(40))}
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from concurrent.futures import ProcessPoolExecutor
        from flexctl.app.sweep import sweep
        from test_sweep_store import slow_noisy
        with ProcessPoolExecutor(2) as pool:
            sweep(slow_noisy, {grid!r}, executor=pool, seed={SEED}, store={str(store)!r},
                  progress=False)
        """)
    env = {**os.environ, "PYTHONPATH": str(Path(flexctl.__file__).parents[1])}
    child = subprocess.Popen([sys.executable, "-c", script], env=env, stderr=subprocess.PIPE,
                             text=True)
    deadline = time.monotonic() + PATIENCE
    while stored_keys(store) < 4 and child.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=PATIENCE)
    assert child.returncode != 0 and "KeyboardInterrupt" in err
    kept = stored_keys(store)
    assert 4 <= kept < len(grid["x"])
    with ProcessPoolExecutor(2) as pool:
        table = sweep(slow_noisy, grid, executor=pool, seed=SEED, store=store, resume=True,
                      progress=False)
    assert table.resumed == kept
    assert_same_rows(table, sweep(noisy, grid, seed=SEED, progress=False))


# ---------------------------------------------------------------------------- lost workers
def test_a_broken_process_pool_is_replaced_by_the_factory(tmp_path, uninterrupted):
    task = DieOnce(marker=str(tmp_path / "died"))
    table = sweep(task, GRID, seed=SEED, executor=lambda: ProcessPoolExecutor(2),
                  store=tmp_path / "runs.sqlite", progress=False)
    assert os.path.exists(task.marker) and table.failed == ()
    assert_same_rows(table, uninterrupted)


def test_a_broken_pool_given_is_named_and_the_store_resumes(tmp_path, uninterrupted):
    task = DieOnce(marker=str(tmp_path / "died"))
    store = tmp_path / "runs.sqlite"
    with ProcessPoolExecutor(2) as pool, \
            pytest.raises(SweepError, match="the executor broke .*BrokenProcessPool.*factory"):
        sweep(task, GRID, seed=SEED, executor=pool, store=store, progress=False)
    with ProcessPoolExecutor(2) as pool:
        table = sweep(task, GRID, seed=SEED, executor=pool, store=store, resume=True,
                      progress=False)
    assert_same_rows(table, uninterrupted)


def test_a_task_that_always_kills_its_worker_is_recorded_after_its_retries():
    class Lost:
        """An executor whose every future is lost with its worker."""

        def submit(self, fn, *args):
            from concurrent.futures import Future
            from concurrent.futures.process import BrokenProcessPool

            future = Future()
            future.set_exception(BrokenProcessPool("a child process terminated abruptly"))
            return future

        def shutdown(self, wait=True, cancel_futures=False):
            pass

    with pytest.warns(RuntimeWarning, match="2 of 2 points failed"):
        table = sweep(unseeded, {"x": [1, 2]}, executor=Lost, retries=1, progress=False)
    assert table.rows[0]["failure"] == ("lost 2 times: BrokenProcessPool: a child process "
                                        "terminated abruptly")


def test_a_worker_killed_on_a_dask_cluster_loses_no_row(tmp_path, uninterrupted):
    distributed = pytest.importorskip("distributed")
    task = DieOnce(marker=str(tmp_path / "died"))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        table = sweep(task, GRID, seed=SEED, executor=client.get_executor(),
                      store=tmp_path / "runs.sqlite", progress=False)
    assert os.path.exists(task.marker) and table.failed == ()
    assert_same_rows(table, uninterrupted)


# ---------------------------------------------------------------------------- a real task
def test_a_resumed_point_mass_sweep_equals_one_run(tmp_path):
    task = PointMassAmplitudes.from_scene("hub-beam-mass", t_final=6.0)
    grid = {"mass_ratio": [0.0, 0.5, 1.0]}
    store = tmp_path / "runs.sqlite"
    sweep(task, {"mass_ratio": grid["mass_ratio"][:2]}, store=store, progress=False)
    table = sweep(task, grid, store=store, resume=True, progress=False)
    assert table.resumed == 2
    assert_same_rows(table, sweep(task, grid, progress=False))


def test_outcomes_round_trip_through_the_store_bit_for_bit(tmp_path):
    outputs = {"tiny": 5e-324, "third": 1.0 / 3.0, "nan": float("nan"), "neg0": -0.0,
               "inf": float("inf"), "flag": True, "count": 3, "text": "ok",
               "array": np.linspace(0.0, 1.0, 7)}
    with SweepStore(tmp_path / "runs.sqlite", task="t", fingerprint="f", seed=None) as store:
        store.record("k", TaskOutcome(status="ok", outputs=outputs))
        back = store.outcomes()["k"].outputs
    assert bits({k: v for k, v in back.items() if k != "array"}) == \
        bits({k: v for k, v in outputs.items() if k != "array"})
    assert type(back["flag"]) is bool and type(back["count"]) is int
    assert back["array"].tobytes() == outputs["array"].tobytes()


# ---------------------------------------------------------------------------- the users
def test_a_resumed_monte_carlo_study_equals_one_run(tmp_path):
    from controllers import design_pd
    from controllers.analysis.robustness import Dispersion, RobustnessTask, robustness_summary

    system = flexctl.load_scene("slew-90").system
    pd = design_pd(flexctl.build_model(system, 2), bandwidth=2.0, damping_ratio=0.9)
    dispersion = Dispersion(youngs_modulus=0.3, point_mass=0.5, hub_inertia=0.3)
    task = RobustnessTask(system=system, controller=pd, n_modes=3, dispersion=dispersion)
    store = tmp_path / "robustness.sqlite"
    sweep(task, {"sample": range(3)}, seed=SEED, store=store, progress=False)
    with ThreadPoolExecutor(2) as pool:
        table = sweep(task, {"sample": range(6)}, seed=SEED, store=store, resume=True,
                      executor=pool, progress=False)
    assert table.resumed == 3
    assert_same_rows(table, sweep(task, {"sample": range(6)}, seed=SEED, progress=False))
    first = dispersion.draw(task_seed(SEED, task_key({"sample": 0})))
    assert {k: table.rows[0][k] for k in first} == first
    assert len(set(table.column("youngs_modulus_scale").tolist())) == 6
    assert robustness_summary(table).n_samples == 6
    failed = dataclasses.replace(table, rows=table.rows[:5] + ({"sample": 5, "failure":
                                                                  "LinAlgError: singular"},),
                                 failed=(5,))
    with pytest.raises(ValueError, match="row 5 is a failed sample .*without_failures"):
        robustness_summary(failed)
    assert robustness_summary(failed.without_failures()).n_samples == 5
    given = dataclasses.replace(task, dispersion=None)        # factors as the points
    samples = dispersion.samples(2, seed=1)
    rows = sweep(given, samples, seed=SEED, progress=False).rows
    assert bits([dict(r) for r in rows]) == bits([given(**s) for s in samples])


@pytest.mark.parametrize("call, match", [
    pytest.param(lambda t, d: t(sample=1), "sample=1 needs a dispersion", id="no-dispersion"),
    pytest.param(lambda t, d: dataclasses.replace(t, dispersion=d)(youngs_modulus_scale=1.1,
                                                                   seed=3),
                 "draws its factors from the seed", id="factors-and-dispersion"),
    pytest.param(lambda t, d: dataclasses.replace(t, dispersion=d)(sample=2),
                 "got seed=None", id="no-seed"),
    pytest.param(lambda t, d: dataclasses.replace(t, dispersion=0.1),
                 "dispersion must be a Dispersion; got float", id="not-a-dispersion"),
    pytest.param(lambda t, d: d.draw(-1), "draw seed must be an integer >= 0; got -1",
                 id="negative-seed"),
])
def test_monte_carlo_draws_need_a_dispersion_and_a_seed(call, match):
    from controllers import design_pd
    from controllers.analysis.robustness import Dispersion, RobustnessTask

    system = flexctl.load_scene("slew-90").system
    pd = design_pd(flexctl.build_model(system, 2), bandwidth=2.0, damping_ratio=0.9)
    task = RobustnessTask(system=system, controller=pd, n_modes=2)
    with pytest.raises((ValueError, TypeError), match=match):
        call(task, Dispersion())


def test_a_resumed_bench_equals_one_run(tmp_path):
    from flexctl.app.bench import BenchConfig, run_bench
    from flexctl.app.cli import EXIT_BAD_INPUT, EXIT_OK, main

    config = BenchConfig(scenes=("kane-spinup",), modes=(1, 2), variants=("first_order",),
                         methods=("cvodes", "DOP853"), rtols=(1e-6,), reference_modes=4,
                         reference_rtol=1e-10, t_final=5.0)
    store = tmp_path / "bench.sqlite"
    whole = run_bench(config, tmp_path / "one", progress=False, store=store)[0]
    assert stored_keys(store) == len(whole.rows) == 4
    with sqlite3.connect(store) as db:          # a bench stopped after its first two runs
        db.execute("DELETE FROM runs WHERE rowid > 2")
    resumed = run_bench(config, tmp_path / "two", progress=False, store=store, resume=True)[0]
    assert stored_keys(store) == 4
    got = [dataclasses.asdict(r) for r in resumed.rows]
    want = [dataclasses.asdict(r) for r in whole.rows]
    assert bits(got[:2]) == bits(want[:2])             # taken from the store, as measured
    for row in got + want:                             # run again: all but the wall time
        row.pop("wall_time_s")
    assert bits(got) == bits(want)
    args = ["bench", "--scene", "kane-spinup", "--modes", "1,2", "--variants", "first_order",
            "--methods", "cvodes,DOP853", "--rtols", "1e-6", "--reference-modes", "4",
            "--t-final", "5", "--no-progress", "--out", str(tmp_path / "cli"),
            "--store", str(store)]
    assert main(args) == EXIT_BAD_INPUT                # it holds runs: --resume or remove it
    assert main(args + ["--resume"]) == EXIT_OK
    with sqlite3.connect(store) as db:                 # the store's own record of its task
        meta = dict(db.execute("SELECT name, value FROM meta"))
    db.close()
    key = task_key({"scene": "kane-spinup", "variant": "first_order", "n_modes": 1,
                    "method": "cvodes", "rtol": 1e-6})
    with SweepStore(store, task=meta["task"], fingerprint=meta["fingerprint"], seed=None,
                    resume=True) as kept:              # a row of an older BenchRow
        kept.record(key, TaskOutcome(status="ok", outputs={"scene": "kane-spinup"}))
    with pytest.raises(StoreError, match=f"sweep store '{store}' holds under task "
                       r'\{"method":"cvodes".* a row that is not a bench row \(.*missing'):
        run_bench(config, tmp_path / "three", progress=False, store=store, resume=True)


calls = []


def logged(x):
    calls.append(x)
    return {"y": x}


def test_a_serial_sweep_runs_in_grid_order_and_a_repeated_point_once():
    calls.clear()
    table = sweep(logged, [{"x": 3}, {"x": 1}, {"x": 3}, {"x": 2}], progress=False)
    assert calls == [3, 1, 2]
    assert table.column("y").tolist() == [3.0, 1.0, 3.0, 2.0]
