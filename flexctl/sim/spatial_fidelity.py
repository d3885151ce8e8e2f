"""How many modes a spatial structure needs for a manoeuvre (``modes = "auto"``).

The structure's rigid motion comes first: Euler's equations of the whole structure, straight
and rigid (its inertia about the hub's centre, or about the centre of mass on a free hub),
from the initial angular velocity under the torque. Each appendage's two bending planes are
then judged as the planar hub-beam problems they are closest to, with
:func:`~flexctl.sim.fidelity.choose_modes`: the appendage's beam with the plane's bending
stiffness (``second_moment`` along the normal, ``second_moment_lateral`` along the lateral
direction) and its point masses, clamped at its root's distance along its axis from a hub
that turns as the rigid motion does about the axis that bends that plane (``direction x
normal`` bends along the normal, ``direction x lateral`` along the lateral direction): the
component of the rigid angular velocity and acceleration about that axis, so that a spin
about it stiffens the plane and a nutation's rocking about it drives it. The appendage gets
the larger of its two planes' counts for every field (torsion included: its modes move the
tips only through second-order coupling). Not in the estimate: the centrifugal loading of a
spin about other axes, and the structure's flexibility feeding back on the rigid motion; the
planar problems aim at :data:`MARGIN` times less than the tolerance for them (measured on
``examples/scenes/spatial-spin.toml``, 3 s: its one mode per field, which the planar
problems alone found within 0.43 % of their converged tips at a 1 % tolerance, was 1.15 %
from the spatial model's 4 modes; the margin takes it to 2 modes, within 5.9e-4, and
``spatial-two-arrays.toml``'s arrays and boom from 2, 2 and 1 modes, 1.1e-3 and 4.4e-2 from
4 modes, to 2 each, within 1.1e-3 and 9.3e-4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.checks import check_array, check_real
from ..model.errors import InputTypeError, InputValueError
from ..model.parameters import Beam, Hub, HubBeam
from ..model.spatial_dynamics import MAX_SPATIAL_MODES
from ..model.spatial_structure import SpatialStructure
from .fidelity import DEFAULT_TOLERANCE, choose_modes

__all__ = ["SpatialModeChoice", "choose_spatial_modes"]

#: The planar problems aim at the tolerance divided by this: a margin for what they leave out.
MARGIN = 4.0
#: The bending planes judged, and the appendage's section property of each.
PLANES = (("normal", "second_moment"), ("lateral", "second_moment_lateral"))


@dataclass(frozen=True)
class SpatialModeChoice:
    """Modes per field chosen for a spatial structure and a manoeuvre.

    Attributes
    ----------
    n_modes : int or tuple of int
        One count for every appendage, or one per appendage (as
        :func:`~flexctl.model.spatial_dynamics.spatial_modes` takes it).
    by_plane : dict
        ``{appendage: {"normal": n, "lateral": n}}``: each bending plane's count.
    estimated_error : float
        Largest estimated relative tip error of the counts chosen, over the planar problems
        (which aim at ``tolerance / MARGIN``).
    tolerance : float
        Relative tip error asked for.
    explanation : str
    """

    n_modes: object
    by_plane: dict
    estimated_error: float
    tolerance: float
    explanation: str


class _RigidMotion:
    """The structure's rigid rotation: Euler's equations from ``w0`` under ``torque``, with
    the integral of ``w`` (hub frame) as a state for the angles."""

    def __init__(self, inertia, torque, w0, t_final: float):
        from scipy.integrate import solve_ivp

        inverse = np.linalg.pinv(inertia)

        def rate(t, y):
            w = y[:3]
            tau = np.zeros(3) if torque is None else np.asarray(torque(t), float).reshape(3)
            return np.concatenate([inverse @ (tau - np.cross(w, inertia @ w)), w])

        self.rate_of = rate
        breaks = sorted({float(b) for b in getattr(torque, "breakpoints", ())
                         if 0.0 < float(b) < t_final} | {0.0, t_final})
        self.breakpoints = tuple(breaks[1:-1])
        self.pieces, y = [], np.concatenate([np.asarray(w0, float), np.zeros(3)])
        for a, b in zip(breaks[:-1], breaks[1:]):
            solution = solve_ivp(rate, (a, b), y, method="DOP853", rtol=1e-10, atol=1e-12,
                                 dense_output=True)
            if solution.status != 0:
                raise InputValueError(f"the structure's rigid motion could not be followed "
                                      f"from t = {a:g} s: {solution.message}")
            self.pieces.append((a, b, solution.sol))
            y = solution.y[:, -1]

    def state(self, t) -> np.ndarray:
        """``(w, int w dt, w_t)`` at the times ``t``, shape (9, P)."""
        times = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.zeros((9, times.size))
        edges = np.array([b for _, b, _ in self.pieces])
        which = np.minimum(np.searchsorted(edges, times), len(self.pieces) - 1)
        for k, (a, b, sol) in enumerate(self.pieces):
            here = which == k
            if np.any(here):
                out[:6, here] = sol(np.clip(times[here], a, b))
        for j, time in enumerate(times):
            out[6:, j] = self.rate_of(time, out[:6, j])[:3]
        return out


class _AboutAxis:
    """The rigid motion about one axis, as a planar prescribed hub motion (rad, rad/s,
    rad/s^2)."""

    def __init__(self, motion: _RigidMotion, axis):
        self.motion, self.axis = motion, np.asarray(axis, dtype=float)
        self.breakpoints = motion.breakpoints

    def _part(self, t, rows: slice):
        values = self.axis @ self.motion.state(t)[rows]
        return values.reshape(np.shape(t)) if np.ndim(t) else float(values[0])

    def angle(self, t):
        return self._part(t, slice(3, 6))

    def rate(self, t):
        return self._part(t, slice(0, 3))

    def acceleration(self, t):
        return self._part(t, slice(6, 9))


def choose_spatial_modes(structure: SpatialStructure, torque, t_final: float,
                         tolerance: float = DEFAULT_TOLERANCE,
                         angular_velocity=(0.0, 0.0, 0.0)) -> SpatialModeChoice:
    """The fewest modes per field each appendage needs for ``torque`` (module description).

    Parameters
    ----------
    structure : SpatialStructure
        The hub and its appendages.
    torque : callable or None
        Hub torque ``torque(t) -> (3,)`` in the hub frame, N m (a
        :class:`~flexctl.sim.spatial_run.VectorTorque`, a scene's manoeuvre); None: none.
    t_final : float
        Horizon, s (> 0).
    tolerance : float, optional
        Relative tip error in (0, 1) each plane's count aims at. Default 1e-2.
    angular_velocity : array_like, shape (3,), optional
        Initial hub angular velocity, hub frame, rad/s. Default zero.

    Returns
    -------
    SpatialModeChoice
    """
    if not isinstance(structure, SpatialStructure):
        raise InputTypeError(f"structure must be a SpatialStructure; got "
                             f"{type(structure).__name__}")
    t_final = check_real("", "t_final", t_final, minimum=0.0, strict=True, maximum=1e6)
    if torque is not None and not callable(torque):
        raise InputTypeError(f"torque must be a function of time or None; got "
                             f"{type(torque).__name__}")
    w0 = check_array("", "angular_velocity", angular_velocity, shape=(3,))
    whole = structure.rigid_inertia
    inertia = whole
    if structure.hub.free:              # turning about the centre of mass
        mass = structure.total_mass
        centre = structure.first_moment / mass
        inertia = whole - mass * (centre @ centre * np.eye(3) - np.outer(centre, centre))
    motion = _RigidMotion(inertia, torque, w0, t_final)
    by_plane, counts, worst = {}, [], 0.0
    for k, appendage in enumerate(structure.appendages):
        rest = whole - structure.appendage_inertia(k)
        root = appendage.root_point(structure.hub)
        radius = max(float(root @ appendage.direction), 0.0)
        planes = {}
        for plane, moment in PLANES:
            bend = appendage.normal if plane == "normal" else appendage.lateral
            axis = np.cross(appendage.direction, bend)
            system = HubBeam(hub=Hub(inertia=max(float(axis @ rest @ axis), 0.0),
                                     radius=radius),
                             beam=Beam(length=appendage.length, density=appendage.density,
                                       area=appendage.area,
                                       second_moment=getattr(appendage, moment),
                                       youngs_modulus=appendage.youngs_modulus),
                             masses=appendage.masses)
            choice = choose_modes(system, _AboutAxis(motion, axis), tolerance / MARGIN,
                                  max_modes=MAX_SPATIAL_MODES, t_final=t_final)
            planes[plane] = int(choice.n_modes)
            worst = max(worst, float(choice.estimated_error))
        by_plane[appendage.name] = planes
        counts.append(max(planes.values()))
    n_modes = counts[0] if len(set(counts)) == 1 else tuple(counts)
    what = "; ".join(f"{name}: {p['normal']} along the normal, {p['lateral']} laterally"
                     for name, p in by_plane.items())
    return SpatialModeChoice(
        n_modes=n_modes, by_plane=by_plane, estimated_error=worst, tolerance=tolerance,
        explanation=(f"each bending plane judged as a planar hub-beam problem turning as the "
                     f"rigid structure does about its axis ({what}); the centrifugal loading "
                     "of a spin about other axes and the flexibility's feedback on the rigid "
                     "motion are not in the estimate"))
