"""The physics: parameters, cantilever modes, modal matrices, model variants, exports.

Imports nothing from :mod:`flexctl.sim`, :mod:`flexctl.app` or :mod:`controllers`.

===============  ==============================================================================
module           contents
===============  ==============================================================================
``parameters``   ``Hub``, ``Beam``, ``PointMass``, ``HubBeam``: validated physical parameters
``structure``    ``Appendage``, ``Structure``: several appendages on a pinned or free hub
``layout``       ``StateLayout``: names and slices of every block of the state vector
``modes``        cantilever roots and mode shapes at quadrature points
``matrices``     the modal matrices, assembled once and cached
``variant``      ``Variant``: a variant's name and the terms it contributes
``variants``     ``Model``: the variants of one beam on a pinned hub, built on one assembly
``structure*``   ``StructureModel``: several appendages on a pinned or free hub
                 (``structure_matrices``, ``structure_dynamics``, ``structure_model``)
``actuators``    ``ReactionWheel``, ``DCMotor``: what turns the hub
``actuated``     ``ActuatedModel``: a structure driven through an actuator
``build``        ``build_model``: the model of a system
``exports``      the model as a python-control system or a CasADi function
``reduction``    ``modal_truncation``, ``balanced_truncation``: reduced design models, their error
``modal_*``      ``modal_uncertainty.with_modes``: each coupled mode's frequency and damping
                 moved, its shape kept
``discrete``     the model held over a sample: a CasADi step ``(x, u) -> x_next``
===============  ==============================================================================

Conventions
-----------
Signs
    The hub angle ``theta`` (rad) and a positive hub torque (N m) turn counter-clockwise about
    ``+z``. A beam's deflection ``w(x)`` (m) is along the hub frame's ``+y`` at the root, the
    direction a positive rotation moves it, so a positive torque first bends the beam to
    negative ``w`` (it lags).
Modal coordinates
    ``w(x, t) = sum_i phi_i(x) q_i(t)`` with cantilever modes normalised so that
    ``int_0^l phi_i phi_j dx = l delta_ij`` and ``phi_i(l) = 2 (-1)^(i+1)``: ``q_i`` is in
    metres but is not a tip deflection; the tip deflection is
    ``w(l) = 2 (q_1 - q_2 + q_3 - ...)`` (the output ``tip_deflection``).
Outputs
    ``theta`` (rad), ``theta_dot`` (rad/s), then per appendage ``tip_deflection`` (m),
    ``root_moment`` (N m, the bending moment ``EI w''(0)`` at the clamp, positive when the beam
    bends towards ``+y``) and ``tip_angle`` (rad): the line-of-sight angle of the tip seen
    from the hub centre, ``theta + w(l) / (b + l)`` (``b`` the hub radius) for the
    small-deflection variants and ``theta + atan2(p_y(l), p_x(l))`` for the exact one, not the
    beam's slope at the tip.
State order
    ``[theta, (hub_x, hub_y), q of each appendage, theta_dot, (hub_x_dot, hub_y_dot), q_dot of
    each appendage, (actuator states)]``: :attr:`Model.state_names` and :attr:`Model.layout`
    (a :class:`StateLayout`) name and slice every block; an appendage's coordinates are
    ``<name>.q1``..., and python-control signals carry ``_`` for the dot
    (:func:`~flexctl.model.exports.signal_names`).
"""

from .parameters import Beam, Hub, HubBeam, PointMass, check_real
from .structure import Appendage, Structure, as_structure
from .layout import StateLayout
from .modes import cantilever_roots, mode_shapes
from .matrices import ModalMatrices, assemble, tension
from .variant import VARIANTS, Variant
from .variants import Model, SingularMassMatrixError
from .structure_model import StructureModel
from .actuators import DCMotor, ReactionWheel
from .actuated import ActuatedModel
from .build import build_model
from .reduction import Reduction, balanced_truncation, hinf_norm, modal_truncation

__all__ = [
    "Beam", "Hub", "HubBeam", "PointMass", "check_real", "StateLayout", "Appendage",
    "Structure", "as_structure",
    "cantilever_roots", "mode_shapes",
    "ModalMatrices", "assemble", "tension",
    "VARIANTS", "Variant", "Model", "StructureModel", "SingularMassMatrixError", "build_model",
    "ReactionWheel", "DCMotor", "ActuatedModel",
    "Reduction", "modal_truncation", "balanced_truncation", "hinf_norm",
]
