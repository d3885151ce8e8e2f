"""Collocated PD control of the hub angle, with optional reference, feedforward and saturation.

The torque acts on the hub and the law reads only the hub angle and rate (sensor and actuator
collocated), so for positive gains it is passive: it cannot destabilise any flexible mode,
however many the plant has, and it damps every mode that moves the hub.

Examples
--------
>>> import numpy as np
>>> import flexctl
>>> from controllers.feedback.pd import design_pd
>>> from controllers.slew.reference import SlewProfile
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> pd = design_pd(model, bandwidth=3.0, damping_ratio=0.9,
...                reference=SlewProfile(slew_angle=np.pi / 2, duration=2.0))
>>> round(pd.kp / model.matrices.J0, 6), round(pd.kd / model.matrices.J0, 6)
(9.0, 5.4)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import check_integer, check_real
from flexctl.model.layout import StateLayout

from flexctl.model.errors import InputValueError

from ..design.plant_state import checked_rigid_inertia
from .reference_feedback import ReferenceFeedback
from ..slew.reference import casadi_evaluate, evaluate_reference, reference_parameters

__all__ = ["PD", "pd_gains", "design_pd"]


#: Outputs a PD law may read (with their rates): the collocated hub angle, the tip angle
#: ``theta + tip_deflection / (b + l)`` and the tip deflection in the hub frame.
SENSORS = ("theta", "tip_angle", "tip_deflection")


@dataclass(frozen=True, kw_only=True)
class PD(ReferenceFeedback):
    """Collocated PD law on hub angle and rate (a :class:`flexctl.Controller`, no states).

    ``torque = kp (theta_ref - theta) + kd (rate_ref - theta_dot) + J acc_ref``, clipped to
    ``[-torque_limit, torque_limit]``.

    Parameters
    ----------
    reference : object, optional
        Hub reference with ``angle(t)``, ``rate(t)``, ``acceleration(t)`` (rad, rad/s, rad/s^2),
        e.g. :class:`~controllers.slew.reference.SlewProfile`. Default: regulate to 0.
    feedforward_inertia : float, optional
        ``J`` of the feedforward term, kg m^2 (> 0), normally the rigid inertia ``J0``.
        Default: no feedforward.
    torque_limit : float, optional
        Saturation, N m (> 0). Default: none.
    plant_layout : StateLayout, optional
        The plant state's layout, set by :meth:`for_plant` (:func:`flexctl.simulate` binds
        every law to its plant). Default None: the hub read from a bare state.
    kp : float
        Angle gain, N m/rad (> 0).
    kd : float
        Rate gain, N m s/rad (> 0; with ``kd = 0`` the undamped beam would never settle).

    Notes
    -----
    The plant state is ``x = [theta, q_1..q_N, theta_dot, q_1_dot..q_N_dot]`` for any ``N``;
    only ``theta`` and ``theta_dot`` are read (:func:`controllers.design.plant_state.hub_state`).
    """

    kp: float
    kd: float

    owner = "pd"

    def __post_init__(self):
        object.__setattr__(self, "kp", check_real("pd", "kp", self.kp, minimum=0.0, strict=True))
        object.__setattr__(self, "kd", check_real("pd", "kd", self.kd, minimum=0.0, strict=True))
        super().__post_init__()

    def state_gain(self, n_modes) -> np.ndarray:
        """``K`` with ``torque = -K x`` for a plant with ``n_modes`` modes, or of that
        :class:`~flexctl.model.layout.StateLayout` (no reference, no saturation), shape
        (1, n).

        Parameters
        ----------
        n_modes : int or StateLayout
            The plant's modes ``N`` (one beam, ``n = 2 N + 2`` states), or the plant state's
            layout.
        """
        layout = n_modes if isinstance(n_modes, StateLayout) else StateLayout.single(
            check_integer("pd.state_gain", "n_modes", n_modes, minimum=1))
        gain = np.zeros((1, layout.n_states))
        gain[0, layout.theta], gain[0, layout.theta_dot] = self.kp, self.kd
        return gain

    def plant_gain(self, plant, spin_rate: float = 0.0, sensor: str = "theta") -> np.ndarray:
        """``K`` with ``u = -K x`` on ``plant``'s linearisation at ``spin_rate``: ``kp c +
        kd c A`` for the output ``c x`` the law reads (``c B = 0`` for them), shape (1, n).

        Parameters
        ----------
        plant : flexctl.Model
            The plant (its linearisation, output matrix and output names).
        spin_rate : float, optional
            Steady hub rate of the linearisation, rad/s. Default 0.
        sensor : {"theta", "tip_angle", "tip_deflection"}, optional
            The output the law reads in place of the hub angle (:data:`SENSORS`), with its
            rate. Default ``"theta"``.

        Raises
        ------
        InputValueError
            If ``sensor`` is not one of :data:`SENSORS`.
        """
        if sensor not in SENSORS:
            raise InputValueError(f"pd.sensor must be one of {', '.join(SENSORS)}; got "
                                  f"{sensor!r}")
        a, _ = plant.linear_matrices(spin_rate)
        row = plant.output_matrix[plant.output_names.index(sensor)]
        return (self.kp * row + self.kd * (row @ a))[None, :]

    def torque(self, t: float, x, z=None) -> float:
        """Hub torque, N m.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state of any mode count, in the order of the plant's layout; only the hub
            angle and rate are read.
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        theta, rate = self._hub_state(x)
        angle_ref, rate_ref, acc_ref = evaluate_reference(self.reference, t)
        return self._apply(self.kp * (angle_ref - theta) + self.kd * (rate_ref - rate), acc_ref)

    @property
    def casadi_parameters(self) -> tuple:
        """``(structure, values)``: what shapes :meth:`casadi_torque` (the reference, which
        options are on) and its numbers ``[kp, kd, feedforward_inertia, torque_limit,
        reference numbers]`` (0 for an option that is off). Compiled runs of PD laws of one
        structure (a slew of any angle and duration included) share their integrators."""
        reference, numbers = reference_parameters(self.reference)
        structure = (reference, self.feedforward_inertia is None, self.torque_limit is None)
        return structure, np.concatenate(([self.kp, self.kd, self.feedforward_inertia or 0.0,
                                           self.torque_limit or 0.0], numbers))

    def casadi_torque(self, t, x, parameters=None):
        """:meth:`torque` as a CasADi expression of the symbols ``t`` and ``x``; the numbers
        are symbols too when ``parameters`` is given.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state, in the order of the plant's layout.
        parameters : CasADi column, optional
            Symbols laid out as the values of :attr:`casadi_parameters`. Default: this
            law's numbers.
        """
        kp, kd, inertia, limit, numbers = self.kp, self.kd, None, None, None
        if parameters is not None:
            kp, kd, inertia, limit = parameters[0], parameters[1], parameters[2], parameters[3]
            numbers = parameters[4:]
        theta, rate = self._casadi_hub_state(x)
        angle_ref, rate_ref, acc_ref = casadi_evaluate(self.reference, t, numbers)
        return self._casadi_apply(kp * (angle_ref - theta) + kd * (rate_ref - rate), acc_ref,
                                  inertia, limit)


def pd_gains(model_or_inertia, bandwidth: float, damping_ratio: float = 0.7) -> tuple:
    """PD gains that place the rigid-body poles at a wanted bandwidth and damping.

    The rigid hub-beam ``J0 theta_tt = torque`` under PD becomes
    ``J0 s^2 + kd s + kp = 0``; ``kp = J0 w^2`` and ``kd = 2 zeta w J0`` give natural
    frequency ``w = bandwidth`` and damping ratio ``zeta``.

    Parameters
    ----------
    model_or_inertia : flexctl.Model or float
        A model (its rigid inertia ``model.rigid_inertia`` is used) or the inertia, kg m^2.
    bandwidth : float
        Rigid-body natural frequency ``w``, rad/s (> 0).
    damping_ratio : float, optional
        ``zeta`` in (0, 1]. Default 0.7.

    Returns
    -------
    kp : float
        N m/rad.
    kd : float
        N m s/rad.

    Examples
    --------
    >>> pd_gains(2.0, bandwidth=3.0, damping_ratio=1.0)
    (18.0, 12.0)
    """
    inertia = checked_rigid_inertia("pd_gains", model_or_inertia)
    w = check_real("pd_gains", "bandwidth", bandwidth, minimum=0.0, strict=True)
    zeta = check_real("pd_gains", "damping_ratio", damping_ratio, minimum=0.0, strict=True,
                 maximum=1.0)
    return inertia * w ** 2, 2.0 * zeta * w * inertia


def design_pd(model, bandwidth: float, damping_ratio: float = 0.7, *, reference=None,
              feedforward: bool = True, torque_limit: float | None = None,
              plant=None) -> PD:
    """PD controller from :func:`pd_gains`, with the rigid inertia ``J0`` as feedforward.

    Parameters
    ----------
    model : flexctl.Model
        Any variant and mode count; only ``model.rigid_inertia`` is used.
    bandwidth, damping_ratio : float
        See :func:`pd_gains`.
    reference : object, optional
        See :class:`PD`.
    feedforward : bool, optional
        Add ``J0 acc_ref`` (default True).
    torque_limit : float, optional
        N m.
    plant : flexctl.Model, optional
        The plant the law will run on (its own modes and variant): the loop is checked on
        its linearisation (:func:`controllers.design.stability.check_loop`) and an unstable or
        nearly unstable loop warns (:class:`~controllers.design.stability.LoopStabilityWarning`).

    Returns
    -------
    PD
    """
    from ..design.stability import checked_on

    kp, kd = pd_gains(model, bandwidth, damping_ratio)
    inertia = float(model.rigid_inertia) if feedforward else None
    return checked_on(PD(kp=kp, kd=kd, reference=reference, feedforward_inertia=inertia,
                         torque_limit=torque_limit), plant)
