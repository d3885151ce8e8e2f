"""The common part of the feedback laws that track a hub reference.

PD (:mod:`controllers.feedback.pd`), LQR (:mod:`controllers.feedback.lqr`), gain-scheduled LQR
(:mod:`controllers.feedback.scheduling`) and LQG (:mod:`controllers.feedback.lqg`) all apply

``torque = feedback(t, x) + J acc_ref(t)``, clipped to ``[-torque_limit, torque_limit]``,

where ``feedback`` is the law's own (a PD on the hub, a gain on the design state's deviation
from the reference state), ``acc_ref`` the reference's hub acceleration and ``J`` the
feedforward inertia (normally the rigid inertia ``J0``). :class:`ReferenceFeedback` owns the
three settings this shares (``reference``, ``feedforward_inertia``, ``torque_limit``): their
validation, the breakpoints they give the integrator, and the feedforward and saturation in
numpy and CasADi.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from flexctl.model.errors import InputValueError

from ..design.plant_state import casadi_hub_state, design_rows, hub_state
from ..slew.reference import casadi_saturate, check_reference, has_casadi, optional_positive, \
    saturate

__all__ = ["ReferenceFeedback", "ReferenceSaturationWarning", "warn_if_reference_saturates"]


class ReferenceSaturationWarning(UserWarning):
    """A reference whose feedforward alone asks more than the torque limit gives."""


def warn_if_reference_saturates(owner: str, reference, inertia, torque_limit) -> float | None:
    """Warn when the feedforward ``J acc_ref`` of ``reference`` exceeds ``torque_limit``.

    Parameters
    ----------
    owner : str
        The law's name in the message.
    reference : object
        A hub reference with ``peak_acceleration`` (rad/s^2), e.g. a
        :class:`~controllers.slew.reference.SlewProfile`; anything else is not checked.
    inertia, torque_limit : float or None
        Feedforward inertia (kg m^2) and saturation (N m); either None: nothing to check.

    Returns
    -------
    float or None
        The feedforward's peak, N m, when checked.
    """
    peak = getattr(reference, "peak_acceleration", None)
    if peak is None or inertia is None or torque_limit is None:
        return None
    needed = float(inertia) * float(peak)
    if needed > torque_limit * (1.0 + 1e-9):
        from ..slew.reference import minimum_slew_duration

        shortest = minimum_slew_duration(reference.slew_angle, inertia, torque_limit,
                                         reference.shape)
        warnings.warn(
            f"{owner}: the reference slew of {reference.slew_angle:.6g} rad in "
            f"{reference.duration:.6g} s needs {needed:.3g} N m of feedforward "
            f"({inertia:.6g} kg m^2 times its peak acceleration {peak:.4g} rad/s^2), more "
            f"than torque_limit = {torque_limit:.6g} N m: the torque saturates and the hub "
            f"lags the reference; at this limit the slew needs at least {shortest:.4g} s "
            "(controllers.minimum_slew_duration)", ReferenceSaturationWarning, stacklevel=4)
    return needed


@dataclass(frozen=True, kw_only=True, eq=False)
class ReferenceFeedback:
    """Base of the laws that track a hub reference with feedforward and saturation.

    A static law (``n_states = 0``) unless a subclass overrides :attr:`n_states`,
    :meth:`initial_state` and :meth:`derivative`.

    Parameters
    ----------
    reference : object, optional
        Hub reference with ``angle(t)``, ``rate(t)``, ``acceleration(t)`` (rad, rad/s,
        rad/s^2), e.g. :class:`~controllers.slew.reference.SlewProfile`. Default: regulate to 0.
    feedforward_inertia : float, optional
        ``J`` of the feedforward term ``J acc_ref``, kg m^2 (> 0). Default: no feedforward.
    torque_limit : float, optional
        Saturation of the total torque, N m (> 0). Default: none.
    plant_layout : StateLayout, optional
        The plant state's layout, set by :meth:`for_plant` (:func:`flexctl.simulate` binds
        every law to its plant). Default None: a bare state read with the design's blocks.
    """

    reference: object = None
    feedforward_inertia: float | None = None
    torque_limit: float | None = None
    #: The plant state's layout, set by :meth:`for_plant` (``flexctl.simulate`` binds every
    #: law to its plant); ``None``: a bare state read with the design's blocks.
    plant_layout: object = None

    #: The law's name in error messages (``"pd"``, ``"lqr"``, ...).
    owner: ClassVar[str] = "controller"
    n_states = 0

    def __post_init__(self):
        object.__setattr__(self, "reference", check_reference(self.owner, self.reference))
        object.__setattr__(self, "feedforward_inertia", optional_positive(
            self.owner, "feedforward_inertia", self.feedforward_inertia))
        object.__setattr__(self, "torque_limit", optional_positive(
            self.owner, "torque_limit", self.torque_limit))
        if self.plant_layout is None:       # once, at design (for_plant rebinds it)
            warn_if_reference_saturates(self.owner, self.reference, self.feedforward_inertia,
                                        self.torque_limit)

    def for_plant(self, model):
        """The same law reading the states of plant ``model`` (its ``model.layout``): needed
        for a plant of several appendages, whose mode counts a bare state does not tell.

        Parameters
        ----------
        model : flexctl.Model
            The plant the law runs on (any number of modes, an actuated one included).
        """
        from dataclasses import replace
        return replace(self, plant_layout=model.layout)

    def _plant_rows(self, design, x_size: int):
        """Indices of the ``design`` layout's state in a plant state of ``x_size`` entries
        (through :attr:`plant_layout` when bound), or None to read it as a bare state."""
        plant = self.plant_layout
        if plant is None or plant.n_states != x_size:
            return None
        return plant.projection(design)

    def _design_state(self, x):
        """The design state (layout ``self.layout``) of numpy plant state ``x``."""
        x = np.asarray(x, dtype=float)
        rows = self._plant_rows(self.layout, x.size)
        if rows is None:
            if x.ndim != 1:
                raise InputValueError(f"{self.owner}: the plant state must be a vector; got "
                                      f"shape {x.shape}")
            rows = design_rows(self.layout, x.size)
        return x[rows]

    def _hub_state(self, x) -> tuple:
        """Hub angle (rad) and rate (rad/s) of numpy plant state ``x``: by
        :attr:`plant_layout` when bound (its actuator's states follow the structure's), else as
        one beam's state of its size."""
        plant = self.plant_layout
        if plant is not None and np.ndim(x) == 1 and plant.n_states == np.size(x):
            x = np.asarray(x, dtype=float)
            return float(plant.hub_angle(x)), float(plant.hub_rate(x))
        return hub_state(x)

    def _casadi_hub_state(self, x) -> tuple:
        """``_hub_state`` of a CasADi plant state."""
        plant = self.plant_layout
        if plant is not None and plant.n_states == x.numel():
            return plant.hub_angle(x), plant.hub_rate(x)
        return casadi_hub_state(x)

    def _casadi_design_state(self, x):
        """The design state of a CasADi plant state."""
        rows = self._plant_rows(self.layout, x.numel())
        return x[(design_rows(self.layout, x.numel()) if rows is None else rows).tolist()]

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the reference is not smooth."""
        return tuple(getattr(self.reference, "breakpoints", ()) or ())

    @property
    def has_casadi_form(self) -> bool:
        """True when the reference (if any) has a CasADi form (``casadi_reference``)."""
        return has_casadi(self.reference)

    def initial_state(self, x0) -> np.ndarray:
        """No internal state: shape (0,).

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Initial plant state (not read).
        """
        return np.zeros(0)

    def derivative(self, t: float, x, z=None) -> np.ndarray:
        """No internal state: shape (0,).

        Parameters
        ----------
        t : float
            Time, s (not read).
        x : array_like, shape (n,)
            Plant state (not read).
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        return np.zeros(0)

    def _apply(self, feedback: float, acceleration: float) -> float:
        """``feedback + J acc_ref``, saturated, N m."""
        if self.feedforward_inertia is not None:
            feedback += self.feedforward_inertia * acceleration
        return saturate(feedback, self.torque_limit)

    def _casadi_apply(self, feedback, acceleration, inertia=None, limit=None):
        """``_apply`` on CasADi expressions; ``inertia`` and ``limit`` replace the
        settings' numbers (e.g. by parameter symbols) where given, and are ignored where the
        setting is off."""
        if self.feedforward_inertia is not None:
            feedback += (self.feedforward_inertia if inertia is None else inertia) \
                * acceleration
        if self.torque_limit is None:
            return feedback
        return casadi_saturate(feedback, self.torque_limit if limit is None else limit)
