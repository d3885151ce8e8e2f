"""Closed-loop stability of a design on the plant it will run on, checked at design time.

A feedback law designed on ``M`` modes runs on a plant of ``N >= M`` modes. The modes the
design left out come back through the torque (control spillover) and through what the law
reads (observation spillover); on an undamped beam they sit on the imaginary axis, and a
little spillover of the wrong phase makes them grow slowly: unseen in a few-second slew,
fatal over minutes. :func:`check_loop` closes the loop of a law on the plant's linearisation
and names every pole that grows or barely decays; :func:`warn_if_unstable` turns that into
a :class:`LoopStabilityWarning`.

Notes
-----
A continuous law (PD, LQR, scheduled LQR, the trajectory tracker, LQG) is closed as
:func:`controllers.analysis.loops.loop_transfer` breaks it; a law sampled with a zero-order hold
(:class:`flexctl.sim.digital.ZeroOrderHold`) and NMPC's terminal LQR (discrete, held over
the NMPC's sample time) are closed on the plant discretised at their sample time, each
eigenvalue ``z`` read as ``s = log(z) / T``. A pole whose real part exceeds
``-NEARLY_UNSTABLE_RATE`` (1/s) is reported: above ``+STABILITY_TOLERANCE`` times the
loop's largest pole magnitude it grows (unstable), below it the loop is nearly unstable
(an e-fold decay slower than ``1 / NEARLY_UNSTABLE_RATE`` s). Poles of modes the torque
cannot move (:func:`controllers.design.controllable.controllable_part`: identical appendages
bending against each other, a free hub's translation) are the plant's own, whatever the
design: they are listed apart (``hidden_modes``) and do not count against it.

Each reported pole is named by the plant's open-loop flexible mode nearest in frequency
(``mode = 1`` the lowest); ``mode = 0`` is the rigid hub motion (below half the first
flexible frequency).

Examples
--------
>>> import flexctl
>>> from controllers import design_pd
>>> from controllers.design.stability import check_loop
>>> plant = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=4)
>>> design = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> check = check_loop(plant, design_pd(design, bandwidth=2.0, damping_ratio=0.9))
>>> check.stable, check.nearly_unstable, check.plant_modes
(True, False, 4)
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from flexctl.model import Model
from flexctl.model.checks import check_real
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.user_warnings import user_stacklevel

__all__ = ["LoopStability", "GrowingPole", "LoopStabilityWarning", "check_loop",
           "warn_if_unstable", "checked_on", "loop_stability", "least_damped_pole",
           "NEARLY_UNSTABLE_RATE", "stability_verdict"]

#: A pole that decays slower than this (1/s, an e-fold in 1000 s) is reported as nearly
#: unstable: far longer than any manoeuvre, so the loop does not damp it in practice.
NEARLY_UNSTABLE_RATE = 1e-3
#: A closed loop is stable when its largest pole real part is below ``STABILITY_TOLERANCE``
#: times its largest pole magnitude (eigenvalue rounding of an undamped mode is ~1e-13 of it).
STABILITY_TOLERANCE = 1e-10
#: Relative frequency within which a closed-loop pole is taken to be a hidden mode's.
_HIDDEN_TOLERANCE = 1e-6


class LoopStabilityWarning(UserWarning):
    """A design whose loop is unstable or nearly unstable on the plant it will run on."""


@dataclass(frozen=True, kw_only=True)
class GrowingPole:
    """One closed-loop pole (of a complex pair: the one with ``frequency >= 0``).

    Attributes
    ----------
    mode : int
        The plant's open-loop flexible mode nearest in frequency (1 = lowest), 0 for the rigid
        hub motion.
    frequency : float
        Imaginary part, rad/s (>= 0).
    growth_rate : float
        Real part, 1/s: positive grows, negative decays.
    """

    mode: int
    frequency: float
    growth_rate: float

    def describe(self) -> str:
        """``"mode 3 at 68.49 rad/s grows at 0.0236 1/s"`` (or ``decays at``)."""
        where = "the rigid hub motion" if self.mode == 0 else f"mode {self.mode}"
        verb = "grows" if self.growth_rate > 0 else "decays only"
        return (f"{where} at {self.frequency:.4g} rad/s {verb} at "
                f"{abs(self.growth_rate):.3g} 1/s")


@dataclass(frozen=True, kw_only=True)
class LoopStability:
    """What :func:`check_loop` found: the loop of a law on a plant.

    Attributes
    ----------
    law : str
        The law's kind (class name).
    plant_variant : str
    plant_modes : int
        The plant's mode count (all appendages).
    spin_rate : float
        Steady hub rate of the plant's linearisation, rad/s.
    sample_time : float or None
        Sample time, s, for a loop closed in discrete time; None for a continuous one.
    spectral_abscissa : float
        Largest real part of the closed-loop poles (hidden modes left out), 1/s.
    stable : bool
        No pole grows (``spectral_abscissa < STABILITY_TOLERANCE`` times the largest pole
        magnitude, as in :func:`controllers.analysis.loops.loop_margins`).
    poles : tuple of GrowingPole
        The poles with real part above ``-NEARLY_UNSTABLE_RATE``, fastest growth first.
    hidden_modes : tuple of float
        Frequencies (rad/s) of the modes the torque cannot move, whatever the law.
    """

    law: str
    plant_variant: str
    plant_modes: int
    spin_rate: float
    sample_time: float | None
    spectral_abscissa: float
    stable: bool
    poles: tuple
    hidden_modes: tuple = ()

    @property
    def nearly_unstable(self) -> bool:
        """Stable, but a pole decays slower than ``NEARLY_UNSTABLE_RATE``."""
        return self.stable and bool(self.poles)

    @property
    def ok(self) -> bool:
        """Neither unstable nor nearly unstable."""
        return self.stable and not self.poles

    def message(self) -> str:
        """One line: the verdict, the worst pole, and how many more there are."""
        where = (f"the {self.plant_variant} plant with {self.plant_modes} modes"
                 + (f" at {self.spin_rate:g} rad/s spin" if self.spin_rate else ""))
        if self.ok:
            return f"{self.law} is stable on {where}"
        state = "unstable" if not self.stable else "nearly unstable"
        worst, rest = self.poles[0], self.poles[1:]
        text = f"{self.law} is {state} on {where}: {worst.describe()}"
        if worst.growth_rate > 0:
            text += f" (an e-fold in {1.0 / worst.growth_rate:.3g} s)"
        if rest:
            text += "; also " + ", ".join(f"mode {p.mode} ({p.growth_rate:+.3g} 1/s)"
                                          for p in rest)
        return text

    def as_dict(self) -> dict:
        """Plain numbers for a summary or a table."""
        worst = self.poles[0] if self.poles else None
        return {"closed_loop_stable": self.stable, "nearly_unstable": self.nearly_unstable,
                "spectral_abscissa": self.spectral_abscissa,
                "plant_variant": self.plant_variant, "plant_modes": self.plant_modes,
                "worst_mode": None if worst is None else worst.mode,
                "worst_mode_frequency": None if worst is None else worst.frequency,
                "worst_growth_rate": None if worst is None else worst.growth_rate,
                "message": self.message()}


# --------------------------------------------------------------------------- the loop
def _unwrap(controller) -> tuple:
    """The feedback law inside the wrappers (a zero-order hold, an observer, a DC motor's
    voltage) and the sample time of a hold, if any."""
    sample_time, seen = None, set()
    law = controller
    while id(law) not in seen:
        seen.add(id(law))
        if sample_time is None and getattr(law, "sample_time", None) is not None \
                and hasattr(law, "law"):
            sample_time = float(law.sample_time)
        inner = getattr(law, "law", None)
        if inner is None:
            break
        law = inner
    return law, sample_time


def _plant_for(plant, law):
    """The plant the law's loop closes on: the actuated plant for a law that reads the
    actuator's states (``reads_actuator``: LQR with the wheel's lag), else the structure
    (the law's torque taken as given)."""
    return plant if getattr(law, "reads_actuator", False) else getattr(plant, "mechanical",
                                                                        plant)


def _lifted(gain, plant_layout, design_layout) -> np.ndarray:
    """A gain on the design state lifted to the plant state (zero on the other entries)."""
    gain = np.asarray(gain, dtype=float).reshape(1, -1)
    if design_layout is None or design_layout.n_states != gain.shape[1] \
            or design_layout.n_modes > plant_layout.n_modes or not np.all(np.isfinite(gain)):
        raise InputValueError(f"check_loop.controller gain must be finite with shape (1, 2 M "
                              f"+ 2), M <= the plant's {plant_layout.n_modes} modes; got shape "
                              f"{gain.shape}")
    return gain @ np.eye(plant_layout.n_states)[plant_layout.projection(design_layout)]


def _closed_loop(plant: Model, law, spin_rate: float, sample_time):
    """Closed-loop matrix and its sample time (None: continuous), from the law's own linear
    loop: ``terminal_gain()`` (NMPC), a gain array, ``plant_gain(plant, spin_rate)`` (the
    static laws) or ``closed_loop_matrix(plant, spin_rate)`` (LQG)."""
    from .plant_state import resized

    if callable(getattr(law, "terminal_gain", None)):
        gain, design, sample_time = law.terminal_gain()
        gain = _lifted(gain, plant.layout, design)
    elif isinstance(law, np.ndarray):
        gain = _lifted(law, plant.layout, resized(plant.layout, law.size))
    elif callable(getattr(law, "plant_gain", None)):
        gain = np.asarray(law.plant_gain(plant, spin_rate), dtype=float)
    elif callable(getattr(law, "closed_loop_matrix", None)):
        if sample_time is not None:
            raise InputValueError("check_loop: a law with internal states (LQG) runs "
                                  "continuously; it cannot sit behind a zero-order hold")
        return np.asarray(law.closed_loop_matrix(plant, spin_rate), dtype=float), None
    else:
        raise InputTypeError("check_loop.controller must be a PD, LQR, ScheduledLQR, "
                             "TrajectoryTracker, LQG, NMPC or a gain array (or one of these "
                             f"behind a hold, an observer or a motor); got "
                             f"{type(law).__name__}")
    if sample_time is None:
        a, b = plant.linear_matrices(spin_rate)
        return a - b @ gain, None
    from .controllable import held

    a_d, b_d = held(*plant.linear_matrices(spin_rate), sample_time)
    return a_d - b_d @ gain, sample_time


def _poles(matrix, sample_time, plant: Model, spin_rate: float) -> tuple:
    """Closed-loop poles as ``s`` (1/s) and the open-loop mode each lies nearest to.

    A discrete pole ``z`` is matched to the nearest open-loop ``exp(lambda T)`` in the
    z-plane (a mode above the Nyquist frequency aliases), and its frequency is that mode's."""
    a, _ = plant.linear_matrices(spin_rate)
    open_loop = np.linalg.eigvals(a)
    scale = max(1.0, float(np.max(np.abs(open_loop))))
    flexible = np.sort(open_loop.imag[open_loop.imag > 1e-9 * scale])
    eig = np.linalg.eigvals(matrix)
    if sample_time is None:
        return eig, np.array([_mode_of(float(abs(p.imag)), flexible) for p in eig]), flexible
    targets = np.concatenate(([0.0], flexible, -flexible))
    z_open = np.exp(1j * targets * sample_time)
    nearest = np.array([int(np.argmin(np.abs(z_open - z / max(abs(z), 1e-300)))) for z in eig])
    with np.errstate(divide="ignore"):
        growth = np.log(np.abs(eig)) / sample_time
    modes = np.where(nearest > flexible.size, nearest - flexible.size, nearest)
    return growth + 1j * targets[nearest], modes, flexible


def _mode_of(frequency: float, flexible: np.ndarray) -> int:
    if flexible.size == 0 or frequency < 0.5 * flexible[0]:
        return 0
    return int(np.argmin(np.abs(flexible - frequency))) + 1


def _hidden(plant: Model, spin_rate: float) -> tuple:
    from .controllable import controllable_part

    try:
        return controllable_part(plant, spin_rate).dropped
    except (AttributeError, NotImplementedError):    # a model with no modal report
        return ()


def check_loop(plant, controller, spin_rate: float = 0.0) -> LoopStability:
    """Close a law's loop on the linearised plant and report its slow and growing poles.

    Parameters
    ----------
    plant : flexctl.Model
        The plant the law will run on, with its own mode count and variant (an actuated
        plant is checked on its structure: the law's torque taken as given).
    controller : object
        PD, LQR, ScheduledLQR, TrajectoryTracker, LQG, a gain array, NMPC (its terminal LQR,
        which is also the gain of its unconstrained real-time iteration), or any of these
        behind a zero-order hold, an observer or a DC motor's voltage. Behind an observer
        (:class:`controllers.Observed`) the loop is checked as it flies: sampled, with the
        sensors' delay and the Kalman filter of the law's own model
        (:meth:`~controllers.feedback.observer.Observed.sampled_loop`); a law with no
        linear loop there (an NMPC, a motor's voltage) is checked on the true state.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.

    Returns
    -------
    LoopStability

    Raises
    ------
    InputTypeError
        If ``plant`` is not a Model or the law is of no kind with a linear loop.
    """
    if not isinstance(plant, Model):
        raise InputTypeError(f"check_loop.plant must be a flexctl Model; got "
                             f"{type(plant).__name__}")
    spin_rate = check_real("check_loop", "spin_rate", spin_rate)
    flown = _flown_loop(plant, controller, spin_rate)
    if flown is not None:
        return flown
    law, sample_time = _unwrap(controller)
    plant = _plant_for(plant, law)
    matrix, sample_time = _closed_loop(plant, law, spin_rate, sample_time)
    name = "NMPC terminal LQR" if type(law).__name__ == "NMPC" else type(law).__name__
    return loop_stability(plant, matrix, name, spin_rate, sample_time)


def _flown_loop(plant, controller, spin_rate: float):
    """The :class:`LoopStability` of a law that reads sensors or passes its command through
    structural filters, by its loop as it flies (``controller.loop_matrices``: sampled, late,
    through its own Kalman filter, with the filters' states); None for another law, or one
    whose loop has no linear form (an NMPC, a motor's voltage), which is then checked on the
    true state."""
    if not (callable(getattr(controller, "loop_matrices", None))
            or (getattr(controller, "measures", False)
                and callable(getattr(controller, "sampled_loop", None)))):
        return None
    try:
        if callable(getattr(controller, "loop_matrices", None)):
            a, b, c, dt, _ = controller.loop_matrices(plant, spin_rate)
        else:
            loop = controller.sampled_loop(plant, spin_rate)
            a, b, c, dt = loop.A, loop.B, loop.C, loop.dt
    except (InputTypeError, InputValueError):
        return None
    matrix = np.asarray(a) - np.asarray(b) @ np.asarray(c)
    law = controller.law
    law = getattr(law, "law", law) if hasattr(controller, "cascade") else law
    name = type(law).__name__
    if getattr(controller, "measures", False):
        name += " on its Kalman filter"
    if hasattr(controller, "cascade"):
        name += " with structural filters"
    return loop_stability(plant, matrix, name, spin_rate, float(dt))


def loop_stability(plant, matrix, law: str, spin_rate: float = 0.0,
                   sample_time: float | None = None) -> LoopStability:
    """The :class:`LoopStability` of a closed-loop matrix on ``plant``'s linearisation.

    Parameters
    ----------
    plant : flexctl.Model
        The plant whose modes name the poles (its states first in ``matrix``).
    matrix : array_like, shape (n, n)
        Closed-loop ``A`` (continuous) or ``A_d`` (held over ``sample_time``).
    law : str
        The law's name in the message.
    spin_rate : float, optional
        Steady hub rate of the plant's linearisation, rad/s. Default 0.
    sample_time : float, optional
        Sample time, s, for a discrete ``matrix``. Default: continuous.
    """
    matrix = np.asarray(matrix, dtype=float)
    poles, modes, _ = _poles(matrix, sample_time, plant, spin_rate)
    hidden = _hidden(plant, spin_rate)
    stable, abscissa, keep = stability_verdict(
        poles, [complex(0.0, w) for w in hidden] + [complex(0.0, -w) for w in hidden])
    poles, modes = (poles[keep], modes[keep]) if keep.any() else (np.zeros(1, complex), [0])
    slow = sorted((k for k, p in enumerate(poles)
                   if p.real > -NEARLY_UNSTABLE_RATE and p.imag >= 0.0),
                  key=lambda k: -poles[k].real)
    reported = tuple(GrowingPole(mode=int(modes[k]), frequency=float(poles[k].imag),
                                 growth_rate=float(poles[k].real)) for k in slow)
    return LoopStability(law=law, plant_variant=str(plant.variant),
                         plant_modes=int(plant.layout.n_modes), spin_rate=float(spin_rate),
                         sample_time=sample_time, spectral_abscissa=abscissa,
                         stable=stable, poles=reported,
                         hidden_modes=tuple(float(w) for w in hidden))


def stability_verdict(poles, hidden=(), scale: float | None = None) -> tuple:
    """The one stability verdict of a closed loop's poles, shared by :func:`check_loop` and
    :func:`controllers.analysis.loops.loop_margins`.

    The poles on the imaginary axis that lie on a hidden mode (one the loop can neither move
    nor see: a free hub's rigid translation, a mode with a node at the sensor and the
    actuator) are left out: they are the plant's own, neither growing nor decaying whatever
    the law, and rounding splits their repeated poles by ~1e-8 to either side. A hidden pole
    off the axis is counted like any other. The loop is stable when the largest real part of
    the others is below :data:`STABILITY_TOLERANCE` times the largest pole magnitude (at
    least 1/s): a pole on the axis to rounding (about 1e-13 of it) does not grow.

    Parameters
    ----------
    poles : array_like of complex, shape (n,)
        The closed loop's poles, 1/s (a discrete loop's as ``log(z) / T``).
    hidden : sequence of complex, optional
        The hidden modes' poles, 1/s: every closed-loop pole within ``1e-6`` of the largest
        pole magnitude of one of them, and of the axis, is left out. Default none.
    scale : float, optional
        The loop's rate scale, 1/s, in place of the largest finite pole magnitude: a sampled
        loop's Nyquist rate ``pi / T`` (a pole at ``z = 0`` has no finite rate, and one near
        it an arbitrary one). Default: the largest finite pole magnitude.

    Returns
    -------
    stable : bool
    spectral_abscissa : float
        Largest real part of the poles kept, 1/s (of all of them when every one is hidden).
    kept : ndarray of bool, shape (n,)
        Which poles were kept.
    """
    poles = np.asarray(poles, dtype=complex).reshape(-1)
    finite = np.abs(poles[np.isfinite(poles)])
    radius = max(1.0, float(scale) if scale is not None
                 else float(np.max(finite, initial=0.0)))
    hidden = np.asarray(list(hidden), dtype=complex).reshape(-1)
    hidden = hidden[np.isfinite(hidden)]         # a sampled loop's z = 0 decays at once
    # a repeated hidden pole (a free hub's translation: a double pole at 0 per axis) splits
    # under rounding, by ~1e-8 of a sampled loop's rate: every pole that near it is its
    kept = np.array([not any(abs(p - h) <= _HIDDEN_TOLERANCE * max(abs(h), radius)
                             and abs(p.real) <= _HIDDEN_TOLERANCE * max(abs(h), radius)
                             for h in hidden) for p in poles], dtype=bool)
    counted = poles[kept] if kept.any() else poles
    abscissa = float(np.max(counted.real)) if counted.size else -math.inf
    return bool(abscissa < STABILITY_TOLERANCE * radius), abscissa, kept


def least_damped_pole(plant, matrix, spin_rate: float = 0.0,
                      sample_time: float | None = None) -> GrowingPole:
    """The pole of largest real part of a closed-loop matrix on ``plant`` (as in
    :func:`loop_stability`, hidden modes included), named by its mode.

    Parameters
    ----------
    plant : flexctl.Model
        The plant whose open-loop modes name the pole.
    matrix : array_like, shape (m, m)
        Closed-loop ``A`` (continuous) or ``A_d`` (held over ``sample_time``), of the plant's
        states and any states of the law.
    spin_rate : float, optional
        Steady hub rate of the plant's linearisation, rad/s. Default 0.
    sample_time : float, optional
        Sample time, s, for a discrete ``matrix``. Default: continuous.
    """
    poles, modes, _ = _poles(np.asarray(matrix, dtype=float), sample_time, plant, spin_rate)
    k = max((k for k, p in enumerate(poles) if p.imag >= 0.0), key=lambda k: poles[k].real)
    return GrowingPole(mode=int(modes[k]), frequency=float(poles[k].imag),
                       growth_rate=float(poles[k].real))


def warn_if_unstable(check: LoopStability, stacklevel: int | None = 2) -> LoopStability:
    """Warn (:class:`LoopStabilityWarning`) when ``check`` is unstable or nearly so; return
    ``check``.

    Parameters
    ----------
    check : LoopStability
        What :func:`check_loop` found.
    stacklevel : int or None, optional
        ``stacklevel`` of the warning as seen from the caller of this function (2: the
        caller's caller); None: the first line outside flexctl and controllers (the user's,
        :func:`flexctl.model.user_warnings.user_stacklevel`). Default 2.

    Raises
    ------
    InputTypeError
        If ``check`` is not a :class:`LoopStability`.
    """
    if not isinstance(check, LoopStability):
        raise InputTypeError(f"warn_if_unstable.check must be a LoopStability; got "
                             f"{type(check).__name__}")
    if not check.ok:
        warnings.warn(check.message(), LoopStabilityWarning,
                      stacklevel=user_stacklevel() if stacklevel is None else stacklevel + 1)
    return check


def checked_on(controller, plant, stacklevel: int = 2):
    """``controller``, its loop checked on ``plant`` (warning when unstable or nearly so);
    unchecked when ``plant`` is None. For the design functions' ``plant`` argument.

    Parameters
    ----------
    controller : object
        A law :func:`check_loop` takes (PD, LQR, ScheduledLQR, LQG, ..., or one of these
        behind a hold, an observer or a motor).
    plant : flexctl.Model or None
        The plant the law will run on; None skips the check.
    stacklevel : int, optional
        ``stacklevel`` of the warning as seen from the caller of this function (2: the
        caller's caller). Default 2.
    """
    if plant is not None:
        warn_if_unstable(check_loop(plant, controller), stacklevel=stacklevel + 1)
    return controller
