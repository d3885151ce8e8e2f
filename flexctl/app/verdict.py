"""A run's verdict in one word or line: what every table and console line of a run shows.

A run is judged by two facts: how its simulation ended (``status``: ``ok``, ``diverged``,
...), and, for a controlled slew, whether the design's own loop check
(:func:`controllers.check_loop`, the summary's ``slew.loop_stability``) finds the loop stable
on the plant it flew. A run that reached its final time with a loop that grows is not "ok":
its growth may simply be slower than the run (an e-fold in 60 s on a 7 s slew).
:func:`run_verdict` is the one place that joins the two.

Examples
--------
>>> run_verdict("ok")
'ok'
>>> run_verdict("ok", {"closed_loop_stable": False, "message": "LQR is unstable"})
'ok, loop unstable'
>>> run_verdict("diverged", {"closed_loop_stable": False})
'diverged'
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["run_verdict", "loop_unstable", "summary_verdict"]


def loop_unstable(loop_stability) -> bool:
    """True when a loop check (a :meth:`~controllers.LoopStability.as_dict` dict) found the
    loop unstable; False for a stable one or no check (None).

    Parameters
    ----------
    loop_stability : dict or None
        The check's ``closed_loop_stable`` entry is read.
    """
    return isinstance(loop_stability, Mapping) \
        and loop_stability.get("closed_loop_stable") is False


def run_verdict(status: str, loop_stability=None) -> str:
    """The run's verdict: its status, and ``", loop unstable"`` after an ``ok`` one whose
    loop check found the loop unstable on the plant it flew.

    Parameters
    ----------
    status : str
        How the simulation ended (:attr:`flexctl.SimulationResult.status`).
    loop_stability : dict, optional
        The design's loop check on the plant (``summary["slew"]["loop_stability"]``, or
        :attr:`controllers.BuiltController.info` ``["loop_stability"]``). Default: none.
    """
    if status == "ok" and loop_unstable(loop_stability):
        return "ok, loop unstable"
    return str(status)


def summary_verdict(summary: Mapping) -> str:
    """:func:`run_verdict` of a run's ``summary.json`` (its ``status`` and, for a controlled
    slew, ``slew.loop_stability``).

    Parameters
    ----------
    summary : dict
        A run's summary (:func:`flexctl.app.report.summarize`).
    """
    slew = summary.get("slew") or {}
    return run_verdict(summary["status"], slew.get("loop_stability"))
