"""Building a scene table's dataclass, its errors named by the table's key.

:func:`construct` is how every scene table (``[hub]``, ``[beam]``, ``[[masses]]``,
``[maneuver]``, ``[model]``, ``[simulation]``, ``[actuator]``, ``[sensors]``) becomes its
validated dataclass: a missing required key and any error of the dataclass's own checks come
back as a :class:`SceneError` under the scene key.
"""

from __future__ import annotations

import dataclasses

from controllers.spec import SceneError

__all__ = ["construct"]


def construct(cls, key: str, kwargs: dict, rename: str | None = None):
    """``cls(**kwargs)``, its error a :class:`SceneError` under the scene key ``key``; with
    ``rename``, every ``key.`` in the message becomes ``rename.`` (an appendage's beam)."""
    if dataclasses.is_dataclass(cls):
        for f in dataclasses.fields(cls):
            if f.init and f.name not in kwargs and f.default is dataclasses.MISSING \
                    and f.default_factory is dataclasses.MISSING:
                raise SceneError(f"{rename or key}.{f.name} is required")
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
