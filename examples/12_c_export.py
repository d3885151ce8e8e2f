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
# # 12. A slew controller exported as C
#
# A law designed in Python has to run on a flight computer in the end. `controllers.codegen`
# writes a designed law as self-contained C99 (no allocation, no global state, no library
# but `libm`), compiles it, and loads it back so it can close the loop on the same plant.
# This notebook takes the `slew-90` NMPC (a real-time iteration with CasADi's `qrqp`, designed
# on a 2-mode first-order model) through:
#
# 1. the export: four files, and the C interface in the header;
# 2. compiling and loading it (`CompiledLaw`);
# 3. the compiled law in the loop on the 6-mode exact plant, against the Python law;
# 4. the generated Makefile and its demo program.

# %%
import os
import shutil
import subprocess
import tempfile

import matplotlib.pyplot as plt
import numpy as np

import flexctl
from controllers import from_spec
from controllers.codegen import export_c
from flexctl.sim.metrics import slew_metrics

scene = flexctl.load_scene("slew-90", {"controller.kind": "nmpc",
                                       "model.design_variant": "first_order"})
plant = scene.build_model()
built = from_spec(scene, plant)
print(scene.description)
print(f"{built.kind} on {built.design_modes} design modes, manoeuvre ends at "
      f"{built.maneuver_end:g} s")

# %% [markdown]
# ## 1. The export
#
# `export_c(law, plant, directory)` writes `flexctl_ctrl.h`, `flexctl_ctrl.c`, `main.c` and a
# `Makefile`. `describe()` says what was written: the law, what it reads (here the plant
# state, in the plant's order), its sample time, and the sizes of the arrays in its struct.

# %%
directory = tempfile.mkdtemp()
exported = export_c(built.controller, plant, directory)
for key, value in exported.describe().items():
    if key == "files":          # the files' names (they are in a temporary folder)
        value = [os.path.basename(name) for name in value]
    print(f"{key:16s} {value}")

# %% [markdown]
# The header is the whole interface: sizes and sample time as macros, the return codes, and
# three functions. The caller owns the memory (`flexctl_ctrl_size()` bytes), `init` sets the
# law's memory to its start, and `step` gives the command to hold until the next sample.
# Above this part, the header's comment lists the input entries in order.

# %%
header = exported.header.read_text().splitlines()
start = next(i for i, line in enumerate(header) if line.startswith("#define FLEXCTL_NX"))
stop = next(i for i, line in enumerate(header) if "flexctl_ctrl_step(" in line)
print("\n".join(header[start:stop + 1]))

# %% tags=["remove-cell"]
assert f"#define FLEXCTL_NX {plant.n_states}" in "\n".join(header)

# %% [markdown]
# ## 2. Compiled and loaded
#
# `compile()` builds the source with the system C compiler at `-std=c99 -Wall -Wextra
# -Werror` into a shared library and loads it through `ctypes`. `step(t, v)` calls
# `flexctl_ctrl_step` and returns the command and the return code (0 is `FLEXCTL_OK`).

# %%
law = exported.compile()
print(f"struct {law.struct_bytes} bytes, code and constants {law.code_bytes} bytes, "
      f"compiled in {law.compile_time_s:.2f} s")
u, code = law.step(0.0, np.zeros(plant.n_states))
print(f"first command at rest: u = {u:.6g} N m (code {code})")

# %% tags=["remove-cell"]
assert code == 0 and abs(u) <= scene.maneuver.torque_bound

# %% [markdown]
# ## 3. In the loop
#
# `law.controller()` is the compiled law as a flexctl controller, sampled at its sample time
# (its memory reset at the start of the run). The same slew with the Python NMPC and with the
# compiled one, on the 6-mode exact plant:

# %%
r_py = flexctl.simulate(plant, 6.0, controller=built.controller)
r_c = flexctl.simulate(plant, 6.0, controller=law.controller())
angle, end = scene.maneuver.angle, built.maneuver_end
d_theta = np.max(np.abs(r_py.theta - r_c.theta))
d_torque = np.max(np.abs(r_py.torque - r_c.torque))
residual = {label: slew_metrics(r, angle, end).residual_vibration
            for label, r in (("python", r_py), ("compiled", r_c))}
print(f"max |theta difference| {d_theta:.3g} rad, max |torque difference| {d_torque:.3g} N m")
print("residual vibration:", {k: f"{v:.4g} m" for k, v in residual.items()})
report = r_c.controller_report
print(f"compiled step: median {1e6 * report['cpu_time_median_s']:.1f} us, 99th percentile "
      f"{1e6 * report['cpu_time_p99_s']:.1f} us CPU over {report['steps']} steps "
      f"({report['recovered_steps']} recovered)")
print(f"Python NMPC solve: median {1e6 * r_py.controller_report['solve_time_median_s']:.1f} us")

fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
for label, r, style in (("Python NMPC", r_py, "-"), ("compiled C", r_c, "--")):
    axes[0].plot(r.t, np.degrees(r.theta), style, label=label, lw=1)
    axes[1].plot(r.t, r.torque, style, label=label, lw=1)
axes[0].set_ylabel("hub angle (deg)"), axes[1].set_ylabel("torque (N m)")
axes[1].set_xlabel("time (s)"), axes[0].legend()
plt.show()

# %% tags=["remove-cell"]
assert np.array_equal(r_py.t, r_c.t)
assert d_theta < 1e-6 and d_torque < 1e-5
assert abs(residual["compiled"] - residual["python"]) <= 1e-6 * residual["python"] + 1e-9

# %% [markdown]
# ## 4. The Makefile
#
# The export builds on its own: `make` in the directory compiles a static library and
# `flexctl_ctrl_demo`, which runs the law on a state given on its command line (zeros here)
# for ten samples.

# %%
if shutil.which("make"):
    subprocess.run(["make", "-C", str(exported.directory)], check=True,
                   capture_output=True, text=True)
    demo = subprocess.run([str(exported.directory / "flexctl_ctrl_demo")], check=True,
                          capture_output=True, text=True)
    print(demo.stdout)
else:
    print("make not found: skipped building the demo program")
shutil.rmtree(directory)       # the exported files; keep them to use the law elsewhere

# %% tags=["remove-cell"]
if shutil.which("make"):
    assert "(code 0)" in demo.stdout

# %% [markdown]
# ## Other laws, and the command line
#
# The other built-in laws export the same way: PD, LQR, scheduled LQR and the trajectory
# tracker as static laws (sample time 0, evaluated whenever called); LQG with its continuous
# Kalman filter discretised at a sample time you give, `export_c(lqg, plant, dir,
# sample_time=0.01)`; and the `Observed` laws of the hardware scenes, which read the sensors'
# readings rather than the state (their `FLEXCTL_NY` is nonzero). A law with no C form (a
# Python callable, an NMPC solved by IPOPT) is refused with the reason (`ExportRefused`).
#
# From the shell, `flexctl export slew-90 --set controller.kind=nmpc --out build/ctrl` designs
# a scene's controller and writes the same files.
