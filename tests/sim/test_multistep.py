"""CVODES's multistep family: Adams-Moulton for lightly damped oscillations resolved over the
run, BDF where a pole decays fast or the modes lie far above anything the run excites; and
an Adams run's error estimate bounds its actual error."""

import dataclasses

import numpy as np
import pytest

from controllers import PD
from flexctl import SineTorque, build_model, load_scene, simulate
from flexctl.model.errors import InputValueError
from flexctl.sim.compiled import SegmentIntegrator
from flexctl.sim.request import (ADAMS_DAMPING, ADAMS_PHASE, LOOP_FACTOR, choose_multistep)


def _fastest(model) -> float:
    return float(model.natural_frequencies(0.0, hub="free")[-1])


def _with_beam(system, **changes):
    return dataclasses.replace(system, beam=dataclasses.replace(system.beam, **changes))


@pytest.fixture(scope="module")
def slew_system():
    return load_scene("slew-90").system


def test_undamped_slew_takes_adams(slew_system):
    model = build_model(slew_system, 4, "exact")
    assert choose_multistep(model, _fastest(model), 0.0, 6.0) == "adams"


def test_fast_decays_keep_bdf(slew_system):
    model = build_model(slew_system, 4, "first_order")
    omega = _fastest(model)
    # a beam damped beyond the bound: its high modes' poles lie near the real axis
    damped = build_model(_with_beam(slew_system, damping_ratio=1.5 * ADAMS_DAMPING), 4)
    assert choose_multistep(damped, _fastest(damped), 0.0, 6.0) == "bdf"
    # a controller whose gains put the loop's fastest pole far beyond the plant's modes
    assert choose_multistep(model, omega, 1.01 * LOOP_FACTOR * omega, 6.0) == "bdf"
    # hub friction decaying the hub's rate faster than the fastest mode turns
    rubbing = dataclasses.replace(slew_system, hub=dataclasses.replace(
        slew_system.hub, friction=2.0 * omega * model.rigid_inertia))
    rubbed = build_model(rubbing, 4)
    assert choose_multistep(rubbed, _fastest(rubbed), 0.0, 6.0) == "bdf"
    # modes turning far more than ADAMS_PHASE radians: BDF steps over them
    assert choose_multistep(model, omega, 0.0, 1.01 * ADAMS_PHASE / omega) == "bdf"
    assert choose_multistep(model, omega, 0.0, 0.99 * ADAMS_PHASE / omega) == "adams"
    assert choose_multistep(model, float("inf"), 0.0, 1.0) == "bdf"


def test_a_plant_behind_an_actuator_keeps_bdf():
    scene = load_scene("wheel-slew")
    model = build_model(scene.system, 3, actuator=scene.actuator)
    assert choose_multistep(model, _fastest(model), 0.0, 1.0) == "bdf"


def test_adams_run_estimates_its_error(slew_system):
    """slew-90's exact 4-mode plant under a saturated PD: the run takes Adams, its estimate
    bounds its actual error against a run at 1e-11, and that error is within 10 rtol."""
    model = build_model(slew_system, 4, "exact")
    x0 = model.rest_state(-np.pi / 2)
    law = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    options = dict(controller=law, x0=x0, method="cvodes", check_validity=False)
    tight = simulate(model, 6.0, rtol=1e-11, **options)
    run = simulate(model, 6.0, rtol=1e-6, **options)
    assert run.status == "ok" and tight.status == "ok"
    peak = tight.peak_tip_deflection
    actual = float(np.max(np.abs(run.tip_deflection - tight.tip_deflection)))
    assert actual <= 10 * 1e-6 * peak
    assert run.integration_error >= actual


def test_many_modes_agree_under_both_families(hub_beam_mass_system):
    """hub-beam-mass's sine torque on 20 first_order modes over 1 s (Adams) against the
    same run with a long horizon's choice (BDF, the modes turning beyond ADAMS_PHASE)."""
    model = build_model(hub_beam_mass_system, 20)
    torque = SineTorque(peak_torque=2.0, duration=2.0)
    assert choose_multistep(model, _fastest(model), 0.0, 1.0) == "adams"
    adams = simulate(model, 1.0, torque=torque, rtol=1e-8, method="cvodes",
                     check_validity=False)
    tight = simulate(model, 1.0, torque=torque, rtol=1e-11, method="cvodes",
                     check_validity=False)
    peak = tight.peak_tip_deflection
    assert np.max(np.abs(adams.tip_deflection - tight.tip_deflection)) <= 1e-5 * peak


@pytest.mark.parametrize("bad", ["rk45", "BDF", None, 2])
def test_segment_integrator_refuses_an_unknown_family_by_name(slew_system, bad):
    model = build_model(slew_system, 2)
    with pytest.raises(InputValueError, match="multistep"):
        SegmentIntegrator(model, 0.0, np.array([0.5, 1.0]), np.ones(model.n_states), 1e-6,
                          torque=SineTorque(peak_torque=1.0, duration=1.0), multistep=bad)


@pytest.mark.parametrize("bad", [float("nan"), -1.0, "fast", None, True])
def test_choices_refuse_a_bad_rate_by_name(slew_system, bad):
    from flexctl.sim.request import choose_continuous

    model = build_model(slew_system, 2)
    with pytest.raises((InputValueError, TypeError), match="omega_max"):
        choose_continuous(model, 1.0, bad)
    with pytest.raises((InputValueError, TypeError), match="omega_plant"):
        choose_multistep(model, bad, 0.0, 1.0)
    with pytest.raises((InputValueError, TypeError), match="loop_frequency"):
        choose_multistep(model, 1.0, bad, 1.0)


@pytest.mark.parametrize("bad", [float("nan"), -1.0, float("inf"), "long"])
def test_choices_refuse_a_bad_horizon_or_model_by_name(slew_system, bad):
    from flexctl.sim.request import choose_continuous

    model = build_model(slew_system, 2)
    with pytest.raises((InputValueError, TypeError), match="t_final"):
        choose_multistep(model, 1.0, 0.0, bad)
    with pytest.raises((InputValueError, TypeError), match="t_final"):
        choose_continuous(model, bad, 1.0)
    with pytest.raises(TypeError, match="model"):
        choose_multistep(slew_system, 1.0, 0.0, 1.0)
