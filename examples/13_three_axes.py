# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3 (ipykernel)
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 13. Three axes: a spacecraft that turns about any axis
#
# A spacecraft slews about any axis, and its solar arrays bend in two planes and twist. This
# notebook builds a hub with two arrays in three dimensions (`SpatialStructure`,
# `docs/guide/spatial.md`) and shows
#
# 1. which modes each torque axis moves (`spatial_modal_visibility`), and that they are the
#    linear plant's (`linearize_spatial`);
# 2. a torque about a tilted axis on the exact spatial model, against the planar model of the
#    same structure turning about z (`SpatialStructure.to_planar`): the planar model sees only
#    the stiff in-plane bending, the spatial one the soft out-of-plane bending too;
# 3. the run's energy and angular momentum, which the torque changes and nothing else.

# %%
import matplotlib.pyplot as plt
import numpy as np

import flexctl
from flexctl import (SpatialAppendage, SpatialHub, SpatialStructure, VectorTorque,
                     linearize_spatial, simulate_spatial, spatial_modal_visibility)
from flexctl.sim.inputs import SampledTorque


def array(name, direction):
    """A solar array along ``direction``, flexible along z (its normal), stiff in the plane."""
    return SpatialAppendage(name=name, direction=direction, normal=(0.0, 0.0, 1.0), length=1.8,
                            density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
                            shear_modulus=2.6e10, torsion_constant=1.9531e-9)


craft = SpatialStructure(hub=SpatialHub(inertia=[[1.30, 0.05, 0.0], [0.05, 1.16, 0.0],
                                                 [0.0, 0.0, 1.45]], radius=0.06),
                         appendages=(array("wing_a", (0.0, 1.0, 0.0)),
                                     array("wing_b", (0.0, -1.0, 0.0))))
N_MODES = 2

# %% [markdown]
# ## 1. Which modes each torque axis moves
#
# The modes at rest: three rigid rotations, then each array's bending along its normal (z),
# in the plane and its twist. The two arrays bending together out of the plane leave the hub
# unforced: no torque axis moves that mode.

# %%
report = spatial_modal_visibility(craft, n_modes=N_MODES)
for j, frequency in enumerate(report.frequencies):
    shares = ", ".join(f"{axis} {share:.2f}" for axis, share in zip(report.inputs,
                                                                     report.input_share[j]))
    print(f"mode {j:2d} {frequency:9.3f} rad/s   {shares}")
nobody = set.intersection(*(set(report.uncontrollable(axis)) for axis in report.inputs))
flexible_nobody = [j for j in nobody if report.frequencies[j] > 0.0]
print("moved by no torque axis:", [f"{report.frequencies[j]:.3f} rad/s" for j in flexible_nobody])

# %% tags=["remove-cell"]
assert flexible_nobody, "some flexible mode should be moved by no torque axis"

# %%
plant = linearize_spatial(craft, n_modes=N_MODES)
plant.input_labels, plant.output_labels[:6]

# %% tags=["remove-cell"]
poles = np.linalg.eigvals(plant.A)
plant_frequencies = np.sort(np.abs(poles.imag[poles.imag > 1e-6]))
assert np.allclose(plant_frequencies, report.frequencies[report.frequencies > 0.0], rtol=1e-9)

# %% [markdown]
# ## 2. A torque about a tilted axis, in three dimensions and in the plane
#
# A bang-bang torque about (0.6, 0, 0.8): the planar model turns about z under its z part
# only, and its arrays bend in the x-y plane, where they are 100 times stiffer.

# %%
times = [0.0, 0.5, 1.0, 1.5]
values = [[0.3, 0.0, 0.4], [-0.3, 0.0, -0.4], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
spatial = simulate_spatial(craft, 1.5, VectorTorque(times, values, "hold"), n_modes=N_MODES,
                           output_step=0.005)
planar_model = flexctl.build_model(craft.to_planar(), N_MODES, "exact")
planar = flexctl.simulate(planar_model, 1.5, SampledTorque(times, [v[2] for v in values],
                                                           interpolation="hold"),
                          output_step=0.005, check_validity=False)
print(spatial.status, f"estimated integration error {spatial.integration_error:.2g}")

fig, ax = plt.subplots(figsize=(8, 3.5))
for name in craft.names:
    tip = spatial.tips[name]
    ax.plot(spatial.t, 1e3 * tip[2], label=f"{name}: out of plane, spatial")
    ax.plot(planar.t, 1e3 * planar.tip_deflections[name], "--", label=f"{name}: in plane, planar")
ax.set_xlabel("t (s)")
ax.set_ylabel("tip (mm)")
ax.legend(fontsize=8)
plt.show()

out_of_plane = max(np.max(np.abs(spatial.tips[n][2])) for n in craft.names)
in_plane = max(np.max(np.abs(planar.tip_deflections[n])) for n in craft.names)
print(f"peak out of plane {1e3 * out_of_plane:.3f} mm, planar model's in plane "
      f"{1e3 * in_plane:.4f} mm")

# %% tags=["remove-cell"]
assert spatial.ok and out_of_plane > 10 * in_plane

# %% [markdown]
# The in-plane part of the spatial run follows the planar model closely; the difference is the
# coupling of the tilted torque's roll part through the product of inertia.

# %%
for name, appendage in zip(craft.names, craft.appendages):
    across = np.cross([0.0, 0.0, 1.0], appendage.direction)
    flat = planar.tip_deflections[name]
    gap = np.max(np.abs(across @ spatial.tips[name] - flat)) / np.max(np.abs(flat))
    print(f"{name}: in-plane tips differ by {gap:.2%} of the planar peak")

# %% tags=["remove-cell"]
for name, appendage in zip(craft.names, craft.appendages):
    across = np.cross([0.0, 0.0, 1.0], appendage.direction)
    flat = planar.tip_deflections[name]
    gap = np.max(np.abs(across @ spatial.tips[name] - flat)) / np.max(np.abs(flat))
    assert gap < 0.1

# %% [markdown]
# ## 3. Energy and angular momentum
#
# After the torque ends (t = 1 s) nothing acts on the structure: its energy and its angular
# momentum vector (in the inertial frame) stay as they were.

# %%
after = spatial.t >= 1.0
energy = spatial.energy()[after]
momentum = spatial.momentum()[0][:, after]
drift_energy = np.ptp(energy) / np.max(energy)
drift_momentum = np.max(np.ptp(momentum, axis=1)) / np.max(np.linalg.norm(momentum, axis=0))
print(f"energy kept to {drift_energy:.1e}, angular momentum to {drift_momentum:.1e}")

# %% tags=["remove-cell"]
assert drift_energy < 1e-6 and drift_momentum < 1e-6
