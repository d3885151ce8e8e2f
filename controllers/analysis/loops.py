"""The frequency-domain view of a flexible loop, built on python-control.

A controller on a flexctl plant, linearised about a steady spin, seen as control engineers
first judge a flexible loop: the plant's channels, the loop transfer function broken at the
plant input, its stability margins, and how poles and zeros move with the spin rate. Every
system is a python-control ``StateSpace`` as python-control returns it; plot them with
:mod:`flexctl.app.plotting_loops` or python-control's own ``bode_plot`` / ``pole_zero_plot``.

===========================  =============================================================
function                     result
===========================  =============================================================
:func:`plant_channels`       torque to hub angle (collocated), tip deflection and tip angle
:func:`loop_transfer`        ``L(s)`` of a PD (any sensor), LQR, scheduled LQR, tracker or LQG
:func:`loop_margins`         gain and phase margins, crossovers, closed-loop stability
:func:`poles_vs_spin`        plant poles, hub-angle zeros and closed-loop poles against spin
===========================  =============================================================

Notes
-----
Plant state with ``N`` modes, ``n = 2 N + 2`` entries (as in :mod:`flexctl.model`)::

    x = [theta, q_1 .. q_N, theta_dot, q_1_dot .. q_N_dot]

Sign convention of the loop: the controller returns the torque ``u = -L(s) u_in`` to a
torque ``u_in`` injected at the plant input, so the closed loop is
``control.feedback(L)`` (negative feedback, unit gain) and its poles are the poles of the
plant under the controller. A gain margin ``g`` means the loop stays stable when ``L`` is
multiplied by any factor between the gain-reduction margin and ``g``.

On an undamped beam the flexible poles, and the hub-angle zeros between them, lie on the
imaginary axis: there the frequency response is infinite or zero and its phase undefined,
and python-control's polynomial margin search reports a phase crossing at each of them
(a gain margin of about 0 or infinity). :func:`loop_margins` leaves those out; a crossing
a little away from such a pole, on the skirt of its resonance, is kept.

Examples
--------
>>> import flexctl
>>> from controllers import design_pd
>>> from controllers.analysis.loops import loop_margins, loop_transfer
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=3)
>>> pd = design_pd(model, bandwidth=2.0, damping_ratio=0.9)
>>> margins = loop_margins(loop_transfer(model, pd))
>>> margins.closed_loop_stable, margins.gain_margin, round(margins.phase_margin)
(True, inf, 66)
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from flexctl.model import Model
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.checks import check_real
from flexctl.model.layout import StateLayout

from ..feedback.lqg import LQG
from ..feedback.lqr import LQR, checked_model, truncation_matrix
from ..design.plant_state import resized
from ..feedback.pd import PD, SENSORS
from ..feedback.scheduling import ScheduledLQR
from ..design.stability import stability_verdict
from ..feedback.tracking import TrajectoryTracker
from ..feedback.actuated import LaggedLQR
from ..feedback.observed_loop import observed_loop
from ..feedback.observer import Observed
from ..feedback.structural_filters import Filtered
from ..design.controllable import held
from flexctl.sim.digital import ZeroOrderHold
from .channels import PlantChannels, plant_channels

__all__ = ["closed_loop_verdict", "SENSORS", "PlantChannels", "plant_channels",
           "loop_transfer", "LoopMargins", "loop_margins", "PolesVsSpin", "poles_vs_spin",
           "hidden_poles"]

#: A pole of the open loop still a pole, to this fraction of its magnitude (at least 1/s), of
#: the loop closed at two gains is a hidden mode's (:func:`hidden_poles`).
_HIDDEN_RELATIVE = 1e-6
#: Frequencies at which a sampled loop's response is evaluated for its margins (evenly spaced
#: up to the Nyquist frequency; crossings are interpolated between them).
SAMPLED_GRID = 8_000
#: Relative distance within which a margin crossing is taken to sit on an undamped pole or
#: zero of the loop (or, times the loop's largest pole magnitude, on the origin).
AXIS_TOLERANCE = 1e-6


def _readonly(array) -> np.ndarray:
    array = np.array(array)
    array.setflags(write=False)
    return array


# --------------------------------------------------------------------------- loops
def _design_gain(owner: str, gain, plant: StateLayout,
                 design: StateLayout | None = None) -> np.ndarray:
    """A gain on a design state (layout ``design``, ``M <= N`` modes; by default the plant's
    blocks on the gain's mode count) lifted to the plant state (layout ``plant``), shape
    (1, n)."""
    gain = np.asarray(gain, dtype=float).reshape(1, -1)
    size = gain.shape[1]
    if design is None:
        design = resized(plant, size)
    if design is None or design.n_states != size or design.n_modes > plant.n_modes \
            or not np.all(np.isfinite(gain)):
        raise InputValueError(f"{owner}.controller gain must be finite with shape (1, 2 M + 2),"
                              f" M <= the plant's {plant.n_modes} modes; got shape {gain.shape}")
    return gain @ truncation_matrix(plant, design)


def _state_gain(model: Model, controller, spin_rate: float, sensor):
    """``K`` (1, n) of a static law on the plant state, or None for a dynamic law."""
    if isinstance(controller, PD):
        sensor = "theta" if sensor is None else sensor
        if sensor not in SENSORS:
            raise InputValueError(f"loop_transfer.sensor must be one of {', '.join(SENSORS)}; "
                                  f"got {sensor!r}")
        return controller.plant_gain(model, spin_rate, sensor)
    if sensor is not None:
        raise InputValueError("loop_transfer.sensor applies to a PD law only (an LQR, LQG or "
                              f"tracker reads what it was designed for); got {sensor!r} with "
                              f"a {type(controller).__name__}")
    if isinstance(controller, np.ndarray):
        return _design_gain("loop_transfer", controller, model.layout)
    if isinstance(controller, (LQR, ScheduledLQR, TrajectoryTracker)):
        return controller.plant_gain(model, spin_rate)
    if isinstance(controller, LaggedLQR):
        # a gain on the actuated plant's state, the wheel's lag included
        return controller.plant_gain(model, spin_rate)
    return None


def loop_transfer(model, controller, spin_rate: float = 0.0, *, sensor: str | None = None):
    """Loop transfer function ``L(s)`` of a controller on a plant, broken at the plant input.

    Parameters
    ----------
    model : flexctl.Model
        The plant, linearised about ``spin_rate`` (``N`` modes; the controller may have been
        designed on fewer).
    controller : PD, LQR, ScheduledLQR, TrajectoryTracker, LaggedLQR, LQG, Observed, Filtered or ndarray
        - :class:`~controllers.feedback.pd.PD`: ``u = -kp y - kd y_dot`` on the output ``sensor``;
        - :class:`~controllers.feedback.lqr.LQR`,
          :class:`~controllers.feedback.scheduling.ScheduledLQR` (its
          gain at ``spin_rate``), :class:`~controllers.feedback.tracking.TrajectoryTracker` (its
          feedback gain) or a gain array of shape (1, 2 M + 2): ``u = -K P x`` with ``P`` the
          truncation to the design's ``M`` modes
          (:func:`~controllers.feedback.lqr.truncation_matrix`);
        - :class:`~controllers.feedback.lqg.LQG`: its compensator (:meth:`LQG.compensator`) reading
          ``[theta, root_moment]`` of this plant;
        - :class:`~controllers.LaggedLQR`: its gain on the plant with the reaction wheel
          (``model`` built with ``actuator=wheel``), the wheel's lag in the loop;
        - :class:`~controllers.Observed`: the loop as it flies, sampled, held and late,
          through its Kalman filter: a discrete ``L(z)``
          (:func:`~controllers.feedback.observed_loop.observed_loop`);
        - :class:`~flexctl.sim.digital.ZeroOrderHold` of a law with a state gain: the held
          plant's discrete loop ``K (z I - Phi)^-1 Gamma``;
        - :class:`~controllers.Filtered`: a sampled law's discrete loop with its structural
          filters on the command, ``F(z) L(z)``
          (:meth:`~controllers.Filtered.loop_matrices`).

        References, feedforward and saturation play no part in the loop.
    spin_rate : float, optional
        Steady hub rate of the plant's linearisation, rad/s. Default 0.
    sensor : {"theta", "tip_angle", "tip_deflection"}, optional
        What a PD law reads: ``"theta"`` (default) is collocated with the torque, the others
        are not (:data:`SENSORS`). Only for PD.

    Returns
    -------
    control.StateSpace
        SISO, input ``torque`` (N m), output ``return_torque`` (N m): minus the torque the
        controller returns. ``control.feedback(L)`` is the closed loop (module Notes); its
        states are the plant's, then the controller's (LQG).

    Raises
    ------
    InputTypeError
        If ``model`` is not a Model or the controller is of no supported kind.
    InputValueError
        For a bad ``sensor``, a sensor given to a non-PD law, or a gain of the wrong shape.

    Examples
    --------
    >>> import numpy as np, control, flexctl
    >>> from controllers import PD
    >>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
    >>> loop = loop_transfer(model, PD(kp=10.0, kd=6.0))
    >>> loop.input_labels, loop.output_labels
    (['torque'], ['return_torque'])
    >>> bool(control.poles(control.feedback(loop)).real.max() < 0)
    True
    """
    import control

    model = checked_model("loop_transfer", model)
    spin_rate = check_real("loop_transfer", "spin_rate", spin_rate)
    a, b = model.linear_matrices(spin_rate)
    states = list(model.state_names)
    gain = _state_gain(model, controller, spin_rate, sensor)
    name = f"{type(controller).__name__.lower()}_loop"
    if gain is not None:
        return control.ss(a, b, gain, np.zeros((1, 1)), states=states, inputs=["torque"],
                          outputs=["return_torque"], name=name)
    if isinstance(controller, Observed):
        return observed_loop(model, controller, spin_rate, state_gain=_state_gain)
    if isinstance(controller, ZeroOrderHold):
        held_gain = _state_gain(model, controller.law, spin_rate, sensor)
        if held_gain is None:
            raise InputTypeError("loop_transfer.controller: the law inside the ZeroOrderHold "
                                 "must be one with a state gain (PD, LQR, ScheduledLQR, "
                                 "TrajectoryTracker, LaggedLQR or a gain array); got "
                                 f"{type(controller.law).__name__}")
        phi, gam = held(a, b, controller.sample_time)
        return control.ss(phi, gam, held_gain, np.zeros((1, 1)), dt=controller.sample_time,
                          states=states, inputs=["torque"], outputs=["return_torque"],
                          name=name)
    if isinstance(controller, Filtered):
        a, b, c, dt, names = controller.loop_matrices(model, spin_rate)
        return control.ss(a, b, c, np.zeros((1, 1)), dt=dt, states=list(names),
                          inputs=["torque"], outputs=["return_torque"], name=name)
    if not isinstance(controller, LQG):
        raise InputTypeError("loop_transfer.controller must be a PD, LQR, ScheduledLQR, "
                             "TrajectoryTracker, LaggedLQR, LQG, Observed, Filtered or a gain "
                             f"array; got {type(controller).__name__}")
    compensator = controller.compensator()
    meas = controller.for_plant(model).measurement_matrix
    sensors = control.ss(a, b, meas, np.zeros((meas.shape[0], 1)), states=states, inputs=["torque"],
                         outputs=list(compensator.input_labels))
    loop = -control.series(sensors, compensator)
    loop.update_names(inputs=["torque"], outputs=["return_torque"], name=name)
    return loop


# --------------------------------------------------------------------------- margins
def _optional_frequency(owner: str, name: str, value) -> float:
    value = float(value)
    if not (math.isnan(value) or value >= 0.0):
        raise InputValueError(f"{owner}.{name} must be >= 0 rad/s or NaN (no crossing); "
                              f"got {value!r}")
    return value


@dataclass(frozen=True, kw_only=True)
class LoopMargins:
    """Stability margins of a loop transfer function (:func:`loop_margins`).

    Attributes
    ----------
    gain_margin : float
        Factor by which the loop gain may grow before the closed loop loses stability,
        ``>= 1``; ``inf`` when no phase crossing limits it.
    gain_reduction_margin : float
        Factor to which the loop gain may shrink, in ``[0, 1]``; 0 when nothing but zero
        gain limits it.
    phase_margin : float
        Phase margin at the gain crossover closest to -180 deg, deg (python-control's
        sign: negative when the phase there lies past -180); ``inf`` without a crossover.
    stability_margin : float
        Smallest distance of the Nyquist plot from -1, ``min |1 + L(jw)|`` (1 / peak
        sensitivity).
    phase_crossover_frequency : float
        Where ``gain_margin`` is read, rad/s (NaN when infinite).
    gain_crossover_frequency : float
        Where ``phase_margin`` is read, rad/s (NaN without a crossover).
    stability_margin_frequency : float
        Where ``stability_margin`` is read, rad/s.
    spectral_abscissa : float
        Largest real part of the closed-loop poles, 1/s.
    closed_loop_stable : bool
        No closed-loop pole grows, the loop's hidden poles (:func:`hidden_poles`: a free
        hub's rigid translation) left out: the verdict :func:`controllers.check_loop` gives
        (:func:`~controllers.design.stability.stability_verdict`).
        When False, the two gain margins are the nearest factors at which the number of
        unstable closed-loop poles changes: the loop may regain stability there (tip
        feedback on a lightly damped beam does below its gain-reduction margin) or not.
    crossings : tuple of tuple
        Every crossing kept, by frequency: ``("phase", w, g)`` where the phase crosses
        -180 deg at ``w`` rad/s with the gain factor ``g`` left there, ``("gain", w, p)``
        where the gain crosses 1 with the phase margin ``p`` deg. Not in :meth:`as_dict`.
    """

    gain_margin: float
    gain_reduction_margin: float
    phase_margin: float
    stability_margin: float
    phase_crossover_frequency: float
    gain_crossover_frequency: float
    stability_margin_frequency: float
    spectral_abscissa: float
    closed_loop_stable: bool
    crossings: tuple = ()

    def __post_init__(self):
        owner = "loop_margins"
        object.__setattr__(self, "crossings", tuple(
            (str(kind), float(w), float(v)) for kind, w, v in self.crossings))
        if self.gain_margin != math.inf:
            object.__setattr__(self, "gain_margin", check_real(
                owner, "gain_margin", self.gain_margin, minimum=1.0))
        object.__setattr__(self, "gain_reduction_margin", check_real(
            owner, "gain_reduction_margin", self.gain_reduction_margin, minimum=0.0,
            maximum=1.0))
        pm = float(self.phase_margin)
        if not (pm == math.inf or -180.0 <= pm <= 180.0):
            raise InputValueError(f"{owner}.phase_margin must lie in [-180, 180] deg or be inf;"
                                  f" got {self.phase_margin!r}")
        object.__setattr__(self, "phase_margin", pm)
        sm = float(self.stability_margin)
        if not (sm >= 0.0):
            raise InputValueError(f"{owner}.stability_margin must be >= 0; got {sm!r}")
        object.__setattr__(self, "stability_margin", sm)
        for name in ("phase_crossover_frequency", "gain_crossover_frequency",
                     "stability_margin_frequency"):
            object.__setattr__(self, name, _optional_frequency(owner, name,
                                                               getattr(self, name)))
        object.__setattr__(self, "spectral_abscissa", check_real(
            owner, "spectral_abscissa", self.spectral_abscissa))
        if not isinstance(self.closed_loop_stable, (bool, np.bool_)):
            raise InputTypeError(f"{owner}.closed_loop_stable must be a bool; got "
                                 f"{self.closed_loop_stable!r}")
        object.__setattr__(self, "closed_loop_stable", bool(self.closed_loop_stable))

    @property
    def gain_margin_db(self) -> float:
        """:attr:`gain_margin` in dB, ``20 log10(gain_margin)``."""
        return 20.0 * math.log10(self.gain_margin)

    def as_dict(self) -> dict:
        """The scalar fields as a plain dict (a sweep row): every field but
        :attr:`crossings`."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__
                if name != "crossings"}


def _axis_frequencies(loop, tolerance: float) -> tuple:
    """Frequencies (rad/s) of the loop's poles and zeros on the imaginary axis, and the
    loop's frequency scale (its largest pole magnitude, at least 1)."""
    import control

    roots = np.concatenate((control.poles(loop), control.zeros(loop)))
    roots = roots[np.isfinite(roots) & (roots != 0)] if not loop.isctime() else roots
    roots = _as_rates(roots, loop)
    roots = roots[np.isfinite(roots)]
    scale = max(1.0, float(np.max(np.abs(roots), initial=0.0)))
    on_axis = np.abs(roots.real) <= tolerance * np.maximum(np.abs(roots), scale * tolerance)
    return np.unique(np.abs(roots[on_axis].imag)), scale


def _off_axis(frequencies, singular, scale, tolerance) -> np.ndarray:
    """Mask of the crossing frequencies that sit on none of the ``singular`` frequencies
    (within ``tolerance`` of each, relatively) and away from the origin (``tolerance *
    scale``)."""
    w = np.asarray(frequencies, dtype=float).reshape(-1, 1)
    near = np.abs(w - singular[None, :]) <= tolerance * singular[None, :]
    return ~np.any(near, axis=1) & (w[:, 0] > tolerance * scale)


def loop_margins(loop, *, tolerance: float = AXIS_TOLERANCE) -> LoopMargins:
    """Gain and phase margins of a SISO loop, from ``control.stability_margins``.

    Parameters
    ----------
    loop : control.LTI
        SISO loop transfer function, negative-feedback convention (e.g.
        :func:`loop_transfer`): continuous, or sampled (an observed law's), whose poles are
        judged as rates ``log(z) / T``.
    tolerance : float, optional
        Relative distance within which a crossing sits on an undamped pole or zero and is
        left out (module Notes). Default :data:`AXIS_TOLERANCE`.

    Returns
    -------
    LoopMargins
        The upward and downward gain margins are the crossings nearest to 1 on either side,
        from all crossings python-control finds (``returnall=True``); the phase margin is the
        one python-control picks (smallest in magnitude) among the kept crossovers.

    Raises
    ------
    InputTypeError
        If ``loop`` is not a python-control LTI system.
    InputValueError
        If it is not SISO or not continuous-time, or ``tolerance`` is not in (0, 1e-2].
    """
    import control

    if not isinstance(loop, control.LTI):
        raise InputTypeError(f"loop_margins.loop must be a python-control LTI system; got "
                             f"{type(loop).__name__}")
    if loop.ninputs != 1 or loop.noutputs != 1 or loop.dt is True:
        raise InputValueError("loop_margins.loop must be a SISO system, continuous or with a "
                              f"sample time; got {loop.noutputs} x {loop.ninputs}, dt = "
                              f"{loop.dt!r}")
    tolerance = check_real("loop_margins", "tolerance", tolerance, minimum=0.0, strict=True,
                           maximum=1e-2)
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        # the response is NaN exactly on an undamped pole: python-control compares it
        warnings.simplefilter("ignore", RuntimeWarning)
        gm, pm, sm, w180, wc, wms = control.stability_margins(_margin_data(loop),
                                                              returnall=True)
    singular, scale = _axis_frequencies(loop, tolerance)
    keep = _off_axis(w180, singular, scale, tolerance) & np.isfinite(gm)
    gm, w180 = np.asarray(gm)[keep], np.asarray(w180)[keep]
    keep = _off_axis(wc, singular, scale, tolerance) & np.isfinite(pm)
    pm, wc = np.asarray(pm)[keep], np.asarray(wc)[keep]

    up, down = gm > 1.0, gm < 1.0
    k_up = np.argmin(np.where(up, gm, np.inf)) if up.any() else None
    k_pm = np.argmin(np.abs(pm)) if pm.size else None
    sm, wms = np.asarray(sm, dtype=float), np.asarray(wms, dtype=float)
    k_sm = np.argmin(sm) if sm.size else None
    stable, abscissa = closed_loop_verdict(loop)
    return LoopMargins(
        gain_margin=float(gm[k_up]) if k_up is not None else math.inf,
        gain_reduction_margin=float(np.max(gm[down])) if down.any() else 0.0,
        phase_margin=float(pm[k_pm]) if k_pm is not None else math.inf,
        stability_margin=float(sm[k_sm]) if k_sm is not None else math.inf,
        phase_crossover_frequency=float(w180[k_up]) if k_up is not None else math.nan,
        gain_crossover_frequency=float(wc[k_pm]) if k_pm is not None else math.nan,
        stability_margin_frequency=float(wms[k_sm]) if k_sm is not None else math.nan,
        spectral_abscissa=abscissa, closed_loop_stable=stable,
        crossings=tuple(sorted([("phase", w, g) for w, g in zip(w180, gm)]
                               + [("gain", w, p) for w, p in zip(wc, pm)],
                               key=lambda item: item[1])))


def _margin_data(loop):
    """What the margins are read from: a continuous loop itself (python-control's polynomial
    search), a sampled one's frequency response on :data:`SAMPLED_GRID` frequencies up to
    its Nyquist frequency (the polynomial search in ``z`` loses its roots at the few tens
    of states of an observed loop)."""
    import control

    if loop.isctime():
        return loop
    nyquist = math.pi / float(loop.dt)
    return control.frd(loop, np.linspace(1e-4 * nyquist, (1.0 - 1e-9) * nyquist,
                                         SAMPLED_GRID))


def closed_loop_verdict(loop) -> tuple:
    """``(stable, spectral abscissa 1/s)`` of ``control.feedback(loop)``: the stability verdict
    :func:`loop_margins` and :func:`~controllers.check_loop` share
    (:func:`~controllers.design.stability.stability_verdict`, hidden modes left out).

    Parameters
    ----------
    loop : control.LTI
        A loop transfer of :func:`loop_transfer`, continuous or sampled.
    """
    import control

    poles = _as_rates(control.poles(control.feedback(loop)), loop)
    stable, abscissa, _ = stability_verdict(
        poles, _as_rates(hidden_poles(loop), loop),
        scale=None if loop.isctime() else math.pi / float(loop.dt))
    return stable, abscissa


def _as_rates(poles, loop) -> np.ndarray:
    """Poles as rates, 1/s: themselves for a continuous loop, ``log(z) / T`` for a sampled
    one."""
    poles = np.asarray(poles, dtype=complex)
    if loop.isctime():
        return poles
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(poles) / float(loop.dt)


def hidden_poles(loop) -> np.ndarray:
    """The loop's hidden poles: those of its open loop that no loop gain moves (its modes
    the input cannot move or the output cannot see, such as a free hub's rigid translation
    under a hub torque), 1/s.

    A pole of ``L`` that is still a pole of the closed loops ``feedback(L)`` and
    ``feedback(2 L)`` (within ``1e-6`` of its magnitude, at least 1/s) is hidden: a mode
    the loop both moves and sees moves with the gain. :func:`loop_margins` leaves them out
    of its verdict (:func:`~controllers.design.stability.stability_verdict`), as
    :func:`~controllers.check_loop` leaves out the plant's hidden modes.

    Parameters
    ----------
    loop : control.StateSpace
        SISO loop transfer function (negative-feedback convention), continuous or sampled.

    Returns
    -------
    ndarray of complex, shape (k,)
        In the loop's own variable: ``s`` (1/s), or ``z`` for a sampled loop.
    """
    import control

    open_loop = np.linalg.eigvals(np.asarray(loop.A, dtype=float))
    hidden = []
    moved = [np.asarray(control.poles(control.feedback(gain * loop)), dtype=complex)
             for gain in (1.0, 2.0)]
    for pole in open_loop:
        tol = _HIDDEN_RELATIVE * max(abs(pole), 1.0)
        if all(others.size and np.min(np.abs(others - pole)) <= tol for others in moved):
            hidden.append(pole)
    return np.array(hidden, dtype=complex)


# --------------------------------------------------------------------------- against spin
def _sorted_roots(roots) -> np.ndarray:
    """Roots sorted by imaginary, then real part (a reproducible order for tables)."""
    roots = np.asarray(roots, dtype=complex)
    return roots[np.lexsort((roots.real, roots.imag))]


def _padded(roots, size: int) -> np.ndarray:
    out = np.full(size, np.nan + 0j)
    roots = _sorted_roots(roots)[:size]
    out[:roots.size] = roots
    return out


@dataclass(frozen=True, kw_only=True, eq=False)
class PolesVsSpin:
    """Poles and zeros of a plant, and of a closed loop, at a list of spin rates.

    Build with :func:`poles_vs_spin`. Each row is one spin rate; within a row, roots are
    sorted by imaginary, then real part.

    Attributes
    ----------
    spin_rates : ndarray, shape (S,)
        rad/s.
    plant_poles : ndarray of complex, shape (S, 2 N + 2)
        Poles of ``model.linearize(spin_rate)``, 1/s.
    hub_angle_zeros : ndarray of complex, shape (S, 2 N)
        Zeros of the collocated channel torque -> hub angle, 1/s (NaN where fewer were
        found).
    natural_frequencies : ndarray, shape (S, N)
        Hub-free flexible frequencies, rad/s (:meth:`Model.natural_frequencies`).
    closed_loop_poles : ndarray of complex, shape (S, m), or None
        Poles of ``control.feedback(loop_transfer(...))`` with the controller fixed (designed
        once), 1/s; None without a controller.
    """

    spin_rates: np.ndarray
    plant_poles: np.ndarray
    hub_angle_zeros: np.ndarray
    natural_frequencies: np.ndarray
    closed_loop_poles: np.ndarray | None = None

    def __post_init__(self):
        rates = np.asarray(self.spin_rates, dtype=float)
        arrays = {"plant_poles": self.plant_poles, "hub_angle_zeros": self.hub_angle_zeros,
                  "natural_frequencies": self.natural_frequencies}
        if self.closed_loop_poles is not None:
            arrays["closed_loop_poles"] = self.closed_loop_poles
        for name, value in arrays.items():
            value = np.asarray(value)
            if value.ndim != 2 or value.shape[0] != rates.size:
                raise InputValueError(f"poles_vs_spin.{name} must have one row per spin rate "
                                      f"({rates.size}); got shape {value.shape}")
            object.__setattr__(self, name, _readonly(value))
        object.__setattr__(self, "spin_rates", _readonly(rates))


def _spin_rates(values) -> np.ndarray:
    if isinstance(values, (str, bytes)):
        raise InputTypeError(f"poles_vs_spin.spin_rates must be a sequence of numbers (rad/s);"
                             f" got {type(values).__name__}")
    try:
        rates = np.array(values, dtype=float, ndmin=1)
    except (TypeError, ValueError):
        raise InputTypeError("poles_vs_spin.spin_rates must be a sequence of numbers (rad/s); "
                             f"got {values!r}") from None
    if rates.ndim != 1 or rates.size == 0 or not np.all(np.isfinite(rates)):
        raise InputValueError("poles_vs_spin.spin_rates must be a non-empty 1-D sequence of "
                              f"finite numbers (rad/s); got {values!r}")
    return rates


def poles_vs_spin(model, spin_rates, controller=None, *,
                  sensor: str | None = None) -> PolesVsSpin:
    """The pole-zero map of a plant, and of a closed loop, against the spin rate.

    Parameters
    ----------
    model : flexctl.Model
        The plant, linearised about each spin rate.
    spin_rates : sequence of float
        Steady hub rates, rad/s.
    controller : optional
        Any controller :func:`loop_transfer` takes, designed once; default none (plant only).
    sensor : str, optional
        For a PD law, see :func:`loop_transfer`.

    Returns
    -------
    PolesVsSpin

    Examples
    --------
    >>> import numpy as np, flexctl
    >>> model = flexctl.build_model(flexctl.load_scene("kane-spinup").system, n_modes=2)
    >>> table = poles_vs_spin(model, [0.0, 5.0])
    >>> frequencies = np.abs(table.plant_poles.imag).max(axis=1)
    >>> bool(frequencies[1] > frequencies[0])      # spin stiffens the beam
    True
    """
    import control

    model = checked_model("poles_vs_spin", model)
    rates = _spin_rates(spin_rates)
    n = model.n_modes
    plant_poles, zeros, frequencies, closed = [], [], [], []
    for rate in rates:
        channels = plant_channels(model, rate)
        plant_poles.append(_sorted_roots(control.poles(channels.hub_angle)))
        zeros.append(_padded(control.zeros(channels.hub_angle), 2 * n))
        frequencies.append(channels.natural_frequencies)
        if controller is not None:
            loop = loop_transfer(model, controller, rate, sensor=sensor)
            closed.append(_sorted_roots(control.poles(control.feedback(loop))))
    return PolesVsSpin(spin_rates=rates, plant_poles=np.array(plant_poles),
                       hub_angle_zeros=np.array(zeros),
                       natural_frequencies=np.array(frequencies),
                       closed_loop_poles=np.array(closed) if closed else None)

