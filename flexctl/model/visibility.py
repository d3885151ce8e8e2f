"""Which modes a linearised model's input can move and its outputs can see.

Identical appendages placed symmetrically have modes in which they bend against each other
(``docs/theory/free_hub.md`` section 5): such a mode leaves the hub rows unforced, so the hub
torque neither excites it nor do hub sensors see it. :func:`modal_visibility` finds them from
the undamped modes of the linearisation's second-order form ``M c_tt + K c = f u``.

With the mass-normalised mode shapes ``v_j`` (``v_j^T M v_j = 1``), the input's share of mode
``j`` is ``|v_j^T f| / sqrt(f^T M^-1 f)`` (the squares over all modes sum to 1), and an output
row ``[c_p, c_v]`` sees mode ``j`` by ``|c_p v_j| / (|c_p| |v_j|)`` through its position part
and ``|c_v v_j| / (|c_v| |v_j|)`` through its rate part. A share below
:data:`VISIBILITY_TOLERANCE` is zero. Modes of equal frequency are first rotated so that the
input moves at most one of them: any combination of such modes is a mode too.

Examples
--------
>>> import math
>>> from flexctl import Appendage, Beam, Hub, Structure, build_model
>>> panel = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
...              youngs_modulus=6.9e10)
>>> craft = Structure(hub=Hub(inertia=1.16, radius=0.06), appendages=(
...     Appendage(name="a", beam=panel), Appendage(name="b", beam=panel, angle=math.pi)))
>>> report = build_model(craft, n_modes=2).modal_visibility()
>>> report.uncontrollable("torque")
(1, 3)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .errors import InputValueError

__all__ = ["ModalVisibility", "modal_visibility", "visibility_of", "VISIBILITY_TOLERANCE"]

#: Relative share below which an input does not move, or an output does not see, a mode.
VISIBILITY_TOLERANCE = 1e-8
#: Relative distance of two frequencies that makes them one (degenerate) frequency.
_DEGENERATE = 1e-7


@dataclass(frozen=True, eq=False)
class ModalVisibility:
    """The undamped modes of a linearisation and what its input and outputs see of them.

    Attributes
    ----------
    frequencies : ndarray, shape (n_c,)
        Natural frequencies, rad/s, ascending (0 for rigid-body modes).
    shapes : ndarray, shape (n_c, n_c)
        Mass-normalised mode shapes in the generalized coordinates (columns).
    coordinates : tuple of str
        Names of the generalized coordinates (the rows of ``shapes``).
    inputs, outputs : tuple of str
    input_share : ndarray, shape (n_c, n_inputs)
        Each input's relative share of each mode, in [0, 1].
    output_share : ndarray, shape (n_outputs, n_c)
        How much each output sees of each mode (position and rate parts, the larger), in [0, 1].
    """

    frequencies: np.ndarray
    shapes: np.ndarray
    coordinates: tuple
    inputs: tuple
    outputs: tuple
    input_share: np.ndarray
    output_share: np.ndarray

    def __repr__(self):
        hidden = self.uncontrollable(self.inputs[0]) if self.inputs else ()
        rigid = sum(1 for j in hidden if self.frequencies[j] <= 0.0)
        flexible = [self.mode_name(j).split()[1] for j in hidden if self.frequencies[j] > 0.0]
        parts = ([f"{rigid} rigid motion{'s' if rigid > 1 else ''}"] if rigid else []) \
            + ([f"mode{'s' if len(flexible) > 1 else ''} {', '.join(flexible)}"]
               if flexible else [])
        return (f"ModalVisibility({self.frequencies.size} modes, {self.frequencies.min():.4g} "
                f"to {self.frequencies.max():.4g} rad/s; inputs {', '.join(self.inputs)}; "
                f"{len(self.outputs)} outputs; "
                + (f"{self.inputs[0]} cannot move {' and '.join(parts)})" if hidden
                   else "every mode controllable)"))

    def _mode_list(self, mask) -> tuple:
        return tuple(int(j) for j in np.flatnonzero(mask))

    def uncontrollable(self, input: str = "torque") -> tuple:
        """Indices (into :attr:`frequencies`, from 0) of the modes that ``input`` cannot
        move; :meth:`mode_name` gives each the name the loop checks use.

        Parameters
        ----------
        input : str, optional
            One of :attr:`inputs`. Default ``"torque"``.
        """
        return self._mode_list(self.input_share[:, self._index(self.inputs, input, "input")]
                               <= VISIBILITY_TOLERANCE)

    def unobservable(self, output: str) -> tuple:
        """Indices of the modes that ``output`` cannot see.

        Parameters
        ----------
        output : str
            One of :attr:`outputs`.
        """
        return self._mode_list(self.output_share[self._index(self.outputs, output, "output")]
                               <= VISIBILITY_TOLERANCE)

    @staticmethod
    def _index(names, name, what) -> int:
        if name not in names:
            raise InputValueError(f"{what} must be one of {', '.join(names)}; got {name!r}")
        return names.index(name)

    def mode_name(self, index: int) -> str:
        """The mode at ``index`` (of :attr:`frequencies`) as the loop checks name it
        (:class:`controllers.design.stability.GrowingPole`): ``"mode k"`` for the ``k``-th
        flexible mode counted from 1 in ascending frequency, ``"a rigid motion"`` for a mode
        of zero frequency; the index follows in brackets.

        Parameters
        ----------
        index : int
            Index into :attr:`frequencies` and the columns of :attr:`shapes` (from 0), as
            :meth:`uncontrollable` and :meth:`unobservable` give them.
        """
        index = int(index)
        if not 0 <= index < self.frequencies.size:
            raise InputValueError(f"mode_name index must lie in [0, {self.frequencies.size}); "
                                  f"got {index}")
        flexible = np.flatnonzero(self.frequencies > 0.0)
        if self.frequencies[index] > 0.0:
            return f"mode {int(np.searchsorted(flexible, index)) + 1} [index {index}]"
        return f"a rigid motion [index {index}]"

    def describe(self, input: str = "torque") -> str:
        """One line per mode that ``input`` cannot move, named as the loop checks name modes
        (:meth:`mode_name`), with its frequency and the outputs that see it (empty when every
        mode is controllable).

        Parameters
        ----------
        input : str, optional
            One of :attr:`inputs`. Default ``"torque"``.
        """
        lines = []
        for j in self.uncontrollable(input):
            seen = [o for k, o in enumerate(self.outputs)
                    if self.output_share[k, j] > VISIBILITY_TOLERANCE]
            lines.append(f"{self.mode_name(j)} at {self.frequencies[j]:.6g} rad/s: {input} "
                         f"cannot move it; seen by {', '.join(seen) if seen else 'no output'}")
        return "\n".join(lines)


def _separate(shapes, frequencies, load):
    """Rotate each group of equal frequencies so that the inputs (the columns of ``load``)
    move as few of its modes as they span: one input, at most one mode."""
    shapes = shapes.copy()
    j = 0
    while j < len(frequencies):
        k = j + 1
        while k < len(frequencies) and abs(frequencies[k] - frequencies[j]) <= _DEGENERATE * max(
                abs(frequencies[j]), 1e-12):
            k += 1
        if k - j > 1:
            group = shapes[:, j:k]
            share = group.T @ load
            if np.linalg.norm(share) > 0.0:
                basis, _ = np.linalg.qr(np.column_stack((share, np.eye(k - j))))
                shapes[:, j:k] = group @ basis[:, :k - j]
        j = k
    return shapes


def modal_visibility(model, spin_rate: float = 0.0) -> ModalVisibility:
    """The :class:`ModalVisibility` of ``model`` linearised at ``spin_rate``.

    Parameters
    ----------
    model : Model
        Any flexctl model.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s (0 for a free hub). Default 0.
    """
    mass, stiffness, _, load = model.second_order_form(spin_rate)
    layout, c = model.layout, model.output_matrix
    return visibility_of(mass, stiffness, load[:, None], c[:, layout.coordinates],
                         c[:, layout.velocities],
                         coordinates=tuple(layout.names[layout.coordinates]),
                         inputs=tuple(model.input_names), outputs=tuple(model.output_names))


def visibility_of(mass, stiffness, load, c_position, c_rate, *, coordinates, inputs,
                  outputs) -> ModalVisibility:
    """The :class:`ModalVisibility` of the undamped second-order system ``M c_tt + K c = F u``
    observed by ``y = C_p c + C_v c_t``.

    Parameters
    ----------
    mass, stiffness : ndarray, shape (n_c, n_c)
        ``M`` (positive definite) and ``K`` (symmetric; rigid-body modes at 0), SI units of
        the coordinates.
    load : ndarray, shape (n_c, n_inputs)
        ``F``: each input's generalized forces.
    c_position, c_rate : ndarray, shape (n_outputs, n_c)
        The outputs' position and rate parts.
    coordinates, inputs, outputs : tuple of str
        Names of the coordinates, inputs and outputs.
    """
    mass = 0.5 * (mass + mass.T)
    lam, shapes = scipy.linalg.eigh(0.5 * (stiffness + stiffness.T), mass)
    frequencies = np.sign(lam) * np.sqrt(np.abs(lam))
    frequencies[np.abs(lam) <= 1e-12 * max(np.max(np.abs(lam)), 1e-300)] = 0.0
    order = np.argsort(frequencies, kind="stable")
    frequencies, shapes = frequencies[order], shapes[:, order]
    shapes = _separate(shapes, frequencies, load)
    reach = np.sqrt(np.einsum("ij,ij->j", load, np.linalg.solve(mass, load)))
    with np.errstate(invalid="ignore", divide="ignore"):
        input_share = np.where(reach > 0.0, np.abs(shapes.T @ load) / reach, 0.0)
    norms = np.linalg.norm(shapes, axis=0)
    parts = []
    for rows in (c_position, c_rate):
        scale = np.linalg.norm(rows, axis=1)[:, None] * norms[None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            parts.append(np.where(scale > 0.0, np.abs(rows @ shapes) / scale, 0.0))
    return ModalVisibility(
        frequencies=frequencies, shapes=shapes, coordinates=tuple(coordinates),
        inputs=tuple(inputs), outputs=tuple(outputs), input_share=np.minimum(input_share, 1.0),
        output_share=np.minimum(np.maximum(*parts), 1.0))
