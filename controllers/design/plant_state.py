"""How a controller reads the plant state it is handed: the plant's layout, the design state
and the hub angle and rate.

A controller receives the plant state ``x`` alone (the :class:`flexctl.Controller` protocol),
and the plant may carry more modes than the design model the controller was built on. The
plant's :class:`~flexctl.model.layout.StateLayout` is then the design layout's blocks on the
mode count that gives ``x`` its length (:func:`resized`); the design state is the plant's
hub states and the first modes of each block (:func:`design_rows`, from
:meth:`StateLayout.projection`). A state or gain handed over without any layout is read with
:data:`DEFAULT_LAYOUT`'s blocks (one appendage on a pinned hub).

Examples
--------
>>> layout = resized(DEFAULT_LAYOUT, 8)
>>> layout.n_modes, layout.theta_dot
(3, 4)
>>> design_rows(layout.with_modes(1), 8).tolist()
[0, 1, 4, 5]
"""

from __future__ import annotations

import functools

import numpy as np

from flexctl.model.checks import check_real
from flexctl.model.errors import InputValueError
from flexctl.model.layout import StateLayout

__all__ = ["DEFAULT_LAYOUT", "mode_count", "resized", "design_rows", "hub_state",
           "casadi_hub_state", "spatial_design_plant"]

#: The blocks of a state or gain handed over without a layout: one appendage, pinned hub.
DEFAULT_LAYOUT = StateLayout.single(1)

_HUB_STATE_RULE = ("plant state must be a vector [theta, q_1..q_N, theta_dot, "
                   "q_1_dot..q_N_dot] with N >= 1")


def mode_count(template: StateLayout, n_states: int) -> int | None:
    """Modes of ``template``'s single appendage that give a state of ``n_states`` entries
    (possibly below 1), or None when no count does.

    Parameters
    ----------
    template : StateLayout
        A layout of one appendage; its hub and first-order blocks are kept as they are.
    n_states : int
        Length of the state vector.

    Raises
    ------
    ValueError
        If ``template`` has several appendages (their mode counts are not told apart by the
        length of a state alone).
    """
    if len(template.appendages) != 1:
        raise InputValueError("a state of several appendages must come with its StateLayout; "
                              f"got a bare state of {n_states} entries for {template!r}")
    # each mode adds one coordinate and its rate
    more, odd = divmod(int(n_states) - template.n_states, 2)
    return None if odd else template.n_modes + more


@functools.lru_cache(maxsize=256)
def resized(template: StateLayout, n_states: int) -> StateLayout | None:
    """``template``'s blocks on the mode count that gives ``n_states`` states (see
    :func:`mode_count`), or None when no count of at least 1 does.

    Parameters
    ----------
    template : StateLayout
        A layout of one appendage (hashable: the result is cached).
    n_states : int
        Length of the state vector.
    """
    modes = mode_count(template, n_states)
    return None if modes is None or modes < 1 else template.with_modes(modes)


@functools.lru_cache(maxsize=256)
def design_rows(design: StateLayout, n_plant_states: int,
                owner: str = "truncate_state") -> np.ndarray:
    """Indices of the design state (layout ``design``) in a plant state of
    ``n_plant_states`` entries, read-only, shape (design.n_states,).

    Parameters
    ----------
    design : StateLayout
        Layout of the design model's state (one appendage).
    n_plant_states : int
        Length of the plant state vector.
    owner : str, optional
        Function named in the error messages. Default ``"truncate_state"``.

    Raises
    ------
    ValueError
        If no plant of ``design``'s blocks has ``n_plant_states`` states, or fewer modes than
        the design.
    """
    modes = mode_count(design, n_plant_states)
    if modes is None or n_plant_states < 2:
        raise InputValueError(f"{owner}.x must be a plant state vector of even length; got "
                              f"shape ({n_plant_states},)")
    if modes < design.n_modes:
        raise InputValueError(f"{owner}.n_design_modes must be <= the plant's {modes} modes; "
                              f"got {design.n_modes}")
    rows = design.with_modes(modes).projection(design)
    rows.setflags(write=False)
    return rows


def hub_state(x) -> tuple:
    """Hub angle (rad) and rate (rad/s) of a plant state of any mode count.

    Parameters
    ----------
    x : array_like, shape (2 N + 2,)
        One beam's plant state ``[theta, q_1..q_N, theta_dot, q_1_dot..q_N_dot]``, N >= 1.
    """
    x = np.asarray(x, dtype=float)
    layout = resized(DEFAULT_LAYOUT, x.size) if x.ndim == 1 else None
    if layout is None:
        raise InputValueError(f"{_HUB_STATE_RULE}; got shape {x.shape}")
    return float(layout.hub_angle(x)), float(layout.hub_rate(x))


def casadi_hub_state(x) -> tuple:
    """:func:`hub_state` of a CasADi state vector.

    Parameters
    ----------
    x : casadi.SX or casadi.MX, shape (2 N + 2, 1)
        One beam's plant state ``[theta, q_1..q_N, theta_dot, q_1_dot..q_N_dot]``, N >= 1.
    """
    layout = resized(DEFAULT_LAYOUT, x.numel())
    if layout is None:
        raise InputValueError(f"{_HUB_STATE_RULE}; got shape {x.shape}")
    return layout.hub_angle(x), layout.hub_rate(x)


def checked_rigid_inertia(owner: str, model_or_inertia) -> float:
    """``model.rigid_inertia`` of a flexctl Model (``J_0``, about the centre of mass for a
    free hub), or a given inertia (kg m^2, > 0).

    Parameters
    ----------
    owner : str
        Function named in the error message.
    model_or_inertia : Model or float
        A flexctl Model, or the rigid inertia itself, kg m^2 (> 0).
    """
    from flexctl.model import Model

    if isinstance(model_or_inertia, Model):
        return float(model_or_inertia.rigid_inertia)
    return check_real(owner, "inertia", model_or_inertia, minimum=0.0, strict=True)


def spatial_design_plant(owner: str, structure, n_modes, variant: str,
                         angular_velocity=(0.0, 0.0, 0.0)) -> tuple:
    """The linear plant of a spatial structure at rest (or about a steady spin) that a
    three-axis design works on, and its state names.

    Parameters
    ----------
    owner : str
        Who asks (named in errors).
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, sequence of int or mapping
        Modes per field (:func:`~flexctl.model.spatial_dynamics.spatial_modes`).
    variant : str
        One of :data:`~flexctl.model.spatial_dynamics.SPATIAL_VARIANTS`.
    angular_velocity : array_like, shape (3,), optional
        The steady spin linearised about, hub frame, rad/s. Default zero.

    Returns
    -------
    tuple
        ``(plant, names)``: the :class:`control.StateSpace` of
        :func:`~flexctl.model.spatial_plant.linearize_spatial` and its state names, ``ex, ey,
        ez`` then the spatial model's own after the quaternion (a free hub's position and
        velocity, the modal coordinates, ``wx wy wz``, the modal rates).
    """
    from flexctl.model.checks import check_choice, check_instance
    from flexctl.model.spatial_dynamics import SPATIAL_VARIANTS, spatial_equations, spatial_modes
    from flexctl.model.spatial_plant import linearize_spatial
    from flexctl.model.spatial_structure import SpatialStructure

    check_instance(owner, "structure", structure, SpatialStructure)
    n_modes = spatial_modes(owner, structure, n_modes)
    variant = check_choice(owner, "variant", variant, SPATIAL_VARIANTS)
    plant = linearize_spatial(structure, n_modes, angular_velocity=angular_velocity,
                              variant=variant)
    layout = spatial_equations(structure, n_modes, variant).layout
    c = layout.n_coordinates
    kept = list(range(c - layout.n_elastic, c)) + list(range(c, c + layout.n_speeds))
    names = ("ex", "ey", "ez", *(layout.state_names[k] for k in kept))
    if len(names) != plant.nstates:
        raise AssertionError("the design plant's states and the model's layout disagree")
    return plant, names
