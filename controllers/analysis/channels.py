"""A flexible plant's channels from the hub torque, as python-control systems.

:func:`plant_channels` gives the transfer from the hub torque to the hub angle (collocated),
the tip deflection and the tip angle of a plant linearised about a steady spin
(:class:`PlantChannels`); :mod:`controllers.analysis.loops` builds the loop on them.

Examples
--------
>>> import flexctl
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> plant_channels(model).hub_angle.ninputs
1
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexctl.model import Model
from flexctl.model.checks import check_real
from flexctl.model.errors import InputTypeError, InputValueError

from ..feedback.lqr import checked_model

__all__ = ["PlantChannels", "plant_channels"]


def _readonly(array) -> np.ndarray:
    array = np.array(array)
    array.setflags(write=False)
    return array


def _channel(model: Model, plant, output: str):
    """The SISO channel torque -> ``output`` of the linear plant, names kept."""
    import control

    row = model.output_names.index(output)
    return control.ss(plant.A, plant.B, plant.C[row:row + 1], plant.D[row:row + 1],
                      states=list(model.state_names), inputs=["torque"], outputs=[output],
                      name=f"{plant.name}_{output}")


@dataclass(frozen=True, kw_only=True, eq=False)
class PlantChannels:
    """SISO channels of a linear plant from the hub torque (N m).

    Build with :func:`plant_channels`.

    Attributes
    ----------
    spin_rate : float
        Steady hub rate of the linearisation, rad/s.
    hub_angle : control.StateSpace
        Torque to hub angle, rad/(N m): collocated. Its zeros are the flexible frequencies
        with the hub held (``natural_frequencies(spin, hub="clamped")``), interlaced with the
        poles.
    tip_deflection : control.StateSpace
        Torque to tip deflection in the hub frame, m/(N m): non-collocated.
    tip_angle : control.StateSpace
        Torque to ``theta + tip_deflection / (b + l)``, rad/(N m): non-collocated, with zeros
        in the right half-plane.
    natural_frequencies : ndarray, shape (N,)
        Flexible frequencies with the hub free, rad/s (the poles ``+-j w_i`` of an undamped
        plant).
    clamped_frequencies : ndarray, shape (N,)
        Flexible frequencies with the hub held, rad/s.
    """

    spin_rate: float
    hub_angle: object
    tip_deflection: object
    tip_angle: object
    natural_frequencies: np.ndarray
    clamped_frequencies: np.ndarray

    def __post_init__(self):
        import control

        object.__setattr__(self, "spin_rate",
                           check_real("plant_channels", "spin_rate", self.spin_rate))
        for name in ("hub_angle", "tip_deflection", "tip_angle"):
            sys = getattr(self, name)
            if not isinstance(sys, control.StateSpace) or sys.ninputs != 1 \
                    or sys.noutputs != 1:
                raise InputTypeError(f"plant_channels.{name} must be a SISO control.StateSpace;"
                                     f" got {type(sys).__name__}")
        for name in ("natural_frequencies", "clamped_frequencies"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.ndim != 1 or not np.all(np.isfinite(value)):
                raise InputValueError(f"plant_channels.{name} must be a finite vector (rad/s);"
                                      f" got shape {value.shape}")
            object.__setattr__(self, name, _readonly(value))

    def __repr__(self):
        # One line: the matrices of the three channels would print hundreds of lines.
        outputs = ", ".join(sys.output_labels[0] for sys in
                            (self.hub_angle, self.tip_deflection, self.tip_angle))
        frequencies = "".join(
            f", first {kind} frequency {values[0]:.4g} rad/s"
            for kind, values in (("natural", self.natural_frequencies),
                                 ("clamped", self.clamped_frequencies)) if values.size)
        return (f"PlantChannels(torque -> {outputs}; spin_rate={self.spin_rate:.6g} rad/s, "
                f"{self.hub_angle.nstates} states, {self.natural_frequencies.size} modes"
                f"{frequencies})")


def plant_channels(model, spin_rate: float = 0.0) -> PlantChannels:
    """The hub-angle, tip-deflection and tip-angle channels of ``model.linearize(spin_rate)``.

    Parameters
    ----------
    model : flexctl.Model
        Any variant (the exact variant linearises to first_order's stiffness).
    spin_rate : float, optional
        Steady hub rate ``Omega`` of the linearisation, rad/s. Default 0.

    Returns
    -------
    PlantChannels

    Examples
    --------
    >>> import numpy as np, control, flexctl
    >>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    >>> channels = plant_channels(model)
    >>> zeros = np.sort(np.abs(control.zeros(channels.hub_angle).imag))[::2]
    >>> bool(np.allclose(zeros, channels.clamped_frequencies))
    True
    """
    model = checked_model("plant_channels", model)
    spin_rate = check_real("plant_channels", "spin_rate", spin_rate)
    plant = model.linearize(spin_rate)
    return PlantChannels(spin_rate=spin_rate,
                         hub_angle=_channel(model, plant, "theta"),
                         tip_deflection=_channel(model, plant, "tip_deflection"),
                         tip_angle=_channel(model, plant, "tip_angle"),
                         natural_frequencies=model.natural_frequencies(spin_rate, hub="free"),
                         clamped_frequencies=model.natural_frequencies(spin_rate))
