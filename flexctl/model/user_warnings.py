"""Warnings that point at the user's line, not at ours.

A warning's ``stacklevel`` counts frames from the call of :func:`warnings.warn`; ours are
raised several calls deep, at depths that vary with the path taken (a scene run, a
``simulate`` call, a design), so a fixed level names a line of the library and Python prints
that line under the message. :func:`user_stacklevel` counts the frames up to the first one
outside the ``flexctl`` and ``controllers`` packages, and :func:`warn_user` warns there.

Examples
--------
>>> import warnings
>>> with warnings.catch_warnings(record=True) as caught:
...     warnings.simplefilter("always")
...     warn_user("a note", UserWarning)
>>> caught[0].filename == __file__ or caught[0].filename.endswith(">")
True
"""

from __future__ import annotations

import functools
import os
import sys
import warnings
from pathlib import Path

__all__ = ["user_stacklevel", "warn_user"]

#: The folders of the packages whose frames a warning skips: flexctl and its sibling
#: controllers (side by side in the source tree and in an installed wheel).
_OURS = tuple(str(Path(__file__).resolve().parents[2] / name) for name in
              ("flexctl", "controllers"))


def _ours(filename: str) -> bool:
    """Whether ``filename`` lies in flexctl or controllers (an absolute name resolved once:
    a frame's file does not move; a relative one each time, as it follows the directory)."""
    return (_ours_absolute if os.path.isabs(filename) else _resolved_ours)(filename)


def _resolved_ours(filename: str) -> bool:
    try:
        path = str(Path(filename).resolve())
    except (OSError, ValueError):
        return False
    return path.startswith(_OURS)


_ours_absolute = functools.lru_cache(maxsize=1024)(_resolved_ours)


def user_stacklevel(depth: int = 1) -> int:
    """The ``stacklevel`` that makes a warning raised ``depth`` frames above this call name
    the first frame outside ``flexctl`` and ``controllers``.

    Parameters
    ----------
    depth : int, optional
        Frames between this call and the one that calls :func:`warnings.warn`: 1 when that
        function calls this one itself. Default 1.
    """
    frame, level = sys._getframe(depth), 1
    while frame is not None and _ours(frame.f_code.co_filename):
        frame, level = frame.f_back, level + 1
    return level


def warn_user(message: str, category: type = UserWarning) -> None:
    """:func:`warnings.warn` at the user's line (:func:`user_stacklevel`).

    Parameters
    ----------
    message : str
        The warning's text.
    category : type, optional
        A ``Warning`` subclass. Default ``UserWarning``.
    """
    warnings.warn(message, category, stacklevel=user_stacklevel())
