"""A sweep's finished tasks on disk, each committed as it arrives, for sweeps that resume.

:func:`flexctl.app.sweep.sweep` with ``store=path`` writes every finished task to an SQLite
file, one transaction per task, so a worker that dies, a Ctrl-C or a crash of the whole
process loses at most the tasks still running; ``resume=True`` then runs only the tasks the
store does not hold. The pieces, usable on their own (the bench keeps its runs here too):

- :func:`task_key`: a point's identity, the canonical JSON of its parameters;
- :func:`task_seed`: a task's own seed, from the sweep's seed and the task's key, so that a
  task draws the same numbers whatever worker runs it, in whatever order, resumed or not;
- :class:`TaskOutcome`: what one task gave, its outputs or its error;
- :class:`SweepStore`: the table of outcomes, keyed by task key.

Notes
-----
The file holds two tables. ``runs``: ``key`` (TEXT, primary key), ``status`` (``"ok"`` or
``"failed"``), ``error`` (TEXT, ``"Type: message"`` of a failure), ``seed`` (INTEGER, the
task's seed, NULL for a task without one), ``attempts`` (INTEGER, submissions it took),
``outputs`` (BLOB, the outputs dict pickled: floats bit for bit, any type a task returns),
``outputs_json`` (TEXT, the same for people and other tools, objects as their repr) and
``finished_at`` (REAL, Unix time, s). ``meta``: ``name``, ``value`` pairs; ``format``, ``task``
and ``seed`` make sure a resume continues the same sweep. Loading a store unpickles it: open
only stores you wrote.

Examples
--------
>>> task_key({"b": 2, "a": 0.1})
'{"a":0.1,"b":2}'
>>> task_seed(0, '{"a":0.1,"b":2}') == task_seed(0, '{"b":2,"a":0.1}')
False
>>> task_seed(0, task_key({"b": 2, "a": 0.1})) == task_seed(0, task_key({"a": 0.1, "b": 2}))
True
"""

from __future__ import annotations

import hashlib
import json
import pickle
import sqlite3
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.errors import InputTypeError, InputValueError

__all__ = ["task_key", "task_seed", "TaskOutcome", "SweepStore", "OK", "FAILED"]

OK, FAILED = "ok", "failed"
#: Version of the file layout (the ``meta`` table's ``format``).
STORE_FORMAT = "1"
#: Seeds are kept below 2**63: an SQLite INTEGER is a signed 64-bit number.
SEED_BITS = 63

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    key TEXT PRIMARY KEY,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    error TEXT,
    seed INTEGER,
    attempts INTEGER NOT NULL,
    outputs BLOB,
    outputs_json TEXT,
    finished_at REAL NOT NULL
);
"""


def _key_value(value):
    """JSON form of the NumPy values a grid may hold; anything else is refused."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise InputTypeError("sweep point values must be numbers, strings, bools, None or lists "
                         "of them (a task's key is their JSON); got "
                         f"{type(value).__name__} {value!r}")


def task_key(point: Mapping) -> str:
    """The key of a sweep point: its parameters as canonical JSON.

    Parameters
    ----------
    point : mapping
        ``{name: value}``; values numbers, strings, bools, None or lists of them.

    Returns
    -------
    str
        Names sorted, no spaces, floats as their shortest round-trip repr: equal points give
        equal keys in any process, and ``json.loads`` gives the point back.
    """
    if not isinstance(point, Mapping):
        raise InputTypeError(f"task_key point must be a dict {{name: value}}; got "
                             f"{type(point).__name__}")
    return json.dumps({str(k): v for k, v in point.items()}, sort_keys=True,
                      separators=(",", ":"), default=_key_value)


def task_seed(seed: int, key: str) -> int:
    """A task's own seed: the sweep's ``seed`` spawned by the task's ``key``.

    ``numpy.random.SeedSequence(entropy=seed, spawn_key=...)`` with the spawn key taken from
    the SHA-256 of ``key``: independent streams for different keys, the same stream for the
    same key in any process, order or worker.

    Parameters
    ----------
    seed : int
        The sweep's seed, >= 0.
    key : str
        The task's key (:func:`task_key`).

    Returns
    -------
    int
        In ``[0, 2**63)``; give it to ``numpy.random.default_rng``.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputValueError(f"sweep seed must be an integer >= 0; got {seed!r}")
    digest = hashlib.sha256(key.encode("utf-8")).digest()
    words = tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, 32, 4))
    state = np.random.SeedSequence(entropy=int(seed), spawn_key=words).generate_state(
        1, np.uint64)
    return int(state[0]) >> (64 - SEED_BITS)


@dataclass(frozen=True, kw_only=True)
class TaskOutcome:
    """What one task of a sweep gave.

    Attributes
    ----------
    status : {"ok", "failed"}
    outputs : dict
        The task's outputs (empty for a failure).
    error : str
        ``"Type: message"`` of the exception a failed task raised, or why it was lost; ``""``
        when ok.
    seed : int or None
        The seed the task was given (None: it takes none).
    attempts : int
        Submissions it took (> 1 when a worker was lost under it), >= 1.
    exception : BaseException or None
        The exception itself, in this process only (never stored); None when unknown.
    """

    status: str
    outputs: dict
    error: str = ""
    seed: int | None = None
    attempts: int = 1
    exception: BaseException | None = None

    def __post_init__(self):
        if self.status not in (OK, FAILED):
            raise InputValueError(f"task_outcome.status must be {OK!r} or {FAILED!r}; got "
                                  f"{self.status!r}")
        if not isinstance(self.outputs, dict):
            raise InputTypeError(f"task_outcome.outputs must be a dict; got "
                                 f"{type(self.outputs).__name__}")

    @property
    def ok(self) -> bool:
        return self.status == OK


class SweepStore:
    """The finished tasks of one sweep in an SQLite file (see the module Notes).

    Parameters
    ----------
    path : str or path-like
        The file; created with its folder when missing.
    task : str
        What the sweep runs (a name); a resume must give the same.
    seed : int or None
        The sweep's seed (None: its tasks take none); a resume must give the same.
    resume : bool
        Keep and use the tasks already stored. False refuses a store that holds tasks (hours
        of results are not overwritten by mistake: remove the file to start again).

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "runs.sqlite")
    >>> with SweepStore(path, task="square", seed=0) as store:
    ...     store.record('{"x":2}', TaskOutcome(status="ok", outputs={"y": 4.0}))
    >>> with SweepStore(path, task="square", seed=0, resume=True) as store:
    ...     store.outcomes()['{"x":2}'].outputs
    {'y': 4.0}
    """

    def __init__(self, path, *, task: str, seed: int | None, resume: bool = False):
        if not isinstance(path, (str, Path)) or not str(path).strip():
            raise InputTypeError(f"sweep store must be a file path; got {path!r}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._db = sqlite3.connect(self.path)
            # WAL: each commit is one append, and a reader (a progress check) never blocks it
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            with self._db:
                self._db.executescript(_SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise InputValueError(f"sweep store must be an SQLite file flexctl can write; "
                                  f"{str(self.path)!r} is not: {exc}") from None
        try:
            self._check_meta(task, seed, resume)
        except BaseException:
            self._db.close()
            raise

    def _check_meta(self, task: str, seed, resume: bool) -> None:
        meta = dict(self._db.execute("SELECT name, value FROM meta"))
        want = {"format": STORE_FORMAT, "task": str(task), "seed": json.dumps(seed)}
        if len(self) and not resume:
            raise InputValueError(f"sweep store {str(self.path)!r} already holds {len(self)} "
                                  "tasks: pass resume=True to continue that sweep, or remove "
                                  "the file to start again")
        for name, value in want.items():
            if name in meta and meta[name] != value:
                raise InputValueError(f"sweep store {str(self.path)!r} belongs to a sweep with "
                                      f"{name} {meta[name]}; this one has {name} {value}: a "
                                      "resume must run the same task with the same seed")
        with self._db:
            self._db.executemany("INSERT OR IGNORE INTO meta VALUES (?, ?)", want.items())

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        """Close the file (every recorded task is already committed)."""
        self._db.close()

    def __len__(self) -> int:
        return self._db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]

    def __repr__(self):
        return f"SweepStore({str(self.path)!r}, {len(self)} tasks)"

    def record(self, key: str, outcome: TaskOutcome) -> None:
        """Commit one task's outcome (replacing one stored under the same key).

        Parameters
        ----------
        key : str
            The task's key (:func:`task_key`).
        outcome : TaskOutcome
            What the task gave; its outputs must pickle.
        """
        try:
            blob = pickle.dumps(outcome.outputs, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:
            raise InputTypeError(f"sweep store: the outputs of task {key} must be picklable "
                                 f"to be stored; {type(exc).__name__}: {exc}") from None
        text = json.dumps(outcome.outputs, default=repr, allow_nan=True)
        with self._db:
            self._db.execute("INSERT OR REPLACE INTO runs VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                             (key, outcome.status, outcome.error, outcome.seed,
                              outcome.attempts, blob, text, time.time()))

    def outcomes(self, keys=None) -> dict:
        """``{key: TaskOutcome}`` of the stored tasks (of those among ``keys`` if given)."""
        wanted = None if keys is None else set(keys)
        found = {}
        for key, status, error, seed, attempts, blob in self._db.execute(
                "SELECT key, status, error, seed, attempts, outputs FROM runs"):
            if wanted is None or key in wanted:
                found[key] = TaskOutcome(status=status, outputs=pickle.loads(blob),
                                         error=error or "", seed=seed, attempts=attempts)
        return found

    def forget(self, keys) -> int:
        """Remove tasks from the store (to run them again on resume); return how many."""
        with self._db:
            return sum(self._db.execute("DELETE FROM runs WHERE key = ?", (k,)).rowcount
                       for k in keys)

    def failed_keys(self) -> list:
        """Keys of the stored failures (``forget`` them to try again on resume)."""
        return [k for (k,) in self._db.execute("SELECT key FROM runs WHERE status = ?",
                                               (FAILED,))]

