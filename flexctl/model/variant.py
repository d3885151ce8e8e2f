"""The model variants as small objects: each says which terms it contributes (:ref:`sections 4
<variants>` and :ref:`4.5 <sec-exact>` of the model), and code asks it about those terms instead
of comparing its name.

============  ===============================  ==================  ============================
variant       beam stiffness at spin rate w    hub inertia         geometry
============  ===============================  ==================  ============================
first_order   ``K_ff - w^2 (M_ff - K_g)``      ``J_0``             small deflection
zero_order    ``K_ff - w^2 M_ff``              ``J_0``             small deflection
consistent    ``K_ff - w^2 (M_ff - K_g)``      ``J_0 + q^T D q``   small deflection
exact         first_order's, linearised        ``M(q)``            exact (slope-angle beam)
============  ===============================  ==================  ============================

A :class:`Variant` is a ``str`` (``"first_order"``, ...), so it is written, compared, printed
and stored as its name; its properties are the terms it contributes.

Examples
--------
>>> from flexctl.model.variant import Variant
>>> Variant("consistent").quadratic_inertia, Variant("consistent") == "consistent"
(True, True)
>>> Variant("zero_order").dynamic_stiffening
False
"""

from __future__ import annotations

import numpy as np

from .errors import InputTypeError, InputValueError
from .exact import EXACT_MAX_MODES

__all__ = ["Variant", "VARIANTS", "MAX_MODES", "EXACT_CURL", "check_reach",
           "model_reach"]

#: The variants, from the usual design model to the most faithful one.
VARIANTS = ("first_order", "zero_order", "consistent", "exact")
#: Most cantilever modes per appendage of the small-deflection variants.
MAX_MODES = 200
#: The exact variant's reach: its modal tip ``phi(l)^T q``, the integral of the slope angle over
#: the beam, may pass this many beam lengths before the run stops as "diverged": a mean slope of
#: 2 rad is a beam curled back on itself, beyond what a few modes describe.
EXACT_CURL = 2.0

# name: (dynamic stiffening, quadratic hub inertia, exact geometry)
_TERMS = {
    "first_order": (True, False, False),
    "zero_order": (False, False, False),
    "consistent": (True, True, False),
    "exact": (True, False, True),
}


class Variant(str):
    """A model variant: its name, and the terms it contributes.

    Parameters
    ----------
    name : str
        One of :data:`VARIANTS`.

    Raises
    ------
    InputValueError, InputTypeError
        For a name that is not one of :data:`VARIANTS`.
    """

    __slots__ = ()

    def __new__(cls, name):
        if isinstance(name, Variant):
            return name
        if not isinstance(name, str):
            raise InputTypeError(f"variant must be one of {', '.join(VARIANTS)}; got "
                                 f"{name!r}"[:300])
        if name not in _TERMS:
            raise InputValueError(f"variant must be one of {', '.join(VARIANTS)}; got "
                                  f"{name!r}"[:300])
        return super().__new__(cls, name)

    def __reduce__(self):
        return Variant, (str(self),)

    @property
    def dynamic_stiffening(self) -> bool:
        """Whether the spin stiffens the beam (the geometric stiffness ``K_g``): the beam's
        stiffness at spin rate ``w`` is ``K_ff - w^2 D``, ``D = M_ff - K_g``; without it
        (zero_order) ``K_ff - w^2 M_ff``, which loses its stiffness above the first clamped
        frequency."""
        return _TERMS[self][0]

    @property
    def quadratic_inertia(self) -> bool:
        """Whether the hub inertia grows with the deflection, ``J(q) = J_0 + q^T D q``, with its
        Coriolis term ``2 w q^T D q_t`` (consistent): energy-consistent, and the effective hub
        inertia may reach zero (a singular mass matrix) on a light hub."""
        return _TERMS[self][1]

    @property
    def exact(self) -> bool:
        """Whether positions and velocities are geometrically exact (the slope-angle beam of
        :ref:`section 4.5 of the model <sec-exact>`, its mass matrix ``M(q)`` by quadrature):
        the variant for large deflection, with a regular mass matrix for a massless hub."""
        return _TERMS[self][2]

    @property
    def reach(self) -> float:
        """How far a modal tip ``phi(l)^T q`` may go, in beam lengths: 1 for the
        small-deflection variants, which leave their range there; :data:`EXACT_CURL` for the
        exact beam, which cannot, and stops when its mean slope passes that many radians."""
        return EXACT_CURL if self.exact else 1.0

    @property
    def max_modes(self) -> int:
        """Most modes per appendage this variant takes (the exact geometry grows as the square
        of the modes times the quadrature points)."""
        return EXACT_MAX_MODES if self.exact else MAX_MODES

    def spin_matrix(self, matrices):
        """The matrix that the square of the spin rate takes from the beam's stiffness:
        ``D = M_ff - K_g`` with dynamic stiffening, ``M_ff`` without.

        Parameters
        ----------
        matrices : ModalMatrices or StructureMatrices
            The model's modal matrices.

        Returns
        -------
        ndarray, shape (N, N)
            kg.
        """
        return matrices.D if self.dynamic_stiffening else matrices.M_ff


def model_reach(model) -> np.ndarray:
    """Largest ``|phi_k(l_k)^T q_k|`` the model covers for each appendage, m, shape (K,): the
    beam length for the small-deflection variants, which leave their range there;
    :data:`EXACT_CURL` lengths for the exact beam, which cannot, and stops only when its mean
    slope passes ``EXACT_CURL`` rad.

    Parameters
    ----------
    model : Model
        Any flexctl model: its beam lengths and variant.
    """
    return np.asarray(model.lengths, dtype=float) * model.variant.reach


def check_reach(model, x, owner: str = "", name: str = "x0") -> None:
    """Refuse a state whose modal tip is already beyond the range of the model's variant
    (:attr:`~flexctl.model.variant.Variant.reach` beam lengths): :func:`flexctl.simulate` and
    :meth:`Model.linearize` take the same states.

    Parameters
    ----------
    model : Model
        The model the state is for.
    x : ndarray, shape (n,)
        The state, in :attr:`Model.layout` order.
    owner : str, optional
        What the message starts with (e.g. ``"linearize: "``).
    name : str, optional
        The argument's name in the message. Default ``"x0"``.

    Raises
    ------
    InputValueError
        Naming the appendage, its modal tip (m) and the reach (m).
    """
    from .checks import check_array

    x = check_array(owner.rstrip(": ") or "check_reach", name, x, shape=(model.n_states,))
    reach = model_reach(model)
    tips = model.tip_matrix @ model.layout.modal(x)
    k = int(np.argmax(np.abs(tips) / reach))
    if not abs(tips[k]) < reach[k]:
        label = model.structure.names[k]
        where = f" of appendage {label!r}" if label else ""
        raise InputValueError(f"{owner}{name} puts the modal tip{where} at {tips[k]:.4g} m, beyond "
                              f"the {reach[k]:g} m the {model.variant} model covers (beam length "
                              f"{model.lengths[k]:g} m); got {name} = {x!r}"[:600])

