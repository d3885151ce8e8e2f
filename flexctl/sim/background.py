"""Work started beside the caller on a spare core: a run's accuracy check, an estimate's runs.

CasADi lets go of Python's global interpreter lock while its integrators run, so a second
integration on another thread runs on another core. :class:`Beside` starts a call on a small
module-wide pool of threads (one per core beyond the first) and gives its result when asked;
the caller meanwhile does its own work. Where no core is spare (one core, the pool busy with
another caller's work, or this is itself a pool thread), the call runs in the caller's thread
when its result is asked for, exactly as it would have without this module: the results are
the same either way, only the wall time differs.

``FLEXCTL_BACKGROUND=0`` in the environment, or :data:`ENABLED` set to False, runs every call
in the caller's thread.

Examples
--------
>>> job = Beside(sum, [1, 2, 3])
>>> job.result()
6
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

__all__ = ["Beside", "ENABLED", "spare_cores"]

#: Start calls beside the caller (where a core is spare); False runs them in the caller's thread.
ENABLED = os.environ.get("FLEXCTL_BACKGROUND", "1").strip() not in ("0", "false", "no", "off")

_PREFIX = "flexctl-beside"
_LOCK = threading.Lock()
_POOL: dict = {}          # {"pid": ..., "executor": ...}: rebuilt in a forked child


def spare_cores() -> int:
    """Cores this process may use beyond the caller's own (0 on one core)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):          # pragma: no cover - not on Linux
        cores = os.cpu_count() or 1
    return max(0, cores - 1)


def _executor():
    """The pool of this process (a forked child builds its own: its parent's threads are
    not in it), or None where no core is spare."""
    workers = spare_cores()
    if workers == 0:
        return None
    with _LOCK:
        if _POOL.get("pid") != os.getpid():
            _POOL.update(pid=os.getpid(), executor=ThreadPoolExecutor(
                max_workers=workers, thread_name_prefix=_PREFIX))
        return _POOL["executor"]


class Beside:
    """``function(*args, **kwargs)``, started on a spare core if there is one (and
    ``beside`` is true: false makes a call that runs when its result is asked for).

    :meth:`result` returns its value (or raises its exception), waiting for it if it is
    running, running it in the caller's thread if it has not started. :meth:`abandon` says
    the result will not be asked for: a call not yet started never starts. A call already
    running finishes on its own, unless it takes a keyword ``cancelled``: a
    ``threading.Event`` that :meth:`abandon` sets, for the function to look at between
    pieces of its work.
    """

    def __init__(self, function, *args, beside: bool = True, **kwargs):
        self._call = (function, args, kwargs)
        self.cancelled = kwargs.get("cancelled")
        self._future = None
        if beside and ENABLED and not threading.current_thread().name.startswith(_PREFIX):
            executor = _executor()
            if executor is not None:
                try:
                    self._future = executor.submit(function, *args, **kwargs)
                except RuntimeError:           # pragma: no cover - interpreter shutting down
                    self._future = None

    @property
    def started(self) -> bool:
        """Whether the call was handed to a pool thread."""
        return self._future is not None

    def result(self):
        """The call's value: from the pool thread, or computed now if it never started."""
        future = self._future
        if future is not None and not future.cancel():
            return future.result()
        function, args, kwargs = self._call
        return function(*args, **kwargs)

    def abandon(self) -> None:
        """Give up the result: cancel the call if it has not started, else ask it to stop."""
        if self.cancelled is not None:
            self.cancelled.set()
        if self._future is not None:
            self._future.cancel()
