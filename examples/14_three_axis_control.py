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
# # 14. Three-axis control of a flexible spacecraft
#
# A bus with two damped solar arrays slews 20 degrees about a tilted axis through a pyramid of
# four reaction wheels, reading a star tracker and a gyro through the attitude filter. This
# notebook designs three laws on the linear flexible spacecraft and flies each on the exact
# model (`docs/guide/spatial.md`):
#
# 1. quaternion feedback (proportional and rate, from the rigid inertia);
# 2. an LQR on the attitude, the rate and the arrays' modes (it reads the true state);
# 3. an LQG: the same regulator on a Kalman filter of the attitude and rate the attitude
#    filter gives, which estimates the modes.
#
# Then it reads each held loop's disk margins, compares the slews (pointing, residual
# vibration with its error, wheel speeds and power, torque used), flies the LQG exported as C,
# and runs a small Monte Carlo over the arrays' stiffness and the sensors' noise.

# %%
import tempfile

import matplotlib.pyplot as plt
import numpy as np

from controllers.analysis.spatial_loops import loop_disk_margins, lq_loop, quaternion_loop
from controllers.codegen import export_c
from controllers.codegen.spatial_program import compiled_spatial_law
from controllers.feedback.lqr import LQRWeights
from controllers.feedback.mekf import AttitudeFilter
from controllers.feedback.quaternion import QuaternionFeedback
from controllers.feedback.spatial_lqr import design_spatial_lqg, design_spatial_lqr
from flexctl import SpatialAppendage, SpatialHub, SpatialStructure, linearize_spatial
from flexctl.model.wheel_cluster import WheelCluster
from flexctl.sim.attitude_sensors import AttitudeSensors, Gyro, StarTracker
from flexctl.sim.quaternions import error_angles, from_rotation_vector
from flexctl.sim.spatial_loop import simulate_spatial_loop


def array(name, direction):
    """A solar array along ``direction``, flexible along z, with 0.5 % modal damping."""
    return SpatialAppendage(name=name, direction=direction, normal=(0.0, 0.0, 1.0), length=1.8,
                            density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                            second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
                            shear_modulus=2.6e10, torsion_constant=1.0e-9,
                            damping_ratio=0.005)


craft = SpatialStructure(hub=SpatialHub(inertia=[[1.30, 0.05, 0.0], [0.05, 1.20, 0.0],
                                                 [0.0, 0.0, 1.40]], radius=0.06),
                         appendages=(array("wing_a", (0.0, 1.0, 0.0)),
                                     array("wing_b", (0.0, -1.0, 0.0))))
wheels = WheelCluster.pyramid(angle=54.7356, inertia=0.01, torque_limit=0.1, speed_limit=314.16)
sensors = AttitudeSensors(star_tracker=StarTracker(cross_noise=2e-5, boresight_noise=1e-4,
                                                   sample_time=0.5),
                          gyro=Gyro(angle_random_walk=3e-5), gyro_sample_time=0.1, seed=3)
target = from_rotation_vector(np.radians(20.0) * np.array([0.6, 0.0, 0.8]))
T_FINAL, N_MODES, SAMPLE = 30.0, 2, 0.1

# %% [markdown]
# ## 1. Three designs
#
# The LQR and LQG weigh an attitude error of 0.05 rad, a rate of 0.05 rad/s, a tip deflection
# of 5 mm and a torque of 0.1 N m per axis. They act on the part of the plant the torque moves
# below the loop's Nyquist frequency: the arrays bending against each other and the fast
# in-plane and torsion modes keep their own poles (`law.note`).

# %%
weights = LQRWeights(hub_angle=0.05, hub_rate=0.05, tip_deflection=0.005, torque=0.1)
laws = {
    "quaternion": QuaternionFeedback.design(craft.rigid_inertia, 0.5, target, damping=0.9,
                                            torque_limit=0.1),
    "LQR": design_spatial_lqr(craft, weights, target, n_modes=1, sample_time=SAMPLE,
                              torque_limit=0.1),
    "LQG": design_spatial_lqg(craft, weights, target, SAMPLE, n_modes=1, torque_limit=0.1),
}
print(laws["LQR"].note)

# %% [markdown]
# ## 2. Each loop's disk margins, on the plant with every mode of the run
#
# The LQR and LQG loops are held at 10 Hz, the LQG's with its filter in the loop; quaternion
# feedback's is the continuous law's. Per torque axis with the other two closed, and all three
# axes perturbed at once (SLICOT's structured singular value through python-control).

# %%
plant = linearize_spatial(craft, N_MODES)
margins = {"quaternion": loop_disk_margins(quaternion_loop(laws["quaternion"], craft,
                                                           n_modes=N_MODES)),
           "LQR": loop_disk_margins(lq_loop(laws["LQR"], plant)),
           "LQG": loop_disk_margins(lq_loop(laws["LQG"], plant))}
for name, m in margins.items():
    print(f"{name}:\n{m}")

# %% tags=["remove-cell"]
for name, m in margins.items():
    assert m.closed_loop_stable and np.all(m.gain_margin_db > 6.0)
    assert np.all(m.phase_margin_deg > 30.0)

# %% [markdown]
# ## 3. The slews on the exact model
#
# Each law flies the exact model with two modes per field through the wheels; quaternion
# feedback and the LQG read the sensors through the attitude filter, the LQR the true state.
# Each metric's error is its change when the integration's tolerance is divided by 10.

# %%
def fly(law, rtol=1e-7):
    reads_sensors = not getattr(law, "state_feedback", False)
    return simulate_spatial_loop(
        craft, T_FINAL, law, sample_time=None if reads_sensors else SAMPLE, n_modes=N_MODES,
        wheels=wheels, sensors=sensors if reads_sensors else None,
        estimator=AttitudeFilter(sensors, (1.0, 0.0, 0.0, 0.0), attitude_sigma=1e-3)
        if reads_sensors else None, rtol=rtol).result


def metrics(result):
    tips = np.array([np.linalg.norm(v, axis=0) for v in result.tips.values()])
    late = result.t >= T_FINAL - 10.0
    return {"pointing (mrad)": 1e3 * np.linalg.norm(error_angles(target,
                                                                 result.states[0:4, -1])),
            "residual (um)": 1e6 * np.max(tips[:, late]),
            "wheel speed (rad/s)": np.max(np.abs(result.wheel_speeds)),
            "wheel power (W)": np.max(result.wheel_power),
            "torque used (N m s)": np.sum(np.abs(result.torque[:, :-1]) * np.diff(result.t))}


runs = {name: fly(law) for name, law in laws.items()}
table = {name: metrics(run) for name, run in runs.items()}
errors = {name: metrics(fly(law, rtol=1e-8)) for name, law in laws.items()}
print(f"{'':12s}" + "".join(f"{k:>22s}" for k in table["LQR"]))
for name in laws:
    print(f"{name:12s}" + "".join(f"{v:12.4g} (+-{abs(v - errors[name][k]):7.1g})"
                                   for k, v in table[name].items()))

# %% tags=["remove-cell"]
assert all(run.ok for run in runs.values())
assert table["LQR"]["residual (um)"] < table["quaternion"]["residual (um)"]
assert all(t["pointing (mrad)"] < 0.5 for t in table.values())

# %%
fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
for name, run in runs.items():
    pointing = [np.linalg.norm(error_angles(target, run.states[0:4, k]))
                for k in range(run.t.size)]
    axes[0].semilogy(run.t, pointing, label=name)
    tips = np.max([np.linalg.norm(v, axis=0) for v in run.tips.values()], axis=0)
    axes[1].semilogy(run.t, 1e3 * np.maximum(tips, 1e-12), label=name)
    axes[2].plot(run.t, np.max(np.abs(run.wheel_speeds), axis=0), label=name)
axes[0].set_ylabel("pointing error, rad")
axes[1].set_ylabel("largest tip displacement, mm")
axes[2].set_ylabel("fastest wheel, rad/s")
axes[2].set_xlabel("t, s")
for ax in axes:
    ax.grid(True, alpha=0.3)
    ax.legend()
fig.suptitle("20 degree slew about (0.6, 0, 0.8) through a wheel pyramid")
plt.show()

# %% [markdown]
# ## 4. The LQG as C, flown in the loop
#
# The exported step reads the attitude and rate (`qw qx qy qz wx wy wz`) and commands three
# torques; flown in the same loop, it gives the Python law's slew to the integration's
# tolerance.

# %%
build = tempfile.TemporaryDirectory(prefix="lqg-c-")  # removed when the kernel stops
compiled = export_c(laws["LQG"], None, build.name).compile()
flown = fly(compiled_spatial_law(compiled))
difference = np.max(np.abs(flown.states - runs["LQG"].states))
print(f"C against Python in the loop: largest state difference {difference:.2g}, "
      f"the C struct {compiled.struct_bytes} bytes")

# %% tags=["remove-cell"]
assert difference < 1e-5

# %% [markdown]
# ## 5. A small Monte Carlo
#
# The LQG designed once, flown on arrays 15 % softer or stiffer and a hub 5 % lighter or
# heavier, each run with its own sensor noise (`spatial_monte_carlo` runs any such table,
# on a Dask cluster too; here three runs of the same slew, as a scene).

# %%
from flexctl import load_scene  # noqa: E402
from flexctl.app.spatial_monte_carlo import spatial_monte_carlo  # noqa: E402

scene = load_scene("scenes/spatial-lqg-slew.toml", overrides={"simulation.t_final": 15.0})
sweep_table = spatial_monte_carlo(scene, 3, stiffness_spread=0.15, seed=2)
for row in sweep_table.rows:
    print(f"stiffness {row['stiffness']:.3f}, inertia {row['inertia']:.3f}: {row['status']}, "
          f"pointing {1e3 * row['pointing_error']:.3f} mrad, residual "
          f"{1e6 * row['residual_vibration']:.2f} um")

# %% tags=["remove-cell"]
assert not sweep_table.failed and all(r["status"] == "ok" for r in sweep_table.rows)
