"""A spatial motion that stays in one plane: the spatial equations restricted to it.

A spatial structure whose appendages all lie in one plane through the hub's centre (each
rod's direction and normal in it, so that its lateral axis is the plane's normal ``a``), on a
hub for which ``a`` is a principal axis of inertia, turned about ``a`` by a torque along
``a``, moves in that plane for ever once it starts there: the reflection through the plane
maps the structure, the torque (an axial vector along the reflection's normal) and such a
state onto themselves, so the out-of-plane fields (lateral bending ``ql`` and twist ``qt``),
the angular velocity across ``a`` and a free hub's velocity along ``a`` stay zero.
:func:`motion_plane` recognises such a run; :func:`plane_motion` gives the spatial
equations restricted to the plane: the whole model's right-hand side evaluated at the
in-plane states (the attitude quaternion, a free hub's position, the normal bending ``qn``
of every appendage, the rate ``omega`` about ``a``, a free hub's two in-plane velocities and
the ``qn`` rates), whose symbolic zeros CasADi's expressions drop. On the two panels of
``benchmarks/bench_spatial.py`` (a) at 4 modes per field its C is 355 kB instead of 3 MB
and it takes 17 141 operations against 134 082; integrated with Newton's iterations
(:func:`~flexctl.sim.spatial_run.simulate_spatial`), 6 265 evaluations against the whole
model's 13 336, a run with its check took 3.5 times the planar exact model's time on 2 and
4 modes, where the whole model took 10 and 34 times. The states it returns are the whole
model's with the out-of-plane fields zero, as the whole model keeps them.

Only a motion that cannot leave the plane by its own dynamics is restricted: ``a`` must be
the axis of largest or smallest moment of inertia of the structure as it starts (about the
centre of mass for a free hub). About the intermediate axis a turn is unstable and the
whole model, whose out-of-plane states hold round-off, may leave the plane; it is then
integrated whole.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..model.spatial_dynamics import SpatialEquations

__all__ = ["PlaneMotion", "motion_plane", "plane_motion", "PLANE_TOLERANCE"]

#: Largest component across the plane's normal, relative to the vector's length, of an
#: appendage's direction and normal, a hub inertia's ``J a``, an angular velocity and a
#: torque taken as lying along (or in) the plane (round-off of unit vectors).
PLANE_TOLERANCE = 1e-12


@dataclass(frozen=True, eq=False)
class PlaneMotion:
    """The spatial equations restricted to a plane.

    Attributes
    ----------
    axis : ndarray, shape (3,)
        The plane's unit normal ``a``, hub frame.
    embedding : ndarray, shape (n_states, n_plane)
        ``x = embedding @ x_plane``: the whole state of an in-plane one (orthonormal
        columns, so that ``x_plane = embedding.T @ x``).
    rhs : casadi.Function
        ``(x_plane, torque (3)) -> x_plane_t``: the whole model's rate at the in-plane
        state, the torque's component along ``a`` applied, restricted to the plane.
    tips : casadi.Function
        ``x_plane -> tips (3, n_appendages)``: the whole model's tip displacements
        (:attr:`~flexctl.model.spatial_dynamics.SpatialEquations.tips`) at the in-plane
        state (a third of their operations on two panels of 2 modes).
    """

    axis: np.ndarray
    embedding: np.ndarray
    rhs: object
    tips: object

    @property
    def n_states(self) -> int:
        """States in the plane."""
        return self.embedding.shape[1]

    def restrict(self, x) -> np.ndarray:
        """The in-plane state of a whole one, shape (n_plane,).

        Parameters
        ----------
        x : array_like, shape (n_states,)
            A state of the spatial model (:class:`~flexctl.model.spatial_dynamics.SpatialLayout`).
        """
        return self.embedding.T @ np.asarray(x, dtype=float)

    def embed(self, states) -> np.ndarray:
        """Whole states (n_states, P) of in-plane ones (n_plane, P).

        Parameters
        ----------
        states : ndarray, shape (n_plane, P)
            In-plane states, one column per sample.
        """
        return self.embedding @ states


def _along(vector, axis) -> bool:
    """Whether ``vector`` lies along ``axis`` (zero included)."""
    vector = np.asarray(vector, dtype=float)
    across = vector - (vector @ axis) * axis
    return bool(np.linalg.norm(across) <= PLANE_TOLERANCE * np.linalg.norm(vector))


def _in_plane(vector, axis) -> bool:
    """Whether ``vector`` lies in the plane of normal ``axis``."""
    vector = np.asarray(vector, dtype=float)
    return bool(abs(vector @ axis) <= PLANE_TOLERANCE * np.linalg.norm(vector))


def motion_plane(equations: SpatialEquations, x0, drive, edges) -> np.ndarray | None:
    """The normal of the plane a run stays in, or None.

    Parameters
    ----------
    equations : SpatialEquations
        The spatial model.
    x0 : ndarray, shape (n_states,)
        The initial state.
    drive : callable
        The hub torque: :class:`~flexctl.sim.spatial_run.VectorTorque`, a constant, or any
        torque with a ``segment_form(a, b)`` (the 11 numbers of
        ``p[0:3] + p[3:6] t + p[6:9] sin(...)`` on a segment); another one (a Python
        function) is never taken to lie in a plane.
    edges : ndarray
        The run's segments' ends, s, ascending (the torque's forms are looked at on each).

    Returns
    -------
    ndarray, shape (3,) or None
        The plane's unit normal in the hub frame (the first appendage's lateral axis).
    """
    structure, layout = equations.structure, equations.layout
    axis = np.asarray(structure.appendages[0].lateral, dtype=float)
    hub = structure.hub
    for a in structure.appendages:
        if not (_in_plane(a.direction, axis) and _in_plane(a.normal, axis)
                and abs(a.root_point(hub) @ axis) <= PLANE_TOLERANCE * a.length):
            return None
    if not _along(np.asarray(hub.inertia) @ axis, axis):
        return None
    _, _, eta, w, v, eta_t = layout.split(np.asarray(x0, dtype=float))
    out_of_plane = np.concatenate([eta[layout.modal(k, f)] for k in range(len(structure.names))
                                   for f in ("ql", "qt")])
    out_rates = np.concatenate([eta_t[layout.modal(k, f)]
                                for k in range(len(structure.names)) for f in ("ql", "qt")])
    if np.any(out_of_plane != 0.0) or np.any(out_rates != 0.0) or not _along(w, axis):
        return None
    if v is not None and not _in_plane(v, axis):
        return None
    if not _torque_along(drive, edges, axis):
        return None
    if not _extreme_axis(equations, x0, axis):
        return None
    return axis


def _torque_along(drive, edges, axis) -> bool:
    """Whether the torque lies along ``axis`` on every segment."""
    values = getattr(drive, "values", None)
    if values is not None and getattr(drive, "times", None) is not None:       # samples
        return all(_along(v, axis) for v in np.asarray(values, dtype=float))
    form = getattr(drive, "segment_form", None)
    if form is None:
        return False
    for a, b in zip(edges[:-1], edges[1:]):
        p = np.asarray(form(float(a), float(b)), dtype=float)
        if not all(_along(p[k:k + 3], axis) for k in (0, 3, 6)):
            return False
    return True


def _extreme_axis(equations: SpatialEquations, x0, axis) -> bool:
    """Whether ``axis`` is the axis of largest or smallest moment of inertia of the
    structure at ``x0`` (about the centre of mass for a free hub): a turn about it does not
    leave the plane by itself."""
    mass = np.asarray(equations.mass_matrix(x0).full())
    inertia = mass[0:3, 0:3]
    if equations.layout.free:       # the rigid block about the centre of mass
        coupling = mass[0:3, 3:6]
        inertia = inertia - coupling @ np.linalg.solve(mass[3:6, 3:6], coupling.T)
    about = float(axis @ inertia @ axis)
    basis = np.column_stack(_across(axis))
    others = np.linalg.eigvalsh(0.5 * (basis.T @ (inertia + inertia.T) @ basis))
    return bool(about >= others[-1] or about <= others[0])


def _across(axis) -> tuple:
    """Two unit vectors completing ``axis`` to a right-handed orthonormal basis."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    b1 = np.cross(axis, helper)
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(axis, b1)


@lru_cache(maxsize=16)
def _cached(equations: SpatialEquations, axis: tuple) -> PlaneMotion:
    import casadi as ca

    layout = equations.layout
    a = np.asarray(axis, dtype=float)
    b1, b2 = _across(a)
    columns = [np.eye(layout.n_states)[:, k] for k in range(4)]         # the quaternion
    c = 4
    if layout.free:
        columns += [np.eye(layout.n_states)[:, c + k] for k in range(3)]
        c += 3
    normal = [c + i for k in range(len(layout.names))
              for i in range(layout.modal(k, "qn").start, layout.modal(k, "qn").stop)]
    columns += [np.eye(layout.n_states)[:, i] for i in normal]
    w = layout.n_coordinates
    for vector, start in [(a, w)] + ([(b1, w + 3), (b2, w + 3)] if layout.free else []):
        column = np.zeros(layout.n_states)
        column[start:start + 3] = vector
        columns.append(column)
    speeds = w + (6 if layout.free else 3) - c
    columns += [np.eye(layout.n_states)[:, i + speeds] for i in normal]
    embedding = np.column_stack(columns)
    x = ca.SX.sym("x", embedding.shape[1])
    torque = ca.SX.sym("torque", 3)
    whole = ca.SX.zeros(layout.n_states, 1)
    for row in range(layout.n_states):
        entries = np.flatnonzero(embedding[row])
        if entries.size:
            whole[row] = sum(float(embedding[row, j]) * x[int(j)] for j in entries)
    along = ca.mtimes(ca.DM(np.outer(a, a)), torque)
    rate = ca.mtimes(ca.DM(embedding.T), equations.rhs(whole, along))
    rhs = ca.Function("spatial_plane_rhs", [x, torque], [rate], ["x", "torque"], ["x_dot"],
                      {"cse": True})
    tips = ca.Function("spatial_plane_tips", [x], [equations.tips(whole)], ["x"], ["tips"],
                       {"cse": True})
    embedding.setflags(write=False)
    return PlaneMotion(axis=a, embedding=embedding, rhs=rhs, tips=tips)


def plane_motion(equations: SpatialEquations, axis) -> PlaneMotion:
    """The spatial equations restricted to the plane of normal ``axis`` (kept per equations
    and axis).

    Parameters
    ----------
    equations : SpatialEquations
        The spatial model.
    axis : array_like, shape (3,)
        The plane's unit normal, hub frame (:func:`motion_plane`).

    Returns
    -------
    PlaneMotion
    """
    return _cached(equations, tuple(float(v) for v in np.asarray(axis, dtype=float)))
