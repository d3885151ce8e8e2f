"""Independent geometrically exact reference simulator for the planar hub-beam-mass system.

This module deliberately does not import ``flexctl``: it is a second, independent model
against which the toolbox can be checked (MODEL.md sections 1, 5, 6 and 7).

Formulation: rigid finite elements (Kruszewski / Wittbrodt "rigid finite element method")
----------------------------------------------------------------------------------------
The beam of length ``l`` is meshed with nodes ``0 = x_0 < x_1 < ... < x_n = l`` (the point
masses sit on nodes). Each segment ``[x_{i-1}, x_i]`` of length ``h_i`` carries its bending
flexibility in a rotational spring of stiffness ``EI / h_i`` at its midpoint; the material
between two consecutive springs is a rigid, exactly inextensible link that carries the beam's
distributed mass (uniform ``rhoA``) and the point masses inside it. The first half-segment
``[0, h_1/2]`` is rigid with the hub, the last ``[l - h_n/2, l]`` is the free tip link.

Generalized coordinates are the *inertial* angles of the links, ``phi_0 = theta`` (the hub
together with the clamped root part; link 0 runs from O to the first spring, length
``b + h_1/2``) and ``phi_1 .. phi_n`` (link ``i`` runs between springs ``i`` and ``i + 1``).
This is a planar chain of rigid bodies pinned at O, so everything is exact for arbitrarily
large rotations: foreshortening, centrifugal stiffening and softening, Coriolis coupling all
come out of the geometry, and the axial direction is exactly rigid (no penalty stiffness).

Kinetic energy ``T = 1/2 phi_dot^T M(phi) phi_dot`` with ``M_jk = A_jk cos(phi_j - phi_k)``;
``A`` is a constant symmetric matrix built from the links' lengths, masses and first and second
mass moments (plus ``J_h`` on the hub). Potential ``V = sum_i EI/(2 h_i) (phi_i - phi_{i-1})^2``.
Lagrange's equations

    M(phi) phi_dd + S(phi) phi_dot^2 + K phi = T_h e_0,    S_jk = A_jk sin(phi_j - phi_k)

are integrated with the fixed-step implicit midpoint rule (second order, unconditionally
stable, non-dissipative) with Newton iterations on an exact analytic Jacobian: the bending
springs make the system stiff, and with a light hub the torque excites the stiff modes a
little, which an adaptive error control (scipy Radau, still available) would resolve at great
cost. With a prescribed hub motion the first equation is dropped and returns the hub torque
the motion needs.

The method converges as O(h^2) in the element size (first clamped-free frequency: relative
error 0.23 / n_elements^2).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["FESystem", "simulate_fe", "convergence_study", "spin_up_motion", "sine_torque"]


@dataclass(frozen=True)
class FESystem:
    """A planar hub-beam-mass system, SI units.

    Parameters
    ----------
    hub_inertia : float
        Hub moment of inertia ``J_h`` about the axis O, kg m^2 (may be 0).
    hub_radius : float
        Hub radius ``b``, m (may be 0); the beam is clamped radially there.
    length : float
        Beam length ``l``, m.
    linear_density : float
        ``rhoA``, kg/m.
    bending_stiffness : float
        ``EI``, N m^2.
    masses : tuple of (float, float)
        Point masses as ``(mass, distance_from_root)`` pairs, distance in ``[0, l]``.
    """

    hub_inertia: float
    hub_radius: float
    length: float
    linear_density: float
    bending_stiffness: float
    masses: tuple = ()


# --------------------------------------------------------------------------------------------
# reference manoeuvres (MODEL.md section 5)

def spin_up_motion(w_s: float, t_s: float):
    """Kane, Ryan and Banerjee's spin-up as a ``hub_motion`` callable.

    Parameters
    ----------
    w_s : float
        Final spin rate, rad/s.
    t_s : float
        Ramp time, s.

    Returns
    -------
    callable
        ``t -> (theta, theta_dot, theta_ddot)``.
    """
    def motion(t):
        if t < t_s:
            c = 2.0 * np.pi / t_s
            theta = (w_s / t_s) * (t * t / 2.0 + (np.cos(c * t) - 1.0) / c ** 2)
            theta_d = (w_s / t_s) * (t - np.sin(c * t) / c)
            theta_dd = (w_s / t_s) * (1.0 - np.cos(c * t))
            return theta, theta_d, theta_dd
        return w_s * (t - t_s / 2.0), w_s, 0.0
    return motion


def sine_torque(amplitude: float, period: float):
    """One-period sine torque ``T = amplitude sin(2 pi t / period)`` for ``t <= period``, else 0."""
    def torque(t):
        return amplitude * np.sin(2.0 * np.pi * t / period) if t <= period else 0.0
    return torque


# --------------------------------------------------------------------------------------------
# discretization

def _mesh(system: FESystem, n_elements: int) -> np.ndarray:
    """Beam nodes ``x_0 = 0 .. x_n = l`` with every point mass on a node."""
    l = float(system.length)
    cuts = sorted({0.0, l} | {float(d) for _, d in system.masses if 0.0 < d < l})
    pieces = np.diff(cuts)
    if n_elements < len(pieces):
        raise ValueError("n_elements must be at least the number of pieces between masses")
    counts = np.maximum(1, np.round(n_elements * pieces / l).astype(int))
    while counts.sum() > n_elements:          # fix rounding so the total is exact
        counts[np.argmax(pieces / counts * (counts > 1))] -= 1
    while counts.sum() < n_elements:
        counts[np.argmax(pieces / counts)] += 1
    nodes = [np.linspace(a, b, c + 1)[:-1] for a, b, c in zip(cuts[:-1], cuts[1:], counts)]
    return np.concatenate(nodes + [[l]])


class _Chain:
    """Rigid-link chain of the rigid finite element model (internal)."""

    def __init__(self, system: FESystem, n_elements: int):
        if system.length <= 0 or system.linear_density <= 0 or system.bending_stiffness <= 0:
            raise ValueError("length, linear_density and bending_stiffness must be positive")
        b, rho = float(system.hub_radius), float(system.linear_density)
        ei = float(system.bending_stiffness)
        x = _mesh(system, n_elements)
        h = np.diff(x)
        n = len(h)
        # spring positions (arc length) and link boundaries
        springs = x[:-1] + h / 2.0
        starts = np.concatenate([[0.0], springs])          # link i starts at arc length starts[i]
        ends = np.concatenate([springs, [x[-1]]])
        # link 0 is measured from O: radius b + s; links i >= 1 from their spring
        lengths = np.concatenate([[b + ends[0]], ends[1:] - starts[1:]])
        mass = rho * (ends - starts)                       # beam mass on each link
        # first and second mass moments about the link's start point
        first = np.empty(n + 1)
        second = np.empty(n + 1)
        first[0] = rho * ((b + ends[0]) ** 2 - b ** 2) / 2.0
        second[0] = rho * ((b + ends[0]) ** 3 - b ** 3) / 3.0 + float(system.hub_inertia)
        first[1:] = mass[1:] * lengths[1:] / 2.0
        second[1:] = mass[1:] * lengths[1:] ** 2 / 3.0
        for m, d in system.masses:
            m, d = float(m), float(d)
            if not 0.0 <= d <= x[-1]:
                raise ValueError("point mass outside the beam")
            i = int(np.searchsorted(ends, d, side="left")) if d > 0 else 0
            i = min(i, n)
            r = (b + d) if i == 0 else (d - starts[i])
            mass[i] += m
            first[i] += m * r
            second[i] += m * r * r
        beyond = np.concatenate([np.cumsum(mass[::-1])[::-1][1:], [0.0]])  # mass of links > i
        a = np.empty((n + 1, n + 1))
        for j in range(n + 1):
            a[j, j] = second[j] + lengths[j] ** 2 * beyond[j]
            k = np.arange(j + 1, n + 1)
            a[j, k] = lengths[j] * (first[k] + lengths[k] * beyond[k])
            a[k, j] = a[j, k]
        stiff = ei / h                                     # spring i+1 joins links i and i+1
        kmat = np.zeros((n + 1, n + 1))
        idx = np.arange(n)
        kmat[idx, idx] += stiff
        kmat[idx + 1, idx + 1] += stiff
        kmat[idx, idx + 1] -= stiff
        kmat[idx + 1, idx] -= stiff
        self.n, self.x, self.h, self.a, self.k, self.lengths = n, x, h, a, kmat, lengths
        self.b, self.l = b, float(system.length)

    def parts(self, phi, w):
        """Mass matrix ``M``, ``C = A cos``, ``S = A sin`` and the force without the torque."""
        e = np.exp(1j * np.asarray(phi, dtype=float))
        both = self.a * np.outer(e, e.conj())             # A exp(i (phi_j - phi_k))
        cm, sm = both.real, both.imag
        force = -sm @ (w * w) - self.k @ phi
        return cm, sm, force

    def jac_parts(self, cm, sm, w, acc):
        """``dF/dphi - d(M acc)/dphi`` and ``dF/dw`` for the Jacobian."""
        w2 = w * w
        g = -self.k.copy()
        g -= np.diag(cm @ w2)
        g += cm * w2[None, :]
        g -= np.diag(-(sm @ acc))
        g -= sm * acc[None, :]
        gw = -2.0 * sm * w[None, :]
        return g, gw

    def tip(self, phi):
        """Tip position in the hub frame, rows ``(x, y)``."""
        rel = phi[1:] - phi[0]
        ln = self.lengths[1:, None]
        return self.lengths[0] + (ln * np.cos(rel)).sum(axis=0), (ln * np.sin(rel)).sum(axis=0)

    def energy(self, phi, w):
        """Kinetic plus bending energy and the angular momentum about O (columns of states)."""
        out_e, out_h = [], []
        for j in range(phi.shape[1]):
            cm, _, _ = self.parts(phi[:, j], w[:, j])
            mw = cm @ w[:, j]
            out_e.append(0.5 * w[:, j] @ mw + 0.5 * phi[:, j] @ self.k @ phi[:, j])
            out_h.append(mw.sum())
        return np.array(out_e), np.array(out_h)

    def link_angles(self, slope):
        """Hub-frame link angles for an initial slope-angle function of arc length."""
        starts = np.concatenate([[0.0], self.x[:-1] + self.h / 2.0])
        ends = np.concatenate([starts[1:], [self.x[-1]]])
        mids = 0.5 * (starts[1:] + ends[1:])
        return np.concatenate([[0.0], [float(slope(s)) for s in mids]])


# --------------------------------------------------------------------------------------------
# simulation

class _DenseInverse:
    """The inverse of a dense iteration matrix, applied as one product."""

    def __init__(self, z):
        self.inv = np.linalg.inv(z)

    def solve(self, v):
        return self.inv @ v


def _midpoint(problem, q0, w0, t_final, dt, tol, rate_scale, factor=_DenseInverse):
    """Fixed-step implicit midpoint rule for ``M(q) w' = f(t, q, w)``, ``q' = w``.

    ``problem(t, q, w, with_jac)`` returns ``(M, f)`` or ``(M, f, Jq, Jw)`` with
    ``J = d(f - M a)/d(q, w)`` at ``a = M^-1 f``. Each step solves for the midpoint rate
    ``wm``: ``M(qm) (wm - w) = dt/2 f(tm, qm, wm)``, ``qm = q + dt/2 wm``, by Newton with the
    iteration matrix ``M - dt/2 (dt/2 Jq + Jw)`` inverted by ``factor`` (an object with
    ``solve(v)``; default a dense inverse) and reused across
    iterations and steps (an iteration costs one evaluation of ``M`` and ``f`` and two
    products, no solve). Then
    ``q += dt wm``, ``w = 2 wm - w``. Non-dissipative, unconditionally stable, second order.
    """
    n_steps = max(1, int(np.ceil(t_final / dt - 1e-9)))
    dt = t_final / n_steps
    nq = len(q0)
    ts = np.linspace(0.0, t_final, n_steps + 1)
    qs = np.empty((n_steps + 1, nq))
    ws = np.empty((n_steps + 1, nq))
    qs[0], ws[0] = q0, w0
    q, w = np.array(q0, float), np.array(w0, float)
    inv, age = None, 0
    n_jac = n_it = 0
    h = dt / 2.0
    for i in range(n_steps):
        tm = ts[i] + h
        wm = w.copy()
        age += 1
        if age > 25:
            inv = None
        for it in range(60):
            qm = q + h * wm
            if inv is None:
                m, f, jq, jw = problem(tm, qm, wm, True)
                inv = factor(m - h * (h * jq + jw))
                n_jac += 1
                age = 0
            else:
                m, f = problem(tm, qm, wm, False)
            step = inv.solve(m @ (wm - w) - h * f)
            wm -= step
            n_it += 1
            if np.max(np.abs(step)) <= tol * (np.max(np.abs(wm)) + rate_scale):
                break
            if it in (3, 10, 25):
                inv = None
        else:
            raise RuntimeError(f"Newton iteration did not converge at t = {tm:.6g}")
        q = q + dt * wm
        w = 2.0 * wm - w
        qs[i + 1], ws[i + 1] = q, w
    return ts, qs, ws, n_it, n_jac, dt


def simulate_fe(system: FESystem, t_final: float, *, torque=None, hub_motion=None,
                n_elements: int = 24, rtol: float = 1e-8, t_eval=None, dt=None,
                initial_slope=None, initial_theta: float = 0.0,
                initial_theta_dot: float = 0.0, method: str = "midpoint") -> dict:
    """Simulate the geometrically exact rigid-finite-element model.

    Parameters
    ----------
    system : FESystem
        The hub-beam-mass system.
    t_final : float
        End time, s (start at 0).
    torque : callable, optional
        ``t -> T_h`` in N m, applied to the free hub. With neither ``torque`` nor
        ``hub_motion`` the hub is free and unforced.
    hub_motion : callable, optional
        ``t -> (theta, theta_dot, theta_ddot)``: prescribed hub motion (exclusive with
        ``torque``); the torque it needs is returned as ``'torque'``.
    n_elements : int
        Number of beam elements (point masses are put on nodes).
    rtol : float
        Newton tolerance of the midpoint rule (relative tolerance for the ``solve_ivp`` methods).
    t_eval : array_like, optional
        Output times (linear interpolation between steps); by default every time step.
    dt : float, optional
        Time step of the midpoint rule; default ``T_1 / 2000`` with ``T_1`` the clamped first
        period, which puts the time-discretization error of a peak well below 1e-4.
    initial_slope : callable, optional
        ``s -> psi(s)``: initial slope angle (rad) of the beam in the hub frame against arc
        length ``s`` from the root (exact geometry; the root is clamped). Default straight.
        Initial deflection rates in the hub frame are zero.
    initial_theta, initial_theta_dot : float
        Initial hub angle and rate for a free or torque-driven hub (ignored with
        ``hub_motion``).
    method : str
        ``'midpoint'`` (fixed-step implicit midpoint rule, default) or a
        ``scipy.integrate.solve_ivp`` method such as ``'Radau'`` (adaptive, with the analytic
        Jacobian; much slower when the hub is light, because it resolves the stiff modes).

    Returns
    -------
    dict
        ``'t'``, ``'theta'``, ``'theta_dot'``, ``'tip_deflection'`` (tip lateral position in
        the hub frame, m, positive in the direction of positive rotation), ``'tip_foreshortening'``
        (``b + l - x_tip``, m), ``'energy'`` (kinetic plus bending, J), ``'angular_momentum'``
        (about O, kg m^2/s), ``'torque'`` (applied or needed hub torque, N m), ``'n_elements'``,
        ``'dt'``, ``'cpu_time'`` (s).
    """
    if torque is not None and hub_motion is not None:
        raise ValueError("give either torque or hub_motion, not both")
    chain = _Chain(system, n_elements)
    n = chain.n
    nq = n + 1
    rel0 = chain.link_angles(initial_slope) if initial_slope is not None else np.zeros(nq)
    omega1 = 1.8751041 ** 2 * np.sqrt(system.bending_stiffness
                                      / (system.linear_density * system.length ** 4))
    if dt is None:
        dt = 2.0 * np.pi / omega1 / 2000.0

    size = len(rel0) if hub_motion is None else len(rel0) - 1
    if hub_motion is None:
        drive = torque if torque is not None else (lambda t: 0.0)
        q0 = rel0 + initial_theta
        w0 = np.full(nq, float(initial_theta_dot))

        def balance(t, q, w, with_jac):
            cm, sm, f = chain.parts(q, w)
            f[0] += drive(t)
            if not with_jac:
                return cm, f
            g, gw = chain.jac_parts(cm, sm, w, np.linalg.solve(cm, f))
            return cm, f, g, gw

        def full_state(t, q, w):
            return q, w
    else:
        th0, thd0, _ = hub_motion(0.0)
        q0 = rel0[1:] + th0
        w0 = np.full(n, float(thd0))

        def full_state(t, q, w):
            th, thd, _ = hub_motion(t)
            return np.concatenate([[th], q]), np.concatenate([[thd], w])

        def balance(t, q, w, with_jac):
            th, thd, thdd = hub_motion(t)
            phi = np.concatenate([[th], q])
            om = np.concatenate([[thd], w])
            cm, sm, f = chain.parts(phi, om)
            mass, force = cm[1:, 1:], f[1:] - cm[1:, 0] * thdd
            if not with_jac:
                return mass, force
            g, gw = chain.jac_parts(cm, sm, om,
                                    np.concatenate([[thdd], np.linalg.solve(mass, force)]))
            return mass, force, g[1:, 1:], gw[1:, 1:]

    def dynamics(t, q, w, with_jac):
        """The accelerations, and with ``with_jac`` their derivatives ``(a, da/dq, da/dw)``."""
        if not with_jac:
            mass, force = balance(t, q, w, False)
            return np.linalg.solve(mass, force)
        mass, force, g, gw = balance(t, q, w, True)
        j = np.linalg.solve(mass, np.hstack([force[:, None], g, gw]))
        return j[:, 0], j[:, 1:size + 1], j[:, size + 1:]

    start = time.process_time()
    if method == "midpoint":
        t, qs, ws, _, _, _ = _midpoint(balance, q0, w0, t_final, dt,
                                       min(rtol, 1e-8) * 1e-2, omega1)
        q, w = qs.T, ws.T
    else:
        def rhs(t, y):
            return np.concatenate([y[size:], dynamics(t, y[:size], y[size:], False)])

        def jac(t, y):
            _, jq, jw = dynamics(t, y[:size], y[size:], True)
            return np.block([[np.zeros((size, size)), np.eye(size)], [jq, jw]])
        atol = np.concatenate([np.full(size, rtol * 1e-2),
                               np.full(size, rtol * 1e-2 * max(omega1, 1.0))])
        sol = solve_ivp(rhs, (0.0, t_final), np.concatenate([q0, w0]), method=method,
                        rtol=rtol, atol=atol,
                        jac=jac if method in ("Radau", "BDF", "LSODA") else None,
                        t_eval=np.linspace(0.0, t_final, 2001) if t_eval is None else t_eval)
        if not sol.success:
            raise RuntimeError(f"integration failed: {sol.message}")
        t, q, w = sol.t, sol.y[:size], sol.y[size:]
    cpu = time.process_time() - start

    phi = np.empty((nq, len(t)))
    om = np.empty((nq, len(t)))
    tq = np.empty(len(t))
    for j in range(len(t)):
        phi[:, j], om[:, j] = full_state(t[j], q[:, j], w[:, j])
        if hub_motion is None:
            tq[j] = drive(t[j])
        else:
            thdd = hub_motion(t[j])[2]
            cm, _, f = chain.parts(phi[:, j], om[:, j])
            acc = np.concatenate([[thdd], dynamics(t[j], q[:, j], w[:, j], False)])
            tq[j] = cm[0] @ acc - f[0]
    xt, yt = chain.tip(phi)
    energy, momentum = chain.energy(phi, om)
    out = {
        "t": t, "theta": phi[0], "theta_dot": om[0], "tip_deflection": yt,
        "tip_foreshortening": chain.b + chain.l - xt, "energy": energy,
        "angular_momentum": momentum, "torque": tq,
    }
    if t_eval is not None and method == "midpoint":
        t_eval = np.asarray(t_eval, dtype=float)
        out = {k: np.interp(t_eval, t, v) for k, v in out.items()}
    out.update(n_elements=n, dt=dt if method == "midpoint" else None, cpu_time=cpu)
    return out


def convergence_study(system: FESystem, t_final: float, elements=(16, 32, 64), **kwargs) -> dict:
    """Peak absolute tip deflection for several mesh sizes.

    Parameters
    ----------
    system : FESystem
    t_final : float
    elements : sequence of int
        Mesh sizes to run.
    **kwargs
        Passed to :func:`simulate_fe` (``torque``, ``hub_motion``, ``rtol`` ...).

    Returns
    -------
    dict
        ``'elements'``, ``'peaks'`` (m), ``'changes'`` (relative change of the peak from each
        mesh to the next), ``'cpu_times'`` (s).
    """
    peaks, cpu = [], []
    for ne in elements:
        r = simulate_fe(system, t_final, n_elements=ne, **kwargs)
        peaks.append(float(np.max(np.abs(r["tip_deflection"]))))
        cpu.append(r["cpu_time"])
    peaks = np.array(peaks)
    return {"elements": tuple(elements), "peaks": peaks,
            "changes": np.abs(np.diff(peaks)) / np.abs(peaks[1:]), "cpu_times": np.array(cpu)}
