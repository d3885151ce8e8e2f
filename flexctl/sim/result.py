"""The result of a run, and its assembly from what the integration handed back.

Only the output grid and the last time (``t_final`` or the stop) are reported; the arrays of a
stopped run end at the stop time and never hold NaN or overflowed values. A small-deflection
run's energy is balanced against the work of the hub torque (:mod:`flexctl.sim.energy`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from .energy import EnergyBalance, ModelValidityWarning, energy_balance
from .stops import StopReason, softened, stiffness_reason
from ..model import Model
from ..model.errors import InputValueError

__all__ = ["SimulationResult", "assemble_result", "audit_energy"]


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Outcome of :func:`simulate`.

    Attributes
    ----------
    model : Model
        The model simulated.
    t : ndarray, shape (P,)
        Output times, s.
    states : ndarray, shape (n, P)
        Plant states in the order of :attr:`Model.state_names` (:attr:`Model.layout`).
    torque : ndarray, shape (P,)
        Hub torque, N m (the torque the prescribed motion needs, for ``hub_motion`` runs;
        the torque the actuator puts on the structure, for a model with an actuator).
    tip_deflection, root_moment : ndarray, shape (P,)
        m and N m; with several appendages, the largest in magnitude over them at each time
        (each appendage's own in :attr:`outputs` and :attr:`tip_deflections`).
    status : {"ok", "diverged", "singular"}
    message : str
        Why the run stopped, with the time and the physical reason.
    wall_time : float
        Integration wall time, s.
    n_evaluations : int
        Number of right-hand-side evaluations.
    method : str
        The integrator that ran (after the stiffness guard;
        :data:`~flexctl.sim.simulation.METHODS`).
    rtol : float
        The relative tolerance it ran at.
    controller_states : ndarray, shape (n_z, P)
        The controller's internal states at the output times (``n_z = 0`` without any).
    integration_error : float or None
        Estimated largest integration error of the tip deflection, m: the difference from a
        check run at 10 times the tolerance (conservative). ``None`` where no check ran (SciPy
        methods, stopped runs, ``check_accuracy=False``).
    validity : ModelValidity or None
        Deflection reached and estimated geometric model error
        (:func:`flexctl.sim.validity.assess_run`; for scene runs with the scene's tolerance);
        ``None`` from ``simulate(..., check_validity=False)``.
    stop_reason : StopReason
        Why the run ended (``status`` is ``stop_reason.status``).
    energy_balance : EnergyBalance or None
        Energy against the work done, from the outputs (:func:`energy_balance`); ``None`` for
        the exact variant and a singular stop (whose hub rate outruns the samples). When it is
        violated the message says so, and a run that reached ``t_final`` warns
        (:class:`ModelValidityWarning`).
    controller_report : dict or None
        For a sampled controller (:mod:`flexctl.sim.digital`): the session's report (e.g. solve
        times) with ``samples``, ``sample_time`` (s) and ``controller_time`` (s, wall time in
        the controller); ``None`` otherwise.
    command : ndarray, shape (P,), or None
        For a model with an actuator (:class:`~flexctl.model.actuated.ActuatedModel`): the
        command it was given (N m of torque asked of a reaction wheel, V across a DC motor);
        ``None`` otherwise.
    measurements : dict or None
        For a run with sensors (:mod:`flexctl.sim.sensors`): what the controller saw, each
        reading by name with its sample times under ``"t"``; ``None`` otherwise.
    """

    model: Model
    t: np.ndarray
    states: np.ndarray
    torque: np.ndarray
    tip_deflection: np.ndarray
    root_moment: np.ndarray
    status: str
    message: str
    wall_time: float
    n_evaluations: int
    method: str
    rtol: float
    controller_states: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    integration_error: float | None = None
    validity: object = None
    controller_report: dict | None = None
    stop_reason: StopReason | None = None
    energy_balance: EnergyBalance | None = None
    command: np.ndarray | None = None
    measurements: dict | None = None

    @classmethod
    def from_states(cls, model: Model, t, states, torque, **fields) -> "SimulationResult":
        """A result whose tip deflection and root moment are computed from ``states``; for a
        model with an actuator ``torque`` is the plant's input, kept as :attr:`command`, and
        the torque on the hub is computed from it.

        Parameters
        ----------
        model : Model
            The model simulated.
        t : ndarray, shape (P,)
            Output times, s.
        states : ndarray, shape (n, P)
            Plant states, in the order of ``model.layout``.
        torque : ndarray, shape (P,)
            Hub torque, N m; for a model with an actuator, its command (N m or V).
        **fields
            The other fields of :class:`SimulationResult` (``status``, ``message``, ``wall_time``,
            ``n_evaluations``, ``method``, ``rtol``, ...).
        """
        if getattr(model, "actuator", None) is not None and "command" not in fields:
            fields["command"] = np.asarray(torque, dtype=float)
            torque = np.asarray(model.applied_torque(states, torque), dtype=float).reshape(-1)
        roots = np.atleast_2d(model.matrices.root) @ model.layout.modal(states)
        pick = np.argmax(np.abs(roots), axis=0)
        return cls(model=model, t=t, states=states, torque=torque,
                   tip_deflection=np.asarray(model.tip_deflection(states), dtype=float),
                   root_moment=np.take_along_axis(roots, pick[None], 0)[0], **fields)

    @property
    def tip_deflections(self) -> dict:
        """Each appendage's tip deflection in its own frame, m, ``{name: (P,)}`` (the name
        ``""`` for one beam)."""
        tips = np.atleast_2d(self.model.tip_deflections(self.states))
        return dict(zip(self.model.structure.names, tips))

    @property
    def deflection_ratio(self) -> float:
        """Largest ``|tip deflection|`` of an appendage divided by its beam length."""
        if not self.t.size:
            return 0.0
        tips = np.atleast_2d(self.model.tip_deflections(self.states))
        return float(np.max(np.max(np.abs(tips), axis=1) / self.model.lengths))

    @property
    def ok(self) -> bool:
        """True when the run reached ``t_final``."""
        return self.status == "ok"

    @property
    def theta(self) -> np.ndarray:
        """Hub angle, rad, shape (P,)."""
        return self.model.layout.hub_angle(self.states)

    @property
    def theta_dot(self) -> np.ndarray:
        """Hub rate, rad/s, shape (P,)."""
        return self.model.layout.hub_rate(self.states)

    @property
    def q(self) -> np.ndarray:
        """Modal coordinates, m, shape (N, P)."""
        return self.model.layout.modal(self.states)

    @property
    def outputs(self) -> dict:
        """Every model output by name (:attr:`Model.output_names`), each shape (P,)."""
        y = self.model.outputs(self.states)
        return dict(zip(self.model.output_names, y))

    def to_time_response(self):
        """The run as a python-control ``TimeResponseData``: time, the model's named outputs,
        states and input (the actuator's command where there is one, else the hub torque),
        python-control's signal names (:func:`~flexctl.model.exports.signal_names`), and
        ``success``/``message`` from the run's status."""
        import control

        from ..model.exports import signal_names

        model = self.model
        inputs = self.torque if self.command is None else self.command
        return control.TimeResponseData(
            self.t, np.atleast_2d(model.outputs(self.states)), states=self.states,
            inputs=np.asarray(inputs, dtype=float)[None, :],
            output_labels=signal_names(model.output_names),
            state_labels=signal_names(model.state_names), input_labels=list(model.input_names),
            sysname=f"flexctl_{model.variant}", success=self.ok, message=self.message)

    def to_pandas(self, states: bool = True):
        """The run as a ``pandas.DataFrame`` indexed by time ``t`` (s): the command (the
        actuator's where there is one, else ``torque``), the hub ``torque``, the model's named
        outputs, the actuator's signals and, with ``states``, every state, under the model's
        names (an appendage's ``wing_a.q1``). pandas is an optional dependency.

        Parameters
        ----------
        states : bool, optional
            Add every state as a column. Default True.

        Raises
        ------
        ImportError
            If pandas is not installed (``pip install pandas``).
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("SimulationResult.to_pandas needs pandas: pip install pandas") \
                from None
        columns = {"torque": self.torque}
        if self.command is not None:
            columns["command"] = self.command
        columns.update(self.outputs)
        columns.update(self.actuator_signals)
        if states:
            columns.update({name: self.states[k] for k, name in enumerate(self.model.state_names)
                            if name not in columns})
        frame = pd.DataFrame({name: np.asarray(v, dtype=float).reshape(-1)
                              for name, v in columns.items()},
                             index=pd.Index(np.asarray(self.t, dtype=float), name="t"))
        frame.attrs.update(status=self.status, message=self.message,
                           variant=self.model.variant)
        return frame

    @property
    def actuator_signals(self) -> dict:
        """The actuator's signals by name, each shape (P,) (``wheel_speed``, ``wheel_torque``;
        ``motor_voltage``, ``motor_current``); empty without an actuator."""
        if self.command is None:
            return {}
        return {name: np.asarray(v, dtype=float).reshape(-1) for name, v in
                self.model.actuator_signals(self.states, self.command).items()}

    @property
    def peak_tip_deflection(self) -> float:
        """Largest ``|tip_deflection|``, m."""
        return float(np.max(np.abs(self.tip_deflection))) if self.t.size else 0.0

    def __repr__(self):
        return (f"SimulationResult(status={self.status!r}, t_end={self.t[-1]:.6g} s, "
                f"points={self.t.size}, peak_tip_deflection={self.peak_tip_deflection:.6g} m, "
                f"wall_time={self.wall_time:.3g} s)")


def audit_energy(model: Model, result_arrays, reason: StopReason, message: str,
                 stacklevel: int):
    """``(EnergyBalance or None, message)`` of a run, the message naming a broken balance.

    A run that reached its end with a broken balance warns (:class:`ModelValidityWarning`); a
    stopped one gets the balance as its physical reason, and zero_order or first_order the
    loss of beam stiffness when the hub rate has passed it. A singular stop has its own reason.

    Parameters
    ----------
    model : Model
        The model simulated (a small-deflection variant has an energy balance).
    result_arrays : tuple
        ``(t, states, torque)``: output times, s, shape (P,); plant states, shape (n, P); the
        plant's input, shape (P,) (hub torque, N m, or an actuator's command).
    reason : StopReason
        Why the run ended.
    message : str
        The run's message so far.
    stacklevel : int
        ``stacklevel`` of the warning.
    """
    if reason is StopReason.SINGULAR_MASS:
        # the hub rate outruns the output samples near the singularity: a balance would
        # measure their quadrature, not the model (which conserves energy)
        return None, message
    balance = energy_balance(*mechanical_arrays(model, *result_arrays))
    if balance is None:
        return balance, message
    message = message.rstrip(".")
    if reason is not StopReason.REACHED_END and reason is not StopReason.TIP_PAST_LENGTH \
            and not model.variant.quadratic_inertia and balance.violated:
        spin = float(model.layout.hub_rate(result_arrays[1][:, -1]))
        if softened(model, spin):
            message = f"{message}: {stiffness_reason(model, spin)}"
    if not balance.violated:
        return balance, message
    if reason is StopReason.REACHED_END:
        warnings.warn(f"energy balance violated: {balance.message}", ModelValidityWarning,
                      stacklevel=stacklevel)
        return balance, f"{message}; energy balance violated: {balance.message}"
    return balance, f"{message}; {balance.message}"


def mechanical_arrays(model, t, states, inputs):
    """``(model, t, states, torque)`` of the structure alone: for a model with an actuator,
    its mechanical model and states and the torque the actuator puts on the hub (whose work
    the structure's energy balances); the arguments as they are otherwise.

    Parameters
    ----------
    model : Model
        The model simulated; an actuated model's structure is its ``mechanical`` model.
    t : ndarray, shape (P,)
        Output times, s.
    states : ndarray, shape (n, P)
        Plant states, in the order of ``model.layout``.
    inputs : ndarray, shape (P,)
        The plant's input: hub torque, N m, or an actuator's command (N m or V).
    """
    if getattr(model, "actuator", None) is None:
        return model, t, states, inputs
    torque = np.asarray(model.applied_torque(states, inputs), dtype=float).reshape(-1)
    return model.mechanical, t, model.mechanical_states(states), torque


def output_samples(grid, traj):
    """The trajectory's samples on the output grid and at its last time, cut before the first
    non-finite one: ``(t, y)``.

    A non-finite sample stops ``traj`` (``StopReason.NON_FINITE_STATE``).

    Parameters
    ----------
    grid : array_like, shape (P,)
        Output times, s.
    traj : Trajectory
        What the integration handed back: samples ``y`` of shape (m, K) per piece.

    Returns
    -------
    t : ndarray, shape (P',)
        s.
    y : ndarray, shape (m, P')
        The integrated state at those times.
    """
    t_all = np.concatenate(traj.ts)
    y_all = np.concatenate(traj.ys, axis=1)
    # segment ends at breakpoints off the grid were integration restarts, not outputs
    grid = np.asarray(grid, dtype=float)
    at = np.minimum(np.searchsorted(grid, t_all), max(grid.size - 1, 0))
    on_grid = grid[at] == t_all if grid.size else np.zeros(t_all.size, dtype=bool)
    keep = np.concatenate(([True], np.diff(t_all) > 0)) & on_grid
    keep[-1] = True
    t_all, y_all = t_all[keep], y_all[:, keep]
    finite = np.all(np.isfinite(y_all), axis=0)
    if not finite.all():
        first_bad = int(np.argmin(finite))
        t_all, y_all = t_all[:first_bad], y_all[:, :first_bad]
        traj.stop(StopReason.NON_FINITE_STATE,
                  f"the state became non-finite after t = {t_all[-1]:.6g} s")
    return t_all, y_all


def _finite_torque(t_all, states, z_all, torque, traj):
    """The arrays cut before the first non-finite torque (the torque a prescribed motion
    needs, or an input's own array form, overflowed)."""
    finite = np.isfinite(torque)
    if finite.all():
        return t_all, states, z_all, torque
    first_bad = int(np.argmin(finite))
    if first_bad == 0:
        raise InputValueError(f"the hub torque is {torque[0]!r} at t = 0 s; the inputs must "
                              "keep it finite")
    traj.stop(StopReason.NON_FINITE_TORQUE,
              f"the hub torque became non-finite after t = {t_all[first_bad - 1]:.6g} s")
    return (t_all[:first_bad], states[:, :first_bad], z_all[:, :first_bad],
            torque[:first_bad])


def assemble_result(request, plan, drive, stops, traj, wall: float) -> SimulationResult:
    """The :class:`SimulationResult` of an integrated run: outputs, torque, stop message,
    energy audit and the notes of the stiffness guard and the accuracy check.

    Parameters
    ----------
    request : RunRequest
        The checked run.
    plan : IntegrationPlan
        How it was integrated (its method and the stiffness guard's note).
    drive : PrescribedDrive or TorqueDrive
        What was integrated: turns ``y`` into plant states and torque.
    stops : StopConditions
        Names the physical reason of a stop.
    traj : Trajectory
        What the integration handed back.
    wall : float
        Integration wall time, s.
    """
    model = request.model
    t_all, y_all = output_samples(request.grid, traj)
    states = np.asarray(drive.plant_state(t_all, y_all))
    z_all = drive.controller_states(y_all)
    torque = np.asarray(drive.torque_output(t_all, states, z_all, request.symbolic),
                        dtype=float).reshape(-1)
    t_all, states, z_all, torque = _finite_torque(t_all, states, z_all, torque, traj)
    message = traj.message or f"reached t_final = {request.t_final:g} s"
    if traj.found:
        message = stops.message(traj.reason, float(t_all[-1]), states[:, -1])
    balance, message = audit_energy(model, (t_all, states, torque), traj.reason, message, 4)
    for note in (plan.stiffness_note, traj.accuracy_note):
        if note:
            message = f"{message} ({note})"
    return SimulationResult.from_states(
        model, t_all, states, torque, status=traj.reason.status, message=message,
        wall_time=wall, n_evaluations=int(traj.n_eval), method=plan.method, rtol=plan.rtol,
        controller_states=z_all, integration_error=traj.integration_error,
        stop_reason=traj.reason, energy_balance=balance)
