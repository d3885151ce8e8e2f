"""A variant is a small object that says which terms it contributes; the models built on it
carry those terms and only those."""

import json
import pickle

import numpy as np
import pytest

from flexctl import build_model
from flexctl.model import VARIANTS, Variant
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.exact import EXACT_MAX_MODES
from flexctl.model.variant import MAX_MODES

SPIN = 2.0        # rad/s, below the hub-beam-mass beam's first clamped frequency


@pytest.mark.parametrize("name", VARIANTS)
def test_a_variant_is_its_name(name):
    variant = Variant(name)
    assert variant == name and str(variant) == name and hash(variant) == hash(name)
    assert json.loads(json.dumps({"variant": variant})) == {"variant": name}
    again = pickle.loads(pickle.dumps(variant))
    assert isinstance(again, Variant) and again == name
    assert Variant(variant) is variant


@pytest.mark.parametrize(("bad", "error"), [("second_order", InputValueError),
                                            ("", InputValueError), (3, InputTypeError),
                                            (None, InputTypeError)])
def test_an_unknown_variant_is_refused_by_name(bad, error):
    with pytest.raises(error, match="variant must be one of first_order"):
        Variant(bad)


@pytest.mark.parametrize("name", VARIANTS)
def test_the_spin_takes_the_variants_matrix_from_the_stiffness(hub_beam_mass_system, name):
    model = build_model(hub_beam_mass_system, n_modes=3, variant=name)
    assert isinstance(model.variant, Variant)
    mat = model.matrices
    # dynamic stiffening: the geometric stiffness K_g offsets the spin softening M_ff
    softening = mat.M_ff - mat.K_g if model.variant.dynamic_stiffening else mat.M_ff
    np.testing.assert_allclose(model.stiffness_matrix(SPIN), mat.K_ff - SPIN ** 2 * softening,
                               rtol=1e-12, atol=1e-12 * np.max(np.abs(mat.K_ff)))
    assert model.variant.dynamic_stiffening == (name != "zero_order")


@pytest.mark.parametrize("name", VARIANTS)
def test_only_the_quadratic_and_exact_variants_change_the_hub_inertia(hub_beam_mass_system, name):
    model = build_model(hub_beam_mass_system, n_modes=3, variant=name)
    rest, bent = model.rest_state(), model.rest_state()
    bent[model.layout.q] = 0.1
    change = float(model.effective_hub_inertia(bent) - model.effective_hub_inertia(rest))
    varies = model.variant.quadratic_inertia or model.variant.exact
    assert (abs(change) > 1e-6 * float(model.effective_hub_inertia(rest))) == varies
    assert model.variant.max_modes == (EXACT_MAX_MODES if name == "exact" else MAX_MODES)


@pytest.mark.parametrize("bad", ["abc", [1.0, 2.0], np.full(6, np.nan), None],
                         ids=["str", "short", "nan", "none"])
def test_the_reach_check_refuses_what_is_not_a_state(hub_beam_mass_system, bad):
    from flexctl.model.errors import InputError
    from flexctl.model.variant import check_reach

    model = build_model(hub_beam_mass_system, n_modes=2)
    with pytest.raises(InputError, match="x0"):
        check_reach(model, bad)
    check_reach(model, model.rest_state())
