"""A rest-to-rest slew about a fixed axis (an eigenaxis slew) for three-axis laws.

:class:`EigenaxisSlew` turns a planar angle profile ``theta(t)`` (a
:class:`~controllers.slew.reference.SlewProfile`, or one shaped against the modes,
:func:`~controllers.slew.shaping.shape`) into a three-axis reference about the hub-frame
``axis`` from the ``start`` attitude: the attitude ``q_ref(t) = start (x) exp(theta(t) axis /
2)``, the rate ``theta'(t) axis`` and the feedforward torque that turns the rigid structure so
(``J theta'' axis + theta' axis x J theta' axis``, ``J`` the structure's rigid inertia). About
a fixed axis the rotation vector of ``target^-1 (x) q_ref(t)`` is ``(theta(t) - theta_f)
axis`` exactly, so a law that regulates the error from the final ``target`` follows the
reference by regulating ``x - x_ref(t)``
(:class:`~controllers.feedback.spatial_lqr.SpatialLQR`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import KeywordOnly, check_array, check_direction
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.quaternions import from_rotation_vector, product

from .reference import check_reference, evaluate_reference

__all__ = ["EigenaxisSlew"]


@dataclass(frozen=True, kw_only=True, eq=False)
class EigenaxisSlew(KeywordOnly):
    """A slew about ``axis`` following ``profile`` (module description).

    Parameters
    ----------
    axis : array_like, shape (3,)
        The slew axis, hub frame (normalised).
    profile : object
        The angle about it: ``angle(t)``, ``rate(t)``, ``acceleration(t)`` (rad, rad/s,
        rad/s^2), at rest before its start and after its end, for example a
        :class:`~controllers.slew.reference.SlewProfile`; its final angle is the slew's.
    inertia : array_like, shape (3, 3)
        The structure's rigid inertia about its turning point, kg m^2 (a
        ``SpatialStructure.rigid_inertia``), for the feedforward torque.
    start : array_like, shape (4,), optional
        The attitude at the start, hub to inertial, scalar first. Default the identity.
    """

    axis: np.ndarray
    profile: object
    inertia: np.ndarray
    start: np.ndarray = (1.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "axis", check_direction("eigenaxis_slew", "axis", self.axis))
        if self.profile is None:
            raise InputTypeError("eigenaxis_slew.profile is required (e.g. a SlewProfile)")
        check_reference("eigenaxis_slew", self.profile)
        if not np.isfinite(self.end_time):
            raise InputTypeError("eigenaxis_slew.profile must say when it ends: an end_time "
                                 "or breakpoints (a SlewProfile, or a shaped one)")
        inertia = np.array(check_array("eigenaxis_slew", "inertia", self.inertia, shape=(3, 3)))
        if not np.all(np.linalg.eigvalsh(0.5 * (inertia + inertia.T)) > 0):
            raise InputValueError("eigenaxis_slew.inertia must be positive definite")
        inertia.setflags(write=False)
        object.__setattr__(self, "inertia", inertia)
        start = np.array(check_array("eigenaxis_slew", "start", self.start, shape=(4,)))
        if not np.max(np.abs(start)) > 0:
            raise InputValueError("eigenaxis_slew.start must be a non-zero quaternion")
        start /= np.max(np.abs(start))
        start /= np.linalg.norm(start)
        start.setflags(write=False)
        object.__setattr__(self, "start", start)

    @property
    def end_time(self) -> float:
        """When the profile comes to rest, s (its ``end_time``, else its last breakpoint)."""
        end = getattr(self.profile, "end_time", None)
        if end is None:
            points = [float(p) for p in getattr(self.profile, "breakpoints", ()) or ()]
            end = max(points) if points else float("inf")
        return float(end)

    @property
    def final_angle(self) -> float:
        """``theta_f``, rad."""
        return evaluate_reference(self.profile, self.end_time)[0]

    @property
    def target(self) -> np.ndarray:
        """The attitude at the end, hub to inertial, scalar first."""
        return product(self.start, from_rotation_vector(self.final_angle * self.axis))

    def at(self, t: float) -> tuple:
        """The reference at ``t``.

        Parameters
        ----------
        t : float
            Time, s.

        Returns
        -------
        tuple
            ``(error, rate, torque)``: the rotation vector of ``target^-1 (x) q_ref(t)``
            (rad), the rate (rad/s, hub frame) and the feedforward torque (N m, hub frame).
        """
        angle, rate, acceleration = evaluate_reference(self.profile, float(t))
        spin = rate * self.axis
        torque = acceleration * (self.inertia @ self.axis) + np.cross(spin, self.inertia @ spin)
        return (angle - self.final_angle) * self.axis, spin, torque
