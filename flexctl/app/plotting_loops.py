"""Figures of the frequency-domain view of a flexible loop (:mod:`controllers.analysis.loops`).

python-control draws the Bode and pole-zero plots (``bode_plot``, ``pole_zero_plot``) into
axes of a bare :class:`matplotlib.figure.Figure` (:mod:`flexctl.app.figures`: no pyplot, safe
on the Agg backend); these functions add what a flexible structure needs on top: the flexible
modes marked at their natural frequencies, the poles against the spin rate, and the margins
of a Monte Carlo study, and the Nichols chart with an exclusion zone. They compute nothing
physical.

Examples
--------
>>> import flexctl
>>> from controllers import design_pd
>>> from controllers.analysis.loops import loop_transfer, plant_channels
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> loop = loop_transfer(model, design_pd(model, bandwidth=2.0))
>>> fig = plot_bode({"PD": loop}, natural_frequencies=model.natural_frequencies(hub="free"))
>>> len(fig.axes), fig.axes[0].get_ylabel()
(2, 'Magnitude')
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..model.errors import InputTypeError, InputValueError
from .figures import figure_for, new_figure

__all__ = ["plot_bode", "plot_nichols", "plot_pole_zero", "plot_poles_vs_spin",
           "plot_frequencies_vs_spin", "plot_robustness", "mark_modes"]

_MODE_STYLE = {"color": "0.55", "linestyle": ":", "linewidth": 0.9}


def _systems(systems) -> dict:
    """``{label: system}`` from one system or a mapping."""
    import control

    if isinstance(systems, control.LTI):
        return {systems.name or "loop": systems}
    if isinstance(systems, Mapping) and systems \
            and all(isinstance(s, control.LTI) for s in systems.values()):
        return {str(label): s for label, s in systems.items()}
    raise InputTypeError("systems must be a python-control LTI system or a non-empty dict "
                         f"{{label: LTI system}}; got {type(systems).__name__}")


def _frequencies(natural_frequencies) -> np.ndarray:
    if natural_frequencies is None:
        return np.zeros(0)
    values = np.asarray(natural_frequencies, dtype=float).reshape(-1)
    if not np.all(np.isfinite(values)):
        raise InputValueError(f"natural_frequencies must be finite (rad/s); got {values!r}")
    return values[values > 0.0]


def mark_modes(ax, natural_frequencies, *, axis: str = "x", label: bool = True) -> None:
    """Dotted lines at the flexible modes' natural frequencies (rad/s).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Axes to draw into.
    natural_frequencies : array_like, shape (N,)
        The frequencies, rad/s; non-positive ones (a mode that has lost its stiffness) are
        skipped.
    axis : {"x", "y"}, optional
        ``"x"``: vertical lines at ``w_i`` (a Bode plot); ``"y"``: horizontal lines at
        ``+-w_i`` (the imaginary axis of a pole-zero plot).
    label : bool, optional
        Write ``mode i`` next to each line, one label for a group of near-equal modes
        (``modes i, j``: within :data:`LABEL_RATIO`). Default True.
    """
    frequencies = _frequencies(natural_frequencies)
    if axis not in ("x", "y"):
        raise InputValueError(f"axis must be 'x' or 'y'; got {axis!r}")
    for w in frequencies:
        if axis == "x":
            ax.axvline(w, **_MODE_STYLE)
        else:
            for sign in (1.0, -1.0):
                ax.axhline(sign * w, **_MODE_STYLE)
    if not label:
        return
    for w, text in _mode_labels(frequencies):
        if axis == "x":
            ax.text(w, 1.0, f" {text}", transform=ax.get_xaxis_transform(),
                    rotation=90, va="top", ha="right", fontsize=7, color="0.4")
        else:
            ax.text(1.0, w, f"{text} ", transform=ax.get_yaxis_transform(),
                    va="bottom", ha="right", fontsize=7, color="0.4")


#: Modes whose frequencies lie within this ratio of the first of a group share one label
#: (a pair of near-equal modes, twin arrays' in-phase and anti-phase, would overprint).
LABEL_RATIO = 1.15


def _mode_labels(frequencies) -> list:
    """``(w, "mode i")`` or ``(w, "modes i, j")`` per group of modes within
    :data:`LABEL_RATIO` of each other, at the group's first frequency; modes numbered from 1
    as everywhere (:meth:`flexctl.model.visibility.ModalVisibility.mode_name`)."""
    groups = []
    for i, w in enumerate(frequencies, start=1):
        if groups and w <= LABEL_RATIO * groups[-1][0]:
            groups[-1][1].append(i)
        else:
            groups.append((w, [i]))
    return [(w, f"mode {members[0]}" if len(members) == 1 else
             f"modes {', '.join(map(str, members))}") for w, members in groups]


def plot_bode(systems, *, natural_frequencies=None, omega_limits=None, omega_num: int = 3000,
              axes=None, title: str | None = None):
    """Bode plot of one or more loops (or plant channels), flexible modes marked.

    Parameters
    ----------
    systems : control.LTI or dict of {str: control.LTI}
        SISO systems, e.g. :func:`~controllers.analysis.loops.loop_transfer` of several controllers.
    natural_frequencies : array_like, optional
        Flexible frequencies to mark, rad/s (e.g. ``model.natural_frequencies(hub="free")``).
    omega_limits : (float, float), optional
        Frequency range, rad/s. Default: python-control's choice.
    omega_num : int, optional
        Points of the logarithmic grid (undamped resonances are sharp). Default 3000.
    axes : sequence of two matplotlib Axes, optional
        Magnitude and phase axes to draw into; default a new figure.
    title : str, optional
        Figure title. Default none.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import control

    named = _systems(systems)
    if axes is None:
        fig, axes = new_figure((7.0, 5.5), nrows=2, sharex=True)
    else:
        axes = list(axes)
        if len(axes) != 2:
            raise InputValueError(f"axes must be two Axes (magnitude, phase); got {len(axes)}")
        fig = axes[0].figure
    responses = [control.frequency_response(sys, omega_limits=omega_limits,
                                            omega_num=omega_num) for sys in named.values()]
    # undamped poles and zeros flip the phase by 180 deg: unwrapped, it drifts by turns
    control.bode_plot(responses, ax=np.array(axes).reshape(2, 1), label=list(named),
                      title=title or "", wrap_phase=True)
    for ax in axes:
        mark_modes(ax, natural_frequencies, label=ax is axes[0])
    return fig


def plot_nichols(systems, *, natural_frequencies=None, omega_limits=None, omega_num: int = 3000,
                 margins=None, ax=None, title: str | None = None):
    """Nichols chart of one or more loops, each flexible mode marked on every curve, with an
    optional exclusion zone around the critical points.

    Parameters
    ----------
    systems : control.LTI or dict of {str: control.LTI}
        SISO loop transfers (e.g. :func:`~controllers.analysis.loops.loop_transfer`),
        continuous or sampled.
    natural_frequencies : array_like, optional
        Flexible frequencies to mark on each curve, rad/s (``mode i`` where the curve passes
        it).
    omega_limits : (float, float), optional
        Frequency range, rad/s. Default: python-control's choice.
    omega_num : int, optional
        Points of the logarithmic grid. Default 3000.
    margins : (float, float), optional
        ``(gain margin dB, phase margin deg)`` required of the loop: the rectangle of gains and
        phases within them of each critical point ``(-180 + k 360 deg, 0 dB)`` is shaded (a
        curve through it misses the requirement). Default none.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    title : str, optional
        Axes title. Default none.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> import flexctl
    >>> from controllers import design_pd
    >>> from controllers.analysis.loops import loop_transfer
    >>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    >>> loop = loop_transfer(model, design_pd(model, bandwidth=2.0))
    >>> fig = plot_nichols({"PD": loop}, natural_frequencies=model.natural_frequencies(
    ...     hub="free"), margins=(6.0, 30.0))
    >>> fig.axes[0].get_xlabel()
    'Phase [deg]'
    """
    import control
    from matplotlib.patches import Rectangle

    named = _systems(systems)
    if any(not sys.issiso() for sys in named.values()):
        raise InputValueError("plot_nichols takes SISO loops (break a MIMO loop one axis at a "
                              "time)")
    fig, ax = figure_for(ax, (7.0, 5.5))
    frequencies = _frequencies(natural_frequencies)
    for label, sys in named.items():
        response = control.frequency_response(sys, omega_limits=omega_limits,
                                              omega_num=omega_num)
        value = np.asarray(response.complex).reshape(-1)
        with np.errstate(divide="ignore"):
            gain = 20.0 * np.log10(np.abs(value))
        # the phase in one window, [-360, 0) deg: an undamped mode turns it by 180 deg at
        # once, and an unwrapped phase would drift by whole turns across the modes
        phase = np.mod(np.degrees(np.angle(value)), 360.0) - 360.0
        jumps = np.flatnonzero(np.abs(np.diff(phase)) > 90.0) + 1     # a resonance: a gap
        line, = ax.plot(np.insert(phase, jumps, np.nan), np.insert(gain, jumps, np.nan),
                        label=label)
        omega = np.asarray(response.omega)
        for w, text in _mode_labels(frequencies):
            if omega[0] <= w <= omega[-1]:
                k = int(np.argmin(np.abs(np.log(omega / w))))
                ax.plot(phase[k], gain[k], "o", color=line.get_color(), markersize=4)
                ax.annotate(text, (phase[k], gain[k]), textcoords="offset points",
                            xytext=(4, 4), fontsize=7, color="0.3")
    ax.set_xlim(-360.0, 0.0)
    control.nichols_grid(ax=ax)
    ax.set_xlabel("Phase [deg]")
    ax.set_ylabel("Magnitude [dB]")
    if title:
        ax.set_title(title)
    if len(named) > 1:
        ax.legend(loc="upper left")
    if margins is not None:
        gain_db, phase_deg = (float(v) for v in margins)
        if not (gain_db > 0 and 0 < phase_deg < 180):
            raise InputValueError(f"margins must be (gain dB > 0, phase deg in (0, 180)); got "
                                  f"{margins!r}")
        low, high = ax.get_xlim()
        for k in range(int(np.floor((low + 180.0) / 360.0)) - 1,
                       int(np.ceil((high + 180.0) / 360.0)) + 1):
            centre = -180.0 + 360.0 * k
            ax.add_patch(Rectangle((centre - phase_deg, -gain_db), 2 * phase_deg, 2 * gain_db,
                                   color="tab:red", alpha=0.15, linewidth=0))
        ax.set_xlim(low, high)
    return fig


def plot_pole_zero(systems, *, natural_frequencies=None, ax=None, xlim=None, ylim=None,
                   title: str | None = None):
    """Pole-zero map of one or more systems, flexible frequencies marked on the imaginary axis.

    Parameters
    ----------
    systems : control.LTI or dict of {str: control.LTI}
        The systems, each drawn in its colour (labelled by its key).
    natural_frequencies : array_like, optional
        Flexible frequencies to mark at ``+-j w_i``, rad/s. Default none.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    xlim, ylim : (float, float), optional
        Axis limits, 1/s (high modes lie far up the imaginary axis).
    title : str, optional
        Axes title. Default none.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import control

    named = _systems(systems)
    fig, ax = figure_for(ax, (6.0, 5.0))
    control.pole_zero_plot(list(named.values()), ax=ax, label=list(named), title=title or "")
    mark_modes(ax, natural_frequencies, axis="y")
    if xlim is not None:
        ax.set_xlim(xlim)
    if ylim is not None:
        ax.set_ylim(ylim)
    return fig


def plot_poles_vs_spin(table, *, which: str = "closed_loop", ax=None, cmap: str = "viridis",
                       title: str | None = None):
    """Poles in the complex plane, coloured by spin rate (``PolesVsSpin``).

    Parameters
    ----------
    table : controllers.analysis.loops.PolesVsSpin
        Poles and zeros at each spin rate (:func:`~controllers.analysis.loops.poles_vs_spin`).
    which : {"closed_loop", "plant"}, optional
        The closed-loop poles (default), or the plant's poles (crosses) with the hub-angle
        zeros (dots).
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    cmap : str, optional
        Colour map of the spin rate. Default ``"viridis"``.
    title : str, optional
        Axes title. Default none.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if which not in ("closed_loop", "plant"):
        raise InputValueError(f"which must be 'closed_loop' or 'plant'; got {which!r}")
    if which == "closed_loop" and table.closed_loop_poles is None:
        raise InputValueError("which='closed_loop' needs a table built with a controller "
                              "(poles_vs_spin(model, spin_rates, controller))")
    fig, ax = figure_for(ax, (6.0, 5.0))
    rates = np.asarray(table.spin_rates, dtype=float)
    layers = ([(table.closed_loop_poles, "x", "closed-loop poles")] if which == "closed_loop"
              else [(table.plant_poles, "x", "plant poles"),
                    (table.hub_angle_zeros, "o", "hub-angle zeros")])
    points = None
    for roots, marker, label in layers:
        roots = np.asarray(roots)
        colour = np.repeat(rates, roots.shape[1])
        points = ax.scatter(roots.real.ravel(), roots.imag.ravel(), c=colour, cmap=cmap,
                            marker=marker, s=22 if marker == "x" else 10, label=label)
    fig.colorbar(points, ax=ax, label="spin rate (rad/s)")
    ax.axvline(0.0, color="0.3", linewidth=0.6)
    _widen_real_axis(ax, [roots for roots, _, _ in layers])
    ax.set_xlabel("real part (1/s)")
    ax.set_ylabel("imaginary part (rad/s)")
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return fig


def _widen_real_axis(ax, root_sets) -> None:
    """Undamped roots have real parts of rounding size: keep the real axis readable."""
    roots = np.concatenate([np.asarray(r).ravel() for r in root_sets])
    roots = roots[np.isfinite(roots)]
    if roots.size and np.ptp(roots.real) < 1e-6 * max(1.0, np.max(np.abs(roots.imag))):
        half = 0.05 * max(1.0, np.max(np.abs(roots.imag)))
        ax.set_xlim(-half, half)


def plot_frequencies_vs_spin(table, *, ax=None, title: str | None = None):
    """Frequencies of the plant's poles and hub-angle zeros against the spin rate.

    The poles of an undamped plant sit at ``+-j`` its hub-free natural frequencies and the
    zeros of the collocated channel at its clamped ones; both rise with the spin rate
    (centrifugal stiffening) and stay interlaced. Drawn from the upper half-plane roots.

    Parameters
    ----------
    table : controllers.analysis.loops.PolesVsSpin
        Poles and zeros at each spin rate (:func:`~controllers.analysis.loops.poles_vs_spin`).
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    title : str, optional
        Axes title. Default none.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = figure_for(ax, (6.0, 4.5))
    rates = np.asarray(table.spin_rates, dtype=float)
    for roots, style, label in ((table.plant_poles, "-", "poles (hub free)"),
                                (table.hub_angle_zeros, "--", "hub-angle zeros (hub held)")):
        roots = np.asarray(roots)
        upper = np.where(roots.imag > 0.0, roots.imag, np.nan)
        upper = np.sort(upper, axis=1)          # NaN last: mode k in column k
        columns = [k for k in range(upper.shape[1]) if np.isfinite(upper[:, k]).any()]
        for j, k in enumerate(columns):
            ax.plot(rates, upper[:, k], style, color=f"C{j}",
                    label=label if j == 0 else None)
    ax.set_xlabel("spin rate (rad/s)")
    ax.set_ylabel("frequency (rad/s)")
    ax.set_yscale("log")
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return fig


def plot_robustness(table, x: str = "youngs_modulus_scale", y: str = "phase_margin", *,
                    ax=None, title: str | None = None):
    """Scatter of a Monte Carlo study: one margin against one dispersed factor.

    Stable samples as dots, unstable ones as red crosses (column ``closed_loop_stable``).

    Parameters
    ----------
    table : SweepResult or sequence of dict
        Rows of :class:`controllers.analysis.robustness.RobustnessTask`.
    x, y : str, optional
        Column names. Defaults ``youngs_modulus_scale`` and ``phase_margin``.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    title : str, optional
        Axes title. Default none.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from .plotting_sweeps import table_column

    xs, ys = table_column(table, x), table_column(table, y)
    stable = table_column(table, "closed_loop_stable").astype(bool)
    fig, ax = figure_for(ax, (6.0, 4.0))
    ax.scatter(xs[stable], ys[stable], s=14, label=f"stable ({stable.sum()})")
    if (~stable).any():
        ax.scatter(xs[~stable], ys[~stable], s=22, marker="x", color="tab:red",
                   label=f"unstable ({(~stable).sum()})")
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return fig
