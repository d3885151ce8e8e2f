"""Is the model valid for this run? Deflection, geometric model error, and the variant to use.

first_order, zero_order and consistent are small-deflection models: their error against a
geometrically exact beam grows with the tip deflection relative to the length (:ref:`section 4.5
of the model <sec-exact>`). This module measures that error for a run without paying for the
exact model on every mode:

* :func:`geometric_error` runs the run's variant and the exact variant, both on
  :data:`ESTIMATE_MODES` modes, under the run's own inputs (torque, hub motion or controller)
  from the run's initial state, and returns their largest tip difference relative to the
  exact peak. The geometric nonlinearity lives in the low modes that carry the deflection, so
  the few-mode difference tracks the difference of the full models (``tests/sim/test_validity.py``
  checks it on the papers' manoeuvres and slews, within a factor of 2).
* :func:`assess` adds the deflection ratio, the run's own energy balance
  (:class:`~flexctl.sim.energy.EnergyBalance`, measured by :func:`flexctl.simulate` from
  its outputs) and a warning when the estimate passes a tolerance or the balance is broken.
* :func:`choose_variant` picks the cheapest variant whose estimated geometric error for a
  manoeuvre meets a tolerance (``[model] variant = "auto"``); slews are judged by their rigid
  rest-to-rest torque, as for the choice of modes.

Examples
--------
>>> from flexctl import load_scene
>>> from flexctl.sim.validity import choose_variant
>>> scene = load_scene("hub-beam-mass")
>>> choose_variant(scene.system, scene.maneuver, 1e-2, t_final=6.0).variant
'first_order'
"""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..model import Model, build_model
from ..model.build import rebuild
from ..model.checks import check_instance, check_real
from ..model.errors import InputTypeError, InputValueError
from ..model.user_warnings import warn_user
from ..model.variant import Variant
from .fidelity import DEFAULT_TOLERANCE, maneuver_input, check_tolerance, is_prescribed
from .compile_cache import CompileCacheWarning
from .energy import ENERGY_TOLERANCE, ModelValidityWarning
from .function_samples import recorded_sampling
from .inputs import as_vector
from .request import DEFAULT_OUTPUT_POINTS
from .runs import run_once, start_states_run

__all__ = ["ModelValidity", "VariantChoice", "ModelValidityWarning", "EstimateBeside", "assess",
           "assess_run", "run_assessed", "choose_variant", "geometric_error", "ESTIMATE_MODES",
           "SCREEN_DEFLECTION"]

#: Modes of the two models compared by :func:`geometric_error`.
ESTIMATE_MODES = 2
#: Relative tolerance of the estimate's runs (far below any tolerance asked of the estimate).
ESTIMATE_RTOL = 1e-6
#: The estimate's errors are relative to the peak deflection, or to this fraction of the beam
#: length if the peak is smaller: the geometric nonlinearity goes as the square of the
#: deflection, 1e-18 of it there.
DEFLECTION_FLOOR = 1e-9
#: Tip deflection (relative to the length) below which :func:`assess_run` bounds the
#: geometric error by :data:`SCREEN_FACTOR` times its square instead of running the estimate.
SCREEN_DEFLECTION = 0.02
#: The geometric error goes as the square of the deflection ratio: on hub-beam-mass's sine
#: torques of 0.2 to 4 N m it is 0.27 to 0.28 times it (a ratio of 1.5 % to 29 %); four times
#: that is the bound, 1.6e-4 at the screen.
SCREEN_FACTOR = 0.4



@contextlib.contextmanager
def quiet_estimate():
    """Silence the estimate's own runs (their accuracy and validity warnings are about a model
    the user did not ask for), but not a damaged compile cache: that is said once, whatever
    run meets it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        warnings.simplefilter("default", CompileCacheWarning)
        yield


def geometric_error(model, t_final: float, *, torque=None, hub_motion=None, controller=None,
                    n_modes: int = ESTIMATE_MODES, sensors=None, x0=None, run=None,
                    output_step=None) -> float:
    """Estimated relative tip error of ``model``'s variant against exact geometry.

    Parameters
    ----------
    model : Model
        Gives the system and the variant; its own number of modes is not used.
    t_final : float
        Horizon, s.
    torque, hub_motion, controller : object or None, optional
        The run's inputs, as for :func:`flexctl.simulate`. A torque function that a run
        ending at ``t_final`` sampled (it could not be traced) is taken as sampled
        (:func:`~flexctl.sim.function_samples.recorded_sampling`), not called again.
    n_modes : int, optional
        Modes of the two compared models (at least those a controller was designed on; the
        model's own for a controller with ``fixed_plant = True``, which reads exactly the
        plant's state, such as a compiled law). Default :data:`ESTIMATE_MODES`.
    sensors : Sensors, optional
        What a sampled controller reads, as for :func:`flexctl.simulate` (read noiseless
        here, so that the two runs differ only by their models).
    x0 : array_like, shape (n,), optional
        The run's initial plant state (``model``'s layout; default rest): each compared
        model starts from its states of the same names (the modes beyond ``n_modes`` left
        out).
    run : SimulationResult, optional
        The finished run being assessed (of ``model``, to ``t_final``, from ``x0``, with
        these inputs). Where it is itself the estimate's run of the variant (its model is
        the variant on the compared modes, it reached its end at ``rtol`` at most
        :data:`ESTIMATE_RTOL`, and no sensors are read), its states stand for that run and
        only the exact model is run, on its output grid.
    output_step : float, optional
        The run's output spacing, s, as given to :func:`flexctl.simulate` (default: its
        default); used with ``run``, whose states stand for the variant's run only on a grid
        at least as fine as the estimate's own (``t_final / DEFAULT_OUTPUT_POINTS``, of
        ``flexctl.sim.request``).

    Returns
    -------
    float
        ``max_t |tip_variant - tip_exact| / max_t |tip_exact|`` on ``n_modes`` modes; 0 for the
        exact variant; ``inf`` when one of the two runs stops early.
    """
    t_final = check_real("geometric_error", "t_final", t_final, minimum=0.0, strict=True)
    check_instance("geometric_error", "model", model, Model, "flexctl Model")
    if model.variant.exact:
        return 0.0
    x0 = _checked_initial_state(model, x0)
    if output_step is not None:
        output_step = check_real("geometric_error", "output_step", output_step, minimum=0.0,
                                 strict=True)
    # the run itself is the variant's run where it reached its end (and is one on the
    # compared modes, at least as accurate and not read through sensors: _Estimate)
    run_rtol = (float(getattr(run, "rtol", np.inf))
                if run is not None and getattr(run, "status", None) == "ok" else None)
    estimate = _Estimate(model, t_final, torque, hub_motion, controller, n_modes, sensors, x0,
                         output_step, run_rtol)
    return estimate.error(run)


class _Estimate:
    """The two runs of :func:`geometric_error`, started (``start_states_run``: the exact
    run's compiled steps on a spare core, or queued for one, while the caller goes on), and
    the estimate from them (:meth:`error`).

    Where ``run_rtol`` is given (the rtol of a run of ``model`` that reached ``t_final``:
    :func:`geometric_error`'s ``run``), that run stands for the variant's where it is the
    variant on the compared modes, at least as accurate as the estimate's runs and not read
    through sensors, and on a grid at least as fine as the estimate's own (``output_step``);
    ``same`` says so.
    """

    def __init__(self, model, t_final, torque, hub_motion, controller, n_modes, sensors, x0,
                 output_step, run_rtol):
        self.model, self.t_final, self.x0 = model, t_final, x0
        self.inputs = (torque, hub_motion, controller, sensors)
        # a torque function sampled for the run is replayed as sampled: its small error is
        # common to the two models' responses, whose difference is the estimate
        torque = recorded_sampling(torque, t_final)
        # a controller reads at least the modes it was designed on; one compiled for the
        # plant's state (``fixed_plant``) reads exactly the plant's
        self.n_modes = n_modes = (
            model.mode_spec if getattr(controller, "fixed_plant", False)
            else min(max(n_modes, _law_modes(controller)), min(model.modes)))
        compared = [rebuild(model, n_modes=n_modes, variant=variant)
                    for variant in ("exact", model.variant)]
        # ... and on a grid at least as fine as the estimate's own (a coarse grid would miss
        # the largest difference)
        self.same = (run_rtol is not None and sensors is None and run_rtol <= ESTIMATE_RTOL
                     and (output_step is None
                          or output_step <= t_final / DEFAULT_OUTPUT_POINTS)
                     and _same_model(compared[1], model))
        grid = {"output_step": output_step} if self.same else {}
        self.runs = []
        try:
            for small in compared:
                if self.same and small is compared[1]:
                    self.runs.append((small, None))
                    continue
                on_small = controller
                if callable(getattr(controller, "for_plant", None)):  # sensors set for a plant
                    on_small = controller.for_plant(small)
                # with noiseless readings: a quantised, noisy loop's vibration is not
                # repeatable from one model to the other, while the model error is the
                # manoeuvre's
                drive = {"torque": torque, "hub_motion": hub_motion, "controller": on_small,
                         "sensors": None if sensors is None else sensors.noiseless(),
                         "x0": _initial_state_of(small, model, x0)}
                with quiet_estimate():
                    self.runs.append((small, start_states_run(
                        small, t_final, rtol=ESTIMATE_RTOL, check_accuracy=False, **grid,
                        **drive)))
        except BaseException:
            self.abandon()
            raise

    def error(self, run=None) -> float:
        """:func:`geometric_error` from the started runs (``run``'s states standing for the
        variant's where ``same``)."""
        try:
            tips = []
            for small, started in reversed(self.runs):
                if started is None:
                    ok, states = True, run.states
                else:
                    with quiet_estimate():
                        ok, states = started.result()
                if not ok:
                    return float("inf")
                tips.append(np.atleast_2d(small.tip_deflections(states)))
        finally:
            self.abandon()
        if tips[0].shape != tips[1].shape:
            # the run's grid is not the one asked for the exact run: both runs made
            torque, hub_motion, controller, sensors = self.inputs
            return _Estimate(self.model, self.t_final, torque, hub_motion, controller,
                             self.n_modes, sensors, self.x0, None, None).error()
        # each appendage relative to its peak, but not below DEFLECTION_FLOOR of its length:
        # a deflection of 1e-38 m has no geometric error, only the integrators' rounding
        peak = np.maximum(np.max(np.abs(tips[1]), axis=1),
                          DEFLECTION_FLOOR * self.model.lengths)
        return float(np.max(np.max(np.abs(tips[0] - tips[1]), axis=1) / peak))

    def abandon(self) -> None:
        """Give up the runs not yet asked for."""
        for _, started in self.runs:
            if started is not None:
                started.abandon()


class EstimateBeside:
    """The validity estimate's runs for one run of :func:`flexctl.simulate`, started while that
    run integrates (its :func:`~flexctl.sim.runs.run_once` ``alongside``).

    Called with the run's checked request and plan, once its accuracy check has started, it
    starts the runs :func:`geometric_error` will need for the run (queued for a spare core,
    behind the check): the exact model's, and the variant's unless the run stands for it,
    judged by the run's plan. :func:`assess_run` then takes them where they are the ones it
    would make (the run reached its end from the same state) and otherwise makes its own; a
    run screened as small gives them up (:meth:`abandon`). Work that cannot start (a model
    the estimate cannot build) is left to the assessment, which says why.

    Parameters
    ----------
    model : Model
        The run's model.
    torque, hub_motion, controller, sensors : object or None, optional
        The run's inputs, as :func:`flexctl.simulate` takes them.
    output_step : float or None, optional
        The run's output spacing, s, as given to :func:`flexctl.simulate`.
    """

    def __init__(self, model, *, torque=None, hub_motion=None, controller=None, sensors=None,
                 output_step=None):
        self.model = check_instance("EstimateBeside", "model", model, Model, "flexctl Model")
        self.output_step = output_step if output_step is None else check_real(
            "EstimateBeside", "output_step", output_step, minimum=0.0, strict=True)
        self.inputs = (torque, hub_motion, controller, sensors)
        self.estimate, self.t_final, self.x0 = None, None, None

    def __call__(self, request, plan) -> None:
        if self.model.variant.exact or self.estimate is not None:
            return
        torque, hub_motion, controller, sensors = self.inputs
        try:
            self.estimate = _Estimate(self.model, request.t_final, torque, hub_motion,
                                      controller, ESTIMATE_MODES, sensors, request.x_init,
                                      self.output_step, float(plan.rtol))
        except Exception:                     # noqa: BLE001 - the assessment says why
            self.estimate = None
            return
        self.t_final, self.x0 = request.t_final, request.x_init

    def take(self, result, t_end: float, x0):
        """The started estimate where it is the one :func:`geometric_error` makes for
        ``result``, else None (its runs given up); taken once.

        Parameters
        ----------
        result : SimulationResult
            The finished run.
        t_end : float
            Where it ended, s.
        x0 : ndarray, shape (n,) or None
            Its initial state.
        """
        estimate, self.estimate = self.estimate, None
        if estimate is None:
            return None
        if (t_end == self.t_final and x0 is not None and np.array_equal(x0, self.x0)
                and (not estimate.same or (result.status == "ok" and result.model is self.model
                                           and float(result.rtol) <= ESTIMATE_RTOL))):
            return estimate
        estimate.abandon()
        return None

    def abandon(self) -> None:
        """Give up the started runs (a run screened as small needs none)."""
        if self.estimate is not None:
            self.estimate.abandon()
            self.estimate = None


def _same_model(one, other) -> bool:
    """Whether two models are the same plant: of one kind, variant, modes, system and
    actuator (:func:`~flexctl.model.build.rebuild` may give an equal one, not the same
    object)."""
    return one is other or (
        type(one) is type(other) and one.variant == other.variant
        and one.mode_spec == other.mode_spec and one.n_states == other.n_states
        and one.system == other.system
        and getattr(one, "actuator", None) == getattr(other, "actuator", None))


def _checked_initial_state(model, x0):
    """``x0`` as ``model``'s states (shape (n,), finite), or None for rest."""
    if x0 is None:
        return None
    n = model.layout.n_states
    x0 = as_vector("geometric_error x0", x0, f"the model's {n} states as numbers")
    if x0.shape != (n,) or not np.all(np.isfinite(x0)):
        raise InputValueError(f"geometric_error x0 must be the model's {n} states as finite "
                              f"numbers; got shape {x0.shape}"
                              f"{'' if x0.shape != (n,) else ' with a non-finite entry'}")
    return x0


def _initial_state_of(small, model, x0):
    """``model``'s checked initial state ``x0`` on the layout of ``small`` (the same plant on
    fewer modes), state by state name; None for rest."""
    if x0 is None:
        return None
    index = {name: k for k, name in enumerate(model.layout.names)}
    return x0[[index[name] for name in small.layout.names]]


def _law_modes(controller) -> int:
    """The most modes a law reads, through its wrappers (a hold, an observer, a motor's
    voltage hold the law in ``law``): 0 for none."""
    most, seen = 0, set()
    while controller is not None and id(controller) not in seen:
        seen.add(id(controller))
        modes = getattr(controller, "n_modes", 0)
        most = max(most, modes if isinstance(modes, int) else 0)
        controller = getattr(controller, "law", None)
    return most


@dataclass(frozen=True, kw_only=True)
class ModelValidity:
    """How far a run stayed inside its model's range.

    Attributes
    ----------
    variant : str
    deflection_ratio : float
        Largest ``|tip deflection|`` divided by the beam length.
    geometric_error : float
        Estimated relative tip error against exact geometry (:func:`geometric_error`); 0 for
        the exact variant.
    tolerance : float
        Relative tip error accepted.
    energy_balance : EnergyBalance or None
        The run's energy against the work done on it (``result.energy_balance``); ``None``
        for the exact variant.
    t_end : float or None
        Where the run ended, s; a run that stopped at ``t = 0`` has nothing to assess.
    screened : bool
        ``geometric_error`` is the bound :data:`SCREEN_FACTOR` times the squared deflection
        ratio (a tip under :data:`SCREEN_DEFLECTION` of the length), not an estimate's runs.
    """

    variant: str
    deflection_ratio: float
    geometric_error: float
    tolerance: float
    energy_balance: object = None
    t_end: float | None = None
    screened: bool = False

    @property
    def energy_error(self) -> float | None:
        """Energy created or destroyed relative to the run's energy scale."""
        balance = self.energy_balance
        return None if balance is None else balance.relative_imbalance

    @property
    def valid(self) -> bool:
        """True when the estimated geometric error is within the tolerance and the energy
        balance within :data:`~flexctl.sim.energy.ENERGY_TOLERANCE`."""
        energy_ok = self.energy_balance is None or not self.energy_balance.violated
        return self.geometric_error <= self.tolerance and energy_ok

    @property
    def message(self) -> str:
        """One sentence for people."""
        how = "bounded (small deflection)" if self.screened else "estimated"
        text = (f"peak tip deflection {100 * self.deflection_ratio:.3g} % of the beam length; "
                f"{how} geometric model error {self.geometric_error:.2g} of the peak")
        if Variant(self.variant).exact:
            return (f"peak tip deflection {100 * self.deflection_ratio:.3g} % of the beam "
                    "length; exact geometry")
        if self.t_end is not None and self.t_end <= 0.0:
            return "not assessed: the run stopped at t = 0"
        if self.valid:
            return f"{text}, within the tolerance {self.tolerance:.2g}"
        if self.geometric_error > self.tolerance:
            text = (f"{text}, above the tolerance {self.tolerance:.2g}: the {self.variant} model "
                    "is used outside its small-deflection range")
        if self.energy_balance is not None and self.energy_balance.violated:
            text = (f"{text}; energy balance violated (more than {ENERGY_TOLERANCE:g} of the "
                    f"energy scale): {self.energy_balance.message}")
        return f"{text}; use variant = \"exact\""

    def to_dict(self) -> dict:
        """JSON types only (as written to ``summary.json``)."""
        error = self.geometric_error
        return {"variant": self.variant, "deflection_ratio": self.deflection_ratio,
                "geometric_error": error if np.isfinite(error) else None,
                "tolerance": self.tolerance, "valid": self.valid,
                "energy_error": _finite_or_none(self.energy_error), "message": self.message}


def _finite_or_none(value):
    return float(value) if value is not None and np.isfinite(value) else None


def assess_run(result, *, torque=None, hub_motion=None, controller=None, sensors=None,
               tolerance: float = DEFAULT_TOLERANCE, warn: bool = True,
               output_step=None, started=None) -> ModelValidity:
    """:func:`assess`, with the estimate's runs made only where they can matter.

    A small-deflection run whose tip stays under :data:`SCREEN_DEFLECTION` of the length is
    bounded by :data:`SCREEN_FACTOR` times its squared deflection ratio (``screened``); the
    exact variant has no geometric error; every other run is assessed by :func:`assess`.
    Used by :func:`flexctl.simulate` for every run (``check_validity``).

    Parameters
    ----------
    result : SimulationResult
        The finished run.
    torque, hub_motion, controller, sensors : object, optional
        The inputs the run was made with, as :func:`flexctl.simulate` takes them.
    tolerance : float, optional
        Relative tip error accepted, in (0, 1). Default 1e-2.
    warn : bool, optional
        Issue a :class:`ModelValidityWarning` when the estimate is above ``tolerance`` or the
        run's energy balance is violated. Default True.
    output_step : float, optional
        The run's output spacing, s, as given to :func:`flexctl.simulate` (:func:`assess`).
    started : EstimateBeside, optional
        The estimate's runs, started while the run integrated (as :func:`flexctl.simulate`
        starts them): taken where they are the ones the estimate needs, given up otherwise.

    Returns
    -------
    ModelValidity
    """
    check_tolerance(tolerance)
    model = result.model
    ratio = float(result.deflection_ratio) if np.isfinite(result.deflection_ratio) else np.inf
    if not model.variant.exact and ratio > SCREEN_DEFLECTION:
        return _assess(result, torque=torque, hub_motion=hub_motion, controller=controller,
                       sensors=sensors, tolerance=tolerance, warn=warn,
                       output_step=output_step, started=started)
    if started is not None:
        started.abandon()
    t_end = float(result.t[-1]) if result.t.size else 0.0
    validity = ModelValidity(variant=model.variant, deflection_ratio=ratio,
                             geometric_error=0.0 if model.variant.exact
                             else SCREEN_FACTOR * ratio ** 2,
                             tolerance=float(tolerance),
                             energy_balance=getattr(result, "energy_balance", None),
                             t_end=t_end, screened=not model.variant.exact)
    if warn and not validity.valid:
        warn_user(validity.message, ModelValidityWarning)
    return validity


def run_assessed(model, t_final: float, torque=None, hub_motion=None, controller=None,
                 x0=None, *, tolerance: float = DEFAULT_TOLERANCE, check_validity: bool = True,
                 **options):
    """:func:`~flexctl.sim.runs.run_once`, its validity assessed (:func:`assess_run`) on the
    estimate's runs started while it integrates (:class:`EstimateBeside`): the run of
    :func:`flexctl.simulate`, at any ``tolerance``.

    Parameters
    ----------
    model : Model
        The model to simulate.
    t_final : float
        End time, s.
    torque, hub_motion, controller : object, optional
        The run's inputs, as :func:`flexctl.simulate` takes them.
    x0 : array_like, shape (n,), optional
        Initial plant state; default rest at zero.
    tolerance : float, optional
        Largest acceptable geometric error, relative to the peak tip deflection (default
        :data:`~flexctl.sim.fidelity.DEFAULT_TOLERANCE`).
    check_validity : bool, optional
        Assess the run (default True); False: ``validity`` stays None.
    **options
        The other keywords of :func:`flexctl.simulate` (``rtol``, ``atol``, ``method``,
        ``output_step``, ``max_step``, ``check_accuracy``, ``progress``, ``sensors``).

    Returns
    -------
    SimulationResult
        The run, with its ``validity``.
    """
    # a bad argument is left to run_once, which names it as the run's
    started = None
    if check_validity:
        check_tolerance(tolerance)          # before the run, not after it
        with contextlib.suppress(InputTypeError, InputValueError):
            started = EstimateBeside(model, torque=torque, hub_motion=hub_motion,
                                     controller=controller, sensors=options.get("sensors"),
                                     output_step=options.get("output_step"))
    try:
        result = run_once(model, t_final, torque, hub_motion, controller, x0,
                          alongside=started, **options)
        if not check_validity:
            return result
        return replace(result, validity=assess_run(
            result, torque=torque, hub_motion=hub_motion, controller=controller,
            sensors=options.get("sensors"), tolerance=tolerance,
            output_step=options.get("output_step"), started=started))
    finally:
        if started is not None:
            started.abandon()


def assess(result, *, torque=None, hub_motion=None, controller=None, sensors=None,
           tolerance: float = DEFAULT_TOLERANCE, warn: bool = True,
           output_step=None) -> ModelValidity:
    """The :class:`ModelValidity` of a finished run, warning when the model was out of range.

    Parameters
    ----------
    result : SimulationResult
        The finished run: its model, states and energy balance.
    torque, hub_motion, controller : object or None, optional
        The inputs the run was made with.
    sensors : Sensors, optional
        What its sampled controller read, if any.
    tolerance : float, optional
        Relative tip error accepted, in (0, 1). Default 1e-2.
    warn : bool, optional
        Issue a :class:`ModelValidityWarning` when the estimate is above ``tolerance`` or the
        run's energy balance is violated. Default True.
    output_step : float, optional
        The run's output spacing, s, as given to :func:`flexctl.simulate` (default: its
        default): where the run is itself the estimate's run of its variant, its states are
        taken for it (:func:`geometric_error`'s ``run``).
    """
    return _assess(result, torque=torque, hub_motion=hub_motion, controller=controller,
                   sensors=sensors, tolerance=tolerance, warn=warn, output_step=output_step)


def _assess(result, *, torque, hub_motion, controller, sensors, tolerance, warn, output_step,
            started=None) -> ModelValidity:
    """:func:`assess`, on the estimate's runs ``started`` beside the run where they are the
    ones it needs (:class:`EstimateBeside`)."""
    check_tolerance(tolerance)
    model = result.model
    t_end = float(result.t[-1]) if result.t.size else 0.0
    x0 = result.states[:, 0] if np.ndim(result.states) == 2 and result.t.size else None
    estimate = None if started is None else started.take(result, t_end, x0)
    if estimate is not None:
        error = estimate.error(result)
    else:
        error = (geometric_error(model, t_end, torque=torque, hub_motion=hub_motion,
                                 controller=controller, sensors=sensors, x0=x0, run=result,
                                 output_step=output_step)
                 if t_end > 0 else 0.0)
    validity = ModelValidity(variant=model.variant,
                             deflection_ratio=result.deflection_ratio,
                             geometric_error=error, tolerance=float(tolerance),
                             energy_balance=getattr(result, "energy_balance", None),
                             t_end=t_end)
    if warn and not validity.valid:
        warn_user(validity.message, ModelValidityWarning)
    return validity


@dataclass(frozen=True, kw_only=True)
class VariantChoice:
    """The variant a manoeuvre needs, as chosen by :func:`choose_variant`.

    Attributes
    ----------
    variant : {"first_order", "exact"}
    geometric_error : float
        Estimated relative tip error of first_order against exact geometry.
    deflection_ratio : float
        Peak tip deflection of the estimate relative to the beam length.
    tolerance : float
    explanation : str
    """

    variant: str
    geometric_error: float
    deflection_ratio: float
    tolerance: float
    explanation: str

    def to_dict(self) -> dict:
        """JSON types only."""
        error = self.geometric_error
        return {"variant": self.variant, "deflection_ratio": self.deflection_ratio,
                "geometric_error": error if np.isfinite(error) else None,
                "tolerance": self.tolerance, "explanation": self.explanation}


def choose_variant(system, maneuver, tolerance: float = DEFAULT_TOLERANCE, *,
                   t_final: float) -> VariantChoice:
    """The cheapest variant whose estimated geometric error meets ``tolerance``.

    first_order when :func:`geometric_error` of first_order on the manoeuvre (a slew by its
    rigid rest-to-rest torque) is within ``tolerance``; exact otherwise.

    Parameters
    ----------
    system : HubBeam or Structure
        The structure the models are built on.
    maneuver : SpinUp, SineTorque, Slew or similar
        A prescribed hub motion, a torque ``f(t)`` (N m) or a slew (judged by its rigid
        rest-to-rest torque, :func:`~flexctl.sim.fidelity.rigid_slew_torque`).
    tolerance : float, optional
        Relative tip error accepted, in (0, 1). Default 1e-2.
    t_final : float
        Horizon of the estimate's runs, s.

    Returns
    -------
    VariantChoice
    """
    check_tolerance(tolerance)
    return _choose(system, maneuver, float(tolerance), float(t_final))


@lru_cache(maxsize=64)
def _choose(system, maneuver, tolerance, t_final) -> VariantChoice:
    drive = maneuver_input(system, maneuver)
    key = "hub_motion" if is_prescribed(drive) else "torque"
    model = build_model(system, n_modes=ESTIMATE_MODES, variant="exact")
    with quiet_estimate():
        run = run_once(model, t_final, rtol=ESTIMATE_RTOL, check_accuracy=False,
                       **{key: drive})
    ratio = run.deflection_ratio
    error = geometric_error(build_model(system, n_modes=ESTIMATE_MODES), t_final,
                            **{key: drive})
    if error <= tolerance:
        variant = "first_order"
        why = (f"first_order: estimated geometric error {error:.2g} of the peak is within the "
               f"tolerance {tolerance:.2g} (peak tip deflection {100 * ratio:.3g} % of the "
               "length)")
    else:
        variant = "exact"
        why = (f"exact: first_order's estimated geometric error {error:.2g} of the peak is "
               f"above the tolerance {tolerance:.2g} (peak tip deflection {100 * ratio:.3g} % "
               "of the length)")
    return VariantChoice(variant=variant, geometric_error=error, deflection_ratio=ratio,
                         tolerance=tolerance, explanation=why)
