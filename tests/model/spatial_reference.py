"""Independent reference for tests: a hub turning about any axis, carrying flexible rods.

This module imports neither ``flexctl`` nor any other test helper (numpy, scipy and casadi
only): it is a second, independent model of the spatial structures of ``MODEL.md`` section 8
against which a modal model is checked. A rigid hub, pinned at its centre (free to rotate about
every axis) or floating free (six degrees of freedom, mass ``m_h`` at its centre), with inertia
tensor ``J_h`` (3 x 3, about the centre, in the hub frame ``B``) carries any number of flexible
appendages; a torque (in ``B``, a pure couple) acts on the hub only. No gravity, no damping.

Frames and coordinates
----------------------
Inertial ``N``; hub frame ``B``, attitude a unit quaternion ``q`` (scalar first, ``v_N = R(q)
v_B``), angular velocity ``w`` in ``B``; a free hub's centre at ``r`` in ``N`` with velocity ``v``
in ``B``. Appendage ``a``: root point ``r_a`` in ``B``, unit axis
``e1`` (``direction``), unit ``e3`` (``normal``, the section's flexible direction), ``e2 = e3 x
e1``; an inextensible rod of length ``l`` with ``rhoA``, ``EI_n`` (bending along ``e3``, i.e.
curvature about ``e2``), ``EI_l`` (bending along ``e2``, curvature about ``e3``), ``GJ`` and the
polar mass moment of inertia per length ``rho_Ip`` (rotary inertia of bending neglected), and
point masses ``m_k`` at arc lengths ``d_k`` (no rotary inertia).

Discretisation: a rigid-element chain (a discrete geometrically exact rod)
-------------------------------------------------------------------------
Each rod is cut into ``n`` equal elements of length ``h = l / n``; element ``i`` (arc length
``[i h, (i+1) h]``) keeps its flexibility in a spherical joint with rotational springs at its
midpoint ``s_i = (i + 1/2) h`` and the material between consecutive joints is a rigid,
inextensible link: link 0 (``[0, h/2]``) is clamped to the hub, links ``1 .. n-1`` are
``h`` long and the tip link ``n`` (``[l - h/2, l]``) is ``h/2`` long. This is the midpoint rule
for the rod's compliance (a static tip deflection is the midpoint-rule quadrature of a
polynomial), so every quantity converges as ``h^2`` (full-length links with a joint of
stiffness ``EI / h`` at the clamp would make it a one-sided, first-order, rule).

Link ``k`` has the frame ``C_k`` (columns: its ``e1, e2, e3`` in ``B``), ``C_0 = [e1 e2 e3]``,
``C_k = C_{k-1} exp([theta_{k-1}]x)``: the generalized coordinates of joint ``i`` are the
rotation vector ``theta_i`` of link ``i+1`` relative to link ``i``, in link ``i``'s frame (the
log map of the relative rotation). The joint stores

    V_i = 1/2 (GJ theta_i1^2 + EI_n theta_i2^2 + EI_l theta_i3^2) / h

(a rotation about ``e1`` is twist; a rotation about ``e2`` moves the rod along ``-e3``, i.e. is
the bending along the normal, stiffness ``EI_n``; a rotation about ``e3`` bends it along ``e2``,
``EI_l``): exactly the continuum energy ``1/2 int (GJ tau^2 + EI_n kappa_n^2 + EI_l kappa_l^2)
ds`` of an element bent to a uniform curvature vector, in any large rotation.

Each link is a rigid body carrying its share of the distributed mass exactly: mass ``rhoA L``
at its midpoint, principal inertia ``rho_Ip L`` about its axis and ``rhoA L^3 / 12`` (the
distributed line mass about the link's centre, not a section rotary inertia) transverse to
it. Point masses sit exactly at arc length ``d_k`` on the link that holds them.

Equations of motion
-------------------
Derived by CasADi from the Lagrangian (nothing hand-derived beyond ``T`` and ``V``): positions
and link frames are symbolic functions of the ``theta``; their rates come from
``casadi.jtimes`` along ``theta_dot``; a link's inertial velocity in ``B`` is ``w x c + c_t``
(``v + w x c + c_t`` on a free hub) and its angular velocity in its own frame
``C^T w + vee(C^T C_t)``. With ``u = (w, theta_dot)`` (pinned) or ``u = (w, v, theta_dot)``
(free) the kinetic energy ``T(theta, u) = 1/2 u^T M(theta) u`` (plus ``1/2 m_h |v|^2`` free)
depends on neither the attitude nor the position, so the Lagrange equations in the
quasi-velocities ``w`` and ``v`` (Euler-Poincare / Hamel) and the ``theta`` read

    d/dt dT/dw + w x dT/dw + v x dT/dv = torque,     d/dt dT/dv + w x dT/dv = 0 (free hub),
    d/dt dT/dtheta_dot - dT/dtheta + K theta = 0,

i.e. ``M u_t = (torque - w x p_w - v x p_v ; - w x p_v ; dT/dtheta - K theta) - d(M u)/dtheta .
theta_dot`` with ``p = dT/du`` (``p_w`` is the angular momentum about the hub centre, ``p_v``
the linear momentum, both in ``B``; pinned, the ``v`` terms and rows are absent). CasADi
returns per appendage the scaled body velocities ``V`` (``T = 1/2 |V|^2``), their Jacobian
``dV/du`` (so ``M = sum (dV/du)^T (dV/du) + diag(J_h, m_h I)``, the Hessian of ``T`` in the
velocities), ``dT/dtheta`` and the ``jtimes`` term; the arrowhead ``M`` is factorised by
Cholesky. ``q_t = 1/2 q (0, w)`` and ``r_t = R(q) v``; neither the quaternion nor the position
feeds back into the dynamics; the quaternion is renormalised at output. A free structure's
invariants are its linear momentum ``R p_v``, its angular momentum about the centre of mass
``R (p_w - c x p_v)`` (``c = sum m c_k / m`` the centre of mass from the hub centre, in ``B``)
and the uniform motion of the centre of mass ``r + R c``.

Integration
-----------
scipy's ``Radau`` (order 5, L-stable), ``rtol`` :data:`RTOL`, ``atol`` :data:`ATOL_ANGLE` on the
quaternion and the angles and :data:`ATOL_RATE` on the rates. The chain's highest modes are far
too stiff for an explicit method (3.2e5 rad/s, lateral zig-zag of the ``MODEL.md`` rod at 40
elements); a torque or a spin applied at once excites them with amplitudes far below the
absolute tolerances, which lets Radau step over them (it damps what it does not resolve; the
unforced check below keeps the energy to 1e-12). The Newton iterations use the stiff part of
the Jacobian only (``dtheta_t/dtheta_dot = I``, ``du_t/dtheta = -M(theta)^-1 K`` and the
quaternion rows), which sets their convergence rate, not the solution. Tighter absolute
tolerances resolve the spurious high modes and cost much more for nothing; looser ones cost
accuracy (a rate tolerance of 1e-7 instead of 1e-8 leaves up to 6e-7 of the tip peak).
The rate tolerance sets the smallest tip component that is resolved, not a fraction of the
peak: a torque whose jumps or kinks excite the stiff lateral plane (``EI_l`` 100 times
``EI_n``) leaves a lateral vibration of a few 1e-7 m that Radau damps away unless the joint
rates are resolved (a 1 m boom bending laterally by 5e-6 m: 2.5 % of that component lost with
a rate tolerance of 1e-6, 3e-4 with 1e-8 and 2e-4 with 1e-10, against the modal model). A
jump of the torque (``breakpoints``) restarts the integration; otherwise a step across it
would be rejected until it is tiny.
Keep each OpenBLAS on one thread (the test suite does, through ``tests/conftest.py``): with
their default threads on a busy two-core machine one Cholesky factorisation of the mass
matrix took 80 ms instead of 0.5 ms.

Measured (``tests/model/test_spatial_reference.py`` checks the first three and the free hub)
---------------------------------------------------------------------------------------------
- Clamped frequencies of the bare ``MODEL.md`` rod against the closed forms, relative error
  of modes 1, 2, 3 at 20 / 40 / 80 elements: bending (either plane) +5.7e-4, +2.0e-3,
  +3.3e-3 / +1.4e-4, +5.0e-4, +8.2e-4 / +3.6e-5, +1.2e-4, +2.0e-4; torsion -2.6e-4, -2.3e-3,
  -6.4e-3 / -6.4e-5, -5.8e-4, -1.6e-3 / -1.6e-5, -1.4e-4, -4.0e-4: second order (first mode
  ``0.23 / n^2`` bending, ``-0.10 / n^2`` torsion).
- Unforced, spinning at (0.6, -0.4, 1.0) rad/s, two soft oblique rods with point masses, a hub
  with products of inertia, tips moving by centimetres in every direction: ``H_N`` constant
  to 1.4e-13 and the energy to 6e-13 (relative) over 2 s.
- Plane motion (torque about the axis normal to the bending plane): out-of-plane tip motion,
  ``w_x``, ``w_y`` exactly 0; against the independent planar chain of
  ``tests/fe_multibody.py`` (same mesh, 10 elements, its implicit-midpoint steps extrapolated)
  the tip deflection agrees to 3e-8 of its peak, the hub angle to 4e-9.
- Response histories converge as ``h^2``: two ``MODEL.md`` rods (along ``+x`` and ``-x``,
  normals ``y`` and ``z``, tip masses) on the hub with small products of inertia, a 3-D
  one-period sine torque (0.5 N m, 1 s), 2 s: the largest change of each tip component,
  relative to that component's peak, is 0.7-1.8 % from 10 to 20 elements, 0.18-0.49 % from 20
  to 40 and 0.044-0.13 % from 40 to 80 (ratio 4.0). 40 elements are within 0.06-0.17 % of
  the converged history; ``fine + (fine - coarse) / 3`` from 20 and 40 elements is within
  1e-4 of it (3e-6 to 8e-6 on the large components). Wall time of :func:`chain_response`
  for that run (2 s, two appendages, one BLAS thread, a shared two-core machine): 9 s at 10
  elements, 19 s at 20, 33 s at 40, 126 s at 80.
- A free hub: unforced, the soft structure spinning and drifting keeps its energy, its linear
  momentum and its angular momentum about the centre of mass to 1e-12 over 1 s while the hub
  centre moves by 7 to 18 cm; under a torque the angular momentum about the centre of mass
  changes by the torque's impulse (to 1e-8, the quadrature of the check). In a plane, against
  the free-hub planar chain of ``tests/fe_multibody.py``: tip deflection, hub angle and hub
  centre within 4e-8 of the tip peak.
- Integration error with the default tolerances: about 1e-8 of the tip peak (the planar
  check above, 10 elements, 2 s: 8e-9 with the defaults, 7e-9 with every tolerance 100 times
  tighter, the rest being the planar chain's own error).
"""

from __future__ import annotations

import functools
import itertools
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.integrate import solve_ivp
from scipy.linalg import cho_factor, cho_solve, eigh

__all__ = ["ATOL_ANGLE", "ATOL_RATE", "RTOL", "ChainSystem", "chain_frequencies",
           "chain_response"]

#: Relative tolerance of the integrator.
RTOL = 1e-10
#: Absolute tolerance of the integrator on the quaternion and the joint angles (rad).
ATOL_ANGLE = 1e-9
#: Absolute tolerance of the integrator on ``w`` and the joint rates (rad/s).
ATOL_RATE = 1e-8


# ---------------------------------------------------------------------------------------------
# one rod
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Rod:
    """One appendage, discretised (hashable: the key of the CasADi function cache)."""

    name: str
    root: tuple
    frame: tuple          # 3 x 3, columns e1, e2, e3 in B, row-major tuple of tuples
    length: float
    rhoA: float
    EI_n: float
    EI_l: float
    GJ: float
    rho_Ip: float
    masses: tuple         # ((mass, arc length), ...)
    n: int

    @property
    def h(self) -> float:
        """Element length, m."""
        return self.length / self.n

    @property
    def link_lengths(self) -> np.ndarray:
        """Lengths of links ``0 .. n`` (half links at both ends), m."""
        h = self.h
        return np.array([h / 2] + [h] * (self.n - 1) + [h / 2])

    @property
    def link_starts(self) -> np.ndarray:
        """Arc length of the start of links ``0 .. n``, m."""
        h = self.h
        return np.concatenate([[0.0], (np.arange(self.n) + 0.5) * h])

    @property
    def stiffness(self) -> np.ndarray:
        """Diagonal of the joint stiffness ``K`` (3 per joint: twist, normal, lateral), N m."""
        return np.tile([self.GJ, self.EI_n, self.EI_l], self.n) / self.h


def _rod(appendage: dict, n_elements: int) -> _Rod:
    """Check and freeze an appendage dictionary (see :func:`chain_response`)."""
    n = int(n_elements)
    if n < 1:
        raise ValueError("n_elements must be at least 1")
    e1 = np.asarray(appendage["direction"], float).reshape(3)
    e3 = np.asarray(appendage["normal"], float).reshape(3)
    e1 = e1 / np.linalg.norm(e1)
    e3 = e3 / np.linalg.norm(e3)
    if abs(e1 @ e3) > 1e-9:
        raise ValueError("normal must be perpendicular to direction")
    e2 = np.cross(e3, e1)
    frame = np.column_stack([e1, e2, e3])
    length = float(appendage["length"])
    values = {k: float(appendage[k]) for k in ("rhoA", "EI_n", "EI_l", "GJ", "rho_Ip")}
    if length <= 0 or min(values.values()) <= 0:
        raise ValueError("length, rhoA, EI_n, EI_l, GJ and rho_Ip must be positive")
    masses = []
    for mass, position in appendage.get("masses", ()):
        mass, position = float(mass), float(position)
        if mass < 0 or not 0.0 <= position <= length:
            raise ValueError("point masses need mass >= 0 and 0 <= position <= length")
        masses.append((mass, position))
    return _Rod(name=str(appendage["name"]),
                root=tuple(np.asarray(appendage["root"], float).reshape(3)),
                frame=tuple(map(tuple, frame)), length=length, masses=tuple(masses), n=n,
                **values)


def _exp_so3(theta):
    """Rotation matrix ``exp([theta]x)`` (Rodrigues), smooth and NaN-free at 0 (SX)."""
    x2 = ca.dot(theta, theta)
    small = x2 < 1e-4
    x = ca.sqrt(ca.fmax(x2, 1e-4))          # the unused branch stays finite
    a_big = ca.sin(x) / x
    b_big = 0.5 * (ca.sin(x / 2) / (x / 2)) ** 2          # (1 - cos x) / x^2 without cancellation
    a_small = 1 - x2 / 6 * (1 - x2 / 20 * (1 - x2 / 42 * (1 - x2 / 72)))
    b_small = 0.5 * (1 - x2 / 12 * (1 - x2 / 30 * (1 - x2 / 56 * (1 - x2 / 90))))
    a = ca.if_else(small, a_small, a_big)
    b = ca.if_else(small, b_small, b_big)
    s = ca.skew(theta)
    return ca.SX.eye(3) + a * s + b * ca.mtimes(s, s)


def _vee(s):
    """The vector of the skew-symmetric part of a 3 x 3 matrix."""
    return 0.5 * ca.vertcat(s[2, 1] - s[1, 2], s[0, 2] - s[2, 0], s[1, 0] - s[0, 1])


@functools.lru_cache(maxsize=32)
def _rod_symbolic(rod: _Rod, free: bool = False):
    """Symbolic kinematics of one rod (CasADi SX).

    Returns ``(theta, theta_dot, w, v, V, tip, moment)``: the symbols (``v``, the hub centre's
    velocity in ``B``, only on a free hub, else None), the scaled body velocities ``V``
    (``T = 1/2 |V|^2`` is the kinetic energy of the rod and its point masses: per link
    ``sqrt(m) (v + w x c + c_t)`` and ``sqrt(I) * omega``, per point mass
    ``sqrt(m) (v + w x p + p_t)``), the tip position in ``B`` (m) and the first moment of mass
    ``sum m c`` of the links and point masses about the hub centre, in ``B`` (kg m).
    """
    n = rod.n
    th = ca.SX.sym("theta", 3 * n)
    thd = ca.SX.sym("theta_dot", 3 * n)
    w = ca.SX.sym("w", 3)
    v = ca.SX.sym("v", 3) if free else None
    lengths, starts = rod.link_lengths, rod.link_starts
    origins, frames = [], []
    origin = ca.DM(np.array(rod.root))
    c = ca.DM(np.array(rod.frame))
    for k in range(n + 1):
        if k > 0:
            c = ca.mtimes(c, _exp_so3(th[3 * k - 3:3 * k]))
        origins.append(origin)
        frames.append(c)
        origin = origin + c[:, 0] * lengths[k]
    tip = origin

    # bodies: (position in B, frame or None, mass, principal inertias or None)
    bodies = []
    for k in range(n + 1):
        mass = rod.rhoA * lengths[k]
        inertia = [rod.rho_Ip * lengths[k], mass * lengths[k] ** 2 / 12.0,
                   mass * lengths[k] ** 2 / 12.0]
        bodies.append((origins[k] + frames[k][:, 0] * (lengths[k] / 2), frames[k], mass,
                       inertia))
    for mass, position in rod.masses:
        k = min(n, int(np.floor(position / rod.h + 0.5)))      # the link holding arc length d
        bodies.append((origins[k] + frames[k][:, 0] * (position - starts[k]), None, mass, None))

    x = ca.vertcat(*[ca.vertcat(p, ca.vec(f)) if f is not None else p
                     for p, f, _, _ in bodies])
    x_dot = ca.jtimes(x, th, thd)
    velocities, row = [], 0
    moment = sum(mass * p for p, _, mass, _ in bodies)
    for p, f, mass, inertia in bodies:
        p_dot = x_dot[row:row + 3]
        velocity = ca.cross(w, p) + p_dot
        velocities.append(np.sqrt(mass) * (velocity + v if free else velocity))
        row += 3
        if f is not None:
            f_dot = ca.reshape(x_dot[row:row + 9], 3, 3)
            row += 9
            omega = ca.mtimes(f.T, w) + _vee(ca.mtimes(f.T, f_dot))
            velocities.append(np.sqrt(np.array(inertia)) * omega)
    return th, thd, w, v, ca.vertcat(*velocities), tip, moment


@functools.lru_cache(maxsize=32)
def _rod_functions(rod: _Rod, free: bool = False):
    """CasADi functions of one rod.

    ``dyn(theta, theta_dot, w[, v]) -> (V, dV/du, dT/dtheta, d(dT/du)/dtheta . theta_dot)``
    with ``u = (w, theta_dot)`` on a pinned hub, ``u = (w, v, theta_dot)`` on a free one, and
    ``T = 1/2 |V|^2`` the rod's (and its masses') kinetic energy; ``tip(theta) -> tip
    position in B`` (m); ``moment(theta) -> sum m c`` in ``B`` (kg m).
    """
    th, thd, w, v, velocities, tip, moment = _rod_symbolic(rod, free)
    hub = [w, v] if free else [w]
    u = ca.vertcat(*hub, thd)
    kinetic = 0.5 * ca.dot(velocities, velocities)
    dyn = ca.Function("dyn", [th, thd, *hub],
                      [ca.densify(velocities), ca.densify(ca.jacobian(velocities, u)),
                       ca.densify(ca.gradient(kinetic, th)),
                       ca.densify(ca.jtimes(ca.gradient(kinetic, u), th, thd))])
    return dyn, ca.Function("tip", [th], [tip]), ca.Function("moment", [th], [moment])


def _rest_mass_matrix(rod: _Rod) -> np.ndarray:
    """``d2T/dtheta_dot2`` of the rod at rest, straight, hub held (the ``theta`` block of M).

    ``V`` is linear in ``theta_dot``: its columns are ``V`` at unit rates (cheaper than a
    symbolic Jacobian for long chains).
    """
    th, thd, w, _, v, _, _ = _rod_symbolic(rod)
    m = 3 * rod.n
    velocity = ca.Function("velocity", [th, thd, w], [v]).map(m)
    jac = np.asarray(velocity(np.zeros((m, m)), np.eye(m), np.zeros((3, m))))
    return jac.T @ jac


# ---------------------------------------------------------------------------------------------
# the structure
# ---------------------------------------------------------------------------------------------

def _skew(a) -> np.ndarray:
    """``[a]x``, the matrix of ``a x .``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _rotation(q: np.ndarray) -> np.ndarray:
    """``R(q)`` (B to N) of a unit quaternion, scalar first."""
    q0, qv = q[0], q[1:]
    return (q0 * q0 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) + 2 * q0 * _skew(qv)


class _BufferedCall:
    """Evaluates a CasADi function into preallocated numpy arrays (no conversions)."""

    def __init__(self, function):
        self.buffer, self.trigger = function.buffer()
        self.args = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        self.results = []
        for i in range(function.n_out()):
            shape = function.size_out(i)
            if function.nnz_out(i) != shape[0] * shape[1]:
                raise ValueError("outputs must be dense")
            out = np.zeros(shape, order="F")
            flat = out.reshape(-1, order="F")
            assert np.shares_memory(out, flat)
            self.results.append(out[:, 0] if shape[1] == 1 else out)
            self.buffer.set_res(i, flat)
        for i, a in enumerate(self.args):
            self.buffer.set_arg(i, a)

    def __call__(self, *args):
        for a, x in zip(self.args, args):
            a[:] = x
        self.trigger()
        return self.results


class ChainSystem:
    """The rigid-element chain model of a hub, pinned or free, with appendages.

    State ``y = (q (4), r (3, free hub), theta (N), w (3), v (3, free hub), theta_dot (N))``
    with ``r`` the hub centre in ``N`` (m), ``v`` its velocity in ``B`` (m/s) and ``theta`` the
    joint rotation vectors of all appendages in order (3 per joint, components twist, normal,
    lateral).

    Parameters
    ----------
    hub_inertia : array_like, shape (3, 3)
        Hub inertia tensor about its centre, in ``B``, kg m^2.
    appendages : list of dict
        As in :func:`chain_response`.
    n_elements : int
        Elements per appendage.
    hub_mass : float or None
        None: the hub's centre is pinned; a number (kg, >= 0): the hub floats free with this
        mass at its centre.
    """

    def __init__(self, hub_inertia, appendages, n_elements: int = 40, hub_mass=None):
        self.hub_inertia = np.asarray(hub_inertia, float).reshape(3, 3)
        if not np.allclose(self.hub_inertia, self.hub_inertia.T, rtol=0, atol=1e-12):
            raise ValueError("hub_inertia must be symmetric")
        self.free = hub_mass is not None
        self.hub_mass = float(hub_mass) if self.free else 0.0
        if self.hub_mass < 0:
            raise ValueError("hub_mass must be >= 0")
        self.rods = [_rod(a, n_elements) for a in appendages]
        if len({r.name for r in self.rods}) != len(self.rods):
            raise ValueError("appendage names must be unique")
        self.functions = [_rod_functions(r, self.free) for r in self.rods]
        self.calls = [_BufferedCall(dyn) for dyn, _, _ in self.functions]
        sizes = [3 * r.n for r in self.rods]
        self.slices = [slice(a, b) for a, b in zip(np.cumsum([0] + sizes[:-1]),
                                                     np.cumsum(sizes))]
        self.n_theta = int(sum(sizes))
        #: Hub speeds: ``w`` (and ``v`` for a free hub).
        self.n_hub = 6 if self.free else 3
        self.stiffness = np.concatenate([r.stiffness for r in self.rods] + [np.zeros(0)])
        #: Total mass, kg: hub (free) plus rods and point masses.
        self.total_mass = self.hub_mass + sum(r.rhoA * r.length + sum(m for m, _ in r.masses)
                                              for r in self.rods)

    # state layout
    @property
    def n_coordinates(self) -> int:
        """Coordinates: quaternion, hub position (free), joint angles."""
        return 4 + (3 if self.free else 0) + self.n_theta

    def split(self, y):
        """``(q, theta, w, theta_dot)`` views of a state vector (see :meth:`split_free`)."""
        q, _, theta, w, _, theta_dot = self.split_free(y)
        return q, theta, w, theta_dot

    def split_free(self, y):
        """``(q, r, theta, w, v, theta_dot)`` views of a state vector (``r``, ``v`` None on
        a pinned hub)."""
        c, n = self.n_coordinates, self.n_theta
        r = y[4:7] if self.free else None
        v = y[c + 3:c + 6] if self.free else None
        return y[:4], r, y[c - n:c], y[c:c + 3], v, y[c + self.n_hub:]

    def initial_state(self, angular_velocity=(0.0, 0.0, 0.0),
                      velocity=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Straight, undeformed, at rest relative to the hub, ``q = (1, 0, 0, 0)``, a free
        hub's centre at the origin.

        Parameters
        ----------
        angular_velocity : array_like, shape (3,)
            ``w`` in ``B``, rad/s.
        velocity : array_like, shape (3,)
            A free hub centre's velocity ``v`` in ``B``, m/s (ignored when pinned).

        Returns
        -------
        ndarray
            The state.
        """
        y = np.zeros(self.n_coordinates + self.n_hub + self.n_theta)
        y[0] = 1.0
        c = self.n_coordinates
        y[c:c + 3] = np.asarray(angular_velocity, float)
        if self.free:
            y[c + 3:c + 6] = np.asarray(velocity, float)
        return y

    def _evaluate(self, theta, w, v, theta_dot):
        """Mass matrix, momentum ``p = M u``, ``dT/dtheta``, the ``jtimes`` term and ``T``
        (``u = (w, v (free), theta_dot)``)."""
        n, k = self.n_theta, self.n_hub
        mass = np.zeros((k + n, k + n))
        mass[:3, :3] = self.hub_inertia
        momentum = np.zeros(k + n)
        momentum[:3] = self.hub_inertia @ w
        kinetic = 0.5 * w @ self.hub_inertia @ w
        hub_speeds = (w,)
        if self.free:
            mass[3:6, 3:6] = self.hub_mass * np.eye(3)
            momentum[3:6] = self.hub_mass * v
            kinetic += 0.5 * self.hub_mass * v @ v
            hub_speeds = (w, v)
        grad = np.zeros(n)
        bias = np.zeros(k + n)
        for call, s in zip(self.calls, self.slices):
            vel, jac, g, b = call(theta[s], theta_dot[s], *hub_speeds)
            jh, jt = jac[:, :k], jac[:, k:]
            rows = slice(k + s.start, k + s.stop)
            mass[:k, :k] += jh.T @ jh
            mass[:k, rows] = jh.T @ jt
            mass[rows, :k] = mass[:k, rows].T
            mass[rows, rows] = jt.T @ jt
            momentum[:k] += jh.T @ vel
            momentum[rows] = jt.T @ vel
            grad[s] = g
            bias[:k] += b[:k]
            bias[rows] = b[k:]
            kinetic += 0.5 * vel @ vel
        return mass, momentum, grad, bias, kinetic

    def rhs(self, t, y, torque=None):
        """``dy/dt``.

        The hub rows are the Euler-Poincare (Hamel) equations in the quasi-velocities ``w``
        and ``v``: ``d/dt dT/dw + w x dT/dw + v x dT/dv = torque`` and
        ``d/dt dT/dv + w x dT/dv = 0`` (no force), ``r_t = R(q) v``.

        Parameters
        ----------
        t : float
            Time, s.
        y : ndarray
            State.
        torque : callable or None
            ``t -> (3,)`` hub torque in ``B``, N m; None: no torque.

        Returns
        -------
        ndarray
            The state's rate.
        """
        q, _, theta, w, v, theta_dot = self.split_free(y)
        k = self.n_hub
        mass, momentum, grad, bias, _ = self._evaluate(theta, w, v, theta_dot)
        force = -bias
        force[:3] -= np.cross(w, momentum[:3])
        if self.free:
            force[:3] -= np.cross(v, momentum[3:6])
            force[3:6] -= np.cross(w, momentum[3:6])
        if torque is not None:
            force[:3] += np.asarray(torque(t), float).reshape(3)
        force[k:] += grad - self.stiffness * theta
        u_dot = cho_solve(cho_factor(mass), force)
        q_dot = 0.5 * np.concatenate([[-q[1:] @ w], q[0] * w + np.cross(q[1:], w)])
        r_dot = [_rotation(q) @ v] if self.free else []
        return np.concatenate([q_dot, *r_dot, theta_dot, u_dot])

    def stiff_jacobian(self, t, y, torque=None):
        """The stiff part of ``d(dy/dt)/dy`` (for the Newton iterations of the integrator).

        Parameters
        ----------
        t : float
            Time, s.
        y : ndarray
            State.
        torque : callable or None
            Unused (the signature of :meth:`rhs`).

        Returns
        -------
        scipy.sparse.csc_matrix
            ``dq_t/d(q, w)``, ``dr_t/dv = R(q)`` (free hub), ``dtheta_t/dtheta_dot = I`` and
            ``du_t/dtheta = -M^-1 K``.
        """
        q, _, theta, w, v, theta_dot = self.split_free(y)
        n, k, c = self.n_theta, self.n_hub, self.n_coordinates
        mass = self._evaluate(theta, w, v, theta_dot)[0]
        block = -cho_solve(cho_factor(mass), np.eye(k + n)[:, k:]) * self.stiffness
        q0, qv = q[0], q[1:]
        jac = np.zeros((y.size, y.size))
        jac[:4, :4] = 0.5 * np.block([[np.zeros((1, 1)), -w[None, :]], [w[:, None], -_skew(w)]])
        jac[:4, c:c + 3] = 0.5 * np.vstack([-qv[None, :], q0 * np.eye(3) + _skew(qv)])
        if self.free:
            jac[4:7, c + 3:c + 6] = _rotation(q)
        jac[c - n:c, c + k:] = np.eye(n)
        jac[c:, c - n:c] = block
        return sp.csc_matrix(jac)

    def first_moment(self, y) -> np.ndarray:
        """``sum m c`` of the rods and point masses about the hub centre, in ``B``, kg m (the
        hub's own mass sits at the centre).

        Parameters
        ----------
        y : ndarray
            State.

        Returns
        -------
        ndarray, shape (3,)
        """
        theta = self.split(y)[1]
        return sum(np.asarray(moment(theta[s])).ravel()
                   for (_, _, moment), s in zip(self.functions, self.slices))

    def invariants(self, y) -> dict:
        """Momenta, energy and centre of mass of a state.

        Parameters
        ----------
        y : ndarray
            State.

        Returns
        -------
        dict
            ``angular`` (3,): the angular momentum in ``N`` about the hub centre (pinned) or
            about the centre of mass (free), kg m^2/s; ``energy``: ``T + V``, J; for a free
            hub also ``linear`` (3,): the linear momentum in ``N``, kg m/s, and
            ``centre_of_mass`` (3,): in ``N``, m.
        """
        q, r, theta, w, v, theta_dot = self.split_free(y)
        _, momentum, _, _, kinetic = self._evaluate(theta, w, v, theta_dot)
        rotation = _rotation(q / np.linalg.norm(q))
        out = {"energy": kinetic + 0.5 * theta @ (self.stiffness * theta)}
        if not self.free:
            out["angular"] = rotation @ momentum[:3]
            return out
        offset = self.first_moment(y) / self.total_mass         # centre of mass from r, in B
        out["angular"] = rotation @ (momentum[:3] - np.cross(offset, momentum[3:6]))
        out["linear"] = rotation @ momentum[3:6]
        out["centre_of_mass"] = r + rotation @ offset
        return out

    def tip_displacements(self, y) -> dict:
        """Each tip's position minus its undeformed position, in ``B`` (m).

        Parameters
        ----------
        y : ndarray
            State.

        Returns
        -------
        dict
            ``{name: (3,)}``.
        """
        theta = self.split(y)[1]
        out = {}
        for rod, (_, tip, _), s in zip(self.rods, self.functions, self.slices):
            straight = np.array(rod.root) + rod.length * np.array(rod.frame)[:, 0]
            out[rod.name] = np.asarray(tip(theta[s])).ravel() - straight
        return out

    def simulate(self, torque, t_final: float, times, angular_velocity=(0.0, 0.0, 0.0),
                 velocity=(0.0, 0.0, 0.0), *, breakpoints=(), rtol: float = RTOL,
                 atol_angle: float = ATOL_ANGLE, atol_rate: float = ATOL_RATE):
        """Integrate from the straight state at rest relative to the hub.

        Parameters
        ----------
        torque : callable
            ``t -> (3,)`` hub torque in ``B``, N m.
        t_final : float
            End time, s.
        times : array_like
            Output times in ``[0, t_final]``, s.
        angular_velocity : array_like, shape (3,)
            Initial ``w`` in ``B``, rad/s.
        velocity : array_like, shape (3,)
            Initial ``v`` of a free hub's centre in ``B``, m/s (ignored when pinned).
        breakpoints : array_like
            Times, s, where the torque jumps or kinks: the integration stops and restarts
            there, so that no step crosses one.
        rtol : float
            Relative tolerance of ``Radau``.
        atol_angle : float
            Absolute tolerance on the quaternion, the joint angles (rad) and a free hub's
            position (m).
        atol_rate : float
            Absolute tolerance on ``w``, the joint rates (rad/s) and a free hub's velocity
            (m/s).

        Returns
        -------
        scipy.integrate OdeResult
            With ``y`` the states at ``times`` (quaternions renormalised) and ``stats``
            (function and Jacobian calls, steps, wall time).
        """
        times = np.asarray(times, float)
        if times.size and (times.min() < 0.0 or times.max() > t_final):
            raise ValueError("times must lie in [0, t_final]")
        atol = np.concatenate([np.full(self.n_coordinates, float(atol_angle)),
                               np.full(self.n_hub + self.n_theta, float(atol_rate))])
        t_final = float(t_final)
        edges = np.unique(np.concatenate([[0.0], [b for b in np.asarray(breakpoints, float)
                                                  if 0.0 < b < t_final], [t_final]]))
        start = time.perf_counter()
        y = self.initial_state(angular_velocity, velocity)
        states, counts = [], np.zeros(3, int)
        for a, b in itertools.pairwise(edges):
            inside = times[(times >= a) & ((times < b) | (b == t_final))]
            sol = solve_ivp(self.rhs, (a, b), y, method="Radau",
                            t_eval=np.unique(np.append(inside, b)), rtol=rtol, atol=atol,
                            jac=self.stiff_jacobian, args=(torque,))
            if not sol.success:
                raise RuntimeError(f"integration failed: {sol.message}")
            states.append(sol.y[:, :inside.size])
            counts += (sol.nfev, sol.njev, sol.nlu)
            y = sol.y[:, -1]
        sol.t = times
        sol.y = np.hstack(states)
        sol.y[:4] /= np.linalg.norm(sol.y[:4], axis=0)
        sol.nfev, sol.njev, sol.nlu = map(int, counts)
        sol.stats = {"nfev": sol.nfev, "njev": sol.njev, "nlu": sol.nlu,
                     "seconds": time.perf_counter() - start}
        return sol


# ---------------------------------------------------------------------------------------------
# public interface
# ---------------------------------------------------------------------------------------------

def chain_response(hub_inertia, appendages, torque, t_final, times, angular_velocity=(0, 0, 0),
                   n_elements=40, hub_mass=None, breakpoints=(), rtol=RTOL,
                   atol_angle=ATOL_ANGLE, atol_rate=ATOL_RATE):
    """Response of the rigid-element chain model to a hub torque (pinned or free hub).

    Parameters
    ----------
    hub_inertia : array_like, shape (3, 3)
        Hub inertia tensor about its centre, in ``B``, kg m^2.
    appendages : list of dict
        Keys ``name``; ``root`` (3,) root point in ``B``, m; ``direction`` (3,) unit axis
        ``e1``; ``normal`` (3,) unit ``e3``, perpendicular to ``e1``, the flexible direction;
        ``length`` m; ``rhoA`` kg/m; ``EI_n`` (bending along the normal) and ``EI_l`` (along
        ``e2 = e3 x e1``) N m^2; ``GJ`` N m^2; ``rho_Ip`` polar mass moment of inertia per
        length, kg m; ``masses`` list of ``(mass kg, arc length from the root m)``.
    torque : callable
        ``t -> (3,)`` hub torque in ``B``, N m.
    t_final : float
        End time, s.
    times : array_like, shape (P,)
        Output times in ``[0, t_final]``, s.
    angular_velocity : array_like, shape (3,)
        Initial ``w`` in ``B``, rad/s (the structure starts straight and at rest relative to
        the hub, ``q = (1, 0, 0, 0)``, a free hub's centre at the origin and at rest).
    n_elements : int
        Elements per appendage.
    hub_mass : float or None
        None: the hub's centre is pinned; a number: the hub floats free with this mass, kg.
    breakpoints : array_like
        Times, s, of the torque's jumps and kinks (the integration restarts there).
    rtol, atol_angle, atol_rate : float
        Tolerances of the integration (see :meth:`ChainSystem.simulate`).

    Returns
    -------
    dict
        ``t`` (P,); ``quaternion`` (4, P) B to N, scalar first; ``w`` (3, P) rad/s in ``B``;
        ``tips`` ``{name: (3, P)}``, each tip's displacement from where the rigidly moving
        undeformed tip would be, in ``B`` components, m; for a free hub also ``position``
        (3, P), the hub centre in ``N``, m, and ``centre_of_mass`` (3, P), in ``N``, m.
    """
    system = ChainSystem(hub_inertia, appendages, n_elements, hub_mass=hub_mass)
    sol = system.simulate(torque, t_final, times, angular_velocity, breakpoints=breakpoints,
                          rtol=rtol, atol_angle=atol_angle, atol_rate=atol_rate)
    q, r, _, w, _, _ = system.split_free(sol.y)
    tips = {r_.name: np.empty((3, sol.y.shape[1])) for r_ in system.rods}
    for j in range(sol.y.shape[1]):
        for name, d in system.tip_displacements(sol.y[:, j]).items():
            tips[name][:, j] = d
    out = {"t": sol.t, "quaternion": q, "w": w, "tips": tips}
    if system.free:
        out["position"] = r
        out["centre_of_mass"] = np.column_stack(
            [system.invariants(sol.y[:, j])["centre_of_mass"] for j in range(sol.y.shape[1])])
    return out


def chain_frequencies(appendage, n_elements=40, count=4):
    """Clamped natural frequencies of one appendage from the chain linearised at rest.

    The hub is held; at rest the straight rod's twist, normal and lateral motions decouple
    (checked), and each is solved as ``K v = omega^2 M v`` on its own joint components.

    Parameters
    ----------
    appendage : dict
        As in :func:`chain_response`.
    n_elements : int
        Elements of the chain.
    count : int
        Frequencies per family (at most ``n_elements``).

    Returns
    -------
    dict
        ``{'normal': (count,), 'lateral': (count,), 'torsion': (count,)}``, rad/s, ascending.
    """
    rod = _rod(appendage, n_elements)
    if not 1 <= count <= rod.n:
        raise ValueError("count must be between 1 and n_elements")
    mass = _rest_mass_matrix(rod)
    stiffness = rod.stiffness
    out = {}
    for family, k in (("torsion", 0), ("normal", 1), ("lateral", 2)):
        idx = np.arange(k, 3 * rod.n, 3)
        other = np.setdiff1d(np.arange(3 * rod.n), idx)
        coupling = np.abs(mass[np.ix_(idx, other)]).max(initial=0.0)
        if coupling > 1e-12 * np.abs(mass).max():
            raise AssertionError(f"{family} couples to the other motions at rest")
        values = eigh(np.diag(stiffness[idx]), mass[np.ix_(idx, idx)], eigvals_only=True)
        out[family] = np.sqrt(values[:count])
    return {f: out[f] for f in ("normal", "lateral", "torsion")}


def _example_appendage(name="a", root=(0.06, 0.0, 0.0), direction=(1.0, 0.0, 0.0),
                       normal=(0.0, 1.0, 0.0), masses=((0.085, 1.62),)):
    """The 1.8 m aluminium rod of ``MODEL.md`` (``I_n`` 1.3021e-10, ``I_l`` 5.2e-8 m^4).

    Parameters
    ----------
    name : str
        Appendage name.
    root : tuple
        Root point in ``B``, m.
    direction : tuple
        Axis ``e1``.
    normal : tuple
        Flexible direction ``e3``.
    masses : tuple
        ``(mass, arc length)`` pairs.

    Returns
    -------
    dict
        An appendage for :func:`chain_response`.
    """
    rho, area, e_mod, g_mod = 2766.0, 2.5e-4, 6.9e10, 2.6e10
    i_n, i_l, j = 1.3021e-10, 5.2e-8, 5e-10
    return {"name": name, "root": root, "direction": direction, "normal": normal,
            "length": 1.8, "rhoA": rho * area, "EI_n": e_mod * i_n, "EI_l": e_mod * i_l,
            "GJ": g_mod * j, "rho_Ip": rho * (i_n + i_l), "masses": list(masses)}
