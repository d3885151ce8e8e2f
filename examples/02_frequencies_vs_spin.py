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
# # 2. Natural frequencies against spin rate: stiffening against softening
#
# A spinning beam feels two centrifugal effects (sections {ref}`2 <sec-continuous>` and
# {ref}`4 <variants>` of the model):
#
# - **softening**: the term `-theta_t^2 y` of the transverse acceleration, `-Omega^2 M_ff`
#   in the stiffness;
# - **stiffening**: the centrifugal tension acting on the bending slope, `+Omega^2 K_g`.
#
# `first_order` (the papers' model) and `consistent` keep both, `K_ff - Omega^2 (M_ff - K_g)`;
# `zero_order` drops the stiffening, `K_ff - Omega^2 M_ff`, and loses all stiffness once the
# spin passes the first clamped frequency. The plot below is the whole story of why dynamic
# stiffening matters.

# %%
# %matplotlib inline
import numpy as np

import flexctl
from flexctl.app.plotting import plot_frequencies_vs_spin

kane = flexctl.load_scene("kane-spinup").system
models = {v: flexctl.build_model(kane, n_modes=4, variant=v) for v in flexctl.VARIANTS}
omega_1 = models["first_order"].first_clamped_frequency
print(f"first clamped frequency at rest: {omega_1:.4f} rad/s")

# %%
spin = np.linspace(0.0, 6.0, 121)
fig = plot_frequencies_vs_spin(models, spin, n_frequencies=2)
fig

# %% [markdown]
# ## Southwell coefficients
#
# On a beam with hub radius 0, each clamped mode obeys (to first order in the mode coupling)
# `omega_i(Omega)^2 = omega_i^2 + (S_i - 1) Omega^2` with the Southwell coefficient
# `S_i = K_g[i, i] / M_ff[i, i]`: 1.1933 and 6.478 for the first two cantilever modes
# ({ref}`section 7 of the model <published-numbers>`). `S_1 > 1`, so the first_order
# frequency rises with spin; without `K_g` it is `omega_1^2 - Omega^2`, which reaches zero at
# `Omega = omega_1`.

# %%
mat = models["first_order"].matrices
southwell = np.diag(mat.K_g)[:2] / np.diag(mat.M_ff)[:2]
print("Southwell coefficients:", southwell.round(4))

rows = []
for w in (0.0, 1.0, 2.0, 2.5, 4.0, 6.0):
    f = {v: m.natural_frequencies(w)[0] for v, m in models.items()}
    rows.append((w, f["first_order"], f["zero_order"], f["consistent"]))
    print(f"Omega = {w:3.1f} rad/s: first_order {f['first_order']:7.4f}, "
          f"zero_order {f['zero_order']:8.4f}, consistent {f['consistent']:7.4f} rad/s, "
          f"Southwell estimate {np.sqrt(omega_1 ** 2 + (southwell[0] - 1) * w ** 2):7.4f}")

# %% tags=["remove-cell"]
assert np.allclose(southwell, [1.1933, 6.478], rtol=2e-4)
# Stiffening: first_order rises as sqrt(omega_1^2 + (S_1 - 1) Omega^2) within 1 % up to
# Omega of about omega_1 (beyond, K_g couples the modes and the rise is slower), and
# consistent shares its beam stiffness exactly.
for w, first, zero, consistent in rows:
    if w <= omega_1:
        assert abs(first - np.sqrt(omega_1 ** 2 + (southwell[0] - 1) * w ** 2)) < 0.01 * first
    assert np.isclose(consistent, first, rtol=1e-12)
    if w < omega_1:
        # Softening: zero_order falls as sqrt(omega_1^2 - Omega^2) (M_ff is diagonal here).
        assert np.isclose(zero, np.sqrt(omega_1 ** 2 - w ** 2), rtol=1e-6)
    else:
        # Above omega_1 the zero_order mode has no stiffness: a negative value is its growth
        # rate, sqrt(Omega^2 - omega_1^2).
        assert zero < 0 and np.isclose(-zero, np.sqrt(w ** 2 - omega_1 ** 2), rtol=1e-6)
first_order = [r[1] for r in rows]
assert np.all(np.diff(first_order) > 0)               # first_order stiffens with spin

# %% [markdown]
# ## With the hub free
#
# The frequencies a controller sees (hub free to rotate, at rest) are higher than the clamped
# ones because the hub counter-rotates; for the heavy 300 kg m^2 hub of the Kane case the
# difference is small.

# %%
free = models["first_order"].natural_frequencies(0.0, hub="free")
clamped = models["first_order"].natural_frequencies(0.0, hub="clamped")
print("hub free   :", free.round(4), "rad/s")
print("hub clamped:", clamped.round(4), "rad/s")

# %% tags=["remove-cell"]
assert np.all(free >= clamped)
