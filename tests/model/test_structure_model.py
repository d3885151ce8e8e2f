"""Contracts of the structure model (several appendages, pinned or free hub) that the
independent reference (tests/model/test_structure_fe.py) does not cover: the one-appendage structure
is the one-beam model, the symmetric modes the torque cannot move, designs on the rest, and
the refusals of what a free hub does not have."""

import math

import numpy as np
import pytest

from controllers.design.controllable import controllable_part
from controllers.feedback.lqr import LQRWeights, design_lqr
from controllers.slew.shaping import design_shaper, shaper_frequencies
from flexctl import (VARIANTS, Appendage, Beam, Hub, HubBeam, PointMass, SineTorque,
                     Structure, build_model, simulate)
from flexctl.model.errors import InputValueError

PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
             youngs_modulus=6.9e10)
BOOM = Beam(length=1.0, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
            youngs_modulus=6.9e10)
TIP = (PointMass(mass=0.085, position=1.62),)


def hub(support="pinned"):
    return Hub(inertia=1.16, radius=0.06, mass=3.0, support=support)


def twins(support="pinned", angle=math.pi):
    return Structure(hub=hub(support), appendages=(
        Appendage(name="wing_a", beam=PANEL, masses=TIP),
        Appendage(name="wing_b", beam=PANEL, masses=TIP, angle=angle)))


@pytest.mark.parametrize("variant", VARIANTS)
def test_one_appendage_structure_is_the_one_beam_model(variant):
    system = HubBeam(hub=Hub(inertia=1.16, radius=0.06), beam=PANEL, masses=TIP)
    one, general = build_model(system, 3, variant), build_model(
        Structure.from_hub_beam(system), 3, variant)
    x = np.random.default_rng(1).normal(size=(one.n_states, 4)) * 0.05
    u = np.array([0.3, -1.0, 2.0, 0.0])
    scale = np.max(np.abs(one.dynamics(0.0, x, u)))
    assert np.max(np.abs(general.dynamics(0.0, x, u) - one.dynamics(0.0, x, u))) <= 1e-12 * scale
    assert general.state_names == one.state_names and general.output_names == one.output_names
    assert np.allclose(general.outputs(x), one.outputs(x), rtol=0, atol=1e-12)
    assert np.allclose(general.energy(x), one.energy(x), rtol=1e-12)
    assert np.allclose(general.angular_momentum(x), one.angular_momentum(x), rtol=1e-12)
    assert np.allclose(general.natural_frequencies(0.0, "free"),
                       one.natural_frequencies(0.0, "free"), rtol=1e-9)


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_twins_bending_against_each_other_are_hidden_from_the_torque(support):
    model = build_model(twins(support), 2)
    report = model.linearize().modal_visibility
    hidden = [j for j in report.uncontrollable("torque") if report.frequencies[j] > 0.0]
    assert len(hidden) == 2                                  # one per mode of each array
    for j in hidden:
        assert j in report.unobservable("theta") and j in report.unobservable("theta_dot")
        assert j not in report.unobservable("wing_a.root_moment")
        shape = report.shapes[:, j]
        a, b = model.layout.modal_slice("wing_a"), model.layout.modal_slice("wing_b")
        assert np.allclose(shape[a], -shape[b], atol=1e-9 * np.max(np.abs(shape)))
    # twins at any angle are mirror images about their bisector: the torque (odd under the
    # mirror) cannot move their even modes
    skew = build_model(twins(support, angle=math.pi / 2), 2).modal_visibility()
    assert len([j for j in skew.uncontrollable("torque") if skew.frequencies[j] > 0.0]) == 2
    # unequal appendages have no such symmetry: the torque moves every flexible mode
    mixed = build_model(Structure(hub=hub(support), appendages=(
        Appendage(name="wing", beam=PANEL, masses=TIP),
        Appendage(name="boom", beam=BOOM, angle=math.pi))), 2).modal_visibility()
    assert all(mixed.frequencies[j] == 0.0 for j in mixed.uncontrollable("torque"))
    # modes are named as the loop checks name them: flexible ones counted from 1
    flexible = np.sort(report.frequencies[report.frequencies > 0.0])
    for j in hidden:
        k = int(report.mode_name(j).split()[1])
        assert flexible[k - 1] == report.frequencies[j]
        assert f"{report.mode_name(j)} at" in report.describe()
    # its repr is one line naming what the torque cannot move, not its arrays
    text = repr(report)
    assert "\n" not in text and len(text) < 200 and "array(" not in text
    names = [report.mode_name(j).split()[1] for j in hidden]
    assert "cannot move" in text and f"modes {', '.join(names)})" in text


@pytest.mark.parametrize("support", ["pinned", "free"])
def test_lqr_designs_on_the_modes_the_torque_moves(support):
    model = build_model(twins(support), 2)
    lqr = design_lqr(model, LQRWeights(hub_angle=0.01, torque=2.0, tip_deflection=0.01))
    part = controllable_part(model)
    hidden_states = part.basis.shape[1] < model.n_states
    assert hidden_states
    # no feedback on the hidden modes, and every mode the torque moves is damped
    report = model.modal_visibility()
    for j in report.uncontrollable("torque"):
        shape = np.zeros(model.n_states)
        shape[model.layout.coordinates] = report.shapes[:, j]
        assert abs(float(lqr.gain[0] @ shape)) <= 1e-9 * np.linalg.norm(lqr.gain)
    a, b = model.linear_matrices()
    a_r, b_r = part.reduce(a, b)
    reduced_gain = lqr.gain @ part.basis
    assert np.all(np.linalg.eigvals(a_r - b_r @ reduced_gain).real < 0.0)


def test_lqr_slews_the_free_two_array_craft_and_keeps_its_centre_of_mass():
    craft = twins("free")
    from controllers.slew.reference import SlewProfile

    slew = SlewProfile(slew_angle=0.5, duration=4.0)
    lqr = design_lqr(build_model(craft, 2),
                     LQRWeights(hub_angle=0.01, torque=2.0, tip_deflection=0.01), reference=slew)
    plant = build_model(craft, 3, "exact")
    run = simulate(plant, 8.0, controller=lqr, output_step=0.02)
    assert run.ok and abs(run.theta[-1] - 0.5) < 1e-3
    center = plant.center_of_mass(run.states)
    assert np.max(np.abs(center - center[:, :1])) < 1e-9
    tips = run.tip_deflections
    assert np.allclose(tips["wing_a"], tips["wing_b"], atol=1e-9)


def test_shaper_of_unequal_appendages_cancels_each_fundamental():
    craft = Structure(hub=hub(), appendages=(Appendage(name="wing", beam=PANEL, masses=TIP),
                                             Appendage(name="boom", beam=BOOM, angle=1.0)))
    model = build_model(craft, 3)
    frequencies = [w for w, _ in shaper_frequencies(model)]
    assert len(frequencies) == 2 and frequencies[0] < frequencies[1]
    shaper = design_shaper(model, "zv")
    for w in frequencies:             # the impulse train leaves no vibration at either
        residual = sum(a * np.exp(1j * w * t) for t, a in zip(shaper.times, shaper.amplitudes))
        assert abs(residual) < 1e-9


def test_free_hub_refuses_a_steady_spin_and_a_prescribed_rotation():
    model = build_model(twins("free"), 2)
    for call in (lambda: model.linearize(1.0),
                 lambda: model.natural_frequencies(2.0, hub="free"),
                 lambda: model.beam_accelerations(np.zeros(4), np.zeros(4), 0.0, 0.0)):
        with pytest.raises(InputValueError, match="free hub"):
            call()
    # held spinning, its beams are clamped ones, stiffened as on a pinned hub
    pinned = build_model(twins("pinned"), 2)
    assert np.allclose(model.natural_frequencies(2.0), pinned.natural_frequencies(2.0),
                       rtol=1e-12)


def test_single_wing_pushes_the_free_hub_and_momenta_balance():
    craft = Structure(hub=hub("free"), appendages=(Appendage(name="wing", beam=PANEL,
                                                             masses=TIP),))
    model = build_model(craft, 3, "first_order")
    push = SineTorque(peak_torque=1.0, duration=2.0)
    run = simulate(model, 4.0, torque=push, output_step=0.01)
    hub_travel = np.hypot(run.outputs["hub_x"], run.outputs["hub_y"])
    assert np.max(hub_travel) > 1e-3
    center = model.center_of_mass(run.states)
    assert np.max(np.abs(center - center[:, :1])) < 1e-9
    assert np.max(np.abs(model.linear_momentum(run.states))) < 1e-9
    impulse = np.concatenate(([0.0], np.cumsum(np.diff(run.t) * 0.5 * (
        run.torque[1:] + run.torque[:-1]))))
    h = model.angular_momentum(run.states)
    assert np.max(np.abs(h - h[0] - impulse)) < 1e-4 * np.max(np.abs(impulse))


def test_python_control_signals_carry_underscores():
    plant = build_model(twins(), 2).linearize()
    assert "wing_a_tip_deflection" in plant.output_labels
    assert "wing_b_q2_dot" in plant.state_labels
