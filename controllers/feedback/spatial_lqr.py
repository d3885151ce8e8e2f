"""LQR and LQG in three axes, designed on the linear flexible spacecraft.

:func:`design_spatial_lqr` linearises a spatial structure at rest
(:func:`flexctl.model.spatial_plant.linearize_spatial`: states the attitude error ``e``, the
modal coordinates, ``w``, a free hub's velocity and the modal rates; inputs the hub torque),
turns :class:`~controllers.feedback.lqr.LQRWeights` into ``Q`` and ``R`` per axis (Bryson's
rule: ``(e_i / hub_angle)^2``, ``(w_i / hub_rate)^2``, ``(tip_i / tip_deflection)^2`` for
every tip component, ``(u_i / torque)^2``) and solves the Riccati equation on the part of the
plant the torque can move (:func:`~controllers.design.controllable.input_part`: appendages
bending against each other, a free hub's linear momentum are left at their open-loop poles).
With a ``sample_time`` the gain is the discrete LQR of the plant held over it.

:class:`SpatialLQR` is a full-state law: it reads the attitude, the rate and the modal states of
the plant it flies on (:func:`flexctl.sim.spatial_loop.simulate_spatial_loop` hands them to a
law whose ``state_feedback`` is true), by name, so that the plant may carry more modes than
the design (those are neither fed back nor estimated). The attitude error is the rotation
vector of ``target^-1 (x) q``, the short way round, and the command ``u = -K x``, clipped per
axis at ``torque_limit``.

:class:`SpatialLQG` reads only what a spacecraft measures, the attitude and the rate (the
truth, or the attitude filter's estimate from a star tracker and a gyro), and estimates the
modes with a discrete Kalman filter on the held design plant (a disturbance torque of
``process_torque`` N m per axis, white over each sample; readings with ``angle_noise`` rad and
``rate_noise`` rad/s): at each sample the filter takes the reading, the law commands
``-K x_hat``, and the filter predicts the next sample with the command it was given (clipped)
and with the attitude's own kinematics (the rotation vector's rate ``w + 1/2 e x w + ...``,
which the linear plant's ``e_t = w`` leaves out: over a 20 degree slew about a tilted axis,
that left the estimate 3e-3 rad off).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import check_instance, check_quaternion, check_real
from flexctl.model.errors import InputValueError
from flexctl.sim.quaternions import error_angles

from ..design.plant_state import spatial_design_plant
from ..design.controllable import (ControllablePart, design_failure, held, input_part,
                                   state_gain)
from .lqr import LQRWeights

__all__ = ["SpatialLQR", "SpatialLQG", "design_spatial_lqr", "design_spatial_lqg",
           "spatial_weight_matrices", "spatial_lq_gain", "fed_back_rows", "state_reader",
           "reference_target",
           "FREQUENCY_FACTOR", "NOISE_FLOOR"]

#: Default cut-off of a continuous design's modes, in multiples of the rigid loop's bandwidth.
FREQUENCY_FACTOR = 100.0
#: Smallest noise level of an LQG's filter (rad, rad/s, N m): a Riccati equation whose noise
#: squares underflow has no reliable solution.
NOISE_FLOOR = 1e-12


def spatial_weight_matrices(plant, weights: LQRWeights) -> tuple:
    """``Q`` (n, n) and ``R`` (3, 3) of :class:`~controllers.feedback.lqr.LQRWeights` on a
    spatial linear plant, per axis.

    Parameters
    ----------
    plant : control.StateSpace
        A plant of :func:`~flexctl.model.spatial_plant.linearize_spatial`.
    weights : LQRWeights
        Largest acceptable attitude error (rad), rate (rad/s), tip deflection (m) and torque
        (N m), each per axis or component. ``modal_energy`` is refused.

    Returns
    -------
    tuple
        ``(Q, R)``.
    """
    check_instance("spatial_weight_matrices", "weights", weights, LQRWeights)
    if weights.modal_energy is not None:
        raise InputValueError("spatial_weight_matrices: weights.modal_energy has no spatial "
                              "form; weight the tips (tip_deflection) instead")
    n = plant.nstates
    q_mat = np.zeros((n, n))
    q_mat[0:3, 0:3] = np.eye(3) / weights.hub_angle ** 2
    outputs = list(plant.output_labels)
    if weights.hub_rate is not None:
        rows = plant.C[[outputs.index(f"w{a}") for a in "xyz"], :]
        q_mat += rows.T @ rows / weights.hub_rate ** 2
    if weights.tip_deflection is not None:
        tips = plant.C[[k for k, name in enumerate(outputs) if "_tip_" in name], :]
        q_mat += tips.T @ tips / weights.tip_deflection ** 2
    return 0.5 * (q_mat + q_mat.T), np.eye(3) / weights.torque ** 2


@dataclass(frozen=True, eq=False)
class SpatialLQR:
    """A three-axis LQR on the attitude, the rate and the modal states (module description).

    Attributes
    ----------
    gain : ndarray, shape (3, n)
        ``K``, ``u = -K x`` on the plant's state ``x`` (zero on the poles left out).
    plant : control.StateSpace
        The design plant (:func:`~flexctl.model.spatial_plant.linearize_spatial` at rest).
    state_names : tuple of str
        The design state's names: ``ex, ey, ez`` and then the spatial model's own
        (:attr:`~flexctl.model.spatial_dynamics.SpatialLayout.state_names`).
    target : ndarray, shape (4,)
        Target attitude, hub to inertial, scalar first.
    poles : ndarray
        Closed-loop poles of the part the gain acts on, 1/s (continuous, or the held part's
        ``log(z) / T`` with ``sample_time``); :meth:`loop_poles` gives those of a whole plant.
    sample_time : float or None
        The hold the gain was designed for, s (None: continuous).
    torque_limit : float or None
        Per-axis saturation of the command, N m.
    part : ControllablePart
        The part of the design plant the gain acts on (``z = P x``, ``x = T z``;
        :func:`~controllers.design.controllable.input_part`).
    note : str
        What the design left out (``""``: nothing).
    reference : EigenaxisSlew, SpatialSlewSolution or None
        A slew to follow to :attr:`target`: the law regulates ``x - x_ref(t)`` (the
        reference's attitude error and rate; a planned slew's whole design state) and adds its
        feedforward torque. None: a step to the target.
    """

    gain: np.ndarray
    plant: object
    state_names: tuple
    target: np.ndarray
    poles: np.ndarray
    sample_time: float | None
    torque_limit: float | None
    part: ControllablePart
    note: str
    reference: object = None

    def command(self, t: float, state) -> np.ndarray:
        """``clip(-K (x - x_ref(t)) + u_ff(t))`` for the design state ``x`` (the attitude
        error from :attr:`target` first).

        Parameters
        ----------
        t : float
            Time, s.
        state : array_like, shape (n,)
            The design state (:attr:`state_names`).

        Returns
        -------
        ndarray, shape (3,)
            Torque, N m, hub frame.
        """
        state = np.asarray(state, dtype=float)
        if self.reference is None:
            return self.limited(-self.gain @ state)
        error, rate, torque = self.reference.at(t)
        whole = getattr(self.reference, "state_at", None)
        if whole is not None:                   # a planned slew: its whole design state
            return self.limited(-self.gain @ (state - whole(t)) + torque)
        deviation = state.copy()
        deviation[0:3] -= error
        deviation[self.rate_at:self.rate_at + 3] -= rate
        return self.limited(-self.gain @ deviation + torque)

    #: The loop hands this law the plant's whole state.
    state_feedback = True

    def start(self, state_names=None) -> "_StateFeedbackSession":
        """A session on a plant whose states are ``state_names``.

        Parameters
        ----------
        state_names : sequence of str, optional
            The flown plant's state names (the spatial model's own); default the design's
            model (modal states by their names).

        Returns
        -------
        callable
            ``session(t, attitude, rate, state) -> torque`` (N m, hub frame).
        """
        return _StateFeedbackSession(self, state_names)

    def reader(self, plant) -> np.ndarray:
        """``Pi`` (n, N): the design state ``x = Pi x_plant`` read from the state of ``plant``
        (:func:`state_reader`).

        Parameters
        ----------
        plant : control.StateSpace
            A plant of :func:`~flexctl.model.spatial_plant.linearize_spatial` of the same
            structure, with at least the design's modes.

        Returns
        -------
        ndarray
        """
        return state_reader(self.state_names, plant)

    def loop_poles(self, plant=None) -> np.ndarray:
        """Poles of the loop this law closes around a linear plant, 1/s: continuous, or for a
        sampled law the held loop's ``log(z) / T``.

        Parameters
        ----------
        plant : control.StateSpace, optional
            The plant flown (:func:`~flexctl.model.spatial_plant.linearize_spatial` at rest,
            as many modes as wanted: those beyond the design are neither read nor fed back).
            Default the design plant.

        Returns
        -------
        ndarray, shape (N,)
        """
        return _closed_poles(self.broken_loop(self.plant if plant is None else plant),
                             self.sample_time)

    def broken_loop(self, plant) -> tuple:
        """``(A, B, C)`` of the loop around ``plant`` broken at its torque inputs, in negative
        feedback (``L = C (sI - A)^-1 B``, or ``(zI - A)^-1`` of the plant held over
        :attr:`sample_time`): what :meth:`loop_poles` closes and
        :func:`controllers.analysis.spatial_loops.lq_loop` hands python-control.

        Parameters
        ----------
        plant : control.StateSpace
            A plant of :func:`~flexctl.model.spatial_plant.linearize_spatial` at rest.

        Returns
        -------
        tuple of ndarray
        """
        gain = self.gain @ self.reader(plant)
        if self.sample_time is None:
            return plant.A, plant.B, gain
        a_d, b_d = held(plant.A, plant.B, self.sample_time)
        return a_d, b_d, gain

    @functools.cached_property
    def rate_at(self) -> int:
        """Where ``wx wy wz`` start in the design state (found once: each step reads it)."""
        return self.state_names.index("wx", 3)

    def limited(self, torque) -> np.ndarray:
        """``torque`` clipped per axis at :attr:`torque_limit`.

        Parameters
        ----------
        torque : array_like, shape (3,)
            Command, N m.

        Returns
        -------
        ndarray, shape (3,)
        """
        torque = np.asarray(torque, dtype=float)
        if self.torque_limit is None:
            return torque
        return np.clip(torque, -self.torque_limit, self.torque_limit)


def state_reader(state_names, plant) -> np.ndarray:
    """``Pi`` (n, N): a design state named ``state_names`` read from the state of ``plant``.

    Parameters
    ----------
    state_names : sequence of str
        The design state's names (the attitude error ``ex, ey, ez`` then the model's own).
    plant : control.StateSpace
        A plant of :func:`~flexctl.model.spatial_plant.linearize_spatial` of the same
        structure, with at least the design's modes.

    Returns
    -------
    ndarray

    Raises
    ------
    InputValueError
        If the plant lacks a state the design reads (the message names it).
    """
    from flexctl.model.exports import signal_names

    index = {name: k for k, name in enumerate(plant.state_labels)}
    names = signal_names(list(state_names))
    missing = [name for name in names if name not in index]
    if missing:
        raise InputValueError(f"the plant has no state {missing[0]!r} that the law reads: "
                              "give a plant of the design's structure with at least its "
                              "modes")
    reader = np.zeros((len(names), plant.nstates))
    reader[np.arange(len(names)), [index[name] for name in names]] = 1.0
    return reader


def fed_back_rows(names, state_names):
    """Where a full-state law's ``names`` sit in a flown plant's state.

    Parameters
    ----------
    names : sequence of str
        The plant states the law feeds back.
    state_names : sequence of str or None
        The flown plant's state names (None: the design model's own order).

    Returns
    -------
    ndarray of int or None
        The rows, in the order of ``names``; None with ``state_names`` None.

    Raises
    ------
    InputValueError
        If the plant lacks one of them (the message names it).
    """
    if state_names is None:
        return None
    index = {name: k for k, name in enumerate(state_names)}
    missing = [name for name in names if name not in index]
    if missing:
        raise InputValueError(
            f"the plant has no state {missing[0]!r} that the law feeds back: fly it on a "
            "plant with the design's appendages and at least its modes")
    return np.array([index[name] for name in names], dtype=int)


class _StateFeedbackSession:
    """A :class:`SpatialLQR` reading a plant's state by name."""

    def __init__(self, law: SpatialLQR, state_names):
        self.law = law
        self.rows = fed_back_rows(law.state_names[3:], state_names)

    def __call__(self, t, attitude, rate, state) -> np.ndarray:
        law = self.law
        x = np.asarray(state, dtype=float)
        rest = x[3:] if self.rows is None else x[self.rows]
        design = np.concatenate([error_angles(law.target, attitude), rest])
        return law.command(t, design)


@dataclass(frozen=True, eq=False)
class SpatialLQG:
    """A three-axis LQG: the LQR's gain on a discrete Kalman filter's estimate from the
    attitude and the rate (module description).

    Attributes
    ----------
    regulator : SpatialLQR
        The gain (designed for the loop's hold) and its design plant.
    filter_gain : ndarray, shape (r, 6)
        The Kalman filter's gain on the part ``z = P x`` the gain acts on
        (:attr:`SpatialLQR.part`).
    a_held, b_held : ndarray
        The held part's ``z+ = A_d z + B_d u``, shapes (r, r) and (r, 3).
    measured : ndarray, shape (6, r)
        ``y = C z``: the attitude error and the rate.
    estimator_poles : ndarray
        ``eig(A_d - L C A_d)`` of the filter, as ``log(z) / T``, 1/s.
    """

    regulator: SpatialLQR
    filter_gain: np.ndarray
    a_held: np.ndarray
    b_held: np.ndarray
    measured: np.ndarray
    estimator_poles: np.ndarray

    #: The loop hands this law what it reads, not the plant's state.
    state_feedback = False

    @property
    def target(self) -> np.ndarray:
        """Target attitude, hub to inertial, scalar first."""
        return self.regulator.target

    @property
    def sample_time(self) -> float:
        """The loop's hold, s."""
        return self.regulator.sample_time

    @property
    def note(self) -> str:
        """What the design left out (:attr:`SpatialLQR.note`)."""
        return self.regulator.note

    def loop_poles(self, plant=None) -> np.ndarray:
        """Poles of the held loop of this law and its filter around a linear plant,
        ``log(z) / T`` (1/s): the plant's modes beyond the design are seen by the readings
        (observation spillover) and moved by the commands.

        Parameters
        ----------
        plant : control.StateSpace, optional
            The plant flown (:func:`~flexctl.model.spatial_plant.linearize_spatial` at rest);
            default the design plant.

        Returns
        -------
        ndarray, shape (N + r,)
        """
        return _closed_poles(self.broken_loop(self.regulator.plant if plant is None else plant),
                             self.sample_time)

    def broken_loop(self, plant) -> tuple:
        """``(A, B, C)`` of the held loop around ``plant`` broken at its torque inputs, in
        negative feedback: the plant held, its readings through the filter (which predicts
        with the command it gave) to the command. What :meth:`loop_poles` closes and
        :func:`controllers.analysis.spatial_loops.lq_loop` hands python-control.

        Parameters
        ----------
        plant : control.StateSpace
            A plant of :func:`~flexctl.model.spatial_plant.linearize_spatial` at rest.

        Returns
        -------
        tuple of ndarray
            States: the plant's, then the filter's prediction.
        """
        regulator = self.regulator
        a_d, b_d = held(plant.A, plant.B, self.sample_time)
        outputs = list(plant.output_labels)
        c_plant = plant.C[[outputs.index(name) for name in ("ex", "ey", "ez", "wx", "wy",
                                                            "wz")], :]
        basis, size = regulator.part.basis, self.a_held.shape[0]
        from_plant = self.filter_gain @ c_plant                    # estimate: on the plant
        from_filter = np.eye(size) - self.filter_gain @ self.measured  # ... on the prediction
        k_plant = regulator.gain @ basis @ from_plant        # the command is -(these) . state
        k_filter = regulator.gain @ basis @ from_filter
        a = np.block([[a_d, np.zeros((a_d.shape[0], size))],
                      [self.a_held @ from_plant - self.b_held @ k_plant,
                       self.a_held @ from_filter - self.b_held @ k_filter]])
        return a, np.vstack([b_d, np.zeros((size, 3))]), np.hstack([k_plant, k_filter])

    def start(self) -> "_ObservedSession":
        """A session whose filter starts at the first reading, its modes at rest.

        Returns
        -------
        callable
            ``session(t, attitude, rate) -> torque`` (N m, hub frame).
        """
        return _ObservedSession(self)

    def __call__(self, t, attitude, rate) -> np.ndarray:
        """The command of a fresh session (the filter at its first reading).

        Parameters
        ----------
        t : float
            Time, s.
        attitude : array_like, shape (4,)
            Attitude read, hub to inertial, scalar first.
        rate : array_like, shape (3,)
            Rate read, hub frame, rad/s.

        Returns
        -------
        ndarray, shape (3,)
            Torque, N m, hub frame.
        """
        return self.start()(t, attitude, rate)


class _ObservedSession:
    """A :class:`SpatialLQG` with its filter's state."""

    def __init__(self, law: SpatialLQG):
        self.law = law
        self.predicted = None
        self.last = None

    def __call__(self, t, attitude, rate) -> np.ndarray:
        law = self.law
        y = np.concatenate([error_angles(law.target, attitude), np.asarray(rate, float)])
        if self.predicted is None:
            part = law.regulator.part
            start = np.zeros(part.basis.shape[0])
            start[0:3] = y[0:3]
            start[law.regulator.rate_at:][:3] = y[3:6]
            self.predicted = part.projector @ start
        elif self.last is not None and abs(t - self.last - law.sample_time) > \
                1e-9 * max(1.0, abs(t)):
            raise InputValueError(f"the LQG was designed for a {law.sample_time:g} s hold; it "
                                  f"was called {t - self.last:g} s after its last command")
        estimate = self.predicted + law.filter_gain @ (y - law.measured @ self.predicted)
        part = law.regulator.part
        state = part.basis @ estimate
        command = law.regulator.command(t, state)
        at = law.regulator.rate_at
        turned = _kinematics(state[0:3], state[at:at + 3]) * law.sample_time
        self.predicted = (law.a_held @ estimate + law.b_held @ command
                          + part.projector[:, 0:3] @ turned)
        self.last = t
        return command


def _kinematics(e, w) -> np.ndarray:
    """What the rotation vector's rate adds to the linear ``e_t = w``, rad/s:
    ``e_t = w + 1/2 e x w + c(|e|) e x (e x w)``, ``c(a) = (1 - (a/2) cot(a/2)) / a^2``."""
    angle = float(np.linalg.norm(e))
    if angle < 1e-4:
        factor = 1.0 / 12.0 + angle * angle / 720.0
    else:
        factor = (1.0 - 0.5 * angle / np.tan(0.5 * angle)) / (angle * angle)
    cross = np.cross(e, w)
    return 0.5 * cross + factor * np.cross(e, cross)


def _closed_poles(loop: tuple, sample_time) -> np.ndarray:
    """Poles of a broken loop ``(A, B, C)`` closed in negative feedback, 1/s: of ``A - B C``,
    those of a loop held over ``sample_time`` as ``log(z) / T``."""
    a, b, c = loop
    poles = np.linalg.eigvals(a - b @ c)
    return poles if sample_time is None else _continuous(poles, sample_time)


def _continuous(z, sample_time: float) -> np.ndarray:
    """``log(z) / T`` of discrete poles (a pole at 0 becomes -inf)."""
    z = np.asarray(z, dtype=complex)
    with np.errstate(divide="ignore"):
        return np.log(z) / sample_time


def _design_plant(structure, n_modes, variant):
    """The design plant at rest and its state names (the spatial model's own)."""
    return spatial_design_plant("design_spatial_lqr", structure, n_modes, variant)


def spatial_lq_gain(owner: str, structure, plant, weights: LQRWeights, *,
                    sample_time: float | None = None,
                    max_frequency: float | None = None) -> tuple:
    """The LQR gain of a spatial linear plant on the part its torque moves (module
    description): what :func:`design_spatial_lqr` solves, at rest or about a steady spin.

    Parameters
    ----------
    owner : str
        Who asks (named in errors).
    structure : SpatialStructure
        The structure of ``plant`` (its rigid inertia sets the default cut-off).
    plant : control.StateSpace
        :func:`~flexctl.model.spatial_plant.linearize_spatial`'s plant.
    weights : LQRWeights
        Bryson weights per axis.
    sample_time : float, optional
        The hold, s: the discrete LQR of the held plant. Default: continuous.
    max_frequency : float, optional
        Cut-off of the modes designed on, rad/s (as :func:`design_spatial_lqr`'s).

    Returns
    -------
    tuple
        ``(gain, poles, part)``: the gain on the whole plant state (3, n), the closed-loop
        poles of the part (1/s; a held design's ``log(z) / T``) and the
        :class:`~controllers.design.controllable.ControllablePart`.
    """
    q_mat, r_mat = spatial_weight_matrices(plant, weights)
    a, b = plant.A, plant.B
    if max_frequency is None:
        rigid = np.sqrt(weights.torque / weights.hub_angle
                        / np.linalg.eigvalsh(structure.rigid_inertia)[-1])
        max_frequency = (np.pi / sample_time if sample_time is not None
                         else FREQUENCY_FACTOR * rigid)
    max_frequency = check_real(owner, "max_frequency", max_frequency, minimum=0.0,
                               strict=True)
    part = input_part(a, b, max_frequency=max_frequency)
    with design_failure("lqr", owner, structure, weights=weights, sample_time=sample_time):
        q_r = part.basis.T @ q_mat @ part.basis
        gain_r = state_gain(part.projector @ a @ part.basis, part.projector @ b,
                            0.5 * (q_r + q_r.T), r_mat, sample_time)
    gain = gain_r @ part.projector
    a_r, b_r = part.projector @ a @ part.basis, part.projector @ b
    if sample_time is None:
        poles = np.linalg.eigvals(a_r - b_r @ gain_r)
    else:
        a_d, b_d = held(a_r, b_r, sample_time)
        poles = _continuous(np.linalg.eigvals(a_d - b_d @ gain_r), sample_time)
    return gain, poles, part


def design_spatial_lqr(structure, weights: LQRWeights, target, *, n_modes=2,
                       variant: str = "exact", sample_time: float | None = None,
                       torque_limit: float | None = None,
                       max_frequency: float | None = None, reference=None) -> SpatialLQR:
    """A three-axis LQR on the linear flexible spacecraft at rest.

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    weights : LQRWeights
        Bryson weights per axis (:func:`spatial_weight_matrices`).
    target : array_like, shape (4,) or None
        Target attitude, hub to inertial, scalar first (normalised here); None with a
        ``reference``: its end.
    n_modes : int, sequence of int or mapping, optional
        The design plant's modes per field (:func:`~flexctl.model.spatial_dynamics.spatial_modes`).
        Default 2.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model linearised (at rest all three give the same plant). Default ``"exact"``.
    sample_time : float, optional
        The loop's hold, s: the discrete LQR of the held plant. Default: continuous.
    torque_limit : float, optional
        Per-axis saturation of the command, N m.
    max_frequency : float, optional
        Modes faster than this (rad/s) are left out of the design: their gain is zero and
        they keep their open-loop poles (a Riccati equation on undamped modes thousands of
        times faster than the loop has no reliable solution, and a gain on them would only
        amplify noise). Default: the Nyquist frequency ``pi / sample_time`` of a sampled
        design, else :data:`FREQUENCY_FACTOR` times the rigid loop's bandwidth
        ``sqrt(torque / (hub_angle J_max))`` (``J_max`` the largest principal rigid inertia).
    reference : EigenaxisSlew or SpatialSlewSolution, optional
        A slew to follow to the target: about a fixed axis
        (:class:`~controllers.slew.eigenaxis.EigenaxisSlew`), or planned on the flexible
        structure (:func:`~controllers.slew.spatial_trajopt.solve_spatial_slew`, on the same
        design modes: the law then follows its whole state). Default: a step to the target.

    Returns
    -------
    SpatialLQR

    Examples
    --------
    >>> import numpy as np
    >>> from flexctl import SpatialHub, SpatialAppendage, SpatialStructure
    >>> rod = SpatialAppendage(name="wing", direction=(0, 1, 0), normal=(0, 0, 1), length=1.8,
    ...                        density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
    ...                        second_moment=5.2e-10, second_moment_lateral=5.2e-8,
    ...                        shear_modulus=2.6e10, torsion_constant=1e-9)
    >>> craft = SpatialStructure(hub=SpatialHub(inertia=np.diag([1.3, 1.2, 1.4]), radius=0.06),
    ...                          appendages=(rod,))
    >>> law = design_spatial_lqr(craft, LQRWeights(hub_angle=0.05, torque=0.1),
    ...                          (1.0, 0.0, 0.0, 0.0), n_modes=1)
    >>> law.gain.shape, bool(law.poles.real.max() < 0)
    ((3, 12), True)
    """
    check_instance("design_spatial_lqr", "weights", weights, LQRWeights)
    target = reference_target("design_spatial_lqr", target, reference)
    if sample_time is not None:
        sample_time = check_real("design_spatial_lqr", "sample_time", sample_time,
                                 minimum=1e-6, strict=True, maximum=100.0)
        _check_plan_sampling("design_spatial_lqr", reference, sample_time)
    if torque_limit is not None:
        torque_limit = check_real("design_spatial_lqr", "torque_limit", torque_limit,
                                  minimum=0.0, strict=True, maximum=1e9)
    plant, names = _design_plant(structure, n_modes, variant)
    planned = getattr(reference, "state_names", None)
    if planned is not None and tuple(planned) != tuple(names):
        raise InputValueError(
            f"design_spatial_lqr.reference was planned on a design state of {len(planned)} "
            f"entries, the law's has {len(names)} ({', '.join(names[3:])}): plan the slew "
            "on the law's structure and n_modes")
    gain, poles, part = spatial_lq_gain("design_spatial_lqr", structure, plant, weights,
                                        sample_time=sample_time, max_frequency=max_frequency)
    return SpatialLQR(gain=gain, plant=plant, state_names=names, target=target, poles=poles,
                      sample_time=sample_time, torque_limit=torque_limit, part=part,
                      note=part.note, reference=reference)


def design_spatial_lqg(structure, weights: LQRWeights, target, sample_time: float, *,
                       angle_noise: float = 1e-4, rate_noise: float = 1e-5,
                       process_torque: float = 1e-3, n_modes=2, variant: str = "exact",
                       torque_limit: float | None = None,
                       max_frequency: float | None = None, reference=None) -> SpatialLQG:
    """A three-axis LQG: :func:`design_spatial_lqr` held over ``sample_time`` and a discrete
    Kalman filter of the attitude and rate readings.

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    weights : LQRWeights
        The regulator's Bryson weights per axis.
    target : array_like, shape (4,) or None
        Target attitude, hub to inertial, scalar first (None with a ``reference``).
    sample_time : float
        The loop's hold and the filter's step, s.
    angle_noise : float, optional
        Standard deviation of each axis of the attitude read, rad (at least
        :data:`NOISE_FLOOR`, as the two below). Default 1e-4.
    rate_noise : float, optional
        Standard deviation of each axis of the rate read, rad/s. Default 1e-5.
    process_torque : float, optional
        Standard deviation of a disturbance torque per axis, constant over each sample, N m.
        Default 1e-3.
    n_modes : int, sequence of int or mapping, optional
        The design plant's modes per field. Default 2.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model linearised. Default ``"exact"``.
    torque_limit : float, optional
        Per-axis saturation of the command, N m.
    max_frequency : float, optional
        Modes faster than this are out of the design and of the filter, rad/s; default the
        Nyquist frequency ``pi / sample_time`` (:func:`design_spatial_lqr`).
    reference : EigenaxisSlew or SpatialSlewSolution, optional
        A slew to follow (:func:`design_spatial_lqr`); the filter estimates the state from
        the final target and predicts with the whole command.

    Returns
    -------
    SpatialLQG
    """
    import scipy.linalg

    if sample_time is None:
        raise InputValueError("design_spatial_lqg.sample_time is required (s): the filter "
                              "is discrete")
    sample_time = check_real("design_spatial_lqg", "sample_time", sample_time, minimum=1e-6,
                             strict=True, maximum=100.0)
    noise = {name: check_real("design_spatial_lqg", name, value, minimum=NOISE_FLOOR,
                              maximum=1e6)
             for name, value in (("angle_noise", angle_noise), ("rate_noise", rate_noise),
                                 ("process_torque", process_torque))}
    regulator = design_spatial_lqr(structure, weights, target, n_modes=n_modes,
                                   variant=variant, sample_time=sample_time,
                                   torque_limit=torque_limit, max_frequency=max_frequency,
                                   reference=reference)
    plant, part = regulator.plant, regulator.part
    basis = part.basis
    a_d, b_d = held(part.projector @ plant.A @ basis, part.projector @ plant.B, sample_time)
    outputs = list(plant.output_labels)
    rows = [outputs.index(name) for name in ("ex", "ey", "ez", "wx", "wy", "wz")]
    measured = plant.C[rows, :] @ basis
    q_d = b_d @ b_d.T * noise["process_torque"] ** 2
    r_d = np.diag([noise["angle_noise"] ** 2] * 3 + [noise["rate_noise"] ** 2] * 3)
    with design_failure("lqg", "design_spatial_lqg", structure,
                        solving="the Kalman filter Riccati equation", **noise):
        p_mat = scipy.linalg.solve_discrete_are(a_d.T, measured.T, 0.5 * (q_d + q_d.T), r_d)
        if not np.all(np.isfinite(p_mat)):
            raise np.linalg.LinAlgError("the filter's covariance is not finite")
    gain = p_mat @ measured.T @ np.linalg.inv(measured @ p_mat @ measured.T + r_d)
    closed = a_d - gain @ measured @ a_d
    poles = _continuous(np.linalg.eigvals(closed), sample_time)
    return SpatialLQG(regulator=regulator, filter_gain=gain, a_held=a_d,
                      b_held=b_d, measured=measured, estimator_poles=poles)


def _check_plan_sampling(owner: str, reference, sample_time: float) -> None:
    """Refuse a held law that follows a planned slew at samples that do not fall on the
    plan's holds: its feedforward is the torque held over the sample, the plan's only when
    each sample lies within one hold (a sample across two holds commands neither, and the
    slew ends off target, its modes ringing)."""
    hold = getattr(getattr(reference, "model", None), "hold", None)
    if hold is None or not hasattr(reference, "state_at"):
        return
    ratio = float(hold) / sample_time
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
        raise InputValueError(
            f"{owner}.sample_time must divide the planned slew's hold ({float(hold):g} s) so "
            f"that each sample lies within one of the plan's holds; got {sample_time:g} s "
            "(plan with n_intervals = duration / sample_time, or sample at the hold)")


def reference_target(owner: str, target, reference=None, kinds=None) -> np.ndarray:
    """The target attitude of a three-axis law: ``target`` (a unit quaternion, hub to
    inertial, scalar first), or the end of ``reference``, which ``target`` must then equal
    (either sign) when both are given.

    Parameters
    ----------
    owner : str
        Who takes them (named in errors).
    target : array_like, shape (4,), or None
        The target attitude.
    reference : EigenaxisSlew or SpatialSlewSolution, optional
        A slew ending at the target.
    kinds : tuple of type, optional
        The references ``owner`` follows. Default both kinds.

    Returns
    -------
    ndarray, shape (4,)
    """
    if reference is not None:
        if kinds is None:
            from ..slew.eigenaxis import EigenaxisSlew
            from ..slew.spatial_trajopt import SpatialSlewSolution

            kinds = (EigenaxisSlew, SpatialSlewSolution)
        check_instance(owner, "reference", reference, kinds)
        end = reference.target
        if target is None:
            return end
        value = check_quaternion(owner, "target", target)
        if min(np.linalg.norm(value - end), np.linalg.norm(value + end)) > 1e-9:
            raise InputValueError(f"{owner}.target must be the reference's end attitude (or "
                                  "None)")
        return value
    if target is None:
        raise InputValueError(f"{owner}.target is required without a reference (a unit "
                              "quaternion, hub to inertial, scalar first)")
    return check_quaternion(owner, "target", target)
