"""A sweep's finished tasks on disk, each committed as it arrives, for sweeps that resume.

:func:`flexctl.app.sweep.sweep` with ``store=path`` writes every finished task to an SQLite
file, one transaction per task, so a worker that dies, a Ctrl-C or a crash of the whole
process loses at most the tasks still running; ``resume=True`` then runs only the tasks the
store does not hold. A store knows what it holds: the task's name and fingerprint
(:func:`~flexctl.app.task_fingerprint.task_fingerprint`, its code and inputs) and the sweep's
seed, and it is resumed only by the same task with the same seed. A file that is not a store,
a damaged one, another task's or one of an older format is refused by a :class:`StoreError`
that names the file and what is wrong with it. The pieces, usable on their own (the bench
keeps its runs here too):

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
``outputs_json`` (TEXT, the same for people and other tools, objects as their repr),
``finished_at`` (REAL, Unix time, s) and ``checksum`` (TEXT, the SHA-256 of the row's other
columns, so that a damaged row is refused by its key rather than unpickled or returned
changed). ``meta``: ``name``, ``value`` pairs, exactly these four:

- ``format``: the file layout's version, :data:`STORE_FORMAT` (``"2"``; format ``"1"`` had
  neither fingerprints nor checksums, and is refused);
- ``task``: the task's name (its module and qualified name; for the bench, its settings);
- ``fingerprint``: the SHA-256 of the task's code and inputs;
- ``seed``: the sweep's seed as JSON (``null`` for a task without one).

``resume=True`` requires all four to match. ``resume=False`` refuses a store that holds tasks
(hours of results are not overwritten by mistake) and takes over an empty one, its meta
rewritten for the new sweep.

Opening a store checks it before anything is written: SQLite's ``quick_check`` of the whole
file, then its tables against the ones this module creates, then the meta table. The journal
is SQLite's write-ahead log (WAL) with ``synchronous=NORMAL``: a commit appends the row's pages
and a commit record to the ``-wal`` file, readers (a progress check from another process) never
block the writer, and a transaction cut off by a crash lacks its commit record (or its frames'
checksums), so the next open ignores it and finds every committed row intact. A crash of the
process loses no committed row; a power cut may lose the last commits, never the file's
consistency. (SQLite's default rollback journal would keep the file readable too, copying
every page a commit changes to the journal first and syncing twice per commit; WAL needs a
local file system, not a network share.) Loading a store unpickles it: open only stores you
wrote.

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

import contextlib
import functools
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

__all__ = ["task_key", "task_seed", "TaskOutcome", "SweepStore", "StoreError", "OK", "FAILED",
           "STORE_FORMAT"]

OK, FAILED = "ok", "failed"
#: Version of the file layout (the ``meta`` table's ``format``).
STORE_FORMAT = "2"
#: Seeds are kept below 2**63: an SQLite INTEGER is a signed 64-bit number.
SEED_BITS = 63
#: The names of the ``meta`` table, in the order they are written.
META_NAMES = ("format", "task", "fingerprint", "seed")
#: Hexadecimal digits of a fingerprint shown in messages.
SHOWN_DIGITS = 12

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
    finished_at REAL NOT NULL,
    checksum TEXT NOT NULL
);
"""
_COLUMNS = "key, status, error, seed, attempts, outputs, outputs_json, finished_at, checksum"


class StoreError(InputValueError):
    """A sweep store that cannot be used as asked: not a store, damaged, another sweep's, of
    an older format, or holding tasks a fresh sweep would overwrite; the message names the
    file and what is wrong."""


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


def _is_integer(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


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
        The seed the task was given, in ``[0, 2**63)`` (None: it takes none).
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
        if not isinstance(self.error, str):
            raise InputTypeError(f"task_outcome.error must be a str; got "
                                 f"{type(self.error).__name__}")
        if self.seed is not None and not (_is_integer(self.seed)
                                          and 0 <= self.seed < 2**SEED_BITS):
            raise InputValueError(f"task_outcome.seed must be None or an integer in "
                                  f"[0, 2**{SEED_BITS}); got {self.seed!r}")
        if not (_is_integer(self.attempts) and self.attempts >= 1):
            raise InputValueError(f"task_outcome.attempts must be an integer >= 1; got "
                                  f"{self.attempts!r}")

    @property
    def ok(self) -> bool:
        return self.status == OK


def _checksum(values) -> str:
    """SHA-256 of a row's columns as SQLite gives them back (each with its type and length,
    floats as their hexadecimal form: bit for bit)."""
    digest = hashlib.sha256()
    for value in values:
        if isinstance(value, bytes):
            data = value
        else:
            text = value.hex() if isinstance(value, float) else str(value)
            data = text.encode("utf-8", "surrogatepass")
        digest.update(f"{type(value).__name__}:{len(data)}:".encode())
        digest.update(data)
    return digest.hexdigest()


@functools.lru_cache(maxsize=1)
def _schema_objects() -> dict:
    """``{(type, name): sql}`` of the tables and indexes ``_SCHEMA`` creates."""
    with contextlib.closing(sqlite3.connect(":memory:")) as db:
        db.executescript(_SCHEMA)
        return _objects(db)


def _objects(db: sqlite3.Connection) -> dict:
    """``{(type, name): sql}`` of a database's schema (the statistics tables of ANALYZE
    left out)."""
    return {(kind, name): sql for kind, name, sql in db.execute(
                "SELECT type, name, sql FROM sqlite_master")
            if not str(name).startswith("sqlite_stat")}


def _short(fingerprint) -> str:
    return f"{str(fingerprint)[:SHOWN_DIGITS]}..."


class SweepStore:
    """The finished tasks of one sweep in an SQLite file (see the module Notes).

    Parameters
    ----------
    path : str or path-like
        The file; created with its folder when missing.
    task : str
        What the sweep runs (a name); a resume must give the same.
    fingerprint : str
        What the task computes, its code and inputs
        (:func:`~flexctl.app.task_fingerprint.task_fingerprint`); a resume must give the
        same.
    seed : int or None
        The sweep's seed (None: its tasks take none); a resume must give the same.
    resume : bool
        Keep and use the tasks already stored. False refuses a store that holds tasks (hours
        of results are not overwritten by mistake: remove the file to start again) and takes
        over an empty one.

    Raises
    ------
    StoreError
        When the file is not a sweep store, is damaged, is of another format, belongs to
        another task or seed, or holds tasks and ``resume`` is False; the message names the
        file.

    Examples
    --------
    >>> import os, tempfile
    >>> from flexctl.app.task_fingerprint import task_fingerprint
    >>> def square(x):
    ...     return {"y": x * x}
    >>> path = os.path.join(tempfile.mkdtemp(), "runs.sqlite")
    >>> mark = task_fingerprint(square)
    >>> with SweepStore(path, task="square", fingerprint=mark, seed=None) as store:
    ...     store.record('{"x":2}', TaskOutcome(status="ok", outputs=square(2.0)))
    >>> with SweepStore(path, task="square", fingerprint=mark, seed=None, resume=True) as store:
    ...     store.outcomes()['{"x":2}'].outputs
    {'y': 4.0}
    """

    def __init__(self, path, *, task: str, fingerprint: str, seed: int | None,
                 resume: bool = False):
        if not isinstance(path, (str, Path)) or not str(path).strip():
            raise InputTypeError(f"sweep store must be a file path; got {path!r}")
        for name, value in (("task", task), ("fingerprint", fingerprint)):
            if not isinstance(value, str) or not value:
                raise InputTypeError(f"sweep store {name} must be a non-empty str; got "
                                     f"{value!r}")
        self.path = Path(path)
        self._db = self._connect()
        try:
            with self._guard("opened"):
                self._check_file()
                self._check_schema()
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=NORMAL")
                self._check_meta({"format": STORE_FORMAT, "task": task,
                                  "fingerprint": fingerprint, "seed": json.dumps(seed)},
                                 resume)
        except BaseException:
            self._db.close()
            raise

    def _refused(self, what: str) -> StoreError:
        return StoreError(f"sweep store {str(self.path)!r} {what}")

    def _connect(self) -> sqlite3.Connection:
        """The connection to the file (its folder created); a folder or a path that cannot
        be opened is refused."""
        if self.path.is_dir():
            raise self._refused("is a folder; give the path of a file")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(self.path)
        except (OSError, sqlite3.Error) as exc:
            raise self._refused(f"cannot be opened ({type(exc).__name__}: {exc})") from None
        # damaged text (a key, SQLite's own report) decodes, to fail a checksum or be shown
        db.text_factory = functools.partial(str, encoding="utf-8", errors="replace")
        return db

    @contextlib.contextmanager
    def _guard(self, doing: str):
        """Turn an SQLite error while ``doing`` into a :class:`StoreError` naming the file."""
        try:
            yield
        except sqlite3.Error as exc:
            reason = ("it is not an SQLite database, or it is damaged; "
                      if type(exc) in (sqlite3.DatabaseError, sqlite3.DataError) else "")
            raise self._refused(f"cannot be {doing}: {reason}SQLite says "
                                f"{type(exc).__name__}: {exc}") from None
        except UnicodeDecodeError:       # SQLite's message quotes damaged bytes of the file
            raise self._refused(f"cannot be {doing}: it is damaged (SQLite's report of the "
                                "error quotes bytes that are not text)") from None

    def _check_file(self) -> None:
        """SQLite's ``quick_check`` of the whole file (pages, records, free list)."""
        problems = [row[0] for row in self._db.execute("PRAGMA quick_check")]
        if problems != ["ok"]:
            said = "; ".join(" ".join(str(p).split()) for p in problems[:3])
            raise self._refused(f"is damaged: SQLite's quick_check says {said}")

    def _check_schema(self) -> None:
        """Create the tables in an empty file; refuse a file whose tables are not a store's
        (checked before anything is written to it)."""
        found = _objects(self._db)
        if not found:
            self._db.executescript(_SCHEMA)
            return
        if found == _schema_objects():
            return
        stored = self._stored_format()
        if stored is not None and stored != STORE_FORMAT:
            raise self._format_refusal(stored)
        tables = sorted(str(name) for kind, name in found if kind == "table")
        what = ("its meta and runs tables are not laid out as flexctl writes them"
                if tables == ["meta", "runs"] else
                f"it holds the tables {', '.join(tables) or '(none)'}, not meta and runs")
        raise self._refused(f"is not a sweep store of format {STORE_FORMAT}: {what} "
                            "(another program's file, or a damaged one); give another file")

    def _stored_format(self):
        """The ``format`` of a foreign-looking file's meta table, or None when unreadable."""
        try:
            row = self._db.execute("SELECT value FROM meta WHERE name = 'format'").fetchone()
        except sqlite3.Error:
            return None
        return None if row is None else row[0]

    def _format_refusal(self, stored) -> StoreError:
        why = (" (format '1' kept neither the task's fingerprint nor row checksums, so what "
               "it holds cannot be checked)" if stored == "1" else "")
        return self._refused(f"was written in store format {stored!r}, and this flexctl reads "
                             f"format {STORE_FORMAT!r}{why}: run the sweep again into a new "
                             "store file")

    def _check_meta(self, want: dict, resume: bool) -> None:
        """Refuse a store of another format, task, fingerprint or seed (see the Notes); write
        ``want`` into a new or taken-over one."""
        meta = dict(self._db.execute("SELECT name, value FROM meta"))
        held = len(self)
        if not meta and held:
            raise self._refused(f"is damaged: it holds {held} tasks but no record of the sweep "
                                "they belong to (its meta table is empty)")
        if meta and set(meta) != set(META_NAMES):
            raise self._refused(f"is damaged: its meta table holds {sorted(map(str, meta))}, "
                                f"not {list(META_NAMES)}")
        if meta and meta["format"] != STORE_FORMAT:
            raise self._format_refusal(meta["format"])
        if held and not resume:
            raise self._refused(f"already holds {held} tasks: pass resume=True to continue "
                                "that sweep, or remove the file to start again")
        if meta and resume:
            self._check_same_sweep(meta, want)
        if meta == want:
            return
        with self._db:
            self._db.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                                 [(name, want[name]) for name in META_NAMES])

    def _check_same_sweep(self, meta: dict, want: dict) -> None:
        """Refuse to resume ``meta``'s sweep with another task or seed."""
        if (meta["task"], meta["fingerprint"]) != (want["task"], want["fingerprint"]):
            why = ("its code or inputs differ" if meta["task"] == want["task"]
                   else "another task")
            raise self._refused(
                f"holds results of task {meta['task']!r} with fingerprint "
                f"{_short(meta['fingerprint'])} but this sweep runs {want['task']!r} with "
                f"fingerprint {_short(want['fingerprint'])} ({why}): a resume must run the "
                "same task; use another store file, or remove this one to start again")
        if meta["seed"] != want["seed"]:
            raise self._refused(f"belongs to a sweep with seed {meta['seed']}; this one has "
                                f"seed {want['seed']}: a resume must run the same task with "
                                "the same seed")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        """Close the file (every recorded task is already committed)."""
        self._db.close()

    def __len__(self) -> int:
        with self._guard("read"):
            return self._db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]

    def __repr__(self):
        try:
            held = f"{len(self)} tasks"
        except StoreError:
            held = "unreadable"
        return f"SweepStore({str(self.path)!r}, {held})"

    def record(self, key: str, outcome: TaskOutcome) -> None:
        """Commit one task's outcome (replacing one stored under the same key).

        Parameters
        ----------
        key : str
            The task's key (:func:`task_key`).
        outcome : TaskOutcome
            What the task gave; its outputs must pickle.
        """
        if not isinstance(key, str):
            raise InputTypeError(f"sweep store key must be a str (task_key); got "
                                 f"{type(key).__name__}")
        try:
            blob = pickle.dumps(outcome.outputs, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:
            raise InputTypeError(f"sweep store: the outputs of task {key} must be picklable "
                                 f"to be stored; {type(exc).__name__}: {exc}") from None
        text = json.dumps(outcome.outputs, default=repr, allow_nan=True)
        seed = None if outcome.seed is None else int(outcome.seed)
        values = (key, outcome.status, outcome.error, seed, int(outcome.attempts), blob, text,
                  time.time())
        with self._guard(f"written (task {key})"), self._db:
            self._db.execute(f"INSERT OR REPLACE INTO runs ({_COLUMNS}) VALUES "
                             "(?, ?, ?, ?, ?, ?, ?, ?, ?)", values + (_checksum(values),))

    def outcomes(self, keys=None) -> dict:
        """The stored tasks' outcomes.

        Parameters
        ----------
        keys : iterable of str, optional
            Only these tasks; default all.

        Returns
        -------
        dict
            ``{key: TaskOutcome}``.

        Raises
        ------
        StoreError
            When a row is damaged (named by its key: :meth:`forget` it to run that task
            again) or the file cannot be read.
        """
        wanted = None if keys is None else set(keys)
        with self._guard("read"):
            rows = self._db.execute(f"SELECT {_COLUMNS} FROM runs").fetchall()
        return {row[0]: self._outcome(row) for row in rows
                if wanted is None or row[0] in wanted}

    def _outcome(self, row: tuple) -> TaskOutcome:
        """The outcome of one row, its checksum checked first."""
        key, status, error, seed, attempts, blob, _, _, checksum = row
        if checksum != _checksum(row[:-1]):
            raise self._damaged(key, "fails its checksum (a changed or damaged row)")
        try:
            outputs = pickle.loads(blob)
        except Exception as exc:
            raise self._damaged(key, f"cannot be unpickled ({type(exc).__name__}: {exc}; the "
                                "outputs may hold objects of classes this code no longer "
                                "has)") from None
        try:
            return TaskOutcome(status=status, outputs=outputs, error=error or "", seed=seed,
                               attempts=attempts)
        except (TypeError, ValueError) as exc:
            raise self._damaged(key, f"is not a task's outcome ({exc})") from None

    def _damaged(self, key, what: str) -> StoreError:
        return self._refused(f"is damaged: the row of task {key} {what}; forget that task "
                             "(SweepStore.forget) to run it again, or use a new store")

    def forget(self, keys) -> int:
        """Remove tasks from the store (to run them again on resume).

        Parameters
        ----------
        keys : iterable of str
            The tasks' keys (:func:`task_key`); keys the store lacks are skipped.

        Returns
        -------
        int
            How many were removed.
        """
        with self._guard("written"), self._db:
            return sum(self._db.execute("DELETE FROM runs WHERE key = ?", (k,)).rowcount
                       for k in keys)

    def failed_keys(self) -> list:
        """Keys of the stored failures (``forget`` them to try again on resume)."""
        with self._guard("read"):
            return [k for (k,) in self._db.execute("SELECT key FROM runs WHERE status = ?",
                                                   (FAILED,))]
