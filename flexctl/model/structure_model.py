"""A model of several appendages on a pinned or free hub (``docs/theory/free_hub.md``).

:class:`StructureModel` is a :class:`~flexctl.model.variants.Model` whose system is a
:class:`~flexctl.model.structure.Structure`; :func:`flexctl.build_model` builds one for a
``Structure`` (or a ``HubBeam`` on a free hub). Its equations are CasADi functions
(:mod:`flexctl.model.structure_dynamics`), which its numpy methods evaluate at one state or at
a batch of states.

Notes
-----
States (:class:`~flexctl.model.layout.StateLayout`)::

    x = [theta, (hub_x, hub_y), <a>.q1 .. <b>.qN, theta_dot, (hub_x_dot, hub_y_dot),
         <a>.q1_dot .. <b>.qN_dot]

``hub_x, hub_y`` (m, inertial axes) for a free hub only. Input ``torque`` (N m). Outputs::

    y = [theta, theta_dot, (hub_x, hub_y),
         <a>.tip_deflection, <a>.root_moment, <a>.tip_angle, <b>.tip_deflection, ...]

Each tip deflection is the tip's transverse position in its appendage's own frame (m, positive
counter-clockwise), each tip angle the hub angle plus the tip's angle from the appendage's
mounting direction seen from the hub centre (rad). An appendage with the empty name (a
``HubBeam`` on a free hub) has unprefixed names.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .errors import InputValueError
from .exports import signal_names
from .layout import StateLayout
from .structure_dynamics import structure_functions
from .variant import Variant
from .variants import Model, SingularMassMatrixError, at_operating_point, checked_spin, system_name

__all__ = ["StructureModel", "output_names"]


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
class StructureModel(Model):
    """A model of a :class:`~flexctl.model.structure.Structure` (see the module Notes).

    Build with :func:`flexctl.build_model`. Besides :class:`~flexctl.model.variants.Model`'s
    attributes, ``modes`` (tuple of int, the modes of each appendage) and :attr:`functions`
    (the CasADi functions, built on first use).

    Attributes
    ----------
    system : Structure
        The hub and its appendages.
    n_modes : int
        Modes of all the appendages together, ``N``.
    variant : Variant
        ``"first_order"``, ``"zero_order"``, ``"consistent"`` or ``"exact"``.
    matrices : StructureMatrices
        The structure's modal matrices at rest (:mod:`flexctl.model.structure_matrices`).
    """

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

    def _rebuilt(self, system) -> "StructureModel":
        """This model (modes, variant) of another ``system`` of the same kind."""
        return structure_model(system, self.mode_spec, self.variant)

    @property
    def mode_spec(self) -> tuple:
        """The ``n_modes`` of :func:`flexctl.build_model` for these modes: :attr:`modes`."""
        return self.modes

    @property
    def structure(self):
        """The :class:`~flexctl.model.structure.Structure` (the same as :attr:`system`)."""
        return self.system

    def __repr__(self):
        hub = "free" if self.system.free else "pinned"
        return (f"StructureModel(variant={self.variant!r}, modes={dict(zip(self.system.names, self.modes))}, "
                f"{hub} hub, J0={self.matrices.J0:.6g} kg m^2)")

    @property
    def functions(self):
        """The CasADi functions (:class:`~flexctl.model.structure_dynamics.StructureFunctions`)."""
        if "functions" not in self._c:
            self._c["functions"] = structure_functions(self)
        return self._c["functions"]

    @property
    def geometry(self):
        """The CasADi functions for every variant (the same as :attr:`functions`)."""
        return self.functions

    def _batch(self, function, x, *args):
        x = self._check_state(x)
        return self._evaluate(function, x.ndim > 1, x, *args)

    def _pinned_only(self, what: str):
        if self.system.free:
            raise InputValueError(
                f"{what} needs a pinned hub: a free hub's translation follows from the forces "
                "on it, and a prescribed hub rotation leaves it undetermined here; drive the "
                "free hub by its torque instead")

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
        torque = np.broadcast_to(torque, x.shape[1:])
        xdot = self._evaluate(self.functions.rhs, x.ndim > 1, x, torque)
        if not np.all(np.isfinite(xdot)) and np.all(np.isfinite(x)):
            raise SingularMassMatrixError(
                "mass matrix is singular at this state: the effective hub inertia "
                f"{np.min(self.effective_hub_inertia(x)):.3g} kg m^2 is not positive")
        return xdot

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
        if not self.system.free:
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
        if not self.system.free:
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
        if not (self.variant.exact or self.variant.quadratic_inertia) and not self.system.free:
            j = self._c["j_rigid_eff"]
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
        return self._evaluate(self.functions.beam, np.ndim(q) > 1, q, q_dot, theta_dot,
                              theta_tt)

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
        return self._batch(self.functions.torque, x, theta_tt, q_tt)[0]

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

    # ------------------------------------------------------------------ outputs
    @property
    def output_matrix(self) -> np.ndarray:
        """``C``, the outputs' linearisation at rest, shape (n_outputs, n)."""
        if "c_out" not in self._c:
            import casadi as ca
            x = ca.SX.sym("x", self.n_states)
            jac = ca.Function("c", [x], [ca.jacobian(self.functions.outputs(x), x)])
            c = np.array(jac(np.zeros(self.n_states)))
            c.setflags(write=False)
            self._c["c_out"] = c
        return self._c["c_out"]

    def outputs(self, x) -> np.ndarray:
        """Outputs (:attr:`output_names`) at state(s) ``x``; shape (n_out,) or (n_out, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        return self._batch(self.functions.outputs, x)

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
        if not self.system.free:
            return float(mat.J0)
        return float(mat.J0 - mat.first @ mat.first / mat.mass)

    def quasi_static_gain(self) -> np.ndarray:
        """``q = -g theta_tt`` at rest under a slow hub acceleration, m per rad/s^2, (N,)."""
        mass = self.rest_mass_matrix()
        n_h = mass.shape[0] - self.matrices.n_modes
        coupling = mass[n_h:, 0]
        if self.system.free:
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

    def tip_position(self, x):
        """Not available: a structure has one tip per appendage (raises
        ``NotImplementedError``); use :meth:`tip_deflections` or the named outputs.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        raise NotImplementedError("StructureModel has one tip per appendage: use "
                                  "tip_deflections or the named outputs")

    def deflection(self, x, position: float):
        """Not available: a structure has several appendages (raises ``NotImplementedError``);
        use the named outputs.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        position : float
            Distance from the beam root, m.
        """
        raise NotImplementedError("StructureModel has several appendages: use the named "
                                  "outputs")

    # ------------------------------------------------------------------ balances
    def energy(self, x) -> np.ndarray:
        """Mechanical energy, J, shape () or (P,) (the consistent energy for the
        small-deflection variants).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        return self._batch(self.functions.energy, x)[0]

    def angular_momentum(self, x) -> np.ndarray:
        """Angular momentum about the inertial origin, kg m^2/s, shape () or (P,).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            State(s) in :attr:`layout` order.
        """
        return self._batch(self.functions.momentum, x)[0]

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
        if spin_rate != 0.0 and self.system.free:
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
        """``M``, ``K``, ``C``, ``f`` of the linearisation in the generalized coordinates
        (:meth:`Model.second_order_form <flexctl.model.variants.Model.second_order_form>`).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate, rad/s; must be 0 for a free hub. Default 0.
        """
        spin_rate = self._spin_for(spin_rate, "linearisation")
        return super().second_order_form(spin_rate)

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
        """
        if not isinstance(hub, str) or hub not in ("clamped", "free"):
            raise InputValueError(f"hub must be 'clamped' or 'free'; got {hub!r}")
        # a free hub held spinning has clamped beams; turning freely it has no steady spin
        spin_rate = self._spin_for(spin_rate, "natural frequencies") if hub == "free" \
            else checked_spin(spin_rate)
        stiff = self.stiffness_matrix(spin_rate)
        mass = self.rest_mass_matrix()
        n_h = mass.shape[0] - self.matrices.n_modes
        reduced = mass[n_h:, n_h:]
        if hub == "free":
            reduced = reduced - mass[n_h:, :n_h] @ np.linalg.solve(mass[:n_h, :n_h],
                                                                   mass[:n_h, n_h:])
        lam = scipy.linalg.eigh(stiff, 0.5 * (reduced + reduced.T), eigvals_only=True)
        return np.sort(np.sign(lam) * np.sqrt(np.abs(lam)))

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


def structure_model(system, n_modes, variant: str) -> StructureModel:
    """The :class:`StructureModel` of a Structure, or of a HubBeam on a free hub (its one
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
    return StructureModel(system=structure, n_modes=matrices.n_modes, variant=variant,
                          matrices=matrices)
