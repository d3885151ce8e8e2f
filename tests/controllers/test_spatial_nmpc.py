"""The three-axis NMPC (:mod:`controllers.mpc.spatial_nmpc`): its linearisation is the hold's,
it slews the two arrays to rest on target through wheels within their limits, and it follows
a planned slew."""

import shutil

import numpy as np
import pytest

from controllers.feedback.lqr import LQRWeights
from controllers.mpc.spatial_nmpc import (SpatialNMPC, _attitude_errors, _hold_jacobians,
                                          design_spatial_nmpc)
from controllers.slew.spatial_trajopt import (SpatialSlewProblem, hold_functions,
                                              solve_spatial_slew)
from flexctl.model.errors import InputError
from flexctl.model.wheel_cluster import WheelCluster
from flexctl.sim.quaternions import (conjugate, error_angles, from_rotation_vector, product,
                                     rotation_vector)
from flexctl.sim.spatial_loop import simulate_spatial_loop
from tests.controllers.test_spatial_trajopt import CRAFT, TARGET, WHEELS


PYRAMID = WheelCluster.pyramid(angle=54.7356, distribution="null_motion", null_gain=0.2,
                               bias_speed=30.0, inertia=0.01, torque_limit=0.1,
                               speed_limit=314.16)
WEIGHTS = LQRWeights(hub_angle=0.05, hub_rate=0.05, tip_deflection=0.005, torque=0.1)


def _fly(law, wheels, t_final=20.0):
    loop = simulate_spatial_loop(CRAFT, t_final, law, sample_time=law.sample_time,
                                 n_modes=2, variant="exact", wheels=wheels, rtol=1e-8)
    assert loop.ok
    return loop.result, loop.session


@pytest.mark.parametrize("wheels", [WHEELS, PYRAMID, None],
                         ids=["wheels", "a null-motion pyramid", "hub torque"])
def test_the_hold_jacobians_are_the_holds(wheels):
    """The analytic Jacobians in the local coordinates (the attitude perturbed in its tangent
    space) against central differences of the hold itself."""
    law = design_spatial_nmpc(CRAFT, WEIGHTS, TARGET, 0.1, horizon=2, n_modes=1, wheels=wheels,
                              torque_limit=None if wheels else 0.1)
    model, count = law.model, 0 if wheels is None else wheels.count
    advance = hold_functions(model, wheels).advance
    n = model.a.shape[0]
    rng = np.random.default_rng(0)
    x = 1e-3 * rng.normal(size=n)
    x[model.rate_at:model.rate_at + 3] = [0.05, -0.03, 0.04]
    q = from_rotation_vector([0.3, -0.2, 0.5])
    speeds, torques = 50.0 * rng.normal(size=count), 0.05 * rng.normal(size=(3, 2))
    _, _, _, held, jac = (np.asarray(v) for v in law.predict(x, q, speeds, torques))
    xs = np.asarray(law.predict(x, q, speeds, torques)[0])
    ss = np.asarray(law.predict(x, q, speeds, torques)[2])
    a_all, b_all = _hold_jacobians(law, np.hstack([x[:, None], xs[:, :-1]]),
                                   np.hstack([speeds[:, None], ss[:, :-1]]), held, jac)
    nominal = np.asarray(advance(x, q, speeds, torques[:, 0])[1]).ravel()

    def local(dz, du):
        out = [np.asarray(v).ravel() for v in advance(
            x + dz[:n], product(q, from_rotation_vector(dz[n:n + 3])), speeds + dz[n + 3:],
            torques[:, 0] + du)]
        return np.concatenate([out[0], rotation_vector(product(conjugate(nominal), out[1])),
                               out[2]])

    m, eps = n + 3 + count, 1e-6
    for k in range(m):
        dz = np.zeros(m)
        dz[k] = eps
        column = (local(dz, np.zeros(3)) - local(-dz, np.zeros(3))) / (2 * eps)
        assert np.allclose(a_all[0][:, k], column, atol=1e-7 * max(1.0, np.abs(column).max()))
    for k in range(3):
        du = np.zeros(3)
        du[k] = eps
        column = (local(np.zeros(m), du) - local(np.zeros(m), -du)) / (2 * eps)
        assert np.allclose(b_all[0][:, k], column, atol=1e-8 * max(1.0, np.abs(column).max()))


@pytest.mark.parametrize("wheels", [PYRAMID, None], ids=["a null-motion pyramid", "hub torque"])
def test_the_compiled_linearisation_is_the_holds(wheels):
    """The compiled rollout's states are the hold's (``predict``), its Jacobians central
    differences of the hold (exact, where the closed form keeps second order in the hold's
    rotation), over a horizon of 3 from a tumbling state."""
    law = design_spatial_nmpc(CRAFT, WEIGHTS, TARGET, 0.1, horizon=3, n_modes=1, wheels=wheels,
                              torque_limit=None if wheels else 0.1)
    if law.linearise is None:
        pytest.skip("no C compiler: the NMPC takes the closed form")
    model, count = law.model, 0 if wheels is None else wheels.count
    advance = hold_functions(model, wheels).advance
    n, m = model.a.shape[0], model.a.shape[0] + 3 + count
    rng = np.random.default_rng(2)
    x = 1e-3 * rng.normal(size=n)
    x[model.rate_at:model.rate_at + 3] = [0.2, -0.1, 0.15]
    q = from_rotation_vector([0.3, -0.2, 0.5])
    speeds, torques = 50.0 * rng.normal(size=count), 0.05 * rng.normal(size=(3, 3))
    xs, qs, ss, a_side, b_side = law.linearise(x, q, speeds, torques)
    expected = [np.asarray(v) for v in law.predict(x, q, speeds, torques)[:3]]
    for got, want in zip((xs, qs, ss), expected):
        assert np.allclose(got, want, rtol=1e-12, atol=1e-14)
    # the second hold, from the first one's end
    start = (xs[:, 0], qs[:, 0], ss[:, 0])
    nominal = np.asarray(advance(*start, torques[:, 1])[1]).ravel()

    def local(dz, du):
        out = [np.asarray(v).ravel() for v in advance(
            start[0] + dz[:n], product(start[1], from_rotation_vector(dz[n:n + 3])),
            start[2] + dz[n + 3:], torques[:, 1] + du)]
        return np.concatenate([out[0], rotation_vector(product(conjugate(nominal), out[1])),
                               out[2]])

    a_one, b_one, eps = a_side[:, m:2 * m], b_side[:, 3:6], 1e-6
    for k in range(m + 3):
        dz, du = np.zeros(m), np.zeros(3)
        (dz if k < m else du)[k % m if k < m else k - m] = eps
        column = (local(dz, du) - local(-dz, -du)) / (2 * eps)
        got = a_one[:, k] if k < m else b_one[:, k - m]
        assert np.allclose(got, column, atol=2e-8 * max(1.0, np.abs(column).max()))


def test_the_unconstrained_step_is_the_qps_solution():
    """Where the Newton step satisfies every row it is returned without the QP solver, and it
    is the QP solver's minimiser; where it violates one, None (the QP solver decides)."""
    import casadi as ca

    from controllers.mpc.nmpc import conic_solver
    from controllers.mpc.spatial_nmpc import _unconstrained

    rng = np.random.default_rng(3)
    root = rng.normal(size=(6, 6))
    hessian = root @ root.T + 6 * np.eye(6)
    gradient, rows = rng.normal(size=6), rng.normal(size=(4, 6))
    free = -np.linalg.solve(hessian, gradient)
    loose = {"h": hessian, "g": gradient, "a": rows, "lba": rows @ free - 1.0,
             "uba": rows @ free + 1.0, "lbx": np.full(6, -np.inf), "ubx": np.full(6, np.inf)}
    qp = conic_solver("test_qp", "qpoases", ca.Sparsity.dense(6, 6), ca.Sparsity.dense(4, 6))
    assert np.allclose(_unconstrained(loose), free, rtol=1e-12)
    assert np.allclose(np.asarray(qp(**loose)["x"]).ravel(), free, atol=1e-9)
    tight = dict(loose, uba=rows @ free - 1e-3)
    assert _unconstrained(tight) is None
    assert _unconstrained(dict(loose, ubx=free - 1e-3)) is None


def test_attitude_errors_are_the_short_rotation():
    rng = np.random.default_rng(1)
    target = from_rotation_vector(rng.normal(size=3))
    quaternions = np.array([from_rotation_vector(rng.normal(size=3)) for _ in range(5)]
                           + [target, -target]).T
    expected = np.array([error_angles(target, q) for q in quaternions.T])
    assert np.allclose(_attitude_errors(target, quaternions), expected, atol=1e-14)


@pytest.fixture(scope="module")
def step_flight():
    law = design_spatial_nmpc(CRAFT, WEIGHTS, TARGET, 0.1, horizon=20, n_modes=1, wheels=WHEELS)
    return law, *_fly(law, WHEELS)


def test_it_slews_to_rest_on_target_within_the_wheels_torque(step_flight):
    law, run, session = step_flight
    assert isinstance(law, SpatialNMPC) and session.failed_steps == 0
    assert np.linalg.norm(error_angles(TARGET, run.quaternion[:, -1])) < 1e-4
    late = run.t > 15.0
    assert max(np.max(np.abs(tip[:, late])) for tip in run.tips.values()) < 5e-5
    assert np.max(np.abs(run.wheel_torques)) <= 0.1 * (1 + 1e-9)
    print(f"median step {1e3 * np.median(session.step_times):.2f} ms")


def test_a_speed_limit_is_a_constraint(step_flight):
    """The free slew's wheels reach some peak speed; with a speed limit below it (its 0.9
    margin kept in the prediction) the wheels stay below the limit, and the slew still
    ends on target."""
    _, free, _ = step_flight
    peak = float(np.max(np.abs(free.wheel_speeds)))
    slow = WheelCluster.orthogonal(inertia=0.01, torque_limit=0.1, speed_limit=0.7 * peak)
    law = design_spatial_nmpc(CRAFT, WEIGHTS, TARGET, 0.1, horizon=20, n_modes=1, wheels=slow)
    run, session = _fly(law, slow, t_final=30.0)
    print(f"free peak {peak:.2f} rad/s, limited peak "
          f"{np.max(np.abs(run.wheel_speeds)):.2f} of {0.7 * peak:.2f}")
    assert np.max(np.abs(run.wheel_speeds)) <= 0.7 * peak
    assert np.linalg.norm(error_angles(TARGET, run.quaternion[:, -1])) < 1e-3


def test_it_follows_a_planned_slew_to_the_target():
    """On a 12 s plan within the wheels' limits the NMPC ends the slew on target; the step's
    NMPC is still turning there."""
    plan = solve_spatial_slew(CRAFT, SpatialSlewProblem(target=TARGET, duration=12.0,
                                                        n_intervals=120, wheels=WHEELS),
                              n_modes=1)
    law = design_spatial_nmpc(CRAFT, WEIGHTS, None, 0.1, horizon=20, n_modes=1, wheels=WHEELS,
                              reference=plan)
    run, session = _fly(law, WHEELS, t_final=14.0)
    end = int(np.argmin(np.abs(run.t - 12.0)))
    error = np.linalg.norm(error_angles(TARGET, run.quaternion[:, end]))
    print(f"pointing at the plan's end {error:.2e} rad")
    assert error < 1e-4 and session.failed_steps == 0


@pytest.mark.parametrize("kwargs, pattern", [
    ({"sample_time": 0.0}, r"design_spatial_nmpc\.sample_time"),
    ({"horizon": 1}, r"design_spatial_nmpc\.horizon"),
    ({"horizon": 2.5}, r"design_spatial_nmpc\.horizon"),
    ({"qp_solver": "cplex"}, r"design_spatial_nmpc\.qp_solver"),
    ({"qp_solver": "hpipm"}, r"design_spatial_nmpc\.qp_solver"),
    ({"speed_margin": 0.0}, r"design_spatial_nmpc\.speed_margin"),
    ({"wheels": WHEELS, "torque_limit": 0.1}, r"design_spatial_nmpc\.torque_limit bounds"),
    ({"torque_limit": -1.0}, r"design_spatial_nmpc\.torque_limit"),
    ({"target": None}, r"design_spatial_nmpc\.target is required"),
    ({"target": (0, 0, 0, 0)}, r"design_spatial_nmpc\.target must be a non-zero"),
    ({"n_modes": 0}, r"n_modes"),
    ({"structure": "craft"}, r"design_spatial_nmpc\.structure must be a SpatialStructure"),
    ({"weights": "heavy"}, r"weights"),
    ({"reference": "a slew"}, r"design_spatial_nmpc\.reference"),
    ({"wheels": "four"}, r"design_spatial_nmpc\.wheels"),
    ({"wheels": 3}, r"design_spatial_nmpc\.wheels"),
])
def test_bad_arguments_are_refused_by_name(kwargs, pattern):
    arguments = {"structure": CRAFT, "weights": WEIGHTS, "target": TARGET, **kwargs}
    with pytest.raises(InputError, match=pattern):
        design_spatial_nmpc(**arguments)


def test_its_linear_law_about_rest_is_a_stable_held_state_feedback(step_flight):
    """About rest at the target the NMPC is a held linear gain: the gain reproduces a step
    from a small offset (to second order in it), and its loop on the linear plant with two
    modes per field is stable with disk margins."""
    from controllers.analysis.spatial_loops import loop_disk_margins, lq_loop
    from flexctl.model.spatial_plant import linearize_spatial

    law = step_flight[0]
    linear = law.linear_law()
    offset = np.zeros(len(law.state_names))
    offset[0:3] = [1e-6, -2e-6, 5e-7]
    offset[law.state_names.index("wx")] = 1e-6
    session = law.start(None)
    count = law.wheels.count
    state = np.concatenate([product(law.target, from_rotation_vector(offset[0:3])),
                            offset[3:], np.zeros(count)])
    command = session(0.0, state[0:4], offset[law.state_names.index("wx"):][:3], state)
    assert np.allclose(command, -linear.gain @ offset, rtol=1e-5, atol=1e-13)
    margins = loop_disk_margins(lq_loop(linear, linearize_spatial(CRAFT, 2)))
    print(margins.gain_margin_db, margins.phase_margin_deg)
    assert margins.closed_loop_stable and np.all(margins.gain_margin_db > 6.0)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                    reason="no C compiler")
@pytest.mark.parametrize("planned", [False, True], ids=["step", "planned slew"])
def test_the_nmpc_as_c_commands_and_flies_as_python(planned, tmp_path):
    """The real-time iteration written as C (qrqp): fed the inputs the Python law read at each
    sample of its run, the same commands (a null-motion pyramid, its torque limit reached on
    the step; the wheels following a plan at its holds), and the same flight; following a plan
    at samples other than its holds is refused with the reason."""
    from controllers.codegen import ExportRefused, export_c
    from controllers.codegen.spatial_program import compiled_spatial_law
    from spatial_c_check import flown_as_python

    wheels, plan, step = PYRAMID, None, 0.1
    if planned:
        wheels, step = WHEELS, 0.2
        plan = solve_spatial_slew(CRAFT, SpatialSlewProblem(
            target=TARGET, duration=12.0, n_intervals=60, wheels=WHEELS), n_modes=1)
        elsewhere = design_spatial_nmpc(CRAFT, WEIGHTS, None, 0.1, horizon=5, n_modes=1,
                                        wheels=WHEELS, reference=plan)
        with pytest.raises(ExportRefused, match=r"samples at the plan's holds \(0.2 s"):
            export_c(elsewhere, None, tmp_path / "elsewhere")
    law = design_spatial_nmpc(CRAFT, WEIGHTS, None if planned else TARGET, step, horizon=5,
                              n_modes=1, wheels=wheels, reference=plan)
    compiled = export_c(law, None, tmp_path / "c").compile()
    assert compiled.program.kind == "spatial_nmpc"
    sessions = []

    def fly(flown_law):
        loop = simulate_spatial_loop(CRAFT, 8.0, flown_law, sample_time=step, n_modes=1,
                                     variant="first_order", wheels=wheels, rtol=1e-9)
        assert loop.ok
        sessions.append(loop.session)
        return loop.result

    commands, states, run = flown_as_python(law, compiled_spatial_law(compiled), fly)
    assert sessions[0].failed_steps == 0
    peak = float(np.max(np.abs(run.wheel_torques)))
    assert planned or peak >= 0.1 * (1 - 1e-9)          # the step saturates a wheel
    print(f"commands within {commands:.1e} N m, states within {states:.1e}")
    assert commands < 1e-9 and states < 1e-7
