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
# # 7. Speed against error: how many modes, which integrator, what tolerance
#
# `flexctl bench` sweeps the number of modes, the model variant, the integrator and its
# tolerance on a scene, and measures each run's wall time and its tip error against a
# converged reference (many modes, tight tolerance). The error splits in two:
#
# - *truncation*: what the `N`-mode model leaves out (the `N`-mode model at the reference
#   tolerance against the reference);
# - *integration*: what the integrator adds (the run against that same `N`-mode run).
#
# Here the Python API (`flexctl.app.bench`) runs a small sweep on the Kane spin-up. The same from
# the shell:
#
# ```bash
# flexctl bench --scene kane-spinup --modes 1-4,6 --variants first_order \
#     --methods cvodes,DOP853 --rtols 1e-4,1e-6,1e-8 --reference-modes 12 --out bench
# ```

# %%
# %matplotlib inline
import dataclasses

import numpy as np
from matplotlib.figure import Figure

import flexctl
from flexctl.app.bench import BenchConfig, bench_scene
from flexctl.app.plotting import plot_pareto, plot_sweep
from flexctl.app.sweep import pareto_front

scene = flexctl.load_scene("kane-spinup")
config = BenchConfig(modes=(1, 2, 3, 4, 6), variants=("first_order",),
                     methods=("cvodes", "DOP853"), rtols=(1e-4, 1e-6, 1e-8),
                     reference_modes=12, reference_rtol=1e-10, time_limit=20.0)
bench = bench_scene(scene, config, progress=False)
rows = [dataclasses.asdict(r) for r in bench.rows]      # a tidy table: one dict per run
print(f"{len(rows)} runs; reference: {bench.references['first_order']['status']}, "
      f"{bench.references['first_order']['wall_time_s']:.2f} s")

# %%
print(f"{'modes':>5s} {'method':>7s} {'rtol':>6s} {'wall (s)':>9s} {'error':>9s} "
      f"{'truncation':>10s} {'integration':>11s}")
for r in rows:
    print(f"{r['n_modes']:5d} {r['method_used']:>7s} {r['rtol']:6.0e} {r['wall_time_s']:9.3g} "
          f"{r['error']:9.2e} {r['truncation_error']:10.2e} {r['integration_error']:11.2e}")

# %% [markdown]
# ## The trade-off
#
# Every run is a point (wall time, error); the Pareto front joins the runs that no other
# beats on both. Compiled CVODES integration (`method="auto"` picks it for the built-in
# manoeuvres) is an order of magnitude faster than SciPy's DOP853 at the same accuracy, so
# the front is made of CVODES runs; along it, more modes buy accuracy.

# %%
fig = Figure(figsize=(13.0, 4.8), layout="constrained")
ax_front, ax_modes, ax_rtol = fig.subplots(1, 3)
plot_pareto(rows, "wall_time_s", "error", by="method_used", label="n_modes", ax=ax_front,
            xlabel="wall time (s)", ylabel="relative tip error",
            title="Kane spin-up: speed against error")
truncation = [{"n_modes": n, "truncation_error": e} for n, e in sorted(bench.truncation.items())]
plot_sweep(truncation, "n_modes", "truncation_error", ax=ax_modes, logy=True,
           xlabel="number of modes N", ylabel="truncation error",
           title="Truncation: converging with N")
four = [r for r in rows if r["n_modes"] == 4]
plot_sweep(four, "rtol", "integration_error", by="method_used", ax=ax_rtol, logx=True,
           logy=True, xlabel="relative tolerance rtol", ylabel="integration error",
           title="Integration error, N = 4")
fig

# %% [markdown]
# ## How many modes?
#
# `flexctl.sim.fidelity.choose_modes` estimates the truncation error from linear responses,
# without running the nonlinear model, and picks the fewest modes within a tolerance (1 %
# here). The bench measures the actual truncation error of that choice.

# %%
choice = bench.choice
print(f"chosen: {choice.n_modes} modes, estimated error {choice.estimated_error:.2e}, "
      f"actual {bench.choice_actual_error:.2e} (tolerance {config.tolerance:g})")
print(choice.explanation)

# %% [markdown]
# ## Asserted

# %%
# CVODES is about ten times faster than DOP853 at equal settings (median over the runs).
done = [r for r in rows if r["status"] == "ok"]
speedup = np.median([d["wall_time_s"] / c["wall_time_s"] for c in done for d in done
                     if c["method_used"] == "cvodes" and d["method_used"] == "DOP853"
                     and (c["n_modes"], c["rtol"]) == (d["n_modes"], d["rtol"])])
print(f"median speed-up of cvodes over DOP853: {speedup:.1f}x")

# %% tags=["remove-cell"]
# Ritz convergence: the truncation error falls with every mode added.
errors = [e for _, e in sorted(bench.truncation.items())]
assert np.all(np.diff(errors) < 0), errors
assert errors[-1] < 1e-3 < errors[0]

# Tighter tolerances integrate more accurately, for every integrator and mode count.
for method in config.methods:
    for n in config.modes:
        by_rtol = {r["rtol"]: r["integration_error"] for r in rows
                   if r["method"] == method and r["n_modes"] == n and r["status"] == "ok"}
        assert by_rtol[1e-8] < by_rtol[1e-4], (method, n, by_rtol)

# The mode choice meets its tolerance, and its estimate is within a factor 3 of the truth.
assert bench.choice_actual_error <= config.tolerance
assert 1 / 3 < choice.estimated_error / bench.choice_actual_error < 3

# The bench's Pareto front and flexctl.app.sweep.pareto_front agree.
mine = pareto_front([r["wall_time_s"] for r in done], [r["error"] for r in done])
ours = {(r["n_modes"], r["method_used"], r["rtol"]) for r, keep in zip(done, mine) if keep}
theirs = {(r.n_modes, r.method_used, r.rtol) for r in bench.front("first_order")}
assert ours == theirs, (ours ^ theirs)

assert speedup > 2
