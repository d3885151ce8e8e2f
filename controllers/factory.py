"""Build the controller a slew scene's ``[controller]`` table asks for.

The scene (:class:`flexctl.Scene`) carries the goal (:class:`flexctl.sim.maneuvers.Slew`:
angle, duration or free, actuator torque bound), the plant model and the design model size
(``[model] design_modes`` and ``design_variant``); :func:`from_spec` designs the controller on
a model of ``design_modes`` modes of the scene's design variant (exact on an exact plant,
first_order otherwise) and returns it ready for :func:`flexctl.simulate`.

Settings (all optional) per ``kind``:

==============  ================================================================================
kind            settings
==============  ================================================================================
pd              ``bandwidth`` (rad/s, default 2), ``damping_ratio`` (0.9), ``feedforward`` (true)
lqr             ``angle_error`` (rad, 0.05), ``rate_error`` (rad/s, 0.02), ``tip_deflection``
                (m, 0.01), ``modal_energy`` (J, off), ``torque`` (N m, 1.0), ``spin_rate``
                (rad/s, 0), ``reference`` ("poly7" or "cycloidal")
lqg             lqr settings plus ``angle_noise`` (rad, 1e-3), ``moment_noise`` (N m, 0.1),
                ``process_torque`` (N m, 0.1)
scheduled       lqr settings plus ``spin_rates`` (rad/s, [0, 1, 2])
trajopt         ``intervals`` (40), ``objective`` ("effort"; "time" when duration is free),
                ``transcription``, ``torque_rate_bound`` (N m/s), ``tip_bound`` (m)
trajopt+lqr     trajopt settings; LQR feedback about the optimal trajectory (Bryson weights:
                5 % of the angle, 3 % of the beam length at the tip, the torque bound)
bang_bang       none: rigid time-optimal at the torque bound, or the torque that fits the duration
zv, zvd         none: the bang-bang torque shaped at the first hub-free frequency
nmpc            ``horizon`` (20 samples), ``mode`` ("rti" or "converged"), ``qp_solver`` ("qrqp"),
                ``terminal`` ("lqr" or "rest"), ``reference`` ("trajopt": track the optimal slew,
                with the trajopt settings; or "none": regulate to the target),
                ``torque_rate_bound`` (N m/s), ``tip_bound`` (m), ``estimator`` ("state" or
                "kalman": extended Kalman filter on hub angle and root moment, with the lqg
                noise settings); runs at ``sample_time`` (0.02 s)
==============  ================================================================================

Every kind also takes ``sample_time`` (s): the law runs sampled with a zero-order hold
(:class:`flexctl.sim.digital.ZeroOrderHold`; not LQG, whose estimator is continuous).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from flexctl.model import Model, build_model
from flexctl.model.variants import EXACT_MAX_MODES
from flexctl.sim.digital import ZeroOrderHold
from flexctl.sim.maneuvers import Slew

from .lqg import NoiseLevels, design_lqg
from .lqr import LQRWeights, design_lqr
from .nmpc import NMPC
from .pd import design_pd
from .reference import SlewProfile, minimum_slew_duration
from .scheduling import design_scheduled_lqr
from .shaping import bang_bang, design_shaper, shape
from .spec import ControllerSpec, SceneError
from .tracking import TrajectoryTracker
from .trajopt import SlewProblem, solve_slew

__all__ = ["BuiltController", "OpenLoop", "from_spec"]

_LQR_DEFAULTS = {"angle_error": 0.05, "rate_error": 0.02, "tip_deflection": 0.01,
                 "modal_energy": None, "torque": 1.0}


@dataclass(frozen=True, eq=False)
class OpenLoop:
    """A torque function of time played open loop, as a static controller.

    Keeps the function's ``breakpoints`` so that :func:`flexctl.simulate` restarts there.
    """

    torque_function: object
    n_states: int = 0

    @property
    def breakpoints(self) -> tuple:
        """Times (s) where the torque is not smooth."""
        return tuple(getattr(self.torque_function, "breakpoints", ()) or ())

    def initial_state(self, x0):
        return np.zeros(0)

    def torque(self, t, x, z):
        return float(self.torque_function(t))

    @property
    def has_casadi_form(self) -> bool:
        """True when the torque function has a CasADi form (``casadi(t)``)."""
        return callable(getattr(self.torque_function, "casadi", None)) \
            and bool(getattr(self.torque_function, "has_casadi_form", True))

    def casadi_torque(self, t, x):
        """The torque function's CasADi expression of the symbol ``t`` (``x`` unused)."""
        return self.torque_function.casadi(t)

    def derivative(self, t, x, z):
        return np.zeros(0)


@dataclass(frozen=True, eq=False)
class BuiltController:
    """A controller built from a scene, with what its design measured.

    Attributes
    ----------
    controller : object
        Ready for ``flexctl.simulate(..., controller=...)``.
    kind : str
    maneuver_end : float
        Time at which the commanded slew is meant to be over, s (residual vibration is measured
        after it).
    design_modes : int
    info : dict
        E.g. ``solve_time_s``, ``ipopt_status``, ``iterations`` for trajectory optimisation.
    """

    controller: object
    kind: str
    maneuver_end: float
    design_modes: int
    info: dict = field(default_factory=dict)


def _setting(spec: ControllerSpec, key: str, default, kind=float):
    value = spec.settings.get(key, default)
    if value is None:
        return None
    if kind is float and (isinstance(value, bool) or not isinstance(value, (int, float))):
        raise SceneError(f"controller.{key} must be a number; got {value!r}")
    if kind is bool and not isinstance(value, bool):
        raise SceneError(f"controller.{key} must be true or false; got {value!r}")
    return value


def _wrap(func, *args, **kwargs):
    try:
        return func(*args, **kwargs)
    except SceneError:
        raise
    except ValueError as exc:
        raise SceneError(f"controller: {exc}") from None


def _lqr_weights(spec: ControllerSpec) -> LQRWeights:
    names = {"angle_error": "hub_angle", "rate_error": "hub_rate",
             "tip_deflection": "tip_deflection", "modal_energy": "modal_energy",
             "torque": "torque"}
    kwargs = {names[k]: _setting(spec, k, d) for k, d in _LQR_DEFAULTS.items()}
    return _wrap(LQRWeights, **kwargs)


def from_spec(scene, plant: Model | None = None) -> BuiltController:
    """Design the controller of a slew scene.

    Parameters
    ----------
    scene : flexctl.Scene
        A scene whose manoeuvre is a :class:`~flexctl.sim.maneuvers.Slew` with a ``[controller]``.
    plant : Model, optional
        The model the controller will run against (needed by LQG for its measurements);
        default ``scene.build_model()``.

    Returns
    -------
    BuiltController

    Raises
    ------
    flexctl.SceneError
        On a bad setting (naming it), or a trajectory optimisation that fails (with IPOPT's
        status).
    """
    maneuver, spec = scene.maneuver, scene.controller
    if not isinstance(maneuver, Slew) or spec is None:
        raise SceneError(f"scene {scene.name!r} is not a slew with a [controller] table")
    plant = scene.build_model() if plant is None else plant
    n_design = scene.model.design_modes
    if n_design > plant.n_modes:
        raise SceneError(f"model.design_modes must be <= model.modes = {plant.n_modes}; "
                         f"got {n_design}")
    if scene.design_variant == "exact" and n_design > EXACT_MAX_MODES:
        raise SceneError(f"model.design_modes must be at most {EXACT_MAX_MODES} for the exact "
                         f"design variant; got {n_design}")
    design = build_model(scene.design_system, n_modes=n_design, variant=scene.design_variant)
    angle, bound = maneuver.angle, maneuver.torque_bound
    kind = spec.kind

    duration = maneuver.duration
    if duration is None:
        if bound is None:
            raise SceneError("maneuver.torque_bound is required when maneuver.duration is "
                             "\"free\"")
        if kind in ("trajopt", "trajopt+lqr"):
            duration = None
        elif kind in ("bang_bang", "zv", "zvd"):
            duration = None
        else:
            duration = minimum_slew_duration(angle, design.matrices.J0, bound)

    if kind in ("pd", "lqr", "lqg", "scheduled"):
        profile_shape = spec.settings.get("reference", "poly7")
        info = {}
        if bound is not None:
            # a smooth reference the actuator cannot follow only winds the loop up: stretch it
            # to the shortest one the torque bound allows (5 % margin for the feedback)
            feasible = 1.05 * _wrap(minimum_slew_duration, angle, design.matrices.J0, bound,
                                    shape=profile_shape)
            if feasible > duration:
                info["reference_duration"] = feasible
                info["note"] = (f"the {profile_shape} reference needs {feasible:.3g} s at "
                                f"{bound:g} N m; stretched from {duration:.3g} s")
                duration = feasible
        profile = _wrap(SlewProfile, slew_angle=angle, duration=duration, shape=profile_shape)
        common = {"reference": profile, "torque_limit": bound}
        if kind == "pd":
            ctrl = _wrap(design_pd, design, _setting(spec, "bandwidth", 2.0),
                         _setting(spec, "damping_ratio", 0.9),
                         feedforward=_setting(spec, "feedforward", True, bool), **common)
        elif kind == "lqr":
            ctrl = _wrap(design_lqr, design, _lqr_weights(spec),
                         _setting(spec, "spin_rate", 0.0), **common)
        elif kind == "lqg":
            noise = _wrap(NoiseLevels, angle=_setting(spec, "angle_noise", 1e-3),
                          root_moment=_setting(spec, "moment_noise", 0.1),
                          torque=_setting(spec, "process_torque", 0.1))
            ctrl = _wrap(design_lqg, design, _lqr_weights(spec), noise,
                         _setting(spec, "spin_rate", 0.0), plant=plant, **common)
        else:
            rates = spec.settings.get("spin_rates", [0.0, 1.0, 2.0])
            ctrl = _wrap(design_scheduled_lqr, design, _lqr_weights(spec), rates, **common)
        return _sampled(spec, BuiltController(ctrl, kind, float(duration), n_design, info))

    if kind in ("bang_bang", "zv", "zvd"):
        limits = {"torque_limit": bound} if duration is None else {"duration": duration}
        base = _wrap(bang_bang, design, angle, **limits)
        if bound is not None and duration is not None and base.peak_torque > bound:
            raise SceneError(f"maneuver.duration {duration:g} s is shorter than the rigid "
                             f"minimum time at torque_bound {bound:g} N m")
        end = 2.0 * np.sqrt(abs(angle) * design.matrices.J0 / base.peak_torque)
        torque = base
        if kind != "bang_bang":
            shaper = design_shaper(design, kind)
            torque = shape(base, shaper)
            end += float(max(shaper.times))
        return _sampled(spec, BuiltController(OpenLoop(torque), kind, float(end), n_design))

    if bound is None:
        raise SceneError(f"controller kind {kind!r} needs maneuver.torque_bound")
    if kind == "nmpc":
        return _sampled(spec, _nmpc(spec, design, angle, duration, bound, n_design))
    solution, info = _trajectory(spec, design, angle, duration, bound)
    if kind == "trajopt":
        ctrl = OpenLoop(solution.torque_function())
    else:
        ctrl = _wrap(TrajectoryTracker, solution=solution, torque_limit=bound)
    return _sampled(spec, BuiltController(ctrl, kind, float(solution.duration), n_design,
                                          info))


def _trajectory(spec: ControllerSpec, design: Model, angle, duration, bound) -> tuple:
    """The optimal slew of the ``trajopt`` settings on the design model, and what its solve
    measured."""
    objective = spec.settings.get("objective", "time" if duration is None else "effort")
    problem = _wrap(SlewProblem, angle=angle, duration=duration, torque_bound=bound,
                    n_intervals=int(_setting(spec, "intervals", 40)), objective=objective,
                    torque_rate_bound=_setting(spec, "torque_rate_bound", None),
                    tip_bound=_setting(spec, "tip_bound", None),
                    transcription=spec.settings.get("transcription"))
    start = time.perf_counter()
    try:
        solution = _wrap(solve_slew, design, problem)
    except RuntimeError as exc:
        raise SceneError(f"controller: trajectory optimisation failed: {exc}") from None
    info = {"solve_time_s": time.perf_counter() - start, "ipopt_status": solution.return_status,
            "iterations": solution.iterations, "cost": solution.cost,
            "duration": solution.duration}
    return solution, info


def _nmpc(spec: ControllerSpec, design: Model, angle, duration, bound, n_design):
    """Nonlinear MPC tracking the optimal slew (``reference = "trajopt"``, default) or
    regulating to the target at rest (``reference = "none"``)."""
    reference = spec.settings.get("reference", "trajopt")
    if reference not in ("trajopt", "none"):
        raise SceneError("controller.reference for kind 'nmpc' must be \"trajopt\" or "
                         f"\"none\"; got {reference!r}")
    info, solution = {}, None
    if reference == "trajopt":
        solution, info = _trajectory(spec, design, angle, duration, bound)
        end = float(solution.duration)
    else:
        end = float(duration if duration is not None
                    else minimum_slew_duration(angle, design.matrices.J0, bound))
    settings = {key: spec.settings[key] for key in ("horizon", "mode", "qp_solver", "terminal")
                if key in spec.settings}
    estimator = spec.settings.get("estimator", "state")
    if estimator not in ("state", "kalman"):
        raise SceneError("controller.estimator for kind 'nmpc' must be \"state\" or "
                         f"\"kalman\"; got {estimator!r}")
    if estimator == "kalman":
        settings["noise"] = _wrap(NoiseLevels, angle=_setting(spec, "angle_noise", 1e-3),
                                  root_moment=_setting(spec, "moment_noise", 0.1),
                                  torque=_setting(spec, "process_torque", 0.1))
    start = time.perf_counter()
    ctrl = _wrap(NMPC, model=design, target=angle, torque_limit=bound, reference=solution,
                 sample_time=_setting(spec, "sample_time", 0.02),
                 torque_rate_limit=_setting(spec, "torque_rate_bound", None),
                 tip_limit=_setting(spec, "tip_bound", None), **settings)
    _wrap(ctrl.prepare)
    info["nmpc_build_time_s"] = time.perf_counter() - start
    info["substeps"] = ctrl.substeps
    return BuiltController(ctrl, "nmpc", end, n_design, info)


def _sampled(spec: ControllerSpec, built: BuiltController) -> BuiltController:
    """``built`` run at ``controller.sample_time`` with a zero-order hold, when given."""
    if "sample_time" not in spec.settings or built.kind == "nmpc":
        return built
    held = _wrap(ZeroOrderHold, built.controller, _setting(spec, "sample_time", None))
    return dataclasses.replace(built, controller=held,
                               info={**built.info, "sample_time": held.sample_time})
