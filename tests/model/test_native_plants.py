"""Plants and results the python-control, CasADi and pandas way: discrete steps, laws as
I/O systems wired with ``control.interconnect``, results as DataFrames and full CSV files."""

import csv

import numpy as np
import pytest

import flexctl
from controllers import from_spec, to_iosys
from flexctl.app.cli import main
from flexctl.model.errors import InputTypeError, InputValueError


@pytest.fixture(scope="module")
def plant():
    scene = flexctl.load_scene("slew-90", {"model.variant": "first_order", "model.modes": 3})
    return scene, scene.build_model()


# ---------------------------------------------------------------- discretize
@pytest.mark.parametrize("variant", ["first_order", "exact"])
def test_discrete_step_meets_its_stated_accuracy(variant):
    model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2,
                                variant=variant)
    rk4 = model.discretize(0.02)
    assert rk4.function.name_in() == ["x", "u"] and rk4.function.name_out() == ["x_next"]
    assert rk4.substeps >= np.ceil(rk4.fastest_frequency * 0.02 / 0.5)
    reference = model.discretize(0.02, "cvodes", rtol=1e-11)
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = np.zeros(model.n_states)
        x[model.layout.q] = rng.normal(scale=0.01, size=model.layout.n_modes)
        x[model.layout.theta_dot] = rng.normal(scale=0.1)
        u = rng.normal()
        got = np.array(rk4(x, u)).ravel()
        exact = np.array(reference(x, u)).ravel()
        # the stated accuracy, with a factor 3 for states other than the probes
        assert np.max(np.abs(got - exact)) <= 3 * rk4.relative_error * np.max(np.abs(exact))
    # finer substeps: the error falls as h^4 (measured error, not the stated one)
    fine = model.discretize(0.02, substeps=4 * rk4.substeps)
    assert fine.relative_error < rk4.relative_error / 50


def test_discrete_step_in_an_opti_problem():
    import casadi as ca

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    step = model.discretize(0.05)
    opti = ca.Opti()
    n = model.n_states
    x = opti.variable(n, 11)
    u = opti.variable(1, 10)
    opti.subject_to(x[:, 0] == 0)
    for k in range(10):
        opti.subject_to(x[:, k + 1] == step(x[:, k], u[k]))
    opti.subject_to(x[model.layout.theta, 10] == 0.05)
    opti.minimize(ca.sumsqr(u))
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes"})
    solution = opti.solve()
    assert abs(solution.value(x[0, 10]) - 0.05) < 1e-8


def test_discretize_refuses_bad_settings():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    for dt in (0.0, -1.0, np.nan, np.inf, "0.1", None):
        with pytest.raises((InputTypeError, InputValueError), match="dt"):
            model.discretize(dt)
    with pytest.raises(InputValueError, match="method"):
        model.discretize(0.01, "euler")
    with pytest.raises((InputTypeError, InputValueError), match="substeps"):
        model.discretize(0.01, substeps=0)
    with pytest.raises((InputTypeError, InputValueError), match="substeps"):
        model.discretize(0.01, substeps=2.5)
    with pytest.raises(InputValueError, match="stability"):
        model.discretize(1.0, substeps=1)
    with pytest.raises(InputValueError, match="substeps"):
        model.discretize(0.01, "cvodes", substeps=2)
    with pytest.raises((InputTypeError, InputValueError), match="rtol"):
        model.discretize(0.01, "cvodes", rtol=0.0)


# ---------------------------------------------------------------- laws as I/O systems
def _closed_loop_response(model, law, x0, t):
    import control

    if type(law).__name__ == "LQG":
        parts = [model.nonlinear(), to_iosys(law, model)]
        z0 = law.for_plant(model).initial_state(x0)
        start = np.concatenate((x0, z0))
    else:
        parts = [model.nonlinear(outputs="states"), to_iosys(law, model)]
        start = x0
    loop = control.interconnect(parts, inplist=[], outlist=["theta"], check_unused=False)
    response = control.input_output_response(
        loop, t, X0=start, solve_ivp_method="LSODA",
        solve_ivp_kwargs={"rtol": 1e-9, "atol": 1e-11})
    return np.ravel(response.outputs)


@pytest.mark.parametrize("kind", ["pd", "lqr", "scheduled", "trajopt+lqr", "lqg"])
def test_interconnect_reproduces_simulate(plant, kind):
    scene, model = plant
    scene = flexctl.load_scene("slew-90", {"model.variant": "first_order", "model.modes": 3,
                                           "controller.kind": kind})
    law = from_spec(scene, model).controller
    t = np.linspace(0.0, 3.0, 61)
    x0 = np.zeros(model.n_states)
    ours = flexctl.simulate(model, 3.0, controller=law, rtol=1e-10)
    theirs = _closed_loop_response(model, law, x0, t)
    expected = np.interp(t, ours.t, ours.theta)
    assert expected[-1] > 1.0                     # the slew happened
    print(f"{kind}: {np.max(np.abs(theirs - expected)):.2e} rad")
    assert np.max(np.abs(theirs - expected)) <= 1e-5 * np.pi / 2


def test_to_iosys_names_and_refusals(plant):
    scene, model = plant
    law = from_spec(flexctl.load_scene("slew-90", {"controller.kind": "lqg"}), model).controller
    system = to_iosys(law, model)
    assert system.input_labels == ["theta", "root_moment"]
    assert system.output_labels == ["torque"]
    assert system.nstates == law.n_states and system.state_labels[0] == "xhat_theta"
    with pytest.raises(InputTypeError, match="Model"):
        to_iosys(law, "plant")
    # a name is joined to the signals' names by python-control: a number failed inside re
    with pytest.raises(InputTypeError, match="name must be a str; got 5"):
        to_iosys(law, model, name=5)
    with pytest.raises(InputValueError, match="without dots; got 'a.b'"):
        to_iosys(law, model, name="a.b")
    assert to_iosys(law, model, name="estimator").name == "estimator"
    with pytest.raises(InputTypeError, match="feedback law"):
        to_iosys(lambda t, x: 0.0, model)
    from flexctl.sim.digital import ZeroOrderHold
    pd = from_spec(flexctl.load_scene("slew-90", {"controller.kind": "pd"}), model).controller
    held = to_iosys(ZeroOrderHold(pd, 0.01), model)
    assert held.dt == 0.01 and held.nstates == 0 and held.output_labels == ["torque"]
    bus = flexctl.load_scene("bus-slew")
    bus_plant = bus.build_model()
    observed = from_spec(bus, bus_plant).controller
    with pytest.raises(InputValueError, match="sampled law with states of its own"):
        to_iosys(observed, bus_plant)
    with pytest.raises(InputValueError, match="outputs"):
        model.nonlinear(outputs="all")


# ---------------------------------------------------------------- results
def test_result_to_pandas(plant):
    pd = pytest.importorskip("pandas")
    _, model = plant
    result = flexctl.simulate(model, 0.5, torque=flexctl.SineTorque(peak_torque=1.0,
                                                                    duration=0.5))
    frame = result.to_pandas()
    assert isinstance(frame, pd.DataFrame) and frame.index.name == "t"
    np.testing.assert_array_equal(frame.index.to_numpy(), result.t)
    for name in (*model.output_names, *model.state_names, "torque"):
        assert name in frame.columns, name
    np.testing.assert_array_equal(frame["root_moment"], result.outputs["root_moment"])
    np.testing.assert_array_equal(frame["q2_dot"], result.states[model.state_names.index(
        "q2_dot")])
    assert frame.attrs["status"] == "ok"
    assert "q1" not in result.to_pandas(states=False).columns


def test_timeseries_has_every_output_and_optionally_every_state(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "hub-beam-mass", "--out", str(out), "--set",
                 "simulation.t_final=0.5"]) == 0
    header = next(csv.reader(open(out / "timeseries.csv")))
    assert "root_moment" in header and "tip_angle" in header
    assert "q1_dot" not in header
    assert main(["run", "hub-beam-mass", "--out", str(out), "--set",
                 "simulation.t_final=0.5", "--set", "simulation.states=true"]) == 0
    rows = list(csv.reader(open(out / "timeseries.csv")))
    header = rows[0]
    assert "q1_dot" in header and len(header) == len(set(header))
    k = header.index("q1_dot")
    assert np.all(np.isfinite([float(r[k]) for r in rows[1:]]))
    assert main(["run", "hub-beam-mass", "--out", str(out), "--set",
                 "simulation.states=1"]) == 2


# ---------------------------------------------------------------- physical parameters
KEYS = ["beam.youngs_modulus", "hub.inertia", "masses[0].mass", "hub.friction"]


def _rebuilt(model, key, value):
    from flexctl.model.build import rebuild
    from flexctl.model.parametric import with_parameter

    return rebuild(model, system=with_parameter(model.system, key, value))


def test_parametric_dynamics_exact_at_nominal_with_the_models_derivative():
    import casadi as ca

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=3)
    f = model.casadi(parameters=KEYS)
    assert f.name_in() == ["x", "u", "p"]
    p0 = model.parameter_values(KEYS)
    rng = np.random.default_rng(1)
    x = rng.normal(scale=0.01, size=model.n_states)
    np.testing.assert_allclose(np.array(f(x, 0.7, p0)).ravel(), model.dynamics(0.0, x, 0.7),
                               rtol=1e-13, atol=1e-15)
    p = ca.SX.sym("p", len(KEYS))
    jac = ca.Function("j", [p], [ca.jacobian(f(x, 0.7, p), p)])
    got = np.array(jac(p0))
    for i, key in enumerate(KEYS):
        h = 1e-3 * (abs(p0[i]) or 1.0)
        lower = p0[i] - h if p0[i] - h >= 0 else p0[i]
        width = p0[i] + h - lower
        diff = (_rebuilt(model, key, p0[i] + h).dynamics(0.0, x, 0.7)
                - _rebuilt(model, key, lower).dynamics(0.0, x, 0.7)) / width
        assert np.max(np.abs(got[:, i] - diff)) <= 2e-3 * np.max(np.abs(diff)) + 1e-12, key


def test_parametric_dynamics_linear_parameters_exact_away_from_nominal():
    """An undamped beam's stiffness and the hub friction enter the dynamics linearly: the
    expansion is exact at other values too; the hub inertia (through 1/J) is first order."""
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=3)
    f = model.casadi(parameters=KEYS)
    p0 = model.parameter_values(KEYS)
    x = np.random.default_rng(2).normal(scale=0.01, size=model.n_states)
    x[model.layout.theta_dot] = 0.5
    for i, (key, factor, tol) in enumerate([("beam.youngs_modulus", 1.3, 1e-10),
                                            ("hub.inertia", 1.05, 2e-3)]):
        p = p0.copy()
        p[i] *= factor
        exact = _rebuilt(model, key, p[i]).dynamics(0.0, x, 0.7)
        got = np.array(f(x, 0.7, p)).ravel()
        assert np.max(np.abs(got - exact)) <= tol * np.max(np.abs(exact)), key


def test_parameters_of_a_structure_and_through_python_control():
    import control

    model = flexctl.build_model(flexctl.load_scene("two-array-free").system, n_modes=2)
    keys = ["appendages[1].beam.youngs_modulus", "hub.inertia"]
    f = model.casadi(parameters=keys)
    p0 = model.parameter_values(keys)
    x = np.zeros(model.n_states)
    np.testing.assert_allclose(np.array(f(x, 1.0, p0)).ravel(), model.dynamics(0.0, x, 1.0),
                               rtol=1e-13, atol=1e-15)
    with pytest.raises(InputValueError, match="appendages"):
        model.casadi(parameters=["beam.youngs_modulus"])
    plant = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    system = plant.nonlinear(params=["beam.youngs_modulus"])
    assert system.params == {"beam.youngs_modulus": 6.9e10}
    x0 = np.zeros(plant.n_states)
    x0[1] = 0.01
    t = np.linspace(0.0, 1.0, 51)
    stiffer = control.input_output_response(system, t, 0.0, X0=x0,
                                            params={"beam.youngs_modulus": 8.0e10})
    rebuilt = control.input_output_response(_rebuilt(plant, "beam.youngs_modulus", 8.0e10)
                                            .nonlinear(), t, 0.0, X0=x0)
    np.testing.assert_allclose(stiffer.outputs, rebuilt.outputs, rtol=0, atol=1e-9)


def test_parameter_names_are_checked():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    cases = [(["beam.colour"], InputValueError, "no 'colour'"),
             (["masses[3].mass"], InputValueError, "index 3"),
             (["hub.support"], InputValueError, "not a number"),
             (["Beam.Length!"], InputValueError, "scene key"),
             ([3], InputTypeError, "scene key"),
             (["hub.inertia", "hub.inertia"], InputValueError, "twice"),
             ([], InputValueError, "at least one"),
             ("hub.inertia", InputTypeError, "list")]
    for parameters, error, text in cases:
        with pytest.raises(error, match=text):
            model.casadi(parameters=parameters)
    with pytest.raises(InputTypeError, match="params"):
        model.nonlinear(params="hub.inertia")


def test_discrete_step_with_parameters():
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    keys = ["beam.youngs_modulus", "hub.inertia"]
    p0 = model.parameter_values(keys)
    x = np.zeros(model.n_states)
    x[1] = 0.01
    for method in ("rk4", "cvodes"):
        plain = model.discretize(0.02, method)
        with_p = model.discretize(0.02, method, parameters=keys)
        assert with_p.function.name_in() == ["x", "u", "p"]
        np.testing.assert_allclose(np.array(with_p(x, 0.3, p0)).ravel(),
                                   np.array(plain(x, 0.3)).ravel(), rtol=1e-12, atol=1e-15)
