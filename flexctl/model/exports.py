"""Thin views of a :class:`~flexctl.model.Model` as python-control and CasADi objects.

Both views evaluate the same equations as :meth:`Model.dynamics`; the tests pin them to it.
The state, input and output orders are those of :mod:`flexctl.model`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["to_nonlinear_iosystem", "to_casadi", "to_casadi_outputs", "signal_names",
           "MATRIX_FORM_MODES",
           "linearize_at", "dynamics_jacobians"]


def signal_names(names) -> list:
    """Names as python-control signals: python-control keeps the dot for ``system.signal``,
    so an appendage's ``wing_a.q1`` becomes ``wing_a_q1`` (one-beam names are unchanged).

    Parameters
    ----------
    names : sequence of str
        State, input or output names of a model.

    Raises
    ------
    InputValueError
        If two names become one.
    """
    from .errors import InputValueError

    out = [name.replace(".", "_") for name in names]
    if len(set(out)) != len(out):
        twice = next(n for n in out if out.count(n) > 1)
        raise InputValueError(f"the signal names {list(names)} give {twice!r} twice once the "
                              "dots become underscores for python-control; rename an appendage")
    return out


def to_nonlinear_iosystem(model, outputs: str = "named", params=None):
    """The model as a python-control ``NonlinearIOSystem``.

    States :attr:`Model.state_names`, input :attr:`Model.input_names` (``torque``, N m, or an
    actuator's command), an appendage's dot as an underscore (:func:`signal_names`). A state at
    which the mass matrix is singular raises :class:`~flexctl.model.SingularMassMatrixError`.

    Parameters
    ----------
    model : Model
        Any flexctl model (a StructureModel or an ActuatedModel included).
    outputs : {"named", "states"}, optional
        The system's outputs: :attr:`Model.output_names` (``"named"``, default) or the states
        themselves (``"states"``).
    params : list of str or dict, optional
        Physical parameters by scene key (a list of keys, their nominal values the defaults, or
        a dict of their values), the python-control way: ``updfcn`` and ``outfcn`` read them
        from ``params``, so ``control.input_output_response(sys, ..., params={...})`` runs the
        plant at other values (:mod:`flexctl.model.parametric`: exact at the nominal values,
        first order in the change). Default none.

    Examples
    --------
    >>> from flexctl import load_scene, build_model
    >>> sys = build_model(load_scene("kane-spinup").system, n_modes=2).nonlinear()
    >>> sys.state_labels
    ['theta', 'q1', 'q2', 'theta_dot', 'q1_dot', 'q2_dot']
    """
    import control

    from .errors import InputValueError

    if outputs not in ("named", "states"):
        raise InputValueError(f"nonlinear outputs must be 'named' or 'states'; got {outputs!r}")

    if params is not None:
        return _parametric_iosystem(model, outputs, params)

    def updfcn(t, x, u, params):
        return model.dynamics(t, x, np.asarray(u, dtype=float).reshape(-1)[0])

    def outfcn(t, x, u, params):
        return model.outputs(np.asarray(x, dtype=float))

    states = signal_names(model.state_names)
    if outputs == "states":
        return control.nlsys(updfcn, None, states=states, inputs=list(model.input_names),
                             outputs=list(states), name=f"{model.variant}_N{model.n_modes}")
    return control.nlsys(updfcn, outfcn, states=states,
                         inputs=list(model.input_names), outputs=signal_names(model.output_names),
                         name=f"{model.variant}_N{model.n_modes}")


def _parametric_iosystem(model, outputs, params):
    """:func:`to_nonlinear_iosystem` with physical parameters read from ``params``."""
    import control

    from .errors import InputTypeError

    if isinstance(params, dict):
        keys = list(params)
        values = dict(zip(keys, model.parameter_values(keys)))
        values.update({k: float(v) for k, v in params.items()})
    elif isinstance(params, (list, tuple)) and not isinstance(params, str):
        keys = list(params)
        values = dict(zip(keys, model.parameter_values(keys)))
    else:
        raise InputTypeError("nonlinear params must be a list of scene keys or a dict of their "
                             f"values; got {type(params).__name__}")
    f = model.casadi(parameters=keys)
    h = model._c.setdefault(("casadi_outputs", tuple(keys)),
                            _parametric_outputs(model, keys))

    def vector(params):
        return np.array([float(params.get(k, values[k])) for k in keys])

    def updfcn(t, x, u, params):
        return np.array(f(x, np.asarray(u, dtype=float).reshape(-1)[:1], vector(params)),
                        dtype=float).reshape(-1)

    def outfcn(t, x, u, params):
        return np.array(h(x, 0.0, vector(params)), dtype=float).reshape(-1)

    states = signal_names(model.state_names)
    return control.nlsys(updfcn, outfcn if outputs == "named" else None, states=states,
                         inputs=list(model.input_names),
                         outputs=signal_names(model.output_names) if outputs == "named"
                         else list(states), params=values,
                         name=f"{model.variant}_N{model.n_modes}")


def _parametric_outputs(model, keys):
    from .parametric import parametric_casadi
    return parametric_casadi(model, keys, outputs=True)


#: Modes above which a small-deflection model on a pinned hub enters the integrators in matrix form
#: (MX: products with its dense modal matrices) rather than written out in scalars (SX, then
#: compiled). The scalar form's Jacobian, which CVODES's Newton iterations need, is built in
#: time that grows as the cube of the modes (22 s at 200 modes, for each tolerance) and
#: compiles slowly; the matrix form's is built at once and evaluated with dense products. On
#: hub-beam-mass (3 s of a sine torque, second runs) the compiled scalar form took 14 to 22 %
#: less time at 8 to 16 modes, 7 % less at 24 and 2 % more at 32.
MATRIX_FORM_MODES = 12


def symbolic_dynamics(model, x, u):
    """CasADi expression of ``dx/dt`` in the symbols ``x`` and ``u``.

    Parameters
    ----------
    model : Model
        Any flexctl model.
    x : casadi.SX or casadi.MX, shape (n,)
        State symbols, in :attr:`Model.layout` order.
    u : casadi.SX or casadi.MX, shape (1,)
        Input symbol: the hub torque, N m (an actuated model's command).
    """
    import casadi as ca

    if not (model.matrix_form and (isinstance(x, ca.MX) or model.n_modes > MATRIX_FORM_MODES)):
        return model.functions.rhs(x, u)
    # products with the dense modal matrices: a Jacobian built at once for many modes (and in
    # scalars, built in 0.16 s at 200 modes where the structure's functions take 1.4 to 1.9 s,
    # with the same instruction count to 0.04 %)
    mat, c = model.matrices, model.matrix_terms()
    _, q, w, qd = model.layout.split(x)
    dm = ca.DM
    f_beam = (-ca.mtimes(dm(mat.C_ff), qd) - ca.mtimes(dm(mat.K_ff), q)
              + w ** 2 * ca.mtimes(dm(c["stiff_d"]), q))
    f_hub = u[0] - model.structure.hub.friction * w
    j_eff = c["j_rigid_eff"]
    if model.variant.quadratic_inertia:
        d = dm(mat.D)
        f_hub = f_hub - 2.0 * w * ca.dot(q, ca.mtimes(d, qd))
        j_eff = j_eff + ca.dot(q, ca.mtimes(d, q))
    g = dm(c["g"])
    theta_tt = (f_hub - ca.dot(g, f_beam)) / j_eff
    q_tt = ca.mtimes(dm(c["m_inv"]), f_beam) - g * theta_tt
    return model.layout.join(theta=w, q=qd, theta_dot=theta_tt, q_dot=q_tt)


def symbolic_beam_dynamics(model, y, rate, acceleration):
    """CasADi ``d[q, q_dot]/dt`` under prescribed hub ``rate`` and ``acceleration``.

    Parameters
    ----------
    model : Model
        A model on a pinned hub.
    y : casadi.SX or casadi.MX, shape (2 N,)
        Beam states ``[q, q_dot]`` (m, m/s), in :meth:`StateLayout.without_rotation` order.
    rate : casadi.SX or casadi.MX
        Hub rate ``theta_dot``, rad/s.
    acceleration : casadi.SX or casadi.MX
        Hub acceleration ``theta_tt``, rad/s^2.
    """
    import casadi as ca

    mat, beam = model.matrices, model.layout.without_rotation()
    q, qd = beam.modal(y), beam.modal_rates(y)
    if model.structure.free:
        model._pinned_only("a prescribed hub motion")
    if not (isinstance(y, ca.MX) and model.matrix_form):
        return ca.vertcat(qd, model.functions.beam(q, qd, rate, acceleration))
    dm, c = ca.DM, model.matrix_terms()
    f_beam = (-ca.mtimes(dm(mat.C_ff), qd) - ca.mtimes(dm(mat.K_ff), q)
              + rate ** 2 * ca.mtimes(dm(c["stiff_d"]), q) - dm(mat.m_tf) * acceleration)
    return ca.vertcat(qd, ca.mtimes(dm(c["m_inv"]), f_beam))


def to_casadi(model, sx: bool = True):
    """The dynamics as a CasADi ``Function`` ``f(x, u) -> xdot``.

    Parameters
    ----------
    model : Model
        The model (any variant).
    sx : bool, optional
        Build on ``SX`` scalar symbols (default, fastest to evaluate for small models) or ``MX``.

    Returns
    -------
    casadi.Function
        Inputs ``x`` (n x 1) and ``u`` (1 x 1), output ``xdot`` (n x 1).

    Examples
    --------
    >>> import numpy as np
    >>> from flexctl import load_scene, build_model
    >>> model = build_model(load_scene("kane-spinup").system, n_modes=2)
    >>> f = model.casadi()
    >>> f.name_in(), f.name_out()
    (['x', 'u'], ['xdot'])
    >>> x = np.zeros(6)
    >>> np.allclose(np.array(f(x, 1.0)).ravel(), model.dynamics(0.0, x, 1.0))
    True
    """
    import casadi as ca

    sym = ca.SX.sym if sx else ca.MX.sym
    x = sym("x", model.n_states)
    u = sym("u", 1)
    return ca.Function(f"flexctl_{model.variant}_N{model.n_modes}", [x, u],
                       [symbolic_dynamics(model, x, u)], ["x", "u"], ["xdot"])


def dynamics_jacobians(model, x0, u0=0.0) -> tuple:
    """``f(x0, u0)`` (n,), ``A = df/dx`` (n, n) and ``B = df/du`` (n, 1) of
    :meth:`Model.casadi`; the CasADi function is built once per model.

    Parameters
    ----------
    model : Model
        Any flexctl model.
    x0 : array_like, shape (n,)
        State, finite, in :attr:`Model.layout` order.
    u0 : float, optional
        Input: the hub torque, N m (an actuated model's command). Default 0.
    """
    import casadi as ca

    from .checks import check_array, check_real

    x0 = check_array("dynamics_jacobians", "x0", x0, shape=(model.n_states,))
    u0 = check_real("dynamics_jacobians", "u0", u0)
    if "dynamics_jacobians" not in model._c:
        x, u = ca.SX.sym("x", model.n_states), ca.SX.sym("u")
        xdot = model.casadi()(x, u)
        model._c["dynamics_jacobians"] = ca.Function(
            "flexctl_dynamics_jacobians", [x, u],
            [xdot, ca.jacobian(xdot, x), ca.jacobian(xdot, u)])
    drift, a, b = (np.array(m, dtype=float) for m in model._c["dynamics_jacobians"](x0, u0))
    return drift.reshape(-1), a, b


def linearize_at(model, x0, u0=0.0):
    """The model linearised about any state ``x0`` and input ``u0`` (deflected, spinning,
    accelerating), a python-control ``StateSpace`` in the deviations from them:
    ``d(dx)/dt = A dx + B du``, ``dy = C dx``, with ``A, B, C`` the exact Jacobians of the
    CasADi right-hand side and outputs (:meth:`Model.casadi`). Where ``x0`` is not an
    equilibrium, the plant's attribute ``drift`` holds ``f(x0, u0)``, shape (n,), and
    ``operating_point`` holds ``(x0, u0)``.

    Parameters
    ----------
    model : Model
        Any flexctl model.
    x0 : array_like, shape (n,)
        State, finite, in :attr:`Model.layout` order.
    u0 : float, optional
        Input: the hub torque, N m (an actuated model's command). Default 0.

    Raises
    ------
    InputValueError
        If ``x0`` is not ``n`` finite numbers or ``u0`` one finite number, or the mass matrix
        is singular there (a non-finite Jacobian).
    """
    import casadi as ca
    import control

    from .checks import check_array, check_real
    from .errors import InputValueError

    n = model.n_states
    x0 = check_array("linearize", "x0", x0, shape=(n,))
    u0 = check_real("linearize", "u0", u0)
    # the states simulate takes, and a mass matrix that can be inverted there
    from .errors import SingularMassMatrixError
    from .variant import check_reach

    check_reach(model, x0, "linearize: ")
    inertia = float(np.min(model.effective_hub_inertia(x0)))
    if not inertia > 0.0:
        raise SingularMassMatrixError(
            f"linearize: the mass matrix is singular at x0: the effective hub inertia "
            f"{inertia:.3g} kg m^2 is not positive (the {model.variant} model of a light hub, "
            "deflected)")
    drift, a, b = dynamics_jacobians(model, x0, u0)
    if "output_jacobian" not in model._c:           # built once per model
        x = ca.SX.sym("x", n)
        model._c["output_jacobian"] = ca.Function(
            "flexctl_output_jacobian", [x], [ca.jacobian(to_casadi_outputs(model)(x), x)])
    c = np.array(model._c["output_jacobian"](x0), dtype=float)
    if not all(np.all(np.isfinite(m)) for m in (drift, a, b, c)):
        raise InputValueError("linearize: the Jacobians are not finite at x0 (the mass matrix "
                              "is singular there)")
    plant = control.ss(a, b, c, np.zeros((c.shape[0], 1)),
                       states=signal_names(model.state_names), inputs=list(model.input_names),
                       outputs=signal_names(model.output_names),
                       name=f"{model.variant}_at_operating_point")
    plant.drift, plant.operating_point = drift.reshape(-1), (x0.copy(), u0)
    return plant


def to_casadi_outputs(model, sx: bool = True):
    """The outputs as a CasADi ``Function`` ``h(x) -> y`` (y in :attr:`Model.output_names`).

    Parameters
    ----------
    model : Model
        Any flexctl model.
    sx : bool, optional
        Build on ``SX`` scalar symbols (default) or ``MX``.
    """
    import casadi as ca

    sym = ca.SX.sym if sx else ca.MX.sym
    x = sym("x", model.n_states)
    return ca.Function(f"flexctl_outputs_{model.variant}", [x], [model.functions.outputs(x)],
                       ["x"], ["y"])
