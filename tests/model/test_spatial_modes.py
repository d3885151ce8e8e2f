"""Mode counts of a spatial structure: one per appendage (by order or by name), and
``modes = "auto"`` (:mod:`flexctl.sim.spatial_fidelity`) against the converged model."""

import math
import re
import textwrap

import numpy as np
import pytest
from spatial_craft import CRAFT_TOML

from flexctl.model.errors import InputError, InputValueError
from flexctl.model.parameters import PointMass
from flexctl.model.spatial_dynamics import spatial_equations, spatial_modes
from flexctl.model.spatial_structure import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.sim.spatial_fidelity import choose_spatial_modes
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial

SECTION = dict(length=1.8, density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
               second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
               shear_modulus=2.6e10, torsion_constant=1.9531e-9)
INERTIA = [[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]]


def craft():
    return SpatialStructure(hub=SpatialHub(inertia=INERTIA, radius=0.06), appendages=(
        SpatialAppendage(name="wing_a", direction=(0, 1, 0), normal=(0, 0, 1), **SECTION),
        SpatialAppendage(name="boom", direction=(1, 0, 0), normal=(0, 1, 0),
                         **{**SECTION, "length": 1.0})))


TORQUE = VectorTorque([0.0, 0.5, 1.0], [[0.2, 0.0, 0.3], [-0.2, 0.0, -0.3], [0.0, 0.0, 0.0]],
                      interpolation="hold")


def test_counts_per_appendage_by_order_or_name():
    structure = craft()
    assert spatial_modes("x", structure, {"wing_a": 3, "boom": 1}) == (3, 1)
    assert spatial_modes("x", structure, [2, 2]) == 2
    layout = spatial_equations(structure, (3, 1)).layout
    assert layout.n_elastic == 3 * (3 + 1)
    names = layout.state_names
    assert "wing_a.qt3" in names and "boom.qn1" in names and "boom.qn2" not in names
    assert layout.modal(1, "qt") == slice(11, 12)
    for bad, words in (([2], "one count per appendage"), ({"wing_a": 2}, "no count"),
                       ({"wing_a": 2, "boom": 1, "mast": 1}, "names no appendage 'mast'"),
                       ([2, 0], r"n_modes\[boom\]")):
        with pytest.raises(InputValueError, match=words):
            spatial_modes("x", structure, bad)


@pytest.mark.slow
def test_counts_per_appendage_and_auto_converge_on_the_model_with_more_modes():
    """``(2, 2)`` is the model of ``2``; ``(4, 1)`` brings the wing's tip towards the
    ``(4, 4)`` model's, where ``(1, 1)`` leaves it (the boom's fields reach the wing only
    through the hub); the counts ``"auto"`` chooses for a 1 % tolerance put every tip within
    1 % of its peak from the ``(4, 4)`` model. Measured: wing 6.0e-3 at (1, 1), 1.5e-3 at
    (4, 1); auto chose 2, within 4.4e-4 (wing) and 9.6e-4 (boom)."""
    structure = craft()
    choice = choose_spatial_modes(structure, TORQUE, 1.0, tolerance=1e-2)
    assert choice.estimated_error < 1e-2 and "planar" in choice.explanation
    counts = {2, (2, 2), (1, 1), (4, 1), (4, 4), choice.n_modes}
    assert max(spatial_equations(structure, choice.n_modes).layout.counts) < 4
    runs = {n: simulate_spatial(structure, 1.0, TORQUE, n_modes=n, output_step=0.01,
                                check_accuracy=False) for n in counts}
    np.testing.assert_array_equal(runs[2].states, runs[(2, 2)].states)
    reference = runs[(4, 4)].tips
    error = {n: {name: np.max(np.abs(runs[n].tips[name] - reference[name]))
                 / np.max(np.abs(reference[name])) for name in structure.names} for n in runs}
    print({n: {k: f"{v:.1e}" for k, v in e.items()} for n, e in error.items()})
    assert error[(4, 1)]["wing_a"] < error[(1, 1)]["wing_a"] / 3
    assert max(error[choice.n_modes].values()) < 1e-2


SCENE = CRAFT_TOML + textwrap.dedent("""\
    [model]
    {model}

    [maneuver]
    kind = "sine_torque"
    peak_torque = [0.2, 0.0, 0.3]
    duration = 1.0

    [simulation]
    t_final = 2.0
    """)


def test_a_scene_takes_a_table_of_modes_or_auto(tmp_path):
    from flexctl.app.scenes import load_scene

    path = tmp_path / "craft.toml"
    path.write_text(SCENE.format(model="modes = {wing_a = 3}"))
    assert load_scene(path).n_modes == 3
    path.write_text(SCENE.format(model='modes = "auto"\ntolerance = 0.05'))
    scene = load_scene(path)
    assert scene.mode_choice is not None and scene.n_modes == scene.mode_choice.n_modes
    assert scene.mode_choice.tolerance == 0.05
    for model, words in (("modes = {boom = 3}", r"model\.modes names no appendage 'boom'"),
                         ("modes = {wing_a = 0}", r"model\.modes\.wing_a"),
                         ('modes = "many"', r"model\.modes"),
                         ("modes = 3\ntolerance = 0.01", r"model\.tolerance"),
                         ('modes = "auto"\ntolerance = 2.0', r"model\.tolerance")):
        path.write_text(SCENE.format(model=model))
        with pytest.raises(InputError, match=words):
            load_scene(path)


def test_the_first_moment_is_the_mass_weighted_position_of_every_point():
    """``first_moment``: each rod's line mass (midpoint rule on 4000 pieces) and its point
    masses, positions from the hub's centre; the hub's own mass adds nothing (its centre is
    the origin)."""
    wing = SpatialAppendage(name="wing", direction=(0.6, 0.8, 0.0), normal=(0, 0, 1),
                            root=(0.1, -0.05, 0.02), masses=(PointMass(mass=0.3, position=1.2),),
                            **SECTION)
    boom = SpatialAppendage(name="boom", direction=(0, 0, -1), normal=(1, 0, 0),
                            **{**SECTION, "length": 1.0})
    structure = SpatialStructure(hub=SpatialHub(inertia=INERTIA, radius=0.06, mass=5.0,
                                                support="free"), appendages=(wing, boom))
    expected = np.zeros(3)
    for a in structure.appendages:
        root = a.root_point(structure.hub)
        s = (np.arange(4000) + 0.5) * a.length / 4000
        expected += a.linear_density * a.length / 4000 * np.sum(
            root[:, None] + a.direction[:, None] * s[None, :], axis=1)
        for point in a.masses:
            expected += point.mass * (root + point.position * a.direction)
    np.testing.assert_allclose(structure.first_moment, expected, rtol=1e-12, atol=1e-15)


def test_auto_chooses_the_counts_of_a_free_hub(tmp_path):
    """``modes = "auto"`` on a free hub: the rigid motion about the centre of mass."""
    from flexctl.app.scenes import load_scene

    path = tmp_path / "craft.toml"
    path.write_text(SCENE.format(model='modes = "auto"').replace(
        "radius = 0.06", 'radius = 0.06\nsupport = "free"\nmass = 3.0'))
    scene = load_scene(path)
    assert scene.structure.hub.free
    assert scene.mode_choice is not None and 1 <= min(np.atleast_1d(scene.n_modes))
    assert scene.mode_choice.estimated_error < scene.mode_choice.tolerance


def _too_stiff(monkeypatch):
    """A 0.05 s run of a wing of Young's modulus 1e30 Pa on a step budget of 2 000: it
    fails."""
    from flexctl.sim import spatial_run

    monkeypatch.setattr(spatial_run, "MAX_STEPS", 2000)
    wing = SpatialAppendage(name="wing_a", direction=(0, 1, 0), normal=(0, 0, 1),
                            **{**SECTION, "youngs_modulus": 1e30})
    structure = SpatialStructure(hub=SpatialHub(inertia=INERTIA, radius=0.06),
                                 appendages=(wing,))
    result = simulate_spatial(structure, 0.05, [0.1, 0.0, 0.0], n_modes=2,
                              check_accuracy=False)
    assert result.status == "failed"
    return result


def test_a_run_out_of_steps_names_the_stiff_mode_that_held_them(monkeypatch):
    """A structure far too stiff for its run (Young's modulus 1e30 Pa) uses CVODES's step
    budget: the run fails and says which eigenvalue held the steps, and to what (on Adams-Moulton;
    the exponential steps' failure, below)."""
    from flexctl.sim import spatial_run

    monkeypatch.setattr(spatial_run, "EXPONENTIAL", False)
    result = _too_stiff(monkeypatch)
    words = re.search(r"took all of its 2000 steps between two output times in \[0, "
                      r"0\.05\] s: the model's fastest eigenvalue at t = 0 s, "
                      r"([0-9.e+]+) 1/s, holds its steps near ([0-9.e+-]+) s\. Its source is "
                      r"a stiff mode", result.message)
    assert words, result.message
    fastest = float(words.group(1))
    # the first clamped bending frequency alone is sqrt(E I / (rho A)) (1.875 / L)^2
    first = np.sqrt(1e30 * SECTION["second_moment"] / (SECTION["density"] * SECTION["area"])) \
        * (1.8751 / SECTION["length"]) ** 2
    assert fastest > first
    assert float(words.group(2)) == pytest.approx(0.33 / fastest, rel=0.05)


def test_exponential_steps_out_of_budget_say_what_held_them(monkeypatch):
    """The same structure on exponential steps (the default for a stiff run): the Jacobian's
    finite differences cannot resolve a stiffness of 1e30 Pa, whose remainder the error control
    then holds to steps near 1e-8 s; the run fails and says so, with what would let it finish."""
    result = _too_stiff(monkeypatch)
    words = re.search(r"the exponential steps took more than 2000 steps between two output "
                      r"times in \[0, 0\.05\] s: the error control held them near "
                      r"([0-9.e+-]+) s; a looser rtol", result.message)
    assert words, result.message
    assert float(words.group(1)) < 1e-6


@pytest.mark.parametrize("exponential", [True, False])
def test_a_line_of_samples_out_of_steps_names_its_sample_interval(monkeypatch, exponential):
    """Samples 1 ms apart bound every step of a line through them: an output interval of 1 s
    needs 1000 steps, more than a budget of 300, and the failure says so, on either
    integrator (:data:`~flexctl.sim.spatial_run.STIFF_SPACING` set so that the exponential
    steps take the run, or not)."""
    from flexctl.sim import spatial_run

    monkeypatch.setattr(spatial_run, "MAX_STEPS", 300)
    monkeypatch.setattr(spatial_run, "STIFF_SPACING", 0.0 if exponential else math.inf)
    times = np.linspace(0.0, 2.0, 2001)
    torque = VectorTorque(times, np.outer(np.sin(times), [0.1, 0.0, 0.0]))
    structure = SpatialStructure(hub=SpatialHub(inertia=INERTIA, radius=0.06), appendages=(
        SpatialAppendage(name="wing_a", direction=(0, 1, 0), normal=(0, 0, 1), **SECTION),))
    result = simulate_spatial(structure, 2.0, torque, n_modes=1, output_step=1.0,
                              check_accuracy=False)
    assert result.status == "failed"
    assert "shortest interval, 0.001 s, bounds every step, and an output interval of 1 s " \
           "needs 1e+03 of them" in result.message, result.message
