"""Exports in single precision: no double left in the C, float within its rounding of double,
the closed loop unchanged within a stated fraction, and refusals where float breaks a law."""

import shutil
import warnings

import numpy as np
import pytest

import flexctl
from controllers import NMPC, from_spec
from controllers.codegen import ExportRefused, export_c, program_for
from controllers.codegen.conditioning import (FLOAT_REFUSE_LOSS, FLOAT_WARN_LOSS,
                                              PrecisionWarning, check_float, float_findings)
from controllers.codegen.precision import EPSILON, single_precision_code
from flexctl.app.cli import main
from flexctl.model.errors import InputTypeError, InputValueError

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")

#: Largest change single precision may make to a slew's residual vibration and pointing
#: error after the manoeuvre, as a fraction of the double run's: a thousandth, three orders
#: above float's epsilon times the loop's amplification seen in the runs.
LOOP_FRACTION = 1e-3
#: Largest difference of a float command from the double one, as a fraction of the
#: actuator's torque bound: a ten-thousandth (the float's seven digits, less three for the
#: cancellation in K (x - r(t)) near the reference).
STEP_FRACTION = 1e-4


def _scene(kind, **overrides):
    return flexctl.load_scene("slew-90", {"controller.kind": kind, **overrides})


def test_float_source_has_no_double_left(tmp_path):
    scene = _scene("pd")
    plant = scene.build_model()
    law = from_spec(scene, plant).controller
    exported = export_c(law, plant, tmp_path, precision="float")
    header, source = exported.header.read_text(), exported.source.read_text()
    assert "typedef float flexctl_real;" in header
    assert "flexctl_real t, const flexctl_real *x, flexctl_real *u" in header
    assert "double" not in source.replace("aligned for double", "")
    assert "fmaxf(" in source and " fmax(" not in source
    assert "-Wdouble-promotion" in (tmp_path / "Makefile").read_text()
    compiled = exported.compile()            # -Wdouble-promotion at -Werror
    assert compiled.step(0.0, np.zeros(plant.n_states))[1] == 0
    # literals in strings are left alone, qrqp's double zero thresholds raised
    assert single_precision_code('x = 1e-12 * y; s = "2.0";') == 'x = 1e-06f * y; s = "2.0";'


@pytest.mark.parametrize("kind", ["pd", pytest.param("trajopt+lqr", marks=pytest.mark.slow)])
def test_float_step_is_double_within_a_fraction_of_the_bound(kind, tmp_path):
    """Each float command is the double one within STEP_FRACTION of the torque bound, on the
    states of the law's slew (the rounding of K (x - r(t)) where x nears r). The LQR on the
    poly7 reference is left to the loop test: the polynomial's float evaluation cancels
    (coefficients 35, -84, 70, -20), its commands differ by more."""
    scene = _scene(kind)
    plant = scene.build_model()
    law = from_spec(scene, plant).controller
    laws = {p: export_c(law, plant, tmp_path / p, precision=p).compile()
            for p in ("double", "float")}
    result = flexctl.simulate(plant, 4.0, controller=law)
    picks = np.linspace(0, result.t.size - 1, 60).astype(int)
    worst = 0.0
    for t_k, x in zip(result.t[picks], result.states[:, picks].T):
        double, _ = laws["double"].step(t_k, x)
        single, code = laws["float"].step(t_k, x)
        assert code == 0
        worst = max(worst, abs(single - double))
    bound = scene.maneuver.torque_bound
    assert EPSILON["float"] * 1e-3 < worst <= STEP_FRACTION * bound, worst


def test_float_in_the_loop_leaves_the_slew_as_double(tmp_path):
    """A sampled LQR on the exact plant: float changes the residual vibration and the
    pointing error by less than LOOP_FRACTION of the double run's."""
    from flexctl.app.export_precision import compare_precisions

    scene = _scene("lqr", **{"controller.sample_time": 0.01, "model.modes": 2,
                             "simulation.t_final": 4.0})
    comparison = compare_precisions(scene)
    assert comparison["plant_variant"] == "exact"
    double, single, diff = comparison["double"], comparison["float"], comparison["difference"]
    assert double["status"] == single["status"] == "ok"
    for key in ("residual_vibration", "pointing_error"):
        assert abs(diff[key]) <= LOOP_FRACTION * double[key], (key, diff[key], double[key])
    assert 0.0 < diff["max_command"] < 6.0 * LOOP_FRACTION      # N m, of a 6 N m bound


@pytest.mark.slow
def test_float_nmpc_follows_python_on_its_own_loop(tmp_path):
    """The NMPC with its QP in float: no QP fails on the states of the Python loop, and each
    command stays within the QP's float tolerance of the Python (double) law's."""
    scene = _scene("nmpc", **{"model.design_variant": "first_order"})
    plant = scene.build_model()
    mpc = from_spec(scene, plant).controller
    exported = export_c(mpc, plant, tmp_path, precision="float")
    finding, = float_findings(exported.program)
    assert finding.quantity == "QP Hessian" and finding.verdict == "ok"
    compiled = exported.compile()
    result = flexctl.simulate(plant, 3.0, controller=mpc)
    session = mpc.start(plant, np.zeros(plant.n_states))
    samples = np.arange(0.0, 3.0 - 1e-9, mpc.sample_time)
    states = np.array([np.interp(samples, result.t, row) for row in result.states]).T
    worst = 0.0
    for t_k, x in zip(samples, states):
        expected = session.step(t_k, x)
        got, code = compiled.step(t_k, x)
        assert code == 0, f"float QP failed at t = {t_k:g} s"
        worst = max(worst, abs(got - expected))
    # the plan's relative error is bounded by cond(H) eps; the torque limit is 6 N m
    assert worst <= 6.0 * finding.loss, worst


def test_float_refused_for_an_ill_conditioned_qp(tmp_path):
    """An angle weighted 1e12 times the rest and a free torque: the QP Hessian's condition
    leaves float no digit; the double export is unaffected."""
    plant = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2,
                                variant="first_order")
    weights = np.r_[1e6, np.full(plant.n_states - 1, 1e-6)]
    mpc = NMPC(model=plant, target=1.0, torque_limit=5.0, state_weights=weights,
               torque_weight=1e-12)
    with pytest.raises(ExportRefused, match=r"float.*condition number.*export it in double"):
        export_c(mpc, plant, tmp_path / "f", precision="float")
    assert not (tmp_path / "f").exists() or not any((tmp_path / "f").iterdir())
    program = program_for(mpc, plant)
    assert program.info["qp_hessian_condition"] * EPSILON["float"] >= FLOAT_REFUSE_LOSS
    assert program.info["qp_hessian_condition"] * EPSILON["double"] < 1e-6


def test_float_warns_between_the_limits():
    from controllers.codegen import ControllerProgram

    plant = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2)
    program = program_for(from_spec(_scene("pd"), plant).controller, plant)
    assert float_findings(program) == ()
    middle = np.sqrt(FLOAT_WARN_LOSS * FLOAT_REFUSE_LOSS) / EPSILON["float"]
    warned = ControllerProgram(**{**program.__dict__, "info": {"qp_hessian_condition": middle}})
    with pytest.warns(PrecisionWarning, match="QP Hessian"):
        found = check_float(warned)
    assert found[0].verdict == "warn"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_float(program)


def test_precision_is_checked(tmp_path, capsys):
    plant = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2)
    law = from_spec(_scene("pd"), plant).controller
    with pytest.raises(InputValueError, match=r"precision must be one of .*got 'single'"):
        export_c(law, plant, tmp_path, precision="single")
    with pytest.raises(InputTypeError, match="precision must be a string"):
        export_c(law, plant, tmp_path, precision=32)
    assert main(["export", "slew-90", "--precision", "half"]) == 2
    assert "invalid choice: 'half'" in capsys.readouterr().err


def test_cli_exports_in_float(tmp_path, capsys):
    import json

    out = tmp_path / "f"
    assert main(["export", "slew-90", "--set", "controller.kind=lqr", "--precision", "float",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "export.json").read_text())
    assert summary["precision"] == "float" and summary["compiled"]
    assert summary["float_conditioning"] == []
    # the float law against its double program near rest: float's rounding (the poly7
    # reference's cancellation), not double's 1e-12
    assert 1e-12 < summary["check_max_difference"] < STEP_FRACTION * 10
    assert "typedef float flexctl_real;" in (out / "flexctl_ctrl.h").read_text()
    assert "precision: float" in capsys.readouterr().out


def test_a_filter_is_judged_by_its_correlations_not_its_units():
    """flexible-link's Kalman filter mixes states in rad, m and rad/s: its covariance's condition
    number is float's limit many times over from the units alone; float rounds each entry
    relative to itself, so the check reads the correlation matrix, and passes it."""
    from controllers.codegen.conditioning import SETTLE_STEPS

    scene = flexctl.load_scene("flexible-link")
    plant = scene.build_model()
    program = program_for(from_spec(scene, plant).controller, plant)
    n = program.info["filter_states"]
    session = program.session()
    for k in range(SETTLE_STEPS):
        session.step(k * program.sample_time, np.zeros(program.n_in))
    p = session.memory[n:n + n * n].reshape(n, n, order="F")
    assert np.linalg.cond(p) * EPSILON["float"] >= FLOAT_REFUSE_LOSS      # units alone
    finding, = float_findings(program)
    assert finding.quantity == "filter covariance's correlation"
    assert finding.verdict == "ok" and finding.condition < 1e3


def test_float_warns_where_the_feedforward_jumps_on_samples(tmp_path):
    """The tracker sampled at 0.01 s: its optimised holds end on samples; float's time decides
    the side of each jump, and the export says so."""
    scene = _scene("trajopt+lqr", **{"controller.sample_time": 0.01})
    plant = scene.build_model()
    law = from_spec(scene, plant).controller
    with pytest.warns(PrecisionWarning, match="jumps fall on samples"):
        exported = export_c(law, plant, tmp_path, precision="float")
    finding = float_findings(exported.program)[0]
    assert finding.count > 0 and finding.verdict == "warn"
    holds = np.asarray(exported.program.info["switch_times"])
    assert np.min(np.abs(holds / 0.01 - np.round(holds / 0.01))) < 1e-6


def test_float_writes_numbers_below_its_range_as_zero(tmp_path):
    """wheel-slew's filter holds couplings of 1e-50 and less, under float's smallest normal
    number: written as zero, the float export builds at -Werror (no truncated constant)."""
    import re

    from controllers.codegen.precision import FLOAT_MIN

    scene = flexctl.load_scene("wheel-slew")
    plant = scene.build_model()
    law = from_spec(scene, plant).controller
    double = export_c(law, plant, tmp_path / "d").source.read_text()
    tiny = [v for v in map(float, re.findall(r"\d\.\d+e-\d+", double)) if 0 < v < FLOAT_MIN]
    assert tiny, "the double export has no number below float's range"
    exported = export_c(law, plant, tmp_path / "f", precision="float")
    compiled = exported.compile()
    assert compiled.step(0.0, np.zeros(exported.program.n_in))[1] == 0
