"""Three-axis loops on the linear flexible spacecraft, and their disk margins.

:func:`quaternion_loop` closes :class:`~controllers.feedback.quaternion.QuaternionFeedback`
around the linear plant of a spatial structure at rest
(:func:`flexctl.model.spatial_plant.linearize_spatial`, every appendage's modes in it): the
law, linearised (``2 dq_v`` is the attitude error ``e`` to first order), is
``u = -(K_p e + K_d w + K_i integral(e))``, so that with ``K(s) = K_p [I 0] + K_d [0 I] +
K_i / s [I 0]`` on the plant's outputs ``y = (e, w)`` the loop broken at the plant's three
torque inputs is ``L(s) = K(s) P(s)`` in negative feedback (python-control's convention). A
delay of the command (a sample's hold and the computation) enters as a Pade approximation of
each input.

:func:`quaternion_disk_margins` reads the loop's disk margins (Seiler, Packard and Gahinet,
2020), balanced (skew 0) unless asked otherwise:

- **loop at a time**: each torque axis perturbed alone, the other two loops closed; from the
  sensitivity's diagonal, ``S_ii = [(I + L)^-1]_ii``, the disk margin of axis ``i`` is
  ``alpha_i = 1 / max_w |S_ii(jw) - (1 - sigma) / 2|`` (gain margin
  ``(1 + (1 - sigma) alpha / 2) / (1 - (1 + sigma) alpha / 2)``, phase margin from the same
  disk), on a frequency grid that holds every pole and zero of the loop's frequency range;
- **all loops at once** (multi-loop, independent perturbations of the three inputs at once):
  python-control's :func:`control.disk_margins` on the MIMO loop, whose structured singular
  value bound comes from SLICOT's AB13MD through slycot (on :data:`MULTILOOP_POINTS` of the
  grid's frequencies and the ``MULTILOOP_PEAKS`` where single loops come closest); None
  where slycot is missing.

:func:`lq_loop` is the loop of a three-axis LQR or LQG
(:mod:`controllers.feedback.spatial_lqr`), continuous or held at its sample time, and
:func:`loop_disk_margins` reads the same margins of any three-axis loop, a sampled one on the
unit circle up to its Nyquist frequency.

A closed loop that is not stable has no margins: they are reported as zero, with the spectral
abscissa that says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexctl.model.checks import check_instance, check_real
from flexctl.model.errors import InputValueError
from flexctl.model.spatial_plant import linearize_spatial
from flexctl.model.spatial_structure import SpatialStructure

from ..feedback.quaternion import QuaternionFeedback
from ..feedback.spatial_lqr import SpatialLQG, SpatialLQR
from ..feedback.spatial_scheduling import ScheduledSpatialLQR

__all__ = ["quaternion_loop", "quaternion_disk_margins", "loop_disk_margins", "lq_loop",
           "DiskMargins", "PADE_ORDER",
           "GRID_POINTS", "MULTILOOP_POINTS", "MULTILOOP_PEAKS"]

#: Order of the Pade approximation of a command delay.
PADE_ORDER = 6
#: Points of the logarithmic frequency grid (poles' and zeros' frequencies are added).
GRID_POINTS = 4000
#: Points of that grid, evenly spaced, on which the margin of all loops at once is read, and
#: how many of the frequencies where single loops come closest are added to them.
MULTILOOP_POINTS = 300
MULTILOOP_PEAKS = 100
#: A closed-loop pole counts as growing past this real part, relative to the loop's fastest
#: pole (a free hub's rigid translation sits at zero, up to rounding).
GROWTH_TOLERANCE = 1e-9


def quaternion_loop(law, structure, *, n_modes=4, variant: str = "exact",
                    delay: float = 0.0):
    """The loop transfer ``L = K P`` of ``law`` on ``structure``'s linear plant at rest,
    broken at the plant's torque inputs.

    Parameters
    ----------
    law : QuaternionFeedback
        The three-axis law (its gains; its saturation is not in a linear loop).
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, optional
        Modes per field of every appendage. Default 4.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model linearised (at rest all three give one plant). Default ``"exact"``.
    delay : float, optional
        Delay of the command, s (>= 0), as a Pade approximation of order
        :data:`PADE_ORDER` on each input. Default 0.

    Returns
    -------
    control.StateSpace
        3 inputs (``tx, ty, tz`` perturbations) and 3 outputs (the law's torques), negative
        feedback.
    """
    import control

    check_instance("quaternion_loop", "law", law, QuaternionFeedback)
    check_instance("quaternion_loop", "structure", structure, SpatialStructure)
    delay = check_real("quaternion_loop", "delay", delay, minimum=0.0, maximum=10.0)
    if np.any(np.asarray(law.target_rate) != 0.0):
        raise InputValueError(f"quaternion_loop: the loop is taken at rest; the law's "
                              f"target_rate must be zero, got {np.asarray(law.target_rate)}")
    plant = linearize_spatial(structure, n_modes, variant=variant)
    outputs = [plant.output_labels.index(n) for n in ("ex", "ey", "ez", "wx", "wy", "wz")]
    p = control.ss(plant.A, plant.B, plant.C[outputs, :], plant.D[outputs, :])
    pick_e = np.hstack([np.eye(3), np.zeros((3, 3))])
    gains = np.hstack([law.kp, law.kd])
    if np.any(law.ki != 0.0):
        k = control.ss(np.zeros((3, 3)), pick_e, law.ki, gains)
    else:
        k = control.ss(np.zeros((0, 0)), np.zeros((0, 6)), np.zeros((3, 0)), gains)
    loop = k * p
    if delay > 0.0:
        num, den = control.pade(delay, PADE_ORDER)
        hold = control.ss(control.tf(num, den))
        loop = loop * control.append(hold, hold, hold)
    return control.ss(loop.A, loop.B, loop.C, loop.D, inputs=["tx", "ty", "tz"],
                      outputs=["ux", "uy", "uz"], name="quaternion_loop")


@dataclass(frozen=True)
class DiskMargins:
    """Disk margins of a three-axis loop (:func:`quaternion_disk_margins`).

    Attributes
    ----------
    disk_margin : ndarray, shape (3,)
        ``alpha`` of each torque axis, loop at a time.
    gain_margin_db : ndarray, shape (3,)
        The disk's gain margin of each axis, dB (``inf`` when the disk holds every gain).
    phase_margin_deg : ndarray, shape (3,)
        The disk's phase margin of each axis, deg.
    frequency : ndarray, shape (3,)
        Where each axis's margin is read, rad/s.
    multiloop : tuple or None
        ``(alpha, gain margin dB, phase margin deg)`` for perturbations of all three inputs
        at once (python-control's ``disk_margins`` on the MIMO loop); None without slycot.
    closed_loop_stable : bool
        No closed-loop pole grows.
    spectral_abscissa : float
        Largest real part of the closed-loop poles, 1/s.
    skew : float
        The disks' skew ``sigma`` (0 balanced, 1 the sensitivity's, -1 the complementary's).
    """

    disk_margin: np.ndarray
    gain_margin_db: np.ndarray
    phase_margin_deg: np.ndarray
    frequency: np.ndarray
    multiloop: tuple | None
    closed_loop_stable: bool
    spectral_abscissa: float
    skew: float

    def __str__(self):
        lines = [f"closed loop {'stable' if self.closed_loop_stable else 'UNSTABLE'} "
                 f"(spectral abscissa {self.spectral_abscissa:.3g} 1/s); disk margins, skew "
                 f"{self.skew:g}:"]
        for axis, a, g, p, w in zip("xyz", self.disk_margin, self.gain_margin_db,
                                    self.phase_margin_deg, self.frequency):
            lines.append(f"  axis {axis}: alpha {a:.3g}, gain +-{g:.3g} dB, phase +-{p:.3g} "
                         f"deg at {w:.4g} rad/s")
        if self.multiloop is not None:
            a, g, p = self.multiloop
            lines.append(f"  all axes at once: alpha {a:.3g}, gain +-{g:.3g} dB, phase +-"
                         f"{p:.3g} deg")
        return "\n".join(lines)


def _disk(alpha: float, skew: float) -> tuple:
    """``(gain margin dB, phase margin deg)`` of the disk of gains of size ``alpha`` and
    ``skew``, ``(1 + (1 - skew) d / 2) / (1 - (1 + skew) d / 2)`` for ``|d| <= alpha``, as
    python-control reads them: the gain margin is the smaller of the factors by which the
    gain may grow and shrink, the phase margin the largest angle of a unit gain in the disk
    (90 deg once the disk holds every larger gain)."""
    low = (1.0 - 0.5 * alpha * (1.0 - skew)) / (1.0 + 0.5 * alpha * (1.0 + skew))
    down = 1.0 - 0.5 * alpha * (1.0 + skew)
    high = math.inf if down <= 0.0 else (1.0 + 0.5 * alpha * (1.0 - skew)) / down
    shrink = math.inf if low <= 0.0 else 1.0 / low
    gain = 20.0 * math.log10(min(shrink, high))
    if math.isinf(high):
        return gain, 90.0
    cos_phi = (1.0 + low * high) / (low + high)
    return gain, math.inf if abs(cos_phi) >= 1.0 else math.degrees(math.acos(cos_phi))


def _grid(loop) -> np.ndarray:
    """Frequencies that span the loop's poles and zeros, with each one's frequency on it (a
    sampled loop's up to its Nyquist frequency)."""
    poles = np.linalg.eigvals(loop.A).astype(complex) if loop.A.size else np.zeros(0, complex)
    nyquist = math.inf
    if loop.isdtime(strict=True):
        nyquist = math.pi / loop.dt
        with np.errstate(divide="ignore"):
            poles = np.log(poles) / loop.dt
    poles = np.abs(poles[np.isfinite(poles)])
    marks = poles[poles > 0.0]
    low = max(1e-4, 1e-2 * float(np.min(marks))) if marks.size else 1e-3
    high = min(1e2 * float(np.max(marks)) if marks.size else 1e3, nyquist * (1 - 1e-9))
    base = np.logspace(np.log10(low), np.log10(high), GRID_POINTS)
    near = np.concatenate([marks * f for f in (0.999, 0.9999, 1.0, 1.0001, 1.001)])
    grid = np.unique(np.concatenate([base, near]))
    return grid[grid < nyquist]


def quaternion_disk_margins(law, structure, *, n_modes=4, variant: str = "exact",
                            delay: float = 0.0, skew: float = 0.0) -> DiskMargins:
    """Disk margins of ``law`` on ``structure`` (:func:`quaternion_loop`), loop at a time
    and all loops at once.

    Parameters
    ----------
    law : QuaternionFeedback
        The three-axis law.
    structure : SpatialStructure
        The hub and its appendages.
    n_modes : int, optional
        Modes per field of every appendage. Default 4.
    variant : {"exact", "first_order", "zero_order"}, optional
        The model linearised. Default ``"exact"``.
    delay : float, optional
        Delay of the command, s (>= 0). Default 0.
    skew : float, optional
        The disks' skew, in [-1, 1]. Default 0 (balanced).

    Returns
    -------
    DiskMargins
    """
    # checked here too, so that the error names the function called
    skew = check_real("quaternion_disk_margins", "skew", skew, minimum=-1.0, maximum=1.0)
    loop = quaternion_loop(law, structure, n_modes=n_modes, variant=variant, delay=delay)
    return loop_disk_margins(loop, skew=skew)


def loop_disk_margins(loop, *, skew: float = 0.0) -> DiskMargins:
    """Disk margins of any three-axis loop broken at the plant's torque inputs, continuous or
    sampled (a discrete python-control system: its frequency response on the unit circle, up
    to the Nyquist frequency), loop at a time and all loops at once (module description).

    Parameters
    ----------
    loop : control.StateSpace
        ``L``, 3 inputs and 3 outputs, in negative feedback.
    skew : float, optional
        The disks' skew, in [-1, 1]. Default 0 (balanced).

    Returns
    -------
    DiskMargins
    """
    import control

    skew = check_real("loop_disk_margins", "skew", skew, minimum=-1.0, maximum=1.0)
    if not isinstance(loop, control.StateSpace) or loop.ninputs != 3 or loop.noutputs != 3:
        raise InputValueError("loop_disk_margins.loop must be a python-control StateSpace of 3 "
                              "inputs and 3 outputs")
    closed = control.feedback(loop, np.eye(3))
    poles = np.linalg.eigvals(closed.A).astype(complex)
    sampled = loop.isdtime(strict=True)
    if sampled:
        with np.errstate(divide="ignore"):
            poles = np.log(poles) / loop.dt
        poles = poles[np.isfinite(poles)]
    abscissa = float(np.max(poles.real))
    stable = abscissa <= GROWTH_TOLERANCE * max(1.0, float(np.max(np.abs(poles))))
    omega = _grid(loop)
    if not stable:
        zeros = np.zeros(3)
        return DiskMargins(zeros, zeros, zeros, np.full(3, np.nan), (0.0, 0.0, 0.0)
                           if _has_slycot() else None, False, abscissa, skew)
    response = loop(np.exp(1j * omega * loop.dt) if sampled else 1j * omega)   # (3, 3, F)
    sensitivity = np.linalg.inv(np.eye(3)[None] + np.moveaxis(response, -1, 0))
    shifted = np.abs(np.diagonal(sensitivity, axis1=1, axis2=2) - (1.0 - skew) / 2.0)
    worst = np.argmax(shifted, axis=0)
    alpha = 1.0 / shifted[worst, np.arange(3)]
    margins = [_disk(float(a), skew) for a in alpha]
    multiloop = None
    if _has_slycot():
        # the structured singular value costs about a millisecond a frequency: it is read on
        # a coarser grid, the poles' frequencies and where the single loops come closest
        coarse = omega[np.unique(np.concatenate([
            np.linspace(0, omega.size - 1, MULTILOOP_POINTS).astype(int),
            np.argsort(np.max(shifted, axis=1))[-MULTILOOP_PEAKS:]]))]
        dm, dgm, dpm = control.disk_margins(loop, coarse, skew=skew)
        # python-control gives the gain margin in dB and the phase margin in degrees
        multiloop = (float(dm), float(dgm), float(dpm))
    return DiskMargins(disk_margin=alpha, gain_margin_db=np.array([g for g, _ in margins]),
                       phase_margin_deg=np.array([p for _, p in margins]),
                       frequency=omega[worst], multiloop=multiloop, closed_loop_stable=True,
                       spectral_abscissa=abscissa, skew=skew)


def lq_loop(law, plant, spin: float | None = None):
    """The loop of a three-axis LQR or LQG around a linear plant, broken at the plant's
    torque inputs: ``L = K Pi (sI - A)^-1 B`` of a continuous LQR, its held form ``(zI -
    A_d)^-1`` of a sampled one, and for an LQG the plant held, its readings through the
    filter (which predicts with the command it gave) to the command; of a scheduled LQR, the
    gain interpolated at ``spin`` around the plant linearised about that spin.

    Parameters
    ----------
    law : SpatialLQR, SpatialLQG or ScheduledSpatialLQR
        The designed law (its saturation is not in a linear loop).
    plant : control.StateSpace
        A plant of :func:`~flexctl.model.spatial_plant.linearize_spatial` of the law's
        structure, with at least the design's modes: at rest, or for a scheduled LQR about
        the spin ``spin`` about its axis.
    spin : float, optional
        A scheduled LQR's spin rate (rad/s); required for it, refused for the others.

    Returns
    -------
    control.StateSpace
        3 inputs (``tx, ty, tz`` perturbations), 3 outputs (the law's torques), negative
        feedback; discrete (``dt`` the law's sample time) for a sampled law.
    """
    import control

    if not isinstance(plant, control.StateSpace) or plant.ninputs != 3 or \
            "ex" not in plant.output_labels:
        raise InputValueError("lq_loop.plant must be a linear plant of linearize_spatial (a "
                              f"python-control StateSpace); got {type(plant).__name__}")
    if isinstance(law, ScheduledSpatialLQR):
        if spin is None:
            raise InputValueError("lq_loop.spin is required for a ScheduledSpatialLQR: the "
                                  "spin rate (rad/s) its gain is interpolated at")
        a, b, c = law.broken_loop(plant, spin)
    elif isinstance(law, (SpatialLQR, SpatialLQG)):
        if spin is not None:
            raise InputValueError(f"lq_loop.spin is for a ScheduledSpatialLQR; a "
                                  f"{type(law).__name__} is designed at rest")
        a, b, c = law.broken_loop(plant)
    else:
        raise InputValueError(f"lq_loop.law must be a SpatialLQR, SpatialLQG or "
                              f"ScheduledSpatialLQR; got {type(law).__name__}")
    dt = law.sample_time or 0
    return control.ss(a, b, c, np.zeros((3, 3)), dt, inputs=["tx", "ty", "tz"],
                      outputs=["ux", "uy", "uz"], name="lq_loop")


def _has_slycot() -> bool:
    try:
        import slycot  # noqa: F401
    except ImportError:
        return False
    return True
