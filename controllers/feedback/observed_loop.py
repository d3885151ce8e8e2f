"""The loop of an observed law as it flies: sampled, held, late, through its Kalman filter.

:func:`observed_loop` gives the discrete loop transfer function ``L(z)`` of an
:class:`~controllers.Observed` law on a plant, broken at the plant input: the plant under the
zero-order hold of the command, read by the sensors ``delay`` seconds late, the filter of the
law's own model (the nominal one it was built on, whatever the plant) in its steady state,
the estimate extrapolated over the delay, and the law's state gain.
:func:`~controllers.analysis.loops.loop_transfer` returns it for an ``Observed`` law,
:func:`~controllers.analysis.loops.loop_margins` reads it as it reads a continuous loop, and
:func:`~controllers.check_loop` judges an observed law by it
(:meth:`~controllers.feedback.observer.Observed.sampled_loop`).

Notes
-----
Sample interval ``T``, delay ``d`` in ``[0, T)``, plant ``x' = A x + B v`` (``v`` the held
input, the loop's input), hold ``Phi(h) = exp(A h)``, ``Gamma(h)``; the filter's model
``Phi_f``, ``Gamma_f``, ``C_f``, ``D_f`` and its steady-state gain ``K_f`` (the
covariance's recursion run to convergence from the session's start). The loop's state at
sample ``k``::

    w_k = [x_k, v_(k-1), u_(k-1), z_k]      (plant, held input, own last command, prediction)

    e_k   = Phi(d)^-1 (x_k - Gamma(d) v_(k-1))        the plant d seconds ago
    y_k   = C e_k + D v_(k-1)                        the readings
    z+_k  = z_k + K_f (y_k - C_f z_k - D_f u_(k-1))  the update at the epoch t_k - d
    x^_k  = Phi_f(d) z+_k + Gamma_f(d) u_(k-1)       extrapolated to t_k (plant block)
    u_k   = -K x^_k                                  the law
    z_(k+1) = Phi_f(T - d) (Phi_f(d) z+_k + Gamma_f(d) u_(k-1)) + Gamma_f(T - d) u_k
    x_(k+1) = Phi(T) x_k + Gamma(T) v_k

and the loop's output is ``-u_k`` (negative-feedback convention): ``feedback(L)`` is the
closed loop as it flies, less the saturation and the filter's start.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg

from flexctl.model.errors import InputTypeError, InputValueError

__all__ = ["observed_loop", "observed_loop_matrices", "LoopMatrices", "steady_kalman_gain"]

#: The gain has settled when a doubling of the samples changes it by less than this,
#: relatively.
GAIN_TOLERANCE = 1e-10
#: At most this many doublings (2^60 samples of the recursion).
MAX_DOUBLINGS = 60


def steady_kalman_gain(ad, c, q, r, p0) -> np.ndarray:
    """The gain ``K_f`` (n_f, m) a Kalman filter's update reaches: the recursion of its
    covariance (update, then predict over one sample) from ``p0``, run until the gain
    settles.

    A filter of a plant with modes it cannot see (a free hub's translation read by attitude
    sensors) has no stabilising Riccati solution; its gain on them settles at zero all the
    same, which the recursion finds.

    Parameters
    ----------
    ad : ndarray, shape (n_f, n_f)
        The filter state's transition over one sample.
    c : ndarray, shape (m, n_f)
        The readings per filter state.
    q : ndarray, shape (n_f, n_f)
        Process noise covariance over one sample.
    r : ndarray, shape (m, m)
        Reading noise covariance (positive definite).
    p0 : ndarray, shape (n_f, n_f)
        The covariance of the first prediction.

    Notes
    -----
    The recursion ``P+ = A_d P (I + G P)^-1 A_d^T + Q`` (``G = C^T R^-1 C``) is doubled
    (the structure-preserving doubling algorithm, Chu, Fan and Lin 2005):
    ``P_(2^k) = H_k + A_k^T P_0 (I + G_k P_0)^-1 A_k``, with ``A_0 = A_d^T``, ``G_0 = G``,
    ``H_0 = Q`` and ``W = I + G_k H_k``::

        A_(k+1) = A_k W^-1 A_k
        G_(k+1) = G_k + A_k W^-1 G_k A_k^T
        H_(k+1) = H_k + A_k^T H_k W^-1 A_k

    so ``2^k`` samples cost ``k`` steps, and the gain is taken at ``P_(2^k)`` once a doubling
    changes it by less than :data:`GAIN_TOLERANCE`. Unlike a Riccati solver it needs no
    stabilising solution, and it reaches the recursion's limit where that limit converges
    slowly (its error there was 1e-6 of the gain when the recursion was run sample by sample
    until one sample changed the gain by 1e-10).
    """
    p0 = np.array(p0, dtype=float)
    eye = np.eye(p0.shape[0])
    g = c.T @ np.linalg.solve(r, c)
    a, g, h = np.array(ad, dtype=float).T, 0.5 * (g + g.T), np.array(q, dtype=float)
    previous = _update_gain(p0, c, r)
    for _ in range(MAX_DOUBLINGS):
        p = h + a.T @ p0 @ np.linalg.solve(eye + g @ p0, a)
        gain = _update_gain(0.5 * (p + p.T), c, r)
        if np.max(np.abs(gain - previous)) <= GAIN_TOLERANCE * max(
                1.0, float(np.max(np.abs(gain)))):
            return gain
        previous = gain
        w = eye + g @ h
        w_a = np.linalg.solve(w, a)
        a, g, h = (a @ w_a, g + a @ np.linalg.solve(w, g) @ a.T, h + a.T @ h @ w_a)
        g, h = 0.5 * (g + g.T), 0.5 * (h + h.T)
    return previous


def _update_gain(p, c, r) -> np.ndarray:
    """The Kalman update's gain ``P C^T (C P C^T + R)^-1`` (n_f, m)."""
    return scipy.linalg.solve(c @ p @ c.T + r, c @ p, assume_a="pos").T


def _plant_gain(model, law, spin_rate, sensor):
    """A static law's own gain on the plant state (its ``plant_gain``), or None."""
    if sensor is not None or not callable(getattr(law, "plant_gain", None)):
        return None
    return law.plant_gain(model, spin_rate)


def _law_gain(model, observed, spin_rate, state_gain) -> np.ndarray:
    """The law's gain on the plant state, shape (1, n)."""
    law = observed.law
    if callable(getattr(law, "plant_gain", None)) and getattr(law, "reads_actuator", False):
        return np.asarray(law.plant_gain(model, spin_rate), dtype=float).reshape(1, -1)
    gain = (state_gain or _plant_gain)(model, law, spin_rate, None)
    if gain is None:
        raise InputTypeError("loop_transfer.controller: the law inside Observed must be one "
                             "with a state gain (PD, LQR, ScheduledLQR, TrajectoryTracker, "
                             f"LaggedLQR or a gain array); got {type(law).__name__}")
    return np.asarray(gain, dtype=float).reshape(1, -1)


def observed_loop(model, observed, spin_rate: float = 0.0, *, state_gain=None):
    """The discrete loop ``L(z)`` of an observed law on ``model`` (module Notes).

    Parameters
    ----------
    model : flexctl.Model
        The plant flown (with its actuator when the law commands one), linearised about
        ``spin_rate``; the filter keeps its own model when the law was built with one.
    observed : Observed
        The law on the Kalman filter of the sensors' readings.
    spin_rate : float, optional
        Steady hub rate of the plant's linearisation, rad/s. Default 0.
    state_gain : callable, optional
        ``state_gain(model, law, spin_rate, sensor)``: the gain (1, n) of a static law on the
        plant state, or None (:func:`controllers.analysis.loops.loop_transfer` gives its
        own). Default: the law's ``plant_gain(model, spin_rate)``.

    Returns
    -------
    control.StateSpace
        Discrete (``dt`` the sample time), SISO: input ``torque`` (the held command, in the
        plant input's unit), output ``return_torque``.

    Raises
    ------
    InputValueError
        If the sensors' delay is not shorter than the sample time.
    InputTypeError
        If the law has no gain on the plant state (an NMPC, a motor's voltage).
    """
    import control

    loop = observed_loop_matrices(model, observed, spin_rate, state_gain=state_gain)
    return control.ss(loop.a, loop.b, loop.c, np.zeros((1, 1)), dt=loop.sample_time,
                      states=list(loop.state_names), inputs=["torque"],
                      outputs=["return_torque"], name="observed_loop")


class LoopMatrices(NamedTuple):
    """The discrete loop of :func:`observed_loop` as arrays (``D`` is zero).

    Attributes
    ----------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n, 1)
    c : ndarray, shape (1, n)
    sample_time : float
        s.
    state_names : tuple of str
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    sample_time: float
    state_names: tuple


def observed_loop_matrices(model, observed, spin_rate: float = 0.0, *,
                           state_gain=None) -> LoopMatrices:
    """:func:`observed_loop`'s ``L(z)`` as arrays, without python-control (whose import
    takes longer than the loop's construction): what a stability check needs.

    Parameters
    ----------
    model : flexctl.Model
        The plant flown, linearised about ``spin_rate``.
    observed : Observed
        The law on the Kalman filter of the sensors' readings.
    spin_rate : float, optional
        Steady hub rate of the plant's linearisation, rad/s. Default 0.
    state_gain : callable, optional
        As for :func:`observed_loop`.

    Raises
    ------
    InputValueError
        If the sensors' delay is not shorter than the sample time.
    InputTypeError
        If the law has no gain on the plant state.
    """
    period, delay = observed.sample_time, observed.sensors.delay
    if delay >= period:
        raise InputValueError(f"loop_transfer: the observed loop is built for sensors.delay "
                              f"shorter than the sample time {period:g} s; got {delay:g} s")
    n = model.layout.n_states
    session = observed.start(model, np.zeros(n))
    mats = session.matrices
    gain = _law_gain(model, observed, spin_rate, state_gain)
    a, b = (np.asarray(v, dtype=float) for v in model.linear_matrices(spin_rate))
    c_y, d_y = (np.asarray(v, dtype=float) for v in measurement(model, observed))
    phi_t, gam_t = _hold(a, b, period)
    phi_d, gam_d = _hold(a, b, delay)
    back = np.linalg.inv(phi_d)
    f_d, g_d, q_d = session.hold(delay)
    f_r, g_r, q_r = session.hold(period - delay)
    ad_f = f_r @ f_d
    q_f = f_r @ q_d @ f_r.T + q_r
    kf = steady_kalman_gain(ad_f, mats.C, q_f, mats.R, session.covariance)
    n_f = mats.C.shape[1]
    # blocks of w = [x, v_prev, u_prev, z]
    ix, iv, iu, iz = slice(0, n), n, n + 1, slice(n + 2, n + 2 + n_f)
    size = n + 2 + n_f
    # y = Y w, the innovation = y - C_f z - D_f u_prev
    y_of = np.zeros((c_y.shape[0], size))
    y_of[:, ix] = c_y @ back
    y_of[:, iv] = -(c_y @ back @ gam_d)[:, 0] + d_y[:, 0]
    innovation = y_of.copy()
    innovation[:, iz] -= mats.C
    innovation[:, iu] -= mats.D[:, 0]
    z_plus = kf @ innovation
    z_plus[:, iz] += np.eye(n_f)
    x_hat = f_d[:n, :] @ z_plus
    x_hat[:, iu] += g_d[:n, 0]
    u_of = -gain @ x_hat                                   # (1, size)
    z_next = f_r @ (f_d @ z_plus)
    z_next[:, iu] += (f_r @ g_d)[:, 0]
    z_next += g_r @ u_of
    a_loop = np.zeros((size, size))
    b_loop = np.zeros((size, 1))
    a_loop[ix, ix] = phi_t
    b_loop[ix, 0] = gam_t[:, 0]
    b_loop[iv, 0] = 1.0
    a_loop[iu, :] = u_of[0]
    a_loop[iz, :] = z_next
    names = (*model.state_names, "held_input", "last_command",
             *(f"filter_{k}" for k in range(n_f)))
    return LoopMatrices(a_loop, b_loop, -u_of, float(period), names)


def measurement(model, observed) -> tuple:
    """``(C, D)`` of the sensors' readings on the plant flown (not the filter's model).

    Parameters
    ----------
    model : flexctl.Model
        The plant flown.
    observed : Observed
        Its sensors are read.
    """
    from flexctl.sim.sensors import measurement_matrix

    return measurement_matrix(model, observed.sensors)


def _hold(a, b, h) -> tuple:
    """``(Phi(h), Gamma(h))`` of ``x' = A x + B u`` under a command held over ``h`` s."""
    n = a.shape[0]
    block = np.zeros((n + b.shape[1], n + b.shape[1]))
    block[:n, :n], block[:n, n:] = a, b
    hold = scipy.linalg.expm(block * h)
    return hold[:n, :n], hold[:n, n:]
