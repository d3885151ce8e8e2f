"""What a scene's ``[controller]`` table may hold: the controller kinds and their settings.

Each kind declares its settings once, in :data:`CONTROLLER_KINDS` (name, type, default, rule,
unit, one-line doc). :class:`ControllerSpec` validates a table against it, the factory
(:func:`controllers.from_spec`) reads its defaults from it, the command line lists it
(``flexctl run --help``) and :func:`settings_table` renders the table in
:mod:`controllers.factory`'s docstring (a test keeps the two equal).

A setting takes the name of the argument it sets (``hub_angle`` sets
``LQRWeights.hub_angle``, ``n_intervals`` sets ``SlewProblem.n_intervals``; the exceptions and
their reasons are in ``tests/app/test_scene_keys.py``). A renamed setting keeps its former name in
``Setting.former_names`` for one release: :func:`current_names` turns it into the new one with
a ``FutureWarning`` (shown by default, since scene authors, not programmers, read it).

The controllers package owns the kinds it builds; :mod:`flexctl.app.scenes` reads them from
here and re-exports :class:`ControllerSpec` and :class:`SceneError`, so the dependency runs
from the application layer to the controllers and never back. :class:`SceneError` lives here
because the factory is the lowest place that raises it, for a bad ``[controller]`` setting.

Examples
--------
>>> CONTROLLER_KINDS["pd"].setting("bandwidth").default
2.0
>>> ControllerSpec(kind="pd", settings={"bandwidth": -1.0})
Traceback (most recent call last):
...
controllers.spec.SceneError: controller.bandwidth (kind 'pd') must be a number > 0; got -1.0
"""

from __future__ import annotations

import math
import textwrap
import warnings
from dataclasses import dataclass, field
from numbers import Integral, Real

from flexctl.model.errors import InputValueError

# Choices of the controller kinds' settings, owned here (the registry the scene parser reads) and
# imported by the modules that act on them (controllers.feedback.lqr, reference, trajopt, nmpc).
#: Bryson values of ``LQRWeights`` lie within [1 / WEIGHT_RANGE, WEIGHT_RANGE].
WEIGHT_RANGE = 1e12
SHAPES = ("poly7", "cycloidal")
OBJECTIVES = ("effort", "time")
TRANSCRIPTIONS = ("multiple_shooting", "collocation")
MODES = ("rti", "converged")
QP_SOLVERS = ("qrqp", "osqp", "qpoases", "hpipm")
TERMINALS = ("lqr", "rest")
#: Structural filter kinds of a ``filters`` table (:mod:`controllers.feedback.structural_filters`).
FILTERS = ("notch", "roll_off", "lead_lag")

__all__ = ["FILTERS", "CONTROLLER_KEYS", "CONTROLLER_KINDS", "ControllerKind", "ControllerSpec",
           "FORMER_NAMES", "SceneError", "Setting", "current_name", "current_names",
           "settings_table", "refuse_ignored_settings", "OPEN_LOOP_KINDS"]


class SceneError(InputValueError):
    """A scene file or override is malformed; the message names the key (a ``ValueError`` and
    a :class:`flexctl.model.errors.InputError`)."""


_TYPE_NAMES = {float: "a number", int: "an integer", bool: "true or false", str: "a string",
               tuple: "an array of numbers",
               list: "an array of tables, each with kind = " + " | ".join(
                   f'"{k}"' for k in FILTERS)}


@dataclass(frozen=True, kw_only=True)
class Setting:
    """One setting of a controller kind.

    Attributes
    ----------
    name : str
        Key in the ``[controller]`` table.
    type : {float, int, bool, str, tuple, list}
        ``tuple``: an array of numbers; ``list``: an array of structural filter tables, each
        with a ``kind`` of :data:`FILTERS` (their other keys are checked where the filters
        are built).
    default : object
        Used when the table does not give the setting; ``None``: off, or chosen by the design
        as ``doc`` says.
    doc : str
        One line.
    unit : str
        SI unit of a number ("" for none).
    choices : tuple of str
        Allowed strings (``type`` str).
    minimum, maximum : float, optional
        Bounds of a number (inclusive unless ``strict``, which makes ``minimum`` exclusive).
    strict : bool
        Whether ``minimum`` is exclusive (a number must exceed it). Default False.
    former_names : tuple of str
        Names the setting had before it took the name of the constructor argument it sets;
        still accepted for one release, with a ``FutureWarning`` (:func:`current_names`).
    """

    name: str
    type: type
    default: object
    doc: str
    unit: str = ""
    choices: tuple = ()
    minimum: float | None = None
    maximum: float | None = None
    strict: bool = False
    former_names: tuple = ()

    @property
    def rule(self) -> str:
        """The rule a value must meet, in words (used in error messages and help)."""
        if self.choices:
            return "one of " + ", ".join(f'"{c}"' for c in self.choices)
        text = _TYPE_NAMES[self.type]
        if self.type is tuple:
            text += " >= 0" if self.minimum == 0 else ""
        elif self.minimum is not None and self.maximum is not None:
            text += f" in {'(' if self.strict else '['}{self.minimum:g}, {self.maximum:g}]"
        elif self.minimum is not None:
            text += f" {'>' if self.strict else '>='} {self.minimum:g}"
        elif self.type is float:
            text = "a finite number"
        return text

    @property
    def default_text(self) -> str | None:
        """:attr:`default` as written in TOML (None when there is no default value)."""
        value = self.default
        if isinstance(value, bool):
            return str(value).lower()
        if isinstance(value, str):
            return f'"{value}"'
        if isinstance(value, tuple):
            return "[" + ", ".join(f"{v:g}" for v in value) + "]"
        return None if value is None else f"{value:g}"

    def check(self, kind: str, value):
        """``value`` when it meets :attr:`rule`; raise :class:`SceneError` naming the key.

        Parameters
        ----------
        kind : str
            The controller kind whose table holds the setting (named in the message).
        value : object
            The value the ``[controller]`` table gives, as parsed from TOML.
        """
        if not self._accepts(value):
            raise SceneError(f"controller.{self.name} (kind {kind!r}) must be {self.rule}; "
                             f"got {value!r}")
        return value

    def _accepts(self, value) -> bool:
        if self.type is bool or self.type is str:
            return isinstance(value, self.type) and (not self.choices or value in self.choices)
        if self.type is tuple:
            return isinstance(value, (list, tuple)) and len(value) > 0 \
                and all(self._number_ok(v, Real) for v in value)
        if self.type is list:
            return isinstance(value, (list, tuple)) and len(value) > 0 and all(
                isinstance(v, dict) and v.get("kind") in FILTERS for v in value)
        return self._number_ok(value, Integral if self.type is int else Real)

    def _number_ok(self, value, number_type) -> bool:
        if isinstance(value, bool) or not isinstance(value, number_type) \
                or not math.isfinite(value):
            return False
        low_ok = self.minimum is None or (value > self.minimum if self.strict
                                          else value >= self.minimum)
        return low_ok and (self.maximum is None or value <= self.maximum)


@dataclass(frozen=True, kw_only=True)
class ControllerKind:
    """A controller kind: its name, one line on what it does, and its settings.

    Parameters
    ----------
    name : str
        The kind, as a scene's ``controller.kind`` names it (``"pd"``, ``"lqr"``, ...).
    doc : str
        One line on what the controller does.
    settings : tuple of Setting
        The settings its ``[controller]`` table may hold, in the order they are listed.
    """

    name: str
    doc: str
    settings: tuple

    def setting(self, name: str) -> Setting:
        """The setting called ``name``; ``KeyError`` when the kind has none by that name.

        Parameters
        ----------
        name : str
            The setting's current name (a key of the ``[controller]`` table).
        """
        for item in self.settings:
            if item.name == name:
                return item
        raise KeyError(f"controller kind {self.name!r} has no setting {name!r}")

    @property
    def names(self) -> frozenset:
        """Names of the settings."""
        return frozenset(item.name for item in self.settings)


def _weight(name, default, unit, doc, former_names=()):
    return Setting(name=name, type=float, default=default, unit=unit, doc=doc,
                   minimum=1.0 / WEIGHT_RANGE, maximum=WEIGHT_RANGE, former_names=former_names)


def _positive(name, default, unit, doc):
    return Setting(name=name, type=float, default=default, unit=unit, doc=doc, minimum=0.0,
                   strict=True)


_SAMPLE_TIME = _positive("sample_time", None, "s", "run the law sampled with a zero-order "
                         "hold at this period (default: continuous)")
_REFERENCE = Setting(name="reference", type=str, default="poly7", choices=SHAPES,
                     doc="shape of the reference slew the loop tracks")
_WEIGHTS = (
    _weight("hub_angle", 0.05, "rad", "LQR (Bryson) weight: acceptable hub angle error",
            former_names=("angle_error",)),
    _weight("hub_rate", 0.02, "rad/s", "LQR weight: acceptable hub rate error",
            former_names=("rate_error",)),
    _weight("tip_deflection", 0.01, "m", "LQR weight: acceptable tip deflection"),
    _weight("modal_energy", None, "J", "LQR weight: acceptable modal energy (default: off)"),
    _weight("torque", 1.0, "N m", "LQR weight: acceptable torque"),
    _REFERENCE,
)
_FILTERS = Setting(name="filters", type=list, default=None,
                   doc="structural filters on the sampled command (needs sample_time or "
                   "[sensors]), e.g. [{kind = \"notch\", frequency = 23.8, depth_db = 20}]; "
                   "notch: frequency (rad/s), depth_db, width; roll_off: frequency, damping; "
                   "lead_lag: zero, pole (rad/s)")
_SPIN_RATE = Setting(name="spin_rate", type=float, default=0.0, unit="rad/s",
                     doc="hub rate of the linearization the gain is designed at")
_NOISE = (
    _positive("angle_noise", 1e-3, "rad", "hub angle measurement noise (estimator)"),
    _positive("moment_noise", 0.1, "N m", "root bending moment measurement noise (estimator)"),
    _positive("process_torque", 0.1, "N m", "disturbance torque on the hub (estimator)"),
)
_TRAJOPT = (
    Setting(name="n_intervals", type=int, default=40, minimum=2,
            doc="control intervals of the transcription", former_names=("intervals",)),
    Setting(name="objective", type=str, default=None, choices=OBJECTIVES,
            doc="default: effort, or time when maneuver.duration is free"),
    Setting(name="transcription", type=str, default=None, choices=TRANSCRIPTIONS,
            doc="default: by the design model (collocation for exact)"),
    _positive("torque_rate_bound", None, "N m/s", "bound on the torque rate (default: none)"),
    _positive("tip_bound", None, "m", "bound on the tip deflection (default: none)"),
    _positive("effort_tolerance", 0.01, "", "largest relative excess of the torque holds' "
              "least effort over the converged slew's (fixed duration)"),
)
_SHAPED = "the bang-bang torque shaped at the first hub-free frequency"

_KINDS = (
    ControllerKind(name="pd", doc="PD on the hub angle about a smooth reference", settings=(
        _positive("bandwidth", 2.0, "rad/s", "closed-loop bandwidth"),
        _positive("damping_ratio", 0.9, "", "closed-loop damping ratio"),
        Setting(name="feedforward", type=bool, default=True,
                doc="add the rigid-body torque of the reference"),
        _REFERENCE, _SAMPLE_TIME, _FILTERS)),
    ControllerKind(name="lqr", doc="full-state LQR about a smooth reference",
                   settings=(*_WEIGHTS, _SPIN_RATE, _SAMPLE_TIME, _FILTERS)),
    # no sample_time: the estimator integrates continuously (ZeroOrderHold refuses it)
    ControllerKind(name="lqg", doc="LQR on a Kalman-Bucy estimate from hub angle and root "
                   "moment", settings=(*_WEIGHTS, _SPIN_RATE, *_NOISE, _FILTERS)),
    ControllerKind(name="scheduled", doc="LQR gains designed at several spin rates, "
                   "interpolated at the hub rate", settings=(
                       *_WEIGHTS,
                       Setting(name="spin_rates", type=tuple, default=(0.0, 1.0, 2.0),
                               minimum=0.0, unit="rad/s",
                               doc="design spin rates, strictly increasing"),
                       _SAMPLE_TIME, _FILTERS)),
    ControllerKind(name="trajopt", doc="optimal slew on the design model, played open loop",
                   settings=(*_TRAJOPT, _SAMPLE_TIME)),
    ControllerKind(name="trajopt+lqr", doc="optimal slew with LQR feedback about it (Bryson "
                   "weights: 5 % of the angle, 3 % of the beam length at the tip, the torque "
                   "bound)", settings=(*_TRAJOPT, _SAMPLE_TIME, _FILTERS)),
    ControllerKind(name="bang_bang", doc="rigid time-optimal at the torque bound, or the "
                   "torque that fits the duration", settings=(_SAMPLE_TIME,)),
    ControllerKind(name="zv", doc=f"ZV shaper: {_SHAPED}", settings=(_SAMPLE_TIME,)),
    ControllerKind(name="zvd", doc=f"ZVD shaper: {_SHAPED}", settings=(_SAMPLE_TIME,)),
    ControllerKind(name="nmpc", doc="nonlinear MPC on the design model, run sampled",
                   settings=(
                       Setting(name="horizon", type=int, default=20, minimum=2, maximum=500,
                               unit="samples", doc="prediction horizon"),
                       Setting(name="mode", type=str, default="rti", choices=MODES,
                               doc="real-time iteration or solved to convergence (IPOPT)"),
                       Setting(name="qp_solver", type=str, default="qrqp", choices=QP_SOLVERS,
                               doc="CasADi QP solver of the real-time iteration"),
                       Setting(name="terminal", type=str, default="lqr", choices=TERMINALS,
                               doc="terminal cost (LQR) or terminal rest constraint"),
                       Setting(name="reference", type=str, default="trajopt",
                               choices=("trajopt", "none"),
                               doc="track the optimal slew, or regulate to the target"),
                       *_TRAJOPT,
                       Setting(name="estimator", type=str, default="state",
                               choices=("state", "kalman"),
                               doc="measured state, or an extended Kalman filter on hub angle "
                               "and root moment"),
                       *_NOISE,
                       _positive("sample_time", 0.02, "s", "sample period"),
                   )),
)

#: The controller kinds, by name: what a scene's ``[controller]`` table may hold.
CONTROLLER_KINDS = {kind.name: kind for kind in _KINDS}
#: Names of the settings of each kind (derived from :data:`CONTROLLER_KINDS`).
CONTROLLER_KEYS = {name: kind.names for name, kind in CONTROLLER_KINDS.items()}
#: Former setting names still accepted, with the name each now has:
#: ``{"angle_error": "hub_angle", ...}`` (derived from :data:`CONTROLLER_KINDS`).
FORMER_NAMES = {old: item.name for kind in _KINDS for item in kind.settings
                for old in item.former_names}


def current_name(key: str) -> str:
    """The current name of setting ``key``: ``key`` itself, or for a former name
    (:data:`FORMER_NAMES`) the name it now has, with a ``FutureWarning`` that names both.

    A ``FutureWarning`` rather than a ``DeprecationWarning``, because the people who write
    scene files and ``--set`` overrides see it: Python shows it by default.

    Parameters
    ----------
    key : str
        A key of a ``[controller]`` table.
    """
    new = FORMER_NAMES.get(key)
    if new is None:
        return key
    warnings.warn(f"controller.{key} is deprecated and will be removed in the next release: "
                  f"write controller.{new} instead (same meaning)", FutureWarning, stacklevel=3)
    return new


def current_names(table: dict) -> dict:
    """``table`` (a ``[controller]`` table) with each former setting name replaced by its
    current one (:func:`current_name`, in the same place); a table that gives a setting
    under both names is refused.

    Parameters
    ----------
    table : dict
        A ``[controller]`` table, ``{key: value}`` as parsed from TOML.

    Examples
    --------
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     current_names({"kind": "lqr", "angle_error": 0.1})
    {'kind': 'lqr', 'hub_angle': 0.1}
    """
    out = {}
    for key, value in table.items():
        if key in FORMER_NAMES and FORMER_NAMES[key] in table:
            raise SceneError(f"controller.{key} is the former name of "
                             f"controller.{FORMER_NAMES[key]}; give only "
                             f"controller.{FORMER_NAMES[key]}")
        out[current_name(key)] = value
    return out


@dataclass(frozen=True, kw_only=True)
class ControllerSpec:
    """A scene's ``[controller]`` table: the controller ``kind`` and its ``settings``.

    Names and values are checked against :data:`CONTROLLER_KINDS`; :meth:`get` gives a
    setting or its default. The :mod:`controllers` package turns it into a controller
    (``controllers.from_spec``).

    Parameters
    ----------
    kind : str
        A key of :data:`CONTROLLER_KINDS` (``"pd"``, ``"lqr"``, ...).
    settings : dict, optional
        The table's other keys, ``{setting name: value}``; former names are turned into the
        current ones (:func:`current_names`). Default: every setting at its default.
    """

    kind: str
    settings: dict = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "settings", current_names(self.settings))
        if self.kind not in CONTROLLER_KINDS:
            raise SceneError(f"controller.kind must be one of {', '.join(CONTROLLER_KINDS)}; "
                             f"got {self.kind!r}")
        kind = CONTROLLER_KINDS[self.kind]
        for key, value in self.settings.items():
            if key not in kind.names:
                raise SceneError(f"unknown scene key 'controller.{key}' for kind "
                                 f"{self.kind!r}; expected one of "
                                 f"{', '.join(sorted(kind.names))}")
            kind.setting(key).check(self.kind, value)

    def get(self, name: str):
        """The value of setting ``name``: the table's, else the registry's default.

        Parameters
        ----------
        name : str
            A setting of the spec's kind (its current name); its value is in the setting's
            :attr:`Setting.unit`.
        """
        return self.settings.get(name, CONTROLLER_KINDS[self.kind].setting(name).default)


def _describe(item: Setting) -> str:
    default = item.default_text
    parts = [item.unit, "" if default is None else f"default {default}", item.rule]
    former = "".join(f" (was ``{name}``, deprecated)" for name in item.former_names)
    return f"``{item.name}`` ({'; '.join(p for p in parts if p)}): {item.doc}{former}"


def settings_table(width: int = 92) -> str:
    """The kinds and their settings as a reStructuredText simple table, ``width`` wide.

    Parameters
    ----------
    width : int, optional
        Width of the table in characters; the settings column wraps to fit. Default 92.
    """
    left = max(len(name) for name in CONTROLLER_KINDS) + 2
    rule = "=" * (left - 2) + "  " + "=" * (width - left)
    lines = [rule, f"{'kind':<{left}}settings", rule]
    described = {}          # a setting shared by several kinds is described once
    for kind in _KINDS:
        cells, shared = [kind.doc + "."], []
        for item in kind.settings:
            owner = described.setdefault(id(item), kind.name)
            if owner != kind.name and shared and shared[-1][0] == owner:
                shared[-1][1].append(item.name)
            elif owner != kind.name:
                shared.append((owner, [item.name]))
                cells.append(shared[-1])
            else:
                cells.append(_describe(item))
        cells = [cell if isinstance(cell, str) else
                 ", ".join(f"``{name}``" for name in cell[1]) + f": as for {cell[0]}"
                 for cell in cells]
        first = True
        for cell in cells:
            for part in textwrap.wrap(cell, width - left, subsequent_indent="  "):
                lines.append(f"{kind.name if first else '':<{left}}{part}".rstrip())
                first = False
    lines.append(rule)
    return "\n".join(lines)


#: Kinds that play a torque open loop: they read no sensor.
OPEN_LOOP_KINDS = ("bang_bang", "zv", "zvd", "trajopt")
#: Settings a design takes from the scene's [sensors] when it has them, with the reason.
_SENSED_SETTINGS = {
    "angle_noise": "the Kalman filter of the sensors takes each reading's noise from the "
                   "[sensors] table",
    "moment_noise": "the Kalman filter of the sensors takes each reading's noise from the "
                    "[sensors] table",
    "estimator": "with [sensors] the law always reads the Kalman estimate of their readings",
}


def refuse_ignored_settings(spec: ControllerSpec, *, sensed: bool, actuator=None) -> None:
    """Refuse, by name, a setting the scene gives that the design it asks for would not use.

    Parameters
    ----------
    spec : ControllerSpec
        The scene's ``[controller]`` table; only the settings it gives are judged (a default
        is never refused).
    sensed : bool
        True when the scene has ``[sensors]``: the loop then reads a Kalman estimate built
        from the sensors' own noise models, and the estimator settings of ``lqg`` and
        ``nmpc`` that describe measurement noise have no part in it; an open-loop kind
        reads no sensor at all. Without sensors an NMPC on the exact state
        (``estimator = "state"``) has no use for noise settings.
    actuator : object, optional
        The plant's actuator: a reaction wheel's LQR is designed at rest on the structure
        augmented with its motor lag, so a non-zero ``spin_rate`` would be ignored.

    Raises
    ------
    SceneError
        Naming the setting, the rule and the value given.
    """
    given = spec.settings
    if sensed and spec.kind in OPEN_LOOP_KINDS:
        raise SceneError(f"sensors: controller kind {spec.kind!r} plays its torque open loop "
                         "and reads no sensor; remove the [sensors] table or choose a feedback "
                         "kind (pd, lqr, lqg, scheduled, trajopt+lqr, nmpc)")
    if not sensed and spec.kind == "nmpc" and spec.get("estimator") == "state":
        for name in ("angle_noise", "moment_noise", "process_torque"):
            if name in given:
                raise SceneError(f"controller.{name} (kind 'nmpc') is not used with "
                                 "estimator = \"state\" (the NMPC reads the exact state): set "
                                 "estimator = \"kalman\" or remove it (got "
                                 f"{given[name]!r})")
    if sensed:
        for name, reason in _SENSED_SETTINGS.items():
            if name in given and not (name == "estimator" and given[name] == "kalman"):
                raise SceneError(f"controller.{name} (kind {spec.kind!r}) is not used when the "
                                 f"scene has [sensors]: {reason}; remove it (got "
                                 f"{given[name]!r})")
    wheel = getattr(actuator, "kind", None) == "reaction_wheel"
    if wheel and spec.kind in ("lqr", "lqg") and given.get("spin_rate", 0.0) != 0.0:
        raise SceneError(f"controller.spin_rate (kind {spec.kind!r}) must be 0 with a reaction "
                         "wheel: the wheel's LQR is designed at rest on the structure with the "
                         f"motor lag; got {given['spin_rate']!r}")
