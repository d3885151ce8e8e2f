"""Built-in feedback laws as python-control I/O systems, to wire with ``control.interconnect``.

:func:`to_iosys` gives a law bound to its plant as a ``control.NonlinearIOSystem`` with named
signals (python-control's names: an appendage's dot as an underscore,
:func:`flexctl.model.exports.signal_names`):

- a state law (PD, LQR, scheduled LQR, the trajectory tracker, the wheel-lag LQR): inputs the
  plant's states, output the plant's input (``torque``, or an actuator's command), no states;
  connect it to ``model.nonlinear(outputs="states")``;
- LQG: inputs the readings it measures (``theta`` and each appendage's ``root_moment``, the
  plant's named outputs, to which it adds its own ``measurement_noise`` as
  :func:`flexctl.simulate` does), states its estimate ``z`` (``xhat_theta``, ...), output the
  torque; connect it to ``model.nonlinear()``;
- a sampled state law (a :class:`~flexctl.sim.digital.ZeroOrderHold` of one) and its
  structural filters (:class:`~controllers.Filtered`): a discrete-time system (``dt`` the
  sample time), inputs the plant's states, states the filters' (``structural_filter_0``,
  ...), output the held command; connect it to the plant held over the sample (a discrete
  system of :meth:`flexctl.Model.discretize`, as in :func:`to_iosys`'s example).

The time argument carries the law's reference, so ``control.interconnect`` of the two and
``control.input_output_response`` reproduce :func:`flexctl.simulate`'s closed loop.

Examples
--------
>>> import numpy as np, control, flexctl
>>> from controllers import design_pd
>>> from controllers.feedback.iosys import to_iosys
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> pd = design_pd(model, bandwidth=3.0, damping_ratio=0.9)
>>> law = to_iosys(pd, model)
>>> law.input_labels, law.output_labels
(['theta', 'q1', 'q2', 'theta_dot', 'q1_dot', 'q2_dot'], ['torque'])
>>> loop = control.interconnect([model.nonlinear(outputs="states"), law],
...                             inplist=[], outlist=["theta"])
>>> x0 = np.zeros(model.n_states); x0[0] = 0.1
>>> response = control.input_output_response(loop, np.linspace(0.0, 2.0, 201), X0=x0)
>>> bool(abs(np.ravel(response.outputs)[-1]) < 0.05)          # regulated towards 0
True
"""

from __future__ import annotations

import numpy as np

from flexctl.model import Model
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.exports import signal_names

__all__ = ["to_iosys"]


def to_iosys(law, plant, *, name: str | None = None):
    """``law`` bound to ``plant`` as a python-control ``NonlinearIOSystem`` (module docstring).

    Parameters
    ----------
    law : object
        A built-in feedback law: PD, LQR, ScheduledLQR, TrajectoryTracker, LaggedLQR, LQG; or
        one of the state laws sampled (a ZeroOrderHold of it), with its structural filters or
        not (:class:`~controllers.Filtered`), which gives a discrete-time system.
    plant : flexctl.Model
        The plant it reads and drives.
    name : str, optional
        The system's name (default the law's class name, lower case).

    Raises
    ------
    InputTypeError
        If ``plant`` is not a flexctl Model, or ``law`` not a flexctl feedback law.
    InputValueError
        For a sampled law with states of its own (an observed law's Kalman filter).

    Examples
    --------
    A held PD behind a notch, flown on the plant held over the same sample:

    >>> import numpy as np, control, flexctl
    >>> from controllers import Filtered, Notch, design_pd
    >>> from flexctl.sim.digital import ZeroOrderHold
    >>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    >>> law = Filtered(law=ZeroOrderHold(design_pd(model, bandwidth=3.0), 0.01),
    ...                filters=[Notch(frequency=24.3, depth_db=20.0)])
    >>> sampled = to_iosys(law, model)
    >>> sampled.dt, sampled.state_labels
    (0.01, ['structural_filter_0', 'structural_filter_1'])
    >>> step = model.discretize(0.01)
    >>> plant = control.nlsys(lambda t, x, u, p: step(x, u[0]).full().ravel(), None, dt=0.01,
    ...                       states=sampled.input_labels, inputs=["torque"],
    ...                       outputs=sampled.input_labels, name="plant")
    >>> loop = control.interconnect([plant, sampled], inplist=[], outlist=["theta"])
    >>> x0 = np.zeros(model.n_states); x0[0] = 0.1
    >>> response = control.input_output_response(loop, np.arange(301) * 0.01,
    ...                                          X0=np.concatenate((x0, np.zeros(2))))
    >>> bool(abs(np.ravel(response.outputs)[-1]) < 0.02)
    True
    """
    import control

    from .lqg import LQG, measured_outputs

    if not isinstance(plant, Model):
        raise InputTypeError(f"to_iosys plant must be a flexctl Model; got "
                             f"{type(plant).__name__}")
    if getattr(law, "sample_time", None) is not None and callable(getattr(law, "start", None)):
        return _sampled_iosys(law, plant, _checked_name(name, law))
    if not (callable(getattr(law, "torque", None)) and hasattr(law, "n_states")):
        raise InputTypeError(f"to_iosys law must be a flexctl feedback law; got "
                             f"{type(law).__name__}")
    if callable(getattr(law, "for_plant", None)):
        law = law.for_plant(plant)
    name = _checked_name(name, law)
    output = list(plant.input_names)
    if isinstance(law, LQG):
        return _lqg_iosys(law, plant, name, signal_names(measured_outputs(plant)), output)
    if law.n_states:
        raise InputValueError(f"to_iosys: {type(law).__name__} has {law.n_states} internal "
                              "states and no readings to take; only LQG's estimator is wired")
    none = np.zeros(0)

    def outfcn(t, x, u, params):
        return np.array([law.torque(t, np.asarray(u, dtype=float), none)])

    return control.nlsys(None, outfcn, inputs=signal_names(plant.state_names),
                         outputs=output, name=name)


def _checked_name(name, law) -> str:
    if name is not None and not isinstance(name, str):
        raise InputTypeError(f"to_iosys name must be a str; got {name!r}"[:300])
    if name is not None and (not name.strip() or "." in name):
        # python-control joins it to its signals' names ("name.torque")
        raise InputValueError(f"to_iosys name must be a non-blank str without dots; got "
                              f"{name!r}"[:300])
    return name or type(law).__name__.lower()


def _sampled_iosys(law, plant, name):
    """A held state law, its structural filters' states its own: a discrete-time system."""
    import control

    from .structural_filters import Filtered, bounded

    from flexctl.sim.digital import ZeroOrderHold

    filtered = law if isinstance(law, Filtered) else None
    held = filtered.law if filtered is not None else law
    inner = held.law if isinstance(held, ZeroOrderHold) else None
    if callable(getattr(inner, "for_plant", None)):
        inner = inner.for_plant(plant)
    if not (callable(getattr(inner, "torque", None)) and getattr(inner, "n_states", 1) == 0):
        what = (f"a ZeroOrderHold of a {type(inner).__name__}, not a flexctl feedback law"
                if isinstance(held, ZeroOrderHold) else
                f"{type(held).__name__} is a sampled law with states of its own (an estimator)")
        raise InputValueError(f"to_iosys: {what}; only a held state law (PD, LQR, "
                              "ScheduledLQR, TrajectoryTracker, LaggedLQR in a ZeroOrderHold), "
                              "with structural filters or not, is wired as a discrete system")
    none, dt = np.zeros(0), float(held.sample_time)
    cascade = filtered.cascade if filtered is not None else None
    limit = filtered.torque_limit if filtered is not None else None
    order = cascade.order if cascade is not None else 0

    def command(t, u):
        return float(inner.torque(t, np.asarray(u, dtype=float), none))

    def updfcn(t, w, u, params):
        return cascade.step(w, command(t, u))[1]

    def outfcn(t, w, u, params):
        v = command(t, u)
        return np.array([v if cascade is None else bounded(cascade.step(w, v)[0], limit)])

    return control.nlsys(updfcn if order else None, outfcn,
                         inputs=signal_names(plant.state_names),
                         outputs=list(plant.input_names),
                         states=[f"structural_filter_{k}" for k in range(order)] or None,
                         dt=dt,
                         name=name)


def _lqg_iosys(lqg, plant, name, readings, output):
    """LQG: the estimator's states, the readings in (noise added as the law's own)."""
    import control

    names = [f"xhat_{n}" for n in signal_names(lqg.layout.names)]

    def readings_of(t, u):
        y = np.asarray(u, dtype=float).reshape(-1)
        if lqg.measurement_noise is not None:
            y = y + np.asarray(lqg.measurement_noise(t), dtype=float).reshape(y.shape)
        return y

    def updfcn(t, z, u, params):
        z = np.asarray(z, dtype=float)
        torque = lqg.torque(t, None, z)
        innovation = readings_of(t, u) - lqg.c @ z
        return lqg.a @ z + lqg.b[:, 0] * torque + lqg.estimator_gain @ innovation

    def outfcn(t, z, u, params):
        return np.array([lqg.torque(t, None, np.asarray(z, dtype=float))])

    return control.nlsys(updfcn, outfcn, inputs=readings, outputs=output, states=names,
                         name=name)
