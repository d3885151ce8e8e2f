"""Which modes of a spatial structure each torque axis moves
(flexctl.model.spatial_visibility.spatial_modal_visibility)."""

import numpy as np
import pytest

import flexctl
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure
from flexctl.model.errors import InputError
from flexctl.model.parameters import PointMass
from flexctl.model.spatial_visibility import spatial_modal_visibility
from flexctl.model.visibility import VISIBILITY_TOLERANCE


def _wing(name, direction, normal=(0.0, 0.0, 1.0), masses=()):
    return SpatialAppendage(name=name, direction=direction, normal=normal, length=1.8,
                            density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=1.3e-10, second_moment_lateral=5.2e-8,
                            shear_modulus=2.6e10, torsion_constant=5e-10, masses=masses)


def _pair(support="pinned"):
    return SpatialStructure(hub=SpatialHub(inertia=np.diag([1.0, 1.2, 1.4]), radius=0.06,
                                           support=support, mass=3.0),
                            appendages=(_wing("a", (1.0, 0.0, 0.0)),
                                        _wing("b", (-1.0, 0.0, 0.0))))


def _nobody(report):
    return set.intersection(*(set(report.uncontrollable(a)) for a in ("tx", "ty", "tz")))


@pytest.mark.parametrize("support, rigid", [("pinned", 3), ("free", 6)])
def test_equal_arrays_bending_together_are_moved_by_no_torque(support, rigid):
    report = spatial_modal_visibility(_pair(support), n_modes=2)
    assert np.count_nonzero(report.frequencies == 0.0) == rigid
    flexible = [j for j in _nobody(report) if report.frequencies[j] > 0.0]
    assert flexible
    a = [k for k, name in enumerate(report.coordinates) if name.startswith("a.")]
    b = [k for k, name in enumerate(report.coordinates) if name.startswith("b.")]
    for j in flexible:
        shape = report.shapes[:, j]
        # the arrays move alike (each in its own frame), the hub does not turn (a free hub
        # translates with them)
        np.testing.assert_allclose(np.abs(shape[a]), np.abs(shape[b]),
                                   atol=1e-9 * np.max(np.abs(shape)))
        assert np.max(np.abs(shape[:3])) <= 1e-9 * np.max(np.abs(shape))    # no rotation
    # the first out-of-plane pair: one moved by ty (the arrays bending against each other),
    # the other by no torque
    out_of_plane = [j for j in range(len(report.frequencies)) if report.frequencies[j] > 0.0
                    and report.output_share[report.outputs.index("a.tip_dz"), j] > 1e-3]
    first, second = out_of_plane[:2]
    assert first in flexible and report.input_share[second, 1] > 0.1


def test_each_input_shares_sum_to_one_and_shapes_are_mass_normalised():
    craft = SpatialStructure(
        hub=SpatialHub(inertia=[[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]],
                       radius=0.06),
        appendages=(_wing("a", (1.0, 0.0, 0.0), masses=(PointMass(mass=0.1, position=1.7),)),
                    _wing("b", (0.0, 1.0, 0.0), normal=(0.6, 0.0, 0.8))))
    report = flexctl.spatial_modal_visibility(craft, n_modes=3)
    np.testing.assert_allclose(np.sum(report.input_share ** 2, axis=0), 1.0, atol=1e-9)
    # products of inertia and a tilted section: every flexible mode is moved by some axis
    assert not [j for j in _nobody(report) if report.frequencies[j] > 0.0]
    assert report.inputs == ("tx", "ty", "tz")
    assert report.coordinates[:3] == ("ex", "ey", "ez") and len(report.coordinates) == 3 + 18


def test_the_flexible_frequencies_equal_the_linear_plant_poles():
    craft = _pair()
    report = spatial_modal_visibility(craft, n_modes=2)
    poles = np.linalg.eigvals(flexctl.linearize_spatial(craft, n_modes=2).A)
    plant = np.sort(np.abs(poles.imag[poles.imag > 1e-6]))
    np.testing.assert_allclose(report.frequencies[report.frequencies > 0.0], plant,
                               rtol=1e-9)


@pytest.mark.parametrize("bad, match", [({"structure": "craft"}, "structure"),
                                        ({"n_modes": 0}, "n_modes"),
                                        ({"n_modes": 2.5}, "n_modes")])
def test_bad_arguments_are_refused_by_name(bad, match):
    arguments = {"structure": _pair(), "n_modes": 2, **bad}
    with pytest.raises(InputError, match=match):
        spatial_modal_visibility(**arguments)
