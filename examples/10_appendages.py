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
# # 10. Several appendages on a free-floating hub
#
# A spacecraft carries two solar arrays on opposite sides of its body, or a single wing, and
# its body floats free in orbit. This notebook builds such structures with `Structure` and
# `Appendage` (`docs/theory/free_hub.md` derives their equations), and shows
#
# 1. what the second array and the free hub change against the papers' one beam on a pinned hub;
# 2. the modes in which two identical arrays bend against each other, which the hub torque can
#    neither excite nor see (`linearize().modal_visibility`);
# 3. that the free hub's centre of mass stays at rest and the angular momentum equals the torque
#    impulse;
# 4. an LQR slew designed on the modes the torque moves, run on the exact plant.

# %%
import math

import matplotlib.pyplot as plt
import numpy as np

from flexctl import (Appendage, Beam, Hub, HubBeam, PointMass, SineTorque, Structure,
                     build_model, simulate)

panel = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
             youngs_modulus=6.9e10)
fitting = (PointMass(mass=0.085, position=1.62),)
free_hub = Hub(inertia=1.16, radius=0.06, mass=3.0, support="free")
pinned_hub = Hub(inertia=1.16, radius=0.06)

systems = {
    "one beam, pinned": HubBeam(hub=pinned_hub, beam=panel, masses=fitting),
    "two arrays, pinned": Structure(hub=pinned_hub, appendages=(
        Appendage(name="wing_a", beam=panel, masses=fitting),
        Appendage(name="wing_b", beam=panel, masses=fitting, angle=math.pi))),
    "two arrays, free": Structure(hub=free_hub, appendages=(
        Appendage(name="wing_a", beam=panel, masses=fitting),
        Appendage(name="wing_b", beam=panel, masses=fitting, angle=math.pi))),
    "single wing, free": Structure(hub=free_hub, appendages=(
        Appendage(name="wing_a", beam=panel, masses=fitting),)),
}
models = {label: build_model(s, n_modes=3, variant="exact") for label, s in systems.items()}
models["two arrays, free"].state_names

# %% [markdown]
# ## 1. Frequencies and the inertia the torque turns
#
# The hub-free frequencies (hub free to rotate, and to translate when it floats) and the rigid
# inertia about the axis the structure turns on: the hub centre when pinned, the centre of
# mass when free.

# %%
for label, model in models.items():
    print(f"{label:20s} rigid inertia {model.rigid_inertia:6.3f} kg m^2, hub-free "
          f"frequencies {np.round(model.natural_frequencies(hub='free')[:4], 3)} rad/s")

# %% [markdown]
# ## 2. Modes the torque cannot move
#
# Two identical arrays have a mode in which they bend against each other. On a pinned hub it
# keeps the clamped frequency; on a free hub it also pushes the hub sideways. Either way the
# hub torque does not move it, and the hub angle does not see it; each array's own root moment
# does.

# %%
for label in ("two arrays, pinned", "two arrays, free"):
    plant = models[label].linearize()
    print(label)
    print(plant.modal_visibility.describe("torque"))
    print()

# %% tags=["remove-cell"]
hidden = models["two arrays, pinned"].modal_visibility()
assert hidden.uncontrollable("torque") and all(
    j in hidden.unobservable("theta") for j in hidden.uncontrollable("torque"))

# %% [markdown]
# ## 3. One period of torque on each structure
#
# A 1 N m sine torque for 2 s. The second array halves what each tip bends; the single wing
# drags the free hub sideways as it bends; the symmetric pair leaves the hub centre in place.

# %%
push = SineTorque(peak_torque=1.0, duration=2.0)
results = {label: simulate(model, 5.0, torque=push, output_step=0.01)
           for label, model in models.items()}
fig, (ax_tip, ax_hub) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
for label, result in results.items():
    for name, tip in result.tip_deflections.items():
        ax_tip.plot(result.t, tip, label=f"{label} {name}".strip())
    if "hub_x" in result.outputs:
        out = result.outputs
        ax_hub.plot(result.t, 1e3 * np.hypot(out["hub_x"], out["hub_y"]), label=label)
ax_tip.set_ylabel("tip deflection (m)")
ax_hub.set_ylabel("hub centre travel (mm)")
ax_hub.set_xlabel("time (s)")
ax_tip.legend(fontsize="small")
ax_hub.legend(fontsize="small")
ax_tip.grid(True, alpha=0.3)
ax_hub.grid(True, alpha=0.3)

# %% [markdown]
# The free hub's centre of mass stays where it started, and the angular momentum about the
# origin ends equal to the torque impulse (zero for a full sine period).

# %%
for label in ("two arrays, free", "single wing, free"):
    model, result = models[label], results[label]
    center = model.center_of_mass(result.states)
    drift = np.max(np.abs(center - center[:, :1]))
    momentum = model.angular_momentum(result.states)
    print(f"{label}: centre of mass drift {drift:.2e} m, final angular momentum "
          f"{momentum[-1]:.2e} kg m^2/s")

# %% tags=["remove-cell"]
for label in ("two arrays, free", "single wing, free"):
    model, result = models[label], results[label]
    center = model.center_of_mass(result.states)
    drift = np.max(np.abs(center - center[:, :1]))
    momentum = model.angular_momentum(result.states)
    assert drift < 1e-9 and abs(momentum[-1]) < 1e-6

# %% [markdown]
# ## 4. An LQR slew of the two-array spacecraft
#
# The design model is first_order with 2 modes per array; the LQR acts on the modes the torque
# moves (the antisymmetric ones are left at their open-loop poles), and runs on the exact
# 3-mode plant.

# %%
from controllers.feedback.lqr import LQRWeights, design_lqr  # noqa: E402
from controllers.slew.reference import SlewProfile  # noqa: E402

craft = systems["two arrays, free"]
design = build_model(craft, n_modes=2)
plant = models["two arrays, free"]
slew = SlewProfile(slew_angle=math.radians(30.0), duration=4.0)
lqr = design_lqr(design, LQRWeights(hub_angle=0.01, torque=2.0, tip_deflection=0.01),
                 reference=slew)
run = simulate(plant, 8.0, controller=lqr, output_step=0.01)
after = run.t > slew.duration
print(f"{run.status}: hub angle {math.degrees(run.theta[-1]):.3f} deg, residual tips "
      + ", ".join(f"{name} {np.max(np.abs(tip[after])) * 1e3:.2f} mm"
                  for name, tip in run.tip_deflections.items()))

# %% tags=["remove-cell"]
assert run.ok and abs(run.theta[-1] - slew.slew_angle) < 1e-3
