"""Trajectory optimisation of rest-to-rest slews (controllers/trajopt.py).

Contracts checked: boundary conditions and bounds of the optimum (to solver tolerance), the
optimum re-simulated by an independent integrator, residual vibration against a rigid
bang-bang torque on a plant with more modes, the rigid-body lower bound on the minimum time,
warm starts, IPOPT failures reported with a reason and a remedy, tracking on a plant with an
error, and robustness to fast design modes: the slew-90 grid of design modes x intervals
solves to its converged cost or is refused at once, naming the setting and a value that works.
"""

import dataclasses
import functools
import math
import re
import time

import numpy as np
import pytest

import flexctl
from controllers import trajopt
from controllers.design.hold_grid import HOLD_EFFORT_TOLERANCE, hold_effort_excess
from controllers.slew.trajopt import (HoldTorque, SlewProblem, TrajectoryOptimizationError,
                                      rigid_minimum_time, solve_slew)
from controllers.feedback.tracking import TrajectoryTracker

SYSTEM = flexctl.load_scene("hub-beam-mass").system
ANGLE = math.pi / 2            # rad
DURATION = 2.0                 # s, feasible: above the flexible minimum time (about 1.8 s)
TORQUE_BOUND = 6.0             # N m
DESIGN_MODES = 2
PLANT_MODES = 6                # "truth" plant: more modes than the design model
SETTLE = 3.0                   # s of coasting after the slew to measure residual vibration

BOUNDARY_TOL = 1e-8            # rad, m, rad/s, m/s: linear equalities, solved exactly
BOUND_TOL = 1e-6               # relative excess over a bound that IPOPT may leave
DISCRETISATION_TOL = 1e-3      # final-state error of the re-simulated torque / state scale
INTERPOLATION_TOL = 1e-3       # Hermite interpolation error / state scale
RESIDUAL_RATIO = 0.02          # residual tip vibration: optimal / rigid bang-bang
TRACKING_TOL = 0.02            # relative angle error of the tracked slew
SIM_RTOL = 1e-8


@pytest.fixture(scope="module")
def design():
    return flexctl.build_model(SYSTEM, DESIGN_MODES)


@pytest.fixture(scope="module")
def plant():
    return flexctl.build_model(SYSTEM, PLANT_MODES)


@pytest.fixture(scope="module")
def problem():
    return SlewProblem(angle=ANGLE, duration=DURATION, torque_bound=TORQUE_BOUND)


@pytest.fixture(scope="module")
def solution(design, problem):
    return solve_slew(design, problem)


def state_scale(states):
    """Size of the motion, per kind of state: the largest angle, modal deflection, hub rate
    and modal rate along a trajectory, shape (n, 1). Errors are judged against the motion
    of their kind, not against a mode that hardly moves."""
    n = (states.shape[0] - 2) // 2
    peak = np.max(np.abs(states), axis=1)
    kinds = [slice(0, 1), slice(1, n + 1), slice(n + 1, n + 2), slice(n + 2, 2 * n + 2)]
    return np.concatenate([np.full(k.stop - k.start, peak[k].max()) for k in kinds])[:, None]


def residual_tip(result, t_end):
    """Largest |tip deflection| after the end of the slew, m."""
    return float(np.max(np.abs(result.tip_deflection[result.t >= t_end])))


def rigid_bang_bang(model, angle, duration):
    """Rest-to-rest bang-bang torque of the rigid body: +u on [0, T/2), -u on [T/2, T)."""
    u = 4.0 * angle * model.matrices.J0 / duration ** 2
    return HoldTorque(np.array([0.0, duration / 2, duration]), np.array([u, -u]))


CASES = [
    pytest.param(dict(), id="rk4"),
    # CVODES with sensitivities: 2-4 s per solve on a shared 2-core machine
    pytest.param(dict(integrator="cvodes"), id="cvodes", marks=pytest.mark.slow),
    pytest.param(dict(transcription="collocation"), id="radau"),
    pytest.param(dict(transcription="collocation", collocation_scheme="legendre"),
                 id="legendre"),
    pytest.param(dict(torque_rate_bound=30.0), id="rate-bound"),
    pytest.param(dict(tip_bound=0.45, transcription="collocation"), id="tip-bound"),
]


@pytest.mark.parametrize("options", CASES)
def test_solution_meets_boundary_conditions_and_bounds(design, options):
    problem = SlewProblem(angle=ANGLE, duration=DURATION, torque_bound=TORQUE_BOUND, **options)
    sol = solve_slew(design, problem)
    target = problem.target_state(design.n_states)

    assert sol.return_status == "Solve_Succeeded"
    assert sol.t[0] == 0.0 and sol.t[-1] == pytest.approx(DURATION)
    np.testing.assert_allclose(sol.states[:, 0], 0.0, atol=BOUNDARY_TOL)
    np.testing.assert_allclose(sol.states[:, -1], target, atol=BOUNDARY_TOL)
    assert np.max(np.abs(sol.torque)) <= TORQUE_BOUND * (1 + BOUND_TOL)
    assert sol.cost == pytest.approx(np.sum(sol.torque ** 2) * DURATION / sol.torque.size)
    if problem.torque_rate_bound is not None:
        h = DURATION / problem.n_intervals
        rates = np.abs(np.diff(np.concatenate(([0.0], sol.torque, [0.0])))) / h
        # the bound must hold, and be active (else the case tests nothing)
        assert np.max(rates) <= problem.torque_rate_bound * (1 + BOUND_TOL)
        assert np.max(rates) == pytest.approx(problem.torque_rate_bound, rel=1e-4)
    if problem.tip_bound is not None:
        # bounded at the grid and collocation times; active at some collocation time
        assert np.max(np.abs(sol.tip_deflection)) <= problem.tip_bound * (1 + BOUND_TOL)
        assert np.max(np.abs(sol.tip_deflection)) > 0.99 * problem.tip_bound

    # The torque, integrated by flexctl's own error-controlled integrator, lands on the target.
    result = flexctl.simulate(design, DURATION, torque=sol.torque_function(), rtol=SIM_RTOL)
    assert result.ok
    error = np.abs(result.states[:, -1] - target) / state_scale(sol.states)[:, 0]
    assert np.max(error) < DISCRETISATION_TOL, error


def test_effort_is_above_the_rigid_body_minimum(solution, design):
    """``J_0 psi'' = torque`` for ``psi = theta + m_tf.q / J_0``, which also goes rest to rest
    from 0 to ``angle``: no torque slews with less effort than ``12 angle^2 J_0^2 / T^3``."""
    rigid = 12.0 * ANGLE ** 2 * design.matrices.J0 ** 2 / DURATION ** 3
    assert rigid <= solution.cost < 1.5 * rigid, (rigid, solution.cost)


def test_hold_torque_is_piecewise_constant_with_breakpoints(solution):
    torque = solution.torque_function()
    mid = 0.5 * (solution.t[1:] + solution.t[:-1])
    np.testing.assert_array_equal(torque(mid), solution.torque)
    assert torque(-0.1) == 0.0 and torque(DURATION + 1e-9) == 0.0
    assert torque(solution.t[3]) == solution.torque[3]          # holds are [t_k, t_k+1)
    assert torque.breakpoints == tuple(solution.t[1:])


def test_state_interpolation_follows_the_design_model(design, solution):
    np.testing.assert_allclose(solution.state_at(solution.t), solution.states, atol=1e-14)
    result = flexctl.simulate(design, DURATION, torque=solution.torque_function(),
                              rtol=SIM_RTOL, output_step=DURATION / 400)
    error = np.abs(solution.state_at(result.t) - result.states)
    assert np.max(error / state_scale(result.states)) < INTERPOLATION_TOL
    np.testing.assert_allclose(solution.state_at(DURATION + 5.0), solution.states[:, -1],
                               atol=1e-14)


def test_open_loop_residual_vibration_is_far_below_bang_bang(plant, solution):
    t_final = DURATION + SETTLE
    optimal = flexctl.simulate(plant, t_final, torque=solution.torque_function(), rtol=1e-7)
    bang = flexctl.simulate(plant, t_final, torque=rigid_bang_bang(plant, ANGLE, DURATION),
                            rtol=1e-7)
    assert optimal.ok and bang.ok
    residual_optimal, residual_bang = residual_tip(optimal, DURATION), residual_tip(bang, DURATION)
    assert residual_optimal < RESIDUAL_RATIO * residual_bang, (residual_optimal, residual_bang)
    assert abs(optimal.theta[-1] - ANGLE) < 1e-3 * ANGLE


@pytest.mark.parametrize("transcription", ["multiple_shooting", "collocation"])
def test_minimum_time_lies_between_rigid_bound_and_feasible_time(design, transcription):
    problem = SlewProblem(angle=ANGLE, duration=None, torque_bound=TORQUE_BOUND,
                          transcription=transcription)
    sol = solve_slew(design, problem)
    lower = rigid_minimum_time(ANGLE, design.matrices.J0, TORQUE_BOUND)
    assert problem.objective == "time" and sol.cost == sol.duration
    assert lower * (1 - BOUND_TOL) <= sol.duration < DURATION, (lower, sol.duration)
    np.testing.assert_allclose(sol.states[:, -1], problem.target_state(design.n_states),
                               atol=BOUNDARY_TOL)
    assert np.max(np.abs(sol.torque)) <= TORQUE_BOUND * (1 + BOUND_TOL)
    # minimum time uses the torque: most holds sit on the bound
    assert np.mean(np.abs(sol.torque) > 0.99 * TORQUE_BOUND) > 0.5


def test_rigid_minimum_time_formula():
    # J theta'' = +-u for T/2 each covers u T^2 / (4 J)
    assert rigid_minimum_time(1.0, 2.0, 8.0) == pytest.approx(1.0)
    assert rigid_minimum_time(-1.0, 2.0, 8.0) == pytest.approx(1.0)


def test_warm_start_reduces_iterations(design, solution, problem):
    longer = dataclasses.replace(problem, duration=1.1 * DURATION)
    cold = solve_slew(design, longer)
    warm = solve_slew(design, longer, initial_guess=solution)
    assert warm.iterations < cold.iterations, (warm.iterations, cold.iterations)
    assert warm.cost == pytest.approx(cold.cost, rel=1e-6)
    # plain arrays on another grid are accepted too
    coarse = dataclasses.replace(longer, n_intervals=30)
    from_arrays = solve_slew(design, coarse, initial_guess=(solution.t, solution.states,
                                                             solution.torque))
    assert from_arrays.torque.shape == (30,)


@pytest.mark.parametrize("options, remedy", [
    (dict(duration=0.5), "rigid-body minimum time"),    # far below the rigid minimum 1.74 s
    (dict(duration=DURATION, tip_bound=0.1), "tip_bound"),   # the hub acceleration bends more
], ids=["too-short", "tip-too-tight"])
def test_infeasible_problem_raises_with_the_reason_and_the_setting(design, options, remedy):
    problem = SlewProblem(angle=ANGLE, torque_bound=TORQUE_BOUND, **options)
    with pytest.raises(TrajectoryOptimizationError, match=remedy) as info:
        solve_slew(design, problem)
    status = info.value.return_status
    assert isinstance(info.value, RuntimeError)
    assert status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    # IPOPT's status is kept for programs, out of the message for people
    assert status not in str(info.value)


def _heavier_hub(system, factor):
    hub = dataclasses.replace(system.hub, inertia=factor * system.hub.inertia)
    return dataclasses.replace(system, hub=hub)


def test_tracker_reaches_target_on_plant_with_heavier_hub_and_more_modes(solution):
    plant = flexctl.build_model(_heavier_hub(SYSTEM, 1.2), PLANT_MODES)
    t_final = DURATION + 2.0
    open_loop = flexctl.simulate(plant, t_final, torque=solution.torque_function(), rtol=1e-7)
    tracker = TrajectoryTracker(solution=solution)
    tracked = flexctl.simulate(plant, t_final, controller=tracker, rtol=1e-7)
    assert open_loop.ok and tracked.ok
    # the error in the plant is large enough to matter open loop ...
    assert abs(open_loop.theta[-1] - ANGLE) > TRACKING_TOL * ANGLE
    # ... and the feedback takes it out
    assert abs(tracked.theta[-1] - ANGLE) < TRACKING_TOL * ANGLE
    assert residual_tip(tracked, DURATION) < residual_tip(open_loop, DURATION)


@pytest.mark.parametrize("damping_ratio", [0.0, 0.001], ids=["undamped", "damped"])
def test_tracker_gain_stabilises_larger_plant(solution, damping_ratio):
    """Closed loop of the linearised 8-mode plant (heavier hub) with the design-model gain."""
    system = _heavier_hub(SYSTEM, 1.2)
    system = dataclasses.replace(system, beam=dataclasses.replace(
        system.beam, damping_ratio=damping_ratio))
    plant = flexctl.build_model(system, 8)
    tracker = TrajectoryTracker(solution=solution)
    a, b = plant.linear_matrices(0.0)
    gain = np.array([tracker.design_state(row) @ tracker.gain for row in np.eye(plant.n_states)])
    poles = np.linalg.eigvals(a - b @ gain[None, :])
    assert np.max(poles.real) < 0.0, np.max(poles.real)


def test_tracker_on_the_design_model_reproduces_the_optimum(design, solution):
    result = flexctl.simulate(design, DURATION, controller=TrajectoryTracker(solution=solution),
                              rtol=SIM_RTOL)
    error = np.abs(result.states[:, -1] - solution.states[:, -1])
    error /= state_scale(solution.states)[:, 0]
    assert np.max(error) < DISCRETISATION_TOL


@pytest.mark.parametrize("field, value", [
    ("angle", 0.0), ("angle", float("nan")), ("duration", -1.0), ("torque_bound", 0.0),
    ("n_intervals", 1), ("n_intervals", 0), ("torque_rate_bound", -1.0),
    ("tip_bound", 0.0), ("objective", "fast"), ("transcription", "shooting"),
    ("integrator", "euler"), ("substeps", 0), ("collocation_scheme", "gauss"),
    ("max_duration", 5.0),
])
def test_bad_problem_settings_name_the_parameter(field, value):
    settings = dict(angle=ANGLE, duration=DURATION, torque_bound=TORQUE_BOUND)
    settings[field] = value
    with pytest.raises(ValueError, match=field):
        SlewProblem(**settings)


def test_objective_and_duration_must_agree():
    with pytest.raises(ValueError, match="duration"):
        SlewProblem(angle=ANGLE, duration=DURATION, torque_bound=1.0, objective="time")
    with pytest.raises(ValueError, match="duration"):
        SlewProblem(angle=ANGLE, duration=None, torque_bound=1.0, objective="effort")


def test_bad_solver_inputs_name_the_parameter(design, problem, solution):
    with pytest.raises(ValueError, match="initial_guess"):
        solve_slew(design, problem, initial_guess=(solution.t, solution.states[:3],
                                                   solution.torque))
    with pytest.raises(ValueError, match="ipopt_options"):
        solve_slew(design, problem, ipopt_options=[("max_iter", 3)])
    with pytest.raises(TypeError, match="problem"):
        solve_slew(design, dict(angle=ANGLE))
    with pytest.raises(ValueError, match="state_weights"):
        TrajectoryTracker(solution=solution, state_weights=np.ones(3))
    with pytest.raises(ValueError, match="torque_limit"):
        TrajectoryTracker(solution=solution, torque_limit=-1.0)
    with pytest.raises(ValueError, match="plant.s 1 modes"):
        TrajectoryTracker(solution=solution).torque(0.0, np.zeros(4), np.zeros(0))


def test_iteration_limit_is_reported_as_failure(design, problem):
    with pytest.raises(TrajectoryOptimizationError, match="iteration limit .*max_iter") as info:
        solve_slew(design, problem, ipopt_options={"max_iter": 2})
    assert info.value.return_status == "Maximum_Iterations_Exceeded"


def test_too_few_holds_for_the_terminal_conditions_are_refused_before_solving(design):
    problem = SlewProblem(angle=ANGLE, duration=DURATION, torque_bound=TORQUE_BOUND,
                          n_intervals=2)
    with pytest.raises(ValueError, match=r"n_intervals must be at least the 6 terminal"):
        solve_slew(design, problem)


# ---------------------------------------------------------------------------- fast modes
# Issue 9, item 6: on slew-90's system, every design-mode count 1..8 and interval count
# 20..200 solves to within 1 % of the converged cost, or is refused before IPOPT runs, fast,
# naming the setting to change and a value that works. The whole grid is measured by
# ``python benchmarks/bench_trajopt.py --grid``; here every cell's refusal decision and a
# subset of solves.
SLEW_90 = flexctl.load_scene("slew-90")
GRID_MODES = range(1, 9)
GRID_INTERVALS = (20, 30, 40, 60, 80, 120, 200)
COST_TOL = 0.01                # relative error of the optimum against the converged cost
REFUSAL_BUDGET = 1.0           # s (CPU: the wall clock of a shared CI runner is not ours)
REFERENCE_INTERVALS = 160      # holds whose least effort is within 0.03 % of a continuous
                               # torque's for up to 5 slew-90 modes (hold_effort_excess)


def slew_90_problem(n_intervals):
    slew = SLEW_90.maneuver
    return SlewProblem(angle=slew.angle, duration=slew.duration,
                       torque_bound=slew.torque_bound, n_intervals=n_intervals)


@functools.lru_cache(maxsize=None)
def slew_90_model(variant, n_modes):
    return flexctl.build_model(SLEW_90.system, n_modes=n_modes, variant=variant)


@functools.lru_cache(maxsize=None)
def converged_cost(variant, n_modes):
    return solve_slew(slew_90_model(variant, n_modes),
                      slew_90_problem(REFERENCE_INTERVALS)).cost


@pytest.mark.parametrize("n_intervals", [5, 20, 200])
def test_least_effort_of_rigid_holds_is_the_closed_form(n_intervals):
    """Holds ``u_k`` of a rigid body: the least effort is ``12 (J theta)^2 / (T^3 (1 - 1/K^2))``,
    the continuous one ``12 (J theta)^2 / T^3``."""
    model = slew_90_model("first_order", 1)
    effort = hold_effort_excess(model, 2.0, n_intervals, angle=1.0)
    assert effort.excess[0] == pytest.approx(1.0 / (1.0 - n_intervals ** -2) - 1.0, rel=1e-6)


def test_holds_that_alias_a_mode_near_zero_cost_effort():
    """40 holds of 0.05 s see mode 4 (134.6 rad/s, omega h = 6.7 = 2 pi + 0.45) at 9 rad/s,
    inside the slew's own band: stopping it costs more than 1 %; 60 holds do not."""
    model = slew_90_model("first_order", 4)
    aliased = hold_effort_excess(model, 2.0, 40, SLEW_90.maneuver.angle)
    assert aliased.culprit(HOLD_EFFORT_TOLERANCE) == 4
    assert aliased.excess[3] < HOLD_EFFORT_TOLERANCE < aliased.worst
    assert hold_effort_excess(model, 2.0, 60).worst < HOLD_EFFORT_TOLERANCE


class _WouldSolve(Exception):
    """Raised instead of building the NLP: the checks before IPOPT let the cell through."""


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["first_order", "exact"])
def test_every_grid_cell_is_refused_fast_with_a_remedy_or_let_through(variant, monkeypatch):
    """All 56 cells of a variant: refused within the budget, naming n_intervals or
    model.design_modes and values that the same checks let through, or sent on to IPOPT."""
    def would_solve(*args):
        raise _WouldSolve

    monkeypatch.setattr(trajopt, "transcribe", would_solve)
    for n_modes in GRID_MODES:
        model = slew_90_model(variant, n_modes)
        for n_intervals in GRID_INTERVALS:
            start = time.process_time()
            try:
                solve_slew(model, slew_90_problem(n_intervals))
            except _WouldSolve:
                continue
            except ValueError as exc:
                message = str(exc)
            finally:
                elapsed = time.process_time() - start
            cell = (variant, n_modes, n_intervals, message)
            assert elapsed < REFUSAL_BUDGET, cell
            fewer = re.search(r"at most (\d+) design modes \(model\.design_modes\)", message)
            more = re.search(r"use n_intervals = (\d+)", message)
            tolerance = re.search(r"effort_tolerance = ([0-9.e+-]+) ", message)
            assert fewer or more, cell
            if tolerance:
                with pytest.raises(_WouldSolve):
                    solve_slew(model, dataclasses.replace(slew_90_problem(n_intervals),
                                                          effort_tolerance=float(
                                                              tolerance.group(1))))
            if more:
                with pytest.raises(_WouldSolve):
                    solve_slew(model, slew_90_problem(int(more.group(1))))
            if fewer:
                with pytest.raises(_WouldSolve):
                    solve_slew(slew_90_model(variant, int(fewer.group(1))),
                               slew_90_problem(n_intervals))


GRID_CELLS = [
    # (variant, design modes, intervals): solved cells near the 1 % line and the defaults
    pytest.param("first_order", 1, 20, id="first_order-1x20"),
    pytest.param("first_order", 3, 30, id="first_order-3x30"),
    pytest.param("first_order", 4, 30, id="first_order-4x30"),       # +0.8 %: the worst cell
    pytest.param("first_order", 5, 80, id="first_order-5x80"),
    pytest.param("exact", 2, 20, id="exact-2x20"),
    pytest.param("exact", 2, 40, id="exact-2x40"),                   # the scene's own slew
    # refused: 4 modes on 40 holds ended "acceptable" at 61.7 (issue 9), 6 exact modes on 20
    # holds "Infeasible" after 209 iterations, 6 exact modes on 80 holds take minutes
    pytest.param("first_order", 4, 40, id="first_order-4x40"),
    pytest.param("exact", 6, 20, id="exact-6x20"),
    pytest.param("exact", 6, 80, id="exact-6x80"),
]


@pytest.mark.slow
@pytest.mark.parametrize("variant, n_modes, n_intervals", GRID_CELLS)
def test_grid_cell_solves_to_its_converged_cost_or_is_refused_fast(variant, n_modes,
                                                                    n_intervals):
    model = slew_90_model(variant, n_modes)
    start = time.process_time()
    try:
        solution = solve_slew(model, slew_90_problem(n_intervals))
    except ValueError as exc:
        assert time.process_time() - start < REFUSAL_BUDGET
        assert re.search(r"use n_intervals = \d+|model\.design_modes", str(exc)), str(exc)
        return
    reference = converged_cost(variant, n_modes)
    assert solution.cost == pytest.approx(reference, rel=COST_TOL), (solution.cost, reference)
    # the torques reach the target on the design model's own dynamics, to solver accuracy
    np.testing.assert_allclose(solution.states[:, -1],
                               solution.problem.target_state(model.n_states), atol=BOUNDARY_TOL)


def test_the_effort_tolerance_a_refusal_names_lets_the_holds_through(monkeypatch):
    """Aliasing alone refuses 40 holds for 4 slew-90 modes (5.15 % more effort): the refusal
    names the effort tolerance that accepts them, and with it the checks let the slew through
    (the solve, 6.3 % above the converged cost with the torque bound, is the slow test's)."""
    def would_solve(*args):
        raise _WouldSolve

    monkeypatch.setattr(trajopt, "transcribe", would_solve)
    model = slew_90_model("first_order", 4)
    with pytest.raises(ValueError, match=r"limit 1 %\).*effort_tolerance = 0\.052 ") as info:
        solve_slew(model, slew_90_problem(40))
    assert "controller.effort_tolerance" in str(info.value)
    with pytest.raises(_WouldSolve):
        solve_slew(model, dataclasses.replace(slew_90_problem(40), effort_tolerance=0.052))
    with pytest.raises(ValueError, match=r"limit 5 %\)"):
        solve_slew(model, dataclasses.replace(slew_90_problem(40), effort_tolerance=0.05))


@pytest.mark.slow
def test_a_slew_the_effort_tolerance_accepts_costs_what_the_hold_analysis_says():
    model = slew_90_model("first_order", 4)
    accepted = solve_slew(model, dataclasses.replace(slew_90_problem(40),
                                                     effort_tolerance=0.052))
    excess = accepted.cost / converged_cost("first_order", 4) - 1.0
    # the analysis is of the unbounded linear slew; the torque bound adds a little
    assert 0.0515 - 0.005 < excess < 0.0515 + 0.02, excess


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan"), float("inf"), "0.05", True, None])
def test_effort_tolerance_is_refused_by_name(bad):
    with pytest.raises((TypeError, ValueError), match="effort_tolerance"):
        SlewProblem(angle=1.0, duration=2.0, torque_bound=5.0, effort_tolerance=bad)


@pytest.mark.slow
def test_the_interval_count_a_refusal_names_solves_to_the_converged_cost():
    model = slew_90_model("first_order", 4)
    with pytest.raises(ValueError, match=r"use n_intervals = \d+") as info:
        solve_slew(model, slew_90_problem(40))
    better = int(re.search(r"use n_intervals = (\d+)", str(info.value)).group(1))
    solution = solve_slew(model, slew_90_problem(better))
    assert solution.cost == pytest.approx(converged_cost("first_order", 4), rel=COST_TOL)


def test_free_hub_slew_ends_where_momentum_puts_the_hub():
    """A free hub's centre is not a terminal constraint (the torque exerts no net force), yet
    the optimal slew ends with it at the rest state the model gives: still, and where the
    turn about the fixed centre of mass puts it."""
    import flexctl
    from controllers.slew.slew_nlp import terminal_constraints
    from controllers.slew.trajopt import SlewProblem, solve_slew

    scene = flexctl.load_scene("single-wing-free")
    model = flexctl.build_model(scene.system, 1, variant="first_order")
    layout = model.layout
    problem = SlewProblem(angle=0.5, duration=3.0, torque_bound=20.0, n_intervals=30)
    target = problem.target_state(model)
    rows = terminal_constraints(model, target)
    assert rows.shape == (layout.n_states - 4, layout.n_states)   # all but the centre of mass
    solution = solve_slew(model, problem)
    end = solution.states[:, -1]
    assert np.linalg.norm(target[layout.hub_position]) > 1e-4      # the hub does move
    np.testing.assert_allclose(rows @ (end - target), 0.0, atol=1e-8)
    # the rest follows from the discretised dynamics, within their integration error
    np.testing.assert_allclose(end, target, rtol=0,
                               atol=1e-5 * np.linalg.norm(target[layout.hub_position]))


def test_terminal_constraints_skip_the_modes_a_torque_cannot_reach():
    """Two identical arrays on a pinned hub: the modes that bend both alike are not excited
    by the hub torque and are left out of the end condition; one array: every state is."""
    import flexctl
    from controllers.slew.slew_nlp import terminal_constraints

    scene = flexctl.load_scene("two-array-free")
    pinned = dataclasses.replace(scene.system, hub=dataclasses.replace(scene.system.hub,
                                                                         support="pinned"))
    model = flexctl.build_model(pinned, 2, variant="first_order")
    target = model.rest_state(0.7)
    rows = terminal_constraints(model, target)
    assert rows.shape == (2 * (1 + 2), model.n_states)     # rotation and 2 antisymmetric modes
    single = flexctl.build_model(flexctl.load_scene("slew-90").system, 3, "first_order")
    rows = terminal_constraints(single, single.rest_state(1.0))
    assert rows.shape == (single.n_states, single.n_states)
    assert np.linalg.matrix_rank(rows) == single.n_states


@pytest.mark.parametrize("actuator", ["wheel", "motor"])
def test_terminal_constraints_keep_an_actuators_states(actuator):
    """An actuated design model (a wheel's speed and torque, a motor's current): every
    mechanical mode of one beam is reached through the actuator, and the actuator's states
    keep an end row each."""
    import flexctl
    from controllers.slew.slew_nlp import terminal_constraints
    from flexctl.model import DCMotor, ReactionWheel

    device = (ReactionWheel(inertia=0.01, torque_limit=10.0, speed_limit=200.0,
                            time_constant=0.002) if actuator == "wheel" else
              DCMotor(resistance=1.0, torque_constant=0.05, back_emf_constant=0.05,
                      gear_ratio=50.0, voltage_limit=4.0, rotor_inertia=1e-4))
    model = flexctl.build_model(flexctl.load_scene("slew-90").system, 2, actuator=device)
    rows = terminal_constraints(model, model.rest_state(0.3))
    assert rows.shape == (model.n_states, model.n_states)
    assert np.linalg.matrix_rank(rows) == model.n_states


@pytest.mark.parametrize("bad", [np.zeros(3), np.full(6, np.nan), "rest", np.full(6, np.inf)])
def test_terminal_constraints_refuse_a_bad_target_by_name(bad):
    import flexctl
    from controllers.slew.slew_nlp import terminal_constraints

    model = flexctl.build_model(flexctl.load_scene("slew-90").system, 2, "first_order")
    with pytest.raises((TypeError, ValueError), match="target"):
        terminal_constraints(model, bad)


def test_a_scene_sets_the_effort_tolerance_its_refusal_names(monkeypatch):
    """From the scene as from Python: controller.effort_tolerance reaches the slew's checks."""
    from controllers import from_spec

    def would_solve(*args):
        raise _WouldSolve

    monkeypatch.setattr(trajopt, "transcribe", would_solve)
    settings = {"model.variant": "first_order", "model.design_modes": "4",
                "controller.kind": "trajopt", "controller.n_intervals": "40"}
    with pytest.raises(ValueError, match=r"controller\.effort_tolerance") as info:
        from_spec(flexctl.load_scene("slew-90", overrides=settings))
    value = re.search(r"effort_tolerance = ([0-9.]+) ", str(info.value)).group(1)
    with pytest.raises(_WouldSolve):
        from_spec(flexctl.load_scene("slew-90", overrides={
            **settings, "controller.effort_tolerance": value}))
