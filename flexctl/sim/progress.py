"""Progress of a long run: how far it is, and how long it will still take.

``simulate(..., progress=...)`` integrates a long run in :data:`PROGRESS_CHUNKS` pieces and
hands a :class:`Progress` to the callable after each (``progress=True`` prints them to
stderr, at most every :data:`REPORT_INTERVAL` seconds once the run has taken that long). The
estimate is linear in simulated time: the work per simulated second of a run of this model
hardly changes once its initial transient has passed.

Examples
--------
>>> from flexctl.sim.progress import Progress
>>> print(Progress(t=250.0, t_final=1000.0, elapsed=30.0, phase="integrating"))
t = 250 of 1000 s (25 %) after 30 s; about 1.5 min to go
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

from ..model.errors import InputTypeError, InputValueError

__all__ = ["Progress", "progress_printer", "check_progress", "progress_cuts",
           "PROGRESS_CHUNKS", "REPORT_INTERVAL"]

#: A run reporting progress is integrated in this many pieces of equal simulated time (each a
#: restart of the integrator, which costs a few steps).
PROGRESS_CHUNKS = 50
#: The printer of ``progress=True`` says nothing for this long and then reports at most this
#: often, s.
REPORT_INTERVAL = 5.0


def _duration(seconds: float) -> str:
    if seconds < 90.0:
        return f"{seconds:.2g} s"
    if seconds < 5400.0:
        return f"{seconds / 60.0:.2g} min"
    return f"{seconds / 3600.0:.2g} h"


@dataclass(frozen=True)
class Progress:
    """Where a run is.

    Attributes
    ----------
    t, t_final : float
        Simulated time reached and to reach, s.
    elapsed : float
        Wall time so far, s.
    phase : str
        ``"integrating"``, or ``"checking accuracy"`` (the check run at 10 times the
        tolerance, after the run, takes about as long again).
    """

    t: float
    t_final: float
    elapsed: float
    phase: str = "integrating"

    @property
    def fraction(self) -> float:
        """Share of the simulated time done, in [0, 1]."""
        return min(max(self.t / self.t_final, 0.0), 1.0) if self.t_final > 0 else 1.0

    @property
    def remaining(self) -> float:
        """Estimated wall time to the end of this phase, s (linear in simulated time)."""
        if self.phase != "integrating":
            return self.elapsed
        return self.elapsed * (1.0 - self.fraction) / self.fraction if self.fraction > 0 \
            else float("inf")

    def __str__(self):
        if self.phase != "integrating":
            return (f"t = {self.t_final:g} s reached after {_duration(self.elapsed)}; "
                    f"{self.phase}, about {_duration(self.remaining)} more")
        return (f"t = {self.t:.4g} of {self.t_final:g} s ({100.0 * self.fraction:.0f} %) "
                f"after {_duration(self.elapsed)}; about {_duration(self.remaining)} to go")


def progress_printer(write=None, interval: float = REPORT_INTERVAL):
    """A ``progress`` callable that writes one line per report, the first once the run has
    taken ``interval`` seconds and then at most every ``interval`` seconds.

    Parameters
    ----------
    write : callable, optional
        ``write(line)``; default: to ``sys.stderr``, flushed.
    interval : float, optional
        Least time between two lines, s. Default :data:`REPORT_INTERVAL`.
    """
    if write is None:
        def write(line):
            sys.stderr.write(line + "\n")
            sys.stderr.flush()
    last = [time.perf_counter()]

    def report(progress: Progress) -> None:
        now = time.perf_counter()
        if progress.elapsed >= interval and now - last[0] >= interval:
            last[0] = now
            write(f"simulate: {progress}")
    return report


def check_progress(progress):
    """The callable behind ``simulate``'s ``progress`` argument, or ``None``.

    ``None`` or ``False``: no reports; ``True``: :func:`progress_printer` to stderr; a
    callable: itself, called with a :class:`Progress`.

    Parameters
    ----------
    progress : bool, callable or None
        The argument as given; an exception the callable raises is reported as an
        ``InputValueError`` naming the time.
    """
    if progress is None or progress is False:
        return None
    if progress is True:
        return progress_printer()
    if not callable(progress):
        raise InputTypeError("progress must be True, False, None or a callable "
                             f"progress(Progress); got {type(progress).__name__}")

    def report(state: Progress) -> None:
        try:
            progress(state)
        except Exception as exc:            # the user's callable: named, with the time
            raise InputValueError(f"progress raised {type(exc).__name__} at t = "
                                  f"{state.t:.6g} s: {exc}") from exc
    return report


def progress_cuts(cuts, t_final: float, chunks: int = PROGRESS_CHUNKS) -> list:
    """``cuts`` with a boundary added every ``t_final / chunks`` inside the longer segments,
    sorted.

    Parameters
    ----------
    cuts : list of float
        Segment boundaries, s, ascending from 0 to ``t_final`` (the inputs' breakpoints).
    t_final : float
        End of the run, s (> 0).
    chunks : int, optional
        Pieces of the run between reports. Default :data:`PROGRESS_CHUNKS`.

    Returns
    -------
    list of float
        s.
    """
    step = t_final / chunks
    out = [cuts[0]]
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        pieces = int((hi - lo) // step)
        out.extend(lo + (hi - lo) * k / (pieces + 1) for k in range(1, pieces + 1))
        out.append(hi)
    return out
