"""A structure turned by an actuator: the plant whose input is the actuator's command.

:class:`ActuatedModel` is a :class:`~flexctl.model.variants.Model` whose state
carries the actuator's states after the mechanical ones and whose input is the actuator's
command (:mod:`flexctl.model.actuators`); :func:`flexctl.build_model` builds one when given an
``actuator``. Every view of the model (``dynamics``, ``casadi``, ``nonlinear``, ``linearize``,
outputs, energy, momentum) covers the whole plant, so that every simulation path (compiled
included) integrates the actuator with the structure.

Notes
-----
States (:class:`~flexctl.model.layout.StateLayout`, block ``"actuator"`` last)::

    x = [<mechanical states of the structure>, <actuator states>]

reaction wheel: ``wheel_speed`` (rad/s, relative to the hub), ``wheel_torque`` (N m, the motor
torque on the hub after its lag); DC motor: none. Input: ``torque_command`` (N m) or
``voltage`` (V). Outputs: the structure's, then the actuator's states. The structure the
equations integrate (``system``) is the one given, with a DC motor's reflected rotor
inertia added to the hub.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .errors import InputValueError
from .structure_dynamics import StructureFunctions
from .variants import Model, output_names

__all__ = ["ActuatedModel", "actuated_model"]

BLOCK = "actuator"


@dataclass(frozen=True, eq=False)
class ActuatedModel(Model):
    """A structure model driven through an actuator (see the module Notes).

    Build with :func:`flexctl.build_model` (its ``actuator``). Besides
    :class:`~flexctl.model.variants.Model`'s attributes, :attr:`mechanical`
    (the structure's model, input the hub torque).

    Attributes
    ----------
    system : Structure
        The structure the equations integrate: the one given, with a DC motor's reflected
        rotor inertia added to its hub.
    n_modes : int
        Modes of all the appendages together, ``N``.
    variant : Variant
        ``"first_order"``, ``"zero_order"``, ``"consistent"`` or ``"exact"``.
    matrices : StructureMatrices
        The modal matrices of ``system`` at rest.
    actuator : ReactionWheel or DCMotor
        What turns the hub (:mod:`flexctl.model.actuators`).
    source : Structure
        The structure as given, before the actuator changed its hub.
    """

    HAS_MATRIX_FORM: ClassVar[bool] = False
    actuator: object = field(default=None, kw_only=True)
    #: The structure as given, before the actuator changed its hub (``system``: after).
    source: object = field(default=None, kw_only=True, repr=False)

    def _rebuilt(self, system) -> "ActuatedModel":
        """This model (modes, variant, actuator) of another ``system`` of the same kind."""
        return actuated_model(system, self.mode_spec, self.variant, self.actuator)

    def __post_init__(self):
        super().__post_init__()
        mechanical = Model(system=self.system, n_modes=self.n_modes,
                                    variant=self.variant, matrices=self.matrices)
        layout = mechanical.layout.with_block(BLOCK, self.actuator.state_names) \
            if self.actuator.state_names else mechanical.layout
        object.__setattr__(self, "layout", layout)
        object.__setattr__(self, "state_names", layout.names)
        object.__setattr__(self, "input_names", (self.actuator.input_name,))
        object.__setattr__(self, "output_names",
                           output_names(self.system) + tuple(self.actuator.state_names))
        self._c["mechanical"] = mechanical

    @property
    def mechanical(self) -> Model:
        """The structure's own model (input the hub torque, no actuator states)."""
        return self._c["mechanical"]

    def __repr__(self):
        return (f"ActuatedModel({self.actuator.kind}, variant={self.variant!r}, "
                f"modes={self.modes}, {'free' if self.system.free else 'pinned'} hub)")

    # ------------------------------------------------------------------ equations
    @property
    def functions(self) -> StructureFunctions:
        """The plant's CasADi functions: the structure's with the actuator in them."""
        if "functions" not in self._c:
            self._c["functions"] = _actuated_functions(self)
        return self._c["functions"]

    def actuator_states(self, x) -> np.ndarray:
        """The actuator's states of state(s) ``x``, shape (k,) or (k, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            Plant state(s) in :attr:`layout` order, the actuator's states included.
        """
        x = self._check_state(x)
        return x[self.layout.block(BLOCK)] if self.actuator.state_names else x[:0]

    def mechanical_states(self, x) -> np.ndarray:
        """The structure's states of state(s) ``x``, shape (n_m,) or (n_m, P).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            Plant state(s) in :attr:`layout` order, the actuator's states included.
        """
        return self._check_state(x)[self.layout.mechanical]

    def applied_torque(self, x, u) -> np.ndarray:
        """Torque the actuator puts on the structure at state(s) ``x`` under command(s)
        ``u``, N m, shape () or (P,).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            Plant state(s) in :attr:`layout` order, the actuator's states included.
        u : float or array_like, shape (P,)
            Actuator command(s): ``torque_command`` (N m) of a reaction wheel or ``voltage`` (V) of
            a DC motor; one per state of a batch.
        """
        x = self._check_state(x)
        u = np.broadcast_to(np.asarray(u, dtype=float), x.shape[1:])
        return self._evaluate(self.functions.hub_torque, x.ndim > 1, x, u)[0]

    def actuator_signals(self, x, u) -> dict:
        """The actuator's signals (``wheel_speed``, ``wheel_torque``; or ``motor_voltage``,
        ``motor_current``) at state(s) ``x`` under command(s) ``u``, ``{name: () or (P,)}``.

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            Plant state(s) in :attr:`layout` order, the actuator's states included.
        u : float or array_like, shape (P,)
            Actuator command(s): ``torque_command`` (N m) of a reaction wheel or ``voltage`` (V) of
            a DC motor; one per state of a batch.
        """
        x = self._check_state(x)
        u = np.broadcast_to(np.asarray(u, dtype=float), x.shape[1:])
        values = self._evaluate(self.functions.signals, x.ndim > 1, x, u)
        return dict(zip(self.actuator.signal_names, values))

    def total_angular_momentum(self, x) -> np.ndarray:
        """Angular momentum of hub, beams and actuator about the inertial origin, kg m^2/s,
        shape () or (P,) (the same as :meth:`angular_momentum`).

        Parameters
        ----------
        x : array_like, shape (n,) or (n, P)
            Plant state(s) in :attr:`layout` order, the actuator's states included.
        """
        return self.angular_momentum(x)

    def beam_accelerations(self, *args):
        """Not available: a prescribed hub motion does not go through an actuator (raises
        ``InputValueError``); use ``model.mechanical.beam_accelerations``.

        Parameters
        ----------
        *args
            Those of :meth:`Model.beam_accelerations
            <flexctl.model.variants.Model.beam_accelerations>`; not read.
        """
        raise InputValueError("a prescribed hub motion does not go through an actuator: "
                              "simulate the structure's own model (model.mechanical)")

    def hub_torque(self, *args):
        """Not available: the torque of a prescribed hub motion is the structure's (raises
        ``InputValueError``); use ``model.mechanical.hub_torque``.

        Parameters
        ----------
        *args
            Those of :meth:`Model.hub_torque
            <flexctl.model.variants.Model.hub_torque>`; not read.
        """
        raise InputValueError("the torque of a prescribed hub motion is the structure's: use "
                              "model.mechanical.hub_torque")

    def linear_matrices(self, spin_rate: float = 0.0):
        """``A`` (n, n) and ``B`` (n, 1) of the plant (actuator included) linearised about
        rest (or a steady spin of a pinned hub, the actuator at rest and commanded 0).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate, rad/s; must be 0 for a free hub. Default 0.
        """
        import casadi as ca

        spin_rate = self._spin_for(spin_rate, "linearisation")
        x, u = ca.SX.sym("x", self.n_states), ca.SX.sym("u")
        xdot = self.functions.rhs(x, u)
        jac = ca.Function("actuated_jacobian", [x, u], [ca.jacobian(xdot, x), ca.jacobian(xdot, u)])
        x0 = self.layout.zeros()
        x0[self.layout.theta_dot] = spin_rate
        a, b = (np.array(m, dtype=float) for m in jac(x0, 0.0))
        return a, b.reshape(-1, 1)

    def second_order_form(self, spin_rate: float = 0.0):
        """The structure's second-order form (its coordinates only).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate, rad/s; must be 0 for a free hub. Default 0.
        """
        return self.mechanical.second_order_form(spin_rate)

    def modal_visibility(self, spin_rate: float = 0.0):
        """Which of the structure's modes its hub torque moves (the actuator passes the
        torque on: its own modes are not flexible ones).

        Parameters
        ----------
        spin_rate : float, optional
            Steady hub rate, rad/s, of the linearisation. Default 0.
        """
        return self.mechanical.modal_visibility(spin_rate)


def _actuated_functions(model) -> StructureFunctions:
    """The structure's functions composed with the actuator's equations."""
    import casadi as ca

    mech, act, layout = model.mechanical, model.actuator, model.layout
    base, mlay = mech.functions, mech.layout
    x, u = ca.SX.sym("x", model.n_states), ca.SX.sym("u")
    xm = x[layout.mechanical]
    xa = x[layout.block(BLOCK)] if act.state_names else ca.SX.zeros(0)
    rate = xm[mlay.theta_dot]
    torque = act.hub_torque(xa, rate, u)
    xdot_m = base.rhs(xm, torque)
    xdot_a = act.derivative(xa, rate, xdot_m[mlay.theta_dot], u, torque)
    rhs = ca.Function(f"flexctl_{model.variant}_{act.kind}", [x, u],
                      [ca.vertcat(xdot_m, xdot_a)], ["x", "u"], ["xdot"])
    momentum = base.momentum(xm)
    momentum = ca.vertcat(momentum[0] + act.momentum(xa, rate), momentum[1:])
    fn = lambda name, out, outs: ca.Function(name, [x], [out], ["x"], [outs])  # noqa: E731
    return dataclasses.replace(
        base, rhs=rhs,
        mass=fn("actuated_mass", base.mass(xm), "M"),
        energy=fn("actuated_energy", base.energy(xm) + act.energy(xa, rate), "E"),
        momentum=fn("actuated_momentum", momentum, "h"),
        center=fn("actuated_center", base.center(xm), "r_G"),
        outputs=fn("actuated_outputs", ca.vertcat(base.outputs(xm), act.outputs(xa)), "y"),
        beam=None, torque=None,
        hub_torque=ca.Function("actuated_hub_torque", [x, u], [torque], ["x", "u"], ["T"]),
        signals=ca.Function("actuated_signals", [x, u], [act.signals(xa, rate, u)],
                            ["x", "u"], ["s"]))


def actuated_model(system, n_modes, variant, actuator) -> ActuatedModel:
    """The :class:`ActuatedModel` of ``system`` under ``actuator``.

    Parameters
    ----------
    system : HubBeam or Structure
        The structure turned, before the actuator changes its hub (kept, as a Structure, in
        :attr:`ActuatedModel.source`); a DC motor needs a pinned hub.
    n_modes : int, dict or sequence of int
        Modes of each appendage: one int for all, ``{name: int}``, or one per appendage in order
        (:func:`~flexctl.model.structure_matrices.modes_per_appendage`).
    variant : {"first_order", "zero_order", "consistent", "exact"}
        Model variant.
    actuator : ReactionWheel or DCMotor
        What turns the hub; a DC motor's reflected rotor inertia is added to the hub.
    """
    from .structure import as_structure
    from .structure_matrices import assemble_structure, modes_per_appendage

    structure = source = as_structure(system)
    if actuator.kind == "dc_motor" and structure.free:
        raise InputValueError("actuator: a dc_motor turns the hub against the ground and "
                              "needs a pinned hub; a free-floating hub is turned by a "
                              "reaction_wheel")
    hub = actuator.mechanical_hub(structure.hub)
    if hub is not structure.hub:
        structure = dataclasses.replace(structure, hub=hub)
    modes = modes_per_appendage(structure, n_modes, variant)
    matrices = assemble_structure(structure, modes)
    return ActuatedModel(system=structure, n_modes=matrices.n_modes, variant=variant,
                         matrices=matrices, actuator=actuator, source=source)
