"""The step loop with shared inputs: the same values as CasADi's mapaccum, without the copies."""

import numpy as np
import pytest

import casadi as ca

from flexctl.sim.step_chain import step_chain


def _step():
    x, h, c = ca.MX.sym("x", 3), ca.MX.sym("h"), ca.MX.sym("c", 40)
    moved = x + h * ca.sin(x) * c[:3] + c[10] * h ** 2
    return ca.Function("toy_step", [x, h, c], [moved, ca.vertcat(ca.sum1(x), h)],
                       ["x", "h", "c"], ["x_next", "o"])


@pytest.mark.parametrize("count", [1, 7, 10, 13, 100, 128, 250, np.int64(12)])
def test_chain_equals_mapaccum_step_by_step(count):
    step, rng = _step(), np.random.default_rng(count)
    x0, hs, c = rng.random(3), rng.uniform(0.01, 0.02, (1, count)), rng.random(40)
    ours = step_chain(step, count, "ours", stacked=[1])(x0, hs, c)
    theirs = step.mapaccum("theirs", count)(x0, hs, ca.repmat(ca.DM(c), 1, count))
    for a, b in zip(ours, theirs):
        assert a.shape == b.shape
        np.testing.assert_array_equal(np.array(a), np.array(b))
    # a shared step length is one number for every call
    shared = step_chain(step, count, "shared")(x0, 0.015, c)
    again = step.mapaccum("again", count)(x0, np.full((1, count), 0.015),
                                           ca.repmat(ca.DM(c), 1, count))
    np.testing.assert_array_equal(np.array(shared[0]), np.array(again[0]))


def test_shared_inputs_are_not_copied_per_call(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    step_chain(_step(), 128, "loop").generate("loop.c")
    code = (tmp_path / "loop.c").read_text()
    assert "repmat" not in code
    # the table is read where it lies: no copy of its 40 numbers anywhere in the loop
    assert "40, w" not in code


@pytest.mark.parametrize("count", [0, -3, 2.0, True, None])
def test_count_must_be_a_positive_integer(count):
    with pytest.raises(ValueError, match="count must be a positive integer"):
        step_chain(_step(), count, "bad")


@pytest.mark.parametrize("stacked", [[0], [3], [-1], [1.5], ["h"], 1, None])
def test_stacked_must_index_an_input_after_the_state(stacked):
    with pytest.raises(ValueError, match="stacked must index inputs 1..2 of toy_step"):
        step_chain(_step(), 4, "bad", stacked=stacked)


def test_a_step_of_one_output_loops_too():
    x, h = ca.MX.sym("x"), ca.MX.sym("h")
    decay = ca.Function("decay", [x, h], [x * (1.0 - h)])
    states = np.array(step_chain(decay, 25, "decays")(1.0, 0.1)).ravel()
    np.testing.assert_allclose(states, 0.9 ** np.arange(1, 26), rtol=1e-14)


def test_the_state_must_come_back_in_its_own_shape():
    x, h = ca.MX.sym("x", 2), ca.MX.sym("h")
    bad = ca.Function("bad", [x, h], [ca.sum1(x) * h])
    with pytest.raises(ValueError, match=r"bad's first output must have its first input's "
                                         r"shape \(2, 1\), got \(1, 1\)"):
        step_chain(bad, 3, "bad_chain")


@pytest.mark.parametrize("step, name, error", [
    ("toy_step", "ok", TypeError), (None, "ok", TypeError),
    (_step, "has space", ValueError), (_step, 7, ValueError), (_step, "", ValueError)])
def test_the_step_and_the_name_are_checked(step, name, error):
    with pytest.raises(error, match="step must be a casadi.Function|name must be a valid"):
        step_chain(step() if callable(step) else step, 3, name)
