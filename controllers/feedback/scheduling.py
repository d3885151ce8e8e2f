"""Gain scheduling on the spin rate: LQR gains designed at several steady spins, interpolated.

The beam stiffness of a spinning hub is ``K_ff - Omega^2 D`` (:ref:`section 4 of the model
<variants>`), so the plant linearised about a steady spin changes with ``Omega``.
:func:`design_scheduled_lqr` solves one LQR per design spin rate with
:func:`controllers.feedback.lqr.design_lqr`; :class:`ScheduledLQR` then interpolates the gains
linearly in the measured hub rate.

Notes
-----
The linearisation depends on ``Omega`` only through ``Omega^2`` (there is no Coriolis coupling
in the planar model), so the gains are scheduled on ``|theta_dot|`` and the design spin rates
are ``>= 0``. Outside the designed range the end gains are held. States and the torque law are
those of :mod:`controllers.feedback.lqr` with ``K = K(|theta_dot|)``.

Examples
--------
>>> import flexctl
>>> from controllers.feedback.lqr import LQRWeights
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> sched = design_scheduled_lqr(model, LQRWeights(hub_angle=0.1, hub_rate=0.02, torque=2.0),
...                              spin_rates=[0.0, 1.0, 2.0])
>>> sched.gains.shape
(3, 6)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexctl.model.checks import check_array, check_real
from flexctl.model.errors import InputValueError
from flexctl.model.layout import StateLayout

from ..design.controllable import design_failure
from .reference_feedback import ReferenceFeedback
from .lqr import (LQRWeights, gain_layout, lqr_gain, checked_model, casadi_reference_state,
                  casadi_truncate_state, checked_on, reference_state, static_deflection_gain,
                  truncate_state, truncation_matrix)

__all__ = ["ScheduledLQR", "design_scheduled_lqr"]


def _spin_rates(owner: str, spin_rates) -> np.ndarray:
    rates = check_array(owner, "spin_rates", spin_rates, finite=False).reshape(-1).copy()
    if rates.size < 1 or not np.all(np.isfinite(rates)) or np.any(rates < 0) \
            or np.any(np.diff(rates) <= 0):
        raise InputValueError(f"{owner}.spin_rates must be finite, >= 0 and strictly increasing "
                              f"(rad/s); got {spin_rates!r}")
    return rates


@dataclass(frozen=True, kw_only=True, eq=False)
class ScheduledLQR(ReferenceFeedback):
    """LQR whose gain is interpolated in ``|theta_dot|`` (a :class:`flexctl.Controller`).

    Build with :func:`design_scheduled_lqr`.

    Parameters
    ----------
    reference : object, optional
        Hub reference with ``angle``, ``rate``, ``acceleration`` (e.g. a
        :class:`~controllers.slew.reference.SlewProfile`). Default: regulate to 0.
    feedforward_inertia : float, optional
        ``J`` of the feedforward term, kg m^2 (> 0). Default none.
    torque_limit : float, optional
        Saturation, N m (> 0). Default none.
    plant_layout : StateLayout, optional
        The plant state's layout, set by :meth:`for_plant`. Default None.
    spin_rates : array_like, shape (S,)
        Design spin rates, rad/s, ``>= 0`` and strictly increasing.
    gains : array_like, shape (S, 2 M + 2)
        LQR gain at each design spin rate.
    deflection_gain : ndarray, shape (M,), optional
        Track the quasi-static beam deflection of the reference
        (:func:`~controllers.feedback.lqr.reference_state`); default a rigid reference.
    layout : StateLayout, optional
        The design state's layout; default one appendage of ``M`` modes on a pinned hub.
    """

    spin_rates: np.ndarray
    gains: np.ndarray
    deflection_gain: np.ndarray | None = None
    layout: StateLayout | None = field(default=None, repr=False)

    owner = "scheduled_lqr"

    def __post_init__(self):
        rates = _spin_rates("scheduled_lqr", self.spin_rates)
        gains = check_array("scheduled_lqr", "gains", self.gains, finite=False).copy()
        if gains.ndim != 2 or gains.shape[0] != rates.size or gains.shape[1] < 2 \
                or gains.shape[1] % 2 or not np.all(np.isfinite(gains)):
            raise InputValueError(f"scheduled_lqr.gains must be finite with shape ({rates.size}, "
                                  f"2 M + 2); got shape {gains.shape}")
        for name, value in (("spin_rates", rates), ("gains", gains)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "layout",
                           gain_layout("scheduled_lqr", self.layout, gains.shape[1]))
        super().__post_init__()

    @property
    def n_modes(self) -> int:
        """Design modes ``M``."""
        return self.layout.n_modes

    def gain_at(self, spin_rate: float) -> np.ndarray:
        """Interpolated gain at hub rate ``spin_rate``, shape (1, 2M+2): linear in
        ``|spin_rate|`` between the design spin rates, the end gains held beyond them.

        Parameters
        ----------
        spin_rate : float
            Hub rate, rad/s (either sign).
        """
        w = abs(check_real("scheduled_lqr", "spin_rate", spin_rate))
        rates = self.spin_rates
        if rates.size == 1 or w <= rates[0]:
            return self.gains[:1].copy()
        if w >= rates[-1]:
            return self.gains[-1:].copy()
        k = int(np.searchsorted(rates, w, side="right")) - 1
        frac = (w - rates[k]) / (rates[k + 1] - rates[k])
        return ((1.0 - frac) * self.gains[k] + frac * self.gains[k + 1])[None, :]

    def state_gain(self, n_modes, spin_rate: float = 0.0) -> np.ndarray:
        """Gain at ``spin_rate`` on a plant state with ``n_modes`` modes (or of that layout),
        shape (1, 2N+2).

        Parameters
        ----------
        n_modes : int or StateLayout
            ``N >= M``, the plant's modes, or the plant state's layout.
        spin_rate : float, optional
            Hub rate the gain is interpolated at, rad/s (either sign). Default 0.
        """
        return self.gain_at(spin_rate) @ truncation_matrix(n_modes, self.layout)

    def plant_gain(self, plant, spin_rate: float = 0.0) -> np.ndarray:
        """The gain at ``spin_rate`` on ``plant``'s state, shape (1, n).

        Parameters
        ----------
        plant : flexctl.Model
            The plant, with at least the design's modes in each appendage.
        spin_rate : float, optional
            Hub rate the gain is interpolated at, rad/s (either sign). Default 0.
        """
        return self.state_gain(plant.layout, spin_rate)

    def torque(self, t: float, x, z=None) -> float:
        """Hub torque, N m, with the gain at the measured ``|theta_dot|``.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state (``N >= M`` modes), in the order of the plant's layout.
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        x_design = self._design_state(x)
        x_ref, acc = reference_state(self.reference, t, self.layout, self.deflection_gain)
        gain = self.gain_at(self.layout.hub_rate(x_design))
        return self._apply(-float(gain[0] @ (x_design - x_ref)), acc)

    def casadi_gain_at(self, spin_rate):
        """:meth:`gain_at` of a CasADi hub rate: the gains as a list of 2 M + 2 expressions.

        Parameters
        ----------
        spin_rate : casadi.SX or casadi.MX
            Hub rate, rad/s (either sign).
        """
        import casadi as ca

        w, rates, gains = ca.fabs(spin_rate), self.spin_rates, self.gains
        gain = ca.DM(gains[-1])
        # from the top down, so that each bracket overrides the ones above it
        for k in range(rates.size - 2, -1, -1):
            frac = (w - rates[k]) / (rates[k + 1] - rates[k])
            gain = ca.if_else(w < rates[k + 1], (1.0 - frac) * ca.DM(gains[k])
                              + frac * ca.DM(gains[k + 1]), gain)
        return ca.if_else(w <= rates[0], ca.DM(gains[0]), gain)

    def casadi_torque(self, t, x):
        """:meth:`torque` as a CasADi expression of the symbols ``t`` and ``x``.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state, in the order of the plant's layout.
        """
        import casadi as ca

        x_design = self._casadi_design_state(x)
        x_ref, acc = casadi_reference_state(self.reference, t, self.layout,
                                            self.deflection_gain)
        gain = self.casadi_gain_at(self.layout.hub_rate(x_design))
        return self._casadi_apply(-ca.dot(gain, x_design - x_ref), acc)


def _scheduled_gain(model, weights: LQRWeights, spin_rate: float) -> np.ndarray:
    """The LQR gain of the schedule at ``spin_rate`` (rad/s), shape (1, n)."""
    with design_failure("scheduled lqr", "design_scheduled_lqr", model, spin_rate,
                        weights=weights):
        return lqr_gain(model, weights, spin_rate)[0]


def design_scheduled_lqr(model, weights: LQRWeights, spin_rates, *, reference=None,
                         feedforward: bool = True, torque_limit: float | None = None,
                         flexible_reference: bool = True, plant=None) -> ScheduledLQR:
    """One LQR per spin rate on ``model.linearize(spin_rate)``, scheduled on ``|theta_dot|``.

    Parameters
    ----------
    model : flexctl.Model
        Design model (``M`` modes).
    weights : LQRWeights
        The same weights at every spin rate.
    spin_rates : array_like, shape (S,)
        Design spin rates, rad/s, ``>= 0``, strictly increasing; the gain at each equals
        ``design_lqr(model, weights, spin_rate).gain``.
    reference : object, optional
        Hub reference, as in :func:`controllers.feedback.lqr.design_lqr`.
    feedforward : bool, optional
        Add ``J0 acc_ref``, as in :func:`controllers.feedback.lqr.design_lqr`. Default True.
    torque_limit : float, optional
        Saturation, N m, as in :func:`controllers.feedback.lqr.design_lqr`.
    flexible_reference : bool, optional
        As in :func:`controllers.feedback.lqr.design_lqr`. Default True.
    plant : flexctl.Model, optional
        The plant the law will run on (its own modes and variant): the loop is checked on
        its linearisation at rest (:func:`controllers.design.stability.check_loop`) and an unstable
        or
        nearly unstable loop warns (:class:`~controllers.design.stability.LoopStabilityWarning`).

    Returns
    -------
    ScheduledLQR
    """
    model = checked_model("design_scheduled_lqr", model)
    rates = _spin_rates("design_scheduled_lqr", spin_rates)
    gains = np.vstack([_scheduled_gain(model, weights, float(w)) for w in rates])
    law = ScheduledLQR(spin_rates=rates, gains=gains, reference=reference,
                       feedforward_inertia=float(model.rigid_inertia) if feedforward else None,
                       torque_limit=torque_limit,
                       deflection_gain=(static_deflection_gain(model) if flexible_reference
                                        else None),
                       layout=model.layout)
    return checked_on(law, plant)
