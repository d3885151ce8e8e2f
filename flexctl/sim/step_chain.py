"""A loop of ``count`` calls of a step function whose constant inputs are shared by every call.

CasADi's ``Function.mapaccum`` maps every input that is not accumulated: called with one
column where it expects ``count``, it copies that column ``count`` times before the loop
starts (``repmat`` in the generated code). For a step function whose inputs carry a sampled
input's table or a model's lifted numbers (thousands of numbers), that copy costs more than
the steps themselves. :func:`step_chain` builds the same loop (nested calls in base 10, so that
the generated code holds each level's body once) with the constant inputs passed by reference
to every call.
"""

from __future__ import annotations

import numbers
from typing import Sequence

__all__ = ["step_chain", "skippable"]

#: Calls per level of the nested loop (as CasADi's ``mapaccum``).
BASE = 10


def step_chain(step, count: int, name: str, stacked: Sequence[int] = ()):
    """``count`` calls of ``step`` in sequence, its first output fed to its first input.

    Parameters
    ----------
    step : casadi.Function
        ``step(x, a_1, ..., a_m) -> (x_next, o_1, ..., o_n)``: the first output has the first
        input's shape; every input and output a column vector.
    count : int
        Number of calls (>= 1).
    name : str
        Name of the returned function.
    stacked : sequence of int, optional
        Indices (>= 1) of the inputs that differ from call to call: the returned function
        takes them as ``count`` columns, one per call. Every other input after the first is
        the same for every call and is taken once.

    Returns
    -------
    casadi.Function
        ``chain(x, a_1, ..., a_m) -> (X, O_1, ..., O_n)``, its inputs and outputs named as
        ``step``'s; ``X`` and each ``O_k`` hold one column per call, in order (``X[:, -1]`` is
        the state after the last call).

    Raises
    ------
    TypeError
        If ``step`` is not a CasADi function.
    ValueError
        If ``name`` is not a valid function name, ``count`` is not a positive integer, an
        index of ``stacked`` is not an input after the first, or the first output's shape is
        not the first input's.
    """
    import casadi as ca

    if not isinstance(step, ca.Function):
        raise TypeError(f"step must be a casadi.Function, got {type(step).__name__}")
    if not isinstance(name, str) or not ca.Function.check_name(name):
        raise ValueError(f"name must be a valid CasADi function name, got {name!r}")
    if isinstance(count, bool) or not isinstance(count, numbers.Integral) or count < 1:
        raise ValueError(f"count must be a positive integer, got {count!r}")
    count = int(count)
    if step.n_out() < 1 or step.sparsity_out(0).shape != step.sparsity_in(0).shape:
        raise ValueError(f"{step.name()}'s first output must have its first input's shape "
                         f"{step.sparsity_in(0).shape}, got "
                         f"{step.sparsity_out(0).shape if step.n_out() else 'no output'}")
    given = stacked
    try:
        stacked = frozenset(stacked)
    except TypeError:
        stacked = None
    if stacked is None or not stacked <= set(range(1, step.n_in())):
        raise ValueError(f"stacked must index inputs 1..{step.n_in() - 1} of {step.name()}, "
                         f"got {given!r}")
    # the loop's pieces: `count` in base 10 -> that many calls of each level
    calls, level, size, left = [], step, 1, count
    while True:
        calls += [(level, size)] * (left % BASE)
        left //= BASE
        if not left:
            break
        # ten calls of the level below as one function
        level = _sequence(level, [(level, size)] * BASE, stacked,
                          f"{step.name()}_x{size * BASE}", size)
        size *= BASE
    return _sequence(step, calls, stacked, name)


def _sequence(f, calls, stacked, name: str, size: int = 1):
    """One function calling ``calls`` (each ``(function, its number of steps)``) in order, with
    the argument signature of ``f`` (whose stacked inputs span ``size`` steps) widened to
    every step of the sequence."""
    import casadi as ca

    total = sum(n for _, n in calls)
    args = [ca.MX.sym(f.name_in(k), f.size1_in(k), total * f.size2_in(k) // size
                      if k in stacked else f.size2_in(k)) for k in range(f.n_in())]
    x, outputs, done = args[0], [[] for _ in range(f.n_out())], 0
    for g, n in calls:
        call = [x] + [args[k][:, done:done + n] if k in stacked else args[k]
                      for k in range(1, f.n_in())]
        result = g.call(call)                # a list, of one output too
        for k, value in enumerate(result):
            outputs[k].append(value)
        x = result[0][:, -1]
        done += n
    return ca.Function(name, args, [ca.horzcat(*o) for o in outputs],
                       f.name_in(), f.name_out())


def skippable(step, skip, idle, name: str):
    """``step`` where ``skip`` is false, else ``idle``, the skipped branch never evaluated
    (CasADi's ``Function.conditional``): the body of a chain whose last calls may have nothing
    left to do.

    Parameters
    ----------
    step : casadi.Function
        The step, every input and output a column vector.
    skip : callable
        ``skip(*inputs)``: an MX expression, nonzero where the step is skipped.
    idle : callable
        ``idle(*inputs)``: the list of outputs of a skipped step (MX expressions of the
        step's shapes; its first, the state passed through).
    name : str
        Prefix of the functions built: ``<name>_idle``, ``<name>_switch`` and
        ``<name>_body`` (returned).

    Returns
    -------
    casadi.Function
        ``<name>_body``, with ``step``'s inputs and outputs.
    """
    import casadi as ca

    def inputs():
        return [ca.MX.sym(step.name_in(k), step.sparsity_in(k)) for k in range(step.n_in())]

    symbols = inputs()
    switch = ca.Function.conditional(f"{name}_switch", [step],
                                     ca.Function(f"{name}_idle", symbols, idle(*symbols)))
    symbols = inputs()
    return ca.Function(f"{name}_body", symbols, switch(skip(*symbols), *symbols))
