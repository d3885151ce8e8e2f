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
# # 11. Actuators and sensors in the loop
#
# A spacecraft turns by a reaction wheel and reads a gyro; a lab rig turns by a geared DC
# motor driven by a voltage and reads an encoder. This notebook puts both in the plant
# (`build_model(..., actuator=...)`) and in the loop (`simulate(..., sensors=...)`):
#
# 1. the wheel trades angular momentum with the structure, which hub, beams and wheel keep;
# 2. its torque and speed limits hold under a controller that asks for more;
# 3. the DC motor's torque falls with speed along its voltage line;
# 4. an LQR slew read through noisy, quantised, late sensors by a Kalman filter
#    (`controllers.Observed`), against the same slew on the exact state.

# %%
import dataclasses
import math

import matplotlib.pyplot as plt
import numpy as np

from controllers import Observed, from_spec
from flexctl import DCMotor, ReactionWheel, SineTorque, build_model, load_scene, simulate
from flexctl.app.scenes import run_slew
from flexctl.sim.digital import ZeroOrderHold

scene = load_scene("wheel-slew")
wheel = scene.actuator
plant = scene.build_model()
print(plant)
print("states:", plant.state_names)
print("input:", plant.input_names, " outputs:", plant.output_names[-2:])

# %% [markdown]
# ## 1. Momentum traded, momentum kept
#
# A sine command on the wheel with its friction off: the structure's angular momentum goes
# into the wheel and back, the total stays (`model.angular_momentum` counts the wheel's).

# %%
frictionless = dataclasses.replace(wheel, viscous_friction=0.0, coulomb_friction=0.0)
model = build_model(scene.system, 2, "consistent", actuator=frictionless)
result = simulate(model, 20.0, torque=SineTorque(peak_torque=0.02, duration=10.0),
                  rtol=1e-10)
total = model.angular_momentum(result.states)
structure = model.mechanical.angular_momentum(model.mechanical_states(result.states))
print(f"structure's momentum swings by {np.ptp(structure):.3g} N m s; "
      f"the total drifts by {np.ptp(total):.2e}")

fig, ax = plt.subplots(figsize=(7, 3))
ax.plot(result.t, structure, label="hub and arrays")
ax.plot(result.t, total - structure, label="wheel")
ax.plot(result.t, total, "k--", label="total")
ax.set_xlabel("time (s)"), ax.set_ylabel("angular momentum (N m s)"), ax.legend()
plt.show()

# %% tags=["remove-cell"]
assert np.ptp(total) <= 1e-7 * np.ptp(structure)

# %% [markdown]
# ## 2. Limits that hold
#
# A law that always asks for ten times the torque limit: the motor gives at most its limit,
# and the wheel stops speeding up at its speed limit (the torque fades over the last 1 %).

# %%
small = dataclasses.replace(wheel, speed_limit=40.0)
model = build_model(scene.system, 2, actuator=small)
greedy = ZeroOrderHold(lambda t, x: 10 * small.torque_limit, sample_time=0.05)
result = simulate(model, 20.0, controller=greedy)
signals = result.actuator_signals
print(f"peak motor torque {np.max(np.abs(signals['wheel_torque'])):.4g} N m "
      f"(limit {small.torque_limit:g}); peak wheel speed "
      f"{np.max(np.abs(signals['wheel_speed'])):.4g} rad/s (limit {small.speed_limit:g})")

# %% tags=["remove-cell"]
assert np.max(np.abs(signals["wheel_torque"])) <= small.torque_limit * (1 + 1e-9)
assert np.max(np.abs(signals["wheel_speed"])) <= small.speed_limit * (1 + 1e-3)

# %% [markdown]
# ## 3. The DC motor's voltage line
#
# The flexible-link rig's motor (Quanser SRV02 data): at a fixed voltage the hub torque falls
# linearly with the hub rate, from the stall torque to zero at the no-load speed.

# %%
link = load_scene("flexible-link")
motor = link.actuator
rig = link.build_model()
rates = np.linspace(0.0, motor.no_load_speed, 5)
states = np.zeros((rig.n_states, rates.size))
states[rig.layout.theta_dot] = rates
torques = rig.applied_torque(states, motor.voltage_limit)
print(f"stall torque {motor.stall_torque:.4g} N m, no-load speed {motor.no_load_speed:.4g} "
      "rad/s; torque along the line:", np.round(torques, 4))

# %% tags=["remove-cell"]
assert torques[0] == np.float64(motor.stall_torque) and abs(torques[-1]) < 1e-12

# %% [markdown]
# ## 4. A slew read through sensors
#
# The wheel slew's LQR (designed on the structure augmented with the wheel's lag, discrete at
# the sensors' rate), read on the exact state and through the scene's sensors by the Kalman
# filter that `from_spec` puts in front of it. The readings and their true values are in
# `result.measurements`.

# %%
exact = dataclasses.replace(scene, sensors=None)
runs = {label: run_slew(case, from_spec) for label, case in
        (("exact state", exact), ("sensors", scene))}
for label, (res, built, metrics) in runs.items():
    print(f"{label:12s} residual {metrics.residual_vibration:.3g} m, final error "
          f"{metrics.final_error:.2e} rad, peak wheel speed "
          f"{np.max(np.abs(res.actuator_signals['wheel_speed'])):.4g} rad/s")
sensed = runs["sensors"][0]
seen = sensed.measurements
gyro_error = seen["theta_dot"] - seen["true"]["theta_dot"]
print(f"{seen['t'].size} readings; gyro error std {np.std(gyro_error):.3g} rad/s")

fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
for label, (res, _, _) in runs.items():
    axes[0].plot(res.t, 1e3 * res.tip_deflection, label=label, lw=1)
    axes[1].plot(res.t, np.degrees(res.theta - scene.maneuver.angle), label=label, lw=1)
axes[0].set_ylabel("tip (mm)"), axes[1].set_ylabel("hub error (deg)")
axes[1].set_xlabel("time (s)"), axes[0].legend()
axes[1].set_ylim(-1, 1)
plt.show()

# %% tags=["remove-cell"]
assert isinstance(runs["sensors"][1].controller, Observed)
assert np.max(np.abs(seen["theta"] - seen["true"]["theta"])) <= scene.sensors.encoder_resolution
