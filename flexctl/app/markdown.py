r"""Markdown tables, written one way for every report (demo, runs, bench).

Examples
--------
>>> print("\n".join(markdown_table(["modes", "error"], [[1, "7e-3"], [2, "4e-3"]],
...                                right=[True, True])))
| modes | error |
|---:|---:|
| 1 | 7e-3 |
| 2 | 4e-3 |
"""

from __future__ import annotations

from collections.abc import Sequence

from ..model.errors import InputValueError

__all__ = ["markdown_table"]


def markdown_table(header: Sequence, rows, right: Sequence | None = None) -> list:
    """Lines of a Markdown table: the header, the alignment row, one line per row.

    Parameters
    ----------
    header : sequence
        Column headings.
    rows : iterable of sequences
        Cells of each row, written with ``str``; as many as headings.
    right : sequence of bool, optional
        Which columns are right-aligned (``---:``); default none.

    Returns
    -------
    list of str
    """
    header = [str(h) for h in header]
    right = [False] * len(header) if right is None else list(right)
    if len(right) != len(header):
        raise InputValueError(f"right must give one flag per column ({len(header)}); "
                              f"got {len(right)}")
    lines = ["| " + " | ".join(header) + " |",
             "|" + "|".join("---:" if flag else "---" for flag in right) + "|"]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return lines
