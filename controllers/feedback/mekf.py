"""A multiplicative extended Kalman filter of attitude and gyro bias.

:class:`AttitudeFilter` estimates the hub attitude ``q`` (hub to inertial, scalar first) and
the gyro bias ``b`` from the readings of :mod:`flexctl.sim.attitude_sensors`: it propagates
with every gyro reading and updates with every star tracker reading, a late one (its
``latency``) applied where it belongs by going back to the stored estimate of that time and
propagating the gyro readings since again.

Notes
-----
Error state ``dx = (dtheta, db)`` (6): ``q = q_hat (x) exp(dtheta / 2)`` (a rotation in the
hub frame) and ``db = b - b_hat``. With ``w_hat = w_m - b_hat`` over a gyro interval ``T``
(Markley and Crassidis, *Fundamentals of Spacecraft Attitude Determination and Control*,
2014, section 6.2)::

    q_hat <- q_hat (x) exp(w_hat T / 2)
    Phi   = [[exp(-[w_hat x] T), -T I + T^2 / 2 [w_hat x]], [0, I]]
    Q     = [[s_v^2 T + s_u^2 T^3 / 3, -s_u^2 T^2 / 2], [-s_u^2 T^2 / 2, s_u^2 T]] (x) I_3

``s_v`` the gyro's angle random walk and ``s_u^2`` the bias's rate random walk squared plus
``2 bias_instability^2 / bias_time`` (its Gauss-Markov part taken as a random walk of the
same short-term growth: the filter then slightly over-states the bias's wander over times
longer than ``bias_time``). A star tracker reading ``q_m`` gives the residual ``z =
dtheta(q_hat, q_m)`` with ``H = [I, 0]`` and the tracker's covariance ``R``; the update is
Joseph's form, and the correction moves ``q_hat`` and ``b_hat`` and resets ``dtheta`` to
zero. The gyro's scale factor and misalignment are not estimated (they are noise to the
filter). The appendages' modes are not in this filter.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from flexctl.model.checks import check_array
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.attitude_sensors import AttitudeSensors
from flexctl.model.spatial_rod import cross_matrix
from flexctl.sim.quaternions import (error_angles, from_rotation_vector, product,
                                     rotation_matrix)

__all__ = ["AttitudeFilter"]


class AttitudeFilter:
    """The multiplicative extended Kalman filter (see the module Notes).

    Parameters
    ----------
    sensors : AttitudeSensors
        The sensors it reads: their noise sets its covariances, the gyro's sample time its
        step, the star tracker's latency (a whole number of gyro samples) how far back an
        update goes.
    attitude : array_like, shape (4,)
        Initial estimate of the attitude, hub to inertial, scalar first.
    attitude_sigma : float
        Standard deviation of its error about each axis, rad (> 0).
    bias : array_like, shape (3,), optional
        Initial bias estimate, rad/s. Default zero.
    bias_sigma : float, optional
        Standard deviation of its error per axis, rad/s (> 0). Default 1e-4.

    Examples
    --------
    >>> from flexctl.sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker
    >>> sensors = AttitudeSensors(star_tracker=StarTracker(cross_noise=1e-5,
    ...     boresight_noise=5e-5, sample_time=1.0), gyro=Gyro(angle_random_walk=1e-5),
    ...     gyro_sample_time=0.1)
    >>> estimator = AttitudeFilter(sensors, attitude=[1, 0, 0, 0], attitude_sigma=1e-3)
    >>> estimator.propagate([0.0, 0.0, 0.01])
    >>> round(float(estimator.attitude[3]), 6)
    0.0005
    """

    def __init__(self, sensors: AttitudeSensors, attitude, attitude_sigma: float,
                 bias=(0.0, 0.0, 0.0), bias_sigma: float = 1e-4):
        if not isinstance(sensors, AttitudeSensors):
            raise InputTypeError(f"mekf.sensors must be AttitudeSensors; got "
                                 f"{type(sensors).__name__}")
        q = np.array(check_array("mekf", "attitude", attitude, shape=(4,)))
        if not np.linalg.norm(q) > 0:
            raise InputValueError("mekf.attitude must be a non-zero quaternion")
        for name, value in (("attitude_sigma", attitude_sigma), ("bias_sigma", bias_sigma)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not 0.0 < value < 10.0:
                raise InputValueError(f"mekf.{name} must be in (0, 10); got {value!r}")
        self.sensors = sensors
        self.step = sensors.gyro_sample_time
        lag = sensors.star_tracker.latency / self.step
        if abs(lag - round(lag)) > 1e-9 * max(lag, 1.0):
            raise InputValueError(
                f"star_tracker.latency ({sensors.star_tracker.latency:g} s) must be a whole "
                f"number of gyro samples ({self.step:g} s) for the filter")
        self.lag = int(round(lag))
        self.q = q / np.linalg.norm(q)
        self.b = np.array(check_array("mekf", "bias", bias, shape=(3,)))
        self.P = np.diag([attitude_sigma ** 2] * 3 + [bias_sigma ** 2] * 3)
        gyro = sensors.gyro
        self.sigma_v = gyro.angle_random_walk
        self.sigma_u2 = gyro.rate_random_walk ** 2 + 2 * gyro.bias_instability ** 2 \
            / gyro.bias_time
        self.R = sensors.star_tracker.covariance
        self.history = deque(maxlen=self.lag + 1)      # (q, b, P, gyro reading) per sample

    @property
    def attitude(self) -> np.ndarray:
        """Estimated attitude, hub to inertial, scalar first, shape (4,)."""
        return self.q.copy()

    @property
    def bias(self) -> np.ndarray:
        """Estimated gyro bias, rad/s, shape (3,)."""
        return self.b.copy()

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of ``(dtheta, db)``, shape (6, 6) (rad^2, rad^2/s, rad^2/s^2)."""
        return self.P.copy()

    def propagate(self, gyro_reading) -> None:
        """Advance by one gyro sample.

        Parameters
        ----------
        gyro_reading : array_like, shape (3,)
            The gyro's reading over the sample, rad/s.
        """
        reading = self._gyro_reading(gyro_reading)
        self.history.append((self.q.copy(), self.b.copy(), self.P.copy(), reading))
        self._advance(reading)
        self._check_finite(reading)

    def _gyro_reading(self, gyro_reading) -> np.ndarray:
        """A gyro reading checked: three finite rates of at most ``MAX_SPIN`` rad/s."""
        from flexctl.sim.spatial_run import MAX_SPIN

        reading = np.array(check_array(self._owner, "gyro_reading", gyro_reading, shape=(3,)))
        if np.max(np.abs(reading)) > MAX_SPIN:
            raise InputValueError(f"{self._owner}.gyro_reading must be at most {MAX_SPIN:g} "
                                  f"rad/s in magnitude; got {reading.tolist()}")
        return reading

    def _check_finite(self, reading) -> None:
        """Refuse to go on from an estimate that left the finite numbers."""
        if not (np.all(np.isfinite(self.q)) and np.all(np.isfinite(self.P))):
            raise InputValueError(f"{self._owner}: the estimate left the finite numbers after "
                                  f"the gyro reading {np.asarray(reading).tolist()} (a reading "
                                  "or an input far outside the model's range)")

    def _advance(self, reading) -> None:
        t = self.step
        w = reading - self.b
        self.q = product(self.q, from_rotation_vector(w * t))
        self.q /= np.linalg.norm(self.q)
        phi = np.eye(6)
        phi[:3, :3] = rotation_matrix(from_rotation_vector(-w * t))
        phi[:3, 3:] = -t * np.eye(3) + 0.5 * t * t * cross_matrix(w)
        s_v2, s_u2 = self.sigma_v ** 2, self.sigma_u2
        q = np.zeros((6, 6))
        q[:3, :3] = (s_v2 * t + s_u2 * t ** 3 / 3) * np.eye(3)
        q[:3, 3:] = q[3:, :3] = -s_u2 * t * t / 2 * np.eye(3)
        q[3:, 3:] = s_u2 * t * np.eye(3)
        self.P = phi @ self.P @ phi.T + q
        self.P = 0.5 * (self.P + self.P.T)

    def update(self, measured) -> np.ndarray:
        """Take a star tracker reading (taken ``latency`` s ago, when reported now).

        Parameters
        ----------
        measured : array_like, shape (4,)
            The reading, hub to inertial, scalar first.

        Returns
        -------
        ndarray, shape (3,)
            The residual, rad (before the update).
        """
        owner = self._owner
        q_m = np.array(check_array(owner, "measured", measured, shape=(4,)))
        if not np.linalg.norm(q_m) > 0:
            raise InputValueError(f"{owner}.measured must be a non-zero quaternion")
        replay = []
        if self.lag:
            if len(self.history) < self.lag:
                raise InputValueError(
                    f"a star tracker reading {self.lag} gyro samples old came before the filter "
                    f"had propagated that many ({len(self.history)})")
            entries = list(self.history)[-self.lag:]
            self._restore(entries[0])
            replay = [self._replayed(entry) for entry in entries]
        residual = error_angles(self.q, q_m / np.linalg.norm(q_m))
        size = self.P.shape[0]
        h = np.zeros((3, size))
        h[:, :3] = np.eye(3)
        gain = self.P @ h.T @ np.linalg.inv(h @ self.P @ h.T + self.R)
        self._correct(gain @ residual)
        keep = np.eye(size) - gain @ h
        self.P = keep @ self.P @ keep.T + gain @ self.R @ gain.T
        if replay:
            kept = list(self.history)[:-self.lag]
            self.history = deque(kept, maxlen=self.lag + 1)
            for arguments in replay:
                self.propagate(*arguments)
        return residual

    #: Who the errors of :meth:`update` name.
    _owner = "mekf"

    def _restore(self, entry) -> None:
        """Go back to a stored sample's estimate."""
        self.q, self.b, self.P = (v.copy() for v in entry[:3])

    @staticmethod
    def _replayed(entry) -> tuple:
        """What :meth:`propagate` takes again for a stored sample."""
        return (entry[3],)

    def _correct(self, correction) -> None:
        """Move the estimate by an error-state correction ``(dtheta, db, ...)``."""
        self.q = product(self.q, from_rotation_vector(correction[:3]))
        self.q /= np.linalg.norm(self.q)
        self.b = self.b + correction[3:6]
