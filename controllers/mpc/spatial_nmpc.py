"""Nonlinear model predictive control of a flexible spacecraft in three axes, with its wheels'
torque and speed limits as constraints.

At every sample ``t_k`` the controller predicts ``N`` holds of the design model of
:mod:`controllers.slew.spatial_trajopt` (the linear plant at rest integrated exactly, the model's
nonlinear remainder held, the attitude a quaternion, the wheels' speeds) and solves::

    min   sum_{1<=j<N} |y_j - r_j|_Q^2 + |y_N - r_N|_P^2 + sum_{j<N} |u_j - v_j|_R^2
    s.t.  z_0 = z(t_k),  z_{j+1} = F(z_j, u_j),
          |G^+ u_j| <= torque_limit (per wheel; per hub axis without wheels),
          |Omega_j| <= speed_margin * speed_limit (per wheel, j >= 1)

with ``y = (e, x_l)`` the design state (``e`` the rotation vector of ``r_q^-1 (x) q``), ``r_j``,
``v_j`` the reference's state and torque at ``t_k + j T`` (a planned slew,
:class:`~controllers.slew.spatial_trajopt.SpatialSlewSolution`, or rest at the target), ``Q``
and ``R`` the Bryson weights of :func:`~controllers.feedback.spatial_lqr.spatial_weight_matrices`
and ``P`` the held LQR's cost to go on the part of the plant the torque moves.

It is solved by a real-time iteration: one Gauss-Newton step per sample, linearised along the
design model's rollout from the state read with the previous solution shifted by one sample
(the first sample: the reference's torque). One compiled call gives the rollout and each
hold's Jacobians in the local coordinates (the attitude perturbed in its tangent space),
differentiated exactly by CasADi from the hold's expression (``_linearisation``; where
that expression is too long to compile, one CasADi call gives the rollout and the remainder's
Jacobians and the hold's follow in closed form, ``_hold_jacobians``); the prediction is
condensed onto the ``3 N`` torques in numpy. When the unconstrained minimiser of the
condensed QP meets every limit it is the QP's solution (``_unconstrained``, one Cholesky
factorisation); otherwise one dense QP is solved by a CasADi QP solver (qpOASES by default,
OSQP when it fails). The command is the first torque; the wheels' torque limits hold on it
whatever the linearisation, since they are linear in it.

Measured (``python benchmarks/bench_spatial_nmpc.py [--modes 2]``, a 20 degree step on two
damped arrays through three wheels, horizon 20 at 0.1 s, flown on the exact rod; three runs
each, one after the other, on 2 shared cores): a step's median 1.3 to 2.2 ms with one mode
per field (18 design states), 1.8 to 2.6 ms with two; the 2 ms aimed at is reached on the
quieter runs only. On the same recorded steps in one process, the step without the session
takes 1.5 ms median with the compiled linearisation and 3.8 ms with the closed form (two modes
per field).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import check_choice, check_integer, check_real
from flexctl.model.errors import InputValueError
from flexctl.model.spatial_rod import cross_matrix
from flexctl.sim.buffers import InPlace
from flexctl.sim.quaternions import from_rotation_vector, product, symbolic_product

from ..design.controllable import held, input_part
from ..feedback.lqr import LQRWeights
from ..feedback.spatial_lqr import reference_target, spatial_weight_matrices
from ..slew.spatial_trajopt import (hold_expressions, hold_functions,
                                    remainder_expression, remainder_function,
                                    spatial_hold_model)

__all__ = ["SpatialNMPC", "SpatialNMPCSession", "design_spatial_nmpc", "SPATIAL_QP_SOLVERS",
           "hold_linearisation", "null_matrix", "MAX_LINEARISATION", "WheelRows",
           "wheel_rows"]

#: CasADi QP solvers of the condensed (dense) QP; HPIPM takes only stage-structured QPs.
SPATIAL_QP_SOLVERS = ("qpoases", "qrqp", "osqp")

#: Longest hold linearisation (CasADi instructions) that the real-time iteration compiles:
#: the first_order two-array model with 2 modes per field makes 44 000 (a library compiled in
#: about 3 s, once); the exact one 423 000 (about 85 s), which keeps the closed form.
MAX_LINEARISATION = 100_000


def _prediction(model, functions, horizon: int, count: int):
    """``(x0, q0, speeds0, U) -> (X, Q, S, H, J)``: the rollout of ``U`` (3, N) from the state
    read (the states after each hold, as columns), each hold's input ``[torque, remainder]``
    (3 + n, N) and the remainder's Jacobian at each hold's start (``(n, N (n + 3))``, side by
    side, in ``(x_l, torque)``)."""
    import casadi as ca

    n = model.a.shape[0]
    remainder = remainder_function(model)
    x, tau = ca.MX.sym("x", n), ca.MX.sym("torque", 3)
    jacobian = ca.Function("remainder_jacobian", [x, tau],
                           [ca.jacobian(remainder(x, tau), ca.vertcat(x, tau))])
    roll = functions.advance.mapaccum("spatial_rollout", horizon, 3)
    x0, q0, s0 = ca.MX.sym("x0", n), ca.MX.sym("q0", 4), ca.MX.sym("s0", count)
    us = ca.MX.sym("U", 3, horizon)
    xs, qs, ss = roll(x0, q0, s0, us)
    starts = [ca.horzcat(x0, xs[:, :-1]), ca.horzcat(s0, ss[:, :-1])]
    held = functions.held.map(horizon)(starts[0], starts[1], us)
    jac = jacobian.map(horizon)(starts[0], held[0:3, :])
    return ca.Function("spatial_prediction", [x0, q0, s0, us], [xs, qs, ss, held, jac])


def hold_linearisation(model, wheels):
    """One hold of the design model and its exact Jacobians, as an SX function: ``(x, q,
    speeds, torque) -> (x+, q+, speeds+, A, B)``, ``A`` (m, m) and ``B`` (m, 3) in the local
    coordinates ``(dx, dtheta, dspeeds)`` (the attitude perturbed as ``q (x) exp(dtheta)`` at
    both ends), differentiated by CasADi from the hold's expression
    (:func:`~controllers.slew.spatial_trajopt.hold_expressions`).

    Parameters
    ----------
    model : SpatialHoldModel
        The design model (:attr:`SpatialNMPC.model`).
    wheels : WheelCluster or None
        The wheels the torque is commanded of.

    Returns
    -------
    casadi.Function
    """
    import casadi as ca

    n = model.a.shape[0]
    count = 0 if wheels is None else wheels.count
    m = n + 3 + count
    x, q, s, u = (ca.SX.sym("x", n), ca.SX.sym("q", 4), ca.SX.sym("speeds", count),
                  ca.SX.sym("torque", 3))
    dz, du = ca.SX.sym("dz", m), ca.SX.sym("du", 3)

    def remainder(x_l, torque):
        return remainder_expression(model, x_l, torque)

    nominal = hold_expressions(model, wheels, x, q, s, u, remainder)
    turn = ca.vertcat(1.0, 0.5 * dz[n:n + 3])     # exp(dtheta / 2) to first order
    moved = hold_expressions(model, wheels, x + dz[:n], symbolic_product(q, turn),
                             s + dz[n + 3:], u + du, remainder)
    inverse = ca.vertcat(nominal[1][0], -nominal[1][1:4])
    turned = 2.0 * symbolic_product(inverse, moved[1])[1:4]
    local = ca.vertcat(moved[0], turned, moved[2])
    zero = ca.DM.zeros(m + 3)
    jac = [ca.substitute(ca.jacobian(local, v), ca.vertcat(dz, du), zero) for v in (dz, du)]
    return ca.Function("spatial_hold_linearisation", [x, q, s, u], [*nominal[:3], *jac],
                       {"cse": True})


def _linearisation(model, wheels, horizon: int):
    """``(x0, q0, speeds0, U) -> [X, Q, S, A, B]`` (numpy, :class:`~flexctl.sim.buffers.InPlace`):
    the rollout of ``U`` as ``_prediction``'s, and each hold's Jacobians
    (:func:`hold_linearisation`) side by side, ``A`` (m, N m) and ``B`` (m, 3 N), compiled with
    the numbers lifted (:func:`~flexctl.sim.lifted_constants.lift_constants`: one library per
    structure's shape, kept across processes). None where the hold's linearisation is longer
    than :data:`MAX_LINEARISATION` instructions or compiling is off: the step then takes
    ``_prediction`` and ``_hold_jacobians``."""
    import casadi as ca

    from flexctl.sim.compile_cache import compiled
    from flexctl.sim.lifted_constants import lift_constants

    n = model.a.shape[0]
    count = 0 if wheels is None else wheels.count
    hold = hold_linearisation(model, wheels)
    if hold.n_instructions() > MAX_LINEARISATION:
        return None
    lifted = lift_constants(hold)
    if lifted is None:
        return None
    inner, constants = lifted
    built = compiled(inner, label="the NMPC's hold linearisation")
    if built is inner:                  # compiling is off, impossible or failed
        return None
    x0, q0, s0 = ca.MX.sym("x0", n), ca.MX.sym("q0", 4), ca.MX.sym("s0", count)
    us = ca.MX.sym("U", 3, horizon)
    values = ca.MX(ca.DM(constants))
    state, outs = (x0, q0, s0), [[] for _ in range(5)]
    for j in range(horizon):
        step = built(*state, us[:, j], values)
        state = tuple(step[:3])
        for k in range(5):
            outs[k].append(step[k])
    return InPlace(ca.Function("spatial_linearised_rollout", [x0, q0, s0, us],
                               [ca.densify(ca.horzcat(*o)) for o in outs]))


def _rotation(theta) -> np.ndarray:
    """The rotation matrices of the rotation vectors ``theta`` (N, 3): (N, 3, 3)."""
    angle = np.linalg.norm(theta, axis=1)
    k = cross_matrix(theta)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle ** 2 / 6, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle ** 2 / 24, (1 - np.cos(safe)) / safe ** 2)
    return np.eye(3) + a[:, None, None] * k + b[:, None, None] * (k @ k)


def _hold_jacobians(law, starts, speeds, held, remainder_jacobian) -> tuple:
    """Each hold's ``(A_j, B_j)`` in the local coordinates ``(dx, dtheta, dspeeds)`` (the
    attitude perturbed in its tangent space at both ends): shapes (N, m, m) and (N, m, 3).

    From the module Notes' hold: ``held = [tau, r(x, tau)]``, ``tau = u - w x (G J_w (G^T w
    + s))``, ``x+ = Phi x + Gamma held``, ``q+ = q (x) exp(theta)`` with ``theta = S_x x + S_u
    held``, ``s+ = s - h G^+ u / J_w - G^T (w+ - w)``; a perturbation ``dtheta`` at the start
    reaches the end as ``R(theta)^T dtheta``, one of ``theta`` as ``J_r(theta) dtheta``
    (to second order in ``theta``)."""
    model = law.model
    n, horizon = model.a.shape[0], law.horizon
    count = speeds.shape[0]
    at = model.rate_at
    phi, gamma, s_x, s_u = model.maps
    rates = starts[at:at + 3].T                                         # (N, 3)
    jac = remainder_jacobian.reshape(n, n + 3, horizon, order="F").transpose(2, 0, 1)
    d_tau_x = np.zeros((horizon, 3, n))
    d_tau_s = np.zeros((horizon, 3, count))
    if count:
        g, j_w = law.wheels.axes, law.wheels.inertias
        momentum = (g @ (j_w[:, None] * (g.T @ starts[at:at + 3] + speeds))).T
        d_tau_x[:, :, at:at + 3] = cross_matrix(momentum) - cross_matrix(rates) @ (g * j_w) @ g.T
        d_tau_s[:] = -cross_matrix(rates) @ (g * j_w)
    r_x, r_tau = jac[:, :, :n], jac[:, :, n:]
    d_held_x = np.concatenate([d_tau_x, r_x + r_tau @ d_tau_x], axis=1)
    d_held_s = np.concatenate([d_tau_s, r_tau @ d_tau_s], axis=1)
    d_held_u = np.concatenate([np.broadcast_to(np.eye(3), (horizon, 3, 3)), r_tau], axis=1)
    theta = (s_x @ starts + s_u @ held).T                                # (N, 3)
    j_r = np.eye(3) - 0.5 * cross_matrix(theta) + (cross_matrix(theta) @ cross_matrix(theta)) / 6.0
    m = n + 3 + count
    a_all = np.zeros((horizon, m, m))
    b_all = np.zeros((horizon, m, 3))
    a_all[:, :n, :n] = phi + gamma @ d_held_x
    a_all[:, :n, n + 3:] = gamma @ d_held_s
    b_all[:, :n] = gamma @ d_held_u
    a_all[:, n:n + 3, :n] = j_r @ (s_x + s_u @ d_held_x)
    a_all[:, n:n + 3, n:n + 3] = _rotation(theta).transpose(0, 2, 1)
    a_all[:, n:n + 3, n + 3:] = j_r @ (s_u @ d_held_s)
    b_all[:, n:n + 3] = j_r @ (s_u @ d_held_u)
    if count:
        d_w = a_all[:, at:at + 3, :]
        a_all[:, n + 3:, :] = -g.T @ d_w
        a_all[:, n + 3:, at] += g.T[:, 0]
        a_all[:, n + 3:, at + 1] += g.T[:, 1]
        a_all[:, n + 3:, at + 2] += g.T[:, 2]
        a_all[:, n + 3:, n + 3:] += np.eye(count) + model.hold * law.wheel_rows.null \
            / j_w[:, None]
        b_all[:, n + 3:] = -g.T @ b_all[:, at:at + 3] \
            + model.hold * law.wheel_rows.share / j_w[:, None]
    return a_all, b_all


def null_matrix(wheels) -> np.ndarray:
    """``d u / d Omega`` of the cluster's distribution: ``-k_n P diag(J_w)`` of a
    ``"null_motion"`` cluster (its null-space torques), else zero.

    Parameters
    ----------
    wheels : WheelCluster
        The cluster.

    Returns
    -------
    ndarray, shape (n_w, n_w)
    """
    count = wheels.count
    if wheels.distribution != "null_motion":
        return np.zeros((count, count))
    g = wheels.axes
    projector = np.eye(count) - np.linalg.pinv(g) @ g
    return -wheels.null_gain * projector * wheels.inertias[None, :]


@dataclass(frozen=True, eq=False)
class WheelRows:
    """What the NMPC's QP needs of its wheel cluster, made once per design
    (:func:`wheel_rows`).

    Attributes
    ----------
    share : ndarray, shape (n_w, 3)
        ``-G^+``: each wheel's motor torque per commanded hub torque.
    null : ndarray, shape (n_w, n_w)
        :func:`null_matrix` of the cluster.
    torque_limits : ndarray, shape (n_w,)
        Each wheel's motor torque limit, N m.
    speed_limits : ndarray, shape (n_w,)
        Each wheel's speed limit times the NMPC's ``speed_margin``, rad/s.
    """

    share: np.ndarray
    null: np.ndarray
    torque_limits: np.ndarray
    speed_limits: np.ndarray


def wheel_rows(wheels, speed_margin: float) -> WheelRows:
    """The :class:`WheelRows` of ``wheels`` with ``speed_margin``.

    Parameters
    ----------
    wheels : WheelCluster
        The cluster.
    speed_margin : float
        Fraction of each wheel's speed limit the prediction may use.

    Returns
    -------
    WheelRows
    """
    return WheelRows(share=-np.linalg.pinv(wheels.axes), null=null_matrix(wheels),
                     torque_limits=np.array([w.torque_limit for w in wheels.wheels]),
                     speed_limits=speed_margin * np.array([w.speed_limit
                                                           for w in wheels.wheels]))


def _attitude_errors(target, quaternions) -> np.ndarray:
    """Rotation vectors of ``target^-1 (x) q`` for the columns ``q`` of ``quaternions`` (4, N),
    the short way round, as rows (N, 3)."""
    w0, v0 = target[0], -np.asarray(target[1:])
    qw, qv = quaternions[0], quaternions[1:].T
    scalar = w0 * qw - qv @ v0
    cross = np.column_stack((v0[1] * qv[:, 2] - v0[2] * qv[:, 1],    # v0 x qv, per row
                             v0[2] * qv[:, 0] - v0[0] * qv[:, 2],
                             v0[0] * qv[:, 1] - v0[1] * qv[:, 0]))
    vector = w0 * qv + qw[:, None] * v0[None, :] + cross
    size = np.sqrt(np.einsum("ij,ij->i", vector, vector))
    angle = 2.0 * np.arctan2(size, np.abs(scalar)) * np.where(scalar < 0, -1.0, 1.0)
    scale = np.where(size > 1e-300, angle / np.maximum(size, 1e-300), 2.0)
    return vector * scale[:, None]


@dataclass(frozen=True, eq=False)
class SpatialNMPC:
    """A three-axis NMPC (module description), made by :func:`design_spatial_nmpc`.

    Attributes
    ----------
    state_names : tuple of str
        The design state's names (``ex, ey, ez`` then the spatial model's), as the three-axis
        LQR's.
    target : ndarray, shape (4,)
        The attitude at rest at the end, hub to inertial, scalar first.
    sample_time : float
        s.
    horizon : int
        Holds predicted.
    q_mat, r_mat, p_mat : ndarray
        Stage, torque and terminal weights on the design state and the torque.
    wheels : WheelCluster or None
    torque_limit : float or None
        Per hub axis, N m (without wheels).
    speed_margin : float
        Fraction of each wheel's speed limit the prediction may use.
    reference : SpatialSlewSolution or None
    qp_solver : str
    predict : casadi.Function
        The rollout and the remainder's Jacobians (``_prediction``).
    qp : casadi.Function
        The QP solver.
    constraint_rows : int
        Rows of the QP's constraint matrix (the wheels' torques and speeds).
    model : SpatialHoldModel
        The prediction model (:func:`~controllers.slew.spatial_trajopt.spatial_hold_model`).
    fallback : casadi.Function or None
        OSQP on the same QP, where the first solver fails.
    plant : control.StateSpace
        The design plant at rest (:func:`~flexctl.model.spatial_plant.linearize_spatial`).
    wheel_rows : WheelRows or None
        The wheels' distribution and limits in the QP (None without wheels).
    linearise : InPlace or None
        The rollout with each hold's exact Jacobians, compiled (``_linearisation``); None
        where the step takes :attr:`predict` and the closed form of ``_hold_jacobians``.
    """

    state_names: tuple
    target: np.ndarray
    sample_time: float
    horizon: int
    q_mat: np.ndarray
    r_mat: np.ndarray
    p_mat: np.ndarray
    wheels: object
    torque_limit: float | None
    speed_margin: float
    reference: object
    qp_solver: str
    predict: object
    qp: object
    constraint_rows: int
    model: object
    fallback: object
    plant: object
    linearise: object = None
    wheel_rows: object = None

    #: The loop hands this law the plant's whole state.
    state_feedback = True

    def start(self, state_names=None) -> "SpatialNMPCSession":
        """A session on a plant whose states are ``state_names`` (the spatial model's own,
        with the wheels'); it keeps the previous solution.

        Parameters
        ----------
        state_names : sequence of str, optional
            The flown plant's state names. Default the design model's, wheel speeds after.

        Returns
        -------
        SpatialNMPCSession
        """
        return SpatialNMPCSession(self, state_names)

    def linear_law(self, step: float = 1e-6):
        """The NMPC about rest at its target with no constraint active, as the held state
        feedback it is there: a :class:`~controllers.feedback.spatial_lqr.SpatialLQR` whose
        gain is the first command's derivative in the design state (central differences of
        one real-time iteration, each from rest with the wheels at rest). Without active
        constraints the step's QP has one minimiser, whatever the previous solution, so the
        law near rest is this gain; its loop and margins are those of the held LQR
        (:func:`~controllers.analysis.spatial_loops.lq_loop`).

        Parameters
        ----------
        step : float, optional
            The differences' step in each design state, in its own units. Default 1e-6.

        Returns
        -------
        SpatialLQR
        """
        from ..feedback.spatial_lqr import SpatialLQR

        names = self.state_names
        count = 0 if self.wheels is None else self.wheels.count
        gain = np.zeros((3, len(names)))
        for k in range(len(names)):
            sides = []
            for sign in (1.0, -1.0):
                design = np.zeros(len(names))
                design[k] = sign * step
                attitude = product(self.target, from_rotation_vector(design[0:3]))
                wanted = [self.wanted(np.inf)] * (self.horizon + 1)
                torques = np.zeros((3, self.horizon))
                move = _solve(self, design[3:], attitude, np.zeros(count), torques, wanted)
                if move is None:
                    raise InputValueError("the NMPC's QP failed about rest at its target: no "
                                          "linear law to analyse")
                sides.append(move[0:3])
            gain[:, k] = -(sides[0] - sides[1]) / (2.0 * step)
        part = input_part(self.plant.A, self.plant.B, max_frequency=np.pi / self.sample_time)
        law = SpatialLQR(gain=gain, plant=self.plant, state_names=names, target=self.target,
                         poles=np.zeros(0), sample_time=self.sample_time,
                         torque_limit=None, part=part,
                         note="the NMPC's real-time iteration about rest at the target, no "
                              "constraint active")
        object.__setattr__(law, "poles", law.loop_poles())
        return law

    def wanted(self, t: float) -> tuple:
        """``(r, v)``: the reference's design state and torque at ``t`` (rest at the target
        without a reference).

        Parameters
        ----------
        t : float
            Time, s.

        Returns
        -------
        tuple of ndarray
            Shapes (n + 3,) and (3,).
        """
        if self.reference is None:
            return np.zeros(len(self.state_names)), np.zeros(3)
        return self.reference.state_at(t), self.reference.at(t)[2]


class SpatialNMPCSession:
    """One flight of a :class:`SpatialNMPC`: ``session(t, attitude, rate, state) -> torque``.

    Parameters
    ----------
    law : SpatialNMPC
        The controller.
    state_names : sequence of str or None
        The flown plant's state names (:meth:`SpatialNMPC.start`).

    Attributes
    ----------
    step_times : list of float
        Wall time of each step, s.
    failed_steps : int
        Steps whose QP did not solve (the shifted previous torque was commanded).
    """

    def __init__(self, law: SpatialNMPC, state_names):
        self.law = law
        names = list(law.state_names[3:])
        count = 0 if law.wheels is None else law.wheels.count
        wheel_names = [] if law.wheels is None else list(law.wheels.state_names[:count])
        if state_names is None:
            state_names = ["qw", "qx", "qy", "qz", *names, *wheel_names]
        index = {name: k for k, name in enumerate(state_names)}
        missing = [name for name in names + wheel_names if name not in index]
        if missing:
            raise InputValueError(f"the plant has no state {missing[0]!r} that the NMPC "
                                  "predicts from: fly it on a plant with the design's "
                                  "appendages, at least its modes and its wheels")
        self.rows = np.array([index[n] for n in names], dtype=int)
        self.wheel_rows = np.array([index[n] for n in wheel_names], dtype=int)
        self.torques = None
        self.step_times: list = []
        self.failed_steps = 0
        self._reference: dict = {}

    def _wanted(self, t: float) -> tuple:
        """:meth:`SpatialNMPC.wanted` at ``t``, kept for the next steps' horizons (which
        overlap this one's but for one sample)."""
        key = round(t, 9)
        if key not in self._reference:
            if len(self._reference) > 4 * self.law.horizon:
                oldest = sorted(self._reference)[:len(self._reference) - 2 * self.law.horizon]
                for old in oldest:
                    del self._reference[old]
            self._reference[key] = self.law.wanted(t)
        return self._reference[key]

    def __call__(self, t, attitude, rate, state) -> np.ndarray:
        began = time.perf_counter()
        law = self.law
        state = np.asarray(state, dtype=float)
        x, speeds = state[self.rows], state[self.wheel_rows]
        q = np.asarray(attitude, dtype=float)
        q = q / np.linalg.norm(q)
        t = float(t)
        horizon, step = law.horizon, law.sample_time
        wanted = [self._wanted(t + j * step) for j in range(horizon + 1)]
        if self.torques is None:
            self.torques = np.array([v for _, v in wanted[:horizon]]).T
        else:
            self.torques = np.hstack([self.torques[:, 1:], wanted[horizon - 1][1][:, None]])
        move = _solve(law, x, q, speeds, self.torques, wanted)
        if move is None:
            self.failed_steps += 1
        else:
            self.torques = self.torques + move.reshape(horizon, 3).T
        command = self.torques[:, 0].copy()
        self.step_times.append(time.perf_counter() - began)
        return command


def _solve(law: SpatialNMPC, x, q, speeds, torques, wanted):
    """The Gauss-Newton step of the torques (3 N), or None when the QP fails."""
    n, horizon, count = x.size, law.horizon, speeds.size
    m = n + 3 + count
    if law.linearise is not None:
        xs, qs, ss, a_side, b_side = law.linearise(x, q, speeds, torques)
        a_all = a_side.reshape(m, horizon, m).transpose(1, 0, 2)
        b_all = b_side.reshape(m, horizon, 3).transpose(1, 0, 2)
    else:
        xs, qs, ss, held, jac = (np.asarray(v) for v in law.predict(x, q, speeds, torques))
    speed_starts = np.hstack([speeds[:, None], ss[:, :-1]]) if count else np.zeros((0, horizon))
    if law.linearise is None:
        starts = np.hstack([x[:, None], xs[:, :-1]])
        a_all, b_all = _hold_jacobians(law, starts, speed_starts, held, jac)
    # the design state y = (e, x_l) after each hold, less the wanted one
    residuals = np.hstack([_attitude_errors(law.target, qs), xs.T]) \
        - np.array([y for y, _ in wanted[1:]])
    order = np.r_[n:n + 3, 0:n]                           # y's rows in the local coordinates
    sensitivity = np.zeros((m, 3 * horizon))
    hessian = np.zeros((3 * horizon, 3 * horizon))
    diagonal = hessian.reshape(horizon, 3, horizon, 3)
    diagonal[np.arange(horizon), :, np.arange(horizon), :] = law.r_mat
    gradient = (law.r_mat @ (torques - np.array([v for _, v in wanted[:horizon]]).T)).T.ravel()
    speed_rows = np.zeros((horizon * count, 3 * horizon))
    for j in range(horizon):
        used = 3 * j + 3                    # torques after hold j do not move its end
        sensitivity[:, :used] = a_all[j] @ sensitivity[:, :used]
        sensitivity[:, 3 * j:used] += b_all[j]
        mapped = sensitivity[order, :used]
        weighted = (law.p_mat if j == horizon - 1 else law.q_mat) @ mapped
        hessian[:used, :used] += mapped.T @ weighted
        gradient[:used] += weighted.T @ residuals[j]
        speed_rows[j * count:(j + 1) * count, :used] = sensitivity[n + 3:, :used]
    return _qp(law, hessian, gradient, torques, speed_rows, speed_starts, ss)


def _qp(law: SpatialNMPC, hessian, gradient, torques, speed_rows, speed_starts, speeds):
    """The QP of the step (module description), its wheel rows: each hold's motor torques
    (the distribution at the hold's starting speeds) and the speeds after each hold."""
    horizon = law.horizon
    flat = torques.T.reshape(-1)
    big = np.inf
    if law.wheels is None:
        limit = big if law.torque_limit is None else law.torque_limit
        lbx, ubx = -limit - flat, limit - flat
        rows, lba, uba = np.zeros((0, 3 * horizon)), np.zeros(0), np.zeros(0)
    else:
        lbx, ubx = np.full(3 * horizon, -big), np.full(3 * horizon, big)
        wheels = law.wheels
        count = wheels.count
        limits = law.wheel_rows
        share, null = limits.share, limits.null
        torque_limits, speed_limits = limits.torque_limits, limits.speed_limits
        motor_now = (share @ torques + null @ (speed_starts - wheels.null_target[:, None]))
        motor_rows = np.zeros((horizon * count, 3 * horizon))
        blocks = motor_rows.reshape(horizon, count, horizon, 3)
        blocks[np.arange(horizon), :, np.arange(horizon), :] = share
        if np.any(null):
            motor_rows[count:] += (null @ speed_rows[:-count].reshape(horizon - 1, count, -1)
                                   ).reshape(-1, 3 * horizon)
        rows = np.vstack([motor_rows, speed_rows])
        now = np.concatenate([motor_now.T.reshape(-1), speeds.T.reshape(-1)])
        bound = np.concatenate([np.tile(torque_limits, horizon),
                                np.tile(speed_limits, horizon)])
        lba, uba = -bound - now, bound - now
    data = {"h": 0.5 * (hessian + hessian.T), "g": gradient, "a": rows, "lba": lba,
            "uba": uba, "lbx": lbx, "ubx": ubx}
    free = _unconstrained(data)
    if free is not None:
        return free
    solution = law.qp(**data)
    if not law.qp.stats().get("success", True):
        if law.fallback is None:
            return None
        # a degenerate active set can stop an active-set solver; ADMM does not mind it
        solution = law.fallback(**data)
        if not law.fallback.stats().get("success", True):
            return None
    move = np.asarray(solution["x"]).ravel()
    return move if np.all(np.isfinite(move)) else None


def _unconstrained(data: dict):
    """The QP's minimiser when no constraint binds: the Newton step ``-H^-1 g`` (a Cholesky
    factorisation), if it satisfies every bound and row; else None (the QP solver is needed).

    A convex QP's unconstrained minimiser that is feasible is its minimiser, so this is the
    QP's solution, not an approximation of it: most samples of a slew have no active limit,
    and a factorisation of ``3 N`` unknowns is some twenty times quicker than the active-set
    solver's run."""
    import scipy.linalg

    try:
        factor = scipy.linalg.cho_factor(data["h"], check_finite=False)
    except np.linalg.LinAlgError:
        return None
    move = -scipy.linalg.cho_solve(factor, data["g"], check_finite=False)
    if not np.all(np.isfinite(move)):
        return None
    if np.any(move < data["lbx"]) or np.any(move > data["ubx"]):
        return None
    if data["a"].shape[0]:
        value = data["a"] @ move
        if np.any(value < data["lba"]) or np.any(value > data["uba"]):
            return None
    return move


def _terminal(plant, q_mat, r_mat, sample_time: float) -> np.ndarray:
    """The held LQR's cost to go on the part of ``plant`` the torque moves (below Nyquist),
    on the whole design state."""
    import scipy.linalg

    part = input_part(plant.A, plant.B, max_frequency=np.pi / sample_time)
    a_d, b_d = held(part.projector @ plant.A @ part.basis, part.projector @ plant.B,
                    sample_time)
    q_r = part.basis.T @ q_mat @ part.basis
    cost = scipy.linalg.solve_discrete_are(a_d, b_d, 0.5 * (q_r + q_r.T) * sample_time,
                                           r_mat * sample_time)
    return part.projector.T @ (0.5 * (cost + cost.T)) @ part.projector


def design_spatial_nmpc(structure, weights: LQRWeights, target=None, sample_time: float = 0.1,
                        *, horizon: int = 20, n_modes=1, variant: str = "first_order",
                        wheels=None, torque_limit: float | None = None,
                        speed_margin: float = 0.9, reference=None,
                        qp_solver: str = "qpoases") -> SpatialNMPC:
    """A three-axis NMPC of ``structure`` (module description).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    weights : LQRWeights
        Bryson weights (attitude, rate, tips, torque; :func:`spatial_weight_matrices
        <controllers.feedback.spatial_lqr.spatial_weight_matrices>`).
    target : array_like, shape (4,), optional
        The attitude to rest at (None with a ``reference``: its end).
    sample_time : float, optional
        The hold of each prediction step and of the command, s. Default 0.1.
    horizon : int, optional
        Holds predicted, 2 to 200. Default 20.
    n_modes : int, sequence of int or mapping, optional
        Modes per field in the prediction model. Default 1.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model whose nonlinear remainder the prediction carries. Default ``"first_order"``.
    wheels : WheelCluster, optional
        The wheels the torque is commanded of: their torque and speed limits constrain it.
    torque_limit : float, optional
        Per hub axis, N m (without wheels).
    speed_margin : float, optional
        Fraction of each wheel's speed limit the prediction may use, in ``(0, 1]``. Default
        0.9.
    reference : SpatialSlewSolution, optional
        A planned slew to follow (on the same structure and modes).
    qp_solver : {"qpoases", "qrqp", "osqp"}, optional
        CasADi's QP solver. Default ``"qpoases"`` (a dense active-set solver: on the
        example of the tests 7 ms a step at saturation, where ``qrqp`` took 220 ms).

    Returns
    -------
    SpatialNMPC
    """
    import casadi as ca

    from ..slew.spatial_trajopt import SpatialSlewSolution
    from .nmpc import conic_solver

    owner = "design_spatial_nmpc"
    sample_time = check_real(owner, "sample_time", sample_time, minimum=1e-4, maximum=100.0)
    horizon = check_integer(owner, "horizon", horizon, minimum=2, maximum=200)
    speed_margin = check_real(owner, "speed_margin", speed_margin, minimum=0.0, strict=True,
                              maximum=1.0)
    qp_solver = check_choice(owner, "qp_solver", qp_solver, SPATIAL_QP_SOLVERS)
    if wheels is not None:
        from flexctl.model.checks import check_instance
        from flexctl.model.wheel_cluster import WheelCluster

        check_instance(owner, "wheels", wheels, WheelCluster)
    if wheels is not None and torque_limit is not None:
        raise InputValueError(f"{owner}.torque_limit bounds a hub torque without wheels; with "
                              "wheels their own torque_limit does")
    if torque_limit is not None:
        torque_limit = check_real(owner, "torque_limit", torque_limit, minimum=0.0,
                                  strict=True)
    target = reference_target(owner, target, reference, (SpatialSlewSolution,))
    model = spatial_hold_model(structure, n_modes, variant, sample_time, owner)
    if reference is not None and tuple(reference.state_names) != tuple(model.names):
        raise InputValueError(f"{owner}.reference was planned on other modes than n_modes: "
                              "plan it on the NMPC's structure and n_modes")
    functions = hold_functions(model, wheels)
    count = 0 if wheels is None else wheels.count
    from ..design.plant_state import spatial_design_plant

    plant, _ = spatial_design_plant(owner, structure, n_modes, variant)
    q_mat, r_mat = spatial_weight_matrices(plant, weights)
    p_mat = _terminal(plant, q_mat, r_mat, sample_time)
    rows = 0 if wheels is None else horizon * 2 * count
    sparsity = (ca.Sparsity.dense(3 * horizon, 3 * horizon), ca.Sparsity.dense(rows, 3 * horizon))
    qp = conic_solver("spatial_nmpc_qp", qp_solver, *sparsity)
    return SpatialNMPC(state_names=model.names, target=target, sample_time=sample_time,
                       horizon=horizon, q_mat=q_mat * sample_time, r_mat=r_mat * sample_time,
                       p_mat=p_mat, wheels=wheels, torque_limit=torque_limit,
                       speed_margin=speed_margin, reference=reference, qp_solver=qp_solver,
                       predict=_prediction(model, functions, horizon, count), qp=qp,
                       constraint_rows=rows, model=model,
                       fallback=None if qp_solver == "osqp" else conic_solver(
                           "spatial_nmpc_qp_fallback", "osqp", *sparsity), plant=plant,
                       linearise=_linearisation(model, wheels, horizon),
                       wheel_rows=None if wheels is None else wheel_rows(wheels, speed_margin))
