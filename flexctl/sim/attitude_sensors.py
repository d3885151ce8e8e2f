"""Three-axis attitude sensors: a star tracker and a rate-integrating gyro, seeded.

:class:`StarTracker` and :class:`Gyro` hold the settings (frozen, validated);
:meth:`AttitudeSensors.start` gives an :class:`AttitudeSensorSession`, the random state of one
run, that turns true attitudes and rates into readings. The same seed gives the same readings.

Notes
-----
**Star tracker.** Every ``sample_time`` (s) it reports the attitude (hub to inertial, a unit
quaternion, scalar first) of ``latency`` s before, perturbed by a small rotation in the hub
frame whose components across the boresight have standard deviation ``cross_noise`` and about
it ``boresight_noise`` (rad): ``q_m = q(t - latency) (x) exp(n / 2)``, ``n = S (n_1, n_2,
n_3)``, ``S`` the tracker's axes in the hub frame (its third the boresight). No reading
inside an outage ``(start, end)``.

**Gyro**, each sample ``k`` of interval ``T``::

    w_m = (I + diag(scale_factor)) (I + misalignment) w + b_k + v_k
    v_k ~ N(0, angle_random_walk^2 / T)                   (white rate noise, averaged)
    b_k = g_k + r_k                                        (the bias)
    g_(k+1) = a g_k + sqrt(1 - a^2) bias_instability e_k,  a = exp(-T / bias_time)
    r_(k+1) = r_k + rate_random_walk sqrt(T) e'_k

``angle_random_walk`` in rad/sqrt(s) (a datasheet's deg/sqrt(h) times pi/180/60),
``rate_random_walk`` in rad/s/sqrt(s), ``bias_instability`` (rad/s) the stationary standard
deviation of a first-order Gauss-Markov bias (the usual engineering reading of the Allan
floor), drawn from its stationary distribution at the start; ``r`` starts at
``initial_bias``. ``misalignment`` is a 3 x 3 matrix of small angles with a zero diagonal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..model.checks import (KeywordOnly, check_array, check_direction, check_integer,
                            check_real)
from ..model.errors import InputTypeError, InputValueError
from .quaternions import from_rotation_vector, product

__all__ = ["StarTracker", "Gyro", "AttitudeSensors", "AttitudeSensorSession"]

#: Largest noise level, rad or rad/s: far beyond any sensor, kept finite when squared.
MAX_NOISE = 1.0


def _frame(boresight) -> np.ndarray:
    """Sensor axes in the hub frame as columns, the third the boresight."""
    z = boresight
    x = np.cross([0.0, 1.0, 0.0] if abs(z[1]) < 0.9 else [1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


@dataclass(frozen=True, kw_only=True)
class StarTracker(KeywordOnly):
    """A star tracker (see the module Notes).

    Parameters
    ----------
    cross_noise : float
        Standard deviation of the attitude error across the boresight, rad (>= 0).
    boresight_noise : float
        Standard deviation about the boresight, rad (>= 0; typically several times
        ``cross_noise``).
    sample_time : float
        Interval between readings, s (> 0).
    boresight : array_like, shape (3,), optional
        Boresight in the hub frame (normalised). Default ``z``.
    latency : float, optional
        Age of a reading when it is reported, s (>= 0, at most 10). Default 0.
    outages : tuple of (float, float), optional
        Intervals ``(start, end)``, s, without readings. Default none.
    """

    cross_noise: float
    boresight_noise: float
    sample_time: float
    boresight: np.ndarray = field(default=(0.0, 0.0, 1.0))
    latency: float = 0.0
    outages: tuple = ()

    def __post_init__(self):
        owner = "star_tracker"
        for name in ("cross_noise", "boresight_noise"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, maximum=MAX_NOISE))
        object.__setattr__(self, "sample_time", check_real(
            owner, "sample_time", self.sample_time, minimum=1e-6, maximum=1e4))
        object.__setattr__(self, "latency", check_real(owner, "latency", self.latency,
                                                       minimum=0.0, maximum=10.0))
        object.__setattr__(self, "boresight", check_direction(owner, "boresight",
                                                              self.boresight))
        if isinstance(self.outages, (str, bytes)) or not hasattr(self.outages, "__iter__"):
            raise InputTypeError(f"star_tracker.outages must be a sequence of (start, end) "
                                 f"pairs, s; got {type(self.outages).__name__}")
        outages = []
        for k, pair in enumerate(self.outages):
            interval = check_array(owner, f"outages[{k}]", pair, shape=(2,))
            if not interval[0] < interval[1]:
                raise InputValueError(f"star_tracker.outages[{k}] must have start < end; got "
                                      f"{interval.tolist()}")
            outages.append((float(interval[0]), float(interval[1])))
        object.__setattr__(self, "outages", tuple(outages))

    def __eq__(self, other):
        return isinstance(other, StarTracker) and all(
            np.array_equal(getattr(self, n), getattr(other, n)) if n == "boresight"
            else getattr(self, n) == getattr(other, n) for n in self.__dataclass_fields__)

    def __hash__(self):
        return hash((self.cross_noise, self.boresight_noise, self.sample_time,
                     self.boresight.tobytes(), self.latency, self.outages))

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of the reading's error rotation in the hub frame, rad^2, (3, 3)."""
        frame = _frame(self.boresight)
        return frame @ np.diag([self.cross_noise ** 2, self.cross_noise ** 2,
                                self.boresight_noise ** 2]) @ frame.T

    def available(self, t: float) -> bool:
        """Whether a reading is reported at ``t`` (outside every outage).

        Parameters
        ----------
        t : float
            Time of the report, s.
        """
        return not any(a <= t < b for a, b in self.outages)


@dataclass(frozen=True, kw_only=True)
class Gyro(KeywordOnly):
    """A three-axis rate gyro (see the module Notes).

    Parameters
    ----------
    angle_random_walk : float
        Angle random walk, rad/sqrt(s) (>= 0).
    bias_instability : float, optional
        Stationary standard deviation of the Gauss-Markov bias, rad/s (>= 0). Default 0.
    bias_time : float, optional
        Its correlation time, s (> 0). Default 300.
    rate_random_walk : float, optional
        Rate random walk, rad/s/sqrt(s) (>= 0). Default 0.
    initial_bias : array_like, shape (3,), optional
        Start of the random-walk part of the bias, rad/s. Default zero.
    misalignment : array_like, shape (3, 3), optional
        Small angles, rad, zero diagonal. Default zero.
    scale_factor : array_like, shape (3,), optional
        Scale factor errors (0.001 is 1000 ppm). Default zero.
    """

    angle_random_walk: float
    bias_instability: float = 0.0
    bias_time: float = 300.0
    rate_random_walk: float = 0.0
    initial_bias: np.ndarray = field(default=(0.0, 0.0, 0.0))
    misalignment: np.ndarray = field(default=((0.0,) * 3,) * 3)
    scale_factor: np.ndarray = field(default=(0.0, 0.0, 0.0))

    def __post_init__(self):
        owner = "gyro"
        for name in ("angle_random_walk", "bias_instability", "rate_random_walk"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, maximum=MAX_NOISE))
        object.__setattr__(self, "bias_time", check_real(owner, "bias_time", self.bias_time,
                                                         minimum=1e-3, maximum=1e9))
        bias = check_array(owner, "initial_bias", self.initial_bias, shape=(3,))
        if np.max(np.abs(bias)) > MAX_NOISE:
            raise InputValueError(f"gyro.initial_bias must be at most {MAX_NOISE:g} rad/s in "
                                  f"magnitude; got {bias.tolist()}")
        misalignment = check_array(owner, "misalignment", self.misalignment, shape=(3, 3))
        if np.any(np.diag(misalignment) != 0) or np.max(np.abs(misalignment)) > 0.1:
            raise InputValueError("gyro.misalignment must be small angles (at most 0.1 rad) "
                                  f"with a zero diagonal; got {misalignment.tolist()}")
        scale = check_array(owner, "scale_factor", self.scale_factor, shape=(3,))
        if np.max(np.abs(scale)) > 0.1:
            raise InputValueError(f"gyro.scale_factor errors must be at most 0.1 in magnitude; "
                                  f"got {scale.tolist()}")
        for name, value in (("initial_bias", bias), ("misalignment", misalignment),
                            ("scale_factor", scale)):
            object.__setattr__(self, name, value)

    def __eq__(self, other):
        return isinstance(other, Gyro) and all(
            np.array_equal(getattr(self, n), getattr(other, n)) for n in self.__dataclass_fields__)

    def __hash__(self):
        return hash(tuple(np.asarray(getattr(self, n)).tobytes()
                          for n in self.__dataclass_fields__))

    @property
    def gain(self) -> np.ndarray:
        """``(I + diag(scale_factor)) (I + misalignment)``, (3, 3)."""
        return (np.eye(3) + np.diag(self.scale_factor)) @ (np.eye(3) + self.misalignment)


@dataclass(frozen=True, kw_only=True)
class AttitudeSensors(KeywordOnly):
    """A star tracker and a gyro read together, with the seed of their noise.

    Parameters
    ----------
    star_tracker : StarTracker
        The star tracker.
    gyro : Gyro
        The gyro.
    gyro_sample_time : float
        Gyro sample interval, s (> 0; the star tracker's is a whole multiple of it).
    seed : int, optional
        Seed of every random draw (>= 0). Default 0.
    """

    star_tracker: StarTracker
    gyro: Gyro
    gyro_sample_time: float
    seed: int = 0

    def __post_init__(self):
        if not isinstance(self.star_tracker, StarTracker):
            raise InputTypeError(f"sensors.star_tracker must be a StarTracker; got "
                                 f"{type(self.star_tracker).__name__}")
        if not isinstance(self.gyro, Gyro):
            raise InputTypeError(f"sensors.gyro must be a Gyro; got {type(self.gyro).__name__}")
        step = check_real("sensors", "gyro_sample_time", self.gyro_sample_time, minimum=1e-6,
                          maximum=1e3)
        object.__setattr__(self, "gyro_sample_time", step)
        ratio = self.star_tracker.sample_time / step
        if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
            raise InputValueError(
                f"star_tracker.sample_time ({self.star_tracker.sample_time:g} s) must be a whole "
                f"multiple of sensors.gyro_sample_time ({step:g} s)")
        object.__setattr__(self, "seed", check_integer("sensors", "seed", self.seed,
                                                       minimum=0))

    @property
    def tracker_every(self) -> int:
        """Gyro samples per star tracker sample."""
        return int(round(self.star_tracker.sample_time / self.gyro_sample_time))

    def start(self, seed: int | None = None) -> "AttitudeSensorSession":
        """The random state of one run.

        Parameters
        ----------
        seed : int, optional
            Overrides :attr:`seed` (a Monte Carlo run's own).

        Returns
        -------
        AttitudeSensorSession
        """
        return AttitudeSensorSession(self, self.seed if seed is None else check_integer(
            "sensors", "seed", seed, minimum=0))


class AttitudeSensorSession:
    """The readings of one run: call :meth:`gyro` once per gyro sample, in order, and
    :meth:`star_tracker` for each star tracker sample.

    Parameters
    ----------
    sensors : AttitudeSensors
        The settings.
    seed : int
        Seed of this run's draws.
    """

    def __init__(self, sensors: AttitudeSensors, seed: int):
        self.sensors = sensors
        self._gyro_random = np.random.default_rng([seed, 1])
        self._tracker_random = np.random.default_rng([seed, 2])
        gyro = sensors.gyro
        self.markov = gyro.bias_instability * self._gyro_random.standard_normal(3)
        self.walk = np.array(gyro.initial_bias, dtype=float)
        self._frame = _frame(sensors.star_tracker.boresight)

    @property
    def bias(self) -> np.ndarray:
        """The gyro's bias now, rad/s, shape (3,)."""
        return self.markov + self.walk

    def gyro(self, rate) -> np.ndarray:
        """One gyro reading of the true rate, then the bias moves on by one sample.

        Parameters
        ----------
        rate : array_like, shape (3,)
            True hub angular velocity, hub frame, rad/s (averaged over the sample).

        Returns
        -------
        ndarray, shape (3,)
            rad/s.
        """
        gyro, step = self.sensors.gyro, self.sensors.gyro_sample_time
        draws = self._gyro_random.standard_normal(9)
        reading = (gyro.gain @ np.asarray(rate, dtype=float) + self.bias
                   + gyro.angle_random_walk / math.sqrt(step) * draws[:3])
        a = math.exp(-step / gyro.bias_time)
        self.markov = a * self.markov + math.sqrt(1 - a * a) * gyro.bias_instability * draws[3:6]
        self.walk = self.walk + gyro.rate_random_walk * math.sqrt(step) * draws[6:9]
        return reading

    def star_tracker(self, attitude) -> np.ndarray:
        """One star tracker reading of a true attitude (the caller hands over the attitude
        of ``latency`` s before).

        Parameters
        ----------
        attitude : array_like, shape (4,)
            True attitude, hub to inertial, scalar first.

        Returns
        -------
        ndarray, shape (4,)
            Unit quaternion.
        """
        tracker = self.sensors.star_tracker
        draws = self._tracker_random.standard_normal(3)
        noise = self._frame @ (np.array([tracker.cross_noise, tracker.cross_noise,
                                         tracker.boresight_noise]) * draws)
        q = product(np.asarray(attitude, dtype=float), from_rotation_vector(noise))
        return q / np.linalg.norm(q)
