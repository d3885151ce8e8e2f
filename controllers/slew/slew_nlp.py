"""The discretisation and NLP of a slew for CasADi Opti (see :mod:`controllers.slew.trajopt`).

:func:`discretisation` chooses how each torque hold is integrated (RK4 substeps, CVODES, or
collocation elements) from the design model's fastest mode; :func:`transcribe` builds the
problem that :func:`controllers.solve_slew` hands to IPOPT, in the variable and constraint
order of the :mod:`controllers.slew.trajopt` Notes, from a
:class:`~controllers.slew.trajopt.SlewProblem`, a :class:`Discretisation` and a guess. The
dynamics enter as CasADi ``Function`` objects mapped over the holds or collocation points.
"""

from __future__ import annotations

import functools
import math
import weakref
from dataclasses import dataclass

import numpy as np

from flexctl.model import DCMotor, ReactionWheel
from flexctl.model.discrete import rk4_function
from flexctl.model.errors import InputValueError

from ..design.actuator_limits import hold_voltages, speed_bound, wheel_speed_function
from ..design.hold_grid import LARGEST_STEP, MAX_SUBSTEPS, mode_tolerances, steps_per_hold
from ..design.native_dynamics import (MAX_HOLD_LIBRARY, MAX_INSTRUCTIONS, design_dynamics,
                                      with_compiled_derivatives)

__all__ = ["MAX_INTERVALS", "MAX_ELEMENTS", "MAX_MODE_PHASE", "Discretisation", "discretisation",
           "transcription_for", "rk4_substeps", "refuse_fast_modes", "resolution_reason",
           "Transcribed", "transcribe", "terminal_constraints", "set_initial", "state_scale",
           "torque_scale"]

#: Most torque holds: the NLP grows with them (IPOPT's work about linearly, the refusal checks
#: too), and 400 already converge the slew-90 cost (``benchmarks/bench_trajopt.py --grid``).
MAX_INTERVALS = 5000
#: Most collocation elements over a slew (``m K``): each adds ``n (d + 1)`` variables, and
#: building and solving grows faster than linearly with them (3 IPOPT iterations of slew-90 on
#: 3 first_order modes: 1.1 s for 640 elements, 4 s for 1440, over two minutes for 4720).
MAX_ELEMENTS = 2000
#: Most radians a design mode may turn over a slew: what MAX_INTERVALS holds of MAX_SUBSTEPS
#: RK4 steps of the largest stable step integrate. Beyond it no discretisation within the
#: limits follows the mode, and the hold analysis loses its accuracy in floating point.
MAX_MODE_PHASE = MAX_INTERVALS * MAX_SUBSTEPS * LARGEST_STEP["rk4"]

#: The RK4 hold of each design model, by substeps (built and compiled once per model).
_HOLD_STEPS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()

#: Lower bound on the free final time, as a fraction of the rigid-body minimum time (kept
#: below 1 so that the physical bound is found by the optimiser, not imposed on it).
MIN_TIME_FLOOR = 0.5


#: A free duration is discretised for this many rigid-body minimum times first (minimum-time
#: slews of flexible bodies end a little above 1); a longer optimum is solved again with the
#: steps of its own duration.
TIME_SIZING = 1.5


def transcription_for(problem, model) -> str:
    """The problem's transcription, or the design model's default when it names none.

    Parameters
    ----------
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    model : flexctl.Model
        The design model: collocation for the exact variant, multiple shooting otherwise.
    """
    if problem.transcription is not None:
        return problem.transcription
    return "collocation" if model.variant.exact else "multiple_shooting"


def rk4_substeps(model, hold: float, duration: float | None = None) -> int:
    """RK4 substeps per hold of ``hold`` seconds for the design modes of ``model``.

    As many as integrate each mode over ``duration`` within its tolerance
    (:func:`controllers.design.hold_grid.mode_tolerances`,
    :func:`controllers.design.hold_grid.steps_per_hold`).

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    hold : float
        Hold length ``h``, s (> 0).
    duration : float, optional
        Time over which the errors add up (the slew), s. Default one hold.

    Raises
    ------
    ValueError
        If more than :data:`MAX_SUBSTEPS` would be needed, naming the settings that pass.
    """
    omega, tolerance = mode_tolerances(model)
    duration = duration or hold
    substeps = steps_per_hold("rk4", omega, hold, duration, tolerance=tolerance)
    if substeps > MAX_SUBSTEPS:
        n_intervals = round(duration / hold)
        raise InputValueError(
            f"the fastest of the {model.n_modes} design modes ({float(omega[-1]):.4g} rad/s) "
            f"needs {substeps} RK4 substeps per {hold:.4g} s hold (more than {MAX_SUBSTEPS}): "
            f"use {_resolution_remedies(model, omega, tolerance, hold, duration, n_intervals)}")
    return substeps


def _resolution_remedies(model, omega, tolerance, hold, duration, n_intervals) -> str:
    """Settings that integrate the design modes within the step limits, as a phrase."""
    remedies = []
    more = math.ceil(n_intervals * steps_per_hold("rk4", omega, hold, duration,
                                                  tolerance=tolerance) / MAX_SUBSTEPS)
    if more <= MAX_INTERVALS:
        remedies.append(f"at least n_intervals = {more}")
    fits = [j for j in range(1, omega.size) if steps_per_hold(
        "rk4", omega[:j], hold, duration, tolerance=tolerance[:j]) <= MAX_SUBSTEPS]
    if fits:
        remedies.append("fewer design modes (model.design_modes)")
    if n_intervals * steps_per_hold("radau", omega, hold, duration, 3, tolerance) \
            <= MAX_ELEMENTS:
        remedies.append("transcription 'collocation'")
    if not remedies:
        return ("a design model whose modes are slower against the slew (its fastest mode "
                f"turns {float(omega[-1]) * duration:.3g} rad; see beam and hub parameters)")
    return " or ".join(remedies)


def refuse_fast_modes(model, sized: float, t_rigid: float) -> None:
    """Raise if the fastest design mode turns more than :data:`MAX_MODE_PHASE` over ``sized``
    seconds: no grid of holds within the limits integrates it.

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    sized : float
        Duration the discretisation is sized for, s.
    t_rigid : float
        Rigid-body minimum time of the slew, s (named in the remedies).

    Raises
    ------
    InputValueError
        If the fastest design mode turns too far, naming the settings that pass.
    """
    omega, _ = mode_tolerances(model)
    phase = float(omega[-1]) * sized
    if phase <= MAX_MODE_PHASE:
        return
    remedies = []
    slow = int(np.count_nonzero(omega * sized <= MAX_MODE_PHASE))
    if slow:
        remedies.append(f"at most {slow} design mode{'s' if slow > 1 else ''} "
                        "(model.design_modes)")
    shorter = MAX_MODE_PHASE / float(omega[-1])
    if shorter >= t_rigid:
        remedies.append(f"a duration of at most {shorter:.3g} s (the rigid-body minimum "
                        f"time is {t_rigid:.3g} s)")
    remedy = " or ".join(remedies) or (
        f"a higher torque_bound (no duration above the rigid-body minimum time {t_rigid:.3g} s "
        "keeps even design mode 1 within reach), or check the beam and hub parameters")
    raise InputValueError(
        f"design mode {model.n_modes} ({float(omega[-1]):.4g} rad/s) turns {phase:.3g} rad over "
        f"the {sized:.4g} s slew, more than the {MAX_MODE_PHASE:.3g} rad that {MAX_INTERVALS} "
        f"holds of {MAX_SUBSTEPS} RK4 substeps can integrate (MAX_MODE_PHASE): use {remedy}")


@dataclass(frozen=True)
class Discretisation:
    """How each hold of a slew is integrated (see :func:`slew_discretisation`).

    Attributes
    ----------
    transcription : {"multiple_shooting", "collocation"}
    method : {"rk4", "cvodes", "radau", "legendre"}
        Integrator (multiple shooting) or collocation points.
    steps_per_hold : int
        RK4 substeps or collocation elements per hold (1 for CVODES, which chooses its own).
    sized_for : float
        Duration, s, the steps were chosen for: the fixed duration, or for a free one the
        longest it may take (RK4, which must stay stable) or the expected one (collocation).
    """

    transcription: str
    method: str
    steps_per_hold: int
    sized_for: float


def discretisation(problem, model, t_rigid: float, longest: float,
                   duration: float | None = None, check: bool = True) -> Discretisation:
    """:func:`controllers.slew.trajopt.slew_discretisation`, given the rigid-body minimum time and
    the longest free duration.

    Parameters
    ----------
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    model : flexctl.Model
        The design model, whose fastest mode sets the steps.
    t_rigid : float
        Rigid-body minimum time of the slew, s.
    longest : float
        Longest free duration, s.
    duration : float, optional
        Duration a free-time collocation is sized for, s. Default ``TIME_SIZING`` rigid-body
        minimum times (at most ``longest``).
    check : bool, optional
        Refuse steps beyond the limits (``InputValueError``). False returns them
        (:func:`resolution_reason` says why they are refused). Default True.
    """
    transcription = transcription_for(problem, model)
    if transcription == "collocation":
        sized = problem.duration or duration or min(TIME_SIZING * t_rigid, longest)
        method = problem.collocation_scheme
    else:
        sized = problem.duration or longest
        method = problem.integrator
    if check:
        refuse_fast_modes(model, sized, t_rigid)
    if method == "cvodes":
        return Discretisation(transcription, "cvodes", 1, sized)
    if method == "rk4" and problem.substeps is not None:
        return Discretisation(transcription, "rk4", problem.substeps, sized)
    if method == "rk4" and check:
        steps = rk4_substeps(model, sized / problem.n_intervals, sized)
    else:
        omega, tolerance = mode_tolerances(model)
        steps = steps_per_hold(method, omega, sized / problem.n_intervals, sized,
                               problem.degree if method != "rk4" else 3, tolerance)
    disc = Discretisation(transcription, method, steps, sized)
    if check and resolution_reason(problem, model, disc):
        raise InputValueError(f"{resolution_reason(problem, model, disc)}: use fewer design modes "
                         "(model.design_modes) or transcription 'multiple_shooting'")
    return disc


def resolution_reason(problem, model, disc: Discretisation) -> str | None:
    """Why ``disc`` takes more steps than the limits allow, or None.

    Parameters
    ----------
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    model : flexctl.Model
        The design model (its fastest mode is named).
    disc : Discretisation
        The discretisation to judge.
    """
    K, omega_max = problem.n_intervals, float(mode_tolerances(model)[0][-1])
    hold = disc.sized_for / K
    if disc.method == "rk4" and problem.substeps is None and disc.steps_per_hold > MAX_SUBSTEPS:
        return (f"the fastest of the {model.n_modes} design modes ({omega_max:.4g} rad/s) "
                f"needs {disc.steps_per_hold} RK4 substeps per {hold:.4g} s hold (more than "
                f"{MAX_SUBSTEPS})")
    if disc.transcription == "collocation" and disc.steps_per_hold * K > MAX_ELEMENTS:
        return (f"the fastest of the {model.n_modes} design modes ({omega_max:.4g} rad/s) "
                f"needs {disc.steps_per_hold} {disc.method} collocation elements per "
                f"{hold:.4g} s hold, {disc.steps_per_hold * K} over the slew (more than "
                f"MAX_ELEMENTS = {MAX_ELEMENTS})")
    return None


def _hold_step(model, disc: Discretisation):
    """``(x, u, h) -> x(h)`` of one hold of the design model: CVODES, or RK4 substeps written
    out and compiled with their derivatives (:func:`with_compiled_derivatives`); where those
    would be long (the exact model, many substeps), substeps that call the compiled dynamics,
    so that CasADi differentiates the dynamics once rather than once per substep."""
    import casadi as ca

    plain, n = model.casadi(), model.n_states
    if disc.method != "rk4":
        return _cvodes_step(plain, n)
    steps = _HOLD_STEPS.setdefault(model, {})
    if disc.steps_per_hold not in steps:
        step = None
        if 4 * disc.steps_per_hold * plain.n_instructions() <= MAX_INSTRUCTIONS:
            written = rk4_function(plain, n, disc.steps_per_hold, ca.SX)
            step = with_compiled_derivatives(written, MAX_HOLD_LIBRARY)
            if step is written and design_dynamics(model) is not plain:
                step = None             # too long a library: call the compiled dynamics
        if step is None:
            step = rk4_function(design_dynamics(model), n, disc.steps_per_hold, ca.MX)
        steps[disc.steps_per_hold] = step
    return steps[disc.steps_per_hold]


def _cvodes_step(f, n: int):
    import casadi as ca

    x, p = ca.SX.sym("x", n), ca.SX.sym("p", 2)          # p = [u, h]; time scaled to [0, 1]
    dae = {"x": x, "p": p, "ode": p[1] * f(x, p[0])}
    F = ca.integrator("cvodes_hold", "cvodes", dae, 0.0, 1.0,
                      {"abstol": 1e-10, "reltol": 1e-10})
    xs, us, hs = ca.MX.sym("x", n), ca.MX.sym("u"), ca.MX.sym("h")
    xf = F(x0=xs, p=ca.vertcat(us, hs))["xf"]
    return ca.Function("cvodes_hold", [xs, us, hs], [xf], ["x", "u", "h"], ["xf"])


def _collocation_constraints(f, grid, Xc, held, h_element, scheme: str, degree: int):
    """Defects ``(n, d M)`` and element end states ``(n, M)`` of ``M`` collocation elements.

    ``Z_j C - h f(Xc_j)`` and ``Z_j D`` for every element at once: the linear parts as sparse
    matrix products, the dynamics as one map over the ``d M`` points, so that CasADi
    differentiates ``f`` point by point (``n + 1`` inputs) rather than whole elements.
    """
    import casadi as ca

    elements = held.shape[1]
    start_c, points_c, start_d, points_d = _collocation_blocks(scheme, degree, elements)
    left = grid[:, :-1]
    points = ca.repmat(held, degree, 1)     # (d, M): each element's torque at its d points
    dynamics = f.map(degree * elements)(Xc, ca.reshape(points, 1, degree * elements))
    defect = ca.mtimes(left, start_c) + ca.mtimes(Xc, points_c) - h_element * dynamics
    end = ca.mtimes(left, start_d) + ca.mtimes(Xc, points_d)
    return defect, end


@functools.lru_cache(maxsize=32)
def _collocation_blocks(scheme: str, degree: int, elements: int) -> tuple:
    """The collocation matrices of ``elements`` elements as sparse block-diagonal DMs (the
    same block for every element): ``C``'s row of the element's start and its rows of the
    points, then ``D``'s (``casadi.collocation_coeff``). Built once per grid: a solve of a
    40-hold slew spent 3 ms on them."""
    import casadi as ca
    import scipy.sparse

    C, D, _ = (np.asarray(ca.DM(c)) for c in ca.collocation_coeff(
        ca.collocation_points(degree, scheme)))

    def blocks(matrix):
        return ca.DM(scipy.sparse.kron(scipy.sparse.eye(elements), matrix, format="csc"))

    return blocks(C[:1, :]), blocks(C[1:, :]), blocks(D[:1, :]), blocks(D[1:, :])


def torque_scale(model, problem, duration: float) -> float:
    """Size of the torque, N m: the bound (:attr:`SlewProblem.hub_torque_bound`), unless it
    is over 1000 times the rigid bang-bang torque ``4 J0 |angle| / T^2`` of the slew (a bound
    of 1e300 N m would scale the torque and the modal deflections far out of IPOPT's reach).

    Parameters
    ----------
    model : flexctl.Model
        The design model (its :attr:`~flexctl.Model.rigid_inertia` ``J0``, kg m^2).
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    duration : float
        Slew duration ``T`` (fixed, or the guess of a free one), s.
    """
    bound = problem.hub_torque_bound
    needed = 4.0 * model.rigid_inertia * abs(problem.angle) / duration ** 2
    return min(bound, 1e3 * needed) if needed > 0.0 else bound


def state_scale(model, problem, duration: float) -> np.ndarray:
    """Physical size of each state: angle, mean rate, quasi-static modal deflections.

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    duration : float
        Slew duration ``T`` (fixed, or the guess of a free one), s.

    Returns
    -------
    ndarray, shape (n,)
        In the order of ``model.layout``, in the states' units (rad, m, rad/s, m/s).
    """
    mat = model.matrices
    w = np.sqrt(np.diag(mat.K_ff) / np.diag(mat.M_ff))
    q = (np.abs(model.quasi_static_gain()) * torque_scale(model, problem, duration)
         / model.rigid_inertia)
    # a mode too slow to follow the hub lags it by no more than the slew angle: without this
    # cap a very soft beam's scale (1e15 for E = 1e-6) let IPOPT accept broken dynamics
    q = np.minimum(q, np.abs(mat.m_tf) / np.diag(mat.M_ff) * abs(problem.angle))
    q = np.maximum(q, 1e-6 * model.mode_lengths)
    hub = {}
    if model.layout.hub_position is not None:
        # a free hub's centre moves about as far as the centre of mass sits from it
        reach = max(float(np.min(model.lengths)) * 1e-3,
                    float(np.linalg.norm(mat.first)) / mat.mass * abs(problem.angle))
        hub = dict(hub_position=np.full(2, reach), hub_velocity=np.full(2, reach / duration))
    return model.layout.join(theta=abs(problem.angle), q=q,
                             theta_dot=abs(problem.angle) / duration,
                             q_dot=q * np.maximum(w, 1.0 / duration), **hub)


@dataclass(frozen=True)
class Transcribed:
    """The Opti problem of a slew and the expressions of its results.

    Attributes
    ----------
    opti : casadi.Opti
        The problem: its variables, constraints, objective and solver.
    X : casadi.MX, shape (n, K+1)
        The states at the hold boundaries.
    U : casadi.MX, shape (1, K)
        The held torques, N m.
    T : casadi.MX or float
        The duration, s: a variable (free time) or the fixed number.
    """

    opti: object
    X: object             # states at the hold boundaries (n, K+1)
    U: object             # holds (1, K)
    T: object             # duration: a variable (free time) or the fixed number


def terminal_constraints(model, target) -> np.ndarray:
    """The rows ``R`` of a slew's terminal condition ``R (x_K - target) = 0``: one position
    and one rate row per controllable mode of the design model at rest at the target, shape
    (r, n).

    The hub torque moves only what it can reach. A free hub's centre stays where momentum
    conservation puts it (the torque exerts no net force), and the modes of a symmetric
    structure that bend its arrays alike stay at rest; the dynamics hold them at the target
    already, and constraining them as well repeats constraints, a rank-deficient Jacobian on
    which IPOPT crawls (150 iterations against 30 on ``two-array-slew``). At rest the
    linearisation is ``c'' = -S c + beta u`` in the configuration ``c`` (half the states);
    each group of equal eigenvalues of ``S`` (the rigid rotation, each frequency squared)
    whose modal input ``V^-1 beta`` is not zero gives one row in the configuration and one
    in the rates (``beta``: the input's column and an actuator's states' columns). On a
    pinned single beam every mode is controllable and ``R`` is square. Other states (an
    actuator's) keep a row each.

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    target : array_like, shape (n,)
        The rest state at the slew's end, in the order of ``model.layout``.
    """
    from flexctl.model.checks import check_array
    from flexctl.model.exports import dynamics_jacobians

    n, layout = model.n_states, model.layout
    target = check_array("terminal_constraints", "target", target, shape=(n,))
    _, a, b = dynamics_jacobians(model, target)
    coords, rates = np.arange(n)[layout.coordinates], np.arange(n)[layout.velocities]
    others = np.setdiff1d(np.arange(n), np.r_[coords, rates])
    values, vectors = np.linalg.eig(-a[np.ix_(rates, coords)])
    values, left = values.real, np.linalg.inv(vectors)
    # what drives the rates: the input, and an actuator's states (a wheel's torque)
    modal = left @ np.column_stack([b[rates, 0], a[np.ix_(rates, others)]])
    strongest = float(np.max(np.abs(modal)))
    rows = []
    for g in _equal_groups(values):
        directions, strengths, _ = np.linalg.svd(modal[g, :])
        for k in np.flatnonzero(strengths > 1e-8 * strongest):
            row = np.real(directions[:, k].conj() @ left[g, :])
            rows.append(row / np.linalg.norm(row))
    ends = np.zeros((2 * len(rows), n))
    if rows:
        ends[:len(rows), coords] = rows
        ends[len(rows):, rates] = rows
    return np.vstack([ends, np.eye(n)[others]])


def _equal_groups(values) -> list:
    """Indices of ``values`` grouped where they are equal to rounding (sorted ascending)."""
    order = np.argsort(values)
    top = max(float(np.max(np.abs(values))), 1e-300)
    groups, current = [], [order[0]]
    for i, j in zip(order[:-1], order[1:]):
        if values[j] - values[i] <= 1e-9 * max(abs(values[i]), abs(values[j])) + 1e-12 * top:
            current.append(j)
        else:
            groups.append(current)
            current = [j]
    return groups + [current]


def transcribe(model, problem, disc, guess: tuple, t_rigid: float, t_max: float) -> Transcribed:
    """Variables, constraints and objective in the order of the module Notes.

    Parameters
    ----------
    model : flexctl.Model
        The design model.
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    disc : Discretisation
        How each hold is integrated (:func:`discretisation`).
    guess : tuple
        ``(duration, states, torque)`` to start from: s, shape (n, K+1) at the hold
        boundaries, and shape (K,) N m.
    t_rigid : float
        Rigid-body minimum time, s: the free duration's lower bound is
        ``MIN_TIME_FLOOR`` times it.
    t_max : float
        Upper bound on the free duration, s.
    """
    import casadi as ca

    (t_guess, x_guess, u_guess) = guess
    n, K, layout = model.n_states, problem.n_intervals, model.layout
    umax, target = problem.hub_torque_bound, problem.target_state(model)
    free_time = problem.objective == "time"
    scale = ca.DM(state_scale(model, problem, problem.duration or t_guess))
    collocation = disc.transcription == "collocation"
    m, d = (disc.steps_per_hold, problem.degree) if collocation else (1, 0)
    f = design_dynamics(model) if collocation else None

    opti = ca.Opti()
    grid = opti.variable(n, m * K + 1)                 # X, or the element boundaries
    Xc = opti.variable(n, d * m * K) if collocation else None
    U = opti.variable(1, K)
    T = opti.variable() if free_time else problem.duration
    X = grid[:, ::m] if m > 1 else grid
    h = T / K
    opti.set_linear_scale(grid, ca.repmat(scale, 1, m * K + 1))
    u_scale = torque_scale(model, problem, problem.duration or t_guess)
    opti.set_linear_scale(U, u_scale)

    opti.subject_to(grid[:, 0] == 0, scale)
    if not collocation:
        step = _hold_step(model, disc)
        opti.subject_to(X[:, 1:] == step.map(K)(X[:, :-1], U, h), ca.repmat(scale, 1, K))
    else:
        opti.set_linear_scale(Xc, ca.repmat(scale, 1, d * m * K))
        held = ca.reshape(ca.repmat(U, m, 1), 1, m * K)     # each hold on its m elements
        defect, x_end = _collocation_constraints(f, grid, Xc, held, h / m,
                                                 problem.collocation_scheme, d)
        opti.subject_to(defect == 0, ca.repmat(scale, 1, d * m * K))
        opti.subject_to(grid[:, 1:] == x_end, ca.repmat(scale, 1, m * K))
    ends = terminal_constraints(model, target)
    opti.subject_to(ca.mtimes(ca.DM(ends), X[:, K] - target) == 0,
                    ca.DM(np.abs(ends) @ np.asarray(scale).ravel()))
    opti.subject_to(opti.bounded(-umax, U, umax))
    if problem.torque_rate_bound is not None:
        jumps = ca.diff(ca.horzcat(0, U, 0), 1, 1)
        lim = problem.torque_rate_bound * h
        opti.subject_to(opti.bounded(-lim, jumps, lim), u_scale)
    if problem.tip_bound is not None:
        tip, ymax = ca.DM(model.tip_matrix), problem.tip_bound
        opti.subject_to(opti.bounded(-ymax, ca.mtimes(tip, grid[layout.q, 1:m * K]), ymax),
                        ymax)
        if collocation:
            opti.subject_to(opti.bounded(-ymax, ca.mtimes(tip, Xc[layout.q, :]), ymax), ymax)
    _actuator_constraints(opti, model, problem.actuator, grid, Xc, ca.repmat(U, m, 1))
    if free_time:
        opti.subject_to(opti.bounded(MIN_TIME_FLOOR * t_rigid, T, t_max))
        opti.set_initial(T, min(max(t_guess, MIN_TIME_FLOOR * t_rigid), t_max))
        opti.minimize(T)
    else:
        # U / u_scale first: its square overflows for a torque bound above 1e154 N m
        opti.minimize(h * ca.sumsqr(U / u_scale) / problem.duration)

    set_initial(opti, grid, Xc, problem, m, x_guess)
    opti.set_initial(U, u_guess.reshape(1, K))
    return Transcribed(opti, X, U, T)


def _actuator_constraints(opti, model, actuator, grid, Xc, held) -> None:
    """The wheel speed at the element boundaries after the start (and the collocation
    points), or the motor voltage at both ends of every element, within the actuator's limit
    (:mod:`controllers.design.actuator_limits`); ``held`` (m, K) is each element's torque."""
    import casadi as ca

    if isinstance(actuator, ReactionWheel):
        speed, bound = wheel_speed_function(model, actuator), speed_bound(actuator)
        for states in (grid[:, 1:], Xc):
            if states is not None:
                omega = speed.map(states.size2())(states)
                opti.subject_to(opti.bounded(-bound, omega, bound), bound)
    elif isinstance(actuator, DCMotor):
        rates, limit = grid[model.layout.theta_dot, :], actuator.voltage_limit
        torque = ca.reshape(held, 1, held.numel())           # element by element
        volts = ca.horzcat(*hold_voltages(actuator, torque, rates[:-1], rates[1:]))
        opti.subject_to(opti.bounded(-limit, volts, limit), limit)


def set_initial(opti, grid, Xc, problem, m: int, x_guess: np.ndarray):
    """The guess, given at the hold boundaries, interpolated to the elements and points.

    Parameters
    ----------
    opti : casadi.Opti
        The problem whose initial values are set.
    grid : casadi.MX
        Its states at the element boundaries, shape (n, m K + 1).
    Xc : casadi.MX or None
        Its states at the collocation points, shape (n, d m K); None for multiple shooting.
    problem : SlewProblem
        The slew (:class:`~controllers.slew.trajopt.SlewProblem`).
    m : int
        Collocation elements per hold (1 for multiple shooting).
    x_guess : ndarray, shape (n, K+1)
        Guessed states at the hold boundaries.
    """
    import casadi as ca

    K = problem.n_intervals
    s_guess = np.linspace(0.0, 1.0, K + 1)
    s_grid = np.linspace(0.0, 1.0, m * K + 1)
    opti.set_initial(grid, np.vstack([np.interp(s_grid, s_guess, row) for row in x_guess]))
    if Xc is not None:
        tau = np.asarray(ca.collocation_points(problem.degree, problem.collocation_scheme))
        sc = ((np.arange(m * K)[:, None] + tau[None, :]) / (m * K)).ravel()
        opti.set_initial(Xc, np.vstack([np.interp(sc, s_guess, row) for row in x_guess]))
