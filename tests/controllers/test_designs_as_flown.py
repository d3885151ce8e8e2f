"""A scene's design is the one it asks for, and a study flies that one design.

Contracts checked:

- a setting the design would not use is refused by name (the estimator's measurement noise
  of ``lqg`` and ``nmpc`` when the scene has ``[sensors]``, whose noise models set the
  filter; an NMPC ``estimator = "state"`` behind sensors; a spin rate for a wheel's LQR);
- ``kind = "lqg"`` with ``[sensors]`` is an LQG: the Kalman filter of the readings uses its
  ``process_torque`` (the process noise covariance scales as its square);
- a Monte Carlo of a slew scene designs once on the nominal plant: the filter every dispersed
  run uses is the nominal one (its discrete matrices identical across samples), not one
  rebuilt from the dispersed truth;
- a per-appendage dispersion moves that appendage alone; a common stiffness factor ``s``
  scales every hub-free frequency of a structure by ``sqrt(s)``;
- the study's summary carries the spread of its metrics.
"""

import dataclasses
import math
import warnings

import numpy as np
import pytest

import flexctl
from controllers import (Dispersion, FilterModel, Observed, RobustnessTask, disperse, from_spec,
                         robustness_summary, spread_statistics)
from flexctl.app.scenes import SceneError

#: Frequencies agree to this relative tolerance (rounding of the eigenproblems).
FREQUENCY_RTOL = 1e-9
#: A cheap wheel-slew: 2 modes per array in the plant, 1 in the design.
CHEAP = {"model.modes": 2, "model.design_modes": 1}


def _wheel_slew(**overrides):
    return flexctl.load_scene("wheel-slew", overrides={**CHEAP, **overrides})


def _quiet_from_spec(scene, plant=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return from_spec(scene, plant)


@pytest.mark.parametrize("overrides,named", [
    ({"controller.kind": "lqg", "controller.angle_noise": 0.01}, "controller.angle_noise"),
    ({"controller.kind": "lqg", "controller.moment_noise": 0.5}, "controller.moment_noise"),
    ({"controller.kind": "nmpc", "controller.estimator": "state"}, "controller.estimator"),
    ({"controller.kind": "nmpc", "controller.angle_noise": 0.01}, "controller.angle_noise"),
    ({"controller.kind": "lqr", "controller.spin_rate": 0.5}, "controller.spin_rate"),
], ids=["lqg-angle-noise", "lqg-moment-noise", "nmpc-state", "nmpc-noise", "wheel-spin"])
def test_a_setting_the_design_would_ignore_is_refused_by_name(overrides, named):
    with pytest.raises(SceneError, match=rf"{named} \(kind '\w+'\) (is not used|must be 0)"):
        from_spec(_wheel_slew(**overrides))


def test_sensors_an_open_loop_kind_would_not_read_are_refused():
    with pytest.raises(SceneError, match="sensors: controller kind 'zv' plays its torque open "
                                         "loop and reads no sensor"):
        from_spec(_wheel_slew(**{"controller.kind": "zv"}))


def test_noise_settings_of_an_nmpc_on_the_exact_state_are_refused():
    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": "nmpc",
                                                     "controller.process_torque": 0.2})
    with pytest.raises(SceneError, match="controller.process_torque \\(kind 'nmpc'\\) is not "
                                         "used with estimator = \"state\""):
        from_spec(scene)


def test_lqg_with_sensors_is_an_lqg_with_its_process_noise():
    lqr = _quiet_from_spec(_wheel_slew())
    lqg = _quiet_from_spec(_wheel_slew(**{"controller.kind": "lqg",
                                          "controller.process_torque": 0.3}))
    assert isinstance(lqg.controller, Observed) and lqg.controller.process_noise == 0.3
    assert lqg.info["design"].startswith("LQG") and lqg.info["process_noise"] == 0.3
    plant = _wheel_slew().build_model()
    x0 = np.zeros(plant.n_states)
    q_lqr = lqr.controller.start(plant, x0).matrices.Q
    q_lqg = lqg.controller.start(plant, x0).matrices.Q
    n = plant.n_states          # the plant block (the gyro bias follows it)
    ratio = (0.3 / lqr.controller.process_noise) ** 2
    np.testing.assert_allclose(q_lqg[:n, :n], ratio * q_lqr[:n, :n], rtol=1e-12, atol=0.0)


def test_a_monte_carlo_designs_once_and_keeps_the_nominal_filter():
    scene = _wheel_slew()
    calls = []

    def factory(scene, plant):
        calls.append(plant)
        return _quiet_from_spec(scene, plant)

    task = RobustnessTask.from_scene(scene, factory, Dispersion(youngs_modulus=0.1))
    assert len(calls) == 1 and isinstance(task.controller.model, FilterModel)
    nominal = scene.build_model()
    x0 = np.zeros(nominal.n_states)
    kept = task.controller.start(nominal, x0).matrices
    for seed in (3, 4):
        factors = task.dispersion.draw(seed)
        plant = flexctl.build_model(disperse(task.system, **factors), task.n_modes,
                                    task.variant, actuator=scene.actuator)
        flown = task.controller.start(plant, x0).matrices
        for name in ("Ad", "Bd", "C", "Q", "R"):
            np.testing.assert_array_equal(getattr(flown, name), getattr(kept, name))
        # the filter a per-sample design would have built knows the dispersed truth
        rebuilt = Observed(task.controller.law, task.controller.sensors,
                           task.controller.sample_time).start(plant, x0).matrices
        assert not np.allclose(rebuilt.Ad, kept.Ad, rtol=1e-9, atol=0.0)


def test_the_monte_carlo_of_a_wheel_slew_flies_and_reports_its_spread():
    scene = _wheel_slew()
    task = RobustnessTask.from_scene(scene, _quiet_from_spec, Dispersion())
    rows = [task(sample=k, seed=100 + k) for k in range(2)]
    for row in rows:
        assert row["status"] == "ok" and row["closed_loop_stable"]
        assert row["spectral_abscissa"] < 0.0
        assert abs(row["final_error"]) < 0.01 * scene.maneuver.angle
    summary = robustness_summary(rows)
    assert summary.n_samples == summary.n_stable == 2
    spread = summary.spread["residual_vibration"]
    values = [row["residual_vibration"] for row in rows]
    assert spread["n"] == 2 and spread["min"] == min(values) and spread["max"] == max(values)
    assert spread["mean"] == pytest.approx(np.mean(values))
    # the margins are the sampled loop's as it flies on each plant, the nominal filter in it
    assert 1.0 < summary.worst_gain_margin < math.inf and summary.worst_phase_margin > 0.0
    assert summary.spread["gain_margin"]["n"] == 2
    assert spread_statistics([{"residual_vibration": math.nan}]) == {}


def test_a_per_appendage_factor_moves_that_appendage_alone():
    system = flexctl.load_scene("two-array-slew").system
    stiff = disperse(system, youngs_modulus_scale=1.21)
    nominal = flexctl.build_model(system, 2).natural_frequencies(hub="free")
    np.testing.assert_allclose(flexctl.build_model(stiff, 2).natural_frequencies(hub="free"),
                               1.1 * nominal, rtol=FREQUENCY_RTOL)
    one = disperse(system, appendage_scales={"wing_b": {"youngs_modulus_scale": 0.5,
                                                        "point_mass_scale": 2.0}})
    assert one.appendages[0] == system.appendages[0]
    assert one.appendages[1].beam.youngs_modulus == 0.5 * system.appendages[1].beam.youngs_modulus
    assert one.appendages[1].masses[0].mass == 2.0 * system.appendages[1].masses[0].mass


def test_per_appendage_spreads_leave_the_common_draws_as_they_were():
    plain = Dispersion(youngs_modulus=0.1).samples(5, seed=2)
    own = Dispersion(youngs_modulus=0.1,
                     appendages={"wing_a": {"point_mass": 0.3}}).samples(5, seed=2)
    for a, b in zip(plain, own):
        assert {k: b[k] for k in a} == a
        assert abs(b["wing_a.point_mass_scale"] - 1.0) <= 0.3


@pytest.mark.parametrize("make,match", [
    (lambda: Dispersion(appendages={"wing_a": {"density": 0.1}}),
     r"dispersion.appendages\['wing_a'\] parameter must be one of youngs_modulus, point_mass"),
    (lambda: Dispersion(appendages={"wing_a": {"youngs_modulus": 1.5}}),
     r"dispersion.appendages\['wing_a'\].youngs_modulus must be < 1"),
    (lambda: disperse(flexctl.load_scene("two-array-slew").system,
                      appendage_scales={"boom": {"youngs_modulus_scale": 0.5}}),
     "disperse.appendage_scales must name appendages of the structure"),
    (lambda: robustness_summary([{"closed_loop_stable": True}]),
     "row 0 must hold the columns closed_loop_stable, spectral_abscissa"),
], ids=["parameter", "spread", "appendage", "columns"])
def test_bad_dispersions_are_refused_naming_them(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_an_asymmetric_plant_is_judged_through_the_nominal_filter():
    """The nominal twin arrays hide their anti-phase modes from the hub's sensors, and the
    nominal filter leaves them alone. One array 20 % softer couples them to the hub: the law
    on the true state still holds the loop, but the loop as it flies, the nominal filter
    feeding the law, grows; the study and check_loop both judge the loop that flies."""
    from controllers import check_loop

    scene = _wheel_slew()
    task = dataclasses.replace(RobustnessTask.from_scene(scene, _quiet_from_spec),
                               dispersion=None, slew_time=None)
    soft = {"wing_b": {"youngs_modulus_scale": 0.8}}
    assert task()["closed_loop_stable"]                              # the nominal plant
    row = task(appendage_scales=soft)
    assert row["wing_b.youngs_modulus_scale"] == 0.8
    assert not row["closed_loop_stable"] and row["spectral_abscissa"] > 0.0
    plant = flexctl.build_model(disperse(task.system, appendage_scales=soft), task.n_modes,
                                task.variant, actuator=scene.actuator)
    assert check_loop(plant, task.controller.law).stable      # the law on the true state
    flown = check_loop(plant, task.controller)                # the loop as it flies
    assert not flown.stable
    assert flown.spectral_abscissa == pytest.approx(row["spectral_abscissa"], rel=1e-9)


def test_a_design_warning_names_the_users_line_not_ours():
    scene = flexctl.load_scene("slew-90", overrides={"controller.kind": "lqr"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from_spec(scene)                                     # the reference is stretched
    stretched = [w for w in caught if "stretched" in str(w.message)]
    assert stretched and all(w.filename == __file__ for w in stretched)
