"""The modal matrices of a :class:`~flexctl.model.structure.Structure`, appendage by appendage.

On a pinned hub the appendages couple only through the hub rotation, so the structure's matrices
are the blocks of each appendage's own (:func:`flexctl.model.matrices.assemble` of the
appendage alone at its root radius, ``docs/theory/free_hub.md`` section 3). A free hub adds the
total mass ``m``, the first moment ``S_0`` of the undeformed structure about the hub centre
and the first moments of the modes ``N = [n_k s_k^T]`` (all in the hub frame).

Notes
-----
With ``N`` modes in all (the appendages' modes one after the other):

===========  =========  ==========================================================
name         shape      meaning
===========  =========  ==========================================================
J0           scalar     inertia of the undeformed structure about the hub centre, kg m^2
M_ff, K_ff,  (N, N)     block diagonal: each appendage's modal mass, stiffness, geometric
K_g, C_ff               stiffness and damping
m_tf         (N,)       rigid-flexible inertia coupling, kg m
tip, root    (K, N)     tip deflection and root bending moment of each of the K
                        appendages per modal coordinate (m, N)
mass         scalar     hub, beams and point masses, kg
first        (2,)       ``S_0``, first moment of the undeformed structure about the hub
                        centre in the hub frame, kg m
first_q      (2, N)     ``N``: first moment per modal coordinate, kg
===========  =========  ==========================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .checks import check_counts
from .errors import InputTypeError, InputValueError
from .exact import EXACT_MAX_MODES
from .matrices import ModalMatrices, beam_quadrature, assemble, condensed_hub_inertia
from .modes import mode_shapes
from .structure import Structure
from .variant import MAX_MODES, Variant

__all__ = ["StructureMatrices", "assemble_structure", "modes_per_appendage"]


def modes_per_appendage(structure: Structure, n_modes, variant: str = "first_order") -> tuple:
    """Modes of each appendage from an int (each), a dict ``{name: int}`` or a sequence.

    Parameters
    ----------
    structure : Structure
        The structure whose appendages are counted.
    n_modes : int, dict or sequence of int
        One count for every appendage, ``{name: int}`` for each appendage by name, or one count
        per appendage in order; each from 1 to 200.
    variant : str, optional
        Model variant: ``"exact"`` takes at most :data:`~flexctl.model.exact.EXACT_MAX_MODES`
        modes per appendage. Default ``"first_order"``.

    Raises
    ------
    InputTypeError, InputValueError
        Naming ``n_modes`` (or ``n_modes[name]``), the rule and the value.
    """
    top = Variant(variant).max_modes
    modes = check_counts("", structure.names, n_modes, MAX_MODES)
    if Variant(variant).exact and max(modes) > top:
        raise InputValueError(
            f"n_modes must be at most {EXACT_MAX_MODES} per appendage for the exact variant (its "
            "geometry grows as the square of the modes; converge the higher ones on "
            f"first_order); got {max(modes)}")
    return modes


@dataclass(frozen=True, eq=False)
class StructureMatrices:
    """Assembled matrices of a :class:`Structure` (read-only arrays; see the module Notes).

    Attributes
    ----------
    system : Structure
        The structure assembled.
    modes : tuple of int
        Modes of each appendage.
    parts : tuple of ModalMatrices
        Each appendage's own matrices (:meth:`Structure.appendage_system`).
    slices : tuple of slice
        Each appendage's modal coordinates within ``q``.
    n_modes : int
        Modes of all the appendages, ``N``.
    beam_frequencies : ndarray, shape (N,)
        Clamped frequencies of each appendage's bare beam, rad/s, appendage by appendage.
    J0 : float
        Inertia of the undeformed structure about the hub centre, kg m^2.
    M_ff, K_ff, K_g, C_ff : ndarray, shape (N, N)
        Block diagonal: each appendage's modal mass (kg), bending stiffness (N/m),
        geometric stiffness per unit ``theta_t^2`` (kg) and damping (N s/m).
    m_tf : ndarray, shape (N,)
        Rigid-flexible inertia coupling, kg m.
    tip, root : ndarray, shape (K, N)
        Tip deflection (m) and root bending moment (N m) of each of the K appendages per
        modal coordinate.
    mass : float
        Hub, beams and point masses, kg.
    first : ndarray, shape (2,)
        ``S_0``, first moment of the undeformed structure about the hub centre in the hub
        frame, kg m.
    first_q : ndarray, shape (2, N)
        First moment per modal coordinate, kg.
    condensed_inertia : float
        Effective hub inertia at rest of a pinned hub, ``J_0 - m_tf^T M_ff^-1 m_tf``
        computed without cancellation, kg m^2.
    """

    system: Structure
    modes: tuple
    parts: tuple
    slices: tuple
    n_modes: int
    beam_frequencies: np.ndarray
    J0: float
    M_ff: np.ndarray
    K_ff: np.ndarray
    K_g: np.ndarray
    C_ff: np.ndarray
    m_tf: np.ndarray
    tip: np.ndarray
    root: np.ndarray
    mass: float
    first: np.ndarray
    first_q: np.ndarray
    condensed_inertia: float

    @property
    def D(self) -> np.ndarray:
        """``M_ff - K_g``, kg, shape (N, N)."""
        return self.M_ff - self.K_g


def _mode_first_moment(part: ModalMatrices) -> np.ndarray:
    """``s = rhoA int phi + sum_j m_j phi(d_j)``, kg, shape (N_k,)."""
    system, n = part.system, part.n_modes
    x, w = beam_quadrature(system, n)
    l = system.beam.length
    s = system.beam.linear_density * (mode_shapes(n, x / l) @ w)
    for m in system.masses:
        s = s + m.mass * mode_shapes(n, [m.position / l])[:, 0]
    return s


def _rigid_first_moment(part: ModalMatrices) -> float:
    """``c = rhoA int (b + x) dx + sum_j m_j (b + d_j)``, kg m."""
    system = part.system
    b, l = system.hub.radius, system.beam.length
    return (system.beam.linear_density * l * (b + 0.5 * l)
            + sum(m.mass * (b + m.position) for m in system.masses))


def assemble_structure(structure: Structure, modes: tuple) -> StructureMatrices:
    """Assemble the matrices of ``structure`` with ``modes[k]`` modes on appendage ``k``.

    Parameters
    ----------
    structure : Structure
        The hub and its appendages.
    modes : tuple of int
        Modes of each appendage, in order (:func:`modes_per_appendage`).
    """
    if not isinstance(structure, Structure):
        raise InputTypeError(f"structure must be a Structure; got {type(structure).__name__}")
    parts = tuple(assemble(structure.appendage_system(k), n) for k, n in enumerate(modes))
    bounds = np.cumsum((0,) + tuple(modes))
    slices = tuple(slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]))
    n = int(bounds[-1])
    tip, root = np.zeros((len(parts), n)), np.zeros((len(parts), n))
    first_q, first = np.zeros((2, n)), np.zeros(2)
    for k, (part, block, app) in enumerate(zip(parts, slices, structure.appendages)):
        tip[k, block], root[k, block] = part.tip, part.root
        first_q[:, block] = np.outer(app.normal, _mode_first_moment(part))
        first += _rigid_first_moment(part) * app.direction
    block = lambda name: scipy.linalg.block_diag(*(getattr(p, name) for p in parts))  # noqa
    arrays = dict(M_ff=block("M_ff"), K_ff=block("K_ff"), K_g=block("K_g"), C_ff=block("C_ff"),
                  m_tf=np.concatenate([p.m_tf for p in parts]), tip=tip, root=root,
                  first=first, first_q=first_q,
                  beam_frequencies=np.concatenate([p.beam_frequencies for p in parts]))
    for a in arrays.values():
        a.setflags(write=False)
    condensed = structure.hub.inertia + sum(
        condensed_hub_inertia(p.system, p.n_modes) for p in parts)
    return StructureMatrices(system=structure, modes=tuple(modes), parts=parts, slices=slices,
                             n_modes=n, J0=structure.rigid_inertia, mass=structure.total_mass,
                             condensed_inertia=condensed, **arrays)
