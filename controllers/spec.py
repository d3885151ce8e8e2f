"""What a scene's ``[controller]`` table may hold: the controller kinds and their settings.

The controllers package owns the kinds it builds; :mod:`flexctl.app.scenes` reads them from
here and re-exports :class:`ControllerSpec` and :class:`SceneError`, so the dependency runs
from the application layer to the controllers and never back. :class:`SceneError` lives here
because the factory (:func:`controllers.from_spec`) is the lowest place that raises it, for a
bad ``[controller]`` setting.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from flexctl.model.errors import InputValueError

__all__ = ["CONTROLLER_KEYS", "ControllerSpec", "SceneError"]

#: Settings each controller kind accepts in a scene's [controller] table (the factory builds
#: the controller and checks the values).
_LQR_KEYS = {"spin_rate", "angle_error", "rate_error", "tip_deflection",
             "modal_energy", "torque", "reference"}
CONTROLLER_KEYS = {
    "pd": {"bandwidth", "damping_ratio", "feedforward", "reference"},
    "lqr": _LQR_KEYS,
    "lqg": _LQR_KEYS | {"angle_noise", "moment_noise", "process_torque"},
    "scheduled": _LQR_KEYS | {"spin_rates"},
    "trajopt": {"intervals", "objective", "transcription",
                "torque_rate_bound", "tip_bound"},
    "bang_bang": set(),
    "zv": set(),
    "zvd": set(),
}
CONTROLLER_KEYS["trajopt+lqr"] = CONTROLLER_KEYS["trajopt"]
#: Nonlinear MPC (controllers.nmpc): its own settings and those of the trajectory it tracks.
CONTROLLER_KEYS["nmpc"] = {"horizon", "mode", "qp_solver", "terminal", "reference",
                           "torque_rate_bound", "tip_bound", "intervals", "objective",
                           "transcription", "estimator", "angle_noise", "moment_noise",
                           "process_torque"}
#: Every kind may run sampled with a zero-order hold (NMPC always is; default 0.02 s).
for _keys in CONTROLLER_KEYS.values():
    _keys.add("sample_time")


class SceneError(InputValueError):
    """A scene file or override is malformed; the message names the key (a ``ValueError`` and
    a :class:`flexctl.model.errors.InputError`)."""


@dataclass(frozen=True, kw_only=True)
class ControllerSpec:
    """A scene's ``[controller]`` table: the controller ``kind`` and its ``settings``.

    The :mod:`controllers` package turns it into a controller (``controllers.from_spec``).
    """

    kind: str
    settings: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.kind not in CONTROLLER_KEYS:
            raise SceneError(f"controller.kind must be one of {', '.join(CONTROLLER_KEYS)}; "
                             f"got {self.kind!r}")
        for key in self.settings:
            if key not in CONTROLLER_KEYS[self.kind]:
                raise SceneError(f"unknown scene key 'controller.{key}' for kind "
                                 f"{self.kind!r}; expected one of "
                                 f"{', '.join(sorted(CONTROLLER_KEYS[self.kind]))}")
