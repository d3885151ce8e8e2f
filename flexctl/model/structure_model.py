"""Building the :class:`~flexctl.model.variants.Model` of a structure.

:func:`structure_model` builds the model of a :class:`~flexctl.model.structure.Structure` or
of a :class:`~flexctl.model.HubBeam` (its one-appendage structure), which
:func:`flexctl.build_model` calls. ``StructureModel`` is the same class as ``Model`` (the name
under which several appendages were modelled before one model served every structure).
"""

from __future__ import annotations

from .variants import Model, output_names, structure_model

__all__ = ["StructureModel", "output_names", "structure_model"]

#: The model of any structure: the same class as :class:`~flexctl.model.variants.Model`.
StructureModel = Model
