"""Every built-in controller has a CasADi form that is its numpy law, and runs compiled.

Two contracts per controller: ``casadi_torque`` (and ``casadi_derivative`` for the LQG
estimator) evaluates to ``torque`` (``derivative``) at random states and times, hold switches
and reference ends included; and a closed-loop ``simulate`` takes the compiled CVODES path and
agrees with the SciPy path within the integration tolerance. A user's Python controller keeps
the SciPy path.
"""

import casadi as ca
import numpy as np
import pytest

from controllers import (LQRWeights, NoiseLevels, OpenLoop, SlewProfile, SumOfSines,
                         bang_bang, design_lqg, design_lqr, design_pd,
                         design_scheduled_lqr, design_shaper, from_spec, shape)
from controllers.feedback.pd import PD
from flexctl import build_model, load_scene, simulate
from flexctl.sim import compiled
from flexctl.sim.compiled import is_symbolic, piecewise_constant

#: Largest difference between a CasADi form and its numpy law, relative to max(1, |value|).
LAW_TOLERANCE = 1e-12
#: Random (time, state) samples per controller.
SAMPLES = 200
#: Closed-loop runs at this tolerance ...
CLOSED_LOOP_RTOL = 1e-8
#: ... agree in tip deflection (relative to its peak) and hub angle (rad) within these.
TIP_AGREEMENT = 1e-5
ANGLE_AGREEMENT = 1e-6
#: Plant and design mode counts: the plant has more, so every law truncates.
PLANT_MODES, DESIGN_MODES = 4, 2
SLEW = np.pi / 2
T_FINAL = 4.0

#: The compiled paths a run with CasADi inputs may take under method="auto".
COMPILED = ("cvodes", "RK45", "dop853")


@pytest.fixture(scope="module")
def scene():
    return load_scene("slew-90")


@pytest.fixture(scope="module")
def plant(scene):
    return build_model(scene.system, n_modes=PLANT_MODES)


@pytest.fixture(scope="module")
def design(scene):
    return build_model(scene.system, n_modes=DESIGN_MODES)


def _direct_controllers(design, plant):
    """Controllers built by hand, covering each option of each law."""
    weights = LQRWeights(hub_angle=0.05, hub_rate=0.02, tip_deflection=0.01, torque=1.0)
    poly7 = SlewProfile(slew_angle=SLEW, duration=2.0)
    cycloidal = SlewProfile(slew_angle=SLEW, duration=1.5, start_time=0.25, shape="cycloidal")
    noise = SumOfSines.from_levels([1e-3, 0.05], bandwidth=20.0, n_sines=8)
    base = bang_bang(design, SLEW, duration=2.0)
    shaper = design_shaper(design, "zvd")
    return {
        "pd-regulator": PD(kp=12.0, kd=8.0, torque_limit=6.0),
        "pd-reference": design_pd(design, 2.0, 0.9, reference=poly7, torque_limit=6.0),
        "pd-shaped-reference": design_pd(design, 3.0, 0.7, reference=shape(poly7, shaper)),
        "lqr-rigid-reference": design_lqr(design, weights, reference=cycloidal,
                                          flexible_reference=False),
        "lqr-flexible-reference": design_lqr(design, weights, reference=poly7,
                                             torque_limit=6.0),
        "scheduled": design_scheduled_lqr(design, weights, [0.0, 0.5, 1.0, 2.0],
                                          reference=poly7, torque_limit=6.0),
        "lqg": design_lqg(design, weights, NoiseLevels(angle=1e-3, root_moment=0.1,
                                                       torque=0.1),
                          plant=plant, reference=poly7, torque_limit=6.0),
        "lqg-noisy": design_lqg(design, weights, NoiseLevels(angle=1e-3, root_moment=0.1,
                                                             torque=0.1),
                                plant=plant, reference=poly7, measurement_noise=noise),
        "bang-bang": OpenLoop(base),
        "zvd": OpenLoop(shape(base, shaper)),
    }


@pytest.fixture(scope="module")
def controllers(scene, design, plant):
    built = _direct_controllers(design, plant)
    for kind in ("trajopt", "trajopt+lqr"):
        kind_scene = load_scene("slew-90", overrides={"controller.kind": kind,
                                                      "model.modes": PLANT_MODES})
        built[kind] = from_spec(kind_scene, plant=plant).controller
    return built


NAMES = ["pd-regulator", "pd-reference", "pd-shaped-reference", "lqr-rigid-reference",
         "lqr-flexible-reference", "scheduled", "lqg", "lqg-noisy", "bang-bang", "zvd",
         "trajopt", "trajopt+lqr"]


def _casadi_law(controller, nx, symbol=ca.SX):
    """``(t, x, z) -> (torque, dz/dt)`` evaluated through CasADi."""
    t, x = symbol.sym("t"), symbol.sym("x", nx)
    nz = controller.n_states
    if nz:
        z = symbol.sym("z", nz)
        f = ca.Function("law", [t, x, z], [controller.casadi_torque(t, x, z),
                                           controller.casadi_derivative(t, x, z)])
        return lambda tv, xv, zv: tuple(np.array(v).reshape(-1) for v in f(tv, xv, zv))
    if getattr(controller, "casadi_parameters", None) is not None:
        # the parametric form, its numbers fed in as values
        values = controller.casadi_parameters[1]
        c = symbol.sym("c", values.size)
        f = ca.Function("law", [t, x, c], [controller.casadi_torque(t, x, c)])
        return lambda tv, xv, zv: (np.array(f(tv, xv, values)).reshape(-1), np.zeros(0))
    f = ca.Function("law", [t, x], [controller.casadi_torque(t, x)])
    return lambda tv, xv, zv: (np.array(f(tv, xv)).reshape(-1), np.zeros(0))


def _samples(controller, nx, rng):
    """Times (breakpoints and their neighbours included) and states, some saturating."""
    points = np.array(getattr(controller, "breakpoints", ()) or (), dtype=float)
    near = np.concatenate((points, np.nextafter(points, -np.inf),
                           np.nextafter(points, np.inf)))
    times = np.concatenate((rng.uniform(-0.5, 6.0, SAMPLES - near.size % SAMPLES), near))
    size = np.r_[2.0, np.full((nx - 2) // 2, 0.02), 1.0, np.full((nx - 2) // 2, 0.5)]
    # a quarter of the states small enough to keep the torque off its limit
    shrink = np.where(rng.uniform(size=times.size) < 0.25, 0.01, 1.0)
    states = rng.uniform(-1.0, 1.0, (times.size, nx)) * size * shrink[:, None]
    return times, states


@pytest.mark.parametrize("name", NAMES, ids=NAMES)
def test_casadi_law_equals_numpy_law(controllers, plant, name):
    controller = controllers[name]
    assert is_symbolic(controller=controller)
    rng = np.random.default_rng(9)
    law = _casadi_law(controller, plant.n_states)
    times, states = _samples(controller, plant.n_states, rng)
    for t, x in zip(times, states):
        z = rng.uniform(-1.0, 1.0, controller.n_states)
        u_sym, dz_sym = law(t, x, z)
        u_num = controller.torque(t, x, z)
        assert abs(u_sym[0] - u_num) <= LAW_TOLERANCE * max(1.0, abs(u_num)), (t, u_num)
        if controller.n_states:
            dz_num = controller.derivative(t, x, z)
            np.testing.assert_allclose(dz_sym, dz_num, rtol=LAW_TOLERANCE,
                                       atol=LAW_TOLERANCE * max(1.0, np.max(np.abs(dz_num))))


@pytest.mark.parametrize("name", NAMES, ids=NAMES)
def test_compiled_closed_loop_agrees_with_scipy(controllers, plant, name):
    controller = controllers[name]
    x0 = np.zeros(plant.n_states)
    if name == "pd-regulator":
        x0[0] = -SLEW
    runs = {method: simulate(plant, T_FINAL, controller=controller, x0=x0, method=method,
                             rtol=CLOSED_LOOP_RTOL, output_step=0.01)
            for method in ("auto", "DOP853")}
    compiled, scipy = runs["auto"], runs["DOP853"]
    assert compiled.method in COMPILED and compiled.ok and scipy.ok, compiled.message
    np.testing.assert_array_equal(compiled.t, scipy.t)
    peak = scipy.peak_tip_deflection
    assert np.max(np.abs(compiled.tip_deflection - scipy.tip_deflection)) <= TIP_AGREEMENT * peak
    assert np.max(np.abs(compiled.theta - scipy.theta)) <= ANGLE_AGREEMENT
    if controller.n_states:
        scale = np.max(np.abs(scipy.controller_states))
        assert np.max(np.abs(compiled.controller_states - scipy.controller_states)) \
            <= ANGLE_AGREEMENT * max(1.0, scale)


@pytest.mark.parametrize("name", NAMES, ids=NAMES)
def test_casadi_law_builds_on_mx_symbols(controllers, plant, name):
    """The exact variant's right-hand side is an MX graph: every law must build on MX too."""
    controller = controllers[name]
    rng = np.random.default_rng(5)
    law = _casadi_law(controller, plant.n_states, symbol=ca.MX)
    times, states = _samples(controller, plant.n_states, rng)
    for t, x in list(zip(times, states))[::10]:
        z = rng.uniform(-1.0, 1.0, controller.n_states)
        u_num = controller.torque(t, x, z)
        assert abs(law(t, x, z)[0][0] - u_num) <= LAW_TOLERANCE * max(1.0, abs(u_num))


@pytest.mark.parametrize("name", ["pd-regulator", "pd-reference", "lqr-flexible-reference"])
def test_constant_form_equals_parametric_form(controllers, plant, name):
    controller = controllers[name]
    t, x = ca.SX.sym("t"), ca.SX.sym("x", plant.n_states)
    c = ca.SX.sym("c", controller.casadi_parameters[1].size)
    f = ca.Function("law", [t, x, c], [controller.casadi_torque(t, x),
                                       controller.casadi_torque(t, x, c)])
    rng = np.random.default_rng(3)
    for tv in rng.uniform(0.0, 3.0, 20):
        xv = rng.uniform(-0.2, 0.2, plant.n_states)
        constant, parametric = (float(v) for v in f(tv, xv, controller.casadi_parameters[1]))
        assert abs(constant - parametric) <= LAW_TOLERANCE * max(1.0, abs(constant))


def test_laws_differing_only_in_numbers_share_their_integrators(plant):
    """A second PD of other gains reuses the integrators built for the first, with its own
    numbers: the result equals that of a fresh build."""
    x0 = np.zeros(plant.n_states)
    x0[0] = -SLEW
    first, second = PD(kp=12.0, kd=8.0, torque_limit=6.0), PD(kp=20.0, kd=5.0, torque_limit=4.0)
    compiled._INTEGRATOR_CACHE.clear()
    compiled._RHS_CACHE.clear()
    # the runs alone (the validity estimate's own runs on small models build their own)
    run = {"x0": x0, "rtol": 1e-7, "check_validity": False}
    simulate(plant, 2.0, controller=first, **run)
    built = len(compiled._INTEGRATOR_CACHE), len(compiled._RHS_CACHE)
    reused = simulate(plant, 2.0, controller=second, **run)
    assert (len(compiled._INTEGRATOR_CACHE), len(compiled._RHS_CACHE)) == built
    compiled._INTEGRATOR_CACHE.clear()
    compiled._RHS_CACHE.clear()
    fresh = simulate(plant, 2.0, controller=second, **run)
    np.testing.assert_array_equal(reused.states, fresh.states)
    np.testing.assert_array_equal(reused.torque, fresh.torque)
    assert np.max(np.abs(reused.torque)) == pytest.approx(4.0)


def test_python_controllers_keep_the_scipy_path(plant, design):
    pd = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    x0 = np.zeros(plant.n_states)
    x0[0] = -SLEW

    def law(t, x):
        return pd.torque(t, x)

    class NoForm:
        """A reference without a CasADi form makes its controller a Python one."""

        def angle(self, t):
            return 0.0 * np.asarray(t)

        rate = acceleration = angle

    assert not is_symbolic(controller=law)
    assert not is_symbolic(controller=design_pd(design, 2.0, reference=NoForm()))
    assert not is_symbolic(controller=OpenLoop(lambda t: 0.0))
    result = simulate(plant, 1.0, controller=law, x0=x0, rtol=1e-6)
    assert result.ok and result.method == "DOP853"
    with pytest.raises(ValueError, match="CasADi form"):
        simulate(plant, 1.0, controller=law, x0=x0, method="cvodes")


def test_piecewise_constant_is_the_hold():
    edges = np.array([0.5, 1.0, 2.0])
    values = np.array([3.0, -1.0, 7.5, 0.25])
    t = ca.SX.sym("t")
    f = ca.Function("hold", [t], [piecewise_constant(t, edges, values)])
    for tv in (-1.0, 0.0, 0.5 - 1e-15, 0.5, 0.99, 1.0, 1.5, 2.0, 1e9):
        k = int(np.searchsorted(edges, tv, side="right"))
        assert float(f(tv)) == values[k]
    with pytest.raises(ValueError, match="3 edges for 4 values"):
        piecewise_constant(t, edges[:2], values)
