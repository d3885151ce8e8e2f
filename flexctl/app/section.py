"""A part of the demo report, and how its figures are saved.

:class:`Section` is what each demo section function returns and
:func:`flexctl.app.report.write_demo_report` turns into Markdown.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..sim.atomic_files import atomic_file

__all__ = ["Section", "save_figure", "save_table"]


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


def save_table(header, rows, path: Path) -> Path:
    """Write a section's table as CSV at ``path``, whole or not at all; return ``path``.

    Parameters
    ----------
    header : sequence of str
        Column names.
    rows : sequence of sequence of str
        Cells, already formatted (no commas in them).
    path : Path
        File written.
    """
    from ..sim.atomic_files import write_atomic

    write_atomic(path, ",".join(header) + "\n" + "".join(",".join(row) + "\n" for row in rows))
    return path
