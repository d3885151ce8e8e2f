"""The bare matplotlib figure every plotting function starts from.

A :class:`matplotlib.figure.Figure` with constrained layout, no pyplot and no global state;
matplotlib is imported only when a figure is made, so importing the plotting modules stays
light.
"""

from __future__ import annotations

__all__ = ["new_figure", "figure_for"]


def new_figure(figsize, nrows=1, sharex=False):
    """A figure of ``nrows`` stacked axes; returns ``(figure, list of axes)``.

    Parameters
    ----------
    figsize : tuple of float
        ``(width, height)``, inches.
    nrows : int, optional
        Number of axes, stacked in one column. Default 1.
    sharex : bool, optional
        The axes share their x axis. Default False.

    Examples
    --------
    >>> fig, axes = new_figure((4.0, 3.0), nrows=2)
    >>> len(axes)
    2
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(nrows, 1, sharex=sharex, squeeze=False)[:, 0]
    return fig, list(axes)


def figure_for(ax, figsize):
    """``(figure, ax)``: the figure of the given axes, or a new one-axes figure when ``ax`` is
    None.

    Parameters
    ----------
    ax : matplotlib.axes.Axes or None
        Axes to draw on.
    figsize : tuple of float
        ``(width, height)`` of a new figure, inches.
    """
    if ax is None:
        fig, (ax,) = new_figure(figsize)
        return fig, ax
    return ax.figure, ax
