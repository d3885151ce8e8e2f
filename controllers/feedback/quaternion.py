"""Quaternion feedback: a three-axis attitude law on the attitude error quaternion.

:class:`QuaternionFeedback` commands, with ``dq = target^-1 (x) q = (dq_0, dq_v)`` the
attitude error (in the hub frame) taken the short way round (``dq_0 >= 0``; Wie, Weiss and
Arapostathis, 1989)::

    torque = -K_p 2 dq_v - K_d (w - w_target) - K_i integral(2 dq_v dt)

each gain a 3 x 3 matrix (N m per rad, N m s per rad, N m per rad s), saturated per axis at
``torque_limit``. :meth:`QuaternionFeedback.design` sets them from the rigid inertia for a
bandwidth and damping on each principal axis, ``K_p = J w_n^2``, ``K_d = 2 zeta w_n J`` (and
``K_i = K_p / integral_time``); a flexible structure wants ``bandwidth`` well below its first
mode. The integral is held while the command saturates (no wind-up); it runs in a session
(:meth:`QuaternionFeedback.start`), which is what
:func:`flexctl.sim.spatial_loop.simulate_spatial_loop` calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexctl.model.checks import KeywordOnly, check_array, check_real
from flexctl.model.errors import InputValueError
from flexctl.sim.quaternions import conjugate, product

__all__ = ["QuaternionFeedback", "QuaternionFeedbackSession", "attitude_error"]


def attitude_error(target, attitude) -> np.ndarray:
    """``2 dq_v`` of ``dq = target^-1 (x) attitude``, taken the short way round, rad
    (about the rotation vector for small errors).

    Parameters
    ----------
    target, attitude : array_like, shape (4,)
        Unit quaternions, hub to inertial, scalar first.

    Returns
    -------
    ndarray, shape (3,)
    """
    dq = product(conjugate(target), np.asarray(attitude, dtype=float))
    return 2.0 * dq[1:] * (1.0 if dq[0] >= 0 else -1.0)


def _gain(name, value) -> np.ndarray:
    gain = np.asarray(check_array("quaternion_feedback", name, value), dtype=float)
    if gain.shape == ():
        gain = gain * np.eye(3)
    elif gain.shape == (3,):
        gain = np.diag(gain)
    if gain.shape != (3, 3):
        raise InputValueError(f"quaternion_feedback.{name} must be a number, 3 numbers or a "
                              f"3 x 3 matrix; got shape {gain.shape}")
    gain = np.array(gain)
    gain.setflags(write=False)
    return gain


@dataclass(frozen=True, kw_only=True, eq=False)
class QuaternionFeedback(KeywordOnly):
    """The law (see the module description).

    Parameters
    ----------
    target : array_like, shape (4,)
        Target attitude, hub to inertial, scalar first (normalised).
    kp : float, array_like (3,) or (3, 3)
        Proportional gain, N m/rad.
    kd : float, array_like (3,) or (3, 3)
        Rate gain, N m s/rad.
    ki : float, array_like (3,) or (3, 3), optional
        Integral gain, N m/(rad s). Default 0.
    torque_limit : float or None, optional
        Saturation of each axis's command, N m. Default none.
    target_rate : array_like, shape (3,), optional
        Hub rate to hold, hub frame, rad/s. Default zero.
    """

    target: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    ki: np.ndarray = field(default=0.0)
    torque_limit: float | None = None
    target_rate: np.ndarray = field(default=(0.0, 0.0, 0.0))

    def __post_init__(self):
        target = np.array(check_array("quaternion_feedback", "target", self.target, shape=(4,)))
        if not np.linalg.norm(target) > 0:
            raise InputValueError("quaternion_feedback.target must be a non-zero quaternion")
        target /= np.linalg.norm(target)
        target.setflags(write=False)
        object.__setattr__(self, "target", target)
        for name in ("kp", "kd", "ki"):
            object.__setattr__(self, name, _gain(name, getattr(self, name)))
        if self.torque_limit is not None:
            object.__setattr__(self, "torque_limit", check_real(
                "quaternion_feedback", "torque_limit", self.torque_limit, minimum=0.0,
                strict=True))
        object.__setattr__(self, "target_rate", check_array(
            "quaternion_feedback", "target_rate", self.target_rate, shape=(3,)))

    @classmethod
    def design(cls, inertia, bandwidth: float, target, *, damping: float = 0.7,
               integral_time: float | None = None,
               torque_limit: float | None = None) -> "QuaternionFeedback":
        """Gains from the rigid inertia for a bandwidth and damping on every axis.

        Parameters
        ----------
        inertia : array_like, shape (3, 3)
            Rigid inertia of the structure about its turning point, kg m^2 (a
            ``SpatialStructure.rigid_inertia``).
        bandwidth : float
            Natural frequency ``w_n`` of the closed rigid loop, rad/s (> 0).
        target : array_like, shape (4,)
            Target attitude.
        damping : float, optional
            ``zeta`` (> 0). Default 0.7.
        integral_time : float or None, optional
            ``K_i = K_p / integral_time``, s; None (default): no integral action.
        torque_limit : float or None, optional
            Per-axis saturation, N m.

        Returns
        -------
        QuaternionFeedback
        """
        j = np.array(check_array("quaternion_feedback", "inertia", inertia, shape=(3, 3)))
        w = check_real("quaternion_feedback", "bandwidth", bandwidth, minimum=0.0, strict=True,
                       maximum=1e4)
        zeta = check_real("quaternion_feedback", "damping", damping, minimum=0.0, strict=True,
                          maximum=10.0)
        kp = j * w * w
        ki = 0.0
        if integral_time is not None:
            ki = kp / check_real("quaternion_feedback", "integral_time", integral_time,
                                 minimum=0.0, strict=True)
        return cls(target=target, kp=kp, kd=2 * zeta * w * j, ki=ki, torque_limit=torque_limit)

    def start(self) -> "QuaternionFeedbackSession":
        """A session with its integral at zero.

        Returns
        -------
        QuaternionFeedbackSession
        """
        return QuaternionFeedbackSession(self)

    def __call__(self, t, attitude, rate) -> np.ndarray:
        """The command without integral action (the integral needs a session).

        Parameters
        ----------
        t : float
            Time, s.
        attitude : array_like, shape (4,)
            Attitude, hub to inertial, scalar first.
        rate : array_like, shape (3,)
            Hub rate, hub frame, rad/s.

        Returns
        -------
        ndarray, shape (3,)
            Torque, N m, hub frame.
        """
        return QuaternionFeedbackSession(self)(t, attitude, rate)    # a fresh integral: none

    def _limited(self, torque):
        if self.torque_limit is None:
            return torque
        return np.clip(torque, -self.torque_limit, self.torque_limit)


class QuaternionFeedbackSession:
    """A running :class:`QuaternionFeedback` with its integral (rectangle rule between
    calls), held while the command saturates (conditional integration: no wind-up).

    Parameters
    ----------
    law : QuaternionFeedback
        The law.
    """

    def __init__(self, law: QuaternionFeedback):
        self.law = law
        self.integral = np.zeros(3)
        self.last = None

    def __call__(self, t, attitude, rate) -> np.ndarray:
        """The command at ``t``.

        Parameters
        ----------
        t : float
            Time, s (non-decreasing from call to call).
        attitude : array_like, shape (4,)
            Attitude, hub to inertial, scalar first.
        rate : array_like, shape (3,)
            Hub rate, hub frame, rad/s.

        Returns
        -------
        ndarray, shape (3,)
            Torque, N m, hub frame.
        """
        law = self.law
        error = attitude_error(law.target, attitude)
        feedback = -law.kp @ error - law.kd @ (np.asarray(rate, float) - law.target_rate)
        if self.last is not None:
            grown = self.integral + error * (t - self.last)
            command = feedback - law.ki @ grown
            if law.torque_limit is None or np.all(np.abs(command) <= law.torque_limit):
                self.integral = grown
        self.last = t
        return law._limited(feedback - law.ki @ self.integral)
