"""Model validity: the few-mode geometric error estimate tracks the full-model difference,
runs report it and warn, and ``variant = "auto"`` pays for exact geometry only when needed."""

import warnings

import numpy as np
import pytest

import flexctl
from flexctl import SineTorque, SpinUp, build_model, simulate
from flexctl.model.errors import InputValueError
from flexctl.sim.validity import (EstimateBeside, ModelValidityWarning, assess,
                                  choose_variant, geometric_error)

#: The estimate on 2 modes against the difference of the 6-mode models.
TRACKING_FACTOR = 2.0

CASES = {
    "kane-2rad_s": ("kane-spinup", 20.0, {"hub_motion": SpinUp(spin_rate=2.0, ramp_time=15.0)}),
    "kane-10rad_s": ("kane-spinup", 20.0,
                     {"hub_motion": SpinUp(spin_rate=10.0, ramp_time=15.0)}),
    "massless-hub": ("spacecraft-torque", 6.0,
                     {"torque": SineTorque(peak_torque=50.0, duration=2.0)}),
    "hub-beam-mass": ("hub-beam-mass", 6.0,
                      {"torque": SineTorque(peak_torque=2.0, duration=2.0)}),
    "fast-slew": ("hub-beam-mass", 6.0, {"torque": SineTorque(peak_torque=6.0, duration=1.2)}),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_estimate_tracks_the_full_difference(case):
    name, t_final, drive = CASES[case]
    system = flexctl.load_scene(name).system
    tips = {v: simulate(build_model(system, 6, v), t_final, **drive).tip_deflection
            for v in ("first_order", "exact")}
    full = np.max(np.abs(tips["first_order"] - tips["exact"])) / np.max(np.abs(tips["exact"]))
    estimate = geometric_error(build_model(system, 6), t_final, **drive)
    assert full / TRACKING_FACTOR <= estimate <= full * TRACKING_FACTOR, (estimate, full)


def test_estimate_starts_from_the_runs_initial_state():
    """A PD law from 90 deg off target, at rest: the estimate's runs start where the run does
    (they once started at rest, on target, and saw no motion at all), and the run's reported
    estimate tracks the difference of the 6-mode first_order and exact runs."""
    from controllers import PD

    system = flexctl.load_scene("slew-90").system
    pd = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    x0 = np.zeros(build_model(system, 6).n_states)
    x0[0] = -np.pi / 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelValidityWarning)
        runs = {v: simulate(build_model(system, 6, v), 6.0, controller=pd, x0=x0)
                for v in ("first_order", "exact")}
    exact = runs["exact"].tip_deflection
    full = np.max(np.abs(runs["first_order"].tip_deflection - exact)) / np.max(np.abs(exact))
    reported = runs["first_order"].validity.geometric_error
    assert full > 1e-2
    assert full / TRACKING_FACTOR <= reported <= full * TRACKING_FACTOR, (reported, full)
    # from rest on target the law does nothing: no geometric error
    assert geometric_error(build_model(system, 6), 6.0, controller=pd) < 1e-9
    for bad in (np.zeros(3), np.zeros((2, 7)), np.full(14, np.nan), np.full(14, np.inf)):
        with pytest.raises(ValueError, match="x0 must be the model's 14 states"):
            geometric_error(build_model(system, 6), 6.0, controller=pd, x0=bad)
    with pytest.raises(TypeError, match="x0 must be the model's 14 states"):
        geometric_error(build_model(system, 6), 6.0, controller=pd, x0="abc")


def test_exact_has_no_geometric_error_and_first_order_warns():
    system = flexctl.load_scene("hub-beam-mass").system
    drive = {"torque": SineTorque(peak_torque=6.0, duration=1.2)}
    exact = simulate(build_model(system, 2, "exact"), 3.0, **drive)
    assert assess(exact, **drive).geometric_error == 0.0
    first = simulate(build_model(system, 2), 3.0, **drive)
    with pytest.warns(ModelValidityWarning, match="outside its small-deflection range"):
        validity = assess(first, tolerance=1e-3, **drive)
    assert not validity.valid
    assert validity.deflection_ratio == pytest.approx(first.peak_tip_deflection / 1.8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert assess(first, tolerance=0.5, **drive).valid


def test_bad_tolerance_is_refused():
    system = flexctl.load_scene("hub-beam-mass").system
    result = simulate(build_model(system, 1), 0.5)
    for bad in (0.0, 1.0, -1e-3, float("nan"), "0.01", True):
        with pytest.raises(ValueError, match="tolerance"):
            assess(result, tolerance=bad)


@pytest.mark.parametrize("bad", [None, "hub-beam-mass", 3.0, object()])
def test_the_estimate_refuses_what_is_not_a_model_by_name(bad):
    for make, owner in ((lambda: geometric_error(bad, 1.0), "geometric_error"),
                        (lambda: EstimateBeside(bad), "EstimateBeside")):
        with pytest.raises(TypeError, match=rf"{owner}\.model must be a flexctl Model"):
            make()


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "0.01", True])
def test_a_bad_output_step_is_named_as_the_callers(bad):
    model = build_model(flexctl.load_scene("hub-beam-mass").system, 2)
    with pytest.raises((TypeError, ValueError), match=r"EstimateBeside\.output_step"):
        EstimateBeside(model, output_step=bad)
    # simulate starts the estimate's runs itself: its own argument is what the error names
    with pytest.raises((TypeError, ValueError), match=r"^output_step must be"):
        simulate(model, 1.0, torque=lambda t: 0.1, output_step=bad)


@pytest.mark.parametrize("variant", ["first_order", "exact"])
def test_a_bad_horizon_of_the_estimate_is_refused_by_name(variant):
    model = build_model(flexctl.load_scene("hub-beam-mass").system, 2, variant=variant)
    for bad in (0.0, -1.0, float("nan"), float("inf"), "2", True, None):
        with pytest.raises((TypeError, ValueError), match=r"geometric_error\.t_final"):
            geometric_error(model, bad, torque=lambda t: 0.1)


def test_auto_variant_picks_exact_only_for_large_deflection():
    """A gentle torque stays first_order; a fast slew (28 % deflection) needs exact."""
    system = flexctl.load_scene("hub-beam-mass").system
    gentle = choose_variant(system, SineTorque(peak_torque=0.2, duration=2.0), 1e-2,
                            t_final=6.0)
    assert gentle.variant == "first_order" and gentle.geometric_error <= 1e-2
    fast = choose_variant(system, SineTorque(peak_torque=6.0, duration=1.2), 1e-2, t_final=6.0)
    assert fast.variant == "exact" and fast.geometric_error > 1e-2
    assert "above the tolerance" in fast.explanation


def test_scene_reports_validity_and_auto_variant():
    scene = flexctl.load_scene("hub-beam-mass", overrides={
        "model.variant": "auto", "maneuver.peak_torque": 6.0, "maneuver.duration": 1.2,
        "simulation.t_final": 3.0, "model.modes": 2})
    assert scene.variant == "exact"
    result = flexctl.run_scene(scene)
    assert result.model.variant == "exact"
    assert result.validity.deflection_ratio > 0.2
    with pytest.raises(flexctl.SceneError, match="model.variant"):
        flexctl.load_scene("hub-beam-mass", overrides={"model.variant": "exactly"})
    with pytest.raises(flexctl.SceneError, match="model.design_variant"):
        flexctl.load_scene("slew-90", overrides={"model.design_variant": "auto"})


@pytest.mark.parametrize("kind", ["lqg", "pd"])
def test_closed_loop_slew_on_first_order_reports_and_warns(kind):
    """The estimate re-runs the controller itself (LQG with its sensors moved to the small
    model) and flags first_order on slew-90's 25 % deflection."""
    from controllers import from_spec

    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": kind,
                                                     "model.variant": "first_order"})
    with pytest.warns(ModelValidityWarning):
        result, _, _ = flexctl.run_slew(scene, from_spec)
    assert result.validity.deflection_ratio > 0.2
    assert result.validity.geometric_error > scene.model.tolerance


def test_estimate_runs_equal_full_runs():
    # the estimate keeps only its runs' states (run_states): the same tips as whole runs, and
    # the same states again when the compiled steps run beside the caller (start_states_run)
    from controllers import PD
    from flexctl.sim.runs import run_once, run_states, start_states_run
    from flexctl.sim.validity import ESTIMATE_RTOL

    system = flexctl.load_scene("slew-90").system
    pd = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    tips = []
    for variant in ("first_order", "exact"):
        small = build_model(system, n_modes=2, variant=variant)
        x_small = np.zeros(small.n_states)
        x_small[0] = -np.pi / 2
        full = run_once(small, 6.0, controller=pd, x0=x_small, rtol=ESTIMATE_RTOL,
                        check_accuracy=False)
        ok, states = run_states(small, 6.0, controller=pd, x0=x_small, rtol=ESTIMATE_RTOL,
                                check_accuracy=False)
        assert full.ok and ok
        assert np.array_equal(states, full.states)
        beside = start_states_run(small, 6.0, controller=pd, x0=x_small, rtol=ESTIMATE_RTOL,
                                  check_accuracy=False)
        ok_beside, states_beside = beside.result()
        assert ok_beside and np.array_equal(states_beside, full.states)
        tips.append(small.tip_deflections(states))
    expected = np.max(np.abs(tips[0] - tips[1])) / np.max(np.abs(tips[1]))
    assert expected > 1e-4                          # a slew with a geometric error to find


@pytest.mark.parametrize("variant", ["first_order", "exact"])
def test_estimate_run_that_stops_gives_no_states(variant):
    from flexctl.sim.runs import run_states, start_states_run

    model = build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2,
                        variant=variant)
    push = SineTorque(peak_torque=1e5, duration=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ok, states = run_states(model, 4.0, torque=push)
        # the steps beside pass a stop: the run is made again here, which stops as well
        ok_beside, states_beside = start_states_run(model, 4.0, torque=push,
                                                    check_accuracy=False).result()
    assert not ok and states is None
    assert not ok_beside and states_beside is None


def test_start_states_run_has_no_accuracy_check():
    from flexctl.sim.runs import start_states_run

    model = build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    with pytest.raises(InputValueError, match="check_accuracy"):
        start_states_run(model, 1.0, torque=SineTorque(peak_torque=1.0, duration=1.0))


def test_abandoned_states_run_ends_without_states():
    from flexctl.sim.runs import start_states_run

    model = build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    run = start_states_run(model, 20.0, torque=SineTorque(peak_torque=1.0, duration=1.0),
                           check_accuracy=False)
    run.abandon()
    assert run.result() == (False, None)


def test_the_run_stands_for_the_estimates_run_of_its_variant(monkeypatch):
    # a first_order run on the estimate's two modes, at ESTIMATE_RTOL, is the estimate's
    # first_order run: only the exact model is run, on the run's grid, and the estimate is
    # the one both runs give
    import flexctl.sim.validity as validity

    model = build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    push = SineTorque(peak_torque=2.0, duration=2.0)
    started = []
    real = validity.start_states_run

    def counted(small, *args, **kwargs):
        started.append((str(small.variant), kwargs.get("output_step")))
        return real(small, *args, **kwargs)

    monkeypatch.setattr(validity, "start_states_run", counted)
    result = simulate(model, 8.0, torque=push, rtol=1e-6, output_step=0.002)
    assert result.validity.geometric_error > 1e-4 and not result.validity.screened
    assert started == [("exact", 0.002)]
    started.clear()
    both = validity.geometric_error(model, 8.0, torque=push, x0=result.states[:, 0])
    assert [variant for variant, _ in started] == ["exact", "first_order"]
    assert result.validity.geometric_error == pytest.approx(both, rel=1e-3)
    # a looser run is not the estimate's: both models are run
    started.clear()
    simulate(model, 8.0, torque=push, rtol=1e-4, method="RK45", output_step=0.002)
    assert [variant for variant, _ in started] == ["exact", "first_order"]
    # nor is a run on a grid coarser than the estimate's own (t_final / 2000), which could
    # miss the largest difference: both models are run on the estimate's grid
    started.clear()
    coarse = simulate(model, 8.0, torque=push, rtol=1e-6, output_step=4.0)
    assert started == [("exact", None), ("first_order", None)]
    assert coarse.validity.geometric_error == pytest.approx(both, rel=1e-6)


def _started_runs(monkeypatch):
    """The (variant, output_step) of every estimate run started, and where: inside the run
    (``alongside``: before its steps) or after it."""
    import flexctl.sim.runs as runs
    import flexctl.sim.validity as validity

    started, state = [], {"in_run": False}
    real_start, real_integrate = validity.start_states_run, runs._integrate

    def counted(small, *args, **kwargs):
        started.append((str(small.variant), kwargs.get("output_step"), state["in_run"]))
        return real_start(small, *args, **kwargs)

    def integrate(*args, **kwargs):
        state["in_run"] = True
        try:
            return real_integrate(*args, **kwargs)
        finally:
            state["in_run"] = False
    monkeypatch.setattr(validity, "start_states_run", counted)
    monkeypatch.setattr(runs, "_integrate", integrate)
    return started


@pytest.mark.parametrize("background", [True, False])
@pytest.mark.parametrize("n_modes, rtol, method", [(2, 1e-6, "auto"), (4, 1e-6, "auto"),
                                                   (2, 1e-4, "auto"), (2, 1e-4, "RK45")])
def test_estimate_started_beside_the_run_equals_the_one_made_after_it(monkeypatch, background,
                                                                      n_modes, rtol, method):
    # simulate starts the estimate's runs while the run integrates (queued for a spare core
    # behind the accuracy check); the estimate is the one assess makes after the run, bit for
    # bit, with the work beside or not
    from flexctl.sim import background as beside

    monkeypatch.setattr(beside, "ENABLED", background)
    monkeypatch.setattr(beside, "spare_cores", lambda: 1)
    model = build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=n_modes)
    push = SineTorque(peak_torque=2.0, duration=2.0)
    started = _started_runs(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelValidityWarning)
        result = simulate(model, 8.0, torque=push, rtol=rtol, method=method)
        # the runs were started before the run's steps, the variant's only where the run
        # does not stand for it (on the estimate's modes, at the estimate's tolerance: auto
        # runs the 8(5,3) pair at 1e-6 at least)
        same = n_modes == 2 and result.rtol <= 1e-6
        assert same == (n_modes == 2 and method == "auto")
        assert [(v, inside) for v, _, inside in started] == (
            [("exact", True)] if same else [("exact", True), ("first_order", True)])
        after = assess(result, torque=push)
    assert not result.validity.screened
    assert result.validity.geometric_error == after.geometric_error
    assert after.geometric_error > 1e-4


def test_estimate_started_beside_a_run_is_given_up_where_it_is_not_needed(monkeypatch):
    # a small deflection is screened: the runs started beside it are given up, not waited for
    import flexctl.sim.validity as validity

    model = build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    given_up = []
    real = validity.EstimateBeside.abandon

    def abandon(self):
        given_up.append(self.estimate is not None)
        real(self)
    monkeypatch.setattr(validity.EstimateBeside, "abandon", abandon)
    started = _started_runs(monkeypatch)
    small = simulate(model, 4.0, torque=SineTorque(peak_torque=0.01, duration=2.0))
    assert small.validity.screened and small.validity.deflection_ratio < 0.02
    assert started and all(inside for _, _, inside in started)
    assert given_up[0] is True                 # the screen gave up the started runs
    # a run that stops early: its estimate is made for the part it ran (not the runs started
    # for the whole horizon), and it is the estimate assess gives
    started.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stopped = simulate(model, 8.0, torque=SineTorque(peak_torque=60.0, duration=2.0))
        assert stopped.status != "ok" and stopped.t[-1] < 8.0
        # the exact run started inside the run, then both models' runs after it
        assert [(v, inside) for v, _, inside in started] == [
            ("exact", True), ("exact", False), ("first_order", False)]
        after = assess(stopped, torque=SineTorque(peak_torque=60.0, duration=2.0))
    assert stopped.validity.geometric_error == after.geometric_error


def test_an_estimate_that_cannot_start_beside_the_run_is_made_after_it(monkeypatch):
    # work beside the run that fails to start leaves the estimate to the assessment
    import flexctl.sim.validity as validity

    def broken(*args, **kwargs):
        raise RuntimeError("estimate could not start")
    model = build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    push = SineTorque(peak_torque=2.0, duration=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelValidityWarning)
        expected = simulate(model, 8.0, torque=push).validity.geometric_error
        monkeypatch.setattr(validity, "_Estimate", broken)
        with pytest.raises(RuntimeError, match="estimate could not start"):
            simulate(model, 8.0, torque=push)      # the assessment's own attempt says why
        monkeypatch.undo()
        assert simulate(model, 8.0, torque=push).validity.geometric_error == expected


@pytest.mark.parametrize("bad", [0.0, -0.1, 1.0, float("nan"), float("inf"), "0.01"])
def test_run_assessed_refuses_a_bad_tolerance_before_it_runs(bad, monkeypatch):
    from flexctl.sim import validity

    model = build_model(flexctl.load_scene("hub-beam-mass").system, 2)
    runs = []
    monkeypatch.setattr(validity, "run_once", lambda *a, **k: runs.append(a))
    with pytest.raises(ValueError, match="tolerance must be a relative error"):
        validity.run_assessed(model, 1.0, torque=lambda t: 0.1, tolerance=bad)
    assert runs == []


def test_run_assessed_judges_the_run_by_the_tolerance_it_is_given():
    from flexctl.sim.validity import run_assessed

    model = build_model(flexctl.load_scene("hub-beam-mass").system, 2)
    push = SineTorque(peak_torque=2.0, duration=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelValidityWarning)
        strict = run_assessed(model, 6.0, torque=push, tolerance=1e-4)
        loose = run_assessed(model, 6.0, torque=push, tolerance=0.5)
    # the same run and estimate, judged against two tolerances
    assert strict.validity.geometric_error == loose.validity.geometric_error > 1e-4
    assert strict.validity.tolerance == 1e-4 and loose.validity.tolerance == 0.5
    assert not strict.validity.valid and loose.validity.valid
