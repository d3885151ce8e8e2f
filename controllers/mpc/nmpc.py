"""Nonlinear model predictive control of a slew, by real-time iteration or to convergence.

At every sample ``t_k = k T`` the controller solves, on a design model with few modes (any
variant, the geometrically exact one included)::

    min   sum_{j<N} |x_j - r_j|_Q^2 + R (u_j - v_j)^2  +  |x_N - r_N|_P^2
    s.t.  x_0 = x(t_k),  x_{j+1} = F(x_j, u_j)             (RK4 over the hold, multiple shooting)
          |u_j| <= u_max,  |u_j - u_{j-1}| <= T du_max,  |tip(x_j)| <= d_max
          |Omega(x_j)| <= w_max  (j >= 1)                  (actuator: a reaction wheel)
          |V(u_j, rate_j)| <= V_max, |V(u_j, rate_j+1)| <= V_max    (actuator: a DC motor)
          [x_N = r_N]                                        (terminal = "rest")

with ``r_j, v_j`` the reference (a :class:`~controllers.slew.trajopt.SlewSolution` or a rest
target), ``P`` the discrete LQR Riccati solution of the design model at rest (terminal
cost), and applies ``u_0`` until the next sample (a :class:`flexctl.sim.digital.SampledController`).
With an ``actuator`` the hub torque stays within what it can give
(:mod:`controllers.design.actuator_limits`): ``u_max`` is also a reaction wheel's torque limit,
``Omega(x)`` the wheel's speed relative to the hub for zero total momentum, ``w_max`` its speed
limit less :data:`~controllers.design.actuator_limits.SPEED_MARGIN`; ``V(u, rate)`` the voltage a DC
motor needs for the hub torque ``u`` at the hub rate. The output is still the hub torque.

Two solution modes:

- ``"rti"`` (real-time iteration, Diehl et al.): one Gauss-Newton SQP step per sample. The
  constraint Jacobian and residuals come from one compiled CasADi function, the Hessian is the
  constant Gauss-Newton ``blockdiag(Q, R, ..., P)``, and one structured QP is solved by a QP
  solver shipped with CasADi (``qrqp`` by default; ``osqp``, ``qpoases``, ``hpipm`` are
  accepted where ``casadi.has_conic`` says they are there). The previous solution, shifted by
  one sample, is the linearisation point (warm start).
- ``"converged"``: IPOPT on the same NLP to tolerance from the same warm start, for reference.

RK4 substeps per hold are chosen so that ``omega_max h <= OMEGA_H`` for the design model's
fastest mode, inside RK4's stability interval.

Examples
--------
>>> import numpy as np, flexctl
>>> from controllers.mpc.nmpc import NMPC
>>> model = flexctl.build_model(flexctl.load_scene("slew-90").system, n_modes=2,
...                             variant="first_order")
>>> mpc = NMPC(model=model, target=np.pi / 2, torque_limit=6.0, sample_time=0.05, horizon=20)
>>> result = flexctl.simulate(model, 6.0, controller=mpc)
>>> result.status, bool(abs(result.theta[-1] - np.pi / 2) < 0.05)
('ok', True)
>>> result.controller_report["failed_steps"]
0
"""

from __future__ import annotations

import contextlib
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from flexctl.model import DCMotor, Model, ReactionWheel
from flexctl.model.checks import check_array, check_real
from flexctl.model.discrete import rk4_function
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.digital import check_sample_time
from flexctl.sim.fixed_step import jit_compiled

from ..design.actuator_limits import (check_design_model, horizon_constraints, horizon_rows,
                                      hub_torque_bound, linearised_horizon_constraints)
from ..feedback.lqg import NoiseLevels, measurement_rows
from ..design.plant_state import design_rows
from ..spec import MODES, QP_SOLVERS, TERMINALS
from ..slew.trajopt import SlewSolution

__all__ = ["NMPC", "NMPCSession", "OMEGA_H", "QP_SOLVERS"]

#: Largest ``omega_max h`` of the RK4 substeps in the prediction model (RK4 is stable up to
#: ``2 sqrt 2``; 1 keeps the fastest design mode's phase error per hold small).
OMEGA_H = 1.0
#: Most RK4 substeps per hold.
MAX_SUBSTEPS = 50
#: The condensing is compiled to machine code from this horizon on. On slew-90's exact 2-mode
#: design model (0.02 s samples) compiling it took a step's median from 0.42 to 0.34 ms at a
#: horizon of 5, 0.60 to 0.46 ms at 10 and 1.00 to 0.80 ms at 20, for about half a second of
#: gcc once (the library is kept in the persistent cache).
JIT_CONDENSE_FROM = 1
#: Built problems kept for controllers of the same structure (model, horizon, weights...).
PROBLEM_CACHE_SIZE = 16
_PROBLEMS: OrderedDict = OrderedDict()


def _positive(name, value, optional=False):
    return check_real("nmpc", name, value, minimum=0.0, strict=True, optional=optional)


def hold_function(model: Model, sample_time: float, substeps: int):
    """CasADi ``F(x, u)``: the state after one hold of torque ``u`` (N m) over ``sample_time``,
    by ``substeps`` RK4 steps of the model's dynamics.

    Parameters
    ----------
    model : Model
        The design model, whose state ``x`` (shape (n,)) ``F`` takes and returns.
    sample_time : float
        Length of the hold ``T``, s.
    substeps : int
        RK4 steps per hold (>= 1).
    """
    import casadi as ca

    # one beam's exact model has a vectorized form: the same function, a few thousand times
    # fewer operations written out, so the hold compiles in about a second
    vectorized = model.vectorized_rhs()
    if vectorized is not None:
        sym, f = ca.MX, vectorized
    else:
        sym, f = ca.SX, model.casadi()
    step = rk4_function(f, model.n_states, substeps, sym)     # (x, u, h) -> x(h)
    x, u = sym.sym("x", model.n_states), sym.sym("u")
    return ca.Function("nmpc_hold", [x, u], [step(x, u, sample_time)])


#: Default weights (Bryson's rule): largest hub angle error as a fraction of the slew angle,
#: and largest tip deflection as a fraction of the beam length. Tighter than the tracker's LQR
#: (5 % and 3 %): measured on slew-90 (exact plant, 6 modes; exact 2-mode design), 1.6 % and
#: 0.3 % keep the nominal residual vibration of trajopt+lqr (0.14 mm) and halve it when the
#: design model's stiffness and point mass are 20 % off (29 mm against 53 mm); 0.1 % at the
#: tip lowers that to 12 mm but leaves the hub 2 degrees short at 6 s.
ANGLE_FRACTION = 0.05 / np.sqrt(10.0)
TIP_FRACTION = 0.003


def conic_solver(name: str, solver: str, h_sparsity, a_sparsity, options: dict | None = None):
    """A quiet CasADi QP solver that reports failure in its stats rather than raising.

    Parameters
    ----------
    name : str
        Name of the CasADi function.
    solver : str
        CasADi conic plugin, e.g. ``"qrqp"``, ``"osqp"`` or ``"qpoases"`` (``QP_SOLVERS``).
    h_sparsity : casadi.Sparsity
        Sparsity of the QP's Hessian, shape (N, N) for ``N`` torque steps.
    a_sparsity : casadi.Sparsity
        Sparsity of its constraint matrix, shape (rows, N).
    options : dict, optional
        Options of the plugin added to these (a C export's tolerances, e.g.
        ``{"constr_viol_tol": 1e-5}``). Default none.
    """
    import casadi as ca

    opts = {"error_on_fail": False}
    if solver == "qrqp":
        opts.update(print_iter=False, print_header=False, print_info=False)
    elif solver == "osqp":
        opts.update(osqp={"verbose": False, "polish": False, "eps_abs": 1e-7, "eps_rel": 1e-7,
                          "max_iter": 4000})
    elif solver == "qpoases":
        opts.update(printLevel="none", sparse=False)
    opts.update(options or {})
    if solver != "qpoases":
        return ca.conic(name, solver, {"h": h_sparsity, "a": a_sparsity}, opts)
    with _quiet_stdout():           # qpOASES prints its banner when it is made
        return ca.conic(name, solver, {"h": h_sparsity, "a": a_sparsity}, opts)


@contextlib.contextmanager
def _quiet_stdout():
    """The process's standard output (file descriptor 1) sent to the null device, and Python's
    ``sys.stdout`` to a discarded buffer: CasADi writes its plugins' messages through
    ``sys.stdout``, which is not descriptor 1 under Jupyter or pytest."""
    import io
    import os
    import sys

    with contextlib.redirect_stdout(io.StringIO()):
        try:
            sys.__stdout__.flush()
            saved = os.dup(1)
        except (OSError, ValueError, AttributeError):   # no descriptor 1: nothing more to quiet
            yield
            return
        try:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 1)
                yield
        finally:
            os.dup2(saved, 1)
            os.close(saved)


def _default_weights(model: Model, angle: float, torque_limit: float):
    """Bryson's rule: :data:`ANGLE_FRACTION` of the angle (at least 1 mrad),
    :data:`TIP_FRACTION` of the beam length at the tip, rates from the flexible frequencies,
    the torque limit."""
    mat = model.matrices
    w = np.sqrt(np.diag(mat.K_ff) / np.diag(mat.M_ff))
    theta = max(ANGLE_FRACTION * abs(angle), 1e-3)
    q = TIP_FRACTION * model.mode_lengths / np.maximum(np.abs(model.mode_tips), 1e-12)
    # a free hub's position is not regulated (weight 0)
    hub = ({} if model.layout.hub_position is None
           else dict(hub_position=np.full(2, np.inf), hub_velocity=np.full(2, np.inf)))
    allowed = model.layout.join(theta=theta, q=q, theta_dot=theta * w[0], q_dot=q * w, **hub)
    return 1.0 / allowed ** 2, 1.0 / torque_limit ** 2


def state_slice(n: int, j: int) -> slice:
    """``x_j`` in a vector of stages ``[x_0, u_0, x_1, u_1, ..., x_N]`` (``n`` states each):
    the decision variables, and the references ``[r_0, v_0, ..., r_N]``.

    Parameters
    ----------
    n : int
        States per stage.
    j : int
        Stage, ``0 .. N``.
    """
    return slice(j * (n + 1), j * (n + 1) + n)


def input_index(n: int, j: int) -> int:
    """``u_j`` in a vector of stages (see :func:`state_slice`).

    Parameters
    ----------
    n : int
        States per stage.
    j : int
        Stage, ``0 .. N - 1``.
    """
    return j * (n + 1) + n


def _parameters(par, n: int) -> tuple:
    """The measured state, the previous torque and the references of the NMPC's parameter
    vector ``[x_meas (n), u_prev, r_0, v_0, ..., r_N]``."""
    import casadi as ca

    x_meas, u_prev, refs = ca.vertsplit(par, (0, n, n + 1, par.numel()))
    return x_meas, u_prev, refs


def _stages(v, n: int, big_n: int) -> tuple:
    """The ``N + 1`` states and ``N`` torques of a vector of stages (:func:`state_slice`)."""
    return ([v[state_slice(n, j)] for j in range(big_n + 1)],
            [v[input_index(n, j)] for j in range(big_n)])


#: Columns of ``G_j`` one call of the condensing's product ``A_j G_j`` takes
#: (``_kernels``; the last block of a stage padded with zeros).
PRODUCT_COLUMNS = 4


def _kernels(a_sparsity, n: int, q) -> dict:
    """The products the condensing makes at every stage, as scalar (SX) functions that are
    called rather than written out at each call (``never_inline``): one piece of C each, so
    that the condensing's C stays short, while each is the product's own operations (the
    structural zeros of ``A_j``, of ``a_sparsity``, left out).

    ``product(A_j, M) -> A_j M`` of :data:`PRODUCT_COLUMNS` columns; ``ahead(W, A_j) ->
    Q + A_j' W A_j``, of a symmetric ``W`` (its lower triangle computed, the upper mirrored).
    """
    import casadi as ca

    a, block = ca.SX.sym("a", a_sparsity), ca.SX.sym("m", n, PRODUCT_COLUMNS)
    weight = ca.SX.sym("w", n, n)
    pulled = ca.mtimes(weight, a)
    rows = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            rows[i][j] = rows[j][i] = ca.dot(a[:, i], pulled[:, j]) + float(q[i, j])
    options = {"never_inline": True}
    return {"product": ca.Function("nmpc_a_times", [a, block], [ca.mtimes(a, block)],
                                   options),
            "ahead": ca.Function("nmpc_cost_to_go", [weight, a],
                                 [ca.vertcat(*[ca.horzcat(*row) for row in rows])], options)}


def _times_blocks(product, a, moved):
    """``A moved`` by calls of ``product`` on blocks of :data:`PRODUCT_COLUMNS` columns."""
    import casadi as ca

    n, width = moved.size1(), moved.size2()
    parts = []
    for start in range(0, width, PRODUCT_COLUMNS):
        part = moved[:, start:min(start + PRODUCT_COLUMNS, width)]
        if part.size2() < PRODUCT_COLUMNS:
            part = ca.horzcat(part, ca.MX.zeros(n, PRODUCT_COLUMNS - part.size2()))
        parts.append(product(a, part))
    return ca.horzcat(*parts)[:, :width]


def _state_steps(f, a_all, b_all, xs, x_meas, kernels) -> tuple:
    """``e_j, G_j`` (``j = 0..N``) of the state steps ``dx_j = e_j + G_j du`` about the guess
    ``xs``, from every stage's ``F`` (``f``, shape (n, N)) and ``A, B`` (``a_all``, (n, n N),
    and ``b_all``, (n, N): ``NMPC._condensed``), with the stages' ``A_j`` and ``B_j``; the
    products ``A_j G_j`` by ``kernels["product"]`` (:func:`_kernels`)."""
    import casadi as ca

    n, big_n = xs[0].numel(), f.size2()
    e = [x_meas - xs[0]]
    # G_j moves with the first j torque steps only: its other columns are structural zeros,
    # which the products below (and their C) skip
    g_mats, moved = [ca.MX(n, big_n)], None
    a_list = [a_all[:, j * n:(j + 1) * n] for j in range(big_n)]
    b_list = [b_all[:, j] for j in range(big_n)]
    for j in range(big_n):
        e.append(ca.mtimes(a_list[j], e[j]) + f[:, j] - xs[j + 1])
        moved = b_list[j] if moved is None else ca.horzcat(
            _times_blocks(kernels["product"], a_list[j], moved), b_list[j])
        g_mats.append(moved if j == big_n - 1 else ca.horzcat(moved, ca.MX(n, big_n - j - 1)))
    return e, g_mats, a_list, b_list


def _condensed_cost(pieces: dict, g_mats, stages: tuple, base, us, rv, kernels) -> tuple:
    """Hessian ``H`` and gradient ``g`` of the Gauss-Newton cost in the torque steps, from
    ``G_j``, the stages' ``(A_j, B_j)`` and the residuals ``x_j + e_j - r_j`` (``base``) at
    ``du = 0``, by the backward recursion of the cost-to-go (``O(N^2 n)`` rather than
    ``O(N^3 n)``): ``W_N = P``, ``W_j = Q + A_j' W_{j+1} A_j``; ``v_N = P b_N``, ``v_j = Q b_j +
    A_j' v_{j+1}``; then ``H_kk = B_k' W_{k+1} B_k + r``, ``H_ik = (W_{i+1} B_i)' G_{i+1}[:, k]``
    (``i > k``) and ``g_k = B_k' v_{k+1} + r (u_k - r_k)``; ``W_j`` by ``kernels["ahead"]``
    (:func:`_kernels`)."""
    import casadi as ca

    a_list, b_list = stages
    big_n = us.numel()
    q, p_mat, r = ca.diag(ca.DM(pieces["q"])), ca.DM(pieces["p"]), float(pieces["r"])
    weight, value = p_mat, ca.mtimes(p_mat, base[big_n])
    rows, gradient = [None] * big_n, [None] * big_n
    for k in range(big_n - 1, -1, -1):
        pulled = ca.mtimes(weight, b_list[k])                  # W_{k+1} B_k
        gradient[k] = ca.mtimes(b_list[k].T, value)
        diagonal = ca.mtimes(b_list[k].T, pulled) + r
        below = ca.mtimes(pulled.T, g_mats[k + 1][:, :k]) if k else None
        rows[k] = diagonal if below is None else ca.horzcat(below, diagonal)
        if k:
            weight = kernels["ahead"](weight, a_list[k])
            value = ca.mtimes(q, base[k]) + ca.mtimes(a_list[k].T, value)
    lower = ca.vertcat(*[ca.horzcat(row, ca.MX(1, big_n - k - 1)) if k < big_n - 1 else row
                         for k, row in enumerate(rows)])
    # exactly symmetric: each entry below the diagonal is also the one above it
    hessian = lower + ca.tril(lower, False).T
    return hessian, ca.vertcat(*gradient) + r * (us - rv)


def _expansion(w, n: int, big_n: int, g_sparsity):
    """``expand(w, e, G, du) -> w + dw``: the step ``x_j + e_j + G_j du`` and
    ``u_j + du_j``, in the order of ``w``; ``G`` (the ``G_j`` stacked) has ``g_sparsity``
    (``G_j``'s columns past ``j`` are zero), and the function is in scalars (SX), each
    product of a zero left out."""
    import casadi as ca

    du = ca.MX.sym("du", big_n)
    e_in = ca.MX.sym("e", (big_n + 1) * n)
    g_in = ca.MX.sym("G", g_sparsity)
    dx = e_in + ca.mtimes(g_in, du)
    parts = []
    for j in range(big_n):
        parts += [dx[j * n:(j + 1) * n], du[j]]
    parts.append(dx[big_n * n:])
    return ca.Function("nmpc_expand", [w, e_in, g_in, du], [w + ca.vertcat(*parts)]).expand()


@dataclass(frozen=True, kw_only=True, eq=False)
class NMPC:
    """Nonlinear MPC of a slew (a :class:`flexctl.sim.digital.SampledController`).

    Parameters
    ----------
    model : Model
        Design model (few modes; any variant). The plant may have more modes: the design
        states are its first ones (``plant.layout.projection(model.layout)``).
    target : float
        Hub angle to reach and hold at rest, rad. Ignored where ``reference`` is given (its
        final angle is the target).
    torque_limit : float
        ``u_max``, N m (> 0).
    sample_time : float
        ``T``, s (> 0). Default 0.02.
    horizon : int
        ``N``, samples (>= 2). Default 20.
    reference : SlewSolution, optional
        Trajectory to track (states of a model with the same modes as ``model``, torque as
        feedforward); after its end, rest at its final angle. Default: rest at ``target``.
    torque_rate_limit : float, optional
        ``du_max``, N m/s (> 0). Default none.
    tip_limit : float, optional
        ``d_max``, m (> 0), on the modal tip deflection of the design model. Default none.
    terminal : {"lqr", "rest"}
        Terminal cost ``P`` (default) or terminal equality to the reference.
    mode : {"rti", "converged"}, optional
        Per sample one real-time iteration (one SQP step from the warm start, default) or
        the problem solved to convergence by IPOPT.
    qp_solver : str
        QP solver of the real-time iteration (``QP_SOLVERS``). Default ``"qrqp"``.
    state_weights : array_like, shape (n,), optional
        Diagonal of ``Q``. Default Bryson's rule (``_default_weights``).
    torque_weight : float, optional
        ``R``, 1/(N m)^2. Default ``1 / torque_limit^2``.
    substeps : int, optional
        RK4 substeps per hold; default the fewest with ``omega_max h <= OMEGA_H``.
    noise : NoiseLevels, optional
        Output feedback: the state is estimated by an extended Kalman filter on the design
        model from the hub angle and the root bending moment of the plant (as LQG measures),
        designed for these noise levels. Default: full state feedback (the plant state
        truncated to the design modes).
    actuator : ReactionWheel or DCMotor, optional
        What gives the hub torque (:mod:`controllers.design.actuator_limits`): the torque also
        within
        a wheel's torque limit (:attr:`hub_torque_limit`) and the predicted wheel speed within
        its speed limit (less the margin; hub, beams and wheel at zero total momentum); or the
        voltage for each planned torque at the predicted hub rates within a motor's voltage
        limit. ``model`` is the structure's (for a motor, with the rotor's reflected inertia).
        Default none.

    Attributes
    ----------
    n_states : int
        0: no continuous internal states (the memory lives in the session).
    """

    model: Model
    target: float = 0.0
    torque_limit: float
    sample_time: float = 0.02
    horizon: int = 20
    reference: SlewSolution | None = None
    torque_rate_limit: float | None = None
    tip_limit: float | None = None
    terminal: str = "lqr"
    mode: str = "rti"
    qp_solver: str = "qrqp"
    state_weights: np.ndarray | None = None
    torque_weight: float | None = None
    substeps: int | None = None
    noise: NoiseLevels | None = None
    actuator: ReactionWheel | DCMotor | None = None
    _built: dict = field(init=False, repr=False, default_factory=dict)

    n_states = 0

    def __post_init__(self):
        import casadi as ca

        if not isinstance(self.model, Model):
            raise InputTypeError(f"nmpc.model must be a flexctl Model; got "
                                 f"{type(self.model).__name__}")
        if isinstance(self.target, bool) or not isinstance(self.target, (int, float, np.number)) \
                or not np.isfinite(self.target):
            raise InputValueError(f"nmpc.target must be a finite angle, rad; got "
                                  f"{self.target!r}")
        object.__setattr__(self, "target", float(self.target))
        object.__setattr__(self, "torque_limit", _positive("torque_limit", self.torque_limit))
        object.__setattr__(self, "sample_time", check_sample_time("nmpc", self.sample_time))
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, (int, np.integer)) \
                or not 2 <= self.horizon <= 500:
            raise InputValueError(f"nmpc.horizon must be an integer in [2, 500] samples; got "
                                  f"{self.horizon!r}")
        object.__setattr__(self, "horizon", int(self.horizon))
        if self.noise is not None and not isinstance(self.noise, NoiseLevels):
            raise InputTypeError(f"nmpc.noise must be NoiseLevels (or None); got "
                                 f"{type(self.noise).__name__}")
        if self.reference is not None:
            if not isinstance(self.reference, SlewSolution):
                raise InputTypeError("nmpc.reference must be a SlewSolution (or None); got "
                                     f"{type(self.reference).__name__}")
            if self.reference.model.n_modes != self.model.n_modes:
                raise InputValueError(
                    f"nmpc reference has {self.reference.model.n_modes} modes, the design "
                    f"model {self.model.n_modes}; they must match")
        for name in ("torque_rate_limit", "tip_limit"):
            object.__setattr__(self, name, _positive(name, getattr(self, name), optional=True))
        if self.terminal not in TERMINALS:
            raise InputValueError(f"nmpc.terminal must be one of {', '.join(TERMINALS)}; got "
                                  f"{self.terminal!r}")
        if self.mode not in MODES:
            raise InputValueError(f"nmpc.mode must be one of {', '.join(MODES)}; got "
                                  f"{self.mode!r}")
        if self.qp_solver not in QP_SOLVERS:
            raise InputValueError(f"nmpc.qp_solver must be one of {', '.join(QP_SOLVERS)}; "
                                  f"got {self.qp_solver!r}")
        if not ca.has_conic(self.qp_solver):
            raise InputValueError(f"nmpc qp_solver {self.qp_solver!r} is not in this CasADi "
                                  "build (casadi.has_conic); use 'qrqp'")
        object.__setattr__(self, "actuator", check_design_model(self.model, self.actuator))
        n = self.model.n_states
        q_default, r_default = _default_weights(self.model, self.final_angle,
                                                self.hub_torque_limit)
        q = q_default if self.state_weights is None else check_array(
            "nmpc", "state_weights", self.state_weights, finite=False)
        if q.shape != (n,) or not np.all(np.isfinite(q)) or np.any(q < 0):
            raise InputValueError(f"nmpc.state_weights must be {n} finite numbers >= 0; got "
                                  f"{self.state_weights!r}")
        object.__setattr__(self, "state_weights", q)
        r = r_default if self.torque_weight is None else _positive("torque_weight",
                                                                   self.torque_weight)
        object.__setattr__(self, "torque_weight", float(r))
        omega = float(self.model.natural_frequencies(0.0, hub="free")[-1])
        auto = max(1, int(np.ceil(omega * self.sample_time / OMEGA_H)))
        if self.substeps is None:
            if auto > MAX_SUBSTEPS:
                raise InputValueError(
                    f"nmpc sample_time {self.sample_time:g} s needs {auto} RK4 substeps for the "
                    f"design model's fastest mode ({omega:.4g} rad/s, omega h <= {OMEGA_H:g}), "
                    f"more than {MAX_SUBSTEPS}; shorten sample_time or use fewer design modes")
            object.__setattr__(self, "substeps", auto)
        else:
            if isinstance(self.substeps, bool) or not isinstance(self.substeps,
                                                                 (int, np.integer)) \
                    or not 1 <= self.substeps <= MAX_SUBSTEPS:
                raise InputValueError(f"nmpc.substeps must be an integer in [1, "
                                      f"{MAX_SUBSTEPS}]; got {self.substeps!r}")
            if omega * self.sample_time / self.substeps > 2.0 * np.sqrt(2.0):
                raise InputValueError(
                    f"nmpc substeps {self.substeps} put the fastest design mode at omega h = "
                    f"{omega * self.sample_time / self.substeps:.3g}, outside RK4's stability "
                    f"interval (2.83); use at least {auto}")
            object.__setattr__(self, "substeps", int(self.substeps))

    @property
    def hub_torque_limit(self) -> float:
        """The bound on the hub torque, N m: :attr:`torque_limit`, and a reaction wheel's."""
        return hub_torque_bound(self.torque_limit, self.actuator)

    # ------------------------------------------------------------------ reference
    @property
    def final_angle(self) -> float:
        """The hub angle held at the end, rad."""
        if self.reference is not None:
            return float(self.reference.problem.angle)
        return self.target

    def reference_at(self, t) -> tuple:
        """Reference states ``r`` (n, P) at times ``t`` (s) and torques ``v`` (P,): the mean
        of the reference torque over each hold ``[t, t + sample_time)``, N m (what a hold
        must apply to follow a reference whose own holds need not line up with the samples).

        Parameters
        ----------
        t : float or array_like, shape (P,)
            Sample times, s.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if self.reference is None:
            r = np.repeat(self.model.rest_state(self.target)[:, None], t.size, axis=1)
            return r, np.zeros(t.size)
        states = self.reference.state_at(t)
        edges, values = self._reference_holds()
        impulse = np.concatenate(([0.0], np.cumsum(values * np.diff(edges))))
        before = np.interp(t, edges, impulse)
        after = np.interp(t + self.sample_time, edges, impulse)
        return states, (after - before) / self.sample_time

    def _reference_holds(self) -> tuple:
        """Edges (s) and values (N m) of the reference's hold torque, zero outside."""
        if "holds" not in self._built:
            hold = self.reference.torque_function()
            self._built["holds"] = (np.asarray(hold.t, dtype=float),
                                    np.asarray(hold.values, dtype=float))
        return self._built["holds"]

    # ------------------------------------------------------------------ problem
    def _structure(self) -> tuple:
        """Everything the compiled problem depends on: controllers equal in it share one."""
        numbers = lambda v: None if v is None else float(v)     # noqa: E731
        return (id(self.model), self.horizon, self.sample_time, self.substeps,
                self.state_weights.tobytes(), self.torque_weight, self.torque_limit,
                numbers(self.torque_rate_limit), numbers(self.tip_limit), self.terminal,
                self.mode, self.qp_solver, self.actuator)

    def _problem(self) -> dict:
        """The NLP and its compiled pieces, built once per structure (cached)."""
        if "qp" in self._built:
            return self._built
        key = self._structure()
        if key in _PROBLEMS:
            _PROBLEMS.move_to_end(key)
            self._built.update(_PROBLEMS[key][1])
            return self._built
        self._build_problem()
        # (the reference's own tables stay with this controller)
        _PROBLEMS[key] = (self.model, {k: v for k, v in self._built.items() if k != "holds"})
        while len(_PROBLEMS) > PROBLEM_CACHE_SIZE:
            _PROBLEMS.popitem(last=False)
        return self._built

    def _build_problem(self) -> None:
        """The NLP of the module docstring, its bounds and the compiled pieces of a step."""
        import casadi as ca

        model, big_n, n = self.model, self.horizon, self.model.n_states
        sym = ca.MX if model.variant.exact else ca.SX
        hold = hold_function(model, self.sample_time, self.substeps)
        p_mat = self._terminal_weight()
        # decision variables [x_0, u_0, ..., x_{N-1}, u_{N-1}, x_N]; parameters: measured x,
        # previous u, then the references [r_0, v_0, ..., r_N] in the same stage order
        w = sym.sym("w", (big_n + 1) * n + big_n)
        par = sym.sym("p", n + 1 + (big_n + 1) * n + big_n)
        xs, us = _stages(w, n, big_n)
        x_meas, u_prev, refs = _parameters(par, n)
        rx, rv = _stages(refs, n, big_n)
        cost = self._nlp_cost(xs, us, rx, rv, p_mat)
        g, lbg, ubg = self._nlp_constraints(hold, xs, us, x_meas, u_prev, rx)
        lbw = np.full(w.numel(), -np.inf)
        ubw = np.full(w.numel(), np.inf)
        u_index = np.array([input_index(n, j) for j in range(big_n)])
        lbw[u_index], ubw[u_index] = -self.hub_torque_limit, self.hub_torque_limit

        built = {"n": n, "nw": w.numel(), "u_index": u_index, "lbg": lbg, "ubg": ubg,
                 "lbw": lbw, "ubw": ubw}
        built.update(self._condensed(hold, self.state_weights, self.torque_weight, p_mat))
        built["hold"] = built["hold_one"]
        a_sp, h_sp = built["a_sparsity"], built["h_sparsity"]
        built["qp"] = conic_solver("nmpc_qp", self.qp_solver, h_sp, a_sp)
        # a degenerate active set (torque and rate bounds both active) can stop an active-set
        # solver; the step is then solved again by the ADMM solver, which does not mind
        built["qp_fallback"] = (conic_solver("nmpc_qp_fallback", "osqp", h_sp, a_sp)
                                if self.qp_solver != "osqp" else None)
        if self.mode == "converged":
            built["nlp"] = ca.nlpsol("nmpc_nlp", "ipopt", {"x": w, "p": par, "f": cost, "g": g},
                                     {"ipopt.print_level": 0, "print_time": False,
                                      "ipopt.sb": "yes", "ipopt.tol": 1e-8,
                                      "ipopt.max_iter": 500, "error_on_fail": False})
        self._built.update(built)

    def terminal_gain(self) -> tuple:
        """The terminal LQR of the design model held over ``sample_time``: its gain ``K``
        (shape (1, n), ``u = -K x``), the design state's layout and the sample time (s). It is
        also the gain of the unconstrained real-time iteration (a finite horizon ending on
        the Riccati solution gives the infinite-horizon gain at every stage)."""
        from ..design.controllable import held

        p_mat = self._terminal_weight()
        a_d, b_d = held(*self.model.linear_matrices(0.0), self.sample_time)
        gain = np.linalg.solve(self.torque_weight + b_d.T @ p_mat @ b_d, b_d.T @ p_mat @ a_d)
        return gain, self.model.layout, float(self.sample_time)

    def _terminal_weight(self) -> np.ndarray:
        """``P``: the discrete LQR Riccati solution of the design model at rest, held over
        ``sample_time`` with weights ``Q`` and ``R``, shape (n, n)."""
        from ..design.controllable import design_failure, dlqr_on_part

        with design_failure("nmpc", "NMPC terminal weight", self.model,
                            state_weights=self.state_weights, torque_weight=self.torque_weight,
                            sample_time=self.sample_time,
                            solving="the discrete LQR Riccati equation"):
            return dlqr_on_part(self.model, self.sample_time, np.diag(self.state_weights),
                                np.array([[self.torque_weight]]))

    def _nlp_cost(self, xs, us, rx, rv, p_mat):
        """``1/2 |res|^2``: each stage's residuals weighted by ``sqrt(Q)`` and ``sqrt(R)``, the
        last state's by a square-root factor of ``P``."""
        import casadi as ca

        big_n, r = self.horizon, self.torque_weight
        residuals = []
        sq = np.sqrt(self.state_weights)
        for j in range(big_n):
            residuals.append(ca.DM(sq) * (xs[j] - rx[j]))
            residuals.append(np.sqrt(r) * (us[j] - rv[j]))
        # P = F^T F; P is only semidefinite when the torque cannot move some modes
        # (controllers.design.controllable), so F comes from its eigenvalues, not Cholesky
        lam, vec = np.linalg.eigh(0.5 * (p_mat + p_mat.T))
        factor = np.sqrt(np.clip(lam, 0.0, None))[:, None] * vec.T
        residuals.append(ca.mtimes(ca.DM(factor), xs[big_n] - rx[big_n]))
        return 0.5 * ca.sumsqr(ca.vertcat(*residuals))

    def _nlp_constraints(self, hold, xs, us, x_meas, u_prev, rx) -> tuple:
        """``(g, lbg, ubg)``: the start at the measured state, the shooting gaps, then the
        torque-rate, tip, actuator and terminal-rest constraints that are set, in that order."""
        import casadi as ca

        big_n, n, layout = self.horizon, self.model.n_states, self.model.layout
        g, lbg, ubg = [xs[0] - x_meas], [0.0] * n, [0.0] * n
        for j in range(big_n):
            g.append(hold(xs[j], us[j]) - xs[j + 1])
            lbg += [0.0] * n
            ubg += [0.0] * n
        if self.torque_rate_limit is not None:
            step = self.torque_rate_limit * self.sample_time
            for j in range(big_n):
                g.append(us[j] - (u_prev if j == 0 else us[j - 1]))
                lbg.append(-step)
                ubg.append(step)
        if self.tip_limit is not None:
            tip = ca.DM(self.model.tip_matrix)       # one row per appendage
            for j in range(1, big_n + 1):
                g.append(ca.mtimes(tip, layout.modal(xs[j])))
                lbg += [-self.tip_limit] * tip.size1()
                ubg += [self.tip_limit] * tip.size1()
        if self.actuator is not None:
            limits, lower, upper = horizon_constraints(self.model, self.actuator, xs, us)
            g.append(limits)
            lbg += list(lower)
            ubg += list(upper)
        if self.terminal == "rest":
            g.append(xs[big_n] - rx[big_n])
            lbg += [0.0] * n
            ubg += [0.0] * n
        return ca.vertcat(*g), np.array(lbg), np.array(ubg)

    def _condensed(self, hold, q_diag, r, p_mat, compiled: bool = True) -> dict:
        """The pieces of the condensed Gauss-Newton QP of one real-time iteration.

        Linearised about the current guess (states ``x_j``, torques ``u_j``), the shooting gaps
        ``d_j = F(x_j, u_j) - x_{j+1}`` and the measured start give the state steps as affine
        functions of the torque steps, ``dx_0 = x(t_k) - x_0``,
        ``dx_{j+1} = A_j dx_j + B_j du_j + d_j``, i.e. ``dx_j = e_j + G_j du``: the QP has the
        ``N`` torque steps only (dense ``N x N``, see ``NMPCSession._rti``). One mapped
        function gives every stage's ``F`` and its ``A, B`` (``stages``; the Jacobians of
        :attr:`NMPC.linearisation_model`); the condensing is ``_condensing``. With
        ``compiled`` false they stay CasADi expressions (for C code generation).
        """
        import casadi as ca

        n, big_n = self.model.n_states, self.horizon
        lin_model = self.linearisation_model
        lin_hold = hold if lin_model is self.model else hold_function(
            lin_model, self.sample_time, self.substeps)
        x, u = ca.SX.sym("x", n), ca.SX.sym("u")
        f = lin_hold(x, u)
        # a stage's F and its A, B in one function: the Jacobians' forward sweep is F's own
        stage = ca.Function("nmpc_stage", [x, u], [f if lin_model is self.model else hold(x, u),
                                                   ca.jacobian(f, x), ca.jacobian(f, u)])
        rows = 0
        if self.torque_rate_limit is not None:
            rows += big_n
        if self.tip_limit is not None:
            rows += big_n
        rows += horizon_rows(self.actuator, big_n)
        if self.terminal == "rest":
            rows += n
        # the condensing calls the symbolic pieces (a compiled one cannot be generated into
        # another's C); each is compiled afterwards, on its own
        pieces = {"stages": stage.map(big_n), "hold_one": hold,
                  "q": q_diag, "r": r, "p": p_mat, "rows": rows,
                  "h_sparsity": ca.Sparsity.dense(big_n, big_n),
                  "a_sparsity": ca.Sparsity.dense(rows, big_n)}
        pieces.update(self._condensing(pieces, compiled))
        if compiled:
            pieces["hold_one"] = jit_compiled(hold, self.model, any_variant=True)
        return pieces

    def _condensing(self, pieces, compiled: bool = True) -> dict:
        """``condense(w, p) -> (H, g, A, lba, uba, lbx, ubx, e, G)`` and
        ``expand(w, e, G, du) -> w + dw`` as CasADi functions, so that a step hands CasADi
        matrices from the linearisation to the QP solver and back without converting them to
        numpy: the stages' mapped function, then the algebra in scalars (SX)."""
        import casadi as ca

        n, big_n = self.model.n_states, self.horizon
        w = ca.MX.sym("w", (big_n + 1) * n + big_n)
        par = ca.MX.sym("p", n + 1 + (big_n + 1) * n + big_n)
        # with the stages' sparsity: the structural zeros of A_j (the hub angle's column,
        # which the dynamics do not depend on) drop out of the algebra below
        f, a_all, b_all = (ca.MX.sym(name, pieces["stages"].sparsity_out(k))
                           for k, name in enumerate("FAB"))
        xs, us = _stages(w, n, big_n)
        us = ca.vertcat(*us)
        x_meas, u_prev, refs = _parameters(par, n)
        rx, rv = _stages(refs, n, big_n)
        # the algebra in scalars (SX), in two functions (the state steps, then the QP's
        # matrices): the structural zeros (of A_j, of G_j's later columns) and the common
        # terms drop out, and the products of every stage are called (_kernels), so that the
        # C stays short enough to compile in seconds
        kernels = _kernels(a_all[:, :n].sparsity(), n, np.diag(pieces["q"]))
        e, g_mats, a_list, b_list = _state_steps(f, a_all, b_all, xs, x_meas, kernels)
        e_all, g_all = ca.vertcat(*e), ca.vertcat(*g_mats)
        steps = ca.Function("nmpc_state_steps", [w, par, f, a_all, b_all],
                            [e_all, g_all]).expand()
        e_in, g_in = ca.MX.sym("e", e_all.sparsity()), ca.MX.sym("G", g_all.sparsity())
        e, g_mats = ca.vertsplit(e_in, n), ca.vertsplit(g_in, n)
        base = [xs[j] + e[j] - rx[j] for j in range(big_n + 1)]
        hessian, gradient = _condensed_cost(pieces, g_mats, (a_list, b_list), base, us,
                                            ca.vertcat(*rv), kernels)
        a_qp, lba, uba = self._condensed_constraints(g_mats, e, xs, us, u_prev, base)
        matrices = ca.Function(
            "nmpc_qp_matrices", [w, par, a_all, b_all, e_in, g_in],
            [ca.densify(hessian), gradient, ca.densify(a_qp), lba, uba,
             -self.hub_torque_limit - us, self.hub_torque_limit - us]).expand()
        # the stages' F and A, B: one mapped (looped) function
        f_all, a_in, b_in = pieces["stages"](ca.horzcat(*xs[:-1]), us.T)
        e_out, g_out = steps(w, par, f_all, a_in, b_in)
        condense = ca.Function("nmpc_condense", [w, par], [
            *matrices(w, par, a_in, b_in, e_out, g_out), e_out, g_out])
        if compiled and big_n >= JIT_CONDENSE_FROM:
            condense = jit_compiled(condense, self.model, any_variant=True)
        return {"condense": condense,
                "expand": _expansion(w, n, big_n, g_all.sparsity())}

    def _condensed_constraints(self, g_mats, e, xs, us, u_prev, base) -> tuple:
        """``(A, lba, uba)`` of the QP's ``lba <= A du <= uba``: the torque-rate, tip,
        actuator and terminal-rest rows that are set, in that order (none: no rows)."""
        import casadi as ca

        big_n = self.horizon
        rows, lower, upper = [], [], []
        if self.torque_rate_limit is not None:
            bound = self.torque_rate_limit * self.sample_time
            diff = ca.DM(np.eye(big_n) - np.eye(big_n, k=-1))
            now = us - ca.vertcat(u_prev, us[:-1])
            rows.append(diff)
            lower.append(-bound - now)
            upper.append(bound - now)
        if self.tip_limit is not None:
            tip, layout = ca.DM(self.model.tip_matrix), self.model.layout
            tips = ca.vertcat(*[ca.mtimes(tip, g_mats[j][layout.q, :])
                                for j in range(1, big_n + 1)])
            now = ca.vertcat(*[ca.mtimes(tip, layout.modal(xs[j]) + layout.modal(e[j]))
                               for j in range(1, big_n + 1)])
            rows.append(tips)
            lower.append(-self.tip_limit - now)
            upper.append(self.tip_limit - now)
        if self.actuator is not None:
            for part, piece in zip((rows, lower, upper), linearised_horizon_constraints(
                    self.model, self.actuator, xs, us, e, g_mats)):
                part.append(piece)
        if self.terminal == "rest":
            rows.append(g_mats[-1])
            lower.append(-base[-1])
            upper.append(-base[-1])
        if rows:
            return ca.vertcat(*rows), ca.vertcat(*lower), ca.vertcat(*upper)
        return ca.MX(0, big_n), ca.MX(0, 1), ca.MX(0, 1)

    @property
    def linearisation_model(self) -> Model:
        """The model whose Jacobians the real-time iteration uses: the design model itself, or
        for the exact variant the first_order model of the same modes.

        The exact model's RK4 Jacobians cost some 250 000 operations a stage (26 ms for 20
        stages, measured), the first_order one's a few hundred. Its linearisation agrees with
        the exact one at rest and differs at second order in the deflection; the shooting
        gaps, cost and constraints stay those of the exact model, so the iterations still aim
        at the exact model's optimum (an inexact-Jacobian SQP step).
        """
        if not self.model.variant.exact:
            return self.model
        if "linearisation_model" not in self._built:
            from flexctl.model import build_model

            self._built["linearisation_model"] = build_model(
                self.model.system, n_modes=self.model.mode_spec, variant="first_order")
        return self._built["linearisation_model"]

    def prepare(self) -> "NMPC":
        """Build (and compile, where a C compiler is present) the problem now rather than at
        the first sample; returns ``self``."""
        self._problem()
        return self

    def start(self, model, x0) -> "NMPCSession":
        """A fresh session for a run of the plant ``model`` from ``x0``.

        Parameters
        ----------
        model : Model
            The plant, with at least the design model's modes
            (``model.layout.projection(self.model.layout)`` picks the design state).
        x0 : array_like, shape (n,)
            Plant state at the start of the run, in the order of ``model.layout``.

        Raises
        ------
        InputTypeError
            If ``model`` is not a flexctl Model.
        InputValueError
            If the plant has fewer modes than the design model.
        """
        if not isinstance(model, Model):
            raise InputTypeError(f"nmpc.plant must be a flexctl Model; got "
                                 f"{type(model).__name__}")
        if model.n_modes < self.model.n_modes:
            raise InputValueError(f"nmpc design model has {self.model.n_modes} modes, more "
                                  f"than the plant's {model.n_modes}")
        rows = model.layout.projection(self.model.layout)
        session = NMPCSession(self, self._problem(), np.asarray(x0, dtype=float), rows)
        if self.noise is not None:
            session.filter = _ExtendedKalman(self, measurement_rows(model),
                                             np.asarray(x0, dtype=float)[rows])
        return session


class _ExtendedKalman:
    """Extended Kalman filter on the design model, one prediction and update per sample.

    Prediction through the RK4 hold ``F`` with its Jacobian (of
    :attr:`NMPC.linearisation_model`); process noise a white hub torque of intensity
    ``noise.torque^2`` held over the sample (``B_d Q B_d^T / T``); measurement the plant's hub
    angle and root moment, ``y = C_plant x``, against the design model's ``C``.
    """

    def __init__(self, mpc: NMPC, plant_rows, x0):
        import casadi as ca

        model = mpc.model
        self.mpc = mpc
        self.plant_rows = plant_rows
        self.rows = measurement_rows(model)
        x, u = ca.SX.sym("x", model.n_states), ca.SX.sym("u")
        lin = hold_function(mpc.linearisation_model, mpc.sample_time, mpc.substeps)(x, u)
        self.hold = jit_compiled(hold_function(model, mpc.sample_time, mpc.substeps), model,
                         any_variant=True)
        self.jacobians = jit_compiled(ca.Function("nmpc_ekf_jac", [x, u], [ca.jacobian(lin, x),
                                                                    ca.jacobian(lin, u)]),
                              mpc.linearisation_model)
        self.r = mpc.noise.measurement_covariance
        self.q = float(mpc.noise.process_covariance[0, 0])
        self.x = np.asarray(x0, dtype=float).copy()
        self.p = np.eye(model.n_states) * 1e-8

    def update(self, x_plant, u_prev, first: bool) -> np.ndarray:
        """The estimate at this sample from the plant's measurement and the torque held
        since the last one."""
        if not first:
            a, b = (np.array(v) for v in self.jacobians(self.x, u_prev))
            self.x = np.array(self.hold(self.x, u_prev)).reshape(-1)
            self.p = a @ self.p @ a.T + (self.q / self.mpc.sample_time) * (b @ b.T)
        y = self.plant_rows @ x_plant
        c = self.rows
        s = c @ self.p @ c.T + self.r
        gain = np.linalg.solve(s, c @ self.p).T
        self.x = self.x + gain @ (y - c @ self.x)
        self.p = (np.eye(self.x.size) - gain @ c) @ self.p
        return self.x


class NMPCSession:
    """One closed-loop run of an :class:`NMPC`: warm start, last torque and statistics.

    Made by :meth:`NMPC.start`.

    Parameters
    ----------
    mpc : NMPC
        The controller run.
    built : dict
        Its transcribed problem and solver (built once per controller).
    x0 : array_like, shape (n,)
        Plant state at the start: the warm start's states without a reference.
    rows : array_like of int, optional
        Indices of the design state in the plant state
        (``plant.layout.projection(mpc.model.layout)``); default those of a plant of the
        design model's blocks with ``x0``'s length
        (:func:`controllers.design.plant_state.design_rows`).
    """

    def __init__(self, mpc: NMPC, built: dict, x0, rows=None):
        self.mpc, self.built = mpc, built
        n, big_n = built["n"], mpc.horizon
        self._n = n
        x0 = np.asarray(x0, dtype=float)
        self._rows = design_rows(mpc.model.layout, x0.size) if rows is None \
            else np.asarray(rows)
        x_design = x0[self._rows]
        # initial guess: the reference from now on (or the start state held)
        refs, torques = mpc.reference_at(mpc.sample_time * np.arange(big_n + 1))
        w = np.zeros(built["nw"])
        for j in range(big_n + 1):
            w[state_slice(n, j)] = refs[:, j] if mpc.reference is not None else x_design
        bound = mpc.hub_torque_limit
        w[built["u_index"]] = np.clip(torques[:big_n], -bound, bound)
        self.w = w
        self.u_prev = 0.0
        self.solve_times, self.iterations, self.failures, self.statuses = [], [], 0, {}
        self.fallbacks = 0
        self.filter = None

    def _parameters(self, t, x_design):
        mpc, big_n = self.mpc, self.mpc.horizon
        times = t + mpc.sample_time * np.arange(big_n + 1)
        refs, torques = mpc.reference_at(times)
        block = np.concatenate((np.column_stack((refs[:, :-1].T, torques[:big_n])).reshape(-1),
                                refs[:, -1]))
        return np.concatenate((x_design, [self.u_prev], block))

    def _shift(self):
        """Warm start: the previous solution moved one sample on, its last hold repeated."""
        n, w = self._n, self.w
        width = n + 1
        shifted = np.empty_like(w)
        shifted[:-width] = w[width:]
        last_x = w[-n:]
        last_u = w[-n - 1]
        shifted[-width:-n] = last_u
        shifted[-n:] = np.array(self.built["hold"](last_x, last_u)).reshape(-1)
        if not np.all(np.isfinite(shifted)):
            shifted = w
        return shifted

    def step(self, t, x) -> float:
        """Torque (N m) to hold from ``t``, given the plant state ``x``.

        Parameters
        ----------
        t : float
            Sample time, s.
        x : array_like, shape (n,)
            Plant state at ``t``, in the order of the plant's layout (its design rows are
            read, or its hub angle and root moments by the extended Kalman filter).
        """
        started = time.perf_counter()
        mpc, built = self.mpc, self.built
        if self.filter is not None:
            x_design = self.filter.update(np.asarray(x, dtype=float), self.u_prev,
                                          not self.solve_times).copy()
        else:
            x_design = np.asarray(x, dtype=float)[self._rows]
        p = self._parameters(float(t), x_design)
        guess = self._shift() if self.solve_times else self.w
        guess[:self._n] = x_design
        if mpc.mode == "rti":
            w_new, ok, iterations, status = self._rti(guess, p, x_design)
        else:
            sol = built["nlp"](x0=guess, p=p, lbx=built["lbw"], ubx=built["ubw"],
                               lbg=built["lbg"], ubg=built["ubg"])
            stats = built["nlp"].stats()
            ok = bool(stats.get("success", False))
            iterations = int(stats.get("iter_count", 0) or 0)
            status = str(stats.get("return_status", ""))
            w_new = np.array(sol["x"]).reshape(-1)
        if ok and np.all(np.isfinite(w_new)):
            self.w = w_new
        else:
            # keep the shifted previous plan: its first torque is still feasible
            self.failures += 1
            self.w = guess
        self.statuses[status] = self.statuses.get(status, 0) + 1
        u = float(np.clip(self.w[built["u_index"][0]], -mpc.hub_torque_limit,
                          mpc.hub_torque_limit))
        if mpc.torque_rate_limit is not None and self.solve_times:
            bound = mpc.torque_rate_limit * mpc.sample_time
            u = float(np.clip(u, self.u_prev - bound, self.u_prev + bound))
        self.u_prev = u
        self.iterations.append(iterations)
        self.solve_times.append(time.perf_counter() - started)
        return u

    def _rti(self, guess, p, x_design):
        """One Gauss-Newton SQP step from ``guess``: linearise and condense (one compiled
        call), solve the QP (the fallback solver if the first fails), expand."""
        built = self.built
        h, g, a, lba, uba, lbx, ubx, affine, gains = built["condense"](guess, p)
        data = dict(h=h, g=g, a=a, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
        sol = built["qp"](**data)
        stats = built["qp"].stats()
        ok = bool(stats.get("success", False))
        iterations = int(stats.get("iter_count", 0) or 0)
        status = str(stats.get("return_status", "ok" if ok else "failed"))
        if not ok and built["qp_fallback"] is not None:
            self.fallbacks += 1
            sol = built["qp_fallback"](**data)
            stats = built["qp_fallback"].stats()
            ok = bool(stats.get("success", False))
            iterations += int(stats.get("iter_count", 0) or 0)
            status = "fallback osqp: " + str(stats.get("return_status", "ok" if ok else
                                                        "failed"))
        w_new = built["expand"](guess, affine, gains, sol["x"]).full().reshape(-1)
        return w_new, ok, iterations, status

    def report(self) -> dict:
        """Per-step solve time (s: median, 99th percentile, max), iterations, failed steps
        (the previous plan shifted was applied) and steps re-solved by the fallback QP solver,
        with the solvers' statuses and their counts."""
        times = np.array(self.solve_times) if self.solve_times else np.zeros(1)
        its = np.array(self.iterations) if self.iterations else np.zeros(1)
        return {"estimator": "ekf" if self.filter is not None else "state",
                "mode": self.mpc.mode, "qp_solver": self.mpc.qp_solver if self.mpc.mode == "rti"
                else "ipopt", "horizon": self.mpc.horizon, "design_modes": self.mpc.model.n_modes,
                "substeps": self.mpc.substeps,
                "solve_time_median_s": float(np.median(times)),
                "solve_time_p99_s": float(np.percentile(times, 99)),
                "solve_time_max_s": float(np.max(times)),
                "iterations_median": float(np.median(its)), "iterations_max": int(np.max(its)),
                "failed_steps": int(self.failures), "fallback_steps": int(self.fallbacks),
                "statuses": dict(self.statuses)}
