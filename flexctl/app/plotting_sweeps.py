"""Plots of sweep tables: curves against a parameter, and Pareto fronts (matplotlib).

Like :mod:`flexctl.app.plotting` (which re-exports both functions), every function returns a
bare :class:`matplotlib.figure.Figure` (no pyplot state), draws into axes the caller passes,
and computes nothing physical. The data is any table: a :class:`flexctl.app.sweep.SweepResult`,
a dict of columns ``{name: values}``, or a sequence of rows ``[{name: value}, ...]`` (as a
benchmark might write them).

Examples
--------
>>> from flexctl.app.plotting_sweeps import plot_sweep
>>> table = {"mass_ratio": [0.0, 0.5, 1.0], "peak_amplitude": [0.22, 0.43, 0.51]}
>>> fig = plot_sweep(table, "mass_ratio", "peak_amplitude")
>>> fig.axes[0].get_xlabel(), len(fig.axes[0].lines)
('mass_ratio', 1)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..model.errors import InputTypeError, InputValueError
from .figures import figure_for

__all__ = ["plot_sweep", "plot_pareto", "table_column"]


def table_column(table, name: str) -> np.ndarray:
    """One column of a table, shape (rows,): float when every value is a number, else object.

    Parameters
    ----------
    table : SweepResult, dict of {str: sequence} or sequence of dict
        A sweep's result, its columns by name, or its rows.
    name : str
        The column.

    Raises
    ------
    KeyError
        If the table has no such column (the message lists the columns).
    TypeError
        If ``table`` is none of the accepted kinds.
    """
    if hasattr(table, "column") and callable(table.column):
        return table.column(name)
    if isinstance(table, Mapping):
        if name not in table:
            raise KeyError(f"column must be one of {', '.join(map(str, table))}; got {name!r}")
        values = list(table[name])
    elif isinstance(table, Sequence) and not isinstance(table, str) \
            and all(isinstance(row, Mapping) for row in table):
        names = list(dict.fromkeys(k for row in table for k in row))
        if name not in names:
            raise KeyError(f"column must be one of {', '.join(map(str, names))}; got {name!r}")
        values = [row.get(name, np.nan) for row in table]
    else:
        raise InputTypeError("table must be a SweepResult, a dict of columns or a sequence of row "
                             f"dicts; got {type(table).__name__}")
    try:
        return np.array([np.nan if v is None else v for v in values], dtype=float)
    except (TypeError, ValueError):
        return np.array(values, dtype=object)


def _names(y) -> list:
    if isinstance(y, str):
        return [y]
    if isinstance(y, Sequence) and y and all(isinstance(v, str) for v in y):
        return list(y)
    raise InputTypeError(f"y must be a column name or a non-empty list of names; got {y!r}")


def plot_sweep(table, x: str, y, *, by: str | None = None, ax=None, labels=None,
               reference=None, xlabel: str | None = None, ylabel: str | None = None,
               title: str | None = None, logx: bool = False, logy: bool = False):
    """Sweep curves: output columns against a parameter column.

    Parameters
    ----------
    table : SweepResult, dict of columns or sequence of row dicts
        The sweep's table (:func:`table_column` reads it).
    x : str
        Parameter column on the horizontal axis (rows are drawn sorted by it).
    y : str or list of str
        Output column(s), one curve each.
    by : str, optional
        A further column: one curve per distinct value (e.g. the model variant).
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    labels : dict of {str: str}, optional
        Legend text per ``y`` column; default the column names.
    reference : dict of {str: (x, y) or list of (x, y)}, optional
        Points to mark for comparison, e.g. a paper's published values
        ``{"paper 000": [(0.9, 0.263), (0.9, 0.141)]}``; drawn as black stars, one legend
        entry per key.
    xlabel, ylabel, title : str, optional
        Default ``x``, the ``y`` column name (one column) or none, and none.
    logx, logy : bool, optional
        Logarithmic axes (default linear).

    Returns
    -------
    matplotlib.figure.Figure
        One line with markers per ``y`` column (and per ``by`` value); NaN values (a run that
        stopped before the quantity existed) leave gaps.
    """
    names = _names(y)
    xs = table_column(table, x)
    if xs.dtype == object:
        raise InputTypeError(f"x column {x!r} must hold numbers; got {xs[:3].tolist()}...")
    groups = [(None, np.ones(xs.size, dtype=bool))]
    if by is not None:
        keys = table_column(table, by)
        groups = [(value, keys == value) for value in dict.fromkeys(keys.tolist())]
    fig, ax = figure_for(ax, (7.0, 4.5))
    labels = dict(labels or {})
    markers = "osD^v<>"
    for i, name in enumerate(names):
        ys = table_column(table, name)
        if ys.dtype == object:
            raise InputTypeError(f"y column {name!r} must hold numbers; got {ys[:3].tolist()}...")
        for j, (value, rows) in enumerate(groups):
            order = np.argsort(xs[rows], kind="stable")
            text = labels.get(name, name)
            if value is not None:
                # One output: the groups tell the lines apart; several: both do.
                text = f"{by} = {value}" if len(names) == 1 else f"{text}, {by} = {value}"
            ax.plot(xs[rows][order], ys[rows][order], marker=markers[i % len(markers)],
                    color=f"C{(i * len(groups) + j) % 10}", label=text)
    for label, points in (reference or {}).items():
        points = np.asarray(points, dtype=float)
        if points.shape == (2,):
            points = points[None]
        if points.ndim != 2 or points.shape[1] != 2:
            raise InputValueError(f"reference[{label!r}] must be a point (x, y) or a list of "
                                  f"points; got shape {points.shape}")
        ax.plot(points[:, 0], points[:, 1], marker="*", markersize=13, color="black",
                linestyle="none", label=label)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel or x)
    if ylabel or len(names) == 1:
        ax.set_ylabel(ylabel or names[0])
    if title:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if len(names) > 1 or by is not None or reference:
        ax.legend(loc="best", fontsize="small")
    return fig


def plot_pareto(table, x: str, y: str, *, label: str | None = None, by: str | None = None,
                front_by: str | None = None, marker_by: str | None = None, colors=None,
                markers=None, ax=None, logx: bool = True, logy: bool = True,
                xlabel: str | None = None, ylabel: str | None = None, title: str | None = None):
    """Trade-off of two costs (both minimised), with the Pareto front drawn through.

    Parameters
    ----------
    table : SweepResult, dict of columns or sequence of row dicts
        The runs' table (:func:`table_column` reads it).
    x, y : str
        The two cost columns, e.g. wall time (s) and error (m).
    label : str, optional
        Column whose values annotate the points on the front (e.g. the number of modes;
        numbers are written with ``:g``).
    by : str, optional
        Column whose distinct values get their own colour (e.g. the integrator).
    front_by : str, optional
        Column whose distinct values get a Pareto front each (e.g. the model variant), drawn
        with its own line style and labelled ``Pareto front, <value>``; default one front
        through every point.
    marker_by : str, optional
        Column whose distinct values get their own marker (e.g. the model variant).
    colors, markers : dict, optional
        Colour of each ``by`` value and marker of each ``marker_by`` value, where the default
        cycle will not do.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; default a new figure.
    logx, logy : bool, optional
        Logarithmic axes (default both: costs usually span decades). Points with a cost
        <= 0 are left out of a logarithmic axis.
    xlabel, ylabel, title : str, optional
        Axis labels and title. Default ``x``, ``y`` and none.

    Returns
    -------
    matplotlib.figure.Figure
        Every point as a dot; the non-dominated ones (:func:`flexctl.app.sweep.pareto_front`) ringed
        and joined by a staircase line labelled ``Pareto front``.
    """
    xs, ys, usable = _usable_costs(table, x, y, logx, logy)
    fig, ax = figure_for(ax, (7.0, 5.0))
    _draw_cost_points(ax, xs, ys, _column_groups(table, by, usable), by,
                      _column_groups(table, marker_by, usable), marker_by, dict(colors or {}),
                      dict(markers or {}))
    texts = None if label is None else table_column(table, label)
    for k, (value, rows) in enumerate(_column_groups(table, front_by, usable)):
        _draw_front(ax, xs, ys, rows, texts, linestyle=("-", "--", ":", "-.")[k % 4],
                    text="Pareto front" if value is None else f"Pareto front, {value}")
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel or x)
    ax.set_ylabel(ylabel or y)
    if title:
        ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return fig


def _usable_costs(table, x: str, y: str, logx: bool, logy: bool) -> tuple:
    """The cost columns ``xs, ys`` and the mask of the rows that can be drawn: both finite
    and, on a logarithmic axis, positive.

    Raises
    ------
    TypeError
        If a cost column holds anything but numbers.
    ValueError
        If no row can be drawn.
    """
    xs, ys = table_column(table, x), table_column(table, y)
    for name, values in ((x, xs), (y, ys)):
        if values.dtype == object:
            raise InputTypeError(f"column {name!r} must hold numbers; got "
                                 f"{values[:3].tolist()}...")
    usable = np.isfinite(xs) & np.isfinite(ys)
    if logx:
        usable &= xs > 0
    if logy:
        usable &= ys > 0
    if not usable.any():
        raise InputValueError(f"plot_pareto needs at least one point with finite (and, on a log "
                              f"axis, positive) {x!r} and {y!r}; got none")
    return xs, ys, usable


def _column_groups(table, column: str | None, usable) -> list:
    """``[(value, mask)]``: the usable rows of each distinct value of ``column`` in order of
    appearance, or ``[(None, usable)]`` without a column."""
    if column is None:
        return [(None, usable)]
    keys = table_column(table, column)
    return [(value, usable & (keys == value)) for value in dict.fromkeys(keys[usable].tolist())]


def _draw_cost_points(ax, xs, ys, colour_groups, by, shapes, marker_by, colors,
                      markers) -> None:
    """Every usable point, coloured by its ``by`` group and shaped by its ``marker_by`` group,
    with one legend entry per colour and per marker."""
    for j, (value, rows) in enumerate(colour_groups):
        color = colors.get(value, f"C{j % 10}")
        for k, (shape, cell) in enumerate(shapes):
            named = value is not None and (marker_by is None or k == 0)
            ax.scatter(xs[rows & cell], ys[rows & cell], color=color, s=25, alpha=0.8,
                       marker=markers.get(shape, "osD^v<>p*h"[k % 10]),
                       label=f"{by} = {value}" if named else None)
    if marker_by is not None:
        for k, (shape, _) in enumerate(shapes):
            ax.scatter([], [], color="gray", s=25, label=f"{marker_by} = {shape}",
                       marker=markers.get(shape, "osD^v<>p*h"[k % 10]))


def _draw_front(ax, xs, ys, rows, texts, *, linestyle: str, text: str) -> None:
    """The Pareto front of the points ``rows`` (a mask): a staircase labelled ``text`` through
    the ringed non-dominated points, each annotated with its entry of ``texts`` if given."""
    from .sweep import pareto_front

    front = np.zeros(xs.size, dtype=bool)
    front[rows] = pareto_front(xs[rows], ys[rows])
    order = np.argsort(xs[front])
    fx, fy = xs[front][order], ys[front][order]
    ax.step(fx, fy, where="post", color="black", linewidth=1.2, linestyle=linestyle,
            label=text)
    ax.scatter(fx, fy, s=90, facecolors="none", edgecolors="black", linewidths=1.2)
    if texts is not None:
        for px, py, note in zip(fx, fy, texts[front][order]):
            note = f"{note:g}" if isinstance(note, (int, float, np.number)) else str(note)
            ax.annotate(note, xy=(px, py), xytext=(5, 4), textcoords="offset points",
                        fontsize="x-small")
