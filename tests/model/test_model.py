"""Model variants (MODEL.md section 4): frequencies, linearization, mass matrix, balances."""

import dataclasses

import control
import numpy as np
import pytest
from scipy.optimize import brentq

from conftest import random_states
from flexctl import VARIANTS, PointMass, SingularMassMatrixError, build_model

SMALL_DEFLECTION = tuple(v for v in VARIANTS if v != "exact")

#: Kane beam clamped frequencies, MODEL.md section 6, with half a unit in the last digit.
KANE_FREQUENCIES = [(0, 2.911, 5e-4), (1, 18.24, 5e-3), (2, 51.08, 5e-3)]
#: Roots of cos z cosh z + 1 = 0 tabulated in MODEL.md section 3 (7 decimals).
TABULATED_ROOTS = np.array([1.8751041, 4.6940911, 7.8547574, 10.9955407, 14.1371684])
#: omega ~ z^2: 7 decimals on z give about 1e-7 relative on omega.
ROOT_TABLE_RTOL = 1e-7
#: Tip mass R_M = 1: exact first frequency 1.7325 rad/s (MODEL.md section 6). Ritz converges
#: slowly with a tip mass (the free-end shear condition is violated by the mass), so 20 modes
#: and 1e-3.
TIP_MASS_FREQUENCY = 1.7325
TIP_MASS_MODES = 20
TIP_MASS_RTOL = 1e-3
#: The printed exact value has 5 digits.
TIP_MASS_PRINTED_ATOL = 5e-5
#: python-control's linearize uses forward differences with step 1e-6; the model is
#: polynomial of degree <= 3 in the state, so the difference error is far below this.
LINEARIZE_RTOL = 1e-6
#: Algebraic identities evaluated in floating point.
IDENTITY_RTOL = 1e-10


def _tip_mass_equation(z, mass_ratio):
    """1 + cos z cosh z + R_M z (cos z sinh z - sin z cosh z), scaled by sech z."""
    sech = 1.0 / np.cosh(z)
    return (sech + np.cos(z)
            + mass_ratio * z * (np.cos(z) * np.tanh(z) - np.sin(z)))


# ------------------------------------------------------------------ natural frequencies
@pytest.mark.parametrize("index, expected, atol", KANE_FREQUENCIES,
                         ids=["omega1", "omega2", "omega3"])
def test_kane_beam_frequencies_match_the_paper(kane_system, index, expected, atol):
    omega = build_model(kane_system, n_modes=4).natural_frequencies()
    assert omega[index] == pytest.approx(expected, abs=atol)


def test_bare_beam_beam_frequencies_follow_the_closed_form(kane_system):
    """omega_i = z_i^2 sqrt(EI / (rhoA l^4)) with the tabulated roots."""
    beam = kane_system.beam
    expected = TABULATED_ROOTS ** 2 * np.sqrt(beam.bending_stiffness
                                              / (beam.linear_density * beam.length ** 4))
    omega = build_model(kane_system, n_modes=5).natural_frequencies(0.0, hub="clamped")
    np.testing.assert_allclose(omega, expected, rtol=ROOT_TABLE_RTOL)


def test_tip_mass_frequency_matches_the_exact_frequency_equation(bare_hub_beam_system):
    beam = bare_hub_beam_system.beam
    mass_ratio = 1.0
    system = dataclasses.replace(bare_hub_beam_system, masses=(
        PointMass(mass=mass_ratio * beam.mass, position=beam.length),))
    z = brentq(_tip_mass_equation, 0.5, 1.8, args=(mass_ratio,), xtol=1e-14)
    exact = z ** 2 * np.sqrt(beam.bending_stiffness / (beam.linear_density * beam.length ** 4))
    assert exact == pytest.approx(TIP_MASS_FREQUENCY, abs=TIP_MASS_PRINTED_ATOL)
    omega = build_model(system, n_modes=TIP_MASS_MODES).natural_frequencies()[0]
    assert omega == pytest.approx(exact, rel=TIP_MASS_RTOL)


def test_tip_mass_frequency_converges_from_above(bare_hub_beam_system):
    """Ritz estimates are upper bounds that decrease monotonically toward the exact value."""
    beam = bare_hub_beam_system.beam
    system = dataclasses.replace(bare_hub_beam_system, masses=(
        PointMass(mass=beam.mass, position=beam.length),))
    z = brentq(_tip_mass_equation, 0.5, 1.8, args=(1.0,), xtol=1e-14)
    exact = z ** 2 * np.sqrt(beam.bending_stiffness / (beam.linear_density * beam.length ** 4))
    estimates = np.array([build_model(system, n_modes=n).natural_frequencies()[0]
                          for n in (1, 2, 4, 8, 12, 16, 20)])
    assert np.all(estimates > exact)
    assert np.all(np.diff(estimates) < 0)
    errors = estimates - exact
    assert errors[-1] < 1e-2 * errors[0]


@pytest.mark.parametrize("variant", ["first_order", "consistent"])
def test_stiffening_variants_stiffen_with_spin(hub_beam_mass_system, variant):
    model = build_model(hub_beam_mass_system, n_modes=4, variant=variant)
    spins = [0.0, 1.0, 2.0, 5.0, 10.0]
    omega = np.array([model.natural_frequencies(s) for s in spins])
    assert np.all(np.diff(omega, axis=0) > 0)


def test_first_order_one_mode_follows_southwell(kane_system):
    """With one mode, omega(W)^2 = omega_1^2 + (K_g/M_ff - 1) W^2 exactly."""
    model = build_model(kane_system, n_modes=1)
    mat = model.matrices
    southwell = mat.K_g[0, 0] / mat.M_ff[0, 0]
    for spin in (1.0, 4.0, 10.0):
        expected = np.sqrt(mat.beam_frequencies[0] ** 2 + (southwell - 1.0) * spin ** 2)
        assert model.natural_frequencies(spin)[0] == pytest.approx(expected, rel=IDENTITY_RTOL)


def test_zero_order_softens_and_loses_stiffness_above_first_frequency(kane_system):
    """Without K_g, K_ff - W^2 M_ff of a bare beam is diag(omega_i^2 - W^2): exactly omega_1."""
    model = build_model(kane_system, n_modes=4, variant="zero_order")
    omega1 = model.matrices.beam_frequencies[0]
    spins = np.array([0.0, 0.5, 0.9, 0.99]) * omega1
    omega = np.array([model.natural_frequencies(s) for s in spins])
    assert np.all(np.diff(omega, axis=0) < 0)
    assert omega[-1, 0] > 0
    lost = model.natural_frequencies(1.01 * omega1)
    assert lost[0] < 0
    # the magnitude of a lost mode is its growth rate sqrt(W^2 - omega_1^2)
    assert -lost[0] == pytest.approx(np.sqrt(1.01 ** 2 - 1) * omega1, rel=IDENTITY_RTOL)
    assert np.all(lost[1:] > 0)


def test_zero_order_with_masses_also_loses_stiffness(hub_beam_mass_system):
    model = build_model(hub_beam_mass_system, n_modes=4, variant="zero_order")
    omega1 = model.natural_frequencies()[0]
    assert model.natural_frequencies(0.9 * omega1)[0] > 0
    assert model.natural_frequencies(1.1 * omega1)[0] < 0


def test_free_hub_frequencies_exceed_clamped_for_a_light_hub(spacecraft_system):
    model = build_model(spacecraft_system, n_modes=4)
    free = model.natural_frequencies(hub="free")
    clamped = model.natural_frequencies(hub="clamped")
    assert free.shape == clamped.shape == (4,)
    assert np.all(free > clamped)
    # a massless hub: the beam root is nearly free, so the first frequency rises several times
    assert free[0] > 2.0 * clamped[0]


def test_free_hub_frequencies_tend_to_clamped_for_a_heavy_hub(hub_beam_mass_system):
    heavy = dataclasses.replace(hub_beam_mass_system, hub=dataclasses.replace(
        hub_beam_mass_system.hub, inertia=1e9))
    model = build_model(heavy, n_modes=4)
    np.testing.assert_allclose(model.natural_frequencies(hub="free"),
                               model.natural_frequencies(hub="clamped"), rtol=1e-8)


def test_natural_frequencies_reject_bad_input(hub_beam_mass_system):
    model = build_model(hub_beam_mass_system, n_modes=2)
    with pytest.raises(ValueError, match="hub"):
        model.natural_frequencies(0.0, hub="pinned")
    with pytest.raises(ValueError, match="spin_rate"):
        model.natural_frequencies(np.nan)


# ------------------------------------------------------------------ linearization
def test_linearization_at_rest_is_rigid_body_plus_free_modes(hub_beam_mass_system):
    model = build_model(hub_beam_mass_system, n_modes=4)
    a = model.linearize(0.0).A
    poles = np.linalg.eigvals(a)
    scale = np.max(np.abs(poles))
    at_zero = np.abs(poles) < 1e-9 * scale
    assert at_zero.sum() == 2
    # a double integrator is a Jordan block: one eigenvector for the double pole
    assert np.linalg.matrix_rank(a) == model.n_states - 1
    assert np.linalg.matrix_rank(a @ a) == model.n_states - 2
    flexible = poles[~at_zero]
    np.testing.assert_allclose(flexible.real, 0.0, atol=1e-9 * scale)
    free = model.natural_frequencies(hub="free")
    np.testing.assert_allclose(np.sort(flexible.imag[flexible.imag > 0]), free,
                               rtol=IDENTITY_RTOL)
    np.testing.assert_allclose(np.sort(flexible.imag[flexible.imag < 0]), -free[::-1],
                               rtol=IDENTITY_RTOL)


@pytest.mark.parametrize("spin_rate", [0.0, 2.0], ids=["spin-0", "spin-2"])
@pytest.mark.parametrize("variant", VARIANTS)
def test_linearize_equals_numerical_linearization_of_the_nonlinear_plant(
        lossy_hub_beam_mass_system, variant, spin_rate):
    model = build_model(lossy_hub_beam_mass_system, n_modes=3, variant=variant)
    x0 = np.zeros(model.n_states)
    x0[model.n_modes + 1] = spin_rate
    reference = control.linearize(model.nonlinear(), x0, 0.0)
    linear = model.linearize(spin_rate)
    for name in "ABCD":
        ref, got = getattr(reference, name), getattr(linear, name)
        np.testing.assert_allclose(got, ref, rtol=LINEARIZE_RTOL,
                                   atol=LINEARIZE_RTOL * max(np.max(np.abs(ref)), 1.0),
                                   err_msg=name)


@pytest.mark.parametrize("spin_rate", [0.5, 2.5, -1.25], ids=["0.5", "2.5", "-1.25"])
def test_linearize_accepts_any_finite_spin_rate(hub_beam_mass_system, spin_rate):
    """The steady spin is any real number, not only a whole one."""
    model = build_model(hub_beam_mass_system, n_modes=2)
    plant = model.linearize(spin_rate)
    a, _ = model.linear_matrices(spin_rate)
    np.testing.assert_array_equal(plant.A, a)


def test_linear_plant_carries_names(hub_beam_mass_system):
    model = build_model(hub_beam_mass_system, n_modes=3)
    expected_states = ["theta", "q1", "q2", "q3", "theta_dot", "q1_dot", "q2_dot", "q3_dot"]
    for plant in (model.linearize(0.0), model.nonlinear()):
        assert plant.state_labels == expected_states
        assert plant.input_labels == ["torque"]
        for name in ("theta", "theta_dot", "tip_deflection", "root_moment"):
            assert name in plant.output_labels
    assert list(model.state_names) == expected_states


def test_outputs_are_the_physical_quantities(hub_beam_mass_system):
    """Tip deflection phi(l)^T q, root moment EI phi''(0)^T q, tip angle theta + y(l)/(b+l)."""
    model = build_model(hub_beam_mass_system, n_modes=3)
    beam, b = hub_beam_mass_system.beam, hub_beam_mass_system.hub.radius
    x = np.array([0.3, 0.01, -0.002, 0.0005, 1.5, 0.1, 0.2, 0.3])
    y = dict(zip(model.output_names, model.outputs(x)))
    q = x[1:4]
    tip = model.deflection(x, beam.length)
    assert y["theta"] == 0.3 and y["theta_dot"] == 1.5
    assert y["tip_deflection"] == pytest.approx(tip, rel=IDENTITY_RTOL)
    assert y["tip_deflection"] == pytest.approx(2 * (q[0] - q[1] + q[2]), rel=IDENTITY_RTOL)
    z = np.array([1.8751041, 4.6940911, 7.8547574])
    root = 2.0 * beam.bending_stiffness * (z / beam.length) ** 2 @ q
    assert y["root_moment"] == pytest.approx(root, rel=1e-6)
    assert y["tip_angle"] == pytest.approx(0.3 + tip / (b + beam.length), rel=IDENTITY_RTOL)


# ------------------------------------------------------------------ mass matrix and balances
def _effective_inertia(model, x):
    """J(q) - m_tf^T M_ff^-1 m_tf from the matrices (MODEL.md section 4)."""
    mat = model.matrices
    q = x[1:model.n_modes + 1]
    j = mat.J0 + (q @ mat.D @ q if model.variant == "consistent" else 0.0)
    return j - mat.m_tf @ np.linalg.solve(mat.M_ff, mat.m_tf)


def test_dynamics_solve_the_equations_of_motion(lossy_hub_beam_mass_system, rng):
    """Plug dx/dt back into MODEL.md section 4's equations for every small-deflection variant
    (the exact variant's are checked in test_exact.py)."""
    for variant in SMALL_DEFLECTION:
        model = build_model(lossy_hub_beam_mass_system, n_modes=4, variant=variant)
        mat, n = model.matrices, model.n_modes
        c_h = lossy_hub_beam_mass_system.hub.friction
        for x in random_states(model, rng, 5).T:
            u = rng.uniform(-5, 5)
            dx = model.dynamics(0.0, x, u)
            q, w, qd = x[1:n + 1], x[n + 1], x[n + 2:]
            np.testing.assert_allclose(dx[:n + 1], x[n + 1:], rtol=0, atol=0)
            th_dd, q_dd = dx[n + 1], dx[n + 2:]
            stiff_d = mat.M_ff if variant == "zero_order" else mat.D
            beam = (mat.m_tf * th_dd + mat.M_ff @ q_dd + mat.C_ff @ qd
                    + (mat.K_ff - w ** 2 * stiff_d) @ q)
            hub = mat.J0 * th_dd + mat.m_tf @ q_dd - u + c_h * w
            if variant == "consistent":
                hub += (q @ mat.D @ q) * th_dd + 2 * w * (q @ mat.D @ qd)
            force_scale = np.abs(mat.K_ff @ q).max() + np.abs(mat.M_ff @ q_dd).max()
            np.testing.assert_allclose(beam, 0.0, atol=IDENTITY_RTOL * force_scale,
                                       err_msg=variant)
            assert abs(hub) < IDENTITY_RTOL * (abs(u) + mat.J0 * abs(th_dd) + 1.0), variant


def test_dynamics_accept_batches_of_states(lossy_hub_beam_mass_system, rng):
    for variant in VARIANTS:
        model = build_model(lossy_hub_beam_mass_system, n_modes=3, variant=variant)
        x = random_states(model, rng, 6)
        u = rng.uniform(-5, 5, 6)
        batch = model.dynamics(0.0, x, u)
        single = np.column_stack([model.dynamics(0.0, x[:, k], u[k]) for k in range(6)])
        np.testing.assert_allclose(batch, single, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("variant", VARIANTS)
def test_mass_matrix_and_effective_inertia(lossy_hub_beam_mass_system, rng, variant):
    model = build_model(lossy_hub_beam_mass_system, n_modes=4, variant=variant)
    for x in random_states(model, rng, 5).T:
        mass = model.mass_matrix(x)
        np.testing.assert_array_equal(mass, mass.T)
        assert np.linalg.eigvalsh(mass)[0] > 0
        # the Schur complement of M_ff in the mass matrix
        schur = mass[0, 0] - mass[0, 1:] @ np.linalg.solve(mass[1:, 1:], mass[1:, 0])
        assert float(model.effective_hub_inertia(x)) == pytest.approx(schur, rel=1e-9)
        if variant != "exact":       # MODEL.md section 4's closed form
            assert float(model.effective_hub_inertia(x)) == pytest.approx(
                _effective_inertia(model, x), rel=1e-9)


def test_consistent_light_hub_raises_on_a_singular_mass_matrix(spacecraft_system):
    model = build_model(spacecraft_system, n_modes=4, variant="consistent")
    x = np.zeros(model.n_states)
    x[1] = 0.5   # a deflection of this size brings J(q) - m_tf^T M^-1 m_tf below zero
    assert _effective_inertia(model, x) < 0
    with pytest.raises(SingularMassMatrixError, match="effective hub inertia"):
        model.dynamics(0.0, x, 0.0)
    with pytest.raises(ArithmeticError):
        model.accelerations(x, 0.0)


def test_consistent_energy_balance(lossy_hub_beam_mass_system, rng):
    """dE/dt = T theta_dot - c_h theta_dot^2 - q_dot^T C_ff q_dot (power of torque and losses)."""
    model = build_model(lossy_hub_beam_mass_system, n_modes=4, variant="consistent")
    mat, n = model.matrices, model.n_modes
    c_h = lossy_hub_beam_mass_system.hub.friction
    h = 1e-6
    for x in random_states(model, rng, 8).T:
        u = rng.uniform(-5, 5)
        dx = model.dynamics(0.0, x, u)
        # derivative of E along the flow, by a central difference in the flow direction
        power = (model.energy(x + h * dx) - model.energy(x - h * dx)) / (2 * h)
        w, qd = x[n + 1], x[n + 2:]
        expected = u * w - c_h * w ** 2 - qd @ mat.C_ff @ qd
        scale = abs(u * w) + 0.5 * mat.J0 * w ** 2 + abs(qd @ mat.C_ff @ qd) + 1e-3
        assert power == pytest.approx(expected, abs=1e-6 * scale)


@pytest.mark.parametrize("variant", VARIANTS)
def test_hub_equation_is_an_angular_momentum_balance(lossy_hub_beam_mass_system, rng, variant):
    """dH/dt = T - c_h theta_dot with H = J(q) theta_dot + m_tf^T q_dot (the first row of
    M(q) times the velocities for the exact variant)."""
    model = build_model(lossy_hub_beam_mass_system, n_modes=4, variant=variant)
    mat, n = model.matrices, model.n_modes
    c_h = lossy_hub_beam_mass_system.hub.friction

    def momentum(x):
        if variant == "exact":
            return model.mass_matrix(x)[0] @ x[n + 1:]
        q, w, qd = x[1:n + 1], x[n + 1], x[n + 2:]
        j = mat.J0 + (q @ mat.D @ q if variant == "consistent" else 0.0)
        return j * w + mat.m_tf @ qd

    h = 1e-6
    for x in random_states(model, rng, 5).T:
        u = rng.uniform(-5, 5)
        dx = model.dynamics(0.0, x, u)
        rate = (momentum(x + h * dx) - momentum(x - h * dx)) / (2 * h)
        assert rate == pytest.approx(u - c_h * x[n + 1], abs=1e-6 * (abs(u) + 1.0))


def test_hub_torque_inverts_the_dynamics(lossy_hub_beam_mass_system, rng):
    for variant in VARIANTS:
        model = build_model(lossy_hub_beam_mass_system, n_modes=3, variant=variant)
        n = model.n_modes
        for x in random_states(model, rng, 4).T:
            u = rng.uniform(-5, 5)
            dx = model.dynamics(0.0, x, u)
            assert model.hub_torque(x, dx[n + 1], dx[n + 2:]) == pytest.approx(u, abs=1e-9)
            # and the beam equation alone, under that hub motion, gives the same q_tt
            q_tt = model.beam_accelerations(x[1:n + 1], x[n + 2:], x[n + 1], dx[n + 1])
            np.testing.assert_allclose(q_tt, dx[n + 2:], rtol=1e-9,
                                       atol=1e-9 * np.abs(dx[n + 2:]).max())


# ------------------------------------------------------------------ construction
@pytest.mark.parametrize("kwargs, exc, pattern", [
    ({"variant": "second_order"}, ValueError, "variant"),
    ({"n_modes": 0}, ValueError, "n_modes"),
    ({"n_modes": 201}, ValueError, "n_modes"),
    ({"n_modes": 2.0}, TypeError, "n_modes"),      # a count is an int: a float is the
    ({"n_modes": True}, TypeError, "n_modes"),     # wrong type, as for range(2.0)
], ids=["unknown-variant", "zero-modes", "too-many-modes", "float-modes", "bool-modes"])
def test_build_model_rejects_bad_input(hub_beam_mass_system, kwargs, exc, pattern):
    with pytest.raises(exc, match=pattern):
        build_model(hub_beam_mass_system, **kwargs)


def test_build_model_rejects_a_non_system():
    with pytest.raises(TypeError, match="system"):
        build_model("hub-beam-mass")


def test_state_of_wrong_size_is_rejected(hub_beam_mass_system):
    model = build_model(hub_beam_mass_system, n_modes=3)
    with pytest.raises(ValueError, match=r"state.*\(8,\)"):
        model.dynamics(0.0, np.zeros(7), 0.0)


def test_equal_build_calls_share_one_model_and_others_do_not():
    """build_model keeps the model of an equal call (its assembled matrices, compiled
    functions and integrators come with it); any other number, mode count, variant or
    actuator is a model of its own, and refused input is refused every time."""
    import dataclasses

    from flexctl import load_scene
    from flexctl.model.actuators import ReactionWheel

    system = load_scene("hub-beam-mass").system
    model = build_model(system, 3)
    assert build_model(system, n_modes=3, variant="first_order") is model
    stiffer = dataclasses.replace(system, beam=dataclasses.replace(
        system.beam, youngs_modulus=2.0 * system.beam.youngs_modulus))
    others = [build_model(stiffer, 3), build_model(system, 4),
              build_model(system, 3, variant="zero_order"),
              build_model(system, 3, actuator=ReactionWheel(
                  inertia=1e-3, torque_limit=0.1, speed_limit=600.0, time_constant=0.05))]
    assert all(other is not model for other in others)
    assert others[0].natural_frequencies()[0] == pytest.approx(
        np.sqrt(2.0) * model.natural_frequencies()[0], rel=1e-9)
    for _ in range(2):
        with pytest.raises(ValueError, match="n_modes"):
            build_model(system, 0)
    free = load_scene("two-array-free").system
    assert build_model(free, {"wing_a": 2, "wing_b": 3}) is build_model(
        free, {"wing_b": 3, "wing_a": 2})
    assert build_model(free, [2, 3]) is build_model(free, (2, 3))


def test_natural_frequencies_kept_per_spin_are_the_callers_own_copies(kane_system):
    import scipy.linalg

    from flexctl.model.variants import KEPT_SPINS

    model = build_model(kane_system, n_modes=3)
    first = model.natural_frequencies(4.0)
    first[:] = -1.0                                  # the caller's array, not the kept one
    again = model.natural_frequencies(4.0)
    direct = np.sqrt(scipy.linalg.eigh(model.stiffness_matrix(4.0), model.matrices.M_ff,
                                       eigvals_only=True))
    np.testing.assert_allclose(again, direct, rtol=1e-12)
    assert np.all(again > model.natural_frequencies(0.0))     # spin stiffens every mode
    for spin in np.linspace(0.1, 5.0, 40):            # the kept spins stay few
        model.natural_frequencies(float(spin))
    assert len(model._c["frequencies"]) <= KEPT_SPINS
