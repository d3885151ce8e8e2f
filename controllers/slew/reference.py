"""Smooth rest-to-rest reference profiles for a hub slew.

A :class:`SlewProfile` moves the hub angle from 0 to ``slew_angle`` in ``duration`` seconds,
starting at rest and ending at rest. It evaluates exactly at any time (no sampling), accepts
arrays, and lists its ``breakpoints`` (start and end of the motion), where
:func:`flexctl.simulate` restarts the integrator. It has the ``angle``, ``rate`` and
``acceleration`` methods of a prescribed hub motion, so it can also be passed to
``simulate(model, t_final, hub_motion=profile)``.

Profiles, with ``A = slew_angle``, ``T = duration``, ``tau = (t - start_time) / T`` in
``[0, 1]`` and ``s(tau)`` the fraction of the slew done:

- ``poly7``: ``s = 35 tau^4 - 84 tau^5 + 70 tau^6 - 20 tau^7``; peak rate ``35/16 A/T``,
  peak acceleration ``84 sqrt(5)/25 A/T^2`` (about ``7.51 A/T^2``);
- ``cycloidal``: ``s = tau - sin(2 pi tau) / (2 pi)``; peak rate ``2 A/T``, peak
  acceleration ``2 pi A/T^2``.

``poly7`` starts and ends with zero rate, acceleration and jerk; ``cycloidal`` with zero rate
and acceleration (its jerk steps).

Examples
--------
>>> import numpy as np
>>> from controllers.slew.reference import SlewProfile
>>> slew = SlewProfile(slew_angle=np.pi / 2, duration=2.0)
>>> float(slew.angle(1.0)), float(slew.rate(0.0)), float(slew.angle(5.0))
(0.7853981633974483, 0.0, 1.5707963267948966)
>>> slew.breakpoints
(0.0, 2.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexctl.model.errors import InputTypeError, InputValueError

from flexctl.model.checks import KeywordOnly
from flexctl.model.checks import check_real as _real
from flexctl.sim.maneuvers import RIGID_PEAK_ACCELERATION, rigid_slew_duration

from ..spec import SHAPES

__all__ = ["SlewProfile", "minimum_slew_duration", "SHAPES"]

#: Peak rate of each unit profile, rad/s.
_PEAK_RATE = {"poly7": 35.0 / 16.0, "cycloidal": 2.0}


def optional_positive(owner: str, name: str, value) -> float | None:
    """``None`` or a finite number > 0.

    Parameters
    ----------
    owner : str
        The class or function named in the error message.
    name : str
        The argument named in the error message.
    value : float or None
        The value to check.

    Raises
    ------
    InputTypeError, InputValueError
        If ``value`` is not None and not a finite number > 0.
    """
    return _real(owner, name, value, minimum=0.0, strict=True, optional=True)


def _shape_terms(shape: str, tau, sin, cos) -> tuple:
    """The profile ``s`` and its derivatives ``s'``, ``s''`` in normalised time ``tau`` (a
    float or a CasADi symbol, with the matching ``sin`` and ``cos``)."""
    if shape == "poly7":
        return (tau ** 4 * (35.0 + tau * (-84.0 + tau * (70.0 - 20.0 * tau))),
                140.0 * (tau * (1.0 - tau)) ** 3,
                420.0 * (tau * (1.0 - tau)) ** 2 * (1.0 - 2.0 * tau))
    return (tau - sin(2.0 * math.pi * tau) / (2.0 * math.pi),
            1.0 - cos(2.0 * math.pi * tau),
            2.0 * math.pi * sin(2.0 * math.pi * tau))


@dataclass(frozen=True, kw_only=True)
class SlewProfile(KeywordOnly):
    """Rest-to-rest slew of the hub angle from 0 to ``slew_angle``.

    Parameters
    ----------
    slew_angle : float
        Commanded angle ``A``, rad (finite, either sign).
    duration : float
        Slew time ``T``, s (> 0).
    start_time : float, optional
        Time the slew starts, s (>= 0). Default 0.
    shape : {"poly7", "cycloidal"}, optional
        Profile shape (module table). Default ``"poly7"``.

    Notes
    -----
    Before ``start_time`` the reference rests at 0, after ``start_time + duration`` at
    ``slew_angle``. Every method accepts a float or an array of times and returns the same shape.
    """

    slew_angle: float
    duration: float
    start_time: float = 0.0
    shape: str = "poly7"

    def __post_init__(self):
        object.__setattr__(self, "slew_angle", _real("slew", "slew_angle", self.slew_angle))
        object.__setattr__(self, "duration", _real("slew", "duration", self.duration,
                                                   minimum=0.0, strict=True))
        object.__setattr__(self, "start_time", _real("slew", "start_time", self.start_time,
                                                     minimum=0.0))
        if self.shape not in SHAPES:
            raise InputValueError(f"slew.shape must be one of {', '.join(SHAPES)}; "
                                  f"got {self.shape!r}")

    @property
    def end_time(self) -> float:
        """Time the slew ends, s."""
        return self.start_time + self.duration

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the profile is not smooth: its start and end."""
        return (self.start_time, self.end_time)

    @property
    def peak_rate(self) -> float:
        """Largest ``|rate|``, rad/s."""
        return _PEAK_RATE[self.shape] * abs(self.slew_angle) / self.duration

    @property
    def peak_acceleration(self) -> float:
        """Largest ``|acceleration|``, rad/s^2."""
        return RIGID_PEAK_ACCELERATION[self.shape] * abs(self.slew_angle) / self.duration ** 2

    @property
    def casadi_parameters(self) -> tuple:
        """``(structure, values)``: the shape shapes :meth:`casadi_reference`; its numbers are
        ``[slew_angle, duration, start_time]`` (compiled laws following slews of one shape
        share one function)."""
        return (self.shape,), np.array([self.slew_angle, self.duration, self.start_time])

    def casadi_reference(self, t, parameters=None):
        """Angle, rate and acceleration as CasADi expressions of the symbol ``t`` (the
        formulas of :meth:`angle`, :meth:`rate`, :meth:`acceleration`); the numbers are symbols
        too when ``parameters`` is given.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        parameters : CasADi column, shape (3, 1), optional
            ``[slew_angle, duration, start_time]`` (rad, s, s), laid out as
            :attr:`casadi_parameters`. Default: this profile's numbers.
        """
        import casadi as ca

        angle, duration, start = self.slew_angle, self.duration, self.start_time
        if parameters is not None:
            angle, duration, start = parameters[0], parameters[1], parameters[2]
        tau = ca.fmin(ca.fmax((t - start) / duration, 0.0), 1.0)
        s, ds, dds = _shape_terms(self.shape, tau, ca.sin, ca.cos)
        return angle * s, angle / duration * ds, angle / duration ** 2 * dds

    def _tau(self, t):
        t = np.asarray(t, dtype=float)
        return np.clip((t - self.start_time) / self.duration, 0.0, 1.0)

    def at(self, t: float) -> tuple:
        """Angle (rad), rate (rad/s) and acceleration (rad/s^2) at one time ``t`` (s), as
        floats: the formulas of :meth:`angle`, :meth:`rate` and :meth:`acceleration` on a
        scalar, as a sampled law reads them at every sample.

        Parameters
        ----------
        t : float
            Time, s.
        """
        t = _real("slew.at", "t", t)
        tau = min(max((t - self.start_time) / self.duration, 0.0), 1.0)
        s, ds, dds = _shape_terms(self.shape, tau, math.sin, math.cos)
        return (self.slew_angle * s, self.slew_angle / self.duration * ds,
                self.slew_angle / self.duration ** 2 * dds)

    def _terms(self, t) -> tuple:
        """``s``, ``s'`` and ``s''`` at times ``t`` (``_shape_terms`` on arrays)."""
        return _shape_terms(self.shape, self._tau(t), np.sin, np.cos)

    def angle(self, t):
        """Reference hub angle, rad, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        return self.slew_angle * self._terms(t)[0]

    def rate(self, t):
        """Reference hub rate, rad/s, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        return self.slew_angle / self.duration * self._terms(t)[1]

    def acceleration(self, t):
        """Reference hub acceleration, rad/s^2, shaped as ``t``.

        Parameters
        ----------
        t : float or array_like
            Time(s), s.
        """
        return self.slew_angle / self.duration ** 2 * self._terms(t)[2]


def minimum_slew_duration(slew_angle: float, inertia: float, torque_limit: float,
                          shape: str = "poly7") -> float:
    """Shortest duration for which the rigid feedforward ``inertia * acceleration`` of a
    profile stays within ``torque_limit``.

    Parameters
    ----------
    slew_angle : float
        Hub angle to turn through, rad (finite, nonzero).
    inertia : float
        Rigid inertia, kg m^2 (> 0), e.g. ``model.matrices.J0``.
    torque_limit : float
        N m (> 0).
    shape : {"poly7", "cycloidal"}, optional
        Profile shape (module table). Default ``"poly7"``.

    Returns
    -------
    float
        s.

    Examples
    --------
    >>> round(minimum_slew_duration(1.0, 1.0, 2.0 * 3.141592653589793, "cycloidal"), 12)
    1.0
    """
    angle = _real("minimum_slew_duration", "slew_angle", slew_angle)
    if angle == 0.0:
        raise InputValueError("minimum_slew_duration.slew_angle must be nonzero; got 0.0")
    inertia = _real("minimum_slew_duration", "inertia", inertia, minimum=0.0, strict=True)
    limit = _real("minimum_slew_duration", "torque_limit", torque_limit, minimum=0.0,
                  strict=True)
    if shape not in SHAPES:
        raise InputValueError(f"minimum_slew_duration.shape must be one of {', '.join(SHAPES)}; "
                              f"got {shape!r}")
    return rigid_slew_duration(angle, inertia, limit, shape)


def check_reference(owner: str, reference):
    """``reference`` must be ``None`` or have callable ``angle``, ``rate``, ``acceleration``.

    Parameters
    ----------
    owner : str
        The class or function named in the error message.
    reference : object or None
        Hub reference with methods ``angle(t)``, ``rate(t)``, ``acceleration(t)`` (rad, rad/s,
        rad/s^2 at time ``t``, s), e.g. a :class:`SlewProfile`.

    Raises
    ------
    InputTypeError
        If one of the three methods is missing.
    """
    if reference is None:
        return None
    for attr in ("angle", "rate", "acceleration"):
        if not callable(getattr(reference, attr, None)):
            raise InputTypeError(f"{owner}.reference must have a callable {attr}(t) (e.g. a "
                                 f"SlewProfile); got {type(reference).__name__}")
    return reference


def evaluate_reference(reference, t: float):
    """Reference angle (rad), rate (rad/s) and acceleration (rad/s^2) at ``t``; 0 for None.

    Parameters
    ----------
    reference : object or None
        Hub reference with methods ``angle``, ``rate`` and ``acceleration`` of time
        (:func:`check_reference`), e.g. a :class:`SlewProfile`.
    t : float
        Time, s.
    """
    if reference is None:
        return 0.0, 0.0, 0.0
    if isinstance(reference, SlewProfile) and isinstance(t, (float, int, np.floating)):
        return reference.at(t)
    return (float(reference.angle(t)), float(reference.rate(t)),
            float(reference.acceleration(t)))


def saturate(torque: float, limit: float | None) -> float:
    """Clip ``torque`` to ``[-limit, limit]`` (no clipping for ``limit=None``).

    Parameters
    ----------
    torque : float
        Hub torque, N m.
    limit : float or None
        Saturation, N m (> 0).
    """
    return torque if limit is None else min(max(torque, -limit), limit)


# ---- CasADi forms of the helpers above, for the compiled simulation path ----------------
def has_casadi(source, method: str = "casadi_reference") -> bool:
    """``source`` is absent or offers a CasADi form ``method`` (and does not disown it).

    Parameters
    ----------
    source : object or None
        A reference, a noise source or another part of a law; it disowns its CasADi form
        with a false ``has_casadi_form`` attribute.
    method : str, optional
        Name of the CasADi method looked for. Default ``"casadi_reference"``.
    """
    return source is None or (callable(getattr(source, method, None))
                              and bool(getattr(source, "has_casadi_form", True)))


def _structure_key(source):
    """``source`` itself where it compares by value (a frozen dataclass such as
    :class:`SlewProfile`), else its identity: part of a compiled law's structure."""
    try:
        hash(source)
    except TypeError:
        return ("id", id(source))
    return source


def reference_parameters(reference) -> tuple:
    """``(structure, values)`` of a reference inside a compiled law: its own
    ``casadi_parameters`` where it offers them (its numbers then enter as parameters), else
    the reference itself as structure (``_structure_key``) and no numbers.

    Parameters
    ----------
    reference : object or None
        A hub reference (``angle``, ``rate``, ``acceleration``), or None.
    """
    own = getattr(reference, "casadi_parameters", None) if reference is not None else None
    if own is None:
        return _structure_key(reference), np.zeros(0)
    return (type(reference), own[0]), np.asarray(own[1], dtype=float).reshape(-1)


def casadi_evaluate(reference, t, parameters=None):
    """:func:`evaluate_reference` on the CasADi symbol ``t``; the reference's numbers are the
    symbols ``parameters`` where given.

    Parameters
    ----------
    reference : object or None
        Hub reference with a ``casadi_reference(t[, parameters])`` method (e.g. a
        :class:`SlewProfile`); None gives zeros.
    t : CasADi scalar
        Time, s.
    parameters : CasADi column, optional
        The reference's numbers, laid out as :func:`reference_parameters`; empty or None:
        the reference's own numbers.
    """
    if reference is None:
        return 0.0, 0.0, 0.0
    if parameters is not None and parameters.numel() > 0:
        return reference.casadi_reference(t, parameters)
    return reference.casadi_reference(t)


def casadi_saturate(torque, limit: float | None):
    """:func:`saturate` of a CasADi expression.

    Parameters
    ----------
    torque : CasADi scalar
        Hub torque, N m.
    limit : float, CasADi scalar or None
        Saturation, N m (> 0); None: no clipping.
    """
    import casadi as ca

    return torque if limit is None else ca.fmin(ca.fmax(torque, -limit), limit)
