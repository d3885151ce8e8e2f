"""Work started beside the caller on a spare core: a run's accuracy check.

CasADi lets go of Python's global interpreter lock while its integrators run, so a second
integration on another thread runs on another core. :class:`Beside` starts a call on a thread
of its own, at most one per core beyond the first, and gives its result when asked; the
caller meanwhile does its own work. Where no core is spare (one core, every spare core taken
by another call, or this is itself such a thread), the call runs in the caller's thread when
its result is asked for, exactly as it would have without this module, or, queued, on the
first core another call gives back, whichever comes first: the results are the same either
way, only the wall time differs.

CasADi's symbolic work is not thread-safe (its expressions are reference-counted without
atomics), its numerical evaluation is: a call started here must only evaluate functions
built before it started (see :func:`flexctl.sim.compiled.start_check`).

``FLEXCTL_BACKGROUND=0`` in the environment, or :data:`ENABLED` set to False, runs every call
in the caller's thread.

Examples
--------
>>> job = Beside(sum, [1, 2, 3])
>>> job.result()
6
"""

from __future__ import annotations

import collections
import contextlib
import os
import threading

__all__ = ["Beside", "ENABLED", "spare_cores"]

#: Start calls beside the caller (where a core is spare); False runs them in the caller's thread.
ENABLED = os.environ.get("FLEXCTL_BACKGROUND", "1").strip() not in ("0", "false", "no", "off")

_PREFIX = "flexctl-beside"
_LOCK = threading.Lock()
_SLOTS: dict = {}         # {"pid", "free": semaphore, "queue"}: rebuilt in a forked child
_RUNNING: set = set()     # the done events of the calls running now
#: Longest wait, s, for running calls to finish before this process forks (a call abandoned
#: by a run that stopped early may integrate on for as long as the run did).
FORK_WAIT = 2.0


def spare_cores() -> int:
    """Cores this process may use beyond the caller's own (0 on one core)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):          # pragma: no cover - not on Linux
        cores = os.cpu_count() or 1
    return max(0, cores - 1)


def _free_slots():
    """The semaphore counting this process's spare cores not yet taken by a call (a forked
    child counts its own: its parent's threads are not in it)."""
    with _LOCK:
        if _SLOTS.get("pid") != os.getpid():
            _SLOTS.update(pid=os.getpid(), free=threading.Semaphore(max(1, spare_cores())),
                          queue=collections.deque())
        return _SLOTS["free"]


def _before_fork() -> None:
    """Give the running calls up to :data:`FORK_WAIT` s to finish before the process forks,
    so that the child is not forked in the middle of one (the child gets fresh locks on the
    integrators' buffers, :mod:`flexctl.sim.buffers`, in case it is)."""
    import time

    end = time.monotonic() + FORK_WAIT
    for done in list(_RUNNING):
        if not done.wait(max(0.0, end - time.monotonic())):
            break


def _after_fork_in_child() -> None:
    """The child runs none of its parent's calls."""
    _RUNNING.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_before_fork, after_in_child=_after_fork_in_child)


class Beside:
    """``function(*args, **kwargs)``, started on a spare core if there is one (and
    ``beside`` is true: false makes a call that runs when its result is asked for).

    A call that starts runs on a daemon thread of its own, so an abandoned call never holds
    up the interpreter's exit; a fork waits for it (at most :data:`FORK_WAIT` s), so that a
    child is not forked in the middle of a CasADi call. :meth:`result` returns its value (or
    raises its exception), waiting for it; a call that did not start (no core spare, or this
    is itself such a thread) runs in the caller's thread when :meth:`result` asks for it.
    :meth:`abandon` says the result will not be asked for: a call not started never runs,
    and a running call that takes a keyword ``cancelled`` (a ``threading.Event``) finds it
    set, to look at between pieces of its work.

    Parameters
    ----------
    function : callable
        The work; it must be safe to run on another thread (numeric, not CasADi's symbolic
        work).
    *args
        Its positional arguments.
    beside : bool, optional
        Start it on a spare core now (default True); False: run it in the caller's thread
        when :meth:`result` asks.
    queue : bool, optional
        Where no core is spare now, wait in line for the first one that a call started here
        gives back (it then runs there after the calls queued before it), unless
        :meth:`result` asks for it first, which runs it in the caller's thread. Default
        False: such a call runs in the caller's thread when asked for.
    **kwargs
        Its keyword arguments; a ``cancelled`` among them is the event :meth:`abandon`
        sets.
    """

    def __init__(self, function, *args, beside: bool = True, queue: bool = False, **kwargs):
        self._call = (function, args, kwargs)
        self.cancelled = kwargs.get("cancelled")
        self._done = None
        self._queued = False
        self._outcome = (None, None)
        if not (beside and ENABLED and spare_cores() > 0) or \
                threading.current_thread().name.startswith(_PREFIX):
            return
        free = _free_slots()
        with _LOCK:                # a pool thread gives its core back under this lock
            if not free.acquire(blocking=False):
                if queue:
                    self._done, self._queued = threading.Event(), True
                    _SLOTS["queue"].append(self)
                return
        self._done = threading.Event()
        _RUNNING.add(self._done)
        try:
            threading.Thread(target=self._work, args=(free,), name=_PREFIX,
                             daemon=True).start()
        except RuntimeError:                   # pragma: no cover - no thread to be had
            _RUNNING.discard(self._done)
            free.release()
            self._done = None

    def _work(self, free) -> None:
        job = self
        while job is not None:
            job._run()
            job = _next_queued(free)

    def _run(self) -> None:
        """Make the call on this thread, keep its outcome and say it is done."""
        function, args, kwargs = self._call
        try:
            self._outcome = (function(*args, **kwargs), None)
        except BaseException as exc:           # handed to the caller by result()
            self._outcome = (None, exc)
        finally:
            _RUNNING.discard(self._done)
            self._done.set()

    def _claim(self) -> bool:
        """Take a queued call off the queue (True), so that no spare core starts it; False
        where a spare core has started it or it was never queued."""
        with _LOCK:
            if not self._queued:
                return False
            self._queued, self._done = False, None
            with contextlib.suppress(ValueError):     # a forked child's queue is its own
                _SLOTS["queue"].remove(self)
            return True

    @property
    def started(self) -> bool:
        """Whether the call runs (or ran) on a thread of its own."""
        return self._done is not None and not self._queued

    def result(self):
        """The call's value: from its thread, or computed now if it never started."""
        if self._done is None or self._claim():
            function, args, kwargs = self._call
            return function(*args, **kwargs)
        self._done.wait()
        value, error = self._outcome
        if error is not None:
            raise error
        return value

    def abandon(self) -> None:
        """Give up the result: a queued call leaves the queue; set the call's ``cancelled``
        event, if it has one."""
        self._claim()
        if self.cancelled is not None:
            self.cancelled.set()


def _next_queued(free):
    """The oldest queued call, taken off the queue to run on the calling pool thread, which
    keeps its spare core; None, the core given back to ``free``, when none is queued."""
    with _LOCK:
        queue = _SLOTS.get("queue") if _SLOTS.get("pid") == os.getpid() else None
        while queue:
            job = queue.popleft()
            if job._queued:
                job._queued = False
                _RUNNING.add(job._done)
                return job
        free.release()
        return None
