"""Building a scene table's dataclass, its errors named by the table's key.

:func:`construct` is how every scene table (``[hub]``, ``[beam]``, ``[[masses]]``,
``[maneuver]``, ``[model]``, ``[simulation]``, ``[actuator]``, ``[sensors]``) becomes its
validated dataclass: a missing required key and any error of the dataclass's own checks come
back as a :class:`SceneError` under the scene key. A missing key is described by the first
sentence of its entry in the dataclass's numpydoc Parameters, the one place its meaning and
unit are written: ``masses.0.position is required: distance d_k from the beam root, m, ...``.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
from pathlib import Path

from controllers.spec import SceneError

__all__ = ["construct", "parameter_doc", "read_table_file", "table_of", "check_table_keys"]


def construct(table, key: str, kwargs: dict, rename: str | None = None):
    """``table(**kwargs)``, its error a :class:`SceneError` under the scene key ``key``.

    Parameters
    ----------
    table : type or callable
        The table's dataclass (``Hub``, ``Beam``, ...); a required key it lacks is reported
        with its meaning (:func:`parameter_doc`). Any other callable is called as it is.
    key : str
        The table's scene key (``"hub"``, ``"masses.0"``), prefixing every message.
    kwargs : dict
        The table's entries, passed as keywords.
    rename : str, optional
        Key that every ``key.`` in a message becomes (an appendage's beam).
    """
    if dataclasses.is_dataclass(table):
        for f in dataclasses.fields(table):
            if f.init and f.name not in kwargs and f.default is dataclasses.MISSING \
                    and f.default_factory is dataclasses.MISSING:
                meaning = parameter_doc(table, f.name)
                raise SceneError(f"{rename or key}.{f.name} is required"
                                 + (f": {meaning}" if meaning else ""))
    try:
        return table(**kwargs)
    except SceneError:
        raise
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        if rename is not None:
            msg = msg.replace(f"{key}.", f"{rename}.")
            raise SceneError(msg if msg.startswith(rename) else f"{rename}: {msg}") from None
        for prefix in ("hub.", "beam.", "mass.", "maneuver.", f"{key}."):
            if msg.startswith(prefix):
                msg = msg[len(prefix):]
        raise SceneError(f"{key}.{msg}") from None


def parameter_doc(table, name: str) -> str:
    """The first sentence of parameter ``name`` in ``table``'s numpydoc Parameters, as plain
    text (no reST markup; a capitalised first word in lower case); ``""`` when undocumented.

    Parameters
    ----------
    table : type
        A class with a numpydoc docstring (a scene table's dataclass).
    name : str
        The parameter.

    Examples
    --------
    >>> from flexctl.model.parameters import Beam
    >>> parameter_doc(Beam, "length")
    'length l, m (> 0)'
    """
    doc = inspect.getdoc(table) or ""
    entry = re.search(rf"^{re.escape(name)} :[^\n]*\n((?:[ \t]+\S[^\n]*(?:\n|$))+)", doc,
                      re.MULTILINE)
    if entry is None:
        return ""
    text = " ".join(entry.group(1).split())
    text = re.sub(r":\w+:`~?([^`]+)`", r"\1", text).replace("``", "")
    sentence = re.split(r"(?<=\.)\s+(?=[A-Z(])", text)[0].rstrip(".")
    first, _, rest = sentence.partition(" ")
    if first.replace("-", "").isalpha() and first[0].isupper() and first[1:].islower():
        sentence = f"{first.lower()} {rest}".rstrip()
    return sentence


def read_table_file(file, base_dir, columns: tuple, max_bytes: int) -> tuple:
    """``(where, lines)``: the data lines of a CSV file named by a scene's ``maneuver.file``,
    after its header ``columns``, each with its line number.

    Parameters
    ----------
    file : str
        The path as the scene gives it; a relative one is read from ``base_dir``.
    base_dir : str or path-like or None
        The scene file's directory (default the working directory).
    columns : tuple of str
        The header's cells, lower case (``("t", "torque")``).
    max_bytes : int
        The largest file read, bytes.

    Returns
    -------
    where : str
        How messages name the file (``maneuver.file 'torque.csv'``).
    lines : list of (int, str)
        The non-blank lines after the header, with their line numbers.

    Raises
    ------
    SceneError
        For a missing, unreadable, too large or non-UTF-8 file, or another header.
    """
    wanted = ", ".join(columns)
    if not isinstance(file, str) or not file.strip() or "\0" in file:
        raise SceneError(f"maneuver.file must be the path of a CSV file (columns {wanted}); "
                         f"got {file!r:.80}")
    path = Path(file) if Path(file).is_absolute() else Path(base_dir or ".") / file
    where = f"maneuver.file {file!r}"
    try:
        if not path.is_file():
            raise SceneError(f"{where} does not exist (a relative path is read from the scene "
                             f"file's directory: {str(path)!r})")
        if path.stat().st_size > max_bytes:
            raise SceneError(f"{where} must be at most {max_bytes} bytes; got "
                             f"{path.stat().st_size}")
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except OSError as exc:
        raise SceneError(f"{where} cannot be read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise SceneError(f"{where} must be UTF-8 text (CSV); byte {exc.object[exc.start]:#04x} "
                         f"at offset {exc.start} is not UTF-8") from None
    header = tuple(cell.strip().lower() for cell in lines[0].split(",")) if lines else ()
    if header != tuple(columns):
        raise SceneError(f"{where} must start with the header line '{wanted}'; got "
                         f"{(lines[0] if lines else '')[:80]!r}")
    return where, [(number, line) for number, line in enumerate(lines[1:], start=2)
                   if line.strip()]


def table_of(data: dict, name: str, required: bool = True) -> dict:
    """The scene's table ``name`` (``{}`` when absent and not ``required``).

    Parameters
    ----------
    data : dict
        The scene's tables.
    name : str
        The table's key.
    required : bool, optional
        Refuse a scene without it. Default True.

    Raises
    ------
    SceneError
        For a missing required table, or a key that is not a table.
    """
    table = data.get(name)
    if table is None:
        if required:
            raise SceneError(f"scene is missing the [{name}] table")
        return {}
    if not isinstance(table, dict):
        raise SceneError(f"scene key {name!r} must be a table; got {type(table).__name__}")
    return table


def check_table_keys(where: str, table, allowed) -> None:
    """Refuse a scene table ``where`` that is not a table or holds a key not in ``allowed``.

    Parameters
    ----------
    where : str
        The table's scene key (``"hub"``, ``"appendages.0"``).
    table : object
        The table as read.
    allowed : collection of str
        Its keys.

    Raises
    ------
    SceneError
        Naming the unknown key and the allowed ones.
    """
    if not isinstance(table, dict):
        raise SceneError(f"scene key {where!r} must be a table")
    for sub in table:
        if sub not in allowed:
            raise SceneError(f"unknown scene key '{where}.{sub}'; expected one of "
                             f"{', '.join(sorted(allowed))}")
