"""Compiled fixed-step RK4 (method="rk4"): accuracy, error estimate, breakpoints, stops."""

import dataclasses
import warnings

import numpy as np
import pytest

import flexctl
from controllers import PD
from flexctl.model.errors import InputError
from flexctl.sim import compile_cache
from flexctl.sim.compiled import input_numbers
from flexctl.sim.fixed_step import (RK4_FIRST_OMEGA_H, RK4_OMEGA_H, RK4_STABILITY, hermite,
                                    integrate_fixed_step, step_times)
from flexctl.sim.maneuvers import SineTorque
from flexctl.sim.stops import tip_rows


@pytest.fixture(scope="module")
def kane():
    scene = flexctl.load_scene("kane-spinup")
    reference = flexctl.simulate(flexctl.build_model(scene.system, n_modes=8), 30.0,
                                 hub_motion=scene.maneuver, rtol=1e-10)
    return scene, reference


def test_step_pair_stays_inside_rk4_stability():
    # the coarse run of the first pair has twice the returned run's omega h
    assert 2.0 * RK4_FIRST_OMEGA_H < RK4_STABILITY
    assert RK4_OMEGA_H < RK4_FIRST_OMEGA_H


def test_unstable_first_step_is_refined_not_reported_as_divergence():
    # a first pair whose steps are outside RK4's stability interval for the fastest mode
    # (omega h = 3 and 6) blows up: it is the integrator's instability, not the beam's, so
    # the step is halved down to the resolved one; a run that gives up there is returned
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=3)
    omega = float(model.natural_frequencies(0.0, hub="free")[-1])
    y0 = np.zeros(model.n_states)
    y0[model.layout.names.index("q3")] = 1e-4       # the fastest mode rings
    tips = tip_rows(model, model.layout)
    edges, t_out = np.array([0.0, 3.0]), np.linspace(0.0, 3.0, 31)
    run = integrate_fixed_step(model, edges, t_out, y0, tips, 3.0 / omega, 1e-2,
                               h_resolved=RK4_OMEGA_H / omega)
    assert np.all(np.isfinite(run.states))
    assert omega * run.h <= RK4_OMEGA_H * (1 + 1e-9)
    # its estimate bounds its difference from a run that starts resolved
    resolved = integrate_fixed_step(model, edges, t_out, y0, tips, 0.25 / omega, 1e-2)
    assert np.max(np.abs(tips @ (run.states - resolved.states))) <= run.error
    given_up = integrate_fixed_step(model, edges, t_out, y0, tips, 3.0 / omega, 1e-2,
                                    h_resolved=3.0 / omega)
    assert not np.all(np.isfinite(given_up.states))


def test_kane_spinup_within_one_percent_of_converged(kane):
    scene, reference = kane
    model = flexctl.build_model(scene.system, n_modes=2)
    run = flexctl.simulate(model, 30.0, hub_motion=scene.maneuver, method="rk4")
    assert run.ok and run.method == "rk4"
    assert np.allclose(run.t, reference.t)
    error = np.max(np.abs(run.tip_deflection - reference.tip_deflection))
    assert error < 0.01 * reference.peak_tip_deflection
    # the estimate bounds the integration error (against the same 2-mode model, converged)
    tight = flexctl.simulate(model, 30.0, hub_motion=scene.maneuver, rtol=1e-11)
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    assert run.integration_error is not None
    assert actual <= run.integration_error
    assert run.integration_error <= 1e-2 * run.peak_tip_deflection


def test_tolerance_drives_step_halving(kane):
    scene, _ = kane
    model = flexctl.build_model(scene.system, n_modes=3)
    loose = flexctl.simulate(model, 30.0, hub_motion=scene.maneuver, method="rk4", rtol=1e-2)
    tight = flexctl.simulate(model, 30.0, hub_motion=scene.maneuver, method="rk4", rtol=1e-7)
    assert tight.n_evaluations > loose.n_evaluations
    assert tight.integration_error <= 1e-7 * tight.peak_tip_deflection or \
        "halvings" in tight.message


def test_closed_loop_with_saturation_and_reference():
    system = flexctl.load_scene("slew-90").system
    model = flexctl.build_model(system, n_modes=4, variant="first_order")
    x0 = np.zeros(model.n_states)
    x0[0] = -np.pi / 2
    pd = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    reference = flexctl.simulate(model, 6.0, controller=pd, x0=x0, rtol=1e-11)
    run = flexctl.simulate(model, 6.0, controller=pd, x0=x0, method="rk4", rtol=1e-3)
    assert run.ok
    actual = np.max(np.abs(run.tip_deflection - reference.tip_deflection))
    assert actual <= run.integration_error
    assert actual < 1e-3 * reference.peak_tip_deflection
    assert np.allclose(run.torque, reference.torque, atol=1e-3 * 6.0)


def test_breakpoints_are_step_boundaries():
    # a sine pulse that ends at 2 s: the run restarts there, so the torque after it is zero
    system = flexctl.load_scene("spacecraft-torque").system
    model = flexctl.build_model(system, n_modes=3)
    torque = SineTorque(peak_torque=50.0, duration=2.0)
    run = flexctl.simulate(model, 5.0, torque=torque, method="rk4", rtol=1e-4)
    reference = flexctl.simulate(model, 5.0, torque=torque, rtol=1e-11)
    assert run.ok
    error = np.max(np.abs(run.tip_deflection - reference.tip_deflection))
    assert error <= max(run.integration_error, 1e-4 * reference.peak_tip_deflection)
    starts, sizes, ends = step_times([0.0, 2.0, 5.0], 0.3)
    assert np.isclose(starts[ends[0]] + sizes[ends[0]], 2.0)


def test_hermite_reproduces_cubic():
    t = np.linspace(0.0, 1.0, 5)
    starts, sizes, _ = step_times(t, 0.25)
    poly = lambda s: 1.0 + 2.0 * s - 3.0 * s ** 2 + 0.5 * s ** 3
    dpoly = lambda s: 2.0 - 6.0 * s + 1.5 * s ** 2
    nodes = np.r_[starts, 1.0]
    out = np.linspace(0.0, 1.0, 37)
    dense = hermite(out, starts, sizes, poly(nodes)[None], dpoly(nodes)[None])
    assert np.allclose(dense[0], poly(out), atol=1e-12)


def test_divergence_is_reported_with_reason():
    # zero_order drops dynamic stiffening: spun above its first clamped frequency it buckles
    scene = flexctl.load_scene("kane-spinup")
    model = flexctl.build_model(scene.system, n_modes=2, variant="zero_order")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = flexctl.simulate(model, 30.0, hub_motion=scene.maneuver, method="rk4")
    assert run.status == "diverged"
    assert np.all(np.isfinite(run.states))


def test_python_inputs_refused():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    # (a torque of the state CasADi cannot trace: a branch on t; a traceable one runs
    # compiled, and so does a function of time alone, sampled)
    with pytest.raises(InputError, match="rk4"):
        flexctl.simulate(model, 1.0, torque=lambda t, x: 0.1 if t < 0.5 else 0.0 * x[0],
                         method="rk4")


def test_threads_sharing_the_compiled_loops_get_their_own_runs():
    """Runs on threads share one model's compiled rk4 loops and CVODES integrators (the gains
    are parameters): each thread's run is the one it makes alone."""
    from concurrent.futures import ThreadPoolExecutor

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 2)
    x0 = np.zeros(model.n_states)
    x0[0] = -0.5
    gains = [(3.0 + k, 2.0 + 0.5 * k) for k in range(6)]

    def run(gain, method):
        return flexctl.simulate(model, 3.0, controller=PD(kp=gain[0], kd=gain[1]), x0=x0,
                                method=method, check_validity=False).states

    for method in ("rk4", "cvodes"):
        alone = [run(gain, method) for gain in gains]
        with ThreadPoolExecutor(max_workers=3) as pool:
            together = list(pool.map(lambda gain: run(gain, method), gains * 2))
        for k, states in enumerate(together):
            np.testing.assert_array_equal(states, alone[k % len(gains)], err_msg=method)


@pytest.mark.parametrize("drive", ["hub_motion", "controller"])
def test_exact_model_steps_compiled_and_agree_with_cvodes(drive, monkeypatch):
    # the exact variant's RK4 step runs as machine code; the same run on CasADi's virtual
    # machine and a tight CVODES run agree with it
    from flexctl.sim import fixed_step

    scene = flexctl.load_scene("kane-spinup" if drive == "hub_motion" else "slew-90")
    model = flexctl.build_model(scene.system, n_modes=2, variant="exact")
    if drive == "hub_motion":
        t_final, inputs = 10.0, {"hub_motion": scene.maneuver}
    else:
        x0 = np.zeros(model.n_states)
        x0[0] = -np.pi / 2
        t_final, inputs = 4.0, {"controller": PD(kp=12.0, kd=8.0, torque_limit=6.0), "x0": x0}
    run = flexctl.simulate(model, t_final, method="rk4", rtol=1e-4, check_validity=False,
                           **inputs)
    # the step's library takes the model's numbers as an input: a stiffer beam of the same
    # structure calls the same library (no compile, no load), with its own numbers
    stiffer = dataclasses.replace(scene.system, beam=dataclasses.replace(
        scene.system.beam, youngs_modulus=1.1 * scene.system.beam.youngs_modulus))
    other = flexctl.build_model(stiffer, n_modes=2, variant="exact")
    before = dict(compile_cache.STATS)
    drives = (None, inputs.get("hub_motion"), inputs.get("controller"))
    fixed_step.step_function(other, *drives, input_numbers(drives).size)
    assert compile_cache.STATS["compiles"] == before["compiles"]
    assert compile_cache.STATS["loads"] == before["loads"]
    assert compile_cache.STATS["hits"] == before["hits"] + 1
    stiff_run = flexctl.simulate(other, t_final, method="rk4", rtol=1e-4, check_validity=False,
                                 **inputs)
    stiff_tight = flexctl.simulate(other, t_final, rtol=1e-10, check_validity=False, **inputs)
    assert np.max(np.abs(stiff_run.tip_deflection - stiff_tight.tip_deflection)) \
        <= stiff_run.integration_error
    assert np.max(np.abs(stiff_run.tip_deflection - run.tip_deflection)) \
        > 100.0 * run.integration_error
    tight = flexctl.simulate(model, t_final, rtol=1e-10, check_validity=False, **inputs)
    assert run.ok and run.method == "rk4"
    actual = np.max(np.abs(run.tip_deflection - tight.tip_deflection))
    assert actual <= run.integration_error <= 1e-4 * run.peak_tip_deflection
    monkeypatch.setattr(fixed_step, "USE_JIT", False)
    fixed_step.STEP_CACHE.clear()
    try:
        machine = flexctl.simulate(model, t_final, method="rk4", rtol=1e-4,
                                   check_validity=False, **inputs)
    finally:
        fixed_step.STEP_CACHE.clear()
    assert np.allclose(machine.tip_deflection, run.tip_deflection, rtol=0.0,
                       atol=1e-12 * run.peak_tip_deflection)


def test_a_stop_at_an_output_sample_keeps_the_times_increasing():
    """rk4 past a stopping condition at its first output sample, where SciPy finds no stop
    before it: the sample is the stop's, once."""
    from flexctl.sim.inputs import SampledTorque

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 1)
    run = flexctl.simulate(model, 1.0, torque=SampledTorque([0.0, 1.0], [1e5, 1e5]),
                           method="rk4", check_accuracy=False, check_validity=False)
    assert run.status == "diverged" and np.all(np.diff(run.t) > 0)
