"""Finite-dimensional hub-beam-mass models: first_order, zero_order, consistent and exact.

The variants share one assembly (:func:`flexctl.model.matrices.assemble`); each is a
:class:`~flexctl.model.variant.Variant` that says which terms it contributes (MODEL.md
section 4): the spin softens the beam by ``D = M_ff - K_g`` with dynamic stiffening and by
``M_ff`` without (zero_order), and consistent adds ``q^T D q theta_tt + 2 theta_t q^T D q_t``
to the hub equation ``J_0 theta_tt + m_tf^T q_tt``.

``exact`` is geometrically exact (MODEL.md section 7, :mod:`flexctl.model.exact`): the same
modes describe the slope angle of an inextensible beam, positions and velocities are exact, and
the mass matrix ``M(q)`` depends on the deflection. It stays regular for a massless hub,
reduces to first_order when linearised and to consistent at second order.

Notes
-----
State vector, ``n = 2 N + 2`` entries, in this order::

    x = [theta, q_1 .. q_N, theta_dot, q_1_dot .. q_N_dot]

with ``theta`` in rad, ``q_i`` in m (tip-normalised cantilever modes, ``phi_i(l) = +-2``),
rates in rad/s and m/s. Input ``u = [torque]``, N m. Outputs, in this order::

    y = [theta, theta_dot, tip_deflection, root_moment, tip_angle]

(rad, rad/s, m, N m, rad), linear in the state except for the exact variant, whose tip
deflection is the lateral tip position ``p_y(l)`` in the hub frame and whose tip angle is
``theta + atan2(p_y(l), p_x(l))``. :attr:`Model.output_matrix` is their linearisation at
``q = 0`` for every variant.
"""

from __future__ import annotations

import dataclasses

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from .checks import check_real
from .errors import InputValueError, SingularMassMatrixError
from .exact import EXACT_MAX_MODES, exact_geometry
from .exports import signal_names
from .layout import StateLayout
from .matrices import ModalMatrices, assemble, condensed_hub_inertia
from .parameters import HubBeam
from .variant import VARIANTS, Variant

__all__ = ["Model", "VARIANTS", "SingularMassMatrixError", "EXACT_MAX_MODES"]

#: Largest steady spin rate the linear analysis takes, rad/s: its square multiplies the modal
#: matrices, and must stay far from overflow.
MAX_SPIN_RATE = 1e100
#: Spin rates whose natural frequencies a model keeps (the last ones asked for).
KEPT_SPINS = 16
OUTPUT_NAMES = ("theta", "theta_dot", "tip_deflection", "root_moment", "tip_angle")


@dataclass(frozen=True, eq=False)
class Model:
    """A hub-beam-mass model of one variant on ``n_modes`` cantilever modes.

    Build with :func:`build_model`. See the module Notes for the order of states and outputs.

    Attributes
    ----------
    system : HubBeam
    n_modes : int
    variant : Variant
        ``"first_order"``, ``"zero_order"``, ``"consistent"`` or ``"exact"``, a ``str``
        whose properties are the terms it contributes (:class:`~flexctl.model.variant.Variant`).
    matrices : ModalMatrices
    layout : StateLayout
        Names and slices of the state's blocks (:mod:`flexctl.model.layout`).
    state_names, input_names, output_names : tuple of str
    """

    system: HubBeam
    n_modes: int
    variant: str
    matrices: ModalMatrices = field(repr=False)
    layout: StateLayout = field(init=False, repr=False)
    state_names: tuple = field(init=False, repr=False)
    input_names: tuple = field(init=False, repr=False, default=("torque",))
    output_names: tuple = field(init=False, repr=False, default=OUTPUT_NAMES)

    def __post_init__(self):
        object.__setattr__(self, "variant", Variant(self.variant))
        mat = self.matrices
        layout = StateLayout.single(self.n_modes)
        object.__setattr__(self, "layout", layout)
        object.__setattr__(self, "state_names", layout.names)
        stiff_d = self.variant.spin_matrix(mat)
        cho = scipy.linalg.cho_factor(mat.M_ff)
        m_inv = scipy.linalg.cho_solve(cho, np.eye(self.n_modes))
        m_inv = 0.5 * (m_inv + m_inv.T)
        g = m_inv @ mat.m_tf
        cache = {
            "stiff_d": stiff_d,                       # D of the beam stiffness term
            "m_inv": m_inv,                           # M_ff^-1
            "g": g,                                   # M_ff^-1 m_tf
            # Schur complement J0 - m_tf^T g at q = 0, without the cancelling subtraction
            # (a heavy tip mass made it 30 times too large)
            "j_rigid_eff": condensed_hub_inertia(mat.system, self.n_modes),
            "c_out": self._output_matrix(),
        }
        for a in cache.values():
            if isinstance(a, np.ndarray):
                a.setflags(write=False)
        object.__setattr__(self, "_c", cache)

    # ------------------------------------------------------------------ basics
    @property
    def modes(self) -> tuple:
        """Modes of each appendage: ``(n_modes,)`` for one beam."""
        return (self.n_modes,)

    @property
    def mode_spec(self):
        """The ``n_modes`` that :func:`flexctl.build_model` takes to rebuild this model's
        modes: an int for one beam, the tuple of each appendage's modes for a structure."""
        return self.n_modes

    @property
    def structure(self):
        """The system as a :class:`~flexctl.model.structure.Structure` (one unnamed
        appendage for a ``HubBeam``)."""
        from .structure import as_structure
        return as_structure(self.system)

    @property
    def tip_matrix(self) -> np.ndarray:
        """Linear tip deflection of each appendage per modal coordinate, ``phi_k(l_k)``,
        shape (K, N) (one row for one beam)."""
        return self.matrices.tip[None, :]

    def rest_state(self, theta: float = 0.0) -> np.ndarray:
        """The undeformed structure at rest at hub angle ``theta`` (rad), shape (n,): a free
        hub's centre placed so that the centre of mass is where it is at ``theta = 0`` with
        the hub centre at the origin (a rigid turn about the centre of mass).

        Parameters
        ----------
        theta : float, optional
            Hub angle, rad. Default 0.
        """
        return self.layout.join(theta=float(theta))

    @property
    def mode_lengths(self) -> np.ndarray:
        """Beam length of the appendage each modal coordinate belongs to, m, shape (N,)."""
        return np.concatenate([np.full(n, length) for n, length in zip(self.modes, self.lengths)])

    @property
    def mode_tips(self) -> np.ndarray:
        """Tip deflection of its own appendage per unit of each modal coordinate, shape (N,)."""
        return np.sum(self.tip_matrix, axis=0)

    @property
    def rigid_inertia(self) -> float:
        """Inertia of the undeformed structure about the axis it turns on, kg m^2: ``J_0``
        about the pinned hub's centre; ``J_0 - |S_0|^2 / m`` about the centre of mass for a
        free hub."""
        return float(self.matrices.J0)

    def quasi_static_gain(self) -> np.ndarray:
        """``q = -g theta_tt``: the modal deflection that a slow hub acceleration holds at
        rest (a free hub's centre moving as the acceleration needs), m per rad/s^2, (N,)."""
        return np.linalg.solve(self.matrices.K_ff, self.matrices.m_tf)

    @property
    def lengths(self) -> np.ndarray:
        """Beam length of each appendage, m, shape (K,)."""
        return np.array([a.beam.length for a in self.structure.appendages])

    def tip_deflections(self, x) -> np.ndarray:
        """Each appendage's tip deflection, m, shape (1,) or (1, P) for one beam.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        """
        return np.asarray(self.tip_deflection(x))[None]

    def center_of_mass(self, x) -> np.ndarray:
        """Centre of mass in inertial axes (the pinned hub's centre at the origin), m,
        shape (2,) or (2, P); small-deflection first moments for every variant.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        """
        from .structure_matrices import assemble_structure

        x = self._check_state(x)
        first = assemble_structure(self.structure, self.modes)
        s = (np.multiply.outer(first.first, np.ones(x.shape[1:]))
             + first.first_q @ self.layout.modal(x))
        c, si = np.cos(self.layout.hub_angle(x)), np.sin(self.layout.hub_angle(x))
        return np.stack((c * s[0] - si * s[1], si * s[0] + c * s[1])) / first.mass

    @property
    def n_states(self) -> int:
        """Number of states ``2 N + 2``."""
        return self.layout.n_states

    def __repr__(self):
        return (f"Model(variant={self.variant!r}, n_modes={self.n_modes}, "
                f"J0={self.matrices.J0:.6g} kg m^2, "
                f"first clamped frequency {self.first_clamped_frequency:.6g} rad/s)")

    @property
    def first_clamped_frequency(self) -> float:
        """Lowest natural frequency with the hub held, at rest, point masses included, rad/s."""
        if "w1" not in self._c:
            self._c["w1"] = float(self.natural_frequencies(0.0, hub="clamped")[0])
        return self._c["w1"]

    def split(self, x):
        """Split a state into ``theta, q, theta_dot, q_dot``.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.

        Returns
        -------
        theta : float or ndarray, shape (P,)
            Hub angle, rad.
        q : ndarray, shape (N,) or (N, P)
            Modal coordinates, m.
        theta_dot : float or ndarray, shape (P,)
            Hub rate, rad/s.
        q_dot : ndarray, shape (N,) or (N, P)
            Modal rates, m/s.
        """
        return self.layout.split(np.asarray(x, dtype=float))

    def _check_state(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape[:1] != (self.n_states,):
            raise InputValueError(f"state must have shape ({self.n_states},) for {self.n_modes} "
                                  f"modes; got {x.shape}")
        return x

    # ------------------------------------------------------------------ dynamics
    def effective_hub_inertia(self, x) -> np.ndarray:
        """Schur complement ``J(q) - m_tf^T M_ff^-1 m_tf`` of the mass matrix, kg m^2.

        The mass matrix is singular where it reaches 0. Constant for first_order and
        zero_order; ``J(q) = J_0 + q^T D q`` for consistent; for exact, the Schur complement
        ``M_tt - M_tq M_qq^-1 M_qt`` of ``M(q)``, positive for any deflection.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.

        Returns
        -------
        float or ndarray, shape (P,)
            The effective inertia at each state, kg m^2.
        """
        x = self._check_state(x)
        j = self._c["j_rigid_eff"]
        if self.variant.exact:
            mass = self._exact_mass(x)
            schur = [m[0, 0] - m[0, 1:] @ np.linalg.solve(m[1:, 1:], m[1:, 0]) for m in mass]
            return np.array(schur) if x.ndim > 1 else np.float64(schur[0])
        if not self.variant.quadratic_inertia:
            return np.full(x.shape[1:], j) if x.ndim > 1 else np.float64(j)
        q = self.layout.modal(x)
        return j + np.einsum("i...,ij,j...->...", q, self.matrices.D, q)

    @property
    def geometry(self):
        """The exact variant's CasADi functions (:class:`~flexctl.model.exact.ExactGeometry`),
        built on first use and cached; ``None`` for the other variants."""
        if not self.variant.exact:
            return None
        if "geometry" not in self._c:
            self._c["geometry"] = exact_geometry(self.matrices)
        return self._c["geometry"]

    def integration_rhs(self, evaluate=None):
        """The dynamics as a CasADi ``Function`` ``(x, u) -> xdot`` for implicit integrators.

        For the exact variant, its own right-hand side with the Jacobian of the first_order
        model in place of its own (:meth:`newton_jacobian`): Newton iterations of an implicit
        method need only an approximate Jacobian (accuracy is that of the right-hand side),
        and the exact one costs many evaluations of the right-hand side. The right-hand side
        is the vectorized form (:attr:`~flexctl.model.exact.ExactGeometry.rhs_vectorized`:
        two to four times faster on CasADi's virtual machine, and quick to compile), or
        ``evaluate(x, u)`` (MX symbols in, MX expression out) when given, e.g. a call of a
        compiled :meth:`casadi`. The same as :meth:`casadi` otherwise.

        Parameters
        ----------
        evaluate : callable, optional
            ``evaluate(x, u) -> xdot`` on CasADi MX symbols (``x`` (n x 1), ``u`` (1 x 1)),
            used as the exact variant's right-hand side. Default: the vectorized form, built
            once and cached. Not read by the other variants.
        """
        if not self.variant.exact:
            return self.casadi()
        if evaluate is None and "integration_rhs" in self._c:
            return self._c["integration_rhs"]
        import casadi as ca

        xm, um = ca.MX.sym("x", self.n_states), ca.MX.sym("u")
        xdot = (self.geometry.rhs_vectorized if evaluate is None else evaluate)(xm, um)
        name = f"flexctl_exact_newton_N{self.n_modes}"
        function = ca.Function(name, [xm, um], [xdot], ["x", "u"], ["xdot"],
                               {"custom_jacobian": self.newton_jacobian("rhs"),
                                "jac_penalty": 0})
        if evaluate is None:
            self._c["integration_rhs"] = function
        return function

    def integration_beam(self, evaluate=None):
        """The beam under a prescribed hub motion as a CasADi ``Function``
        ``(y, rate, acceleration) -> dy/dt`` for implicit integrators, ``y = [q, q_dot]``.

        For the exact variant, as :meth:`integration_rhs`: the exact beam
        (:attr:`~flexctl.model.exact.ExactGeometry.beam`, or ``evaluate(q, q_dot, rate,
        acceleration)`` returning ``q_tt``) with first_order's Jacobian for Newton's method.

        Parameters
        ----------
        evaluate : callable, optional
            ``evaluate(q, q_dot, rate, acceleration) -> q_tt`` on CasADi MX symbols (``q``,
            ``q_dot`` (N x 1), m and m/s; hub rate rad/s, hub acceleration rad/s^2), used as
            the exact variant's beam. Default: :attr:`ExactGeometry.beam
            <flexctl.model.exact.ExactGeometry.beam>`. Not read by the other variants.
        """
        import casadi as ca

        from .exports import symbolic_beam_dynamics

        n = self.n_modes
        ym, rate, acc = ca.MX.sym("y", 2 * n), ca.MX.sym("rate"), ca.MX.sym("acceleration")
        if not self.variant.exact:
            return ca.Function("flexctl_beam", [ym, rate, acc],
                               [symbolic_beam_dynamics(self, ym, rate, acc)],
                               ["y", "rate", "acceleration"], ["ydot"])
        q_tt = (self.geometry.beam if evaluate is None else evaluate)(ym[:n], ym[n:], rate, acc)
        return ca.Function(f"flexctl_exact_beam_newton_N{n}", [ym, rate, acc],
                           [ca.vertcat(ym[n:], q_tt)], ["y", "rate", "acceleration"],
                           ["ydot"], {"custom_jacobian": self.newton_jacobian("beam"),
                                      "jac_penalty": 0})

    def newton_jacobian(self, form: str = "rhs"):
        """first_order's Jacobian in the form CasADi's ``custom_jacobian`` takes: of
        ``(x, u) -> xdot`` (``form="rhs"``) or of ``(y, rate, acceleration) -> dy/dt``
        (``form="beam"``), with the nominal output as its last input.

        Parameters
        ----------
        form : {"rhs", "beam"}, optional
            The function differentiated: the whole model's right-hand side (default) or the
            beam under a prescribed hub motion (:meth:`integration_beam`).

        Returns
        -------
        casadi.Function
            Built once per form and cached.
        """
        key = ("newton_jacobian", form)
        if key not in self._c:
            import casadi as ca

            from .exports import symbolic_beam_dynamics

            # the same kind of model on the same matrices (a structure's, an actuated one's)
            linear = dataclasses.replace(self, variant="first_order")
            if form == "rhs":
                x, u, out = (ca.SX.sym("x", self.n_states), ca.SX.sym("u"),
                             ca.SX.sym("out", self.n_states))
                xdot = linear.casadi()(x, u)
                names, args = ["x", "u", "out_xdot"], [x, u, out]
                outputs, out_names = [ca.jacobian(xdot, x), ca.jacobian(xdot, u)], \
                    ["jac_xdot_x", "jac_xdot_u"]
                prefix = "flexctl_exact_newton"
            else:
                n = self.n_modes
                y, rate, acc, out = (ca.SX.sym("y", 2 * n), ca.SX.sym("rate"),
                                     ca.SX.sym("acceleration"), ca.SX.sym("out", 2 * n))
                ydot = symbolic_beam_dynamics(linear, y, rate, acc)
                names, args = ["y", "rate", "acceleration", "out_ydot"], [y, rate, acc, out]
                outputs = [ca.jacobian(ydot, v) for v in (y, rate, acc)]
                out_names = ["jac_ydot_y", "jac_ydot_rate", "jac_ydot_acceleration"]
                prefix = "flexctl_exact_beam_newton"
            self._c[key] = ca.Function(f"jac_{prefix}_N{self.n_modes}", args, outputs, names,
                                       out_names)
        return self._c[key]

    def _exact_mass(self, x) -> list:
        q = np.atleast_2d(self.layout.modal(x).T).T
        masses = [np.array(self.geometry.mass(q[:, k])) for k in range(q.shape[1])]
        return [0.5 * (m + m.T) for m in masses]

    def mass_matrix(self, x) -> np.ndarray:
        """Mass matrix ``[[J(q), m_tf^T], [m_tf, M_ff]]`` at state ``x``, shape (N+1, N+1).

        For the exact variant, the configuration-dependent ``M(q)`` of
        :mod:`flexctl.model.exact`.

        Parameters
        ----------
        x : array_like, shape (n,)
            State in :attr:`layout` order (only its modal coordinates are read).

        Returns
        -------
        ndarray, shape (N+1, N+1)
            Rows and columns in the order ``theta, q_1 .. q_N``; kg m^2, kg m and kg.
        """
        x = self._check_state(x)
        if self.variant.exact:
            return self._exact_mass(x)[0]
        mat = self.matrices
        j = mat.J0
        if self.variant.quadratic_inertia:
            q = self.layout.modal(x)
            j = j + q @ mat.D @ q
        top = np.concatenate(([j], mat.m_tf))
        return np.vstack((top, np.column_stack((mat.m_tf, mat.M_ff))))

    def _forces(self, x, torque):
        """Generalised forces ``f_hub`` (scalar or (P,)) and ``f_beam`` ((N,) or (N, P))."""
        mat, c = self.matrices, self._c
        _, q, w, qd = self.split(x)
        f_beam = -(mat.C_ff @ qd) - mat.K_ff @ q + w ** 2 * (c["stiff_d"] @ q)
        f_hub = torque - self.system.hub.friction * w
        if self.variant.quadratic_inertia:
            f_hub = f_hub - 2.0 * w * np.einsum("i...,ij,j...->...", q, mat.D, qd)
        return f_hub, f_beam

    def accelerations(self, x, torque):
        """Hub and modal accelerations ``theta_tt`` (rad/s^2) and ``q_tt`` (m/s^2).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        torque : float or array_like, shape (P,)
            Hub torque, N m.

        Returns
        -------
        theta_tt : float or ndarray, shape (P,)
            Hub acceleration, rad/s^2.
        q_tt : ndarray, shape (N,) or (N, P)
            Modal accelerations, m/s^2.

        Raises
        ------
        SingularMassMatrixError
            If the effective hub inertia is not positive (consistent variant, light hub).
        """
        x = self._check_state(x)
        if self.variant.exact:
            u = np.broadcast_to(np.asarray(torque, dtype=float), x.shape[1:])
            xdot = self._evaluate(self.geometry.rhs, x.ndim > 1, x, u)
            return self.layout.hub_rate(xdot), self.layout.modal_rates(xdot)
        c = self._c
        f_hub, f_beam = self._forces(x, torque)
        j_eff = self.effective_hub_inertia(x)
        if np.any(j_eff <= 0.0):
            raise SingularMassMatrixError(
                f"mass matrix is singular: effective hub inertia {np.min(j_eff):.3g} kg m^2 <= 0")
        theta_tt = (f_hub - c["g"] @ f_beam) / j_eff
        q_tt = c["m_inv"] @ f_beam - np.multiply.outer(c["g"], theta_tt)
        return theta_tt, q_tt

    def dynamics(self, t, x, u) -> np.ndarray:
        """State derivative ``dx/dt`` (python-control argument order, ``params`` omitted).

        Parameters
        ----------
        t : float
            Time, s (the model is time-invariant).
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        u : float or array_like, shape (1,) or (P,)
            Hub torque, N m.

        Returns
        -------
        ndarray, same shape as ``x``
        """
        x = self._check_state(x)
        u = np.asarray(u, dtype=float)
        torque = u.reshape(()) if u.size == 1 and x.ndim == 1 else u
        theta_tt, q_tt = self.accelerations(x, torque)
        layout = self.layout
        return np.concatenate((x[layout.velocities], np.expand_dims(theta_tt, 0), q_tt), axis=0)

    @staticmethod
    def _evaluate(function, batch: bool, *args) -> np.ndarray:
        """A CasADi function at one point (arguments (k,) or scalars) or at P points
        (``batch``: arguments (k, P) or (P,)), as a float array of shape (m,) or (m, P)."""
        columns = [np.atleast_2d(np.asarray(a, dtype=float).T).T if function.size1_in(i) > 1
                   else np.atleast_2d(np.asarray(a, dtype=float).reshape(-1))
                   for i, a in enumerate(args)]
        out = np.array(function(*columns))
        return out if batch else out[:, 0]

    def beam_accelerations(self, q, q_dot, theta_dot, theta_tt):
        """Modal accelerations under prescribed hub motion, m/s^2, shape (N,) or (N, P).

        ``M_ff q_tt + C_ff q_t + (K_ff - theta_t^2 D) q = -m_tf theta_tt`` (for the exact
        variant, the beam rows of ``M(q)`` with its velocity terms).

        Parameters
        ----------
        q, q_dot : array_like, shape (N,) or (N, P)
            Modal coordinates (m) and rates (m/s).
        theta_dot : float or array_like, shape (P,)
            Hub rate ``theta_t``, rad/s.
        theta_tt : float or array_like, shape (P,)
            Hub acceleration, rad/s^2.
        """
        if self.variant.exact:
            return self._evaluate(self.geometry.beam, np.ndim(q) > 1, q, q_dot, theta_dot,
                                  theta_tt)
        mat, c = self.matrices, self._c
        f_beam = -(mat.C_ff @ q_dot) - mat.K_ff @ q + theta_dot ** 2 * (c["stiff_d"] @ q)
        return c["m_inv"] @ (f_beam - np.multiply.outer(mat.m_tf, theta_tt))

    def hub_torque(self, x, theta_tt, q_tt):
        """Torque that produces the given accelerations at state ``x`` (the hub equation), N m.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        theta_tt : float or array_like, shape (P,)
            Hub acceleration, rad/s^2.
        q_tt : array_like, shape (N,) or (N, P)
            Modal accelerations, m/s^2.
        """
        x = self._check_state(x)
        if self.variant.exact:
            out = self._evaluate(self.geometry.torque, x.ndim > 1, x, theta_tt, q_tt)
            return out[0]
        mat = self.matrices
        _, q, w, qd = self.split(x)
        j = mat.J0
        torque = j * theta_tt + mat.m_tf @ q_tt + self.system.hub.friction * w
        if self.variant.quadratic_inertia:
            qdq = np.einsum("i...,ij,j...->...", q, mat.D, q)
            torque = torque + qdq * theta_tt + 2.0 * w * np.einsum(
                "i...,ij,j...->...", q, mat.D, qd)
        return torque

    # ------------------------------------------------------------------ outputs and energy
    def _output_matrix(self) -> np.ndarray:
        mat, layout = self.matrices, self.layout
        reach = self.system.hub.radius + self.system.beam.length
        return np.vstack((layout.embed(1.0, "theta"), layout.embed(1.0, "theta_dot"),
                          layout.embed(mat.tip), layout.embed(mat.root),
                          layout.embed(1.0, "theta") + layout.embed(mat.tip / reach)))

    @property
    def output_matrix(self) -> np.ndarray:
        """``C`` such that ``y = C x`` for the outputs :attr:`output_names`, shape (5, n).

        Exact for every variant but exact, where it is the linearisation at ``q = 0``.
        """
        return self._c["c_out"]

    def tip_position(self, x) -> np.ndarray:
        """Tip position ``[p_x(l), p_y(l)]`` in the hub frame, m, shape (2,) or (2, P).

        Exact geometry for the exact variant; ``[b + l, phi(l)^T q]`` (no foreshortening) for
        the small-deflection variants.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        """
        x = self._check_state(x)
        q = self.layout.modal(x)
        if self.variant.exact:
            return self.geometry.tip_positions(q)
        tip_y = self.matrices.tip @ q
        return np.stack((np.full_like(tip_y, self.system.hub.radius
                                      + self.system.beam.length), tip_y))

    def tip_deflection(self, x) -> np.ndarray:
        """Lateral tip deflection in the hub frame, m, shape () or (P,).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        """
        if self.variant.exact:
            x = self._check_state(x)
            return self.geometry.tip_deflections(self.layout.modal(x))
        return self.tip_position(x)[1]

    def outputs(self, x) -> np.ndarray:
        """Outputs :attr:`output_names` at state(s) ``x``, shape (5,) or (5, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        """
        x = self._check_state(x)
        y = self.output_matrix @ x
        if self.variant.exact:
            tip = self.tip_position(x)
            y[2] = tip[1]
            y[4] = self.layout.hub_angle(x) + np.arctan2(tip[1], tip[0])
        return y

    def deflection(self, x, position: float) -> np.ndarray:
        """Beam deflection ``y(position)`` in the hub frame, m, at state(s) ``x``.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        position : float
            Distance from the beam root, m, in ``[0, l]``.
        """
        x = self._check_state(x)
        return self.matrices.deflection_vector(position) @ self.layout.modal(x)

    def energy(self, x) -> np.ndarray:
        """Mechanical energy, J.

        For the exact variant its own energy ``1/2 v^T M(q) v + 1/2 q^T K_ff q``; for the
        others that of the consistent model (MODEL.md section 4),
        ``E = 1/2 theta_t^2 (J_0 + q^T D q) + theta_t m_tf^T q_t + 1/2 q_t^T M_ff q_t
        + 1/2 q^T K_ff q``. Each is conserved by its variant when unforced and undamped.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.

        Returns
        -------
        float or ndarray, shape (P,)
            The energy at each state, J.
        """
        x = self._check_state(x)
        if self.variant.exact:
            out = self._evaluate(self.geometry.energy, x.ndim > 1, x)
            return out[0]
        mat = self.matrices
        _, q, w, qd = self.split(x)
        qf = lambda a, m, b: np.einsum("i...,ij,j...->...", a, m, b)  # noqa: E731
        return (0.5 * w ** 2 * (mat.J0 + qf(q, mat.D, q)) + w * (mat.m_tf @ qd)
                + 0.5 * qf(qd, mat.M_ff, qd) + 0.5 * qf(q, mat.K_ff, q))

    # ------------------------------------------------------------------ linear analysis
    def angular_momentum(self, x) -> np.ndarray:
        """Angular momentum about O, ``dT/dtheta_t``, kg m^2/s, shape () or (P,).

        Conserved by each variant when no torque acts and the hub has no friction: the first
        row of ``M(q)`` times the velocities for exact, ``J(q) theta_t + m_tf^T q_t`` for the
        others (``J(q) = J_0 + q^T D q`` for consistent, ``J_0`` otherwise).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State, or P states as columns, in :attr:`layout` order.
        """
        x = self._check_state(x)
        if self.variant.exact:
            mass = self._exact_mass(x)
            v = np.atleast_2d(x[self.layout.velocities].T).T
            h = np.array([m[0] @ v[:, k] for k, m in enumerate(mass)])
            return h if x.ndim > 1 else h[0]
        mat = self.matrices
        _, q, w, qd = self.split(x)
        inertia = mat.J0
        if self.variant.quadratic_inertia:
            inertia = inertia + np.einsum("i...,ij,j...->...", q, mat.D, q)
        return w * inertia + mat.m_tf @ qd

    def stiffness_matrix(self, spin_rate: float = 0.0) -> np.ndarray:
        """Beam stiffness at a steady spin, ``K_ff - spin_rate^2 D``, N/m, shape (N, N).

        The exact variant's linearisation has the stiffness of first_order.

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate ``Omega``, rad/s (at most ``1e100`` in magnitude). Default 0.
        """
        spin_rate = checked_spin(spin_rate)
        return self.matrices.K_ff - spin_rate ** 2 * self._c["stiff_d"]

    def second_order_form(self, spin_rate: float = 0.0):
        """``M``, ``K``, ``C`` and the torque's load vector ``f`` of the linearisation about a
        steady spin, ``M c_tt + C c_t + K c = f T_h`` in the generalized coordinates ``c``
        (the state's coordinate block, :attr:`StateLayout.coordinates`).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate ``Omega``, rad/s (at most ``1e100`` in magnitude). Default 0.

        Returns
        -------
        mass, stiffness, damping : ndarray, shape (n_c, n_c)
        load : ndarray, shape (n_c,)
        """
        spin_rate = checked_spin(spin_rate)
        layout = self.layout
        # the coordinate block keeps the state's order: layout.q and layout.theta index both
        n_c, q, hub = layout.n_coordinates, layout.q, layout.theta
        stiff, damp, load = np.zeros((n_c, n_c)), np.zeros((n_c, n_c)), np.zeros(n_c)
        stiff[q, q] = self.stiffness_matrix(spin_rate)
        damp[hub, hub] = self.system.hub.friction
        damp[q, q] = self.matrices.C_ff
        load[hub] = 1.0
        return self.mass_matrix(layout.zeros()), stiff, damp, load

    def linear_matrices(self, spin_rate: float = 0.0):
        """``A`` (n, n) and ``B`` (n, 1) of the linearisation about a steady spin (``q = 0``).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate ``Omega``, rad/s (at most ``1e100`` in magnitude). Default 0.
        """
        layout = self.layout
        mass, stiff, damp, load = self.second_order_form(spin_rate)
        n_c = layout.n_coordinates
        m_inv_k, m_inv_c, m_inv_b = np.split(np.linalg.solve(
            mass, np.column_stack((stiff, damp, load))), [n_c, 2 * n_c], axis=1)
        a = np.zeros((self.n_states, self.n_states))
        a[layout.coordinates, layout.velocities] = np.eye(n_c)
        a[layout.velocities, layout.coordinates] = -m_inv_k
        a[layout.velocities, layout.velocities] = -m_inv_c
        b = np.zeros((self.n_states, 1))
        b[layout.velocities] = m_inv_b
        return a, b

    def natural_frequencies(self, spin_rate: float = 0.0, hub: str = "clamped") -> np.ndarray:
        """Undamped natural frequencies at a steady spin, rad/s, ascending, shape (N,).

        Parameters
        ----------
        spin_rate : float
            Steady hub rate ``Omega``, rad/s.
        hub : {"clamped", "free"}
            ``"clamped"``: the hub held at constant rate (eigenvalues of
            ``(K_ff - Omega^2 D, M_ff)``). ``"free"``: the hub free to rotate; the rigid-body
            mode at 0 is left out.

        Returns
        -------
        ndarray, shape (N,)
            A mode that has lost its stiffness (zero_order above its first clamped frequency)
            is returned as a negative number whose magnitude is its exponential growth rate, 1/s.
        """
        spin_rate = checked_spin(spin_rate)
        if not isinstance(hub, str) or hub not in ("clamped", "free"):
            raise InputValueError(f"hub must be 'clamped' or 'free'; got {hub!r}")
        key = ("frequencies", hub, spin_rate)
        kept = self._c.setdefault("frequencies", {})
        if key in kept:
            # asked by every run (its stiffness and duration checks, a prescribed spin's
            # fastest mode): kept for the last few spins
            return kept[key].copy()
        stiff = self.stiffness_matrix(spin_rate)
        if hub == "clamped":
            lam = scipy.linalg.eigh(stiff, self.matrices.M_ff, eigvals_only=True)
        else:
            # The hub carries no stiffness: condensing its coordinate out of the mass matrix
            # leaves the flexible modes exactly, without the rigid-body zero to remove.
            mat = self.matrices
            reduced = mat.M_ff - np.outer(mat.m_tf, mat.m_tf) / mat.J0
            lam = scipy.linalg.eigh(stiff, reduced, eigvals_only=True)
        frequencies = np.sort(np.sign(lam) * np.sqrt(np.abs(lam)))
        if len(kept) >= KEPT_SPINS:
            kept.pop(next(iter(kept)))
        kept[key] = frequencies.copy()
        return frequencies

    def linearize(self, spin_rate: float = 0.0, *, x0=None, u0=None):
        """Linear plant about a steady spin, as a python-control ``StateSpace``.

        Parameters
        ----------
        spin_rate : float
            Steady hub rate ``Omega`` (rad/s) about which the model is linearised, ``q = 0``.
        x0, u0 : array_like, shape (n,), and float, optional
            Any operating point instead (a deflected, accelerating state):
            :func:`~flexctl.model.exports.linearize_at` (``u0`` default 0).

        Returns
        -------
        control.StateSpace
            States :attr:`state_names`, input ``torque``, outputs :attr:`output_names`. Its
            attribute ``modal_visibility`` (:class:`~flexctl.model.visibility.ModalVisibility`)
            says which modes the torque cannot move and which outputs cannot see them.
        """
        import control

        if x0 is not None or u0 is not None:
            return at_operating_point(self, spin_rate, x0, u0)
        a, b = self.linear_matrices(spin_rate)
        plant = control.ss(a, b, self.output_matrix, np.zeros((len(self.output_names), 1)),
                          states=signal_names(self.state_names), inputs=list(self.input_names),
                          outputs=signal_names(self.output_names),
                          name=system_name(f"{self.variant}_N{self.n_modes}_spin{spin_rate:g}"))
        # which modes the torque moves and each output sees, beside the plant
        plant.modal_visibility = self.modal_visibility(spin_rate)
        return plant

    def modal_visibility(self, spin_rate: float = 0.0):
        """Which modes of the linearisation at ``spin_rate`` the torque can move and each
        output can see (:func:`flexctl.model.visibility.modal_visibility`).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate ``Omega``, rad/s, of the linearisation. Default 0.
        """
        from .visibility import modal_visibility
        return modal_visibility(self, spin_rate)

    # ------------------------------------------------------------------ exports
    def nonlinear(self, outputs: str = "named", params=None):
        """Nonlinear plant as a python-control ``NonlinearIOSystem`` (:mod:`flexctl.model.exports`).

        Parameters
        ----------
        outputs : {"named", "states"}, optional
            Its outputs: the model's named outputs (``"named"``, default), or its states
            (``"states"``, for a state-feedback law's :func:`controllers.feedback.iosys.to_iosys`
            to connect to by name).
        params : list of str or dict, optional
            Physical parameters (scene keys, or a dict of their values) made python-control
            ``params`` (:func:`~flexctl.model.exports.to_nonlinear_iosystem`). Default none.
        """
        from .exports import to_nonlinear_iosystem
        return to_nonlinear_iosystem(self, outputs, params)

    def casadi_outputs(self):
        """The outputs as a CasADi ``Function`` ``(x, u) -> y`` (inputs ``x`` (n x 1) and ``u``
        (1 x 1), output ``y`` in :attr:`output_names` order; ``u`` is not read: no output feeds
        through), beside :meth:`casadi`."""
        import casadi as ca

        from .exports import to_casadi_outputs

        if "casadi_outputs" not in self._c:
            h = to_casadi_outputs(self)
            x, u = ca.SX.sym("x", self.n_states), ca.SX.sym("u")
            self._c["casadi_outputs"] = ca.Function(
                f"flexctl_{self.variant}_outputs", [x, u], [h(x)], ["x", "u"], ["y"])
        return self._c["casadi_outputs"]

    def _rebuilt(self, system) -> "Model":
        """This model (modes, variant) of another ``system`` of the same kind."""
        return Model(system=system, n_modes=self.n_modes, variant=self.variant,
                     matrices=assemble(system, self.n_modes))

    def parameter_values(self, parameters) -> np.ndarray:
        """Nominal values of the listed physical parameters, shape (P,).

        Parameters
        ----------
        parameters : list of str
            P scene keys of physical parameters (``"beam.youngs_modulus"``,
            ``"hub.inertia"``, ``"masses[0].mass"``, ...); each value in the key's unit.
        """
        from .parametric import parameter_values
        return parameter_values(self, parameters)

    def discretize(self, dt, method: str = "rk4", substeps=None, rtol: float = 1e-8,
                   parameters=None):
        """The model over one sample of ``dt`` s with the input held: a
        :class:`~flexctl.model.discrete.DiscreteStep` around the CasADi Function
        ``(x, u[, p]) -> x_next``, by RK4 substeps or CVODES, with its stated accuracy (see
        :func:`flexctl.model.discrete.discretize`).

        Parameters
        ----------
        dt : float
            Sample time, s (> 0).
        method : {"rk4", "cvodes"}, optional
            RK4 substeps (default) or SUNDIALS CVODES.
        substeps : int, optional
            RK4 steps per sample (1 to 1000); default the fewest with ``omega_max h <= 0.5``.
        rtol : float, optional
            CVODES relative tolerance (1e-14 to 1e-2). Default 1e-8.
        parameters : list of str, optional
            Physical parameters (scene keys) as a third input ``p``: ``(x, u, p) -> x_next``.
        """
        from .discrete import discretize
        return discretize(self, dt, method, substeps, rtol, parameters)

    def casadi(self, parameters=None):
        """Dynamics as a CasADi ``Function`` ``(x, u) -> dx/dt`` (see :mod:`flexctl.model.exports`),
        or ``(x, u, p) -> dx/dt`` with the listed physical ``parameters`` (scene keys such as
        ``"beam.youngs_modulus"``, ``"hub.inertia"``, ``"masses[0].mass"``) as ``p``, in that
        order: exact at their nominal values (:meth:`parameter_values`), differentiable in
        ``p`` (:mod:`flexctl.model.parametric`).

        Built once per model (and parameter list) and cached.

        Parameters
        ----------
        parameters : list of str, optional
            Scene keys of the physical parameters that make the input ``p``, in its order.
            Default None: the function ``(x, u) -> dx/dt`` of the nominal model.
        """
        if parameters is not None:
            from .parametric import parameter_values, parametric_casadi
            parameter_values(self, parameters)          # named as they must be
            key = ("casadi", tuple(parameters))
            if key not in self._c:
                self._c[key] = parametric_casadi(self, parameters)
            return self._c[key]
        if "casadi" not in self._c:
            from .exports import to_casadi
            self._c["casadi"] = to_casadi(self)
        return self._c["casadi"]


def at_operating_point(model, spin_rate, x0, u0):
    """:func:`~flexctl.model.exports.linearize_at`, the operating point given once.

    Parameters
    ----------
    model : Model
        Any flexctl model.
    spin_rate : float
        Must be 0: the operating point replaces the steady spin.
    x0 : array_like, shape (n,), or None
        State; None for the zero state (at rest, hub angle 0).
    u0 : float or None
        Input: the hub torque, N m (an actuated model's command); None for 0.

    Raises
    ------
    InputValueError
        If ``spin_rate`` is not 0.
    """
    from .exports import linearize_at

    if spin_rate:
        raise InputValueError(f"linearize takes spin_rate or an operating point x0, not both; "
                              f"got spin_rate = {spin_rate!r}")
    return linearize_at(model, model.layout.zeros() if x0 is None else x0,
                        0.0 if u0 is None else u0)


def system_name(text: str) -> str:
    """A python-control system name (no dots allowed): ``1.5`` -> ``1p5``, ``-2`` -> ``m2``.

    Parameters
    ----------
    text : str
        The name wanted, with any dots and minus signs.
    """
    return text.replace(".", "p").replace("-", "m")


def checked_spin(spin_rate) -> float:
    """A steady spin rate as a float, refused when it is not a real number of at most
    :data:`MAX_SPIN_RATE` in magnitude.

    Parameters
    ----------
    spin_rate : float
        Steady hub rate, rad/s.

    Raises
    ------
    InputTypeError
        If ``spin_rate`` is not a real number.
    InputValueError
        If ``spin_rate`` is not finite or larger than :data:`MAX_SPIN_RATE` in magnitude.
    """
    spin_rate = check_real("", "spin_rate", spin_rate)
    if abs(spin_rate) > MAX_SPIN_RATE:
        # spin_rate^2 times the modal matrices overflowed (OverflowError at 1e300 rad/s)
        raise InputValueError(f"spin_rate must be finite and at most {MAX_SPIN_RATE:g} rad/s in "
                              f"magnitude (its square scales the stiffness); got {spin_rate!r}")
    return spin_rate

