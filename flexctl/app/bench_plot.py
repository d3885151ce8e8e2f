"""The bench's speed-against-error figure: every run, and each variant's Pareto front.

Draws a :class:`flexctl.app.bench.SceneBench` with the one Pareto plot of the package,
:func:`flexctl.app.plotting_sweeps.plot_pareto`: the fronts are computed there, by
:func:`flexctl.app.sweep.pareto_front`, on the runs of
:meth:`flexctl.app.bench.SceneBench.finished`.
"""

from __future__ import annotations

from .figures import new_figure
from .plotting_sweeps import plot_pareto

__all__ = ["plot_speed_error"]

_METHOD_COLOURS = {"cvodes": "tab:blue", "DOP853": "tab:orange", "LSODA": "tab:green",
                   "RK45": "tab:red", "RK23": "tab:purple", "Radau": "tab:brown",
                   "BDF": "tab:pink", "rk4": "tab:olive", "dop853": "tab:cyan",
                   "auto": "tab:gray"}
_VARIANT_MARKERS = {"first_order": "o", "zero_order": "s", "consistent": "^", "exact": "D"}


def plot_speed_error(bench):
    """Wall time against error of every finished run, with each variant's Pareto front.

    Parameters
    ----------
    bench : SceneBench
        The runs of one scene (:func:`~flexctl.app.bench.bench_scene`).

    Returns
    -------
    matplotlib.figure.Figure
        Log-log axes: wall time (s) across, relative tip error up; colour by integrator used,
        marker by variant, a front per variant with its points labelled by their number of
        modes; the mode-choice tolerance as a dotted line.
    """
    rows = [{"wall_time_s": r.wall_time_s, "error": r.error, "method": r.method_used,
             "variant": r.variant, "modes": f"N{r.n_modes}"}
            for r in bench.finished() if r.error > 0]
    fig, (ax,) = new_figure((8.0, 5.5))
    title = (f"{bench.scene.name}: speed against error over {bench.t_final:g} s "
             f"(reference {bench.config.reference_modes} modes)")
    if not rows:
        ax.set(xlabel="wall time (s)", ylabel="relative tip error", title=title)
        ax.text(0.5, 0.5, "no finished run", ha="center", transform=ax.transAxes)
        return fig
    plot_pareto(rows, "wall_time_s", "error", label="modes", by="method", front_by="variant",
                marker_by="variant", colors=_METHOD_COLOURS, markers=_VARIANT_MARKERS, ax=ax,
                xlabel="wall time (s)", ylabel="relative tip error", title=title)
    ax.axhline(bench.config.tolerance, color="gray", linewidth=0.8, linestyle=":")
    ax.legend(fontsize=7, loc="upper right")
    return fig
