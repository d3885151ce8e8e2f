"""Work beside the caller (flexctl.sim.background): the accuracy check on a spare core gives
the same run, the same error estimate and the same mended runs as the check made after it."""

import multiprocessing
import threading
import warnings

import numpy as np
import pytest

import flexctl
from flexctl.sim import background
from flexctl.sim.background import Beside
from flexctl.sim.maneuvers import SineTorque


@pytest.fixture
def beside(monkeypatch):
    """Calls go to a pool thread even where the machine has one core."""
    monkeypatch.setattr(background, "ENABLED", True)
    monkeypatch.setattr(background, "spare_cores", lambda: 1)
    return background


def test_result_comes_from_a_pool_thread(beside):
    running = threading.Event()

    def name():
        running.set()
        return threading.current_thread().name
    job = Beside(name)
    assert job.started and running.wait(10.0)
    assert job.result().startswith("flexctl-beside")


def test_exception_reaches_the_caller(beside):
    def fails():
        raise RuntimeError("the check integration failed")
    with pytest.raises(RuntimeError, match="check integration failed"):
        Beside(fails).result()


def test_disabled_runs_in_the_callers_thread(monkeypatch):
    monkeypatch.setattr(background, "ENABLED", False)
    job = Beside(lambda: threading.current_thread().name)
    assert not job.started
    assert job.result() == threading.current_thread().name
    assert not Beside(sum, [1], beside=True).started


def test_not_beside_runs_when_asked(beside):
    calls = []
    job = Beside(calls.append, 1, beside=False)
    assert not job.started and calls == []
    job.result()
    assert calls == [1]


def test_call_from_a_pool_thread_runs_inline(beside):
    # a pool thread that asks for work beside it must not wait on its own pool
    running = threading.Event()

    def nested():
        running.set()
        inner = Beside(lambda: threading.current_thread().name)
        return inner.started, inner.result()
    outer = Beside(nested)
    assert running.wait(10.0)                  # the outer call is on the pool thread
    started, name = outer.result()
    assert not started and name.startswith("flexctl-beside")


def test_with_every_spare_core_taken_a_call_waits_for_result(beside):
    gate, ran = threading.Event(), []
    blocker = Beside(gate.wait, 10.0)           # takes the one spare core
    assert blocker.started
    waiting = Beside(ran.append, 1, cancelled=threading.Event())
    assert not waiting.started and ran == []
    waiting.abandon()                           # given up: it never runs
    assert waiting.cancelled.is_set() and ran == []
    gate.set()
    assert blocker.result() is True
    later = Beside(ran.append, 2)               # the core is free again
    assert later.started
    later.result()
    assert ran == [2]


def test_a_queued_call_runs_on_the_core_given_back(beside):
    gate, ran, order = threading.Event(), threading.Event(), []

    def second():
        order.append("second")
        ran.set()
        return threading.current_thread().name
    blocker = Beside(lambda: (gate.wait(10.0), order.append("first")))
    queued = Beside(second, queue=True)
    assert blocker.started and not queued.started and order == []
    gate.set()
    assert ran.wait(10.0)                                  # not asked for: it ran beside
    assert queued.started and queued.result().startswith("flexctl-beside")
    assert order == ["first", "second"]
    later = Beside(order.append, "third")                  # the core was given back
    assert later.started
    later.result()


def test_a_queued_call_asked_for_first_runs_in_the_callers_thread(beside):
    gate, ran = threading.Event(), []
    blocker = Beside(gate.wait, 10.0)
    queued = Beside(lambda: (ran.append(1), threading.current_thread().name)[1], queue=True)
    assert queued.result() == threading.current_thread().name
    gate.set()
    blocker.result()
    assert ran == [1]                           # once: the pool thread did not run it again
    assert Beside(sum, [2]).result() == 2       # and gave its core back


def test_an_abandoned_queued_call_never_runs(beside):
    gate, ran = threading.Event(), []
    blocker = Beside(gate.wait, 10.0)
    queued = Beside(ran.append, 1, queue=True, cancelled=threading.Event())
    queued.abandon()
    assert queued.cancelled.is_set()
    gate.set()
    blocker.result()
    after = Beside(ran.append, 2)               # runs after the blocker's thread is done
    after.result()
    assert ran == [2]


def test_queued_calls_run_in_order_and_raise_to_their_caller(beside):
    gate, ran = threading.Event(), threading.Event()
    blocker = Beside(gate.wait, 10.0)
    order = []

    def fails():
        order.append("fails")
        raise RuntimeError("queued call failed")
    first = Beside(fails, queue=True)
    second = Beside(lambda: (order.append("second"), ran.set()), queue=True)
    gate.set()
    assert ran.wait(10.0)
    second.result()
    with pytest.raises(RuntimeError, match="queued call failed"):
        first.result()
    assert order == ["fails", "second"]


def test_abandoned_call_does_not_hold_up_exit(tmp_path):
    # a call still running when the interpreter ends is not waited for
    import subprocess
    import sys
    import time

    script = ("import time\nfrom flexctl.sim import background as b\n"
              "b.ENABLED = True\nb.spare_cores = lambda: 1\n"
              "job = b.Beside(time.sleep, 60.0)\nassert job.started\njob.abandon()\n")
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=50)
    assert done.returncode == 0, done.stderr
    assert time.perf_counter() - start < 30.0


def test_a_cancelled_chain_stops_before_its_next_segment():
    from flexctl.sim.compiled import run_segments

    calls = []

    class Segment:
        n_evaluations = 1

        def __call__(self, y):
            calls.append(1)
            return np.column_stack((y, y))

    stop = threading.Event()
    states, n = run_segments([Segment(), Segment()], np.zeros(2), stop)
    assert states.shape == (2, 4) and n == 2
    stop.set()
    with pytest.raises(RuntimeError, match="cancelled"):
        run_segments([Segment()], np.zeros(2), stop)
    assert len(calls) == 2


def _runs(name):
    scene = flexctl.load_scene(name)
    model = flexctl.build_model(scene.system, n_modes=3)
    drive = ({"hub_motion": scene.maneuver} if name == "kane-spinup"
             else {"torque": SineTorque(peak_torque=2.0, duration=2.0)})
    return model, drive


@pytest.mark.parametrize("name", ["kane-spinup", "hub-beam-mass"])
def test_check_beside_equals_check_after(beside, monkeypatch, name):
    model, drive = _runs(name)
    results = {}
    for enabled in (False, True):
        monkeypatch.setattr(background, "ENABLED", enabled)
        results[enabled] = flexctl.simulate(model, 4.0, rtol=1e-6, check_validity=False,
                                            **drive)
    after, during = results[False], results[True]
    assert after.ok and during.ok
    assert np.array_equal(after.states, during.states)
    assert after.integration_error is not None
    assert during.integration_error == after.integration_error
    assert during.n_evaluations == after.n_evaluations


def test_check_on_threads_equals_check_alone(beside):
    # simulations on user threads, each with its check beside it, give the runs made alone
    model, drive = _runs("hub-beam-mass")
    peaks = [0.5, 1.0, 1.5, 2.0]

    def run(peak):
        result = flexctl.simulate(model, 2.0, rtol=1e-7, check_validity=False,
                                  torque=SineTorque(peak_torque=peak, duration=2.0))
        return result.states, result.integration_error

    alone = [run(p) for p in peaks]
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(3) as pool:
        together = list(pool.map(run, peaks * 2))
    for (states, error), (again, error_again) in zip(alone * 2, together):
        assert np.array_equal(states, again) and error == error_again


def test_a_run_that_stops_early_abandons_its_check(beside):
    # a torque far beyond the beam's strength: the run stops on the deflection limit
    scene = flexctl.load_scene("hub-beam-mass")
    model = flexctl.build_model(scene.system, n_modes=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = flexctl.simulate(model, 4.0, torque=SineTorque(peak_torque=1e5, duration=2.0),
                                  check_validity=False)
    assert result.status != "ok"
    assert result.integration_error is None


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                    reason="needs fork")
def test_fork_waits_for_running_calls(beside):
    gate = threading.Event()
    job = Beside(gate.wait, 0.5)
    assert job.started and background._RUNNING
    context = multiprocessing.get_context("fork")
    child = context.Process(target=int)
    child.start()                              # the fork waits for the call to end
    assert not background._RUNNING
    child.join(60)
    assert child.exitcode == 0
    assert job.result() is False               # it ran to its time-out, then the fork went


def _evaluate_in_child(buffer, queue):
    queue.put(float(buffer(2.0)[0][0, 0]))


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                    reason="needs fork")
def test_child_forked_while_a_buffer_is_busy_gets_a_fresh_lock():
    # the lock of an integrator's buffer, held by a check running beside its run at the fork,
    # would never be released in the child
    import casadi as ca

    from flexctl.sim.buffers import InPlace

    x = ca.SX.sym("x")
    buffer = InPlace(ca.Function("double", [x], [2 * x]))
    buffer._lock.acquire()                     # as if a thread were evaluating it
    try:
        context = multiprocessing.get_context("fork")
        queue = context.Queue()
        child = context.Process(target=_evaluate_in_child, args=(buffer, queue))
        child.start()
        child.join(60)
    finally:
        buffer._lock.release()
    assert child.exitcode == 0
    assert queue.get(timeout=5) == 4.0


def _child(queue):
    model, drive = _runs("hub-beam-mass")
    result = flexctl.simulate(model, 1.0, check_validity=False, **drive)
    queue.put((result.ok, result.integration_error is not None))


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                    reason="needs fork")
def test_forked_child_builds_its_own_pool(beside):
    Beside(sum, [1]).result()                      # the parent's pool exists
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_child, args=(queue,))
    child.start()
    child.join(120)
    assert child.exitcode == 0
    assert queue.get(timeout=5) == (True, True)
