"""Slew metrics that carry their error (flexctl.sim.metrics.metric_errors, run_slew).

The facts checked: the error of each metric comes from a reference run on a more faithful
plant and bounds the truth; a metric smaller than its error is shown as an upper bound; on
slew-90, for every controller kind, the residual vibration and peak tip of the converged
geometrically exact finite-element beam (tests/fe_reference.py, 32 and 64 elements
extrapolated at its O(h^2) rate) driven by the run's own torque lie inside the reported
bounds. The beam replays the run's torque rather than closing the loop itself: for the
open-loop kinds that is the manoeuvre exactly; for the feedback kinds it is the same torque
on a beam that would, in closed loop, have corrected part of the difference.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import flexctl
from controllers.spec import CONTROLLER_KEYS
from flexctl.model.errors import InputValueError
from flexctl.sim.drives import bound_to_plant
from flexctl.sim.metrics import ERROR_FACTOR, format_metric, metric_errors, slew_metrics

sys.path.insert(0, str(Path(__file__).parent))
from fe_reference import FESystem, simulate_fe  # noqa: E402

#: Element counts of the finite-element runs; their ratio 2 extrapolates the O(h^2) error.
ELEMENTS = (32, 64)
#: Output step of the runs whose torque the finite-element beam replays, s.
REPLAY_STEP = 1e-3
#: Midpoint step of the finite-element runs, s (the slew's modes: below 1e-5 of a period's
#: phase per step).
FE_STEP = 5e-4


def _fe_system(system) -> FESystem:
    return FESystem(hub_inertia=system.hub.inertia, hub_radius=system.hub.radius,
                    length=system.beam.length,
                    linear_density=system.beam.density * system.beam.area,
                    bending_stiffness=system.beam.youngs_modulus * system.beam.second_moment,
                    masses=tuple((m.mass, m.position) for m in system.masses))


def _replayed_torque(result, built, held: bool):
    """The run's hub torque as a function of time, to the accuracy of the bounds checked.

    An open-loop law gives its own function (its jumps exact); a sampled law its samples, held
    (they fall on the output times); a continuous feedback law is evaluated along the run's
    states (and its own states), interpolated between output times, so that a jump of its
    feedforward (the tracker's held plan) stays a jump."""
    own = getattr(built.controller, "torque_function", None)
    if callable(own):
        return lambda s: float(own(s))
    t, torque = result.t, result.torque
    if held:
        return lambda s: float(torque[min(np.searchsorted(t, s + 1e-12, side="right") - 1,
                                          t.size - 1)])
    law = bound_to_plant(built.controller, result.model)
    states, inner = result.states, result.controller_states

    def along(s):
        x = np.array([np.interp(s, t, row) for row in states])
        if getattr(law, "n_states", 0):
            return float(law.torque(s, x, np.array([np.interp(s, t, row) for row in inner])))
        return float(law.torque(s, x))
    return along


def _step_average(drive, dt: float, points: int = 16):
    """``drive`` averaged over the midpoint rule's step around each time it is asked at: the
    impulse of a jump inside a step is then the torque's, not shifted to the step's middle
    (an error of up to ``dt / 2`` in a switching time, which a shaped slew's cancellation
    of its residual vibration does not forgive)."""
    offsets = dt * ((np.arange(points) + 0.5) / points - 0.5)
    last = {}

    def averaged(s):
        if s not in last:
            last.clear()
            last[s] = float(np.mean([drive(s + o) for o in offsets]))
        return last[s]
    return averaged


def _converged_fe_tip(system, result, drive) -> np.ndarray:
    """The finite-element beam's tip under ``drive``, extrapolated to a converged mesh
    (Richardson: ``(4 w_fine - w_coarse) / 3``)."""
    t = result.t
    drive = _step_average(drive, FE_STEP)
    tips = [simulate_fe(_fe_system(system), float(t[-1]), torque=drive, n_elements=n,
                        t_eval=t, dt=FE_STEP)["tip_deflection"] for n in ELEMENTS]
    return (4.0 * tips[1] - tips[0]) / 3.0


@pytest.mark.slow
@pytest.mark.parametrize("kind", CONTROLLER_KEYS)
def test_the_converged_beam_lies_inside_the_reported_bounds(kind):
    from controllers import from_spec

    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": kind,
                                                     "simulation.output_step": REPLAY_STEP})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result, built, metrics = flexctl.run_slew(scene, from_spec)
    assert result.status == "ok" and metrics.errors is not None
    held = kind == "nmpc" or "sample_time" in built.info
    tip = _converged_fe_tip(scene.system, result, _replayed_torque(result, built, held))
    after = result.t >= built.maneuver_end
    true_residual = float(np.max(np.abs(tip[after])))
    true_peak = float(np.max(np.abs(tip)))
    assert abs(true_residual - metrics.residual_vibration) <= metrics.error(
        "residual_vibration"), (true_residual, metrics.shown("residual_vibration"))
    assert abs(true_peak - metrics.peak_tip_deflection) <= metrics.error(
        "peak_tip_deflection"), (true_peak, metrics.shown("peak_tip_deflection"))


@pytest.fixture(scope="module")
def lqr_slew():
    from controllers import from_spec

    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": "lqr"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return scene, flexctl.run_slew(scene, from_spec)


def test_errors_are_the_reference_difference_counted_twice_plus_integration(lqr_slew):
    scene, (result, built, metrics) = lqr_slew
    errors = metrics.errors
    assert errors.reference == "exact, 8 modes"
    # against itself a run differs by nothing: only its integration error is left
    same = metric_errors(result, result, scene.maneuver.angle, built.maneuver_end)
    assert same.model == 0.0
    assert same.residual_vibration == pytest.approx(result.integration_error)
    assert errors.residual_vibration >= errors.integration
    assert errors.peak_tip_deflection <= ERROR_FACTOR * errors.model + errors.integration \
        + 1e-15
    summary = metrics.as_dict()
    assert set(summary["errors"]) >= {"residual_vibration", "settling_time", "reference"}
    assert summary["shown"]["residual_vibration"].endswith("mm")


def test_metric_errors_refuses_runs_on_other_times(lqr_slew):
    scene, (result, built, _) = lqr_slew
    other = flexctl.simulate(result.model, 1.0, controller=built.controller)
    with pytest.raises(InputValueError, match="reference must share the run's output times"):
        metric_errors(result, other, scene.maneuver.angle, built.maneuver_end)
    with pytest.raises(InputValueError, match="geometry"):
        metric_errors(result, result, scene.maneuver.angle, built.maneuver_end,
                      geometry=-1.0)


def test_without_the_estimate_there_are_no_errors():
    from controllers import from_spec

    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": "pd"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result, _, metrics = flexctl.run_slew(scene, from_spec, error_estimate=False)
    plain = slew_metrics(result, scene.maneuver.angle, 2.5)
    assert metrics.errors is None and plain.errors is None
    assert "±" not in metrics.shown("residual_vibration")
    assert "errors" not in metrics.as_dict()


@pytest.mark.parametrize("value, error, unit, shown", [
    (2.19e-4, 6e-4, "m", "< 0.819 mm"),
    (2.19e-3, 1e-4, "m", "2.19 ± 0.1 mm"),
    (1.0e-3, 1.0e-3, "rad", "1 ± 1 mrad"),
    (1.5, None, "s", "1.5 s"),
    (float("inf"), 0.1, "s", "not reached"),
    (1e-3, float("inf"), "m", "1 mm (error unknown)"),
], ids=["bound", "value", "equal", "no-error", "not-settled", "unknown"])
def test_format_metric_shows_a_value_below_its_error_as_a_bound(value, error, unit, shown):
    assert format_metric(value, error, unit) == shown
