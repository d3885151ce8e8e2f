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
# # 1. Modelling: the cantilever basis and its mode shapes
#
# flexctl describes the beam's deflection in the hub frame as a sum of clamped-free
# (cantilever) mode shapes, `y(x, t) = sum_i phi_i(x) q_i(t)`
# ({ref}`section 3 of the model <sec-modes>`). This notebook draws the basis, checks it against
# the closed forms, and shows what a point mass does to the lowest frequency of the
# hub-beam-mass system ({ref}`paper 000 <paper-000>`).
#
# Every number asserted below comes from a closed form or a published value, not from
# flexctl itself.

# %%
# %matplotlib inline
import dataclasses

import numpy as np
from scipy.optimize import brentq

import flexctl
from flexctl.model.modes import cantilever_roots, mode_shapes
from flexctl.app.plotting import plot_mode_shapes

# %% [markdown]
# ## The Kane beam (paper 001, section 3.1)
#
# An 8 m aluminium beam. Its clamped frequencies are `omega_i = z_i^2 sqrt(EI / (rhoA l^4))`
# with `z_i` the roots of `cos z cosh z + 1 = 0`; the flexible-spacecraft paper
# ({ref}`paper 001 <paper-001>`) quotes 2.91 and 18.24 rad/s.

# %%
kane = flexctl.load_scene("kane-spinup").system
model = flexctl.build_model(kane, n_modes=5)
beam = kane.beam
EI, rhoA, length = beam.youngs_modulus * beam.second_moment, beam.density * beam.area, beam.length

# The roots from a bracketing solver, independently of flexctl's own root finder.
roots = np.array([brentq(lambda z: np.cos(z) * np.cosh(z) + 1.0, (i - 0.5) * np.pi - 1.2,
                         (i - 0.5) * np.pi + 1.2) for i in range(1, 6)])
closed_form = roots ** 2 * np.sqrt(EI / (rhoA * length ** 4))
computed = model.natural_frequencies(0.0, hub="clamped")
print("roots z_i      :", roots.round(7))
print("closed form    :", closed_form.round(3), "rad/s")
print("flexctl (clamp):", computed.round(3), "rad/s")

# %% tags=["remove-cell"]
assert np.allclose(cantilever_roots(5), roots, rtol=1e-9)
assert np.allclose(computed, closed_form, rtol=1e-6), "clamped frequencies off the closed form"
# Paper 001 reads 2.91 and 18.24 rad/s; the theory page, section 7: 2.911, 18.24, 51.08.
assert np.allclose(computed[:3], [2.911, 18.24, 51.08], rtol=1e-3)

# %%
fig = plot_mode_shapes(model)
fig

# %% [markdown]
# ## Normalisation
#
# The shapes are normalised so that `integral_0^l phi_i phi_j dx = l delta_ij`, which makes
# every tip value `phi_i(l) = 2 (-1)^(i+1)`. flexctl evaluates them in a cancellation-free
# form, so that 40 modes stay orthonormal; the check below integrates 40 shapes on a fine
# Gauss-Legendre grid.

# %%
n_check = 40
nodes, weights = np.polynomial.legendre.leggauss(400)
panels = np.linspace(0.0, 1.0, 21)
xi = np.concatenate([0.5 * (b - a) * nodes + 0.5 * (a + b) for a, b in zip(panels, panels[1:])])
w = np.concatenate([0.5 * (b - a) * weights for a, b in zip(panels, panels[1:])])
phi = mode_shapes(n_check, xi)
gram = (phi * w) @ phi.T                     # integral over xi in [0, 1] = (1/l) integral dx
tips = mode_shapes(n_check, np.array([1.0]))[:, 0]
print(f"largest orthonormality error over {n_check} modes: "
      f"{np.abs(gram - np.eye(n_check)).max():.2e}")

# %% tags=["remove-cell"]
assert np.abs(gram - np.eye(n_check)).max() < 1e-10
assert np.allclose(tips, 2.0 * (-1.0) ** np.arange(n_check), atol=1e-9)

# %% [markdown]
# ## A point mass on the beam (paper 000)
#
# The hub-beam-mass system carries 0.085 kg at `d = 0.9 l` on a 1.8 m beam. The mass enters
# the modal mass matrix as `m phi(d) phi(d)^T`; it lowers the frequencies more the closer it
# sits to the tip, where the modes move most.

# %%
hbm = flexctl.load_scene("hub-beam-mass").system
bare = dataclasses.replace(hbm, masses=())
with_mass = flexctl.build_model(hbm, n_modes=6)
without = flexctl.build_model(bare, n_modes=6)
print("clamped, no mass  :", without.natural_frequencies()[:3].round(3), "rad/s")
print("clamped, 0.085 kg :", with_mass.natural_frequencies()[:3].round(3), "rad/s")
print("hub free, 0.085 kg:", with_mass.natural_frequencies(hub="free")[:3].round(3), "rad/s")

# %% tags=["remove-cell"]
assert with_mass.natural_frequencies()[0] < without.natural_frequencies()[0]

# %%
fig = plot_mode_shapes(with_mass, n_shapes=3)
fig

# %% [markdown]
# ## Convergence with a tip mass
#
# The Ritz form stays valid with the mass at the very tip (where the papers stop), it only
# converges more slowly there, because every cantilever shape has zero shear at the tip and
# the true shape does not. For a tip mass equal to the beam mass (`R_M = 1`) the exact first
# clamped frequency is the root of
# `1 + cos z cosh z + R_M z (cos z sinh z - sin z cosh z) = 0`.

# %%
ratio = 1.0
z1 = brentq(lambda z: 1 + np.cos(z) * np.cosh(z)
            + ratio * z * (np.cos(z) * np.sinh(z) - np.sin(z) * np.cosh(z)), 0.5, 1.8)
exact = z1 ** 2 * np.sqrt(hbm.beam.youngs_modulus * hbm.beam.second_moment
                          / (hbm.beam.density * hbm.beam.area * hbm.beam.length ** 4))
tip_mass = dataclasses.replace(hbm, masses=(flexctl.PointMass(
    mass=ratio * hbm.beam.density * hbm.beam.area * hbm.beam.length,
    position=hbm.beam.length),))
errors = {}
for n in (2, 4, 8, 16):
    w1 = flexctl.build_model(tip_mass, n_modes=n).natural_frequencies()[0]
    errors[n] = (w1 - exact) / exact
    print(f"{n:2d} modes: first clamped frequency {w1:.6f} rad/s, error {errors[n]:+.2e}")
print(f"exact: {exact:.6f} rad/s (the theory page, section 7: 1.7325)")

# %% tags=["remove-cell"]
assert abs(exact - 1.7325) < 5e-4
# Rayleigh-Ritz approaches from above, and the error falls as modes are added.
assert all(e > 0 for e in errors.values())
assert errors[16] < errors[8] < errors[4] < errors[2] and errors[16] < 1e-4
