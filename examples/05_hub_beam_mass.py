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
# # 5. A point mass on the beam (paper 000, Figs. 5 to 8)
#
# The hub-beam-mass paper ({ref}`paper 000 <paper-000>`), section 3.2: a hub
# (`J_h = 1.16 kg m^2, b = 0.06 m`) carries a 1.8 m beam with a point mass `m_t = 0.085 kg` at
# `d = 0.9 l`, driven by one period of sine torque, `T_h = 2 sin(pi t)` N m for `t <= 2 s`.
# The paper finds that the mass *softens* the beam:
#
# - Fig. 5: the mass at `d = 0.8 l` gives larger peak and residual amplitudes than at `0.2 l`;
# - Fig. 6: against the position ratio `R_d = d/l`, the effect is negligible for
#   `R_d <= 0.3` and grows quickly above ("approximately exponential");
# - Fig. 7: with the mass the peak tip amplitude is 0.263 m and the residual 0.141 m;
#   without it 0.223 m and 0.081 m;
# - Fig. 8: both amplitudes grow with the mass ratio `R_M = m_t / (rhoA l)` in `[0, 1]`
#   ("approximately logarithmic").
#
# The *peak* amplitude is the largest `|tip deflection|` while the torque acts, the
# *residual* the largest after it (`flexctl.app.sweep.response_amplitudes`).

# %%
# %matplotlib inline
import dataclasses
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from matplotlib.figure import Figure

import flexctl
from flexctl.app.plotting import plot_sweep, plot_tip_deflections
from flexctl.app.sweep import PointMassAmplitudes, response_amplitudes, sweep

scene = flexctl.load_scene("hub-beam-mass")
system, torque = scene.system, scene.maneuver
beam = system.beam
print(scene.description)
print(f"beam mass rhoA l = {beam.density * beam.area * beam.length:.4f} kg, "
      f"so R_M = {0.085 / (beam.density * beam.area * beam.length):.4f} for 0.085 kg")


def respond(masses):
    """Run the paper's torque case with the given point masses."""
    model = flexctl.build_model(dataclasses.replace(system, masses=masses), n_modes=4)
    return flexctl.simulate(model, 20.0, torque=torque)


def mass_at(ratio, mass=0.085):
    return (flexctl.PointMass(mass=mass, position=ratio * beam.length),)


TOLERANCE = 0.03        # the papers' figures were read off plots: a few percent

# %% [markdown]
# ## Fig. 7: with and without the mass

# %%
with_mass, without_mass = respond(system.masses), respond(())
fig7 = plot_tip_deflections({"m_t = 0.085 kg at 0.9 l": with_mass, "m_t = 0": without_mass},
                            title="Paper 000 Fig. 7: tip deflection with and without the mass")
amplitudes = {"with mass": response_amplitudes(with_mass, torque.duration),
              "without mass": response_amplitudes(without_mass, torque.duration)}
published = {"with mass": (0.263, 0.141), "without mass": (0.223, 0.081)}
for case, (peak, residual) in amplitudes.items():
    print(f"{case:13s}: peak {peak:.4f} m (paper {published[case][0]}), residual "
          f"{residual:.4f} m (paper {published[case][1]})")
fig7

# %% tags=["remove-cell"]
for case, (peak, residual) in amplitudes.items():
    paper_peak, paper_residual = published[case]
    assert abs(peak - paper_peak) < TOLERANCE * paper_peak, (case, peak)
    assert abs(residual - paper_residual) < TOLERANCE * paper_residual, (case, residual)

# %% [markdown]
# ## Fig. 5: the mass near the root against near the tip

# %%
near_root, near_tip = respond(mass_at(0.2)), respond(mass_at(0.8))
fig5 = plot_tip_deflections({"d = 0.2 l": near_root, "d = 0.8 l": near_tip},
                            title="Paper 000 Fig. 5: the mass at d = 0.2 l and d = 0.8 l")
root_amp = response_amplitudes(near_root, torque.duration)
tip_amp = response_amplitudes(near_tip, torque.duration)
print(f"d = 0.2 l: peak {root_amp[0]:.4f} m, residual {root_amp[1]:.4f} m")
print(f"d = 0.8 l: peak {tip_amp[0]:.4f} m, residual {tip_amp[1]:.4f} m")
fig5

# %% tags=["remove-cell"]
assert tip_amp[0] > 1.05 * root_amp[0] and tip_amp[1] > 1.3 * root_amp[1]

# %% [markdown]
# ## Figs. 6 and 8: sweeps of the position ratio and the mass ratio
#
# `PointMassAmplitudes` is a picklable sweep task: called with `mass_position_ratio` and/or
# `mass_ratio`, it puts one mass on the beam (the other ratio keeps the paper's value) and
# returns the peak and residual amplitudes. `flexctl.app.sweep` runs it on any
# `concurrent.futures`-style executor; here a pool of two processes. On a cluster, pass the
# executor of a Dask client instead:
#
# ```python
# from distributed import Client
# client = Client("tcp://scheduler:8786")
# table = sweep(task, grid, executor=client.get_executor())
# ```

# %%
task = PointMassAmplitudes.from_scene("hub-beam-mass")
ratios = np.round(np.linspace(0.0, 1.0, 11), 2)
default_mass_ratio = task.default_ratios[1]             # 0.085 kg on this beam
with ProcessPoolExecutor(max_workers=2) as pool:
    by_position = sweep(task, {"mass_position_ratio": ratios}, executor=pool,
                        description="d/l sweep")
    by_mass = sweep(task, {"mass_ratio": ratios}, executor=pool, description="R_M sweep")
print(by_position)
for row in by_position:
    print(f"R_d = {row['mass_position_ratio']:.1f}: peak {row['peak_amplitude']:.4f} m, "
          f"residual {row['residual_amplitude']:.4f} m, {row['status']}")

# %%
fig = Figure(figsize=(11.0, 4.5), layout="constrained")
ax6, ax8 = fig.subplots(1, 2)
labels = {"peak_amplitude": "peak amplitude", "residual_amplitude": "residual amplitude"}
plot_sweep(by_position, "mass_position_ratio", ["peak_amplitude", "residual_amplitude"],
           ax=ax6, labels=labels, xlabel="position ratio R_d = d/l", ylabel="tip amplitude (m)",
           title="Fig. 6: m_t = 0.085 kg",
           reference={"paper 000, Fig. 7": [(0.9, 0.263), (0.9, 0.141)]})
ax6.axvspan(0.0, 0.3, color="tab:gray", alpha=0.1)
plot_sweep(by_mass, "mass_ratio", ["peak_amplitude", "residual_amplitude"], ax=ax8,
           labels=labels, xlabel="mass ratio R_M = m_t/(rhoA l)", ylabel="tip amplitude (m)",
           title="Fig. 8: d = 0.9 l",
           reference={"paper 000, Fig. 7": [(default_mass_ratio, 0.263),
                                            (default_mass_ratio, 0.141)]})
fig

# %% [markdown]
# ## The trends, asserted

# %%
position = by_position.column("mass_position_ratio")
peak_d, residual_d = by_position.column("peak_amplitude"), by_position.column("residual_amplitude")
bare_peak, bare_residual = amplitudes["without mass"]

# Negligible for R_d <= 0.3: within 1 % (peak) and 2 % (residual) of the beam without mass.
low = position <= 0.3 + 1e-9
print("largest change for R_d <= 0.3: peak "
      f"{np.max(np.abs(peak_d[low] / bare_peak - 1)):.2%}, residual "
      f"{np.max(np.abs(residual_d[low] / bare_residual - 1)):.2%}")

# Growing above, faster and faster (convex, "approximately exponential").
print(f"at R_d = 1: peak +{peak_d[-1] / bare_peak - 1:.0%}, "
      f"residual +{residual_d[-1] / bare_residual - 1:.0%} over the beam without mass")

# %% tags=["remove-cell"]
assert set(by_position.column("status")) == {"ok"}
assert np.all(np.abs(peak_d[low] / bare_peak - 1) < 0.01)
assert np.all(np.abs(residual_d[low] / bare_residual - 1) < 0.02)

high = position >= 0.4 - 1e-9
for values in (peak_d[high], residual_d[high]):
    assert np.all(np.diff(values) > 0) and np.all(np.diff(values, 2) > 0)
assert peak_d[-1] > 1.2 * bare_peak and residual_d[-1] > 1.8 * bare_residual

# The sweep reproduces Fig. 7's point at R_d = 0.9.
at_09 = np.isclose(position, 0.9)
assert abs(peak_d[at_09][0] - 0.263) < TOLERANCE * 0.263
assert abs(residual_d[at_09][0] - 0.141) < TOLERANCE * 0.141

# %%
for row in by_mass:
    print(f"R_M = {row['mass_ratio']:.1f} ({row['mass']:.3f} kg): peak "
          f"{row['peak_amplitude']:.4f} m, residual {row['residual_amplitude']:.4f} m")

# %% tags=["remove-cell"]
mass_ratio = by_mass.column("mass_ratio")
peak_m, residual_m = by_mass.column("peak_amplitude"), by_mass.column("residual_amplitude")
assert set(by_mass.column("status")) == {"ok"}
# Growing with the mass ratio, ever more slowly (concave, "approximately logarithmic").
for values in (peak_m, residual_m):
    assert np.all(np.diff(values) > 0) and np.all(np.diff(values, 2) < 0)
assert np.isclose(peak_m[0], bare_peak, rtol=1e-3)     # R_M = 0 is the beam without mass

# %% [markdown]
# The table is tidy (one row per point) and goes straight to a file or to pandas:

# %%
print(by_mass.to_csv()[:400])
