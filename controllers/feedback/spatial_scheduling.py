"""Gain scheduling over the spin of a spacecraft in three axes.

A spacecraft spinning at ``Omega`` about a principal axis ``a`` (perpendicular to or along
every appendage, so that the straight structure turning steadily is an equilibrium) is a
different linear plant at every ``Omega``: its rigid axes across the spin are coupled gyroscopically
(nutation), each array's bending is stiffened by the centrifugal load and coupled across its
planes by Coriolis forces. :func:`design_scheduled_spatial_lqr` solves one three-axis LQR
(:func:`~controllers.feedback.spatial_lqr.spatial_lq_gain`) per design spin on
:func:`~flexctl.model.spatial_plant.linearize_spatial` about ``w_0 = Omega a``;
:class:`ScheduledSpatialLQR` interpolates the gains linearly in the measured spin rate
``a . w`` (the end gains held outside the designed range) and follows a spin about ``a``:

- the reference ``q_ref(t) = q_0 (x) exp(theta(t) a / 2)``, ``w_ref = Omega(t) a`` of a
  ``profile`` (its ``angle``, ``rate`` and ``acceleration``: a
  :class:`~flexctl.sim.maneuvers.SpinUp`, a :class:`~controllers.slew.reference.SlewProfile`,
  ...) or of a steady spin at a rate;
- the design state of the linearisation about the spinning reference: the attitude error
  ``e``, the rotation vector of ``q_ref^-1 (x) q`` (hub frame; any number of turns, as the
  reference turns with the craft), the modal coordinates, ``w - w_ref`` and the modal rates;
- the command ``u = J alpha a + w_ref x J w_ref - K(a . w) x_design``, clipped per axis
  (``J`` the rigid inertia: the feedforward of the rigid spin-up).

The law reads the plant's whole state (``state_feedback``), as
:class:`~controllers.feedback.spatial_lqr.SpatialLQR` does.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import (KeywordOnly, check_array, check_direction, check_instance,
                                  check_quaternion, check_real)
from flexctl.model.errors import InputValueError
from flexctl.sim.quaternions import error_angles, from_rotation_vector, product

from ..design.controllable import held
from ..design.plant_state import spatial_design_plant
from ..design.stability import LoopStabilityWarning
from ..slew.reference import check_reference, evaluate_reference
from .lqr import LQRWeights
from .spatial_lqr import fed_back_rows, spatial_lq_gain, state_reader

__all__ = ["ScheduledSpatialLQR", "SteadySpin", "design_scheduled_spatial_lqr",
           "GROWTH_TOLERANCE"]

#: Largest real part of a loop pole (1/s) taken as not growing: the parts of the plant the
#: torque does not move keep their undamped poles, on the axis to round-off.
GROWTH_TOLERANCE = 1e-6


@dataclass(frozen=True, kw_only=True)
class SteadySpin(KeywordOnly):
    """A spin at a constant rate, ``theta(t) = spin_rate t``.

    Parameters
    ----------
    spin_rate : float
        Spin rate, rad/s (finite, at most 1e4 in magnitude).
    """

    spin_rate: float

    def __post_init__(self):
        object.__setattr__(self, "spin_rate", check_real(
            "steady_spin", "spin_rate", self.spin_rate, minimum=-1e4, maximum=1e4))

    def angle(self, t):
        """``spin_rate t``, rad, shaped as ``t``.

        Parameters
        ----------
        t : float or ndarray
            Time, s.
        """
        return self.spin_rate * np.asarray(t, dtype=float)

    def rate(self, t):
        """``spin_rate``, rad/s, shaped as ``t``.

        Parameters
        ----------
        t : float or ndarray
            Time, s.
        """
        return self.spin_rate + 0.0 * np.asarray(t, dtype=float)

    def acceleration(self, t):
        """Zero, rad/s^2, shaped as ``t``.

        Parameters
        ----------
        t : float or ndarray
            Time, s.
        """
        return 0.0 * np.asarray(t, dtype=float)

    def casadi_reference(self, t):
        """Angle, rate and acceleration as CasADi expressions of the symbol ``t``.

        Parameters
        ----------
        t : casadi.SX or casadi.MX
            Scalar time, s.

        Returns
        -------
        tuple
            rad, rad/s, rad/s^2.
        """
        return self.spin_rate * t, self.spin_rate + 0.0 * t, 0.0 * t


@dataclass(frozen=True, eq=False)
class ScheduledSpatialLQR:
    """The scheduled three-axis LQR (module description); made by
    :func:`design_scheduled_spatial_lqr`.

    Attributes
    ----------
    spin_axis : ndarray, shape (3,)
        The spin axis ``a``, hub frame (unit).
    spin_rates : ndarray, shape (S,)
        The design spins, rad/s, increasing.
    gains : ndarray, shape (S, 3, n)
        The gain at each design spin on the design state.
    plants : tuple of control.StateSpace
        The plant linearised about each design spin.
    poles : tuple of ndarray
        The closed-loop poles of each design (1/s; a held design's ``log(z) / T``).
    state_names : tuple of str
        The design state's names (``ex, ey, ez``, then the spatial model's own).
    profile : object
        The spin followed: ``angle(t)``, ``rate(t)``, ``acceleration(t)`` about the axis.
    start_attitude : ndarray, shape (4,)
        The reference's attitude at ``theta = 0``, hub to inertial, scalar first.
    inertia : ndarray, shape (3, 3)
        The rigid inertia of the feedforward, kg m^2.
    sample_time : float or None
        The hold of the designs, s (None: continuous).
    torque_limit : float or None
        Per-axis saturation, N m.
    structure : SpatialStructure
        The structure designed for.
    n_modes : int, sequence of int or mapping
        The design modes per field.
    variant : str
        The model linearised.
    between : tuple of (float, float)
        ``(spin, growth)`` halfway between each pair of design spins: the largest real part
        of :meth:`loop_poles` there (1/s), how the interpolated gain holds the loop.
    """

    spin_axis: np.ndarray
    spin_rates: np.ndarray
    gains: np.ndarray
    plants: tuple
    poles: tuple
    state_names: tuple
    profile: object
    start_attitude: np.ndarray
    inertia: np.ndarray
    sample_time: float | None
    torque_limit: float | None
    structure: object
    n_modes: object
    variant: str
    between: tuple = ()

    #: The loop hands this law the plant's whole state.
    state_feedback = True

    def gain_at(self, spin: float) -> np.ndarray:
        """``K(spin)``: the gains interpolated linearly at the spin rate ``spin`` (rad/s), the
        end gains outside the designed range.

        Parameters
        ----------
        spin : float
            The spin rate ``a . w``, rad/s.

        Returns
        -------
        ndarray, shape (3, n)
        """
        spin = check_real("gain_at", "spin", spin, minimum=-1e4, maximum=1e4)
        rates = self.spin_rates
        if rates.size == 1 or spin <= rates[0]:
            return self.gains[0]
        if spin >= rates[-1]:
            return self.gains[-1]
        k = int(np.searchsorted(rates, spin)) - 1
        weight = (spin - rates[k]) / (rates[k + 1] - rates[k])
        return (1.0 - weight) * self.gains[k] + weight * self.gains[k + 1]

    def reference_at(self, t: float) -> tuple:
        """The spin followed at ``t``.

        Parameters
        ----------
        t : float
            Time, s.

        Returns
        -------
        tuple
            ``(q_ref, w_ref, torque)``: attitude (4,), rate (3,, rad/s, hub frame) and the
            feedforward torque (3,, N m, hub frame).
        """
        angle, rate, acceleration = evaluate_reference(self.profile, float(t))
        axis = self.spin_axis
        attitude = product(self.start_attitude, from_rotation_vector(angle * axis))
        spin = rate * axis
        torque = acceleration * (self.inertia @ axis) + np.cross(spin, self.inertia @ spin)
        return attitude, spin, torque

    def command(self, t: float, attitude, rest) -> np.ndarray:
        """The command for the attitude and the rest of the design state (absolute rates).

        Parameters
        ----------
        t : float
            Time, s.
        attitude : array_like, shape (4,)
            Attitude, hub to inertial, scalar first.
        rest : array_like, shape (n - 3,)
            The plant's entries named :attr:`state_names` after ``ez``, its rates ``wx wy
            wz`` as they are (not less the reference's).

        Returns
        -------
        ndarray, shape (3,)
            Torque, N m, hub frame.
        """
        q_ref, spin, torque = self.reference_at(t)
        rest = np.array(rest, dtype=float)
        at = self.rate_at - 3
        rate = rest[at:at + 3].copy()
        rest[at:at + 3] -= spin
        design = np.concatenate([error_angles(q_ref, attitude), rest])
        command = torque - self.gain_at(float(self.spin_axis @ rate)) @ design
        if self.torque_limit is None:
            return command
        return np.clip(command, -self.torque_limit, self.torque_limit)

    @property
    def rate_at(self) -> int:
        """Where ``wx wy wz`` start in the design state."""
        return self.state_names.index("wx", 3)

    def start(self, state_names=None):
        """A session on a plant whose states are ``state_names`` (as
        :meth:`SpatialLQR.start <controllers.feedback.spatial_lqr.SpatialLQR.start>`).

        Parameters
        ----------
        state_names : sequence of str, optional
            The flown plant's state names; default the design model's.

        Returns
        -------
        callable
            ``session(t, attitude, rate, state) -> torque`` (N m, hub frame).
        """
        rows = fed_back_rows(self.state_names[3:], state_names)

        def session(t, attitude, rate, state):
            x = np.asarray(state, dtype=float)
            return self.command(t, attitude, x[3:] if rows is None else x[rows])
        return session

    def plant_at(self, spin: float):
        """The design model linearised about the spin ``spin`` about :attr:`spin_axis`.

        Parameters
        ----------
        spin : float
            Spin rate about :attr:`spin_axis`, rad/s.

        Returns
        -------
        control.StateSpace
        """
        spin = check_real("plant_at", "spin", spin, minimum=-1e4, maximum=1e4)
        k = np.flatnonzero(self.spin_rates == spin)
        if k.size:
            return self.plants[int(k[0])]
        plant, _ = spatial_design_plant("loop_poles", self.structure, self.n_modes,
                                        self.variant, angular_velocity=spin * self.spin_axis)
        return plant

    def broken_loop(self, plant, spin: float) -> tuple:
        """``(A, B, C)`` of the loop the gain ``K(spin)`` closes around ``plant``, broken at
        its torque inputs, in negative feedback (``L = C (sI - A)^-1 B``, or ``(zI - A)^-1``
        of the plant held over :attr:`sample_time`): what
        :func:`controllers.analysis.spatial_loops.lq_loop` hands python-control.

        Parameters
        ----------
        plant : control.StateSpace
            A plant of :func:`~flexctl.model.spatial_plant.linearize_spatial` of the
            structure linearised about the spin ``spin`` about :attr:`spin_axis`, with at
            least the design's modes (those beyond it are neither read nor fed back).
        spin : float
            The spin rate, rad/s, the gain is interpolated at.

        Returns
        -------
        tuple of ndarray
        """
        gain = self.gain_at(float(spin)) @ state_reader(self.state_names, plant)
        if self.sample_time is None:
            return plant.A, plant.B, gain
        a_d, b_d = held(plant.A, plant.B, self.sample_time)
        return a_d, b_d, gain

    def loop_poles(self, spin: float) -> np.ndarray:
        """Poles of the loop the interpolated gain ``K(spin)`` closes around the design model
        linearised about ``spin`` (1/s; held: ``log(z) / T``): between the design spins,
        how the schedule holds; on one, that design's whole loop (the parts its torque does
        not move at their open-loop poles).

        Parameters
        ----------
        spin : float
            Spin rate about :attr:`spin_axis`, rad/s.

        Returns
        -------
        ndarray
        """
        plant = self.plant_at(float(spin))
        gain = self.gain_at(float(spin))
        a, b = plant.A, plant.B
        if self.sample_time is None:
            return np.linalg.eigvals(a - b @ gain)
        a_d, b_d = held(a, b, self.sample_time)
        z = np.linalg.eigvals(a_d - b_d @ gain).astype(complex)
        return np.log(np.where(z == 0, 1e-300, z)) / self.sample_time


def _profile(owner: str, profile):
    if isinstance(profile, (int, float, np.floating, np.integer)) \
            and not isinstance(profile, bool):
        return SteadySpin(spin_rate=float(profile))
    try:
        check_reference(owner, profile)
    except (TypeError, ValueError) as exc:
        raise type(exc)(str(exc).replace(f"{owner}.reference", f"{owner}.profile")) from None
    return profile


def design_scheduled_spatial_lqr(structure, weights: LQRWeights, spin_axis, spin_rates,
                                 profile, *, start=(1.0, 0.0, 0.0, 0.0), n_modes=2,
                                 variant: str = "exact", sample_time: float | None = None,
                                 torque_limit: float | None = None,
                                 max_frequency: float | None = None) -> ScheduledSpatialLQR:
    """One three-axis LQR per design spin, scheduled on the spin rate (module description).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    weights : LQRWeights
        The same Bryson weights at every spin
        (:func:`~controllers.feedback.spatial_lqr.spatial_weight_matrices`).
    spin_axis : array_like, shape (3,)
        The spin axis, hub frame: a principal axis of the structure perpendicular to or along
        every appendage (normalised here).
    spin_rates : array_like, shape (S,)
        Design spins about it, rad/s, strictly increasing (either sign).
    profile : object or float
        The spin to follow: ``angle(t)``, ``rate(t)``, ``acceleration(t)`` about the axis
        (rad, rad/s, rad/s^2; a :class:`~flexctl.sim.maneuvers.SpinUp` for example), a
        :class:`SteadySpin`, or a number: a steady spin at that rate (rad/s).
    start : array_like, shape (4,), optional
        The reference's attitude at ``theta = 0``, hub to inertial, scalar first. Default the
        identity.
    n_modes : int, sequence of int or mapping, optional
        Design modes per field. Default 2.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model linearised (they differ about a spin: use the one flown). Default
        ``"exact"``.
    sample_time : float, optional
        The loop's hold, s (the discrete LQR of each held plant). Default: continuous.
    torque_limit : float, optional
        Per-axis saturation, N m.
    max_frequency : float, optional
        Modes faster than this are left out of every design (rad/s), as in
        :func:`~controllers.feedback.spatial_lqr.design_spatial_lqr`.

    Returns
    -------
    ScheduledSpatialLQR

    Warns
    -----
    LoopStabilityWarning
        When halfway between two design spins the interpolated gain leaves the loop on the
        plant linearised there with a pole growing faster than :data:`GROWTH_TOLERANCE`
        (:attr:`ScheduledSpatialLQR.between`): more design spins are needed there.

    Raises
    ------
    InputValueError
        If a design spin about the axis is no steady turn of the straight structure (the
        axis is not principal, or not perpendicular to an appendage), or a design fails.
    """
    owner = "design_scheduled_spatial_lqr"
    check_instance(owner, "weights", weights, LQRWeights)
    axis = check_direction(owner, "spin_axis", spin_axis)
    rates = np.array(check_array(owner, "spin_rates", spin_rates), dtype=float)
    if rates.ndim > 1:
        raise InputValueError(f"{owner}.spin_rates must be a sequence of spin rates (rad/s); "
                              f"got an array of shape {rates.shape}")
    rates = rates.reshape(-1)
    if rates.size < 1 or rates.size > 50 or np.any(np.diff(rates) <= 0) \
            or np.max(np.abs(rates)) > 1e4:
        raise InputValueError(f"{owner}.spin_rates must be 1 to 50 strictly increasing spin "
                              f"rates within 1e4 rad/s; got {spin_rates!r:.80}")
    profile = _profile(owner, profile)
    start = check_quaternion(owner, "start", start)
    if sample_time is not None:
        sample_time = check_real(owner, "sample_time", sample_time, minimum=1e-6,
                                 strict=True, maximum=100.0)
    if torque_limit is not None:
        torque_limit = check_real(owner, "torque_limit", torque_limit, minimum=0.0,
                                  strict=True, maximum=1e9)
    gains, plants, poles, names = [], [], [], None
    for rate in rates:
        try:
            plant, names = spatial_design_plant(owner, structure, n_modes, variant,
                                                angular_velocity=rate * axis)
        except InputValueError as exc:
            if "steady turn" not in str(exc):
                raise
            raise InputValueError(f"{owner}: the design spin {rate:g} rad/s about "
                                  f"{np.round(axis, 6).tolist()}: {exc}") from None
        gain, closed, _ = spatial_lq_gain(owner, structure, plant, weights,
                                          sample_time=sample_time, max_frequency=max_frequency)
        gains.append(gain)
        plants.append(plant)
        poles.append(closed)
    inertia = np.array(structure.rigid_inertia, dtype=float)
    inertia.setflags(write=False)
    stacked = np.array(gains)
    stacked.setflags(write=False)
    rates.setflags(write=False)
    law = ScheduledSpatialLQR(spin_axis=axis, spin_rates=rates, gains=stacked,
                              plants=tuple(plants), poles=tuple(poles),
                              state_names=tuple(names), profile=profile,
                              start_attitude=start, inertia=inertia, sample_time=sample_time,
                              torque_limit=torque_limit, structure=structure,
                              n_modes=n_modes, variant=variant)
    between = tuple((float(m), float(np.max(law.loop_poles(m).real)))
                    for m in 0.5 * (rates[1:] + rates[:-1]))
    growing = [(m, g) for m, g in between if g > GROWTH_TOLERANCE]
    if growing:
        spin, growth = max(growing, key=lambda item: item[1])
        warnings.warn(
            f"{owner}: halfway between design spins the interpolated gain leaves the loop "
            f"unstable: at {spin:g} rad/s a pole grows at {growth:.3g} 1/s (doubling in "
            f"{np.log(2) / growth:.3g} s); design more spins there", LoopStabilityWarning,
            stacklevel=2)
    return dataclasses.replace(law, between=between)
