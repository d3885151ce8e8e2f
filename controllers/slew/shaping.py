"""Open-loop baselines: rigid-body bang-bang torque and ZV / ZVD input shaping.

:class:`BangBang` is the time-optimal rest-to-rest torque of the *rigid* hub-beam
(``J0 theta_tt = torque``, ``|torque| <= peak_torque``): full torque for half the time, full
reverse torque for the other half. On the flexible plant it leaves the beam ringing.

An input shaper (:class:`Shaper`) is a train of impulses ``sum_i A_i delta(t - t_i)``
(``sum A_i = 1``); convolving a command with it (:func:`shape`) cancels the residual vibration
of one mode of frequency ``omega`` and damping ratio ``zeta``:

=====  ===================================  ======================================
kind   amplitudes                           times
=====  ===================================  ======================================
ZV     ``[1, K] / (1 + K)``                 ``[0, pi/omega_d]``
ZVD    ``[1, 2K, K^2] / (1 + K)^2``         ``[0, pi/omega_d, 2 pi/omega_d]``
=====  ===================================  ======================================

with ``K = exp(-zeta pi / sqrt(1 - zeta^2))`` and ``omega_d = omega sqrt(1 - zeta^2)``. ZVD
costs twice the delay of ZV and is far less sensitive to an error in ``omega``. For open-loop
torque the mode to cancel is the first flexible mode with the hub free,
``model.natural_frequencies(hub="free")[0]`` (:func:`design_shaper`).

Every command here evaluates exactly at any time and lists its ``breakpoints``.

Examples
--------
>>> import numpy as np
>>> bb = BangBang(slew_angle=np.pi / 2, inertia=2.0, peak_torque=np.pi)
>>> bb.duration, float(bb(0.5)), float(bb(1.5)), float(bb.angle(2.0))
(2.0, 3.141592653589793, -3.141592653589793, 1.5707963267948966)
>>> zv = zv_shaper(frequency=np.pi)
>>> zv.times, zv.amplitudes
((0.0, 1.0), (0.5, 0.5))
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import check_real
from flexctl.model.errors import InputTypeError, InputValueError

from flexctl.sim.maneuvers import rigid_slew_duration

from ..design.plant_state import checked_rigid_inertia

__all__ = ["BangBang", "bang_bang", "Shaper", "zv_shaper", "zvd_shaper", "design_shaper",
           "convolve", "shaper_frequencies",
           "ShapedTorque", "ShapedReference", "shape"]


@dataclass(frozen=True, kw_only=True)
class BangBang:
    """Rigid-body time-optimal slew torque, a function of time with ``breakpoints``.

    Parameters
    ----------
    slew_angle : float
        Hub angle to turn through, rad (finite, nonzero; its sign is the direction).
    inertia : float
        Rigid inertia ``J0``, kg m^2 (> 0).
    peak_torque : float
        Torque magnitude of both halves, N m (> 0).
    start_time : float, optional
        Time the slew starts, s (>= 0). Default 0.

    Notes
    -----
    ``duration = 2 sqrt(|slew_angle| inertia / peak_torque)``; the torque is
    ``sign(slew_angle) peak_torque`` on ``[start, start + duration/2)``, the opposite on
    ``[start + duration/2, start + duration)``, 0 elsewhere. :meth:`angle`, :meth:`rate` and
    :meth:`acceleration` give the rigid motion it produces.
    """

    slew_angle: float
    inertia: float
    peak_torque: float
    start_time: float = 0.0

    def __post_init__(self):
        angle = check_real("bang_bang", "slew_angle", self.slew_angle)
        if angle == 0.0:
            raise InputValueError("bang_bang.slew_angle must be nonzero; got 0.0")
        object.__setattr__(self, "slew_angle", angle)
        for name in ("inertia", "peak_torque"):
            object.__setattr__(self, name, check_real("bang_bang", name, getattr(self, name),
                                                 minimum=0.0, strict=True))
        object.__setattr__(self, "start_time", check_real("bang_bang", "start_time",
                                                     self.start_time, minimum=0.0))
        # once: a SciPy run asks the torque at every step
        object.__setattr__(self, "_duration", rigid_slew_duration(
            self.slew_angle, self.inertia, self.peak_torque))

    @property
    def duration(self) -> float:
        """Slew time, s."""
        return self._duration

    @property
    def breakpoints(self) -> tuple:
        """Switching times, s."""
        t0, half = self.start_time, 0.5 * self.duration
        return (t0, t0 + half, t0 + 2.0 * half)

    def acceleration(self, t):
        """Rigid acceleration ``torque / inertia``, rad/s^2, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        t = np.asarray(t, dtype=float) - self.start_time
        half, a = 0.5 * self.duration, math.copysign(self.peak_torque / self.inertia,
                                                    self.slew_angle)
        return np.where((t >= 0) & (t < half), a, np.where((t >= half) & (t < 2 * half),
                                                           -a, 0.0))

    def __call__(self, t):
        """Torque at time(s) ``t``, N m."""
        return self.inertia * self.acceleration(t)

    def casadi(self, t):
        """The torque as a CasADi expression of the symbol ``t``, N m.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        import casadi as ca

        t = t - self.start_time
        half, a = 0.5 * self.duration, math.copysign(self.peak_torque / self.inertia,
                                                    self.slew_angle)
        acc = ca.if_else(ca.logic_and(t >= 0, t < half), a,
                         ca.if_else(ca.logic_and(t >= half, t < 2 * half), -a, 0.0))
        return self.inertia * acc

    def rate(self, t):
        """Rigid hub rate, rad/s, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        t = np.clip(np.asarray(t, dtype=float) - self.start_time, 0.0, self.duration)
        half, a = 0.5 * self.duration, math.copysign(self.peak_torque / self.inertia,
                                                    self.slew_angle)
        return np.where(t < half, a * t, a * (2 * half - t))

    def angle(self, t):
        """Rigid hub angle from the start, rad, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        t = np.clip(np.asarray(t, dtype=float) - self.start_time, 0.0, self.duration)
        half, a = 0.5 * self.duration, math.copysign(self.peak_torque / self.inertia,
                                                    self.slew_angle)
        return np.where(t < half, 0.5 * a * t ** 2,
                        self.slew_angle - 0.5 * a * (2 * half - t) ** 2)


def bang_bang(model_or_inertia, slew_angle: float, *, torque_limit: float | None = None,
              duration: float | None = None, start_time: float = 0.0) -> BangBang:
    """Bang-bang slew from a torque limit (time-optimal) or from a duration.

    Parameters
    ----------
    model_or_inertia : flexctl.Model or float
        Model (its ``rigid_inertia`` is used) or rigid inertia, kg m^2.
    slew_angle : float
        Hub angle to turn through, rad (nonzero).
    torque_limit : float, optional
        Peak torque, N m; the slew takes the shortest time this torque allows.
    duration : float, optional
        Slew time, s; the torque is the one that slews in this time. Give exactly one of the
        two.
    start_time : float, optional
        Time the slew starts, s (>= 0). Default 0.
    """
    inertia = checked_rigid_inertia("bang_bang", model_or_inertia)
    if (torque_limit is None) == (duration is None):
        raise InputValueError("bang_bang needs exactly one of torque_limit and duration; got "
                              f"torque_limit={torque_limit!r}, duration={duration!r}")
    if duration is not None:
        duration = check_real("bang_bang", "duration", duration, minimum=0.0, strict=True)
        angle = check_real("bang_bang", "slew_angle", slew_angle)
        torque_limit = 4.0 * abs(angle) * inertia / duration ** 2
    return BangBang(slew_angle=slew_angle, inertia=inertia, peak_torque=torque_limit,
                    start_time=start_time)


@dataclass(frozen=True, kw_only=True)
class Shaper:
    """Impulse train ``sum_i A_i delta(t - t_i)``.

    Parameters
    ----------
    times : tuple of float
        ``t_i``, s: start at 0, strictly increasing.
    amplitudes : tuple of float
        ``A_i``: positive, summing to 1.
    """

    times: tuple
    amplitudes: tuple

    def __post_init__(self):
        times = tuple(check_real("shaper", "times", t) for t in self.times)
        amps = tuple(check_real("shaper", "amplitudes", a, minimum=0.0, strict=True)
                     for a in self.amplitudes)
        if len(times) != len(amps) or not times or times[0] != 0.0 \
                or any(b <= a for a, b in zip(times, times[1:])):
            raise InputValueError("shaper.times must start at 0, increase strictly and match "
                                  f"amplitudes in length; got times={self.times!r}, "
                                  f"amplitudes={self.amplitudes!r}")
        if abs(sum(amps) - 1.0) > 1e-12:
            raise InputValueError(f"shaper.amplitudes must sum to 1; got sum {sum(amps)!r}")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "amplitudes", amps)

    @property
    def duration(self) -> float:
        """Delay the shaper adds to a command, s."""
        return self.times[-1]


def _shaper_terms(owner, frequency, damping_ratio):
    w = check_real(owner, "frequency", frequency, minimum=0.0, strict=True)
    zeta = check_real(owner, "damping_ratio", damping_ratio, minimum=0.0, maximum=1.0)
    if zeta >= 1.0:
        raise InputValueError(f"{owner}.damping_ratio must be < 1 (an oscillating mode); "
                              f"got {zeta}")
    root = math.sqrt(1.0 - zeta ** 2)
    return math.exp(-zeta * math.pi / root), math.pi / (w * root)


def zv_shaper(frequency: float, damping_ratio: float = 0.0) -> Shaper:
    """Zero-vibration shaper for a mode of ``frequency`` and ``damping_ratio``.

    Parameters
    ----------
    frequency : float
        Undamped natural frequency ``omega`` of the mode, rad/s (> 0).
    damping_ratio : float, optional
        Modal damping ratio ``zeta`` (0 <= zeta < 1). Default 0.
    """
    k, half = _shaper_terms("zv_shaper", frequency, damping_ratio)
    return Shaper(times=(0.0, half), amplitudes=(1.0 / (1.0 + k), k / (1.0 + k)))


def zvd_shaper(frequency: float, damping_ratio: float = 0.0) -> Shaper:
    """Zero-vibration-derivative shaper for a mode of ``frequency``.

    Parameters
    ----------
    frequency : float
        Undamped natural frequency ``omega`` of the mode, rad/s (> 0).
    damping_ratio : float, optional
        Modal damping ratio ``zeta`` (0 <= zeta < 1). Default 0.
    """
    k, half = _shaper_terms("zvd_shaper", frequency, damping_ratio)
    s = (1.0 + k) ** 2
    return Shaper(times=(0.0, half, 2.0 * half), amplitudes=(1.0 / s, 2.0 * k / s, k * k / s))


def convolve(first: Shaper, second: Shaper) -> Shaper:
    """The shaper whose impulse train is ``first`` convolved with ``second``: it cancels the
    vibration each of them cancels (times that coincide merge).

    Parameters
    ----------
    first, second : Shaper
        The two impulse trains (their delays add).
    """
    impulses = {}
    for t1, a1 in zip(first.times, first.amplitudes):
        for t2, a2 in zip(second.times, second.amplitudes):
            key = round(t1 + t2, 15)
            impulses[key] = impulses.get(key, 0.0) + a1 * a2
    times = sorted(impulses)
    amplitudes = [impulses[t] for t in times]
    total = sum(amplitudes)
    return Shaper(times=tuple(times), amplitudes=tuple(a / total for a in amplitudes))


def shaper_frequencies(model, spin_rate: float = 0.0) -> tuple:
    """``(frequency, damping ratio)`` of the modes a shaper of ``model`` cancels: the first
    hub-free flexible mode for one beam; for several appendages the lowest mode the torque
    moves in which each appendage bends most (its fundamental in the coupled structure),
    each once.

    Parameters
    ----------
    model : flexctl.Model
        The model whose modes are cancelled (one beam or a structure).
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.

    Returns
    -------
    tuple of (float, float)
        Each mode's natural frequency (rad/s) and its beam's modal damping ratio, by
        ascending frequency.
    """
    apps = model.structure.appendages
    if len(apps) == 1:
        return ((float(model.natural_frequencies(spin_rate, hub="free")[0]),
                 apps[0].beam.damping_ratio),)
    report = model.modal_visibility(spin_rate)
    moved = [j for j in range(report.frequencies.size)
             if report.frequencies[j] > 0.0 and j not in report.uncontrollable("torque")]
    layout, picks = model.layout, []
    for k, app in enumerate(apps):
        block = layout.modal_slice(app.name)
        share = [np.linalg.norm(report.shapes[block, j]) / np.linalg.norm(report.shapes[:, j])
                 for j in moved]
        own = [j for j, f in zip(moved, share) if f >= max(share) * 0.5]
        if own:
            picks.append((float(report.frequencies[own[0]]), app.beam.damping_ratio))
    unique = []
    for w, zeta in sorted(picks):
        if not unique or abs(w - unique[-1][0]) > 1e-6 * w:
            unique.append((w, zeta))
    return tuple(unique)


def design_shaper(model, kind: str = "zv", spin_rate: float = 0.0) -> Shaper:
    """ZV or ZVD shaper at the fundamental flexible frequencies of ``model``.

    One beam: ``model.natural_frequencies(spin_rate, hub="free")[0]`` with the beam's modal
    damping ratio. Several appendages: one ZV or ZVD shaper per frequency of
    :func:`shaper_frequencies` (each appendage's fundamental among the modes the torque moves),
    convolved: the multi-mode shaper of unequal appendages.

    Parameters
    ----------
    model : flexctl.Model
        The model whose fundamental modes are cancelled.
    kind : {"zv", "zvd"}, optional
        :func:`zv_shaper` or :func:`zvd_shaper` for each frequency. Default ``"zv"``.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.
    """
    makers = {"zv": zv_shaper, "zvd": zvd_shaper}
    if kind not in makers:
        raise InputValueError(f"design_shaper.kind must be 'zv' or 'zvd'; got {kind!r}")
    shapers = [makers[kind](w, zeta) for w, zeta in shaper_frequencies(model, spin_rate)]
    out = shapers[0]
    for extra in shapers[1:]:
        out = convolve(out, extra)
    return out


def _shifted_breakpoints(base, shaper):
    points = getattr(base, "breakpoints", ()) or ()
    return tuple(sorted({float(b) + t for b in points for t in shaper.times}))


@dataclass(frozen=True, kw_only=True, eq=False)
class ShapedTorque:
    """Torque ``sum_i A_i base(t - t_i)``, N m; ``base`` is a torque function of time.

    Made by :func:`shape`.

    Parameters
    ----------
    base : callable
        The command shaped: torque (N m) as a function of time (s), with ``breakpoints``
        and ``casadi(t)`` when it has them.
    shaper : Shaper
        The impulse train it is convolved with.
    """

    base: object
    shaper: Shaper

    @property
    def breakpoints(self) -> tuple:
        """Every breakpoint of ``base`` shifted by every impulse time, s."""
        return _shifted_breakpoints(self.base, self.shaper)

    def __call__(self, t):
        """Torque at time(s) ``t``, N m."""
        t = np.asarray(t, dtype=float)
        return sum(a * np.asarray(self.base(t - ti), dtype=float)
                   for ti, a in zip(self.shaper.times, self.shaper.amplitudes))

    @property
    def has_casadi_form(self) -> bool:
        """True when ``base`` has a CasADi form (``casadi(t)``)."""
        return callable(getattr(self.base, "casadi", None)) \
            and bool(getattr(self.base, "has_casadi_form", True))

    def casadi(self, t):
        """The torque as a CasADi expression of the symbol ``t``, N m.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        return sum(a * self.base.casadi(t - ti)
                   for ti, a in zip(self.shaper.times, self.shaper.amplitudes))


@dataclass(frozen=True, kw_only=True, eq=False)
class ShapedReference:
    """Reference ``sum_i A_i base(t - t_i)`` for angle, rate and acceleration.

    ``base`` must rest at its initial value before its start (as
    :class:`~controllers.slew.reference.SlewProfile` does). Made by :func:`shape`.

    Parameters
    ----------
    base : object
        The reference shaped: ``angle(t)`` (rad), ``rate(t)`` (rad/s) and
        ``acceleration(t)`` (rad/s^2) of time (s), with ``breakpoints`` and
        ``casadi_reference(t)`` when it has them.
    shaper : Shaper
        The impulse train it is convolved with.
    """

    base: object
    shaper: Shaper

    @property
    def breakpoints(self) -> tuple:
        """Every breakpoint of ``base`` shifted by every impulse time, s."""
        return _shifted_breakpoints(self.base, self.shaper)

    def _sum(self, name, t):
        t = np.asarray(t, dtype=float)
        method = getattr(self.base, name)
        return sum(a * np.asarray(method(t - ti), dtype=float)
                   for ti, a in zip(self.shaper.times, self.shaper.amplitudes))

    def angle(self, t):
        """Reference hub angle, rad, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        return self._sum("angle", t)

    def rate(self, t):
        """Reference hub rate, rad/s, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        return self._sum("rate", t)

    def acceleration(self, t):
        """Reference hub acceleration, rad/s^2, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        return self._sum("acceleration", t)

    @property
    def has_casadi_form(self) -> bool:
        """True when ``base`` has a CasADi form (``casadi_reference(t)``)."""
        return callable(getattr(self.base, "casadi_reference", None)) \
            and bool(getattr(self.base, "has_casadi_form", True))

    def casadi_reference(self, t):
        """Angle (rad), rate (rad/s) and acceleration (rad/s^2) as CasADi expressions of the
        symbol ``t``.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.
        """
        parts = [self.base.casadi_reference(t - ti) for ti in self.shaper.times]
        return tuple(sum(a * part[j] for a, part in zip(self.shaper.amplitudes, parts))
                     for j in range(3))


def shape(command, shaper: Shaper):
    """Convolve a command with a shaper.

    Parameters
    ----------
    command : callable or reference
        A torque function of time (e.g. :class:`BangBang`), or a reference with ``angle``,
        ``rate`` and ``acceleration`` methods (e.g. a
        :class:`~controllers.slew.reference.SlewProfile`). A :class:`BangBang` is shaped as a
        torque.
    shaper : Shaper
        The impulse train to convolve with.

    Returns
    -------
    ShapedTorque or ShapedReference
    """
    if not isinstance(shaper, Shaper):
        raise InputTypeError(f"shape.shaper must be a Shaper; got {type(shaper).__name__}")
    if callable(command):
        return ShapedTorque(base=command, shaper=shaper)
    if all(callable(getattr(command, n, None)) for n in ("angle", "rate", "acceleration")):
        return ShapedReference(base=command, shaper=shaper)
    raise InputTypeError("shape.command must be a torque function of time or a reference with "
                         f"angle, rate and acceleration; got {type(command).__name__}")
