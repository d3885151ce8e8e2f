"""A validated run request, and the integration plan drawn from it.

:func:`run_request` checks every argument of :func:`flexctl.simulate` and turns the inputs into
the forms the integrators take (samples into interpolants, Python functions traced into
CasADi where the run is compiled, a callable controller into a
:class:`~flexctl.sim.drives.StaticLaw`). :func:`plan_integration` then fixes what the
integration of a given drive needs: tolerances per state, the method the stiffness of the
model and the closed loop allow, the segments between the inputs' breakpoints.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from numbers import Real

import numpy as np

from .compiled import CHECK_FACTOR, is_symbolic
from .digital import is_sampled
from .embedded_rk import PAIR_OMEGA_H, choose_hold
from .fixed_step import RK4_OMEGA_H
from .drives import as_controller, bound_to_plant
from .inputs import (as_vector, check_method, check_rtol, check_time, jacobian_frequency,
                     output_grid, time_function)
from .progress import check_progress, progress_cuts
from .sensors import Sensors
from .tracing import torque_input
from ..model import Model, SingularMassMatrixError
from ..model.variant import check_reach
from ..model.checks import check_instance, check_real
from ..model.errors import InputTypeError, InputValueError

__all__ = ["RunRequest", "IntegrationPlan", "run_request", "plan_integration", "state_scale",
           "StiffnessWarning", "ManyModesWarning", "MANY_MODES", "METHODS", "SAMPLED_METHODS",
           "plan_sampled", "choose_continuous", "choose_multistep", "actuator_frequency",
           "ADAMS_DAMPING", "ADAMS_PHASE", "BDF_REPLACES", "PAIRS", "DOP853_RTOL",
           "ADAMS_TOLERANCE", "ATOL_LIMIT"]

#: Integration methods: "auto" (resolved by :func:`plan_integration` when every input has a
#: CasADi form, else DOP853), "cvodes" (compiled, :mod:`flexctl.sim.compiled`), "rk4"
#: (compiled fixed step, :mod:`flexctl.sim.fixed_step`), "dop853" (compiled Dormand-Prince
#: 8(5,3) steps, :mod:`flexctl.sim.embedded_rk`; SciPy's "DOP853" where an input has no
#: CasADi form) and the ``scipy.integrate.solve_ivp``
#: methods ("RK45" and "BDF" compiled where the inputs have a CasADi form:
#: :mod:`flexctl.sim.embedded_rk`, :mod:`flexctl.sim.compiled_bdf`), and "Adams" (the compiled
#: Adams-Moulton methods of :mod:`flexctl.sim.compiled_bdf`; CVODES's where it cannot be
#: compiled).
METHODS = ("auto", "cvodes", "rk4", "dop853", "Adams", "DOP853", "RK45", "RK23", "Radau", "BDF",
           "LSODA")
#: The methods of a sampled controller's loop: "auto" (resolved for each run by
#: :func:`flexctl.sim.embedded_rk.choose_hold`: the compiled Dormand-Prince pair, the scheme
#: of SciPy's "RK45", for a plant that is not stiff over a sample; CVODES otherwise),
#: "cvodes", "RK45" and "rk4", all compiled (:mod:`flexctl.sim.digital`).
SAMPLED_METHODS = ("auto", "cvodes", "RK45", "rk4")
#: Default tolerances: of the error-controlled methods, and of "rk4" (relative to the peak tip
#: deflection, for "fast, and 1 % is enough").
DEFAULT_RTOL = 1e-8
RK4_RTOL = 1e-2
#: Shortest run, s.
MIN_T_FINAL = 1e-9
#: Output samples over the run when no ``output_step`` is given.
DEFAULT_OUTPUT_POINTS = 2000

# ---- stiffness guard -------------------------------------------------------------------
#: Largest ``omega h`` at which each explicit method stays stable on an undamped mode of
#: frequency ``omega``: half the extent of its stability region along the imaginary axis
#: (where ``|R(iy)| <= 1 + 1e-3``: DOP853 5.96, RK45 1.34, RK23 1.73), the margin that error
#: control keeps in practice.
EXPLICIT_STABILITY_LIMITS = {"DOP853": 3.0, "dop853": 3.0, "RK45": 0.67, "RK23": 0.87}
#: An explicit method predicted to need more steps than this (about 5 s of DOP853 at ~40 us a
#: right-hand side) is not used when the compiled implicit path can take the run.
EXPLICIT_STEP_LIMIT = 10_000
#: Compiled instructions of a right-hand side (about a microsecond an evaluation) up to which
#: a continuous ``method="auto"`` run takes the compiled Dormand-Prince pair rather than
#: CVODES (:func:`choose_continuous`).
PAIR_INSTRUCTIONS = 5000
#: Most steps times instructions of a right-hand side for the pair (:func:`choose_continuous`):
#: about 0.17 s of its arithmetic (7 evaluations a step at some 0.4 ns an instruction).
PAIR_WORK = 6e7
#: The choices of :func:`choose_continuous` that a continuous ``method="auto"`` run replaces
#: by the compiled BDF (:mod:`flexctl.sim.compiled_bdf`) where it can have it, per variant:
#: the exact model's, whose right-hand side costs far more than the integrator's own work
#: (see :func:`choose_continuous` for the measurements).
BDF_REPLACES = {"exact": ("cvodes", "dop853")}
#: Loosest ``rtol`` at which a continuous ``method="auto"`` run takes the compiled 8(5,3)
#: pair (``"dop853"``, :func:`choose_continuous`): a looser one is tightened to it, and the
#: result's ``rtol`` and message say so. Looser, the pair's error on an input with a corner it
#: is not told of (``np.where(t <= 2, sin(pi t), 0)``, a sampled function's) stalls near the
#: tolerance while its steps stay long, and its accuracy check at 10 times the tolerance
#: falls short of it: on hub-beam-mass's 4 modes over 20 s, errors of 3.9e-5, 2.0e-5 and
#: 1.05e-5 of the peak at rtol 1e-3, 1e-4 and 1e-5 against estimates of 3.1e-5, 1.7e-5 and
#: 1.04e-5; at 3.2e-6 and tighter every estimate measured was 2 to 60 times the error
#: (8.3e-7 against 1.5e-5 at 3.2e-6, 2.4e-7 against 2.3e-6 at 1e-6). On these undamped
#: models its steps are mostly held by their bound, so the tighter tolerance costs little:
#: that run took 14.6 ms at 1e-6 against 13.1 ms at 1e-5 and the 5(4) pair's 32.7 at 1e-5.
DOP853_RTOL = 1e-6
#: The explicit pairs that run compiled (:class:`~flexctl.sim.embedded_rk.EmbeddedRun`) when
#: every input has a CasADi form and :func:`choose_continuous` does not take CVODES:
#: Dormand-Prince 5(4) (``"RK45"``, SciPy's name, whose ``solve_ivp`` scheme it is) and 8(5,3)
#: (``"dop853"``; ``"DOP853"`` is SciPy's ``solve_ivp`` of the same scheme, which calls the
#: inputs from Python at every stage).
PAIRS = ("RK45", "dop853")
#: Largest ``atol`` accepted, in multiples of each state's physical size (``state_scale``):
#: a tenth of the shortest beam's length for a coordinate, 0.1 rad for the hub angle.
ATOL_LIMIT = 100.0
#: Loosest tolerance at which a continuous ``method="auto"`` run takes the compiled
#: Adams-Moulton methods (:data:`BDF_REPLACES`), in the run and in its accuracy check at ten
#: times its tolerance: ``rtol`` and ``atol`` over each state's physical size.
#: Adams-Moulton's orders 3 and 4, and 7 and more, amplify an undamped oscillation a little
#: at every step (by 0.25 % at ``omega h = 0.5`` at order 3, by 59 % at
#: order 12), which only an error control that sees the oscillation holds back. On
#: hub-beam-mass's exact model under a 2 N m sine torque over 20 s at rtol 1e-6, with ``atol``
#: 1e-3 times the physical sizes, the compiled run's estimate bounded its error (7e-3 /
#: 2e-3, 5e-3 / 4e-4, 8e-3 / 6e-4 of the peak on 2, 4, 6 modes) and at 1e-2 times them
#: still did; at 0.1 times them it fell short (0.46 against 0.71 on 4 modes), at 1 it could
#: not run on 6 modes, and at 10 the run diverged on 4 and 6 modes, where the compiled BDF
#: stays bounded and says how far off it is. At rtol 1e-3 the run's estimates still bounded
#: its errors, but its check at 1e-2 was far off (2.1 times the peak against an error of
#: 6e-3 on 6 modes) and took longer than the run. Looser runs take the BDF.
ADAMS_TOLERANCE = 1e-3
#: The closed loop counts as made stiff by its controller when its fastest pole is this many
#: times the plant's fastest mode.
LOOP_FACTOR = 2.0
#: Highest beam damping ratio for which CVODES takes Adams-Moulton (:func:`choose_multistep`).
ADAMS_DAMPING = 0.2
#: Most radians the fastest mode may turn over a run for which CVODES takes Adams-Moulton.
ADAMS_PHASE = 2e4
#: An explicit method kept for Python inputs is refused past this many steps (some 15 minutes
#: of DOP853 at ~40 us a right-hand side).
EXPLICIT_REFUSE_LIMIT = 2e6
#: A run may span at most this many periods of the model's slowest mode: any integrator
#: takes several steps a period. hub-beam-mass on 4 modes took 19 s for 8.7e3 periods
#: (1e4 s, with its accuracy check), so the limit is some 4 minutes there, growing linearly;
#: inside one CVODES call no interrupt reaches the run.
MAX_PERIODS = 1e5
#: A controller whose gains put the fastest closed-loop pole beyond this many times the
#: plant's fastest mode is refused: nothing the model describes is that fast, and the run
#: would crawl (a PD loop of bandwidth 1e6 rad/s on slew-90 took some 25 minutes).
LOOP_LIMIT = 1e4
#: CVODES may take at least this many steps between two output times, and
#: CVODES_STEPS_PER_RADIAN per radian of the fastest mode over the interval; a run that needs
#: more has blown up (a diverging beam stiffens without bound), and failing fast hands the
#: interval to the SciPy path, which locates the stop.
CVODES_MIN_STEPS = 5_000
CVODES_STEPS_PER_RADIAN = 10.0


class StiffnessWarning(RuntimeWarning):
    """An explicit method was asked for on a model whose fastest mode makes it crawl."""


class ManyModesWarning(RuntimeWarning):
    """A run of more modes than a manoeuvre usually excites, said before it starts."""


#: Modes per appendage above which a run says up front what its fastest mode costs: a
#: torque of a few seconds excites a handful (``modes = "auto"`` picked 3 to 6 on the
#: built-in scenes at 1 %), and every mode more is integrated to the run's tolerance.
MANY_MODES = 24


def _warn_many_modes(model) -> None:
    """Warn (:class:`ManyModesWarning`) for more than :data:`MANY_MODES` modes on an
    appendage, naming the fastest mode and the mode choice that fits a manoeuvre."""
    most = int(np.max(np.atleast_1d(getattr(model, "modes", model.n_modes))))
    if most <= MANY_MODES:
        return
    fastest = float(model.natural_frequencies(0.0, hub="free")[-1])
    warnings.warn(
        f"{most} modes on an appendage: the fastest at {fastest:.4g} rad/s (a period of "
        f"{2.0 * np.pi / fastest:.3g} s) is integrated to the run's tolerance, far above what "
        "a smooth torque excites, and the run's cost grows with it; "
        "flexctl.sim.fidelity.choose_modes (a scene's [model] modes = \"auto\") gives the "
        "modes a manoeuvre needs", ManyModesWarning, stacklevel=4)


@dataclass(frozen=True, eq=False)
class RunRequest:
    """The checked arguments of one :func:`flexctl.simulate` call.

    Attributes
    ----------
    model : Model
        The model simulated.
    t_final : float
        End time, s.
    method : str
        The method asked for, ``"auto"`` resolved (the stiffness guard may still change it);
        a sampled controller's ``"auto"`` is resolved by its run
        (:func:`~flexctl.sim.embedded_rk.choose_hold`), which knows the plant's fastest pole.
    rtol : float
        Relative tolerance.
    atol : object
        As given (``None``: each state's physical scale times ``rtol``).
    grid : ndarray, shape (P,)
        Output times, s.
    step : float
        Spacing of the output times, s.
    max_step : float
        Largest step, s (``inf``: none), the inputs' own bounds included.
    check_accuracy : bool
        Estimate the integration error.
    torque, hub_motion, controller : object
        The inputs in the form the integrators take (``controller`` a
        :class:`~flexctl.sim.drives.Controller` or a sampled controller).
    torque_fn : callable or None
        ``torque`` as a checked ``g(t, x)``.
    x_init : ndarray, shape (n,)
        Initial plant state.
    symbolic : bool
        Every input has a CasADi form.
    spin_frequency : float
        Fastest beam frequency at the initial hub rate, rad/s (0 at rest).
    report : callable or None
        Progress reporter.
    sensors : Sensors or None
        What a sampled controller measures, checked against it. Default None.
    input_note : str
        What the run says about a torque function: sampled, or called at every step and why
        (:func:`~flexctl.sim.tracing.torque_input`). Default "".
    """

    model: Model
    t_final: float
    method: str
    rtol: float
    atol: object
    grid: np.ndarray
    step: float
    max_step: float
    check_accuracy: bool
    torque: object
    hub_motion: object
    controller: object
    torque_fn: object
    x_init: np.ndarray
    symbolic: bool
    spin_frequency: float
    report: object
    sensors: object = None
    input_note: str = ""

    @property
    def prescribed(self) -> bool:
        """The hub follows a prescribed motion."""
        return self.hub_motion is not None

    @property
    def sampled(self) -> bool:
        """The controller runs sampled (:mod:`flexctl.sim.digital`)."""
        return is_sampled(self.controller)


def state_scale(model: Model, layout) -> np.ndarray:
    """Each state's physical size in ``layout`` (the model's, with a controller block, or
    without the hub rotation): 1e-3 rad, 1e-3 of the length, rates at the first clamped
    frequency, 1e-3 for a controller's state. Times ``rtol``, the default ``atol``.

    Parameters
    ----------
    model : Model
        The model whose states are scaled: its beam lengths and first clamped
        frequency set the sizes.
    layout : StateLayout
        The integrated states' layout: ``model.layout``, with a ``"controller"`` block, or
        without the hub rotation (a prescribed hub motion).

    Returns
    -------
    ndarray, shape (layout.n_states,)
        In each state's unit (m, rad, m/s, rad/s; the actuator's own sizes).
    """
    rate = max(model.first_clamped_frequency, 1.0)
    length = 1e-3 * float(np.min(model.lengths))
    scale = np.full(layout.n_states, 1e-3)
    scale[layout.coordinates] = length
    scale[layout.velocities] = length * rate
    if layout.rotation:
        scale[layout.theta], scale[layout.theta_dot] = 1e-3, 1e-3 * rate
    actuator = getattr(model, "actuator", None)
    if actuator is not None and actuator.state_names:
        scale[layout.block("actuator")] = actuator.state_scale()
    return scale


def _check_arguments(model, t_final, hub_motion, torque, controller, method, rtol,
                     output_step, max_step, progress):
    """The plain arguments, checked: ``(t_final, method, rtol, output_step, max_step,
    report)``."""
    if not isinstance(model, Model):
        raise InputTypeError(f"model must be a flexctl Model; got {type(model).__name__}")
    t_final = check_time("t_final", t_final)
    if t_final < MIN_T_FINAL:
        # no integrator can step where t + h rounds to t, and nothing in these models moves
        # on such a scale: a subnormal t_final divided by zero, 1e-300 s hung LSODA
        raise InputValueError(f"t_final must be at least {MIN_T_FINAL:g} s; got {t_final!r}")
    method = check_method(method, METHODS)
    report = check_progress(progress)
    rtol = check_rtol((RK4_RTOL if method == "rk4" else DEFAULT_RTOL) if rtol is None else rtol)
    if hub_motion is not None and (torque is not None or controller is not None):
        raise InputValueError("hub_motion prescribes the hub: it cannot be combined with "
                              "torque or controller")
    if hub_motion is not None and getattr(model, "actuator", None) is not None:
        raise InputValueError("hub_motion prescribes the hub, which then needs no actuator: "
                              "simulate the structure's own model (model.mechanical)")
    if hub_motion is not None:
        for attr in ("angle", "rate", "acceleration"):
            if not callable(getattr(hub_motion, attr, None)):
                raise InputTypeError(f"hub_motion must have a callable {attr}(t); got "
                                     f"{type(hub_motion).__name__}")
    if output_step is not None:
        output_step = check_time("output_step", output_step)
    max_step = check_time("max_step", max_step, allow_inf=True)
    return t_final, method, rtol, output_step, max_step, report


def _step_bound(max_step: float, *sources) -> float:
    """The shortest of ``max_step`` and the positive ``max_step`` the inputs declare, s."""
    bounds = [getattr(src, "max_step", None) for src in sources]
    return min([max_step] + [float(b) for b in bounds
                             if isinstance(b, Real) and not isinstance(b, bool) and b > 0])


def _resolve_method(method, symbolic, controller, untraced) -> str:
    """The method the inputs allow: ``"auto"`` resolved, a compiled one refused for Python
    inputs."""
    if is_sampled(controller) and method not in SAMPLED_METHODS:
        raise InputValueError(f"method {method!r}: a sampled controller (sample_time "
                              f"{controller.sample_time!r} s) runs on the compiled path; use "
                              "method 'auto', 'cvodes', 'RK45' or 'rk4'")
    if method in ("cvodes", "rk4", "Adams", "dop853") and not symbolic:
        raise InputValueError(f"method {method!r} needs inputs with a CasADi form (the built-in "
                              "manoeuvres, torque samples, controllers with casadi_torque); "
                              "got a Python callable"
                              + (f" (the torque function could not be traced: {untraced})"
                                 if untraced else ""))
    if method == "auto" and not is_sampled(controller) and not symbolic:
        return "DOP853"
    # a continuous "auto" run with CasADi inputs is resolved by its plan (choose_continuous)
    return method


def _check_duration(model, t_final, prescribed):
    """Refuse a run of more than :data:`MAX_PERIODS` periods of the slowest mode."""
    hub = "clamped" if prescribed else "free"
    omega_slow = float(model.natural_frequencies(0.0, hub=hub)[0])
    periods = t_final * omega_slow / (2.0 * np.pi)
    if periods > MAX_PERIODS:
        raise InputValueError(
            f"t_final {t_final:g} s spans {periods:.3g} periods of the slowest mode "
            f"({omega_slow:.4g} rad/s), more than the limit {MAX_PERIODS:g} (each takes an "
            "integrator several steps); shorten t_final")


def _initial_state(model, x0) -> np.ndarray:
    """``x0`` checked (default rest), shape (n,)."""
    nx, names = model.n_states, ", ".join(model.state_names)
    x_init = (model.layout.zeros() if x0 is None else
              as_vector("x0", x0, f"{nx} numbers (states {names})").reshape(-1))
    if x_init.shape != (nx,) or not np.all(np.isfinite(x_init)):
        raise InputValueError(f"x0 must be {nx} finite numbers (states {names}); got {x0!r}")
    return x_init


def _spin_frequency(model, x_init, x0, t_final, prescribed) -> float:
    """Fastest beam frequency at the initial hub rate, rad/s; a rate that would take an
    explicit method beyond :data:`EXPLICIT_REFUSE_LIMIT` steps is refused."""
    spin0 = 0.0 if prescribed else float(model.layout.hub_rate(x_init))
    if not spin0:
        return 0.0
    # a stop on the way must be located by an explicit method, which resolves the fastest
    # frequency the spin gives the beam
    try:
        with np.errstate(all="ignore"):
            w_spin = float(np.max(np.abs(model.natural_frequencies(spin0, hub="clamped"))))
    except (OverflowError, np.linalg.LinAlgError, ValueError):  # spin0 ** 2 overflowed
        w_spin = np.inf
    if not w_spin * t_final / 3.0 <= EXPLICIT_REFUSE_LIMIT:
        raise InputValueError(
            f"x0: the hub rate {spin0:g} rad/s gives the beam frequencies up to "
            f"{w_spin:.3g} rad/s, some {w_spin * t_final / 3.0:.3g} steps over t_final "
            f"{t_final:g} s, beyond the {EXPLICIT_REFUSE_LIMIT:.3g} a run may take; got "
            f"x0 = {x0!r}")
    return w_spin




def _check_sensors(sensors, controller, t_final: float):
    """Sensors are read by a sampled controller that takes readings, and only by one, and
    give it readings within the run: a delay and a reading interval shorter than ``t_final``
    (s)."""
    reads = bool(getattr(controller, "measures", False))
    if sensors is None:
        if reads:
            raise InputValueError("the controller reads sensors (it measures): pass "
                                  "sensors=flexctl.sim.sensors.Sensors(...)")
        return None
    if not isinstance(sensors, Sensors):
        raise InputTypeError("sensors must be a flexctl.sim.sensors.Sensors; got "
                             f"{type(sensors).__name__}")
    if not is_sampled(controller) or not reads:
        raise InputValueError(
            "sensors are read by a sampled controller that takes readings (e.g. "
            "controllers.Observed, which estimates the state from them); the controller given "
            f"({type(controller).__name__}) reads the plant's exact state")
    if sensors.sample_time is not None and not np.isclose(sensors.sample_time,
                                                          controller.sample_time, rtol=1e-9):
        raise InputValueError(f"sensors.sample_time {sensors.sample_time:g} s must be the "
                              f"controller's sample_time {controller.sample_time:g} s (the "
                              "controller reads them at its own samples)")
    if sensors.delay >= t_final:
        raise InputValueError(f"sensors.delay {sensors.delay:g} s must be shorter than the run "
                              f"(t_final = {t_final:g} s): no reading of the moving plant would "
                              "reach the controller")
    interval = sensors.interval(controller.sample_time)
    if interval >= t_final:
        raise InputValueError(f"the sensors' sample time {interval:g} s must be shorter than the "
                              f"run (t_final = {t_final:g} s): the controller would read them "
                              "once, at the start, and never see the plant move")
    return sensors


def run_request(model, t_final, torque=None, hub_motion=None, controller=None, x0=None, *,
                rtol=None, atol=None, method="auto", output_step=None, max_step=np.inf,
                check_accuracy=True, progress=None, sensors=None) -> RunRequest:
    """Check the arguments of :func:`flexctl.simulate` (the same signature) and give the run
    they ask for.

    Each argument is described in full by :func:`flexctl.simulate`.

    Parameters
    ----------
    model : Model
        The model to simulate.
    t_final : float
        End time, s (at least :data:`MIN_T_FINAL`).
    torque : callable, (times, values) or SampledTorque, optional
        Hub torque, N m; traced into CasADi where the run is compiled.
    hub_motion : object, optional
        Prescribed hub motion (``angle``, ``rate``, ``acceleration``: rad, rad/s, rad/s^2).
    controller : callable, Controller or SampledController, optional
        Feedback; a callable ``(t, x)`` becomes a :class:`~flexctl.sim.drives.StaticLaw`.
    x0 : array_like, shape (n,), optional
        Initial plant state; default rest at zero.
    rtol : float, optional
        Relative tolerance; default :data:`DEFAULT_RTOL` (``RK4_RTOL`` for ``"rk4"``).
    atol : float or array_like, optional
        Absolute tolerance, one or one per state; kept as given (checked by the plan).
    method : str, optional
        One of :data:`METHODS`. Default ``"auto"``.
    output_step : float, optional
        Spacing of the output times, s. Default ``t_final / DEFAULT_OUTPUT_POINTS``.
    max_step : float, optional
        Largest step, s. Default ``inf``.
    check_accuracy : bool, optional
        Estimate the integration error. Default True.
    progress : bool or callable, optional
        Progress reports (:func:`~flexctl.sim.progress.check_progress`). Default none.
    sensors : Sensors, optional
        Read by a sampled controller that measures.
    """
    t_final, method, rtol, output_step, max_step, report = _check_arguments(
        model, t_final, hub_motion, torque, controller, method, rtol, output_step, max_step,
        progress)
    # samples become an interpolant; a Python function is traced into CasADi when the rest
    # of the run is compiled (flexctl.sim.tracing)
    compiled_feedback = (controller is None or is_sampled(controller)
                         or is_symbolic(controller=controller))
    torque, untraced, input_note = torque_input(
        torque, t_final=t_final, n_states=model.n_states,
        trace=(method in ("auto", "cvodes", "rk4", "Adams", "dop853") and hub_motion is None
               and compiled_feedback),
        state_scale=state_scale(model, model.layout), rtol=rtol)
    max_step = _step_bound(max_step, torque)
    symbolic = is_symbolic(torque, hub_motion, None if is_sampled(controller) else controller)
    method = _resolve_method(method, symbolic, controller, untraced)
    step = output_step if output_step is not None else t_final / DEFAULT_OUTPUT_POINTS
    grid = output_grid(t_final, step)
    _check_duration(model, t_final, hub_motion is not None)
    x_init = _initial_state(model, x0)
    w_spin = _spin_frequency(model, x_init, x0, t_final, hub_motion is not None)
    torque_fn = time_function(torque, "torque") if torque is not None else None
    if not is_sampled(controller):
        controller = bound_to_plant(as_controller(controller, x_init), model)
    check_reach(model, x_init)
    sensors = _check_sensors(sensors, controller, t_final)
    _warn_many_modes(model)
    return RunRequest(model=model, t_final=float(t_final), method=method, rtol=float(rtol),
                      atol=atol, grid=grid, step=float(step), max_step=max_step,
                      check_accuracy=bool(check_accuracy), torque=torque,
                      hub_motion=hub_motion, controller=controller, torque_fn=torque_fn,
                      x_init=x_init, symbolic=symbolic, spin_frequency=w_spin, report=report,
                      sensors=sensors, input_note=input_note)


def check_atol(atol, scale: np.ndarray, names=None) -> np.ndarray:
    """A user's ``atol``: one positive finite number or one per state, as shape (n,).

    An ``atol`` above :data:`ATOL_LIMIT` times a state's size is refused: the error control
    would accept errors as large as the motion itself, and a run and its accuracy check can
    then agree on a wrong answer (the exact 4-mode model at ``atol=1e3`` ended "ok", estimated
    at 1e-14, 0.29 m from the true tip deflection).

    Parameters
    ----------
    atol : float or array_like
        The user's absolute tolerance, in each state's unit.
    scale : ndarray, shape (n,)
        Each integrated state's physical size (:func:`state_scale`).
    names : sequence of str, optional
        The states' names, for an error. Default ``"state <k>"``.
    """
    scale = np.asarray(scale, dtype=float)
    size = scale.size
    atol_vec = as_vector("atol", atol, "a positive number or one per state")
    try:
        atol_vec = np.broadcast_to(atol_vec, (size,)).astype(float)
    except ValueError:
        raise InputValueError(f"atol must be one number or {size}; got shape "
                              f"{atol_vec.shape}") from None
    if not np.all(np.isfinite(atol_vec)) or np.any(atol_vec <= 0):
        raise InputValueError(f"atol must be positive and finite; got {atol!r}"[:300])
    blind = np.flatnonzero(atol_vec > ATOL_LIMIT * scale)
    if blind.size:
        i = int(blind[0])
        name = names[i] if names is not None else f"state {i}"
        raise InputValueError(
            f"atol for {name} is {atol_vec[i]:g}, more than {ATOL_LIMIT:g} times that state's "
            f"physical size ({scale[i]:g}: 1e-3 rad, 1e-3 of the shortest beam's length, rates "
            f"at the first clamped frequency): the error control would not see the motion. "
            f"Give at most {ATOL_LIMIT * scale[i]:g} there, or leave atol None")
    return atol_vec


@dataclass(frozen=True, eq=False)
class IntegrationPlan:
    """How a drive is integrated: the method, tolerances per state and the segments.

    Attributes
    ----------
    method : str
        The method used (after the stiffness guard); ``fallback`` the SciPy method that
        locates a stop.
    atol : ndarray
        Absolute tolerance per integrated state; ``scale = atol / rtol``.
    rtol : float
        Relative tolerance.
    cuts : list of float
        Segment boundaries (the inputs' breakpoints), s.
    drive_cuts : list of float
        The boundaries the segment loop steps through, s: ``cuts``, and more where progress
        is reported.
    omega_plant, loop_frequency : float
        Fastest mode of the plant at rest and fastest pole of the closed loop, rad/s.
    actuator_frequency : float
        Fastest pole of the plant behind its actuator, linearised at rest (a wheel's torque
        lag, its friction knee, a motor's back-EMF damping), rad/s; 0 without an actuator.
    cvodes_steps : int
        CVODES's step budget between two output times.
    cvodes_step : float or None
        CVODES's largest step, s.
    cvodes_multistep : {"bdf", "adams"}
        CVODES's multistep family (:func:`choose_multistep`).
    stiffness_note : str
        What the stiffness guard did, or how the method met a fast actuator ("" when
        nothing).
    compiled : bool
        ``method="BDF"`` or ``"Adams"`` runs compiled (:mod:`flexctl.sim.compiled_bdf`), not
        SciPy's BDF; the plan is made without compiling, and where the library cannot be
        built when the run starts the run takes ``uncompiled`` instead.
    uncompiled : str
        The method without the compiled integrator (the plan's own choice without it).
    """

    method: str
    atol: np.ndarray
    rtol: float
    cuts: list
    drive_cuts: list
    omega_plant: float
    loop_frequency: float
    cvodes_steps: int
    cvodes_step: float | None
    stiffness_note: str
    cvodes_multistep: str = "bdf"
    compiled: bool = False
    uncompiled: str = "cvodes"
    actuator_frequency: float = 0.0

    @property
    def fastest_pole(self) -> float:
        """The fastest pole the run meets at its start but a spin's, rad/s: the plant's
        fastest mode, the closed loop's and the actuator's fastest poles."""
        return max(self.omega_plant, self.loop_frequency, self.actuator_frequency)

    def without_compiled(self) -> "IntegrationPlan":
        """The plan with :attr:`uncompiled` in place of a compiled method that cannot be built
        (CVODES keeps the multistep family chosen), its note saying so."""
        said = (f"the compiled {self.method} could not be built (compiling off, no C "
                f"compiler, or a drive too large to compile): {self.uncompiled} took the run")
        note = f"{self.stiffness_note}; {said}" if self.stiffness_note else said
        return replace(self, method=self.uncompiled, compiled=False, stiffness_note=note)

    @property
    def fallback(self) -> str:
        """The SciPy method that locates a stop: DOP853 behind CVODES, the compiled
        fixed-step RK4, the compiled 8(5,3) pair and the compiled multistep methods, else the
        method."""
        return "DOP853" if self.method in ("cvodes", "Adams", "rk4", "dop853") or (
            self.method == "BDF" and self.compiled) else self.method

    @property
    def scale(self) -> np.ndarray:
        """Each integrated state's physical size, ``atol / rtol``."""
        return self.atol / self.rtol


def _loop_frequency(request, drive, scale, omega_plant) -> float:
    """Fastest pole of the closed loop at the start, rad/s (0 without a controller); gains
    beyond :data:`LOOP_LIMIT` times the plant's fastest pole (``omega_plant``, rad/s: its
    fastest mode or its actuator's fastest pole) are refused."""
    if request.controller is None:
        return 0.0
    try:
        frequency = jacobian_frequency(drive.rhs, 0.0, drive.y_init, scale)
    except SingularMassMatrixError:     # reported as such by the run itself
        return 0.0
    if frequency > LOOP_LIMIT * omega_plant:
        raise InputValueError(
            f"controller gains put the fastest closed-loop pole at {frequency:.4g} rad/s, "
            f"more than {LOOP_LIMIT:g} times the fastest pole of the "
            f"{request.model.n_modes}-mode plant ({omega_plant:.4g} rad/s): the model "
            "describes nothing that fast and the run would crawl; lower the gains (e.g. the "
            "bandwidth)")
    return frequency


def actuator_frequency(model: Model) -> float:
    """Fastest pole of ``model``'s plant behind its actuator, linearised at rest, rad/s: the
    largest ``|eigenvalue|`` of its ``A`` (a wheel's torque lag ``1/tau``, its friction knee,
    a motor's back-EMF damping, and the structure's modes); 0 without an actuator, ``inf``
    where the linearisation is not finite.

    Parameters
    ----------
    model : Model
        The model of the run.
    """
    check_instance("actuator_frequency", "model", model, Model, "flexctl Model")
    if getattr(model, "actuator", None) is None:
        return 0.0
    a = np.asarray(model.linear_matrices(0.0)[0], dtype=float)
    if not np.all(np.isfinite(a)):
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(a)))) if a.size else 0.0


def _actuator_note(method: str, actuator: float, omega_plant: float) -> str:
    """What a run says when its actuator is fast against the structure (more than
    :data:`LOOP_FACTOR` times its fastest mode): the ratio and the method taken."""
    if not actuator > LOOP_FACTOR * omega_plant:
        return ""
    ratio = actuator / omega_plant if omega_plant > 0.0 else math.inf
    implicit = method in ("cvodes", "BDF", "LSODA", "Radau")
    return (f"the actuator's fastest pole, {actuator:.4g} 1/s, is {ratio:.3g} times the "
            f"structure's fastest mode ({omega_plant:.4g} rad/s): "
            + (f"{method} steps over it implicitly" if implicit else
               f"{method} is explicit and resolves it"))


def stiffness_guard(model: Model, t_final: float, method: str, symbolic: bool,
                    prescribed: bool, loop_frequency: float = 0.0,
                    actuator_frequency: float = 0.0):
    """``(method to use, reason)``: reason is empty when ``method`` is kept silently.

    The step of an explicit method on an undamped mode ``omega`` is bounded by
    ``limit / omega`` whatever the tolerance, so a run needs at least
    ``omega_max t_final / limit`` steps, ``omega_max`` the highest natural frequency (hub held
    for a prescribed motion, free otherwise). Past :data:`EXPLICIT_STEP_LIMIT` the run moves to
    CVODES (BDF, compiled) when the inputs have a CasADi form. Python inputs keep the explicit
    method with a warning: on these undamped models the fast modes are excited and must be
    resolved by any method, and LSODA measured 1.8 to 2.9 times slower than DOP853 (Kane,
    spacecraft and hub-beam-mass scenes, 12 and 16 modes, rtol 1e-5 and 1e-8, with and
    without beam damping).

    A controller's gains can make the fastest pole of the closed loop (``loop_frequency``) far
    faster than any mode of the plant, and so can an actuator (a wheel's torque lag,
    ``actuator_frequency``). When they do, the fast poles are damped ones that an implicit
    method steps over, so a run with Python inputs moves to LSODA (implicit BDF where the
    problem is stiff) rather than crawl for minutes.

    Parameters
    ----------
    model : Model
        The model of the run; its highest natural frequency bounds an explicit
        method's step.
    t_final : float
        End time, s.
    method : str
        The method asked for.
    symbolic : bool
        Every input has a CasADi form (the run can move to CVODES).
    prescribed : bool
        The hub follows a prescribed motion (the fastest mode is the clamped beam's).
    loop_frequency : float, optional
        Fastest pole of the closed loop at the start, rad/s (:func:`jacobian_frequency`).
        Default 0 (no controller).
    actuator_frequency : float, optional
        Fastest pole of the plant behind its actuator, rad/s (:func:`actuator_frequency`).
        Default 0 (no actuator).

    Raises
    ------
    InputValueError
        If Python inputs would keep an explicit method beyond :data:`EXPLICIT_REFUSE_LIMIT`
        steps.
    """
    limit = EXPLICIT_STABILITY_LIMITS.get(method)
    if limit is None:
        return method, ""
    omega_plant = float(model.natural_frequencies(
        0.0, hub="clamped" if prescribed else "free")[-1])
    omega_max = max(omega_plant, float(loop_frequency), float(actuator_frequency))
    steps = omega_max * float(t_final) / limit
    if steps <= EXPLICIT_STEP_LIMIT:
        return method, ""
    by_controller = omega_max > LOOP_FACTOR * omega_plant
    by_actuator = by_controller and float(actuator_frequency) >= float(loop_frequency)
    source = (f"the actuator's fastest pole ({omega_max:.4g} 1/s; the structure's fastest mode "
              f"is {omega_plant:.4g} rad/s)" if by_actuator else
              f"the fastest pole of the closed loop ({omega_max:.4g} rad/s, set by the "
              f"controller's gains; the plant's fastest mode is {omega_plant:.4g} rad/s)"
              if by_controller else
              f"the fastest mode of this {model.n_modes}-mode model ({omega_max:.4g} rad/s, hub "
              f"{'held' if prescribed else 'free'})")
    reason = (f"stiffness: {method} is explicit and {source} bounds its step to about "
              f"{limit:g}/{omega_max:.4g} s, some {steps:.3g} steps over {float(t_final):g} s "
              f"(more than {EXPLICIT_STEP_LIMIT})")
    if symbolic:
        return "cvodes", reason + "; switched to cvodes (implicit BDF, compiled)"
    if by_controller:
        return "LSODA", reason + "; switched to LSODA (implicit BDF where the problem is stiff)"
    if steps > EXPLICIT_REFUSE_LIMIT:
        raise InputValueError(f"t_final {float(t_final):g} s: {reason}, beyond the "
                              f"{EXPLICIT_REFUSE_LIMIT:.3g} steps a run may take; shorten "
                              "t_final, use fewer modes or give the inputs a CasADi form")
    return method, (reason + f"; kept {method} because the inputs have no CasADi form (give "
                    "them one, e.g. the built-in manoeuvres, to run on cvodes)")


def choose_multistep(model: Model, omega_plant: float, loop_frequency: float = 0.0,
                     t_final: float = 0.0) -> str:
    """CVODES's multistep family for a run: ``"adams"`` where every fast pole is a lightly
    damped oscillation, else ``"bdf"``.

    On these models the fast poles are the beam modes, undamped or lightly damped, and they
    must be resolved by any method. BDF's orders 3 to 5 amplify such oscillations at long
    steps, so CVODES holds them to short, low-order steps (and the accuracy check sometimes
    redoes a run with BDF2), while Adams-Moulton follows them at high order. At rtol 1e-6 with
    the accuracy check, BDF / Adams in ms, and their largest tip errors against a run at 1e-11
    relative to the peak (``benchmarks/bench_multistep.py``): slew-90 under a saturated PD,
    exact, 4 modes 32.5 / 24.5 (3.5e-6 / 1.4e-6) and 6 modes 76.0 / 50.8 (2.5e-6 / 2.3e-6);
    hub-beam-mass's sine torque on 30 first_order modes over 2 s 630 / 48 (3e-7 / 6.1e-6);
    spacecraft-torque, 6 modes, 330 / 253 (7e-4 / 5.1e-5); the Kane spin-up, 4 modes,
    first_order 25.9 / 17.9 (3.1e-6 / 5.5e-7) and exact 63.2 / 47.3 (3.1e-6 / 4.5e-7). On 12
    modes over 20 s, which the phase bound below keeps on BDF, Adams took 231 ms against 346
    but its error was 1.7e-5 against 1.7e-7.

    BDF stays where a pole decays fast, which Adams-Moulton would follow with steps as short
    as its time constant: a beam damping ratio above :data:`ADAMS_DAMPING` (the highest
    modes' poles then near the real axis), hub friction faster than the plant's fastest
    mode, or a controller whose gains set the loop's fastest pole beyond
    :data:`LOOP_FACTOR` times it. BDF stays too where the fastest mode turns more than
    :data:`ADAMS_PHASE` radians over the run (``t_final``, s): such modes lie far above
    anything the inputs excite, and BDF steps over them where Adams would resolve each
    period (a beam a million times stiffer, 4 modes over 4 s, deflects quasi-statically
    under BDF and carries tolerance-sized vibration under Adams). A plant behind an actuator
    keeps BDF too: a wheel's torque lag, a motor's back-EMF damping and a smoothed friction
    knee are fast decays of their own.

    Parameters
    ----------
    model : Model
        The model of the run: its beam damping and hub friction.
    omega_plant : float
        Fastest mode of the plant at rest, rad/s (>= 0; ``inf`` allowed).
    loop_frequency : float, optional
        Fastest pole of the closed loop, rad/s (>= 0). Default 0.
    t_final : float, optional
        Length of the run, s (>= 0). Default 0.
    """
    check_instance("choose_multistep", "model", model, Model, "flexctl Model")
    # a rate of inf (a model beyond floating point) is allowed: it goes to BDF
    omega_plant = check_real("choose_multistep", "omega_plant", omega_plant, minimum=0.0,
                             infinite=True)
    loop_frequency = check_real("choose_multistep", "loop_frequency", loop_frequency,
                                minimum=0.0, infinite=True)
    t_final = check_real("choose_multistep", "t_final", t_final, minimum=0.0)
    if getattr(model, "actuator", None) is not None:
        return "bdf"
    zeta = max(a.beam.damping_ratio for a in model.structure.appendages)
    friction = model.structure.hub.friction / max(float(model.rigid_inertia), 1e-300)
    oscillatory = (zeta <= ADAMS_DAMPING and friction <= omega_plant
                   and loop_frequency <= LOOP_FACTOR * omega_plant
                   and math.isfinite(omega_plant) and omega_plant * t_final <= ADAMS_PHASE)
    return "adams" if oscillatory else "bdf"


def choose_continuous(model: Model, t_final: float, omega_max: float) -> str:
    """The method of a continuous ``method="auto"`` run whose inputs have a CasADi form:
    ``"dop853"`` (compiled Dormand-Prince 8(5,3) steps,
    :class:`~flexctl.sim.embedded_rk.EmbeddedRun`; at an ``rtol`` no looser than
    :data:`DOP853_RTOL`) or ``"cvodes"``.

    The rule was measured on Dormand-Prince 5(4) (``"RK45"``, the pair of the table below).
    On these undamped models the pair's steps are held to ``omega_max h`` of about 0.5 on the
    fastest pole ``omega_max`` (rad/s), by its error control and by its bound
    (:data:`~flexctl.sim.embedded_rk.PAIR_OMEGA_H`), so a run takes some
    ``omega_max t_final / 0.5`` steps of 7 evaluations, where CVODES takes about half as many
    steps of one or two evaluations each but spends some 3 us of its own on each. The pair is
    cheaper while an evaluation of the right-hand side costs about a microsecond or less
    (:data:`PAIR_INSTRUCTIONS` compiled instructions) and its steps times those instructions
    stay within :data:`PAIR_WORK`: past that, CVODES at a loose tolerance steps over fast
    modes that the inputs leave alone. Measured at rtol 1e-4, 1e-6 and 1e-8 (ms, without the
    accuracy check; the pair's steps times instructions last):

    =======================================  ===========  ===========  =======
    run                                      CVODES       the pair     work
    =======================================  ===========  ===========  =======
    slew-90 PD, first_order, 6 modes, 6 s    -/25/-       -/8.6/-      1.0e6
    slew-90 PD, exact, 2 modes, 6 s          -/9.2/-      -/8.3/-      1.3e6
    hub-beam-mass, 6 modes, 20 s             52/51/67     25/25/25     3.4e6
    spacecraft-torque, 6 modes, 20 s         121/300/653  42/72/158    7.6e6
    hub-beam-mass, 12 modes, 20 s            318/309/303  158/154/158  5.0e7
    hub-beam-mass, 20 modes, 2 s             88/-/160     110/-/109    3.7e7
    hub-beam-mass, 30 modes, 2 s             251/-/730    453/-/461    1.8e8
    =======================================  ===========  ===========  =======

    The exact model on 4 and 6 modes (10 018 and 19 482 instructions) took 44 and 142 ms on
    the pair against CVODES's 31 and 74 ms (slew-90 PD, 1e-6). The consistent variant keeps
    CVODES.

    CVODES's columns are its BDF. With Adams where :func:`choose_multistep` takes it, at
    rtol 1e-6 and with the accuracy check (CVODES / the pair, ms): slew-90 PD first_order 6
    modes 24 / 13, exact 2 modes 12 / 12, exact 4 and 6 modes 26 and 52 / 46 and 148;
    hub-beam-mass 6 modes over 20 s 28 / 21, 20 modes over 2 s 118 / 107; spacecraft-torque
    222 / 66. The rule's choices stand.

    Where the rule takes a pair, it takes 8(5,3): its stability function keeps within the
    unit circle on the imaginary axis up to ``|h lambda|`` of 5.96 where 5(4)'s leaves it
    at 1, so its steps may be five times as long
    (:data:`~flexctl.sim.embedded_rk.DOP853_OMEGA_H`) for 16 evaluations a step (its
    continuous extension included) against 7. With the
    accuracy check, best of 4 (ms, rtol 1e-4 / 1e-6 / 1e-8; 5(4) then 8(5,3); every error
    within its estimate):

    ========================================  ===============  ===============
    run                                       5(4)             8(5,3)
    ========================================  ===============  ===============
    slew-90 PD, first_order, 6 modes, 6 s     15 / 21 / 26     16 / 22 / 20
    hub-beam-mass, 6 modes, 20 s              24 / 29 / 28     23 / 15 / 22
    hub-beam-mass, 12 modes, 20 s             193 / 189 / 189  111 / 84 / 83
    hub-beam-mass, 20 modes, 2 s              134 / 130 / 141  69 / 70 / 93
    spacecraft-torque, 6 modes, 20 s          88 / 106 / 189   51 / 82 / 91
    Kane spin-up, first_order, 4 modes, 30 s  12 / 10 / 10     5.6 / 5.5 / 5.7
    ========================================  ===============  ===============

    A looser ``rtol`` runs the 8(5,3) pair at :data:`DOP853_RTOL` (see there).

    Parameters
    ----------
    model : Model
        The model of the run.
    t_final : float
        Length of the run, s (>= 0).
    omega_max : float
        Fastest pole of the run, rad/s (>= 0; ``inf`` allowed): of the plant, the closed loop
        or the initial spin.
    """
    check_instance("choose_continuous", "model", model, Model, "flexctl Model")
    t_final = check_real("choose_continuous", "t_final", t_final, minimum=0.0)
    omega_max = check_real("choose_continuous", "omega_max", omega_max, minimum=0.0,
                           infinite=True)
    steps = omega_max * t_final / PAIR_OMEGA_H
    # the consistent variant's mass matrix can turn singular on the way: CVODES stops there
    # and the stop is located and named, where explicit steps could step across it
    if model.variant.quadratic_inertia or not math.isfinite(steps):
        return "cvodes"
    instructions = rhs_instructions(model)
    cheap = instructions <= PAIR_INSTRUCTIONS and steps * instructions <= PAIR_WORK
    return "dop853" if cheap else "cvodes"


def rhs_instructions(model: Model) -> float:
    """Instructions of one evaluation of ``model``'s right-hand side in scalar form
    (``model.casadi()``; ``inf`` where it has none).

    Parameters
    ----------
    model : Model
        The model whose compiled right-hand side is measured.
    """
    function = model.casadi()
    return float(function.n_instructions()) if function.is_a("SXFunction") else math.inf


def _breakpoints(*sources) -> list:
    points = set()
    for src in sources:
        points.update(float(b) for b in getattr(src, "breakpoints", ()) or ())
    return sorted(points)


def plan_integration(request: RunRequest, drive, stacklevel: int = 3) -> IntegrationPlan:
    """The integration of ``drive`` under ``request``; warns (:class:`StiffnessWarning`) when
    the stiffness guard changes or keeps an explicit method on a stiff run.

    Parameters
    ----------
    request : RunRequest
        The checked run (:func:`run_request`).
    drive : PrescribedDrive or TorqueDrive
        What is integrated (:mod:`flexctl.sim.drives`): its layout, initial state, right-hand
        side and inputs.
    stacklevel : int, optional
        ``stacklevel`` of the warning. Default 3.

    Returns
    -------
    IntegrationPlan
    """
    model, rtol, t_final = request.model, request.rtol, request.t_final
    sizes = state_scale(model, drive.layout)
    atol = rtol * sizes if request.atol is None else check_atol(request.atol, sizes,
                                                                 drive.layout.names)
    omega_plant = float(model.natural_frequencies(
        0.0, hub="clamped" if request.prescribed else "free")[-1])
    actuator = actuator_frequency(model)
    loop = _loop_frequency(request, drive, atol / rtol, max(omega_plant, actuator))
    fastest = max(omega_plant, loop, request.spin_frequency, actuator)
    # a Jacobian beyond floating point: no rate to trust, CVODES's BDF takes the run
    fastest, loop = (v if v == v else math.inf for v in (fastest, loop))
    compiled, possible = False, _compiled_bdf(request)
    multistep = choose_multistep(model, omega_plant, loop, t_final)
    # Adams-Moulton only where the error control sees the modes (ADAMS_TOLERANCE), in the
    # run and in its accuracy check at CHECK_FACTOR times the tolerance
    seen = ADAMS_TOLERANCE / CHECK_FACTOR
    adams_seen = rtol <= seen and bool(np.all(atol <= seen * sizes))
    uncompiled = "cvodes"
    if request.method == "auto":
        method, note = choose_continuous(model, t_final, fastest), ""
        if actuator > LOOP_FACTOR * omega_plant:
            # a fast decay, not an oscillation to follow: an implicit method steps over it
            method = "cvodes"
        uncompiled = method
        if method in BDF_REPLACES.get(model.variant, ()) and possible:
            family = "adams" if multistep == "adams" and adams_seen else "bdf"
            method, compiled = ("Adams" if family == "adams" else "BDF"), True
    elif request.method == "BDF" and possible:
        method, note, compiled, uncompiled = "BDF", "", True, "BDF"
    elif request.method == "Adams":
        # compiled, or CVODES's Adams-Moulton where it cannot be (no compiler, compiling off)
        compiled, multistep = possible, "adams"
        method = "Adams" if compiled else "cvodes"
        note = "" if adams_seen else (
            f"method 'Adams' at rtol {rtol:g} or an atol beyond {seen:g} of the states' sizes: "
            "its error control (and its check's, at 10 times the tolerance) may not see an "
            "undamped mode that Adams-Moulton's steps amplify; method 'auto' takes BDF there")
    elif request.method in PAIRS and request.symbolic and \
            choose_continuous(model, t_final, fastest) != "cvodes":
        method, note = request.method, ""          # the compiled pair, within its work
    else:
        method, note = stiffness_guard(model, t_final, request.method, request.symbolic,
                                       request.prescribed, loop, actuator)
    if note:
        warnings.warn(note, StiffnessWarning, stacklevel=stacklevel)
    else:
        note = _actuator_note(method, actuator, omega_plant)
    if request.method == "auto" and method == "dop853" and rtol > DOP853_RTOL:
        atol, rtol = atol * (DOP853_RTOL / rtol), DOP853_RTOL
        tightened = (f"rtol {request.rtol:g} tightened to {rtol:g} for the 8(5,3) pair, whose "
                     "accuracy check is reliable from there")
        note = f"{note}; {tightened}" if note else tightened
    cuts = [0.0] + [b for b in _breakpoints(*drive.sources) if 0.0 < b < t_final] + [t_final]
    steps = int(min(1e6, max(CVODES_MIN_STEPS, CVODES_STEPS_PER_RADIAN
                             * max(omega_plant, loop) * request.step)))
    return IntegrationPlan(
        method=method, atol=atol, rtol=rtol, cuts=cuts,
        drive_cuts=cuts if request.report is None else progress_cuts(cuts, t_final),
        omega_plant=omega_plant, loop_frequency=loop, cvodes_steps=steps,
        cvodes_step=request.max_step if np.isfinite(request.max_step) else None,
        stiffness_note=note, compiled=compiled, uncompiled=uncompiled,
        cvodes_multistep=multistep, actuator_frequency=actuator)


def plan_sampled(request: RunRequest) -> tuple:
    """``(integrator, h_max)`` of a sampled loop's holds, beside :func:`plan_integration`'s
    choice for a continuous run: the named method, or for ``"auto"`` the compiled
    Dormand-Prince pair or CVODES (:func:`~flexctl.sim.embedded_rk.choose_hold`).

    Parameters
    ----------
    request : RunRequest
        A run under a sampled controller.

    Returns
    -------
    integrator : {"cvodes", "RK45", "rk4"}
    h_max : float or None
        The fixed-step RK4's coarse step (:data:`~flexctl.sim.fixed_step.RK4_OMEGA_H` over the
        fastest mode, at the initial spin too), or the pair's first step (a radian of the
        held plant's fastest pole, at most a sample), s; None for CVODES.
    """
    model, integrator = request.model, request.method
    if integrator == "rk4":
        omega_max = max(float(model.natural_frequencies(0.0, hub="free")[-1]),
                        request.spin_frequency)
        return integrator, RK4_OMEGA_H / omega_max
    if integrator in ("auto", "RK45"):
        chosen, omega = choose_hold(model, request.controller.sample_time,
                                    request.spin_frequency)
        h_first = min(request.controller.sample_time,
                      1.0 / omega if 0.0 < omega < np.inf else np.inf)
        return (chosen if integrator == "auto" else integrator), h_first
    return integrator, None


def _compiled_bdf(request: RunRequest) -> bool:
    """Whether ``request`` may run on the compiled multistep methods
    (:func:`~flexctl.sim.compiled_bdf.bdf_possible`: nothing is built here)."""
    from .compiled_bdf import bdf_possible

    return bdf_possible(request.model, request.torque, request.hub_motion, request.controller)
