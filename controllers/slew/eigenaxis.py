"""A rest-to-rest slew about a fixed axis (an eigenaxis slew) for three-axis laws.

:class:`EigenaxisSlew` turns a planar angle profile ``theta(t)`` (a
:class:`~controllers.slew.reference.SlewProfile`, or one shaped against the modes,
:func:`~controllers.slew.shaping.shape`) into a three-axis reference about the hub-frame
``axis`` from the ``start`` attitude: the attitude ``q_ref(t) = start (x) exp(theta(t) axis /
2)``, the rate ``w = theta'(t) axis`` and the feedforward torque that turns the rigid structure so.
A torque on the hub from outside (thrusters, or a scene's hub torque) must also turn the
rigid body's own momentum: ``J theta'' axis + w x J w`` (``J`` the structure's rigid inertia).
A torque commanded of reaction wheels is the motors' reaction, and the wheels' momentum turns
with the hub: the hub and wheels' total angular momentum ``H`` (inertial frame) is conserved,
and the torque that turns the structure so is ``J theta'' axis + w x H_b(t)``, ``H_b`` the
total in the reference's hub frame (``momentum``; zero from rest with the wheels at rest, so
``J theta'' axis`` alone: counting ``w x J w`` there would be counting the wheels' gyroscopic
torque twice). About
a fixed axis the rotation vector of ``target^-1 (x) q_ref(t)`` is ``(theta(t) - theta_f)
axis`` exactly, so a law that regulates the error from the final ``target`` follows the
reference by regulating ``x - x_ref(t)``
(:class:`~controllers.feedback.spatial_lqr.SpatialLQR`).

:func:`eigenaxis_shaper` shapes the profile against the modes a torque about the axis moves
(input shaping per mode, :mod:`controllers.slew.shaping`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import KeywordOnly, check_array, check_direction, check_quaternion
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.quaternions import from_rotation_vector, product, rotation_matrix

from .reference import check_reference, evaluate_reference

__all__ = ["EigenaxisSlew", "eigenaxis_shaper", "eigenaxis_modes"]


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
    momentum : array_like, shape (3,), optional
        With the torque commanded of reaction wheels: the total angular momentum of the
        structure and its wheels, inertial frame, N m s (zeros from rest with the wheels at
        rest). Default None: the torque acts on the hub from outside (module description).
    """

    axis: np.ndarray
    profile: object
    inertia: np.ndarray
    start: np.ndarray = (1.0, 0.0, 0.0, 0.0)
    momentum: np.ndarray | None = None

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
        object.__setattr__(self, "start", check_quaternion("eigenaxis_slew", "start",
                                                           self.start))
        if self.momentum is not None:
            momentum = np.array(check_array("eigenaxis_slew", "momentum", self.momentum,
                                            shape=(3,)))
            momentum.setflags(write=False)
            object.__setattr__(self, "momentum", momentum)

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
        return ((angle - self.final_angle) * self.axis, rate * self.axis,
                self.feedforward(angle, rate, acceleration))

    def feedforward(self, angle, rate, acceleration):
        """The feedforward torque (module description) at the profile's angle, rate and
        acceleration, numbers or CasADi scalars (a C export's step).

        Parameters
        ----------
        angle, rate, acceleration : float or casadi.SX or casadi.MX
            ``theta``, ``theta'`` and ``theta''`` of the profile: rad, rad/s, rad/s^2.

        Returns
        -------
        ndarray or casadi.SX or casadi.MX, shape (3,)
            N m, hub frame.
        """
        symbolic = any(type(v).__module__.startswith("casadi")
                       for v in (angle, rate, acceleration))
        if symbolic:
            import casadi as lib

            cross, times, array = lib.cross, lib.mtimes, lib.DM
        else:
            angle, rate, acceleration = (float(v) for v in (angle, rate, acceleration))
            lib, cross, times, array = np, np.cross, np.matmul, np.asarray
        axis, inertia = array(self.axis), array(self.inertia)
        spin = rate * axis
        if self.momentum is None:
            held = times(inertia, spin)
        else:
            # H in the reference's hub frame: the start's, turned back by theta about the axis
            start = rotation_matrix(self.start).T @ self.momentum
            c, s = lib.cos(angle), lib.sin(angle)
            held = c * array(start) - s * array(np.cross(self.axis, start)) \
                + (1 - c) * float(self.axis @ start) * axis
        return acceleration * times(inertia, axis) + cross(spin, held)


def eigenaxis_shaper(structure, axis, kind: str = "zv", n_shaped: int = 1, n_modes=2):
    """The input shaper of a slew about ``axis``: one ZV or ZVD shaper per mode that a torque
    about ``axis`` moves, the ``n_shaped`` lowest, convolved.

    A torque ``tau a`` about the unit axis ``a`` forces the mass-normalised mode ``j`` of the
    structure at rest by ``phi_j[e] . a`` (its attitude rows): the modes with a force above
    1e-9 of the largest are the ones the slew moves. Their frequencies and damping ratios are
    those of the linear plant's poles (:func:`~flexctl.model.spatial_plant.linearize_spatial`
    at rest), so each appendage's modal damping is counted as the coupled mode carries it.
    Shape the slew's profile with it (:func:`~controllers.slew.shaping.shape`) before making
    the :class:`EigenaxisSlew`.

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    axis : array_like, shape (3,)
        The slew axis, hub frame.
    kind : {"zv", "zvd"}, optional
        The shaper of each mode (:func:`~controllers.slew.shaping.zv_shaper` or
        :func:`~controllers.slew.shaping.zvd_shaper`). Default ``"zv"``.
    n_shaped : int, optional
        How many of the moved modes, from the lowest, are shaped (>= 1). Default 1.
    n_modes : int, sequence of int or mapping, optional
        Modes per field of each appendage in the model the modes are taken from (the forms of
        :func:`~controllers.feedback.spatial_lqr.design_spatial_lqr`). Default 2.

    Returns
    -------
    Shaper
        The convolved impulse train (:func:`eigenaxis_modes` gives the modes it cancels).

    Raises
    ------
    InputValueError
        When fewer than ``n_shaped`` modes move under a torque about ``axis`` in that model.
    """
    from .shaping import convolve, zv_shaper, zvd_shaper

    makers = {"zv": zv_shaper, "zvd": zvd_shaper}
    if not isinstance(kind, str) or kind not in makers:
        raise InputValueError(f"eigenaxis_shaper.kind must be 'zv' or 'zvd'; got {kind!r:.80}")
    modes = eigenaxis_modes(structure, axis, n_shaped, n_modes)
    shaper = None
    for frequency, damping in modes:
        one = makers[kind](frequency, damping)
        shaper = one if shaper is None else convolve(shaper, one)
    return shaper


def eigenaxis_modes(structure, axis, n_shaped: int = 1, n_modes=2) -> tuple:
    """``(frequency, damping ratio)`` of the ``n_shaped`` lowest modes a torque about
    ``axis`` moves (rad/s; see :func:`eigenaxis_shaper`).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    axis : array_like, shape (3,)
        The slew axis, hub frame.
    n_shaped : int, optional
        How many modes (>= 1). Default 1.
    n_modes : int, sequence of int or mapping, optional
        Modes per field of each appendage in the model. Default 2.

    Returns
    -------
    tuple of (float, float)
        By ascending frequency.
    """
    from flexctl.model.checks import check_integer
    from flexctl.model.spatial_plant import linearize_spatial
    from flexctl.model.spatial_visibility import spatial_modal_visibility

    axis = check_direction("eigenaxis_shaper", "axis", axis)
    n_shaped = check_integer("eigenaxis_shaper", "n_shaped", n_shaped, minimum=1)
    report = spatial_modal_visibility(structure, n_modes)
    rows = [report.coordinates.index(name) for name in ("ex", "ey", "ez")]
    force = np.abs(report.shapes[rows, :].T @ axis)
    flexible = report.frequencies > 0.0
    largest = float(np.max(force[flexible], initial=0.0))
    moved = [j for j in np.flatnonzero(flexible) if force[j] > 1e-9 * largest]
    if len(moved) < n_shaped:
        raise InputValueError(
            f"eigenaxis_shaper.n_shaped must be at most {len(moved)}: a torque about "
            f"{np.round(axis, 6).tolist()} moves {len(moved)} modes of the model "
            f"({', '.join(f'{report.frequencies[j]:.4g}' for j in moved)} rad/s); got "
            f"{n_shaped} (more modes per field in the model give more)")
    poles = np.linalg.eigvals(linearize_spatial(structure, n_modes).A)
    poles = poles[poles.imag > 0.0]
    out = []
    for j in moved[:n_shaped]:
        pole = poles[np.argmin(np.abs(np.abs(poles) - report.frequencies[j]))]
        out.append((float(abs(pole)), float(max(-pole.real / abs(pole), 0.0))))
    return tuple(out)
