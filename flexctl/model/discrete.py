"""The model over one sample: a discrete-time step ``x_next = F(x, u)`` as a CasADi Function.

:func:`discretize` (``model.discretize(dt, ...)``) holds the input ``u`` over ``dt`` seconds
and integrates the model's CasADi right-hand side (:meth:`flexctl.Model.casadi`):

- ``"rk4"``: ``substeps`` classical Runge-Kutta steps, an explicit expression (differentiable
  to any order, code-generable, for ``Opti``/``nlpsol`` problems and estimators). By default
  the fewest substeps with ``omega_max h <= 0.5`` for the fastest mode ``omega_max`` (rad/s,
  at rest, the hub free to turn), inside RK4's stability interval (``omega h < 2.8``). Its
  accuracy is measured when the step is built: the step against one of twice the substeps
  (Richardson, ``|F_s - F_2s| 16/15``) from probe states (each mode deflected by 1 % of the
  shortest beam, the input alone, both), relative to the largest state entry.
- ``"cvodes"``: SUNDIALS CVODES (BDF) to the relative tolerance ``rtol``, with its forward and
  adjoint sensitivities for derivatives.

The result is a :class:`DiscreteStep`: callable like the CasADi Function it holds (on numbers,
``SX`` or ``MX``), with the step's settings and its stated accuracy.

Examples
--------
>>> import numpy as np, flexctl
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> step = model.discretize(0.01)
>>> step.function.name_in(), step.function.name_out()
(['x', 'u'], ['x_next'])
>>> x0 = np.zeros(model.n_states)
>>> x0[model.layout.q] = 0.01                       # deflected, released under 1 N m
>>> rk4 = np.array(step(x0, 1.0)).ravel()
>>> bdf = np.array(model.discretize(0.01, "cvodes", rtol=1e-10)(x0, 1.0)).ravel()
>>> bool(np.max(np.abs(rk4 - bdf)) <= step.relative_error * np.max(np.abs(bdf)))
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .checks import check_integer, check_real
from .errors import InputValueError

__all__ = ["DiscreteStep", "discretize", "rk4_function", "rk4_step", "METHODS", "OMEGA_H"]

METHODS = ("rk4", "cvodes")
#: Largest ``omega_max h`` of the default RK4 substeps.
OMEGA_H = 0.5
#: Most RK4 substeps (the expression grows with them).
MAX_SUBSTEPS = 1000


def rk4_step(f, t, y, h, end: float = 1.0) -> tuple:
    """One classical RK4 step of ``y' = f(t, y)`` as expressions: ``(y_next, k1)``, the state
    after ``h`` and the first stage's derivative (the rate at the step's start).

    Parameters
    ----------
    f : callable
        ``f(t, y)``, the derivative (CasADi or numpy expressions).
    t : float or casadi.SX or casadi.MX
        The step's start, s.
    y : casadi.SX or casadi.MX or ndarray, shape (n,)
        The state at ``t``.
    h : float or casadi.SX or casadi.MX
        The step, s.
    end : float, optional
        Where in the step the last stage is evaluated, as a fraction of ``h``: 1 (default), or
        just below it for a held input seen from the left.
    """
    k1 = f(t, y)
    k2 = f(t + 0.5 * h, y + 0.5 * h * k1)
    k3 = f(t + 0.5 * h, y + 0.5 * h * k2)
    k4 = f(t + h * end, y + h * k3)
    return y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4), k1


def rk4_function(f, n: int, substeps: int, symbol=None):
    """CasADi ``(x, u, h) -> x(h)``: ``substeps`` RK4 steps of ``f(x, u)`` over ``h`` s with
    ``u`` held; for ``f(x, u, p)``, ``(x, u, h, p) -> x(h)`` with ``p`` held too.

    Parameters
    ----------
    f : casadi.Function
        ``f(x, u) -> xdot`` or ``f(x, u, p) -> xdot`` (e.g. :meth:`flexctl.Model.casadi`).
    n : int
        Number of states, the size of ``x``.
    substeps : int
        RK4 steps over ``h``, >= 1.
    symbol : {casadi.SX, casadi.MX}, optional
        Symbol type of the function built. Default ``casadi.SX``.
    """
    import casadi as ca

    symbol = symbol or ca.SX
    x, u, h = symbol.sym("x", n), symbol.sym("u", f.size1_in(1)), symbol.sym("h")
    extra = [symbol.sym("p", f.size1_in(2))] if f.n_in() > 2 else []
    xk, dt = x, h / substeps
    for _ in range(substeps):
        xk = rk4_step(lambda _, state: f(state, u, *extra), 0.0, xk, dt)[0]
    return ca.Function("rk4_hold", [x, u, h, *extra], [xk], ["x", "u", "h"]
                       + ["p"] * len(extra), ["xf"])


@dataclass(frozen=True, eq=False)
class DiscreteStep:
    """A model held over one sample (module docstring).

    Called, and asked any :class:`casadi.Function` method (``name_in``, ``generate``,
    ``jacobian``, ``map``, ...), it is its :attr:`function`; pass :attr:`function` itself
    where a ``casadi.Function`` instance is required.

    Attributes
    ----------
    function : casadi.Function
        ``(x (n,), u (1,)) -> x_next (n,)``, named inputs ``x``, ``u`` and output ``x_next``.
    dt : float
        s.
    method : {"rk4", "cvodes"}
    substeps : int or None
        RK4 steps per sample (None for cvodes).
    rtol : float or None
        CVODES relative tolerance (None for rk4).
    fastest_frequency : float
        The fastest mode at rest (hub free to turn), rad/s.
    relative_error : float
        The stated accuracy of one step: the largest error over the probe states relative to
        the largest state entry, measured by step doubling (rk4), or ``rtol`` (cvodes).
    """

    function: object
    dt: float
    method: str
    substeps: int | None
    rtol: float | None
    fastest_frequency: float
    relative_error: float

    def __call__(self, *args, **kwargs):
        return self.function(*args, **kwargs)

    def __getattr__(self, name):
        # every casadi.Function method (name_in, generate, jacobian, expand, ...) on the step
        if name.startswith("__") or name == "function":
            raise AttributeError(name)
        return getattr(self.function, name)

    def map(self, *args, **kwargs):
        """:meth:`casadi.Function.map` of :attr:`function`.

        Parameters
        ----------
        *args, **kwargs : int, str, list or dict
            As :meth:`casadi.Function.map` takes them, e.g. ``map(10)`` or
            ``map(10, "thread", 2)``: the number of evaluations, the parallelization and its
            options.
        """
        return self.function.map(*args, **kwargs)

    def __repr__(self):
        how = (f"{self.substeps} RK4 substeps" if self.method == "rk4"
               else f"CVODES rtol {self.rtol:g}")
        return (f"DiscreteStep(dt={self.dt:g} s, {how}, fastest mode "
                f"{self.fastest_frequency:.4g} rad/s, relative error about "
                f"{self.relative_error:.2g} a step)")


def _fastest(model) -> float:
    """The fastest mode at rest with the hub free to turn, rad/s (0 without modes)."""
    omega = np.asarray(model.natural_frequencies(0.0, hub="free"), dtype=float)
    return float(np.max(np.abs(omega))) if omega.size else 0.0


def _probes(model) -> list:
    """``(x, u)`` probe states: each mode deflected by 1 % of the shortest beam, the input
    alone from rest, and both."""
    layout, n = model.layout, model.n_states
    lengths = np.atleast_1d(np.asarray(getattr(model, "lengths", [1.0]), dtype=float))
    scale = 0.01 * float(np.min(lengths)) if lengths.size else 0.01
    modal = np.arange(n)[layout.q]
    probes = []
    for k in modal:
        x = np.zeros(n)
        x[k] = scale
        probes.append((x, 0.0))
    all_modes = np.zeros(n)
    all_modes[modal] = scale
    return probes + [(np.zeros(n), 1.0), (all_modes, 1.0)]


def _richardson(model, hold, finer, dt) -> float:
    """The step's error relative to the largest state entry, largest over ``_probes``."""
    worst = 0.0
    for x, u in _probes(model):
        coarse = np.array(hold(x, u, dt), dtype=float).ravel()
        fine = np.array(finer(x, u, dt), dtype=float).ravel()
        size = float(np.max(np.abs(fine)))
        if size > 0.0:
            worst = max(worst, float(np.max(np.abs(coarse - fine))) * 16.0 / 15.0 / size)
    return worst


def discretize(model, dt, method: str = "rk4", substeps=None, rtol: float = 1e-8,
               parameters=None) -> DiscreteStep:
    """The model's step over ``dt`` s with the input held (module docstring).

    Parameters
    ----------
    model : flexctl.Model
        The model stepped (any variant; an actuated model's input is its command).
    dt : float
        Sample time, s (> 0).
    method : {"rk4", "cvodes"}, optional
        RK4 substeps (default) or SUNDIALS CVODES.
    substeps : int, optional
        RK4 steps per sample (1 to 1000); default the fewest with ``omega_max h <= 0.5``.
    rtol : float, optional
        CVODES relative tolerance (1e-14 to 1e-2); absolute tolerance ``1e-3 rtol``.
        Default 1e-8.
    parameters : list of str, optional
        Physical parameters (scene keys) as a third input ``p``: ``(x, u, p) -> x_next``
        (:meth:`flexctl.Model.casadi` with ``parameters``).

    Raises
    ------
    InputValueError
        For a bad ``dt``, ``method``, ``substeps`` or ``rtol``, or explicit substeps that put
        the fastest mode outside RK4's stability interval (``omega h > 2.8``).
    """
    import casadi as ca

    dt = check_real("discretize", "dt", dt, minimum=0.0, strict=True)
    if method not in METHODS:
        raise InputValueError(f"discretize method must be one of {', '.join(METHODS)}; got "
                              f"{method!r}")
    n, f = model.n_states, model.casadi(parameters)
    omega = _fastest(model)
    x, u = ca.SX.sym("x", n), ca.SX.sym("u", f.size1_in(1))
    extra = [ca.SX.sym("p", f.size1_in(2))] if parameters is not None else []
    names = ["x", "u"] + ["p"] * len(extra)
    if method == "rk4":
        auto = max(1, math.ceil(omega * dt / OMEGA_H))
        steps = auto if substeps is None else check_integer(
            "discretize", "substeps", substeps, minimum=1, maximum=MAX_SUBSTEPS)
        if steps > MAX_SUBSTEPS:
            raise InputValueError(
                f"discretize: dt = {dt:g} s needs {steps} RK4 substeps for the fastest mode "
                f"({omega:.4g} rad/s), more than {MAX_SUBSTEPS}; use method='cvodes' or fewer "
                "modes")
        if omega * dt / steps > 2.8:
            raise InputValueError(
                f"discretize substeps = {steps} put the fastest mode ({omega:.4g} rad/s) at "
                f"omega h = {omega * dt / steps:.3g}, outside RK4's stability interval (2.8); "
                f"use at least {math.ceil(omega * dt / 2.8)}")
        hold = rk4_function(f, n, steps)
        x_next = hold(x, u, dt, *extra)
        error = _richardson(model, rk4_function(model.casadi(), n, steps),
                            rk4_function(model.casadi(), n, 2 * steps), dt)
        tolerance = None
    else:
        if substeps is not None:
            raise InputValueError("discretize substeps is for method='rk4'; CVODES chooses "
                                  "its own steps (set rtol)")
        tolerance = check_real("discretize", "rtol", rtol, minimum=1e-14, maximum=1e-2)
        held = ca.vertcat(u, *extra)
        integrator = ca.integrator("flexctl_cvodes_step", "cvodes",
                                   {"x": x, "p": held, "ode": f(x, u, *extra)}, 0.0, dt,
                                   {"reltol": tolerance, "abstol": 1e-3 * tolerance})
        xs, us = ca.MX.sym("x", n), ca.MX.sym("u", f.size1_in(1))
        ps = [ca.MX.sym("p", f.size1_in(2))] if extra else []
        function = ca.Function(f"flexctl_{model.variant}_step", [xs, us, *ps],
                               [integrator(x0=xs, p=ca.vertcat(us, *ps))["xf"]], names,
                               ["x_next"])
        return DiscreteStep(function, dt, method, None, tolerance, omega, tolerance)
    function = ca.Function(f"flexctl_{model.variant}_step", [x, u, *extra], [x_next], names,
                           ["x_next"])
    return DiscreteStep(function, dt, method, steps, tolerance, omega, error)
