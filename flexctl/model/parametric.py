"""Physical parameters as symbols: the dynamics ``f(x, u, p)`` for robust design, estimation
and identification.

A parameter is named by its scene key: ``"hub.inertia"``, ``"hub.friction"``,
``"beam.youngs_modulus"``, ``"beam.density"``, ``"masses[0].mass"``, ``"masses[0].position"``;
on a :class:`~flexctl.model.Structure`, ``"appendages[1].beam.second_moment"``,
``"appendages[0].masses[0].mass"``, ``"appendages[0].angle"`` (and the one-beam keys for its
first appendage when it has only one). Every number of the model's system is one.

:func:`parametric_casadi` (``model.casadi(parameters=[...])``) gives ``f(x, u, p)``, ``p`` the
listed parameters in order, as the first-order expansion in ``p`` about the nominal values

    f(x, u, p) = f(x, u, p_0) + sum_i  df/dp_i(x, u, p_0) (p_i - p_0,i)

with ``df/dp_i`` the central difference of two models rebuilt at ``p_0,i (1 +- 1e-4)`` (a
parameter at 0: ``+- 1e-4`` in its unit; one-sided where the lower value is not allowed, e.g. a
friction of 0): exact at the nominal values, differentiable in ``p`` (its derivative there the
model's, to about ``1e-8`` relative), and linear in ``p`` away from them. For identification
over large changes, rebuild the model at the new values (:func:`with_parameter`).
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

from .errors import InputTypeError, InputValueError

__all__ = ["parameter_value", "parameter_values", "with_parameter", "parametric_casadi",
           "RELATIVE_STEP"]

#: Relative step of the central differences in the parameters.
RELATIVE_STEP = 1e-4
_KEY = re.compile(r"[a-z_]+(\[\d+\])?(\.[a-z_]+(\[\d+\])?)*")
_PART = re.compile(r"([a-z_]+)(?:\[(\d+)\])?")


def _parts(system, key) -> list:
    """``[(field, index or None), ...]`` of ``key`` on ``system`` (aliases resolved)."""
    from .structure import Structure

    if not isinstance(key, str):
        raise InputTypeError(f"a parameter must be named by its scene key (a string such as "
                             f"'beam.youngs_modulus'); got {type(key).__name__} {key!r}")
    if not _KEY.fullmatch(key):
        raise InputValueError(f"parameter {key!r} is not a scene key such as 'hub.inertia', "
                              "'beam.youngs_modulus' or 'masses[0].mass'")
    parts = [(m.group(1), None if m.group(2) is None else int(m.group(2)))
             for m in _PART.finditer(key)]
    if isinstance(system, Structure) and parts[0][0] in ("beam", "masses", "angle", "radius"):
        if len(system.appendages) != 1:
            raise InputValueError(f"parameter {key!r}: the structure has "
                                  f"{len(system.appendages)} appendages; name one, e.g. "
                                  f"'appendages[0].{key}'")
        parts = [("appendages", 0)] + parts
    return parts


def _step_into(owner, name, index, key):
    if not dataclasses.is_dataclass(owner) or name not in {f.name for f in
                                                            dataclasses.fields(owner)}:
        raise InputValueError(f"parameter {key!r}: {type(owner).__name__} has no {name!r}")
    value = getattr(owner, name)
    if index is None:
        return value
    if not isinstance(value, tuple) or not 0 <= index < len(value):
        count = len(value) if isinstance(value, tuple) else 0
        raise InputValueError(f"parameter {key!r}: {name} has {count} entries; index {index} "
                              "is outside")
    return value[index]


def parameter_value(system, key: str) -> float:
    """The nominal value of parameter ``key`` of ``system`` (its scene key's unit).

    Parameters
    ----------
    system : HubBeam or Structure
        The system whose number is read.
    key : str
        Scene key of the parameter, e.g. ``"beam.youngs_modulus"``, ``"masses[0].position"``
        or ``"appendages[1].beam.second_moment"`` (module docstring).
    """
    value = system
    for name, index in _parts(system, key):
        value = _step_into(value, name, index, key)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
        raise InputValueError(f"parameter {key!r} is not a number ({type(value).__name__})")
    if value is None:
        raise InputValueError(f"parameter {key!r} is not set")
    return float(value)


def with_parameter(system, key: str, value: float):
    """``system`` with parameter ``key`` set to ``value`` (validated as the system is).

    Parameters
    ----------
    system : HubBeam or Structure
        The system to change (it is not modified: a changed copy is returned).
    key : str
        Scene key of the parameter, e.g. ``"beam.youngs_modulus"``, ``"masses[0].position"``
        or ``"appendages[1].beam.second_moment"`` (module docstring).
    value : float
        The new value, in the unit of the scene key.
    """
    parts = _parts(system, key)
    parameter_value(system, key)

    def put(owner, rest):
        (name, index), rest = rest[0], rest[1:]
        current = getattr(owner, name)
        if index is None:
            new = float(value) if not rest else put(current, rest)
        else:
            items = list(current)
            items[index] = put(items[index], rest) if rest else float(value)
            new = tuple(items)
        return dataclasses.replace(owner, **{name: new})

    return put(system, parts)


def _system_of(model):
    return getattr(model, "source", None) or model.system


def parameter_values(model, parameters) -> np.ndarray:
    """The nominal values of ``parameters`` of ``model``'s system, shape (P,).

    Parameters
    ----------
    model : Model
        Any flexctl model; for an actuated model, the system before the actuator changed its
        hub (:attr:`~flexctl.model.actuated.ActuatedModel.source`).
    parameters : list or tuple of str
        Scene keys of the parameters, in order (module docstring).
    """
    if isinstance(parameters, str) or not isinstance(parameters, (list, tuple)):
        raise InputTypeError("parameters must be a list of scene keys, e.g. "
                             f"['beam.youngs_modulus', 'hub.inertia']; got {parameters!r}")
    system = _system_of(model)
    return np.array([parameter_value(system, key) for key in parameters], dtype=float)


def parametric_casadi(model, parameters, outputs: bool = False) -> object:
    """``f(x, u, p) -> xdot`` (module docstring), named inputs ``x``, ``u``, ``p``; with
    ``outputs``, ``h(x, u, p) -> y`` (the model's named outputs, e.g. the root moment, which
    scales with the bending stiffness) expanded the same way.

    Parameters
    ----------
    model : Model
        Any flexctl model.
    parameters : list or tuple of str
        Scene keys of the parameters ``p``, in order, each named once.
    outputs : bool, optional
        Expand the outputs ``h`` instead of the dynamics ``f``. Default False.

    Raises
    ------
    InputTypeError, InputValueError
        For a parameter that is not a number of the model's system, named twice, or whose
        nominal neighbourhood the system refuses.
    """
    import casadi as ca

    nominal = parameter_values(model, parameters)
    if not parameters:
        raise InputValueError("parameters must name at least one parameter")
    if len(set(parameters)) != len(parameters):
        raise InputValueError(f"parameters names one twice: {list(parameters)}")
    system = _system_of(model)
    of = (lambda m: m.casadi_outputs()) if outputs else (lambda m: m.casadi())
    f0 = of(model)
    x, u, p = ca.SX.sym("x", model.n_states), ca.SX.sym("u", f0.size1_in(1)), \
        ca.SX.sym("p", len(parameters))
    value = f0(x, u)
    for i, key in enumerate(parameters):
        step = RELATIVE_STEP * (abs(nominal[i]) or 1.0)
        upper = model._rebuilt(with_parameter(system, key, nominal[i] + step))
        try:
            lower = model._rebuilt(with_parameter(system, key, nominal[i] - step))
            low, width = of(lower)(x, u), 2.0 * step
        except (InputTypeError, InputValueError, ValueError):
            low, width = value, step
        value = value + (of(upper)(x, u) - low) / width * (p[i] - nominal[i])
    name = "outputs" if outputs else "parametric"
    return ca.Function(f"flexctl_{model.variant}_{name}", [x, u, p], [value],
                       ["x", "u", "p"], ["y" if outputs else "xdot"])
