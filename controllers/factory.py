"""Build the controller a slew scene's ``[controller]`` table asks for.

The scene (:class:`flexctl.Scene`) carries the goal (:class:`flexctl.sim.maneuvers.Slew`:
angle, duration or free, actuator torque bound), the plant model and the design model size
(``[model] design_modes`` and ``design_variant``); :func:`from_spec` designs the controller on
a model of ``design_modes`` modes of the scene's design variant (exact on an exact plant,
first_order otherwise) and returns it ready for :func:`flexctl.simulate`.

Settings (all optional) per ``kind``, from the registry :data:`controllers.spec.CONTROLLER_KINDS`
(``tests/controllers/test_controller_registry.py`` checks that this table is
:func:`controllers.spec.settings_table`)::

    ===========  ===============================================================================
    kind         settings
    ===========  ===============================================================================
    pd           PD on the hub angle about a smooth reference.
                 ``bandwidth`` (rad/s; default 2; a number > 0): closed-loop bandwidth
                 ``damping_ratio`` (default 0.9; a number > 0): closed-loop damping ratio
                 ``feedforward`` (default true; true or false): add the rigid-body torque of the
                   reference
                 ``reference`` (default "poly7"; one of "poly7", "cycloidal"): shape of the
                   reference slew the loop tracks
                 ``sample_time`` (s; a number > 0): run the law sampled with a zero-order hold
                   at this period (default: continuous)
                 ``filters`` (an array of tables, each with kind = "notch" | "roll_off" |
                   "lead_lag"): structural filters on the sampled command (needs sample_time or
                   [sensors]), e.g. [{kind = "notch", frequency = 23.8, depth_db = 20}]; notch:
                   frequency (rad/s), depth_db, width; roll_off: frequency, damping; lead_lag:
                   zero, pole (rad/s)
    lqr          full-state LQR about a smooth reference.
                 ``hub_angle`` (rad; default 0.05; a number in [1e-12, 1e+12]): LQR (Bryson)
                   weight: acceptable hub angle error (was ``angle_error``, deprecated)
                 ``hub_rate`` (rad/s; default 0.02; a number in [1e-12, 1e+12]): LQR weight:
                   acceptable hub rate error (was ``rate_error``, deprecated)
                 ``tip_deflection`` (m; default 0.01; a number in [1e-12, 1e+12]): LQR weight:
                   acceptable tip deflection
                 ``modal_energy`` (J; a number in [1e-12, 1e+12]): LQR weight: acceptable modal
                   energy (default: off)
                 ``torque`` (N m; default 1; a number in [1e-12, 1e+12]): LQR weight: acceptable
                   torque
                 ``reference``, ``sample_time``, ``filters``: as for pd
                 ``spin_rate`` (rad/s; default 0; a finite number): hub rate of the
                   linearization the gain is designed at
    lqg          LQR on a Kalman-Bucy estimate from hub angle and root moment.
                 ``hub_angle``, ``hub_rate``, ``tip_deflection``, ``modal_energy``, ``torque``:
                   as for lqr
                 ``reference``: as for pd
                 ``spin_rate``: as for lqr
                 ``angle_noise`` (rad; default 0.001; a number > 0): hub angle measurement noise
                   (estimator)
                 ``moment_noise`` (N m; default 0.1; a number > 0): root bending moment
                   measurement noise (estimator)
                 ``process_torque`` (N m; default 0.1; a number > 0): disturbance torque on the
                   hub (estimator)
                 ``filters``: as for pd
    scheduled    LQR gains designed at several spin rates, interpolated at the hub rate.
                 ``hub_angle``, ``hub_rate``, ``tip_deflection``, ``modal_energy``, ``torque``:
                   as for lqr
                 ``reference``, ``sample_time``, ``filters``: as for pd
                 ``spin_rates`` (rad/s; default [0, 1, 2]; an array of numbers >= 0): design
                   spin rates, strictly increasing
    trajopt      optimal slew on the design model, played open loop.
                 ``n_intervals`` (default 40; an integer >= 2): control intervals of the
                   transcription (was ``intervals``, deprecated)
                 ``objective`` (one of "effort", "time"): default: effort, or time when
                   maneuver.duration is free
                 ``transcription`` (one of "multiple_shooting", "collocation"): default: by the
                   design model (collocation for exact)
                 ``torque_rate_bound`` (N m/s; a number > 0): bound on the torque rate (default:
                   none)
                 ``tip_bound`` (m; a number > 0): bound on the tip deflection (default: none)
                 ``effort_tolerance`` (default 0.01; a number > 0): largest relative excess of
                   the torque holds' least effort over the converged slew's (fixed duration)
                 ``sample_time``: as for pd
    trajopt+lqr  optimal slew with LQR feedback about it (Bryson weights: 5 % of the angle, 3 %
                   of the beam length at the tip, the torque bound).
                 ``n_intervals``, ``objective``, ``transcription``, ``torque_rate_bound``,
                   ``tip_bound``, ``effort_tolerance``: as for trajopt
                 ``sample_time``, ``filters``: as for pd
    bang_bang    rigid time-optimal at the torque bound, or the torque that fits the duration.
                 ``sample_time``: as for pd
    zv           ZV shaper: the bang-bang torque shaped at the first hub-free frequency.
                 ``sample_time``: as for pd
    zvd          ZVD shaper: the bang-bang torque shaped at the first hub-free frequency.
                 ``sample_time``: as for pd
    nmpc         nonlinear MPC on the design model, run sampled.
                 ``horizon`` (samples; default 20; an integer in [2, 500]): prediction horizon
                 ``mode`` (default "rti"; one of "rti", "converged"): real-time iteration or
                   solved to convergence (IPOPT)
                 ``qp_solver`` (default "qrqp"; one of "qrqp", "osqp", "qpoases", "hpipm"):
                   CasADi QP solver of the real-time iteration
                 ``terminal`` (default "lqr"; one of "lqr", "rest"): terminal cost (LQR) or
                   terminal rest constraint
                 ``reference`` (default "trajopt"; one of "trajopt", "none"): track the optimal
                   slew, or regulate to the target
                 ``n_intervals``, ``objective``, ``transcription``, ``torque_rate_bound``,
                   ``tip_bound``, ``effort_tolerance``: as for trajopt
                 ``estimator`` (default "state"; one of "state", "kalman"): measured state, or
                   an extended Kalman filter on hub angle and root moment
                 ``angle_noise``, ``moment_noise``, ``process_torque``: as for lqg
                 ``sample_time`` (s; default 0.02; a number > 0): sample period
    ===========  ===============================================================================

``sample_time`` runs the law with a zero-order hold (:class:`flexctl.sim.digital.ZeroOrderHold`);
LQG does not take it, since its estimator integrates continuously.

With ``[sensors]`` a feedback law reads the discrete Kalman estimate of their readings
(:class:`~controllers.feedback.observer.Observed`), its filter built once on the plant the
design is given: ``lqg`` is then the LQR on that estimate with ``process_torque`` as the
filter's process noise, the readings' noise being the sensors' own. A setting the design
would not use is refused by name rather than dropped (:func:`refuse_ignored_settings`):
``angle_noise`` or ``moment_noise`` with ``[sensors]``, an NMPC's noise settings on the
exact state, ``[sensors]`` for an open-loop kind, a spin rate for a wheel's LQR.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

from flexctl.model import Model, build_model
from flexctl.model.errors import InputTypeError
from flexctl.model.user_warnings import warn_user
from flexctl.model.variants import EXACT_MAX_MODES
from flexctl.sim.digital import ZeroOrderHold, is_sampled
from flexctl.sim.maneuvers import Slew
from flexctl.sim.sensors import DEFAULT_SAMPLE_TIME as DEFAULT_SENSOR_SAMPLE_TIME
from flexctl.sim.simulation import StaticLaw

from .feedback.actuated import (actuator_torque_bound, check_reference_fits, design_wheel_lqr,
                                through_actuator)
from .feedback.lqg import NoiseLevels, design_lqg
from .feedback.lqr import LQRWeights, design_lqr
from .mpc.nmpc import NMPC
from .feedback.observer import Observed
from .feedback.pd import design_pd
from .slew.reference import SlewProfile, minimum_slew_duration
from .feedback.scheduling import design_scheduled_lqr
from .slew.shaping import bang_bang, design_shaper, shape
from .spec import CONTROLLER_KINDS, ControllerSpec, SceneError, refuse_ignored_settings
from .design.stability import check_loop, warn_if_unstable
from .feedback.tracking import TrajectoryTracker
from .slew.trajopt import SlewProblem, SlewSolution, solve_slew

__all__ = ["BuiltController", "OpenLoop", "from_spec", "DesignChangedWarning",
           "refuse_ignored_settings"]

class OpenLoop(StaticLaw):
    """A torque function of time played open loop, as a static controller.

    ``OpenLoop(f)`` gives ``torque(t, x) = f(t)``; ``f``'s ``breakpoints`` are kept so that
    :func:`flexctl.simulate` restarts there, and its ``casadi(t)`` form, if any, runs it
    compiled.

    Parameters
    ----------
    law : callable
        ``f(t)``: the hub torque, N m, at time ``t`` (s).
    """

    @property
    def torque_function(self):
        """The played function of time."""
        return self.law

    def torque(self, t, x, z=None) -> float:
        """``f(t)``, N m.

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state (not read).
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        return float(self.law(t))

    @property
    def has_casadi_form(self) -> bool:
        """True when the torque function has a CasADi form (``casadi(t)``)."""
        return callable(getattr(self.law, "casadi", None)) \
            and bool(getattr(self.law, "has_casadi_form", True))

    def casadi_torque(self, t, x):
        """The torque function's CasADi expression of the symbol ``t``.

        Parameters
        ----------
        t : CasADi scalar
            Time, s.
        x : CasADi column, shape (n, 1)
            Plant state (not read).
        """
        return self.law.casadi(t)


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
        Modes of the design model, all appendages together.
    info : dict
        E.g. ``solve_time_s``, ``ipopt_status``, ``iterations`` for trajectory optimisation.
    """

    controller: object
    kind: str
    maneuver_end: float
    design_modes: int
    info: dict = field(default_factory=dict)

    @property
    def reference_angle(self):
        """The hub-angle reference the controller tracks, as ``angle(t)`` (rad, ``t`` in s, a
        float or an array), or None for a law that tracks none (open loop, regulation).

        Looked for through the wrappers that hold a law in ``law`` (zero-order hold,
        observer, DC-motor voltage): a ``reference`` with ``angle(t)`` (a
        :class:`~controllers.slew.reference.SlewProfile`), or a planned slew
        (:class:`~controllers.slew.trajopt.SlewSolution`, the tracker's ``solution`` or the
        NMPC's ``reference``) whose design-model hub angle is the reference.
        """
        law, seen = self.controller, set()
        while law is not None and id(law) not in seen:
            seen.add(id(law))
            reference = getattr(law, "reference", None)
            if callable(getattr(reference, "angle", None)):
                return reference.angle
            plan = reference if isinstance(reference, SlewSolution) \
                else getattr(law, "solution", None)
            if isinstance(plan, SlewSolution):
                return lambda t, plan=plan: plan.model.layout.hub_angle(plan.state_at(t))
            law = getattr(law, "law", None)
        return None


class DesignChangedWarning(UserWarning):
    """The scene's design was changed to one the hardware can fly (e.g. a reference slew
    stretched to what the torque bound allows); the summary's ``slew.note`` says the same."""


def _wrap(func, *args, **kwargs):
    try:
        return func(*args, **kwargs)
    except SceneError:
        raise
    except ValueError as exc:
        raise SceneError(f"controller: {exc}") from None


#: LQRWeights fields, set by the settings of the same names.
_WEIGHT_SETTINGS = ("hub_angle", "hub_rate", "tip_deflection", "modal_energy", "torque")
#: NoiseLevels fields and the settings that set them: the [controller] table is flat, so the
#: noise settings carry "noise" (and "process") to tell them from the LQR weights.
NOISE_SETTINGS = {"angle": "angle_noise", "root_moment": "moment_noise",
                  "torque": "process_torque"}


def _lqr_weights(spec: ControllerSpec) -> LQRWeights:
    return _wrap(LQRWeights, **{name: spec.get(name) for name in _WEIGHT_SETTINGS})


def _noise(spec: ControllerSpec) -> NoiseLevels:
    return _wrap(NoiseLevels, **{field: spec.get(key) for field, key in NOISE_SETTINGS.items()})


#: Kinds that track a smooth reference slew with feedback (``_feedback``).
_FEEDBACK_KINDS = ("pd", "lqr", "lqg", "scheduled")
#: Kinds that play the rigid bang-bang torque, shaped or not (``_open_loop``).
_OPEN_LOOP_KINDS = ("bang_bang", "zv", "zvd")
#: Kinds that take a free duration as a minimum-time problem of their own.
_OWN_DURATION_KINDS = ("trajopt", "trajopt+lqr") + _OPEN_LOOP_KINDS


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
    actuator = getattr(plant, "actuator", None)
    refuse_ignored_settings(spec, sensed=scene.sensors is not None, actuator=actuator)
    design = _design_model(scene, plant)
    angle, kind = maneuver.angle, spec.kind
    bound = actuator_torque_bound(actuator, maneuver.torque_bound)
    duration = _slew_duration(dataclasses.replace(maneuver, torque_bound=bound), kind, design)
    if kind in _FEEDBACK_KINDS:
        # with sensors, LQG's estimator is the sampled Kalman filter of their readings
        # (_hardware): the law behind it is LQR
        law = "lqr" if kind == "lqg" and scene.sensors is not None else kind
        built = _feedback(spec, design, plant, angle, duration, bound, law,
                          _loop_sample_time(scene, spec))
    elif kind in _OPEN_LOOP_KINDS:
        built = _open_loop(spec, design, angle, duration, bound, actuator)
    elif bound is None:
        raise SceneError(f"controller kind {kind!r} needs maneuver.torque_bound")
    elif kind == "nmpc":
        built = _nmpc(spec, design, angle, duration, bound, design.n_modes, actuator,
                      scene.sensors is not None)
    else:
        built = _optimal(spec, design, angle, duration, bound, actuator)
    return _checked(_filtered(spec, plant, _hardware(scene, plant, spec, built)), plant)


def _filter_of(k: int, table: dict):
    """The structural filter of ``controller.filters[k]``, its errors naming the key."""
    from .feedback.structural_filters import FILTER_KINDS

    cls = FILTER_KINDS[table["kind"]]
    params = {key: value for key, value in table.items() if key != "kind"}
    where = f"controller.filters[{k}]"
    allowed = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise SceneError(f"{where}.{unknown[0]} is not a setting of a {table['kind']} filter; "
                         f"expected {', '.join(allowed)}")
    missing = [f.name for f in dataclasses.fields(cls) if f.name not in params
               and f.default is dataclasses.MISSING]
    if missing:
        raise SceneError(f"{where}.{missing[0]} is required for a {table['kind']} filter")
    try:
        return cls(**params)
    except (TypeError, ValueError) as exc:
        raise SceneError(str(exc).replace(f"{cls.__name__}.", f"{where}.")) from None


def _filtered(spec: ControllerSpec, plant: Model, built: BuiltController) -> BuiltController:
    """``built`` with ``controller.filters`` on its sampled command, when given."""
    tables = spec.get("filters") if "filters" in _kind_settings(spec) else None
    if not tables:
        return built
    from .feedback.structural_filters import Filtered

    if getattr(plant, "actuator", None) is not None \
            and getattr(plant.actuator, "kind", "") == "dc_motor":
        raise SceneError("controller.filters shape a torque command; a DC motor's law "
                         "commands a voltage")
    if not is_sampled(built.controller):
        raise SceneError(f"controller.filters need a sampled loop (the filters are discrete): "
                         f"set controller.sample_time or add [sensors]; kind {spec.kind!r} "
                         "runs continuously here")
    filters = [_filter_of(k, table) for k, table in enumerate(tables)]
    try:
        law = Filtered(law=built.controller, filters=filters)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"controller.filters: {exc}") from None
    names = ", ".join(type(f).__name__ for f in filters)
    return dataclasses.replace(built, controller=law,
                               info={**built.info, "structural_filters": names})


def _checked(built: BuiltController, plant: Model) -> BuiltController:
    """``built`` with its loop checked on the plant's linearisation (:mod:`.stability`): a
    warning when unstable or nearly so, and ``info["loop_stability"]``. Open-loop kinds have
    no loop to check."""
    try:
        check = check_loop(plant, built.controller)
    except InputTypeError:                  # an open-loop torque: nothing feeds back
        return built
    warn_if_unstable(check, stacklevel=None)
    return dataclasses.replace(built, info={**built.info, "loop_stability": check.as_dict()})


def _hardware(scene, plant: Model, spec: ControllerSpec, built) -> BuiltController:
    """``built`` as the scene's hardware runs it: its hub torque turned into the actuator's
    command, and, with ``[sensors]``, sampled behind a Kalman filter of the readings (on the
    plant augmented with the actuator); else sampled when ``sample_time`` is given."""
    controller = through_actuator(built.controller, plant)
    built = dataclasses.replace(built, controller=controller)
    if scene.sensors is None:
        return _sampled(spec, built)
    period = _loop_sample_time(scene, spec)
    process = {}
    if spec.kind == "lqg" or "process_torque" in spec.settings:
        process = {"process_noise": spec.get("process_torque")}
    # the filter is built here, once, on the plant the design was given (the nominal one):
    # flown on a dispersed plant it keeps the nominal model, as a flight computer does
    observed = _wrap(Observed, law=controller, sensors=scene.sensors, sample_time=period,
                     model=plant, **process)
    info = {**built.info, "sample_time": period, "estimator": "kalman (sensors)",
            "process_noise": observed.process_noise}
    if spec.kind == "lqg":
        info["design"] = (f"LQG: {info.get('design', 'LQR')}, on the discrete Kalman "
                          f"estimate of the sensors' readings (process torque "
                          f"{observed.process_noise:g} N m)")
    return dataclasses.replace(built, controller=observed, info=info)


def _design_model(scene, plant: Model) -> Model:
    """The model the controller is designed on: ``design_modes`` modes per appendage (one
    count for all, or ``{name: modes}``; each at most the plant's) of the scene's design
    variant, its input the hub torque (a DC motor's rotor inertia on the hub, as on the
    plant)."""
    asked = scene.model.design_modes
    names = plant.structure.names
    counts = dict(asked) if isinstance(asked, dict) else dict.fromkeys(names, asked)
    for name, n_plant in zip(names, plant.modes):
        key = f"model.design_modes{'.' + name if isinstance(asked, dict) else ''}"
        where = f"model.modes.{name}" if isinstance(scene.model.modes, dict) else (
            "model.modes" if not scene.model.auto else "model.modes (auto)")
        if counts[name] > n_plant:
            raise SceneError(f"{key} must be <= {where} = {n_plant} (the plant's modes"
                             f"{' of ' + name if name else ''}); got {counts[name]}")
        if scene.design_variant == "exact" and counts[name] > EXACT_MAX_MODES:
            raise SceneError(f"{key} must be at most {EXACT_MAX_MODES} for the exact "
                             f"design variant; got {counts[name]}")
    n_modes = counts if all(names) else counts[names[0]]
    return build_model(scene.design_system, n_modes=n_modes, variant=scene.design_variant)


def _slew_duration(maneuver: Slew, kind: str, design: Model):
    """The slew's duration, s: the manoeuvre's; for a free one, None for the kinds that find
    their own (``_OWN_DURATION_KINDS``), else the rigid minimum time at the torque bound."""
    duration = maneuver.duration
    if duration is None:
        if maneuver.torque_bound is None:
            raise SceneError("maneuver.torque_bound is required when maneuver.duration is "
                             "\"free\"")
        if kind not in _OWN_DURATION_KINDS:
            duration = minimum_slew_duration(maneuver.angle, design.rigid_inertia,
                                             maneuver.torque_bound)
    return duration


def _reference(spec: ControllerSpec, design: Model, angle, duration, bound) -> tuple:
    """``(profile, duration, info)``: the smooth reference slew of the ``reference`` setting,
    stretched to the shortest one the torque bound allows (``info`` says so)."""
    profile_shape = spec.get("reference")
    info = {}
    if bound is not None:
        # a smooth reference the actuator cannot follow only winds the loop up: stretch it
        # to the shortest one the torque bound allows (5 % margin for the feedback)
        feasible = 1.05 * _wrap(minimum_slew_duration, angle, design.rigid_inertia, bound,
                                shape=profile_shape)
        if feasible > duration:
            info["reference_duration"] = feasible
            info["note"] = (f"the {profile_shape} reference needs {feasible:.3g} s at "
                            f"{bound:g} N m; stretched from {duration:.3g} s")
            warn_user(f"controller: {info['note']}", DesignChangedWarning)
            duration = feasible
    profile = _wrap(SlewProfile, slew_angle=angle, duration=duration, shape=profile_shape)
    return profile, duration, info


def _loop_sample_time(scene, spec: ControllerSpec) -> float | None:
    """The sample time the loop will run at (s): the sensors', else the controller's, else
    :data:`DEFAULT_SENSOR_SAMPLE_TIME` with sensors; None for a continuous loop."""
    own = spec.get("sample_time") if "sample_time" in _kind_settings(spec) else None
    if scene.sensors is None:
        return own
    if own is not None and scene.sensors.sample_time is not None \
            and abs(own - scene.sensors.sample_time) > 1e-12 * own:
        raise SceneError(f"controller.sample_time {own:g} s and sensors.sample_time "
                         f"{scene.sensors.sample_time:g} s must agree: the controller runs "
                         "at the rate it reads the sensors; give one of them")
    return scene.sensors.sample_time or own or DEFAULT_SENSOR_SAMPLE_TIME


def _kind_settings(spec: ControllerSpec) -> set:
    """The names of the settings ``spec``'s kind takes."""
    return {item.name for item in CONTROLLER_KINDS[spec.kind].settings}


def _feedback(spec: ControllerSpec, design: Model, plant: Model, angle, duration,
              bound, kind: str, sample_time: float | None = None) -> BuiltController:
    """PD, LQR, LQG or scheduled LQR on the design model about the reference slew
    (``_reference``); ``kind`` the law designed."""
    profile, duration, info = _reference(spec, design, angle, duration, bound)
    actuator = getattr(plant, "actuator", None)
    info.update(_wrap(check_reference_fits, actuator, design.rigid_inertia, profile))
    common = {"reference": profile, "torque_limit": bound}
    if kind == "lqr" and actuator is not None and actuator.kind == "reaction_wheel":
        ctrl = _wrap(design_wheel_lqr, design, actuator, _lqr_weights(spec),
                     sample_time=sample_time, **common)
        info["design"] = "LQR on the structure augmented with the wheel's motor lag"
    elif kind == "pd":
        ctrl = _wrap(design_pd, design, spec.get("bandwidth"), spec.get("damping_ratio"),
                     feedforward=spec.get("feedforward"), **common)
    elif kind == "lqr":
        ctrl = _wrap(design_lqr, design, _lqr_weights(spec), spec.get("spin_rate"),
                     sample_time=sample_time, **common)
    elif kind == "lqg":
        # the loop is checked once, as it runs (_checked)
        ctrl = _wrap(design_lqg, design, _lqr_weights(spec), _noise(spec),
                     spec.get("spin_rate"), plant=plant, check_stability=False, **common)
        if actuator is not None and actuator.kind == "dc_motor":
            ctrl = dataclasses.replace(ctrl, motor=actuator)
    else:
        ctrl = _wrap(design_scheduled_lqr, design, _lqr_weights(spec),
                     list(spec.get("spin_rates")), **common)
    return BuiltController(ctrl, spec.kind, float(duration), design.n_modes, info)


def _open_loop(spec: ControllerSpec, design: Model, angle, duration,
               bound, actuator=None) -> BuiltController:
    """The rigid bang-bang torque (at the bound for a free duration), shaped at the first
    hub-free frequency for ``zv`` and ``zvd``, played open loop."""
    limits = {"torque_limit": bound} if duration is None else {"duration": duration}
    base = _wrap(bang_bang, design, angle, **limits)
    if bound is not None and duration is not None and base.peak_torque > bound:
        raise SceneError(f"maneuver.duration {duration:g} s is shorter than the rigid "
                         f"minimum time at torque_bound {bound:g} N m")
    end = base.duration
    info = _wrap(check_reference_fits, actuator, design.rigid_inertia, base)
    torque = base
    if spec.kind != "bang_bang":
        shaper = design_shaper(design, spec.kind)
        torque = shape(base, shaper)
        end += float(max(shaper.times))
    return BuiltController(OpenLoop(torque), spec.kind, float(end), design.n_modes, info)


def _optimal(spec: ControllerSpec, design: Model, angle, duration, bound,
             actuator=None) -> BuiltController:
    """The optimal slew played open loop (``trajopt``) or tracked with LQR feedback
    (``trajopt+lqr``)."""
    solution, info = _trajectory(spec, design, angle, duration, bound, actuator)
    if spec.kind == "trajopt":
        ctrl = OpenLoop(solution.torque_function())
    else:
        ctrl = _wrap(TrajectoryTracker, solution=solution, torque_limit=bound)
    return BuiltController(ctrl, spec.kind, float(solution.duration), design.n_modes, info)


def _trajectory(spec: ControllerSpec, design: Model, angle, duration, bound,
                actuator=None) -> tuple:
    """The optimal slew of the ``trajopt`` settings on the design model, and what its solve
    measured."""
    # objective None: SlewProblem takes "time" for a free duration, else "effort"
    problem = _wrap(SlewProblem, angle=angle, duration=duration, torque_bound=bound,
                    n_intervals=spec.get("n_intervals"), objective=spec.get("objective"),
                    torque_rate_bound=spec.get("torque_rate_bound"),
                    tip_bound=spec.get("tip_bound"), transcription=spec.get("transcription"),
                    effort_tolerance=spec.get("effort_tolerance"), actuator=actuator)
    start = time.perf_counter()
    try:
        solution = _wrap(solve_slew, design, problem)
    except RuntimeError as exc:
        raise SceneError(f"controller: trajectory optimisation failed: {exc}") from None
    info = {"solve_time_s": time.perf_counter() - start, "ipopt_status": solution.return_status,
            "iterations": solution.iterations, "cost": solution.cost,
            "duration": solution.duration}
    return solution, info


def _nmpc(spec: ControllerSpec, design: Model, angle, duration, bound, n_design,
          actuator=None, sensed: bool = False):
    """Nonlinear MPC tracking the optimal slew (``reference = "trajopt"``, default) or
    regulating to the target at rest (``reference = "none"``)."""
    info, solution = {}, None
    if spec.get("reference") == "trajopt":
        solution, info = _trajectory(spec, design, angle, duration, bound, actuator)
        end = float(solution.duration)
    else:
        end = float(duration if duration is not None
                    else minimum_slew_duration(angle, design.rigid_inertia, bound))
    settings = {key: spec.get(key) for key in ("horizon", "mode", "qp_solver", "terminal")}
    if spec.get("estimator") == "kalman" and not sensed:
        # with sensors the Kalman filter of their readings (_hardware) estimates the state
        settings["noise"] = _noise(spec)
    start = time.perf_counter()
    ctrl = _wrap(NMPC, model=design, target=angle, torque_limit=bound, reference=solution,
                 sample_time=spec.get("sample_time"),
                 torque_rate_limit=spec.get("torque_rate_bound"),
                 tip_limit=spec.get("tip_bound"), actuator=actuator, **settings)
    _wrap(ctrl.prepare)
    info["nmpc_build_time_s"] = time.perf_counter() - start
    info["substeps"] = ctrl.substeps
    return BuiltController(ctrl, "nmpc", end, n_design, info)


def _sampled(spec: ControllerSpec, built: BuiltController) -> BuiltController:
    """``built`` run at ``controller.sample_time`` with a zero-order hold, when given."""
    # nmpc samples itself; lqg takes no sample_time (its estimator is continuous)
    if built.kind in ("nmpc", "lqg") or spec.get("sample_time") is None:
        return built
    held = _wrap(ZeroOrderHold, built.controller, spec.get("sample_time"))
    return dataclasses.replace(built, controller=held,
                               info={**built.info, "sample_time": held.sample_time})
