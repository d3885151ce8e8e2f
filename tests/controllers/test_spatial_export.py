"""The three-axis LQR and LQG as C (issue 44, item 5): the same commands as Python on the
same inputs, the same slew in the loop, in double and in float."""

import shutil
import warnings

import numpy as np
import pytest
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
    return {"lqr": design_spatial_lqr(CRAFT, WEIGHTS, TARGET, n_modes=1, sample_time=0.1,
                                      torque_limit=0.1),
            "lqg": design_spatial_lqg(CRAFT, WEIGHTS, TARGET, 0.1, n_modes=1,
                                      torque_limit=0.1)}


def _inputs(law, result):
    """What the law reads at each sample of a run."""
    layout = result.equations.layout
    c = layout.n_coordinates
    for k, t in enumerate(result.t):
        attitude, rate = result.states[0:4, k], result.states[c:c + 3, k]
        yield (t, attitude, rate, result.states[:, k]) if law.state_feedback else \
            (t, attitude, rate)


def _start(law, names):
    return law.start(names) if law.state_feedback else law.start()


@pytest.mark.parametrize("kind", ["lqr", "lqg"])
def test_the_c_law_commands_what_python_commands(kind, tmp_path):
    law = _laws()[kind]
    export = export_c(law, None, tmp_path / kind)
    header = (tmp_path / kind / "flexctl_ctrl.h").read_text()
    assert "#define FLEXCTL_NU 3" in header
    compiled = export.compile()
    run = simulate_spatial_loop(CRAFT, 20.0, law, sample_time=0.1, n_modes=2, rtol=1e-8,
                                variant="first_order")
    names = run.result.equations.layout.state_names
    python, c_law = _start(law, names), _start(compiled_spatial_law(compiled), names)
    # the same inputs, sample by sample (the LQG's filter carried along in each)
    worst = max(np.max(np.abs(python(*args) - c_law(*args)))
                for args in _inputs(law, run.result))
    assert worst < 1e-13
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
    with pytest.raises(InputTypeError, match="SpatialLQR or SpatialLQG"):
        spatial_program(object())
    with pytest.raises(InputTypeError, match="compiled three-axis law"):
        compiled_spatial_law(object())
    compiled = export_c(law, None, tmp_path / "b").compile()
    one_array = SpatialStructure(hub=CRAFT.hub, appendages=CRAFT.appendages[:1])
    with pytest.raises(InputValueError, match="no state 'b.qn1'"):
        simulate_spatial_loop(one_array, 1.0, compiled_spatial_law(compiled), sample_time=0.1,
                              n_modes=1)
