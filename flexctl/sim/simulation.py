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
"""

from __future__ import annotations

import inspect
import math
import time
import warnings
from dataclasses import dataclass, field
from enum import Enum
from numbers import Real
from typing import Protocol, runtime_checkable

import numpy as np
from scipy.integrate import solve_ivp

from .compiled import (SegmentIntegrator, is_symbolic, numeric_rhs, torque_history,
                       verify_accuracy)
from .digital import is_sampled, run_sampled
from .energy import EnergyBalance, ModelValidityWarning, energy_balance
from .progress import Progress, check_progress, progress_cuts
from .fixed_step import MAX_HALVINGS, RK4_OMEGA_H, integrate_fixed_step
from .inputs import (as_vector, check_method, check_rtol, check_time, input_value,
                     jacobian_frequency, output_grid, time_function)
from .tracing import torque_input
from ..model import Model, SingularMassMatrixError
from ..model.errors import InputTypeError, InputValueError

__all__ = ["simulate", "SimulationResult", "Controller", "StaticLaw", "StopReason",
           "StiffnessWarning", "AccuracyWarning", "ModelValidityWarning", "EnergyBalance",
           "energy_balance"]

#: Integration stops as "singular" when the effective hub inertia falls below this fraction
#: of its value at rest (the exact singularity cannot be integrated up to).
SINGULAR_FRACTION = 1e-9
#: The exact variant stops as "diverged" when its modal tip ``phi(l)^T q``, the integral of the
#: slope angle over the beam, passes this many beam lengths: a mean slope of 2 rad is a beam
#: curled back on itself, beyond what a few modes describe.
EXACT_CURL = 2.0

#: Integration methods: "auto" (CVODES when every input has a CasADi form, else DOP853),
#: "cvodes" (compiled, :mod:`flexctl.sim.compiled`), "rk4" (compiled fixed step,
#: :mod:`flexctl.sim.fixed_step`) and the ``scipy.integrate.solve_ivp`` methods.
METHODS = ("auto", "cvodes", "rk4", "DOP853", "RK45", "RK23", "Radau", "BDF", "LSODA")

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
EXPLICIT_STABILITY_LIMITS = {"DOP853": 3.0, "RK45": 0.67, "RK23": 0.87}
#: An explicit method predicted to need more steps than this (about 5 s of DOP853 at ~40 us a
#: right-hand side) is not used when the compiled implicit path can take the run.
EXPLICIT_STEP_LIMIT = 10_000
#: The closed loop counts as made stiff by its controller when its fastest pole is this many
#: times the plant's fastest mode.
LOOP_FACTOR = 2.0
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


class AccuracyWarning(RuntimeWarning):
    """The accuracy check of a compiled run found it wrong and what was done about it."""


class StiffnessWarning(RuntimeWarning):
    """An explicit method was asked for on a model whose fastest mode makes it crawl."""


#: Where a compiled segment fails, SciPy locates the stop with at most this many evaluations
#: of the right-hand side (1 to 5 s of DOP853 steps); a state so stiff that they do not
#: reach it ends the run as an integrator failure, with its stiffness named. The 3e4 kg
#: tip-mass divergence of first_order took 7.5e4.
FALLBACK_EVALUATIONS = 200_000


class _BudgetSpent(Exception):
    """The fallback integrator spent its evaluations at time ``t`` in state ``y``."""

    def __init__(self, t, y):
        super().__init__(f"evaluation budget spent at t = {t:.6g} s")
        self.t, self.y = float(t), np.array(y, dtype=float)


class _Budgeted:
    """A right-hand side that raises :class:`_BudgetSpent` past ``budget`` evaluations."""

    def __init__(self, rhs, budget: int):
        self.rhs, self.left = rhs, int(budget)

    def __call__(self, t, y):
        self.left -= 1
        if self.left < 0:
            raise _BudgetSpent(t, y)
        return self.rhs(t, y)


class StopReason(Enum):
    """Why a run ended; :attr:`status` is the ``SimulationResult.status`` it gives."""

    REACHED_END = "reached t_final"
    TIP_PAST_LENGTH = "the modal tip passed the beam length (small-deflection variants)"
    BEAM_CURLED = "the exact beam curled back on itself"
    SINGULAR_MASS = "the mass matrix turned singular"
    STATE_OVERFLOW = "the state overflowed"
    INTEGRATOR_FAILED = "the integrator failed"
    NON_FINITE_STATE = "the state became non-finite"
    NON_FINITE_TORQUE = "the hub torque became non-finite"

    @property
    def status(self) -> str:
        """``"ok"``, ``"singular"`` or ``"diverged"``."""
        if self is StopReason.REACHED_END:
            return "ok"
        return "singular" if self is StopReason.SINGULAR_MASS else "diverged"


def _geometric_stop(model: Model) -> StopReason:
    """The stop of a run whose tip left the range of ``model``."""
    return StopReason.BEAM_CURLED if model.variant == "exact" else StopReason.TIP_PAST_LENGTH


def _stop_message(model: Model, reason: StopReason, t_end: float, state) -> str:
    """The physical reason of a stop found by an event or a bad sample, at ``t_end`` (s) in
    the plant state ``state``."""
    n = model.n_modes
    if reason is StopReason.BEAM_CURLED:
        return (f"the beam curled back on itself at t = {t_end:.6g} s (mean slope angle above "
                f"{EXACT_CURL:g} rad): the load is beyond what a beam of {n} modes can "
                "describe")
    if reason is StopReason.TIP_PAST_LENGTH:
        return (f"tip deflection passed the beam length {model.system.beam.length:g} m at "
                f"t = {t_end:.6g} s: " + _stiffness_reason(model, float(state[n + 1])))
    if reason is StopReason.SINGULAR_MASS:
        return _singular_message(model, t_end, state)
    return reason.value + f" at t = {t_end:.6g} s"


def _singular_message(model: Model, t_end: float, state) -> str:
    """Why the consistent model's mass matrix turned singular at ``t_end`` (s) in ``state``.

    Its Schur complement is the effective hub inertia at rest (computed without cancellation,
    :func:`flexctl.model.matrices.condensed_hub_inertia`) plus ``q^T D q``: a real
    singularity of the model, reached when the second-order inertia cancels the first.
    """
    system, n = model.system, model.n_modes
    j_eff = float(model.effective_hub_inertia(state))
    j_rest = float(model.effective_hub_inertia(np.zeros(model.n_states)))
    tip = float(model.matrices.tip @ np.asarray(state)[1:n + 1])
    point_mass, beam_mass = system.total_point_mass, system.beam.mass
    cause = (f"the point masses ({point_mass:.4g} kg, {point_mass / beam_mass:.3g} times the "
             "beam mass) make it large against the hub's own inertia"
             if point_mass > beam_mass else
             f"a light hub (J_h = {system.hub.inertia:.4g} kg m^2) loses all of it")
    return (f"mass matrix singular at t = {t_end:.6g} s: the effective hub inertia "
            f"J_0 + q^T D q - m_tf^T M_ff^-1 m_tf fell to {j_eff:.3g} kg m^2 from "
            f"{j_rest:.4g} kg m^2 at rest (J_0 = {model.matrices.J0:.4g} kg m^2) as the "
            f"second-order inertia q^T D q reached {j_eff - j_rest:.4g} kg m^2 at a tip "
            f"deflection of {100 * abs(tip) / system.beam.length:.3g} % of the length; in the "
            f"consistent model the deflection lowers the hub inertia, and {cause}; the exact "
            "variant's mass matrix stays positive definite (MODEL.md section 7)")


def _audit_energy(model: Model, result_arrays, reason: StopReason, message: str,
                  stacklevel: int):
    """``(EnergyBalance or None, message)`` of a run, the message naming a broken balance.

    ``result_arrays`` is ``(t, states, torque)``. A run that reached its end with a broken
    balance warns (:class:`ModelValidityWarning`); a stopped one gets the balance as its
    physical reason, and zero_order or first_order the loss of beam stiffness when the hub
    rate has passed it. A singular stop has its own reason (:func:`_singular_message`).
    """
    if reason is StopReason.SINGULAR_MASS:
        # the hub rate outruns the output samples near the singularity: a balance would
        # measure their quadrature, not the model (which conserves energy)
        return None, message
    balance = energy_balance(model, *result_arrays)
    if balance is None:
        return balance, message
    message = message.rstrip(".")
    state = result_arrays[1][:, -1]
    if reason is not StopReason.REACHED_END and reason is not StopReason.TIP_PAST_LENGTH \
            and model.variant != "consistent" and balance.violated:
        spin = float(state[model.n_modes + 1])
        with np.errstate(all="ignore"):
            softened = np.linalg.eigvalsh(model.stiffness_matrix(spin))[0] < 0.0 \
                if np.isfinite(spin ** 2) else True
        if softened:
            message = f"{message}: {_stiffness_reason(model, spin)}"
    if not balance.violated:
        return balance, message
    if reason is StopReason.REACHED_END:
        warnings.warn(f"energy balance violated: {balance.message}", ModelValidityWarning,
                      stacklevel=stacklevel)
        return balance, f"{message}; energy balance violated: {balance.message}"
    return balance, f"{message}; {balance.message}"


def _stiffness_guard(model: Model, t_final: float, method: str, symbolic: bool,
                     prescribed: bool, loop_frequency: float = 0.0):
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

    ``loop_frequency`` (rad/s) is the fastest pole of the closed loop (:func:`jacobian_frequency`
    at the start): a controller's gains can make it far faster than any mode of the plant.
    When they do, the fast poles are damped ones that an implicit method steps over, so a run
    with Python inputs moves to LSODA (implicit BDF where the problem is stiff) rather than
    crawl for minutes.
    """
    limit = EXPLICIT_STABILITY_LIMITS.get(method)
    if limit is None:
        return method, ""
    hub = "clamped" if prescribed else "free"
    omega_plant = float(model.natural_frequencies(0.0, hub=hub)[-1])
    omega_max = max(omega_plant, float(loop_frequency))
    steps = omega_max * float(t_final) / limit
    if steps <= EXPLICIT_STEP_LIMIT:
        return method, ""
    by_controller = omega_max > LOOP_FACTOR * omega_plant
    source = (f"the fastest pole of the closed loop ({omega_max:.4g} rad/s, set by the "
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


@runtime_checkable
class Controller(Protocol):
    """Feedback law with optional internal states ``z`` (e.g. an estimator).

    Attributes
    ----------
    n_states : int
        Number of internal states (0 for a static law).
    """

    n_states: int

    def initial_state(self, x0: np.ndarray) -> np.ndarray:
        """Internal state at ``t = 0`` given the plant's initial state, shape (n_states,)."""

    def torque(self, t: float, x: np.ndarray, z: np.ndarray) -> float:
        """Hub torque (N m) at time ``t`` for plant state ``x`` and internal state ``z``."""

    def derivative(self, t: float, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """``dz/dt``, shape (n_states,)."""


@dataclass(frozen=True, eq=False)
class StaticLaw:
    """A static feedback law ``torque = law(t, x)`` as a :class:`Controller` (no states).

    :func:`simulate` wraps a callable ``controller`` in this; :class:`controllers.OpenLoop`
    is the open-loop case ``torque = f(t)``.

    Parameters
    ----------
    law : callable
        ``law(t, x)``: hub torque, N m, at time ``t`` (s) for plant state ``x`` (shape (n,)).
        Its ``breakpoints`` attribute (times, s, where it is not smooth), if any, is kept so
        that :func:`simulate` restarts the integrator there.
    """

    law: object
    n_states = 0

    def __post_init__(self):
        if not callable(self.law):
            raise InputTypeError(f"{type(self).__name__}.law must be callable; got "
                                 f"{type(self.law).__name__}")

    @property
    def breakpoints(self) -> tuple:
        """The wrapped law's times of non-smoothness, s."""
        return tuple(getattr(self.law, "breakpoints", ()) or ())

    def initial_state(self, x0) -> np.ndarray:
        """No internal state: shape (0,)."""
        return np.zeros(0)

    def torque(self, t, x, z=None) -> float:
        """Hub torque, N m."""
        return self.law(t, x)

    def derivative(self, t, x, z=None) -> np.ndarray:
        """No internal state: shape (0,)."""
        return np.zeros(0)


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Outcome of :func:`simulate`.

    Attributes
    ----------
    model : Model
    t : ndarray, shape (P,)
        Output times, s.
    states : ndarray, shape (n, P)
        Plant states in the order of :attr:`Model.state_names`.
    torque : ndarray, shape (P,)
        Hub torque, N m (the torque the prescribed motion needs, for ``hub_motion`` runs).
    tip_deflection, root_moment : ndarray, shape (P,)
        m and N m.
    status : {"ok", "diverged", "singular"}
    message : str
        Why the run stopped, with the time and the physical reason.
    wall_time : float
        Integration wall time, s.
    n_evaluations : int
        Number of right-hand-side evaluations.
    controller_states : ndarray, shape (n_z, P)
    integration_error : float or None
        Estimated largest integration error of the tip deflection, m: the difference from a
        check run at 10 times the tolerance (conservative). ``None`` where no check ran (SciPy
        methods, stopped runs, ``check_accuracy=False``).
    validity : ModelValidity or None
        Deflection reached and estimated geometric model error
        (:func:`flexctl.sim.validity.assess`); set by scene runs, ``None`` from
        :func:`simulate` itself.
    stop_reason : StopReason
        Why the run ended (``status`` is ``stop_reason.status``).
    energy_balance : EnergyBalance or None
        Energy against the work done, from the outputs (:func:`energy_balance`); ``None`` for
        the exact variant and a singular stop (whose hub rate outruns the samples). When it is violated the message says so, and a run that reached
        ``t_final`` warns (:class:`ModelValidityWarning`).
    controller_report : dict or None
        For a sampled controller (:mod:`flexctl.sim.digital`): the session's report (e.g. solve
        times) with ``samples``, ``sample_time`` (s) and ``controller_time`` (s, wall time in
        the controller); ``None`` otherwise.
    """

    model: Model
    t: np.ndarray
    states: np.ndarray
    torque: np.ndarray
    tip_deflection: np.ndarray
    root_moment: np.ndarray
    status: str
    message: str
    wall_time: float
    n_evaluations: int
    method: str
    rtol: float
    controller_states: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    integration_error: float | None = None
    validity: object = None
    controller_report: dict | None = None
    stop_reason: StopReason | None = None
    energy_balance: EnergyBalance | None = None

    @property
    def deflection_ratio(self) -> float:
        """Largest ``|tip_deflection|`` divided by the beam length."""
        return self.peak_tip_deflection / self.model.system.beam.length

    @property
    def ok(self) -> bool:
        """True when the run reached ``t_final``."""
        return self.status == "ok"

    @property
    def theta(self) -> np.ndarray:
        """Hub angle, rad, shape (P,)."""
        return self.states[0]

    @property
    def theta_dot(self) -> np.ndarray:
        """Hub rate, rad/s, shape (P,)."""
        return self.states[self.model.n_modes + 1]

    @property
    def q(self) -> np.ndarray:
        """Modal coordinates, m, shape (N, P)."""
        return self.states[1:self.model.n_modes + 1]

    @property
    def outputs(self) -> dict:
        """Every model output by name (:attr:`Model.output_names`), each shape (P,)."""
        y = self.model.outputs(self.states)
        return dict(zip(self.model.output_names, y))

    @property
    def peak_tip_deflection(self) -> float:
        """Largest ``|tip_deflection|``, m."""
        return float(np.max(np.abs(self.tip_deflection))) if self.t.size else 0.0

    def __repr__(self):
        return (f"SimulationResult(status={self.status!r}, t_end={self.t[-1]:.6g} s, "
                f"points={self.t.size}, peak_tip_deflection={self.peak_tip_deflection:.6g} m, "
                f"wall_time={self.wall_time:.3g} s)")


def _step_bound(max_step: float, *sources) -> float:
    """The shortest of ``max_step`` and the positive ``max_step`` the inputs declare, s."""
    bounds = [getattr(src, "max_step", None) for src in sources]
    return min([max_step] + [float(b) for b in bounds
                             if isinstance(b, Real) and not isinstance(b, bool) and b > 0])


def _breakpoints(*sources):
    points = set()
    for src in sources:
        points.update(float(b) for b in getattr(src, "breakpoints", ()) or ())
    return sorted(points)


def _default_atol(model: Model, rtol: float, prescribed: bool) -> np.ndarray:
    """Absolute tolerances scaled to each state's physical size."""
    n, l = model.n_modes, model.system.beam.length
    w1 = model.first_clamped_frequency
    q_scale = 1e-3 * l
    angle = [1e-3] if not prescribed else []
    rate = [1e-3 * max(w1, 1.0)] if not prescribed else []
    return rtol * np.array(angle + [q_scale] * n + rate + [q_scale * max(w1, 1.0)] * n)


def _stiffness_reason(model: Model, spin: float) -> str:
    w1 = model.first_clamped_frequency
    try:
        lowest = np.linalg.eigvalsh(model.stiffness_matrix(spin))[0]
    except (OverflowError, ValueError, np.linalg.LinAlgError):
        # a runaway (e.g. a torque of 1e12 N m) spun the hub so fast its square overflows
        return (f"the hub rate reached {abs(spin):.4g} rad/s, whose square overflows the beam "
                f"stiffness (first clamped frequency {w1:.4g} rad/s)")
    if lowest < 0.0:
        if model.variant == "zero_order":
            term = "M_ff"
            extra = " (the zero_order model drops dynamic stiffening; use first_order)"
        else:
            term, extra = "(M_ff - K_g)", ""
        return (f"at hub rate {abs(spin):.4g} rad/s, above the first clamped frequency "
                f"{w1:.4g} rad/s, the beam stiffness K_ff - theta_dot^2 {term} has lost positive "
                f"definiteness and centrifugal softening wins over bending stiffness{extra}")
    return ("the deflection left the small-deflection range of the model "
            f"(hub rate {abs(spin):.4g} rad/s, first clamped frequency {w1:.4g} rad/s)")


def _bad_sample_reason(model: Model, y, prescribed: bool, j_floor: float,
                       singular_possible: bool) -> StopReason:
    """Which stopping condition the first bad output sample ``y`` of a run met."""
    if not np.all(np.isfinite(y)):
        return StopReason.NON_FINITE_STATE
    if singular_possible and not prescribed \
            and float(model.effective_hub_inertia(y[:model.n_states])) <= j_floor:
        return StopReason.SINGULAR_MASS
    return _geometric_stop(model)


def _simulate_sampled(model, t_final, controller, x_init, torque, rtol, atol, step, reach,
                      check_accuracy, method) -> SimulationResult:
    """:func:`simulate` under a sampled controller (:mod:`flexctl.sim.digital`)."""
    n, nx = model.n_modes, model.n_states
    tip = model.matrices.tip
    if atol is None:
        scale = _default_atol(model, rtol, False) / rtol
    else:
        atol_vec = as_vector("atol", atol, "a positive number or one per state")
        try:
            atol_vec = np.broadcast_to(atol_vec, (nx,)).astype(float)
        except ValueError:
            raise InputValueError(f"atol must be one number or {nx}; got shape "
                                  f"{atol_vec.shape}") from None
        if not np.all(np.isfinite(atol_vec)) or np.any(atol_vec <= 0):
            raise InputValueError(f"atol must be positive and finite; got {atol!r}")
        scale = atol_vec / rtol

    def bad_sample(y_seg):
        bad = ~np.all(np.isfinite(y_seg), axis=0) | (np.abs(tip @ y_seg[1:n + 1]) >= reach)
        return int(np.argmax(bad)) if bad.any() else None

    omega_max = float(model.natural_frequencies(0.0, hub="free")[-1])
    spin = float(x_init[n + 1])
    if spin:
        with np.errstate(all="ignore"):
            omega_max = max(omega_max, float(np.max(np.abs(model.natural_frequencies(
                spin, hub="clamped")))))
    start = time.perf_counter()
    run = run_sampled(model, t_final, controller, x_init, torque=torque, output_step=step,
                      scale=scale, rtol=rtol, bad_sample=bad_sample,
                      check_accuracy=check_accuracy,
                      integrator="rk4" if method == "rk4" else "cvodes",
                      h_max=RK4_OMEGA_H / omega_max)
    wall = time.perf_counter() - start
    accuracy_note = ""
    if method == "rk4" and run.integration_error is not None:
        peak = float(np.max(np.abs(tip @ run.states[1:n + 1])))
        if run.integration_error > rtol * max(peak, 1e-12):
            accuracy_note = (f"rk4: the estimated tip error {run.integration_error:.3g} m is "
                             f"above rtol {rtol:g} of the peak {peak:.3g} m; use method "
                             "'cvodes' for this accuracy")
            warnings.warn(accuracy_note, AccuracyWarning, stacklevel=3)
    message = run.message
    if run.stop is None:
        reason = StopReason.REACHED_END
    elif run.stop == "integrator":
        reason = StopReason.INTEGRATOR_FAILED
    else:
        reason = _bad_sample_reason(model, run.stop_state, False, 0.0, False)
        message = _stop_message(model, reason, float(run.t[-1]), run.states[:, -1])
    status = reason.status
    states = run.states
    balance, message = _audit_energy(model, (run.t, states, run.torque), reason, message, 4)
    if accuracy_note:
        message = f"{message} ({accuracy_note})"
    report = dict(run.report, controller_time=run.controller_time)
    return SimulationResult(model=model, t=run.t, states=states, torque=run.torque,
                            tip_deflection=np.asarray(model.tip_deflection(states), dtype=float),
                            root_moment=model.matrices.root @ states[1:n + 1], status=status,
                            message=message, wall_time=wall, n_evaluations=run.n_evaluations,
                            method="rk4" if method == "rk4" else "cvodes", rtol=float(rtol),
                            controller_states=np.zeros((0, run.t.size)),
                            integration_error=run.integration_error, controller_report=report,
                            stop_reason=reason, energy_balance=balance)


def simulate(model: Model, t_final: float, torque=None, hub_motion=None, controller=None,
             x0=None, *, rtol: float | None = None, atol=None, method: str = "auto",
             output_step: float | None = None, max_step: float = np.inf,
             check_accuracy: bool = True, progress=None) -> SimulationResult:
    """Simulate the nonlinear model.

    Parameters
    ----------
    model : Model
    t_final : float
        End time, s (> 0).
    torque : callable, (times, values) or SampledTorque, optional
        Hub torque, N m. Default 0. A function ``torque(t)`` or ``torque(t, x)``: one that
        CasADi can trace runs compiled, any other on SciPy (:mod:`flexctl.sim.tracing` gives
        the rule). Samples ``(times, values)`` (arrays of shape (K,), as python-control's
        ``T`` and ``U``), interpolated linearly, or a
        :class:`~flexctl.sim.inputs.SampledTorque` for a hold or a spline; they must cover
        ``[0, t_final]``.
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
        Absolute tolerance; default ``rtol`` times each state's physical scale.
    method : str, optional
        ``"auto"`` (default): ``"cvodes"`` when every input has a CasADi form (the built-in
        manoeuvres, torque samples, traced torque functions), else ``"DOP853"``.
        ``"cvodes"``: compiled SUNDIALS integration (:mod:`flexctl.sim.compiled`); or a
        ``scipy.integrate.solve_ivp`` method (``"DOP853"``, ``"RK45"``, ``"RK23"``,
        ``"Radau"``, ``"BDF"``, ``"LSODA"``). An explicit method
        (DOP853, RK45, RK23) on a model too stiff for it is replaced by ``"cvodes"`` when the
        inputs allow, with a :class:`StiffnessWarning` and a note in the result's ``message``
        (``method`` of the result is the one used); see :func:`_stiffness_guard`.
        ``"rk4"``: compiled fixed-step RK4 for loose tolerances, its step set by the fastest
        mode and halved until a step-doubling error estimate meets ``rtol``
        (:mod:`flexctl.sim.fixed_step`); needs inputs with a CasADi form.
    output_step : float, optional
        Spacing of the output times, s. Default: ``t_final / 2000``.
    max_step : float, optional
        Largest integration step, s, on every path (for ``"rk4"``, of the coarser run of its
        step-doubling pair). An input's own ``max_step`` (a sampled torque's sample
        interval) bounds it too.
    check_accuracy : bool, optional
        For the compiled (``"cvodes"``) path: repeat the run at 10 times the tolerance to
        estimate the integration error (``result.integration_error``), and redo it with
        A-stable BDF2 if the two disagree grossly (:func:`flexctl.sim.compiled.verify_accuracy`).
        Default True.
    progress : bool or callable, optional
        Report the progress of a long run: ``True`` prints a line with the simulated time
        reached and an estimate of the time to go to stderr every 5 s once the run has taken
        5 s; a callable is called with a :class:`~flexctl.sim.progress.Progress` after every
        :data:`~flexctl.sim.progress.PROGRESS_CHUNKS`-th of the run (which is then integrated
        in that many pieces). Default: no reports.

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
    if hub_motion is not None:
        for attr in ("angle", "rate", "acceleration"):
            if not callable(getattr(hub_motion, attr, None)):
                raise InputTypeError(f"hub_motion must have a callable {attr}(t); got "
                                     f"{type(hub_motion).__name__}")
    if output_step is not None:
        output_step = check_time("output_step", output_step)
    max_step = check_time("max_step", max_step, allow_inf=True)
    # samples become an interpolant; a Python function is traced into CasADi when the rest
    # of the run is compiled (flexctl.sim.tracing)
    compiled_feedback = (controller is None or is_sampled(controller)
                         or is_symbolic(controller=controller))
    torque, untraced = torque_input(
        torque, t_final=t_final, n_states=model.n_states,
        trace=(method in ("auto", "cvodes", "rk4") and hub_motion is None
               and compiled_feedback),
        state_scale=_default_atol(model, 1.0, False))
    max_step = _step_bound(max_step, torque)
    cvodes_step = max_step if np.isfinite(max_step) else None
    symbolic = is_symbolic(torque, hub_motion, None if is_sampled(controller) else controller)
    if is_sampled(controller) and method not in ("auto", "cvodes", "rk4"):
        raise InputValueError(f"method {method!r}: a sampled controller (sample_time "
                              f"{controller.sample_time!r} s) runs on the compiled path; use "
                              "method 'auto' or 'cvodes'")
    if method in ("cvodes", "rk4") and not symbolic:
        raise InputValueError(f"method {method!r} needs inputs with a CasADi form (the built-in "
                              "manoeuvres, torque samples, controllers with casadi_torque); "
                              "got a Python callable"
                              + (f" (the torque function could not be traced: {untraced})"
                                 if untraced else ""))
    if method == "auto":
        method = "cvodes" if symbolic else "DOP853"
    step = output_step if output_step is not None else t_final / DEFAULT_OUTPUT_POINTS
    grid = output_grid(t_final, step)
    hub = "clamped" if hub_motion is not None else "free"
    omega_slow = float(model.natural_frequencies(0.0, hub=hub)[0])
    if t_final * omega_slow / (2.0 * np.pi) > MAX_PERIODS:
        raise InputValueError(
            f"t_final {t_final:g} s spans {t_final * omega_slow / (2.0 * np.pi):.3g} periods of "
            f"the slowest mode ({omega_slow:.4g} rad/s), more than the limit {MAX_PERIODS:g} "
            "(each takes an integrator several steps); shorten t_final")

    n, nx = model.n_modes, model.n_states
    x_init = (np.zeros(nx) if x0 is None else
              as_vector("x0", x0, f"{nx} numbers (states {', '.join(model.state_names)})")
              .reshape(-1))
    if x_init.shape != (nx,) or not np.all(np.isfinite(x_init)):
        raise InputValueError(f"x0 must be {nx} finite numbers (states "
                              f"{', '.join(model.state_names)}); got {x0!r}")

    spin0 = 0.0 if hub_motion is not None else float(x_init[n + 1])
    if spin0:
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
    torque_fn = time_function(torque, "torque") if torque is not None else None
    if controller is not None and not is_sampled(controller) \
            and not isinstance(controller, Controller):
        if not callable(controller):
            raise InputTypeError("controller must be callable as controller(t, x) or follow "
                                 "the flexctl Controller protocol; got "
                                 f"{type(controller).__name__}")
        law = time_function(controller, "controller")    # its errors named, with the time
        try:
            inspect.signature(controller).bind(0.0, x_init)
        except TypeError:
            raise InputTypeError(
                "controller must be callable as controller(t, x); got "
                f"{getattr(controller, '__name__', type(controller).__name__)}, which cannot "
                "take the state (a torque of time alone is passed as torque=)") from None
        except ValueError:          # no signature to read (a builtin): its calls will tell
            pass
        law.breakpoints = tuple(getattr(controller, "breakpoints", ()) or ())
        controller = StaticLaw(law)
    nz = controller.n_states if controller is not None and not is_sampled(controller) else 0
    prescribed = hub_motion is not None
    mat = model.matrices
    length = model.system.beam.length
    tip = mat.tip
    # the small-deflection variants leave their range when the modal tip passes the length;
    # the exact beam cannot, and stops only when its mean slope passes EXACT_CURL rad
    reach = length * (EXACT_CURL if model.variant == "exact" else 1.0)
    if abs(tip @ x_init[1:n + 1]) >= reach:
        raise InputValueError(f"x0 puts the modal tip at {tip @ x_init[1:n + 1]:.4g} m, beyond "
                              f"the {reach:g} m the {model.variant} model covers (beam length "
                              f"{length:g} m); got x0 = {x0!r}")

    if is_sampled(controller):
        return _simulate_sampled(model, t_final, controller, x_init, torque, rtol, atol, step,
                                 reach, check_accuracy, method)

    # Inputs are evaluated inside the current smooth segment: at its closed end the integrator
    # must see the value from the left, not the next piece's.
    segment_end = [np.inf]

    def inside(t):
        return min(t, segment_end[0])

    if prescribed:
        beam_slice = np.r_[1:n + 1, n + 2:nx]
        y_init = x_init[beam_slice]

        def rhs(t, y):
            q, qd = y[:n], y[n:]
            t = inside(t)
            qdd = model.beam_accelerations(
                q, qd, input_value("hub_motion.rate", hub_motion.rate(t), t, "rad/s"),
                input_value("hub_motion.acceleration", hub_motion.acceleration(t), t,
                            "rad/s^2"))
            return np.concatenate((qd, qdd))

        def plant_state(t, y):
            t = np.asarray(t)
            return np.concatenate((np.atleast_2d(hub_motion.angle(t)), y[:n][None] if y.ndim == 1
                                   else y[:n], np.atleast_2d(hub_motion.rate(t)),
                                   y[n:][None] if y.ndim == 1 else y[n:]), axis=0)
    else:
        z_init = (np.asarray(controller.initial_state(x_init), dtype=float).reshape(-1)
                  if controller is not None else np.zeros(0))
        if z_init.shape != (nz,):
            raise InputValueError(f"controller.initial_state must return {nz} values; got "
                                  f"shape {z_init.shape}")
        y_init = np.concatenate((x_init, z_init))

        def applied_torque(t, x, z):
            u = torque_fn(t, x) if torque_fn is not None else 0.0
            if controller is not None:
                u += input_value("controller", controller.torque(t, x, z), t)
            return u

        def rhs(t, y):
            x, z = y[:nx], y[nx:]
            u = applied_torque(inside(t), x, z)
            dx = model.dynamics(t, x, u)
            if nz:
                dz = np.asarray(controller.derivative(t, x, z), dtype=float).reshape(-1)
                if dz.shape != (nz,) or not np.all(np.isfinite(dz)):
                    raise InputValueError(f"controller.derivative must return {nz} finite "
                                          f"numbers; got {dz!r} at t = {t:.6g} s")
                return np.concatenate((dx, dz))
            return dx

        def plant_state(t, y):
            return y[:nx]

    def tip_event(t, y):
        q = y[:n] if prescribed else y[1:n + 1]
        return reach - abs(tip @ q)
    tip_event.terminal = True

    events = [tip_event]
    # relative to the effective hub inertia at rest (computed without cancellation), not to
    # J_0, which heavy point masses dominate: with 3e4 kg at the tip a J_0-based floor stopped
    # runs at 1e-4 kg m^2 of a true 1.16
    j_floor = (SINGULAR_FRACTION * float(model.effective_hub_inertia(np.zeros(nx)))
               if model.variant == "consistent" else 0.0)
    if model.variant == "consistent" and not prescribed:

        def singular_event(t, y):
            return float(model.effective_hub_inertia(y[:nx])) - j_floor
        singular_event.terminal = True
        events.append(singular_event)

    if atol is None:
        atol_vec = _default_atol(model, rtol, prescribed)
        atol_vec = np.concatenate((atol_vec, np.full(nz, rtol * 1e-3)))
    else:
        atol_vec = as_vector("atol", atol, "a positive number or one per state")
        try:
            atol_vec = np.broadcast_to(atol_vec, (y_init.size,)).copy()
        except ValueError:
            raise InputValueError(f"atol must be one number or {y_init.size}; got shape "
                                  f"{atol_vec.shape}") from None
        if not np.all(np.isfinite(atol_vec)) or np.any(atol_vec <= 0):
            raise InputValueError(f"atol must be positive and finite; got {atol!r}")

    # the closed loop's fastest pole joins the stiffness guard
    omega_plant = float(model.natural_frequencies(0.0, hub=hub)[-1])
    loop_frequency = 0.0
    if controller is not None:
        try:
            loop_frequency = jacobian_frequency(rhs, 0.0, y_init, atol_vec / rtol)
        except SingularMassMatrixError:     # reported as such by the run itself
            pass
        if loop_frequency > LOOP_LIMIT * omega_plant:
            raise InputValueError(
                f"controller gains put the fastest closed-loop pole at {loop_frequency:.4g} "
                f"rad/s, more than {LOOP_LIMIT:g} times the fastest mode of the "
                f"{model.n_modes}-mode model ({omega_plant:.4g} rad/s): the model describes "
                "nothing that fast and the run would crawl; lower the gains (e.g. the "
                "bandwidth)")
    method, stiffness_note = _stiffness_guard(model, t_final, method, symbolic, prescribed,
                                              loop_frequency)
    if stiffness_note:
        warnings.warn(stiffness_note, StiffnessWarning, stacklevel=2)
    fallback = "DOP853" if method == "cvodes" else method
    # every input once at the start: a wrong type or a non-finite value is named here, before
    # any integrator sees it
    if prescribed:
        rhs(0.0, y_init)
    else:
        applied_torque(0.0, x_init, y_init[nx:])
    cvodes_steps = int(min(1e6, max(CVODES_MIN_STEPS, CVODES_STEPS_PER_RADIAN
                                    * max(omega_plant, loop_frequency) * step)))

    fallback_rhs = None             # SciPy's right-hand side where a compiled segment fails
    if method == "cvodes" and model.variant != "consistent":
        # where a compiled segment fails (a run blowing up), SciPy locates the stop on the
        # compiled right-hand side; consistent keeps the Python one, which names a singular
        # mass matrix
        compiled_rhs = []           # built on first use: most runs never need it

        def compiled_fallback(t, y):
            if not compiled_rhs:
                compiled_rhs.append(numeric_rhs(model, torque, hub_motion, controller))
            dy = compiled_rhs[0](t, y, segment_end[0])
            if not np.all(np.isfinite(dy)):
                raise FloatingPointError("the state derivative is not finite")
            return dy
        fallback_rhs = compiled_fallback

    cuts = [0.0] + [b for b in _breakpoints(torque, hub_motion, controller)
                    if 0.0 < b < t_final] + [float(t_final)]

    def first_bad_sample(y_seg):
        """Index of the first output sample past a stopping condition, or None."""
        q = y_seg[:n] if prescribed else y_seg[1:n + 1]
        bad = ~np.all(np.isfinite(y_seg), axis=0) | (np.abs(tip @ q) >= reach)
        if len(events) > 1:
            bad |= np.asarray(model.effective_hub_inertia(y_seg[:nx])) <= j_floor
        return int(np.argmax(bad)) if bad.any() else None

    reason, message = StopReason.REACHED_END, f"reached t_final = {float(t_final):g} s"
    found = False           # True once an event or a bad sample stopped the run (message due)
    ts, ys = [np.array([0.0])], [y_init[:, None]]
    compiled_segments = []
    n_eval = 0
    y = y_init
    start = time.perf_counter()
    integration_error, accuracy_note = None, ""
    drive_cuts = cuts if report is None else progress_cuts(cuts, float(t_final))
    if method == "rk4":
        drive_cuts = []         # the whole run is one compiled call
        tip_map = np.zeros(y_init.size)
        tip_map[(0 if prescribed else 1):(0 if prescribed else 1) + n] = tip
        omega_max = max(omega_plant, loop_frequency, w_spin if spin0 else 0.0)
        if prescribed:
            rates = np.asarray(hub_motion.rate(grid), dtype=float)
            spin_max = float(np.max(np.abs(rates))) if rates.size else 0.0
            if np.isfinite(spin_max) and spin_max > 0.0:
                omega_max = max(omega_max, float(model.natural_frequencies(
                    spin_max, hub="clamped")[-1]))
        try:
            fixed = integrate_fixed_step(model, np.array(cuts), grid, y_init, tip_map,
                                         min(RK4_OMEGA_H / omega_max, 0.5 * max_step), rtol,
                                         torque=torque, hub_motion=hub_motion,
                                         controller=controller)
        except ValueError as exc:
            raise InputValueError(f"method 'rk4': {exc}; use method 'cvodes'") from None
        n_eval = fixed.evaluations
        t_fixed, y_fixed = grid, fixed.states
        bad = first_bad_sample(y_fixed)
        if bad is not None:
            t_fixed, y_fixed = t_fixed[:bad + 1], y_fixed[:, :bad + 1]
            reason, found = _bad_sample_reason(model, y_fixed[:, -1], prescribed, j_floor,
                                               len(events) > 1), True
        else:
            integration_error = fixed.error
            peak = float(np.max(np.abs(tip_map @ y_fixed))) if y_fixed.size else 0.0
            if integration_error is not None and integration_error > rtol * max(peak, 1e-12):
                accuracy_note = (f"rk4: the estimated tip error {integration_error:.3g} m is "
                                 f"above rtol {rtol:g} of the peak {peak:.3g} m after "
                                 f"{MAX_HALVINGS} step halvings (step {fixed.h:.3g} s); use "
                                 "method 'cvodes' for this accuracy")
                warnings.warn(accuracy_note, AccuracyWarning, stacklevel=2)
        ts.append(t_fixed)
        ys.append(y_fixed)
    for lo, hi in zip(drive_cuts[:-1], drive_cuts[1:]):
        t_eval = grid[(grid > lo) & (grid <= hi)]
        if t_eval.size == 0 or t_eval[-1] < hi:
            t_eval = np.append(t_eval, hi)
        segment_end[0] = np.nextafter(hi, lo)
        if method == "cvodes":
            try:
                integ = SegmentIntegrator(model, lo, t_eval, atol_vec / rtol, rtol,
                                          torque=torque, hub_motion=hub_motion,
                                          controller=controller, max_steps=cvodes_steps,
                                          max_step=cvodes_step)
                y_seg = integ(y)
                n_eval += integ.n_evaluations
                bad = first_bad_sample(y_seg)
            except RuntimeError:
                y_seg, bad = None, 0
            if bad is None:
                ts.append(t_eval)
                ys.append(y_seg)
                compiled_segments.append((lo, t_eval))
                y = y_seg[:, -1]
                if report is not None:
                    report(Progress(hi, float(t_final), time.perf_counter() - start))
                continue
            # Something stops the run in this segment: find where, exactly, with SciPy
            # from the last good sample.
            if bad > 0:
                ts.append(t_eval[:bad])
                ys.append(y_seg[:, :bad])
                lo, y = float(t_eval[bad - 1]), y_seg[:, bad - 1]
            t_eval = t_eval[bad:]
        locate = fallback_rhs or rhs
        if method == "cvodes":
            locate = _Budgeted(locate, FALLBACK_EVALUATIONS)
        try:
            with np.errstate(over="raise", invalid="raise"):
                sol = solve_ivp(locate, (lo, hi), y, method=fallback, t_eval=t_eval,
                                rtol=rtol, atol=atol_vec, events=events, max_step=max_step)
        except _BudgetSpent as spent:
            reason = StopReason.INTEGRATOR_FAILED
            try:                    # a diagnosis only: any failure of it leaves it unknown
                with np.errstate(all="ignore"):
                    w = jacobian_frequency(fallback_rhs or rhs, spent.t, spent.y,
                                           atol_vec / rtol)
            except (ArithmeticError, ValueError, SingularMassMatrixError):
                w = math.inf
            message = (f"integration failed at t = {lo:.6g} s: the compiled integrator could "
                       f"not pass it and {FALLBACK_EVALUATIONS:.3g} evaluations of {fallback} "
                       f"from there reached only t = {spent.t:.6g} s; the state had become "
                       f"stiff (fastest rate {w:.3g} 1/s against the fastest mode at rest, "
                       f"{omega_plant:.3g} rad/s)")
            break
        except SingularMassMatrixError as exc:
            reason, message = StopReason.SINGULAR_MASS, str(exc)
            found = "effective" in message      # named again from the state, with J_eff
            break
        except FloatingPointError as exc:
            reason = StopReason.STATE_OVERFLOW
            message = f"the state overflowed between t = {lo:.6g} s and {hi:.6g} s ({exc})"
            break
        n_eval += sol.nfev
        # (solve_ivp hands back lists when an event fires before the first output time)
        t_seg = np.asarray(sol.t, dtype=float)
        y_seg = np.asarray(sol.y, dtype=float).reshape(y.size, t_seg.size)
        hits = [(float(te[0]), k, ye[0]) for k, (te, ye) in
                enumerate(zip(sol.t_events, sol.y_events)) if te.size]
        stop_time = None
        if hits:
            stop_time, kind, y_stop = min(hits, key=lambda h: h[0])
            before = t_seg < stop_time
            t_seg = np.append(t_seg[before], stop_time)
            y_seg = np.column_stack((y_seg[:, before], y_stop))
            reason = _geometric_stop(model) if kind == 0 else StopReason.SINGULAR_MASS
            found = True
        if t_seg.size:
            ts.append(t_seg)
            ys.append(y_seg)
        if stop_time is not None:
            break
        if sol.status != 0:
            reason = StopReason.INTEGRATOR_FAILED
            message = f"integration failed at t = {sol.t[-1]:.6g} s: {sol.message}"
            break
        y = sol.y[:, -1]
        if report is not None:
            report(Progress(hi, float(t_final), time.perf_counter() - start))

    if check_accuracy and method == "cvodes" and reason is StopReason.REACHED_END \
            and len(compiled_segments) == len(drive_cuts) - 1:
        if report is not None:
            report(Progress(float(t_final), float(t_final), time.perf_counter() - start,
                            "checking accuracy"))
        tip_map = np.zeros(y_init.size)
        first_q = 0 if prescribed else 1
        tip_map[first_q:first_q + n] = tip
        y_checked, integration_error, accuracy_note, n_check = verify_accuracy(
            model, compiled_segments, y_init, atol_vec / rtol, rtol,
            np.concatenate(ys[1:], axis=1), tip_map, n_eval, torque=torque,
            hub_motion=hub_motion, controller=controller, max_step=cvodes_step)
        n_eval += n_check
        ys = [ys[0], y_checked]
        if accuracy_note:
            warnings.warn(accuracy_note, AccuracyWarning, stacklevel=2)
    wall = time.perf_counter() - start

    t_all = np.concatenate(ts)
    y_all = np.concatenate(ys, axis=1)
    # Only the output grid and the last time (t_final or the stop) are reported; segment
    # ends at breakpoints off the grid were integration restarts, not outputs.
    keep = np.concatenate(([True], np.diff(t_all) > 0)) & np.isin(t_all, grid)
    keep[-1] = True
    t_all, y_all = t_all[keep], y_all[:, keep]
    finite = np.all(np.isfinite(y_all), axis=0)
    if not finite.all():
        first_bad = int(np.argmin(finite))
        t_all, y_all = t_all[:first_bad], y_all[:, :first_bad]
        reason, found = StopReason.NON_FINITE_STATE, False
        message = f"the state became non-finite after t = {t_all[-1]:.6g} s"
    states = np.asarray(plant_state(t_all, y_all))
    z_all = y_all[nx:] if not prescribed else np.zeros((0, t_all.size))

    if prescribed:
        acc = hub_motion.acceleration(t_all)
        qdd = model.beam_accelerations(states[1:n + 1], states[n + 2:], states[n + 1], acc)
        torque_out = model.hub_torque(states, acc, qdd)
    else:
        torque_out = None
        if controller is None and (torque is None or symbolic) \
                and not getattr(torque, "state_dependent", False):
            # no torque, or a manoeuvre with a CasADi form: those evaluate a whole time array
            # at once (checked, since a user's own class may not)
            torque_out = (np.zeros(t_all.size) if torque is None
                          else np.asarray(torque(t_all), dtype=float).reshape(-1))
            if torque_out.shape != t_all.shape:
                torque_out = None
        if torque_out is None and symbolic:
            torque_out = torque_history(model, t_all, states, z_all, torque, controller)
        if torque_out is None:
            torque_out = np.array([applied_torque(t, states[:, k], z_all[:, k])
                                   for k, t in enumerate(t_all)])
    torque_out = np.asarray(torque_out, dtype=float).reshape(-1)
    finite = np.isfinite(torque_out)
    if not finite.all():
        # the torque a prescribed motion needs, or an input's own array form, overflowed:
        # the arrays end at the last finite sample, as for the state
        first_bad = int(np.argmin(finite))
        if first_bad == 0:
            raise InputValueError(f"the hub torque is {torque_out[0]!r} at t = 0 s; the inputs "
                                  "must keep it finite")
        t_all, states, z_all = t_all[:first_bad], states[:, :first_bad], z_all[:, :first_bad]
        torque_out = torque_out[:first_bad]
        reason, found = StopReason.NON_FINITE_TORQUE, False
        message = f"the hub torque became non-finite after t = {t_all[-1]:.6g} s"

    if found:
        message = _stop_message(model, reason, float(t_all[-1]), states[:, -1])
    balance, message = _audit_energy(model, (t_all, states, torque_out), reason, message, 3)
    if stiffness_note:
        message = f"{message} ({stiffness_note})"
    if accuracy_note:
        message = f"{message} ({accuracy_note})"

    return SimulationResult(model=model, t=t_all, states=states, torque=torque_out,
                            tip_deflection=np.asarray(model.tip_deflection(states), dtype=float),
                            root_moment=mat.root @ states[1:n + 1], status=reason.status,
                            message=message, wall_time=wall, n_evaluations=int(n_eval),
                            method=method, rtol=float(rtol), controller_states=z_all,
                            integration_error=integration_error, stop_reason=reason,
                            energy_balance=balance)
