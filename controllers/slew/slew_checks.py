"""What :func:`controllers.solve_slew` refuses before IPOPT runs, and the settings that pass.

A slew whose holds cannot reach its true optimum, or whose solve would take minutes, is refused
in well under a second with a ``ValueError`` that gives the reason and the settings that would
pass *every* check: the next interval count (``n_intervals``), the most design modes
(``model.design_modes``), for the exact variant the first_order design variant, and where
aliasing alone refuses, the effort tolerance that accepts the holds asked for
(``effort_tolerance``).

- **Aliasing** (fixed duration): holds whose least effort exceeds the converged one by more
  than ``SlewProblem.effort_tolerance`` (default
  :data:`~controllers.design.hold_grid.HOLD_EFFORT_TOLERANCE`; :class:`~.hold_grid.HoldGrid`).
- **Work** (exact variant): the exact dynamics' derivatives cost about ``n_states ** 3`` per
  evaluation; more than :data:`MAX_EXACT_WORK` per IPOPT iteration is minutes of solving.
"""

from __future__ import annotations

import dataclasses
import functools
import math

from flexctl.model.errors import InputValueError

from ..design.hold_grid import HoldGrid, largest_step, mode_tolerances
from .slew_nlp import (MAX_INTERVALS, Discretisation, discretisation, refuse_fast_modes,
                       resolution_reason, transcription_for)

__all__ = ["MAX_EXACT_WORK", "exact_work", "refuse_unsolvable"]

#: Largest work per IPOPT iteration for the exact variant's dynamics, in dynamics evaluations
#: (collocation points or RK4 stages) times the cube of the state count, which the cost of
#: their derivatives follows: 3.5e6 is about two minutes of solving on the 2-core machine of
#: ``benchmarks/bench_trajopt.py`` (slew-90 on 4 exact modes and 60 holds: 9e5, 33 s).
MAX_EXACT_WORK = 3.5e6


def exact_work(problem, disc: Discretisation, n_states: int) -> float:
    """Dynamics evaluations per IPOPT iteration times ``n_states ** 3`` (0 for CVODES).

    Parameters
    ----------
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    disc : Discretisation
        How each hold is integrated (its method and steps per hold).
    n_states : int
        Length of the design model's state.
    """
    if disc.method == "cvodes":
        return 0.0
    per_step = 4 if disc.method == "rk4" else problem.degree
    return per_step * disc.steps_per_hold * problem.n_intervals * n_states ** 3


class _Checks:
    """The checks of one design model over one slew duration, for any interval count."""

    def __init__(self, model, problem, t_rigid: float, longest: float):
        self.model, self.problem, self.bounds = model, problem, (t_rigid, longest)

    @functools.cached_property
    def holds(self) -> HoldGrid | None:
        if self.problem.duration is None:
            return None
        return HoldGrid(self.model, self.problem.duration, self.problem.angle)

    @functools.cached_property
    def modes(self):
        """Hub-free frequencies (rad/s) and tolerances of the design modes."""
        return mode_tolerances(self.model)

    def least_work(self) -> float:
        """The work of the fewest steps any interval count can take (0 but for exact)."""
        if not self.model.variant.exact:
            return 0.0
        try:
            disc = discretisation(self.problem, self.model, *self.bounds)
        except ValueError:                   # more RK4 substeps than MAX_SUBSTEPS
            return math.inf
        if disc.method == "cvodes":
            return 0.0
        per_step = 4 if disc.method == "rk4" else self.problem.degree
        steps = max(w * disc.sized_for / largest_step(disc.method, w, disc.sized_for,
                                                      self.problem.degree, tol)
                    for w, tol in zip(*self.modes))
        return per_step * steps * self.model.n_states ** 3

    def resolution_reason(self, n_intervals: int) -> str | None:
        """Why ``n_intervals`` holds need more steps than the limits allow, or None."""
        problem = dataclasses.replace(self.problem, n_intervals=n_intervals)
        return resolution_reason(problem, self.model, discretisation(
            problem, self.model, *self.bounds, check=False))

    def work_reason(self, n_intervals: int) -> str | None:
        if not self.model.variant.exact:
            return None
        problem = dataclasses.replace(self.problem, n_intervals=n_intervals)
        disc = discretisation(problem, self.model, *self.bounds, check=False)
        work = exact_work(problem, disc, self.model.n_states)
        if work <= MAX_EXACT_WORK:
            return None
        evaluations = round(work / self.model.n_states ** 3)
        return (f"the exact design model's {self.model.n_modes} modes need {evaluations} "
                f"dynamics evaluations ({disc.steps_per_hold} {disc.method} steps per "
                f"{disc.sized_for / n_intervals:.3g} s hold to integrate mode "
                f"{self.model.n_modes} at {self.modes[0][-1]:.4g} rad/s over "
                f"{disc.sized_for:.3g} s), whose derivatives take "
                f"{work / MAX_EXACT_WORK:.2g} times the work allowed per iteration "
                "(MAX_EXACT_WORK: minutes of solving)")

    def reason(self, n_intervals: int) -> str | None:
        """Why ``n_intervals`` holds are refused, or None."""
        resolution = self.resolution_reason(n_intervals)
        if resolution is not None:           # before the hold analysis, which it would upset
            return resolution
        aliasing = self.holds.reason(n_intervals, self.problem.effort_tolerance) \
            if self.holds else None
        if aliasing is None:
            return self.work_reason(n_intervals)
        n_modes = self.model.n_modes
        return (f"n_intervals = {n_intervals} is too coarse for {n_modes} design "
                f"mode{'s' if n_modes > 1 else ''}: {aliasing}")

    def passes(self, n_intervals: int) -> bool:
        if self.resolution_reason(n_intervals) is not None \
                or self.work_reason(n_intervals) is not None:
            return False
        return self.holds is None or self.holds.passes(n_intervals,
                                                       self.problem.effort_tolerance)


def _more_intervals(checks: _Checks, n_intervals: int) -> int | None:
    """The smallest count above ``n_intervals`` that passes, searched up to twice the count
    that puts every design mode below the hold Nyquist frequency (or twice the count asked)."""
    if checks.holds is None or checks.least_work() > MAX_EXACT_WORK:
        return None
    nyquist = math.ceil(checks.holds.frequencies[-1] * checks.problem.duration / math.pi)
    for count in range(n_intervals + 1, min(2 * max(nyquist, n_intervals, 10),
                                            MAX_INTERVALS) + 1):
        if checks.passes(count):
            return count
    return None


def _fewer_modes(checks: _Checks, n_intervals: int) -> int | None:
    """The most design modes below the model's that pass at ``n_intervals``."""
    from flexctl.model import build_model

    model = checks.model
    for n_modes in range(model.n_modes - 1, 0, -1):
        fewer = _Checks(build_model(model.system, n_modes=n_modes, variant=model.variant),
                        checks.problem, *checks.bounds)
        if fewer.least_work() <= MAX_EXACT_WORK and fewer.passes(n_intervals):
            return n_modes
    return None


def _accepting_tolerance(checks: _Checks, n_intervals: int) -> float | None:
    """The effort tolerance, rounded up to two digits, that accepts ``n_intervals`` holds
    when aliasing alone refuses them (None when another check does too, or the holds cannot
    reach the target at all)."""
    if checks.holds is None or checks.resolution_reason(n_intervals) is not None \
            or checks.work_reason(n_intervals) is not None:
        return None
    worst = checks.holds.effort(n_intervals).worst
    if not math.isfinite(worst):
        return None
    digits = 1 - math.floor(math.log10(worst))
    return math.ceil(worst * 10 ** digits * (1 + 1e-9)) / 10 ** digits


def refuse_unsolvable(model, problem, t_rigid: float, longest: float) -> None:
    """Raise ``ValueError`` if ``problem`` on ``model`` fails a check, with the reason and the
    settings that pass every check.

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    t_rigid, longest : float
        Rigid-body minimum time and longest free duration, s.

    Examples
    --------
    >>> import flexctl
    >>> from controllers.slew.trajopt import SlewProblem
    >>> model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=4)
    >>> problem = SlewProblem(angle=1.57, duration=2.0, torque_bound=6.0, n_intervals=40)
    >>> refuse_unsolvable(model, problem, 1.0, 10.0)
    Traceback (most recent call last):
    ...
    flexctl.model.errors.InputValueError: n_intervals = 40 is too coarse for 4 design modes: holds of 0.05 s see design \
mode 4 (134.6 rad/s) at its alias 8.92 rad/s, and stopping it costs 5.15 % more effort than \
the converged slew (limit 1 %); use n_intervals = 45 or at most 3 design modes \
(model.design_modes) or effort_tolerance = 0.052 (controller.effort_tolerance: accepts the \
holds' 5.15 % more effort than the converged slew)
    """
    # modes too fast for any grid of holds first: the hold analysis of such a slew is
    # inaccurate in floating point (or overflows), and no other setting helps
    refuse_fast_modes(model, problem.duration or longest, t_rigid)
    checks = _Checks(model, problem, t_rigid, longest)
    K = problem.n_intervals
    reason = checks.reason(K)
    if reason is None:
        return
    remedies = []
    more = _more_intervals(checks, K)
    if more is not None:
        remedies.append(f"n_intervals = {more}")
    fewer = _fewer_modes(checks, K)
    if fewer is not None:
        remedies.append(f"at most {fewer} design modes (model.design_modes)")
    tolerance = _accepting_tolerance(checks, K)
    if tolerance is not None:
        remedies.append(f"effort_tolerance = {tolerance:.2g} (controller.effort_tolerance: "
                        f"accepts the holds' {100 * checks.holds.effort(K).worst:.3g} % more "
                        "effort than the converged slew)")
    if model.variant.exact and checks.work_reason(K) is not None:
        remedies.append("model.design_variant 'first_order' (small deflection, solved in "
                        "seconds)")
    if not remedies and checks.holds is not None:
        # the search went up to MAX_INTERVALS: no interval count helps
        omega = checks.modes[0]
        remedies.append(f"a design model whose modes turn fewer radians over the slew (design "
                        f"mode {model.n_modes} at {omega[-1]:.4g} rad/s turns "
                        f"{omega[-1] * problem.duration:.3g} rad, and no n_intervals up to "
                        f"{MAX_INTERVALS} passes): check the beam and hub parameters")
    if not remedies and transcription_for(problem, model) == "collocation":
        # elements over the slew hardly change with the interval count
        remedies.append("fewer design modes (model.design_modes) or transcription "
                        "'multiple_shooting'")
    raise InputValueError(f"{reason}; use {' or '.join(remedies) or 'more n_intervals'}")
