"""Model only what a manoeuvre needs: number of modes and whether stiffening matters.

:func:`choose_modes` estimates, without running the converged nonlinear model, how far the tip
deflection of an ``N``-mode model is from that of a converged one, and picks the smallest ``N``
within a tolerance. The estimate compares *linear* responses:

1. the manoeuvre's input is sampled on a time grid: the hub torque (hub free) or, for a
   prescribed hub motion, the hub acceleration (hub held, the beam loaded by ``-m_tf theta_tt``);
2. each model is linearised about the largest spin rate the manoeuvre reaches (the prescribed
   final rate; for a torque, the rigid-body rate ``max |integral T dt| / J_0``), which gives the
   strongest coupling of the cantilever modes through ``K_g`` and so the conservative estimate;
3. its undamped modes (``eigh(K, M)``, modal damping kept on the diagonal) are driven by the
   sampled input, each integrated exactly for a piecewise-linear input (first-order hold, a
   matrix exponential per mode), so that even the fastest modes cost nothing;
4. the tip responses of ``N = 1 .. max_modes`` modes are compared with that of
   ``reference_modes`` modes: ``error(N) = max_t |tip_N - tip_ref| / max_t |tip_ref|``.

The linear response sees the two ways truncation spoils a run: the quasi-static response of the
missing modes and the frequency error of the kept ones, whose phase drift grows over the horizon.
On the built-in scenes it lands within a factor of about three of the error of the nonlinear
runs (``flexctl bench`` reports both).

A slew (:class:`~flexctl.sim.maneuvers.Slew`), a goal for a controller rather than an input, is
judged by the torque of the rigid cycloidal rest-to-rest slew of the same angle and duration
(one period of sine torque; in the fastest time the torque bound allows when the duration is
free).

Stiffening matters when, at that largest spin rate, the first clamped frequency with stiffening
(first_order) and without (zero_order) differ by more than the tolerance.

Examples
--------
>>> from flexctl import load_scene
>>> from flexctl.sim.fidelity import choose_modes
>>> scene = load_scene("kane-spinup")
>>> choice = choose_modes(scene.system, scene.maneuver, 1e-2, t_final=30.0)
>>> choice.n_modes, choice.stiffening_matters
(3, True)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import scipy.linalg

from .maneuvers import SineTorque, Slew, rigid_slew_duration
from ..model import VARIANTS, build_model
from ..model.errors import InputTypeError, InputValueError
from ..model.parameters import Hub, HubBeam
from ..model.structure import Structure

__all__ = ["ModeChoice", "choose_modes", "linear_tip_responses", "largest_spin_rate",
           "rigid_slew_torque",
           "DEFAULT_TOLERANCE", "DEFAULT_MAX_MODES"]

#: Relative tip error a scene with ``modes = "auto"`` accepts by default.
DEFAULT_TOLERANCE = 1e-2
#: Largest number of modes :func:`choose_modes` considers by default.
DEFAULT_MAX_MODES = 12
#: Samples of the input over the horizon, and at least this many per input segment (between
#: breakpoints), so that a short pulse is resolved too.
GRID_POINTS = 3000
SEGMENT_POINTS = 200
#: Horizon when none is given, in units of the manoeuvre's own time (ramp or pulse duration).
HORIZON_FACTOR = {"prescribed": 2.0, "torque": 10.0}


@dataclass(frozen=True, kw_only=True)
class ModeChoice:
    """The number of modes a manoeuvre needs, as chosen by :func:`choose_modes`.

    Attributes
    ----------
    n_modes : int or tuple of int
        Smallest number of modes whose estimated error is within ``tolerance`` (``max_modes``
        when none is); for a Structure, one per appendage.
    estimated_error : float
        Estimated relative tip error of ``n_modes`` modes: largest tip deflection difference from
        a converged model over the horizon, divided by the largest tip deflection.
    tolerance : float
        Relative tip error asked for.
    variant : str
        Model variant the choice is for.
    error_by_modes : tuple of float
        Estimated relative error of ``1, 2, .., max_modes`` modes.
    reference_modes : int
        Modes of the model taken as converged.
    t_final : float
        Horizon of the estimate, s.
    max_spin_rate : float
        Largest hub rate of the manoeuvre, rad/s (rigid-body estimate for a torque).
    stiffening_effect : float
        ``(w1_first - w1_zero) / w1_first``: relative shift of the first clamped frequency at
        ``max_spin_rate`` that dynamic stiffening makes (above 1 when zero_order has lost all
        stiffness there).
    stiffening_matters : bool
        ``stiffening_effect > tolerance``.
    explanation : str
        One or two sentences for people.
    """

    n_modes: int
    estimated_error: float
    tolerance: float
    variant: str
    error_by_modes: tuple
    reference_modes: int
    t_final: float
    max_spin_rate: float
    stiffening_effect: float
    stiffening_matters: bool
    explanation: str = field(default="", compare=False)

    def __post_init__(self):
        counts = self.n_modes if isinstance(self.n_modes, tuple) else (self.n_modes,)
        if not counts or any(isinstance(n, bool) or not isinstance(n, (int, np.integer))
                             or not 1 <= n <= len(self.error_by_modes) for n in counts):
            raise InputValueError(f"n_modes must be an integer in "
                                  f"[1, {len(self.error_by_modes)}] (a tuple of them per "
                                  f"appendage); got {self.n_modes!r}")
        object.__setattr__(self, "n_modes", tuple(int(n) for n in counts)
                           if isinstance(self.n_modes, tuple) else int(self.n_modes))
        check_tolerance(self.tolerance)
        if self.variant not in VARIANTS:
            raise InputValueError(f"variant must be one of {', '.join(VARIANTS)}; "
                                  f"got {self.variant!r}")
        errors = tuple(float(e) for e in self.error_by_modes)
        if any(not e >= 0.0 for e in errors):
            raise InputValueError(f"error_by_modes must be >= 0 (inf allowed); got {errors!r}")
        object.__setattr__(self, "error_by_modes", errors)
        object.__setattr__(self, "estimated_error", float(self.estimated_error))
        object.__setattr__(self, "stiffening_matters", bool(self.stiffening_matters))

    @property
    def meets_tolerance(self) -> bool:
        """True when the estimated error is within the tolerance."""
        return self.estimated_error <= self.tolerance

    def to_dict(self) -> dict:
        """The choice with JSON types only (as written to ``summary.json``)."""
        def num(v):
            return float(v) if math.isfinite(v) else str(v)
        return {"n_modes": self.n_modes, "tolerance": self.tolerance,
                "estimated_error": num(self.estimated_error),
                "meets_tolerance": self.meets_tolerance, "variant": self.variant,
                "error_by_modes": [num(e) for e in self.error_by_modes],
                "reference_modes": self.reference_modes, "t_final": self.t_final,
                "max_spin_rate": self.max_spin_rate,
                "stiffening_effect": num(self.stiffening_effect),
                "stiffening_matters": self.stiffening_matters, "explanation": self.explanation}


def check_tolerance(tolerance):
    """Refuse a tolerance that is not a relative error in (0, 1) (``InputValueError``).

    Parameters
    ----------
    tolerance : float
        A relative tip error, e.g. of :func:`choose_modes`.
    """
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float, np.floating)) \
            or not 0.0 < tolerance < 1.0:
        raise InputValueError(f"tolerance must be a relative error in (0, 1); got {tolerance!r}")


def rigid_slew_torque(system: HubBeam, slew: Slew) -> SineTorque:
    """Torque of the rigid cycloidal rest-to-rest slew: one period of sine torque.

    ``theta = A (t/T - sin(2 pi t/T) / (2 pi))`` gives ``J_0 theta_tt = (2 pi J_0 A / T^2)
    sin(2 pi t / T)``. A free duration takes the shortest ``T`` whose peak torque is the bound.

    Parameters
    ----------
    system : HubBeam
        Gives the rigid inertia ``J_0``, kg m^2.
    slew : Slew
        The slew angle ``A`` (rad), and its duration ``T`` (s) or torque bound (N m).

    Returns
    -------
    SineTorque
        Peak torque ``2 pi J_0 A / T^2``, N m, over the duration ``T``, s.

    Raises
    ------
    ValueError
        If the slew has neither a duration nor a torque bound.
    """
    j0, angle = system.rigid_inertia, slew.angle
    duration = slew.duration
    if duration is None:
        if slew.torque_bound is None:
            raise InputValueError("a slew needs a duration or a torque_bound to set its time "
                                  "scale; got neither")
        duration = rigid_slew_duration(angle, j0, slew.torque_bound, "cycloidal")
    return SineTorque(peak_torque=2.0 * math.pi * j0 * angle / duration ** 2, duration=duration)


def maneuver_input(system: HubBeam, maneuver):
    """What drives the hub in a manoeuvre: a slew's rigid cycloidal torque
    (:func:`rigid_slew_torque`), any other manoeuvre as it is.

    Parameters
    ----------
    system : HubBeam
        Gives the rigid inertia of a slew's torque.
    maneuver : SpinUp, SineTorque, Slew or similar
        A prescribed hub motion, a torque ``f(t)`` (N m) or a :class:`~flexctl.sim.maneuvers.Slew`.
    """
    return rigid_slew_torque(system, maneuver) if isinstance(maneuver, Slew) else maneuver


def is_prescribed(maneuver) -> bool:
    """True for a prescribed hub motion (``angle``, ``rate``, ``acceleration``), False for a
    torque ``f(t)``; ``InputTypeError`` for anything else.

    Parameters
    ----------
    maneuver : object
        A manoeuvre as :func:`choose_modes` takes it.
    """
    if all(callable(getattr(maneuver, a, None)) for a in ("angle", "rate", "acceleration")):
        return True
    if callable(maneuver):
        return False
    raise InputTypeError("maneuver must be a prescribed hub motion (angle, rate, acceleration) "
                         f"or a torque callable torque(t); got {type(maneuver).__name__}")


def _time_grid(maneuver, t_final: float) -> np.ndarray:
    """Grid over ``[0, t_final]`` with every breakpoint of the manoeuvre on it, s."""
    cuts = sorted({0.0, float(t_final), *(float(b) for b in getattr(maneuver, "breakpoints", ())
                                           if 0.0 < b < t_final)})
    step = t_final / GRID_POINTS
    pieces = [np.zeros(1)]
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        count = max(SEGMENT_POINTS, int(math.ceil((hi - lo) / step)))
        pieces.append(np.linspace(lo, hi, count + 1)[1:])
    return np.concatenate(pieces)


def largest_spin_rate(system: HubBeam, maneuver, t) -> float:
    """Largest ``|hub rate|`` of a manoeuvre over the times ``t`` (s), rad/s.

    The prescribed rate for a hub motion; for a torque, the rigid-body rate
    ``integral_0^t T dt / J_0`` (the beam taken rigid).

    Parameters
    ----------
    system : HubBeam
        Gives the rigid inertia ``J_0``, kg m^2.
    maneuver : SpinUp, SineTorque, Slew or similar
        A prescribed hub motion, a torque ``f(t)`` (N m) or a slew (its
        :func:`rigid_slew_torque`).
    t : array_like, shape (P,)
        Ascending times from 0, s; the torque's integral is the trapezoidal rule over them.
    """
    t = np.asarray(t, dtype=float)
    maneuver = maneuver_input(system, maneuver)
    if is_prescribed(maneuver):
        return float(np.max(np.abs(maneuver.rate(t))))
    torque = np.asarray(maneuver(t), dtype=float) * np.ones_like(t)
    momentum = np.concatenate(([0.0], np.cumsum(0.5 * (torque[1:] + torque[:-1]) * np.diff(t))))
    return float(np.max(np.abs(momentum)) / system.rigid_inertia)


def _modal_form(model, spin_rate: float, prescribed: bool):
    """Squared frequencies (1/s^2), modal damping (1/s) and tip gain of each flexible mode."""
    mat = model.matrices
    if prescribed:
        mass, stiff, damp = mat.M_ff, model.stiffness_matrix(spin_rate), mat.C_ff
        load, tip = -mat.m_tf, model.mode_tips
    else:
        mass, stiff, damp, load = model.second_order_form(spin_rate)
        tip = model.layout.embed(model.mode_tips, size=model.layout.n_coordinates)
    w2, vecs = scipy.linalg.eigh(stiff, mass)
    if not prescribed:
        # the rigid-body mode (w = 0) moves the hub only: no tip deflection
        keep = np.arange(w2.size) != np.argmin(np.abs(w2))
        w2, vecs = w2[keep], vecs[:, keep]
    modal_damping = np.einsum("ik,ij,jk->k", vecs, damp, vecs)
    return w2, modal_damping, (tip @ vecs) * (load @ vecs)


def _unit_responses(w2, damping, t, u) -> np.ndarray:
    """Responses ``eta_k(t)`` of ``eta'' + c_k eta' + w2_k eta = u(t)``, shape (K, P).

    Exact for ``u`` linear between the samples (first-order hold); one 4 x 4 matrix exponential
    per mode and distinct step length.
    """
    out = np.zeros((w2.size, t.size))
    x = np.zeros((w2.size, 2))
    steps = np.diff(t)
    cache = {}
    for k, dt in enumerate(steps):
        key = float(f"{dt:.12g}")
        if key not in cache:
            aug = np.zeros((w2.size, 4, 4))
            aug[:, 0, 1] = 1.0
            aug[:, 1, 0] = -w2
            aug[:, 1, 1] = -damping
            aug[:, 1, 2] = 1.0
            aug[:, 2, 3] = 1.0 / dt
            e = scipy.linalg.expm(aug * dt)
            cache[key] = (e[:, :2, :2], e[:, :2, 2] - e[:, :2, 3], e[:, :2, 3])
        phi, b_now, b_next = cache[key]
        x = np.einsum("kij,kj->ki", phi, x) + b_now * u[k] + b_next * u[k + 1]
        out[:, k + 1] = x[:, 0]
    return out


def linear_tip_responses(system: HubBeam, maneuver, mode_counts, *, t_final: float,
                         variant: str = "first_order", spin_rate: float | None = None):
    """Tip deflection of the linearised models of several mode counts under a manoeuvre.

    Parameters
    ----------
    system : HubBeam
        The hub, beam and point masses.
    maneuver : SpinUp, SineTorque or similar
        A prescribed hub motion (``angle``, ``rate``, ``acceleration``) or a torque ``f(t)``.
    mode_counts : iterable of int
        Numbers of modes ``N``.
    t_final : float
        Horizon, s.
    variant : str, optional
        Whose stiffness ``K_ff - spin^2 D`` the linearisation takes (first_order and consistent
        share it). Default ``"first_order"``.
    spin_rate : float, optional
        Spin rate of the linearisation, rad/s; default :func:`largest_spin_rate`.

    Returns
    -------
    t : ndarray, shape (P,)
        Times, s.
    tips : dict
        ``{N: tip deflection, m, shape (P,)}``.
    stable : bool
        False when some model has lost stiffness at that spin (zero_order above its first
        clamped frequency): its response then grows exponentially.
    """
    maneuver = maneuver_input(system, maneuver)
    prescribed = is_prescribed(maneuver)
    t = _time_grid(maneuver, t_final)
    u = np.asarray(maneuver.acceleration(t) if prescribed else maneuver(t), dtype=float)
    u = u * np.ones_like(t)
    spin = largest_spin_rate(system, maneuver, t) if spin_rate is None else float(spin_rate)
    counts = sorted(set(int(n) for n in mode_counts))
    forms = [_modal_form(build_model(system, n, variant), spin, prescribed) for n in counts]
    w2 = np.concatenate([f[0] for f in forms])
    responses = _unit_responses(w2, np.concatenate([f[1] for f in forms]), t, u)
    tips, start = {}, 0
    for n, (w2_n, _, gain) in zip(counts, forms):
        tips[n] = gain @ responses[start:start + w2_n.size]
        start += w2_n.size
    return t, tips, bool(np.all(w2 > 0.0))


def _appendage_stand_in(structure, k: int) -> HubBeam:
    """Appendage ``k`` alone on a pinned hub that carries the rest of the structure's
    inertia: the one-beam system whose mode count stands in for the appendage's."""
    app = structure.appendages[k]
    alone = structure.appendage_system(k)
    hub = Hub(inertia=structure.rigid_inertia - alone.rigid_inertia,
              radius=structure.root_radius(app), friction=structure.hub.friction)
    return HubBeam(hub=hub, beam=app.beam, masses=app.masses)


def _choose_structure_modes(structure, maneuver, *args, **kwargs) -> "ModeChoice":
    """:func:`choose_modes` of each appendage on its stand-in hub; the modes as a tuple."""
    choices = [choose_modes(_appendage_stand_in(structure, k), maneuver, *args, **kwargs)
               for k in range(len(structure.appendages))]
    worst = max(choices, key=lambda c: c.estimated_error)
    modes = tuple(c.n_modes for c in choices)
    why = "; ".join(f"{app.name}: {c.n_modes} modes" for app, c in
                    zip(structure.appendages, choices))
    return dataclasses.replace(worst, n_modes=modes, explanation=(
        f"each appendage on a hub carrying the rest of the structure ({why}); "
        + worst.explanation))


def choose_modes(system: HubBeam, maneuver, tolerance: float = DEFAULT_TOLERANCE,
                 variant: str = "first_order", max_modes: int = DEFAULT_MAX_MODES, *,
                 reference_modes: int | None = None, t_final: float | None = None) -> ModeChoice:
    """Smallest number of modes whose estimated tip error is within ``tolerance``.

    See the module docstring for the estimate. Results are cached per argument set.

    Parameters
    ----------
    system : HubBeam or Structure
        For a Structure each appendage is judged alone on a pinned hub that carries the rest
        of the structure's inertia, and ``n_modes`` is the tuple of their counts.
    maneuver : SpinUp, SineTorque, Slew or similar
        A prescribed hub motion, a torque ``f(t)`` (N m), or a slew (judged by
        :func:`rigid_slew_torque`).
    tolerance : float, optional
        Relative tip error in (0, 1): largest tip deflection error over the horizon divided by
        the largest tip deflection. Default 1e-2.
    variant : {"first_order", "zero_order", "consistent"}, optional
        The variant whose modes are counted. Default ``"first_order"``.
    max_modes : int, optional
        Largest number of modes considered (1 to 100). Default 12.
    reference_modes : int, optional
        Modes of the model taken as converged; default ``max(2 max_modes, max_modes + 8)``.
    t_final : float, optional
        Horizon, s; default twice the ramp time of a spin-up, ten times the duration of a torque
        pulse (its ``breakpoints``), or 10 s.

    Returns
    -------
    ModeChoice

    Raises
    ------
    ValueError
        On a tolerance outside (0, 1), an unknown variant, or bad mode counts or horizon.
    TypeError
        If ``maneuver`` is neither a hub motion nor a torque callable.
    """
    if isinstance(system, Structure):
        return _choose_structure_modes(system, maneuver, tolerance, variant, max_modes,
                                       reference_modes=reference_modes, t_final=t_final)
    check_tolerance(tolerance)
    if variant not in VARIANTS:
        raise InputValueError(f"variant must be one of {', '.join(VARIANTS)}; got {variant!r}")
    if isinstance(max_modes, bool) or not isinstance(max_modes, (int, np.integer)) \
            or not 1 <= max_modes <= 100:
        raise InputValueError(f"max_modes must be an integer in [1, 100]; got {max_modes!r}")
    if reference_modes is None:
        reference_modes = max(2 * int(max_modes), int(max_modes) + 8)
    if isinstance(reference_modes, bool) or not isinstance(reference_modes, (int, np.integer)) \
            or not max_modes < reference_modes <= 200:
        raise InputValueError(f"reference_modes must be an integer in (max_modes = "
                              f"{max_modes}, 200]; got {reference_modes!r}")
    prescribed = is_prescribed(maneuver_input(system, maneuver))
    if t_final is None:
        scale = max((float(b) for b in getattr(maneuver_input(system, maneuver), "breakpoints", ())
                     or ()), default=0.0)
        key = "prescribed" if prescribed else "torque"
        t_final = HORIZON_FACTOR[key] * scale if scale > 0 else 10.0
    if isinstance(t_final, bool) or not isinstance(t_final, (int, float, np.floating)) \
            or not 0.0 < t_final < math.inf:
        raise InputValueError(f"t_final must be a positive finite time (s); got {t_final!r}")
    args = (system, maneuver, float(tolerance), variant, int(max_modes), int(reference_modes),
            float(t_final))
    try:
        return _choose_cached(*args)
    except TypeError:                      # an unhashable manoeuvre: no caching
        return _choose(*args)


@lru_cache(maxsize=64)
def _choose_cached(*args) -> ModeChoice:
    return _choose(*args)


def _choose(system, maneuver, tolerance, variant, max_modes, reference_modes,
            t_final) -> ModeChoice:
    counts = list(range(1, max_modes + 1)) + [reference_modes]
    t, tips, stable = linear_tip_responses(system, maneuver, counts, t_final=t_final,
                                           variant=variant)
    spin = largest_spin_rate(system, maneuver, t)
    note = ""
    if not stable:
        # zero_order above its first clamped frequency grows without bound whatever N is;
        # truncation is then judged on the stiffened linearisation (same modes).
        t, tips, _ = linear_tip_responses(system, maneuver, counts, t_final=t_final,
                                          variant="first_order")
        note = (f" The {variant} model loses its stiffness at {spin:.4g} rad/s and diverges "
                "whatever the number of modes; the estimate uses the first_order "
                "linearisation.")
    reference = tips[reference_modes]
    peak = float(np.max(np.abs(reference)))
    if peak > 0.0:
        errors = tuple(float(np.max(np.abs(tips[n] - reference))) / peak
                       for n in range(1, max_modes + 1))
    else:
        errors = (0.0,) * max_modes
    n_modes = next((n for n, e in enumerate(errors, start=1) if e <= tolerance), max_modes)

    w_first = build_model(system, reference_modes, "first_order").natural_frequencies(spin)[0]
    w_zero = build_model(system, reference_modes, "zero_order").natural_frequencies(spin)[0]
    effect = float((w_first - w_zero) / w_first)
    matters = effect > tolerance
    zero_text = (f"{w_zero:.4g} rad/s without it" if w_zero > 0 else
                 "lost without it (zero_order diverges)")
    verdict = "matters" if matters else "does not matter"
    met = "" if errors[n_modes - 1] <= tolerance else (
        f" No model of up to {max_modes} modes meets the tolerance.")
    explanation = (
        f"{n_modes} mode{'s' if n_modes > 1 else ''}: estimated tip error "
        f"{errors[n_modes - 1]:.2g} of the peak (tolerance {tolerance:.2g}) from linear "
        f"responses at {spin:.4g} rad/s over {t_final:g} s against {reference_modes} modes."
        f"{met} Stiffening {verdict}: at {spin:.4g} rad/s the first clamped frequency is "
        f"{w_first:.4g} rad/s with stiffening and {zero_text} (a relative shift of "
        f"{effect:.2g})."
        + note)
    return ModeChoice(n_modes=n_modes, estimated_error=errors[n_modes - 1],
                      tolerance=tolerance, variant=variant, error_by_modes=errors,
                      reference_modes=reference_modes, t_final=t_final, max_spin_rate=spin,
                      stiffening_effect=effect, stiffening_matters=matters,
                      explanation=explanation)
