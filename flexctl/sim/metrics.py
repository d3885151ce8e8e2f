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

__all__ = ["SlewMetrics", "MetricErrors", "ERROR_METRICS", "slew_metrics", "metric_errors", "settling_time",
           "format_metric", "ERROR_FACTOR"]

#: The difference between the run and the reference run (the plant at more modes, exact
#: geometry) is counted twice in each error: once for what it measures, once for what the
#: reference itself still leaves out (the modes beyond it, the estimate's own error).
ERROR_FACTOR = 2.0


def settling_time(t, signal, target: float, band: float = 0.02) -> float:
    """First time after which ``signal`` stays within ``band * |target|`` of ``target``, s.

    Returns ``inf`` when the signal is outside the band at the last sample.

    Parameters
    ----------
    t : array_like, shape (P,)
        Sample times, s, ascending (at least one).
    signal : array_like, shape (P,)
        The signal at those times (e.g. the hub angle, rad).
    target : float
        Its final value, in the signal's unit.
    band : float, optional
        Half-width of the band as a fraction of ``|target|`` (>= 0); for ``target = 0`` an
        absolute half-width, in the signal's unit. Default 0.02.
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
    errors : MetricErrors or None
        Error estimates of the metrics (:func:`metric_errors`); None without a reference run.
    """

    settling_time: float
    overshoot: float
    final_error: float
    peak_torque: float
    peak_tip_deflection: float
    residual_vibration: float
    errors: "MetricErrors | None" = None

    def as_dict(self) -> dict:
        """Plain dictionary (JSON-ready; ``inf`` settling time becomes ``None``); with
        :attr:`errors`, an ``errors`` entry of each metric's error and its shown text."""
        out = asdict(self)
        out.pop("errors")
        if not np.isfinite(out["settling_time"]):
            out["settling_time"] = None
        if self.errors is not None:
            out["errors"] = self.errors.as_dict()
            out["shown"] = {name: self.shown(name) for name in _ERROR_UNITS}
        return out

    def error(self, name: str) -> float | None:
        """The error estimate of metric ``name`` (its unit), or None without estimates.

        Parameters
        ----------
        name : str
            One of :data:`ERROR_METRICS`.
        """
        if name not in _ERROR_UNITS:
            raise InputValueError(f"SlewMetrics.error name must be one of "
                                  f"{', '.join(_ERROR_UNITS)}; got {name!r}")
        return None if self.errors is None else getattr(self.errors, name)

    def shown(self, name: str) -> str:
        """Metric ``name`` as a person should read it: ``"0.219 ± 0.03 mm"``, or an upper
        bound ``"< 0.6 mm"`` when the metric is smaller than its error
        (:func:`format_metric`).

        Parameters
        ----------
        name : str
            One of :data:`ERROR_METRICS`.
        """
        value = getattr(self, name) if name in _ERROR_UNITS else None
        if value is None:
            raise InputValueError(f"SlewMetrics.shown name must be one of "
                                  f"{', '.join(_ERROR_UNITS)}; got {name!r}")
        return format_metric(abs(value) if name == "final_error" else value,
                             self.error(name), _ERROR_UNITS[name])


#: The metrics that carry an error, with the unit they are shown in.
_ERROR_UNITS = {"residual_vibration": "m", "peak_tip_deflection": "m", "final_error": "rad",
                "settling_time": "s"}
#: Their names, in that order.
ERROR_METRICS = tuple(_ERROR_UNITS)


@dataclass(frozen=True, kw_only=True)
class MetricErrors:
    """Error estimates of a slew's metrics, in the metrics' units (see :func:`metric_errors`).

    Attributes
    ----------
    residual_vibration, peak_tip_deflection : float
        m.
    final_error : float
        rad.
    settling_time : float
        s (``inf`` when the run or the reference did not settle).
    integration : float
        The run's own integration error of the tip (its accuracy check), m; 0 where none ran.
    geometry : float
        The bound on the geometric error added to the tip metrics, m (0 when the reference
        run had exact geometry).
    model : float
        Largest tip difference from the reference run, m.
    reference : str
        What the reference run was, e.g. ``"exact, 8 modes"``.
    reference_wall_time : float
        Wall time of the reference run, s (what the error estimate cost).
    """

    residual_vibration: float
    peak_tip_deflection: float
    final_error: float
    settling_time: float
    integration: float
    model: float
    reference: str
    geometry: float = 0.0
    reference_wall_time: float = 0.0

    def as_dict(self) -> dict:
        """JSON types (an infinite settling-time error becomes None)."""
        out = asdict(self)
        if not np.isfinite(out["settling_time"]):
            out["settling_time"] = None
        return out


def _tips(result) -> np.ndarray:
    """Tip deflections of every appendage, shape (A, P), m."""
    return np.atleast_2d(result.model.tip_deflections(result.states))


def metric_errors(result, reference, angle: float, duration: float,
                  band: float = 0.02, *, geometry: float = 0.0) -> MetricErrors:
    """Error estimates of :func:`slew_metrics` of ``result``, from a more faithful run.

    Parameters
    ----------
    result : SimulationResult
        The run whose metrics are reported.
    reference : SimulationResult
        The same closed loop on a more faithful plant (more modes, exact geometry), at the
        same output times.
    angle : float
        Commanded slew angle, rad (non-zero), as for :func:`slew_metrics`.
    duration : float
        Nominal manoeuvre time, s, as for :func:`slew_metrics`.
    band : float, optional
        Settling band as a fraction of ``angle``, as for :func:`slew_metrics`. Default 0.02.
    geometry : float, optional
        A bound on the tip's geometric model error not in ``reference`` (a reference of the
        run's own small-deflection variant), m; added to the tip metrics. Default 0.

    Returns
    -------
    MetricErrors
        Each metric's error is :data:`ERROR_FACTOR` times its difference between the two runs
        (for the tip metrics, the largest tip-history difference over the span each metric
        reads, which bounds the metric's change), plus the run's integration error
        (``result.integration_error``, m of tip; divided by the arm ``b + l`` for the hub
        angle).
    """
    if reference.t.shape != result.t.shape or not np.allclose(reference.t, result.t):
        raise InputValueError("metric_errors.reference must share the run's output times; got "
                              f"{reference.t.size} against {result.t.size} samples")
    integration = float(result.integration_error or 0.0)
    geometry = check_real("metric_errors", "geometry", geometry, minimum=0.0)
    hub = getattr(result.model.system, "hub", None)
    arm = float(np.max(result.model.lengths)) + float(getattr(hub, "radius", 0.0))
    tips, tips_ref = _tips(result), _tips(reference)
    difference = np.max(np.abs(tips - tips_ref), axis=0)
    after = result.t >= duration
    reported = slew_metrics(result, angle, duration, band)
    other = slew_metrics(reference, angle, duration, band)
    angle_error = (ERROR_FACTOR * abs(reported.final_error - other.final_error)
                   + integration / arm)
    settle = ERROR_FACTOR * abs(reported.settling_time - other.settling_time)
    return MetricErrors(
        residual_vibration=ERROR_FACTOR * float(np.max(difference[after], initial=0.0))
        + integration + geometry,
        peak_tip_deflection=ERROR_FACTOR * float(np.max(difference)) + integration + geometry,
        final_error=angle_error,
        settling_time=settle if np.isfinite(settle) else math.inf,
        integration=integration, model=float(np.max(difference)), geometry=geometry,
        reference=f"{reference.model.variant}, {reference.model.n_modes} modes",
        reference_wall_time=float(getattr(reference, "wall_time", 0.0)))


def format_metric(value: float, error: float | None, unit: str) -> str:
    """``value`` with its error: ``"0.219 ± 0.03 mm"``, or ``"< 0.6 mm"`` when ``value`` is
    smaller than ``error`` (the value is then no better known than its bound), or the value
    alone when its error is zero.

    Lengths are shown in mm, angles in mrad, times in s.

    Parameters
    ----------
    value : float or None
        In ``unit``; None, NaN or inf: ``"not reached"`` for a time, else ``"n/a"``.
    error : float or None
        Its error bound, in ``unit`` (>= 0); None: not shown; NaN or inf: shown as unknown.
    unit : {"m", "rad", "s"}
        The SI unit of ``value`` and ``error``.

    Examples
    --------
    >>> format_metric(2.19e-4, 6e-4, "m")
    '< 0.819 mm'
    >>> format_metric(2.19e-3, 1e-4, "m")
    '2.19 ± 0.1 mm'
    >>> format_metric(1.5, None, "s")
    '1.5 s'
    >>> format_metric(3.23, 0.0, "s")
    '3.23 s'
    """
    units = {"m": (1e3, "mm"), "rad": (1e3, "mrad"), "s": (1.0, "s")}
    if unit not in units:
        raise InputValueError(f"format_metric.unit must be one of {', '.join(units)}; got "
                              f"{unit!r}")
    scale, shown_unit = units[unit]
    if value is None or not np.isfinite(value):
        return "not reached" if unit == "s" else "n/a"
    v = scale * float(value)
    if error is None:
        return f"{v:.3g} {shown_unit}"
    if not np.isfinite(error):
        return f"{v:.3g} {shown_unit} (error unknown)"
    if error < 0:
        raise InputValueError(f"format_metric.error must be >= 0 (or None, NaN, inf: "
                              f"unknown); got {error!r}")
    e = scale * float(error)
    if v < e:
        return f"< {v + e:.3g} {shown_unit}"
    if float(f"{e:.2g}") == 0.0:           # "3.23 ± 0 s" says less than "3.23 s"
        return f"{v:.3g} {shown_unit}"
    return f"{v:.3g} ± {e:.2g} {shown_unit}"


def slew_metrics(result, angle: float, duration: float, band: float = 0.02) -> SlewMetrics:
    """Metrics of a slew by ``angle`` (rad) meant to take ``duration`` (s).

    Parameters
    ----------
    result : SimulationResult
        The run of the slew.
    angle : float
        Commanded slew angle, rad (non-zero).
    duration : float
        Nominal manoeuvre time, s: residual vibration is measured after it.
    band : float, optional
        Settling band as a fraction of ``angle``. Default 0.02.
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
