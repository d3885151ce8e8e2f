"""Plots of simulation results, mode shapes and frequencies (matplotlib).

Every function returns a :class:`matplotlib.figure.Figure` and never calls ``plt.show()``.
Figures are built as bare ``Figure`` objects, not through ``pyplot``, so that scripts and the
command line can make many of them without a display and without pyplot's global state;
each function also draws into axes the caller passes. matplotlib is imported only when a
function runs, so ``import flexctl`` stays light.

This module draws; it computes nothing physical. Frequencies come from
:meth:`flexctl.Model.natural_frequencies`, mode shapes from :func:`flexctl.model.modes.mode_shapes`,
slew metrics from :func:`flexctl.sim.metrics.slew_metrics`. Sweep curves and Pareto fronts
(:func:`plot_sweep`, :func:`plot_pareto`) live in :mod:`flexctl.app.plotting_sweeps` and are
importable from here.

Examples
--------
>>> from flexctl import load_scene, run_scene
>>> from flexctl.app.plotting import plot_response
>>> result = run_scene(load_scene("kane-spinup", overrides={"simulation.t_final": "2"}))
>>> fig = plot_response(result)
>>> [ax.get_ylabel() for ax in fig.axes]
['hub angle (rad)', 'torque (N m)', 'tip deflection (m)', 'hub rate (rad/s)']
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..model.errors import InputTypeError, InputValueError
from .figures import figure_for, new_figure
# Sweep and Pareto plots live in their own module; they are importable from here too.
from .plotting_sweeps import plot_pareto, plot_sweep

__all__ = ["plot_response", "plot_mode_shapes", "plot_frequencies_vs_spin",
           "plot_tip_deflections", "plot_controller_comparison", "plot_sweep", "plot_pareto"]

#: Colours of the run status marks.
_STATUS_COLOURS = {"ok": "tab:green", "diverged": "tab:red", "singular": "tab:purple"}
#: Line styles that keep overlapping variants visible (first_order and consistent share
#: their clamped stiffness, so their curves coincide).
_VARIANT_STYLES = {"first_order": dict(linestyle="-", linewidth=2.2),
                   "zero_order": dict(linestyle="--", linewidth=1.6),
                   "consistent": dict(linestyle=":", linewidth=2.0),
                   "exact": dict(linestyle="-.", linewidth=2.0)}


def plot_response(result, fig=None, title: str | None = None, *, reference=None,
                  target_angle: float | None = None, torque_bound: float | None = None):
    """Hub angle and rate, torque and tip deflection against time.

    Parameters
    ----------
    result : SimulationResult
        A run of :func:`flexctl.simulate` (any status).
    fig : matplotlib.figure.Figure, optional
        Figure to draw into (it should be empty); default a new 8 x 7.5 in figure.
    title : str, optional
        Figure title; default the model variant, mode count and run status.
    reference : callable, optional
        The hub-angle reference a controller tracked, ``reference(t)`` (rad, ``t`` in s),
        drawn dashed on the hub angle plot with the label ``"reference"``
        (e.g. :attr:`controllers.factory.BuiltController.reference_angle`).
    target_angle : float, optional
        The slew's target hub angle, rad, drawn as a horizontal dashed line labelled
        ``"target"`` when no ``reference`` is given.
    torque_bound : float, optional
        The actuator's torque bound, N m, drawn as dashed lines at ``+-torque_bound`` on the
        torque plot (labelled ``"torque bound"``).

    Returns
    -------
    matplotlib.figure.Figure
        Three axes sharing the time axis (s): hub angle (rad, left) with hub rate (rad/s,
        right, a twin axis, the fourth of ``fig.axes``), hub torque (N m; for a free hub
        with the hub centre's travel, mm, on a fifth, twin axis) and tip deflection (m, one
        trace per appendage); with an actuator, a fourth row of its demand (the wheel's
        speed, rad/s, or the motor's voltage, V) after the others.
        A run that stopped early (status ``"diverged"`` or ``"singular"``) has its stop time
        marked on every axis and its status written on the deflection plot.
    """
    model = result.model
    rows = 4 if result.actuator_signals else 3
    if fig is None:
        fig, axes = new_figure((8.0, 2.5 * rows), nrows=rows, sharex=True)
    else:
        axes = list(fig.subplots(rows, 1, sharex=True))
    ax_angle, ax_torque, ax_tip = axes[:3]
    t = result.t

    _draw_hub(result, ax_angle)
    ax_torque.plot(t, result.torque, color="tab:gray")
    ax_torque.set_ylabel("torque (N m)")
    _draw_slew_goal(ax_angle, ax_torque, result, reference, target_angle, torque_bound)

    _draw_structure(result, ax_torque, ax_tip)
    ax_tip.set_ylabel("tip deflection (m)")
    _draw_actuator(result, axes[3:])
    axes[-1].set_xlabel("time (s)")

    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.axhline(0.0, color="black", linewidth=0.5)

    status = result.status
    colour = _STATUS_COLOURS.get(status, "tab:red")
    if status != "ok" and t.size:
        t_end = float(t[-1])
        for ax in axes:
            ax.axvline(t_end, color=colour, linestyle="--", linewidth=1.2)
        ax_tip.plot([t_end], [result.tip_deflection[-1]], marker="X", markersize=10,
                    color=colour, linestyle="none")
        ax_tip.annotate(f"{status} at t = {t_end:.4g} s", xy=(t_end, result.tip_deflection[-1]),
                        xytext=(-10, -10), textcoords="offset points", ha="right", va="top",
                        color=colour, fontweight="bold",
                        bbox=dict(boxstyle="round", facecolor="white", edgecolor=colour))
    if title is None:
        end = f"t = {float(t[-1]):.4g} s" if t.size else "no output"
        modes = (f"{model.n_modes} modes" if len(model.modes) == 1
                 else f"modes {'+'.join(map(str, model.modes))}")
        title = f"{model.variant}, {modes}: {status} ({end})"
    fig.suptitle(title, color="black" if status == "ok" else colour)
    return fig


def _draw_hub(result, ax_angle) -> None:
    """Hub angle (rad) on ``ax_angle`` and hub rate (rad/s) on a twin axis on its right."""
    ax_angle.plot(result.t, result.theta, color="tab:blue", label="hub angle")
    ax_angle.set_ylabel("hub angle (rad)")
    ax_rate = ax_angle.twinx()
    ax_rate.plot(result.t, result.theta_dot, color="tab:orange", label="hub rate")
    ax_rate.set_ylabel("hub rate (rad/s)")
    # The two scales are told apart by colour: a legend would hide data of either curve.
    ax_angle.tick_params(axis="y", labelcolor="tab:blue")
    ax_angle.yaxis.label.set_color("tab:blue")
    ax_rate.tick_params(axis="y", labelcolor="tab:orange")
    ax_rate.yaxis.label.set_color("tab:orange")


def _draw_slew_goal(ax_angle, ax_torque, result, reference, target_angle,
                    torque_bound) -> None:
    """The hub-angle reference (or else the target angle) and the torque bound, dashed and
    labelled, each axes that got one with a small legend."""
    t = result.t
    if reference is not None and t.size:
        ax_angle.plot(t, _sampled(reference, t), color="black", linestyle="--",
                      linewidth=1.0, label="reference")
    elif target_angle is not None:
        ax_angle.axhline(float(target_angle), color="black", linestyle="--", linewidth=1.0,
                         label="target")
    else:
        ax_angle = None
    if torque_bound is not None:
        for sign, label in ((1.0, "torque bound"), (-1.0, "_torque bound")):
            ax_torque.axhline(sign * float(torque_bound), color="tab:red", linestyle="--",
                              linewidth=1.0, label=label)
        # the bound lines inside the frame, not on its edge
        top = 1.1 * max(float(torque_bound), float(np.max(np.abs(result.torque), initial=0.0)))
        ax_torque.set_ylim(-top, top)
    else:
        ax_torque = None
    for ax in (ax_angle, ax_torque):
        if ax is not None:
            ax.legend(loc="lower right", fontsize="small")


def _sampled(function, t: np.ndarray) -> np.ndarray:
    """``function`` at the times ``t``: called on the array when it takes one, else point by
    point."""
    try:
        values = np.asarray(function(t), dtype=float)
    except (TypeError, ValueError):
        values = None
    if values is None or values.shape != t.shape:
        values = np.array([float(function(float(ti))) for ti in t])
    return values


def _draw_actuator(result, axes) -> None:
    """The actuator's demand against its limit, on the fourth row (if any)."""
    if not axes:
        return
    signals, actuator = result.actuator_signals, result.model.actuator
    name, limit, unit = (("wheel_speed", actuator.speed_limit, "rad/s")
                         if "wheel_speed" in signals else
                         ("motor_voltage", actuator.voltage_limit, "V"))
    axes[0].plot(result.t, signals[name], color="tab:green")
    for bound in (-limit, limit):
        axes[0].axhline(bound, color="tab:red", linestyle=":", linewidth=1.0)
    axes[0].set_ylabel(f"{name.replace('_', ' ')} ({unit})")


#: Line styles of the appendages' tip traces, in order.
TRACE_STYLES = ("-", "--", ":", "-.")
#: A free hub's travel below this fraction of its longest appendage is rounding, drawn as 0.
ROUNDING_TRAVEL = 1e-9


def _draw_structure(result, ax_torque, ax_tip) -> None:
    """One tip trace per appendage; a free hub's centre travel (mm) on a twin of the torque
    axis."""
    tips = result.tip_deflections
    for k, (name, tip) in enumerate(tips.items()):
        # a line style each: equal traces (twin arrays) stay visible on top of each other
        ax_tip.plot(result.t, tip, label=name or None,
                    linestyle=TRACE_STYLES[k % len(TRACE_STYLES)])
    if len(tips) > 1:
        ax_tip.legend(loc="best", fontsize="small")
    if result.model.layout.hub_position is not None:
        outputs = result.outputs
        travel = np.hypot(outputs["hub_x"], outputs["hub_y"])
        scale = max(app.beam.length for app in result.model.structure.appendages)
        label = "hub centre travel (mm)"
        if np.max(travel, initial=0.0) <= ROUNDING_TRAVEL * scale:
            # a symmetric structure's hub stays put: what is left is rounding, not a signal
            travel, label = np.zeros_like(travel), "hub centre travel (mm): none"
        ax_hub = ax_torque.twinx()
        ax_hub.plot(result.t, travel * 1e3, color="tab:green", linestyle="--")
        ax_hub.set_ylabel(label, color="tab:green")
        ax_hub.tick_params(axis="y", labelcolor="tab:green")


def plot_mode_shapes(model, n_shapes: int | None = None, n_points: int = 201, ax=None):
    """Cantilever mode shapes ``phi_i(x)`` used as the model's basis, over the beam.

    Parameters
    ----------
    model : Model
        Model whose basis is drawn (its beam length, mode count and point masses).
    n_shapes : int, optional
        Number of shapes to draw (1 to ``model.n_modes``); default all.
    n_points : int, optional
        Points along the beam (>= 2). Default 201.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        Shapes against the distance from the root ``x`` (m); they are dimensionless and
        tip-normalised, ``|phi_i(l)| = 2``. Point masses are marked at their positions.
    """
    from ..model.modes import mode_shapes

    n_modes = model.n_modes
    if n_shapes is None:
        n_shapes = n_modes
    if isinstance(n_shapes, bool) or not isinstance(n_shapes, (int, np.integer)) \
            or not 1 <= n_shapes <= n_modes:
        raise InputValueError(f"n_shapes must be an integer in [1, {n_modes}]; got {n_shapes!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 2:
        raise InputValueError(f"n_points must be an integer >= 2; got {n_points!r}")
    fig, ax = figure_for(ax, (7.0, 4.0))
    length = model.system.beam.length
    xi = np.linspace(0.0, 1.0, int(n_points))
    shapes = mode_shapes(n_modes, xi)[:n_shapes]
    for i, shape in enumerate(shapes, start=1):
        ax.plot(xi * length, shape, label=f"mode {i}")
    for mass in model.system.masses:
        ax.axvline(mass.position, color="black", linestyle=":", linewidth=1.0)
        ax.annotate(f"{mass.mass:g} kg", xy=(mass.position, 1.0),
                    xycoords=("data", "axes fraction"), xytext=(3, -12),
                    textcoords="offset points", fontsize="small")
    ax.axhline(0.0, color="black", linewidth=0.5)
    ax.set_xlabel("distance from the root x (m)")
    ax.set_ylabel("mode shape phi_i(x) (-)")
    ax.set_title(f"Cantilever basis, {n_shapes} of {n_modes} modes, beam length {length:g} m")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return fig


def _models_from(models, variants, n_modes):
    """The ``models`` argument of :func:`plot_frequencies_vs_spin` as ``{label: Model}``."""
    from ..model import Model, build_model
    from ..model.parameters import HubBeam

    if isinstance(models, HubBeam):
        if isinstance(variants, str):
            variants = (variants,)
        return {v: build_model(models, n_modes=n_modes, variant=v) for v in variants}
    if isinstance(models, Model):
        models = [models]
    if isinstance(models, Mapping):
        pairs = list(models.items())
    elif isinstance(models, Sequence) and not isinstance(models, str):
        pairs = [(m.variant if isinstance(m, Model) else None, m) for m in models]
    else:
        raise InputTypeError("models must be a HubBeam, a Model, a sequence of Models or a dict "
                             f"{{label: Model}}; got {type(models).__name__}")
    out = {}
    for label, m in pairs:
        if not isinstance(m, Model):
            raise InputTypeError(f"models must hold flexctl Models; got {type(m).__name__}")
        label = str(label)
        while label in out:
            label += "'"
        out[label] = m
    if not out:
        raise InputValueError("models must hold at least one Model; got none")
    return out


def plot_frequencies_vs_spin(models, spin_rates, variants=("first_order", "zero_order",
                                                           "consistent"),
                             n_modes: int = 4, n_frequencies: int = 2, ax=None):
    """Campbell-style plot: clamped natural frequencies against steady spin rate.

    Parameters
    ----------
    models : HubBeam, Model, sequence of Model or dict of {str: Model}
        A system (one model is built per entry of ``variants`` on ``n_modes`` modes), or ready
        models, labelled by their variant (or by the dict keys).
    spin_rates : array_like, shape (S,)
        Steady hub rates ``Omega``, rad/s (finite).
    variants : sequence of str, optional
        Variants to build when ``models`` is a system. Default all three.
    n_modes : int, optional
        Modes of the models built from a system. Default 4.
    n_frequencies : int, optional
        Lowest frequencies drawn per model. Default 2.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        One line per model and frequency of ``model.natural_frequencies(Omega, hub="clamped")``
        (rad/s), with the line ``omega = Omega`` for reference. A negative value is a mode that
        has lost its stiffness (zero_order above its first clamped frequency); it is drawn as
        it is returned, its magnitude being the exponential growth rate (1/s), in a shaded band
        with a note. Each line's label is ``"<label> mode <i>"``.
    """
    spin = np.asarray(spin_rates, dtype=float).reshape(-1)
    if spin.size < 2 or not np.all(np.isfinite(spin)):
        raise InputValueError(f"spin_rates must hold at least two finite rates (rad/s); "
                              f"got {spin_rates!r}")
    labelled = _models_from(models, variants, n_modes)
    n_max = min(m.n_modes for m in labelled.values())
    if isinstance(n_frequencies, bool) or not isinstance(n_frequencies, (int, np.integer)) \
            or not 1 <= n_frequencies <= n_max:
        raise InputValueError(f"n_frequencies must be an integer in [1, {n_max}]; "
                              f"got {n_frequencies!r}")
    fig, ax = figure_for(ax, (7.5, 5.0))

    lowest = 0.0
    colours = [f"C{i}" for i in range(10)]
    for k, (label, model) in enumerate(labelled.items()):
        freqs = np.array([model.natural_frequencies(w, hub="clamped")[:n_frequencies]
                          for w in spin])
        lowest = min(lowest, float(freqs.min()))
        style = _VARIANT_STYLES.get(model.variant, {})
        for i in range(n_frequencies):
            ax.plot(spin, freqs[:, i], color=colours[k % len(colours)],
                    alpha=1.0 if i == 0 else 0.6, label=f"{label} mode {i + 1}", **style)
    ax.plot(spin, np.abs(spin), color="black", linewidth=0.8, linestyle="-.",
            label="omega = Omega")
    ax.axhline(0.0, color="black", linewidth=0.8)
    if lowest < 0.0:
        ax.axhspan(lowest * 1.05, 0.0, color="tab:red", alpha=0.08)
        ax.text(0.02, 0.03, "below 0: stiffness lost, the mode grows;\n"
                "value = -(growth rate), 1/s", transform=ax.transAxes, color="tab:red",
                fontsize="small", va="bottom")
    ax.set_xlabel("spin rate Omega (rad/s)")
    ax.set_ylabel("clamped natural frequency (rad/s)")
    ax.set_title("Clamped natural frequencies against spin rate")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize="small", ncol=2)
    return fig


def _results_from(results, name: str = "results") -> dict:
    """``results`` as ``{label: SimulationResult}`` (a dict, or a sequence labelled by index)."""
    if isinstance(results, Mapping):
        pairs = [(str(k), v) for k, v in results.items()]
    elif isinstance(results, Sequence) and not isinstance(results, str):
        pairs = [(f"run {k}", v) for k, v in enumerate(results)]
    else:
        raise InputTypeError(f"{name} must be a dict {{label: SimulationResult}} or a sequence of "
                             f"results; got {type(results).__name__}")
    for label, r in pairs:
        if not all(hasattr(r, a) for a in ("t", "tip_deflection", "status", "model")):
            raise InputTypeError(f"{name}[{label!r}] must be a flexctl SimulationResult; got "
                                 f"{type(r).__name__}")
    if not pairs:
        raise InputValueError(f"{name} must hold at least one result; got none")
    return dict(pairs)


def plot_tip_deflections(results, ax=None, title: str | None = None,
                         clip_stopped: bool = True):
    """Tip deflection of several runs against time, on one axes.

    Parameters
    ----------
    results : dict of {str: SimulationResult} or sequence of SimulationResult
        Runs to overlay, labelled by the dict keys. Line style follows the model variant
        (first_order solid, zero_order dashed, consistent dotted, exact dash-dotted), colour the run.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    title : str, optional
        Axes title.
    clip_stopped : bool, optional
        When some runs reached their final time and others stopped early (diverged or
        singular), scale the deflection axis to the runs that finished, so that a diverging
        run leaves the plot instead of flattening the others. Default True.

    Returns
    -------
    matplotlib.figure.Figure
        Tip deflection (m) against time (s). A stopped run ends in an ``X`` at its stop time,
        and its legend entry says ``diverged at t = ... s`` (or ``singular``).
    """
    runs = _results_from(results)
    fig, ax = figure_for(ax, (8.0, 4.0))
    finished = []
    for k, (label, r) in enumerate(runs.items()):
        colour = f"C{k % 10}"
        style = _VARIANT_STYLES.get(r.model.variant, {})
        text = label if r.status == "ok" else f"{label}: {r.status} at t = {r.t[-1]:.3g} s"
        ax.plot(r.t, r.tip_deflection, color=colour, label=text, **style)
        if r.status != "ok" and r.t.size:
            ax.plot([r.t[-1]], [r.tip_deflection[-1]], marker="X", markersize=9,
                    color=_STATUS_COLOURS.get(r.status, "tab:red"), linestyle="none")
        elif r.t.size:
            finished.append(float(np.max(np.abs(r.tip_deflection))))
    if clip_stopped and finished and len(finished) < len(runs):
        top = 1.3 * max(finished)
        ax.set_ylim(-top, top)
    ax.axhline(0.0, color="black", linewidth=0.5)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tip deflection (m)")
    if title:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


#: Metrics drawn as bars by :func:`plot_controller_comparison`: (key, label, log scale
#: allowed). A metric that may be log-scaled is, only when its values span a decade or more
#: (``_LOG_SPAN``).
_COMPARISON_BARS = (("residual_vibration", "residual tip vibration (m)", True),
                    ("settling_time", "2 % settling time (s)", False),
                    ("peak_torque", "peak torque (N m)", False))


#: Ratio of the largest to the smallest positive bar from which a log axis is used: below it a
#: log axis covers less than a decade and makes close values (0.77 mm and 0.84 mm) look a
#: decade apart.
_LOG_SPAN = 10.0


def _metric(metrics, key):
    value = metrics.get(key) if isinstance(metrics, Mapping) else getattr(metrics, key, None)
    return np.nan if value is None else float(value)


def plot_controller_comparison(results, metrics=None, target_angle: float | None = None,
                               maneuver_end: float | None = None, torque_bound=None,
                               fig=None, title: str | None = None):
    """Closed-loop slews of several controllers side by side.

    Parameters
    ----------
    results : dict of {str: SimulationResult}
        One run per controller, labelled (e.g. by controller kind).
    metrics : dict of {str: SlewMetrics or dict}, optional
        Metrics per label (:func:`flexctl.sim.metrics.slew_metrics`); when given, a bar chart of
        residual vibration (m; on a log axis when the values span a factor of 10 or more,
        otherwise on a linear axis from zero), settling time (s) and peak torque (N m) is drawn
        next to the time histories. A settling time of ``inf`` or ``None`` (not settled) is
        drawn as a hatched bar up to the end of the run.
    target_angle : float, optional
        Commanded slew angle, rad, drawn on the hub angle plot.
    maneuver_end : float, optional
        Nominal end of the manoeuvre, s, drawn on every time plot.
    torque_bound : float, optional
        Actuator bound, N m, drawn on the torque plot (``+-``).
    fig : matplotlib.figure.Figure, optional
        Empty figure to draw into; default a new one (8 x 8 in, or 13 x 8 with metrics).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        Hub angle (rad), torque (N m) and tip deflection (m) against time (s), sharing the
        time axis, in this order in ``fig.axes``; then the metric bars, if any.
    """
    runs = _results_from(results)
    _check_comparison_metrics(metrics, runs)
    if fig is None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(13.0 if metrics else 8.0, 8.0), layout="constrained")
    grid = fig.add_gridspec(3, 2 if metrics else 1,
                            width_ratios=[1.6, 1.0] if metrics else None)
    colours = {label: f"C{k % 10}" for k, label in enumerate(runs)}
    _draw_comparison_histories(fig, grid, runs, colours, target_angle, maneuver_end,
                               torque_bound)
    if metrics:
        t_end = max(float(r.t[-1]) for r in runs.values())
        for row, (key, axis_label, log) in enumerate(_COMPARISON_BARS):
            _draw_metric_bars(fig.add_subplot(grid[row, 1]), metrics, key, axis_label, log,
                              colours, t_end)
    if title:
        fig.suptitle(title)
    return fig


def _check_comparison_metrics(metrics, runs) -> None:
    """Raise unless ``metrics`` is None or a dict holding every label of ``runs``."""
    if metrics is None:
        return
    if not isinstance(metrics, Mapping):
        raise InputTypeError(f"metrics must be a dict {{label: SlewMetrics}}; got "
                             f"{type(metrics).__name__}")
    missing = [label for label in runs if label not in metrics]
    if missing:
        raise InputValueError(f"metrics must hold every label of results; missing {missing}")


def _draw_comparison_histories(fig, grid, runs, colours, target_angle, maneuver_end,
                               torque_bound) -> None:
    """Hub angle, torque and tip deflection of every run against time, in the first column of
    ``grid``, with the target angle, the torque bound and the end of the manoeuvre."""
    ax_angle = fig.add_subplot(grid[0, 0])
    ax_torque = fig.add_subplot(grid[1, 0], sharex=ax_angle)
    ax_tip = fig.add_subplot(grid[2, 0], sharex=ax_angle)
    for label, r in runs.items():
        c = colours[label]
        ax_angle.plot(r.t, r.theta, color=c, label=label)
        ax_torque.plot(r.t, r.torque, color=c, label=label)
        ax_tip.plot(r.t, r.tip_deflection, color=c, label=label)
    if target_angle is not None:
        ax_angle.axhline(target_angle, color="black", linestyle=":", linewidth=1.0,
                         label="target")
    if torque_bound is not None:
        for sign in (1.0, -1.0):
            ax_torque.axhline(sign * float(torque_bound), color="black", linestyle=":",
                              linewidth=1.0)
    for ax, ylabel in ((ax_angle, "hub angle (rad)"), (ax_torque, "torque (N m)"),
                       (ax_tip, "tip deflection (m)")):
        if maneuver_end is not None:
            ax.axvline(maneuver_end, color="black", linestyle="--", linewidth=0.8)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    ax_tip.set_xlabel("time (s)")
    ax_angle.legend(loc="lower right", fontsize="small", ncol=2)


def _draw_metric_bars(ax, metrics, key: str, axis_label: str, log: bool, colours,
                      t_end: float) -> None:
    """One metric of every run as horizontal bars, in the order of ``colours``; a run that
    never settled gets a hatched settling-time bar up to ``t_end`` (s). With ``log``, the axis
    is logarithmic only when the bars span a factor of ``_LOG_SPAN`` or more."""
    labels = list(colours)
    positions = np.arange(len(labels))
    values = np.array([_metric(metrics[label], key) for label in labels])
    unsettled = ~np.isfinite(values)
    shown = np.where(unsettled, t_end, values) if key == "settling_time" else values
    bars = ax.barh(positions, shown, color=[colours[label] for label in labels])
    for bar, hatch in zip(bars, unsettled):
        if hatch and key == "settling_time":
            bar.set_hatch("//")
            bar.set_alpha(0.5)
    _set_value_scale(ax, shown, log)
    ax.set_yticks(positions, labels, fontsize="small")
    ax.invert_yaxis()
    ax.set_xlabel(axis_label)
    ax.grid(True, axis="x", alpha=0.3)


def _set_value_scale(ax, values, log: bool) -> None:
    """The bars' value axis: log when allowed, every finite value is positive and they span
    ``_LOG_SPAN`` or more; otherwise linear from zero. Few ticks, labelled without
    overlap (decades only on a log axis, a common power of ten on a linear one)."""
    from matplotlib.ticker import LogLocator, MaxNLocator, NullFormatter, ScalarFormatter

    finite = values[np.isfinite(values)]
    positive = finite[finite > 0]
    if (log and positive.size == finite.size and positive.size
            and positive.max() / positive.min() >= _LOG_SPAN):
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10.0, numticks=5))
        ax.xaxis.set_minor_formatter(NullFormatter())
        return
    ax.xaxis.set_major_locator(MaxNLocator(nbins=4))
    formatter = ScalarFormatter(useMathText=True)
    formatter.set_powerlimits((-2, 3))
    ax.xaxis.set_major_formatter(formatter)
    if finite.size and finite.min() >= 0:
        ax.set_xlim(left=0.0)
