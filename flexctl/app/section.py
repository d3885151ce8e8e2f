"""A part of the demo report, and how its figures are saved.

:class:`Section` is what each demo section function returns and
:func:`flexctl.app.report.write_demo_report` turns into Markdown.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..sim.atomic_files import atomic_file

__all__ = ["Section", "save_figure"]


@dataclass(frozen=True)
class Section:
    """A part of the demo report.

    Attributes
    ----------
    title : str
    paragraphs : tuple of str
        Markdown text, one paragraph each.
    table : tuple
        ``(header, rows)``: column names and rows of cells (already formatted), or ``()``.
    images : tuple of (str, Path)
        ``(caption, path)`` of each figure.
    files : tuple of Path
        Data written (CSV), linked from the report.
    """

    title: str
    paragraphs: tuple = ()
    table: tuple = ()
    images: tuple = ()
    files: tuple = field(default=())


def save_figure(fig, path: Path) -> Path:
    """Save ``fig`` as a PNG of the demo's resolution at ``path``, whole or not at all
    (through a temporary file); return ``path``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure to save.
    path : Path
        File written.
    """
    with atomic_file(path) as partial:
        fig.savefig(partial, dpi=90)
    return path
