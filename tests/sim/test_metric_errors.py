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
#: Midpoint step of the finite-element runs, s (halved for the open-loop kinds).
FE_STEP = 5e-4


def _fe_system(system) -> FESystem:
    return FESystem(hub_inertia=system.hub.inertia, hub_radius=system.hub.radius,
                    length=system.beam.length,
                    linear_density=system.beam.density * system.beam.area,
                    bending_stiffness=system.beam.youngs_modulus * system.beam.second_moment,
                    masses=tuple((m.mass, m.position) for m in system.masses))


def _law_torques(result, built, times) -> np.ndarray:
    """A continuous feedback law's torque at ``times``, along the run's states (and the
    law's own), interpolated between output times: its CasADi form mapped over the times,
    so that a jump of its feedforward (the tracker's held plan) stays a jump."""
    import casadi as ca

    law = bound_to_plant(built.controller, result.model)
    t_sym = ca.SX.sym("t")
    x_sym = ca.SX.sym("x", result.states.shape[0])
    n_z = int(getattr(law, "n_states", 0))
    z_sym = ca.SX.sym("z", n_z)
    torque = law.casadi_torque(t_sym, x_sym, z_sym) if n_z else law.casadi_torque(t_sym, x_sym)
    function = ca.Function("replay", [t_sym, x_sym, z_sym], [torque]).map(times.size)

    def along(rows):
        return np.array([np.interp(times, result.t, row) for row in rows]).reshape(-1, times.size)
    return np.asarray(function(times[None, :], along(result.states),
                               along(result.controller_states))).ravel()


def _step_torques(result, built, held: bool, dt: float, points: int = 16):
    """The run's hub torque averaged over each step of the finite-element beam's midpoint
    rule, as a function of the step's midpoint time (the only time the rule asks at).

    Averaged, a jump inside a step keeps its impulse instead of moving to the step's middle
    (up to ``dt / 2`` off in a switching time, which a shaped slew's cancellation of its
    residual vibration does not forgive). The torque itself is an open-loop law's own
    function (its jumps exact), a sampled law's samples held (they fall on output times), or
    a continuous feedback law along the run's states (:func:`_law_torques`)."""
    t_final = float(result.t[-1])
    n_steps = max(1, int(np.ceil(t_final / dt - 1e-9)))
    dt = t_final / n_steps
    times = ((np.arange(n_steps)[:, None] + (np.arange(points) + 0.5) / points) * dt).ravel()
    own = getattr(built.controller, "torque_function", None)
    if callable(own):
        values = np.array([float(own(s)) for s in times])
    elif held:
        index = np.searchsorted(result.t, times + 1e-12, side="right") - 1
        values = result.torque[np.clip(index, 0, result.t.size - 1)]
    else:
        values = _law_torques(result, built, times)
    return _StepTorque(values.reshape(n_steps, points).mean(axis=1), dt)


class _StepTorque:
    """A torque constant over each midpoint step (picklable, for the worker processes)."""

    def __init__(self, averaged: np.ndarray, dt: float):
        self.averaged, self.dt = averaged, dt

    def __call__(self, s: float) -> float:
        return float(self.averaged[min(int(s / self.dt), self.averaged.size - 1)])


def _fe_tip(system, t, drive, n_elements: int) -> np.ndarray:
    return simulate_fe(_fe_system(system), float(t[-1]), torque=drive, n_elements=n_elements,
                       t_eval=t, dt=drive.dt)["tip_deflection"]


def _converged_fe_tip(system, result, drive) -> np.ndarray:
    """The finite-element beam's tip under ``drive`` (a :class:`_StepTorque`), extrapolated
    to a converged mesh (Richardson: ``(4 w_fine - w_coarse) / 3``); the two meshes run in
    two processes."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=len(ELEMENTS)) as pool:
        coarse, fine = pool.map(_fe_tip, *zip(*[(system, result.t, drive, n)
                                                for n in ELEMENTS]))
    return (4.0 * fine - coarse) / 3.0


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
    # a shaped or optimal open-loop slew cancels its vibration by its switching times: its
    # residual needs the finer step
    step = FE_STEP / 2.0 if callable(getattr(built.controller, "torque_function", None)) \
        else FE_STEP
    tip = _converged_fe_tip(scene.system, result, _step_torques(result, built, held, step))
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
    (3.23, 0.0, "s", "3.23 s"),
], ids=["bound", "value", "equal", "no-error", "not-settled", "unknown", "zero-error"])
def test_format_metric_shows_a_value_below_its_error_as_a_bound(value, error, unit, shown):
    assert format_metric(value, error, unit) == shown


def test_console_summary_shows_the_metrics_with_errors_and_the_loop_check(lqr_slew, tmp_path):
    from flexctl.app.report import format_summary
    from flexctl.app.runner import execute, write_complete

    scene, _ = lqr_slew
    result, extra, reference = execute(scene)
    summary = write_complete(scene, result, tmp_path / "run", {}, extra, reference)
    lines = format_summary(summary).splitlines()
    slew = next(line for line in lines if "slew by lqr" in line)
    assert "residual tip vibration" in slew and "±" in slew
    assert any(line.strip().startswith("metric errors: against the loop on the exact, 8 modes")
               for line in lines)
    assert any(line.strip() == "loop on the plant: LQR is stable on the exact plant with 6 "
               "modes" for line in lines)


def test_format_metric_refuses_an_unknown_unit_and_a_negative_error():
    with pytest.raises(InputValueError, match="format_metric.unit must be one of m, rad, s"):
        format_metric(1.0, 0.1, "mm")
    with pytest.raises(InputValueError, match="format_metric.error must be >= 0"):
        format_metric(1.0, -1e300, "m")
