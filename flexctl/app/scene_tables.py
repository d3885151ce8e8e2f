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

from controllers.spec import SceneError

__all__ = ["construct", "parameter_doc"]


def construct(cls, key: str, kwargs: dict, rename: str | None = None):
    """``cls(**kwargs)``, its error a :class:`SceneError` under the scene key ``key``.

    Parameters
    ----------
    cls : type or callable
        The table's dataclass (``Hub``, ``Beam``, ...); a required key it lacks is reported
        with its meaning (:func:`parameter_doc`). Any other callable is called as it is.
    key : str
        The table's scene key (``"hub"``, ``"masses.0"``), prefixing every message.
    kwargs : dict
        The table's entries, passed as keywords.
    rename : str, optional
        Key that every ``key.`` in a message becomes (an appendage's beam).
    """
    if dataclasses.is_dataclass(cls):
        for f in dataclasses.fields(cls):
            if f.init and f.name not in kwargs and f.default is dataclasses.MISSING \
                    and f.default_factory is dataclasses.MISSING:
                meaning = parameter_doc(cls, f.name)
                raise SceneError(f"{rename or key}.{f.name} is required"
                                 + (f": {meaning}" if meaning else ""))
    try:
        return cls(**kwargs)
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


def parameter_doc(cls, name: str) -> str:
    """The first sentence of parameter ``name`` in ``cls``'s numpydoc Parameters, as plain
    text (no reST markup; a capitalised first word in lower case); ``""`` when undocumented.

    Examples
    --------
    >>> from flexctl.model.parameters import Beam
    >>> parameter_doc(Beam, "length")
    'length l, m (> 0)'
    """
    doc = inspect.getdoc(cls) or ""
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
