"""The spatial model against an independent computation: the rigid-element chain of
``tests/model/spatial_reference.py`` (a discrete geometrically exact rod, its equations derived
by CasADi from the Lagrangian), extrapolated in its element count.

Two rods on a hub with products of inertia, one with a tip mass and one whose section is tilted
(its normal neither along nor across the hub's axes), under a sine torque about all three axes.
Every tip component whose peak is not negligible is compared relative to its own peak. (The
spinning case is not run here: the chain, integrated implicitly, takes minutes per run there.)

Measured on the 3 s, 20 and 40 element form of this case (at rest): the modal model on 3, 4 and
5 modes per field within 6.8e-4, 2.7e-4 and 1.4e-4 of each component's peak of the
extrapolated chain, whose own 40-element result is 0.06 to 0.17 % from it.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from spatial_reference import chain_response  # noqa: E402

from flexctl.model.parameters import PointMass  # noqa: E402
from flexctl.model.spatial_structure import (SpatialAppendage, SpatialHub,  # noqa: E402
                                             SpatialStructure)
from flexctl.sim.spatial_run import simulate_spatial  # noqa: E402

#: The modal model (3 modes per field) within this of the extrapolated chain, relative to each
#: tip component's peak. Measured: 5.3e-4 at most (1.1e-4 to 5.3e-4 over the six components),
#: where the 20-element chain alone is 1.5e-3 to 5.2e-3 from the extrapolation.
AGREEMENT = 2e-3
#: Components whose peak is below this fraction of their tip's largest are not compared
#: (a foreshortening of microns under a bending of centimetres).
NEGLIGIBLE = 1e-3

RHO, AREA, E, G = 2766.0, 2.5e-4, 6.9e10, 2.6e10
I_N, I_L, J = 1.3021e-10, 5.2e-9, 5e-10
INERTIA = np.array([[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]])
RODS = [("a", (0.06, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), [(0.085, 1.62)]),
        ("b", (0.0, 0.06, 0.0), (0.0, 1.0, 0.0), (0.6, 0.0, 0.8), [])]
PEAK = np.array([0.4, -0.3, 0.8])
DURATION = 1.0


def torque(t):
    return PEAK * np.sin(2 * np.pi * t / DURATION) if t <= DURATION else np.zeros(3)


class _Sine:
    """The same torque with its breakpoint and segment form for the modal run."""

    breakpoints = np.array([DURATION])

    def __call__(self, t):
        return torque(t)

    def segment_form(self, a, b):
        inside = b <= DURATION + 1e-12
        return np.concatenate([np.zeros(6), PEAK if inside else np.zeros(3),
                               [2 * np.pi / DURATION, a]])


def _structure():
    return SpatialStructure(hub=SpatialHub(inertia=INERTIA, radius=0.06), appendages=tuple(
        SpatialAppendage(name=name, direction=d, normal=n, root=root, length=1.8, density=RHO,
                         area=AREA, youngs_modulus=E, second_moment=I_N,
                         second_moment_lateral=I_L, shear_modulus=G, torsion_constant=J,
                         masses=tuple(PointMass(mass=m, position=p) for m, p in masses))
        for name, root, d, n, masses in RODS))


def _chain_rods():
    return [{"name": name, "root": root, "direction": d, "normal": n, "length": 1.8,
             "rhoA": RHO * AREA, "EI_n": E * I_N, "EI_l": E * I_L, "GJ": G * J,
             "rho_Ip": RHO * (I_N + I_L), "masses": masses}
            for name, root, d, n, masses in RODS]


@pytest.mark.slow
def test_tips_agree_with_an_independent_rigid_element_chain():
    spin = (0.0, 0.0, 0.0)
    t_final = 1.5
    times = np.linspace(0.0, t_final, 151)
    coarse, fine = (chain_response(INERTIA, _chain_rods(), torque, t_final, times,
                                   angular_velocity=spin, n_elements=n)["tips"]
                    for n in (10, 20))
    result = simulate_spatial(_structure(), t_final, _Sine(), n_modes=3,
                              angular_velocity=spin, output_step=0.01, rtol=1e-9,
                              check_accuracy=False)
    assert result.status == "ok", result.message
    np.testing.assert_allclose(result.t, times, atol=1e-12)
    for name in fine:
        reference = fine[name] + (fine[name] - coarse[name]) / 3       # h^2 extrapolation
        peaks = np.max(np.abs(reference), axis=1)
        compared = peaks > NEGLIGIBLE * np.max(peaks)
        error = np.max(np.abs(result.tips[name] - reference), axis=1) / peaks
        assert np.all(error[compared] < AGREEMENT), (name, error, peaks)
