"""The loop as it flies, and one stability verdict for it.

- On a free hub, ``loop_margins`` and ``check_loop`` give the same verdict and the same
  spectral abscissa: the rigid translation's poles, which no hub torque moves, are left out
  of both (they sat at +1e-14 1/s and made the margins call the loop unstable).
- ``loop_transfer`` takes the wheel's LQR (its gain on the plant with the wheel) and the
  observed law (a sampled ``L(z)`` with the hold, the delay and the Kalman filter): the
  closed loop ``feedback(L)`` holds the poles of the state feedback on the held plant
  (separation: the filter's model is the plant's), its slowest pole is the one
  ``check_loop`` finds, and its gain margin is the gain at which a pole crosses the unit
  circle.
- ``check_loop`` on a plant without the wheel the law commands says so.
"""

import warnings

import control
import numpy as np
import pytest
import scipy.linalg

import flexctl
from controllers import (LQRWeights, check_loop, design_lqr, from_spec, loop_margins,
                         loop_transfer)
from flexctl.model.errors import InputValueError

#: Poles agree to this fraction of the largest pole magnitude.
POLE_RTOL = 1e-7
#: The loop closed just inside and outside its gain margin: factors (1 -+ MARGIN_STEP).
MARGIN_STEP = 0.02


@pytest.fixture(scope="module")
def wheel_slew():
    scene = flexctl.load_scene("wheel-slew", overrides={"model.modes": 2,
                                                        "model.design_modes": 1})
    plant = scene.build_model()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        built = from_spec(scene, plant)
    return scene, plant, built


@pytest.fixture(scope="module")
def observed(wheel_slew):
    """The wheel-slew's observed law, its sampled loop and that loop's margins."""
    _, plant, built = wheel_slew
    loop = loop_transfer(plant, built.controller)
    return built.controller, loop, loop_margins(loop)


def _largest_rate(loop, gain=1.0):
    """The largest real part of the closed loop's poles off the axis's hidden modes, 1/s."""
    poles = np.asarray(control.poles(control.feedback(gain * loop)), dtype=complex)
    if not loop.isctime():
        with np.errstate(divide="ignore"):
            poles = np.log(poles) / loop.dt
    poles = poles[np.isfinite(poles) & (np.abs(poles) > 1e-5)]
    return float(np.max(poles.real))


def test_margins_and_check_agree_on_a_free_hub():
    scene = flexctl.load_scene("two-array-slew", overrides={"model.variant": "first_order"})
    model = flexctl.build_model(scene.system, 2)
    lqr = design_lqr(model, LQRWeights(hub_angle=0.05, torque=1.0))
    margins, check = loop_margins(loop_transfer(model, lqr)), check_loop(model, lqr)
    assert margins.closed_loop_stable and check.stable
    assert margins.spectral_abscissa == pytest.approx(check.spectral_abscissa, rel=1e-9)
    assert margins.spectral_abscissa < 0.0


def test_the_wheel_lqr_loop_closes_on_the_plant_with_the_wheel(wheel_slew):
    _, plant, built = wheel_slew
    lagged = built.controller.law
    loop = loop_transfer(plant, lagged)
    assert loop.nstates == plant.n_states
    a, b = plant.linear_matrices(0.0)
    expected = np.linalg.eigvals(a - b @ lagged.plant_gain(plant))
    got = control.poles(control.feedback(loop))
    scale = np.max(np.abs(expected))
    assert np.all([np.min(np.abs(got - p)) <= POLE_RTOL * scale for p in expected])
    with pytest.raises(InputValueError, match="must carry the reaction wheel the law commands"):
        check_loop(flexctl.build_model(plant.structure, 2), lagged)


def test_the_observed_loop_is_the_sampled_loop_as_it_flies(wheel_slew, observed):
    _, plant, _ = wheel_slew
    observed, loop, margins = observed
    assert loop.dt == observed.sample_time and loop.ninputs == loop.noutputs == 1
    # separation: the state feedback's poles on the held plant are the closed loop's
    a, b = plant.linear_matrices(0.0)
    n = plant.n_states
    block = np.zeros((n + 1, n + 1))
    block[:n, :n], block[:n, n:] = a, b
    hold = scipy.linalg.expm(block * observed.sample_time)
    law = np.linalg.eigvals(hold[:n, :n] - hold[:n, n:] @ observed.law.plant_gain(plant))
    closed = control.poles(control.feedback(loop))
    assert np.all([np.min(np.abs(closed - z)) <= 1e-7 for z in law])
    check = check_loop(plant, observed)
    assert margins.closed_loop_stable and check.stable
    assert margins.spectral_abscissa == pytest.approx(check.spectral_abscissa, rel=1e-6)
    # the gain margin is where a pole leaves the unit circle
    assert 1.0 < margins.gain_margin < 10.0
    assert _largest_rate(loop, (1.0 - MARGIN_STEP) * margins.gain_margin) < 0.0
    assert _largest_rate(loop, (1.0 + MARGIN_STEP) * margins.gain_margin) > 0.0


def test_every_crossing_is_listed_and_the_margins_are_among_them(observed):
    _, _, margins = observed
    kinds = {kind for kind, _, _ in margins.crossings}
    assert kinds <= {"phase", "gain"} and margins.crossings
    frequencies = [w for _, w, _ in margins.crossings]
    assert frequencies == sorted(frequencies)
    assert ("phase", margins.phase_crossover_frequency, margins.gain_margin) \
        in margins.crossings
    assert ("gain", margins.gain_crossover_frequency, margins.phase_margin) \
        in margins.crossings
    assert "crossings" not in margins.as_dict()


def _recursion_gain(ad, c, q, r, p0, samples):
    """The Kalman covariance recursion, one sample at a time: the gain after ``samples``."""
    p = np.array(p0, dtype=float)
    for _ in range(samples):
        gain = np.linalg.solve(c @ p @ c.T + r, c @ p).T
        keep = np.eye(p.shape[0]) - gain @ c
        p = ad @ (keep @ p @ keep.T + gain @ r @ gain.T) @ ad.T + q
    return np.linalg.solve(c @ p @ c.T + r, c @ p).T


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_doubled_recursion_reaches_the_recursions_limit(seed):
    """A free hub's translation (a double integrator no torque moves and no sensor reads),
    the rigid rotation and two undamped modes read by two sensors: the doubled recursion
    gives the gain of 20 000 samples of the plain one, and zero gain on the translation."""
    from controllers.feedback.observed_loop import steady_kalman_gain

    rng = np.random.default_rng(seed)
    a = np.zeros((8, 8))
    a[0, 1] = a[2, 3] = a[4, 6] = a[5, 7] = 1.0
    a[6, 4], a[7, 5] = -rng.uniform(1.0, 400.0, 2)
    ad = scipy.linalg.expm(0.1 * a)
    c = np.zeros((2, 8))
    c[0, 2], c[1, 3], c[0, 4], c[1, 7] = 1.0, 1.0, rng.uniform(0.1, 1.0), rng.uniform(0.1, 1.0)
    b = np.zeros((8, 1))
    b[3], b[6], b[7] = 1.0, rng.normal(), rng.normal()
    q, r, p0 = 1e-3 * b @ b.T, np.diag([1e-6, 1e-4]), 1e-3 * np.eye(8)
    gain = steady_kalman_gain(ad, c, q, r, p0)
    limit = _recursion_gain(ad, c, q, r, p0, 20_000)
    np.testing.assert_allclose(gain, limit, rtol=0, atol=1e-8 * np.max(np.abs(limit)))
    assert np.all(gain[:2] == 0.0)


def test_the_loop_matrices_are_the_sampled_loops(wheel_slew, observed):
    _, plant, _ = wheel_slew
    law, loop, _ = observed
    a, b, c, dt, names = law.loop_matrices(plant)
    assert dt == loop.dt and list(names) == list(loop.state_labels)
    for mine, theirs in ((a, loop.A), (b, loop.B), (c, loop.C)):
        np.testing.assert_array_equal(mine, np.asarray(theirs))
