"""Companions that give a compiled CasADi function its derivatives.

A function loaded from a library (:func:`flexctl.sim.compile_cache.compiled`) is
differentiable only through the functions compiled with it: ``jac_<name>``,
``adj1_<name>`` and ``jac_adj1_<name>`` (CasADi's names for the Jacobian, the reverse sweep
and its Jacobian). :func:`with_derivatives` builds the three, :func:`jacobian_companion`
the first alone; both leave out the inputs held constant (the lifted constants of
:func:`flexctl.sim.lifted_constants.lift_constants`), whose blocks are structurally zero.
"""

from __future__ import annotations

__all__ = ["with_derivatives", "jacobian_companion"]


def with_derivatives(function, fixed=()):
    """The companions of ``function`` that give its compiled form first and second
    derivatives (see :func:`~flexctl.sim.compile_cache.compiled`).

    Built in SX like CasADi's own ``jacobian()``, ``reverse(1)`` and
    ``reverse(1).jacobian()``, except that the inputs listed in ``fixed`` (the constants of
    :func:`~flexctl.sim.lifted_constants.lift_constants`, say) are not differentiated: their blocks are structurally zero,
    which spares the Jacobians thousands of columns that no caller asks for.

    Parameters
    ----------
    function : casadi.Function
        An SX function with dense inputs.
    fixed : sequence of int, optional
        Inputs held constant.

    Returns
    -------
    tuple of casadi.Function
        ``(jac_<name>, adj1_<name>, jac_adj1_<name>)``. With these in its library, a compiled
        function's forward derivatives come from ``jac_<name>``, its reverse ones from
        ``adj1_<name>`` (with the option ``jac_penalty = -1``), and the derivatives of those
        (an optimiser's exact Hessian) from ``jac_adj1_<name>``.

    Examples
    --------
    >>> import casadi as ca
    >>> x, c = ca.SX.sym("x", 2), ca.SX.sym("c")
    >>> f = ca.Function("doc_f", [x, c], [c * x[0] * x[1]], ["x", "c"], ["y"])
    >>> [g.name() for g in with_derivatives(f, fixed=(1,))]
    ['jac_doc_f', 'adj1_doc_f', 'jac_adj1_doc_f']
    """
    import casadi as ca
    import numpy as np

    free = _free_inputs(function, fixed)
    name, n_in = function.name(), function.n_in()
    jac, inputs, outs, z, stacked, jz = _jacobian_parts(function, free)
    out_names = [f"out_{o}" for o in function.name_out()]
    seeds = [ca.SX.sym(f"adj_{o}", function.sparsity_out(k))
             for k, o in enumerate(function.name_out())]
    weighted = ca.dot(ca.vertcat(*[ca.vec(seed) for seed in seeds]), stacked)
    gradient = ca.gradient(weighted, z)                  # reverse mode: one sweep
    offsets = np.cumsum([0] + [inputs[k].numel() for k in free])
    span = dict(zip(free, zip(offsets[:-1], offsets[1:])))
    sensitivities = [ca.reshape(ca.densify(gradient[int(span[k][0]):int(span[k][1])]),
                                inputs[k].shape) if k in free else ca.SX.zeros(inputs[k].shape)
                     for k in range(n_in)]
    adj_in = inputs + outs + seeds
    adj_in_names = function.name_in() + out_names + [f"adj_{o}" for o in function.name_out()]
    adj_out_names = [f"adj_{i}" for i in function.name_in()]
    adj = ca.Function(f"adj1_{name}", adj_in, sensitivities, adj_in_names, adj_out_names,
                      {"cse": True})
    # the sensitivities' Jacobian: the Lagrangian's Hessian in the free inputs, and the
    # transposed Jacobian in the seeds (the same expressions as jac_<name>'s)
    hessian, columns = ca.hessian(weighted, z)[0], z.numel() + stacked.numel()
    rows = [ca.horzcat(hessian[int(span[k][0]):int(span[k][1]), :],
                       jz.T[int(span[k][0]):int(span[k][1]), :]) if k in free
            else ca.SX(inputs[k].numel(), columns) for k in range(n_in)]
    adj_outs = [ca.SX.sym(f"out_{o}", adj.sparsity_out(k)) for k, o in enumerate(adj_out_names)]
    jac_adj = _jacobian_function(
        f"jac_adj1_{name}", adj_in + adj_outs, adj_in_names + [f"out_{o}" for o in adj_out_names],
        adj_out_names, free + [len(inputs) + len(outs) + j for j in range(len(seeds))],
        ca.vertcat(*rows), [inputs[k].numel() for k in range(n_in)])
    return jac, adj, jac_adj


def jacobian_companion(function, fixed=()):
    """``jac_<name>``, the first companion of :func:`with_derivatives` alone: enough for a
    compiled function whose callers take first derivatives only (an integrator's Newton
    iterations).

    Parameters
    ----------
    function : casadi.Function
        An SX function with dense inputs.
    fixed : sequence of int, optional
        Inputs held constant: their Jacobian blocks are structurally zero. Default none.

    Returns
    -------
    casadi.Function
        ``jac_<name>``, with CasADi's ``jacobian()`` signature.

    Examples
    --------
    >>> import casadi as ca
    >>> x, c = ca.SX.sym("x", 2), ca.SX.sym("c")
    >>> f = ca.Function("doc_g", [x, c], [c * x[0] * x[1]], ["x", "c"], ["y"])
    >>> jacobian_companion(f, fixed=(1,)).name_out()
    ['jac_y_x', 'jac_y_c']
    """
    return _jacobian_parts(function, _free_inputs(function, fixed, "jacobian_companion"))[0]


def _jacobian_parts(function, free: list) -> tuple:
    """``jac_<name>`` of ``function`` in its ``free`` inputs, with what it is made of: the
    symbolic inputs, the nominal outputs' symbols, the stacked free inputs, the stacked
    outputs and their Jacobian."""
    import casadi as ca

    inputs = function.sx_in()
    outputs = function.call(inputs)
    out_names = [f"out_{o}" for o in function.name_out()]
    outs = [ca.SX.sym(o, function.sparsity_out(k)) for k, o in enumerate(out_names)]
    z = ca.vertcat(*[ca.vec(inputs[k]) for k in free])
    stacked = ca.vertcat(*[ca.vec(o) for o in outputs])
    jz = ca.jacobian(stacked, z)
    jac = _jacobian_function(f"jac_{function.name()}", inputs + outs,
                             function.name_in() + out_names, function.name_out(), free, jz,
                             [o.numel() for o in outputs])
    return jac, inputs, outs, z, stacked, jz


def _free_inputs(function, fixed, owner: str = "with_derivatives") -> list:
    """The inputs of ``function`` that :func:`with_derivatives` (or ``owner``)
    differentiates: all but ``fixed``, after checking both."""
    import casadi as ca

    from ..model.checks import check_integer
    from ..model.errors import InputTypeError, InputValueError

    if not isinstance(function, ca.Function) or not function.is_a("SXFunction"):
        raise InputTypeError(f"{owner}: function must be an SX casadi.Function; got "
                             f"{type(function).__name__}")
    n_in = function.n_in()
    if not all(function.sparsity_in(k).is_dense() for k in range(n_in)):
        raise InputValueError(f"{owner}: every input of function must be dense")
    if isinstance(fixed, (str, bytes)) or not hasattr(fixed, "__iter__"):
        raise InputTypeError(f"{owner}: fixed must be a sequence of input indices; "
                             f"got {fixed!r}")
    held = {check_integer(owner, "fixed", k, minimum=0, maximum=n_in - 1)
            for k in fixed}
    return [k for k in range(n_in) if k not in held]


def _jacobian_function(name: str, inputs: list, in_names: list, out_names: list, free: list,
                       whole, heights: list):
    """``name(*inputs) -> jac_<o>_<i>`` for every output ``o`` (of ``heights`` entries) and
    every input ``i`` but the trailing nominal outputs (CasADi's Jacobian signature): the
    blocks of ``whole``, the Jacobian of the stacked outputs in the stacked ``free`` inputs,
    and structurally zero in the other inputs."""
    import casadi as ca
    import numpy as np

    differentiated = len(inputs) - len(out_names)        # the rest are the nominal outputs
    rows = np.cumsum([0] + list(heights))
    columns = dict(zip(free, np.cumsum([0] + [inputs[k].numel() for k in free])))
    blocks, names = [], []
    for j, out_name in enumerate(out_names):
        for k, in_name in enumerate(in_names[:differentiated]):
            width = inputs[k].numel()
            blocks.append(whole[int(rows[j]):int(rows[j + 1]),
                                int(columns[k]):int(columns[k]) + width] if k in free
                          else ca.SX(int(rows[j + 1] - rows[j]), width))
            names.append(f"jac_{out_name}_{in_name}")
    # common subexpressions eliminated: a fifth fewer instructions in the exact model's
    # Lagrangian Hessian, whose forward-over-reverse sweeps repeat many products
    return ca.Function(name, inputs, blocks, in_names, names, {"cse": True})
