"""Slew performance metrics of a simulation result.

Examples
--------
>>> import numpy as np
>>> from flexctl.sim.metrics import settling_time
>>> t = np.linspace(0.0, 10.0, 1001)
>>> round(settling_time(t, 1.0 - np.exp(-t), target=1.0, band=0.02), 2)
3.92
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..model.checks import check_array, check_real
from ..model.errors import InputValueError

__all__ = ["SlewMetrics", "slew_metrics", "settling_time"]


def settling_time(t, signal, target: float, band: float = 0.02) -> float:
    """First time after which ``signal`` stays within ``band * |target|`` of ``target``, s.

    Returns ``inf`` when the signal is outside the band at the last sample.
    """
    t = check_array("settling_time", "t", t, shape=(None,))
    signal = check_array("settling_time", "signal", signal, shape=(t.size,))
    if t.size == 0:
        raise InputValueError("settling_time.t must hold at least one sample; got none")
    target = check_real("settling_time", "target", target)
    band = check_real("settling_time", "band", band, minimum=0.0)
    tol = band * abs(target) if target != 0 else band
    outside = np.abs(signal - target) > tol
    if outside[-1]:
        return float("inf")
    if not outside.any():
        return float(t[0])
    last = np.nonzero(outside)[0][-1]
    return float(t[last + 1])


@dataclass(frozen=True)
class SlewMetrics:
    """How well a rest-to-rest slew went.

    Attributes
    ----------
    settling_time : float
        2 % settling time of the hub angle, s (``inf`` if not settled by the end).
    overshoot : float
        Largest excursion of the hub angle past the target, as a fraction of the slew angle.
    final_error : float
        Hub angle error at the end of the run, rad.
    peak_torque : float
        Largest ``|torque|``, N m.
    peak_tip_deflection : float
        Largest ``|tip deflection|``, m.
    residual_vibration : float
        Largest ``|tip deflection|`` after the manoeuvre's nominal duration, m.
    """

    settling_time: float
    overshoot: float
    final_error: float
    peak_torque: float
    peak_tip_deflection: float
    residual_vibration: float

    def as_dict(self) -> dict:
        """Plain dictionary (JSON-ready; ``inf`` settling time becomes ``None``)."""
        out = asdict(self)
        if not np.isfinite(out["settling_time"]):
            out["settling_time"] = None
        return out


def slew_metrics(result, angle: float, duration: float, band: float = 0.02) -> SlewMetrics:
    """Metrics of a slew by ``angle`` (rad) meant to take ``duration`` (s).

    Parameters
    ----------
    result : SimulationResult
    angle : float
        Commanded slew angle, rad (non-zero).
    duration : float
        Nominal manoeuvre time, s: residual vibration is measured after it.
    band : float
        Settling band as a fraction of ``angle``.
    """
    angle = check_real("slew_metrics", "angle", angle)
    if not angle:
        raise InputValueError(f"slew_metrics.angle must be non-zero; got {angle!r}")
    if not (duration == math.inf or duration == -math.inf):   # an end never reached
        duration = check_real("slew_metrics", "duration", duration)
    band = check_real("slew_metrics", "band", band, minimum=0.0)
    t, theta = result.t, result.theta
    past = (theta - angle) * np.sign(angle)
    after = t >= duration
    residual = float(np.max(np.abs(result.tip_deflection[after]))) if after.any() else 0.0
    return SlewMetrics(
        settling_time=settling_time(t, theta, angle, band),
        overshoot=float(max(np.max(past), 0.0) / abs(angle)),
        final_error=float(angle - theta[-1]),
        peak_torque=float(np.max(np.abs(result.torque))) if result.torque.size else 0.0,
        peak_tip_deflection=result.peak_tip_deflection,
        residual_vibration=residual,
    )
