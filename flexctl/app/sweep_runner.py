"""Running a sweep's tasks: here or on an executor, one outcome recorded as each arrives.

:func:`flexctl.app.sweep.sweep` hands its tasks to :func:`outcomes`, which takes the ones a
store holds and runs the others with :func:`run_here` or :func:`run_on`, and a
:class:`Recorder` that commits each outcome to the store, counts it and moves the progress bar.
The concerns kept apart:

- a task that raises is an outcome (``status="failed"`` with its error), caught where it ran
  (:func:`evaluate`), so that anything a future raises means the worker was lost;
- a task lost with its worker is submitted again, up to ``retries`` more times. Dask
  reschedules such a task by itself first (up to ``distributed.scheduler.allowed-failures``
  times, default 3), and raises ``KilledWorker`` past that; a process pool breaks as a whole
  (``BrokenProcessPool``), and only a pool factory lets the sweep build a fresh one. A pool
  cannot tell which task broke it, so every task lost in the break counts an attempt;
- a Ctrl-C (or any exception out of the recorder) cancels the futures not yet started and
  propagates; every outcome recorded so far is already committed.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import inspect
import pickle
from collections.abc import Mapping

from .sweep_store import FAILED, OK, SweepStore, TaskOutcome, task_seed
from .task_fingerprint import task_fingerprint

__all__ = ["SweepError", "outcomes", "evaluate", "run_here", "run_on", "Recorder",
           "is_executor"]


class SweepError(RuntimeError):
    """A task failed at one point of a sweep (``on_error="raise"``), or the executor broke;
    the message names the point or the way out."""


def describe(exc: BaseException) -> str:
    """``"Type: message"`` of an exception.

    Parameters
    ----------
    exc : BaseException
        The exception described.
    """
    return f"{type(exc).__name__}: {exc}"


def _portable(exc: Exception):
    """``exc`` if it survives pickling (it travels back from a worker), else None."""
    try:
        pickle.dumps(exc)
    except Exception:
        return None
    return exc


def evaluate(task, point: dict, seed: int | None = None, attempt: int = 1) -> TaskOutcome:
    """Run ``task(**point)`` (with ``seed=seed`` when given); return its outcome.

    Module level so that it pickles.

    Parameters
    ----------
    task : callable
        The sweep's task.
    point : dict
        ``{parameter: value}`` of one point of the grid.
    seed : int, optional
        The task's own seed (:func:`~flexctl.app.sweep_store.task_seed`), passed as ``seed=``;
        default none.
    attempt : int, optional
        Submissions of this task so far, from 1. Not used: it makes a retry a new call, which
        Dask (that keys a pure call by its arguments) would otherwise take for the old one.
    """
    kwargs = dict(point) if seed is None else {**point, "seed": seed}
    try:
        out = task(**kwargs)
    except Exception as exc:
        return TaskOutcome(status=FAILED, outputs={}, error=describe(exc), seed=seed,
                           exception=_portable(exc))
    outputs = dict(out) if isinstance(out, Mapping) else {"value": out}
    return TaskOutcome(status=OK, outputs=outputs, seed=seed)


def is_executor(obj) -> bool:
    """True for an executor instance (it has ``submit``); a class is a factory.

    Parameters
    ----------
    obj : object
        The sweep's ``executor`` argument: an executor, or a class that makes one.
    """
    return not isinstance(obj, type) and callable(getattr(obj, "submit", None))


class Recorder:
    """Where a sweep's outcomes go as they arrive: the store, the tally, the progress bar.

    Parameters
    ----------
    store : SweepStore or None
        Where each outcome is committed as it arrives; None: kept in memory only.
    bar : tqdm.tqdm
        Its postfix shows done, failed and remaining.
    name : str
        The task's name, for errors.
    points : dict
        ``{key: (grid index, point)}`` of every task of the sweep.
    raise_errors : bool
        Raise :class:`SweepError` at the first failure (after recording it).
    """

    def __init__(self, store, bar, name: str, points: dict, raise_errors: bool):
        self.store, self.bar, self.name = store, bar, name
        self.points, self.raise_errors = points, raise_errors
        self.outcomes = {}
        self.failed = 0

    def resumed(self, outcomes: dict) -> None:
        """Count the outcomes a store already held (raising for a failure when asked).

        Parameters
        ----------
        outcomes : dict
            ``{key: TaskOutcome}`` read from the store.
        """
        self.failed += sum(not o.ok for o in outcomes.values())
        self._show(len(outcomes))
        for key, outcome in outcomes.items():
            self._check(key, outcome)

    def __call__(self, key: str, outcome: TaskOutcome) -> None:
        if self.store is not None:
            self.store.record(key, outcome)
        self.outcomes[key] = outcome
        self.failed += not outcome.ok
        self.bar.update()
        self._show(self.bar.n)
        self._check(key, outcome)

    def _show(self, done: int) -> None:
        self.bar.set_postfix_str(f"done {done}, failed {self.failed}, "
                                 f"remaining {len(self.points) - done}", refresh=False)

    def _check(self, key: str, outcome: TaskOutcome) -> None:
        if outcome.ok or not self.raise_errors:
            return
        k, point = self.points[key]
        raise SweepError(f"sweep task {self.name} failed at point {k} {point}: "
                         f"{outcome.error}") from outcome.exception


def outcomes(task, index: dict, executor, name: str, *, store, resume: bool, seed: int,
             progress: bool, on_error: str, retries: int) -> tuple:
    """``({key: TaskOutcome} taken from the store, {key: TaskOutcome} run now)`` for the
    tasks of ``index``; the options are those of :func:`flexctl.app.sweep.sweep`.

    Parameters
    ----------
    task : callable
        The sweep's task.
    index : dict
        ``{key: (grid index, point)}`` of every task of the sweep, keyed by
        :func:`~flexctl.app.sweep_store.task_key`.
    executor : concurrent.futures.Executor-like, callable or None
        An executor or a factory of them (:func:`run_on`); None: run here, in order
        (:func:`run_here`).
    name : str
        The task's name: the progress bar's label, and named in errors.
    store : str, path-like or None
        SQLite file each outcome is committed to (:class:`~flexctl.app.sweep_store.SweepStore`,
        which records the task's name and
        :func:`~flexctl.app.task_fingerprint.task_fingerprint`); None: none.
    resume : bool
        Take the tasks the store already holds and run only the others.
    seed : int
        The sweep's seed, from which a task with a ``seed`` parameter gets its own.
    progress : bool
        Show the progress bar.
    on_error : {"record", "raise"}
        ``"raise"``: :class:`SweepError` at the first failure, after recording it.
    retries : int
        Times a task lost with its worker is submitted again, >= 0.
    """
    from tqdm import tqdm

    seeded = _takes_seed(task)
    with contextlib.ExitStack() as stack:
        kept = None if store is None else stack.enter_context(SweepStore(
            store, task=_task_name(task), fingerprint=task_fingerprint(task),
            seed=seed if seeded else None, resume=resume))
        done = {} if kept is None else kept.outcomes(index)
        todo = {key: (point, task_seed(seed, key) if seeded and "seed" not in point else None)
                for key, (_, point) in index.items() if key not in done}
        bar = stack.enter_context(tqdm(total=len(index), initial=len(done), desc=name,
                                       disable=not progress, unit="point"))
        record = Recorder(kept, bar, name, index, raise_errors=on_error == "raise")
        record.resumed(done)
        if executor is None:
            run_here(task, todo, record)
        else:
            run_on(executor, task, todo, record, retries)
    return done, record.outcomes


def _takes_seed(task) -> bool:
    """True when ``task`` has a parameter named ``seed`` (``**kwargs`` does not count)."""
    try:
        parameter = inspect.signature(task).parameters.get("seed")
    except (TypeError, ValueError):
        return False
    return parameter is not None and parameter.kind in (parameter.POSITIONAL_OR_KEYWORD,
                                                        parameter.KEYWORD_ONLY)


def _task_name(task) -> str:
    """The task's qualified name, which a resumed store must match (with its fingerprint:
    two lambdas share a name)."""
    kind = task if inspect.isfunction(task) else type(task)
    return f"{kind.__module__}.{kind.__qualname__}"


def run_here(task, todo: dict, record: Recorder) -> None:
    """Run ``todo`` in this process, in order.

    Parameters
    ----------
    task : callable
        The sweep's task.
    todo : dict
        ``{key: (point, seed)}`` of the tasks to run, ``seed`` None for a task without one.
    record : Recorder
        Called with each task's key and outcome as it arrives.
    """
    for key, (point, seed) in todo.items():
        record(key, evaluate(task, point, seed))


def run_on(executor, task, todo: dict, record: Recorder, retries: int) -> None:
    """Run ``todo`` on ``executor``, submitting lost tasks again.

    Parameters
    ----------
    executor : concurrent.futures.Executor-like or callable
        An executor (the caller owns it) or a factory of executors (the sweep owns what it
        builds, shuts it down at the end and builds a fresh one after lost tasks).
    task : callable
        The sweep's task.
    todo : dict
        ``{key: (point, seed)}`` of the tasks to run, ``seed`` None for a task without one.
    record : Recorder
        Called with each task's key and outcome as it arrives.
    retries : int
        Times a task lost with its worker is submitted again, >= 0; past that it is recorded
        as failed.

    Raises
    ------
    SweepError
        When an executor given (not a factory) breaks with tasks unfinished.
    """
    factory = None if is_executor(executor) else executor
    pool = executor if factory is None else _built(factory)
    attempts = dict.fromkeys(todo, 0)
    pending = list(todo)
    try:
        while pending:
            pending, broken = _one_round(pool, task, todo, pending, attempts, record, retries)
            if pending and factory is not None:
                pool.shutdown(wait=False, cancel_futures=True)
                pool = _built(factory)
            elif pending and broken is not None:
                raise SweepError(
                    f"sweep task {record.name}: the executor broke ({describe(broken)}) with "
                    f"{len(pending)} tasks unfinished. Pass a factory instead, e.g. "
                    "executor=lambda: ProcessPoolExecutor(4), and the sweep replaces a broken "
                    "pool; with a store, resume=True runs only the unfinished tasks") \
                    from broken
    finally:
        if factory is not None:
            pool.shutdown(wait=False, cancel_futures=True)


def _built(factory):
    """The executor a factory builds, checked."""
    pool = factory()
    if not is_executor(pool):
        raise SweepError(f"sweep executor factory {factory!r} must return an executor (with "
                         f"submit); got {type(pool).__name__}")
    return pool


def _submit(pool, *args) -> concurrent.futures.Future:
    """``pool.submit(evaluate, *args)``; a refusal (a broken pool) as a failed future."""
    try:
        return pool.submit(evaluate, *args)
    except Exception as exc:
        future = concurrent.futures.Future()
        future.set_exception(exc)
        return future


def _finished(futures: list):
    """The futures as they finish (``concurrent.futures`` ones), else in order."""
    if all(isinstance(f, concurrent.futures.Future) for f in futures):
        return concurrent.futures.as_completed(futures)
    return iter(futures)


def _one_round(pool, task, todo, keys, attempts, record, retries) -> tuple:
    """Submit ``keys`` once; record what comes back.

    Returns
    -------
    lost : list of str
        Keys lost with their worker that may be tried again.
    broken : BaseException or None
        The error of a broken executor (``concurrent.futures.BrokenExecutor``), if seen.
    """
    futures, lost, broken = [], [], None
    for key in keys:
        attempts[key] += 1
        point, seed = todo[key]
        futures.append(_submit(pool, task, point, seed, attempts[key]))
    index = {id(f): key for f, key in zip(futures, keys)}
    try:
        for future in _finished(futures):
            key = index[id(future)]
            try:
                outcome = future.result()
            except Exception as exc:    # the task's own errors are outcomes: a lost worker
                if isinstance(exc, concurrent.futures.BrokenExecutor):
                    broken = exc
                if attempts[key] <= retries:
                    lost.append(key)
                    continue
                outcome = TaskOutcome(status=FAILED, outputs={}, seed=todo[key][1],
                                      error=f"lost {attempts[key]} times: {describe(exc)}",
                                      exception=_portable(exc))
            record(key, dataclasses.replace(outcome, attempts=attempts[key]))
    except BaseException:
        for future in futures:
            future.cancel()
        raise
    return lost, broken
