"""A design model's dynamics for the optimisers, compiled with their derivatives.

IPOPT's callbacks in a trajectory optimisation (:mod:`controllers.slew.trajopt`) evaluate the
design model's dynamics, their Jacobian and the Hessian of the Lagrangian at every collocation
point of every iteration. For the exact variant these dominate: on CasADi's virtual machine
they took 93 % of a two-array slew's 17 s solve. :func:`design_dynamics` returns the model's
``(x, u) -> xdot`` whose value, first derivatives and second derivatives run as machine code
from the persistent cache (:mod:`flexctl.sim.compile_cache`): one library per structure (its
numbers are lifted into an input, :func:`~flexctl.sim.lifted_constants.lift_constants`) holding
the function and the derivative functions CasADi's algorithmic differentiation asks for
(:func:`~flexctl.sim.compiled_derivatives.with_derivatives`). The other variants' dynamics, a few
hundred operations, are compiled the same way: on CasADi's virtual machine the calls and the
derivative graphs around them cost more than the arithmetic. A multiple-shooting hold (RK4
substeps of the dynamics) is compiled as one function (:func:`with_compiled_derivatives`).

Where compiling is off or impossible, or the dynamics are longer than
:data:`MAX_INSTRUCTIONS`, the model's own :meth:`~flexctl.Model.casadi` is returned.
"""

from __future__ import annotations

import weakref

from flexctl.model.checks import check_integer
from flexctl.sim.compile_cache import compiled
from flexctl.sim.compiled_derivatives import with_derivatives
from flexctl.sim.lifted_constants import lift_constants

__all__ = ["design_dynamics", "with_compiled_derivatives", "MAX_INSTRUCTIONS", "MAX_LIBRARY",
           "MAX_HOLD_LIBRARY"]

#: Longest dynamics compiled with their derivatives, instructions. The Hessian's code is about
#: ten times longer: the exact two-array design model (2 modes per array, free hub: 9 900
#: instructions, Hessian 109 000) makes a library of 218 000 (see :data:`MAX_LIBRARY`).
MAX_INSTRUCTIONS = 12_000
#: Longest library (the function and its derivatives) compiled by default, instructions: the
#: exact two-array design model (2 modes per array) makes 218 000, about 15 s of ``-Og``, once,
#: for IPOPT callbacks ten times faster.
MAX_LIBRARY = 250_000
#: Longest library of an RK4 hold: a hold of many substeps has a Hessian far longer than its
#: dynamics' (two arrays, first order, 6 substeps: 6 100 instructions, Hessian 262 000, 39 s
#: to compile), and its substeps can call the compiled dynamics instead
#: (:func:`controllers.slew.slew_nlp.transcribe`).
MAX_HOLD_LIBRARY = 120_000

_BUILT: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def design_dynamics(model):
    """``(x, u) -> xdot`` of ``model`` for an optimiser, compiled with its first and second
    derivatives (:func:`with_compiled_derivatives` of :meth:`flexctl.Model.casadi`).

    Parameters
    ----------
    model : flexctl.Model
        A design model (one beam or a structure, any variant).

    Returns
    -------
    casadi.Function
        Inputs ``x`` (n,) and ``u`` (1,), output ``xdot`` (n,), as :meth:`~flexctl.Model.casadi`.
    """
    if model not in _BUILT:
        _BUILT[model] = with_compiled_derivatives(model.casadi())
    return _BUILT[model]


def with_compiled_derivatives(function, max_library: int = MAX_LIBRARY):
    """An SX ``function`` as an MX function of the same inputs and outputs that calls its
    compiled form, whose value, Jacobian and second derivatives run as machine code; or
    ``function`` itself where compiling is off or impossible, it is longer than
    ``MAX_INSTRUCTIONS`` or not SX, or its library would be longer than ``max_library``
    instructions.

    Its numbers are lifted into an input (:func:`~flexctl.sim.lifted_constants.lift_constants`),
    so that one library serves every function of the same structure.

    Parameters
    ----------
    function : casadi.Function
        The function to compile, e.g. ``(x, u) -> xdot`` of :meth:`flexctl.Model.casadi` or
        an RK4 hold.
    max_library : int, optional
        Longest library (the function and its derivatives) to compile, instructions (>= 0).
        Default :data:`MAX_LIBRARY`.
    """
    import casadi as ca

    max_library = check_integer("with_compiled_derivatives", "max_library", max_library,
                                minimum=0)
    lifted = lift_constants(function, MAX_INSTRUCTIONS)
    if lifted is None:
        return function
    inner, constants = lifted
    companions = with_derivatives(inner, fixed=(inner.n_in() - 1,))
    if sum(f.n_instructions() for f in (inner, *companions)) > max_library:
        return function
    built = compiled(inner, label=f"{function.name()} and its derivatives",
                     companions=companions, options={"jac_penalty": -1})
    if built is inner:                  # compiling is off, impossible or failed
        return function
    args = [ca.MX.sym(function.name_in(k), function.sparsity_in(k))
            for k in range(function.n_in())]
    return ca.Function(f"{function.name()}_native", args, [built(*args, ca.DM(constants))],
                       function.name_in(), function.name_out())
