"""A spatial motion that stays in one plane runs on the spatial equations restricted to it
(:mod:`flexctl.sim.spatial_plane`): the same rates as the whole model's, the same run, and
only where the motion cannot leave the plane."""

import math

import numpy as np
import pytest

from flexctl.app.spatial_scene import SpatialSine
from flexctl.model.errors import InputError
from flexctl.model.parameters import Beam, Hub, PointMass
from flexctl.model.spatial_dynamics import spatial_equations
from flexctl.model.spatial_structure import SpatialHub, SpatialStructure
from flexctl.model.structure import Appendage, Structure
from flexctl.sim import compile_cache, spatial_run
from flexctl.sim.spatial_adams import CompiledAdams
from flexctl.sim.spatial_plane import motion_plane, plane_motion
from flexctl.sim.spatial_run import VectorTorque, initial_state, simulate_spatial

PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=5.2083e-10,
             youngs_modulus=6.9e10)
#: Rates of the restriction within this of the whole model's, relative to the largest.
ROUND_OFF = 1e-13


def _planar(support="pinned", angle=-math.pi / 3):
    return Structure(hub=Hub(inertia=1.45, radius=0.06, mass=3.0, support=support),
                     appendages=(Appendage(name="a", beam=PANEL, angle=math.pi / 2,
                                           masses=(PointMass(mass=0.085, position=1.62),)),
                                 Appendage(name="b", beam=PANEL, angle=angle)))


def _sine(peak=(0.0, 0.0, 0.5)):
    return SpatialSine(np.array(peak), 2.0)


EDGES = np.array([0.0, 2.0, 3.0])


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_the_restriction_has_the_whole_models_rates_in_the_plane(support):
    equations = spatial_equations(SpatialStructure.from_planar(_planar(support)), 3)
    x0 = initial_state(equations, angular_velocity=(0.0, 0.0, 0.3))
    axis = motion_plane(equations, x0, _sine(), EDGES)
    assert axis is not None and abs(abs(axis[2]) - 1.0) < 1e-15
    plane = plane_motion(equations, axis)
    assert plane.rhs.n_instructions() < equations.rhs.n_instructions() / 4
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = rng.normal(size=plane.n_states) * 0.2      # deflected, turning, drifting
        x[0:4] /= np.linalg.norm(x[0:4])
        torque = rng.normal(size=3)
        whole = equations.rhs(plane.embed(x), (torque @ axis) * axis).full().ravel()
        restricted = plane.embed(plane.rhs(x, torque).full().ravel())
        assert np.max(np.abs(restricted - whole)) <= ROUND_OFF * np.max(np.abs(whole))
        np.testing.assert_allclose(plane.restrict(plane.embed(x)), x, rtol=0, atol=1e-15)


def test_a_motion_that_may_leave_the_plane_is_not_restricted():
    structure = SpatialStructure.from_planar(_planar())
    equations = spatial_equations(structure, 2)
    layout = equations.layout
    x0 = initial_state(equations, angular_velocity=(0.0, 0.0, 0.3))
    assert motion_plane(equations, x0, _sine(), EDGES) is not None
    # a torque, a turn or a deflection across the plane
    assert motion_plane(equations, x0, _sine((0.0, 1e-6, 0.5)), EDGES) is None
    held = VectorTorque([0.0, 1.0], [[0.0, 0.0, 1.0], [0.1, 0.0, 1.0]], "hold")
    assert motion_plane(equations, x0, held, EDGES) is None
    assert motion_plane(equations, initial_state(equations, angular_velocity=(1e-3, 0.0, 0.3)),
                        _sine(), EDGES) is None
    twisted = x0.copy()
    twisted[layout.state_names.index("a.qt1")] = 1e-9
    assert motion_plane(equations, twisted, _sine(), EDGES) is None
    # a torque known only as a Python function
    assert motion_plane(equations, x0, lambda t: np.array([0.0, 0.0, 1.0]), EDGES) is None
    # products of inertia across the plane's normal
    tilted = SpatialHub(inertia=[[1.45, 0.0, 0.01], [0.0, 1.45, 0.0], [0.01, 0.0, 1.45]],
                        radius=0.06)
    tilted = spatial_equations(SpatialStructure(hub=tilted, appendages=structure.appendages), 2)
    assert motion_plane(tilted, initial_state(tilted), _sine(), EDGES) is None
    # the intermediate axis of inertia: a turn about it is unstable
    lopsided = SpatialHub(inertia=np.diag([3.0, 2.0, 1.0]), radius=0.06)
    lopsided = spatial_equations(SpatialStructure(hub=lopsided, appendages=tuple(
        a for a in structure.appendages if a.name == "a")), 2)
    assert motion_plane(lopsided, initial_state(lopsided), _sine(), EDGES) is None


@pytest.mark.parametrize("form", ["line", "segments"])
def test_a_run_in_the_plane_is_the_whole_models(monkeypatch, form):
    """The same run on the restriction and on the whole model (whose out-of-plane states
    stay zero), within their integration errors: a line through many samples (one
    integration) and a sine then nothing (two segments, each with its own Jacobian)."""
    structure = SpatialStructure.from_planar(_planar())
    torque = VectorTorque(np.linspace(0.0, 1.0, 41), np.outer(np.sin(np.linspace(0, 3, 41)),
                                                                [0.0, 0.0, 0.8])) \
        if form == "line" else SpatialSine(np.array([0.0, 0.0, -0.8]), 1.0)
    runs = {}
    for restricted in (True, False):
        monkeypatch.setattr(spatial_run, "PLANE_MOTION", restricted)
        runs[restricted] = simulate_spatial(structure, 1.5, torque, n_modes=2,
                                            angular_velocity=(0.0, 0.0, 0.2),
                                            output_step=0.01, rtol=1e-9)
    plane, whole = runs[True], runs[False]
    assert plane.status == whole.status == "ok"
    out = [k for k, name in enumerate(whole.layout.state_names) if ".ql" in name or ".qt" in name]
    assert np.all(plane.states[out] == 0.0)
    assert np.max(np.abs(whole.states[out])) < 1e-12
    for name, tips in whole.tips.items():
        peaks = np.maximum(np.max(np.abs(tips), axis=1), 1e-12)
        error = np.max(np.abs(plane.tips[name] - tips), axis=1) / peaks
        assert np.all(error < 1e-6), (name, error)
    assert plane.integration_error < 1e-6
    # the whole model's stiff run takes exponential steps, whose error at rtol 1e-9 leaves the
    # attitude within 3e-9 of a run at rtol 1e-13 (the restriction's within 3e-10)
    np.testing.assert_allclose(plane.quaternion, whole.quaternion, rtol=0, atol=1e-8)


@pytest.mark.skipif(compile_cache.compiler() is None, reason="no C compiler")
def test_a_run_in_the_plane_takes_compiled_adams_moulton_steps(monkeypatch):
    """Under a torque of segments the restriction is integrated by the compiled
    Adams-Moulton methods (:mod:`flexctl.sim.spatial_adams`), a line through many samples
    and a run without compiling by CVODES: the same run within their errors."""
    structure = SpatialStructure.from_planar(_planar())
    equations = spatial_equations(structure, 2)
    x0 = initial_state(equations, angular_velocity=(0.0, 0.0, 0.2))
    times = np.linspace(0.0, 1.5, 151)
    torque = SpatialSine(np.array([0.0, 0.0, -0.8]), 1.0)
    plan = spatial_run._Plan(equations, x0, times, torque, torque.breakpoints)
    assert isinstance(plan.integration(1e-9, 1e-12).segments, CompiledAdams)
    line = VectorTorque(np.linspace(0.0, 1.5, 41), np.outer(np.linspace(0, 1, 41), [0, 0, 1]))
    plan = spatial_run._Plan(equations, x0, times, line, np.zeros(0))
    assert isinstance(plan.integration(1e-9, 1e-12).segments, spatial_run.SpatialSegments)
    runs = {}
    for compiling in ("1", "0"):
        monkeypatch.setenv("FLEXCTL_COMPILE", compiling)
        runs[compiling] = simulate_spatial(structure, 1.5, torque, n_modes=2,
                                           angular_velocity=(0.0, 0.0, 0.2),
                                           output_step=0.01, rtol=1e-9)
    compiled, cvodes = runs["1"], runs["0"]
    assert compiled.status == cvodes.status == "ok"
    for name, tips in cvodes.tips.items():
        peaks = np.maximum(np.max(np.abs(tips), axis=1), 1e-12)
        error = np.max(np.abs(compiled.tips[name] - tips), axis=1) / peaks
        assert np.all(error < 1e-6), (name, error)
    assert 0.0 < compiled.integration_error < 1e-6
    np.testing.assert_allclose(compiled.quaternion, cvodes.quaternion, rtol=0, atol=1e-8)


def test_the_compiled_steps_name_a_spent_budget_and_a_blow_up(monkeypatch):
    """A step budget spent between two outputs is named with the model's fastest eigenvalue;
    a torque no step can follow fails the run with a message, never a NaN."""
    structure = SpatialStructure.from_planar(_planar())
    monkeypatch.setattr(spatial_run, "MAX_STEPS", 50)
    run = simulate_spatial(structure, 1.0, _sine(), n_modes=3, output_step=0.5)
    assert run.status == "failed"
    assert "took all of its 50 steps" in run.message and "fastest eigenvalue" in run.message
    monkeypatch.setattr(spatial_run, "MAX_STEPS", 2_000_000)
    run = simulate_spatial(structure, 1.0, _sine((0.0, 0.0, 1e150)), n_modes=2,
                           output_step=0.01)
    assert run.status in ("failed", "diverged") and "t = 0 s" in run.message
    assert np.all(np.isfinite(run.states))
    assert run.integration_error is None


@pytest.mark.parametrize("torque", [
    VectorTorque([0.0, 0.3, 0.6], [[0.0, 0.0, 0.1], [0.2, 0.0, -0.1], [0.0, 0.3, 0.2]]),
    VectorTorque([0.0, 0.3, 0.6], [[0.0, 0.0, 0.1], [0.2, 0.0, -0.1], [0.0, 0.3, 0.2]],
                 "hold"),
    SpatialSine(np.array([0.1, -0.2, 0.3]), 0.5),
    spatial_run.ConstantTorque(np.array([0.1, 0.0, -0.4]))])
def test_a_torque_history_is_its_values_at_each_time(torque):
    """``at(times)`` (a run's torque history at once) is the torque at each time, before,
    between, on and after the samples; times that are not finite are refused by name."""
    times = np.array([-1.0, 0.0, 0.1, 0.3, 0.45, 0.5, 0.6, 2.0])
    np.testing.assert_allclose(torque.at(times), np.column_stack([torque(t) for t in times]),
                               rtol=0, atol=1e-15)
    assert torque.at(np.zeros(0)).shape == (3, 0)
    for bad in (np.array([0.1, np.nan]), [np.inf], "soon"):
        with pytest.raises(InputError, match="times"):
            torque.at(bad)


@pytest.mark.skipif(compile_cache.compiler() is None, reason="no C compiler")
@pytest.mark.parametrize("name, value", [
    ("rtol", 0.0), ("rtol", float("nan")), ("rtol", 2.0), ("atol", -1.0),
    ("atol", float("inf")), ("max_steps", 0), ("max_steps", 2.5), ("h_first", 0.0),
    ("h_first", float("nan")), ("n_states", 0), ("n_states", 14), ("built", None),
    ("built", (1, 2)), ("drive", lambda t: np.zeros(3))])
def test_compiled_adams_refuses_bad_arguments_by_name(name, value):
    equations = spatial_equations(SpatialStructure.from_planar(_planar()), 2)
    x0 = initial_state(equations, angular_velocity=(0.0, 0.0, 0.2))
    plan = spatial_run._Plan(equations, x0, np.linspace(0.0, 1.0, 11), _sine(),
                             _sine().breakpoints)
    good = dict(built=plan.library, n_states=plan.x0.size, drive=_sine(), rtol=1e-8,
                atol=1e-11, max_steps=100, h_first=1e-3)
    assert good["n_states"] == 13
    CompiledAdams(**good)
    with pytest.raises(InputError, match=name if name != "drive" else "segment_form"):
        CompiledAdams(**{**good, name: value})
