"""The optimal rest-to-rest slew of a flexible spacecraft (:mod:`controllers.slew.spatial_trajopt`):
it respects its limits, it ends at rest on its target when flown, it rings the arrays less
than the rigid eigenaxis slew of the same length, and a three-axis LQR follows it."""

import shutil

import numpy as np
import pytest

from controllers.feedback.lqr import LQRWeights
from controllers.feedback.spatial_lqr import design_spatial_lqr
from controllers.slew.eigenaxis import EigenaxisSlew
from controllers.slew.reference import SlewProfile
from controllers.slew.spatial_trajopt import (SpatialSlewProblem, SpatialSlewSolution,
                                              solve_spatial_slew)
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.errors import InputError
from flexctl.model.wheel_cluster import WheelCluster
from flexctl.sim.quaternions import error_angles, from_rotation_vector
from flexctl.sim.spatial_loop import simulate_spatial_loop
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial


def _wing(name, direction):
    return SpatialAppendage(name=name, direction=direction, normal=(0, 0, 1), length=1.8,
                            density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
                            shear_modulus=2.6e10, torsion_constant=1.0e-9,
                            damping_ratio=0.005)


CRAFT = SpatialStructure(hub=SpatialHub(inertia=[[1.3, 0.05, 0.0], [0.05, 1.2, 0.0],
                                                 [0.0, 0.0, 1.4]], radius=0.06),
                         appendages=(_wing("wing_a", (0, 1, 0)), _wing("wing_b", (0, -1, 0))))
AXIS = np.array([0.6, 0.0, 0.8])
ANGLE = np.radians(20.0)
TARGET = from_rotation_vector(ANGLE * AXIS)
WHEELS = WheelCluster.orthogonal(inertia=0.01, torque_limit=0.1, speed_limit=314.16)


def _fly(torque, duration, *, wheels=None, n_modes=1, variant="first_order", after=4.0):
    """Open loop: the pointing error at the end and the largest tip deflection after it."""
    run = simulate_spatial(CRAFT, duration + after, torque, n_modes=n_modes, variant=variant,
                           wheels=wheels, rtol=1e-10, output_step=0.01, check_accuracy=False)
    late = run.t > duration + 1e-9
    at_end = int(np.argmin(np.abs(run.t - duration)))
    residual = max(np.max(np.abs(tip[:, late])) for tip in run.tips.values())
    peak = max(np.max(np.abs(tip)) for tip in run.tips.values())
    return (float(np.linalg.norm(error_angles(TARGET, run.quaternion[:, at_end]))),
            residual, peak)


@pytest.fixture(scope="module")
def plan():
    return solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=12.0,
                                                        n_intervals=60, torque_limit=0.1),
                              n_modes=1)


def test_the_plan_solves_within_its_limits(plan):
    assert isinstance(plan, SpatialSlewSolution) and plan.return_status == "Solve_Succeeded"
    assert np.max(np.abs(plan.torque)) <= 0.8 * 0.1 * (1 + 1e-6)
    assert plan.cost == pytest.approx(plan.problem.duration / 60 * np.sum(plan.torque ** 2),
                                      rel=1e-6)
    # it ends on the target at rest on its design model
    assert np.linalg.norm(error_angles(TARGET, plan.quaternions[-1])) < 1e-8
    assert np.max(np.abs(plan.states[-1])) < 1e-8
    assert np.allclose(np.linalg.norm(plan.quaternions, axis=1), 1.0, atol=1e-12)


def test_flown_open_loop_it_ends_at_rest_on_target_and_converges_with_the_holds():
    """The plan's torque held on the design's own model: pointing error of first order in
    the hold (the remainder held at each hold's start), the arrays still."""
    errors = []
    for holds in (30, 60, 120):
        slew = solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=12.0,
                                                            n_intervals=holds), n_modes=1)
        error, residual, peak = _fly(slew.torque_function(), 12.0)
        errors.append(error)
        assert residual < 0.02 * peak
    print("pointing errors at the end, 30/60/120 holds:", errors)
    assert errors[2] < 2e-4
    assert errors[0] > 1.3 * errors[1] and errors[1] > 1.5 * errors[2]


def test_it_rings_the_arrays_less_than_the_rigid_eigenaxis_slew(plan):
    """The same 12 s slew as a rigid seventh-order eigenaxis profile's feedforward torque,
    flown open loop on the exact rod: the plan ends closer to its target and leaves the
    arrays stiller."""
    rigid = EigenaxisSlew(axis=AXIS, profile=SlewProfile(slew_angle=ANGLE, duration=12.0),
                          inertia=CRAFT.rigid_inertia)
    times = np.linspace(0.0, 12.0, 1201)
    feedforward = VectorTorque(times, np.array([rigid.at(t)[2] for t in times]))
    planned = _fly(plan.torque_function(), 12.0, variant="exact")
    eigenaxis = _fly(feedforward, 12.0, variant="exact")
    print("pointing, residual, peak: planned", planned, "eigenaxis", eigenaxis)
    assert planned[0] < 0.3 * eigenaxis[0]
    assert planned[1] < 0.2 * eigenaxis[1]


def test_the_wheels_limits_hold_and_a_speed_limit_changes_the_plan():
    """With wheels: motor torques within the margin, speeds within theirs; a speed limit
    below the free plan's peak speed is respected at a higher cost."""
    free = solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=12.0,
                                                        n_intervals=60, wheels=WHEELS),
                              n_modes=1)
    assert np.max(np.abs(free.motor_torques)) <= 0.08 * (1 + 1e-6)
    peak = float(np.max(np.abs(free.wheel_speeds)))
    slow = WheelCluster.orthogonal(inertia=0.01, torque_limit=0.1, speed_limit=0.8 * peak / 0.9)
    limited = solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=12.0,
                                                           n_intervals=60, wheels=slow),
                                 n_modes=1)
    assert np.max(np.abs(limited.wheel_speeds)) <= 0.8 * peak * (1 + 1e-6)
    assert limited.cost > free.cost * (1 + 1e-3)
    assert limited.peak_power > 0.0
    # the plan's wheel speeds are those the cluster reaches flown open loop
    run = simulate_spatial(CRAFT, 12.0, limited.torque_function(), n_modes=1,
                           variant="first_order", wheels=slow, rtol=1e-10,
                           output_step=0.2, check_accuracy=False)
    assert np.max(np.abs(run.wheel_speeds.T - limited.wheel_speeds)) < 0.01 * peak


def test_the_reference_is_continuous_and_matches_the_plan_at_its_holds(plan):
    h = plan.problem.duration / plan.problem.n_intervals
    for k in (0, 7, 31, 60):
        state = plan.state_at(k * h)
        assert np.allclose(state[3:], plan.states[k], atol=1e-12)
        assert np.allclose(state[0:3], error_angles(TARGET, plan.quaternions[k]), atol=1e-12)
    # within a hold the state moves continuously into the next knot
    inside = plan.state_at(31 * h - 1e-7)
    assert np.allclose(inside, plan.state_at(31 * h), atol=1e-7 * 10)
    error, rate, torque = plan.at(31.5 * h)
    assert np.allclose(torque, plan.torque[31]) and np.allclose(plan.at(31 * h)[2], plan.torque[31])
    assert np.allclose(plan.at(20.0)[2], 0.0) and np.allclose(plan.state_at(20.0), 0.0,
                                                              atol=1e-8)


def test_an_lqr_follows_the_plan_on_the_exact_plant(plan):
    """Held at the plan's holds (0.2 s), the LQR follows its whole state: on the exact rod
    with two modes per field it ends the slew on target with the arrays still."""
    law = design_spatial_lqr(CRAFT, LQRWeights(hub_angle=0.05, hub_rate=0.05,
                                               tip_deflection=0.005, torque=0.1),
                             None, n_modes=1, sample_time=0.2, torque_limit=0.1,
                             reference=plan)
    loop = simulate_spatial_loop(CRAFT, 16.0, law, sample_time=0.2, n_modes=2,
                                 variant="exact", rtol=1e-8)
    assert loop.ok
    run = loop.result
    at_end = int(np.argmin(np.abs(run.t - 12.0)))
    error = np.linalg.norm(error_angles(TARGET, run.quaternion[:, at_end]))
    late = run.t > 12.0
    residual = max(np.max(np.abs(tip[:, late])) for tip in run.tips.values())
    print(f"pointing at the end {error:.2e} rad, residual tip {residual:.2e} m")
    assert error < 1e-4 and residual < 2e-5


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                    reason="no C compiler")
def test_the_lqr_following_the_plan_as_c_commands_and_flies_as_python(plan, tmp_path):
    """The plan's design state and torque tabulated at its holds' ends in the C: at the
    law's samples (the holds) the same commands as Python, and the same slew, for the LQR
    and the LQG; a law that samples elsewhere is refused with the reason."""
    from controllers.codegen import ExportRefused, export_c
    from controllers.codegen.spatial_program import compiled_spatial_law
    from controllers.feedback.spatial_lqr import design_spatial_lqg
    from spatial_c_check import flown_as_python

    def fly(law):
        return simulate_spatial_loop(CRAFT, 14.0, law, sample_time=0.2, n_modes=1,
                                     variant="first_order", rtol=1e-9).result

    weights = LQRWeights(hub_angle=0.05, hub_rate=0.05, tip_deflection=0.005, torque=0.1)
    laws = {"lqr": design_spatial_lqr(CRAFT, weights, None, n_modes=1, sample_time=0.2,
                                      torque_limit=0.1, reference=plan),
            "lqg": design_spatial_lqg(CRAFT, weights, None, 0.2, n_modes=1, reference=plan)}
    for name, law in laws.items():
        compiled = export_c(law, None, tmp_path / name).compile()
        assert "following a planned slew" in compiled.program.description
        commands, states, _ = flown_as_python(law, compiled_spatial_law(compiled), fly)
        assert commands < 1e-12 and states < 1e-7
    elsewhere = design_spatial_lqr(CRAFT, weights, None, n_modes=1, sample_time=0.1,
                                   reference=plan)
    with pytest.raises(ExportRefused, match=r"samples at the plan's holds \(0.2 s"):
        export_c(elsewhere, None, tmp_path / "d")


@pytest.mark.parametrize("kwargs, pattern", [
    ({"duration": 0.0}, r"spatial_slew\.duration"),
    ({"duration": np.nan}, r"spatial_slew\.duration"),
    ({"n_intervals": 1}, r"spatial_slew\.n_intervals"),
    ({"n_intervals": 10.0}, r"spatial_slew\.n_intervals"),
    ({"target": (0, 0, 0, 0)}, r"spatial_slew\.target must be a non-zero quaternion"),
    ({"target": (1, 0, 0)}, r"spatial_slew\.target"),
    ({"torque_limit": 0.1, "wheels": WHEELS}, r"spatial_slew\.torque_limit bounds"),
    ({"wheel_speeds": (1.0, 2.0, 3.0)}, r"spatial_slew\.wheel_speeds needs wheels"),
    ({"wheels": WHEELS, "wheel_speeds": (300.0, 0.0, 0.0)}, r"wheel_speeds\[0\] must be within"),
    ({"wheels": WHEELS, "wheel_speeds": (1.0, 2.0)}, r"spatial_slew\.wheel_speeds"),
    ({"speed_margin": 0.0}, r"spatial_slew\.speed_margin"),
    ({"torque_margin": 1.5}, r"spatial_slew\.torque_margin"),
    ({"wheels": "three"}, r"spatial_slew\.wheels"),
])
def test_a_bad_problem_is_refused_by_name(kwargs, pattern):
    arguments = {"target": TARGET, "duration": 12.0, **kwargs}
    with pytest.raises(InputError, match=pattern):
        SpatialSlewProblem(**arguments)


def test_a_slew_shorter_than_the_rigid_bang_bang_is_refused():
    with pytest.raises(InputError, match=r"spatial_slew\.duration must be at least [\d.]+ s, "
                                         r"the rigid structure's bang-bang time"):
        solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=1.0,
                                                     torque_limit=0.1), n_modes=1)


def test_a_plan_on_other_modes_is_refused_by_the_law(plan):
    with pytest.raises(InputError, match=r"design_spatial_lqr\.reference was planned on"):
        design_spatial_lqr(CRAFT, LQRWeights(hub_angle=0.05, torque=0.1), None, n_modes=2,
                           sample_time=0.2, reference=plan)


def test_a_null_motion_pyramid_is_planned_with_its_null_torques():
    """A biased pyramid whose distribution adds null-space torques: the plan counts them in
    each wheel's torque (within the margin), its speeds are those the cluster reaches flown
    open loop, and wheels started against their null target are refused before IPOPT."""
    pyramid = WheelCluster.pyramid(angle=54.7356, distribution="null_motion", null_gain=0.2,
                                   bias_speed=30.0, inertia=0.01, torque_limit=0.1,
                                   speed_limit=314.16)
    start = np.array(pyramid.null_target)
    plan = solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=12.0,
                                                        n_intervals=60, wheels=pyramid,
                                                        wheel_speeds=start), n_modes=1)
    assert np.max(np.abs(plan.motor_torques)) <= 0.08 * (1 + 1e-6)
    run = simulate_spatial(CRAFT, 12.0, plan.torque_function(), n_modes=1,
                           variant="first_order", wheels=pyramid, wheel_speeds=start,
                           rtol=1e-10, output_step=0.2, check_accuracy=False)
    drift = np.max(np.abs(run.wheel_speeds.T - plan.wheel_speeds))
    print(f"plan against flight, wheel speeds: {drift:.2e} rad/s")
    assert drift < 0.02 * np.max(np.abs(plan.wheel_speeds - start))
    with pytest.raises(InputError, match=r"null motion asks wheel \d for .* null_gain"):
        solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=12.0,
                                                     wheels=pyramid, wheel_speeds=-start),
                           n_modes=1)


def test_smoothness_softens_the_torque_and_the_lag_it_meets():
    """``smoothness``: the torque starts and ends nearer zero, and through wheels with a
    20 ms motor lag the arrays ring less after the slew (open loop; measured 1.2e-5 m
    against 3.0e-6 m)."""
    lagged = WheelCluster.orthogonal(inertia=0.01, torque_limit=0.1, speed_limit=314.16,
                                     time_constant=0.02)
    found = {}
    for smoothness in (0.0, 1.0):
        plan = solve_spatial_slew(CRAFT, SpatialSlewProblem(
            target=TARGET, duration=12.0, n_intervals=60, wheels=lagged,
            smoothness=smoothness), n_modes=1)
        ends = float(max(np.max(np.abs(plan.torque[0])), np.max(np.abs(plan.torque[-1]))))
        found[smoothness] = (ends, *_fly(plan.torque_function(), 12.0, wheels=lagged)[:2])
    print(found)
    assert found[1.0][0] < 0.3 * found[0.0][0]
    assert found[1.0][2] < 0.5 * found[0.0][2]


@pytest.mark.parametrize("kwargs, pattern", [
    ({"structure": "craft"}, r"solve_spatial_slew\.structure must be a SpatialStructure"),
    ({"ipopt_options": "fast"}, r"solve_spatial_slew\.ipopt_options must be a dict"),
    ({"problem": "slew"}, r"solve_spatial_slew\.problem"),
    ({"variant": "consistent"}, r"solve_spatial_slew\.variant"),
])
def test_bad_arguments_to_the_solver_are_refused_by_name(kwargs, pattern):
    arguments = {"structure": CRAFT, "problem": SpatialSlewProblem(target=TARGET, duration=12.0),
                 "n_modes": 1, **kwargs}
    with pytest.raises(InputError, match=pattern):
        solve_spatial_slew(**arguments)


@pytest.mark.parametrize("sample_time", [0.3, 0.15, 0.07])
def test_a_law_sampling_across_the_plans_holds_is_refused(plan, sample_time):
    """A held law's feedforward is the plan's only when each sample lies within one hold
    (0.2 s here): 0.1 s and 0.2 s are accepted, samples across holds refused by name."""
    weights = LQRWeights(hub_angle=0.05, torque=0.1)
    for fine in (0.1, 0.2):
        design_spatial_lqr(CRAFT, weights, None, n_modes=1, sample_time=fine, reference=plan)
    with pytest.raises(InputError, match=r"design_spatial_lqr\.sample_time must divide the "
                                         r"planned slew's hold \(0.2 s\)"):
        design_spatial_lqr(CRAFT, weights, None, n_modes=1, sample_time=sample_time,
                           reference=plan)
