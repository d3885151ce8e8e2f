"""What drives a run: a prescribed hub motion, or a torque with a continuous controller.

A drive owns the state the integrator carries (its :class:`~flexctl.model.layout.StateLayout`),
its right-hand side for SciPy, the plant state and the hub torque it reports. The compiled
paths build their own right-hand sides from the same inputs (:mod:`flexctl.sim.compiled`); a
sampled controller has its own loop (:mod:`flexctl.sim.digital`).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from .compiled import torque_history
from .inputs import input_value, time_function
from .native_rhs import prescribed_torque
from ..model import Model
from ..model.errors import InputTypeError, InputValueError

__all__ = ["Controller", "StaticLaw", "PrescribedDrive", "TorqueDrive", "as_controller",
           "bound_to_plant"]


@runtime_checkable
class Controller(Protocol):
    """Feedback law with optional internal states ``z`` (e.g. an estimator).

    Attributes
    ----------
    n_states : int
        Number of internal states (0 for a static law).
    """

    n_states: int

    def initial_state(self, x0: np.ndarray) -> np.ndarray:
        """Internal state at ``t = 0`` given the plant's initial state, shape (n_states,).

        Parameters
        ----------
        x0 : ndarray, shape (n,)
            Initial plant state, in the order of ``model.layout``.
        """

    def torque(self, t: float, x: np.ndarray, z: np.ndarray) -> float:
        """Hub torque (N m) at time ``t`` for plant state ``x`` and internal state ``z``.

        Parameters
        ----------
        t : float
            Time, s.
        x : ndarray, shape (n,)
            Plant state, in the order of ``model.layout``.
        z : ndarray, shape (n_states,)
            Internal state.
        """

    def derivative(self, t: float, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """``dz/dt``, shape (n_states,).

        Parameters
        ----------
        t : float
            Time, s.
        x : ndarray, shape (n,)
            Plant state, in the order of ``model.layout``.
        z : ndarray, shape (n_states,)
            Internal state.
        """


@dataclass(frozen=True, eq=False)
class StaticLaw:
    """A static feedback law ``torque = law(t, x)`` as a :class:`Controller` (no states).

    :func:`simulate` wraps a callable ``controller`` in this; :class:`controllers.OpenLoop`
    is the open-loop case ``torque = f(t)``.

    Parameters
    ----------
    law : callable
        ``law(t, x)``: hub torque, N m, at time ``t`` (s) for plant state ``x`` (shape (n,)).
        Its ``breakpoints`` attribute (times, s, where it is not smooth), if any, is kept so
        that :func:`simulate` restarts the integrator there.
    """

    law: object
    n_states = 0

    def __post_init__(self):
        if not callable(self.law):
            raise InputTypeError(f"{type(self).__name__}.law must be callable; got "
                                 f"{type(self.law).__name__}")

    @property
    def breakpoints(self) -> tuple:
        """The wrapped law's times of non-smoothness, s."""
        return tuple(getattr(self.law, "breakpoints", ()) or ())

    def initial_state(self, x0) -> np.ndarray:
        """No internal state: shape (0,).

        Parameters
        ----------
        x0 : ndarray, shape (n,)
            Initial plant state (not read).
        """
        return np.zeros(0)

    def torque(self, t, x, z=None) -> float:
        """Hub torque, N m.

        Parameters
        ----------
        t : float
            Time, s.
        x : ndarray, shape (n,)
            Plant state, in the order of ``model.layout``.
        z : ndarray, shape (0,), optional
            Ignored (no internal state).
        """
        return self.law(t, x)

    def derivative(self, t, x, z=None) -> np.ndarray:
        """No internal state: shape (0,).

        Parameters
        ----------
        t : float
            Time, s. Ignored.
        x : ndarray, shape (n,)
            Plant state. Ignored.
        z : ndarray, shape (0,), optional
            Ignored.
        """
        return np.zeros(0)


def bound_to_plant(law, model):
    """``law`` reading the states of plant ``model``: a law that reads the plant by its
    layout (``for_plant``, ``plant_layout`` still None) bound to ``model``'s, since a bare state
    does not tell its blocks (several appendages, an actuator's states); else ``law``.

    Parameters
    ----------
    law : object
        A feedback law or controller; bound only when it has a callable ``for_plant`` and its
        ``plant_layout`` is None.
    model : Model
        The plant whose states the law reads.
    """
    if callable(getattr(law, "for_plant", None)) and getattr(law, "plant_layout", 0) is None:
        return law.for_plant(model)
    return law


def as_controller(controller, x_init):
    """``controller`` as a :class:`Controller`: a callable ``(t, x)`` becomes a
    :class:`StaticLaw` whose errors name it with the time; anything else is refused by name.

    Parameters
    ----------
    controller : callable, Controller or None
        The ``controller`` argument of :func:`flexctl.simulate`; None and a :class:`Controller`
        are returned as they are.
    x_init : ndarray, shape (n,)
        Initial plant state, used to check that a callable takes ``(t, x)``.
    """
    if controller is None or isinstance(controller, Controller):
        return controller
    if not callable(controller):
        raise InputTypeError("controller must be callable as controller(t, x) or follow "
                             f"the flexctl Controller protocol; got {type(controller).__name__}")
    law = time_function(controller, "controller")    # its errors named, with the time
    try:
        inspect.signature(controller).bind(0.0, x_init)
    except TypeError:
        raise InputTypeError(
            "controller must be callable as controller(t, x); got "
            f"{getattr(controller, '__name__', type(controller).__name__)}, which cannot "
            "take the state (a torque of time alone is passed as torque=)") from None
    except ValueError:          # no signature to read (a builtin): its calls will tell
        pass
    law.breakpoints = tuple(getattr(controller, "breakpoints", ()) or ())
    return StaticLaw(law)


class _Drive:
    """Shared part of the drives: the model, the segment end the inputs are held to.

    Inputs are evaluated inside the current smooth segment: at its closed end the integrator
    must see the value from the left, not the next piece's (:attr:`segment_end`).
    """

    prescribed = False
    hub_motion = None
    controller = None
    torque = None

    def __init__(self, model: Model):
        self.model = model
        self.segment_end = np.inf

    def inside(self, t):
        """``t`` held to the end of the current segment."""
        return min(t, self.segment_end)

    @property
    def sources(self) -> tuple:
        """The inputs, for breakpoints and step bounds."""
        return (self.torque, self.hub_motion, self.controller)

    def controller_states(self, y_all) -> np.ndarray:
        """The controller's states over the run, shape (n_z, P)."""
        return np.zeros((0, np.shape(y_all)[1]))


class PrescribedDrive(_Drive):
    """The hub follows ``hub_motion``; only the beam is integrated
    (state :meth:`~flexctl.model.layout.StateLayout.without_rotation`).

    Parameters
    ----------
    model : Model
        The model of the run (a pinned hub).
    hub_motion : object
        The prescribed motion: ``angle(t)``, ``rate(t)`` and ``acceleration(t)`` (rad,
        rad/s, rad/s^2).
    x_init : ndarray, shape (n,)
        Initial plant state; its beam states start the integration.
    """

    prescribed = True

    def __init__(self, model: Model, hub_motion, x_init):
        super().__init__(model)
        self.hub_motion = hub_motion
        self.layout = model.layout.without_rotation()
        self.y_init = x_init[model.layout.beam]

    def rhs(self, t, y):
        """``d[q, q_dot]/dt`` under the prescribed rate and acceleration.

        Parameters
        ----------
        t : float
            Time, s; held to the end of the current segment for the inputs.
        y : ndarray, shape (m,)
            Integrated state ``[q, q_dot]`` (the beam's modal coordinates and rates), in the order
            of ``self.layout``.
        """
        beam, motion = self.layout, self.hub_motion
        t = self.inside(t)
        qdd = self.model.beam_accelerations(
            beam.modal(y), beam.modal_rates(y),
            input_value("hub_motion.rate", motion.rate(t), t, "rad/s"),
            input_value("hub_motion.acceleration", motion.acceleration(t), t, "rad/s^2"))
        return np.concatenate((y[beam.velocities], qdd))

    def check_inputs(self):
        """Every input once at the start: a wrong type or a non-finite value is named."""
        self.rhs(0.0, self.y_init)

    def plant_state(self, t, y):
        """The plant states at times ``t`` (shape (P,)) from the integrated ``y`` (m, P).

        Parameters
        ----------
        t : array_like, shape (P,)
            Times, s, at which the hub motion gives the angle and rate.
        y : ndarray, shape (m, P)
            Integrated ``[q, q_dot]`` at those times.

        Returns
        -------
        ndarray, shape (n, P)
            Plant states in the order of ``model.layout``.
        """
        t = np.asarray(t)
        return self.model.layout.from_beam(y, self.hub_motion.angle(t), self.hub_motion.rate(t))

    def torque_output(self, t_all, states, z_all, symbolic):
        """The torque the motion needs, N m, shape (P,).

        Parameters
        ----------
        t_all : ndarray, shape (P,)
            Output times, s.
        states : ndarray, shape (n, P)
            Plant states at those times.
        z_all : ndarray, shape (0, P)
            Controller states; ignored (a prescribed motion has no controller).
        symbolic : bool
            Whether every input has a CasADi form; ignored here.
        """
        model = self.model
        acc = self.hub_motion.acceleration(t_all)
        native = prescribed_torque(model, states, acc)
        if native is not None:
            return native
        _, q, rate, q_dot = model.layout.split(states)
        qdd = model.beam_accelerations(q, q_dot, rate, acc)
        return model.hub_torque(states, acc, qdd)


class TorqueDrive(_Drive):
    """A hub torque (a function of time or of time and state) plus a continuous controller
    with internal states ``z``; integrated state ``[x, z]``.

    Parameters
    ----------
    model : Model
        The model of the run.
    torque : object or None
        The hub torque input, N m (a function of time, of time and state, or samples), or
        None.
    controller : Controller or None
        The continuous controller, or None; its ``initial_state(x_init)`` starts ``z``.
    x_init : ndarray, shape (n,)
        Initial plant state.
    """

    def __init__(self, model: Model, torque, controller, x_init):
        super().__init__(model)
        self.torque, self.controller = torque, controller
        self.torque_fn = time_function(torque, "torque") if torque is not None else None
        self.nz = controller.n_states if controller is not None else 0
        z_init = (np.asarray(controller.initial_state(x_init), dtype=float).reshape(-1)
                  if controller is not None else np.zeros(0))
        if z_init.shape != (self.nz,):
            raise InputValueError(f"controller.initial_state must return {self.nz} values; "
                                  f"got shape {z_init.shape}")
        self.layout = (model.layout.with_block("controller", [f"z{k}" for k in range(self.nz)])
                       if self.nz else model.layout)
        self.plant = slice(0, model.n_states)      # the model's own blocks, actuators included
        self.y_init = np.concatenate((x_init, z_init))

    def _z(self, y):
        return y[self.layout.block("controller")] if self.nz else y[:0]

    def applied_torque(self, t, x, z):
        """The hub torque, N m: the torque input plus the controller's.

        Parameters
        ----------
        t : float
            Time, s.
        x : ndarray, shape (n,)
            Plant state, in the order of ``model.layout``.
        z : ndarray, shape (n_z,)
            The controller's internal state.
        """
        u = self.torque_fn(t, x) if self.torque_fn is not None else 0.0
        if self.controller is not None:
            u += input_value("controller", self.controller.torque(t, x, z), t)
        return u

    def rhs(self, t, y):
        """``d[x, z]/dt``.

        Parameters
        ----------
        t : float
            Time, s; the inputs are evaluated at it held to the end of the current segment.
        y : ndarray, shape (m,)
            Integrated state ``[x, z]``: the plant's ``n`` states, then the controller's ``n_z``.
        """
        x, z = y[self.plant], self._z(y)
        dx = self.model.dynamics(t, x, self.applied_torque(self.inside(t), x, z))
        if not self.nz:
            return dx
        dz = np.asarray(self.controller.derivative(t, x, z), dtype=float).reshape(-1)
        if dz.shape != (self.nz,) or not np.all(np.isfinite(dz)):
            raise InputValueError(f"controller.derivative must return {self.nz} finite "
                                  f"numbers; got {dz!r} at t = {t:.6g} s")
        return np.concatenate((dx, dz))

    def check_inputs(self):
        """Every input once at the start: a wrong type or a non-finite value is named."""
        self.applied_torque(0.0, self.y_init[self.plant], self._z(self.y_init))

    def plant_state(self, t, y):
        """The plant states from the integrated ``y``.

        Parameters
        ----------
        t : array_like
            Times, s; ignored (the plant states are integrated).
        y : ndarray, shape (m,) or (m, P)
            Integrated ``[x, z]``.

        Returns
        -------
        ndarray, shape (n,) or (n, P)
            The first ``n`` rows of ``y``.
        """
        return y[self.plant]

    def controller_states(self, y_all) -> np.ndarray:
        """The controller's states over the run, shape (n_z, P).

        Parameters
        ----------
        y_all : ndarray, shape (m, P)
            Integrated states ``[x, z]`` at the output times.
        """
        return self._z(y_all)

    def torque_output(self, t_all, states, z_all, symbolic):
        """The hub torque over the run, N m, shape (P,).

        Parameters
        ----------
        t_all : ndarray, shape (P,)
            Output times, s.
        states : ndarray, shape (n, P)
            Plant states at those times.
        z_all : ndarray, shape (n_z, P)
            The controller's internal states at those times.
        symbolic : bool
            Every input has a CasADi form (``RunRequest.symbolic``): the torque is then evaluated
            from that form over the whole run at once.
        """
        torque, controller = self.torque, self.controller
        out = None
        if controller is None and (torque is None or symbolic) \
                and not getattr(torque, "state_dependent", False):
            # no torque, or a manoeuvre with a CasADi form: those evaluate a whole time array
            # at once (checked, since a user's own class may not)
            out = (np.zeros(t_all.size) if torque is None
                   else np.asarray(torque(t_all), dtype=float).reshape(-1))
            if out.shape != t_all.shape:
                out = None
        if out is None and symbolic:
            out = torque_history(self.model, t_all, states, z_all, torque, controller)
        if out is None:
            out = np.array([self.applied_torque(t, states[:, k], z_all[:, k])
                            for k, t in enumerate(t_all)])
        return out
