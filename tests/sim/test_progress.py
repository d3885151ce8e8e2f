"""Progress of long runs: reports that reach the end, an estimate, and the same answer."""

import numpy as np
import pytest

import flexctl
from flexctl.model.errors import InputTypeError
from flexctl.sim.progress import PROGRESS_CHUNKS, Progress, progress_cuts, progress_printer


@pytest.fixture(scope="module")
def scene():
    return flexctl.load_scene("hub-beam-mass")


def test_reports_reach_t_final_in_order_and_the_answer_is_the_same(scene):
    model = flexctl.build_model(scene.system, n_modes=2)
    seen = []
    result = flexctl.simulate(model, 60.0, torque=scene.maneuver, progress=seen.append)
    plain = flexctl.simulate(model, 60.0, torque=scene.maneuver)
    integrating = [p for p in seen if p.phase == "integrating"]
    times = [p.t for p in integrating]
    assert len(integrating) >= PROGRESS_CHUNKS and times == sorted(times)
    assert times[-1] == pytest.approx(60.0)
    assert seen[-1].phase == "checking accuracy"
    assert all(np.isfinite(p.remaining) and p.remaining >= 0.0 for p in integrating)
    # the pieces restart the integrator; the answer changes by less than its own error bar
    difference = np.max(np.abs(result.tip_deflection - plain.tip_deflection))
    assert difference <= 10.0 * max(result.integration_error, plain.integration_error)


def test_the_scipy_path_reports_too(scene):
    model = flexctl.build_model(scene.system, n_modes=1)
    seen = []
    flexctl.simulate(model, 5.0, torque=lambda t: 0.1 * np.sin(t) + 0.0 * t ** 2,
                     method="DOP853", progress=seen.append)
    assert seen and seen[-1].t == pytest.approx(5.0)


@pytest.mark.parametrize("bad", ["yes", 1, 2.0])
def test_progress_must_be_a_flag_or_a_callable(scene, bad):
    model = flexctl.build_model(scene.system, n_modes=1)
    with pytest.raises(InputTypeError, match="progress must be"):
        flexctl.simulate(model, 1.0, progress=bad)


def test_estimate_is_linear_in_simulated_time():
    report = Progress(t=25.0, t_final=100.0, elapsed=10.0)
    assert report.fraction == 0.25 and report.remaining == pytest.approx(30.0)
    assert "25 %" in str(report) and "30 s to go" in str(report)


def test_printer_waits_then_throttles():
    lines = []
    printer = progress_printer(lines.append, interval=0.0)
    printer(Progress(t=1.0, t_final=2.0, elapsed=0.5))
    assert lines == ["simulate: t = 1 of 2 s (50 %) after 0.5 s; about 0.5 s to go"]
    quiet = progress_printer(lines.append, interval=3600.0)
    quiet(Progress(t=1.0, t_final=2.0, elapsed=10.0))
    assert len(lines) == 1


def test_cuts_keep_the_breakpoints_and_bound_the_pieces():
    cuts = progress_cuts([0.0, 2.0, 100.0], 100.0, chunks=10)
    assert 2.0 in cuts and cuts[0] == 0.0 and cuts[-1] == 100.0
    assert np.max(np.diff(cuts)) <= 10.0 + 1e-12 and np.all(np.diff(cuts) > 0)


def test_a_progress_callable_that_raises_is_named(scene):
    model = flexctl.build_model(scene.system, n_modes=1)
    with pytest.raises(ValueError, match="progress raised ZeroDivisionError") as raised:
        flexctl.simulate(model, 1.0, progress=lambda p: 1 / 0)
    assert isinstance(raised.value.__cause__, ZeroDivisionError)
