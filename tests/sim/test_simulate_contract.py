"""What simulate promises about its inputs: a wrong type is a TypeError naming the argument, a
non-finite input value is named as the cause, an absurd output grid or closed loop is refused
at once, a blow-up is reported promptly, and no returned array holds NaN or inf."""

import re
import time

import numpy as np
import pytest

from flexctl import build_model, simulate
from flexctl.model.errors import InputError, InputTypeError, InputValueError
from flexctl.sim.inputs import MAX_OUTPUT_SAMPLES
from flexctl.sim.maneuvers import SineTorque, SpinUp
from flexctl.sim.simulation import LOOP_LIMIT, StiffnessWarning

#: A blow-up that leaves the beam at t = 0.013 s took minutes on the compiled path; it must
#: be reported within this wall time (seconds, generous for a loaded machine).
PROMPT = 30.0
#: Refusals come before any integration: well under this many seconds.
AT_ONCE = 5.0


@pytest.fixture(scope="module")
def model(hub_beam_mass_system):
    return build_model(hub_beam_mass_system, n_modes=2)


class _Motion:
    """A hub motion whose rate turns NaN after ``bad_after`` seconds."""

    def __init__(self, bad_after):
        self.bad_after = bad_after

    def angle(self, t):
        return 0.1 * np.asarray(t) ** 2

    def rate(self, t):
        return float("nan") if t > self.bad_after else 0.2 * t

    def acceleration(self, t):
        return 0.2 * np.ones_like(np.asarray(t, dtype=float))


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"t_final": "3"}, r"t_final must be a real number.*'3'"),
    ({"rtol": "1e-6"}, r"rtol must be a real number.*'1e-6'"),
    ({"output_step": "0.1"}, r"output_step must be a real number"),
    ({"method": 3}, r"method must be one of .*got 3"),
    ({"x0": "abc"}, r"x0 must be 6 numbers"),
    ({"atol": "tight"}, r"atol must be"),
    ({"torque": lambda t: None}, r"torque must return a real number.*None at t = 0 s"),
    ({"torque": lambda t: np.ones(3)}, r"torque must return one real number.*shape \(3,\)"),
    ({"torque": lambda t: "1"}, r"torque must return a real number.*'1'"),
    ({"torque": lambda t, x, y: 1.0}, r"torque must be callable as torque\(t\) or "
     r"torque\(t, x\).*3 required arguments"),
    ({"torque": 3.0}, r"torque must be callable"),
    ({"controller": lambda t, x: [1.0, 2.0]}, r"controller must return one real number"),
], ids=["t_final-str", "rtol-str", "output_step-str", "method-int", "x0-str", "atol-str",
        "torque-None", "torque-array", "torque-str", "torque-3-args", "torque-number",
        "controller-list"])
def test_wrong_types_are_type_errors_naming_the_argument(model, kwargs, match):
    kwargs = {"t_final": 1.0, **kwargs}
    with pytest.raises(InputTypeError, match=match):
        simulate(model, **kwargs)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"torque": lambda t: float("nan")}, r"torque returned nan at t = 0 s"),
    ({"torque": lambda t: float("inf") if t > 0.5 else 0.0},
     r"torque returned inf at t = 0\.[5-9]"),
    ({"controller": lambda t, x: float("nan")}, r"controller returned nan at t = 0 s"),
    ({"hub_motion": _Motion(bad_after=0.3)}, r"hub_motion\.rate returned nan at t = 0\.[3-9]"),
], ids=["torque-nan", "torque-inf-later", "controller-nan", "hub-rate-nan"])
def test_non_finite_input_is_named_as_the_cause(model, kwargs, match):
    with pytest.raises(InputValueError, match=match):
        simulate(model, 1.0, **kwargs)


@pytest.mark.parametrize(("t_final", "output_step", "samples"), [
    (3.0, 1e-9, "3e+09"), (1e9, 0.01, "1e+11")], ids=["tiny-step", "huge-horizon"])
def test_absurd_output_grid_is_refused_before_allocating(model, t_final, output_step, samples):
    start = time.perf_counter()
    with pytest.raises(InputValueError, match=re.escape(
            f"asks for {samples} output samples, more than the limit {MAX_OUTPUT_SAMPLES:.3g}")):
        simulate(model, t_final, output_step=output_step)
    assert time.perf_counter() - start < AT_ONCE


def test_initial_tip_beyond_the_beam_is_rejected(model):
    x0 = np.zeros(model.n_states)
    x0[1] = 20.0
    with pytest.raises(InputValueError, match=r"x0 puts the modal tip at .* beyond the 1\.8 m"):
        simulate(model, 1.0, x0=x0)


@pytest.mark.parametrize("variant", ["first_order", "zero_order"])
def test_compiled_blow_up_is_reported_promptly_and_finite(hub_beam_mass_system, variant):
    model = build_model(hub_beam_mass_system, n_modes=4, variant=variant)
    start = time.perf_counter()
    result = simulate(model, 20.0, torque=SineTorque(peak_torque=1e6, duration=2.0),
                      output_step=0.01)
    assert time.perf_counter() - start < PROMPT
    assert result.status == "diverged"
    assert result.t[-1] < 0.05
    assert "tip deflection passed the beam length" in result.message
    for name in ("t", "states", "torque", "tip_deflection", "root_moment"):
        assert np.all(np.isfinite(getattr(result, name))), name


def test_prescribed_spin_far_beyond_the_model_is_reported_promptly(kane_system):
    model = build_model(kane_system, n_modes=4)
    start = time.perf_counter()
    result = simulate(model, 30.0, hub_motion=SpinUp(spin_rate=1e6, ramp_time=15.0),
                      output_step=0.01)
    assert time.perf_counter() - start < PROMPT
    assert result.status == "diverged"
    assert np.all(np.isfinite(result.torque))


def test_controller_far_faster_than_the_model_is_refused(model):
    n = model.n_modes

    def stiff_pd(t, x):
        return -1e14 * x[0] - 2e7 * x[n + 1]
    start = time.perf_counter()
    with pytest.raises(InputValueError, match=rf"fastest closed-loop pole .* more than "
                       rf"{LOOP_LIMIT:g} times the fastest pole"):
        simulate(model, 5.0, controller=stiff_pd)
    assert time.perf_counter() - start < AT_ONCE


def test_controller_stiffer_than_the_plant_moves_to_an_implicit_method(model):
    """Gains whose damped poles are 30 times the plant's fastest mode: DOP853 would crawl, LSODA
    steps over them."""
    omega = float(model.natural_frequencies(0.0, hub="free")[-1])
    wc = 30.0 * omega
    j0, n = model.matrices.J0, model.n_modes

    def pd(t, x):
        return -j0 * wc ** 2 * (x[0] - 0.1) - 1.8 * j0 * wc * x[n + 1]
    with pytest.warns(StiffnessWarning, match="closed loop.*switched to LSODA"):
        result = simulate(model, 20.0, controller=pd)
    assert result.method == "LSODA"
    assert result.status == "ok"
    assert result.theta[-1] == pytest.approx(0.1, rel=1e-3)


def test_input_errors_are_value_and_type_errors(model):
    """Callers that catch ValueError / TypeError keep working."""
    with pytest.raises(ValueError):
        simulate(model, -1.0)
    with pytest.raises(TypeError):
        simulate(model, None)
    with pytest.raises(InputError):
        simulate(model, 1.0, rtol=2.0)
