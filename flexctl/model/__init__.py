"""The physics: parameters, cantilever modes, modal matrices, model variants, exports.

Imports nothing from :mod:`flexctl.sim`, :mod:`flexctl.app` or :mod:`controllers`.

=============  ==============================================================================
module         contents
=============  ==============================================================================
``parameters`` ``Hub``, ``Beam``, ``PointMass``, ``HubBeam``: validated physical parameters
``structure``  ``Appendage``, ``Structure``: several appendages on a pinned or free hub
``layout``     ``StateLayout``: names and slices of every block of the state vector
``modes``      cantilever roots and mode shapes at quadrature points
``matrices``   the modal matrices, assembled once and cached
``variants``   ``Model``: the variants of one beam on a pinned hub, built on one assembly
``structure_matrices``, ``structure_dynamics``, ``structure_model``
               ``StructureModel``: several appendages on a pinned or free hub
``actuators``   ``ReactionWheel``, ``DCMotor``: what turns the hub
``actuated``   ``ActuatedModel``: a structure driven through an actuator
``build``      ``build_model``: the model of a system
``exports``    the model as a python-control system or a CasADi function
=============  ==============================================================================
"""

from .parameters import Beam, Hub, HubBeam, PointMass, check_real
from .structure import Appendage, Structure, as_structure
from .layout import StateLayout
from .modes import cantilever_roots, mode_shapes
from .matrices import ModalMatrices, assemble, tension
from .variants import VARIANTS, Model, SingularMassMatrixError
from .structure_model import StructureModel
from .actuators import DCMotor, ReactionWheel
from .actuated import ActuatedModel
from .build import build_model

__all__ = [
    "Beam", "Hub", "HubBeam", "PointMass", "check_real", "StateLayout", "Appendage",
    "Structure", "as_structure",
    "cantilever_roots", "mode_shapes",
    "ModalMatrices", "assemble", "tension",
    "VARIANTS", "Model", "StructureModel", "SingularMassMatrixError", "build_model",
    "ReactionWheel", "DCMotor", "ActuatedModel",
]
