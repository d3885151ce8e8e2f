"""Simulation of a spatial structure: a hub turning about any axis (:doc:`the spatial model
</guide/spatial>`).

:func:`simulate_spatial` integrates a spatial model
(:func:`~flexctl.model.spatial_dynamics.spatial_equations`: the exact rod by default, or its
first_order or zero_order expansion) under a hub torque given in the hub
frame: none, a constant 3-vector, a function of time, or samples (:class:`VectorTorque`, as a
scene's ``torque_samples`` gives them). The right-hand side runs as machine code from the
persistent compile cache where a compiler is found.

- **Integration.** CVODES's Adams-Moulton methods with functional iteration (no Jacobian)
  on the compiled right-hand side, from breakpoint to breakpoint: every sample of a
  :class:`VectorTorque` is one (a kink of a line, a jump of a hold), so no step crosses it; a
  line through more than :data:`THROUGH_SAMPLES` samples runs in one integration, its steps
  bounded by the sample interval. A stiff run (:data:`STIFF_SPACING`: a torsion or stiff-plane
  bending mode that turns ten radians or more between output times) takes exponential steps
  instead (:mod:`flexctl.sim.exponential`: the linear part integrated exactly, the steps set
  by the slew rather than by the fastest mode; ``benchmarks/bench_spatial.py`` (b)). A torque
  given as a Python function runs on SciPy's ``DOP853``. The error per step is below ``rtol``
  relative and ``atol`` absolute (on the exponential steps, a modal rate's ``atol`` times its
  mode's frequency).
- **Motion in one plane.** A run that cannot leave a plane (:mod:`flexctl.sim.spatial_plane`:
  appendages in the plane, the hub turning about its normal, a principal axis of extreme
  inertia, under a torque along it) integrates the equations restricted to the plane, some
  8 times cheaper to evaluate; its states are the whole model's, the out-of-plane ones
  zero. Under a torque of segments (a sine, steps, a hold, a few samples) they run on the
  compiled Adams-Moulton methods of the planar models (:mod:`flexctl.sim.spatial_adams`:
  Newton's iterations, no interface cost per step), else on CVODES's with Newton's
  iterations on the Jacobian at each segment's start. :data:`PLANE_MOTION` False integrates
  the whole model instead (``benchmarks/bench_spatial.py`` (a): 1.4 to 1.9 times the planar
  exact model's time at the same tolerances).
- **Its error.** With ``check_accuracy`` (default) the run is repeated at a tenth of the
  tolerances and :attr:`SpatialResult.integration_error` is the largest difference of any tip
  component, relative to that component's peak (the largest over the appendages). The
  repeat runs beside the run on a spare core where there is one
  (:class:`~flexctl.sim.background.Beside`), else after it.
- **The attitude** is a unit quaternion; its kinematics keep ``|q| = 1`` attracting, the
  largest departure over the run is :attr:`SpatialResult.quaternion_drift` (the run fails if
  it exceeds :data:`MAX_QUATERNION_DRIFT`), and the quaternions returned are normalised.
- **Divergence.** A state that leaves the finite numbers, or a failed integration, ends the
  run with ``status = "diverged"`` or ``"failed"`` and the message says why; nothing is
  silently returned as NaN.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from functools import cached_property, lru_cache, partial

import numpy as np

from ..model.checks import check_array, check_choice, check_real
from ..model.errors import InputTypeError, InputValueError
from ..model.spatial_dynamics import (SPATIAL_VARIANTS, SpatialEquations, spatial_equations,
                                      spatial_modes)
from ..model.spatial_structure import SpatialStructure
from .background import Beside
from .compile_cache import compiling_enabled
from .exponential import (Abandoned, ExponentialSegments, SegmentFailed, central_jacobian,
                          sample_bound, segment_torque)
from .spatial_adams import CompiledAdams, adams_library
from .spatial_plane import motion_plane, plane_motion

__all__ = ["VectorTorque", "SpatialResult", "simulate_spatial", "initial_state",
           "simulate_spatial_setup", "SpatialSegments", "ConstantTorque", "SegmentFailed",
           "machine_function",
           "quaternion_drift",
           "MAX_QUATERNION_DRIFT", "DEFAULT_RTOL"]

#: Largest ``| |q| - 1 |`` accepted over a run.
MAX_QUATERNION_DRIFT = 1e-6
#: Largest initial hub rate, rad/s: a run's steps follow the turn, and faster ones take hours.
MAX_SPIN = 1e3
#: Most steps of one integration from breakpoint to breakpoint (CVODES's budget): a run that
#: needs more ends "failed" and says so rather than running for hours.
MAX_STEPS = 2_000_000
#: Default relative tolerance.
DEFAULT_RTOL = 1e-8
#: A line through more samples than this runs in one integration with bounded steps.
THROUGH_SAMPLES = 16
#: Longest run, s (as a scene's ``simulation.t_final``).
MAX_T_FINAL = 1e6
#: Most output samples of one run.
MAX_SAMPLES = 2_000_000
#: Integrate a motion that stays in one plane on the equations restricted to that plane
#: (:mod:`flexctl.sim.spatial_plane`); False integrates the whole model (to compare).
PLANE_MOTION = True
#: Whether a stiff run of the whole model (:data:`STIFF_SPACING`) without wheels, under a
#: torque with a segment form, takes exponential steps (:mod:`flexctl.sim.exponential`);
#: False: CVODES's Adams-Moulton methods for every run.
EXPONENTIAL = True
#: The exponential steps are taken where the fastest mode of the model at the start (the
#: largest eigenvalue of the rate's Jacobian) turns at least this many radians over the median
#: interval between output times and breakpoints: Adams-Moulton would then take some 30 or
#: more steps an interval, held by that mode (``h omega = 0.33``), where the exponential steps
#: need only what their accuracy asks.
STIFF_SPACING = 10.0


@dataclass(frozen=True)
class VectorTorque:
    """A hub torque in the hub frame from samples.

    Parameters
    ----------
    times : array_like, shape (K,)
        Sample times, s: finite and strictly increasing, ``K >= 1``.
    values : array_like, shape (K, 3)
        Torque ``(tx, ty, tz)`` at each sample, N m: finite.
    interpolation : {"linear", "hold"}, optional
        Straight lines between samples, or each value held until the next sample. Outside
        the samples the first or last value. Default ``"linear"``.

    Examples
    --------
    >>> push = VectorTorque([0.0, 1.0], [[0.0, 0.0, 0.0], [2.0, 0.0, -1.0]])
    >>> push(0.5).tolist()
    [1.0, 0.0, -0.5]
    """

    times: np.ndarray
    values: np.ndarray
    interpolation: str = "linear"

    def __post_init__(self):
        times = np.array(check_array("torque samples", "times", self.times, shape=(None,)))
        if times.size < 1:
            raise InputValueError("torque samples: times must hold at least one sample")
        values = np.array(check_array("torque samples", "values", self.values,
                                      shape=(times.size, 3)))
        steps = np.diff(times)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0)) + 1
            raise InputValueError(f"torque samples: times must be strictly increasing (s); got "
                                  f"times[{k}] = {times[k]!r} after times[{k - 1}] = "
                                  f"{times[k - 1]!r}")
        if np.max(np.abs(values), initial=0.0) > 1e150:
            raise InputValueError("torque samples: values must be at most 1e150 N m in "
                                  "magnitude")
        check_choice("torque samples", "interpolation", self.interpolation, ("linear", "hold"))
        times.setflags(write=False)
        values.setflags(write=False)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)

    def __call__(self, t) -> np.ndarray:
        """The torque at time ``t`` (s), N m, shape (3,).

        Parameters
        ----------
        t : float
        """
        t = float(t)
        if self.interpolation == "hold" or self.times.size == 1:
            k = int(np.searchsorted(self.times, t, side="right")) - 1
            return np.array(self.values[max(k, 0)])
        return np.array([np.interp(t, self.times, self.values[:, j]) for j in range(3)])

    def at(self, times) -> np.ndarray:
        """The torque at each of ``times``, N m, shape (3, P): as ``self(t)`` for each.

        Parameters
        ----------
        times : array_like, shape (P,)
            Times, s: finite.
        """
        times = check_array("VectorTorque.at", "times", times, shape=(None,))
        if self.interpolation == "hold" or self.times.size == 1:
            k = np.searchsorted(self.times, times, side="right") - 1
            return np.array(self.values[np.maximum(k, 0)].T)
        return np.array([np.interp(times, self.times, self.values[:, j]) for j in range(3)])

    def segment_form(self, a: float, b: float) -> np.ndarray:
        """The torque on ``[a, b]`` (no sample inside), as the 11 numbers of
        ``p[0:3] + p[3:6] t + p[6:9] sin(p[9] (p[10] + t))`` in the segment's time ``t``.

        Parameters
        ----------
        a, b : float
            The segment, s.
        """
        start = self(a)
        slope = np.zeros(3) if self.interpolation == "hold" or self.times.size == 1 \
            else (self(b) - start) / (b - a)
        if self.interpolation == "hold":
            start = self(a + 0.5 * (b - a))         # the value held on the whole segment
        return np.concatenate([start, slope, np.zeros(5)])

    @property
    def breakpoints(self) -> np.ndarray:
        """Every sample time, s: the integration restarts there."""
        return self.times


@dataclass(frozen=True, eq=False)
class SpatialResult:
    """A spatial run's time histories.

    Attributes
    ----------
    structure : SpatialStructure
    n_modes : int or tuple of int
        Modes per field: of every appendage, or of each.
    t : ndarray, shape (P,)
        Output times, s.
    states : ndarray, shape (n, P)
        States, in the order of ``layout.state_names`` (quaternions normalised).
    torque : ndarray, shape (3, P)
        Hub torque, hub frame, N m: with wheels, the torque commanded of them.
    status : str
        ``"ok"``, ``"diverged"`` or ``"failed"``.
    message : str
    integration_error : float or None
        Estimated error of the tips, relative to each component's peak (the largest).
    quaternion_drift : float
        Largest ``| |q| - 1 |`` before normalising.
    wall_time : float
        Seconds.
    rtol : float
    n_steps : int
        Integration steps of the run (its accuracy check's not counted; 0 on SciPy's path,
        which does not report them).
    n_evaluations : int
        Right-hand-side evaluations of the run (its accuracy check's not counted).
    equations : SpatialEquations
        The model's CasADi functions the run integrated.
    """

    structure: SpatialStructure
    n_modes: int
    t: np.ndarray
    states: np.ndarray
    torque: np.ndarray
    status: str
    message: str
    integration_error: float | None
    quaternion_drift: float
    wall_time: float
    rtol: float
    equations: SpatialEquations = field(repr=False, default=None)
    n_steps: int = 0
    n_evaluations: int = 0

    @property
    def layout(self):
        """The state layout (:class:`~flexctl.model.spatial_dynamics.SpatialLayout`)."""
        return self.equations.layout

    @property
    def ok(self) -> bool:
        """True when the run reached its final time."""
        return self.status == "ok"

    @property
    def variant(self) -> str:
        """The model simulated: ``"exact"``, ``"first_order"`` or ``"zero_order"``."""
        return self.equations.variant

    @property
    def quaternion(self) -> np.ndarray:
        """Hub attitude, hub to inertial, scalar first, shape (4, P)."""
        return self.states[0:4]

    @property
    def angular_velocity(self) -> np.ndarray:
        """Hub angular velocity in the hub frame, rad/s, shape (3, P)."""
        c = self.layout.n_coordinates
        return self.states[c:c + 3]

    @property
    def hub_position(self) -> np.ndarray | None:
        """A free hub's centre in the inertial frame, m, shape (3, P); None when pinned."""
        return self.states[4:7] if self.layout.free else None

    @cached_property
    def tips(self) -> dict:
        """Each appendage's tip displacement from where the rigidly moving undeformed tip
        would be, hub frame, m: ``{name: (3, P)}``."""
        tips = machine_function(self.equations.tips).map(self.t.size)(self.states).full().reshape(
            3, -1, self.t.size, order="F") if self.t.size else np.zeros((3, 0, 0))
        return {name: tips[:, k, :] for k, name in enumerate(self.structure.names)}

    @property
    def wheel_speeds(self) -> np.ndarray | None:
        """Wheel speeds relative to the hub, rad/s, shape (n_wheels, P); None without
        wheels."""
        cluster = self.equations.cluster
        if cluster is None:
            return None
        start = self.layout.n_states - len(self.layout.wheels)
        return self.states[start:start + cluster.count]

    @cached_property
    def _wheel_outputs(self) -> tuple:
        outputs = self.equations.wheel_outputs
        if outputs is None or not self.t.size:
            count = 0 if outputs is None else self.equations.cluster.count
            return np.zeros((count, 0)), np.zeros(0)
        motor, power = outputs.map(self.t.size)(self.states, self.torque)
        return motor.full(), power.full().ravel()

    @property
    def wheel_torques(self) -> np.ndarray | None:
        """Motor torque on each rotor about its spin axis, N m, shape (n_wheels, P) (the hub
        feels its opposite); None without wheels."""
        return None if self.equations.cluster is None else self._wheel_outputs[0]

    @property
    def wheel_power(self) -> np.ndarray | None:
        """Power the wheels' motors draw, W, shape (P,); None without wheels."""
        return None if self.equations.cluster is None else self._wheel_outputs[1]

    def euler_angles(self) -> np.ndarray:
        """Hub attitude as 3-2-1 (yaw, pitch, roll) Euler angles, rad, shape (3, P)."""
        w, x, y, z = self.quaternion
        yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
        roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        return np.vstack([yaw, pitch, roll])

    def energy(self) -> np.ndarray:
        """Kinetic plus elastic energy at every sample, J, shape (P,)."""
        kinetic, elastic = self.equations.energy.map(self.t.size)(self.states)
        return kinetic.full().ravel() + elastic.full().ravel()

    def momentum(self) -> tuple:
        """``(angular (3, P), linear (3, P))`` momentum in the inertial frame: about the hub's
        centre (pinned) or the centre of mass (free), N m s, and N s."""
        angular, linear = self.equations.momentum.map(self.t.size)(self.states)
        return angular.full(), linear.full()


def initial_state(equations: SpatialEquations, angular_velocity=(0.0, 0.0, 0.0),
                  quaternion=(1.0, 0.0, 0.0, 0.0)) -> np.ndarray:
    """The state of a straight structure at rest relative to its hub.

    Parameters
    ----------
    equations : SpatialEquations
        The model's functions (:func:`~flexctl.model.spatial_dynamics.spatial_equations`).
    angular_velocity : array_like, shape (3,)
        Hub angular velocity, hub frame, rad/s.
    quaternion : array_like, shape (4,)
        Attitude, scalar first (normalised here).

    Returns
    -------
    ndarray, shape (n_states,)
    """
    layout = equations.layout
    w = check_array("initial", "angular_velocity", angular_velocity, shape=(3,))
    q = np.array(check_array("initial", "quaternion", quaternion, shape=(4,)))
    norm = float(np.linalg.norm(q))
    if not norm > 0:
        raise InputValueError("initial.quaternion must be non-zero")
    if np.max(np.abs(w)) > MAX_SPIN:
        raise InputValueError(f"initial.angular_velocity must be at most {MAX_SPIN:g} rad/s in "
                              f"magnitude; got {w.tolist()}")
    x = np.zeros(layout.n_states)
    x[0:4] = q / norm
    c = layout.n_coordinates
    x[c:c + 3] = w
    return x


def _torque_function(torque):
    """``(callable t -> (3,), breakpoints)`` of a torque argument."""
    if torque is None:
        return ConstantTorque(np.zeros(3)), np.zeros(0)
    if isinstance(torque, VectorTorque):
        return torque, torque.breakpoints
    if callable(torque) and hasattr(torque, "breakpoints"):    # a scene's manoeuvre
        return torque, np.asarray(torque.breakpoints, dtype=float)
    if callable(torque):
        def checked(t):          # a Python function: no segment form, SciPy's DOP853
            value = np.asarray(torque(t), dtype=float).reshape(-1)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise InputValueError(f"torque(t) must return 3 finite numbers (N m, hub "
                                      f"frame); at t = {t:g} s it returned {value!r:.80}")
            return value
        return checked, np.zeros(0)
    return ConstantTorque(np.array(check_array("", "torque", torque, shape=(3,)))), np.zeros(0)


class ConstantTorque:
    """A constant torque, N m, hub frame (``value``, shape (3,); a sampled loop sets it anew
    for each sample).

    Parameters
    ----------
    value : ndarray, shape (3,)
        The torque.
    """

    def __init__(self, value):
        self.value = value

    def __call__(self, t):
        """The torque at ``t`` (any time), N m.

        Parameters
        ----------
        t : float
            Time, s.
        """
        return self.value

    def at(self, times) -> np.ndarray:
        """The torque at each of ``times``, N m, shape (3, P).

        Parameters
        ----------
        times : array_like, shape (P,)
            Times, s: finite.
        """
        times = check_array("ConstantTorque.at", "times", times, shape=(None,))
        return np.repeat(np.asarray(self.value, dtype=float)[:, None], times.size, axis=1)

    def segment_form(self, a, b):
        """The 11 parameters of the torque on ``[a, b]`` (:class:`SpatialSegments`).

        Parameters
        ----------
        a, b : float
            The segment's ends, s.
        """
        return np.concatenate([self.value, np.zeros(8)])


def simulate_spatial(structure: SpatialStructure, t_final: float, torque=None, *,
                     n_modes: int = 4, angular_velocity=(0.0, 0.0, 0.0),
                     quaternion=(1.0, 0.0, 0.0, 0.0), x0=None,
                     rtol: float = DEFAULT_RTOL, atol: float | None = None,
                     output_step: float | None = None,
                     check_accuracy: bool = True, variant: str = "exact",
                     wheels=None, wheel_speeds=None) -> SpatialResult:
    """Simulate a spatial structure from ``0`` to ``t_final``.

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    t_final : float
        End time, s (> 0, at most :data:`MAX_T_FINAL`).
    torque : None, array_like (3,), callable or VectorTorque, optional
        Hub torque in the hub frame, N m: none (default), constant, ``torque(t) -> (3,)``, or
        samples.
    n_modes : int, sequence of int or mapping of str to int, optional
        Modes per field (1 to 12) of every appendage, or of each: a count per appendage in
        their order or by name (:func:`~flexctl.model.spatial_dynamics.spatial_modes`).
        Default 4.
    angular_velocity : array_like, shape (3,), optional
        Initial hub angular velocity, hub frame, rad/s (the structure starts straight and at
        rest relative to the hub). Default zero.
    quaternion : array_like, shape (4,), optional
        Initial attitude, hub to inertial, scalar first. Default the identity.
    x0 : array_like, shape (n_states,), optional
        The whole initial state instead (overrides ``angular_velocity``).
    rtol : float, optional
        Relative tolerance, in ``[1e-13, 1e-2]``. Default :data:`DEFAULT_RTOL`.
    atol : float, optional
        Absolute tolerance. Default ``rtol * 1e-3``. On exponential steps a modal rate's is
        this times its mode's frequency (:mod:`flexctl.sim.exponential`).
    output_step : float, optional
        Spacing of the output samples, s. Default ``t_final / 1000``.
    check_accuracy : bool, optional
        Repeat at a tenth of the tolerances to estimate the integration error. Default True.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model (:data:`~flexctl.model.spatial_dynamics.SPATIAL_VARIANTS`): the
        geometrically exact rod (default) or its equations to first order in the deflections,
        with or without the centrifugal stiffening.
    wheels : WheelCluster, optional
        Reaction wheels on the hub (:mod:`flexctl.model.wheel_cluster`): ``torque`` is then
        the hub torque commanded of them, distributed by their law. Default none (``torque``
        acts on the hub directly).
    wheel_speeds : array_like, shape (n_wheels,), optional
        Initial wheel speeds relative to the hub, rad/s (with ``wheels``; default zero;
        ignored with ``x0``, which holds them).

    Returns
    -------
    SpatialResult
    """
    t_final = check_real("", "t_final", t_final, minimum=0.0, strict=True, maximum=MAX_T_FINAL)
    rtol = check_real("", "rtol", rtol, minimum=1e-13, maximum=1e-2)
    atol = rtol * 1e-3 if atol is None else check_real("", "atol", atol, minimum=0.0,
                                                       strict=True)
    step = t_final / 1000 if output_step is None else check_real(
        "", "output_step", output_step, minimum=0.0, strict=True)
    if t_final / step > MAX_SAMPLES:
        raise InputValueError(f"output_step {step:g} s gives more than {MAX_SAMPLES} samples "
                              f"over t_final = {t_final:g} s")
    if not isinstance(check_accuracy, bool):
        raise InputTypeError(f"check_accuracy must be True or False; got {check_accuracy!r}")
    equations, x_start = simulate_spatial_setup(structure, n_modes, variant, wheels,
                                                wheel_speeds, angular_velocity, quaternion, x0)
    n_modes = equations.layout.n_modes
    drive, breakpoints = _torque_function(torque)
    times = np.unique(np.concatenate([np.arange(0.0, t_final, step), [t_final]]))
    start = time.perf_counter()
    # the run and its accuracy check are planned here, in the caller's thread (CasADi's
    # symbolic work is not thread-safe), and the check then runs beside the run
    plan = _Plan(equations, x_start, times, drive, breakpoints)
    run = plan.integration(rtol, atol)
    check = None
    if check_accuracy:
        fine = plan.integration(rtol / 10, atol / 10)
        check = Beside(fine, beside=fine.ready, cancelled=threading.Event())
    status, states, message, drift = run()
    error = None
    if check is not None:
        if status == "ok":
            fine_run = check.result()
            if fine_run is not None and fine_run[0] == "ok":
                error = _tip_error(plan, states, fine_run[1])
        else:
            check.abandon()
    reached = times[:states.shape[1]]
    torque_history = drive.at(reached) if hasattr(drive, "at") \
        else np.array([drive(t) for t in reached], dtype=float).reshape(-1, 3).T
    if states.shape[1]:
        states = states.copy()
        states[0:4] /= np.linalg.norm(states[0:4], axis=0)
    return SpatialResult(structure=structure, n_modes=n_modes, t=times[:states.shape[1]],
                         states=states, torque=torque_history, status=status, message=message,
                         integration_error=error, quaternion_drift=drift,
                         wall_time=time.perf_counter() - start, rtol=rtol,
                         equations=equations, n_steps=run.steps,
                         n_evaluations=run.evaluations)


def simulate_spatial_setup(structure: SpatialStructure, n_modes, variant: str, wheels,
                           wheel_speeds, angular_velocity, quaternion, x0=None) -> tuple:
    """The checked model and initial state of a spatial run (:func:`simulate_spatial`'s
    arguments of the same names).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, sequence of int or mapping of str to int
        Modes per field.
    variant : str
        One of :data:`~flexctl.model.spatial_dynamics.SPATIAL_VARIANTS`.
    wheels : WheelCluster or None
        Reaction wheels on the hub.
    wheel_speeds : array_like or None
        Their initial speeds, rad/s.
    angular_velocity : array_like, shape (3,)
        Initial hub rate, hub frame, rad/s.
    quaternion : array_like, shape (4,)
        Initial attitude, scalar first.
    x0 : array_like, optional
        The whole initial state instead.

    Returns
    -------
    tuple
        ``(equations, x0)``: the :class:`SpatialEquations` and the initial state.
    """
    if not isinstance(structure, SpatialStructure):
        raise InputTypeError(f"structure must be a SpatialStructure; got "
                             f"{type(structure).__name__}")
    n_modes = spatial_modes("", structure, n_modes)
    equations = spatial_equations(structure, n_modes,
                                  check_choice("", "variant", variant, SPATIAL_VARIANTS))
    if wheels is not None:
        equations = _with_wheels(equations, wheels)
    elif wheel_speeds is not None:
        raise InputValueError("wheel_speeds needs wheels (a WheelCluster)")
    if x0 is None:
        x_start = initial_state(equations, angular_velocity, quaternion)
        if wheel_speeds is not None:
            speeds = check_array("", "wheel_speeds", wheel_speeds, shape=(wheels.count,))
            for k, (speed, wheel) in enumerate(zip(speeds, wheels.wheels)):
                if abs(speed) > wheel.speed_limit:
                    raise InputValueError(
                        f"wheel_speeds[{k}] must be within the wheel's speed_limit "
                        f"({wheel.speed_limit:g} rad/s); got {speed!r}")
            start = equations.layout.n_states - len(equations.layout.wheels)
            x_start[start:start + wheels.count] = speeds
    else:
        x_start = np.array(check_array("", "x0", x0, shape=(equations.layout.n_states,)))
        norm = float(np.linalg.norm(x_start[0:4]))
        if not 1e-6 < norm < 1e6:
            raise InputValueError(f"x0[0:4] is the attitude quaternion and must be non-zero "
                                  f"(it is normalised); got {x_start[0:4].tolist()}")
        x_start[0:4] /= norm
        if np.max(np.abs(x_start[4:])) > 1e12:
            raise InputValueError("x0 entries must be at most 1e12 in magnitude (m, rad, "
                                  "m/s, rad/s)")
    return equations, x_start


@lru_cache(maxsize=16)
def _with_wheels(equations: SpatialEquations, wheels) -> SpatialEquations:
    """The equations with ``wheels`` (kept: a run and its repeats share the compiled
    right-hand side)."""
    from ..model.wheel_cluster import WheelCluster, with_wheels

    if not isinstance(wheels, WheelCluster):
        raise InputTypeError(f"wheels must be a WheelCluster; got {type(wheels).__name__}")
    return with_wheels(equations, wheels)


@lru_cache(maxsize=32)
def machine_function(function):
    """``function`` (a right-hand side, the tips) from the compile cache, kept: the cache
    finds it by its serialisation, which takes longer than many runs on the plane (0.5 s for
    the two-array model's right-hand side); the tips of a run and its check take 0.15 s on
    CasADi's virtual machine.

    Parameters
    ----------
    function : casadi.Function
        A spatial model's function.

    Returns
    -------
    casadi.Function
        Its compiled form (CasADi's own where no compiler is found).
    """
    import casadi as ca

    from .compile_cache import compiled

    native, values = _native(function)
    if native is not None:
        args = [ca.MX.sym(function.name_in(k), function.sparsity_in(k))
                for k in range(function.n_in())]
        return ca.Function(f"{function.name()}_native", args,
                           native.call(args + [ca.DM(values)]), function.name_in(),
                           function.name_out())
    return compiled(function, options=_NATIVE_OPTIONS)


#: finite differences only stand in for derivatives CasADi asks for when it builds an
#: integrator; CVODES's functional iteration (Adams) never evaluates them
_NATIVE_OPTIONS = {"enable_fd": True}


@lru_cache(maxsize=32)
def _native(function) -> tuple:
    """``(native, values)``: ``function`` with its numbers lifted into a last input
    (:func:`~flexctl.sim.lifted_constants.lift_constants`: one library for every structure
    of the same shape, a Monte Carlo's dispersed stiffness or another array length) as
    loaded from the compile cache, and those numbers; ``(None, None)`` where compiling is
    off, impossible or failed."""
    from .compile_cache import compiled
    from .lifted_constants import lift_constants

    lifted = lift_constants(function)
    if lifted is not None:
        built = compiled(lifted[0], options=_NATIVE_OPTIONS, label=function.name())
        if built is not lifted[0]:
            return built, np.asarray(lifted[1], dtype=float).ravel()
    return None, None


@lru_cache(maxsize=32)
def _mapped(function, count: int, numbers: bool = False):
    """``function.map(count)``, kept (for calls in the thread that plans a run); with
    ``numbers`` its last input (lifted numbers) the same for every column."""
    if numbers:
        return function.map(count, [False] * (function.n_in() - 1) + [True], [False])
    return function.map(count)


@lru_cache(maxsize=32)
def _adams_library(function):
    """:func:`~flexctl.sim.spatial_adams.adams_library` of ``function``'s compiled form, or
    None."""
    native, values = _native(function)
    return None if native is None else adams_library(native, values)


class _Plan:
    """What a run and its accuracy check share: the right-hand side they integrate (the
    whole model's, or its restriction to the plane the motion stays in,
    :mod:`flexctl.sim.spatial_plane`), the initial state and the segments."""

    def __init__(self, equations: SpatialEquations, x0, times, drive, breakpoints):
        self.equations, self.times, self.drive = equations, times, drive
        t_final = times[-1]
        self.line = (isinstance(drive, VectorTorque) and drive.interpolation == "linear"
                     and drive.times.size > THROUGH_SAMPLES)
        if self.line:    # a line through many samples: one run, bounded steps
            breakpoints = np.zeros(0)
        self.edges = np.unique(np.concatenate([[0.0], breakpoints[(breakpoints > 0)
                                                                  & (breakpoints < t_final)],
                                               [t_final]]))
        axis = motion_plane(equations, x0, drive, self.edges) \
            if PLANE_MOTION and equations.cluster is None else None
        self.plane = None if axis is None else plane_motion(equations, axis)
        self.rhs = machine_function(equations.integration_rhs if self.plane is None
                                    else self.plane.rhs)
        self.modal = equations.layout.modal_indices
        self.x0 = np.asarray(x0, dtype=float) if self.plane is None \
            else self.plane.restrict(x0)
        self.jacobian = None
        # the plane's compiled Adams-Moulton steps (a torque of segments)
        self.library = _adams_library(self.plane.rhs) if self.plane is not None \
            and not self.line and hasattr(drive, "segment_form") and compiling_enabled() \
            else None
        if self.library is not None:
            # the first step a hundredth of a radian of the fastest mode
            fastest = _spectral_radius(_difference_jacobian(
                _mapped(self.rhs, self.x0.size + 1), self.x0, drive(0.0)))
            self.h_first = float(min(0.01 / fastest if 0.0 < fastest < math.inf else math.inf,
                                     times[1] - times[0] if times.size > 1 else times[-1]))
        if EXPONENTIAL and self.plane is None and equations.cluster is None \
                and hasattr(drive, "segment_form"):
            self.jacobian = self._stiff(drive, breakpoints)

    def _stiff(self, drive, breakpoints):
        """The Jacobian of the rate at the start where the exponential steps are taken (the
        fastest mode turns more than :data:`STIFF_SPACING` radians over the median interval
        between two output times or breakpoints), else None."""
        jacobian = central_jacobian(_mapped(self.rhs, 2 * self.x0.size), self.x0, drive(0.0))
        self.fastest = _spectral_radius(jacobian)
        if not math.isfinite(self.fastest):
            return None
        ends = np.concatenate([self.times, self.edges, breakpoints if not self.line else
                               drive.times])
        ends = np.unique(ends[(ends >= 0.0) & (ends <= self.times[-1])])
        spacing = float(np.median(np.diff(ends))) if ends.size > 1 else float(self.times[-1])
        return jacobian if self.fastest * spacing >= STIFF_SPACING else None

    def integration(self, rtol: float, atol: float) -> "_Integration":
        """The integration at tolerances ``rtol``, ``atol``, its integrators built."""
        adams = SpatialSegments(self.rhs, self.x0.size, self.drive, rtol, atol, self.line,
                                newton=self.plane is not None and self.library is None)
        if self.library is not None:
            return _Integration(self, CompiledAdams(
                self.library, self.x0.size, self.drive, rtol, atol, MAX_STEPS, self.h_first,
                explain=partial(adams.too_much_work,
                                integrator="the compiled Adams-Moulton integrator")))
        if self.jacobian is None:
            return _Integration(self, adams)
        # the exponential steps give a segment up to Adams-Moulton where they are held below
        # a radian of the fastest mode (Adams-Moulton's steps are 0.33 radian at most, of
        # some 2 evaluations, theirs of 4)
        return _Integration(self, ExponentialSegments(
            self.rhs, self.x0.size, self.drive, rtol, atol, self.line, MAX_STEPS, self.modal,
            jacobian=self.jacobian, floor=1.0 / self.fastest), fallback=adams)


#: Integrators built ahead of a run at most (more distinct segments are built as they come,
#: and the accuracy check then runs after the run).
MAX_INTEGRATORS = 256
#: Adams-Moulton integrators built ahead as a fallback of exponential steps at most.
FALLBACKS_AHEAD = 4


class _Integration:
    """One integration over the plan's output times; called (in any thread), it gives
    ``(status, states (n, P'), message, drift)`` (whole states) or, cancelled, None."""

    def __init__(self, plan: _Plan, segments, fallback=None):
        self.plan, self.segments, self.fallback = plan, segments, fallback
        self.spent = (0, 0)            # steps and evaluations of abandoned exponential steps
        self.creator = threading.get_ident()
        self.pieces = []
        times = plan.times
        for a, b in zip(plan.edges[:-1], plan.edges[1:]):
            inside = times[(times > a) & (times <= b)]
            wanted = inside if inside.size and inside[-1] == b else np.append(inside, b)
            self.pieces.append((a, b, inside.size, wanted))
        # every integrator built now, in the caller's thread: a run may then go beside it
        self.ready = segments.form is not None and \
            segments.count([(a, b, wanted) for a, b, _, wanted in self.pieces]) \
            <= MAX_INTEGRATORS
        pieces = [(a, b, wanted) for a, b, _, wanted in self.pieces]
        # the fallback is built ahead only where it is cheap (a line: one integrator); else
        # as it is needed, in this thread
        self.fallback_built = self.ready and fallback is not None \
            and fallback.count(pieces) <= FALLBACKS_AHEAD
        if self.ready:
            for a, b, wanted in pieces:
                segments.build(a, b, wanted)
                if self.fallback_built:
                    fallback.build(a, b, wanted)

    @property
    def steps(self) -> int:
        """Steps taken (0 on SciPy's path)."""
        return self.segments.steps + self.spent[0]

    @property
    def evaluations(self) -> int:
        """Right-hand-side evaluations."""
        return self.segments.evaluations + self.spent[1]

    def _advance(self, a, b, x, wanted):
        try:
            return self.segments.advance(a, b, x, wanted)
        except Abandoned:
            if self.fallback_built or threading.get_ident() == self.creator:
                # the rest of the run on Adams-Moulton, from this segment's start
                self.spent = (self.segments.steps, self.segments.evaluations)
                self.segments, self.fallback = self.fallback, None
            else:        # beside the run, where no integrator may be built: go on as it was
                self.segments.floor = 0.0
            return self.segments.advance(a, b, x, wanted)

    def __call__(self, cancelled=None):
        plan = self.plan
        x = plan.x0.copy()
        states = np.zeros((x.size, plan.times.size))
        states[:, 0] = x
        done = 1
        for a, b, count, wanted in self.pieces:
            if cancelled is not None and cancelled.is_set():
                return None
            try:
                values = self._advance(a, b, x, wanted)
            except SegmentFailed as exc:
                whole = self._whole(states[:, :done])
                return "failed", whole, f"the integration failed at t = {a:g} s: {exc}", \
                    quaternion_drift(whole)
            if not np.all(np.isfinite(values)):
                whole = self._whole(states[:, :done])
                return "diverged", whole, (f"the run diverged between t = {a:g} and {b:g} s: "
                                           "the state left the finite numbers"), \
                    quaternion_drift(whole)
            states[:, done:done + count] = values[:, :count]
            done += count
            x = values[:, -1]
        whole = self._whole(states)
        drift = quaternion_drift(whole)
        if drift > MAX_QUATERNION_DRIFT:
            return "failed", whole, (f"the attitude quaternion's norm drifted by {drift:.3g} "
                                     f"(more than {MAX_QUATERNION_DRIFT:g})"), drift
        return "ok", whole, "reached t_final", drift

    def _whole(self, states) -> np.ndarray:
        return states if self.plan.plane is None else self.plan.plane.embed(states)


class SpatialSegments:
    """CVODES's Adams-Moulton methods from breakpoint to breakpoint, the torque on a segment
    ``a + b t + c sin(omega (t0 + t))`` in the segment's own time; one integrator per
    distinct output grid, kept. A torque of another form (a Python function) runs on SciPy's
    ``DOP853`` instead. A line through more than :data:`THROUGH_SAMPLES` samples (``line``)
    is integrated in one run, the torque interpolated inside the right-hand side and every
    step bounded by the shortest sample interval (so that no sample is stepped over), rather
    than restarted at every sample (each restart begins again at order 1 with a tiny step).

    The whole model's corrector is functional iteration (no Jacobian). With ``newton`` (the
    restriction to a plane) it is Newton's iteration on the Jacobian of the right-hand side
    at the segment's start (forward differences, ``n + 1`` evaluations), held over the
    segment. Measured on ``benchmarks/bench_spatial.py``: (a), the restriction on 4 modes,
    5 507 steps and 6 265 evaluations against functional iteration's 8 170 and 14 542 (1.6
    times less processor time), its tips 1.3e-7 of their peaks from a run at rtol 1e-12
    against 2.7e-7. (b), the whole two-array model, took 2.6 times fewer steps so (42 000
    against 110 000: its torsion and lateral modes, up to 3.6e3 rad/s, then bound the step
    by accuracy rather than by the iteration's convergence) and 3 times less processor time,
    but its tips came 1.2e-6 to 1.5e-6 from a run at rtol 1e-12 against 6.5e-7: the whole
    model keeps functional iteration. CasADi's own Jacobian of the compiled right-hand side
    (finite differences at each of CVODES's 4 400 linear setups, 56 evaluations each) cost
    more than the steps saved (297 000 evaluations against 207 600); CVODES's BDF took
    69 000 steps on (b) and 461 000 on (a)'s whole model, whose undamped modes its orders 3
    to 5 amplify.

    Parameters
    ----------
    rhs : casadi.Function
        ``(x, torque) -> x_t``.
    n_states : int
        Length of ``x``.
    drive : callable
        The torque, ``t -> (3,)``, with ``segment_form(a, b)`` (its 11 parameters on a
        segment) where it has one.
    rtol, atol : float
        CVODES's tolerances.
    line : bool
        A :class:`VectorTorque` line through many samples, integrated in one run.
    newton : bool, optional
        Newton's iterations on the Jacobian at each segment's start. Default False.
    """

    def __init__(self, rhs, n_states: int, drive, rtol: float, atol: float, line: bool,
                 newton: bool = False):
        self.rhs, self.n_states, self.drive = rhs, n_states, drive
        self.rtol, self.atol, self.line, self.newton = rtol, atol, line, newton
        self.integrators: dict = {}
        self.steps = self.evaluations = 0
        self.form = getattr(drive, "segment_form", None)
        # built here, in the caller's thread, for the differences taken as the run goes
        self.differences = rhs.map(n_states + 1) if newton else None

    def _key(self, a: float, b: float, wanted) -> tuple:
        if self.line:
            return ("line", tuple(np.asarray(wanted) - a))
        return (round(b - a, 15), tuple(np.round(np.asarray(wanted) - a, 15)))

    def count(self, pieces) -> int:
        """Distinct integrators of ``pieces``.

        Parameters
        ----------
        pieces : list of tuple
            ``(a, b, wanted)`` each: a segment's ends (s) and its output times.
        """
        return len({self._key(a, b, wanted) for a, b, wanted in pieces})

    def build(self, a: float, b: float, wanted):
        """The integrator of the segment ``[a, b]`` onto ``wanted``, built once.

        Parameters
        ----------
        a, b : float
            The segment's ends, s.
        wanted : array_like
            Output times in ``(a, b]``, ascending, ending at ``b``, s.
        """
        key = self._key(a, b, wanted)
        if key not in self.integrators:
            if len(self.integrators) > MAX_INTEGRATORS:
                self.integrators.clear()
            self.integrators[key] = self._line_integrator(key[1]) if self.line \
                else self._segment_integrator(key[1])
        return self.integrators[key]

    def _line_integrator(self, grid: tuple):
        import casadi as ca

        drive = self.drive
        times = np.concatenate([[min(0.0, drive.times[0] - 1.0)], drive.times,
                                [drive.times[-1] + 1.0]])
        values = np.vstack([drive.values[:1], drive.values, drive.values[-1:]])
        table = ca.interpolant("torque", "linear", [times], values.T.ravel(order="F"))
        state, t = ca.MX.sym("x", self.n_states), ca.MX.sym("t")
        p = ca.MX.sym("p", 1)                      # the segment's start time
        ode, p = self._ode(state, table(p[0] + t), p)
        return ca.integrator(
            "spatial_line", "cvodes", {"x": state, "t": t, "p": p, "ode": ode},
            0.0, list(grid), {**self._options(), "max_step_size": float(np.min(np.diff(
                drive.times)))})

    def _segment_integrator(self, grid: tuple):
        import casadi as ca

        state, t, p = ca.MX.sym("x", self.n_states), ca.MX.sym("t"), ca.MX.sym("p", 11)
        torque = segment_torque(p, t)
        ode, p = self._ode(state, torque, p)
        return ca.integrator("spatial", "cvodes", {"x": state, "t": t, "p": p, "ode": ode},
                             0.0, list(grid), self._options())

    def _ode(self, state, torque, p) -> tuple:
        """``(ode, parameters)``: the rate, and with ``newton`` the Jacobian its Newton
        iterations take, the parameters ``p`` then followed by its ``n^2`` entries."""
        import casadi as ca

        rate = self.rhs(state, torque)
        if not self.newton:
            return rate, p
        n = self.n_states
        entries = ca.MX.sym("jacobian", n * n)
        jacobian = ca.reshape(entries, n, n)
        # the rate's value, and the held Jacobian as its derivative
        ode = ca.stop_diff(rate - ca.mtimes(jacobian, state), 1) + ca.mtimes(jacobian, state)
        return ode, ca.vertcat(p, entries)

    def _options(self) -> dict:
        return {"linear_multistep_method": "adams",
                "nonlinear_solver_iteration": "newton" if self.newton else "functional",
                "abstol": self.atol, "reltol": self.rtol, "max_num_steps": MAX_STEPS}

    def _jacobian(self, a: float, x) -> np.ndarray:
        """The right-hand side's Jacobian at ``x`` and the torque at ``a``, by forward
        differences (column-major entries)."""
        self.evaluations += self.n_states + 1
        return _difference_jacobian(self.differences, x, self.drive(a)).ravel(order="F")

    def too_much_work(self, a: float, b: float, x, wanted, integrator: str = "CVODES") -> str:
        """Why an integrator ran out of steps between two of the output times ``wanted`` on
        ``[a, b]``: a line's sample interval that bounds every step, or the fastest
        eigenvalue of the model at ``a`` and the step it allows.

        Parameters
        ----------
        a, b : float
            The segment's ends, s.
        x : ndarray, shape (n_states,)
            The state at ``a``.
        wanted : array_like
            The segment's output times, s.
        integrator : str, optional
            Its name in the message. Default ``"CVODES"``.
        """
        head = (f"{integrator} took all of its {MAX_STEPS:g} steps between two output times "
                f"in [{a:g}, {b:g}] s")
        bound = sample_bound(self.drive.times, a, wanted, MAX_STEPS) if self.line else None
        if bound is not None:
            return f"{head}: {bound}"
        mapped = self.differences if self.differences is not None \
            else self.rhs.map(self.n_states + 1)
        fastest = _spectral_radius(_difference_jacobian(mapped, x, self.drive(a)))
        if not fastest > 0:
            return head
        return (f"{head}: the model's fastest eigenvalue at t = {a:g} s, {fastest:.3g} 1/s, "
                f"holds its steps near {0.33 / fastest:.2g} s. Its source is a stiff mode "
                f"(torsion, a stiff bending plane, a short or very stiff appendage), a fast "
                f"wheel lag, or a torque that spins the structure up at once; fewer modes per "
                f"field, a less stiff structure, a smaller torque or a shorter output_step "
                f"would let the run finish")

    def advance(self, a: float, b: float, x, wanted) -> np.ndarray:
        """The states at ``wanted``, from ``x`` at ``a``.

        Parameters
        ----------
        a, b : float
            The segment's ends, s.
        x : ndarray, shape (n_states,)
            The state at ``a``.
        wanted : array_like
            Output times in ``(a, b]``, ascending, ending at ``b``, s.

        Returns
        -------
        ndarray, shape (n_states, len(wanted))

        Raises
        ------
        SegmentFailed
            When the integration cannot go on (the message says why).
        """
        if self.form is None:
            return self._scipy(a, b, x, wanted)
        p = np.atleast_1d(a if self.line else self.form(a, b))
        if self.newton:
            p = np.concatenate([p, self._jacobian(a, x)])
        try:
            return self._call(self.build(a, b, wanted), x, p)
        except SegmentFailed as exc:
            if "CV_TOO_MUCH_WORK" in str(exc):
                raise SegmentFailed(self.too_much_work(a, b, x, wanted)) from None
            raise

    def _call(self, integrator, x, p) -> np.ndarray:
        """``integrator`` from ``x`` with parameters ``p``, its steps and evaluations
        counted."""
        try:
            result = integrator(x0=x, p=p)["xf"].full()
        except RuntimeError as exc:
            raise SegmentFailed(" ".join(str(exc).split())[-300:]) from None
        finally:
            stats = integrator.stats()
            self.steps += int(stats.get("nsteps", 0))
            self.evaluations += int(stats.get("nfevals", 0))
        return result

    def _scipy(self, a, b, x, wanted) -> np.ndarray:
        from scipy.integrate import solve_ivp

        def rate(t, y):
            return self.rhs(y, self.drive(t)).full().ravel()

        try:
            solution = solve_ivp(rate, (a, b), x, method="DOP853", t_eval=wanted,
                                 rtol=self.rtol, atol=self.atol)
        except (ValueError, ArithmeticError) as exc:
            raise SegmentFailed(str(exc)) from None
        self.evaluations += int(solution.nfev)
        if solution.status != 0 or solution.y.shape[1] != len(wanted):
            if solution.y.size and not np.all(np.isfinite(solution.y)):
                return np.full((self.n_states, len(wanted)), np.nan)
            raise SegmentFailed(solution.message)
        return solution.y


def _difference_jacobian(mapped, x, torque) -> np.ndarray:
    """A right-hand side's Jacobian (n, n) at ``x`` under ``torque`` (3,), by forward
    differences; ``mapped`` is the right-hand side mapped over ``n + 1`` columns."""
    x = np.asarray(x, dtype=float)
    n = x.size
    steps = 1.5e-8 * np.maximum(np.abs(x), 1.0)
    points = np.tile(x[:, None], (1, n + 1))
    points[np.arange(n), np.arange(n)] += steps
    torques = np.tile(np.asarray(torque, dtype=float)[:, None], (1, n + 1))
    rates = mapped(points, torques).full()
    return (rates[:, :n] - rates[:, n:]) / steps


def _spectral_radius(jacobian: np.ndarray) -> float:
    """The largest eigenvalue's modulus of a rate's Jacobian, 1/s (``inf`` where an entry is
    not finite)."""
    if not np.all(np.isfinite(jacobian)):
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(jacobian))))


def quaternion_drift(states) -> float:
    """Largest ``| |q| - 1 |`` over a run's states.

    Parameters
    ----------
    states : ndarray, shape (n, P)
        States, the quaternion first.
    """
    if not states.shape[1]:
        return 0.0
    return float(np.max(np.abs(np.linalg.norm(states[0:4], axis=0) - 1.0)))


def _tip_error(plan: _Plan, coarse, fine) -> float:
    """Largest tip difference, relative to each component's peak (at least 1e-12 m)."""
    count = min(coarse.shape[1], fine.shape[1])
    both = np.hstack([coarse[:, :count], fine[:, :count]])
    tips = plan.equations.tips
    if plan.plane is not None:
        tips, both = plan.plane.tips, plan.plane.embedding.T @ both
    native, values = _native(tips)
    if native is not None:       # the compiled function, its numbers the same for every column
        both = _mapped(native, 2 * count, True)(both, values).full()
    else:
        both = machine_function(tips).map(2 * count)(both).full()
    half = both.shape[1] // 2
    a, b = both[:, :half], both[:, half:]
    peaks = np.maximum(np.max(np.abs(b.reshape(3, -1, count, order="F")), axis=2), 1e-12)
    diff = np.max(np.abs((a - b).reshape(3, -1, count, order="F")), axis=2)
    return float(np.max(diff / peaks)) if math.isfinite(float(np.max(diff))) else math.inf
