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
# # 9. The flexible loop in the frequency domain
#
# Control engineers judge a flexible loop first by its Bode plot, its margins and where its
# poles sit. `controllers.analysis.loops` gives that view of any controller on a flexctl plant,
# built on python-control (every system is a `control.StateSpace`), and
# `controllers.analysis.robustness` runs a Monte Carlo study of it through `flexctl.app.sweep`. This
# notebook, on the `slew-90` system (1.8 m beam, 85 g near the tip, an undamped beam),
#
# 1. looks at the plant's channels: the hub angle (collocated with the torque) and the tip;
# 2. shows why collocated PD is robust and tip feedback is not;
# 3. reads the margins of the PD, LQR and LQG loops that `flexctl run slew-90` builds;
# 4. follows the poles as the hub spins;
# 5. disperses the beam stiffness, the point mass and the hub inertia (Monte Carlo).

# %%
# %matplotlib inline
import dataclasses
from concurrent.futures import ProcessPoolExecutor

import control
import numpy as np

import flexctl
from controllers import (PD, Dispersion, LQRWeights, NoiseLevels, RobustnessTask, check_loop,
                         design_lqg, from_spec, loop_margins, loop_transfer, plant_channels,
                         poles_vs_spin, robustness_summary)
from flexctl.app.plotting_loops import (plot_bode, plot_frequencies_vs_spin, plot_pole_zero,
                                        plot_poles_vs_spin, plot_robustness)
from flexctl.app.sweep import sweep

scene = flexctl.load_scene("slew-90")
plant = scene.build_model()                 # the scene's 6-mode plant
design = flexctl.build_model(scene.system, scene.model.design_modes, scene.design_variant)
free = plant.natural_frequencies(hub="free")
print(plant)
print("hub-free frequencies:", free.round(2), "rad/s")
print("clamped frequencies: ", plant.natural_frequencies().round(2), "rad/s")

# %% [markdown]
# ## 1. The plant: collocated and non-collocated channels
#
# Torque to hub angle has the rigid double pole at 0, the flexible poles at `+-j` the
# hub-free frequencies and zeros at `+-j` the *clamped* frequencies (the beam vibrating
# with the hub held still): pole, zero, pole, zero up the imaginary axis. That interlacing
# is what collocation buys. Torque to the tip angle `theta + w(l) / (b + l)` has zeros in the
# right half-plane: the tip first moves the wrong way.

# %%
channels = plant_channels(plant)
hub_zeros = control.zeros(channels.hub_angle)
tip_zeros = control.zeros(channels.tip_angle)
zero_frequencies = np.sort(np.abs(hub_zeros.imag))[::2]
print("hub-angle zeros at +-j", zero_frequencies.round(2), "rad/s")
print("tip-angle zeros with positive real part:", np.sort(tip_zeros[tip_zeros.real > 0]).round(1))
fig = plot_pole_zero({"hub angle": channels.hub_angle, "tip angle": channels.tip_angle},
                     natural_frequencies=free, xlim=(-90, 90), ylim=(-150, 150),
                     title="slew-90 plant: poles (x) and zeros (o)")
fig

# %% tags=["remove-cell"]
assert np.allclose(zero_frequencies, channels.clamped_frequencies, rtol=1e-6)
assert np.all(zero_frequencies < free) and np.all(free[:-1] < zero_frequencies[1:])
assert np.max(tip_zeros.real) > 1.0

# %% [markdown]
# ## 2. Why collocated PD is robust and tip feedback is not
#
# The PD law of `flexctl run slew-90 --set controller.kind=pd` (2 rad/s, damping ratio 0.9)
# acts on the hub angle and rate. Its loop `L(s) = (kp + kd s) P_theta(s)` keeps a phase
# between -180 and 0 deg away from the resonances, whatever the number of modes: its gain
# margin is infinite and the loop stays stable for *every* positive gain. The same gains on
# the tip angle (the position one actually wants to control) destabilise the undamped beam
# at every gain; on a beam with 0.5 % damping, the tip loop is stable only when turned down
# by a factor of about 60.
#
# (On an undamped beam the phase flips by 180 deg at every pole and zero; the margins leave
# those singular crossings out, see `controllers.analysis.loops`.)

# %%
pd = from_spec(flexctl.load_scene("slew-90", overrides={"controller.kind": "pd"}),
               plant).controller
gains = np.logspace(-3, 2, 21)


def abscissa(loop, gain):
    """Largest real part of the closed-loop poles with the loop gain scaled, 1/s."""
    return control.poles(control.feedback(gain * loop)).real.max()


hub_loop = loop_transfer(plant, pd)
tip_loop = loop_transfer(plant, pd, sensor="tip_angle")
collocated = [abscissa(hub_loop, g) for g in gains]
tip = [abscissa(tip_loop, g) for g in gains]
print(f"collocated PD: largest pole real part in [{min(collocated):.3g}, "
      f"{max(collocated):.3g}] 1/s for gains x{gains[0]:g} to x{gains[-1]:g}")
print(f"tip-angle PD:  in [{min(tip):.3g}, {max(tip):.3g}] 1/s")
print("collocated margins:", loop_margins(hub_loop))

damped_system = dataclasses.replace(
    scene.system, beam=dataclasses.replace(scene.system.beam, damping_ratio=0.005))
damped_plant = flexctl.build_model(damped_system, plant.n_modes)
turn_down = loop_margins(loop_transfer(damped_plant, pd, sensor="tip_angle"))
quiet_pd = PD(kp=0.5 * turn_down.gain_reduction_margin * pd.kp,
              kd=0.5 * turn_down.gain_reduction_margin * pd.kd)
quiet_tip = loop_margins(loop_transfer(damped_plant, quiet_pd, sensor="tip_angle"))
print(f"0.5 % damping: the tip loop is stable below x{turn_down.gain_reduction_margin:.4f} "
      f"of the PD gains; at half that its gain margin is {quiet_tip.gain_margin:.2f}")

# %%
fig = plot_bode({"PD on hub angle": hub_loop, "PD on tip angle": tip_loop},
                natural_frequencies=free, omega_limits=(0.1, 500.0),
                title="Collocated and tip feedback, same gains")
fig

# %% tags=["remove-cell"]
hub_margins = loop_margins(hub_loop)
assert max(collocated) < 0.0 and min(tip) > 0.0
assert hub_margins.closed_loop_stable and hub_margins.gain_margin == np.inf
assert not turn_down.closed_loop_stable and turn_down.gain_reduction_margin < 0.05
assert quiet_tip.closed_loop_stable and quiet_tip.gain_margin < 2.5

# %% [markdown]
# ## 3. The margins of the PD, LQR and LQG loops on slew-90
#
# The scene's factory designs each controller on the 2-mode design model; the loop is
# broken at the torque. On the design model, LQR (full state feedback) has Kalman's
# guarantees: phase margin at least 60 deg, gain margin infinite upwards and at least 1/2
# downwards, `|1 + L| >= 1`. LQG (a Kalman filter on the hub angle and root bending moment)
# has no guarantee and a finite gain margin. On the 6-mode plant the unmodelled modes come
# in: for LQR only as a finite gain margin at the third mode. The root moment reads every
# mode, so the built-in LQG's filter models all six of the plant's (its regulator acts on
# the design's two): a filter of the design modes only would read the third mode and feed
# it back with the wrong phase, and on the *undamped* plant it would grow at about
# 0.02 1/s (a 40 s time constant, unseen in a 6 s slew). `controllers.check_loop`, run by
# every design given its plant, names it.

# %%
controllers = {kind: from_spec(flexctl.load_scene("slew-90",
                                                  overrides={"controller.kind": kind}),
                               plant).controller
               for kind in ("pd", "lqr", "lqg")}
filter_model = flexctl.build_model(scene.system, plant.n_modes, scene.design_variant)
margins = {}
print(f"{'loop':12s} {'stable':>6s} {'GM up':>8s} {'GM down':>8s} {'PM (deg)':>9s} "
      f"{'at (rad/s)':>10s} {'min|1+L|':>9s} {'max Re (1/s)':>12s}")
for kind, controller in controllers.items():
    # the LQG's own model is its filter's: the design variant on the plant's modes
    own = filter_model if kind == "lqg" else design
    for label, model in (("design", own), ("plant", plant)):
        m = loop_margins(loop_transfer(model, controller))
        margins[kind, label] = m
        print(f"{kind + ' ' + label:12s} {str(m.closed_loop_stable):>6s} {m.gain_margin:8.3g} "
              f"{m.gain_reduction_margin:8.3g} {m.phase_margin:9.1f} "
              f"{m.gain_crossover_frequency:10.3g} {m.stability_margin:9.3f} "
              f"{m.spectral_abscissa:12.3g}")

spillover = design_lqg(design, LQRWeights(hub_angle=0.05, hub_rate=0.02, tip_deflection=0.01,
                                           torque=1.0),
                       NoiseLevels(angle=1e-3, root_moment=0.1, torque=0.1), plant=plant,
                       estimate_plant_modes=False, check_stability=False)
spillover_check = check_loop(plant, spillover)
print("filter of the design modes only:", spillover_check.message())
lightly_damped = flexctl.build_model(dataclasses.replace(
    scene.system, beam=dataclasses.replace(scene.system.beam, damping_ratio=0.002)),
    plant.n_modes)
lqg_damped = loop_margins(loop_transfer(lightly_damped, spillover))
print(f"that filter on the plant with 0.2 % damping: stable {lqg_damped.closed_loop_stable}, "
      f"largest pole real part {lqg_damped.spectral_abscissa:.3f} 1/s")

# %%
loops = {kind: loop_transfer(plant, c) for kind, c in controllers.items()}
fig = plot_bode(loops, natural_frequencies=free, omega_limits=(0.1, 1000.0),
                title="slew-90 loops on the 6-mode plant, broken at the torque")
fig

# %% tags=["remove-cell"]
lqr_design, lqg_design = margins["lqr", "design"], margins["lqg", "design"]
assert lqr_design.closed_loop_stable and lqr_design.gain_margin == np.inf
assert abs(lqr_design.phase_margin) >= 60.0 and lqr_design.gain_reduction_margin <= 0.5
assert lqr_design.stability_margin >= 1.0 - 1e-9
assert lqg_design.closed_loop_stable and 1.0 < lqg_design.gain_margin < 10.0
assert margins["pd", "plant"].gain_margin == np.inf and margins["pd", "plant"].closed_loop_stable
assert margins["lqr", "plant"].closed_loop_stable and margins["lqr", "plant"].gain_margin < np.inf
assert margins["lqg", "plant"].closed_loop_stable
assert not spillover_check.stable and spillover_check.poles[0].mode == 3
assert 0.0 < spillover_check.spectral_abscissa < 0.05
assert lqg_damped.closed_loop_stable
# the loops close on the same poles as the controllers' own (python-control-free) checks
lqg_poles = controllers["lqg"].closed_loop_poles(plant)
assert np.isclose(lqg_poles.real.max(), margins["lqg", "plant"].spectral_abscissa, rtol=1e-6)
assert np.isclose(spillover.closed_loop_poles(plant).real.max(),
                  spillover_check.spectral_abscissa, rtol=1e-6)

# %% [markdown]
# ## 4. How the poles move with the spin rate
#
# About a steady spin the beam stiffens (centrifugal tension): every hub-free frequency and
# every clamped one rises, and they stay interlaced, so collocation keeps its property at
# any spin. The LQR designed at rest keeps its closed-loop poles in the left half-plane up
# to 12 rad/s, losing a little damping as the plant moves away from its design point.

# %%
spins = np.linspace(0.0, 12.0, 25)
analysis_plant = flexctl.build_model(scene.system, 4)      # linearised, first_order = exact
table = poles_vs_spin(analysis_plant, spins, controllers["lqr"])
fig = plot_frequencies_vs_spin(table, title="Poles (hub free) and hub-angle zeros (hub held)")
fig

# %%
fig = plot_poles_vs_spin(table, title="LQR designed at rest, closed loop against spin")
fig.axes[0].set_xlim(-6.0, 0.5)
fig

# %%
first = table.natural_frequencies[:, 0]
print(f"first mode {first[0]:.2f} rad/s at rest, {first[-1]:.2f} rad/s at 12 rad/s")
print("largest closed-loop real part:", table.closed_loop_poles.real.max(axis=1)[[0, 12, 24]])

# %% tags=["remove-cell"]
upper_zeros = np.sort(np.where(table.hub_angle_zeros.imag > 0,
                               table.hub_angle_zeros.imag, np.inf), axis=1)[:, :4]
assert np.all(np.diff(table.natural_frequencies, axis=0) > 0)
assert np.all(upper_zeros < table.natural_frequencies)               # still interlaced
assert np.all(table.natural_frequencies[:, :-1] < upper_zeros[:, 1:])
assert np.all(table.closed_loop_poles.real.max(axis=1) < 0)

# %% [markdown]
# ## 5. Monte Carlo robustness
#
# 60 plants with Young's modulus within 10 %, the point mass within 20 % and the hub
# inertia within 10 % of nominal (uniform draws), each judged by its loop with the
# controller designed on the nominal system. `RobustnessTask` is a picklable frozen
# dataclass, so the samples go through `flexctl.app.sweep.sweep` on any executor: here two
# worker processes; `Client(...).get_executor()` of Dask distributed takes it to a cluster.
# The LQG whose filter models the design modes only is judged on the 0.2 % damped beam (on
# the undamped one it is never stable, as section 3 showed).

# %%
samples = Dispersion(youngs_modulus=0.1, point_mass=0.2, hub_inertia=0.1).samples(60, seed=9)
tasks = {"pd": RobustnessTask(system=scene.system, controller=controllers["pd"], n_modes=4),
         "lqr": RobustnessTask(system=scene.system, controller=controllers["lqr"], n_modes=4),
         "lqg": RobustnessTask(system=lightly_damped.system, controller=spillover,
                               n_modes=4)}
studies = {}
with ProcessPoolExecutor(max_workers=2) as pool:
    for name, task in tasks.items():
        studies[name] = sweep(task, samples, executor=pool, progress=False)
summaries = {name: robustness_summary(study) for name, study in studies.items()}
for name, s in summaries.items():
    print(f"{name:4s} stable {s.n_stable:2d}/{s.n_samples}, worst gain margin "
          f"{s.worst_gain_margin:.3g}, worst phase margin {s.worst_phase_margin:.1f} deg, "
          f"worst min|1+L| {s.worst_stability_margin:.3f}")

# %% [markdown]
# PD and LQR keep every sample stable, with about the nominal margins. That LQG does not: its
# Kalman filter predicts the beam with the nominal stiffness, and a beam a few percent
# softer than that is enough to destabilise the loop (Doyle's point: LQG has no guaranteed
# margins). Stiffer beams are harmless. The point mass and the hub inertia matter much less.

# %%
fig = plot_robustness(studies["lqg"], "youngs_modulus_scale", "spectral_abscissa",
                      title="LQG, design-mode filter (0.2 % damping): largest closed-loop "
                            "real part")
fig.axes[0].axhline(0.0, color="0.3", linewidth=0.6)
fig

# %%
lqg_study = studies["lqg"]
stiffness = lqg_study.column("youngs_modulus_scale")
stable = lqg_study.column("closed_loop_stable").astype(bool)
print(f"LQG: unstable for {np.sum(~stable)} of 60 samples, all with Young's modulus "
      f"at most {stiffness[~stable].max():.3f} x nominal")

# %% tags=["remove-cell"]
assert summaries["pd"].stable_fraction == 1.0 and summaries["pd"].worst_gain_margin == np.inf
assert summaries["lqr"].stable_fraction == 1.0 and summaries["lqr"].worst_phase_margin > 60.0
assert 0.0 < summaries["lqg"].stable_fraction < 1.0
assert np.all(stable[stiffness > 1.0]) and not np.any(stable[stiffness < 0.94])
