"""The bench's speed-against-error figure: every run, and each variant's Pareto front.

Draws a :class:`flexctl.app.bench.SceneBench`; computes nothing (the fronts come from
``SceneBench.front``, i.e. :func:`flexctl.app.bench.pareto_front`).
"""

from __future__ import annotations

from .figures import new_figure

__all__ = ["plot_pareto"]

_METHOD_COLOURS = {"cvodes": "tab:blue", "DOP853": "tab:orange", "LSODA": "tab:green",
                   "RK45": "tab:red", "RK23": "tab:purple", "Radau": "tab:brown",
                   "BDF": "tab:pink", "auto": "tab:gray"}
_VARIANT_MARKERS = {"first_order": "o", "zero_order": "s", "consistent": "^", "exact": "D"}


def plot_pareto(bench: SceneBench):
    """Wall time against error of every finished run, with each variant's Pareto front.

    Returns
    -------
    matplotlib.figure.Figure
        Log-log axes: wall time (s) across, relative tip error up; colour by integrator used,
        marker by variant; front points labelled with their number of modes.
    """
    fig, (ax,) = new_figure((8.0, 5.5))
    done = [r for r in bench.rows if r.status == "ok" and r.error > 0]
    for r in done:
        ax.plot(r.wall_time_s, r.error, _VARIANT_MARKERS.get(r.variant, "o"), alpha=0.55,
                color=_METHOD_COLOURS.get(r.method_used, "black"))
    for variant in bench.config.variants:
        front = [r for r in bench.front(variant) if r.error > 0]
        if front:
            ax.step([r.wall_time_s for r in front], [r.error for r in front], where="post",
                    color="black", linewidth=1.0,
                    linestyle={"first_order": "-", "zero_order": "--"}.get(variant, ":"))
            for r in front:
                ax.annotate(f"N{r.n_modes}", (r.wall_time_s, r.error), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
    used = [m for m in _METHOD_COLOURS if any(r.method_used == m for r in done)]
    ax.legend(handles=[ax.plot([], [], "o", color=_METHOD_COLOURS[m], label=m)[0] for m in used]
              + [ax.plot([], [], _VARIANT_MARKERS[v], color="gray", label=v)[0]
                 for v in bench.config.variants], fontsize=8, loc="upper right")
    ax.axhline(bench.config.tolerance, color="gray", linewidth=0.8, linestyle=":")
    ax.set(xscale="log", yscale="log", xlabel="wall time (s)", ylabel="relative tip error")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(f"{bench.scene.name}: speed against error over {bench.t_final:g} s "
                 f"(reference {bench.config.reference_modes} modes)")
    return fig
