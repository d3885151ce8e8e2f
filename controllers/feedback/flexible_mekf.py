"""The attitude filter with the appendages' modes in it: a multiplicative extended Kalman filter
of the attitude, the gyro bias and the design model's flexible state, driven by the torque.

:class:`FlexibleAttitudeFilter` is :class:`~controllers.feedback.mekf.AttitudeFilter` with the
structure's dynamics inside: where that filter integrates the gyro's reading (the gyro is its
model), this one predicts the hub's rotation and the appendages' modes from the torque on the
structure through the linear flexible spacecraft at rest, and reads the gyro as a measurement
of the rotation over each sample. It estimates the modal coordinates and rates the gyro and
the star tracker see through the hub's motion, for a law or a monitor that wants them.

Notes
-----
State: the attitude ``q`` (multiplicative error ``dtheta``, as the attitude filter's), the gyro
bias ``b`` and ``x_l`` (the design state of
:func:`~controllers.slew.spatial_trajopt.spatial_hold_model` after the attitude error: the
modal coordinates, the hub rate ``w``, the modal rates). Over a gyro sample ``T`` with the
torque ``u`` held on the structure (the design model's at rest, integrated exactly)::

    x_l <- Phi x_l + Gamma (u + w_u)          phi = S_x x_l + S_u (u + w_u)
    q   <- q (x) exp(phi / 2)                 (the rotation over the sample)
    z_g  = phi / T + b + v                    (the gyro's reading over the sample)

``w_u`` a torque disturbance held over the sample (standard deviation ``torque_sigma`` per
axis, what the design model leaves out: friction, the nonlinear remainder) and ``v`` the
gyro's rate noise (``angle_random_walk^2 / T``); the bias follows the attitude filter's random
walk. The reading depends on the state at the sample's start and on the same ``w_u`` as the
prediction: each sample is one step of the Kalman predictor with correlated noise (the gain
``(F P H^T + G Q D^T) S^-1``), the error state ``(dtheta, db, dx_l)`` with ``F = [[R(phi)^T,
0, J_r(phi) S_x], [0, I, 0], [0, 0, Phi]]``, ``H = [0, I, S_x / T]``, ``G = [J_r(phi) S_u; 0;
Gamma]`` and ``D = S_u / T``. A star tracker reading updates as in the attitude filter (``H =
[I, 0, 0]``), a late one replayed from the stored samples. Rotation increments are taken as
commuting within a sample and the model is the one at rest: slow slews, where the modes are
small.

**Through reaction wheels** (:mod:`flexctl.model.wheel_cluster`) the structure feels the
motors' reaction and the wheels' gyroscopic torque ``-w x H`` (``H = G h`` the rotors' axial
momentum, hub frame). The loop hands the filter the motors' torque on the structure averaged
over the sample, ``u = -G (h_end - h_start) / T`` (exact by the rotor equation, whatever the
lag, friction and limits did: ``h_k = J_k (g_k . w + Omega_k)`` from the tachometers' speeds
and the gyro's rate), and ``H`` at the sample's start; the filter adds ``[H]x w`` to the torque
from its own rate estimate, held over the sample like the rest: ``Phi``, ``S_x`` and ``H``
above become ``Phi + Gamma C``, ``S_x + S_u C`` and their reading, ``C = [H]x E_w`` (``E_w``
the rate rows of ``x_l``).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from flexctl.model.checks import check_array, check_real
from flexctl.model.errors import InputValueError
from flexctl.model.spatial_rod import cross_matrix
from flexctl.sim.quaternions import error_angles, from_rotation_vector, product, rotation_matrix

from ..design.controllable import input_part
from .mekf import AttitudeFilter

__all__ = ["FlexibleAttitudeFilter", "EstimatedStateLaw"]


def _right_jacobian(phi) -> np.ndarray:
    """``J_r(phi)``: ``exp(phi + d) = exp(phi) exp(J_r(phi) d)`` to first order in ``d``."""
    angle = float(np.linalg.norm(phi))
    k = cross_matrix(phi)
    if angle < 1e-6:
        return np.eye(3) - 0.5 * k + k @ k / 6.0
    return (np.eye(3) - (1 - np.cos(angle)) / angle ** 2 * k
            + (angle - np.sin(angle)) / angle ** 3 * (k @ k))


class FlexibleAttitudeFilter(AttitudeFilter):
    """The attitude filter with the design model's modes (module Notes).

    Parameters
    ----------
    sensors : AttitudeSensors
        The sensors it reads (as :class:`~controllers.feedback.mekf.AttitudeFilter`'s).
    structure : SpatialStructure
        The structure whose linear model at rest it carries.
    attitude : array_like, shape (4,)
        Initial attitude estimate, hub to inertial, scalar first.
    attitude_sigma : float
        Its standard deviation about each axis, rad (> 0).
    n_modes : int, sequence of int or mapping, optional
        Modes per field of the design model. Default 1.
    variant : {"first_order", "zero_order", "exact"}, optional
        The spatial model linearised at rest. Default ``"first_order"``.
    bias, bias_sigma : optional
        As the attitude filter's.
    rate_sigma : float, optional
        Standard deviation of the initial hub rate estimate (zero), rad/s (> 0). Default 1e-3.
    mode_sigma : float, optional
        Standard deviation of the initial modal coordinates and rates (zero), in their units
        (> 0). Default 1e-3.
    torque_sigma : float, optional
        Standard deviation of the disturbance torque held over each sample, N m per axis
        (> 0). Default 1e-4.

    Attributes
    ----------
    names : tuple of str
        The flexible state's names (``x_l``'s).
    model : SpatialHoldModel
        The design model over one gyro sample.
    part : ControllablePart
        The part of ``x_l`` the filter carries (``z = P x_l``, ``x_l = T z``).
    phi, gamma, s_x, s_u, gamma_r, s_r : ndarray
        ``Phi``, ``Gamma``, ``S_x`` and ``S_u`` (module Notes) on that part, and the
        remainder's columns of the hold.
    reading_noise : ndarray, shape (3, 3)
        The gyro reading's noise covariance (its rate noise and the disturbance's share).
    disturbance_cross : ndarray, shape (3, 3)
        ``(D Q)^T``: the disturbance's covariance with the reading.
    bias_walk : ndarray
        The bias's random walk over a sample, on the error state.
    torque_variance : float
        ``torque_sigma^2``, N^2 m^2.
    """

    #: The loop hands :meth:`propagate` the torque held over the sample.
    takes_torque = True

    def __init__(self, sensors, structure, attitude, attitude_sigma: float, *, n_modes=1,
                 variant: str = "first_order", bias=(0.0, 0.0, 0.0), bias_sigma: float = 1e-4,
                 rate_sigma: float = 1e-3, mode_sigma: float = 1e-3,
                 torque_sigma: float = 1e-4):
        from ..slew.spatial_trajopt import remainder_function, spatial_hold_model

        super().__init__(sensors, attitude, attitude_sigma, bias, bias_sigma)
        owner = "flexible_mekf"
        sigmas = {name: check_real(owner, name, value, minimum=0.0, strict=True, maximum=1e6)
                  for name, value in (("rate_sigma", rate_sigma), ("mode_sigma", mode_sigma),
                                      ("torque_sigma", torque_sigma))}
        self.model = spatial_hold_model(structure, n_modes, variant, self.step, owner)
        self.names = tuple(self.model.names[3:])
        # the part of x_l the torque moves below the gyro's Nyquist frequency: z = P x_l,
        # x_l = T z (the faster and the unreachable modes are left to the model's error)
        self.part = input_part(self.model.a, self.model.b, max_frequency=np.pi / self.step)
        basis, projector = self.part.basis, self.part.projector
        n = basis.shape[1]
        at = self.model.rate_at
        self.x = np.zeros(n)
        scale = np.full(len(self.names), sigmas["mode_sigma"])
        scale[at:at + 3] = sigmas["rate_sigma"]
        spread = np.sqrt(np.diag(projector @ np.diag(scale ** 2) @ projector.T))
        covariance = np.zeros((6 + n, 6 + n))
        covariance[:6, :6] = self.P
        covariance[6:, 6:] = np.diag(spread ** 2)
        self.P = covariance
        self.torque_variance = sigmas["torque_sigma"] ** 2
        phi, gamma, s_x, s_u = self.model.maps
        self.phi, self.gamma = projector @ phi @ basis, projector @ gamma[:, :3]
        self.s_x, self.s_u = s_x @ basis, s_u[:, :3]
        self.gamma_r, self.s_r = projector @ gamma[:, 3:], s_u[:, 3:]
        self.remainder = remainder_function(self.model)
        # what each sample's step does not change: the gyro's H and its noise covariance
        # (rate noise plus the disturbance's share), D Q, and the bias's random walk
        t = self.step
        self._h = np.zeros((3, 6 + n))
        self._h[:, 3:6] = np.eye(3)
        self._h[:, 6:] = self.s_x / t
        self.disturbance_cross = self.torque_variance * self.s_u.T / t    # (D Q)^T, (3, 3)
        self.reading_noise = (self.s_u @ self.disturbance_cross / t
                              + self.sigma_v ** 2 / t * np.eye(3))
        self.bias_walk = np.zeros((6 + n, 6 + n))
        self.bias_walk[3:6, 3:6] = self.sigma_u2 * t * np.eye(3)
        self.history = deque(maxlen=self.lag + 1)   # (q, b, x, P, reading, torque, H)

    @property
    def flexible_state(self) -> np.ndarray:
        """Estimated ``x_l`` (:attr:`names`; the left-out modes' part zero), shape (n,)."""
        return self.part.basis @ self.x

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of ``(dtheta, db, dz)``, ``z = P x_l`` the filtered part (``part``),
        shape (6 + r, 6 + r)."""
        return self.P.copy()

    def propagate(self, gyro_reading, torque=(0.0, 0.0, 0.0), wheel_momentum=None) -> None:
        """Take the gyro's reading over the sample just past, with the torque held on the
        structure over it, and advance one sample.

        Parameters
        ----------
        gyro_reading : array_like, shape (3,)
            The gyro's reading, rad/s.
        torque : array_like, shape (3,), optional
            The torque on the structure over the sample, N m, hub frame, besides the wheels'
            gyroscopic torque (through wheels: the motors' reaction averaged over the
            sample, module Notes). Default zero.
        wheel_momentum : array_like, shape (3,), optional
            The wheels' axial momentum ``G h`` at the sample's start, N m s, hub frame (its
            gyroscopic torque ``-w x G h`` is added from the estimated rate). Default none.
        """
        owner = "flexible_mekf"
        reading = self._gyro_reading(gyro_reading)
        u = np.array(check_array(owner, "torque", torque, shape=(3,)))
        momentum = None if wheel_momentum is None else np.array(check_array(
            owner, "wheel_momentum", wheel_momentum, shape=(3,)))
        self.history.append((self.q.copy(), self.b.copy(), self.x.copy(), self.P.copy(),
                             reading, u, momentum))
        with np.errstate(all="ignore"):      # a blown-up estimate is reported just below
            self._predict(reading, u, momentum)
        self._check_finite(reading)

    def _predict(self, reading, u, momentum=None) -> None:
        t, n = self.step, self.x.size
        phi, s_x, h = self.phi, self.s_x, self._h
        if momentum is not None:     # the wheels' -w x H = [H]x w, w from the estimate
            at = self.model.rate_at
            coupling = cross_matrix(momentum) @ self.part.basis[at:at + 3]
            phi = phi + self.gamma @ coupling
            s_x = s_x + self.s_u @ coupling
            h = h.copy()
            h[:, 6:] = s_x / t
        # the model's nonlinear remainder (gyroscopic torques, Coriolis, stiffening) held over
        # the sample at the estimate, as the design model's hold; its derivatives left out of
        # the covariance (small where the rates are)
        rest = np.asarray(self.remainder(self.part.basis @ self.x, u)).ravel()
        turned = s_x @ self.x + self.s_u @ u + self.s_r @ rest
        j_r = _right_jacobian(turned)
        f = np.eye(6 + n)
        f[:3, :3] = rotation_matrix(from_rotation_vector(-turned))
        f[:3, 6:] = j_r @ s_x
        f[6:, 6:] = phi
        g = np.zeros((6 + n, 3))
        g[:3] = j_r @ self.s_u
        g[6:] = self.gamma
        innovation_cov = h @ self.P @ h.T + self.reading_noise
        cross = f @ self.P @ h.T + g @ self.disturbance_cross
        gain = np.linalg.solve(innovation_cov, cross.T).T
        innovation = reading - (turned / t + self.b)
        # the nominal prediction, then the correction in the error state at the sample's end
        self.q = product(self.q, from_rotation_vector(turned))
        self.x = phi @ self.x + self.gamma @ u + self.gamma_r @ rest
        correction = gain @ innovation
        self.q = product(self.q, from_rotation_vector(correction[:3]))
        self.q /= np.linalg.norm(self.q)
        self.b = self.b + correction[3:6]
        self.x = self.x + correction[6:]
        self.P = f @ self.P @ f.T + self.torque_variance * g @ g.T + self.bias_walk \
            - gain @ innovation_cov @ gain.T
        self.P = 0.5 * (self.P + self.P.T)

    _owner = "flexible_mekf"

    def _restore(self, entry) -> None:
        self.q, self.b, self.x, self.P = (v.copy() for v in entry[:4])

    @staticmethod
    def _replayed(entry) -> tuple:
        return tuple(entry[4:])

    def _correct(self, correction) -> None:
        super()._correct(correction)
        self.x = self.x + correction[6:]


class EstimatedStateLaw:
    """A three-axis state-feedback law flown on a :class:`FlexibleAttitudeFilter`'s estimate:
    the design state is the attitude error of the filter's attitude and the filter's flexible
    state (its modal coordinates, hub rate and modal rates; the modes it leaves out at zero).

    Fly it in :func:`~flexctl.sim.spatial_loop.simulate_spatial_loop` with the same filter
    as the loop's ``estimator``: the loop updates the filter at each sample before the law
    reads it.

    Parameters
    ----------
    law : SpatialLQR
        The law (``command(t, design_state)``), designed on the filter's structure, modes and
        variant (its ``state_names`` after the attitude error are the filter's ``names``).
    estimator : FlexibleAttitudeFilter
        The filter it reads.
    """

    #: The loop hands this law the attitude and the rate it reads (not the plant's state).
    state_feedback = False

    def __init__(self, law, estimator):
        from flexctl.model.errors import InputTypeError

        if not callable(getattr(law, "command", None)) or not hasattr(law, "state_names"):
            raise InputTypeError(f"estimated_state_law.law must be a three-axis state-feedback "
                                 f"law (a SpatialLQR); got {type(law).__name__}")
        if not isinstance(estimator, FlexibleAttitudeFilter):
            raise InputTypeError(f"estimated_state_law.estimator must be a "
                                 f"FlexibleAttitudeFilter; got {type(estimator).__name__}")
        if tuple(law.state_names[3:]) != tuple(estimator.names):
            raise InputValueError("estimated_state_law: the law's design state is not the "
                                  "filter's (design both on the same structure, modes and "
                                  "variant)")
        self.law, self.estimator = law, estimator

    def start(self) -> "EstimatedStateLaw":
        """The law itself: it keeps no state of its own (the filter does).

        Returns
        -------
        EstimatedStateLaw
        """
        return self

    def __call__(self, t, attitude, rate) -> np.ndarray:
        state = np.concatenate([error_angles(self.law.target, attitude),
                                self.estimator.flexible_state])
        return self.law.command(t, state)
