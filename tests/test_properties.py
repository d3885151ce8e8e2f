"""Property-based tests of the input contracts: whatever is given, a clear error or a finite,
honest result.

Generated: physical parameters, torque functions and simulate's arguments, ``--set`` overrides
of a scene and controller settings (through the command line's ``main`` in this process).
The properties:

- a bad input raises :class:`~flexctl.model.errors.InputError` (a ``TypeError`` or a
  ``ValueError``) whose message names the input; nothing else escapes;
- a run that goes through returns finite arrays, ends at ``t_final`` when its status is ok and
  earlier otherwise;
- the command line exits 0, 2 or 3 (never 1, a bug); exit 2 is one line on stderr; the
  output directory holds every file of the run (exit 0 and 3) or does not exist (exit 2).

Tiny models (one or two modes) and short horizons keep the whole file under a minute;
``MAX_EXAMPLES`` sets the number of inputs of each test.
"""

import contextlib
import io
import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from flexctl import Beam, Hub, HubBeam, PointMass, build_model, load_scene, simulate
from flexctl.app.cli import EXIT_BAD_INPUT, EXIT_OK, EXIT_STOPPED, main
from clear_errors import assert_clear_error
from flexctl.model.errors import InputError

#: Generated inputs per test (five tests: 375 inputs a run).
MAX_EXAMPLES = {"parameters": 120, "simulate": 120, "overrides": 60, "controllers": 45,
                "x0": 30}
PROPERTY_SETTINGS = {"deadline": None, "derandomize": True,
                     "suppress_health_check": [HealthCheck.too_slow]}
OUTPUT_FILES = {"timeseries.csv", "summary.json", "response.png"}
STATUSES = {"ok", "diverged", "singular"}

# ------------------------------------------------------------------ value strategies
#: Numbers a hostile user types: ordinary, zero, negative, tiny, huge, non-finite.
EXTREME_FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, -1.0, 1e-300, 1e-200, 1e-12, 1e12, 1e200, 1e300, 5e-324]),
    st.floats(min_value=1e-3, max_value=1e3))
#: Times that are wrong or absurd (a valid but long horizon would only make the test slow).
ABSURD_TIMES = st.sampled_from([0.0, -0.0, -1.0, math.nan, math.inf, -math.inf, 1e12, 1e300,
                                5e-324, 1e-300])
#: Anything a field might be given instead of a number.
NOT_NUMBERS = st.sampled_from([None, "1.0", "abc", True, [1.0], {"a": 1}, complex(1, 1)])


def _plausible(low, high):
    return st.floats(min_value=low, max_value=high)


def _mostly(valid, *hostile, weight=4):
    """``valid`` about ``weight`` times as often as each ``hostile`` strategy, so that most
    examples get far enough to run while every argument is sometimes bad."""
    return st.one_of(*([valid] * weight), *hostile)


def _field(low, high):
    """Mostly plausible values, sometimes extreme, now and then not a number at all."""
    return _mostly(_plausible(low, high), EXTREME_FLOATS, NOT_NUMBERS, weight=6)



# ------------------------------------------------------------------ parameters
PARAMETER_RANGES = {
    "hub.inertia": (0.0, 10.0), "hub.radius": (0.0, 1.0), "beam.length": (0.1, 10.0),
    "beam.density": (100.0, 1e4), "beam.area": (1e-6, 1e-2),
    "beam.second_moment": (1e-12, 1e-6), "beam.youngs_modulus": (1e8, 1e12),
    "beam.damping_ratio": (0.0, 0.5), "mass.mass": (0.0, 10.0), "mass.position": (0.0, 1.0)}


@st.composite
def _parameters(draw):
    """Plausible values (point-mass position as a fraction of the length); about half the
    examples then get one or two fields replaced by an extreme value or a non-number."""
    values = {k: draw(_plausible(*r)) for k, r in PARAMETER_RANGES.items()}
    values["mass.position"] *= values["beam.length"]
    for key in draw(st.lists(st.sampled_from(sorted(values)), max_size=2, unique=True)):
        values[key] = draw(st.one_of(EXTREME_FLOATS, NOT_NUMBERS))
    return values


def _system(values):
    def part(prefix):
        return {k.split(".")[1]: v for k, v in values.items() if k.startswith(prefix)}
    return HubBeam(hub=Hub(**part("hub.")), beam=Beam(**part("beam.")),
                   masses=(PointMass(**part("mass.")),))


@settings(max_examples=MAX_EXAMPLES["parameters"], **PROPERTY_SETTINGS)
@given(values=_parameters(),
       n_modes=_mostly(st.sampled_from([1, 2]), st.sampled_from([0, -1, 2.5, "2"])),
       variant=_mostly(st.sampled_from(["first_order", "zero_order", "consistent"]),
                       st.just("fourth_order")))
def test_parameters_give_a_clear_error_or_a_finite_model(values, n_modes, variant):
    try:
        system = _system(values)
        model = build_model(system, n_modes=n_modes, variant=variant)
    except (TypeError, ValueError) as exc:
        assert_clear_error(exc, "hub.", "beam.", "mass.", "system.", "ratio", "n_modes",
                           "variant")
        return
    event("built a model")
    frequencies = model.natural_frequencies(0.0, hub="free")
    assert np.all(np.isfinite(frequencies)) and np.all(frequencies > 0.0)
    assert math.isfinite(model.matrices.J0) and model.matrices.J0 > 0.0
    j_eff = float(model.effective_hub_inertia(np.zeros(model.n_states)))
    assert 0.0 <= j_eff <= model.matrices.J0 * (1.0 + 1e-9)


# ------------------------------------------------------------------ simulate
@pytest.fixture(scope="module")
def tiny_model(hub_beam_mass_system):
    return build_model(hub_beam_mass_system, n_modes=1)


def _constant(value):
    return lambda t: value


VALID_TORQUES = st.one_of(
    _plausible(-10.0, 10.0).map(_constant),
    st.sampled_from([lambda t, x: -x[0], lambda t: 2.0 * math.sin(3.0 * t), None,
                     lambda t: np.float32(1.5), lambda t: np.ones((1, 1))]))
HOSTILE_TORQUES = st.one_of(
    EXTREME_FLOATS.map(_constant),
    NOT_NUMBERS.map(_constant),
    st.sampled_from([lambda t: np.ones(2), lambda t, x, y: 1.0, lambda *, t: 1.0,
                     lambda t: 1.0 / (1.0 - t), lambda t: float("nan") if t > 0.3 else 0.0,
                     lambda t: math.exp(50 * t), 3.0, "torque"]))
SIMULATE_ARGUMENTS = {
    "torque": (VALID_TORQUES, HOSTILE_TORQUES),
    "t_final": (_plausible(0.05, 1.0), st.one_of(ABSURD_TIMES, NOT_NUMBERS)),
    "rtol": (st.sampled_from([1e-6, 1e-8]), st.one_of(EXTREME_FLOATS, NOT_NUMBERS)),
    "output_step": (st.one_of(st.none(), _plausible(1e-3, 0.1)), EXTREME_FLOATS),
    "method": (st.sampled_from(["auto", "DOP853", "RK45", "LSODA"]),
               st.sampled_from(["cvodes", "rk4", 4, None]))}


@st.composite
def _simulate_arguments(draw):
    """Valid arguments; about half the examples get one or two of them hostile."""
    hostile = draw(st.lists(st.sampled_from(sorted(SIMULATE_ARGUMENTS)), max_size=2,
                            unique=True))
    return {name: draw(pair[name in hostile]) for name, pair in SIMULATE_ARGUMENTS.items()}


@settings(max_examples=MAX_EXAMPLES["simulate"], **PROPERTY_SETTINGS)
@given(arguments=_simulate_arguments())
def test_simulate_gives_a_clear_error_or_a_finite_honest_result(tiny_model, arguments):
    torque, t_final, rtol, output_step, method = (
        arguments[k] for k in ("torque", "t_final", "rtol", "output_step", "method"))
    try:
        result = simulate(tiny_model, t_final, torque=torque, rtol=rtol,
                          output_step=output_step, method=method, check_accuracy=False)
    except (TypeError, ValueError) as exc:
        assert_clear_error(exc, "torque", "t_final", "rtol", "output_step",
                                "method")
        return
    event(f"ran: {result.status}")
    assert result.status in STATUSES
    for name in ("t", "states", "torque", "tip_deflection", "root_moment"):
        assert np.all(np.isfinite(getattr(result, name))), name
    assert result.t.size >= 1 and np.all(np.diff(result.t) > 0)
    if result.status == "ok":
        assert result.t[-1] == pytest.approx(float(t_final))
        assert result.peak_tip_deflection < tiny_model.system.beam.length
    else:
        assert result.message and result.t[-1] <= float(t_final)


@settings(max_examples=MAX_EXAMPLES["x0"], **PROPERTY_SETTINGS)
@given(x0=st.one_of(st.lists(EXTREME_FLOATS, min_size=4, max_size=4),
                    st.lists(_plausible(-0.5, 0.5), min_size=4, max_size=4),
                    st.lists(_plausible(-0.5, 0.5), min_size=4, max_size=4),
                    st.lists(_plausible(-1.0, 1.0), min_size=0, max_size=6), NOT_NUMBERS))
def test_initial_states_give_a_clear_error_or_a_finite_run(tiny_model, x0):
    try:
        result = simulate(tiny_model, 0.2, x0=x0, check_accuracy=False)
    except (TypeError, ValueError) as exc:
        assert isinstance(exc, InputError) and "x0" in str(exc), str(exc)
        event("clear error")
        return
    event(f"ran: {result.status}")
    assert result.status in STATUSES
    assert np.all(np.isfinite(result.states)) and np.all(np.isfinite(result.torque))


# ------------------------------------------------------------------ command line
def _run_cli(argv):
    """``main(argv)`` in this process: exit code, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def _check_cli_contract(argv):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        code, stdout, stderr = _run_cli(argv + ["--out", str(out)])
        assert code in (EXIT_OK, EXIT_BAD_INPUT, EXIT_STOPPED), f"exit {code}: {stderr}"
        assert sorted(p.name for p in Path(tmp).iterdir()) in ([], ["run"])  # no leftovers
        if code == EXIT_BAD_INPUT:
            lines = stderr.splitlines()
            assert len(lines) == 1 and lines[0].startswith("flexctl: error: "), stderr
            assert stdout == "" and not out.exists()
            event("exit 2")
            return code
        assert {p.name for p in out.iterdir()} == OUTPUT_FILES
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == ("ok" if code == EXIT_OK else summary["status"])
        assert summary["status"] in STATUSES
        table = np.loadtxt(out / "timeseries.csv", delimiter=",", skiprows=1, ndmin=2)
        assert table.shape[0] >= 1 and np.all(np.isfinite(table))
        event(f"exit {code}")
        return code


SCENE_KEYS = ["hub.inertia", "hub.radius", "hub.friction", "beam.length", "beam.density",
              "beam.area", "beam.second_moment", "beam.youngs_modulus", "beam.damping_ratio",
              "masses.0.mass", "masses.0.position", "model.variant", "model.modes",
              "maneuver.peak_torque", "maneuver.duration", "simulation.t_final",
              "simulation.output_step", "simulation.rtol", "simulation.method",
              "beam.lenght", "masses.3.mass", "masses", "model", "nonsense", "", "a..b"]
TOML_VALUES = st.one_of(
    EXTREME_FLOATS.map(repr).map(lambda s: s.replace("inf", "inf").replace("nan", "nan")),
    st.integers(min_value=-3, max_value=6).map(str),
    st.sampled_from(['"abc"', "true", "[1, 2]", "", "{a = 1}", "first_order", '"zero_order"',
                     '"consistent"', '"exact"', '"auto"', '"LSODA"', '"cvodes"', "1e-9",
                     "1e9", "0", "-1", "nan", "inf", "1.0.0", '"2"']),
    st.text(max_size=6))


@settings(max_examples=MAX_EXAMPLES["overrides"], **PROPERTY_SETTINGS)
@given(overrides=st.lists(st.tuples(st.sampled_from(SCENE_KEYS), TOML_VALUES), max_size=3))
def test_overrides_exit_0_2_or_3_with_files_complete_or_absent(overrides):
    argv = ["run", "hub-beam-mass", "--set", "model.modes=1", "--set", "simulation.t_final=0.5",
            "--set", "simulation.output_step=0.01"]
    for key, value in overrides:
        argv += ["--set", f"{key}={value}"]
    _check_cli_contract(argv)


CONTROLLER_SETTINGS = {
    "pd": ["bandwidth", "damping_ratio", "feedforward", "reference"],
    "lqr": ["hub_angle", "hub_rate", "tip_deflection", "modal_energy", "torque",
            "spin_rate", "reference"],
    "bang_bang": [], "zv": [], "zvd": []}
SETTING_VALUES = st.one_of(EXTREME_FLOATS.map(repr), _plausible(0.01, 100.0).map(repr),
                           st.sampled_from(["true", "false", '"poly7"', '"cycloidal"', '"x"',
                                            "[0, 1]", "-2"]))


@st.composite
def _controller_overrides(draw):
    kind = draw(st.sampled_from(sorted(CONTROLLER_SETTINGS)))
    keys = CONTROLLER_SETTINGS[kind] + ["bogus"]
    chosen = draw(st.lists(st.sampled_from(keys), max_size=2, unique=True))
    pairs = [("controller.kind", kind)] + [(f"controller.{k}", draw(SETTING_VALUES))
                                           for k in chosen]
    if draw(st.booleans()):
        pairs.append(("maneuver.torque_bound", draw(st.one_of(
            _plausible(0.5, 20.0).map(repr), EXTREME_FLOATS.map(repr)))))
    if draw(st.booleans()):
        pairs.append(("maneuver.duration", draw(st.one_of(
            _plausible(0.5, 2.5).map(repr), EXTREME_FLOATS.map(repr), st.just('"free"')))))
    return pairs


@settings(max_examples=MAX_EXAMPLES["controllers"], **PROPERTY_SETTINGS)
@given(pairs=_controller_overrides())
def test_controller_settings_exit_0_2_or_3_with_files_complete_or_absent(pairs):
    argv = ["run", "slew-90", "--set", "model.variant=first_order", "--set", "model.modes=2",
            "--set", "model.design_modes=1", "--set", "simulation.t_final=3",
            "--set", "simulation.output_step=0.02"]
    for key, value in pairs:
        argv += ["--set", f"{key}={value}"]
    _check_cli_contract(argv)


def test_the_generated_scene_is_small():
    """The base scenes of the command-line properties load (a typo would make every example
    exit 2 and the properties vacuous)."""
    scene = load_scene("hub-beam-mass", overrides={"model.modes": "1",
                                                   "simulation.t_final": "0.5"})
    assert scene.model.modes == 1
    code, _, err = _run_cli(["run", "slew-90", "--set", "model.variant=first_order",
                             "--set", "model.modes=2", "--set", "model.design_modes=1",
                             "--set", "simulation.t_final=3", "--out",
                             tempfile.mkdtemp()])
    assert code == EXIT_OK, err
