"""Continuous runs on the compiled variable-order BDF and Adams-Moulton methods
(flexctl.sim.compiled_bdf.BdfRun)."""

import numpy as np
import pytest

import flexctl
from conftest import in_threads
from controllers import PD
from flexctl.model.errors import InputError
from flexctl.sim.compiled import integrate_segments
from flexctl.sim.compiled_bdf import OUTPUTS, BdfRun, bdf_available
from flexctl.sim.embedded_rk import EmbeddedRun
from flexctl.sim.request import StiffnessWarning, state_scale

TORQUE = flexctl.SineTorque(peak_torque=2.0, duration=2.0)


@pytest.fixture(scope="module")
def exact():
    """hub-beam-mass's exact 2-mode model and a tight CVODES run under a sine torque."""
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 2, "exact")
    tight = flexctl.simulate(model, 4.0, TORQUE, rtol=1e-12, method="cvodes",
                             check_validity=False)
    return model, tight


def _error(run, tight) -> float:
    return float(np.max(np.abs(run.tip_deflection - tight.tip_deflection)))


#: The compiled methods by the method asked for: "auto" takes Adams-Moulton on these lightly
#: damped beams at these tolerances.
METHODS = [("auto", "Adams"), ("BDF", "BDF")]


@pytest.mark.parametrize("method, taken", METHODS, ids=["auto", "BDF"])
@pytest.mark.parametrize("rtol", [1e-6, 1e-8])
def test_the_exact_model_runs_on_it_by_default_within_its_estimate(exact, rtol, method, taken):
    model, tight = exact
    run = flexctl.simulate(model, 4.0, TORQUE, rtol=rtol, method=method, check_validity=False)
    assert run.ok and run.method == taken
    actual = _error(run, tight)
    # the estimate is the difference from a replay at ten times the tolerance
    assert actual <= run.integration_error <= 200 * rtol * tight.peak_tip_deflection


def test_first_order_keeps_its_choice_and_agrees_when_asked(exact):
    model = flexctl.build_model(exact[0].system, 2)
    tight = flexctl.simulate(model, 4.0, TORQUE, rtol=1e-12, method="cvodes",
                             check_validity=False)
    assert flexctl.simulate(model, 4.0, TORQUE, check_validity=False).method == "dop853"
    run = flexctl.simulate(model, 4.0, TORQUE, rtol=1e-8, method="BDF", check_validity=False)
    assert run.method == "BDF"
    assert _error(run, tight) <= run.integration_error <= 2e-6 * tight.peak_tip_deflection


@pytest.mark.parametrize("method, taken", METHODS, ids=["auto", "BDF"])
def test_a_closed_loop_and_a_prescribed_motion_match_tight_runs(method, taken):
    model = flexctl.build_model(flexctl.load_scene("slew-90").system, 3, "exact")
    x0 = np.zeros(model.n_states)
    x0[0] = -np.pi / 2
    law = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    options = dict(controller=law, x0=x0, check_validity=False)
    run = flexctl.simulate(model, 4.0, rtol=1e-7, method=method, **options)
    tight = flexctl.simulate(model, 4.0, rtol=1e-12, method="cvodes", **options)
    assert run.method == taken and run.ok
    assert _error(run, tight) <= run.integration_error <= 1e-4 * tight.peak_tip_deflection

    scene = flexctl.load_scene("kane-spinup")
    kane = flexctl.build_model(scene.system, 2, "exact")
    run = flexctl.simulate(kane, 20.0, hub_motion=scene.maneuver, rtol=1e-7, method=method,
                           check_validity=False)
    tight = flexctl.simulate(kane, 20.0, hub_motion=scene.maneuver, rtol=1e-12,
                             method="cvodes", check_validity=False)
    assert run.method == taken and run.ok
    assert _error(run, tight) <= run.integration_error <= 1e-4 * tight.peak_tip_deflection


@pytest.mark.parametrize("family", ["bdf", "adams"])
def test_output_times_do_not_change_the_steps(exact, family):
    # the outputs are read from the interpolant: the steps, and the state at the end, are
    # the same for two output times and for more than one call's worth
    model, _ = exact
    scale = state_scale(model, model.layout)
    few, many = np.array([1.0, 3.0]), np.linspace(0.01, 3.0, 3 * OUTPUTS + 7)
    results = []
    for times in (few, many):
        run = BdfRun(model, TORQUE, scale=scale, rtol=1e-8, max_steps=10_000, h_first=1e-4,
                     family=family)
        results.append(run(0.0, times, np.zeros(model.n_states)))
        results.append(run.last_stats["steps"])
    (states_few, _), steps_few, (states_many, _), steps_many = results
    assert steps_few == steps_many
    np.testing.assert_allclose(states_many[:, -1], states_few[:, -1], rtol=0, atol=1e-13)
    # and the interpolated states are those of a tight CVODES run at the same times, within
    # the tolerance (each state against its size)
    tight, _ = integrate_segments(model, [(0.0, many)], np.zeros(model.n_states), scale,
                                  1e-12, torque=TORQUE)
    assert np.max(np.abs(states_many - tight) / scale[:, None]) < 1e-5


@pytest.mark.parametrize("method", ["BDF", "Adams"])
def test_a_diverging_run_is_stopped_and_named(exact, method):
    model, _ = exact
    torque = flexctl.SineTorque(peak_torque=1e6, duration=2.0)
    run = flexctl.simulate(model, 3.0, torque=torque, method=method, check_validity=False)
    assert run.method == method
    reference = flexctl.simulate(model, 3.0, torque=torque, method="cvodes",
                                 check_validity=False)
    assert run.status == reference.status == "diverged"
    assert np.all(np.isfinite(run.states)) and run.t[-1] < 0.1


@pytest.mark.parametrize("run_class", [BdfRun, EmbeddedRun])
def test_bad_arguments_are_refused_by_name(exact, run_class):
    # both compiled continuous runs check their arguments alike
    model, _ = exact
    scale = state_scale(model, model.layout)
    good = dict(torque=TORQUE, scale=scale, rtol=1e-6, max_steps=100, h_first=1e-3)
    run_class(model, **good)
    for name, value in [("scale", scale[:-1]), ("scale", -scale), ("rtol", 0.0),
                        ("rtol", 2.0), ("rtol", float("nan")), ("max_steps", 0),
                        ("max_steps", 2.5), ("h_first", 0.0), ("h_first", float("inf")),
                        ("h_first", "1e-3"), ("max_step", -1.0), ("max_step", "x")]:
        with pytest.raises(InputError, match=name):
            run_class(model, **{**good, name: value})
    with pytest.raises(InputError, match="CasADi form"):
        run_class(model, torque=lambda t: 0.0, scale=scale, rtol=1e-6, max_steps=10,
                  h_first=1e-3)
    with pytest.raises(InputError, match="model"):
        run_class("model", **good)


def test_output_times_must_follow_the_start(exact):
    model, _ = exact
    run = BdfRun(model, TORQUE, scale=state_scale(model, model.layout), rtol=1e-6,
                 max_steps=100, h_first=1e-3)
    for times in ([0.5, 0.4], [0.0, 1.0], [0.5, np.nan]):
        with pytest.raises(InputError, match="output times"):
            run(0.0, np.array(times), np.zeros(model.n_states))


@pytest.mark.parametrize("family", ["bdf", "adams"])
def test_a_step_budget_and_a_non_finite_state_fail_the_segment(exact, family):
    model, _ = exact
    scale = state_scale(model, model.layout)
    run = BdfRun(model, TORQUE, scale=scale, rtol=1e-10, max_steps=1, h_first=1e-3,
                 family=family)
    with pytest.raises(RuntimeError, match="budget"):
        run(0.0, np.array([1.0]), np.zeros(model.n_states))
    run = BdfRun(model, TORQUE, scale=scale, rtol=1e-6, max_steps=1000, h_first=1e-3,
                 family=family)
    bad = np.zeros(model.n_states)
    bad[1] = np.nan
    with pytest.raises(RuntimeError, match="not finite"):
        run(0.0, np.array([0.5, 1.0]), bad)


@pytest.mark.parametrize("family", ["bdf", "adams"])
def test_the_step_budget_holds_between_two_output_times(exact, family):
    """As CVODES's ``max_num_steps``: the budget is that of each output interval, not shared
    by the outputs (many later outputs do not lend their steps to a long first interval)."""
    model, _ = exact
    scale = state_scale(model, model.layout)
    times = np.concatenate([[2.0], 2.0 + 1e-3 * np.arange(1, 200)])
    counted = BdfRun(model, TORQUE, scale=scale, rtol=1e-8, max_steps=10**5, h_first=1e-3,
                     family=family)
    counted(0.0, times, np.zeros(model.n_states))
    first = counted.last_stats["steps"]
    assert first > 100
    # a budget below the first interval's steps fails though the outputs' sum exceeds them
    tight = BdfRun(model, TORQUE, scale=scale, rtol=1e-8, max_steps=first // 4, h_first=1e-3,
                   family=family)
    assert (first // 4) * times.size > first
    with pytest.raises(RuntimeError, match="budget"):
        tight(0.0, times, np.zeros(model.n_states))


def test_without_compiling_the_exact_model_keeps_its_other_methods(exact, monkeypatch):
    model, tight = exact
    monkeypatch.setenv("FLEXCTL_COMPILE", "0")
    assert not bdf_available(model, TORQUE)
    assert not bdf_available(model, TORQUE, family="adams")
    run = flexctl.simulate(model, 1.0, TORQUE, check_validity=False)
    assert run.ok and run.method not in ("BDF", "Adams")
    # an explicit Adams is CVODES's
    assert flexctl.simulate(model, 0.5, TORQUE, method="Adams",
                            check_validity=False).method == "cvodes"
    with pytest.raises(InputError, match="no compiled integrator"):
        BdfRun(model, TORQUE, scale=state_scale(model, model.layout), rtol=1e-6,
               max_steps=10, h_first=1e-3)
    # an explicit BDF is then SciPy's
    assert flexctl.simulate(model, 0.5, TORQUE, method="BDF", check_validity=False).ok


def test_threads_share_the_library_and_agree(exact):
    model, _ = exact
    results = in_threads(lambda k: flexctl.simulate(model, 2.0, TORQUE, rtol=1e-7,
                                                    check_validity=False).tip_deflection)
    np.testing.assert_array_equal(results[0], results[1])
    np.testing.assert_array_equal(results[0], results[2])


def test_a_run_without_a_finite_pole_starts_from_its_output_step(exact, monkeypatch):
    # a Jacobian beyond floating point gives no rate: the first step is the output step's
    from flexctl.sim import request

    monkeypatch.setattr(request, "_loop_frequency", lambda *args: float("nan"))
    model, tight = exact
    run = flexctl.simulate(model, 4.0, TORQUE, rtol=1e-8, check_validity=False)
    # no rate: not a lightly damped oscillation either, the BDF takes it
    assert run.ok and run.method == "BDF"
    assert _error(run, tight) <= run.integration_error


@pytest.mark.parametrize("method, taken", METHODS, ids=["auto", "BDF"])
def test_a_heavy_tip_on_a_massless_hub_converges_on_its_own_jacobian(method, taken):
    # first_order's Jacobian is far from the exact model's here: Newton's iterations on it
    # took 162 000 evaluations or more; on the exact model's, by differences, some 4 400
    # (BDF) and 2 500 (Adams)
    import dataclasses

    base = flexctl.load_scene("hub-beam-mass").system
    system = dataclasses.replace(base, hub=dataclasses.replace(base.hub, inertia=0.0),
                                 masses=(flexctl.PointMass(mass=6e5, position=1.8),))
    model = flexctl.build_model(system, 2, "exact")
    torque = flexctl.SineTorque(peak_torque=1.0, duration=0.5)
    run = flexctl.simulate(model, 1.0, torque, method=method, check_validity=False)
    tight = flexctl.simulate(model, 1.0, torque, rtol=1e-12, method="RK45",
                             check_validity=False)
    assert run.ok and run.method == taken
    assert run.n_evaluations < 20_000
    assert _error(run, tight) <= run.integration_error


def test_a_loose_tolerance_still_has_an_honest_estimate(exact):
    # at rtol 0.5 the replay cannot be ten times looser: it is ten times tighter, and the
    # estimate bounds the run's actual error rather than reading zero
    model, tight = exact
    run = flexctl.simulate(model, 4.0, TORQUE, rtol=0.5, method="BDF", check_validity=False)
    assert run.ok
    assert 0.0 < _error(run, tight) <= 2.0 * run.integration_error


def test_an_absolute_tolerance_beyond_the_motion_is_refused_by_state(exact):
    # at atol 1e3 the run and its replay agreed on a wrong answer: estimate 7e-15, error 0.29 m
    model, _ = exact
    limit = 100.0 * state_scale(model, model.layout)
    with pytest.raises(InputError, match=r"atol for theta is 1000, more than 100 times.*"
                                         r"at most 0\.1 there"):
        flexctl.simulate(model, 4.0, TORQUE, atol=1e3, check_validity=False)
    looser = limit.copy()
    looser[model.layout.names.index("q1")] *= 1.01
    with pytest.raises(InputError, match=r"atol for q1 is"):
        flexctl.simulate(model, 4.0, TORQUE, atol=looser, check_validity=False)


def test_the_loosest_absolute_tolerance_flags_its_run(exact):
    # at the limit the error control hardly sees the beam: the run is far off, and its
    # estimate says so rather than reading zero
    model, tight = exact
    run = flexctl.simulate(model, 4.0, TORQUE, atol=99.0 * state_scale(model, model.layout),
                           check_validity=False)
    assert run.ok and run.method == "BDF"
    assert run.integration_error >= 0.05 * tight.peak_tip_deflection
    assert _error(run, tight) <= 10.0 * run.integration_error


def test_auto_takes_adams_only_where_the_error_control_sees_the_modes(exact):
    # Adams-Moulton's orders 3 and more amplify an undamped oscillation a little each step:
    # at a tolerance, or its check's, looser than ADAMS_TOLERANCE, or on beams damped
    # beyond ADAMS_DAMPING, the run takes the BDF
    import dataclasses

    from flexctl.sim.request import ADAMS_TOLERANCE

    model, tight = exact
    scale = state_scale(model, model.layout)

    def method(run_model=model, **options):
        return flexctl.simulate(run_model, 1.0, TORQUE, check_validity=False,
                                **options).method

    assert method(rtol=ADAMS_TOLERANCE / 10) == "Adams"
    assert method(rtol=ADAMS_TOLERANCE) == "BDF"
    assert method(atol=ADAMS_TOLERANCE / 10 * scale) == "Adams"
    assert method(atol=ADAMS_TOLERANCE * scale) == "BDF"
    system = model.system
    damped = dataclasses.replace(system, beam=dataclasses.replace(system.beam,
                                                                  damping_ratio=0.3))
    assert method(flexctl.build_model(damped, 2, "exact")) == "BDF"
    # asked for, it is taken, and its estimate still bounds its error at rtol 1e-4; looser,
    # with a warning
    run = flexctl.simulate(model, 4.0, TORQUE, rtol=1e-4, method="Adams", check_validity=False)
    assert run.method == "Adams" and _error(run, tight) <= run.integration_error
    with pytest.warns(StiffnessWarning, match="method 'Adams' at rtol 0.001"):
        assert method(rtol=ADAMS_TOLERANCE, method="Adams") == "Adams"


def test_adams_with_a_sampled_controller_or_python_inputs_is_refused(exact):
    model, _ = exact
    sampled = flexctl.sim.ZeroOrderHold(PD(kp=1.0, kd=1.0), sample_time=0.01)
    with pytest.raises(InputError, match="sampled controller"):
        flexctl.simulate(model, 1.0, controller=sampled, method="Adams")
    with pytest.raises(InputError, match="CasADi form"):
        flexctl.simulate(model, 1.0, controller=lambda t, x: -x[0], method="Adams")


@pytest.mark.parametrize("method", ["Adams", "BDF"])
def test_a_vanishing_atol_from_rest_is_a_relative_tolerance(exact, method):
    # from a state at rest every weight of the error norm was atol alone: with atol 1e-300
    # Adams-Moulton's first step overflowed its norm and failed as too short, and the run
    # ended "diverged" behind SciPy
    model, tight = exact
    run = flexctl.simulate(model, 4.0, TORQUE, rtol=1e-8, atol=1e-300, method=method,
                           check_validity=False)
    assert run.ok and run.method == method
    assert _error(run, tight) <= run.integration_error <= 1e-5 * tight.peak_tip_deflection


@pytest.mark.parametrize("method", ["Adams", "BDF"])
def test_segments_ending_on_breakpoints_keep_their_estimate(method):
    # a bang-bang slew cuts the run at 1 and 2 s: steps that ended an ulp or two short of a
    # cut left a rest too short to take, the segment went to SciPy and the estimate was lost
    from controllers import OpenLoop, bang_bang

    system = flexctl.load_scene("slew-90").system
    plant = flexctl.build_model(system, 4, "exact")
    law = OpenLoop(bang_bang(flexctl.build_model(system, 2), np.pi / 2, duration=2.0))
    options = dict(controller=law, check_validity=False)
    run = flexctl.simulate(plant, 4.0, rtol=1e-7, method=method, **options)
    tight = flexctl.simulate(plant, 4.0, rtol=1e-12, method="cvodes", **options)
    assert run.ok and run.method == method and run.integration_error is not None
    assert _error(run, tight) <= run.integration_error <= 1e-4 * tight.peak_tip_deflection


def test_a_segment_the_compiled_run_cannot_take_is_named_without_an_estimate(exact,
                                                                              monkeypatch):
    from flexctl.sim import compiled_bdf

    model, tight = exact
    segment = compiled_bdf.BdfRun._segment

    def failing(self, run, lo, t_out, y, stop):
        if lo > 1.0:                      # the sine torque's second segment, from 2 s
            raise RuntimeError("BDF: step too short at t = 2 s")
        return segment(self, run, lo, t_out, y, stop)

    monkeypatch.setattr(compiled_bdf.BdfRun, "_segment", failing)
    run = flexctl.simulate(model, 4.0, TORQUE, rtol=1e-8, check_validity=False)
    assert run.ok and run.integration_error is None
    assert "accuracy check not run: the compiled integrator failed" in run.message
    assert _error(run, tight) <= 1e-5 * tight.peak_tip_deflection


def test_an_unknown_family_is_refused_by_name(exact):
    model, _ = exact
    with pytest.raises(InputError, match="family must be one of.*'rk'"):
        BdfRun(model, TORQUE, scale=state_scale(model, model.layout), rtol=1e-6,
               max_steps=10, h_first=1e-3, family="rk")


@pytest.mark.parametrize("family", ["bdf", "adams"])
def test_the_model_right_hand_side_reaches_c_as_a_function_pointer(exact, family):
    """The exact model's library calls the model's compiled right-hand side through a C
    function pointer given with each call: a call without one is refused with its status (5),
    not a jump to address 0, and the same library then integrates with it."""
    from flexctl.sim.compiled_bdf import STATUS, _built, _Entry

    model = exact[0]
    external, pieces = _built(model, (TORQUE, None, None), family)
    assert isinstance(pieces["address"], int) and pieces["address"] > 0
    bare = _Entry(external, None)
    bare.evaluate()
    assert bare.results[2][0] == 5.0 and STATUS[5] == "no model right-hand side"
    run = BdfRun(model, TORQUE, scale=np.ones(model.n_states), rtol=1e-8, max_steps=10**5,
                 h_first=1e-4, family=family)
    states, evaluations = run(0.0, np.array([0.5, 1.0]), np.zeros(model.n_states))
    assert evaluations > 0 and np.all(np.isfinite(states))
    tight = exact[1]
    expected = [np.interp(1.0, tight.t, row) for row in tight.states]
    assert np.allclose(states[:, -1], expected, rtol=0, atol=1e-5)


@pytest.mark.parametrize("method, uncompiled", [("auto", "dop853"), ("Adams", "cvodes"),
                                                ("BDF", "BDF")])
def test_the_plan_compiles_nothing_and_a_library_that_cannot_be_built_is_replaced(
        exact, monkeypatch, method, uncompiled):
    """The method is chosen without building a library; a compiled multistep method whose
    library cannot be built when the run starts (a drive too large to compile) gives way to
    the plan's method without it, named in the result, with its accuracy checked."""
    from flexctl.sim import compile_cache, compiled_bdf
    from flexctl.sim.drives import TorqueDrive
    from flexctl.sim.request import plan_integration, run_request

    model, tight = exact
    built = []
    monkeypatch.setattr(compiled_bdf, "_built", lambda *a, **k: built.append(a) or None)
    monkeypatch.setattr(compile_cache, "compiled_source",
                        lambda *a, **k: pytest.fail("the plan compiled a library"))
    request = run_request(model, 2.0, TORQUE, method=method, check_accuracy=False)
    plan = plan_integration(request, TorqueDrive(model, TORQUE, None, request.x_init))
    assert plan.compiled and plan.method in ("Adams", "BDF") and plan.uncompiled == uncompiled
    assert built == []
    run = flexctl.simulate(model, 2.0, TORQUE, method=method, rtol=1e-8, check_validity=False,
                           output_step=float(tight.t[1] - tight.t[0]))
    assert built and run.ok and run.method == uncompiled
    assert f"could not be built (compiling off, no C compiler, or a drive too large to " \
        f"compile): {uncompiled} took the run" in run.message
    assert run.integration_error is not None and np.isfinite(run.integration_error)
    # the replacement run is as accurate as it says (on the tight run's own output times)
    np.testing.assert_allclose(run.t, tight.t[:run.t.size], rtol=0, atol=1e-12)
    error = np.max(np.abs(run.tip_deflection - tight.tip_deflection[:run.t.size]))
    assert error <= max(run.integration_error, 1e-8 * tight.peak_tip_deflection)
