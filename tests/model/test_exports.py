"""python-control and CasADi views of a model evaluate the same equations as the model."""

import casadi as ca
import control
import numpy as np
import pytest

import flexctl
from conftest import random_states
from flexctl.model.errors import InputValueError
from flexctl import VARIANTS, build_model
from flexctl.model.exact import PANEL_TOLERANCE
from flexctl.model.exports import to_casadi, to_casadi_outputs, to_nonlinear_iosystem

#: Three implementations of the same arithmetic agree to round-off.
EXPORT_RTOL = 1e-9
N_SAMPLES = 20
N_MODES = 4


def _assert_close(got, expected, what, rtol=EXPORT_RTOL):
    got, expected = np.asarray(got, dtype=float).ravel(), np.asarray(expected).ravel()
    scale = np.max(np.abs(expected))
    np.testing.assert_allclose(got, expected, rtol=rtol, atol=rtol * scale, err_msg=what)


@pytest.fixture(scope="module", params=VARIANTS)
def model(request, lossy_hub_beam_mass_system):
    """Every variant, with point mass, beam damping and hub friction."""
    return build_model(lossy_hub_beam_mass_system, n_modes=N_MODES, variant=request.param)


def test_casadi_and_nonlinear_iosystem_equal_the_model_dynamics(model, rng):
    sys = model.nonlinear()
    f_sx = model.casadi()
    f_mx = to_casadi(model, sx=False)
    states = random_states(model, rng, N_SAMPLES)
    torques = rng.uniform(-5.0, 5.0, N_SAMPLES)
    for x, u in zip(states.T, torques):
        reference = model.dynamics(0.0, x, u)
        _assert_close(sys.updfcn(0.0, x, np.array([u]), {}), reference, "updfcn")
        _assert_close(sys._rhs(0.0, x, np.array([u])), reference, "_rhs")
        _assert_close(f_sx(x, u), reference, "casadi SX")
        _assert_close(f_mx(x, u), reference, "casadi MX")


def test_outputs_agree(model, rng):
    sys = model.nonlinear()
    h = to_casadi_outputs(model)
    for x in random_states(model, rng, 5).T:
        reference = model.outputs(x)
        _assert_close(sys.outfcn(0.0, x, np.array([0.0]), {}), reference, "outfcn")
        _assert_close(h(x), reference, "casadi outputs")


def test_casadi_jacobian_equals_the_linear_model(model):
    """The exact symbolic Jacobian at a steady spin is the linearization's A and B."""
    x, u = ca.SX.sym("x", model.n_states), ca.SX.sym("u", 1)
    xdot = model.casadi()(x, u)
    jac = ca.Function("linear_parts", [x, u], [ca.jacobian(xdot, x), ca.jacobian(xdot, u)])
    for spin in (0.0, 1.5):
        x0 = np.zeros(model.n_states)
        x0[model.n_modes + 1] = spin
        a_sym, b_sym = (np.array(m) for m in jac(x0, 0.0))
        a, b = model.linear_matrices(spin)
        # the exact variant linearises to first_order's matrices up to its own quadrature
        rtol = 10 * PANEL_TOLERANCE if model.variant == "exact" else EXPORT_RTOL
        _assert_close(a_sym, a, f"A at spin {spin}", rtol)
        _assert_close(b_sym, b, f"B at spin {spin}", rtol)


def test_export_signatures(model):
    f = model.casadi()
    assert f.name_in() == ["x", "u"] and f.name_out() == ["xdot"]
    assert f.size_in(0) == (model.n_states, 1) and f.size_in(1) == (1, 1)
    assert f.size_out(0) == (model.n_states, 1)
    sys = to_nonlinear_iosystem(model)
    assert isinstance(sys, control.NonlinearIOSystem)
    assert (sys.nstates, sys.ninputs, sys.noutputs) == (model.n_states, 1,
                                                        len(model.output_names))
    assert sys.state_labels == list(model.state_names)
    assert sys.output_labels == list(model.output_names)


def test_nonlinear_iosystem_simulates_like_flexctl(hub_beam_mass_system):
    """A python-control simulation of the export follows flexctl's own simulation."""
    from flexctl import simulate
    from flexctl.sim.maneuvers import SineTorque

    model = build_model(hub_beam_mass_system, n_modes=2)
    push = SineTorque(peak_torque=2.0, duration=2.0)
    t = np.linspace(0.0, 2.0, 201)
    response = control.input_output_response(
        model.nonlinear(), t, push(t), np.zeros(model.n_states),
        solve_ivp_kwargs=dict(method="DOP853", rtol=1e-10, atol=1e-12))
    ours = simulate(model, 2.0, torque=push, output_step=0.01, rtol=1e-10)
    tip = response.outputs[list(model.output_names).index("tip_deflection")]
    # python-control interpolates the sampled input linearly: an O(dt^2) torque error
    scale = np.max(np.abs(ours.tip_deflection))
    np.testing.assert_allclose(tip, ours.tip_deflection, atol=1e-3 * scale)
    np.testing.assert_allclose(response.states[0], ours.theta, atol=1e-3 * np.max(ours.theta))


#: python-control's finite-difference linearisation against the exact Jacobians, relative.
OPERATING_POINT_TOLERANCE = 1e-5


@pytest.mark.parametrize("variant", flexctl.VARIANTS)
@pytest.mark.parametrize("scene", ["hub-beam-mass", "two-array-free", "wheel-slew"])
def test_linearisation_about_any_operating_point_is_control_linearize(scene, variant):
    """A deflected, spinning, accelerating state: the plant is python-control's
    ``linearize`` of ``model.nonlinear()`` there, and its drift is ``dynamics(x0, u0)``."""
    import control

    system = flexctl.load_scene(scene)
    model = system.build_model() if scene == "wheel-slew" else None
    model = (flexctl.build_model(system.system, 2, variant) if model is None else
             flexctl.build_model(system.system, 2, variant, actuator=system.actuator))
    rng = np.random.default_rng(7)
    x0 = model.rest_state(0.3)
    x0[model.layout.q] = 0.02 * rng.normal(size=model.n_modes)
    x0[model.layout.q_dot] = 0.05 * rng.normal(size=model.n_modes)
    x0[model.layout.theta_dot] = 0.8
    plant = model.linearize(x0=x0, u0=0.02)
    reference = control.linearize(model.nonlinear(), x0, [0.02])
    for name in ("A", "B", "C"):
        ours, theirs = getattr(plant, name), getattr(reference, name)
        assert np.max(np.abs(ours - theirs)) <= OPERATING_POINT_TOLERANCE * max(
            1.0, np.max(np.abs(ours))), name
    assert np.allclose(plant.drift, model.dynamics(0.0, x0, 0.02), rtol=1e-12, atol=1e-12)
    assert plant.state_labels == model.nonlinear().state_labels


def test_operating_point_refusals():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 2)
    with pytest.raises(InputValueError, match="spin_rate or an operating point"):
        model.linearize(1.0, x0=model.rest_state())
    with pytest.raises(InputValueError, match="linearize.x0"):
        model.linearize(x0=np.zeros(3))
    with pytest.raises(InputValueError, match="linearize.u0"):
        model.linearize(u0=float("nan"))


@pytest.mark.parametrize("scene", ["hub-beam-mass", "two-array-free", "wheel-slew"])
def test_casadi_outputs_and_time_response_carry_the_named_signals(scene):
    loaded = flexctl.load_scene(scene)
    model = loaded.build_model() if scene == "wheel-slew" else build_model(loaded.system, 2)
    h = model.casadi_outputs()
    assert h.name_in() == ["x", "u"] and h.name_out() == ["y"]
    x = model.rest_state(0.2)
    x[model.layout.q] = 0.01
    assert np.allclose(np.array(h(x, 0.3)).ravel(), model.outputs(x), rtol=1e-12, atol=1e-15)
    result = flexctl.simulate(model, 0.5, torque=lambda t: 0.01, output_step=0.05)
    response = result.to_time_response()
    assert response.output_labels == list(model.nonlinear().output_labels)
    assert response.input_labels == list(model.input_names)
    assert np.allclose(response.outputs, model.outputs(result.states))
    assert np.allclose(response.states, result.states) and response.success
    assert np.allclose(response.inputs, 0.01)


@pytest.mark.parametrize("x0, u0", [(np.zeros(3), 0.0), (np.full(6, np.nan), 0.0),
                                    (np.zeros(6), float("inf")), ("rest", 0.0),
                                    (np.zeros(6), "1"), (np.zeros((6, 6)), 0.0)])
def test_dynamics_jacobians_refuse_bad_points_by_name(x0, u0):
    import flexctl
    from flexctl.model.exports import dynamics_jacobians

    model = flexctl.build_model(flexctl.load_scene("slew-90").system, 2)
    with pytest.raises((TypeError, ValueError), match="x0|u0"):
        dynamics_jacobians(model, x0, u0)


def test_dynamics_jacobians_are_the_linearisation():
    """At rest, ``A`` and ``B`` are the linearised plant's, and the drift is zero."""
    import flexctl
    from flexctl.model.exports import dynamics_jacobians

    model = flexctl.build_model(flexctl.load_scene("slew-90").system, 2)
    drift, a, b = dynamics_jacobians(model, model.layout.zeros())
    plant = model.linearize()
    np.testing.assert_allclose(a, plant.A, rtol=1e-12, atol=1e-12 * np.max(np.abs(a)))
    np.testing.assert_allclose(b, plant.B, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(drift, 0.0)


@pytest.mark.parametrize("variant", ["first_order", "exact"])
def test_linearize_refuses_the_states_simulate_refuses(hub_beam_mass_system, variant):
    # a modal tip five beam lengths out: simulate refused it, linearize returned finite matrices
    model = flexctl.build_model(hub_beam_mass_system, n_modes=2, variant=variant)
    far = model.rest_state()
    far[model.layout.q.start] = 2.5 * hub_beam_mass_system.beam.length
    messages = []
    for call in (lambda: model.linearize(x0=far), lambda: flexctl.simulate(model, 1.0, x0=far)):
        with pytest.raises(InputValueError, match="x0 puts the modal tip at") as refused:
            call()
        messages.append(str(refused.value).removeprefix("linearize: "))
    assert messages[0] == messages[1]


def test_linearize_refuses_a_singular_mass_matrix(spacecraft_system):
    # the consistent model of a massless hub, deflected: its effective hub inertia is negative
    model = flexctl.build_model(spacecraft_system, n_modes=2, variant="consistent")
    bent = model.rest_state()
    bent[model.layout.q.start] = 0.2 * spacecraft_system.beam.length
    assert model.effective_hub_inertia(bent) < 0.0
    with pytest.raises(flexctl.SingularMassMatrixError, match="effective hub inertia .* not "
                                                              "positive"):
        model.linearize(x0=bent)
