"""The three-axis LQR and LQG as C (issue 44, item 5): the same commands as Python on the
same inputs, the same slew in the loop, in double and in float."""

import shutil
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from spatial_c_check import largest_command_difference
from test_spatial_lqr import TARGET, WEIGHTS, _craft, _pointing

from controllers.codegen import export_c
from controllers.codegen.spatial_program import compiled_spatial_law, spatial_program
from controllers.feedback.spatial_lqr import design_spatial_lqg, design_spatial_lqr
from flexctl import SpatialStructure
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.spatial_loop import simulate_spatial_loop

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")

CRAFT = _craft()


def _laws():
    from controllers.slew.eigenaxis import EigenaxisSlew
    from controllers.slew.reference import SlewProfile

    slew = EigenaxisSlew(axis=(0.6, 0.0, 0.8), inertia=CRAFT.rigid_inertia,
                         profile=SlewProfile(slew_angle=np.radians(20.0), duration=12.0))
    return {"lqr": design_spatial_lqr(CRAFT, WEIGHTS, TARGET, n_modes=1, sample_time=0.1,
                                      torque_limit=0.1),
            "lqg": design_spatial_lqg(CRAFT, WEIGHTS, TARGET, 0.1, n_modes=1,
                                      torque_limit=0.1),
            "lqr_slew": design_spatial_lqr(CRAFT, WEIGHTS, None, n_modes=1, sample_time=0.1,
                                           torque_limit=0.1, reference=slew),
            "lqg_slew": design_spatial_lqg(CRAFT, WEIGHTS, None, 0.1, n_modes=1,
                                           torque_limit=0.1, reference=slew)}


@pytest.mark.parametrize("kind", ["lqr", "lqg", "lqr_slew", "lqg_slew"])
def test_the_c_law_commands_what_python_commands(kind, tmp_path):
    law = _laws()[kind]
    export = export_c(law, None, tmp_path / kind)
    header = (tmp_path / kind / "flexctl_ctrl.h").read_text()
    assert "#define FLEXCTL_NU 3" in header
    compiled = export.compile()
    run = simulate_spatial_loop(CRAFT, 20.0, law, sample_time=0.1, n_modes=2, rtol=1e-8,
                                variant="first_order")
    # the same inputs, sample by sample (the LQG's filter carried along in each)
    assert largest_command_difference(law, compiled_spatial_law(compiled), run.result) < 1e-13
    # in the loop: the same slew, to the integration's tolerance
    flown = simulate_spatial_loop(CRAFT, 20.0, compiled_spatial_law(compiled), sample_time=0.1,
                                  n_modes=2, rtol=1e-8, variant="first_order")
    assert np.max(np.abs(flown.result.states - run.result.states)) < 1e-6
    assert _pointing(flown.result)[-1] < 1e-4


def test_the_program_steps_as_the_law_and_the_float_c_flies_the_slew(tmp_path):
    law = _laws()["lqg"]
    program = spatial_program(law)
    assert program.n_out == 3 and program.input_names == ("qw", "qx", "qy", "qz", "wx", "wy",
                                                          "wz")
    session, python = program.session(), law.start()
    rng = np.random.default_rng(2)
    for k in range(50):
        attitude = TARGET + 0.05 * rng.normal(size=4)
        rate = 0.01 * rng.normal(size=3)
        v = np.concatenate([attitude / np.linalg.norm(attitude), rate])
        np.testing.assert_allclose(session.step(0.1 * k, v), python(0.1 * k, v[0:4], v[4:]),
                                   rtol=1e-12, atol=1e-15)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        compiled = export_c(law, None, tmp_path / "float", precision="float").compile()
    flown = simulate_spatial_loop(CRAFT, 20.0, compiled_spatial_law(compiled),
                                  sample_time=0.1, n_modes=2, rtol=1e-8, variant="first_order")
    assert flown.ok and _pointing(flown.result)[-1] < 1e-4


def test_a_three_axis_export_refuses_what_it_cannot_use(tmp_path):
    law = _laws()["lqr"]
    with pytest.raises(InputValueError, match="keeps its own sample time"):
        export_c(law, None, tmp_path / "a", sample_time=0.2)
    with pytest.raises(InputTypeError, match="SpatialLQR, SpatialLQG, QuaternionFeedback or ScheduledSpatialLQR"):
        spatial_program(object())
    with pytest.raises(InputTypeError, match="compiled three-axis law"):
        compiled_spatial_law(object())
    import dataclasses

    from controllers.codegen.program import ExportRefused
    from controllers.slew.reference import SlewProfile

    planned = dataclasses.replace(law, reference=SimpleNamespace(target=TARGET))
    with pytest.raises(ExportRefused, match="follows a SimpleNamespace"):
        spatial_program(planned)
    slew = _laws()["lqr_slew"].reference
    numeric = dataclasses.replace(slew, profile=SimpleNamespace(
        **{name: getattr(slew.profile, name) for name in ("angle", "rate", "acceleration",
                                                           "end_time")}))
    with pytest.raises(ExportRefused, match="no CasADi form"):
        spatial_program(dataclasses.replace(law, reference=numeric))
    assert isinstance(slew.profile, SlewProfile)
    compiled = export_c(law, None, tmp_path / "b").compile()
    one_array = SpatialStructure(hub=CRAFT.hub, appendages=CRAFT.appendages[:1])
    with pytest.raises(InputValueError, match="no state 'b.qn1'"):
        simulate_spatial_loop(one_array, 1.0, compiled_spatial_law(compiled), sample_time=0.1,
                              n_modes=1)


# --- quaternion feedback and the attitude filter as C, in the loop with a star tracker and a
# gyro (the loop of test_quaternion_loop, shorter)

def _sensors(latency=0.2):
    from flexctl.sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker

    return AttitudeSensors(
        star_tracker=StarTracker(cross_noise=2e-5, boresight_noise=1e-4, sample_time=0.5,
                                 latency=latency),
        gyro=Gyro(angle_random_walk=3e-5, rate_random_walk=1e-6,
                  initial_bias=(2e-4, -1e-4, 1e-4)),
        gyro_sample_time=0.1, seed=5)


def _filter(sensors):
    from controllers.feedback.mekf import AttitudeFilter

    return AttitudeFilter(sensors, attitude=[1, 0, 0, 0], attitude_sigma=1e-3, bias_sigma=5e-4)


def _quaternion_law():
    from controllers.feedback.quaternion import QuaternionFeedback

    return QuaternionFeedback.design(CRAFT.rigid_inertia, 0.5, TARGET, damping=0.9,
                                     integral_time=8.0, torque_limit=0.05)


def _sensed_loop(law, estimator_of=_filter):
    sensors = _sensors()
    return simulate_spatial_loop(CRAFT, 12.0, law, n_modes=1, sensors=sensors,
                                 estimator=estimator_of(sensors), rtol=1e-8,
                                 variant="first_order")


def test_the_c_quaternion_feedback_steps_and_flies_as_python(tmp_path):
    """Its integral (held while the command saturates) and the short way round, sample by
    sample on random readings; then the sensed slew, flown on the same filter."""
    law = _quaternion_law()
    program = spatial_program(law)
    assert program.kind == "quaternion_feedback" and program.input_names[:4] == (
        "qw", "qx", "qy", "qz")
    compiled = export_c(law, None, tmp_path / "qf").compile()
    c_law, python = compiled_spatial_law(compiled).start(), law.start()
    rng = np.random.default_rng(3)
    saturated = 0
    for k in range(200):
        attitude = rng.choice([-1.0, 1.0]) * (TARGET + 0.1 * rng.normal(size=4))
        rate = 0.02 * rng.normal(size=3)
        v = np.concatenate([attitude / np.linalg.norm(attitude), rate])
        expected = python(0.1 * k, v[0:4], v[4:])
        saturated += np.max(np.abs(expected)) >= 0.05 - 1e-15
        np.testing.assert_allclose(c_law(0.1 * k, v[0:4], v[4:]), expected, rtol=1e-12,
                                   atol=1e-15)
    np.testing.assert_allclose(compiled_spatial_law(compiled).start()(0.0, v[0:4], v[4:]),
                               law.start()(0.0, v[0:4], v[4:]), rtol=1e-12)
    assert 20 < saturated < 200
    run, flown = _sensed_loop(law), _sensed_loop(compiled_spatial_law(compiled))
    assert np.max(np.abs(flown.result.torque - run.result.torque)) < 1e-9
    assert np.max(np.abs(flown.result.states - run.result.states)) < 1e-6


def test_the_c_attitude_filter_estimates_as_python_in_double_and_in_float(tmp_path):
    """The filter as C, fed by the loop's sensors (the tracker 0.2 s late: two gyro samples
    replayed at each update): the same estimates as the Python filter sample by sample; in
    float within 1e-6 rad and 1e-7 rad/s."""
    from controllers.codegen.filter_program import compiled_attitude_filter, filter_program

    law = _quaternion_law()
    run = _sensed_loop(law)
    program = filter_program(_filter(_sensors()))
    assert program.kind == "mekf" and program.info["latency_samples"] == 2
    assert program.n_out == 7 and program.sample_time == 0.1
    estimates = {}
    for precision in ("double", "float"):
        compiled = export_c(_filter(_sensors()), None, tmp_path / precision,
                            precision=precision).compile()
        flown = _sensed_loop(law, lambda s: compiled_attitude_filter(compiled))
        assert flown.ok
        estimates[precision] = (
            np.max(np.abs(flown.attitude_estimates - run.attitude_estimates)),
            np.max(np.abs(flown.bias_estimates - run.bias_estimates)))
    print({k: f"{a:.1e} rad, {b:.1e} rad/s" for k, (a, b) in estimates.items()})
    assert estimates["double"][0] < 1e-11 and estimates["double"][1] < 1e-13
    assert estimates["float"][0] < 1e-6 and estimates["float"][1] < 1e-7
    # the filter moved: its bias estimate left zero toward the gyro's
    assert np.linalg.norm(run.bias_estimates[:, -1]) > 5e-5


def test_a_filter_export_refuses_what_it_cannot_write(tmp_path):
    from controllers.codegen.program import ExportRefused
    from controllers.codegen.filter_program import (MAX_FILTER_LAG, compiled_attitude_filter,
                                                    filter_program)

    with pytest.raises(InputTypeError, match="AttitudeFilter"):
        filter_program(object())
    late = _sensors(latency=0.1 * (MAX_FILTER_LAG + 1))
    with pytest.raises(ExportRefused, match="latency spans 21 gyro samples"):
        filter_program(_filter(late))
    moved = _filter(_sensors())
    moved.propagate([0.0, 0.0, 1e-3])
    with pytest.raises(ExportRefused, match="propagated already"):
        filter_program(moved)
    with pytest.raises(InputValueError, match="give neither sample_time"):
        export_c(_filter(_sensors()), None, tmp_path / "a", sample_time=0.1)
    compiled = export_c(_filter(_sensors()), None, tmp_path / "b").compile()
    with pytest.raises(InputTypeError, match="compiled three-axis law"):
        compiled_spatial_law(compiled)
    with pytest.raises(InputTypeError, match="compiled attitude filter"):
        compiled_attitude_filter(object())
    estimator = compiled_attitude_filter(compiled)
    with pytest.raises(InputValueError, match="propagate first"):
        estimator.update([1.0, 0.0, 0.0, 0.0])
    with pytest.raises(InputValueError, match="gyro_reading must be finite"):
        estimator.propagate([0.0, np.nan, 0.0])
    estimator.propagate([0.0, 0.0, 1e-3])
    with pytest.raises(InputValueError, match="non-zero quaternion"):
        estimator.update([0.0, 0.0, 0.0, 0.0])
