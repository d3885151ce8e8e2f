"""Time simulation of a hub-beam-mass model with error-controlled integration.

Three ways to drive the hub, combined as follows:

- ``torque``: a function of time ``f(t)`` or of time and state ``f(t, x)``, or samples
  ``(times, values)`` (:class:`~flexctl.sim.inputs.SampledTorque`), N m;
- ``controller``: feedback, a callable ``(t, x) -> torque`` or an object following
  :class:`Controller` (with internal states, e.g. an estimator); its torque adds to ``torque``;
- ``hub_motion``: a prescribed ``theta(t)`` with ``rate(t)`` and ``acceleration(t)`` (e.g.
  :class:`~flexctl.sim.maneuvers.SpinUp`); only the beam equation is integrated and the result
  carries the torque the motion needs. Excludes the other two.

Inputs are evaluated at the integrator's own times (never sampled and interpolated), and the
integration restarts at every ``breakpoints`` time an input declares (where it is not smooth);
no step is longer than the ``max_step`` an input declares (a sampled torque: its sample
interval, so that no sample is stepped over) or the one given.

A run stops early, and says so in ``status`` and ``message``, when

- the tip deflection passes the beam length (``"diverged"``): the small-deflection model has
  left its domain, with the physical reason when known (e.g. the zero_order model spinning
  above its first clamped frequency);
- the mass matrix turns singular (``"singular"``): the effective hub inertia of the consistent
  variant reaches zero (a light hub);
- the integrator fails (``"diverged"``, with the integrator's message).

The arrays of a stopped run end at the stop time; they never hold NaN or overflowed values.

Methods
-------
``"cvodes"`` is compiled SUNDIALS integration (:mod:`flexctl.sim.compiled`), Adams-Moulton
for lightly damped oscillations and BDF where poles decay fast
(:func:`flexctl.sim.request.choose_multistep`); every such run
is repeated at 10 times the tolerance to estimate its integration error, and redone with
A-stable BDF2 if the two disagree grossly. ``"dop853"`` is compiled Dormand-Prince 8(5,3)
stepping (:class:`~flexctl.sim.embedded_rk.EmbeddedRun`; the scheme of SciPy's ``"DOP853"``,
which calls the inputs from Python), its outputs read from the pair's continuous extension of
order 7 and its error estimated by a replay at 10 times the tolerance; it needs inputs with a
CasADi form. ``"RK45"`` with such inputs is the same for Dormand-Prince 5(4). ``"BDF"`` with
such inputs is a compiled variable-order BDF and
``"Adams"`` compiled Adams-Moulton methods of orders 1 to 12
(:class:`~flexctl.sim.compiled_bdf.BdfRun`; CVODES's Adams-Moulton where nothing can be
compiled), checked the same way. ``"auto"`` takes ``"dop853"`` (at an ``rtol`` no looser than
:data:`~flexctl.sim.request.DOP853_RTOL`) where it costs less than CVODES (a
cheap right-hand side, a fastest pole that leaves few steps:
:func:`flexctl.sim.request.choose_continuous`), else CVODES, for the exact model in place of
either the compiled Adams-Moulton methods where CVODES would take Adams and the tolerance lets
the error control see the modes (:data:`flexctl.sim.request.ADAMS_TOLERANCE`), else the
compiled BDF (:data:`flexctl.sim.request.BDF_REPLACES`), and ``"DOP853"`` for inputs without a
CasADi form. An ``atol`` beyond :data:`~flexctl.sim.request.ATOL_LIMIT` times a state's
physical size (a tenth of the shortest beam's length, 0.1 rad) is refused: the error control
would not see the motion. An explicit SciPy method
(DOP853, RK45, RK23) on a model too stiff for it is replaced by ``"cvodes"`` when the inputs
allow, with a
:class:`StiffnessWarning` and a note in the result's ``message`` (the result's ``method`` is
the one used; :func:`flexctl.sim.request.stiffness_guard`). ``"rk4"`` is compiled fixed-step
RK4 for loose tolerances, its step set by the fastest mode and halved until a step-doubling
error estimate meets ``rtol`` (:mod:`flexctl.sim.fixed_step`); it needs inputs with a CasADi
form. A ``progress`` callable makes the run integrate in
:data:`~flexctl.sim.progress.PROGRESS_CHUNKS` pieces.

The parts, each in its own module: the validated request and integration plan
(:mod:`~flexctl.sim.request`), the drive (:mod:`~flexctl.sim.drives`), one integration strategy
per method family (:mod:`~flexctl.sim.strategies`), the stopping conditions
(:mod:`~flexctl.sim.stops`) and the result's assembly (:mod:`~flexctl.sim.result`).
"""

from __future__ import annotations


import numpy as np

from .drives import Controller, StaticLaw
from .energy import EnergyBalance, ModelValidityWarning, energy_balance
from .request import LOOP_LIMIT, METHODS, MIN_T_FINAL, StiffnessWarning
from .result import SimulationResult
from .stops import StopReason
from .strategies import FALLBACK_EVALUATIONS, AccuracyWarning
from .validity import run_assessed
from ..model import Model

__all__ = ["simulate", "SimulationResult", "Controller", "StaticLaw", "StopReason",
           "StiffnessWarning", "AccuracyWarning", "ModelValidityWarning", "EnergyBalance",
           "energy_balance", "METHODS", "MIN_T_FINAL", "LOOP_LIMIT", "FALLBACK_EVALUATIONS"]


def simulate(model: Model, t_final: float, torque=None, hub_motion=None, controller=None,
             x0=None, *, rtol: float | None = None, atol=None, method: str = "auto",
             output_step: float | None = None, max_step: float = np.inf,
             check_accuracy: bool = True, progress=None, sensors=None,
             check_validity: bool = True) -> SimulationResult:
    """Simulate the nonlinear model.

    Parameters
    ----------
    model : Model
        The model to simulate: any variant, a structure or an actuated model
        (:func:`flexctl.build_model`).
    t_final : float
        End time, s (> 0).
    torque : callable, (times, values) or SampledTorque, optional
        Hub torque, N m (with an actuator: its command, N m or V, as the ``controller``'s
        output). Default 0. A function ``torque(t)`` or ``torque(t, x)`` (compiled
        where CasADi can trace it, :mod:`flexctl.sim.tracing`), or samples covering
        ``[0, t_final]``: ``(times, values)`` (shape (K,) each, as python-control's ``T`` and
        ``U``) interpolated linearly, or a :class:`~flexctl.sim.inputs.SampledTorque`.
    hub_motion : object, optional
        Prescribed hub motion with methods ``angle(t)``, ``rate(t)``, ``acceleration(t)``
        (rad, rad/s, rad/s^2), e.g. :class:`~flexctl.sim.maneuvers.SpinUp`.
    controller : callable or Controller, optional
        Feedback torque ``controller(t, x)`` or a :class:`Controller` object.
    x0 : array_like, shape (n,), optional
        Initial plant state; default rest at zero. With ``hub_motion`` its hub entries are
        ignored (the motion fixes them).
    rtol : float, optional
        Relative tolerance of the error-controlled integrator. Default 1e-8. For ``"rk4"``:
        the largest estimated tip-deflection error relative to its peak, default 1e-2.
    atol : float or array_like, optional
        Absolute tolerance, one or one per state; default ``rtol`` times each state's
        physical scale (:func:`~flexctl.sim.request.state_scale`), at most 100 times it.
    method : str, optional
        ``"auto"`` (default), ``"cvodes"``, ``"rk4"``, ``"dop853"``, ``"Adams"`` or a
        ``solve_ivp`` method (``"DOP853"``, ``"RK45"``, ``"RK23"``, ``"Radau"``, ``"BDF"``,
        ``"LSODA"``); see the module's Methods.
    output_step : float, optional
        Spacing of the output times, s. Default: ``t_final / 2000``.
    max_step : float, optional
        Largest integration step, s, on every path (for ``"rk4"``, of the coarser run of its
        step-doubling pair). An input's own ``max_step`` (a sampled torque's sample
        interval) bounds it too.
    check_accuracy : bool, optional
        Repeat the run at 10 times the tolerance for ``result.integration_error``: beside the
        run for ``"cvodes"``, ``"Adams"``, ``"dop853"``, compiled ``"RK45"`` and ``"BDF"``
        (:func:`flexctl.sim.compiled.verify_accuracy`,
        :func:`flexctl.sim.strategies.check_embedded_accuracy`), after it for SciPy's methods
        (:func:`flexctl.sim.strategies.replay_error`); ``"rk4"`` is its own step-doubling
        pair. Default True.
    progress : bool or callable, optional
        ``True`` prints the simulated time reached and the time to go to stderr every 5 s
        once the run has taken 5 s; a callable gets a :class:`~flexctl.sim.progress.Progress`
        after every :data:`~flexctl.sim.progress.PROGRESS_CHUNKS`-th of the run. Default
        none.
    sensors : Sensors, optional
        Read by a sampled controller with ``measures = True`` (:class:`controllers.Observed`)
        at its samples (:mod:`flexctl.sim.sensors`); kept in ``result.measurements``.
    check_validity : bool, optional
        Assess the model's range (``result.validity``,
        :func:`~flexctl.sim.validity.assess_run`: past a tip of 2 % of the length, by running
        the same inputs on two small models; a controller that records or counts sees those runs
        too) and warn when a small-deflection variant left it, as a scene run does. Default
        True.

    Returns
    -------
    SimulationResult

    Examples
    --------
    >>> from flexctl import load_scene, build_model, simulate
    >>> from flexctl.sim.maneuvers import SineTorque
    >>> model = build_model(load_scene("spacecraft-torque").system, n_modes=4)
    >>> result = simulate(model, 10.0, torque=SineTorque(peak_torque=50.0, duration=2.0))
    >>> result.status, round(result.peak_tip_deflection, 2)
    ('ok', 0.42)
    """
    # the estimate's runs start while the run integrates (queued beside it for a spare core)
    return run_assessed(model, t_final, torque, hub_motion, controller, x0,
                        check_validity=check_validity, rtol=rtol, atol=atol, method=method,
                        output_step=output_step, max_step=max_step,
                        check_accuracy=check_accuracy, progress=progress, sensors=sensors)
