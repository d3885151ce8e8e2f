"""The persistent compiled-function cache: one compile per function across processes and
concurrent workers, the virtual machine with one warning where there is no compiler, a damaged
entry compiled again, and ``flexctl cache info`` / ``clear``."""

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from flexctl.app.cli import main
from flexctl.sim import compile_cache, lifted_constants
from flexctl.sim.compile_cache import CompileCacheWarning, compiled

ROOT = Path(__file__).resolve().parents[2]

needs_compiler = pytest.mark.skipif(compile_cache.compiler() is None,
                                    reason="no C compiler")

#: A worker process: compile a small function named by argv[1] (its structure set by
#: argv[2]), evaluate it, print the cache counters and the value as JSON.
WORKER = """
import json, sys
import casadi as ca
from flexctl.sim.compile_cache import compiled, STATS
x = ca.SX.sym("x", 3)
f = compiled(ca.Function(sys.argv[1], [x], [ca.sin(x) * x[0] + float(sys.argv[2])]))
print(json.dumps({"stats": STATS, "value": [float(v) for v in f([1.0, 2.0, 3.0]).full().ravel()],
                  "external": f.is_a("External")}))
"""


def expected(shift: float) -> list:
    x = np.array([1.0, 2.0, 3.0])
    return list(np.sin(x) * x[0] + shift)


def run_worker(cache: Path, name: str, shift: float = 0.5, wait: bool = True):
    env = {**os.environ, "FLEXCTL_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    env.pop("FLEXCTL_COMPILE", None)
    process = subprocess.Popen([sys.executable, "-c", WORKER, name, repr(shift)], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return process if not wait else finish(process)


def finish(process) -> dict:
    out, err = process.communicate(timeout=300)
    assert process.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


def libraries(cache: Path) -> list:
    return sorted((cache / "compiled").glob("*.so"))


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """An empty cache directory for this process, with no memory of earlier loads."""
    monkeypatch.setenv("FLEXCTL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("FLEXCTL_COMPILE", raising=False)
    monkeypatch.setattr(compile_cache, "_LOADED", {})
    monkeypatch.setattr(lifted_constants, "_LIFTED", {})
    monkeypatch.setattr(lifted_constants, "_STRUCTURES", {})
    monkeypatch.setattr(compile_cache, "_WARNED", set())
    monkeypatch.setattr(compile_cache, "_COMPILER", {})
    return tmp_path / "cache"


@needs_compiler
def test_one_compile_across_processes(fresh):
    first = run_worker(fresh, "cc_across")
    second = run_worker(fresh, "cc_across")
    assert first["stats"]["compiles"] == 1 and first["external"]
    assert second["stats"]["compiles"] == 0 and second["stats"]["loads"] == 1
    np.testing.assert_allclose(second["value"], expected(0.5), rtol=1e-14)
    assert len(libraries(fresh)) == 1


@needs_compiler
def test_another_structure_is_another_entry(fresh):
    run_worker(fresh, "cc_structure", 0.5)
    other = run_worker(fresh, "cc_structure", 1.5)
    assert other["stats"]["compiles"] == 1
    np.testing.assert_allclose(other["value"], expected(1.5), rtol=1e-14)
    assert len(libraries(fresh)) == 2


@needs_compiler
def test_concurrent_workers_make_one_valid_library(fresh):
    workers = [run_worker(fresh, "cc_concurrent", wait=False) for _ in range(4)]
    results = [finish(w) for w in workers]
    assert sum(r["stats"]["compiles"] for r in results) == 1
    for r in results:
        assert r["external"]
        np.testing.assert_allclose(r["value"], expected(0.5), rtol=1e-14)
    assert len(libraries(fresh)) == 1
    assert not list((fresh / "compiled").glob(".build-*")), "temporary files left behind"


@needs_compiler
def test_damaged_entry_is_compiled_again(fresh):
    run_worker(fresh, "cc_damaged")
    (library,) = libraries(fresh)
    library.write_bytes(b"not a shared library")
    again = run_worker(fresh, "cc_damaged")
    assert again["stats"]["compiles"] == 1 and again["external"]
    np.testing.assert_allclose(again["value"], expected(0.5), rtol=1e-14)


def _no_c_generation(*args):
    raise AssertionError("the C source was generated again")


@needs_compiler
def test_a_later_process_loads_its_library_without_generating_c(fresh, monkeypatch):
    import casadi as ca

    x = ca.SX.sym("x", 2)
    function = ca.Function("cc_index", [x], [ca.exp(x) * x[1]])
    first = compiled(function)
    assert first.is_a("External") and compile_cache.STATS["compiles"] >= 1
    monkeypatch.setattr(compile_cache, "_LOADED", {})          # as in another process
    monkeypatch.setattr(compile_cache, "_source", _no_c_generation)
    again = compiled(ca.Function("cc_index", [x], [ca.exp(x) * x[1]]))
    assert again.is_a("External")
    np.testing.assert_array_equal(np.array(again([0.3, -1.2])), np.array(first([0.3, -1.2])))
    assert len(libraries(fresh)) == 1


@needs_compiler
def test_an_index_naming_a_missing_library_compiles_through(fresh, monkeypatch):
    import casadi as ca

    x = ca.SX.sym("x")
    function = ca.Function("cc_stale", [x], [x ** 3 + 1.0])
    compiled(function)
    (index,) = (fresh / "compiled").glob("cc_stale-*.key")
    index.write_text("0" * 32)                      # a key with no library behind it
    monkeypatch.setattr(compile_cache, "_LOADED", {})
    again = compiled(function)
    assert again.is_a("External") and float(again(2.0)) == 9.0
    assert index.read_text() != "0" * 32            # the index names the real library again
    index.write_text("not a key")
    monkeypatch.setattr(compile_cache, "_LOADED", {})
    assert float(compiled(function)(-1.0)) == 0.0


@needs_compiler
def test_lifted_functions_are_read_back_from_the_cache(fresh, monkeypatch):
    from flexctl.sim.lifted_constants import lift_constants

    model, _ = _exact_pair()
    lifted, constants = lift_constants(model.geometry.rhs)
    (stored,) = (fresh / "compiled").glob("lifted-*.constants")
    assert len(list((fresh / "compiled").glob("lifted-*.casadi"))) == 1
    lift = lifted_constants._lift
    monkeypatch.setattr(lifted_constants, "_LIFTED", {})          # as in another process
    monkeypatch.setattr(lifted_constants, "_lift", _no_c_generation)
    read, read_constants = lift_constants(model.geometry.rhs)
    np.testing.assert_array_equal(read_constants, constants)
    x = 0.1 * np.arange(1, model.n_states + 1)
    np.testing.assert_array_equal(np.array(read(x, 0.7, read_constants)),
                                  np.array(model.geometry.rhs(x, 0.7)))
    # a damaged entry is lifted again
    # another beam's numbers: a constants file of its own, the same lifted function
    monkeypatch.setattr(lifted_constants, "_lift", lift)
    _, stiffer = _exact_pair()
    lift_constants(stiffer.geometry.rhs)
    assert len(list((fresh / "compiled").glob("lifted-*.constants"))) == 2
    assert len(list((fresh / "compiled").glob("lifted-*.casadi"))) == 1
    # a damaged entry is lifted again
    stored.write_bytes(b"damaged")
    monkeypatch.setattr(lifted_constants, "_LIFTED", {})
    again, again_constants = lift_constants(model.geometry.rhs)
    np.testing.assert_array_equal(again_constants, constants)
    assert stored.read_bytes() != b"damaged"


def test_lifting_writes_nothing_with_compiling_off(fresh, monkeypatch):
    import casadi as ca

    from flexctl.sim.lifted_constants import lift_constants

    monkeypatch.setenv("FLEXCTL_COMPILE", "0")
    x = ca.SX.sym("x")
    lifted, constants = lift_constants(ca.Function("cc_off_lift", [x], [2.5 * x - 1.0]))
    assert sorted(constants.tolist()) == [1.0, 2.5]
    assert float(lifted(2.0, constants)) == 4.0
    assert not fresh.exists() or not list(fresh.rglob("lifted-*"))


def test_no_compiler_runs_on_the_virtual_machine_with_one_warning(fresh, monkeypatch):
    import casadi as ca

    monkeypatch.setenv("CC", str(fresh / "no-such-compiler"))
    x = ca.SX.sym("x")
    functions = [ca.Function(f"cc_none{k}", [x], [x ** 2 + k]) for k in range(3)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        results = [compiled(f) for f in functions]
    assert [r is f for r, f in zip(results, functions)] == [True] * 3
    messages = [w for w in caught if issubclass(w.category, CompileCacheWarning)]
    assert len(messages) == 1
    assert "no C compiler" in str(messages[0].message)
    assert "virtual machine" in str(messages[0].message)
    assert float(results[2](3.0)) == 11.0


@needs_compiler
def test_a_function_without_c_code_stays_on_the_virtual_machine(fresh):
    import casadi as ca

    x = ca.SX.sym("x")
    decay = ca.integrator("cc_decay", "cvodes", {"x": x, "ode": -x}, 0.0, 1.0)
    start = ca.MX.sym("start")
    f = ca.Function("cc_no_c_code", [start], [decay(x0=start)["xf"]])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = compiled(f)
    assert result is f
    assert [issubclass(w.category, CompileCacheWarning) for w in caught] == [True]
    assert float(result(1.0)) == pytest.approx(np.exp(-1.0), rel=1e-4)   # CVODES defaults


def test_compiling_off_by_environment(fresh, monkeypatch):
    import casadi as ca

    monkeypatch.setenv("FLEXCTL_COMPILE", "0")
    x = ca.SX.sym("x")
    f = ca.Function("cc_off", [x], [2 * x])
    assert compiled(f) is f
    assert not (fresh / "compiled").exists()


@needs_compiler
def test_cli_cache_info_and_clear(fresh, capsys):
    run_worker(fresh, "cc_cli")
    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert f"directory: {fresh}" in out and "entries: 1" in out
    assert main(["cache", "clear"]) == 0
    assert "removed 1 " in capsys.readouterr().out
    assert libraries(fresh) == []
    assert main(["cache", "info"]) == 0
    assert "entries: 0" in capsys.readouterr().out


def test_cache_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("FLEXCTL_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert compile_cache.cache_dir() == tmp_path / "flexctl"
    monkeypatch.setenv("FLEXCTL_CACHE_DIR", str(tmp_path / "mine"))
    assert compile_cache.cache_dir() == tmp_path / "mine"


#: Final hub angle of a PD slew within this fraction of the commanded angle.
SLEW_TOLERANCE = 1e-3


@pytest.fixture(scope="module")
def slew_model():
    import flexctl

    return flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2)


def _pd_slew(model, angle, duration=4.0):
    from controllers.feedback.pd import design_pd
    from controllers.slew.reference import SlewProfile

    return design_pd(model, bandwidth=2.0, damping_ratio=0.9, torque_limit=20.0,
                     reference=SlewProfile(slew_angle=angle, duration=duration))


@needs_compiler
@pytest.mark.parametrize("method", ["rk4", "cvodes"])
def test_angle_sweep_compiles_once(fresh, slew_model, method):
    """A 10-point sweep over the slew angle (and the duration) builds its compiled functions
    for the first point only, and every point reaches its own angle."""
    import flexctl
    from flexctl.sim import compiled as compiled_path
    from flexctl.sim import fixed_step

    fixed_step.STEP_CACHE.clear()
    compiled_path._RHS_CACHE.clear()
    before = compile_cache.STATS["compiles"]
    builds = []
    for k, angle in enumerate(np.linspace(0.3, 1.6, 10)):
        rhs_before = set(compiled_path._RHS_CACHE)
        result = flexctl.simulate(slew_model, 8.0, controller=_pd_slew(
            slew_model, angle, 4.0 + 0.1 * k), method=method, check_accuracy=False,
            check_validity=False)     # the estimate's exact model compiles once, on its own
        assert result.status == "ok"
        assert result.theta[-1] == pytest.approx(angle, rel=SLEW_TOLERANCE)
        # right-hand sides of this model (not of any model a check builds on the way)
        new = [key for key in set(compiled_path._RHS_CACHE) - rhs_before
               if id(slew_model) in (key[0], key[1][0] if isinstance(key[1], tuple) else None)]
        builds.append((compile_cache.STATS["compiles"] - before, len(new)))
    compiles = [b[0] for b in builds]
    assert compiles[0] <= len(fixed_step.CHUNKS)
    assert compiles == [compiles[0]] * 10, "a later point compiled again"
    assert [b[1] for b in builds[1:]] == [0] * 9, "a later point built another right-hand side"


@needs_compiler
def test_sine_amplitude_sweep_compiles_once(fresh, slew_model):
    import flexctl
    from flexctl.sim import fixed_step
    from flexctl.sim.maneuvers import SineTorque

    fixed_step.STEP_CACHE.clear()
    for k, peak in enumerate((1.0, 2.0, 3.0)):
        sine = SineTorque(peak_torque=peak, duration=2.0)
        result = flexctl.simulate(slew_model, 3.0, sine, method="rk4", check_accuracy=False)
        if k == 0:
            first = compile_cache.STATS["compiles"]
        # each run follows its own amplitude: as the error-controlled default does
        reference = flexctl.simulate(slew_model, 3.0, sine, check_accuracy=False)
        assert result.theta[-1] == pytest.approx(reference.theta[-1], rel=SLEW_TOLERANCE)
    assert compile_cache.STATS["compiles"] == first


@needs_compiler
def test_compiled_and_virtual_machine_runs_agree(fresh, slew_model, monkeypatch):
    import flexctl
    from flexctl.sim import fixed_step

    runs = []
    for setting in ("1", "0"):
        monkeypatch.setenv("FLEXCTL_COMPILE", setting)
        fixed_step.STEP_CACHE.clear()
        runs.append(flexctl.simulate(slew_model, 6.0, controller=_pd_slew(slew_model, 0.8),
                                     method="rk4", check_accuracy=False))
    np.testing.assert_allclose(runs[0].states, runs[1].states, rtol=1e-10, atol=1e-12)


# --------------------------------------------------------------- the exact model, compiled
def _exact_pair():
    """Two exact 2-mode models of hub-beam-mass that differ only in numbers."""
    import dataclasses

    import flexctl

    system = flexctl.load_scene("hub-beam-mass").system
    stiffer = dataclasses.replace(system, beam=dataclasses.replace(
        system.beam, youngs_modulus=1.3 * system.beam.youngs_modulus))
    return (flexctl.build_model(system, 2, variant="exact"),
            flexctl.build_model(stiffer, 2, variant="exact"))


def test_lifted_constants_compute_the_same_numbers():
    from flexctl.sim.lifted_constants import lift_constants

    model, _ = _exact_pair()
    lifted, constants = lift_constants(model.geometry.rhs)
    rng = np.random.default_rng(3)
    for _ in range(5):
        x, u = 0.2 * rng.standard_normal(model.n_states), rng.standard_normal()
        np.testing.assert_array_equal(np.array(lifted(x, u, constants)),
                                      np.array(model.geometry.rhs(x, u)))
    assert lift_constants(model.geometry.rhs, max_instructions=10) is None


@needs_compiler
def test_models_differing_in_numbers_share_one_library(fresh, monkeypatch):
    """The exact right-hand side is compiled once per structure: another beam stiffness
    loads the same library, and the compiled runs agree with the virtual machine's."""
    import flexctl
    from flexctl.sim import native_rhs

    monkeypatch.setattr(native_rhs, "_NATIVE", native_rhs.weakref.WeakKeyDictionary())
    monkeypatch.setattr(native_rhs, "_BUILT", native_rhs.weakref.WeakKeyDictionary())
    first, second = _exact_pair()
    push = flexctl.SineTorque(peak_torque=1.0, duration=1.0)
    before = dict(compile_cache.STATS)
    # on the compiled pair, which the virtual machine also runs (the compiled BDF has no
    # virtual-machine form to compare with)
    runs = [flexctl.simulate(m, 2.0, torque=push, method="RK45", check_validity=False)
            for m in (first, second)]
    assert compile_cache.STATS["compiles"] - before["compiles"] == 1
    assert len(libraries(fresh)) == 1
    # a stiffer beam bends less under the same push: the numbers are not shared
    assert np.max(np.abs(runs[1].tip_deflection)) < 0.9 * np.max(np.abs(runs[0].tip_deflection))
    monkeypatch.setenv("FLEXCTL_COMPILE", "0")
    monkeypatch.setattr(native_rhs, "_NATIVE", native_rhs.weakref.WeakKeyDictionary())
    vm = flexctl.simulate(flexctl.build_model(first.system, 2, variant="exact"), 2.0,
                          torque=push, method="RK45", check_validity=False)
    np.testing.assert_allclose(runs[0].tip_deflection, vm.tip_deflection, rtol=0,
                               atol=1e-9 * np.max(np.abs(vm.tip_deflection)))


@needs_compiler
def test_prescribed_motion_on_the_compiled_exact_beam(fresh, monkeypatch):
    """Under a prescribed spin-up the compiled exact beam and hub torque agree with the
    virtual machine's."""
    import flexctl

    from flexctl.sim import native_rhs

    scene = flexctl.load_scene("kane-spinup")
    runs = []
    for setting in ("1", "0"):
        monkeypatch.setenv("FLEXCTL_COMPILE", setting)
        monkeypatch.setattr(native_rhs, "_NATIVE", native_rhs.weakref.WeakKeyDictionary())
        model = flexctl.build_model(scene.system, 2, variant="exact")
        runs.append(flexctl.simulate(model, 12.0, hub_motion=scene.maneuver,
                                     check_validity=False, rtol=1e-9))
    peak = np.max(np.abs(runs[1].tip_deflection))
    np.testing.assert_allclose(runs[0].tip_deflection, runs[1].tip_deflection, rtol=0,
                               atol=1e-7 * peak)
    np.testing.assert_allclose(runs[0].torque, runs[1].torque, rtol=0,
                               atol=1e-7 * np.max(np.abs(runs[1].torque)))


@pytest.mark.parametrize("bad", ["10", float("nan"), float("inf"), -1, 1.5, True])
def test_lift_constants_refuses_a_bad_size_by_name(bad):
    import casadi as ca

    from flexctl.model.errors import InputTypeError, InputValueError
    from flexctl.sim.lifted_constants import lift_constants

    x = ca.SX.sym("x")
    with pytest.raises((InputTypeError, InputValueError), match="max_instructions"):
        lift_constants(ca.Function("doc_double", [x], [2 * x]), bad)


# ------------------------------------------------- compiled derivatives for the optimisers
def _second_order(function, n: int, points: int = 7):
    """Values, constraint Jacobian and Lagrangian Hessian of ``function`` (x (n,), u) mapped
    over ``points`` points, as CasADi's NLP callbacks build them (MX AD through the call)."""
    import casadi as ca

    X, U, L = ca.MX.sym("X", n, points), ca.MX.sym("U", 1, points), ca.MX.sym("L", n, points)
    y = function.map(points)(X, U)
    z = ca.vertcat(ca.vec(X), ca.vec(U))
    return ca.Function("second_order", [X, U, L],
                       [y, ca.jacobian(ca.vec(y), z), ca.hessian(ca.sum1(ca.sum2(L * y)), z)[0]])


def test_with_derivatives_holds_the_fixed_input_constant():
    import casadi as ca

    from flexctl.sim.compiled_derivatives import with_derivatives

    x, c = ca.SX.sym("x", 2), ca.SX.sym("c", 2)
    f = ca.Function("t_f", [x, c], [ca.vertcat(c[0] * ca.sin(x[0]) * x[1], c[1] * x[1] ** 3)],
                    ["x", "c"], ["y"])
    jac, adj, jac_adj = with_derivatives(f, fixed=(1,))
    assert (jac.name(), adj.name(), jac_adj.name()) == ("jac_t_f", "adj1_t_f", "jac_adj1_t_f")
    assert jac.name_out() == ["jac_y_x", "jac_y_c"]
    assert jac.sparsity_out(1).nnz() == 0             # the constants are not differentiated
    x0, c0, seed = np.array([0.3, -1.2]), np.array([2.0, 0.5]), np.array([0.7, -0.4])
    np.testing.assert_allclose(np.array(jac(x0, c0, 0)[0]),
                               np.array(f.jacobian()(x0, c0, 0)[0]), rtol=1e-14)
    sens = adj(x0, c0, 0, seed)
    np.testing.assert_allclose(np.array(sens[0]).ravel(),
                               np.array(f.reverse(1)(x0, c0, 0, seed)[0]).ravel(), rtol=1e-14)
    np.testing.assert_array_equal(np.array(sens[1]).ravel(), 0.0)
    with pytest.raises(TypeError, match="SX casadi.Function"):
        with_derivatives("t_f")


@needs_compiler
def test_compiled_design_dynamics_have_the_models_derivatives(fresh, monkeypatch):
    """A design model compiled with its derivatives (exact and first_order) gives the same
    values, Jacobian and Lagrangian Hessian as the model on the virtual machine."""
    import flexctl

    from controllers import native_dynamics

    monkeypatch.setattr(native_dynamics, "_BUILT", native_dynamics.weakref.WeakKeyDictionary())
    system = flexctl.load_scene("hub-beam-mass").system
    rng = np.random.default_rng(11)
    for variant in ("exact", "first_order"):
        model = flexctl.build_model(system, 1, variant=variant)
        before = compile_cache.STATS["compiles"]
        native = native_dynamics.design_dynamics(model)
        assert native.is_a("MXFunction") and compile_cache.STATS["compiles"] == before + 1
        args = (0.3 * rng.standard_normal((model.n_states, 7)), rng.standard_normal((1, 7)),
                rng.standard_normal((model.n_states, 7)))
        for mine, theirs in zip(_second_order(native, model.n_states)(*args),
                                _second_order(model.casadi(), model.n_states)(*args)):
            theirs = np.array(theirs.full())
            np.testing.assert_allclose(np.array(mine.full()), theirs, rtol=0,
                                       atol=1e-12 * np.max(np.abs(theirs)))


@needs_compiler
def test_exact_slew_optimum_is_the_same_compiled(fresh, monkeypatch):
    """An optimal slew of the exact model: the same optimum with IPOPT's callbacks compiled
    and on the virtual machine."""
    import flexctl

    from controllers import native_dynamics
    from controllers.slew.trajopt import SlewProblem, solve_slew

    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, 1, variant="exact")
    problem = SlewProblem(angle=1.0, duration=3.0, torque_bound=5.0, n_intervals=20)
    costs = []
    for setting in ("1", "0"):
        monkeypatch.setenv("FLEXCTL_COMPILE", setting)
        monkeypatch.setattr(native_dynamics, "_BUILT",
                            native_dynamics.weakref.WeakKeyDictionary())
        solution = solve_slew(model, problem)
        assert solution.return_status == "Solve_Succeeded"
        costs.append(solution.cost)
    assert costs[0] == pytest.approx(costs[1], rel=1e-9)


@needs_compiler
def test_exact_structure_runs_compiled_and_agrees(fresh, monkeypatch):
    """Two arrays on a free hub, exact: the right-hand side compiled (with the first_order
    structure's Newton Jacobian) gives the virtual machine's run."""
    import flexctl
    from flexctl.sim import native_rhs

    scene = flexctl.load_scene("two-array-free")
    runs = []
    for setting in ("1", "0"):
        monkeypatch.setenv("FLEXCTL_COMPILE", setting)
        monkeypatch.setattr(native_rhs, "_NATIVE", native_rhs.weakref.WeakKeyDictionary())
        monkeypatch.setattr(native_rhs, "_BUILT", native_rhs.weakref.WeakKeyDictionary())
        before = compile_cache.STATS["compiles"]
        model = flexctl.build_model(scene.system, 1, variant="exact")
        # on CVODES both ways (the compiled BDF has no virtual-machine form)
        runs.append(flexctl.simulate(model, 2.0, torque=flexctl.SineTorque(
            peak_torque=5.0, duration=1.0), check_validity=False, rtol=1e-9, method="cvodes"))
        assert (compile_cache.STATS["compiles"] > before) == (setting == "1")
    assert runs[0].status == runs[1].status == "ok"
    peak = np.max(np.abs(runs[1].tip_deflection))
    np.testing.assert_allclose(runs[0].tip_deflection, runs[1].tip_deflection, rtol=0,
                               atol=1e-8 * peak)


@pytest.mark.parametrize("fixed", [(5,), (-1,), (0.5,), "0", 3, (True,), (float("nan"),)])
def test_with_derivatives_refuses_a_bad_fixed_input_by_name(fixed):
    import casadi as ca

    from flexctl.sim.compiled_derivatives import jacobian_companion, with_derivatives

    x, c = ca.SX.sym("x", 2), ca.SX.sym("c")
    f = ca.Function("t_bad", [x, c], [c * x[0] * x[1]])
    for build in (with_derivatives, jacobian_companion):
        with pytest.raises((TypeError, ValueError), match=f"{build.__name__}.*fixed"):
            build(f, fixed=fixed)


@pytest.mark.parametrize("function", ["f", None, 3.0, "mx"], ids=["str", "none", "float", "mx"])
def test_jacobian_companion_refuses_what_is_not_an_sx_function(function):
    import casadi as ca

    from flexctl.sim.compiled_derivatives import jacobian_companion

    if function == "mx":
        x = ca.MX.sym("x", 2)
        function = ca.Function("t_mx", [x], [x * x])
    with pytest.raises(TypeError, match="jacobian_companion: function must be an SX"):
        jacobian_companion(function)


def test_jacobian_companion_gives_the_jacobian_in_the_free_inputs():
    """Its blocks are the Jacobian of the outputs in each free input, and zero (structurally)
    in the fixed ones."""
    import casadi as ca

    from flexctl.sim.compiled_derivatives import jacobian_companion

    x, c = ca.SX.sym("x", 2), ca.SX.sym("c")
    f = ca.Function("t_jac", [x, c], [ca.vertcat(c * x[0] * x[1], ca.sin(x[0]))], ["x", "c"],
                    ["y"])
    jac = jacobian_companion(f, fixed=(1,))
    x0, c0 = np.array([0.3, -1.2]), 2.5
    blocks = jac(x0, c0, f(x0, c0))
    expected = np.array([[c0 * x0[1], c0 * x0[0]], [np.cos(x0[0]), 0.0]])
    np.testing.assert_allclose(np.array(blocks[0]), expected, rtol=1e-14)
    assert jac.sparsity_out(1).nnz() == 0


@pytest.mark.parametrize("bad", ["10", float("nan"), float("inf"), -1, 1.5, True])
def test_with_compiled_derivatives_refuses_a_bad_size_by_name(bad):
    import casadi as ca

    from controllers.design.native_dynamics import with_compiled_derivatives

    x = ca.SX.sym("x")
    with pytest.raises((TypeError, ValueError), match="max_library"):
        with_compiled_derivatives(ca.Function("t_sq", [x], [x ** 2]), bad)


@pytest.mark.parametrize("companions, options", [(("jac_f",), None), (3, None), ((), "x")])
def test_compiled_refuses_bad_companions_and_options_by_name(companions, options):
    import casadi as ca

    x = ca.SX.sym("x")
    with pytest.raises(TypeError, match="companions|options"):
        compiled(ca.Function("t_sq2", [x], [x ** 2]), companions=companions, options=options)


# --------------------------------------------------------- integrator right-hand sides
@needs_compiler
def test_native_dae_has_the_virtual_machines_values_and_jacobian(fresh):
    """The compiled right-hand side of an actuated free-hub structure under a held torque,
    and its Jacobian in t, x and p (what CVODES's Newton iterations call), equal the SX
    function's."""
    import casadi as ca

    import flexctl
    from flexctl.sim import compiled as compiled_path
    from flexctl.sim.embedded_rk import HeldTorque
    from flexctl.sim.native_rhs import native_dae

    model = flexctl.load_scene("wheel-slew").build_model()
    scale = np.linspace(0.5, 2.0, model.n_states)
    monkey = compiled_path.native_dae
    try:
        compiled_path.native_dae = lambda dae: None            # the SX function itself
        vm = compiled_path._rhs_function(model, scale, None, None, HeldTorque(0.0))
    finally:
        compiled_path.native_dae = monkey
    native = native_dae(vm)
    assert vm.is_a("SXFunction") and native is not None
    rng = np.random.default_rng(3)
    point = (0.3, rng.normal(size=model.n_states), ca.DM(0, 1), [0.5, 0.05, 0.9, 0.02],
             ca.DM(0, 1))
    np.testing.assert_allclose(np.array(native(*point)[0]), np.array(vm(*point)[0]),
                               rtol=1e-13, atol=1e-13)
    for k in (0, 1, 3):
        jac_vm, jac_native = (f.factory("j", ["t", "x", "p", "z", "u"],
                                        [f"jac:ode:{f.name_in(k)}"]) for f in (vm, native))
        args = [point[0], point[1], point[3], point[2], point[4]]
        np.testing.assert_allclose(np.array(jac_native(*args)), np.array(jac_vm(*args)),
                                   rtol=1e-12, atol=1e-12)


@needs_compiler
def test_native_dae_refuses_what_it_cannot_compile(fresh):
    import casadi as ca

    from flexctl.sim.native_rhs import native_dae

    x = ca.SX.sym("x", 2)
    plain = ca.Function("plain", [x], [x ** 2])
    assert native_dae(plain) is None                               # not a DAE signature
    assert native_dae("flexctl_rhs") is None
    mx = ca.MX.sym("x", 2)
    assert native_dae(ca.Function("mx", {"x": mx, "ode": -mx}, ca.dyn_in(), ca.dyn_out())) \
        is None                                                    # MX: not lifted


@needs_compiler
def test_sampled_loop_with_sensors_runs_compiled_and_agrees(fresh, monkeypatch):
    """A short wheel slew (free hub, wheel, noisy sensors, observer): the sample
    loop on compiled right-hand sides follows the virtual machine's, reading by reading."""
    import flexctl
    from flexctl.sim import compiled as compiled_path

    scene = flexctl.load_scene("wheel-slew", overrides={
        "maneuver.angle_deg": 1.0, "maneuver.duration": 6.0, "simulation.t_final": 8.0})
    runs = []
    for setting in ("1", "0"):
        monkeypatch.setenv("FLEXCTL_COMPILE", setting)
        compiled_path._RHS_CACHE.clear()
        compiled_path._INTEGRATOR_CACHE.clear()
        before = compile_cache.STATS["compiles"] + compile_cache.STATS["loads"]
        result = flexctl.run_slew(scene)[0]
        used = compile_cache.STATS["compiles"] + compile_cache.STATS["loads"] > before
        assert used == (setting == "1")
        runs.append(result)
    assert runs[0].status == runs[1].status == "ok"
    peak = np.max(np.abs(runs[1].tip_deflection))
    np.testing.assert_allclose(runs[0].tip_deflection, runs[1].tip_deflection, rtol=0,
                               atol=1e-7 * peak)
    readings = [run.measurements for run in runs]
    for name in readings[1]:
        if name != "true":
            np.testing.assert_allclose(readings[0][name], readings[1][name], rtol=1e-6,
                                       atol=1e-9)


@needs_compiler
def test_first_order_beams_differing_in_numbers_share_one_pair_library(fresh):
    """The continuous Dormand-Prince 8(5,3) steps of the small-deflection variants lift the
    model's numbers out of their code: a Monte Carlo over the beam compiles them once."""
    import dataclasses

    import flexctl
    from controllers import PD

    base = flexctl.load_scene("slew-90").system
    law = PD(kp=12.0, kd=8.0, torque_limit=6.0)
    before, peaks = dict(compile_cache.STATS), []
    for length in (1.7, 1.9):
        system = dataclasses.replace(base, beam=dataclasses.replace(base.beam, length=length))
        model = flexctl.build_model(system, n_modes=3)
        x0 = model.rest_state(-np.pi / 2)
        run = flexctl.simulate(model, 2.0, controller=law, x0=x0, check_accuracy=False,
                               check_validity=False)
        assert run.method == "dop853"
        peaks.append(run.peak_tip_deflection)
    assert compile_cache.STATS["compiles"] - before["compiles"] == 1
    assert len([p for p in libraries(fresh) if "dop853" in p.name]) == 1
    # the longer, softer beam deflects more: each run has its own numbers
    assert peaks[1] > 1.1 * peaks[0]


def _swap_files(cache: Path, pattern: str) -> None:
    """Give the two files of the cache matching ``pattern`` each other's contents."""
    first, second = sorted((cache / "compiled").glob(pattern))
    contents = first.read_bytes(), second.read_bytes()
    first.write_bytes(contents[1])
    second.write_bytes(contents[0])


@needs_compiler
def test_an_index_naming_another_functions_library_is_not_trusted(fresh, monkeypatch):
    import casadi as ca

    x, y = ca.SX.sym("x"), ca.SX.sym("y", 2)
    one = ca.Function("cc_swap", [x], [x * 2.0])
    other = ca.Function("cc_swap", [y], [ca.sin(y)])       # same name, another signature
    compiled(one)
    compiled(other)
    _swap_files(fresh, "cc_swap-*.key")                      # each names the other's library
    monkeypatch.setattr(compile_cache, "_LOADED", {})
    assert float(compiled(one)(1.5)) == 3.0
    np.testing.assert_allclose(np.array(compiled(other)([0.1, 0.2])).ravel(),
                               np.sin([0.1, 0.2]), rtol=1e-15)


@needs_compiler
def test_a_stored_lifted_function_of_another_shape_is_lifted_again(fresh, monkeypatch):
    import casadi as ca

    from flexctl.sim.lifted_constants import lift_constants

    x, y = ca.SX.sym("x"), ca.SX.sym("y", 2)
    one = ca.Function("cc_lift_swap", [x], [3.0 * x])
    other = ca.Function("cc_lift_swap", [y], [ca.sum1(4.0 * y)])
    lift_constants(one)
    lift_constants(other)
    _swap_files(fresh, "lifted-*.constants")                 # each names the other's function
    monkeypatch.setattr(lifted_constants, "_LIFTED", {})
    lifted, constants = lift_constants(one)
    assert constants.tolist() == [3.0] and float(lifted(2.0, constants)) == 6.0
    lifted, constants = lift_constants(other)
    assert constants.tolist() == [4.0] and float(lifted([1.0, 2.0], constants)) == 12.0


@needs_compiler
def test_lifted_constants_beyond_the_limit_are_pruned(fresh, monkeypatch):
    import casadi as ca

    from flexctl.sim.lifted_constants import lift_constants

    monkeypatch.setattr(lifted_constants, "LIFTED_KEEP", 2)
    x = ca.SX.sym("x")
    for k in range(4):                  # one structure, four models' numbers
        lift_constants(ca.Function("cc_prune", [x], [(k + 1.5) * x]))
    folder = fresh / "compiled"
    assert len(list(folder.glob("lifted-*.constants"))) == 2
    assert len(list(folder.glob("lifted-*.casadi"))) == 1


@needs_compiler
def test_entry_point_calls_the_loaded_code_and_refuses_what_it_cannot_name(fresh):
    """The address of a cached function's C entry point computes what the function does;
    a function not loaded from the cache has none."""
    import ctypes

    import casadi as ca

    x = ca.SX.sym("x")
    plain = ca.Function("t_entry_point", [x], [3.0 * x + 1.0])
    assert compile_cache.entry_point(plain) is None
    built = compile_cache.compiled(plain)
    address, keep = compile_cache.entry_point(built)
    assert keep is not None
    signature = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p,
                                 ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int)
    value, out = (ctypes.c_double * 1)(2.0), (ctypes.c_double * 1)()
    args = (ctypes.c_void_p * 1)(ctypes.addressof(value))
    results = (ctypes.c_void_p * 1)(ctypes.addressof(out))
    assert signature(address)(args, results, None, None, 0) == 0
    assert out[0] == 7.0
    # another function of the same name and signature is not the one loaded
    assert compile_cache.entry_point(ca.Function("t_entry_point", [x], [x])) is None


@pytest.mark.parametrize("name, source", [("1bad", "int x;"), ("a b", "int x;"), (None, "int x;"),
                                          ("ok_name", ""), ("ok_name", None), ("ok_name", 3)])
def test_compiled_source_refuses_a_bad_name_or_source(name, source):
    from flexctl.model.errors import InputError

    with pytest.raises(InputError, match="compiled_source"):
        compile_cache.compiled_source(name, source)


def test_compiled_source_refuses_loops_that_are_not_a_bool():
    from flexctl.model.errors import InputError

    with pytest.raises(InputError, match="loops must be True or False; got 'yes'"):
        compile_cache.compiled_source("ok_name", "int x;", loops="yes")


def test_compiled_source_is_none_where_compiling_is_off(monkeypatch):
    monkeypatch.setenv("FLEXCTL_COMPILE", "0")
    assert compile_cache.compiled_source("t_off", "int t_off;") is None


@needs_compiler
def test_compiled_source_that_does_not_compile_falls_back_with_a_warning(fresh):
    with pytest.warns(compile_cache.CompileCacheWarning, match="t_broken"):
        assert compile_cache.compiled_source("t_broken", "this is not C;") is None


@needs_compiler
def test_hand_written_loops_are_compiled_with_their_own_flags(fresh, monkeypatch):
    # LOOP_FLAGS are part of the key: the same source is a second library, called alike
    import casadi as ca

    x = ca.SX.sym("x")
    generator = ca.CodeGenerator("t_loops.c", {"with_header": False})
    generator.add(ca.Function("t_loops", [x], [3.0 * x + 1.0]))
    source = generator.dump()
    commands = []
    popen = compile_cache.subprocess.Popen

    def recording(command, **options):
        commands.append(command)
        return popen(command, **options)

    monkeypatch.setattr(compile_cache.subprocess, "Popen", recording)
    plain = compile_cache.compiled_source("t_loops", source)
    loops = compile_cache.compiled_source("t_loops", source, loops=True)
    assert float(plain(2.0)) == float(loops(2.0)) == 7.0
    builds = [c for c in commands if c[-1] == "-lm"]
    assert [c[1:1 + len(compile_cache.FLAGS)] for c in builds] == [
        list(compile_cache.FLAGS), list(compile_cache.LOOP_FLAGS)]
    assert len(list(fresh.rglob(f"t_loops-*{compile_cache._SUFFIX}"))) == 2


@needs_compiler
def test_a_long_compile_says_so_on_one_whole_line(fresh, monkeypatch, capfd):
    import casadi as ca

    monkeypatch.setattr(compile_cache, "PROGRESS_AFTER", 0.0)
    spent = compile_cache.STATS["compile_seconds"]
    x = ca.SX.sym("x", 2)
    compiled(ca.Function("cc_progress", [x], [ca.cos(x) * x[0]]), label="the test function")
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines(keepends=True) if "compiling" in line]
    assert len(lines) == 1 and lines[0].endswith("\n"), err
    assert lines[0].startswith("flexctl: compiling the test function (")
    assert compile_cache.STATS["compile_seconds"] > spent
