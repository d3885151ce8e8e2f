"""Reference manoeuvres of :ref:`section 6 of the model <sec-manoeuvres>` (spin-up, one-period
sine torque), a slew goal and a torque history given as samples.

Each manoeuvre is a frozen dataclass that evaluates exactly at any time (no sampling) and lists
its ``breakpoints``: the times where it is not smooth, at which the integrator restarts.

Examples
--------
>>> from flexctl.sim.maneuvers import SpinUp, SineTorque
>>> spin = SpinUp(spin_rate=4.0, ramp_time=15.0)
>>> float(spin.rate(15.0)), float(spin.rate(40.0))
(4.0, 4.0)
>>> push = SineTorque(peak_torque=50.0, duration=2.0)
>>> float(push(0.5)), float(push(3.0))
(50.0, 0.0)
>>> from flexctl.sim.maneuvers import TorqueSamples
>>> steps = TorqueSamples(times=[1.0, 2.0], values=[3.0, -1.0])
>>> [float(v) for v in steps([0.5, 1.0, 1.5, 2.0, 9.0])]
[0.0, 3.0, 3.0, -1.0, -1.0]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..model.checks import KeywordOnly
from ..model.errors import InputTypeError, InputValueError
from ..model.parameters import check_real as _real
from ..model.variants import MAX_SPIN_RATE
from .inputs import SampledTorque

__all__ = ["SpinUp", "SineTorque", "Slew", "TorqueSamples", "TORQUE_SAMPLE_INTERPOLATIONS",
           "MAX_TORQUE_SAMPLES", "RIGID_PEAK_ACCELERATION", "rigid_slew_duration"]

#: Peak ``|acceleration|`` of each unit rest-to-rest profile (angle 1 rad, duration 1 s), rad/s^2:
#: bang-bang ``4``, cycloidal (one period of sine torque) ``2 pi``, 7th-order polynomial
#: ``84 sqrt(5) / 25`` (about 7.51).
RIGID_PEAK_ACCELERATION = {"bang_bang": 4.0, "cycloidal": 2.0 * math.pi,
                           "poly7": 84.0 * math.sqrt(5.0) / 25.0}


def rigid_slew_duration(angle: float, inertia: float, torque_bound: float,
                        shape: str = "bang_bang") -> float:
    """Shortest rest-to-rest slew of a rigid body whose torque stays within a bound.

    A profile of duration ``T`` peaks at ``c |angle| / T^2`` (``c`` from
    :data:`RIGID_PEAK_ACCELERATION`), so ``T = sqrt(c |angle| inertia / torque_bound)``; for
    ``"bang_bang"`` this is the minimum time ``2 sqrt(|angle| inertia / torque_bound)``.

    Parameters
    ----------
    angle : float
        Slew angle, rad.
    inertia : float
        Rigid inertia, kg m^2 (> 0).
    torque_bound : float
        Largest torque magnitude, N m (> 0).
    shape : {"bang_bang", "cycloidal", "poly7"}, optional
        Acceleration profile of the slew. Default ``"bang_bang"``.

    Returns
    -------
    float
        s.

    Examples
    --------
    >>> rigid_slew_duration(1.0, 1.0, 1.0)
    2.0
    """
    if not isinstance(shape, str) or shape not in RIGID_PEAK_ACCELERATION:
        raise (InputValueError if isinstance(shape, str) else InputTypeError)(
            f"shape must be one of {', '.join(map(repr, RIGID_PEAK_ACCELERATION))}; got "
            f"{shape!r}")
    angle = _real("", "angle", angle)
    inertia = _real("", "inertia", inertia, minimum=0.0, strict=True)
    torque_bound = _real("", "torque_bound", torque_bound, minimum=0.0, strict=True)
    with np.errstate(all="ignore"):
        duration = float(np.sqrt(RIGID_PEAK_ACCELERATION[shape] * abs(np.float64(angle))
                                 * inertia / torque_bound))
    if not math.isfinite(duration):
        raise InputValueError(f"angle * inertia / torque_bound must be finite; got {angle!r} "
                              f"rad * {inertia!r} kg m^2 / {torque_bound!r} N m")
    return duration


@dataclass(frozen=True, kw_only=True)
class SpinUp(KeywordOnly):
    """Prescribed spin-up of the hub (Kane, Ryan and Banerjee 1987).

    ``theta = (w_s/T_s) [t^2/2 + (T_s/(2 pi))^2 (cos(2 pi t/T_s) - 1)]`` for ``t < T_s``,
    ``theta = w_s (t - T_s/2)`` afterwards.

    Parameters
    ----------
    spin_rate : float
        Final hub rate ``w_s``, rad/s (finite, may be negative).
    ramp_time : float
        Ramp duration ``T_s``, s (> 0).
    """

    spin_rate: float
    ramp_time: float

    def __post_init__(self):
        object.__setattr__(self, "spin_rate", _real("maneuver", "spin_rate", self.spin_rate))
        if abs(self.spin_rate) > MAX_SPIN_RATE:
            raise InputValueError(f"maneuver.spin_rate must be at most {MAX_SPIN_RATE:g} rad/s "
                                  "in magnitude (its square scales the beam stiffness); got "
                                  f"{self.spin_rate!r}")
        object.__setattr__(self, "ramp_time", _real("maneuver", "ramp_time", self.ramp_time,
                                                    minimum=0.0, strict=True))
        # the ramp divides by (2 pi / ramp_time)^2: a ramp_time of 1e-300 s overflowed it
        # (OverflowError), 1e300 s underflowed it to 0 (NaN angles); within these bounds
        # spin_rate / ramp_time stays finite too (|spin_rate| <= MAX_SPIN_RATE)
        with np.errstate(all="ignore"):
            k_squared = float((2.0 * np.pi / np.float64(self.ramp_time)) ** 2)
        if not np.finfo(float).tiny <= k_squared < math.inf:
            raise InputValueError(
                "maneuver.ramp_time must make (2 pi / ramp_time)^2 a positive finite number "
                f"(ramp times between about 1e-150 and 1e150 s); got {self.ramp_time!r} s")

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the motion is not smooth."""
        return (self.ramp_time,)

    def angle(self, t):
        """Hub angle ``theta(t)``, rad, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        t = np.asarray(t, dtype=float)
        ws, ts = self.spin_rate, self.ramp_time
        k = 2.0 * np.pi / ts
        ramp = ws / ts * (0.5 * t ** 2 + (np.cos(k * t) - 1.0) / k ** 2)
        return np.where(t < ts, ramp, ws * (t - 0.5 * ts))

    def rate(self, t):
        """Hub rate ``theta_t(t)``, rad/s, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        t = np.asarray(t, dtype=float)
        ws, ts = self.spin_rate, self.ramp_time
        k = 2.0 * np.pi / ts
        return np.where(t < ts, ws / ts * (t - np.sin(k * t) / k), ws)

    def acceleration(self, t):
        """Hub acceleration ``theta_tt(t)``, rad/s^2, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        t = np.asarray(t, dtype=float)
        ws, ts = self.spin_rate, self.ramp_time
        return np.where(t < ts, ws / ts * (1.0 - np.cos(2.0 * np.pi * t / ts)), 0.0)

    @property
    def casadi_parameters(self) -> tuple:
        """``(structure, values)``: nothing shapes :meth:`casadi` but the class; its numbers
        are ``[spin_rate, ramp_time]`` (compiled runs of spin-ups share one function)."""
        return (), np.array([self.spin_rate, self.ramp_time])

    def casadi_reference(self, t, parameters=None):
        """Angle, rate and acceleration as CasADi expressions of the symbol ``t`` (the
        formulas of :meth:`angle`, :meth:`rate`, :meth:`acceleration`): the spin-up as a
        reference a law follows.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        parameters : casadi.SX or casadi.MX, shape (2, 1), optional
            ``[spin_rate, ramp_time]`` (rad/s, s) as symbols; None: this spin-up's numbers.

        Returns
        -------
        angle, rate, acceleration : casadi.SX or casadi.MX
            rad, rad/s and rad/s^2.
        """
        import casadi as ca

        ws, ts = self.spin_rate, self.ramp_time
        if parameters is not None:
            ws, ts = parameters[0], parameters[1]
        k = 2.0 * np.pi / ts
        angle = ca.if_else(t < ts, ws / ts * (0.5 * t * t + (ca.cos(k * t) - 1.0) / (k * k)),
                           ws * (t - 0.5 * ts))
        rate, acceleration = self.casadi(t, parameters)
        return angle, rate, acceleration

    def casadi(self, t, parameters=None):
        """Rate and acceleration as CasADi expressions of the symbol ``t``; the numbers are
        symbols too when ``parameters`` (laid out as :attr:`casadi_parameters`) is given.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        parameters : casadi.SX or casadi.MX, shape (2, 1), optional
            ``[spin_rate, ramp_time]`` (rad/s, s) as symbols; None: this spin-up's numbers.

        Returns
        -------
        rate, acceleration : casadi.SX or casadi.MX
            rad/s and rad/s^2.
        """
        import casadi as ca

        ws, ts = self.spin_rate, self.ramp_time
        if parameters is not None:
            ws, ts = parameters[0], parameters[1]
        k = 2.0 * np.pi / ts
        rate = ca.if_else(t < ts, ws / ts * (t - ca.sin(k * t) / k), ws)
        acceleration = ca.if_else(t < ts, ws / ts * (1.0 - ca.cos(k * t)), 0.0)
        return rate, acceleration


@dataclass(frozen=True, kw_only=True)
class SineTorque(KeywordOnly):
    """One period of sine torque: ``T_hm sin(2 pi t / T_m)`` for ``0 <= t <= T_m``, 0 after.

    Parameters
    ----------
    peak_torque : float
        Amplitude ``T_hm``, N m (finite).
    duration : float
        Period ``T_m``, s (> 0).
    """

    peak_torque: float
    duration: float

    def __post_init__(self):
        object.__setattr__(self, "peak_torque",
                           _real("maneuver", "peak_torque", self.peak_torque))
        object.__setattr__(self, "duration", _real("maneuver", "duration", self.duration,
                                                   minimum=0.0, strict=True))

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the torque is not smooth."""
        return (self.duration,)

    def __call__(self, t):
        """Torque at time(s) ``t``, N m."""
        t = np.asarray(t, dtype=float)
        on = (t >= 0.0) & (t <= self.duration)
        return np.where(on, self.peak_torque * np.sin(2.0 * np.pi * t / self.duration), 0.0)

    @property
    def casadi_parameters(self) -> tuple:
        """``(structure, values)``: nothing shapes :meth:`casadi` but the class; its numbers
        are ``[peak_torque, duration]`` (compiled runs of sine torques share one function)."""
        return (), np.array([self.peak_torque, self.duration])

    def casadi(self, t, parameters=None):
        """The torque as a CasADi expression of the symbol ``t``; the numbers are symbols too
        when ``parameters`` (laid out as :attr:`casadi_parameters`) is given.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        parameters : casadi.SX or casadi.MX, shape (2, 1), optional
            ``[peak_torque, duration]`` (N m, s) as symbols; None: this torque's numbers.

        Returns
        -------
        casadi.SX or casadi.MX
            N m.
        """
        import casadi as ca

        peak, duration = self.peak_torque, self.duration
        if parameters is not None:
            peak, duration = parameters[0], parameters[1]
        on = ca.logic_and(t >= 0.0, t <= duration)
        return ca.if_else(on, peak * ca.sin(2.0 * np.pi * t / duration), 0.0)


@dataclass(frozen=True, kw_only=True)
class Slew(KeywordOnly):
    """Rest-to-rest slew of the hub by ``angle``: a goal for a controller, not an input.

    Parameters
    ----------
    angle : float
        Slew angle, rad (finite, non-zero).
    duration : float or None
        Time allotted to the manoeuvre, s (> 0); ``None`` asks for the fastest slew the
        controller can give (minimum time).
    torque_bound : float or None
        Largest torque the hub actuator gives, N m (> 0); ``None`` for unbounded.
    """

    angle: float
    duration: float | None = None
    torque_bound: float | None = None

    def __post_init__(self):
        angle = _real("maneuver", "angle", self.angle)
        if angle == 0.0:
            raise InputValueError("maneuver.angle must be non-zero; got 0.0")
        object.__setattr__(self, "angle", angle)
        for name in ("duration", "torque_bound"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _real("maneuver", name, getattr(self, name),
                                                     minimum=0.0, strict=True))
        if self.duration is not None:
            # the rigid slew's acceleration 4 angle / duration^2 must be a number: a duration
            # of 1e-300 s overflows it to inf, 1e300 s underflows it to 0
            with np.errstate(all="ignore"):
                acceleration = float(4.0 * abs(angle) / np.float64(self.duration) ** 2)
            if not 0.0 < acceleration < float("inf"):
                raise InputValueError(
                    f"maneuver.duration must make the rigid slew acceleration 4 angle / "
                    f"duration^2 a positive finite number; got {self.duration!r} s, giving "
                    f"{acceleration!r} rad/s^2")


#: How :class:`TorqueSamples` fills the time between samples, and the fewest samples each needs.
TORQUE_SAMPLE_INTERPOLATIONS = {"hold": 1, "linear": 2}
#: Most samples a :class:`TorqueSamples` holds (a 16 MB pair of arrays; beyond that the
#: history is better given as a function).
MAX_TORQUE_SAMPLES = 1_000_000


@dataclass(frozen=True, kw_only=True, eq=False)
class TorqueSamples(KeywordOnly):
    """Hub torque given as a recorded history: samples ``(times, values)``.

    The torque is 0 before ``times[0]``. ``"hold"``: ``values[k]`` on ``[times[k],
    times[k+1])``, the last value to the end; ``"linear"``: straight lines between samples,
    the last value held after ``times[-1]``.

    Parameters
    ----------
    times : array_like, shape (K,)
        Sample times, s: finite, ``>= 0``, strictly increasing; ``1 <= K <=``
        :data:`MAX_TORQUE_SAMPLES` (``K >= 2`` for ``"linear"``).
    values : array_like, shape (K,)
        Torque at each sample time, N m: finite.
    interpolation : {"hold", "linear"}, optional
        Default ``"hold"``.

    Notes
    -----
    ``times`` and ``values`` are stored as read-only float arrays; two manoeuvres are equal
    (and hash alike) when their interpolation and samples are. Every sample time is a
    breakpoint: the integration restarts at each jump (hold) or kink (line). Restarts cost
    time on long records (2 x 10^4 samples of ``hub-beam-mass``: 7 s on cvodes, against
    0.2 s for :class:`~flexctl.sim.inputs.SampledTorque`, which bounds the step on a uniform
    grid instead).

    :meth:`casadi` is ``__call__`` exactly, bit for bit: inside the sampled range both are
    :class:`~flexctl.sim.inputs.SampledTorque`'s lookup (``O(log K)`` in CasADi through
    interpolants, a handful of instructions whatever ``K``, for SX and MX), outside it 0 or
    the last value.

    Examples
    --------
    >>> ramp = TorqueSamples(times=[0.0, 2.0], values=[0.0, 4.0], interpolation="linear")
    >>> float(ramp(0.5)), float(ramp(10.0)), ramp.breakpoints
    (1.0, 4.0, (0.0, 2.0))
    """

    times: np.ndarray
    values: np.ndarray
    interpolation: str = "hold"

    def __post_init__(self):
        interpolation = self.interpolation
        if not isinstance(interpolation, str) or interpolation not in \
                TORQUE_SAMPLE_INTERPOLATIONS:
            raise (InputValueError if isinstance(interpolation, str) else InputTypeError)(
                "maneuver.interpolation must be one of "
                f"{', '.join(map(repr, TORQUE_SAMPLE_INTERPOLATIONS))}; got {interpolation!r}")
        times = _sample_vector("times", self.times, "sample times (s)")
        values = _sample_vector("values", self.values, "torques (N m)")
        _check_samples(times, values, interpolation)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)

    # the CasADi lookup is built once, on first use, and not pickled
    def __getstate__(self):
        return {"times": self.times, "values": self.values,
                "interpolation": self.interpolation}

    def __setstate__(self, state):
        for name in ("times", "values"):
            array = np.array(state[name], dtype=float)
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        object.__setattr__(self, "interpolation", state["interpolation"])

    def __eq__(self, other):
        if not isinstance(other, TorqueSamples):
            return NotImplemented
        return (self.interpolation == other.interpolation
                and np.array_equal(self.times, other.times)
                and np.array_equal(self.values, other.values))

    def __hash__(self):
        return self._hash

    @cached_property
    def _hash(self) -> int:
        return hash((self.interpolation, self.times.tobytes(), self.values.tobytes()))

    def __repr__(self):
        return (f"TorqueSamples({self.times.size} samples over [{self.times[0]:g}, "
                f"{self.times[-1]:g}] s, interpolation={self.interpolation!r})")

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the torque is not smooth: every sample time."""
        return tuple(self.times.tolist())

    @cached_property
    def _sampled(self) -> SampledTorque | None:
        """The lookup inside ``[times[0], times[-1]]`` (None for a single sample)."""
        if self.times.size == 1:
            return None
        return SampledTorque(self.times, self.values, interpolation=self.interpolation)

    def __call__(self, t):
        """Torque at time(s) ``t``, N m: an array of the shape of ``t``."""
        t = np.asarray(t, dtype=float)
        inside = (np.full(t.shape, self.values[0]) if self._sampled is None
                  else np.asarray(self._sampled(t), dtype=float))
        return np.where(t < self.times[0], 0.0, inside)

    def casadi(self, t):
        """The torque as a CasADi expression of the time symbol ``t`` (SX or MX), N m.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        import casadi as ca

        inside = float(self.values[0]) if self._sampled is None else self._sampled.casadi(t)
        return ca.if_else(t < float(self.times[0]), 0.0, inside)


def _sample_vector(name: str, value, what: str) -> np.ndarray:
    """``value`` as a float vector, or an error naming ``maneuver.<name>``."""
    where = f"maneuver.{name}"
    try:
        raw = np.asarray(value) if not isinstance(value, (str, bytes)) else None
    except (TypeError, ValueError):      # ragged nesting
        raw = None
    # a true among numbers is read as 1.0 by numpy: a slip, refused as booleans are
    mixed = isinstance(value, (list, tuple)) and any(isinstance(v, (bool, np.bool_))
                                                     for v in value)
    if raw is None or raw.dtype.kind not in "iuf" or mixed:
        # strings, booleans, complex numbers, None, objects (an int beyond the float range)
        kind = "booleans" if mixed or raw is not None and raw.dtype.kind == "b" \
            else type(value).__name__
        raise InputTypeError(f"{where} must be an array of real numbers, {what}; got "
                             f"{value!r:.80} ({kind})")
    with np.errstate(over="ignore"):
        array = np.array(raw, dtype=float)
    if array.ndim != 1:
        raise InputValueError(f"{where} must be one-dimensional, one number per sample; got "
                              f"shape {array.shape}")
    if array.size > MAX_TORQUE_SAMPLES:
        raise InputValueError(f"{where} must hold at most {MAX_TORQUE_SAMPLES} samples; got "
                              f"{array.size}")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise InputValueError(f"{where} must be finite; got {name}[{bad[0]}] = "
                              f"{float(array[bad[0]])!r}")
    array.flags.writeable = False
    return array


def _check_samples(times: np.ndarray, values: np.ndarray, interpolation: str) -> None:
    """The rules tying the samples together: sizes, start and order of the times."""
    fewest = TORQUE_SAMPLE_INTERPOLATIONS[interpolation]
    if times.size < fewest:
        raise InputValueError(f"maneuver.times must hold at least {fewest} "
                              f"sample{'s' if fewest > 1 else ''} for interpolation "
                              f"{interpolation!r}; got {times.size}")
    if values.size != times.size:
        raise InputValueError(f"maneuver.values must hold one torque per sample time "
                              f"({times.size}); got {values.size}")
    if times[0] < 0.0:
        raise InputValueError(f"maneuver.times must be >= 0 s (a run starts at t = 0); got "
                              f"times[0] = {float(times[0])!r}")
    step = np.diff(times)
    if np.any(step <= 0.0):
        k = int(np.argmax(step <= 0.0)) + 1
        raise InputValueError(f"maneuver.times must be strictly increasing (s); got "
                              f"times[{k}] = {float(times[k])!r} after times[{k - 1}] = "
                              f"{float(times[k - 1])!r}")
