"""Structural filters on a sampled law: their responses, the loop with their states, and the
simulation that steps them.

- Each filter has unit gain at zero frequency, continuous and discrete; a notch's depth at its
  centre, a roll-off's peak at its corner and a lead's largest phase are the textbook values,
  and the matched discretisation keeps them within a few per cent below a tenth of Nyquist.
- The cascade's state space has the product of the filters' responses.
- ``Filtered.loop_matrices`` is the loop that flies: the sampled states of a small-amplitude
  simulation follow the powers of its closed-loop matrix; a roll-off placed at the crossover
  makes ``check_loop`` call the loop unstable, and the simulation grows as it says.
"""

import math
import shutil
import warnings

import control
import numpy as np
import pytest

import flexctl
from controllers import (Filtered, LeadLag, LQRWeights, Notch, RollOff, check_loop, design_lqr,
                         loop_margins, loop_transfer)
from controllers.feedback.structural_filters import FilterCascade
from flexctl.model.errors import InputError
from flexctl.sim.digital import ZeroOrderHold

SAMPLE = 0.01


@pytest.fixture(scope="module")
def plant():
    return flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=4)


@pytest.fixture(scope="module")
def held_lqr():
    design = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=1)
    return ZeroOrderHold(design_lqr(design, LQRWeights(hub_angle=0.05, torque=1.0)), SAMPLE)


FILTERS = [Notch(frequency=23.8, depth_db=20.0, width=0.2), RollOff(frequency=60.0),
           LeadLag(zero=3.0, pole=30.0)]


@pytest.mark.parametrize("item", FILTERS, ids=["notch", "roll_off", "lead_lag"])
def test_unit_gain_at_zero_frequency(item):
    assert abs(item.response([0.0])[0]) == pytest.approx(1.0, rel=1e-12)
    assert abs(item.response([0.0], sample_time=SAMPLE)[0]) == pytest.approx(1.0, rel=1e-12)


def test_the_notch_has_its_depth_at_its_centre():
    notch = FILTERS[0]
    assert abs(notch.response([23.8])[0]) == pytest.approx(0.1, rel=1e-12)
    assert abs(notch.response([23.8], sample_time=SAMPLE)[0]) == pytest.approx(0.1, rel=0.05)
    assert abs(notch.response([2.38])[0]) > 0.99 and abs(notch.response([238.0])[0]) > 0.99


def test_the_roll_off_peaks_at_its_corner_and_falls_at_40_db_a_decade():
    roll = RollOff(frequency=10.0, damping=0.25)
    assert abs(roll.response([10.0])[0]) == pytest.approx(2.0, rel=1e-12)      # 1 / (2 zeta)
    far = abs(roll.response([1000.0])[0])
    assert far == pytest.approx(1e-4, rel=1e-3)


def test_the_lead_gives_its_largest_phase_at_the_geometric_mean():
    lead = FILTERS[2]
    peak = math.degrees(math.asin((30.0 - 3.0) / (30.0 + 3.0)))
    w = math.sqrt(3.0 * 30.0)
    assert math.degrees(np.angle(lead.response([w])[0])) == pytest.approx(peak, rel=1e-12)
    assert math.degrees(np.angle(lead.response([w], sample_time=SAMPLE)[0])) == \
        pytest.approx(peak, rel=0.05)


def test_the_cascade_state_space_has_the_product_of_the_responses():
    cascade = FilterCascade(tuple(FILTERS), SAMPLE)
    assert cascade.order == 5
    w = np.array([0.5, 3.0, 23.8, 60.0, 200.0])
    z = np.exp(1j * w * SAMPLE)
    ss = [complex((cascade.c @ np.linalg.solve(zk * np.eye(5) - cascade.a, cascade.b)
                   + cascade.d)[0, 0]) for zk in z]
    np.testing.assert_allclose(ss, cascade.response(w), rtol=1e-10)
    product = np.prod([f.response(w, sample_time=SAMPLE) for f in FILTERS], axis=0)
    np.testing.assert_allclose(cascade.response(w), product, rtol=1e-12)


def _closed(loop):
    return np.asarray(loop.a) - np.asarray(loop.b) @ np.asarray(loop.c)


def test_the_loop_matrices_are_the_loop_the_simulation_flies(plant, held_lqr):
    law = Filtered(law=held_lqr, filters=FILTERS)
    loop = law.loop_matrices(plant)
    n = plant.n_states
    x0 = plant.layout.join(theta=1e-6)
    result = flexctl.simulate(plant, 1.0, controller=law, x0=x0, output_step=SAMPLE,
                              rtol=1e-11)
    w = np.concatenate((x0, np.zeros(loop.a.shape[0] - n)))
    closed = _closed(loop)
    expected = [w[:n]]
    for _ in range(result.t.size - 1):
        w = closed @ w
        expected.append(w[:n])
    np.testing.assert_allclose(result.states.T, np.array(expected),
                               atol=1e-4 * np.max(np.abs(expected)))


def test_loop_transfer_and_check_loop_read_the_filtered_loop(plant, held_lqr):
    law = Filtered(law=held_lqr, filters=FILTERS[:1])
    loop = loop_transfer(plant, law)
    assert loop.dt == SAMPLE and loop.nstates == plant.n_states + 2
    poles = np.log(np.asarray(control.poles(control.feedback(loop)), dtype=complex)) / SAMPLE
    check = check_loop(plant, law)
    assert check.stable and "structural filters" in check.law
    assert np.max(poles.real) == pytest.approx(check.spectral_abscissa, abs=1e-9)
    assert loop_margins(loop).closed_loop_stable
    # the lag of a roll-off at 60 rad/s turns the fourth mode (134.6 rad/s) unstable
    lagged = check_loop(plant, Filtered(law=held_lqr, filters=FILTERS[:2]))
    assert not lagged.stable and 4 in [p.mode for p in lagged.poles]


def test_a_roll_off_at_the_crossover_is_found_unstable_and_flies_so(plant, held_lqr):
    law = Filtered(law=held_lqr, filters=[RollOff(frequency=4.0, damping=0.05)])
    check = check_loop(plant, law)
    assert not check.stable and check.spectral_abscissa > 0.01
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = flexctl.simulate(plant, 8.0, controller=law,
                                  x0=plant.layout.join(theta=1e-6), output_step=SAMPLE)
    assert result.status == "ok"
    theta = np.abs(result.theta)
    late, early = theta[result.t > 6.0].max(), theta[result.t < 2.0].max()
    # it grows as fast as the slowest-decaying unstable pole says, within a factor of 2
    growth = math.log(late / early) / 5.0
    assert 0.5 * check.spectral_abscissa < growth < 2.0 * check.spectral_abscissa


def test_a_torque_limit_bounds_the_filtered_command(plant, held_lqr):
    law = Filtered(law=held_lqr, filters=[LeadLag(zero=1.0, pole=50.0)], torque_limit=0.5)
    result = flexctl.simulate(plant, 1.0, controller=law, x0=plant.layout.join(theta=0.5))
    assert np.max(np.abs(result.torque)) <= 0.5 + 1e-12


@pytest.mark.parametrize("make, pattern", [
    (lambda: Notch(frequency=float("nan"), depth_db=10.0), "Notch.frequency"),
    (lambda: Notch(frequency=10.0, depth_db=-3.0), "Notch.depth_db"),
    (lambda: Notch(frequency=10.0, depth_db=10.0, width=1.5), "Notch.width"),
    (lambda: Notch(frequency=True, depth_db=10.0), "Notch.frequency"),
    (lambda: RollOff(frequency="10"), "RollOff.frequency"),
    (lambda: RollOff(frequency=10.0, damping=0.0), "RollOff.damping"),
    (lambda: LeadLag(zero=3.0, pole=3.0), "LeadLag.pole"),
    (lambda: LeadLag(zero=-1.0, pole=3.0), "LeadLag.zero"),
    (lambda: FilterCascade((), SAMPLE), "non-empty"),
    (lambda: FilterCascade((1.0,), SAMPLE), r"filters\[0\]"),
    (lambda: FilterCascade((Notch(frequency=300.0, depth_db=10.0),), SAMPLE),
     "Nyquist frequency 314.2 rad/s"),
    (lambda: Filtered(law=lambda t, x: 0.0, filters=FILTERS), "Filtered.law"),
    (lambda: Notch(frequency=1e300, depth_db=10.0), "Notch.frequency"),
    (lambda: LeadLag(zero=1e-300, pole=1.0), "LeadLag.zero"),
    (lambda: RollOff(frequency=float("inf")), "RollOff.frequency"),
], ids=["nan", "negative-depth", "wide", "bool", "string", "no-damping", "equal",
        "negative-zero", "empty", "not-a-filter", "above-nyquist", "continuous-law", "huge",
        "tiny", "inf"])
def test_bad_filters_are_refused_by_name(make, pattern):
    with pytest.raises(InputError, match=pattern):
        make()


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                    reason="no C compiler")
def test_the_exported_c_steps_the_filters_as_python_does(plant, held_lqr, tmp_path):
    from controllers.codegen import export_c

    law = Filtered(law=held_lqr, filters=FILTERS[:2], torque_limit=2.0)
    exported = export_c(law, plant, tmp_path)
    assert exported.program.n_memory == 4 and exported.program.sample_time == SAMPLE
    compiled = exported.compile()
    x0 = plant.layout.join(theta=0.3)
    runs = [flexctl.simulate(plant, 2.0, controller=c, x0=x0)
            for c in (law, compiled.controller())]
    assert np.max(np.abs(runs[0].torque)) == pytest.approx(2.0)      # the bound is reached
    np.testing.assert_allclose(runs[1].torque, runs[0].torque, rtol=1e-12, atol=1e-12)


def test_to_iosys_flies_the_filtered_law_as_simulate_does(plant, held_lqr):
    """The filtered held law as a discrete python-control system, on the plant held over the
    sample (CVODES at 1e-10), flies the torque flexctl.simulate flies, sample for sample;
    the torque bound included."""
    import control

    from controllers import to_iosys

    law = Filtered(law=held_lqr, filters=FILTERS[:2], torque_limit=2.0)
    system = to_iosys(law, plant)
    assert system.dt == SAMPLE and system.nstates == 4
    assert system.output_labels == ["torque"] and system.input_labels[0] == "theta"
    step = plant.discretize(SAMPLE, "cvodes", rtol=1e-10)
    held_plant = control.nlsys(lambda t, x, u, p: step(x, u[0]).full().ravel(), None,
                               dt=SAMPLE, states=system.input_labels, inputs=["torque"],
                               outputs=system.input_labels, name="plant")
    loop = control.interconnect([held_plant, system], inplist=[], outlist=["torque"])
    x0 = plant.layout.join(theta=0.3)
    t = np.arange(201) * SAMPLE
    theirs = np.ravel(control.input_output_response(
        loop, t, X0=np.concatenate((x0, np.zeros(4)))).outputs)
    ours = flexctl.simulate(plant, 2.0, controller=law, x0=x0, rtol=1e-10)
    at_samples = np.interp(t[:-1] + 0.5 * SAMPLE, ours.t, ours.torque)  # held in between
    assert np.max(np.abs(theirs[:-1])) == pytest.approx(2.0)
    np.testing.assert_allclose(theirs[:-1], at_samples, atol=1e-6)


# ------------------------------------------------------------------ the scene's form
NOTCH_TABLE = '[{kind = "notch", frequency = 23.8, depth_db = 20}]'
SLEW = {"model.variant": "first_order", "model.design_variant": "first_order",
        "model.modes": "3", "controller.kind": "lqr", "controller.sample_time": "0.01"}


def _built(**overrides):
    from controllers import from_spec

    settings = {key: value for key, value in {**SLEW, **overrides}.items() if value is not None}
    scene = flexctl.load_scene("slew-90", overrides=settings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return scene, from_spec(scene)


@pytest.mark.filterwarnings("ignore::flexctl.sim.validity.ModelValidityWarning")
def test_a_scene_puts_its_filters_on_the_sampled_command():
    from controllers.spec import FILTERS
    from controllers.feedback.structural_filters import FILTER_KINDS

    assert tuple(FILTER_KINDS) == FILTERS
    scene, built = _built(**{"controller.filters": NOTCH_TABLE})
    law = built.controller
    assert isinstance(law, Filtered) and law.filters == (Notch(frequency=23.8, depth_db=20.0),)
    assert built.info["structural_filters"] == "Notch"
    assert "with structural filters" in built.info["loop_stability"]["message"]
    _, plain = _built()
    result = flexctl.run_scene(scene, controller=law)
    assert result.status == "ok"
    # the notch takes the second mode's frequency out of the command: less of it in the torque
    bare = flexctl.run_scene(scene, controller=plain.controller)
    def second_mode(r):
        spectrum = np.abs(np.fft.rfft(r.torque - np.mean(r.torque)))
        w = 2 * np.pi * np.fft.rfftfreq(r.torque.size, r.t[1] - r.t[0])
        return spectrum[np.argmin(np.abs(w - 23.8))]
    assert second_mode(result) < 0.5 * second_mode(bare)


@pytest.mark.parametrize("overrides, pattern", [
    ({"controller.sample_time": None}, "need a sampled loop"),
    ({"controller.filters": '[{kind = "notch", frequency = 23.8, depth = 20}]'},
     r"controller\.filters\[0\]\.depth is not a setting of a notch filter"),
    ({"controller.filters": '[{kind = "notch", frequency = 23.8, depth_db = 20}, '
                            '{kind = "roll_off", frequency = -1}]'},
     r"controller\.filters\[1\]\.frequency must be finite and >= 1e-06"),
    ({"controller.filters": '[{kind = "comb"}]'}, r"controller\.filters \(kind 'lqr'\) must be"),
    ({"controller.filters": '[{kind = "notch", depth_db = 20}]'},
     r"controller\.filters\[0\]\.frequency is required for a notch filter"),
    ({"controller.filters": '[{kind = "lead_lag", zero = true, pole = 3}]'},
     r"controller\.filters\[0\]\.zero must be"),
    ({"controller.filters": '[]'}, r"controller\.filters \(kind 'lqr'\) must be"),
    ({"controller.filters": '[{kind = "roll_off", frequency = 400}]'},
     "Nyquist frequency 314.2 rad/s"),
], ids=["continuous", "unknown-key", "bad-value", "unknown-kind", "missing", "bool", "empty",
        "above-nyquist"])
def test_bad_filter_tables_are_refused_by_key(overrides, pattern):
    from controllers.spec import SceneError

    with pytest.raises(SceneError, match=pattern):
        _built(**{"controller.filters": NOTCH_TABLE, **overrides})


@pytest.mark.parametrize("kind", ["zvd", "bang_bang"])
def test_kinds_without_a_filters_setting_build_as_before(kind):
    _, built = _built(**{"controller.kind": kind, "controller.sample_time": None})
    assert not isinstance(built.controller, Filtered)
