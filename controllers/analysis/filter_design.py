"""Structural filters placed on a sampled law's command until the loop meets its requirements
over the uncertainty (:func:`design_filters`), or the requirements it cannot meet named with
their shortfall.

Examples
--------
>>> import flexctl
>>> from controllers import LQRWeights, design_lqr
>>> from controllers.analysis.requirements import Requirements
>>> from flexctl.sim.digital import ZeroOrderHold
>>> system = flexctl.load_scene("hub-beam-mass").system
>>> law = ZeroOrderHold(design_lqr(flexctl.build_model(system, n_modes=1),
...                                LQRWeights(hub_angle=0.05, torque=1.0)), 0.01)
>>> design = design_filters(flexctl.build_model(system, n_modes=2), law,
...                         Requirements(gain_stabilised_above=20.0))
>>> design.met, [type(f).__name__ for f in design.added]
(True, ['Notch'])
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from flexctl.model.checks import check_integer
from flexctl.model.errors import InputTypeError

from .requirements import Requirements, Verification, aliased_frequency, verify_requirements

__all__ = ["FilterDesign", "design_filters"]


@dataclass(frozen=True)
class FilterDesign:
    """What :func:`design_filters` found.

    Attributes
    ----------
    controller : object
        The law with the filters placed (a :class:`~controllers.Filtered`), or the law given
        when it met every requirement as it was.
    added : tuple
        The filters placed, in the order they were added.
    verification : Verification
        The verification of :attr:`controller`.
    unmet : tuple of (str, float, float)
        ``(name, worst, required)`` of each requirement still missed (empty on success).
    tried : int
        Candidate designs screened.
    initial : Verification or None
        The verification of the law as given.
    """

    controller: object
    added: tuple
    verification: Verification
    unmet: tuple
    tried: int
    initial: object = None

    @property
    def met(self) -> bool:
        """Whether every requirement is met."""
        return not self.unmet


def _shortfall(verification: Verification) -> tuple:
    """``(unstable, total shortfall, -least ratio)``, smaller is better: whether the loop is
    unstable somewhere in the uncertainty, the sum over the requirements of how far each
    worst value falls short of its required one (relative), and the least ratio of worst to
    required."""
    ratios = [check.worst / check.required for check in verification.checks
              if check.name != "closed_loop_stable" and math.isfinite(check.worst)]
    unstable = any(c.name == "closed_loop_stable" and not c.passed
                   for c in verification.checks)
    return (unstable, sum(max(0.0, 1.0 - r) for r in ratios), -min(ratios, default=0.0))


def _candidates(omega: float, req: Requirements, sample_time: float, peak_db: float = 0.0):
    """Notches where the sampled loop sees the mode at ``omega`` (its alias above the Nyquist
    frequency; deep enough to bring its peak ``peak_db`` to the required attenuation, and
    deeper, and wide enough to cover the frequency uncertainty, and wider) and a roll-off
    below it, each within the sampled loop's reach."""
    from ..feedback.structural_filters import NYQUIST_FRACTION, Notch, RollOff

    limit = NYQUIST_FRACTION * math.pi / sample_time
    seen = float(aliased_frequency(omega, sample_time))
    # the uncertainty is relative to the mode's frequency, not to its alias
    width = max(req.frequency_uncertainty * omega / seen, 0.05)
    found = []
    if seen < limit:
        least = req.flexible_attenuation_db + max(peak_db, 0.0) + 6.0
        for depth in (least, least + 10.0):
            for zeta in (width, 2.0 * width, 3.5 * width, 5.0 * width):
                found.append(Notch(frequency=seen, depth_db=depth, width=min(zeta, 1.0)))
    if 0.5 * seen < limit:
        found.append(RollOff(frequency=0.5 * seen, damping=0.7))
    return found


def _better_filter(plant, base, filters, report, req, spin_rate) -> tuple:
    """``(tried, filter, verification, law)``: for the first failing flexible mode (worst
    first) that a candidate fixes, the candidate that fixes it, keeps every requirement that
    passed and leaves the least shortfall (``_shortfall``); candidates are screened on
    the first stage of the search, the one kept verified in full. ``filter`` None when no
    candidate fixes any mode."""
    from ..feedback.structural_filters import Filtered

    failing = sorted((c for c in report.checks if c.name.startswith("flexible mode")
                      and not c.passed), key=lambda c: c.worst)
    passed = {c.name for c in report.checks if c.passed}
    tried = 0
    for check in failing:
        mode = report.modes[int(check.name.split()[-1]) - 1]
        ranked = []
        for candidate in _candidates(mode.frequency, req, base.sample_time, mode.peak_db):
            trial = Filtered(law=base, filters=[*filters, candidate])
            screen = verify_requirements(plant, trial, req, spin_rate, thorough=False)
            tried += 1
            kept = {c.name for c in screen.checks if c.passed}
            if check.name in kept and passed <= kept:
                ranked.append((_shortfall(screen), len(ranked), candidate, trial))
        for _, _, candidate, trial in sorted(ranked, key=lambda r: r[:2]):
            result = verify_requirements(plant, trial, req, spin_rate)
            kept = {c.name for c in result.checks if c.passed}
            if check.name in kept and passed <= kept:
                return tried, candidate, result, trial
    return tried, None, None, None


def design_filters(plant, controller, requirements: Requirements, *,
                   max_filters: int = 3, spin_rate: float = 0.0) -> FilterDesign:
    """Place notch or roll-off filters on a sampled law's command until the loop meets the
    requirements over the uncertainty, or say which it cannot meet and by how much.

    Greedy: while flexible modes miss their requirement, the candidates for each (worst
    first; notches where the sampled loop sees its nominal frequency, of two depths that bring
    its peak below the required attenuation and four widths, from one covering the frequency
    uncertainty to five times it, and a roll-off at half that frequency) are screened on the first
    stage of the search (``verify_requirements(..., thorough=False)``), and the first that
    makes the mode pass and keeps every requirement that passed, by the least total
    shortfall (the sum over the requirements of how far each worst value falls short of its
    required one, relative), is verified in full and kept. A mode that no candidate fixes is
    left, and named in :attr:`FilterDesign.unmet`.

    Parameters
    ----------
    plant : flexctl.Model
        The nominal plant.
    controller : ZeroOrderHold, Observed or Filtered
        A sampled law (its filters, if any, kept).
    requirements : Requirements
        What the loop must meet.
    max_filters : int, optional
        Most filters to add. Default 3.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.

    Returns
    -------
    FilterDesign
    """
    from ..feedback.structural_filters import Filtered

    max_filters = check_integer("design_filters", "max_filters", max_filters, minimum=1,
                                maximum=10)
    base = controller.law if isinstance(controller, Filtered) else controller
    kept = list(controller.filters) if isinstance(controller, Filtered) else []
    if getattr(base, "sample_time", None) is None:
        raise InputTypeError("design_filters.controller must be a sampled law (a "
                             "ZeroOrderHold, Observed or Filtered law); got "
                             f"{type(controller).__name__}")
    law = controller
    report = initial = verify_requirements(plant, law, requirements, spin_rate)
    tried, added = 1, []
    while len(added) < max_filters:
        better = _better_filter(plant, base, [*kept, *added], report, requirements, spin_rate)
        tried += better[0]
        if better[1] is None:
            break
        added.append(better[1])
        report, law = better[2], better[3]
    unmet = tuple((c.name, c.worst, c.required) for c in report.checks if not c.passed)
    return FilterDesign(law, tuple(added), report, unmet, tried, initial)
