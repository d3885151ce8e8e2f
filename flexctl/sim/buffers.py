"""CasADi functions evaluated on numpy buffers of their own.

A Python call of a CasADi ``Function`` converts every argument to ``DM`` and every result back
(some 20 us per thousand numbers, and tens of microseconds for an integrator's dictionary of
inputs). Loops that call one function thousands of times (a fixed-step chain, an integrator
from sample to sample) call it through :class:`InPlace` instead.
"""

from __future__ import annotations

import os
import threading
import weakref
from collections import OrderedDict

import numpy as np

__all__ = ["InPlace", "borrow", "give_back", "POOL_BYTES"]

_ALL: "weakref.WeakSet" = weakref.WeakSet()
#: Bytes of CasADi work arrays kept in buffers no run is using, for the next run of the same
#: function (:func:`borrow`). A compiled run's buffers hold the work of all its step attempts:
#: 0.3 MB for a first_order model's Dormand-Prince chain, 10.7 MB when its torque is a sampled
#: function's table, whose allocation took 5 to 14 ms a run.
POOL_BYTES = 64 * 2 ** 20
_POOL: "OrderedDict[int, tuple]" = OrderedDict()    # id(function) -> (function, [buffers])
_POOL_LOCK = threading.Lock()


def _fresh_locks_in_child() -> None:
    """A forked child has only the thread that forked: a lock another thread held (an
    accuracy check running beside its run, :mod:`flexctl.sim.background`) would stay taken
    for ever, so every buffer and the pool get a new one."""
    global _POOL_LOCK
    for buffer in list(_ALL):
        buffer._lock = threading.Lock()
    _POOL_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_fresh_locks_in_child)


class InPlace:
    """A CasADi function evaluated on numpy buffers of its own: a call copies the arguments
    in and the results out, with none of the conversion to and from ``DM`` that costs some
    20 us per thousand numbers. Calls from several threads take turns (the buffers are
    shared).

    Parameters
    ----------
    function : casadi.Function
        The function evaluated; its inputs are dense (each buffer holds an input's nonzeros
        in column-major order).
    """

    def __init__(self, function):
        self.function = function
        self.args = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        self.results = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
        self.shapes = [function.size_out(i) for i in range(function.n_out())]
        self.buffer, self.evaluate = function.buffer()
        for i, arg in enumerate(self.args):
            self.buffer.set_arg(i, memoryview(arg))
        for i, result in enumerate(self.results):
            self.buffer.set_res(i, memoryview(result))
        self._lock = threading.Lock()
        _ALL.add(self)

    def __call__(self, *args) -> list:
        """The dense results, shapes as the function's outputs, for ``args`` (as many as the
        function's first inputs; the rest keep their last values)."""
        return self._evaluate(args, False)[0]

    def call_with_stats(self, *args) -> tuple:
        """``(results, stats)``: ``__call__`` and the function's statistics of that call
        (an integrator's steps and evaluations).

        Parameters
        ----------
        *args : array_like
            Values of the function's first inputs, in order; the rest keep their last values.
        """
        return self._evaluate(args, True)

    def _evaluate(self, args, with_stats: bool) -> tuple:
        with self._lock:
            for buffer, value in zip(self.args, args):
                buffer[:] = np.ravel(value, order="F")
            self.evaluate()
            # dense results, column-major
            results = [r.reshape(shape[1], shape[0]).T.copy()
                       for r, shape in zip(self.results, self.shapes)]
            return results, (self.buffer.stats() if with_stats else None)


def _size(buffer: InPlace) -> int:
    """Bytes of a buffer's arrays and of its function's work (8 bytes a number)."""
    numbers = sum(a.size for a in buffer.args) + sum(r.size for r in buffer.results)
    return 8 * (numbers + int(buffer.function.sz_w()))


def borrow(function) -> InPlace:
    """An :class:`InPlace` of ``function``: one that a run gave back (:func:`give_back`), or a
    new one. Its inputs hold what the last user wrote: the borrower sets every input it
    reads.

    Parameters
    ----------
    function : casadi.Function
        The function evaluated.
    """
    with _POOL_LOCK:
        entry = _POOL.get(id(function))
        if entry is not None and entry[0] is function and entry[1]:
            _POOL.move_to_end(id(function))
            return entry[1].pop()
    return InPlace(function)


def give_back(buffer: InPlace) -> None:
    """Keep ``buffer`` for the next :func:`borrow` of its function, within
    :data:`POOL_BYTES` (the least recently used functions' buffers are let go first).

    Parameters
    ----------
    buffer : InPlace
        A buffer that nothing uses any more.
    """
    size = _size(buffer)
    if size > POOL_BYTES:
        return
    with _POOL_LOCK:
        key = id(buffer.function)
        entry = _POOL.get(key)
        if entry is None or entry[0] is not buffer.function:
            entry = _POOL[key] = (buffer.function, [])
        _POOL.move_to_end(key)
        entry[1].append(buffer)
        total = sum(_size(b) for _, kept in _POOL.values() for b in kept)
        while total > POOL_BYTES:
            oldest = next(iter(_POOL))
            kept = _POOL[oldest][1]
            total -= _size(kept.pop(0))
            if not kept:
                del _POOL[oldest]
