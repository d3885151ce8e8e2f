"""The spatial structure (MODEL.md section 8): its planar special case, its conservation laws,
its clamped frequencies, and the checks of its parameters."""

import math

import numpy as np
import pytest

import flexctl
from flexctl.model.errors import InputError
from flexctl.model.parameters import Beam, Hub, HubBeam, PointMass
from flexctl.model.spatial_dynamics import spatial_equations
from flexctl.model.spatial_structure import (SpatialAppendage, SpatialHub,
                                             SpatialStructure)
from flexctl.model.structure import Appendage, Structure

#: Planar and spatial accelerations agree to this, relative to the largest (round-off).
PLANAR_TOLERANCE = 1e-11
#: Energy and angular momentum of a free motion stay within this of their start (relative).
CONSERVATION_TOLERANCE = 1e-8
#: Clamped frequencies of the modal block within this of the planar model's (relative): the
#: spatial mass matrix integrates on the exact model's quadrature, chosen to 1e-5 of its
#: accelerations (as the planar exact model does), the planar matrices exactly.
FREQUENCY_TOLERANCE = 1e-6

PANEL = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
             youngs_modulus=6.9e10)


def wing(name="a", direction=(0.0, 1.0, 0.0), normal=(0.0, 0.0, 1.0), masses=(), **extra):
    """The paper-000 panel as a rod: soft along its normal, 100 times stiffer laterally."""
    fields = dict(name=name, direction=direction, normal=normal, length=1.8, density=2766.0,
                  area=2.5e-4, youngs_modulus=6.9e10, second_moment=5.2083e-10,
                  second_moment_lateral=5.2083e-8, shear_modulus=2.6e10,
                  torsion_constant=1.9531e-9, masses=masses)
    fields.update(extra)
    return SpatialAppendage(**fields)


TILTED_INERTIA = [[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]]

PLANAR_CASES = {
    "one beam with a tip mass": HubBeam(hub=Hub(inertia=1.16, radius=0.06), beam=PANEL,
                                        masses=(PointMass(mass=0.085, position=1.62),)),
    "massless hub": HubBeam(hub=Hub(inertia=0.0, radius=0.06), beam=PANEL,
                            masses=(PointMass(mass=0.085, position=1.62),)),
    "two beams at 0 and 150 deg": Structure(
        hub=Hub(inertia=1.16, radius=0.06),
        appendages=(Appendage(name="a", beam=PANEL),
                    Appendage(name="b", beam=PANEL, angle=math.radians(150.0),
                              masses=(PointMass(mass=0.2, position=0.9),)))),
    "free hub, two beams": Structure(
        hub=Hub(inertia=1.16, radius=0.06, mass=3.0, support="free"),
        appendages=(Appendage(name="a", beam=PANEL),
                    Appendage(name="b", beam=PANEL, angle=math.pi))),
}


def _spatial_name(name: str) -> str:
    """The spatial state of a planar modal state: ``q2`` -> ``beam0.qn2``, ``a.q1_dot`` ->
    ``a.qn1_dot``."""
    appendage, _, field = name.rpartition(".")
    return f"{appendage or 'beam0'}.{field.replace('q', 'qn', 1)}"


def _planar_to_spatial(names, layout, x) -> np.ndarray:
    """The spatial state of planar state ``x`` (motion about z, bending in the plane)."""
    value = dict(zip(names, x))
    index = dict(zip(layout.state_names, range(layout.n_states)))
    theta = value["theta"]
    state = np.zeros(layout.n_states)
    state[0:4] = [math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)]
    state[index["wz"]] = value["theta_dot"]
    for name, v in value.items():
        if name.rpartition(".")[2].startswith("q"):
            state[index[_spatial_name(name)]] = v
    if layout.free:
        state[index["hub_x"]], state[index["hub_y"]] = value["hub_x"], value["hub_y"]
        c, s = math.cos(theta), math.sin(theta)
        vx, vy = value["hub_x_dot"], value["hub_y_dot"]          # inertial -> hub frame
        state[index["hub_vx"]], state[index["hub_vy"]] = c * vx + s * vy, -s * vx + c * vy
    return state


@pytest.mark.parametrize("case", sorted(PLANAR_CASES))
def test_motion_in_one_plane_is_the_planar_exact_model(case):
    """Accelerations of the spatial model, built from the planar structure, equal the planar
    exact model's at strongly deflected, fast states (round-off), and nothing leaves the
    plane."""
    system = PLANAR_CASES[case]
    planar = flexctl.build_model(system, n_modes=3, variant="exact")
    equations = spatial_equations(SpatialStructure.from_planar(system), 3)
    layout, names = equations.layout, planar.layout.names
    index = dict(zip(layout.state_names, range(layout.n_states)))
    rng = np.random.default_rng(8)
    for _ in range(3):
        x = rng.normal(size=len(names))
        for k, name in enumerate(names):
            field = name.rpartition(".")[2]
            if field.startswith("q") and not field.endswith("_dot"):
                x[k] *= 0.3 / int(field[1:]) ** 2             # a strongly deflected beam
        expected = dict(zip(names, np.asarray(planar.dynamics(0.0, x, 0.7)).ravel()))
        state = _planar_to_spatial(names, layout, x)
        rate = equations.rhs(state, [0.0, 0.0, 0.7]).full().ravel()
        scale = max(abs(v) for v in expected.values())
        tolerance = PLANAR_TOLERANCE * scale
        assert rate[index["wz"]] == pytest.approx(expected["theta_dot"], abs=tolerance)
        for name, v in expected.items():
            if name.rpartition(".")[2].startswith("q") and name.endswith("_dot"):
                assert rate[index[_spatial_name(name)]] == pytest.approx(v, abs=tolerance), name
        out_of_plane = [index[n] for n in layout.state_names if ".ql" in n or ".qt" in n]
        out_of_plane += [index["wx"], index["wy"]]
        assert np.max(np.abs(rate[out_of_plane])) <= 1e-12 * scale
        if layout.free:     # the hub's inertial acceleration: R (v_t + w x v)
            theta = x[list(names).index("theta")]
            v_b = state[[index["hub_vx"], index["hub_vy"]]]
            a_b = rate[[index["hub_vx"], index["hub_vy"]]] \
                + state[index["wz"]] * np.array([-v_b[1], v_b[0]])
            c, s = math.cos(theta), math.sin(theta)
            assert c * a_b[0] - s * a_b[1] == pytest.approx(expected["hub_x_dot"],
                                                            abs=tolerance)
            assert s * a_b[0] + c * a_b[1] == pytest.approx(expected["hub_y_dot"],
                                                            abs=tolerance)


def _tumbling(support="pinned"):
    hub = SpatialHub(inertia=TILTED_INERTIA, radius=0.06, mass=3.0, support=support)
    return SpatialStructure(hub=hub, appendages=(
        wing("a", masses=(PointMass(mass=0.085, position=1.62),)),
        wing("b", direction=(0.0, -1.0, 0.0), normal=(1.0, 0.0, 0.0)),
        wing("boom", direction=(0.0, 0.0, 1.0), normal=(1.0, 0.0, 0.0), length=1.0)))


@pytest.mark.slow
@pytest.mark.parametrize("support", ["pinned", "free"])
def test_free_motion_keeps_energy_and_angular_momentum(support):
    """Without torque, a tumbling three-appendage structure (products of inertia, arrays in
    two orientations and a boom) keeps its energy and its angular momentum vector (about the
    centre, or the centre of mass of a free structure) and, free, its linear momentum."""
    from flexctl.sim.spatial_run import simulate_spatial

    result = simulate_spatial(_tumbling(support), 1.0, None, n_modes=2,
                              angular_velocity=(0.4, -0.3, 1.2), output_step=0.01, rtol=1e-10,
                              check_accuracy=False)
    assert result.status == "ok", result.message
    energy = result.energy()
    angular, linear = result.momentum()
    assert np.max(np.abs(energy - energy[0])) <= CONSERVATION_TOLERANCE * energy[0]
    scale = np.linalg.norm(angular[:, 0])
    assert np.max(np.abs(angular - angular[:, :1])) <= CONSERVATION_TOLERANCE * scale
    if support == "free":       # a pin pushes on a pinned hub
        assert np.max(np.abs(linear - linear[:, :1])) <= CONSERVATION_TOLERANCE * max(
            1.0, np.max(np.abs(linear)))
    assert result.quaternion_drift < 1e-9
    # it did deform, in every direction of every appendage
    for name, tip in result.tips.items():
        assert np.max(np.abs(tip)) > 1e-5, name


@pytest.mark.parametrize("masses", [(), (PointMass(mass=0.085, position=1.62),)],
                         ids=["bare", "tip mass"])
def test_clamped_frequencies_are_the_planar_ones_and_torsion_closed_form(masses):
    """The modal block at rest gives each bending plane's clamped frequencies (those of the
    planar model with E I_n and E I_l) and, for the bare rod, torsion's closed form."""
    n_modes = 4
    rod = wing(masses=masses)
    structure = SpatialStructure(hub=SpatialHub(inertia=np.eye(3), radius=0.0),
                                 appendages=(rod,))
    equations = spatial_equations(structure, n_modes)
    x = np.zeros(equations.layout.n_states)
    x[0] = 1.0
    mass = equations.mass_matrix(x).full()[3:, 3:]
    from flexctl.model.spatial_rod import elastic_matrices
    stiffness = elastic_matrices(rod, n_modes)[0]
    for family, beam in (("qn", rod.beam_normal), ("ql", rod.beam_lateral)):
        block = equations.layout.modal(0, family)
        omega = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(
            mass[block, block], stiffness[block, block])).real))
        planar = flexctl.build_model(HubBeam(hub=Hub(inertia=1.0, radius=0.0), beam=beam,
                                             masses=masses), n_modes=n_modes).matrices
        expected = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(planar.M_ff,
                                                                     planar.K_ff)).real))
        np.testing.assert_allclose(omega, expected, rtol=FREQUENCY_TOLERANCE)
    block = equations.layout.modal(0, "qt")
    omega = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(
        mass[block, block], stiffness[block, block])).real))
    closed = [rod.torsion_frequency(k) for k in range(1, n_modes + 1)]
    np.testing.assert_allclose(omega, closed, rtol=1e-6)   # the quadrature of sin^2


@pytest.mark.parametrize("bad, pattern", [
    (dict(normal=(0.0, 1.0, 0.1)), "perpendicular"),
    (dict(direction=(0.0, 0.0, 0.0)), "non-zero"),
    (dict(second_moment_lateral=-1.0), "second_moment_lateral"),
    (dict(torsion_constant=float("nan")), "torsion_constant"),
    (dict(name="1st"), "identifier"),
    (dict(masses=(PointMass(mass=1.0, position=2.0),)), "position"),
], ids=["not perpendicular", "zero direction", "negative stiffness", "NaN", "bad name",
        "mass beyond the tip"])
def test_bad_appendages_are_refused_by_name(bad, pattern):
    with pytest.raises(InputError, match=pattern):
        wing(**bad)


@pytest.mark.parametrize("inertia, pattern", [
    ([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "symmetric"),
    ([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]], "positive semi-definite"),
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 5.0]], "triangle"),
    ([1.0, 1.0, 1.0], "shape"),
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, float("inf")]], "finite"),
], ids=["asymmetric", "indefinite", "no rigid body", "a vector", "infinite"])
def test_bad_hub_inertia_is_refused_by_name(inertia, pattern):
    with pytest.raises(InputError, match=f"hub.inertia.*{pattern}|{pattern}"):
        SpatialHub(inertia=inertia, radius=0.1)


def test_appendage_names_must_be_unique():
    hub = SpatialHub(inertia=np.eye(3), radius=0.1, support="free")
    with pytest.raises(InputError, match="names must be unique|unique"):
        SpatialStructure(hub=hub, appendages=(wing("a"), wing("a")))


def test_a_massless_hub_has_a_positive_definite_mass_matrix():
    """The rods carry the inertia: a hub of zero inertia still gives a regular model."""
    structure = SpatialStructure(hub=SpatialHub(inertia=np.zeros((3, 3)), radius=0.06),
                                 appendages=(wing("a"), wing("b", direction=(1.0, 0.0, 0.0),
                                                             normal=(0.0, 1.0, 0.0))))
    equations = spatial_equations(structure, 2)
    rng = np.random.default_rng(2)
    x = np.zeros(equations.layout.n_states)
    x[0] = 1.0
    x[4:4 + equations.layout.n_elastic] = 0.05 * rng.normal(size=equations.layout.n_elastic)
    assert np.min(np.linalg.eigvalsh(equations.mass_matrix(x).full())) > 0


@pytest.mark.parametrize("spin", [0.0, 3.0], ids=["at rest", "spinning"])
def test_linear_plant_in_one_plane_is_the_planar_plant(spin):
    """About rest or a steady spin about z, the in-plane block of the spatial plant (attitude
    error about z, the normal bending modes, their rates) is decoupled from the rest and has
    the planar plant's poles."""
    from flexctl.model.spatial_plant import linearize_spatial

    system = PLANAR_CASES["one beam with a tip mass"]
    planar = flexctl.build_model(system, n_modes=3, variant="exact").linearize(spin_rate=spin)
    plant = linearize_spatial(SpatialStructure.from_planar(system), 3, (0.0, 0.0, spin))
    names = plant.state_labels
    block = [names.index(n) for n in ("ez", "beam0_qn1", "beam0_qn2", "beam0_qn3", "wz",
                                      "beam0_qn1_dot", "beam0_qn2_dot", "beam0_qn3_dot")]
    rest = [k for k in range(plant.nstates) if k not in block]
    assert np.max(np.abs(plant.A[np.ix_(block, rest)])) == 0.0
    assert np.max(np.abs(plant.A[np.ix_(rest, block)])) == 0.0

    def frequencies(a):
        return np.sort(np.abs(np.linalg.eigvals(a).imag))

    # the planar plant's matrices integrate exactly, the spatial one on the exact model's
    # quadrature (FREQUENCY_TOLERANCE)
    np.testing.assert_allclose(frequencies(plant.A[np.ix_(block, block)]),
                               frequencies(planar.A), rtol=FREQUENCY_TOLERANCE, atol=1e-9)
    assert plant.input_labels == ["tx", "ty", "tz"]
    assert plant.output_labels[:6] == ["ex", "ey", "ez", "wx", "wy", "wz"]


def test_linear_plant_predicts_a_small_response():
    """A small torque about all three axes: the linear plant's tips and attitude follow the
    nonlinear model's to the second order of the amplitude."""
    import control

    from flexctl.model.spatial_plant import linearize_spatial
    from flexctl.sim.spatial_run import VectorTorque, simulate_spatial

    structure = _tumbling()
    plant = linearize_spatial(structure, 2)
    times = np.linspace(0.0, 1.0, 101)
    push = np.outer(np.sin(np.pi * times), [1e-3, -2e-3, 1.5e-3])
    result = simulate_spatial(structure, 1.0, VectorTorque(times, push), n_modes=2,
                              output_step=0.01, rtol=1e-10, check_accuracy=False)
    response = control.forced_response(plant, times, push.T)
    labels = plant.output_labels
    for name in structure.names:
        for k, axis in enumerate(("dx", "dy", "dz")):
            linear = response.outputs[labels.index(f"{name}_tip_{axis}")]
            nonlinear = result.tips[name][k]
            scale = np.max(np.abs(result.tips[name]))
            assert np.max(np.abs(linear - nonlinear)) <= 1e-3 * scale, (name, axis)


def test_a_turn_that_is_no_equilibrium_is_refused():
    from flexctl.model.spatial_plant import linearize_spatial

    oblique = SpatialStructure(hub=SpatialHub(inertia=np.eye(3), radius=0.06), appendages=(
        wing("a", direction=(1.0, 0.0, 1.0), normal=(-1.0, 0.0, 1.0)),))
    with pytest.raises(InputError, match="no steady turn"):
        linearize_spatial(oblique, 2, (0.0, 0.0, 2.0))


def test_nonlinear_plant_is_the_simulated_model():
    """python-control's response of the nonlinear plant follows simulate_spatial's."""
    import control

    from flexctl.model.spatial_plant import nonlinear_spatial
    from flexctl.sim.spatial_run import VectorTorque, initial_state, simulate_spatial

    structure = _tumbling()
    system = nonlinear_spatial(structure, 1)
    times = np.linspace(0.0, 0.5, 51)
    push = np.outer(np.sin(2 * np.pi * times), [0.2, -0.1, 0.3])
    result = simulate_spatial(structure, 0.5, VectorTorque(times, push), n_modes=1,
                              output_step=0.01, rtol=1e-10, check_accuracy=False)
    x0 = initial_state(result.equations)
    response = control.input_output_response(system, times, push.T, x0,
                                             solve_ivp_kwargs={"rtol": 1e-10, "atol": 1e-13})
    labels = system.output_labels
    for name in structure.names:
        for k, axis in enumerate(("dx", "dy", "dz")):
            scale = np.max(np.abs(result.tips[name]))
            got = response.outputs[labels.index(f"{name}_tip_{axis}")]
            assert np.max(np.abs(got - result.tips[name][k])) <= 1e-6 * scale, (name, axis)
    np.testing.assert_allclose(response.outputs[0:4], result.quaternion, atol=1e-9)
