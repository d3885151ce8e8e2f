"""Digital controllers: a law evaluated at a sample rate, its torque held between samples.

A flight computer reads the sensors at ``t_k = k T``, computes a torque and holds it until
``t_{k+1}`` (a zero-order hold). :func:`flexctl.simulate` runs any object following
:class:`SampledController` this way: the plant is integrated from sample to sample with the
held torque as a constant (compiled CVODES, one integrator shared by every sample), and the
controller is called once per sample, from Python, so that it may keep any memory it likes (a
warm start, an estimate, statistics). A plant that is not stiff over a sample takes compiled
Dormand-Prince steps instead, whose size carries over from sample to sample
(:mod:`flexctl.sim.embedded_rk`, ``method="auto"`` or ``"RK45"``).

- :class:`ZeroOrderHold` turns a continuous law (any static :class:`flexctl.Controller`, e.g.
  PD or LQR, or a callable ``law(t, x)``) into a sampled one: the same law, continuous or
  sampled, is one switch.
- A controller with its own solver (e.g. :class:`controllers.mpc.nmpc.NMPC`) implements
  :class:`SampledController` directly: ``start`` gives a session whose ``step`` is called at
  each sample and whose ``report`` lands in ``SimulationResult.controller_report``.

Examples
--------
>>> import flexctl
>>> from flexctl.sim.digital import ZeroOrderHold
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> pd = lambda t, x: 3.0 * (0.1 - x[0]) - 2.0 * x[3]
>>> result = flexctl.simulate(model, 4.0, controller=ZeroOrderHold(pd, sample_time=0.01))
>>> result.status, result.controller_report["samples"]
('ok', 400)
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from .stops import tip_rows
from .compiled import (CHECK_FACTOR, SegmentIntegrator, cached_build, input_key, input_numbers,
                       is_symbolic, min_step_fraction)
from .buffers import InPlace
from .step_chain import step_chain
from .fixed_step import STEP_CACHE, STEP_CACHE_SIZE, jit_compiled, step_function
from .embedded_rk import EmbeddedHold, HeldTorque
from .inputs import input_value, output_grid, time_function
from .drives import bound_to_plant
from .sensors import sensor_names
from ..model.errors import InputTypeError, InputValueError

__all__ = ["SampledController", "ControllerSession", "ZeroOrderHold", "is_sampled",
           "SampledRun", "run_sampled"]

#: Fewest samples a run may have, and most: a sample costs one integrator call (some 50 to
#: 500 us) and one controller call, so 1e6 samples is minutes at least.
MAX_SAMPLES = 1_000_000


@runtime_checkable
class ControllerSession(Protocol):
    """One run of a sampled controller, with whatever memory it keeps between samples."""

    def step(self, t: float, x: np.ndarray) -> float:
        """Torque (N m) to hold from sample time ``t`` (s) to the next, given the plant state
        ``x`` measured at ``t``, shape (n,).

        Parameters
        ----------
        t : float
            Sample time, s.
        x : ndarray, shape (n,) or (m,)
            The plant state at ``t``, in the order of ``model.layout``; for a controller that
            reads sensors (``measures = True``), their ``m`` readings instead
            (:func:`flexctl.sim.sensors.sensor_names`).
        """

    def report(self) -> dict:
        """What the run did (JSON-serialisable): solve times, iterations, failures..."""


@runtime_checkable
class SampledController(Protocol):
    """A controller evaluated every ``sample_time`` seconds (zero-order hold in between).

    Attributes
    ----------
    sample_time : float
        Sample time, s (> 0).
    """

    sample_time: float

    def start(self, model, x0: np.ndarray) -> ControllerSession:
        """A fresh session for a run of ``model`` from the plant state ``x0``.

        Parameters
        ----------
        model : Model
            The plant of the run.
        x0 : ndarray, shape (n,)
            Initial plant state, in the order of ``model.layout``.

        Returns
        -------
        ControllerSession
        """


def is_sampled(controller) -> bool:
    """True for an object following :class:`SampledController`.

    Parameters
    ----------
    controller : object
        Any controller (or None): a ``sample_time`` that is not None and a ``start`` method
        make it sampled.
    """
    return (getattr(controller, "sample_time", None) is not None
            and callable(getattr(controller, "start", None)))


def check_sample_time(owner: str, value) -> float:
    """A sample time checked: a positive, finite number of seconds, as a float.

    Parameters
    ----------
    owner : str
        What to name in an error (e.g. ``"ZeroOrderHold"``).
    value : int or float
        The sample time, s.

    Returns
    -------
    float
        ``value``, s.

    Raises
    ------
    InputTypeError
        If ``value`` is not a number (a bool is not).
    InputValueError
        If it is not positive and finite.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"{owner} sample_time must be a number of seconds; got "
                             f"{type(value).__name__} {value!r}")
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise InputValueError(f"{owner} sample_time must be positive and finite, s; got "
                              f"{value!r}")
    return value


@dataclass(frozen=True, eq=False)
class _HoldSession:
    law: object

    def step(self, t, x):
        return self.law(t, x)

    def report(self):
        return {}


@dataclass(frozen=True, eq=False)
class ZeroOrderHold:
    """A continuous law sampled every ``sample_time`` with its torque held in between.

    Parameters
    ----------
    law : Controller or callable
        A static :class:`flexctl.Controller` (``n_states == 0``: PD, LQR, a tracker, an open-loop
        torque) or a callable ``law(t, x)`` returning N m.
    sample_time : float
        Sample time, s (> 0): the law is evaluated at its multiples.

    Notes
    -----
    A law with internal states (an estimator, e.g. LQG) integrates them continuously and has
    no sampled form here: its estimator would have to be discretised with the hold.
    """

    law: object
    sample_time: float

    def __post_init__(self):
        object.__setattr__(self, "sample_time", check_sample_time("ZeroOrderHold",
                                                             self.sample_time))
        law = self.law
        if is_sampled(law):
            raise InputValueError("ZeroOrderHold law is already sampled (it has a sample_time "
                                  f"of {law.sample_time!r} s); pass the continuous law")
        if callable(getattr(law, "torque", None)) and hasattr(law, "n_states"):
            if law.n_states:
                raise InputValueError(
                    f"ZeroOrderHold law has {law.n_states} internal states (an estimator); "
                    "only a static law (n_states = 0) can be sampled here")
        elif callable(law):
            time_function(law, "ZeroOrderHold law")       # its signature: (t, x)
        else:
            raise InputTypeError("ZeroOrderHold law must be a static flexctl Controller or a "
                                 f"callable law(t, x); got {type(law).__name__}")

    @property
    def continuous(self):
        """The law itself, to run it without the hold."""
        return self.law

    def start(self, model, x0) -> ControllerSession:
        """A session evaluating the law at each sample (a law that reads the plant by its
        layout bound to ``model``'s, as :func:`flexctl.simulate` binds continuous ones).

        Parameters
        ----------
        model : Model
            The plant of the run.
        x0 : ndarray, shape (n,)
            Initial plant state; not used (the law has no state of its own).

        Returns
        -------
        ControllerSession
        """
        law = bound_to_plant(self.law, model)
        if callable(getattr(law, "torque", None)) and hasattr(law, "n_states"):
            z = np.zeros(0)
            return _HoldSession(lambda t, x: law.torque(t, x, z))
        return _HoldSession(law)


@dataclass(frozen=True, eq=False)
class SampledRun:
    """Raw outcome of :func:`run_sampled`, for :func:`flexctl.simulate` to report.

    Attributes
    ----------
    t : ndarray, shape (P,)
        Output times, s: the output grid, and the stop time of a stopped run.
    states : ndarray, shape (n, P)
    torque : ndarray, shape (P,)
        Held torque at each output time (the new sample's value at a sample time), N m.
    sample_times, sample_torques : ndarray, shape (K,)
        Each sample and the torque held from it, s and N m.
    stop : {None, "integrator", "bad_sample"}
        None for a run that reached ``t_final``; ``"integrator"`` when the integration of a
        sample failed (``message`` says where); ``"bad_sample"`` when an output passed a
        stopping condition (``stop_state``, the plant state there, for the caller to name).
    message : str or None
    stop_state : ndarray or None
    n_evaluations : int
    integration_error : float or None
        Estimated largest tip-deflection error, m: the difference from a replay of the held
        torques at ``CHECK_FACTOR`` times the tolerance (CVODES), or with twice the step (RK4);
        conservative, as it is the error of the looser replay.
    report : dict
        The session's report plus ``samples`` and ``sample_time``.
    controller_time : float
        Wall time spent in the controller, s.
    measurements : dict or None
        The sensors' readings at each sample when the controller read sensors: ``{"t": (K,),
        name: (K,) ..., "true": {name: (K,)}}`` (the sample times, each reading, and the
        noiseless values); None otherwise.
    """

    t: np.ndarray
    states: np.ndarray
    torque: np.ndarray
    sample_times: np.ndarray
    sample_torques: np.ndarray
    stop: str | None
    message: str | None
    stop_state: np.ndarray | None
    n_evaluations: int
    integration_error: float | None
    report: dict
    controller_time: float
    measurements: dict | None = None


class _SensorFeed:
    """The sensors' reading at each sample: of the state ``delay`` seconds before it (the
    initial state before ``t = 0``, with no command applied), through their noise
    (:mod:`flexctl.sim.sensors`)."""

    def __init__(self, model, sensors, edges, x0, sample_time):
        self.model, self.x0 = model, np.asarray(x0, dtype=float)
        self.session = sensors.start(model, sample_time)
        self.names = sensor_names(model, sensors)
        self.rates = sensors.has_accelerometers
        self.times = edges[:-1] - sensors.delay     # when each sample's state is read
        self.seen = {}                              # sample -> (state, command held then)
        self.readings, self.truth = [], []

    def _reads_in(self, lo: float, hi: float) -> np.ndarray:
        """The samples whose read time falls in ``(lo, hi]`` (the times ascend)."""
        return np.arange(np.searchsorted(self.times, lo, side="right"),
                         np.searchsorted(self.times, hi, side="right"))

    def times_in(self, lo: float, hi: float) -> np.ndarray:
        """The read times that fall in ``(lo, hi]``."""
        return self.times[self._reads_in(lo, hi)]

    def store(self, lo, t_out, y_seg, u):
        """Keep the states of the interval ``(lo, t_out[-1]]`` at the read times it covers."""
        for k in self._reads_in(lo, t_out[-1]):
            column = int(np.searchsorted(t_out, self.times[k]))
            self.seen[int(k)] = (y_seg[:, column], u)

    def read(self, k: int) -> np.ndarray:
        """Sample ``k``'s reading, shape (m,)."""
        x, u = self.seen.pop(k, (self.x0, 0.0))
        xdot = self.model.dynamics(0.0, x, u) if self.rates else None
        reading, truth = self.session.measure(x, xdot)
        self.readings.append(np.asarray(reading, dtype=float))
        self.truth.append(np.asarray(truth, dtype=float))
        return self.readings[-1]

    def record(self, sample_times) -> dict:
        """``{"t": (K,), name: (K,) reading..., "true": {name: (K,)}}``."""
        k = len(self.readings)
        out = {"t": np.asarray(sample_times[:k], dtype=float)}
        values = np.array(self.readings).reshape(k, len(self.names))
        truth = np.array(self.truth).reshape(k, len(self.names))
        out.update({name: values[:, j] for j, name in enumerate(self.names)})
        out["true"] = {name: truth[:, j] for j, name in enumerate(self.names)}
        return out


def _sample_grid(t_final: float, sample_time: float) -> np.ndarray:
    count = int(np.ceil(t_final / sample_time * (1.0 - 1e-12)))
    if count > MAX_SAMPLES:
        raise InputValueError(f"sample_time {sample_time:g} s gives {count} samples over "
                              f"t_final {t_final:g} s, more than the limit {MAX_SAMPLES}; "
                              "lengthen sample_time or shorten t_final")
    edges = np.minimum(np.arange(count + 1) * sample_time, t_final)
    edges[-1] = t_final
    return edges


class _CvodesHold:
    """One sample under a held torque by CVODES (one integrator shared by every sample)."""

    #: the looser run's difference is taken as the error (conservative)
    error_divisor = 1.0

    def __init__(self, model, torque, scale, rtol, max_steps):
        self.model, self.torque, self.scale = model, torque, scale
        self.rtol, self.max_steps = rtol, max_steps
        self.torque_numbers = input_numbers((torque, None, None))
        # one integrator per shape of sample (output offsets, tolerance, shortest step),
        # moved from sample to sample: a regular grid builds one or two
        self.shapes = {}

    def __call__(self, lo, t_out, y, u, loose=False):
        length = t_out[-1] - lo
        shape = (loose, np.round(t_out - lo, 12).tobytes(), min_step_fraction(t_out[-1], length))
        integ = self.shapes.get(shape)
        if integ is None:
            integ = SegmentIntegrator(self.model, lo, t_out, self.scale,
                                      self.rtol * (CHECK_FACTOR if loose else 1.0),
                                      torque=self.torque, controller=HeldTorque(u),
                                      max_steps=self.max_steps)
            self.shapes[shape] = integ
        else:
            integ = integ.moved(lo, t_out[-1], (*self.torque_numbers, u))
        return integ(y), integ.n_evaluations


class _RK4Hold:
    """One sample under a held torque by compiled RK4 steps of at most ``h_max`` (twice that
    when ``loose``, for the step-doubling error estimate)."""

    #: the difference from the run at twice the step is taken as the error (conservative: it
    #: is the error of the coarser run; Richardson's division by 15 holds only where every
    #: mode is resolved, and the torque steps of a hold excite the fastest ones)
    error_divisor = 1.0

    def __init__(self, model, torque, h_max):
        self.h_max, self.model, self.torque = float(h_max), model, torque
        self.chains = {}
        # the compiled loops are kept across runs (by model, torque kind and step count), like
        # the CVODES integrators: a second run with other gains, another law or another
        # torque amplitude costs no build (the torque's numbers and the held value enter as
        # parameters)
        self.key = input_key(model, (torque, None, None), np.array([1.0]))
        self.torque_numbers = input_numbers((torque, None, None))

    def _final(self, count):
        """Compiled ``count`` steps: ``([y; t], h, [c; u]) -> [y; t]`` at the end."""
        if count not in self.chains:
            self.chains[count] = cached_build(
                STEP_CACHE, STEP_CACHE_SIZE,
                None if self.key is None else ("rk4-hold", self.key, count),
                (self.model, self.torque), lambda: self._build(count))
        return self.chains[count]

    def _build(self, count):
        import casadi as ca

        n_numbers = self.torque_numbers.size + 1
        step = step_function(self.model, self.torque, None, HeldTorque(0.0), n_numbers)[0]
        chain = step_chain(step, count, "flexctl_rk4_hold")
        yt, h = ca.MX.sym("yt", step.size1_in(0)), ca.MX.sym("h")
        c = ca.MX.sym("c", n_numbers)
        ys = chain(yt, h, c)[0]
        return InPlace(jit_compiled(ca.Function("flexctl_rk4_hold_end", [yt, h, c],
                                         [ca.densify(ys[:, -1])]), self.model))

    def __call__(self, lo, t_out, y, u, loose=False):
        h_max = self.h_max * (2.0 if loose else 1.0)
        out, evaluations, start = [], 0, lo
        yt = np.append(y, lo)
        for end in t_out:
            count = max(1, int(np.ceil((end - start) / h_max * (1.0 - 1e-12))))
            yt = self._final(count)(yt, (end - start) / count,
                                    np.append(self.torque_numbers, u))[0].reshape(-1)
            yt[-1] = end
            out.append(yt[:-1])
            evaluations += 4 * count
            start = end
        out = np.column_stack(out)
        if not np.all(np.isfinite(out)):
            raise RuntimeError("non-finite state")
        return out, evaluations


def run_sampled(model, t_final: float, controller, x0, *, torque=None, output_step: float,
                scale, rtol: float, bad_sample, check_accuracy: bool = True,
                max_steps: int = 100_000, integrator: str = "cvodes",
                h_max: float | None = None, sensors=None) -> SampledRun:
    """Integrate ``model`` under a sampled controller, sample by sample.

    Parameters
    ----------
    model : Model
        The plant integrated.
    t_final : float
        End time, s.
    controller : SampledController
        The sampled controller; its session is started at ``t = 0``.
    x0 : ndarray, shape (n,)
        Initial plant state, in the order of ``model.layout``.
    torque : object, optional
        An additional torque with a CasADi form (``casadi(t)``), applied continuously.
    output_step : float
        Spacing of the output times, s (:func:`flexctl.sim.inputs.output_grid`).
    scale : ndarray, shape (n,)
        Physical size of each state (absolute tolerance ``rtol * scale``).
    rtol : float
        Relative tolerance of CVODES and of the pair; unused by ``"rk4"``.
    bad_sample : callable
        ``bad_sample(y)`` for states ``y`` of shape (n, K): index of the first output past a
        stopping condition, or None.
    check_accuracy : bool
        Estimate the integration error (see :class:`SampledRun`).
    max_steps : int, optional
        Step budget of one sample: CVODES's ``max_num_steps``, or the pair's step attempts
        (accepted or not) per output time; unused by ``"rk4"``. Default 100 000.
    integrator : {"cvodes", "RK45", "rk4"}
        Error-controlled CVODES from sample to sample; error-controlled Dormand-Prince 5(4)
        steps whose size carries over from sample to sample
        (:class:`~flexctl.sim.embedded_rk.EmbeddedHold`); or compiled fixed-step RK4.
    h_max : float or None
        For ``"RK45"`` the first step tried, s; for ``"rk4"`` the longest step, s (required);
        unused by ``"cvodes"``.
    sensors : Sensors, optional
        The controller's session gets their readings (:mod:`flexctl.sim.sensors`) instead of
        the state; they are recorded in ``measurements``.

    Returns
    -------
    SampledRun
    """
    if torque is not None and not is_symbolic(torque=torque):
        raise InputValueError("a torque added to a sampled controller needs a CasADi form "
                              "(casadi(t), e.g. the built-in manoeuvres); got a Python "
                              "callable")
    edges = _sample_grid(t_final, controller.sample_time)
    grid = output_grid(t_final, output_step)
    session = controller.start(model, np.array(x0, dtype=float))
    if not isinstance(session, ControllerSession):
        raise InputTypeError("controller.start must return a session with step(t, x) and "
                             f"report(); got {type(session).__name__}")
    if integrator == "rk4":
        hold = _RK4Hold(model, torque, h_max)
    elif integrator == "RK45":
        hold = EmbeddedHold(model, torque, scale, rtol, max_steps, h_first=h_max)
    else:
        hold = _CvodesHold(model, torque, scale, rtol, max_steps)
    log = _SampleLog(x0=np.asarray(x0, dtype=float), t_final=float(t_final))
    feed = None if sensors is None else _SensorFeed(model, sensors, edges, x0,
                                                    controller.sample_time)
    _sample_loop(log, session, hold, edges, grid, bad_sample, feed)
    if check_accuracy and log.stop is None:
        tip_map = tip_rows(model, model.layout)
        log.error = _replay_error(log, hold, edges, tip_map)
    run = _sampled_outputs(log, session, edges, grid, controller.sample_time)
    if feed is not None:
        run = dataclasses.replace(run, measurements=feed.record(edges))
    return run


@dataclass
class _SampleLog:
    """What the sample loop has integrated so far."""

    x0: np.ndarray
    t_final: float
    ts: list = field(default_factory=list)
    ys: list = field(default_factory=list)
    us: list = field(default_factory=list)
    ends: list = field(default_factory=list)
    stop: str | None = None
    message: str | None = None
    stop_state: np.ndarray | None = None
    n_eval: int = 0
    controller_time: float = 0.0
    error: float | None = None

    def __post_init__(self):
        self.ts.append(np.array([0.0]))
        self.ys.append(self.x0[:, None])
        self.message = f"reached t_final = {self.t_final:g} s"


def _sample_loop(log, session, hold, edges, grid, bad_sample, feed=None):
    """From sample to sample: the session's torque at each sample (from the state, or from
    the sensors' ``feed``), held over the interval, until the end, an integrator failure or a
    bad output sample."""
    y = log.x0
    for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        started = time.perf_counter()
        seen = y.copy() if feed is None else feed.read(k)
        u = input_value("controller", session.step(float(lo), seen), float(lo))
        log.controller_time += time.perf_counter() - started
        log.us.append(u)
        t_out = np.append(grid[(grid > lo) & (grid < hi)], hi)
        if feed is not None:
            t_out = np.union1d(t_out, feed.times_in(lo, hi))
        try:
            y_seg, evaluations = hold(lo, t_out, y, u)
            log.n_eval += evaluations
        except RuntimeError:
            log.stop = "integrator"
            log.message = (f"the integration failed between samples t = {lo:.6g} s and "
                           f"{hi:.6g} s under a held torque of {u:.6g} N m")
            return
        bad = bad_sample(y_seg)
        if bad is not None:
            log.ts.append(t_out[:bad])
            log.ys.append(y_seg[:, :bad])
            log.stop, log.message, log.stop_state = "bad_sample", None, y_seg[:, bad]
            return
        if feed is not None:
            feed.store(lo, t_out, y_seg, u)
        log.ts.append(t_out)
        log.ys.append(y_seg)
        log.ends.append(y_seg[:, -1])
        y = y_seg[:, -1]


def _replay_error(log, hold, edges, tip_map) -> float | None:
    """The recorded torques replayed by the looser integration (10x the tolerance, or twice
    the step): the largest tip difference at the samples estimates the run's error, m."""
    try:
        y_check = log.x0
        error = 0.0
        for lo, hi, u, y_end in zip(edges[:-1], edges[1:], log.us, log.ends):
            y_check, evaluations = hold(lo, np.array([hi]), y_check, u, loose=True)
            y_check = y_check[:, -1]
            log.n_eval += evaluations
            error = max(error, float(np.max(np.abs(tip_map @ (y_end - y_check)))))
        return error / hold.error_divisor
    except RuntimeError:
        return None


def _sampled_outputs(log, session, edges, grid, sample_time) -> SampledRun:
    """The run on the output grid (and its last time), with the held torque."""
    sample_times = edges[:len(log.us)]
    sample_torques = np.array(log.us, dtype=float)
    t_all = np.concatenate(log.ts)
    states = np.concatenate(log.ys, axis=1)
    # outputs on the grid (and the last time), as on the continuous path
    keep = np.isin(t_all, grid)
    keep[-1] = True
    t_all, states = t_all[keep], states[:, keep]
    index = np.clip(np.searchsorted(sample_times, t_all, side="right") - 1, 0,
                    max(len(log.us) - 1, 0))
    held = sample_torques[index] if log.us else np.zeros(t_all.size)
    report = dict(session.report() or {})
    report.update(samples=len(log.us), sample_time=sample_time)
    return SampledRun(t=t_all, states=states, torque=held, sample_times=sample_times,
                      sample_torques=sample_torques, stop=log.stop, message=log.message,
                      stop_state=log.stop_state, n_evaluations=log.n_eval,
                      integration_error=log.error, report=report,
                      controller_time=log.controller_time)
