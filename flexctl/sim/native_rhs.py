"""The exact model's right-hand sides for the integrators, as machine code.

CVODES evaluates a model's right-hand side tens of thousands of times a run. For the exact
variant that evaluation dominates on CasADi's virtual machine (11 us at 4 modes against 1 us
for first_order). Here its scalar form (:attr:`Model.functions <flexctl.model.variants.Model.functions>` ``.rhs``,
every quadrature node written out) is compiled through the persistent cache
(:mod:`flexctl.sim.compile_cache`) with its numbers lifted into an input
(:func:`~flexctl.sim.lifted_constants.lift_constants`): one library per structure (modes,
panels, point masses), whatever the beam's numbers, so that a Monte Carlo over the structure
compiles once. It is wrapped with first_order's Jacobian for Newton's method
(:meth:`flexctl.Model.integration_rhs`), as on the virtual machine. A structure's exact
right-hand side (several appendages, a free hub) is compiled the same way, with the
first_order structure's Jacobian.

Where compiling is off or impossible, or the function is larger than
:data:`MAX_INSTRUCTIONS`, the model's own (virtual machine) form is used.
"""

from __future__ import annotations

import weakref

from .compile_cache import compiled, compiling_enabled
from .compiled_derivatives import jacobian_companion
from .lifted_constants import lift_constants

__all__ = ["integration_rhs", "integration_beam", "prescribed_torque", "compiles_prescribed",
           "native_dae", "MAX_INSTRUCTIONS", "MAX_DAE_INSTRUCTIONS"]

#: Largest scalar function compiled, instructions (with ``-Og``: two arrays of 5 modes, 31 500
#: instructions, 740 kB of C, compile in 2 s; hub-beam-mass on 10 modes, 51 500, in 4.5 s; on
#: 14 modes, 163 000, in 24 s), once. Larger ones stay on the virtual machine.
MAX_INSTRUCTIONS = 60_000

#: Largest integrator library (:func:`native_dae`: the right-hand side and its Jacobian)
#: compiled, instructions: about 2 s of ``-Og``, once. A first_order structure's drive and
#: dynamics are a few hundred to a few thousand instructions; its Jacobian is some five times
#: longer.
MAX_DAE_INSTRUCTIONS = 30_000

#: The compiled functions of each exact geometry (shared by the models built on it).
_NATIVE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
#: The wrapped right-hand sides of each model.
_BUILT: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _native(geometry, form: str):
    """``geometry.rhs``, ``.beam`` or ``.torque`` as a function of the same inputs that calls
    its compiled lifted form with the geometry's constants, or None to stay on the virtual
    machine."""
    import casadi as ca

    entry = _NATIVE.setdefault(geometry, {})
    if form not in entry:
        function = getattr(geometry, form)
        lifted = lift_constants(function, MAX_INSTRUCTIONS)
        native = None
        if lifted is not None:
            built = compiled(lifted[0], label=function.name())
            if built is not lifted[0]:          # else compiling is off, impossible or failed
                args = [ca.MX.sym(function.name_in(k), function.sparsity_in(k))
                        for k in range(function.n_in())]
                native = ca.Function(f"{function.name()}_native", args,
                                     [built(*args, ca.DM(lifted[1]))], function.name_in(),
                                     function.name_out())
        entry[form] = native
    return entry[form]


def _built(model, form: str):
    entry = _BUILT.setdefault(model, {})
    if form not in entry:
        native = _native(model.geometry, form)
        build = model.integration_rhs if form == "rhs" else model.integration_beam
        entry[form] = build(native)
    return entry[form]


def compiles_prescribed(model) -> bool:
    """Whether a prescribed hub motion of ``model`` runs its compiled beam and hub torque:
    an exact model on a pinned hub.

    Parameters
    ----------
    model : Model
        The model of the run.
    """
    return model.variant.exact and not model.structure.free


def integration_rhs(model):
    """``(x, u) -> xdot`` for implicit integrators: compiled for an exact model (one beam or
    a structure), :meth:`flexctl.Model.integration_rhs` otherwise.

    Parameters
    ----------
    model : Model
        The model of the run.
    """
    if not model.variant.exact:
        return model.integration_rhs()
    return _built(model, "rhs")


def integration_beam(model):
    """``(y, rate, acceleration) -> dy/dt`` under a prescribed hub motion, ``y = [q,
    q_dot]``: compiled for an exact model on a pinned hub,
    :meth:`flexctl.Model.integration_beam` otherwise.

    Parameters
    ----------
    model : Model
        The model of the run (a pinned hub).
    """
    if not compiles_prescribed(model):
        return model.integration_beam()
    return _built(model, "beam")


def prescribed_torque(model, states, acceleration):
    """The hub torque a prescribed motion needs, N m, shape (P,): the beam's accelerations,
    then the hub equation, both compiled for an exact model on a pinned hub; None where they are not
    (the caller then uses the model's own :meth:`~flexctl.Model.beam_accelerations` and
    :meth:`~flexctl.Model.hub_torque`).

    Parameters
    ----------
    model : Model
        The model of the run.
    states : ndarray, shape (n, P)
        Plant states, in the order of ``model.layout``.
    acceleration : array_like, shape (P,)
        The prescribed hub acceleration at those states, rad/s^2.
    """
    import numpy as np

    if not compiles_prescribed(model):
        return None
    points = np.shape(states)[1]
    along = _torque_along(model, points)
    if along is None:
        return None
    acc = np.asarray(acceleration, dtype=float).reshape(1, points)
    return np.array(along(states, acc)).reshape(points)


def _torque_along(model, points: int):
    """``(states (n, P), acceleration (1, P)) -> torque (1, P)`` from the compiled beam and
    hub equations, for ``points`` points; the last one built is kept with the geometry (a run
    and its accuracy check ask for the same); None where they are not compiled."""
    import casadi as ca

    geometry = model.geometry
    entry = _NATIVE.setdefault(geometry, {})
    kept = entry.get("torque_along")
    if kept is not None and kept[0] == points:
        return kept[1]
    beam, torque = _native(geometry, "beam"), _native(geometry, "torque")
    if beam is None or torque is None:
        return None
    x, acc = ca.MX.sym("x", model.n_states), ca.MX.sym("acceleration")
    _, q, rate, q_dot = model.layout.split(x)
    one = ca.Function("flexctl_torque_along", [x, acc],
                      [torque(x, acc, beam(q, q_dot, rate, acc))])
    along = one.map(points)
    entry["torque_along"] = (points, along)
    return along


def native_dae(dae):
    """An integrator's scalar right-hand side as machine code, with its Jacobian.

    Parameters
    ----------
    dae : casadi.Function
        An SX function of CasADi's integrator signature (``casadi.dyn_in()`` to
        ``casadi.dyn_out()``) with an ODE output only (``z``, ``u``, ``alg``, ``quad`` and
        ``zero`` empty), as :func:`flexctl.sim.compiled.SegmentIntegrator` builds.

    Returns
    -------
    casadi.Function or None
        The same signature and values, computed by a compiled library (numbers lifted into an
        input, :func:`~flexctl.sim.lifted_constants.lift_constants`, so that one library serves
        every model and input of the same structure) that also holds the Jacobian of the ODE
        in ``t``, ``x`` and ``p``: CVODES's Newton iterations call it in one piece. None where
        compiling is off or impossible, or ``dae`` is not such a function or it and its
        Jacobian are longer than :data:`MAX_DAE_INSTRUCTIONS`.
    """
    import casadi as ca

    if (not compiling_enabled() or not isinstance(dae, ca.Function) or not dae.is_a("SXFunction")
            or dae.n_in() != 5 or dae.n_out() != 4
            or any(dae.nnz_in(k) for k in (2, 4)) or any(dae.nnz_out(k) for k in (1, 2, 3))):
        return None
    t, x, p = dae.sx_in(0), dae.sx_in(1), dae.sx_in(3)
    ode = dae(t, x, ca.SX(0, 1), p, ca.SX(0, 1))[0]
    core = ca.Function(f"{dae.name()}_ode", [t, x, p], [ode], ["t", "x", "p"], ["ode"])
    lifted = lift_constants(core, MAX_DAE_INSTRUCTIONS)
    if lifted is None:
        return None
    function, constants = lifted
    jacobian = jacobian_companion(function, fixed=(3,))
    if function.n_instructions() + jacobian.n_instructions() > MAX_DAE_INSTRUCTIONS:
        return None
    built = compiled(function, label=dae.name(), companions=(jacobian,))
    if built is function:
        return None
    tm, xm, pm = (ca.MX.sym(n, dae.sparsity_in(k)) for n, k in (("t", 0), ("x", 1), ("p", 3)))
    empty = ca.MX(0, 1)
    return ca.Function(dae.name(), [tm, xm, empty, pm, empty],
                       [built(tm, xm, pm, ca.DM(constants)), empty, empty, empty],
                       ca.dyn_in(), ca.dyn_out())
