"""A plant's modes moved on their own: frequencies and damping ratios as asked, shapes kept.

- Each coupled mode (hub free) rings at its factor times its frequency, on a pinned and a
  free hub, at rest and at a steady spin of a pinned hub, and on a plant with a wheel.
- The open-loop poles carry the damping ratios asked for.
- The mode shapes, and so the torque's participation in each mode, are the model's.
- Bad factors, ratios and counts are refused by name.
"""

import numpy as np
import pytest

import flexctl
from flexctl.model.errors import InputError
from flexctl.model.modal_uncertainty import coupled_modes, with_modes


def _model(scene, n_modes=3, **kwargs):
    return flexctl.build_model(flexctl.load_scene(scene).system, n_modes=n_modes, **kwargs)


@pytest.mark.parametrize("scene, spin", [("hub-beam-mass", 0.0), ("hub-beam-mass", 3.0),
                                         ("two-array-free", 0.0), ("two-array-slew", 0.0)])
def test_each_mode_rings_at_its_own_factor(scene, spin):
    model = _model(scene, n_modes=2) if scene != "hub-beam-mass" else _model(scene)
    n = model.n_modes
    factors = np.linspace(0.8, 1.25, n)
    changed = with_modes(model, factors, spin_rate=spin)
    before = np.sqrt(coupled_modes(model, spin)[0])
    after = np.sqrt(coupled_modes(changed, spin)[0])
    np.testing.assert_allclose(after, np.sort(factors * before), rtol=1e-9)
    assert type(changed) is type(model) and changed.variant == model.variant


def test_the_poles_carry_the_damping_asked_for():
    model = _model("hub-beam-mass")
    zeta = [0.002, 0.01, 0.05]
    a, _ = with_modes(model, [1.1, 0.9, 1.0], zeta).linear_matrices(0.0)
    poles = np.linalg.eigvals(a)
    flexible = poles[poles.imag > 1e-6]
    flexible = flexible[np.argsort(np.abs(flexible))]
    np.testing.assert_allclose(-flexible.real / np.abs(flexible), zeta, rtol=1e-8)
    expected = np.sqrt(coupled_modes(model)[0]) * [1.1, 0.9, 1.0]
    np.testing.assert_allclose(np.abs(flexible), expected, rtol=1e-8)


def test_the_mode_shapes_are_kept():
    model = _model("hub-beam-mass")
    _, before, reduced = coupled_modes(model)
    _, after, _ = coupled_modes(with_modes(model, [1.2, 0.85, 1.05]))
    # each shape is the same up to its sign
    overlap = np.abs(np.diag(before.T @ reduced @ after))
    np.testing.assert_allclose(overlap, 1.0, rtol=1e-9)


def test_a_wheel_plant_keeps_its_wheel():
    scene = flexctl.load_scene("wheel-slew")
    plant = scene.build_model()
    changed = with_modes(plant, 1.1)
    assert changed.actuator == plant.actuator and changed.n_states == plant.n_states
    before = np.sqrt(coupled_modes(plant)[0])
    np.testing.assert_allclose(np.sqrt(coupled_modes(changed)[0]), 1.1 * before, rtol=1e-9)


@pytest.mark.parametrize("kwargs, pattern", [
    ({"frequency_factors": 0.0}, "with_modes.frequency_factors"),
    ({"frequency_factors": [1.0, 1.1]}, "one per mode"),
    ({"frequency_factors": float("nan")}, "with_modes.frequency_factors"),
    ({"damping_ratios": 1.5}, "with_modes.damping_ratios"),
    ({"damping_ratios": -0.1}, "with_modes.damping_ratios"),
    ({"spin_rate": float("inf")}, "with_modes.spin_rate"),
], ids=["zero", "count", "nan", "damping-high", "damping-negative", "spin"])
def test_bad_changes_are_refused_by_name(kwargs, pattern):
    with pytest.raises(InputError, match=pattern):
        with_modes(_model("hub-beam-mass"), **kwargs)


def test_a_model_that_is_not_one_is_refused():
    with pytest.raises(InputError, match="with_modes.model must be a planar flexctl Model"):
        with_modes("model", 1.0)
