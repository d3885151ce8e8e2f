"""Reduced design models: python-control's slycot tools on flexctl plants, and flexctl's own
modal and balanced truncation held to the theory's error bounds.

The errors are measured independently of :mod:`flexctl.model.reduction`: the largest singular
value of ``G(jw) - G_r(jw)`` from python-control's frequency responses on a dense logarithmic
grid, fine enough (relative step 7e-4) to resolve resonances of damping ratio 0.01.
"""

import math

import control
import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

import flexctl
from flexctl import Appendage, Beam, Hub, Structure, build_model
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.reduction import (Reduction, balanced_truncation, hinf_norm,
                                     modal_truncation)
from clear_errors import assert_clear_error

N_MODES = 6
DAMPING = 0.01
FREQUENCIES = np.logspace(-2, 4, 20000)
#: The grid's peak is below the true one by the resolution of a resonance of damping 0.01.
GRID_RTOL = 1e-3
#: Rigid-body poles are zero to round-off.
ZERO_POLE = 1e-6
#: Two computations of one pole, or of one frequency response, agree to this.
SAME_RTOL = 1e-6


@pytest.fixture(scope="module")
def damped_model():
    scene = flexctl.load_scene("hub-beam-mass", {"beam.damping_ratio": DAMPING})
    return build_model(scene.system, n_modes=N_MODES)


@pytest.fixture(scope="module")
def plant(damped_model):
    return damped_model.linearize()


@pytest.fixture(scope="module")
def undamped_model():
    return build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=N_MODES)


def response(system, frequencies=FREQUENCIES):
    """``G(jw)``, shape (n_w, outputs, inputs), from python-control."""
    return np.moveaxis(system.frequency_response(frequencies).frdata, 2, 0)


def gains(system_a, system_b, frequencies=FREQUENCIES):
    """``sigma_max(G_a(jw) - G_b(jw))`` and ``sigma_max(G_a(jw))`` at each frequency."""
    g_a, g_b = response(system_a, frequencies), response(system_b, frequencies)
    return (np.linalg.svd(g_a - g_b, compute_uv=False)[:, 0],
            np.linalg.svd(g_a, compute_uv=False)[:, 0])


def peak_error(full, reduced):
    return float(np.max(gains(full, reduced)[0]))


def sorted_poles(poles):
    poles = np.asarray(poles)
    return poles[np.lexsort((poles.imag, np.round(np.abs(poles), 6)))]


# ------------------------------------------------------------------ python-control with slycot
def test_minreal_keeps_the_minimal_plant_and_drops_the_hub_angle_unseen_by_a_rate(plant):
    pytest.importorskip("slycot")
    minimal = control.minreal(plant, verbose=False)
    assert minimal.nstates == plant.nstates      # every mode moved by the torque and seen
    error, gain = gains(plant, minimal)
    assert np.all(error <= SAME_RTOL * gain)
    rate = plant[["theta_dot"], ["torque"]]
    assert control.minreal(rate, verbose=False).nstates == plant.nstates - 1


@pytest.mark.parametrize("order", [4, 6, 9])
def test_balred_of_slycot_and_flexctl_balanced_truncation_agree(damped_model, plant, order):
    pytest.importorskip("slycot")
    theirs = control.balred(plant, order)        # keeps the poles at 0 (Re >= alpha = 0)
    ours = balanced_truncation(damped_model, order).system
    assert theirs.nstates == ours.nstates == order
    error, gain = gains(theirs, ours)
    assert np.all(error <= SAME_RTOL * gain)


@pytest.mark.filterwarnings("ignore:connect\\(\\) is deprecated:FutureWarning")
def test_hinfsyn_on_a_modal_design_model_stabilises_the_full_plant():
    """Mixed sensitivity on torque -> hub rate with one mode kept; the stated error of the
    reduction certifies the design on the full plant by the small-gain theorem."""
    pytest.importorskip("slycot")
    scene = flexctl.load_scene("hub-beam-mass", {"beam.damping_ratio": 0.02,
                                                 "hub.friction": 0.05})
    channel = build_model(scene.system, n_modes=4).linearize()[["theta_dot"], ["torque"]]
    reduced = modal_truncation(channel, 1)
    design = control.minreal(reduced.system, verbose=False)   # drops the unseen hub angle
    assert design.nstates == 3
    performance = control.tf([0.5, 0.25], [1.0, 5e-4])
    effort = control.tf([0.02, 0.2], [1e-3, 1.0])
    controller, loop, gamma, _ = control.hinfsyn(control.augw(design, performance, effort),
                                                 1, 1)
    assert gamma < 1.0
    assert np.all(loop.poles().real < 0.0)
    control_sensitivity = hinf_norm(control.ss(control.feedback(controller, design)))
    assert control_sensitivity * reduced.error_bound < 1.0
    full = control.minreal(channel, verbose=False)
    assert np.all(control.feedback(full * controller, 1).poles().real < 0.0)


# ------------------------------------------------------------------ modal truncation
@pytest.mark.parametrize("n_modes", [0, 1, 3, 5, N_MODES])
def test_modal_truncation_keeps_the_rigid_body_and_the_lowest_modes(plant, n_modes):
    reduced = modal_truncation(plant, n_modes)
    full = sorted_poles(np.linalg.eigvals(plant.A))        # two zeros, then mode by mode
    assert reduced.system.nstates == 2 + 2 * n_modes
    np.testing.assert_allclose(sorted_poles(reduced.system.poles()), full[:2 + 2 * n_modes],
                               rtol=SAME_RTOL, atol=ZERO_POLE)
    np.testing.assert_allclose(sorted_poles(reduced.discarded_poles), full[2 + 2 * n_modes:],
                               rtol=SAME_RTOL)
    assert reduced.kept == ("rigid",) + tuple(f"mode{j}" for j in range(1, n_modes + 1))
    assert reduced.discarded == tuple(f"mode{j}" for j in range(n_modes + 1, N_MODES + 1))
    assert reduced.system.input_labels == plant.input_labels
    assert reduced.system.output_labels == plant.output_labels


def test_each_kept_mode_is_an_oscillator_driven_with_unit_gain(plant):
    system = modal_truncation(plant, 3).system
    for j, pole in enumerate(sorted_poles(np.linalg.eigvals(plant.A))[2:8:2], start=1):
        rows = [system.state_labels.index(f"mode{j}"), system.state_labels.index(f"mode{j}_dot")]
        a, b = system.A[np.ix_(rows, rows)], system.B[rows, 0]
        omega, zeta = abs(pole), -pole.real / abs(pole)
        np.testing.assert_allclose(a, [[0.0, 1.0], [-omega ** 2, -2.0 * zeta * omega]],
                                   rtol=SAME_RTOL, atol=SAME_RTOL * omega ** 2)
        np.testing.assert_allclose(b, [0.0, 1.0], atol=SAME_RTOL)


def test_max_frequency_keeps_the_modes_below_it(damped_model):
    by_count = modal_truncation(damped_model, 2)
    by_frequency = modal_truncation(damped_model, max_frequency=50.0)   # modes at 5.5, 24, 68
    assert by_frequency.kept == by_count.kept == ("rigid", "mode1", "mode2")
    assert by_frequency.error_bound == pytest.approx(by_count.error_bound)


@pytest.mark.parametrize("n_modes", [1, 2, 4])
def test_modal_truncation_matches_the_plant_below_the_cutoff(damped_model, plant, n_modes):
    """Well below the first mode left out, the modes left out respond statically: a small
    error, which the static correction removes but for ``(w / w_c)^2``."""
    truncated = modal_truncation(damped_model, n_modes)
    corrected = modal_truncation(damped_model, n_modes, keep_dc_gain=True)
    error, gain = gains(plant, truncated.system)
    error_corrected, _ = gains(plant, corrected.system)
    cutoff = abs(truncated.discarded_poles[0])
    low = FREQUENCIES <= cutoff / 10.0
    assert np.max(error[low] / gain[low]) < 0.1
    # one mode: |G_i(jw) - G_i(0)| / |G_i(0)| = 1.03e-2 at a tenth of its frequency, zeta 0.01
    assert np.max(error_corrected[low] / error[low]) < 0.0125
    for reduced, measured in ((truncated, error), (corrected, error_corrected)):
        # the stated error is the norm of the modes left out: an upper bound, and tight
        assert np.max(measured) <= reduced.error_bound
        assert np.max(measured) >= (1.0 - GRID_RTOL) * reduced.error_bound
        assert reduced.error == reduced.error_bound


def test_the_static_correction_keeps_the_static_bending_under_hub_acceleration(plant):
    """A steady torque accelerates the hub and bends the beam by a steady amount: the tip
    deflection's low-frequency gain, to which every mode contributes."""
    tip = plant[["tip_deflection"], ["torque"]]
    static = response(tip, [1e-3])[0, 0, 0].real
    for keep_dc_gain, rtol in ((True, 1e-8), (False, -1e-3)):
        reduced = modal_truncation(tip, 1, keep_dc_gain=keep_dc_gain).system
        deviation = abs(response(reduced, [1e-3])[0, 0, 0].real - static) / abs(static)
        assert deviation < rtol if keep_dc_gain else deviation > -rtol


def test_modal_truncation_of_an_undamped_beam_states_an_infinite_error(undamped_model):
    reduced = modal_truncation(undamped_model, 2)
    assert reduced.error == reduced.error_bound == math.inf
    assert np.allclose(reduced.discarded_poles.real, 0.0, atol=ZERO_POLE)
    assert reduced.system.nstates == 6


@pytest.mark.parametrize("scene", ["flexible-link", "wheel-slew"])
def test_modal_truncation_keeps_actuator_poles_and_a_free_hub(scene):
    model = flexctl.load_scene(scene).build_model()
    plant = model.linearize()
    reduced = modal_truncation(model, 1)
    full = np.linalg.eigvals(plant.A)
    n_real = int(np.sum(np.abs(full.imag) <= ZERO_POLE * np.abs(full)))
    assert reduced.system.nstates == n_real + 2
    assert "real" in reduced.kept
    assert peak_error(plant, reduced.system) <= reduced.error_bound


def test_modes_of_equal_poles_are_kept_or_discarded_together():
    """Two identical oscillators (and a real pole), seen through two inputs and three outputs:
    any combination of them is a mode, so modal truncation cannot cut between them."""
    def oscillator(omega, zeta):
        return [[0.0, 1.0], [-omega ** 2, -2.0 * zeta * omega]]
    rng = np.random.default_rng(1)
    a = scipy.linalg.block_diag(oscillator(3.0, 0.02), oscillator(3.0, 0.02),
                                oscillator(10.0, 0.05), [[-2.0]])
    system = control.ss(a, rng.standard_normal((7, 2)), rng.standard_normal((3, 7)), 0.0)
    with pytest.raises(InputValueError, match=r"n_modes \(or max_frequency\) must not separate "
                                              r"modes 1 and 2.*got 1 modes kept"):
        modal_truncation(system, 1)
    reduced = modal_truncation(system, 2)
    assert reduced.kept == ("real", "modes1-2") and reduced.discarded == ("mode3",)
    assert peak_error(system, reduced.system) <= reduced.error_bound
    whole = modal_truncation(system, 3)
    error, gain = gains(system, whole.system)
    assert whole.error == 0.0 and np.all(error <= SAME_RTOL * gain)


def test_reduction_at_a_spin_keeps_the_stiffened_modes(damped_model):
    spinning = damped_model.linearize(spin_rate=3.0)
    reduced = modal_truncation(damped_model, 2, spin_rate=3.0)
    full = sorted_poles(np.linalg.eigvals(spinning.A))
    np.testing.assert_allclose(sorted_poles(reduced.system.poles()), full[:6], rtol=SAME_RTOL,
                               atol=ZERO_POLE)


# ------------------------------------------------------------------ balanced truncation
@pytest.mark.parametrize("order", [2, 3, 4, 6, 7, 8, 10, 12])
def test_balanced_truncation_error_lies_between_the_theory_bounds(damped_model, plant, order):
    """``sigma_{k+1} <= ||G - G_r||_inf <= 2 sum_{i > k} sigma_i`` for the stable part; the
    rigid part is kept exactly, so it cancels in ``G - G_r``."""
    reduced = balanced_truncation(damped_model, order)
    k = order - 2
    measured = peak_error(plant, reduced.system)
    assert measured <= reduced.error_bound
    assert measured >= (1.0 - GRID_RTOL) * reduced.hankel_singular_values[k]
    assert reduced.error_bound == pytest.approx(2.0 * sum(reduced.hankel_singular_values[k:]))
    assert reduced.error == pytest.approx(measured, rel=GRID_RTOL)


@pytest.mark.parametrize("reduce", [lambda m: balanced_truncation(m, 5),
                                    lambda m: modal_truncation(m, 2)], ids=["balanced", "modal"])
def test_the_rigid_body_is_kept_exactly(damped_model, plant, reduce):
    """``G(s) = R2 / s^2 + R1 / s + ..`` near 0, with ``R2`` the hub angle (and the tip's line
    of sight) under the total inertia ``J`` about the hub and ``R1`` its rate."""
    system = damped_model.system
    hub, beam = system.hub, system.beam
    inertia = (hub.inertia + beam.density * beam.area * ((hub.radius + beam.length) ** 3
                                                         - hub.radius ** 3) / 3.0
               + sum(p.mass * (hub.radius + p.position) ** 2 for p in system.masses))
    reduced = reduce(damped_model).system
    rigid = [i for i, name in enumerate(reduced.state_labels) if name.startswith("rigid")]
    assert len(rigid) == 2
    a, b, c = reduced.A[np.ix_(rigid, rigid)], reduced.B[rigid], reduced.C[:, rigid]
    np.testing.assert_allclose(a @ a, 0.0, atol=1e-12)         # a double pole at 0
    tolerance = 1e-9 / inertia
    # outputs: theta, theta_dot, tip_deflection, root_moment, tip_angle
    np.testing.assert_allclose((c @ a @ b).ravel(), [1 / inertia, 0, 0, 0, 1 / inertia],
                               atol=tolerance)
    np.testing.assert_allclose((c @ b).ravel(), [0, 1 / inertia, 0, 0, 0], atol=tolerance)
    # so G - G_r stays bounded where G and G_r grow like 1 / w^2 (measurable to ~1e-3 there)
    low = np.logspace(-2, -1, 50)
    assert np.max(gains(plant, reduced, low)[0]) <= (1.0 + GRID_RTOL) * \
        reduce(damped_model).error_bound


def test_hankel_singular_values_come_in_pairs_for_light_damping(damped_model):
    """A lightly damped, well-separated mode contributes two nearly equal values."""
    hsv = balanced_truncation(damped_model, 2).hankel_singular_values
    assert len(hsv) == 2 * N_MODES and np.all(np.diff(hsv) <= 0.0)
    np.testing.assert_allclose(hsv[0::2], hsv[1::2], rtol=0.1)


@settings(max_examples=15, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2 ** 31), n_modes=st.integers(2, 5), order=st.integers(1, 9))
def test_balanced_truncation_bounds_hold_on_random_damped_plants(seed, n_modes, order):
    """Random stable plants (damping 0.005 to 0.5, mixed coordinates, two outputs): the
    computed error lies between the theory's bounds and is not below the grid's peak."""
    rng = np.random.default_rng(seed)
    omega = np.sort(rng.uniform(1.0, 100.0, n_modes))
    zeta = rng.uniform(0.005, 0.5, n_modes)
    n = 2 * n_modes
    a = scipy.linalg.block_diag(*[[[0.0, 1.0], [-w ** 2, -2.0 * z * w]]
                                  for w, z in zip(omega, zeta)])
    mixing = rng.standard_normal((n, n)) + 3.0 * np.eye(n)
    system = control.ss(np.linalg.solve(mixing, a @ mixing), rng.standard_normal((n, 1)),
                        rng.standard_normal((2, n)), np.zeros((2, 1)))
    order = min(order, n)
    try:
        reduced = balanced_truncation(system, order)
    except InputValueError as exc:            # a numerically unobservable random draw
        assert "Hankel singular values" in str(exc)
        return
    hsv = reduced.hankel_singular_values
    round_off = 1e-9 * hsv[0]
    measured = float(np.max(gains(system, reduced.system, np.logspace(-1, 3, 4000))[0]))
    assert measured <= reduced.error * (1.0 + 1e-6) + round_off
    assert reduced.error <= reduced.error_bound * (1.0 + 1e-6) + round_off
    assert reduced.error >= (1.0 - 1e-6) * (hsv[order] if order < n else 0.0)


# ------------------------------------------------------------------ the H_inf norm
@pytest.mark.parametrize("zeta", [0.001, 0.01, 0.1, 0.5])
def test_hinf_norm_of_an_oscillator_is_its_resonant_peak(zeta):
    omega = 7.0
    system = control.ss([[0.0, 1.0], [-omega ** 2, -2.0 * zeta * omega]], [[0.0], [1.0]],
                        [[1.0, 0.0]], 0.0)
    peak = 1.0 / (2.0 * zeta * math.sqrt(1.0 - zeta ** 2) * omega ** 2)
    assert hinf_norm(system) == pytest.approx(peak, rel=SAME_RTOL)


def test_hinf_norm_agrees_with_slycot():
    pytest.importorskip("slycot")
    plant = flexctl.load_scene("flexible-link").build_model().linearize()
    rate = control.minreal(plant[["theta_dot", "tip_deflection"], ["voltage"]], verbose=False)
    assert hinf_norm(rate) == pytest.approx(control.norm(rate, "inf", method="slycot"),
                                            rel=1e-5)


def test_hinf_norm_of_a_plant_with_a_rigid_body_is_infinite(plant):
    assert hinf_norm(plant) == math.inf


# ------------------------------------------------------------------ refusals
def test_balanced_truncation_refuses_an_undamped_beam(undamped_model):
    with pytest.raises(InputValueError, match=r"model_or_sys must have damped flexible modes"
                                              r".*5\.48.*damping_ratio > 0.*modal_truncation"):
        balanced_truncation(undamped_model, 6)


@pytest.mark.parametrize("order, error, pattern", [
    (0, InputValueError, r"order must be an integer >= 1; got 0"),
    (-3, InputValueError, r"order must be an integer >= 1; got -3"),
    (1, InputValueError, r"order must be >= 2, the states of the rigid-body part.*got 1"),
    (15, InputValueError, r"order must be an integer in \[1, 14\]; got 15"),
    (10 ** 30, InputValueError, r"order must be an integer in \[1, 14\]"),
    (6.0, InputTypeError, r"order must be an integer >= 1; got 6.0 of type float"),
    (math.nan, InputTypeError, r"order must be an integer"),
    (True, InputTypeError, r"order must be an integer >= 1; got True of type bool"),
    ("6", InputTypeError, r"order must be an integer"),
    (None, InputTypeError, r"order must be an integer"),
], ids=["zero", "negative", "below-rigid", "above-plant", "huge", "float", "nan", "bool",
        "str", "none"])
def test_balanced_truncation_refuses_a_bad_order(damped_model, order, error, pattern):
    with pytest.raises(error, match=pattern):
        balanced_truncation(damped_model, order)


def test_balanced_truncation_refuses_to_keep_uncontrollable_states():
    """Identical arrays bend against each other in modes the hub torque cannot move."""
    panel = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
                 youngs_modulus=6.9e10, damping_ratio=DAMPING)
    craft = Structure(hub=Hub(inertia=1.16, radius=0.06), appendages=(
        Appendage(name="a", beam=panel), Appendage(name="b", beam=panel, angle=math.pi)))
    model = build_model(craft, n_modes=3)
    with pytest.raises(InputValueError, match=r"order must be <= 8.*uncontrollable.*got 14"):
        balanced_truncation(model, 14)
    assert balanced_truncation(model, 8).error_bound < 1e-6


@pytest.mark.parametrize("kwargs, error, pattern", [
    ({"n_modes": -1}, InputValueError, r"n_modes must be an integer in \[0, 6\]; got -1"),
    ({"n_modes": 7}, InputValueError, r"n_modes must be an integer in \[0, 6\]; got 7"),
    ({"n_modes": 2.0}, InputTypeError, r"n_modes must be an integer.*float"),
    ({}, InputValueError, r"exactly one of n_modes and max_frequency"),
    ({"n_modes": 2, "max_frequency": 30.0}, InputValueError, r"exactly one of n_modes"),
    ({"max_frequency": 0.0}, InputValueError, r"max_frequency must be finite and > 0; got 0.0"),
    ({"max_frequency": -5.0}, InputValueError, r"max_frequency must be finite and > 0"),
    ({"max_frequency": math.nan}, InputValueError, r"max_frequency must be finite"),
    ({"max_frequency": math.inf}, InputValueError, r"max_frequency must be finite"),
    ({"max_frequency": "30"}, InputTypeError, r"max_frequency must be a real number"),
    ({"n_modes": 2, "keep_dc_gain": "yes"}, InputTypeError, r"keep_dc_gain must be a bool"),
    ({"n_modes": 2, "spin_rate": math.nan}, InputValueError, r"spin_rate must be finite"),
], ids=["negative", "too-many", "float", "neither", "both", "zero-frequency",
        "negative-frequency", "nan-frequency", "inf-frequency", "str-frequency", "dc-gain-str",
        "nan-spin"])
def test_modal_truncation_refuses_bad_arguments(damped_model, kwargs, error, pattern):
    with pytest.raises(error, match=pattern):
        modal_truncation(damped_model, **kwargs)


@pytest.mark.parametrize("function", [modal_truncation, balanced_truncation])
def test_the_plant_must_be_a_model_or_a_continuous_state_space(function, plant):
    argument = 2
    with pytest.raises(InputTypeError, match=r"model_or_sys must be a flexctl Model or a "
                                             r"control.StateSpace; got TransferFunction"):
        function(control.tf([1.0], [1.0, 1.0]), argument)
    with pytest.raises(InputTypeError, match=r"got ndarray"):
        function(plant.A, argument)
    with pytest.raises(InputValueError, match=r"continuous-time system; got sample time"):
        function(control.c2d(plant, 0.01), argument)
    with pytest.raises(InputValueError, match=r"spin_rate must be 0 for a StateSpace"):
        function(plant, argument, spin_rate=1.0)
    broken = control.ss(plant.A * np.nan, plant.B, plant.C, plant.D)
    with pytest.raises(InputValueError, match=r"finite A, B, C, D"):
        function(broken, argument)


ARGUMENTS = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 20, 10 ** 20),
                      st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=3))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(order=ARGUMENTS, n_modes=ARGUMENTS, max_frequency=ARGUMENTS)
def test_any_argument_gives_a_clear_error_or_an_honest_reduction(damped_model, order, n_modes,
                                                                 max_frequency):
    for call in (lambda: balanced_truncation(damped_model, order),
                 lambda: modal_truncation(damped_model, n_modes, max_frequency=max_frequency)):
        try:
            reduced = call()
        except Exception as exc:        # noqa: BLE001 - the verdict is assert_clear_error's
            assert_clear_error(exc, "order", "n_modes", "max_frequency")
        else:
            assert 0 < reduced.system.nstates <= damped_model.n_states
            assert math.isfinite(reduced.error) and reduced.error <= reduced.error_bound


def test_hinf_norm_takes_a_state_space_only(damped_model):
    with pytest.raises(InputTypeError, match=r"hinf_norm.system must be a control.StateSpace"):
        hinf_norm(damped_model)


def test_a_reduction_checks_its_fields(plant):
    with pytest.raises(InputValueError, match=r"Reduction.method must be one of"):
        Reduction(system=plant, method="guess", error=0.0, error_bound=0.0, kept=(),
                  discarded=())
    with pytest.raises(InputValueError, match=r"Reduction.error_bound must be finite and >= 0"):
        Reduction(system=plant, method="balanced truncation", error=0.0, error_bound=-1.0,
                  kept=(), discarded=())
    reduced = modal_truncation(plant, 2)
    assert "modal truncation" in repr(reduced) and "6 states kept" in repr(reduced)
    with pytest.raises(ValueError):
        reduced.discarded_poles[0] = 0.0
