"""A sweep store knows what it holds: task fingerprints, refusals by name, crash safety.

Every way a store can be wrong (another task, another format, a foreign or damaged file, a
damaged row) ends in a :class:`~flexctl.app.sweep_store.StoreError` that names the file; a
corrupted store, at random, is refused or gives the rows of a clean run, bit for bit.
"""

import dataclasses
import functools
import hashlib
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import flexctl
from flexctl.app.sweep import PointMassAmplitudes, SceneTask, sweep
from flexctl.app.sweep_store import StoreError, SweepStore, TaskOutcome, task_key
from flexctl.app.task_fingerprint import task_fingerprint

GRID = {"x": list(range(12))}
SEED = 5
#: Wall-time bound on waiting for a subprocess, s (a guard against a hang, not a measurement).
PATIENCE = 120.0
#: Corrupted copies of a store in the property test, and the seed that draws them.
N_CORRUPTIONS, CORRUPTION_SEED = 50, 20240611
#: Float outputs of a row big enough that SQLite writes its pages to the ``-wal`` file before
#: the commit (the page cache holds 2 MB): 8 MB.
BIG_ROW = 1_000_000
#: A global that :func:`labelled` names: a frozenset, whose order differs between processes.
LABELS = frozenset({"alpha", "beta", "gamma", "delta"})


def noisy(x, seed):
    """A cheap seeded task: draws that depend on the seed it is given."""
    rng = np.random.default_rng(seed)
    return {"draw": x + float(rng.standard_normal()), "pair": tuple(rng.uniform(size=2))}


def labelled(x):
    """A task naming a module global (a frozenset, ordered by hash in each process)."""
    return {"n": x + len(LABELS)}


SQUARE = lambda x: {"y": x * x}  # noqa: E731  (a lambda is the point here)


@dataclasses.dataclass(frozen=True)
class Scaled:
    """A callable task with a field and an array."""

    factor: float
    offsets: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(2))

    def __call__(self, x):
        return {"y": self.factor * x + float(self.offsets.sum())}


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
    """Same columns, same rows, floats bit for bit."""
    assert got.columns == want.columns
    assert [bits(dict(r)) for r in got.rows] == [bits(dict(r)) for r in want.rows]


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """``(store file, table)`` of one uninterrupted stored sweep of :func:`noisy`."""
    path = tmp_path_factory.mktemp("clean") / "runs.sqlite"
    table = sweep(noisy, GRID, seed=SEED, store=path, progress=False)
    assert not Path(f"{path}-wal").exists()          # checkpointed: the file is the store
    return path, table


def store_copy(clean, tmp_path) -> Path:
    path = tmp_path / "runs.sqlite"
    shutil.copyfile(clean[0], path)
    return path


def execute(path, *statements) -> None:
    """Change a store file behind flexctl's back (as a damaged disk or another tool would)."""
    with sqlite3.connect(path) as db:
        for statement in statements:
            db.execute(statement)
    db.close()


def digest(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def child_env() -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(flexctl.__file__).parents[1]), str(Path(__file__).parent)])}


# ---------------------------------------------------------------------------- fingerprints
def test_a_fingerprint_sees_code_closures_defaults_and_globals():
    def f(x):
        return {"y": x + 1}

    first = task_fingerprint(f)
    for x in range(2000):                            # bytecode specialised by running
        f(x)
    assert task_fingerprint(f) == first

    def f(x):                                        # redefined, the same name
        return {"y": x + 2}

    assert task_fingerprint(f) != first
    assert task_fingerprint(lambda x: x) != task_fingerprint(lambda x: x + 1)
    assert task_fingerprint(lambda x, k=1: x * k) != task_fingerprint(lambda x, k=2: x * k)

    def closing(k):
        return lambda x: x * k

    assert task_fingerprint(closing(1)) == task_fingerprint(closing(1))
    assert task_fingerprint(closing(1)) != task_fingerprint(closing(2))
    namespaces = [{"K": k} for k in (1, 1, 2)]
    for namespace in namespaces:                     # a global by value, a helper by code
        exec("def helper(x):\n    return x * K\ndef task(x):\n    return helper(x)\n",
             namespace)
    assert len({task_fingerprint(n["task"]) for n in namespaces}) == 2
    with pytest.raises(TypeError, match="task_fingerprint task must be callable; got int"):
        task_fingerprint(3)


def test_a_fingerprint_sees_the_fields_of_a_callable_task_and_the_inputs_given():
    assert task_fingerprint(Scaled(2.0)) == task_fingerprint(Scaled(2.0))
    assert task_fingerprint(Scaled(2.0)) != task_fingerprint(Scaled(3.0))
    assert task_fingerprint(Scaled(2.0)) != task_fingerprint(Scaled(2.0, np.ones(2)))
    assert task_fingerprint(SceneTask(scene="kane-spinup")) != \
        task_fingerprint(SceneTask(scene="kane-spinup", keep_result=True))
    assert task_fingerprint(SceneTask(scene="kane-spinup")) != \
        task_fingerprint(SceneTask(scene="spacecraft-torque"))
    task = PointMassAmplitudes.from_scene("hub-beam-mass", t_final=6.0)
    assert task_fingerprint(task) != task_fingerprint(dataclasses.replace(task, t_final=7.0))
    assert task_fingerprint(functools.partial(noisy, seed=1)) != \
        task_fingerprint(functools.partial(noisy, seed=2))
    assert task_fingerprint(identity, "setting a") != task_fingerprint(identity, "setting b")


def identity(x):
    return x


FINGERPRINTED = textwrap.dedent("""
    import functools
    import numpy as np
    from flexctl.app.sweep import PointMassAmplitudes, SceneTask
    from flexctl.app.task_fingerprint import task_fingerprint
    from test_sweep_store_checks import SQUARE, Scaled, labelled, noisy
    tasks = [noisy, labelled, SQUARE, Scaled(2.0, np.arange(3.0)),
             functools.partial(noisy, seed=3), SceneTask(scene="kane-spinup"),
             PointMassAmplitudes.from_scene("hub-beam-mass", t_final=6.0)]
    print(" ".join(task_fingerprint(t) for t in tasks))
    """)


def test_a_fingerprint_is_the_same_in_another_process():
    tasks = [noisy, labelled, SQUARE, Scaled(2.0, np.arange(3.0)),
             functools.partial(noisy, seed=3), SceneTask(scene="kane-spinup"),
             PointMassAmplitudes.from_scene("hub-beam-mass", t_final=6.0)]
    here = [task_fingerprint(t) for t in tasks]
    env = {**child_env(), "PYTHONHASHSEED": "12345"}  # other set orders, other ids
    child = subprocess.run([sys.executable, "-c", FINGERPRINTED], env=env, text=True,
                           capture_output=True, timeout=PATIENCE, check=False)
    assert child.returncode == 0, child.stderr
    assert child.stdout.split() == here
    assert len(set(here)) == len(here)


# ---------------------------------------------------------------------------- resume refusals
def test_a_store_refuses_a_different_task_of_the_same_name(tmp_path):
    def task(x):
        return {"y": x}

    store = tmp_path / "runs.sqlite"
    sweep(task, {"x": [1, 2]}, store=store, progress=False)

    def task(x):                                     # redefined, the same name
        return {"y": 2 * x}

    name = re.escape(f"'{task.__module__}.{task.__qualname__}'")
    with pytest.raises(StoreError, match=(
            f"^sweep store '{re.escape(str(store))}' holds results of task {name} with "
            rf"fingerprint \w{{12}}\.\.\. but this sweep runs {name} with fingerprint "
            r"\w{12}\.\.\. \(its code or inputs differ\): a resume must run the same task")):
        sweep(task, {"x": [1, 2, 3]}, store=store, resume=True, progress=False)
    sweep(lambda x: {"y": x}, {"x": [1, 2]}, store=tmp_path / "lambda.sqlite", progress=False)
    with pytest.raises(StoreError, match=r"lambda.sqlite' holds results of task '.*<lambda>'"
                       r".*\(its code or inputs differ\)"):
        sweep(lambda x: {"y": 2 * x}, {"x": [1, 2]}, store=tmp_path / "lambda.sqlite",
              resume=True, progress=False)
    sweep(Scaled(2.0), {"x": [1, 2]}, store=tmp_path / "scaled.sqlite", progress=False)
    with pytest.raises(StoreError, match="scaled.sqlite.*its code or inputs differ"):
        sweep(Scaled(3.0), {"x": [1, 2]}, store=tmp_path / "scaled.sqlite", resume=True,
              progress=False)
    table = sweep(Scaled(2.0), {"x": [1, 2, 3]}, store=tmp_path / "scaled.sqlite",
                  resume=True, progress=False)
    assert table.resumed == 2 and table.column("y").tolist() == [2.0, 4.0, 6.0]


def test_resume_false_refuses_a_full_store_and_takes_over_an_empty_one(tmp_path):
    store = tmp_path / "runs.sqlite"
    sweep(Scaled(2.0), {"x": [1]}, store=store, progress=False)
    before = digest(store)
    with pytest.raises(StoreError, match="already holds 1 tasks: pass resume=True"):
        sweep(Scaled(3.0), {"x": [1]}, store=store, progress=False)
    assert digest(store) == before
    execute(store, "DELETE FROM runs")              # a store that holds nothing ...
    table = sweep(Scaled(3.0), {"x": [1]}, store=store, progress=False)
    assert table.column("y").tolist() == [3.0]      # ... is taken over by a fresh sweep
    with pytest.raises(StoreError, match="its code or inputs differ"):
        sweep(Scaled(2.0), {"x": [1]}, store=store, resume=True, progress=False)


# ---------------------------------------------------------------------------- foreign, damaged
FORMAT_1 = """
CREATE TABLE meta (name TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE runs (key TEXT PRIMARY KEY, status TEXT NOT NULL, error TEXT, seed INTEGER,
                   attempts INTEGER NOT NULL, outputs BLOB, outputs_json TEXT,
                   finished_at REAL NOT NULL);
INSERT INTO meta VALUES ('format', '1'), ('task', 'test_sweep_store_checks.noisy'),
                        ('seed', '5');
"""


def foreign_file(kind: str, clean, tmp_path) -> Path:
    """A file that is not a usable store of :func:`noisy`'s sweep, of the given kind."""
    path = tmp_path / "runs.sqlite"
    if kind == "random-bytes":
        path.write_bytes(np.random.default_rng(1).bytes(5000))
    elif kind == "other-database":
        execute(path, "CREATE TABLE people (name TEXT)", "INSERT INTO people VALUES ('ada')")
    elif kind == "format-1":
        with sqlite3.connect(path) as db:
            db.executescript(FORMAT_1)
        db.close()
    else:
        store_copy(clean, tmp_path)
        execute(path, *{
            "extra-table": ["CREATE TABLE notes (text TEXT)"],
            "extra-column": ["ALTER TABLE runs ADD COLUMN note TEXT"],
            "format-7": ["UPDATE meta SET value = '7' WHERE name = 'format'"],
            "meta-extra-name": ["INSERT INTO meta VALUES ('owner', 'me')"],
            "meta-lost-name": ["DELETE FROM meta WHERE name = 'fingerprint'"],
            "meta-lost": ["DELETE FROM meta"],
            "meta-other-seed": ["UPDATE meta SET value = '6' WHERE name = 'seed'"],
            "meta-other-fingerprint": ["UPDATE meta SET value = 'abc' WHERE name = "
                                       "'fingerprint'"]}[kind])
    return path


@pytest.mark.parametrize("kind, match", [pytest.param(*case, id=case[0]) for case in [
    ("random-bytes", "cannot be opened: it is not an SQLite database, or it is damaged; "
                     "SQLite says DatabaseError: file is not a database"),
    ("other-database", "is not a sweep store of format 2: it holds the tables people, not "
                       r"meta and runs \(another program's file, or a damaged one\)"),
    ("extra-table", "is not a sweep store of format 2: it holds the tables meta, notes, runs, "
                    "not meta and runs"),
    ("extra-column", "is not a sweep store of format 2: its meta and runs tables are not laid "
                     "out as flexctl writes them"),
    ("format-1", r"was written in store format '1', and this flexctl reads format '2' \(format "
                 "'1' kept neither the task's fingerprint nor row checksums"),
    ("format-7", "was written in store format '7', and this flexctl reads format '2': run the "
                 "sweep again into a new store file"),
    ("meta-extra-name", r"is damaged: its meta table holds \['fingerprint', 'format', "
                        r"'owner', 'seed', 'task'\]"),
    ("meta-lost-name", r"is damaged: its meta table holds \['format', 'seed', 'task'\]"),
    ("meta-lost", "is damaged: it holds 12 tasks but no record of the sweep they belong to"),
    ("meta-other-seed", "belongs to a sweep with seed 6; this one has seed 5"),
    ("meta-other-fingerprint", r"holds results of task '.*noisy' with fingerprint abc\.\.\. "
                               r"but this sweep runs '.*noisy' with fingerprint \w{12}\.\.\. "
                               r"\(its code or inputs differ\)"),
]])
def test_a_foreign_or_damaged_store_is_refused_by_name_and_left_alone(clean, tmp_path, kind,
                                                                       match):
    path = foreign_file(kind, clean, tmp_path)
    before = digest(path)
    with pytest.raises(StoreError, match=f"^sweep store '{re.escape(str(path))}' {match}"):
        sweep(noisy, GRID, seed=SEED, store=path, resume=True, progress=False)
    assert digest(path) == before                   # refused before anything is written


def test_a_folder_or_an_empty_file_as_store(tmp_path):
    with pytest.raises(StoreError, match=f"sweep store '{re.escape(str(tmp_path))}' is a "
                       "folder; give the path of a file"):
        sweep(noisy, GRID, seed=SEED, store=tmp_path, progress=False)
    empty = tmp_path / "empty.sqlite"
    empty.touch()                                  # an empty file is an empty database
    table = sweep(noisy, {"x": [1]}, seed=SEED, store=empty, resume=True, progress=False)
    assert table.resumed == 0
    assert sweep(noisy, {"x": [1]}, seed=SEED, store=empty, resume=True,
                 progress=False).resumed == 1


def test_a_damaged_row_is_refused_by_its_key_and_forgotten_runs_again(clean, tmp_path):
    path = store_copy(clean, tmp_path)
    key = task_key({"x": 3})
    execute(path, f"UPDATE runs SET attempts = 2 WHERE key = '{key}'")
    with pytest.raises(StoreError, match=f"^sweep store '{re.escape(str(path))}' is damaged: "
                       f"the row of task {re.escape(key)} fails its checksum .*forget that task"):
        sweep(noisy, GRID, seed=SEED, store=path, resume=True, progress=False)
    with SweepStore(path, task=f"{noisy.__module__}.noisy", fingerprint=task_fingerprint(noisy),
                    seed=SEED, resume=True) as store:
        assert store.forget([key]) == 1
    table = sweep(noisy, GRID, seed=SEED, store=path, resume=True, progress=False)
    assert table.resumed == len(GRID["x"]) - 1
    assert_same_rows(table, clean[1])


@dataclasses.dataclass(frozen=True)
class Gone:
    """An output whose class the reading process no longer has."""

    value: float


#: Where :func:`gone` finds its output class: a dict, which its fingerprint takes by type, so
#: the class can go without the task changing (as when code elsewhere is refactored).
OUTPUT_CLASSES = {"gone": Gone}


def gone(x):
    return {"kept": OUTPUT_CLASSES["gone"](float(x))}


def test_a_row_whose_classes_are_gone_is_refused_by_its_key(tmp_path, monkeypatch):
    path = tmp_path / "runs.sqlite"
    sweep(gone, {"x": [1, 2]}, store=path, progress=False)
    monkeypatch.delattr(sys.modules[Gone.__module__], "Gone")
    with pytest.raises(StoreError, match=r'the row of task \{"x":1\} cannot be unpickled '
                       r"\(AttributeError: .*classes this code no longer has"):
        sweep(gone, {"x": [1, 2]}, store=path, resume=True, progress=False)


def corruptions() -> list:
    """``(kind, seed)`` of each corrupted copy: byte flips, and truncations every third."""
    rng = np.random.default_rng(CORRUPTION_SEED)
    kinds = ["truncate" if k % 3 == 2 else "flip" for k in range(N_CORRUPTIONS)]
    return [pytest.param(kind, int(rng.integers(2**32)), id=f"{kind}-{k}")
            for k, kind in enumerate(kinds)]


def corrupt(path: Path, kind: str, seed: int) -> None:
    """Truncate ``path`` at a random length, or flip one to three of its bytes (three times
    in four a byte of content, a non-zero one, else any)."""
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(seed)
    if kind == "truncate":
        del data[int(rng.integers(0, len(data))):]
    else:
        content = np.flatnonzero(np.frombuffer(bytes(data), np.uint8))
        for _ in range(int(rng.integers(1, 4))):
            where = rng.choice(content) if rng.random() < 0.75 else rng.integers(len(data))
            data[int(where)] ^= int(rng.integers(1, 256))
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("kind, seed", corruptions())
def test_a_corrupted_store_is_refused_by_name_or_gives_the_clean_rows(clean, tmp_path, kind,
                                                                      seed):
    path = store_copy(clean, tmp_path)
    corrupt(path, kind, seed)
    try:
        table = sweep(noisy, GRID, seed=SEED, store=path, resume=True, progress=False)
    except StoreError as exc:          # any other exception fails the test
        assert f"sweep store '{path}' " in str(exc)
        return
    assert_same_rows(table, clean[1])      # rows lost to the damage are run again


# ---------------------------------------------------------------------------- crashes
CRASH_AT_COMMIT = textwrap.dedent("""
    import os, sqlite3, sys
    import numpy as np
    from flexctl.app.sweep_store import SweepStore, TaskOutcome

    armed = False
    connect = sqlite3.connect

    def exit_at_commit(statement):
        if armed and statement.strip().upper() == "COMMIT":
            os._exit(9)                 # the row's pages are in the -wal file, its commit not

    def traced(*args, **kwargs):
        db = connect(*args, **kwargs)
        db.set_trace_callback(exit_at_commit)
        return db

    sqlite3.connect = traced
    with SweepStore(sys.argv[1], task="crash", fingerprint="f", seed=None) as store:
        for k in range(3):
            store.record(f"k{k}", TaskOutcome(status="ok", outputs={"x": np.full(100, k)}))
        armed = True
        store.record("big", TaskOutcome(status="ok", outputs={
            "x": np.random.default_rng(0).random(int(sys.argv[2]))}))
    """)

KILLED_WHILE_WRITING = textwrap.dedent("""
    import itertools, sys
    import numpy as np
    from flexctl.app.sweep_store import SweepStore, TaskOutcome

    with SweepStore(sys.argv[1], task="crash", fingerprint="f", seed=None) as store:
        for k in itertools.count():
            store.record(f"k{k}", TaskOutcome(status="ok", outputs={
                "x": np.full(int(sys.argv[2]) // 4, float(k))}))
    """)


def reopened(path) -> dict:
    """The outcomes of a crashed store, opened as a resume would."""
    with SweepStore(path, task="crash", fingerprint="f", seed=None, resume=True) as store:
        outcomes = store.outcomes()
        store.record("after", TaskOutcome(status="ok", outputs={}))   # and it takes more
    return outcomes


def test_a_crash_in_the_middle_of_a_commit_leaves_every_committed_row(tmp_path):
    path = tmp_path / "runs.sqlite"
    child = subprocess.run([sys.executable, "-c", CRASH_AT_COMMIT, str(path), str(BIG_ROW)],
                           env=child_env(), capture_output=True, text=True, timeout=PATIENCE,
                           check=False)
    assert child.returncode == 9, child.stderr
    assert Path(f"{path}-wal").stat().st_size > BIG_ROW        # the cut-off transaction
    outcomes = reopened(path)
    assert sorted(outcomes) == ["k0", "k1", "k2"]
    assert [float(outcomes[f"k{k}"].outputs["x"][0]) for k in range(3)] == [0.0, 1.0, 2.0]


def test_a_process_killed_while_writing_leaves_every_committed_row(tmp_path):
    path = tmp_path / "runs.sqlite"
    child = subprocess.Popen([sys.executable, "-c", KILLED_WHILE_WRITING, str(path),
                              str(BIG_ROW)], env=child_env(), stderr=subprocess.PIPE)
    deadline = time.monotonic() + PATIENCE
    while committed(path) < 4 and child.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    child.send_signal(signal.SIGKILL)
    child.communicate(timeout=PATIENCE)
    assert child.returncode == -signal.SIGKILL
    outcomes = reopened(path)
    assert len(outcomes) >= 4
    assert all(o.outputs["x"][0] == float(key[1:]) for key, o in outcomes.items())


def committed(path) -> int:
    """Rows committed to a store file, read as another process would."""
    try:
        with sqlite3.connect(path) as db:
            return db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
    except sqlite3.OperationalError:        # not created yet
        return 0
