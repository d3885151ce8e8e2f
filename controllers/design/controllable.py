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

import math
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from flexctl.model.errors import InputError, InputValueError

__all__ = ["ControllablePart", "controllable_part", "input_part", "lqr_on_part", "lqe_on_part",
           "dlqr_on_part", "design_failure", "INPUT_TOLERANCE"]

#: Packages whose ``ValueError`` or ``ArithmeticError`` is a numerical failure of a design (a
#: Riccati equation without a stabilising solution, a singular matrix), not a bug of ours.
SOLVER_PACKAGES = ("control", "slycot", "scipy", "numpy")
#: A direction of the state that the inputs cannot move (a left eigenvector ``w`` of ``A``
#: with ``|w^H B| <= INPUT_TOLERANCE |B|``, ``|w| = 1``): :func:`input_part`.
INPUT_TOLERANCE = 1e-8


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
        """``(P A T, P B)``.

        Parameters
        ----------
        a : array_like, shape (n, n)
            State matrix ``A`` of the linearised model.
        b : array_like, shape (n, 1)
            Input matrix ``B`` (the hub torque).
        """
        return self.projector @ a @ self.basis, self.projector @ b


def controllable_part(model, spin_rate: float = 0.0) -> ControllablePart:
    """The :class:`ControllablePart` of ``model`` linearised at ``spin_rate``.

    Parameters
    ----------
    model : flexctl.Model
        The model to linearise (one beam or a structure, free or pinned hub).
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.
    """
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


def input_part(a, b, *, max_frequency: float = math.inf,
               tolerance: float = INPUT_TOLERANCE) -> ControllablePart:
    """The :class:`ControllablePart` of any linear plant ``x' = A x + B u``, from its matrices,
    without the poles faster than ``max_frequency``.

    - **Fast poles.** An ordered real Schur form of ``A^T`` gives orthonormal rows ``P_1``
      that span the left-invariant subspace of the poles with ``|lambda| <= max_frequency``
      (``P_1 A = A_1 P_1``): ``z_1 = P_1 x`` obeys ``z_1' = A_1 z_1 + P_1 B u`` whatever the
      fast poles do, so a gain on ``z_1`` leaves them at their open-loop values. One of
      ``A`` gives the right-invariant subspace ``V_1`` of the same poles, and ``T_1 = V_1
      (P_1 V_1)^-1``: a state of the slow poles is ``x = T_1 z_1`` (an estimator's model of
      the readings, ``y = C T_1 z_1``, misses only the fast poles' part).
    - **Directions the inputs cannot move.** In that part, a left eigenvector ``w`` of ``A_1``
      with ``w^H P_1 B = 0`` (the Popov-Belevitch-Hautus test) evolves on its own; for an
      eigenvalue of several left eigenvectors (identical appendages) the combinations of them
      that the inputs miss are taken. At zero, where a rigid body's double integrator makes
      the matrix defective, its left null space is used instead (a free hub's linear
      momentum: ``p A = 0``, ``p B = 0``). With ``R`` an orthonormal real basis of those
      directions and ``S`` one of its complement, ``z = S^T z_1`` obeys ``z' = S^T A_1 S z +
      S^T P_1 B u + S^T A_1 R (R^T z_1)`` while ``R^T z_1`` moves on its own.

    A design on ``(P A T, P B)`` with ``P = S^T P_1`` and ``T = T_1 S`` (``P T = I``)
    closes the loop on every pole but those left out, which keep their open-loop values.

    Parameters
    ----------
    a : array_like, shape (n, n)
        State matrix ``A``.
    b : array_like, shape (n, m)
        Input matrix ``B``.
    max_frequency : float, optional
        Poles faster than this (``|lambda|``, rad/s) are left out. Default: none.
    tolerance : float, optional
        ``|w^H B| / |B|`` (``|w| = 1``) below which a direction counts as out of the inputs'
        reach. Default :data:`INPUT_TOLERANCE`.

    Returns
    -------
    ControllablePart
        ``basis`` ``T`` (n, r), ``projector`` ``P`` (r, n), the left-out poles' frequencies
        (``|lambda|``, rad/s; 0 for a conserved quantity), and a note saying which.

    Examples
    --------
    >>> a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    >>> part = input_part(a, np.array([[0.0], [1.0], [0.0]]))
    >>> part.basis.shape, part.dropped
    ((3, 2), (1.0,))
    """
    import scipy.linalg

    from flexctl.model.checks import check_array, check_real

    a = np.asarray(check_array("input_part", "a", a), dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or not a.size:
        raise InputValueError(f"input_part.a must be a square matrix; got shape {a.shape}")
    b = np.asarray(check_array("input_part", "b", b), dtype=float)
    if b.ndim != 2 or b.shape[0] != a.shape[0]:
        raise InputValueError(f"input_part.b must have {a.shape[0]} rows (A's); got shape "
                              f"{b.shape}")
    max_frequency = check_real("input_part", "max_frequency", max_frequency, minimum=0.0,
                               strict=True, infinite=True)
    if not float(np.linalg.norm(b)) > 0:
        raise InputValueError("input_part: the input matrix B is zero: nothing can be moved")
    fast = []
    slow, back = np.eye(a.shape[0]), np.eye(a.shape[0])
    if np.isfinite(max_frequency):
        # a rigid body's poles sit at zero up to rounding: always kept
        floor = max(max_frequency, _rigid(a))

        def kept(re, im):
            return math.hypot(re, im) <= floor

        form, vectors, count = scipy.linalg.schur(a.T, output="real", sort=kept)
        slow = vectors[:, :count].T
        right = scipy.linalg.schur(a, output="real", sort=kept)[1][:, :count]
        back = right @ np.linalg.inv(slow @ right)
        fast = sorted(float(w) for w in np.abs(np.linalg.eigvals(form[count:, count:])))
        fast = fast[::2] if all(w > 0 for w in fast) else fast
    a_1, b_1 = slow @ a @ back, slow @ b
    missed, dropped = _missed(a_1, b_1, tolerance)
    if missed is None:
        complement = np.eye(a_1.shape[0])
    else:
        u_r, s_r, _ = np.linalg.svd(np.hstack([missed.real, missed.imag]))
        complement = u_r[:, int(np.sum(s_r > 1e-8 * s_r[0])):]
    projector, basis = complement.T @ slow, back @ complement
    if not projector.shape[0]:
        raise InputValueError(f"input_part: no pole at or below max_frequency "
                              f"{max_frequency:g} rad/s can be moved by the inputs")
    notes = []
    if dropped:
        notes.append(f"{len(dropped)} pole{'s' if len(dropped) > 1 else ''} (at "
                     f"{', '.join(f'{w:.4g}' for w in dropped)} rad/s) cannot be moved by the "
                     "inputs (appendages bending against each other, or a free hub's "
                     "conserved momentum)")
    if fast:
        notes.append(f"{len(fast)} mode{'s' if len(fast) > 1 else ''} faster than "
                     f"{max_frequency:.4g} rad/s (up to {fast[-1]:.4g} rad/s) are out of the "
                     "design")
    note = ("; ".join(notes) + ": the design acts on the others and leaves these at their "
            "open-loop poles") if notes else ""
    return ControllablePart(basis=basis, projector=projector,
                            dropped=tuple(sorted(dropped + fast)), note=note)


def _missed(a, b, tolerance: float) -> tuple:
    """``(directions, frequencies)``: the left eigen-directions (n, d) of ``A`` that ``B``
    misses (None when none) and their poles' ``|lambda|`` (:func:`input_part`)."""
    import scipy.linalg

    size_a, size_b = max(float(np.linalg.norm(a, 2)), 1e-300), float(np.linalg.norm(b, 2))
    directions, dropped = [], []
    u_a, s_a, _ = np.linalg.svd(a)                 # zero: the left null space of A
    null = u_a[:, s_a <= 1e-10 * size_a]
    free = _left_null(null.T @ b, tolerance * size_b)
    if free.shape[1]:
        directions.append(null @ free)
        dropped += [0.0] * free.shape[1]
    lam, left = scipy.linalg.eig(a, left=True, right=False)
    rigid = _rigid(a)
    seen = np.zeros(lam.size, dtype=bool)
    for k in np.argsort(-lam.imag):       # each cluster of (nearly) equal poles together
        if seen[k] or abs(lam[k]) <= rigid or lam[k].imag < 0:
            continue
        cluster = np.abs(lam - lam[k]) <= 1e-7 * abs(lam[k])
        seen |= cluster | (np.abs(lam - lam[k].conjugate()) <= 1e-7 * abs(lam[k]))
        basis = np.linalg.qr(left[:, cluster])[0]
        free = _left_null(basis.conj().T @ b, tolerance * size_b)
        if free.shape[1]:
            directions.append(basis @ free)
            dropped += [float(abs(lam[k]))] * free.shape[1]
    return (np.hstack(directions) if directions else None), dropped


def _rigid(a) -> float:
    """``|lambda|`` below which a pole of ``A`` is a rigid body's zero up to rounding: a
    double integrator's pair spreads by ``sqrt(eps |A|)``, with a margin of 100."""
    return 100.0 * math.sqrt(np.finfo(float).eps * max(float(np.linalg.norm(a, 2)), 1e-300))


def _left_null(m, tolerance: float) -> np.ndarray:
    """Orthonormal ``c`` (k, d) with ``|c^H M| <= tolerance``: the combinations of the rows
    of ``M`` (k, m) that vanish."""
    u, s, _ = np.linalg.svd(m)
    rank = int(np.sum(s > tolerance))
    return u[:, rank:]


def lqr_on_part(model, spin_rate, q_mat, r_mat, sample_time=None):
    """LQR gain (1, n) and closed-loop poles (n,) designed on the controllable part; with a
    ``sample_time``, the discrete LQR of the plant held over it (weights ``Q T``,
    ``R T``: the continuous cost's rectangle rule), for a law run with a zero-order hold.

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    spin_rate : float
        Steady hub rate of the linearisation, rad/s.
    q_mat : array_like, shape (n, n)
        State weight ``Q`` on the model's state (e.g. of
        :func:`~controllers.feedback.lqr.lqr_weight_matrices`).
    r_mat : array_like, shape (1, 1)
        Torque weight ``R``, 1/(N m)^2.
    sample_time : float, optional
        Hold of the sampled law, s. Default: the continuous LQR.

    Returns
    -------
    gain : ndarray, shape (1, n)
        ``K`` on the whole state, ``u = -K x`` (zero on the modes left out).
    poles : ndarray, shape (n,)
        ``eig(A - B K)`` of the continuous linearisation, 1/s.
    part : ControllablePart
        The part designed on (:func:`controllable_part`).
    """
    a, b = model.linear_matrices(spin_rate)
    part = controllable_part(model, spin_rate)
    if not part.dropped:
        gain = state_gain(a, b, q_mat, r_mat, sample_time)
        return gain, np.linalg.eigvals(a - b @ gain), part
    a_r, b_r = part.reduce(a, b)
    q_r = part.basis.T @ q_mat @ part.basis
    gain = state_gain(a_r, b_r, 0.5 * (q_r + q_r.T), r_mat, sample_time) @ part.projector
    return gain, np.linalg.eigvals(a - b @ gain), part


def held(a, b, sample_time: float) -> tuple:
    """``(A_d, B_d)``: ``x' = A x + B u`` with ``u`` held over ``sample_time``.

    The exponential of the block matrix ``[[A, B], [0, 0]] T`` (python-control's ``c2d`` with
    ``"zoh"`` computes the same, through ``scipy.signal``, whose import alone takes longer
    than a design).

    Parameters
    ----------
    a : array_like, shape (n, n)
        Continuous state matrix ``A``.
    b : array_like, shape (n, m)
        Continuous input matrix ``B``.
    sample_time : float
        Length of the zero-order hold, s (> 0).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n, m = a.shape[0], b.shape[1]
    block = np.zeros((n + m, n + m))
    block[:n, :n], block[:n, n:] = a, b
    exp = scipy.linalg.expm(block * float(sample_time))
    return exp[:n, :n], exp[:n, n:]


#: The closed loop of :func:`state_gain` is stable when its poles' real parts (continuous)
#: or moduli minus one (sampled) are below minus this, relative to the largest pole.
STABILITY_MARGIN = 1e-12


def state_gain(a, b, q_mat, r_mat, sample_time=None) -> np.ndarray:
    """The LQR gain of ``(A, B)``, shape (1, n): continuous, or discrete for the plant held
    over ``sample_time`` with the weights ``Q T`` and ``R T``.

    Parameters
    ----------
    a : array_like, shape (n, n)
        State matrix ``A``.
    b : array_like, shape (n, 1)
        Input matrix ``B`` (the hub torque, or an actuator's command).
    q_mat : array_like, shape (n, n)
        State weight ``Q``.
    r_mat : float or array_like, shape (1, 1)
        Input weight ``R``.
    sample_time : float, optional
        Hold of the sampled law, s. Default: the continuous LQR.

    Raises
    ------
    numpy.linalg.LinAlgError
        If the solver returns a gain that is not finite, or the Riccati equation has no
        stabilising solution (the solver fails, or the closed loop of its gain is not
        stable: :data:`STABILITY_MARGIN`).

    Notes
    -----
    The Riccati equations are solved by SciPy (``solve_continuous_are``,
    ``solve_discrete_are``), the gains are ``R^-1 B^T X`` and ``(B^T X B + R)^-1 B^T X A``:
    what ``control.lqr`` and ``control.dlqr`` return, without importing python-control.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    q_mat = np.asarray(q_mat, dtype=float)
    r_mat = np.atleast_2d(np.asarray(r_mat, dtype=float))
    try:
        if sample_time is None:
            x = scipy.linalg.solve_continuous_are(a, b, q_mat, r_mat)
            gain = np.linalg.solve(r_mat, b.T @ x)
        else:
            a_d, b_d = held(a, b, sample_time)
            q_d, r_d = q_mat * sample_time, r_mat * sample_time
            x = scipy.linalg.solve_discrete_are(a_d, b_d, q_d, r_d)
            gain = np.linalg.solve(b_d.T @ x @ b_d + r_d, b_d.T @ x @ a_d)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise np.linalg.LinAlgError(f"the Riccati equation has no stabilising solution "
                                    f"({exc})") from None
    if not np.all(np.isfinite(gain)):
        raise np.linalg.LinAlgError("the solver returned a gain that is not finite")
    # a solver may return a solution that is not the stabilising one (SciPy 1.17 returns
    # X = 0 for Q = 0, where a rigid mode the cost does not see has none): the closed loop
    # must be stable, with a margin of rounding
    closed = a - b @ gain if sample_time is None else a_d - b_d @ gain
    poles = np.linalg.eigvals(closed)
    margin = STABILITY_MARGIN * max(1.0, float(np.max(np.abs(poles))))
    worst = (float(np.max(poles.real)) if sample_time is None
             else float(np.max(np.abs(poles))) - 1.0)
    if not worst < -margin:
        kind = "real part" if sample_time is None else "modulus minus 1"
        raise np.linalg.LinAlgError(f"the Riccati equation has no stabilising solution (the "
                                    f"solver's gain leaves a closed-loop pole with {kind} "
                                    f"{worst:.3g})")
    return gain


def lqe_on_part(model, spin_rate, c_meas, process, measurement):
    """Kalman gain (n, m) and estimator poles (n,) on the controllable part (the modes the
    torque cannot move are not excited by its noise either: the estimate leaves them at 0).

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    spin_rate : float
        Steady hub rate of the linearisation, rad/s.
    c_meas : array_like, shape (m, n)
        Rows of the output matrix that are measured (``y_meas = C_meas x``).
    process : array_like, shape (1, 1)
        ``QN``: covariance of the disturbance torque entering like the command, (N m)^2.
    measurement : array_like, shape (m, m)
        ``RN``: covariance of the measurement noise, in the squared units of the outputs.
    """
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
    controllable part, as a quadratic form on the whole state (zero on the modes left out).

    Parameters
    ----------
    model : flexctl.Model
        The design model, linearised at rest.
    sample_time : float
        Length of the zero-order hold, s (> 0).
    q_mat : array_like, shape (n, n)
        State weight ``Q`` of each sample.
    r_mat : array_like, shape (1, 1)
        Torque weight ``R`` of each sample, 1/(N m)^2.
    """
    import control

    a, b = model.linear_matrices(0.0)
    part = controllable_part(model, 0.0)
    if part.dropped:
        a, b = part.reduce(a, b)
        q_mat = part.basis.T @ q_mat @ part.basis
    a_d, b_d = held(a, b, sample_time)
    _, p_mat, _ = control.dlqr(a_d, b_d, 0.5 * (q_mat + q_mat.T), r_mat)
    p_mat = np.asarray(p_mat)
    if part.dropped:
        p_mat = part.projector.T @ p_mat @ part.projector
    return 0.5 * (p_mat + p_mat.T)


# ---------------------------------------------------------------------------- failures
def _solver_failures() -> tuple:
    """The exception types of a failed solve: numpy's and slycot's arithmetic errors and
    python-control's own argument and dimension errors (a weight made asymmetric by
    rounding)."""
    import control.exception

    kinds = [np.linalg.LinAlgError, control.exception.ControlArgument,
             control.exception.ControlDimension]
    try:
        from slycot.exceptions import SlycotArithmeticError
    except ImportError:            # python-control falls back on SciPy without slycot
        pass
    else:
        kinds.append(SlycotArithmeticError)
    return tuple(kinds)


def _raised_in_solver(exc: BaseException) -> bool:
    """True when ``exc`` was raised inside one of :data:`SOLVER_PACKAGES`."""
    tb = exc.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    package = str(tb.tb_frame.f_globals.get("__name__", "")).partition(".")[0]
    return package in SOLVER_PACKAGES


def _model_facts(model, spin_rate: float) -> str:
    """What of the design model decides whether a Riccati equation is solvable: its mode
    count, its clamped frequencies (first and fastest, rad/s) and ``J0`` (kg m^2)."""
    n_modes = getattr(model, "n_modes", None)
    facts = [f"{n_modes} mode{'' if n_modes == 1 else 's'}"] if n_modes is not None else []
    try:
        w = np.asarray(model.natural_frequencies(spin_rate, hub="clamped"), dtype=float)
    except (ValueError, ArithmeticError, TypeError, AttributeError):
        w = np.zeros(0)        # the facts describe a failure: give what can be had
    if w.size:
        facts.append(f"first clamped frequency {w[0]:.4g} rad/s, fastest mode {w[-1]:.4g} rad/s")
    inertia = getattr(model, "rigid_inertia", None)
    if isinstance(inertia, (int, float)):
        facts.append(f"J0 {inertia:.4g} kg m^2")
    return ", ".join(facts)


def _input_text(name: str, value) -> str:
    if isinstance(value, np.ndarray):
        value = np.array2string(value, precision=3, threshold=8, max_line_width=10_000)
    elif isinstance(value, float):
        value = f"{value:.4g}"
    return f"{name}={value}"


@contextmanager
def design_failure(law: str, function: str, model, spin_rate: float = 0.0, *,
                   solving: str = "the LQR Riccati equation", **inputs):
    """Report a numerical failure of a controller design as an
    :class:`~flexctl.model.errors.InputValueError` that names the design, its inputs and the
    solver's reason, in one line.

    Caught: ``numpy.linalg.LinAlgError``, slycot's ``SlycotArithmeticError``,
    python-control's ``ControlArgument`` / ``ControlDimension``, and a ``ValueError`` or
    ``ArithmeticError`` raised inside :data:`SOLVER_PACKAGES`. Everything else, the
    project's own input errors first, passes through unchanged.

    Parameters
    ----------
    law : str
        The control law, e.g. ``"lqr"``.
    function : str
        The design function, e.g. ``"design_lqr"``.
    model : flexctl.Model
        The design model (its modes, clamped frequencies and ``J0`` go into the message).
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.
    solving : str, optional
        What was being solved, e.g. ``"the Kalman filter Riccati equation"``.
    **inputs
        The design's inputs that matter (weights, sample time, ...), named in the message.

    Examples
    --------
    >>> import flexctl
    >>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=1)
    >>> with design_failure("lqr", "design_lqr", model, torque_weight=1.0):
    ...     raise np.linalg.LinAlgError("Failed to find a finite solution.")
    Traceback (most recent call last):
    ...
    flexctl.model.errors.InputValueError: lqr design (design_lqr) failed on a model with 1 \
mode, first clamped frequency 3.566 rad/s, fastest mode 3.566 rad/s, J0 2.883 kg m^2 (spin \
rate 0 rad/s, torque_weight=1): the LQR Riccati equation has no stabilising solution \
(Failed to find a finite solution)
    """
    try:
        yield
    except InputError:
        raise
    except Exception as exc:
        arithmetic = isinstance(exc, _solver_failures())
        if not arithmetic and not (isinstance(exc, (ValueError, ArithmeticError))
                                   and _raised_in_solver(exc)):
            raise
        detail = " ".join(str(exc).split()).rstrip(".;") or type(exc).__name__
        reason = (f"{solving} has no stabilising solution ({detail})" if arithmetic
                  else f"solving {solving} failed ({type(exc).__name__}: {detail})")
        given = ", ".join([f"spin rate {spin_rate:g} rad/s"]
                          + [_input_text(k, v) for k, v in inputs.items() if v is not None])
        facts = _model_facts(model, spin_rate)
        on = f"a model with {facts}" if facts else f"its {type(model).__name__}"
        raise InputValueError(f"{law} design ({function}) failed on {on} ({given}): "
                              f"{reason}") from exc
