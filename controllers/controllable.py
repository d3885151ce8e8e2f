"""Designs on the part of a linearised model that the hub torque can move.

Identical appendages placed symmetrically bend against each other in modes that the hub
torque can neither excite nor damp, and a free hub's translation is not moved by a torque
either (:mod:`flexctl.model.visibility`). A Riccati solver fails on such a model (it is not
stabilizable). These helpers design on the torque's modal subspace instead and extend the
result to the whole state: the gain is zero on the modes left out, which keep their open-loop
poles (the closed-loop poles reported include them).

With the mass-normalised mode shapes ``V`` of the kept modes (``V^T M V = I``), the state
``x = [c; c_t]`` (generalized coordinates and their rates) of the kept part is ``z = P x``,
``P = blockdiag(V^T M, V^T M)``, and ``x = T z`` with ``T = blockdiag(V, V)``.

Examples
--------
>>> import math
>>> from flexctl import Appendage, Beam, Hub, Structure, build_model
>>> panel = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
...              youngs_modulus=6.9e10)
>>> craft = Structure(hub=Hub(inertia=1.16, radius=0.06), appendages=(
...     Appendage(name="a", beam=panel), Appendage(name="b", beam=panel, angle=math.pi)))
>>> part = controllable_part(build_model(craft, n_modes=2))
>>> part.basis.shape, [round(w, 3) for w in part.dropped]
((10, 6), [3.912, 24.514])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ControllablePart", "controllable_part", "lqr_on_part", "lqe_on_part",
           "dlqr_on_part"]


@dataclass(frozen=True, eq=False)
class ControllablePart:
    """The torque's modal subspace of a linearised model (see the module docstring).

    Attributes
    ----------
    basis : ndarray, shape (n, r)
        ``T``: ``x = T z``.
    projector : ndarray, shape (r, n)
        ``P``: ``z = P x`` (``P T = I``).
    dropped : tuple of float
        Frequencies of the modes left out, rad/s (0 for a rigid-body mode).
    note : str
        Which modes were left out and why ("" when none).
    """

    basis: np.ndarray
    projector: np.ndarray
    dropped: tuple
    note: str

    def reduce(self, a, b):
        """``(P A T, P B)``."""
        return self.projector @ a @ self.basis, self.projector @ b


def controllable_part(model, spin_rate: float = 0.0) -> ControllablePart:
    """The :class:`ControllablePart` of ``model`` linearised at ``spin_rate`` (rad/s)."""
    report = model.modal_visibility(spin_rate)
    drop = report.uncontrollable("torque")
    keep = [j for j in range(report.frequencies.size) if j not in drop]
    mass = model.second_order_form(spin_rate)[0]
    layout = model.layout
    n, n_c = model.n_states, layout.n_coordinates
    shapes = report.shapes[:, keep]
    basis, projector = np.zeros((n, 2 * len(keep))), np.zeros((2 * len(keep), n))
    for k, block in enumerate((layout.coordinates, layout.velocities)):
        basis[block, k * len(keep):(k + 1) * len(keep)] = shapes
        projector[k * len(keep):(k + 1) * len(keep), block] = shapes.T @ mass
    dropped = tuple(float(report.frequencies[j]) for j in drop)
    note = ""
    if drop:
        note = (f"{len(drop)} of the {n_c} modes cannot be moved by the hub torque (at "
                f"{', '.join(f'{w:.4g}' for w in dropped)} rad/s: appendages bending against "
                "each other, or a free hub's translation); the design acts on the others and "
                "leaves these at their open-loop poles")
    return ControllablePart(basis=basis, projector=projector, dropped=dropped, note=note)


def lqr_on_part(model, spin_rate, q_mat, r_mat, sample_time=None):
    """LQR gain (1, n) and closed-loop poles (n,) designed on the controllable part; with a
    ``sample_time`` (s), the discrete LQR of the plant held over it (weights ``Q T``,
    ``R T``: the continuous cost's rectangle rule), for a law run with a zero-order hold."""
    a, b = model.linear_matrices(spin_rate)
    part = controllable_part(model, spin_rate)
    if not part.dropped:
        gain = state_gain(a, b, q_mat, r_mat, sample_time)
        return gain, np.linalg.eigvals(a - b @ gain), part
    a_r, b_r = part.reduce(a, b)
    q_r = part.basis.T @ q_mat @ part.basis
    gain = state_gain(a_r, b_r, 0.5 * (q_r + q_r.T), r_mat, sample_time) @ part.projector
    return gain, np.linalg.eigvals(a - b @ gain), part


def state_gain(a, b, q_mat, r_mat, sample_time=None) -> np.ndarray:
    """The LQR gain of ``(A, B)``, shape (1, n): continuous, or discrete for the plant held
    over ``sample_time`` (s) with the weights ``Q T`` and ``R T``."""
    import control

    if sample_time is None:
        return np.asarray(control.lqr(a, b, q_mat, r_mat)[0], dtype=float)
    n = a.shape[0]
    held = control.c2d(control.ss(a, b, np.eye(n), np.zeros((n, b.shape[1]))),
                       float(sample_time), "zoh")
    return np.asarray(control.dlqr(held.A, held.B, q_mat * sample_time,
                                   np.atleast_2d(r_mat) * sample_time)[0], dtype=float)


def lqe_on_part(model, spin_rate, c_meas, process, measurement):
    """Kalman gain (n, m) and estimator poles (n,) on the controllable part (the modes the
    torque cannot move are not excited by its noise either: the estimate leaves them at 0)."""
    import control

    a, b = model.linear_matrices(spin_rate)
    part = controllable_part(model, spin_rate)
    if not part.dropped:
        gain, _, poles = control.lqe(a, np.eye(a.shape[0]), c_meas,
                                     _noise_input(b, process), measurement)
        return np.asarray(gain, dtype=float), np.asarray(poles)
    a_r, b_r = part.reduce(a, b)
    gain_r, _, _ = control.lqe(a_r, np.eye(a_r.shape[0]), c_meas @ part.basis,
                               _noise_input(b_r, process), measurement)
    gain = part.basis @ np.asarray(gain_r, dtype=float)
    return gain, np.linalg.eigvals(a - gain @ c_meas)


def _noise_input(b, process) -> np.ndarray:
    """``B QN B^T``, exactly symmetric: python-control checks the symmetry of the ``G QN G^T``
    it forms to machine epsilon in absolute terms, which the rounding of a light hub's large
    ``B`` breaks (a 6.7e-3 kg m^2 rig: asymmetry 5e-14)."""
    q = np.asarray(b, dtype=float) @ np.atleast_2d(process) @ np.asarray(b, dtype=float).T
    return 0.5 * (q + q.T)


def dlqr_on_part(model, sample_time, q_mat, r_mat) -> np.ndarray:
    """Discrete LQR cost matrix (n, n) at rest, held over ``sample_time``, of the
    controllable part, as a quadratic form on the whole state (zero on the modes left out)."""
    import control

    a, b = model.linear_matrices(0.0)
    part = controllable_part(model, 0.0)
    if part.dropped:
        a, b = part.reduce(a, b)
        q_mat = part.basis.T @ q_mat @ part.basis
    m = a.shape[0]
    sys_d = control.c2d(control.ss(a, b, np.eye(m), np.zeros((m, 1))), sample_time, "zoh")
    _, p_mat, _ = control.dlqr(sys_d.A, sys_d.B, 0.5 * (q_mat + q_mat.T), r_mat)
    p_mat = np.asarray(p_mat)
    if part.dropped:
        p_mat = part.projector.T @ p_mat @ part.projector
    return 0.5 * (p_mat + p_mat.T)
