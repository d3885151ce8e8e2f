"""The model of a planar structure: one variant (first_order, zero_order, consistent, exact)
on cantilever modes, for one beam or several appendages on a pinned or free hub.

One :class:`Model` serves every structure: a :class:`~flexctl.model.parameters.HubBeam` is
the one-appendage :class:`~flexctl.model.structure.Structure`. Its equations are one set of
CasADi functions (:mod:`flexctl.model.structure_dynamics`), to which each variant
(:class:`~flexctl.model.variant.Variant`) contributes its terms (:ref:`sections 4 <variants>`
and :ref:`4.5 <sec-exact>` of the model): the spin softens the beam by ``D = M_ff - K_g`` with
dynamic stiffening and by ``M_ff`` without (zero_order), consistent adds ``q^T D q`` to the hub
inertia, and exact is geometrically exact (:mod:`flexctl.model.exact`: the modes describe the
slope angle of an inextensible beam, the mass matrix ``M(q)`` depends on the deflection). The
numpy methods evaluate those functions at one state or at a batch of states; the exports
(:mod:`flexctl.model.exports`) and the simulation's compiled paths are derived from them.

Notes
-----
States (:class:`~flexctl.model.layout.StateLayout`)::

    x = [theta, (hub_x, hub_y), <a>.q1 .. <b>.qN, theta_dot, (hub_x_dot, hub_y_dot),
         <a>.q1_dot .. <b>.qN_dot]

``theta`` in rad, ``q_i`` in m (tip-normalised cantilever modes, ``phi_i(l) = +-2``), rates in
rad/s and m/s; ``hub_x, hub_y`` (m, inertial axes) for a free hub only. Input ``torque``
(N m). Outputs::

    y = [theta, theta_dot, (hub_x, hub_y),
         <a>.tip_deflection, <a>.root_moment, <a>.tip_angle, <b>.tip_deflection, ...]

Each tip deflection is the tip's transverse position in its appendage's own frame (m, positive
counter-clockwise), each tip angle the hub angle plus the tip's angle from the appendage's
mounting direction seen from the hub centre (rad): ``theta + atan2(p_y(l), p_x(l))`` for the
exact variant, its linearisation for the others. An appendage with the empty name (a
``HubBeam``) has unprefixed names: ``x = [theta, q_1 .. q_N, theta_dot, q_1_dot ..
q_N_dot]``, ``y = [theta, theta_dot, tip_deflection, root_moment, tip_angle]``.
"""

from __future__ import annotations

import dataclasses

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import scipy.linalg

from .checks import check_real
from .errors import InputValueError, SingularMassMatrixError
from .exact import EXACT_MAX_MODES
from .exports import signal_names
from .layout import StateLayout
from .parameters import HubBeam
from .structure_dynamics import output_function, structure_functions
from .variant import VARIANTS, Variant

__all__ = ["Model", "VARIANTS", "SingularMassMatrixError", "EXACT_MAX_MODES", "output_names",
           "structure_model"]

#: Largest steady spin rate the linear analysis takes, rad/s: its square multiplies the modal
#: matrices, and must stay far from overflow.
MAX_SPIN_RATE = 1e100
#: Spin rates whose natural frequencies a model keeps (the last ones asked for).
KEPT_SPINS = 16


def output_names(structure) -> tuple:
    """The outputs of a structure model, in order (see the module Notes).

    Parameters
    ----------
    structure : Structure
        The hub and its appendages: a free hub adds ``hub_x, hub_y``, each appendage its
        three outputs prefixed by its name.
    """
    names = ["theta", "theta_dot"] + (["hub_x", "hub_y"] if structure.free else [])
    for name in structure.names:
        prefix = f"{name}." if name else ""
        names += [f"{prefix}tip_deflection", f"{prefix}root_moment", f"{prefix}tip_angle"]
    return tuple(names)


@dataclass(frozen=True, eq=False)
class Model:
    """A model of one variant of a structure on its cantilever modes (see the module Notes).

    Build with :func:`flexctl.build_model`.

    Attributes
    ----------
    system : HubBeam or Structure
        The system as given (:attr:`structure` is it as a Structure).
    n_modes : int
        Modes of all the appendages together, ``N``.
    variant : Variant
        ``"first_order"``, ``"zero_order"``, ``"consistent"`` or ``"exact"``, a ``str``
        whose properties are the terms it contributes (:class:`~flexctl.model.variant.Variant`).
    matrices : StructureMatrices
        The structure's modal matrices at rest (:mod:`flexctl.model.structure_matrices`).
    layout : StateLayout
        Names and slices of the state's blocks (:mod:`flexctl.model.layout`).
    state_names, input_names, output_names : tuple of str
    """

    system: object
    n_modes: int
    variant: str
    matrices: object = field(repr=False)
    layout: StateLayout = field(init=False, repr=False)
    state_names: tuple = field(init=False, repr=False)
    input_names: tuple = field(init=False, repr=False, default=("torque",))
    output_names: tuple = field(init=False, repr=False, default=())
    #: Whether a small-deflection model on a pinned hub is its matrix form
    #: (:attr:`matrix_form`); an actuator's equations are not.
    HAS_MATRIX_FORM: ClassVar[bool] = True

    def __post_init__(self):
        object.__setattr__(self, "variant", Variant(self.variant))
        mat = self.matrices
        layout = StateLayout(appendages=tuple(zip(mat.system.names, mat.modes)),
                             free_hub=mat.system.free)
        object.__setattr__(self, "layout", layout)
        object.__setattr__(self, "state_names", layout.names)
        object.__setattr__(self, "output_names", output_names(mat.system))
        stiff_d = self.variant.spin_matrix(mat)
        object.__setattr__(self, "_c", {"stiff_d": stiff_d, "j_rigid_eff": mat.condensed_inertia})

    # ------------------------------------------------------------------ basics
    @property
    def modes(self) -> tuple:
        """Modes of each appendage."""
        return self.matrices.modes

    def _rebuilt(self, system) -> "Model":
        """This model (modes, variant) of another ``system`` of the same kind."""
        return structure_model(system, self.mode_spec, self.variant)

    @property
    def mode_spec(self):
        """The ``n_modes`` that :func:`flexctl.build_model` takes to rebuild this model's
        modes: an int for a HubBeam, the tuple of each appendage's modes for a structure."""
        return self.n_modes if isinstance(self.system, HubBeam) else self.modes

    @property
    def structure(self):
        """The system as a :class:`~flexctl.model.structure.Structure` (one unnamed
        appendage for a ``HubBeam``)."""
        return self.matrices.system

    def __repr__(self):
        hub = "free" if self.structure.free else "pinned"
        names = self.structure.names
        modes = f"n_modes={self.n_modes}" if names == ("",) else \
            f"modes={dict(zip(names, self.modes))}"
        return (f"Model(variant={self.variant!r}, {modes}, {hub} hub, "
                f"J0={self.matrices.J0:.6g} kg m^2)")

    @property
    def matrix_form(self) -> bool:
        """Whether the equations are products with the constant modal matrices (a pinned hub,
        a small-deflection variant, no actuator): the form the integrators take for many
        modes (:data:`flexctl.model.exports.MATRIX_FORM_MODES`)."""
        return self.HAS_MATRIX_FORM and not self.variant.exact and not self.structure.free

    def matrix_terms(self) -> dict:
        """The numbers of the :attr:`matrix_form`: ``M_ff^-1`` (``"m_inv"``), ``g = M_ff^-1
        m_tf`` (``"g"``), the spin term ``D`` (``"stiff_d"``) and the condensed hub inertia
        (``"j_rigid_eff"``), computed once and kept."""
        if "m_inv" not in self._c:
            mat = self.matrices
            m_inv = scipy.linalg.cho_solve(scipy.linalg.cho_factor(mat.M_ff),
                                           np.eye(mat.n_modes))
            m_inv = 0.5 * (m_inv + m_inv.T)
            self._c.update(m_inv=m_inv, g=m_inv @ mat.m_tf)
        return self._c

    @property
    def functions(self):
        """The CasADi functions (:class:`~flexctl.model.structure_dynamics.StructureFunctions`)."""
        if "functions" not in self._c:
            self._c["functions"] = structure_functions(self)
        return self._c["functions"]

    def vectorized_rhs(self):
        """The exact right-hand side ``(x, u) -> xdot`` as an MX function of whole-vector
        operations (:func:`flexctl.model.exact.vectorized_rhs`: a few thousand times fewer
        operations written out than :attr:`functions` ``.rhs``, so that code inlining it
        compiles in seconds) for the exact model of one appendage on a pinned hub; None for
        any other model. Built once and kept."""
        structure = self.structure
        if (not self.variant.exact or structure.free or len(structure.appendages) != 1
                or not self.HAS_MATRIX_FORM):
            return None
        if "vectorized_rhs" not in self._c:
            from .exact import vectorized_rhs

            app = structure.appendages[0]
            hub = dataclasses.replace(structure.hub, radius=structure.root_radius(app))
            system = HubBeam(hub=hub, beam=app.beam, masses=app.masses)
            self._c["vectorized_rhs"] = vectorized_rhs(system, self.n_modes,
                                                       self.functions.rules[0],
                                                       self.matrices.parts[0])
        return self._c["vectorized_rhs"]

    @property
    def geometry(self):
        """The CasADi functions for every variant (the same as :attr:`functions`)."""
        return self.functions

    def _batch(self, function, x, *args):
        x = self._check_state(x)
        return self._evaluate(function, x.ndim > 1, x, *args)

    def _pinned_only(self, what: str):
        if self.structure.free:
            raise InputValueError(
                f"{what} needs a pinned hub: a free hub's translation follows from the forces "
                "on it, and a prescribed hub rotation leaves it undetermined here; drive the "
                "free hub by its torque instead")

    @property
    def mode_lengths(self) -> np.ndarray:
        """Beam length of the appendage each modal coordinate belongs to, m, shape (N,)."""
        return np.concatenate([np.full(n, length) for n, length in zip(self.modes, self.lengths)])

    @property
    def mode_tips(self) -> np.ndarray:
        """Tip deflection of its own appendage per unit of each modal coordinate, shape (N,)."""
        return np.sum(self.tip_matrix, axis=0)

    @property
    def lengths(self) -> np.ndarray:
        """Beam length of each appendage, m, shape (K,)."""
        return np.array([a.beam.length for a in self.structure.appendages])

    @property
    def n_states(self) -> int:
        """Number of states ``2 N + 2``."""
        return self.layout.n_states

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
    def dynamics(self, t, x, u) -> np.ndarray:
        """State derivative ``dx/dt`` at state(s) ``x`` under input ``u`` (python-control
        argument order, ``params`` omitted).

        Parameters
        ----------
        t : float
            Time, s (the model is time-invariant).
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        u : float or array_like, shape (1,) or (P,)
            Hub torque, N m (an :class:`~flexctl.model.actuated.ActuatedModel`'s command, in its
            unit).

        Returns
        -------
        ndarray, same shape as ``x``
        """
        x = self._check_state(x)
        u = np.asarray(u, dtype=float)
        torque = u.reshape(()) if u.size == 1 and x.ndim == 1 else u
        if self.matrix_form:
            theta_tt, q_tt = self._matrix_accelerations(x, torque)
            return np.concatenate((x[self.layout.velocities],
                                   np.asarray(theta_tt)[np.newaxis], q_tt), axis=0)
        torque = np.broadcast_to(torque, x.shape[1:])
        xdot = self._evaluate(self.functions.rhs, x.ndim > 1, x, torque)
        finite = np.all(np.isfinite(xdot))
        if (not finite or self.variant.quadratic_inertia) and np.all(np.isfinite(x)):
            # the consistent variant's J_0 + q^T D q - m_tf^T M_ff^-1 m_tf can reach zero
            inertia = np.min(self.effective_hub_inertia(x))
            if not finite or inertia <= 0.0:
                raise SingularMassMatrixError(
                    "mass matrix is singular at this state: the effective hub inertia "
                    f"{inertia:.3g} kg m^2 is not positive")
        return xdot

    def _matrix_accelerations(self, x, torque):
        """:meth:`accelerations` of a :attr:`matrix_form` model, in numpy (a SciPy run calls
        it at every step: a CasADi call costs more than the arithmetic)."""
        mat, c = self.matrices, self.matrix_terms()
        _, q, w, qd = self.layout.split(x)
        f_beam = -(mat.C_ff @ qd) - mat.K_ff @ q + w ** 2 * (c["stiff_d"] @ q)
        f_hub = torque - self.structure.hub.friction * w
        if self.variant.quadratic_inertia:
            f_hub = f_hub - 2.0 * w * np.einsum("i...,ij,j...->...", q, mat.D, qd)
            j_eff = self.effective_hub_inertia(x)
            singular = np.any(j_eff <= 0.0)
        else:
            j_eff = c["j_rigid_eff"]           # constant without the quadratic inertia
            singular = not j_eff > 0.0
        if singular:
            raise SingularMassMatrixError(
                "mass matrix is singular at this state: the effective hub inertia "
                f"{np.min(j_eff):.3g} kg m^2 is not positive")
        theta_tt = (f_hub - c["g"] @ f_beam) / j_eff
        return theta_tt, c["m_inv"] @ f_beam - np.multiply.outer(c["g"], theta_tt)

    def accelerations(self, x, torque):
        """Hub and modal accelerations ``theta_tt`` (rad/s^2) and ``q_tt`` (m/s^2).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        torque : float or array_like, shape (P,)
            Hub torque, N m (an :class:`~flexctl.model.actuated.ActuatedModel`'s command, in its
            unit).
        """
        xdot = self.dynamics(0.0, x, torque)
        return self.layout.hub_rate(xdot), self.layout.modal_rates(xdot)

    def mass_matrix(self, x) -> np.ndarray:
        """Mass matrix in the accelerations ``(theta_tt, [a], q_tt)`` at state ``x``.

        ``a`` is a free hub's acceleration ``(hub_x_tt, hub_y_tt)``, absent on a pinned hub.

        Parameters
        ----------
        x : array_like, shape (n,)
            State in :attr:`layout` order.
        """
        x = self._check_state(x)
        return np.array(self.functions.mass(x))

    def rest_state(self, theta: float = 0.0) -> np.ndarray:
        """The undeformed structure at rest at hub angle ``theta`` (rad), shape (n,): a free
        hub's centre at ``(S_0 - R(theta) S_0) / m``, so that the centre of mass stays where
        it is at ``theta = 0`` with the hub centre at the origin.

        Parameters
        ----------
        theta : float, optional
            Hub angle, rad. Default 0.
        """
        theta = float(theta)
        if not self.structure.free:
            return self.layout.join(theta=theta)
        mat = self.matrices
        c, s = np.cos(theta), np.sin(theta)
        turned = np.array([c * mat.first[0] - s * mat.first[1],
                           s * mat.first[0] + c * mat.first[1]])
        return self.layout.join(theta=theta, hub_position=(mat.first - turned) / mat.mass)

    def rest_mass_matrix(self) -> np.ndarray:
        """Mass matrix at rest from the modal matrices (every variant linearises to it),
        in the accelerations ``(theta_tt, [a], q_tt)``."""
        mat = self.matrices
        top = [np.concatenate(([mat.J0], mat.m_tf))]
        if not self.structure.free:
            return np.vstack(top + [np.column_stack((mat.m_tf, mat.M_ff))])
        e_s = np.array([-mat.first[1], mat.first[0]])
        return np.block([[np.array([[mat.J0]]), e_s[None, :], mat.m_tf[None, :]],
                         [e_s[:, None], mat.mass * np.eye(2), mat.first_q],
                         [mat.m_tf[:, None], mat.first_q.T, mat.M_ff]])

    def effective_hub_inertia(self, x) -> np.ndarray:
        """Schur complement of the hub rotation in the mass matrix, kg m^2, shape () or (P,).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        x = self._check_state(x)
        if not self.variant.exact and not self.structure.free:
            # J_0 - m_tf^T M_ff^-1 m_tf condensed without the cancelling subtraction (a heavy
            # tip mass made it 30 times too large), plus consistent's q^T D q
            j = self._c["j_rigid_eff"]
            if self.variant.quadratic_inertia:
                q = self.layout.modal(x)
                return j + np.einsum("i...,ij,j...->...", q, self.matrices.D, q)
            return np.full(x.shape[1:], j) if x.ndim > 1 else np.float64(j)
        columns = np.atleast_2d(x.T).T
        out = []
        for k in range(columns.shape[1]):
            m = np.array(self.functions.mass(columns[:, k]))
            m = 0.5 * (m + m.T)
            out.append(m[0, 0] - m[0, 1:] @ np.linalg.solve(m[1:, 1:], m[1:, 0]))
        return np.array(out) if x.ndim > 1 else np.float64(out[0])

    def beam_accelerations(self, q, q_dot, theta_dot, theta_tt):
        """Modal accelerations under a prescribed hub rotation (pinned hub), m/s^2.

        Parameters
        ----------
        q, q_dot : array_like, shape (N,) or (N, P)
            Modal coordinates (m) and rates (m/s) of every appendage.
        theta_dot : float or array_like, shape (P,)
            Hub rate, rad/s.
        theta_tt : float or array_like, shape (P,)
            Hub acceleration, rad/s^2.
        """
        self._pinned_only("a prescribed hub motion")
        if not self.matrix_form:
            return self._evaluate(self.functions.beam, np.ndim(q) > 1, q, q_dot, theta_dot,
                                  theta_tt)
        # M_ff q_tt + C_ff q_t + (K_ff - theta_t^2 D) q = -m_tf theta_tt, in numpy
        mat, c = self.matrices, self.matrix_terms()
        q, q_dot = np.asarray(q, dtype=float), np.asarray(q_dot, dtype=float)
        f_beam = -(mat.C_ff @ q_dot) - mat.K_ff @ q + np.asarray(theta_dot) ** 2 * (
            c["stiff_d"] @ q)
        return c["m_inv"] @ (f_beam - np.multiply.outer(mat.m_tf, theta_tt))

    def hub_torque(self, x, theta_tt, q_tt):
        """Torque that produces the given accelerations at state ``x`` (pinned hub), N m.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        theta_tt : float or array_like, shape (P,)
            Hub acceleration, rad/s^2.
        q_tt : array_like, shape (N,) or (N, P)
            Modal accelerations, m/s^2.
        """
        self._pinned_only("the hub torque of a prescribed motion")
        if not self.matrix_form:
            return self._batch(self.functions.torque, x, theta_tt, q_tt)[0]
        mat = self.matrices
        _, q, w, qd = self.split(self._check_state(x))
        torque = mat.J0 * theta_tt + mat.m_tf @ q_tt + self.structure.hub.friction * w
        if self.variant.quadratic_inertia:
            qf = lambda a, b: np.einsum("i...,ij,j...->...", a, mat.D, b)  # noqa: E731
            torque = torque + qf(q, q) * theta_tt + 2.0 * w * qf(q, qd)
        return torque

    def integration_rhs(self, evaluate=None):
        """The dynamics for implicit integrators (:meth:`Model.integration_rhs`): the same as
        :meth:`casadi`, or ``evaluate(x, u)`` (MX in, MX out; e.g. a call of a compiled
        :meth:`casadi`) with the first_order structure's Jacobian for Newton's method.

        Parameters
        ----------
        evaluate : callable, optional
            ``evaluate(x, u) -> xdot`` on CasADi MX symbols (``x`` (n x 1), ``u`` (1 x 1)),
            used by the exact variant only. Default None: :meth:`casadi`.
        """
        if evaluate is None or not self.variant.exact:
            return self.casadi()
        import casadi as ca

        xm, um = ca.MX.sym("x", self.n_states), ca.MX.sym("u")
        return ca.Function(f"flexctl_exact_newton_N{self.n_modes}", [xm, um],
                           [evaluate(xm, um)], ["x", "u"], ["xdot"],
                           {"custom_jacobian": self.newton_jacobian("rhs"), "jac_penalty": 0})

    def integration_beam(self, evaluate=None):
        """The beam under a prescribed hub motion as a CasADi ``Function``
        ``(y, rate, acceleration) -> dy/dt`` for implicit integrators, ``y = [q, q_dot]``.

        For the exact variant, as :meth:`integration_rhs`: the exact beam
        (:attr:`~flexctl.model.structure_dynamics.StructureFunctions.beam`, or
        ``evaluate(q, q_dot, rate, acceleration)`` returning ``q_tt``) with first_order's
        Jacobian for Newton's method.

        Parameters
        ----------
        evaluate : callable, optional
            ``evaluate(q, q_dot, rate, acceleration) -> q_tt`` on CasADi MX symbols (``q``,
            ``q_dot`` (N x 1), m and m/s; hub rate rad/s, hub acceleration rad/s^2), used as
            the exact variant's beam. Default: :attr:`functions` ``.beam``. Not read by the
            other variants.
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

    @staticmethod
    def _evaluate(function, batch: bool, *args) -> np.ndarray:
        """A CasADi function at one point (arguments (k,) or scalars) or at P points
        (``batch``: arguments (k, P) or (P,)), as a float array of shape (m,) or (m, P)."""
        columns = [np.atleast_2d(np.asarray(a, dtype=float).T).T if function.size1_in(i) > 1
                   else np.atleast_2d(np.asarray(a, dtype=float).reshape(-1))
                   for i, a in enumerate(args)]
        out = np.array(function(*columns))
        return out if batch else out[:, 0]

    # ------------------------------------------------------------------ outputs
    @property
    def output_matrix(self) -> np.ndarray:
        """``C``, the outputs' linearisation at rest, shape (n_outputs, n): the outputs
        themselves where they are linear in the state (every variant but exact)."""
        if "c_out" not in self._c:
            import casadi as ca
            x = ca.SX.sym("x", self.n_states)
            built = self._c.get("functions")
            # a small-deflection model's outputs alone: the whole set of functions costs
            # seconds for many modes
            if built is not None:
                outputs = built.outputs
            elif self.variant.exact:
                outputs = self.functions.outputs
            else:
                outputs = output_function(self)
            jacobian = ca.jacobian(outputs(x), x)
            c = np.array(ca.Function("c", [x], [jacobian])(np.zeros(self.n_states)))
            c.setflags(write=False)
            self._c["c_out"] = c
            self._c["linear_outputs"] = not ca.depends_on(jacobian, x)
        return self._c["c_out"]

    def outputs(self, x) -> np.ndarray:
        """Outputs (:attr:`output_names`) at state(s) ``x``; shape (n_out,) or (n_out, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        x = self._check_state(x)
        y = self.output_matrix @ x
        if self._c["linear_outputs"]:
            return y
        # the exact tips in numpy (a run's output times: no CasADi call per column)
        theta = self.layout.hub_angle(x)
        for name, tip in zip(self.structure.names, self._exact_tips(x)):
            prefix = f"{name}." if name else ""
            y[self.output_names.index(f"{prefix}tip_deflection")] = tip[1]
            y[self.output_names.index(f"{prefix}tip_angle")] = theta + np.arctan2(tip[1], tip[0])
        return y

    def _exact_tips(self, x) -> list:
        """Each appendage's exact tip ``[b + int_0^l cos psi, int_0^l sin psi]`` (m, shape (2,)
        or (2, P)) on its own quadrature, as :attr:`functions` computes it."""
        if "tip_rules" not in self._c:
            from .exact import PanelRule

            rules = []
            for app, rule in zip(self.structure.appendages, self.functions.rules):
                panels = PanelRule.build(rule.panels, app.beam.length, rule.points)
                part = len(rules)
                slopes = np.array(panels.slopes(self.modes[part]))
                rules.append((self.structure.root_radius(app), slopes, panels.weights))
            self._c["tip_rules"] = rules
        q = self.layout.modal(x)
        tips = []
        for k, (radius, slopes, weights) in enumerate(self._c["tip_rules"]):
            psi = slopes @ q[self.matrices.slices[k]]
            tips.append(np.stack((radius + weights @ np.cos(psi), weights @ np.sin(psi))))
        return tips

    def output(self, x, name: str) -> np.ndarray:
        """One named output at state(s) ``x``.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        name : str
            One of :attr:`output_names`.
        """
        if name not in self.output_names:
            raise InputValueError(f"output must be one of {', '.join(self.output_names)}; "
                                  f"got {name!r}")
        return self.outputs(x)[self.output_names.index(name)]

    @property
    def tip_matrix(self) -> np.ndarray:
        """Linear tip deflection of each appendage per modal coordinate, shape (K, N)."""
        return self.matrices.tip

    @property
    def rigid_inertia(self) -> float:
        """Inertia of the undeformed structure about the axis it turns on, kg m^2 (``J_0``
        pinned, ``J_0 - |S_0|^2 / m`` free)."""
        mat = self.matrices
        if not self.structure.free:
            return float(mat.J0)
        return float(mat.J0 - mat.first @ mat.first / mat.mass)

    def quasi_static_gain(self) -> np.ndarray:
        """``q = -g theta_tt`` at rest under a slow hub acceleration, m per rad/s^2, (N,)."""
        mass = self.rest_mass_matrix()
        n_h = mass.shape[0] - self.matrices.n_modes
        coupling = mass[n_h:, 0]
        if self.structure.free:
            coupling = coupling - mass[n_h:, 1:n_h] @ np.linalg.solve(mass[1:n_h, 1:n_h],
                                                                      mass[1:n_h, 0])
        return np.linalg.solve(self.matrices.K_ff, coupling)

    def tip_deflections(self, x) -> np.ndarray:
        """Each appendage's tip deflection in its own frame, m, shape (K,) or (K, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        y = self.outputs(x)
        rows = [self.output_names.index(n) for n in self.output_names
                if n.endswith("tip_deflection")]
        return y[rows]

    def tip_deflection(self, x) -> np.ndarray:
        """The tip deflection of largest magnitude over the appendages, m (signed), shape ()
        or (P,).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        tips = np.atleast_1d(self.tip_deflections(x))
        pick = np.argmax(np.abs(tips), axis=0)
        return np.take_along_axis(tips, np.expand_dims(pick, 0), 0)[0]

    def _appendage(self, appendage) -> int:
        """The index of ``appendage`` (a name; None for the only one)."""
        names = self.structure.names
        if appendage is None and len(names) == 1:
            return 0
        if not isinstance(appendage, str) or appendage not in names:
            raise InputValueError(f"appendage must be one of {list(names)} (None for a "
                                  f"single appendage); got {appendage!r}")
        return names.index(appendage)

    def tip_position(self, x, appendage=None) -> np.ndarray:
        """Tip position ``[p_x(l), p_y(l)]`` of an appendage in its own frame (from the hub
        centre along its mounting direction), m, shape (2,) or (2, P).

        Exact geometry for the exact variant; ``[b + l, phi(l)^T q]`` (no foreshortening) for
        the small-deflection variants.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        appendage : str, optional
            Its name; default the only appendage.
        """
        k = self._appendage(appendage)
        x = self._check_state(x)
        if self.variant.exact:
            return self._exact_tips(x)[k]
        reach = self.structure.root_radius(self.structure.appendages[k]) \
            + self.structure.appendages[k].beam.length
        tip = self.matrices.tip[k] @ self.layout.modal(x)
        return np.stack((np.full_like(tip, reach), tip))

    def deflection(self, x, position: float, appendage=None) -> np.ndarray:
        """Linear deflection ``phi(position)^T q`` of an appendage, m, shape () or (P,).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        position : float
            Distance from the beam root, m, in ``[0, l]``.
        appendage : str, optional
            Its name; default the only appendage.
        """
        k = self._appendage(appendage)
        x = self._check_state(x)
        position = check_real("deflection", "position", position)
        part = self.matrices.parts[k]
        return part.deflection_vector(position) @ self.layout.modal(x)[self.matrices.slices[k]]

    # ------------------------------------------------------------------ balances
    def energy(self, x) -> np.ndarray:
        """Mechanical energy, J, shape () or (P,) (the consistent energy for the
        small-deflection variants).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        if not self.matrix_form:
            return self._batch(self.functions.energy, x)[0]
        mat = self.matrices
        _, q, w, qd = self.split(self._check_state(x))
        qf = lambda a, m, b: np.einsum("i...,i...->...", a, m @ b)  # noqa: E731
        return (0.5 * w ** 2 * (mat.J0 + qf(q, mat.D, q)) + w * (mat.m_tf @ qd)
                + 0.5 * qf(qd, mat.M_ff, qd) + 0.5 * qf(q, mat.K_ff, q))

    def angular_momentum(self, x) -> np.ndarray:
        """Angular momentum about the inertial origin, kg m^2/s, shape () or (P,).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        if not self.matrix_form:
            return self._batch(self.functions.momentum, x)[0]
        mat = self.matrices
        _, q, w, qd = self.split(self._check_state(x))
        inertia = mat.J0
        if self.variant.quadratic_inertia:
            inertia = inertia + np.einsum("i...,ij,j...->...", q, mat.D, q)
        return w * inertia + mat.m_tf @ qd

    def linear_momentum(self, x) -> np.ndarray:
        """Linear momentum of the whole structure (free hub; zero on a pinned one, whose pin
        carries it), kg m/s, shape (2,) or (2, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        return self._batch(self.functions.momentum, x)[1:]

    def center_of_mass(self, x) -> np.ndarray:
        """Centre of mass of the whole structure in inertial axes, m, shape (2,) or (2, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        return self._batch(self.functions.center, x)

    # ------------------------------------------------------------------ linear analysis
    def _spin_for(self, spin_rate, what: str) -> float:
        spin_rate = checked_spin(spin_rate)
        if spin_rate != 0.0 and self.structure.free:
            raise InputValueError(
                f"spin_rate must be 0 for the {what} of a free hub; got {spin_rate!r}: at a "
                "steady spin a free hub's centre circles the centre of mass, so its state in "
                "inertial axes is not a fixed point to linearise about")
        return spin_rate

    def stiffness_matrix(self, spin_rate: float = 0.0) -> np.ndarray:
        """Beam stiffness at a steady spin, ``K_ff - spin_rate^2 D``, N/m, shape (N, N)
        (for a free hub: its beams' stiffness while the hub is held spinning).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate, rad/s (at most ``1e100`` in magnitude). Default 0.
        """
        spin_rate = checked_spin(spin_rate)
        return self.matrices.K_ff - spin_rate ** 2 * self._c["stiff_d"]

    def second_order_form(self, spin_rate: float = 0.0):
        """``M``, ``K``, ``C`` and the torque's load vector ``f`` of the linearisation about
        rest or a steady spin, ``M c_tt + C c_t + K c = f T_h`` in the generalized
        coordinates ``c`` (the state's coordinate block, :attr:`StateLayout.coordinates`).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate ``Omega``, rad/s (at most ``1e100`` in magnitude); must be 0 for a
            free hub. Default 0.

        Returns
        -------
        mass, stiffness, damping : ndarray, shape (n_c, n_c)
        load : ndarray, shape (n_c,)
        """
        spin_rate = self._spin_for(spin_rate, "linearisation")
        layout = self.layout
        # the coordinate block keeps the state's order: layout.q and layout.theta index both
        n_c, q, hub = layout.n_coordinates, layout.q, layout.theta
        stiff, damp, load = np.zeros((n_c, n_c)), np.zeros((n_c, n_c)), np.zeros(n_c)
        stiff[q, q] = self.stiffness_matrix(spin_rate)
        damp[hub, hub] = self.structure.hub.friction
        damp[q, q] = self.matrices.C_ff
        load[hub] = 1.0
        # a small-deflection variant's mass matrix at rest is its modal matrices' (the exact
        # geometry's differs by its quadrature, about 1e-7 relative)
        mass = self.mass_matrix(layout.zeros()) if self.variant.exact \
            else self.rest_mass_matrix()
        return mass, stiff, damp, load

    def natural_frequencies(self, spin_rate: float = 0.0, hub: str = "clamped") -> np.ndarray:
        """Undamped natural frequencies, rad/s, ascending, shape (N,).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate, rad/s; must be 0 for ``hub="free"`` on a free-floating hub. Default 0.
        hub : {"clamped", "free"}, optional
            ``"clamped"`` (default): the hub held (rotation and translation), at any spin;
            ``"free"``: the hub free to rotate, and to translate when it floats free; its rigid-body
            modes are left out.

        Returns
        -------
        ndarray, shape (N,)
            A mode that has lost its stiffness (zero_order above its first clamped frequency)
            is returned as a negative number whose magnitude is its exponential growth rate, 1/s.
        """
        if not isinstance(hub, str) or hub not in ("clamped", "free"):
            raise InputValueError(f"hub must be 'clamped' or 'free'; got {hub!r}")
        # a free hub held spinning has clamped beams; turning freely it has no steady spin
        spin_rate = self._spin_for(spin_rate, "natural frequencies") if hub == "free" \
            else checked_spin(spin_rate)
        key = (hub, spin_rate)
        kept = self._c.setdefault("frequencies", {})
        if key in kept:
            # asked by every run (its stiffness and duration checks, a prescribed spin's
            # fastest mode): kept for the last few spins
            return kept[key].copy()
        stiff = self.stiffness_matrix(spin_rate)
        mass = self.rest_mass_matrix()
        n_h = mass.shape[0] - self.matrices.n_modes
        reduced = mass[n_h:, n_h:]
        if hub == "free":
            reduced = reduced - mass[n_h:, :n_h] @ np.linalg.solve(mass[:n_h, :n_h],
                                                                   mass[:n_h, n_h:])
        lam = scipy.linalg.eigh(stiff, 0.5 * (reduced + reduced.T), eigvals_only=True)
        frequencies = np.sort(np.sign(lam) * np.sqrt(np.abs(lam)))
        if len(kept) >= KEPT_SPINS:
            kept.pop(next(iter(kept)))
        kept[key] = frequencies.copy()
        return frequencies

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

    def linearize(self, spin_rate: float = 0.0, *, x0=None, u0=None):
        """Linear plant about rest (free hub) or a steady spin (pinned hub), a python-control
        ``StateSpace`` with the model's named states, input and outputs (dots as underscores,
        :func:`~flexctl.model.exports.signal_names`); its attribute
        ``modal_visibility`` (:class:`~flexctl.model.visibility.ModalVisibility`) says which
        modes the torque cannot move (symmetric appendages bending against each other) and
        which outputs cannot see them.

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate, rad/s, about which the model is linearised with ``q = 0``; 0 for a
            free hub and with ``x0`` or ``u0``. Default 0.
        x0 : array_like, shape (n,), optional
            Any operating point instead (:func:`~flexctl.model.exports.linearize_at`; the plant then
            carries ``drift`` and ``operating_point`` rather than ``modal_visibility``). Default
            the zero state when only ``u0`` is given.
        u0 : float, optional
            Input at the operating point: the hub torque, N m (an actuated model's command).
            Default 0.
        """
        import control

        if x0 is not None or u0 is not None:
            return at_operating_point(self, spin_rate, x0, u0)
        spin_rate = self._spin_for(spin_rate, "linearisation")
        a, b = self.linear_matrices(spin_rate)
        plant = control.ss(a, b, self.output_matrix, np.zeros((len(self.output_names), 1)),
                          states=signal_names(self.state_names), inputs=list(self.input_names),
                          outputs=signal_names(self.output_names),
                          name=system_name(f"{self.variant}_structure_spin{spin_rate:g}"))

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


def structure_model(system, n_modes, variant: str) -> "Model":
    """The :class:`Model` of a Structure, or of a HubBeam (its one
    appendage unnamed).

    Parameters
    ----------
    system : Structure or HubBeam
        The hub and its appendages.
    n_modes : int, dict or sequence of int
        Modes of each appendage: one int for all, ``{name: int}``, or one per appendage in order
        (:func:`~flexctl.model.structure_matrices.modes_per_appendage`).
    variant : {"first_order", "zero_order", "consistent", "exact"}
        Model variant.
    """
    from .structure import as_structure
    from .structure_matrices import assemble_structure, modes_per_appendage

    structure = as_structure(system)
    modes = modes_per_appendage(structure, n_modes, variant)
    matrices = assemble_structure(structure, modes)
    return Model(system=system, n_modes=matrices.n_modes, variant=variant, matrices=matrices)


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

