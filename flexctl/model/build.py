"""``build_model``: the model of a system, of one variant, on its cantilever modes.

A :class:`~flexctl.model.parameters.HubBeam` (one beam) or a
:class:`~flexctl.model.structure.Structure` (several appendages), on a pinned or free hub,
gives a :class:`~flexctl.model.variants.Model`; with an actuator, an
:class:`~flexctl.model.actuated.ActuatedModel`.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from .actuated import actuated_model
from .actuators import as_actuator
from .checks import check_choice
from .errors import InputTypeError
from .parameters import HubBeam
from .structure import Structure
from .structure_model import structure_model
from .variant import VARIANTS, Variant
from .variants import Model

__all__ = ["build_model", "rebuild"]


#: Models kept by :func:`build_model` for its calls with equal arguments, least recently
#: used dropped first.
MODEL_MEMORY = 32
_BUILT: OrderedDict = OrderedDict()
_BUILT_LOCK = threading.Lock()


def build_model(system: HubBeam, n_modes: int = 4, variant: str = "first_order", *,
                actuator=None) -> Model:
    """Build a hub-beam-mass model.

    Parameters
    ----------
    system : HubBeam or Structure
        One beam, or any number of appendages, on a pinned or free hub.
    n_modes : int, dict or sequence of int, optional
        Number of cantilever modes ``N`` (1 to 200) of each appendage: one int for all, or
        ``{name: int}``, or one per appendage in order. Default 4.
    variant : {"first_order", "zero_order", "consistent", "exact"}, optional
        Default ``"first_order"`` (with dynamic stiffening); ``"exact"`` for large deflection.
    actuator : ReactionWheel or DCMotor, optional
        What turns the hub (:mod:`flexctl.model.actuators`): the model's input is then its
        command and its states follow the structure's (an
        :class:`~flexctl.model.actuated.ActuatedModel`). Default: an ideal hub torque.

    Returns
    -------
    Model
        Models are immutable: a call equal to one of the last :data:`MODEL_MEMORY` returns the
        same object, with what it has computed and compiled so far.

    Examples
    --------
    >>> from flexctl import Hub, Beam, HubBeam, build_model
    >>> kane = HubBeam(hub=Hub(inertia=300.0, radius=0.5),
    ...                beam=Beam(length=8.0, density=2766.67, area=7.2968e-5,
    ...                          second_moment=8.2189e-9, youngs_modulus=6.8952e10))
    >>> model = build_model(kane, n_modes=3)
    >>> model.natural_frequencies().round(2)
    array([ 2.91, 18.24, 51.08])
    """
    key = _memory_key(system, n_modes, variant, actuator)
    with _BUILT_LOCK:
        kept = _BUILT.get(key) if key is not None else None
        if kept is not None:
            _BUILT.move_to_end(key)
            return kept
    model = _build(system, n_modes, variant, actuator)
    if key is not None:
        with _BUILT_LOCK:
            model = _BUILT.setdefault(key, model)     # a thread that built it first wins
            while len(_BUILT) > MODEL_MEMORY:
                _BUILT.popitem(last=False)
    return model


def _memory_key(system, n_modes, variant, actuator):
    """The key under which an equal earlier call's model is kept: the arguments by value
    (frozen, validated dataclasses; a dict of modes by its items), or None when one of them
    is not hashable (it is then built afresh, and checked there)."""
    modes = tuple(sorted(n_modes.items())) if isinstance(n_modes, dict) else n_modes
    if isinstance(modes, list):
        modes = tuple(modes)
    # the type of each part counts too: 2 and 2.0, or True and 1, are equal but not the same
    # argument (the one may be refused where the other is not)
    key = tuple((type(part), part) for part in (system, modes, variant, actuator))
    try:
        hash(key)
    except TypeError:
        return None
    return key


def _build(system, n_modes, variant, actuator) -> Model:
    variant = Variant(check_choice("", "variant", variant, VARIANTS))
    actuator = as_actuator(actuator)
    if not isinstance(system, (HubBeam, Structure)):
        raise InputTypeError(f"system must be a HubBeam or a Structure; got "
                             f"{type(system).__name__}")
    if actuator is not None:
        return actuated_model(system, n_modes, variant, actuator)
    return structure_model(system, n_modes, variant)


def rebuild(model: Model, n_modes=None, variant: str | None = None, *, system=None) -> Model:
    """The same plant as ``model`` (its actuator included) on other modes, another variant or
    another system of the same kind.

    Parameters
    ----------
    model : Model
        A model of :func:`build_model` (a StructureModel or an ActuatedModel included).
    n_modes : int, dict or sequence of int, optional
        Modes of each appendage, as for :func:`build_model`; default the model's own
        (:attr:`~flexctl.model.variants.Model.mode_spec`).
    variant : {"first_order", "zero_order", "consistent", "exact"}, optional
        Default the model's own.
    system : HubBeam or Structure, optional
        Another system of the same kind (for an actuated model, the structure before the
        actuator changed its hub); default the model's own.
    """
    if n_modes is None and variant is None and system is not None:
        return model._rebuilt(system)
    n_modes = model.mode_spec if n_modes is None else n_modes
    variant = model.variant if variant is None else variant
    actuator = getattr(model, "actuator", None)
    if actuator is not None:
        return actuated_model(model.source if system is None else system, n_modes, variant,
                              actuator)
    return build_model(model.system if system is None else system, n_modes=n_modes,
                       variant=variant)

