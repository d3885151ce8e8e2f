"""Noisy sampled sensors: what a digital controller sees of the plant, late and imperfect.

A set the user chooses (``signals``) of: an attitude sensor (a quantised encoder, or a
sensor with white noise and a bias, or both), a rate gyro, a strain gauge at the root of every
appendage, an accelerometer at every tip, all read once per sample. By default the attitude
sensor and the gyro, and the root gauges or the tip accelerometers only when their noise is
given. :class:`Sensors` holds their settings (frozen, validated); :meth:`Sensors.start` gives a :class:`SensorSession`, the
random state of one run, whose :meth:`~SensorSession.read` turns the plant's true state into
one vector of readings. :func:`measurement_matrix` and :func:`noise_covariance` give the same
readings to a Kalman filter (``controllers.feedback.observer``).

Notes
-----
Readings, ``m`` of them, in this order (:func:`sensor_names`), each block present when its
signal is read (:data:`SIGNALS`, :attr:`Sensors.read_signals`)::

    y = [theta, theta_dot, <a>.root_moment .. <b>.root_moment,
         <a>.tip_acceleration .. <b>.tip_acceleration]

in rad, rad/s, N m and m/s^2 (an unnamed single beam gives ``root_moment`` and
``tip_acceleration``). At sample ``k`` each reads the plant's true state at ``t_k - delay``;
the caller applies the delay and hands that state over. With ``T`` the sample interval:

- attitude: ``step * round((theta + c + v_k) / step)``, ``v_k ~ N(0, attitude_noise^2)``,
  ``c ~ N(0, attitude_bias^2)`` drawn once per run from a stream of its own (so that it
  leaves every other draw as it was); no rounding for ``step = 0``;
- gyro: ``theta_dot + b_k + w_k``, ``w_k ~ N(0, gyro_noise^2 / T)`` (the angle random walk
  averaged over one sample), ``b`` a first-order Gauss-Markov bias of stationary standard
  deviation ``gyro_bias_instability`` and correlation time ``gyro_bias_time`` (``tau``),
  drawn from its stationary distribution at the first sample and propagated exactly,
  ``b_(k+1) = a b_k + sqrt(1 - a^2) sigma e_k``, ``a = exp(-T / tau)``. A datasheet's bias
  instability is the floor of the Allan deviation, not a standard deviation; taking it as
  the standard deviation of a Gauss-Markov bias is the usual engineering simplification;
- root moment: the model's output plus ``N(0, root_moment_noise^2)``;
- tip acceleration: the transverse acceleration of each tip in its appendage's frame,
  ``(b_k + l_k) theta_tt + phi_k(l_k)^T q_tt`` (``b_k`` the root radius), plus the hub
  centre's acceleration along the tip's normal for a free hub, plus
  ``N(0, tip_acceleration_noise^2)``. A small-deflection reading: the products of rates
  (centripetal ``-theta_t^2 w``, the axial acceleration seen through the tip slope) are left
  out; they vanish in the linearisation at rest. It needs the state derivative ``xdot``
  under the command held at the reading (``model.dynamics(t, x, u)``).

Every sample draws ``m + 1`` standard normal numbers (one per reading, one for the bias),
whatever the noise levels, so the same seed gives the same readings and each sensor's noise
does not depend on the others' settings.

Examples
--------
>>> import numpy as np
>>> import flexctl
>>> from flexctl.sim.sensors import Sensors, sensor_names
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> sensors = Sensors(encoder_resolution=1e-3, root_moment_noise=0.01, seed=1)
>>> sensor_names(model, sensors)
('theta', 'theta_dot', 'root_moment')
>>> session = sensors.start(model, sample_time=0.01)
>>> x = model.layout.join(theta=0.12345, theta_dot=0.5)
>>> y = session.read(x)
>>> round(float(y[0]), 6), float(y[1])
(0.123, 0.5)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..model.checks import (KeywordOnly, check_array, check_instance, check_integer,
                            check_real)
from ..model.errors import InputValueError

__all__ = ["Sensors", "SensorSession", "sensor_names", "measurement_matrix",
           "noise_covariance", "MAX_DELAY", "MAX_NOISE", "DEFAULT_SAMPLE_TIME", "VARIANCE_FLOOR",
           "SIGNALS"]

#: The signals a set of sensors may read, in reading order: the hub attitude angle, the hub
#: rate (gyro), the appendages' root bending moments, the tips' accelerations.
SIGNALS = ("attitude", "gyro", "root_moment", "tip_acceleration")
#: The settings of each signal's sensor: given for a signal not read, they are refused.
SIGNAL_SETTINGS = {"attitude": ("encoder_resolution", "attitude_noise", "attitude_bias"),
                   "gyro": ("gyro_noise", "gyro_bias_instability"),
                   "root_moment": ("root_moment_noise",),
                   "tip_acceleration": ("tip_acceleration_noise",)}

#: Sample time of a loop that reads sensors when neither they nor the controller give one, s
#: (100 Hz, a common attitude-control and lab-servo rate).
DEFAULT_SAMPLE_TIME = 0.01
#: Largest noise level (in its reading's SI unit): the filter squares it into a variance and
#: divides that by the sample interval, which must stay finite (1e300 overflowed to inf).
MAX_NOISE = 1e100
#: Longest transport delay, s: a longer one is a typing slip (ms written as s).
MAX_DELAY = 10.0
#: Smallest variance :func:`noise_covariance` gives a reading, in its SI unit squared (rad^2,
#: rad^2/s^2, N^2 m^2, m^2/s^4): an ideal sensor becomes one of standard deviation 1e-6, so
#: that the covariance stays invertible and the filter well conditioned.
VARIANCE_FLOOR = 1e-12


@dataclass(frozen=True, kw_only=True)
class Sensors(KeywordOnly):
    """Settings of the sensors a sampled controller reads (see the module Notes).

    Parameters
    ----------
    seed : int or None
        Seed of ``numpy.random.default_rng`` (>= 0); the same seed gives the same readings.
        ``None``: fresh entropy at every run. Default 0.
    encoder_resolution : float
        Quantisation step of the attitude reading, rad (>= 0; 0: not quantised). Default 0.
    attitude_noise : float
        Standard deviation of the attitude reading's white noise, rad (>= 0), as of a star
        tracker or an attitude estimate. Default 0.
    attitude_bias : float
        Standard deviation of the attitude reading's constant bias, rad (>= 0), drawn once per
        run. Default 0.
    gyro_noise : float
        Angle random walk of the rate gyro, rad/sqrt(s) (>= 0). Default 0.
    gyro_bias_instability : float
        Stationary standard deviation of the gyro bias, rad/s (>= 0). Default 0.
    gyro_bias_time : float
        Correlation time of the bias, s (> 0). Default 100.
    root_moment_noise : float or None
        Standard deviation of each root bending moment reading, N m (>= 0); ``None``: no
        root gauges, unless ``signals`` lists them (then exact). Default None.
    tip_acceleration_noise : float or None
        Standard deviation of each tip accelerometer reading, m/s^2 (>= 0); ``None``: no tip
        accelerometers. Default None.
    delay : float
        Transport delay of every reading, s (in [0, :data:`MAX_DELAY`]). Default 0.
    sample_time : float or None
        Sample interval of the readings, s (> 0); ``None``: the controller's. Default None.
    signals : sequence of str or None
        The signals read, among :data:`SIGNALS` (read in that order whatever the order
        given); a setting of a sensor not listed is refused by name. ``None`` (default):
        attitude and gyro, and the root moments and tip accelerations when their noise is
        given.
    """

    seed: int | None = 0
    encoder_resolution: float = 0.0
    attitude_noise: float = 0.0
    attitude_bias: float = 0.0
    gyro_noise: float = 0.0
    gyro_bias_instability: float = 0.0
    gyro_bias_time: float = 100.0
    root_moment_noise: float | None = None
    tip_acceleration_noise: float | None = None
    delay: float = 0.0
    sample_time: float | None = None
    signals: tuple | None = None

    def __post_init__(self):
        if self.seed is not None:
            object.__setattr__(self, "seed", check_integer("sensors", "seed", self.seed,
                                                           minimum=0))
        self._set("encoder_resolution", minimum=0.0)
        for name in ("attitude_noise", "attitude_bias", "gyro_noise", "gyro_bias_instability"):
            self._set(name, minimum=0.0, maximum=MAX_NOISE)
        self._set("gyro_bias_time", minimum=0.0, strict=True)
        for name in ("root_moment_noise", "tip_acceleration_noise"):
            self._set(name, minimum=0.0, optional=True, maximum=MAX_NOISE)
        self._set("delay", minimum=0.0, maximum=MAX_DELAY)
        self._set("sample_time", minimum=0.0, strict=True, optional=True)
        if self.signals is not None:
            object.__setattr__(self, "signals", self._checked_signals(self.signals))

    def _checked_signals(self, signals) -> tuple:
        """``signals`` as a tuple in :data:`SIGNALS` order; refused when unknown, repeated,
        empty, or leaving out a sensor whose setting is given."""
        if isinstance(signals, str) or not isinstance(signals, (list, tuple)) or not signals:
            raise InputValueError(f"sensors.signals must be a non-empty list of "
                                  f"{', '.join(SIGNALS)}; got {signals!r}")
        for name in signals:
            if name not in SIGNALS or list(signals).count(name) > 1:
                raise InputValueError(f"sensors.signals must list each of "
                                      f"{', '.join(SIGNALS)} at most once; got {signals!r}")
        for signal, settings in SIGNAL_SETTINGS.items():
            for name in settings:
                value = getattr(self, name)
                if signal not in signals and value not in (None, 0.0):
                    raise InputValueError(
                        f"sensors.{name} is a setting of the {signal} sensor, which "
                        f"sensors.signals does not list ({', '.join(signals)}): add "
                        f"{signal!r} to the signals or remove it; got {value!r}")
        return tuple(name for name in SIGNALS if name in signals)

    @property
    def read_signals(self) -> tuple:
        """The signals read, in reading order (:data:`SIGNALS`): :attr:`signals`, or by
        default the attitude and the gyro, with the root moments and the tip accelerations
        when their noise is given."""
        if self.signals is not None:
            return self.signals
        return ("attitude", "gyro") \
            + (("root_moment",) if self.root_moment_noise is not None else ()) \
            + (("tip_acceleration",) if self.tip_acceleration_noise is not None else ())

    @property
    def attitude_variance(self) -> float:
        """Variance of the attitude reading's error, rad^2: the quantisation taken as uniform
        noise (``step^2 / 12``), the white noise and the constant bias's spread."""
        return (self.encoder_resolution ** 2 / 12.0 + self.attitude_noise ** 2
                + self.attitude_bias ** 2)

    def _set(self, name: str, **rule):
        object.__setattr__(self, name, check_real("sensors", name, getattr(self, name), **rule))

    @property
    def has_accelerometers(self) -> bool:
        """True when the tips carry accelerometers."""
        return "tip_acceleration" in self.read_signals

    def interval(self, controller_sample_time: float) -> float:
        """The sample interval of the readings, s: :attr:`sample_time`, or the controller's
        when that is ``None``.

        Parameters
        ----------
        controller_sample_time : float
            The controller's sample time, s (> 0); read only when :attr:`sample_time` is
            None.
        """
        if self.sample_time is not None:
            return self.sample_time
        return check_real("sensors", "sample_time", controller_sample_time, minimum=0.0,
                          strict=True)

    def noiseless(self) -> "Sensors":
        """The same sampling and delay with exact readings (no quantisation, noise or bias)."""
        return dataclasses.replace(
            self, encoder_resolution=0.0, attitude_noise=0.0, attitude_bias=0.0,
            gyro_noise=0.0, gyro_bias_instability=0.0,
            root_moment_noise=None if self.root_moment_noise is None else 0.0,
            tip_acceleration_noise=None if self.tip_acceleration_noise is None else 0.0)

    def start(self, model, sample_time: float) -> "SensorSession":
        """A fresh :class:`SensorSession` reading ``model`` every ``sample_time`` s (> 0).

        Parameters
        ----------
        model : Model
            The plant read.
        sample_time : float
            Sample interval of the readings, s (> 0).
        """
        return SensorSession(self, model, sample_time)

    def __repr__(self):
        read, parts = self.read_signals, []
        if "attitude" in read:
            errors = [f"{what} {value:g} rad" for what, value in (
                ("step", self.encoder_resolution), ("noise", self.attitude_noise),
                ("bias", self.attitude_bias)) if value]
            parts.append("attitude " + (" ".join(errors) if errors else "exact"))
        if "gyro" in read:
            parts.append(f"gyro ARW {self.gyro_noise:g} rad/sqrt(s), bias "
                         f"{self.gyro_bias_instability:g} rad/s over {self.gyro_bias_time:g} s")
        if "root_moment" in read:
            parts.append(f"root moment {self.root_moment_noise or 0.0:g} N m")
        if "tip_acceleration" in read:
            parts.append(f"tip accelerometers {self.tip_acceleration_noise or 0.0:g} m/s^2")
        parts += [f"delay {self.delay:g} s",
                 "controller's sample time" if self.sample_time is None
                 else f"sample time {self.sample_time:g} s",
                 f"seed {self.seed}"]
        return f"Sensors({', '.join(parts)})"


def _root_outputs(model) -> list:
    """Indices of the root bending moments among the model's outputs, in output order."""
    return [k for k, name in enumerate(model.output_names) if name.endswith("root_moment")]


def _root_rows(model) -> np.ndarray:
    """Rows ``R`` (shape (K, n)) with the root bending moments ``R @ x``, N m, in output
    order: ``EI w''(0) = sum_i EI phi_i''(0) q_i`` is linear in the modal coordinates for
    every variant (the exact one's curvature is the slope angle's derivative, itself linear
    in them), so a sample reads them without a call of the model's outputs."""
    return np.vstack([model.layout.embed(row)
                      for row in np.atleast_2d(np.asarray(model.matrices.root, dtype=float))])


def sensor_names(model, sensors: Sensors) -> tuple:
    """Names of the readings of ``sensors`` on ``model``, in reading order (module Notes).

    Parameters
    ----------
    model : Model
        Tells the root moments' and the appendages' names.
    sensors : Sensors
        Tells whether the tips carry accelerometers.

    Returns
    -------
    tuple of str
        ``m`` names.
    """
    read = sensors.read_signals
    names = (("theta",) if "attitude" in read else ()) \
        + (("theta_dot",) if "gyro" in read else ())
    if "root_moment" in read:
        names += tuple(model.output_names[k] for k in _root_outputs(model))
    if sensors.has_accelerometers:
        names += tuple(f"{name}.tip_acceleration" if name else "tip_acceleration"
                       for name in model.structure.names)
    return names


def _tip_acceleration_rows(model, theta: float = 0.0) -> np.ndarray:
    """Rows ``r_k`` (shape (K, n)) with tip acceleration ``k`` = ``r_k @ xdot``, at hub angle
    ``theta`` (rad; it turns a free hub's acceleration into the tip's normal)."""
    layout, structure = model.layout, model.structure
    tips = np.asarray(model.tip_matrix, dtype=float)
    rows = np.zeros((len(structure.appendages), layout.n_states))
    for k, app in enumerate(structure.appendages):
        rows[k] = layout.embed(tips[k], "q_dot")
        rows[k, layout.theta_dot] = structure.root_radius(app) + app.beam.length
        if layout.hub_velocity is not None:
            turn = app.angle + theta
            rows[k, layout.hub_velocity] = (-math.sin(turn), math.cos(turn))
    return rows


def measurement_matrix(model, sensors: Sensors) -> tuple:
    """The noiseless readings' linear map at rest, ``y = C x + D u``.

    Parameters
    ----------
    model : flexctl.Model
        The plant read (its linearisation at rest and its outputs).
    sensors : Sensors
        What is read: the tip accelerations only when the sensors have accelerometers.

    Returns
    -------
    C : ndarray, shape (m, n)
        Rows in :func:`sensor_names` order; the root moments are ``model.output_matrix``'s
        rows, each tip acceleration its row over ``xdot`` (module Notes) times ``A``.
    D : ndarray, shape (m, 1)
        Zero but for the tip accelerations, which the torque moves directly (``r_k B``),
        with ``A``, ``B`` from ``model.linear_matrices(0.0)``.
    """
    layout, read = model.layout, sensors.read_signals
    rows = [np.zeros((0, layout.n_states))]
    rows += [layout.embed(1.0, "theta")[None, :]] if "attitude" in read else []
    rows += [layout.embed(1.0, "theta_dot")[None, :]] if "gyro" in read else []
    if "root_moment" in read:
        rows.append(np.asarray(model.output_matrix, dtype=float)[_root_outputs(model)])
    c = np.vstack(rows)
    d = np.zeros((c.shape[0], 1))
    if sensors.has_accelerometers:
        a, b = model.linear_matrices(0.0)
        rows = _tip_acceleration_rows(model)
        c, d = np.vstack((c, rows @ a)), np.vstack((d, rows @ b))
    return c, d


def _variances(model, sensors: Sensors, sample_time: float, with_bias: bool) -> np.ndarray:
    """Each reading's noise variance, unfloored (see :func:`noise_covariance`)."""
    read = sensors.read_signals
    gyro = sensors.gyro_noise ** 2 / sample_time
    if not with_bias:
        gyro += sensors.gyro_bias_instability ** 2
    roots = len(_root_outputs(model)) if "root_moment" in read else 0
    tips = len(model.structure.names) if sensors.has_accelerometers else 0
    return np.array(([sensors.attitude_variance] if "attitude" in read else [])
                    + ([gyro] if "gyro" in read else [])
                    + [(sensors.root_moment_noise or 0.0) ** 2] * roots
                    + [(sensors.tip_acceleration_noise or 0.0) ** 2] * tips, dtype=float)


def noise_covariance(model, sensors: Sensors, sample_time: float, *,
                     with_bias: bool = False) -> np.ndarray:
    """Diagonal measurement-noise covariance ``R`` of the readings for a discrete Kalman filter.

    Parameters
    ----------
    model : flexctl.Model
        Tells how many root moments and tips there are.
    sensors : Sensors
        The sensors' noise levels, quantisation and gyro bias.
    sample_time : float
        Sample interval ``T``, s (> 0).
    with_bias : bool, optional
        True when the filter estimates the gyro bias as a state: the gyro's variance is then
        its white part ``gyro_noise^2 / T`` alone; False (default) adds the bias variance
        ``gyro_bias_instability^2`` as if it were white.

    Returns
    -------
    ndarray, shape (m, m)
        In :func:`sensor_names` order: the encoder's quantisation as uniform noise,
        ``step^2 / 12``, plus the attitude's white noise and bias variances; the gyro's
        (above); ``root_moment_noise^2`` and
        ``tip_acceleration_noise^2``. A variance below :data:`VARIANCE_FLOOR` (an exact
        sensor) is raised to it, so that ``R`` stays invertible.
    """
    sample_time = check_real("noise_covariance", "sample_time", sample_time, minimum=0.0,
                             strict=True)
    return np.diag(np.maximum(_variances(model, sensors, sample_time, bool(with_bias)),
                              VARIANCE_FLOOR))


class SensorSession:
    """The readings of one run: the sensors' random state and their true values.

    Made by :meth:`Sensors.start`. Attributes: ``sensors``, ``model``, ``sample_time`` (s),
    ``names`` (:func:`sensor_names`), ``samples`` (readings taken), ``bias``, the gyro bias
    of the latest reading (before the first one: of the first one), rad/s, and
    ``attitude_offset``, the attitude reading's constant bias of this run, rad.

    Parameters
    ----------
    sensors : Sensors
        The sensors read; their ``seed`` starts the random state.
    model : Model
        The plant read.
    sample_time : float
        Sample interval of the readings, s (> 0).
    """

    def __init__(self, sensors: Sensors, model, sample_time: float):
        check_instance("sensors.start", "sensors", sensors, Sensors)
        self.sensors, self.model = sensors, model
        self.sample_time = check_real("sensors.start", "sample_time", sample_time,
                                      minimum=0.0, strict=True)
        self.names = sensor_names(model, sensors)
        self.samples = 0
        read = sensors.read_signals
        self._attitude = 0 if "attitude" in read else None
        self._gyro = int("attitude" in read) if "gyro" in read else None
        self._roots = _root_rows(model) if "root_moment" in read else None
        # white parts only: the encoder quantises, the biases are states of their own
        white = np.sqrt(_variances(model, sensors, self.sample_time, with_bias=True))
        if self._attitude is not None:
            white[self._attitude] = sensors.attitude_noise
        self._white = white
        # a stream of its own, so that the attitude bias leaves every other draw as it was
        offset = np.random.default_rng(None if sensors.seed is None else (sensors.seed, 1))
        self.attitude_offset = sensors.attitude_bias * float(offset.standard_normal())
        self._decay = math.exp(-self.sample_time / sensors.gyro_bias_time)
        self._innovation = sensors.gyro_bias_instability * math.sqrt(
            -math.expm1(-2.0 * self.sample_time / sensors.gyro_bias_time))
        self._rng = np.random.default_rng(sensors.seed)
        self.bias = sensors.gyro_bias_instability * float(self._rng.standard_normal())

    def _state(self, x, name: str = "x") -> np.ndarray:
        return check_array("sensors.read", name, x, shape=(self.model.layout.n_states,))

    def true_values(self, x, xdot=None) -> np.ndarray:
        """The noiseless, unquantised readings of state ``x`` (n,), shape (m,).

        Parameters
        ----------
        x : array_like, shape (n,)
            The plant's true state, in the order of ``model.layout``.
        xdot : array_like, shape (n,), optional
            The state derivative under the held command; needed when the tips carry
            accelerometers.
        """
        x = self._state(x)
        layout = self.model.layout
        values = [x[layout.theta]] if self._attitude is not None else []
        values += [x[layout.theta_dot]] if self._gyro is not None else []
        values += [] if self._roots is None else list(self._roots @ x)
        if self.sensors.has_accelerometers:
            if xdot is None:
                raise InputValueError(
                    "sensors.read xdot must be given when the tips carry accelerometers "
                    "(tip_acceleration_noise is set): pass model.dynamics(t, x, u) under the "
                    "held command; got None")
            xdot = self._state(xdot, "xdot")
            values += list(_tip_acceleration_rows(self.model, float(x[layout.theta])) @ xdot)
        return np.array(values, dtype=float)

    def read(self, x, xdot=None) -> np.ndarray:
        """One reading of every sensor from the (already delayed) true state ``x`` (n,),
        advancing the noise by one sample; shape (m,), in ``names`` order.

        Parameters
        ----------
        x : array_like, shape (n,)
            The plant's true state, in the order of ``model.layout``.
        xdot : array_like, shape (n,), optional
            The state derivative under the held command; needed when the tips carry
            accelerometers.
        """
        return self.measure(x, xdot)[0]

    def measure(self, x, xdot=None) -> tuple:
        """:meth:`read` and :meth:`true_values` of one sample together: ``(readings,
        values)``, each shape (m,).

        Parameters
        ----------
        x : array_like, shape (n,)
            The plant's true state, in the order of ``model.layout``.
        xdot : array_like, shape (n,), optional
            The state derivative under the held command; needed when the tips carry
            accelerometers.
        """
        values = self.true_values(x, xdot)
        draws = self._rng.standard_normal(values.size + 1)
        if self.samples:
            self.bias = self._decay * self.bias + self._innovation * float(draws[-1])
        readings = values + self._white * draws[:-1]
        if self._gyro is not None:
            readings[self._gyro] += self.bias
        k = self._attitude
        if k is not None:
            readings[k] += self.attitude_offset
            step = self.sensors.encoder_resolution
            if step:
                readings[k] = step * np.round(readings[k] / step)
        self.samples += 1
        return readings, values

    def __repr__(self):
        return (f"SensorSession({len(self.names)} readings every {self.sample_time:g} s, "
                f"{self.samples} taken, gyro bias {self.bias:.3g} rad/s)")
