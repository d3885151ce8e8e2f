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
  torque; connect it to ``model.nonlinear()``.

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
        A built-in continuous feedback law: PD, LQR, ScheduledLQR, TrajectoryTracker,
        LaggedLQR, LQG (a sampled law has no continuous I/O system).
    plant : flexctl.Model
        The plant it reads and drives.
    name : str, optional
        The system's name (default the law's class name, lower case).

    Raises
    ------
    InputTypeError
        If ``plant`` is not a flexctl Model, or ``law`` not a flexctl feedback law.
    InputValueError
        For a sampled law.
    """
    import control

    from .lqg import LQG, measured_outputs

    if not isinstance(plant, Model):
        raise InputTypeError(f"to_iosys plant must be a flexctl Model; got "
                             f"{type(plant).__name__}")
    if getattr(law, "sample_time", None) is not None and callable(getattr(law, "start", None)):
        raise InputValueError(f"to_iosys: {type(law).__name__} is sampled (every "
                              f"{law.sample_time:g} s); a python-control nonlinear system is "
                              "continuous: pass the continuous law")
    if not (callable(getattr(law, "torque", None)) and hasattr(law, "n_states")):
        raise InputTypeError(f"to_iosys law must be a flexctl feedback law; got "
                             f"{type(law).__name__}")
    if callable(getattr(law, "for_plant", None)):
        law = law.for_plant(plant)
    if name is not None and not isinstance(name, str):
        raise InputTypeError(f"to_iosys name must be a str; got {name!r}"[:300])
    if name is not None and (not name.strip() or "." in name):
        # python-control joins it to its signals' names ("name.torque")
        raise InputValueError(f"to_iosys name must be a non-blank str without dots; got "
                              f"{name!r}"[:300])
    name = name or type(law).__name__.lower()
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
