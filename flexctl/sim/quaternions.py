"""Unit quaternions in numpy: scalar first, ``q = (w, x, y, z)``, rotating hub-frame vectors into
the inertial frame (``v_N = R(q) v_B``), composed as ``q_NB = q_NA (x) q_AB``.

The CasADi form of the rotation matrix is
:func:`flexctl.model.spatial_dynamics.quaternion_rotation`; the spatial model's attitude and
the three-axis sensors and filter use these.

Examples
--------
>>> import numpy as np
>>> from flexctl.sim.quaternions import from_rotation_vector, rotation_matrix
>>> q = from_rotation_vector([0.0, 0.0, np.pi / 2])
>>> np.round(rotation_matrix(q) @ [1.0, 0.0, 0.0], 12).tolist()
[0.0, 1.0, 0.0]
"""

from __future__ import annotations

import numpy as np

__all__ = ["product", "symbolic_product", "conjugate", "from_rotation_vector", "rotation_vector",
           "rotation_matrix", "error_angles", "symbolic_from_rotation_vector",
           "symbolic_rotation_vector", "symbolic_rotation_matrix"]


def product(p, q) -> np.ndarray:
    """``p (x) q``, the rotation ``q`` followed by ``p`` (scalar first).

    Parameters
    ----------
    p, q : array_like, shape (4,)
        Quaternions.

    Returns
    -------
    ndarray, shape (4,)
    """
    pw, pv = p[0], np.asarray(p[1:], dtype=float)
    qw, qv = q[0], np.asarray(q[1:], dtype=float)
    return np.concatenate([[pw * qw - pv @ qv], pw * qv + qw * pv + np.cross(pv, qv)])


def symbolic_product(p, q):
    """:func:`product` of CasADi column quaternions (SX, MX or DM), scalar first.

    Parameters
    ----------
    p, q : casadi.SX, casadi.MX or casadi.DM, shape (4, 1)
        Quaternions.

    Returns
    -------
    Same type, shape (4, 1)
    """
    import casadi as ca

    pv, qv = p[1:4], q[1:4]
    return ca.vertcat(p[0] * q[0] - ca.dot(pv, qv), p[0] * qv + q[0] * pv + ca.cross(pv, qv))


def symbolic_from_rotation_vector(phi):
    """:func:`from_rotation_vector` of a CasADi column vector, its series included.

    Parameters
    ----------
    phi : casadi.SX or casadi.MX, shape (3, 1)
        Rotation vector, rad.

    Returns
    -------
    Same type, shape (4, 1)
        Scalar first.
    """
    import casadi as ca

    angle = ca.norm_2(phi)
    half = 0.5 * angle
    scale = ca.if_else(angle > 1e-4, ca.sin(half) / ca.fmax(angle, 1e-300),
                       0.5 - angle * angle / 48.0)
    return ca.vertcat(ca.cos(half), scale * phi)


def symbolic_rotation_vector(q):
    """:func:`rotation_vector` of a CasADi column quaternion (not normalised), the short way
    round.

    Parameters
    ----------
    q : casadi.SX or casadi.MX, shape (4, 1)
        Unit quaternion, scalar first.

    Returns
    -------
    Same type, shape (3, 1)
        rad.
    """
    import casadi as ca

    sign = ca.if_else(q[0] < 0, -1.0, 1.0)
    w, v = sign * q[0], sign * q[1:4]
    s = ca.norm_2(v)
    return ca.if_else(s < 1e-12, 2.0 * v, 2.0 * ca.atan2(s, w) * v / ca.fmax(s, 1e-300))


def symbolic_rotation_matrix(q):
    """:func:`rotation_matrix` of a CasADi column quaternion (normalised here).

    Parameters
    ----------
    q : casadi.SX or casadi.MX, shape (4, 1)
        Quaternion, scalar first.

    Returns
    -------
    Same type, shape (3, 3)
        Hub to inertial.
    """
    import casadi as ca

    q = q / ca.norm_2(q)
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def conjugate(q) -> np.ndarray:
    """The inverse rotation of a unit quaternion.

    Parameters
    ----------
    q : array_like, shape (4,)
        Unit quaternion.

    Returns
    -------
    ndarray, shape (4,)
    """
    return np.concatenate([[q[0]], -np.asarray(q[1:], dtype=float)])


def from_rotation_vector(phi) -> np.ndarray:
    """The quaternion of a rotation by ``|phi|`` rad about ``phi``.

    Parameters
    ----------
    phi : array_like, shape (3,)
        Rotation vector, rad.

    Returns
    -------
    ndarray, shape (4,)
    """
    phi = np.asarray(phi, dtype=float)
    angle = float(np.linalg.norm(phi))
    half = 0.5 * angle
    # sin(x)/x to second order below 1e-4 rad: exact to round-off there
    scale = np.sin(half) / angle if angle > 1e-4 else 0.5 - angle * angle / 48.0
    return np.concatenate([[np.cos(half)], scale * phi])


def rotation_vector(q) -> np.ndarray:
    """The rotation vector (rad) of a unit quaternion, the shorter way round.

    Parameters
    ----------
    q : array_like, shape (4,)
        Unit quaternion.

    Returns
    -------
    ndarray, shape (3,)
        Angle in ``[0, pi]`` times the axis.
    """
    q = np.asarray(q, dtype=float)
    if q[0] < 0:
        q = -q
    s = float(np.linalg.norm(q[1:]))
    if s < 1e-12:
        return 2.0 * q[1:]
    return 2.0 * np.arctan2(s, q[0]) * q[1:] / s


def rotation_matrix(q) -> np.ndarray:
    """``R(q)``: hub-frame vectors to the inertial frame.

    Parameters
    ----------
    q : array_like, shape (4,)
        Quaternion (normalised here).

    Returns
    -------
    ndarray, shape (3, 3)
    """
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def error_angles(estimate, truth) -> np.ndarray:
    """The small rotation, in the estimate's (hub) frame, that takes ``estimate`` to
    ``truth``: ``truth = estimate (x) exp(error / 2)``.

    Parameters
    ----------
    estimate, truth : array_like, shape (4,)
        Unit quaternions.

    Returns
    -------
    ndarray, shape (3,)
        Rotation vector, rad.
    """
    return rotation_vector(product(conjugate(estimate), truth))
