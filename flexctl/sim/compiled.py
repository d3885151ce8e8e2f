"""Compiled integration: the whole right-hand side in CasADi, integrated by SUNDIALS CVODES.

When every input of a run can be written as a CasADi expression (the built-in manoeuvres, and
controllers that offer ``casadi_torque``), the integration runs inside CVODES (variable-order BDF
with Newton iterations on the exact, symbolically derived Jacobian), with no Python call per step.
:func:`flexctl.simulate` uses this path by default and falls back to SciPy for Python inputs and
to locate the exact time at which a run stops.

States are scaled by their physical size before integration, so one absolute tolerance serves
angles, rates and modal coordinates alike.

Controllers join through ``casadi_torque(t, x)`` (static laws) or ``casadi_torque(t, x, z)``
and ``casadi_derivative(t, x, z)`` (laws with internal states ``z``, integrated with the
plant): CasADi expressions of the time symbol ``t`` and the plant's state vector ``x``
(``[theta, q_1..q_N, theta_dot, q_1_dot..q_N_dot]`` of the *plant*, whatever the design model),
equal to the numpy ``torque`` and ``derivative`` of the same law. Saturation is ``fmin`` /
``fmax`` (the exact law); jumps in time (holds, reference ends) stay at the ``breakpoints``
where the integration restarts, and each segment's inputs are evaluated at most at its own
last time.

Each segment is integrated in its own time ``tau = (t - t_0) / h`` in [0, 1], with ``t_0``,
``h`` and the last input time as parameters, so one right-hand side and one integrator per
pattern of output times serve every segment; both are kept (:data:`RHS_CACHE_SIZE`,
``INTEGRATOR_CACHE_SIZE``) for later runs with the same model and inputs, when those are
immutable (frozen dataclasses, as the built-in ones are).
"""

from __future__ import annotations

import copy
from collections import OrderedDict

import numpy as np

from ..model.exports import MATRIX_FORM_MODES, symbolic_beam_dynamics, symbolic_dynamics
from ..model.errors import InputValueError
from .buffers import InPlace
from .native_rhs import compiles_prescribed, integration_beam, integration_rhs, native_dae

__all__ = ["is_symbolic", "piecewise_constant", "torque_history", "SegmentIntegrator",
           "integrate_segments", "numeric_rhs", "check_run", "start_check",
           "segment_integrators", "run_segments"]


def _has_form(source, method: str) -> bool:
    """``source`` offers a callable ``method`` and does not disown it (``has_casadi_form``)."""
    return callable(getattr(source, method, None)) and bool(getattr(source, "has_casadi_form",
                                                                    True))


def is_symbolic(torque=None, hub_motion=None, controller=None) -> bool:
    """True when every given input offers a CasADi form.

    A torque needs ``casadi(t)`` (``casadi(t, x)`` when it declares ``state_dependent =
    True``, e.g. a traced ``f(t, x)``), a hub motion ``casadi(t) -> (rate, acceleration)``, a
    controller ``casadi_torque(t, x)`` (static, ``n_states == 0``) or ``casadi_torque(t, x, z)``
    and ``casadi_derivative(t, x, z)`` (with internal states ``z``). An object whose form
    depends on what it wraps (a shaped command, a reference) says whether it has one with a
    ``has_casadi_form`` attribute (default True).

    Parameters
    ----------
    torque, hub_motion, controller : object or None, optional
        The run's inputs, as :func:`flexctl.simulate` takes them; None is not looked at.
    """
    if torque is not None and not _has_form(torque, "casadi"):
        return False
    if hub_motion is not None and not _has_form(hub_motion, "casadi"):
        return False
    if controller is not None:
        if not _has_form(controller, "casadi_torque"):
            return False
        if getattr(controller, "n_states", 0) and not callable(
                getattr(controller, "casadi_derivative", None)):
            return False
    return True


def piecewise_constant(t, edges, values):
    """CasADi ``values[k]`` for ``t`` past ``k`` of the ``edges``: the zero-order hold.

    Parameters
    ----------
    t : casadi.SX or casadi.MX
        Scalar time, s.
    edges : array_like, shape (K - 1,)
        Ascending interior boundaries, s; hold ``k`` is ``edges[k-1] <= t < edges[k]``
        (``bisect.bisect_right(edges, t)``), the first and last holds extend to infinity.
    values : array_like, shape (K,) or (K, m)
        The value held in each of the K holds (a row of m numbers per hold), in the unit of
        the quantity held.

    Returns
    -------
    casadi.SX or casadi.MX (as ``t``), shape (m, 1)
        Exactly one of the rows of ``values`` (a chain of ``if_else``, no arithmetic on them);
        a constant ``DM`` when there is one hold only.
    """
    import casadi as ca

    values = np.asarray(values, dtype=float)
    rows = values.reshape(values.shape[0], -1)
    edges = np.asarray(edges, dtype=float).reshape(-1)
    if edges.size != rows.shape[0] - 1:
        raise InputValueError(f"piecewise_constant needs {rows.shape[0] - 1} edges for "
                              f"{rows.shape[0]} values; got {edges.size}")
    passed = [t >= float(e) for e in edges]
    out = ca.DM(rows[0])
    for k in range(1, rows.shape[0]):
        out = ca.if_else(passed[k - 1], ca.DM(rows[k]), out)
    return out


def _parametric(source) -> bool:
    """An input whose numbers enter its CasADi form as parameters, so that inputs differing
    only in numbers share one compiled function: it offers ``casadi_parameters``
    (``(structure, values)``) and takes the values as symbols, ``casadi(t, parameters)`` (a
    torque or hub motion) or ``casadi_torque(t, x, parameters)`` (a static controller)."""
    return (source is not None and not getattr(source, "n_states", 0)
            and not getattr(source, "state_dependent", False)
            and getattr(source, "casadi_parameters", None) is not None)


def _parameter_values(source) -> np.ndarray:
    """The numbers of a parametric input (``_parametric``), else none."""
    if not _parametric(source):
        return np.zeros(0)
    return np.asarray(source.casadi_parameters[1], dtype=float).reshape(-1)


def input_numbers(inputs) -> np.ndarray:
    """The numbers of ``inputs = (torque, hub_motion, controller)``, in that order: the
    parameter vector ``c`` of their compiled functions.

    Parameters
    ----------
    inputs : tuple
        ``(torque, hub_motion, controller)``, each None or an input as
        :func:`flexctl.simulate` takes it; only the parametric ones (with
        ``casadi_parameters``) have numbers.

    Returns
    -------
    ndarray, shape (C,)
        Their numbers concatenated; empty when none is parametric.
    """
    return np.concatenate([_parameter_values(source) for source in inputs])


def split_numbers(inputs, c) -> list:
    """``c`` (a CasADi symbol laid out as :func:`input_numbers`) cut into each input's part
    (None for an input without parameters).

    Parameters
    ----------
    inputs : tuple
        ``(torque, hub_motion, controller)``, each None or an input as
        :func:`flexctl.simulate` takes it.
    c : casadi.SX or casadi.MX, shape (C, 1)
        The numbers of the parametric inputs, in the order of :func:`input_numbers`.

    Returns
    -------
    list
        Three entries: each input's slice of ``c``, or None.
    """
    parts, start = [], 0
    for source in inputs:
        size = _parameter_values(source).size
        parts.append(c[start:start + size] if _parametric(source) else None)
        start += size
    return parts


def _applied_torque(t, x, z, torque, controller, parameters=(None, None)):
    """CasADi hub torque of ``torque`` plus ``controller``; ``parameters`` holds each one's
    numbers as symbols (:func:`split_numbers`; None: its numbers are constants)."""
    u = 0.0
    torque_numbers, controller_numbers = parameters
    if torque is not None:
        if getattr(torque, "state_dependent", False):
            u = u + torque.casadi(t, x)
        elif torque_numbers is not None:
            u = u + torque.casadi(t, torque_numbers)
        else:
            u = u + torque.casadi(t)
    if controller is None:
        return u
    if getattr(controller, "n_states", 0):
        return u + controller.casadi_torque(t, x, z)
    if controller_numbers is not None:
        return u + controller.casadi_torque(t, x, controller_numbers)
    return u + controller.casadi_torque(t, x)


def hub_motion_casadi(hub_motion, t, parameters=None) -> tuple:
    """Rate and acceleration of a hub motion on the symbol ``t`` (its numbers the symbols
    ``parameters`` where given).

    Parameters
    ----------
    hub_motion : object
        A hub motion with a CasADi form: ``casadi(t)``, or ``casadi(t, parameters)`` when it is
        parametric.
    t : casadi.SX or casadi.MX
        Scalar time, s.
    parameters : casadi.SX or casadi.MX, optional
        The hub motion's numbers as symbols (its part of :func:`split_numbers`); None: its
        numbers are constants.

    Returns
    -------
    tuple
        ``(rate, acceleration)``, CasADi expressions in rad/s and rad/s^2.
    """
    if parameters is not None:
        return hub_motion.casadi(t, parameters)
    return hub_motion.casadi(t)


def drive_size(model, hub_motion=None, controller=None) -> int:
    """Length of the state a run integrates: the beam's alone under a prescribed hub motion,
    else the plant's and the controller's.

    Parameters
    ----------
    model : Model
        The model of the run.
    hub_motion : object, optional
        The prescribed hub motion, if any.
    controller : object, optional
        The controller; its ``n_states`` internal states are integrated with the plant.
    """
    if hub_motion is not None:
        return model.layout.without_rotation().n_states
    return model.n_states + int(getattr(controller, "n_states", 0) or 0)


def closed_loop_dynamics(model, t, y, torque, controller, parameters=None, rhs=None):
    """CasADi ``d[x, z]/dt`` of the plant ``x`` under ``torque`` and ``controller``, whose
    internal states ``z`` (if any) follow ``casadi_derivative``. On SX symbols the model is
    inlined; on MX (the exact model's fixed-step step) it enters through ``rhs``, whose code
    does not grow with the quadrature.

    Parameters
    ----------
    model : Model
        The model of the plant, with ``n`` states.
    t : casadi.SX or casadi.MX
        Scalar time, s.
    y : casadi.SX or casadi.MX, shape (m, 1)
        The drive's state ``[x, z]``: the plant's ``n`` states, then the controller's.
    torque, controller : object or None
        The run's inputs, with CasADi forms (:func:`is_symbolic`).
    parameters : casadi.SX or casadi.MX, optional
        The symbol of their numbers (:func:`input_numbers` of ``(torque, None, controller)``);
        None: their numbers are constants.
    rhs : casadi.Function, optional
        ``(x, u) -> xdot``, used on MX only: a call of the model's scalar form, its numbers an
        input. Default :meth:`flexctl.Model.integration_rhs`.

    Returns
    -------
    casadi.SX or casadi.MX, shape (m, 1)
    """
    import casadi as ca

    u, dz = drive_terms(model, t, y, torque, controller, parameters)
    x = y[:model.n_states]
    if isinstance(x, ca.MX):
        dx = (model.integration_rhs() if rhs is None else rhs)(x, u)
    else:
        dx = symbolic_dynamics(model, x, ca.vertcat(u))
    return dx if dz is None else ca.vertcat(dx, dz)


def drive_terms(model, t, y, torque, controller, parameters=None) -> tuple:
    """The hub torque ``u`` and the controller's ``dz/dt`` (None without internal states) at
    ``y = [x, z]``, as CasADi expressions.

    Parameters
    ----------
    model : Model
        The model of the plant, with ``n`` states.
    t : casadi.SX or casadi.MX
        Scalar time, s.
    y : casadi.SX or casadi.MX, shape (m, 1)
        The drive's state ``[x, z]``: the plant's ``n`` states, then the controller's.
    torque, controller : object or None
        The run's inputs, with CasADi forms (:func:`is_symbolic`).
    parameters : casadi.SX or casadi.MX, optional
        The symbol of their numbers (:func:`input_numbers` of ``(torque, None, controller)``);
        None: their numbers are constants.

    Returns
    -------
    tuple
        ``(u, dz)``: the plant's input (the hub torque, N m, or an actuator's command) and
        ``dz/dt`` (shape (n_z, 1)) or None.
    """
    x, z = y[:model.n_states], y[model.n_states:]
    numbers = (None, None)
    if parameters is not None:
        numbers = tuple(split_numbers((torque, None, controller), parameters)[::2])
    u = _applied_torque(t, x, z, torque, controller, numbers)
    if controller is not None and getattr(controller, "n_states", 0):
        return u, controller.casadi_derivative(t, x, z)
    return u, None


def _calls_model(model, hub_motion) -> bool:
    """The model enters the right-hand side through a call (:mod:`flexctl.sim.native_rhs`:
    compiled, with first_order's cheap Newton Jacobian) rather than inlined: the one-beam
    exact model, and an exact structure under a torque."""
    return model.variant.exact and (hub_motion is None or compiles_prescribed(model))




def _matrix_form(model) -> bool:
    """Whether ``model`` enters the integrators in matrix form (:data:`MATRIX_FORM_MODES`)."""
    return model.matrix_form and model.n_modes > MATRIX_FORM_MODES


def _drive_symbols(model, scale, inputs, n_numbers) -> tuple:
    """SX symbols ``ys``, ``tau``, ``p`` of ``_rhs_function``, the state ``y = ys * scale``
    and the drive's terms at ``t = min(t_0 + tau h, t_last)``: ``[rate, acceleration]`` of a
    hub motion, or ``[u]`` and, with controller states, ``[u, dz/dt]``."""
    import casadi as ca

    torque, hub_motion, controller = inputs
    ys, tau, p = ca.SX.sym("ys", scale.size), ca.SX.sym("tau"), ca.SX.sym("p", 3 + n_numbers)
    y = ys * ca.DM(scale)
    t_in = ca.fmin(p[0] + tau * p[1], p[2])
    if hub_motion is not None:
        return ys, tau, p, y, list(hub_motion_casadi(hub_motion, t_in,
                                                     split_numbers(inputs, p[3:])[1]))
    u, dz = drive_terms(model, t_in, y, torque, controller, p[3:])
    return ys, tau, p, y, [ca.vertcat(u)] + ([] if dz is None else [dz])


def _model_dynamics(model, y, terms, prescribed: bool, inline: bool):
    """``dy/dt`` from the drive's ``terms`` (``_drive_symbols``): the model inlined into
    scalar expressions, or called (:mod:`flexctl.sim.native_rhs`)."""
    import casadi as ca

    if prescribed:
        return (symbolic_beam_dynamics(model, y, *terms) if inline
                else integration_beam(model)(y, *terms))
    x = y[:model.n_states]
    dx = (symbolic_dynamics(model, x, terms[0]) if inline
          else integration_rhs(model)(x, terms[0]))
    return dx if len(terms) == 1 else ca.vertcat(dx, terms[1])


#: Right-hand sides and integrators kept for reuse, by the identity of the model and inputs
#: (immutable ones only), least recently used dropped first.
RHS_CACHE_SIZE = 16
INTEGRATOR_CACHE_SIZE = 256
_RHS_CACHE: OrderedDict = OrderedDict()
_INTEGRATOR_CACHE: OrderedDict = OrderedDict()


def _immutable(source) -> bool:
    """None, or a frozen dataclass (the built-in inputs): its CasADi form cannot change."""
    params = getattr(source, "__dataclass_params__", None)
    return source is None or (params is not None and params.frozen)


def input_key(model, inputs, scale):
    """Cache key of a right-hand side, or None when an input may change after use.

    Inputs count by identity, except parametric ones (``_parametric``), which count by
    their class and structure: inputs that differ only in numbers share one right-hand side
    and its integrators.

    Parameters
    ----------
    model : Model
        Counts by identity.
    inputs : tuple
        ``(torque, hub_motion, controller)``, each None or an input; all must be immutable (None
        or a frozen dataclass) for a key.
    scale : ndarray
        Each integrated state's physical size (its bytes are part of the key); callers whose
        function does not depend on it pass a tag of their own (e.g. ``np.array([1.0])``).
    """
    if not all(_immutable(source) for source in inputs):
        return None
    parts = [(type(source), source.casadi_parameters[0]) if _parametric(source)
             else id(source) for source in inputs]
    return (id(model), *parts, scale.tobytes())


def cached_build(cache, size, key, keep_alive, build):
    """``build()``, remembered under ``key`` (None: not remembered). ``keep_alive`` holds the
    objects whose ``id`` is in the key, so that no other object can take their ids.

    Parameters
    ----------
    cache : collections.OrderedDict
        Entries ``key -> (keep_alive, value)``, least recently used first.
    size : int
        Most entries kept; the least recently used are dropped beyond it.
    key : hashable or None
        E.g. from :func:`input_key`.
    keep_alive : object
        Stored with the value (e.g. ``(model, torque, hub_motion, controller)``).
    build : callable
        ``build()`` makes the value; called only when ``key`` is new or None.
    """
    if key is None:
        return build()
    if key in cache:
        cache.move_to_end(key)
        return cache[key][1]
    value = build()
    cache[key] = (keep_alive, value)
    while len(cache) > size:
        cache.popitem(last=False)
    return value


def _rhs_function(model, scale, torque, hub_motion, controller):
    """The scaled right-hand side as a CasADi DAE ``Function`` (``casadi.dyn_in`` inputs) in
    the segment's own time ``tau`` in [0, 1]: ``t = t_0 + tau h`` with the parameters
    ``p = [t_0, h, t_last, c]``, ``t_last`` the last time at which the inputs are evaluated and
    ``c`` the numbers of the parametric inputs (:func:`input_numbers`).

    One function (and one integrator per output pattern) then serves every segment: the holds
    of an optimal torque differ only in ``t_0``.
    """
    import casadi as ca

    inputs = (torque, hub_motion, controller)
    ys, tau, p, y, terms = _drive_symbols(model, scale, inputs, input_numbers(inputs).size)
    matrix_form = _matrix_form(model)
    sym = ca.MX if matrix_form or _calls_model(model, hub_motion) else ca.SX
    if sym is ca.MX:
        # two calls: the drive (one scalar function) and the model
        drive = ca.Function("flexctl_drive", [ys, tau, p], terms)
        ys, tau, p = ca.MX.sym("ys", scale.size), ca.MX.sym("tau"), ca.MX.sym("p", p.numel())
        y = ys * ca.DM(scale)
        terms = drive.call([ys, tau, p])
    dy = _model_dynamics(model, y, terms, hub_motion is not None,
                         inline=sym is ca.SX or matrix_form)
    empty = sym(0, 1)
    function = ca.Function("flexctl_rhs", [tau, ys, empty, p, empty],
                           [p[1] * dy / ca.DM(scale), empty, empty, empty], ca.dyn_in(),
                           ca.dyn_out())
    return (native_dae(function) or function) if sym is ca.SX else function


def numeric_rhs(model, torque=None, hub_motion=None, controller=None):
    """The compiled right-hand side as a numpy function ``f(t, y, t_last) -> dy/dt``.

    ``y`` is the state :func:`flexctl.simulate` integrates (plant and controller states, or
    the beam's alone under a prescribed hub motion) and ``t_last`` the last time at which the
    inputs are evaluated (the end of the current smooth segment). SciPy's integrators call
    it where a compiled segment failed: a few microseconds a call, against a few hundred for
    the Python model.

    Parameters
    ----------
    model : Model
        The model of the run.
    torque, hub_motion, controller : object or None, optional
        As in :func:`flexctl.simulate`; each must pass :func:`is_symbolic`.
    """
    n_y = drive_size(model, hub_motion, controller)
    scale = np.ones(n_y)
    inputs = (torque, hub_motion, controller)
    rhs_key = input_key(model, inputs, scale)
    rhs = cached_build(_RHS_CACHE, RHS_CACHE_SIZE, rhs_key, (model, *inputs),
                  lambda: _rhs_function(model, scale, *inputs))
    # a buffer evaluates in about 2 microseconds where a Python call of the Function takes
    # some 150 (argument conversion)
    buffer, evaluate = rhs.buffer()
    t_arg, y_arg, out = np.zeros(1), np.zeros(n_y), np.zeros(n_y)
    p_arg = np.concatenate(([0.0, 1.0, 0.0], input_numbers(inputs)))
    for k, arg in ((0, t_arg), (1, y_arg), (3, p_arg)):
        buffer.set_arg(k, memoryview(arg))
    buffer.set_res(0, memoryview(out))

    def f(t, y, t_last, _keep=(rhs, buffer)):     # the buffer must outlive every call
        t_arg[0], p_arg[2] = t, t_last
        y_arg[:] = y
        evaluate()
        return out.copy()
    return f


def torque_history(model, t, states, controller_states, torque=None, controller=None):
    """Hub torque of ``torque`` plus ``controller`` along a run, through their CasADi forms.

    Parameters
    ----------
    model : Model
        The model of the run's plant.
    t : ndarray, shape (P,)
        Sample times, s.
    states : ndarray, shape (n, P)
        Plant states at those times, in the model's state order.
    controller_states : ndarray, shape (n_z, P)
        The controller's internal states at those times (``n_z = 0`` for a static law or
        none).
    torque, controller : object or None, optional
        As in :func:`flexctl.simulate`; each must pass :func:`is_symbolic`.

    Returns
    -------
    ndarray, shape (P,)
        The hub torque, N m (an actuated model's command, in its unit).
    """
    import casadi as ca

    nz = controller_states.shape[0]

    inputs = (torque, None, controller)
    numbers = input_numbers(inputs)

    def build():
        ts, x, z = ca.SX.sym("t"), ca.SX.sym("x", model.n_states), ca.SX.sym("z", nz)
        c = ca.SX.sym("c", numbers.size)
        u = ca.SX(_applied_torque(ts, x, z, torque, controller,
                                  tuple(split_numbers(inputs, c)[::2])))
        return ca.Function("flexctl_torque", [ts, x, z, c], [u])

    key = input_key(model, (torque, None, controller), np.array([nz], dtype=float))
    law = cached_build(_RHS_CACHE, RHS_CACHE_SIZE, None if key is None else ("torque", key),
                  (model, torque, controller), build)
    t = np.asarray(t, dtype=float).reshape(1, -1)
    # the map over a run's points, kept with the law: building it costs more than calling it
    mapped = cached_build(_RHS_CACHE, RHS_CACHE_SIZE,
                     None if key is None else ("torque map", key, t.size),
                     (model, torque, controller), lambda: law.map(t.size))
    return np.array(mapped(t, states, controller_states,
                           np.repeat(numbers[:, None], t.size, axis=1))).reshape(-1)


def min_step_fraction(t_end: float, length: float) -> float:
    """CVODES's shortest step over a segment of ``length`` s ending at ``t_end`` s, as a
    fraction of the segment: a step this small means a singularity, not accuracy, so the run
    fails fast and the caller locates it (a power of ten, so that segments share
    integrators).

    Parameters
    ----------
    t_end : float
        End of the segment, s.
    length : float
        Length of the segment, s (> 0).
    """
    return 10.0 ** np.floor(np.log10(1e-14 * max(1.0, t_end) / length))


class SegmentIntegrator:
    """CVODES integration of a model over one smooth segment, onto given output times.

    Parameters
    ----------
    model : Model
        The model integrated.
    t_start : float
        Segment start, s.
    t_out : ndarray, shape (K,)
        Output times in ``(t_start, t_end]``, ascending, s.
    scale : ndarray, shape (m,)
        Physical size of each integrated state; ``m = n + n_z`` (torque-driven: the plant
        state, then the controller's ``n_z`` internal states) or ``2 N`` (prescribed hub
        motion: ``[q, q_dot]``).
    rtol : float
        Relative tolerance; the absolute tolerance is ``rtol * scale``.
    torque, hub_motion, controller : object or None, optional
        As in :func:`flexctl.simulate`; each must pass :func:`is_symbolic`.
    max_steps : int, optional
        Most solver steps between two output times before the solver fails. Default
        1 000 000.
    solver : {"cvodes", "idas"}, optional
        SUNDIALS solver; both are variable-order BDF. Default ``"cvodes"``.
    max_order : int, optional
        Highest BDF order (honoured by IDAS). Order 2 is A-stable: it never amplifies an
        undamped oscillation, where orders 3 to 5 can for steps near the oscillation period.
    max_step : float, optional
        Longest step, s (e.g. a sampled torque's sample interval, so that no sample is
        stepped over). Default: unbounded.
    multistep : {"bdf", "adams"}, optional
        CVODES's linear multistep family (ignored by IDAS, which is BDF): ``"adams"``
        (Adams-Moulton, orders 1 to 12) for lightly damped oscillations, which BDF's orders 3
        to 5 follow with short steps; ``"bdf"`` (default) where fast poles are damped
        (:func:`flexctl.sim.request.choose_multistep`).
    """

    def __init__(self, model, t_start, t_out, scale, rtol, torque=None, hub_motion=None,
                 controller=None, max_steps=1_000_000, solver="cvodes", max_order=None,
                 max_step=None, multistep="bdf"):
        import casadi as ca

        if solver == "cvodes" and multistep not in ("bdf", "adams"):
            raise InputValueError(f"SegmentIntegrator multistep must be 'bdf' or 'adams'; got "
                                  f"{multistep!r}")
        scale = np.asarray(scale, dtype=float)
        t_out = np.asarray(t_out, dtype=float)
        inputs = (torque, hub_motion, controller)
        rhs_key = input_key(model, inputs, scale)
        rhs = cached_build(_RHS_CACHE, RHS_CACHE_SIZE, rhs_key, (model, *inputs),
                      lambda: _rhs_function(model, scale, *inputs))
        t_start, t_end = float(t_start), float(t_out[-1])
        length = t_end - t_start
        # output times as fractions of the segment, rounded so that segments of one pattern
        # (equal holds on a regular grid) share an integrator; 1e-12 of a segment is far
        # below any integration error
        fractions = np.round((t_out - t_start) / length, 12)
        fractions[-1] = 1.0
        # a blown-up state (inf in the right-hand side) is the caller's to report, by name
        opts = {"reltol": float(rtol), "abstol": float(rtol), "max_num_steps": int(max_steps),
                "disable_internal_warnings": True, "show_eval_warnings": False}
        if solver == "cvodes":
            opts["min_step_size"] = min_step_fraction(t_end, length)
            opts["linear_multistep_method"] = multistep
        if max_order is not None:
            opts["max_multistep_order"] = int(max_order)
        if max_step is not None and max_step < length:
            opts["max_step_size"] = float(max_step) / length
        key = None if rhs_key is None else (rhs_key, fractions.tobytes(),
                                            tuple(sorted(opts.items())), solver)
        self._scale = scale
        # the inputs see the segment's own piece at its closed end, as on the SciPy path: a
        # solver that evaluates past the last output time must not see the next hold
        self._parameters = [t_start, length, float(np.nextafter(t_end, t_start)),
                            *input_numbers(inputs)]
        # called through numpy buffers (InPlace): some 60 us a call less than with a dict,
        # which a sample loop makes thousands of times
        self._run = cached_build(_INTEGRATOR_CACHE, INTEGRATOR_CACHE_SIZE, key, (model, *inputs),
                            lambda: InPlace(ca.integrator(
                                f"flexctl_{solver}", solver, rhs, 0.0,
                                [float(v) for v in fractions], opts)))
        self._stats = {}

    def moved(self, t_start: float, t_end: float, numbers) -> "SegmentIntegrator":
        """This integrator on another segment of the same shape: from ``t_start`` to
        ``t_end`` (s), with the output times at the same offsets, the same
        :func:`min_step_fraction` and the inputs' ``numbers`` (:func:`input_numbers`).

        Parameters
        ----------
        t_start : float
            Start of the new segment, s (finite).
        t_end : float
            End of the new segment, s (finite, > ``t_start``).
        numbers : sequence of float
            The inputs' numbers (:func:`input_numbers`), as many as this integrator's and all
            finite.

        Returns
        -------
        SegmentIntegrator
            A copy; this one is unchanged.
        """
        t_start, t_end = float(t_start), float(t_end)
        numbers = [float(v) for v in numbers]
        if not (np.isfinite(t_start) and np.isfinite(t_end) and t_end > t_start):
            raise InputValueError(f"SegmentIntegrator.moved needs finite times with t_end > "
                                  f"t_start; got t_start = {t_start!r}, t_end = {t_end!r}")
        if len(numbers) != len(self._parameters) - 3 or not np.all(np.isfinite(numbers)):
            raise InputValueError(f"SegmentIntegrator.moved needs {len(self._parameters) - 3} "
                                  f"finite input numbers; got {numbers!r}"[:300])
        moved = copy.copy(self)
        moved._parameters = [t_start, t_end - t_start, float(np.nextafter(t_end, t_start)),
                             *numbers]
        moved._stats = {}
        return moved

    def __call__(self, y0) -> np.ndarray:
        """States at the output times, shape (m, K); raises ``RuntimeError`` if CVODES fails.

        Parameters
        ----------
        y0 : array_like, shape (m,)
            State at the segment's start, unscaled.
        """
        results, self._stats = self._run.call_with_stats(
            np.asarray(y0, dtype=float) / self._scale, (), self._parameters)
        return results[0] * self._scale[:, None]

    @property
    def n_evaluations(self) -> int:
        """Right-hand-side evaluations of the last call."""
        stats = self._stats
        return int(stats.get("nfevals", 0)) if isinstance(stats, dict) else 0


def integrate_segments(model, segments, y0, scale, rtol, **options):
    """Integrate consecutive segments with CVODES (one :class:`SegmentIntegrator` each).

    Parameters
    ----------
    model : Model
        The model integrated.
    segments : list of (float, ndarray)
        ``(t_start, t_out)`` per segment, as for :class:`SegmentIntegrator`; each segment starts
        where the previous one's outputs end.
    y0 : ndarray, shape (m,)
        State at the first segment's start.
    scale : ndarray, shape (m,)
        Physical size of each integrated state, in its unit.
    rtol : float
        Relative tolerance; the absolute tolerance is ``rtol * scale``.
    **options
        The other arguments of :class:`SegmentIntegrator` (``torque``, ``hub_motion``,
        ``controller``, ``max_steps``, ``solver``, ``max_order``, ``max_step``,
        ``multistep``).

    Returns
    -------
    states : ndarray, shape (m, K)
        At every output time of every segment, in order.
    n_evaluations : int
        Right-hand-side evaluations of all the segments.

    Raises
    ------
    RuntimeError
        If the solver fails on a segment.
    """
    return run_segments(segment_integrators(model, segments, scale, rtol, **options), y0)


def segment_integrators(model, segments, scale, rtol, **options) -> list:
    """One :class:`SegmentIntegrator` per segment (arguments as :func:`integrate_segments`).

    Building them is CasADi symbolic work, which must stay in one thread; calling them
    (:func:`run_segments`) is numeric and may run on another.

    Parameters
    ----------
    model : Model
        The model integrated.
    segments : list of (float, ndarray)
        ``(t_start, t_out)`` per segment, as for :class:`SegmentIntegrator`.
    scale : ndarray, shape (m,)
        Physical size of each integrated state.
    rtol : float
        Relative tolerance; the absolute tolerance is ``rtol * scale``.
    **options
        The other arguments of :class:`SegmentIntegrator` (``torque``, ``hub_motion``,
        ``controller``, ``max_steps``, ``solver``, ``max_order``, ``max_step``, ``multistep``).
    """
    return [SegmentIntegrator(model, t_start, t_out, scale, rtol, **options)
            for t_start, t_out in segments]


def run_segments(integrators, y0, cancelled=None) -> tuple:
    """``(states, n_evaluations)`` of ``integrators`` chained from ``y0`` (see
    :func:`integrate_segments`); ``cancelled``, a ``threading.Event``, is looked at before
    each segment and stops the run with a ``RuntimeError`` once set.

    Parameters
    ----------
    integrators : sequence of SegmentIntegrator
        Consecutive segments, each starting where the previous one's outputs end.
    y0 : array_like, shape (m,)
        State at the first segment's start.
    cancelled : threading.Event, optional
        Default: never cancelled.
    """
    blocks, n_eval, y = [], 0, np.asarray(y0, dtype=float)
    for integ in integrators:
        if cancelled is not None and cancelled.is_set():
            raise RuntimeError("integration cancelled")
        block = integ(y)
        n_eval += integ.n_evaluations
        blocks.append(block)
        y = block[:, -1]
    return np.concatenate(blocks, axis=1), n_eval


#: The accuracy check re-runs at this many times the tolerance ...
CHECK_FACTOR = 10.0
#: ... onto at most this many output times per segment.
CHECK_POINTS = 200
#: A disagreement this many times ``rtol`` (relative to the peak tip deflection) ...
ALARM_FACTOR = 1e4
#: ... with the run taking this many times the evaluations of the check run means the
#: integration went wrong rather than merely inexact: a healthy BDF run at 10x the tolerance
#: costs 1.5 to 3 times fewer steps, while a run that follows spurious ringing of undamped
#: high-frequency modes costs hundreds of times more.
EFFORT_FACTOR = 20.0


def _stride(t_out) -> int:
    """Every how many output times of a segment the check keeps one."""
    return max(1, len(t_out) // CHECK_POINTS)


def _subsample(segments):
    """At most ``CHECK_POINTS`` output times per segment (its end always kept), and the
    indices of those times among all the segments' outputs."""
    check, picks, offset = [], [], 0
    for t_start, t_out in segments:
        k = len(t_out)
        keep = np.unique(np.r_[np.arange(0, k, _stride(t_out)), k - 1])
        check.append((t_start, np.asarray(t_out)[keep]))
        picks.append(offset + keep)
        offset += k
    return check, np.concatenate(picks)


def _run_or_none(integrators, y0, cancelled=None):
    try:
        return run_segments(integrators, y0, cancelled)
    except RuntimeError:
        return None


def check_run(model, segments, y0, scale, rtol, **options):
    """The accuracy check's own run: :func:`integrate_segments` at ``CHECK_FACTOR`` times
    the tolerance onto at most ``CHECK_POINTS`` of each segment's output times, as
    ``(states, n_evaluations)``, or None if it failed.

    It needs only the run's plan, not its result: :func:`start_check` runs it beside the run.

    Parameters
    ----------
    model : Model
        The model integrated.
    segments : list of (float, ndarray)
        ``(t_start, t_out)`` per segment, as for :func:`integrate_segments`.
    y0 : ndarray, shape (m,)
        State at the first segment's start.
    scale : ndarray, shape (m,)
        Physical size of each integrated state.
    rtol : float
        The run's relative tolerance (the check's is ``CHECK_FACTOR`` times it).
    **options
        As for :func:`integrate_segments`.
    """
    return start_check(model, segments, y0, scale, rtol, beside=False, **options).result()


def start_check(model, segments, y0, scale, rtol, beside=True, **options):
    """:func:`check_run`, started on a spare core (:class:`~flexctl.sim.background.Beside`)
    to run while the run it checks runs (``beside``), or to run in the caller's thread when
    its result is asked for; give it to :func:`verify_accuracy` as ``check``, or
    ``abandon()`` it if the run stops early.

    Its integrators are built here, in the caller's thread: CasADi's symbolic work is not
    thread-safe, while its numerical evaluation is and lets go of Python's lock. A step
    budget ``max_steps`` (between output times, as the run's) grows with the check's wider
    output spacing: a check abandoned by a run that stopped early (a diverging one, say)
    then gives up when the run would have, rather than integrating on for minutes.

    Parameters
    ----------
    model : Model
        The model integrated.
    segments : list of (float, ndarray)
        ``(t_start, t_out)`` per segment, as for :func:`integrate_segments`.
    y0 : ndarray, shape (m,)
        State at the first segment's start.
    scale : ndarray, shape (m,)
        Physical size of each integrated state.
    rtol : float
        The run's relative tolerance (the check's is ``CHECK_FACTOR`` times it).
    beside : bool, optional
        Run on a spare core now (default True), else in the caller's thread when the result is
        asked for.
    **options
        As for :func:`integrate_segments`; ``max_steps`` is scaled as above.

    Returns
    -------
    Beside
        Its ``result()`` is ``(states, n_evaluations)`` or None, as :func:`check_run`'s.
    """
    import threading

    from .background import Beside

    if options.get("max_steps") is not None:
        # a budget between output times: the check's are CHECK_POINTS per segment at most
        stride = max(_stride(t_out) for _, t_out in segments)
        options = {**options, "max_steps": int(options["max_steps"]) * stride}
    try:
        integrators = segment_integrators(model, _subsample(segments)[0], scale,
                                          CHECK_FACTOR * rtol, **options)
    except RuntimeError:                # CasADi's: the check cannot run
        return Beside(lambda: None, beside=False)
    except Exception as exc:            # noqa: BLE001 - the run raises it first, if at all
        return Beside(_raise, exc, beside=False)
    return Beside(_run_or_none, integrators, y0, cancelled=threading.Event(), beside=beside)


def _raise(exc):
    raise exc


def verify_accuracy(model, segments, y0, scale, rtol, y_main, tip_map, n_main, check=None,
                    **options):
    """Estimate the integration error of a compiled run, and mend a run that went wrong.

    The run is repeated at ``CHECK_FACTOR`` times the tolerance, onto at most
    ``CHECK_POINTS`` of each segment's output times (:func:`check_run`); the largest
    difference in tip deflection there is the error estimate (conservative: it is the error
    of the looser run). If the
    two disagree by more than ``ALARM_FACTOR * rtol`` of the peak while the run took more than
    ``EFFORT_FACTOR`` times the evaluations of the check, high-order multistep steps (BDF's
    orders 3 to 5, or Adams-Moulton's) have amplified an undamped high-frequency mode, and
    the run is redone with A-stable BDF2 (IDAS).

    Parameters
    ----------
    model : Model
        The model integrated, as for :func:`integrate_segments`.
    segments : list of (float, ndarray)
        ``(t_start, t_out)`` per segment, as for :func:`integrate_segments`.
    y0 : ndarray, shape (m,)
        State at the first segment's start.
    scale : ndarray, shape (m,)
        Physical size of each integrated state.
    rtol : float
        The run's relative tolerance (the check's is ``CHECK_FACTOR`` times it).
    y_main : ndarray, shape (m, K)
        The run to check, at the segments' output times.
    tip_map : ndarray, shape (A, m)
        ``tips = tip_map @ y`` (m), one row per appendage.
    n_main : int
        Right-hand-side evaluations of the run to check.
    check : Beside, optional
        The check run already started (:func:`start_check` with the same arguments);
        default: run it now.
    **options
        The run's other arguments, as for :func:`integrate_segments`.

    Returns
    -------
    states : ndarray, shape (m, K)
        ``y_main``, or the BDF2 run that replaces it.
    error : float or None
        Estimated largest tip error, m (None if the check could not run).
    note : str
        Empty, or what was found and done.
    n_evaluations : int
        Right-hand-side evaluations of the check and of any re-run.
    """
    tip_main = tip_map @ y_main
    picks = _subsample(segments)[1]
    found = (check_run(model, segments, y0, scale, rtol, **options) if check is None
             else check.result())
    if found is None:
        return y_main, None, "accuracy check could not run (the check integration failed)", 0
    y_check, n_eval = found
    error = float(np.max(np.abs(tip_main[:, picks] - tip_map @ y_check)))
    peak = max(float(np.max(np.abs(tip_main))), float(np.max(abs(tip_map) @ scale)) * 1e-3)
    if error <= ALARM_FACTOR * rtol * peak or n_main <= EFFORT_FACTOR * max(n_eval, 1):
        return y_main, error, "", n_eval
    found = (f"accuracy check: CVODES and a check run at {CHECK_FACTOR:g}x the tolerance "
             f"disagreed by {error:.3g} m at the tip, the mark of undamped high-frequency "
             "modes that high-order multistep steps amplify (BDF's orders 3 to 5, "
             "Adams-Moulton's beyond its stability interval)")
    options = {**options, "solver": "idas", "max_order": 2}
    try:
        y_fixed, n_fixed = integrate_segments(model, segments, y0, scale, rtol, **options)
    except RuntimeError:
        y_fixed = None
    fixed_check = None if y_fixed is None else check_run(model, segments, y0, scale, rtol,
                                                         **options)
    if fixed_check is None:
        return y_main, error, found + "; the A-stable re-run failed, result kept", n_eval
    y_fixed_check, n_check = fixed_check
    error = float(np.max(np.abs(tip_map @ (y_fixed[:, picks] - y_fixed_check))))
    return (y_fixed, error, found + "; re-integrated with A-stable BDF2 (IDAS)",
            n_eval + n_fixed + n_check)
