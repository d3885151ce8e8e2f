"""Buffers of compiled functions kept between runs (flexctl.sim.buffers)."""

import casadi as ca
import numpy as np
import pytest

import flexctl
from flexctl.sim import buffers
from flexctl.sim.buffers import InPlace, borrow, give_back
from flexctl.sim.embedded_rk import EmbeddedRun
from flexctl.sim.request import state_scale


def _function(name="f", n=3):
    x = ca.SX.sym("x", n)
    return ca.Function(name, [x], [2.0 * x])


@pytest.fixture
def empty_pool(monkeypatch):
    monkeypatch.setattr(buffers, "_POOL", type(buffers._POOL)())
    return buffers._POOL


def test_a_buffer_given_back_serves_the_next_run_of_its_function_only(empty_pool):
    f, g = _function("f"), _function("g")
    first = borrow(f)
    assert isinstance(first, InPlace) and borrow(f) is not first     # both in use
    give_back(first)
    assert borrow(g) is not first                   # another function: a buffer of its own
    again = borrow(f)
    assert again is first
    np.testing.assert_array_equal(again(np.arange(3.0))[0].ravel(), [0.0, 2.0, 4.0])
    assert borrow(f) is not first                   # handed out once


def test_the_pool_keeps_no_more_than_its_bytes(empty_pool, monkeypatch):
    f = _function("big", 1000)
    kept = [borrow(f) for _ in range(3)]
    size = buffers._size(kept[0])
    monkeypatch.setattr(buffers, "POOL_BYTES", 2 * size)
    for buffer in kept:
        give_back(buffer)
    assert sum(len(entry[1]) for entry in empty_pool.values()) == 2
    monkeypatch.setattr(buffers, "POOL_BYTES", size - 1)
    give_back(InPlace(f))                           # larger than the whole pool: let go
    assert sum(len(entry[1]) for entry in empty_pool.values()) <= 2


def test_runs_one_after_another_share_their_buffers_and_a_released_run_refuses(empty_pool):
    model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    torque = flexctl.SineTorque(peak_torque=2.0, duration=2.0)
    options = dict(scale=state_scale(model, model.layout), rtol=1e-6, max_steps=1000,
                   h_first=1e-3, scheme="dop853")
    first = EmbeddedRun(model, torque=torque, **options)
    states, _ = first(0.0, np.array([0.5, 1.0]), np.zeros(model.n_states))
    buffer = first._run
    first.release()
    with pytest.raises(RuntimeError, match="released"):
        first(0.0, np.array([1.0]), np.zeros(model.n_states))
    second = EmbeddedRun(model, torque=torque, **options)
    assert second._run is buffer
    # the same numbers from the buffer another run used
    again, _ = second(0.0, np.array([0.5, 1.0]), np.zeros(model.n_states))
    np.testing.assert_array_equal(again, states)
    # a run let go without release gives its buffer back too, once
    del second
    third = EmbeddedRun(model, torque=torque, **options)
    assert third._run is buffer and EmbeddedRun(model, torque=torque, **options)._run \
        is not buffer
