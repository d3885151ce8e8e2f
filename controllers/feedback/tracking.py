"""Tracking of an optimal slew: feedforward torque plus LQR feedback about the trajectory.

:class:`TrajectoryTracker` follows a :class:`~controllers.slew.trajopt.SlewSolution` on a plant that
differs from the design model (more modes, parameter errors): the optimal torque as
feedforward plus LQR feedback on the deviation from the optimal state trajectory.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from flexctl.model.checks import KeywordOnly, check_array
from flexctl.model.errors import InputTypeError, InputValueError

from flexctl.model import Model

from ..design.controllable import design_failure, lqr_on_part
from .lqr import casadi_truncate_state, truncate_state, truncation_matrix
from ..slew.trajopt import HoldTorque, SlewSolution, checked_number

__all__ = ["TrajectoryTracker"]


def _default_weights(model: Model, angle: float, torque_bound: float):
    """Bryson's rule: 5 % of the angle, 3 % of the beam length at the tip, ``u_max``."""
    mat = model.matrices
    w = np.sqrt(np.diag(mat.K_ff) / np.diag(mat.M_ff))
    theta = 0.05 * abs(angle)
    q = 0.03 * model.mode_lengths / np.abs(model.mode_tips)
    # a free hub's position is not regulated (weight 0)
    hub = ({} if model.layout.hub_position is None
           else dict(hub_position=np.full(2, np.inf), hub_velocity=np.full(2, np.inf)))
    allowed = model.layout.join(theta=theta, q=q, theta_dot=theta * w[0], q_dot=q * w, **hub)
    return 1.0 / allowed ** 2, 1.0 / torque_bound ** 2


@dataclass(frozen=True, kw_only=True, eq=False)
class TrajectoryTracker(KeywordOnly):
    """Track a :class:`SlewSolution`: feedforward torque plus LQR state feedback.

    Keyword arguments only: ``TrajectoryTracker(solution=solution)``; a positional call is
    refused with the keyword form.

    ``torque(t, x) = u_ff(t) - K (P x - x_opt(t))`` with ``u_ff`` the optimal hold torque,
    ``x_opt`` the optimal state (:meth:`SlewSolution.state_at`, held at the target after the
    slew), ``P`` the selection of the design model's states from the plant state (theta,
    the first N ``q``, theta_dot, the first N ``q_dot``; the plant may carry more modes) and
    ``K`` the LQR gain of the design model linearised at rest. A static law of the
    :class:`flexctl.Controller` protocol (``n_states = 0``).

    Parameters
    ----------
    solution : SlewSolution
        The optimal slew tracked, with its design model.
    state_weights : array_like, shape (n,), optional
        Diagonal of ``Q`` (design states). Default Bryson's rule: 5 % of the angle, 3 % of
        the beam length at the tip, rates from the flexible frequencies.
    torque_weight : float, optional
        ``R``, 1/(N m)^2. Default ``1 / torque_bound^2``.
    torque_limit : float, optional
        Saturate the total torque at this magnitude, N m. Default none.
    plant_layout : StateLayout, optional
        The plant state's layout, set by :meth:`for_plant` (:func:`flexctl.simulate` binds
        it). Default None: a bare state read with the design's blocks.

    Attributes
    ----------
    gain : ndarray, shape (n,)
        ``K``, N m per state unit.
    breakpoints : tuple of float
        The hold boundaries, s (where the feedforward jumps).

    Notes
    -----
    Only ``theta`` and ``theta_dot`` are collocated with the hub torque. Feedback on the
    truncated modal coordinates is not: the plant's unmodelled modes show up in them
    (observation spillover), and on an *undamped* plant with more modes some of those modes
    can be slightly destabilised. With the default weights on the 2-mode hub-beam-mass design,
    the undamped plant stays stable up to 16 modes; at 24 modes one grows at about 1e-4 1/s.
    Structural damping removes this: with a damping ratio of 0.1 % every mode of plants with
    up to 24 modes decays.
    """

    solution: SlewSolution
    state_weights: np.ndarray | None = None
    torque_weight: float | None = None
    torque_limit: float | None = None
    #: The plant state's layout (:meth:`for_plant`; ``flexctl.simulate`` binds it).
    plant_layout: object = None
    gain: np.ndarray = field(init=False, repr=False)
    breakpoints: tuple = field(init=False, repr=False)
    n_states: int = field(init=False, default=0)
    _feedforward: HoldTorque = field(init=False, repr=False)

    def __post_init__(self):
        import control

        if not isinstance(self.solution, SlewSolution):
            raise InputTypeError(f"solution must be a SlewSolution; got "
                                 f"{type(self.solution).__name__}")
        model, problem = self.solution.model, self.solution.problem
        q_default, r_default = _default_weights(model, problem.angle, problem.torque_bound)
        q = q_default if self.state_weights is None else check_array(
            "trajectory_tracker", "state_weights", self.state_weights, finite=False)
        if q.shape != (model.n_states,) or not np.all(np.isfinite(q)) or np.any(q < 0):
            raise InputValueError(f"state_weights must be {model.n_states} finite numbers >= 0; "
                                  f"got {self.state_weights!r}")
        r = r_default if self.torque_weight is None else checked_number("torque_weight",
                                                                 self.torque_weight)
        checked_number("torque_limit", self.torque_limit, optional=True)
        # on the modes the torque moves (symmetric appendages, a free hub's translation left)
        with design_failure("trajectory tracker lqr", "TrajectoryTracker", model,
                            state_weights=q, torque_weight=r):
            gain, _, _ = lqr_on_part(model, 0.0, np.diag(q), np.array([[r]]))
        gain = np.asarray(gain, dtype=float).reshape(-1)
        gain.setflags(write=False)
        object.__setattr__(self, "gain", gain)
        object.__setattr__(self, "breakpoints", self.solution.torque_function().breakpoints)
        object.__setattr__(self, "_feedforward", self.solution.torque_function())

    def for_plant(self, model) -> "TrajectoryTracker":
        """The same law reading the states of plant ``model`` (its layout).

        Parameters
        ----------
        model : flexctl.Model
            The plant the law runs on, with at least the design model's modes.
        """
        return dataclasses.replace(self, plant_layout=model.layout)

    def _rows(self, size: int):
        design, plant = self.solution.model.layout, self.plant_layout
        if plant is None or plant.n_states != size:
            return None
        return plant.projection(design)

    def plant_gain(self, plant, spin_rate: float = 0.0) -> np.ndarray:
        """The feedback gain on ``plant``'s state, shape (1, n).

        Parameters
        ----------
        plant : flexctl.Model
            The plant, with at least the design model's modes in each appendage.
        spin_rate : float, optional
            Steady hub rate, rad/s (not read: the gain is fixed). Default 0.
        """
        return self.gain.reshape(1, -1) @ truncation_matrix(plant.layout,
                                                            self.solution.model.layout)

    def design_state(self, x) -> np.ndarray:
        """The design model's states picked out of a plant state ``x`` (shape (2 M + 2,)).

        Parameters
        ----------
        x : array_like, shape (n,)
            Plant state, in the order of the bound plant's layout (or one beam's, unbound).
        """
        rows = self._rows(np.size(x))
        if rows is None:
            return truncate_state(x, self.solution.model.layout)
        return np.asarray(x, dtype=float)[rows]

    def initial_state(self, x0) -> np.ndarray:
        """No internal states: an empty array (also :meth:`derivative`).

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Initial plant state (not read).
        """
        return np.zeros(0)

    def torque(self, t, x, z=None) -> float:
        """Hub torque, N m.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state (at least the design model's modes), in the order of the plant's
            layout.
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        error = self.design_state(x) - self.solution.state_at(float(t))
        u = self._feedforward(t) - float(self.gain @ error)
        if self.torque_limit is not None:
            u = float(np.clip(u, -self.torque_limit, self.torque_limit))
        return u

    def casadi_torque(self, t, x):
        """:meth:`torque` as a CasADi expression of the symbols ``t`` and ``x``.

        ``K x_opt(t)`` is the Hermite cubic of :meth:`SlewSolution.state_at` with its
        coefficients projected on the gain beforehand: one scalar per coefficient and hold,
        selected with the held feedforward by one chain of comparisons on ``t``.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state, in the order of the plant's layout.
        """
        import casadi as ca

        from flexctl.sim.compiled import piecewise_constant

        grid, coef = self.solution.t, self.solution._hermite      # (K+1,), (K, 4, n)
        table = np.column_stack((grid[:-1], grid[1:], coef @ self.gain,
                                 self._feedforward.values))
        row = piecewise_constant(t, grid[1:-1], table)
        s = ca.fmin(ca.fmax((t - row[0]) / (row[1] - row[0]), 0.0), 1.0)
        optimal = row[2] + s * (row[3] + s * (row[4] + s * row[5]))     # K x_opt(t)
        outside = ca.logic_or(t < self._feedforward.t[0], t >= self._feedforward.t[-1])
        feedforward = ca.if_else(outside, 0.0, row[6])
        rows = self._rows(x.numel())
        design = (casadi_truncate_state(x, self.solution.model.layout) if rows is None
                  else x[rows.tolist()])
        u = feedforward - (ca.dot(ca.DM(self.gain), design) - optimal)
        if self.torque_limit is not None:
            u = ca.fmin(ca.fmax(u, -self.torque_limit), self.torque_limit)
        return u

    def derivative(self, t, x, z=None) -> np.ndarray:  # noqa: D102
        """No internal states: shape (0,).

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

    def __repr__(self):
        return (f"TrajectoryTracker(duration={self.solution.duration:.6g} s, design_modes="
                f"{self.solution.model.n_modes}, torque_limit={self.torque_limit})")
