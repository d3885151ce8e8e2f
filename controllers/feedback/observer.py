"""Observed: a sampled output-feedback controller, a state law on a discrete Kalman estimate.

The flight computer never sees the state: it reads noisy, quantised, late sensors
(:class:`flexctl.sim.sensors.Sensors`) once per sample. :class:`Observed` runs a discrete
Kalman filter on the model's linearisation at rest, discretised with the zero-order hold of
the command, and hands the estimate to a static state law (PD, LQR, a tracker or a callable
``law(t, x)``). It estimates the gyro bias too when the gyro has one. Its class attribute
``measures = True`` tells the simulation to hand :meth:`ObservedSession.step` the sensor
readings instead of the state. :func:`kalman_step` is the filter as a pure function.

Notes
-----
``n`` plant states (``model.layout``), ``m`` readings (:func:`~flexctl.sim.sensors.sensor_names`),
filter state ``z`` of ``n_f = n`` entries, or ``n + 1`` when the gyro has a bias::

    z = [x (model.layout order), b (gyro bias, rad/s)]
    z(t + h) = Phi(h) z(t) + Gamma(h) (u + w),   w ~ N(0, process_noise^2) held over h
    y_k = C z(t_k - d) + D u(t_k - d) + v_k,     v_k ~ N(0, R)

``Phi``, ``Gamma`` are the zero-order hold of ``model.linear_matrices(0.0)`` (and
``exp(-h / tau)`` for the bias, whose process noise keeps its stationary variance); ``C``,
``D``, ``R`` come from :func:`~flexctl.sim.sensors.measurement_matrix` and
:func:`~flexctl.sim.sensors.noise_covariance` (the gyro's white part alone when the bias is a
state). ``Q(h) = Gamma Gamma^T process_noise^2`` on the plant block.

The transport delay ``d = sensors.delay``: the filter estimates the state at the reading
epochs ``t_k - d``. At each sample it predicts from the previous epoch to ``t_k - d``,
updates with ``y_k``, extrapolates the estimate to ``t_k`` with the commands held over
``[t_k - d, t_k)`` (exact for the linear model), applies the law there, and keeps the
command. Every propagation walks the recorded commands piece by piece (each piece's hold is
cached by its length), so any delay up to :data:`flexctl.sim.sensors.MAX_DELAY` is handled;
the process noise of a piece is taken independent of its neighbours'. Before the first sample
the plant is taken as held at ``x0`` (a reading of an earlier time is of ``x0``), and a reading
at a command switch sees the command held before it (the sensors read before the new command
is applied).

The command is clipped to ``model.actuator.command_limit`` when the model has an actuator
with a finite limit: the filter predicts with what the plant receives (the estimator's
anti-windup), and the clipped command is returned.

Examples
--------
>>> import numpy as np
>>> import flexctl
>>> from controllers.feedback.observer import Observed
>>> from flexctl.sim.sensors import Sensors
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> law = lambda t, x: -3.0 * x[0] - 4.0 * x[3]
>>> observed = Observed(law, Sensors(gyro_noise=1e-4, gyro_bias_instability=1e-3),
...                     sample_time=0.01)
>>> session = observed.start(model, np.zeros(model.n_states))
>>> sensors = observed.sensors.start(model, 0.01)
>>> u = session.step(0.0, sensors.read(np.zeros(model.n_states)))
>>> session.report()["samples"], session.estimates.shape
(1, (1, 6))
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from flexctl.model.checks import check_array, check_instance, check_real
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.digital import is_sampled
from flexctl.sim.drives import bound_to_plant
from flexctl.sim.inputs import input_value, time_function
from flexctl.sim.sensors import (VARIANCE_FLOOR, Sensors, measurement_matrix,
                                 noise_covariance, sensor_names)

__all__ = ["Observed", "ObservedSession", "FilterMatrices", "FilterModel", "kalman_update",
           "kalman_predict", "kalman_step"]


# ---------------------------------------------------------------------- pure functions
def kalman_update(x_pred, p_pred, y, C, R, offset=0.0) -> tuple:
    """Measurement update of a Kalman filter (Joseph form, so ``P`` stays symmetric).

    Returns ``x_plus`` (n_f,), ``p_plus`` (n_f, n_f), the innovation ``y - C x_pred - offset``
    (m,) and its covariance ``S = C P C^T + R`` (m, m).

    Parameters
    ----------
    x_pred : ndarray, shape (n_f,)
        The predicted filter state at the reading.
    p_pred : ndarray, shape (n_f, n_f)
        Its covariance.
    y : ndarray, shape (m,)
        The readings, in their sensors' units.
    C : ndarray, shape (m, n_f)
        Readings per filter state.
    R : ndarray, shape (m, m)
        Covariance of the readings' noise.
    offset : float or ndarray, shape (m,), optional
        The input's part of the readings, ``D u``. Default 0.
    """
    innovation = y - C @ x_pred - offset
    s = C @ p_pred @ C.T + R
    # numpy's solve: the innovation covariance is a few readings square, and SciPy's checks
    # cost ten times its arithmetic at every sample of a loop
    gain = np.linalg.solve(s, C @ p_pred).T
    keep = np.eye(p_pred.shape[0]) - gain @ C
    p_plus = keep @ p_pred @ keep.T + gain @ R @ gain.T
    return x_pred + gain @ innovation, 0.5 * (p_plus + p_plus.T), innovation, s


def kalman_predict(x, p, u, Ad, Bd, Q) -> tuple:
    """Time update over one hold: ``Ad x + Bd u`` and ``Ad P Ad^T + Q``.

    Parameters
    ----------
    x : ndarray, shape (n_f,)
        The filter state at the start of the hold.
    p : ndarray, shape (n_f, n_f)
        Its covariance.
    u : float
        The command held: the model's input (N m for a hub torque, V for a DC motor).
    Ad : ndarray, shape (n_f, n_f)
        ``Phi``: the state over the hold.
    Bd : ndarray, shape (n_f, 1)
        ``Gamma``: the held command's effect over the hold.
    Q : ndarray, shape (n_f, n_f)
        Process noise covariance added over the hold.
    """
    p_pred = Ad @ p @ Ad.T + Q
    return Ad @ x + Bd[:, 0] * u, 0.5 * (p_pred + p_pred.T)


def kalman_step(x_hat, p, y, u, Ad, Bd, C, D, Q, R, *, u_held=None) -> tuple:
    """One sample of a discrete Kalman filter: update with ``y``, then predict with ``u``.

    Parameters
    ----------
    x_hat : array_like, shape (n_f,)
        The prediction at the reading.
    p : array_like, shape (n_f, n_f)
        Its covariance.
    y : array_like, shape (m,)
        The readings: ``y = C x + D u_held + v``.
    u : float
        The command held from this sample to the next, N m (the model's input).
    Ad, Bd : array_like, shapes (n_f, n_f) and (n_f, 1)
        The hold over one sample: ``x' = Ad x + Bd u``.
    C, D : array_like, shapes (m, n_f) and (m, 1)
        Readings per filter state and per held command.
    Q : array_like, shape (n_f, n_f)
        Process noise covariance over one sample.
    R : array_like, shape (m, m)
        Covariance of the readings' noise ``v``.
    u_held : float, optional
        The command held when ``y`` was read (the ``D`` term), in ``u``'s unit. Default
        ``u``.

    Returns
    -------
    x_hat_plus, p_plus : ndarray, shapes (n_f,), (n_f, n_f)
        The estimate after the update, and its covariance.
    x_pred, p_pred : ndarray
        The prediction for the next sample.
    """
    x_hat = check_array("kalman_step", "x_hat", x_hat, shape=(None,))
    n, m = x_hat.size, np.size(y)
    args = {"p": (p, (n, n)), "y": (y, (m,)), "Ad": (Ad, (n, n)), "Bd": (Bd, (n, 1)),
            "C": (C, (m, n)), "D": (D, (m, 1)), "Q": (Q, (n, n)), "R": (R, (m, m))}
    p, y, Ad, Bd, C, D, Q, R = (check_array("kalman_step", name, value, shape=shape)
                                for name, (value, shape) in args.items())
    u = check_real("kalman_step", "u", u)
    u_held = u if u_held is None else check_real("kalman_step", "u_held", u_held)
    x_plus, p_plus, _, _ = kalman_update(x_hat, p, y, C, R, D[:, 0] * u_held)
    x_pred, p_pred = kalman_predict(x_plus, p_plus, u, Ad, Bd, Q)
    return x_plus, p_plus, x_pred, p_pred


@dataclass(frozen=True, eq=False)
class FilterMatrices:
    """The filter's model over one sample interval (module Notes).

    Attributes
    ----------
    Ad : ndarray, shape (n_f, n_f)
        ``Phi(h)``: the filter state's transition over one sample interval ``h``.
    Bd : ndarray, shape (n_f, 1)
        ``Gamma(h)``: the state reached from rest per unit of command held over ``h``.
    C : ndarray, shape (m, n_f)
        The readings per filter state.
    D : ndarray, shape (m, 1)
        The readings per unit of command: zero but for the tip accelerations.
    Q : ndarray, shape (n_f, n_f)
        Process noise covariance over ``h``, in the squared units of the filter states.
    R : ndarray, shape (m, m)
        Reading noise covariance, in the squared units of the readings.
    """

    Ad: np.ndarray
    Bd: np.ndarray
    C: np.ndarray
    D: np.ndarray
    Q: np.ndarray
    R: np.ndarray


@dataclass(frozen=True, eq=False)
class FilterModel:
    """What the filter knows of the plant: its linearisation at rest and the readings' map.

    Built once from a model (:meth:`from_model`), usually the nominal plant a design was made
    on, and kept: a run on another plant of the same layout (a dispersed one in a Monte
    Carlo) reads that plant's sensors, while the filter keeps predicting with these matrices,
    as a flight computer does.

    Attributes
    ----------
    A : ndarray, shape (n, n)
        ``model.linear_matrices(0.0)[0]``, 1/s (per state).
    B : ndarray, shape (n, 1)
        ``model.linear_matrices(0.0)[1]``, per unit of the model's input.
    C : ndarray, shape (m, n)
        The readings per plant state (:func:`~flexctl.sim.sensors.measurement_matrix`).
    D : ndarray, shape (m, 1)
        The readings per unit of input.
    names : tuple of str
        The readings, in order (:func:`~flexctl.sim.sensors.sensor_names`).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    names: tuple

    @classmethod
    def from_model(cls, model, sensors: Sensors) -> "FilterModel":
        """The filter's model of ``model`` read by ``sensors``.

        Parameters
        ----------
        model : flexctl.Model
            The plant the filter assumes (its linearisation at rest and its outputs).
        sensors : Sensors
            What is read.
        """
        a, b = model.linear_matrices(0.0)
        c, d = measurement_matrix(model, sensors)
        arrays = [np.array(v, dtype=float) for v in (a, b, c, d)]
        for array in arrays:
            array.setflags(write=False)
        return cls(*arrays, names=tuple(sensor_names(model, sensors)))

    def __repr__(self):
        return (f"FilterModel({self.A.shape[0]} states, {len(self.names)} readings: "
                f"{', '.join(self.names)})")


class _Holds:
    """``Phi(h)``, ``Gamma(h)``, ``Q(h)`` of the filter state over a hold of ``h`` s, cached
    by ``h`` to a billionth of the sample interval."""

    def __init__(self, a, b, sample_time, process_noise, bias_std, bias_time):
        self.a, self.b, self.sample_time, self.process_noise = a, b, sample_time, process_noise
        self.bias_std, self.bias_time, self.cache = bias_std, bias_time, {}

    def __call__(self, h: float) -> tuple:
        key = round(h / self.sample_time, 9)
        if key not in self.cache:
            self.cache[key] = self._hold(key * self.sample_time)
        return self.cache[key]

    def _hold(self, h):
        n = self.a.shape[0]
        block = np.zeros((n + 1, n + 1))
        block[:n, :n], block[:n, n:] = self.a, self.b
        hold = scipy.linalg.expm(block * h)
        phi, gam = hold[:n, :n], hold[:n, n:]
        q = gam @ gam.T * self.process_noise ** 2
        if not self.bias_std:
            return phi, gam, q
        spread = self.bias_std ** 2 * -math.expm1(-2.0 * h / self.bias_time)
        return (scipy.linalg.block_diag(phi, math.exp(-h / self.bias_time)),
                np.vstack((gam, 0.0)), scipy.linalg.block_diag(q, spread))


# ---------------------------------------------------------------------- the controller
@dataclass(frozen=True, eq=False)
class Observed:
    """A static state law on the discrete Kalman estimate of the sensors' readings.

    Parameters
    ----------
    law : Controller, SampledController or callable
        A static :class:`flexctl.Controller` (``n_states == 0``) or ``law(t, x)`` (N m) of
        the plant state, or a sampled controller at ``sample_time`` (e.g.
        :class:`controllers.NMPC`), whose session steps on the estimate.
    sensors : Sensors
        What is read; ``sensors.sample_time`` must be ``None`` or equal ``sample_time``.
    sample_time : float
        Sample time of the filter and the law, s (> 0).
    process_noise : float
        Standard deviation of a white disturbance torque held over each sample, entering
        like the command, N m (>= 0). Default 0.01.
    model : flexctl.Model or FilterModel, optional
        The plant the filter assumes, fixed with the design (kept as its
        :class:`FilterModel`): a run on another plant of the same state layout and readings
        (a dispersed one) keeps this filter. Default None: each run builds its filter on
        the plant it runs.
    """

    law: object
    sensors: Sensors
    sample_time: float
    process_noise: float = 1e-2
    model: object = None

    #: Tells the simulation to hand :meth:`ObservedSession.step` the sensors' readings.
    measures = True

    def __post_init__(self):
        check_instance("observed", "sensors", self.sensors, Sensors)
        object.__setattr__(self, "sample_time", check_real(
            "observed", "sample_time", self.sample_time, minimum=0.0, strict=True))
        object.__setattr__(self, "process_noise", check_real(
            "observed", "process_noise", self.process_noise, minimum=0.0))
        if self.model is not None and not isinstance(self.model, FilterModel):
            if not callable(getattr(self.model, "linear_matrices", None)):
                raise InputTypeError("observed.model must be a flexctl Model or a FilterModel; "
                                     f"got {type(self.model).__name__}")
            object.__setattr__(self, "model", FilterModel.from_model(self.model, self.sensors))
        own = self.sensors.sample_time
        if own is not None and not math.isclose(own, self.sample_time, rel_tol=1e-12):
            raise InputValueError(
                f"observed.sample_time must equal sensors.sample_time (one rate for readings "
                f"and commands); got {self.sample_time!r} s and {own!r} s")
        law = self.law
        if is_sampled(law):
            # a law with its own solver and memory (NMPC): its session gets the estimate
            if not math.isclose(law.sample_time, self.sample_time, rel_tol=1e-12):
                raise InputValueError(
                    f"observed.law samples every {law.sample_time!r} s; it must sample at "
                    f"the readings' sample_time {self.sample_time!r} s")
            if getattr(law, "measures", False):
                raise InputValueError("observed.law reads sensors itself; pass a law that "
                                      "reads the state")
        elif callable(getattr(law, "torque", None)) and hasattr(law, "n_states"):
            if law.n_states:
                raise InputValueError(f"observed.law must be static (n_states = 0): the filter "
                                      f"is the estimator; got {law.n_states} internal states")
        elif callable(law):
            time_function(law, "observed.law")
        else:
            raise InputTypeError("observed.law must be a static flexctl Controller or a "
                                 f"callable law(t, x); got {type(law).__name__}")

    def for_plant(self, model) -> "Observed":
        """The same law and sensors with the filter built on ``model``: for a plant of
        another layout (more modes: the reference run of an error estimate), where the
        design's filter cannot run.

        Parameters
        ----------
        model : flexctl.Model
            The plant the new filter assumes and the controller runs on.
        """
        return dataclasses.replace(self, model=model)

    def sampled_loop(self, model, spin_rate: float = 0.0):
        """The loop as it flies on ``model``: a discrete ``L(z)`` broken at the plant input
        (:func:`controllers.feedback.observed_loop.observed_loop`).

        Parameters
        ----------
        model : flexctl.Model
            The plant flown, linearised about ``spin_rate``.
        spin_rate : float, optional
            Steady hub rate of the linearisation, rad/s. Default 0.
        """
        from .observed_loop import observed_loop

        return observed_loop(model, self, spin_rate)

    def loop_matrices(self, model, spin_rate: float = 0.0):
        """:meth:`sampled_loop` as arrays
        (:class:`~controllers.feedback.observed_loop.LoopMatrices`), without python-control.

        Parameters
        ----------
        model : flexctl.Model
            The plant flown, linearised about ``spin_rate``.
        spin_rate : float, optional
            Steady hub rate of the linearisation, rad/s. Default 0.
        """
        from .observed_loop import observed_loop_matrices

        return observed_loop_matrices(model, self, spin_rate)

    def start(self, model, x0) -> "ObservedSession":
        """A fresh session for a run of ``model`` from the plant state ``x0``.

        Parameters
        ----------
        model : flexctl.Model
            The plant the filter is built on (its linearisation at rest and its outputs).
        x0 : array_like, shape (n,)
            Plant state at the start, in the order of ``model.layout``: the filter's initial
            estimate.
        """
        return ObservedSession(self, model, x0)

    def __repr__(self):
        law = getattr(self.law, "__name__", type(self.law).__name__)
        return (f"Observed(law={law}, sample_time={self.sample_time:g} s, "
                f"process_noise={self.process_noise:g} N m, {self.sensors!r})")


def _bound_law(law, model, x0):
    """``law`` as ``f(t, x) -> float`` reading ``model``'s plant state (a sampled law's
    session, started at ``x0``), and that session (None for a static law)."""
    if is_sampled(law):
        session = law.start(model, x0)
        return (lambda t, x: input_value("observed.law", session.step(t, x), t)), session
    law = bound_to_plant(law, model)
    if callable(getattr(law, "torque", None)) and hasattr(law, "n_states"):
        none = np.zeros(0)
        return (lambda t, x: input_value("observed.law", law.torque(t, x, none), t)), None
    return time_function(law, "observed.law"), None


def _command_limit(model) -> float | None:
    """The actuator's finite ``command_limit`` (N m), or None."""
    limit = getattr(getattr(model, "actuator", None), "command_limit", None)
    if limit is None or not math.isfinite(float(limit)):
        return None
    return abs(float(limit))


def _filter_model(controller: Observed, model) -> FilterModel:
    """The controller's fixed filter model, checked against the plant run; or one of that
    plant when the controller has none."""
    if controller.model is None:
        return FilterModel.from_model(model, controller.sensors)
    known, n = controller.model, model.layout.n_states
    names = sensor_names(model, controller.sensors)
    if known.A.shape[0] != n or known.names != names:
        raise InputValueError(
            f"observed.model must have the run plant's layout and readings: the filter has "
            f"{known.A.shape[0]} states reading {', '.join(known.names)}; the plant has {n} "
            f"states reading {', '.join(names)}")
    return known


class ObservedSession:
    """One run of :class:`Observed` (module Notes); made by :meth:`Observed.start`.

    Parameters
    ----------
    controller : Observed
        The controller run: its law, sensors, sample time and noise settings.
    model : flexctl.Model
        The plant the filter is built on (its linearisation at rest and its outputs).
    x0 : array_like, shape (n,)
        Plant state at the start, in the order of ``model.layout``: the filter's initial
        estimate.

    Attributes
    ----------
    matrices : FilterMatrices
        The filter's model over one sample interval.
    names : tuple of str
        The readings :meth:`step` takes, in order.
    """

    def __init__(self, controller: Observed, model, x0):
        sensors, n = controller.sensors, model.layout.n_states
        x0 = check_array("observed.start", "x0", x0, shape=(n,))
        self.controller, self.model, self.names = controller, model, sensor_names(model, sensors)
        self._law, self._inner = _bound_law(controller.law, model, x0)
        self._limit = _command_limit(model)
        bias = sensors.gyro_bias_instability > 0.0 and "theta_dot" in self.names
        known = _filter_model(controller, model)
        self._holds = _Holds(known.A, known.B, controller.sample_time, controller.process_noise,
                             sensors.gyro_bias_instability if bias else 0.0,
                             sensors.gyro_bias_time)
        c, d = known.C, known.D
        if bias:
            c = np.column_stack((c, np.zeros(c.shape[0])))
            c[self.names.index("theta_dot"), n] = 1.0
        r = noise_covariance(model, sensors, controller.sample_time, with_bias=bias)
        self.matrices = FilterMatrices(*self._holds(controller.sample_time)[:2], c, d,
                                       self._holds(controller.sample_time)[2], r)
        self._n, self._bias = n, bias
        self._z = np.concatenate((x0, [0.0] if bias else []))
        # the start is known up to one sample of disturbance; the bias to its stationary spread
        p0 = self.matrices.Q + VARIANCE_FLOOR * np.eye(self._z.size)
        if bias:
            p0[n, n] = sensors.gyro_bias_instability ** 2
        self._p, self._epoch, self._start = p0, None, None
        self._times, self._commands = [], []
        self._estimates, self._filtered, self._worst, self._clipped = [], [], 0.0, 0

    def hold(self, duration: float) -> tuple:
        """The filter's model over a hold: ``(Phi, Gamma, Q)`` of the filter state over
        ``duration`` s of a held command (module Notes), shapes (n_f, n_f), (n_f, 1) and
        (n_f, n_f).

        Parameters
        ----------
        duration : float
            Length of the hold, s (>= 0).
        """
        duration = check_real("observed.hold", "duration", duration, minimum=0.0)
        return self._holds(duration)

    # ------------------------------------------------------------------ commands held
    def _pieces(self, t_from: float, t_to: float) -> list:
        """``(duration, command)`` of each hold within ``[t_from, t_to]``, the time before
        the first sample left out (the plant held at ``x0``)."""
        tol = 1e-9 * self.controller.sample_time
        t_from, pieces = max(t_from, self._start), []
        while t_from < t_to - tol:
            j = bisect.bisect_right(self._times, t_from + tol) - 1
            end = self._times[j + 1] if j + 1 < len(self._times) else t_to
            end = min(end, t_to)
            pieces.append((end - t_from, self._commands[j]))
            t_from = end
        return pieces

    def _held_at(self, t: float) -> float:
        """The command held just before ``t`` (0 before the first one)."""
        j = bisect.bisect_left(self._times, t - 1e-9 * self.controller.sample_time) - 1
        return self._commands[j] if j >= 0 else 0.0

    def _propagate(self, z, p, t_from, t_to):
        """Filter state and covariance (``p`` None: state alone) from ``t_from`` to ``t_to``."""
        for h, u in self._pieces(t_from, t_to):
            phi, gam, q = self._holds(h)
            if p is None:
                z = phi[:z.size, :z.size] @ z + gam[:z.size, 0] * u
            else:
                z, p = kalman_predict(z, p, u, phi, gam, q)
        return z, p

    # ------------------------------------------------------------------ the sample
    def step(self, t: float, y) -> float:
        """Command (N m) to hold from sample time ``t``, given the readings ``y`` taken at
        ``t``.

        Parameters
        ----------
        t : float
            Sample time, s.
        y : array_like, shape (m,)
            Readings of :attr:`names` taken at ``t`` (of the plant ``sensors.delay`` s
            earlier), in their sensors' units.
        """
        t = check_real("observed.step", "t", t)
        y = check_array("observed.step", "y", y, shape=(len(self.names),))
        epoch = t - self.controller.sensors.delay
        if self._start is None:
            self._start = t
        else:
            self._z, self._p = self._propagate(self._z, self._p, self._epoch, epoch)
        mats = self.matrices
        self._z, self._p, innovation, s = kalman_update(
            self._z, self._p, y, mats.C, mats.R, mats.D[:, 0] * self._held_at(epoch))
        self._epoch = epoch
        self._worst = max(self._worst, float(np.max(np.abs(innovation)
                                                    / np.sqrt(np.diag(s)))))
        x_now, _ = self._propagate(self._z[:self._n], None, epoch, t)
        command = self._law(t, x_now)
        applied = command if self._limit is None else float(np.clip(command, -self._limit,
                                                                    self._limit))
        self._clipped += applied != command
        self._record(t, applied, x_now)
        return applied

    def _record(self, t, command, x_now):
        self._times.append(t)
        self._commands.append(command)
        # the commands still needed: the one held at the epoch, and the later ones
        keep = bisect.bisect_right(self._times, self._epoch) - 1
        if keep > 0:
            del self._times[:keep], self._commands[:keep]
        self._estimates.append(x_now)
        self._filtered.append(self._z.copy())

    # ------------------------------------------------------------------ what it did
    @property
    def estimates(self) -> np.ndarray:
        """The plant state the law read at each sample (the estimate extrapolated to the
        sample time), shape (K, n)."""
        return np.array(self._estimates).reshape(-1, self._n)

    @property
    def filtered(self) -> np.ndarray:
        """The filter state after each update, at the reading epochs, shape (K, n_f)."""
        return np.array(self._filtered).reshape(-1, self._z.size)

    @property
    def bias_estimates(self) -> np.ndarray | None:
        """The estimated gyro bias after each update, rad/s, shape (K,); None without one."""
        return self.filtered[:, self._n] if self._bias else None

    @property
    def covariance(self) -> np.ndarray:
        """The filter's current covariance, shape (n_f, n_f)."""
        return self._p.copy()

    def report(self) -> dict:
        """Samples, the final estimated gyro bias (rad/s, None without one), the largest
        innovation over its standard deviation, and the samples whose command was clipped."""
        bias = self.bias_estimates
        inner = {} if self._inner is None else dict(self._inner.report() or {})
        return {**inner, "samples": len(self._filtered),
                "gyro_bias": None if bias is None or not bias.size else float(bias[-1]),
                "largest_normalised_innovation": self._worst,
                "clipped_samples": int(self._clipped),
                "delay": self.controller.sensors.delay}

    def __repr__(self):
        return (f"ObservedSession({len(self._filtered)} samples, {self._z.size} filter "
                f"states, {len(self.names)} readings)")
