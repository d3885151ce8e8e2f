"""Hostile inputs to :func:`controllers.solve_slew`: a clear error or an honest solution.

Whatever the design model and the :class:`~controllers.SlewProblem`, ``solve_slew`` returns a
finite solution or raises ``TypeError`` (a wrong type) or ``ValueError`` (a wrong value, or a
slew refused before solving) naming the parameter or the physical reason, or a
:class:`~controllers.TrajectoryOptimizationError` saying what to change. No internal error
(IndexError, LinAlgError, OverflowError) and no numpy/scipy warning escapes.

Explicit cases for each input class that misbehaved, then a property-based test over
generated systems and problems (``MAX_EXAMPLES`` inputs a run).
"""

import dataclasses
import math
import time
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import flexctl
from flexctl.model.errors import InputError
from controllers import SlewProblem, TrajectoryOptimizationError, solve_slew
from controllers.slew.slew_nlp import MAX_INTERVALS

BASE = flexctl.load_scene("slew-90").system
ANGLE, DURATION, TORQUE_BOUND = 1.57, 5.0, 1.0      # rad, s, N m: solvable on BASE
FAST_REFUSAL_S = 1.0                                # a refusal before solving, s
SOFT_BEAM_END_TOL = 5e-3       # rad, m, rad/s, m/s: a 1-substep hold on spin-stiffened modes
#: Generated inputs per run of the property test.
MAX_EXAMPLES = 60
#: What a clear error names: a parameter, a setting, or the physical reason.
NAMES = ("angle", "duration", "torque_bound", "n_intervals", "torque_rate_bound", "tip_bound",
         "objective", "transcription", "integrator", "substeps", "collocation_scheme",
         "max_duration", "initial_guess", "design mode", "beam.", "hub.", "ratio", "mass")


def system(hub_inertia=None, masses=None, **beam):
    hub = BASE.hub if hub_inertia is None else dataclasses.replace(BASE.hub,
                                                                   inertia=hub_inertia)
    return dataclasses.replace(BASE, hub=hub, beam=dataclasses.replace(BASE.beam, **beam),
                               masses=BASE.masses if masses is None else masses)


def problem(**changes):
    return SlewProblem(**{"angle": ANGLE, "duration": DURATION, "torque_bound": TORQUE_BOUND,
                          **changes})


def refused(model, slew, error=ValueError, match=None):
    """Run ``solve_slew`` with warnings as errors; return the error's message and time."""
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(error, match=match) as info:
            solve_slew(model, slew)
    return str(info.value), time.perf_counter() - start


def finite(solution):
    return all(np.all(np.isfinite(a)) for a in (solution.t, solution.states, solution.torque,
                                                solution.multipliers)) \
        and math.isfinite(solution.cost)


# ---------------------------------------------------------------------------- explicit cases
@pytest.mark.parametrize("density", [1e-6, 1e-12, 1e-50], ids=lambda d: f"density={d:g}")
def test_modes_too_fast_for_any_hold_grid_are_refused_naming_mode_and_duration(density):
    """The reproducer: no hub, no tip mass and a feather-light beam make J0 tiny and the
    modes millions of rad/s; the hold analysis overflowed (RuntimeWarning) and an IndexError
    escaped. Now: the fastest mode, its phase over the slew and a duration that fits."""
    model = flexctl.build_model(system(hub_inertia=0.0, density=density, masses=()), 2)
    message, elapsed = refused(model, problem(), match=r"design mode 2 \(.* rad/s\) turns")
    assert "MAX_MODE_PHASE" in message and "duration of at most" in message
    assert elapsed < FAST_REFUSAL_S


@pytest.mark.parametrize("youngs_modulus", [1e-6, 1e-12], ids=lambda e: f"E={e:g}")
def test_beam_too_soft_to_follow_the_hub_is_refused(youngs_modulus):
    """A singular Gramian raised numpy's LinAlgError (E = 1e-6); now: mode 1 hardly moves."""
    model = flexctl.build_model(system(youngs_modulus=youngs_modulus), 2)
    message, elapsed = refused(model, problem(), match="design mode 1 hardly moves")
    assert "beam.youngs_modulus" in message and elapsed < FAST_REFUSAL_S


@pytest.mark.parametrize("youngs_modulus", [1e20, 1e50], ids=lambda e: f"E={e:g}")
def test_beam_too_stiff_for_the_holds_is_refused(youngs_modulus):
    """E = 1e50 printed LAPACK errors and raised LinAlgError from an overflowed hold map."""
    model = flexctl.build_model(system(youngs_modulus=youngs_modulus), 2)
    _, elapsed = refused(model, problem(), match="MAX_MODE_PHASE")
    assert elapsed < FAST_REFUSAL_S


def test_substeps_no_interval_count_can_cut_are_refused_without_a_false_remedy():
    """It suggested "6670 times as many n_intervals", far above the interval limit."""
    model = flexctl.build_model(system(hub_inertia=0.0, density=1e-3, masses=()), 2)
    message, elapsed = refused(model, problem(), match="RK4 substeps per")
    assert f"no n_intervals up to {MAX_INTERVALS} passes" in message
    assert elapsed < FAST_REFUSAL_S


def test_collocation_elements_beyond_the_limit_are_refused_fast():
    """A free-time collocation slew of 4720 elements took minutes to build."""
    model = flexctl.build_model(system(hub_inertia=1000.0, masses=(
        dataclasses.replace(BASE.masses[0], mass=10.0),)), 3)
    slew = problem(angle=2.8, duration=None, torque_bound=12.5, n_intervals=80,
                   transcription="collocation")
    message, elapsed = refused(model, slew, match="MAX_ELEMENTS")
    assert "model.design_modes" in message and elapsed < FAST_REFUSAL_S


def test_the_fast_mode_refusal_names_a_duration_that_passes_the_phase_check():
    model = flexctl.build_model(system(hub_inertia=0.0, density=1e-6, masses=()), 2)
    message, _ = refused(model, problem())
    shorter = float(message.split("duration of at most ")[1].split(" s")[0])
    message, _ = refused(model, problem(duration=shorter))
    assert "MAX_MODE_PHASE" not in message        # another check, with its own remedy


def test_huge_torque_bound_solves_with_a_finite_optimum():
    """torque_bound 1e300 overflowed squaring it in the objective (OverflowError) and then
    scaled the torque out of IPOPT's reach."""
    model = flexctl.build_model(BASE, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bounded = solve_slew(model, problem(torque_bound=1e300))
        ordinary = solve_slew(model, problem(torque_bound=1e3))
    assert finite(bounded)
    assert bounded.cost == pytest.approx(ordinary.cost, rel=1e-6)


def test_soft_beam_minimum_time_slew_is_what_its_torque_does():
    """E = 1e-6 scaled the modal states by 1e15, so IPOPT accepted dynamics broken by 4e-2
    at the end of the slew while reporting rest; the kinematic cap keeps them honest."""
    from scipy.integrate import solve_ivp

    model = flexctl.build_model(system(youngs_modulus=1e-6), 2)
    solution = solve_slew(model, problem(duration=None))
    torque = solution.torque_function()
    again = solve_ivp(lambda t, x: model.dynamics(t, x, torque(t)), (0.0, solution.duration),
                      np.zeros(model.n_states), rtol=1e-10, atol=1e-12,
                      max_step=solution.duration / 400)
    assert np.max(np.abs(again.y[:, -1] - solution.states[:, -1])) < SOFT_BEAM_END_TOL


@pytest.mark.parametrize("field, value", [
    ("angle", "1.57"), ("angle", None), ("angle", True), ("duration", "5"),
    ("torque_bound", [1.0]), ("n_intervals", True), ("n_intervals", "40"),
    ("n_intervals", 40.0), ("n_intervals", 2.5),
    ("substeps", 2j), ("objective", 5), ("transcription", ["collocation"]),
], ids=lambda v: repr(v))
def test_wrong_types_raise_type_error_naming_the_field(field, value):
    with pytest.raises(TypeError, match=field):
        problem(**{field: value})


@pytest.mark.parametrize("field, value", [
    ("n_intervals", 0), ("n_intervals", 10 ** 9),
    ("substeps", 10 ** 9), ("torque_bound", 1e-300 * 0), ("duration", math.inf),
], ids=repr)
def test_out_of_range_values_raise_value_error_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        problem(**{field: value})


def test_max_duration_below_the_rigid_body_time_is_refused():
    model = flexctl.build_model(BASE, 2)
    refused(model, problem(duration=None, max_duration=1e-3), match="max_duration")


def test_interval_bound_is_the_documented_limit():
    assert problem(n_intervals=MAX_INTERVALS).n_intervals == MAX_INTERVALS
    with pytest.raises(ValueError, match=str(MAX_INTERVALS)):
        problem(n_intervals=MAX_INTERVALS + 1)


# ---------------------------------------------------------------------------- property
def _scaled(base, factors):
    return st.sampled_from(factors).map(lambda f: base * f)


HOSTILE_NUMBERS = st.sampled_from([0.0, -1.0, math.nan, math.inf, -math.inf, 1e-300, 1e300,
                                   "1", None, True])


def _mostly(valid, hostile, one_in=8):
    """``hostile`` about once in ``one_in`` draws, so that most examples reach the solver."""
    return st.integers(0, one_in - 1).flatmap(lambda i: hostile if i == one_in - 1 else valid)


@st.composite
def systems(draw):
    """Keyword arguments of :func:`system` (the ratio checks of HubBeam may refuse them)."""
    return dict(
        hub_inertia=draw(st.sampled_from([BASE.hub.inertia, 0.0, 1e-12, 1e3])),
        masses=draw(st.sampled_from([BASE.masses, ()]
                                    + [(dataclasses.replace(BASE.masses[0], mass=m),)
                                       for m in (10.0, 1e3)])),
        density=draw(_scaled(BASE.beam.density, [1.0, 1.0, 1.0, 1e-3, 1e-9, 1e-40, 1e6])),
        youngs_modulus=draw(_scaled(BASE.beam.youngs_modulus, [1.0, 1.0, 1.0, 1e-12, 1e-4, 1e6,
                                                               1e30])))


@st.composite
def problems(draw):
    free_time = draw(st.booleans().map(lambda b: b and draw(st.booleans())))
    return dict(
        angle=draw(_mostly(st.floats(0.2, 3.0) | st.floats(-3.0, -0.2), HOSTILE_NUMBERS)),
        duration=None if free_time else draw(_mostly(st.floats(2.0, 20.0), HOSTILE_NUMBERS)),
        torque_bound=draw(_mostly(st.floats(1.0, 50.0), HOSTILE_NUMBERS)),
        n_intervals=draw(_mostly(st.sampled_from([20, 40, 80]),
                                 st.sampled_from([0, 1, 2, 5, 10 ** 6, 40.0, True, "40"]))),
        transcription=draw(st.sampled_from([None, None, "collocation"])),
        torque_rate_bound=draw(st.sampled_from([None, None, None, 1e-300, 1e300])),
        tip_bound=draw(st.sampled_from([None, None, None, 1e-300, 1e300])))


@settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(hub_beam=systems(), settings_=problems(), n_modes=st.sampled_from([1, 2, 3]))
def test_solve_slew_gives_a_clear_error_or_a_finite_solution(hub_beam, settings_, n_modes):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            model = flexctl.build_model(system(**hub_beam), n_modes)
        except (TypeError, ValueError) as exc:
            event("model refused")
            assert isinstance(exc, InputError), f"{type(exc).__name__} escaped: {exc}"
            return
        try:
            solution = solve_slew(model, SlewProblem(**settings_),
                                  ipopt_options={"max_iter": 60})
        except (TypeError, ValueError) as exc:
            event(f"refused: {type(exc).__name__}")
            assert isinstance(exc, InputError), f"{type(exc).__name__} escaped: {exc}"
            assert any(name in str(exc) for name in NAMES), str(exc)
            return
        except TrajectoryOptimizationError as exc:
            event("optimiser failed")
            assert "iterations" in str(exc) or "minimum time" in str(exc), str(exc)
            return
    event("solved")
    assert finite(solution)
    assert solution.states[0, -1] == pytest.approx(settings_["angle"], abs=1e-6)
