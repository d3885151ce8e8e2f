"""Loop requirements as data, and their verification on the nominal plant and over the
uncertainty of the structure.

:class:`Requirements` holds what an attitude loop on a flexible structure must meet, in the
usual form of a flexible spacecraft's sign-off: rigid-body gain and phase margins (and
optionally a delay margin and a least bandwidth), and for every flexible mode either an
attenuation (gain-stabilised) or a phase margin where the loop crosses unit gain near it
(phase-stabilised). :func:`verify_requirements` measures each on the loop as it flies
(:func:`~controllers.analysis.loops.loop_transfer`: continuous, held or observed, with its
structural filters) and reports its nominal value, its worst case over the uncertainty and
whether it passes.

Notes
-----
- **Rigid-body loop.** The rigid-body margins are read at the loop's crossings outside every
  flexible mode's window (+-:data:`MODE_WINDOW`, relative, about the mode's frequency on the
  plant judged), on a logarithmic grid of :data:`RIGID_POINTS` frequencies; the flexible
  modes are judged inside their windows. The closed loop's stability is the verdict
  :func:`~controllers.analysis.loops.loop_margins` and :func:`~controllers.check_loop`
  share (:func:`~controllers.analysis.loops.closed_loop_verdict`).
- **A flexible mode** passes when, over its window, the loop stays out of the exclusion zone
  about the critical point of the Nichols chart: gains within ``flexible_attenuation_db`` of
  0 dB with phases within ``flexible_phase_margin_deg`` of -180 deg (mod 360). Its figure
  of merit is the least, over the window, of ``max(|gain dB| / flexible_attenuation_db,
  phase distance / flexible_phase_margin_deg)``: it passes at 1 or more. A mode attenuated
  by the required amount is gain-stabilised; one that is not passes only by its phase
  (phase-stabilised). The window is sampled on :data:`WINDOW_POINTS` logarithmic points and
  ``PEAK_POINTS`` more about the loop's peak in it.
- **Gain stabilisation required.** With ``gain_stabilised_above``, a mode whose nominal
  frequency is above it is measured by its attenuation alone: ``-peak dB /
  flexible_attenuation_db``, 1 at the required attenuation.
- **Sampled loops.** A sampled loop sees a mode above the Nyquist frequency at its alias:
  its window, and the rigid-body loop's exclusion of it, are about the folded frequency.
- **Uncertainty** (:class:`UncertainPlant`): each coupled mode's frequency scaled by its own
  factor in ``1 +- frequency_uncertainty`` and its damping ratio anywhere in
  ``damping_range``, its shape kept (:func:`flexctl.model.modal_uncertainty.with_modes`), on
  a structure whose beams' Young's modulus, point masses and hub inertia are scaled within
  ``1 +- stiffness_uncertainty``, ``mass_uncertainty``, ``hub_inertia_uncertainty``. The
  worst case of each requirement is searched globally, then locally: a grid of
  :data:`FREQUENCY_POINTS` common frequency factors by the ends and middle of the damping
  range, the corners of the structure's ranges and :data:`RANDOM_POINTS` random plants;
  from the worst of these, the structure's ranges at their ends, the requirement's own mode
  (the first for a rigid-body requirement) on a grid of frequencies by
  :data:`DAMPING_POINTS` damping ratios refined by a Nelder-Mead search, and sweeps over
  every other mode's frequency and damping, until a sweep finds nothing worse. The report
  states this coverage and the plants evaluated; :func:`monte_carlo_requirements` draws
  random plants of the same ranges to check it (a check that must find no worse case).
- **Nominal damping.** A plant whose beams have no damping is judged at the lower end of
  ``damping_range`` (an undamped mode's peak is infinite); one with damping, at its own.

Examples
--------
>>> Requirements(gain_margin_db=6.0, phase_margin_deg=30.0).flexible_attenuation_db
6.0
>>> Requirements(damping_range=(0.01, 0.001))
Traceback (most recent call last):
...
flexctl.model.errors.InputValueError: requirements.damping_range must be (low, high) with \
0 <= low <= high < 1; got (0.01, 0.001)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from flexctl.model import HubBeam, Model, Structure
from flexctl.model.build import rebuild
from flexctl.model.checks import KeywordOnly, check_integer, check_real
from flexctl.model.errors import InputTypeError, InputValueError

from flexctl.model.modal_uncertainty import with_modes

from .dispersion import disperse
from .loops import closed_loop_verdict, loop_transfer

__all__ = ["Requirements", "RequirementCheck", "ModeVerdict", "Verification",
           "UncertainPlant", "monte_carlo_requirements", "aliased_frequency",
           "verify_requirements", "MODE_WINDOW", "FREQUENCY_POINTS", "RIGID_POINTS"]

#: Half-width of the window a flexible mode is judged in, relative to its frequency.
MODE_WINDOW = 0.15
#: Frequency factors of the uncertainty grid (the ends included).
FREQUENCY_POINTS = 9
#: Random plants of the search's first stage, and the seed they are drawn with.
RANDOM_POINTS = 64
RANDOM_SEED = 20261129
#: Frequency factors at which every other mode is tried (the ends included).
OTHER_POINTS = 5
#: Most sweeps over the other modes (they stop when a sweep finds nothing worse).
SWEEPS = 2
#: Damping ratios of a mode's own grid (the ends of the range included).
DAMPING_POINTS = 4
#: Most evaluations of a mode's Nelder-Mead refinement over its frequency and damping.
REFINE_EVALUATIONS = 24
#: Points of a mode window's frequency grid.
WINDOW_POINTS = 600
#: Relative half-width and points of the finer grid about a mode window's peak (a mode with
#: damping 0.001 is 0.2 % wide).
PEAK_SPAN = 0.005
PEAK_POINTS = 400
#: Points of the rigid-body loop's frequency grid (logarithmic, up to the Nyquist frequency
#: of a sampled loop or three times the highest flexible frequency).
RIGID_POINTS = 3000


@dataclass(frozen=True, kw_only=True)
class Requirements(KeywordOnly):
    """What a loop must meet (module Notes).

    Parameters
    ----------
    gain_margin_db : float, optional
        Rigid-body gain margin, dB (> 0). Default 6.
    phase_margin_deg : float, optional
        Rigid-body phase margin, deg (in (0, 180)). Default 30.
    delay_margin : float, optional
        Least delay margin of the rigid-body loop, s (> 0). Default none.
    bandwidth : float, optional
        Least rigid-body gain-crossover frequency, rad/s (> 0). Default none.
    flexible_attenuation_db : float, optional
        A flexible mode is gain-stabilised by this attenuation, dB (> 0). Default 6.
    flexible_phase_margin_deg : float, optional
        ... or phase-stabilised with this phase margin, deg (in (0, 180)). Default 30.
    frequency_uncertainty : float, optional
        Relative uncertainty of each coupled mode's frequency, on its own, in [0, 0.5].
        Default 0.
    damping_range : (float, float), optional
        Each coupled mode's damping ratio, ``0 <= low <= high < 1``. Default (0.001, 0.01).
    stiffness_uncertainty : float, optional
        Relative uncertainty of every beam's Young's modulus (all together), in [0, 0.5].
        Default 0.
    mass_uncertainty : float, optional
        Relative uncertainty of every point mass (all together), in [0, 0.5]. Default 0.
    hub_inertia_uncertainty : float, optional
        Relative uncertainty of the hub's inertia, in [0, 0.5]. Default 0.
    gain_stabilised_above : float, optional
        A flexible mode whose nominal frequency is above this, rad/s, passes only
        gain-stabilised (attenuated by ``flexible_attenuation_db``): its phase is not trusted.
        Default none (every mode may be phase-stabilised).
    """

    gain_margin_db: float = 6.0
    phase_margin_deg: float = 30.0
    delay_margin: float | None = None
    bandwidth: float | None = None
    flexible_attenuation_db: float = 6.0
    flexible_phase_margin_deg: float = 30.0
    frequency_uncertainty: float = 0.0
    damping_range: tuple = (0.001, 0.01)
    stiffness_uncertainty: float = 0.0
    mass_uncertainty: float = 0.0
    hub_inertia_uncertainty: float = 0.0
    gain_stabilised_above: float | None = None

    def __post_init__(self):
        owner = "requirements"
        put = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        for name in ("gain_margin_db", "flexible_attenuation_db"):
            put(name, check_real(owner, name, getattr(self, name), minimum=0.0, strict=True))
        for name in ("phase_margin_deg", "flexible_phase_margin_deg"):
            put(name, check_real(owner, name, getattr(self, name), minimum=0.0, maximum=180.0,
                                 strict=True))
        for name in ("delay_margin", "bandwidth", "gain_stabilised_above"):
            put(name, check_real(owner, name, getattr(self, name), minimum=0.0, strict=True,
                                 optional=True))
        for name in ("frequency_uncertainty", "stiffness_uncertainty", "mass_uncertainty",
                     "hub_inertia_uncertainty"):
            put(name, check_real(owner, name, getattr(self, name), minimum=0.0, maximum=0.5))
        put("damping_range", _damping_range(self.damping_range))


def _damping_range(value) -> tuple:
    rule = "must be (low, high) with 0 <= low <= high < 1"
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputValueError(f"requirements.damping_range {rule}; got {value!r}"[:300])
    low, high = (check_real("requirements", "damping_range", v, minimum=0.0, maximum=0.999)
                 for v in value)
    if low > high:
        raise InputValueError(f"requirements.damping_range {rule}; got {tuple(value)!r}")
    return (low, high)


@dataclass(frozen=True)
class RequirementCheck:
    """One requirement: what it asks, its nominal and worst values, and whether it passes.

    Attributes
    ----------
    name : str
        E.g. ``"gain_margin_db"`` or ``"flexible mode 2"``.
    required : float
        The least value that passes, in :attr:`unit`.
    nominal, worst : float
        The value on the nominal plant and the least over the uncertainty.
    unit : str
    detail : str
        Where the worst case is, and for a flexible mode how it is stabilised.
    worst_at : UncertainPlant or None
        The plant of the worst case.
    """

    name: str
    required: float
    nominal: float
    worst: float
    unit: str
    detail: str = ""
    worst_at: object = None

    @property
    def passed(self) -> bool:
        """Whether the worst case meets the requirement."""
        return bool(self.worst >= self.required)

    def as_dict(self) -> dict:
        """``name``, ``required``, ``nominal``, ``worst``, ``pass``, ``unit`` and ``detail``
        (JSON types; an infinite margin becomes None)."""
        number = lambda v: float(v) if math.isfinite(v) else None  # noqa: E731
        return {"name": self.name, "required": float(self.required),
                "nominal": number(self.nominal), "worst": number(self.worst),
                "pass": self.passed, "unit": self.unit, "detail": self.detail}


@dataclass(frozen=True)
class ModeVerdict:
    """How the nominal loop stabilises one flexible mode.

    Attributes
    ----------
    mode : int
        From 1, ascending frequency.
    frequency : float
        rad/s.
    kind : {"gain", "phase"}
        Gain-stabilised (attenuated) or phase-stabilised.
    peak_db : float
        The loop's largest gain in the mode's window, dB.
    phase_margin_deg : float
        Least phase distance from -180 deg at the window's unit-gain crossings, deg (inf with
        no crossing).
    score : float
        The least, over the window, of ``max(|gain dB| / flexible_attenuation_db, phase
        distance from -180 deg / flexible_phase_margin_deg)``: 1 or more keeps the loop out of
        the exclusion zone about the critical point (module Notes).
    peak_frequency : float
        Where the loop's gain peaks in the window, rad/s.
    """

    mode: int
    frequency: float
    kind: str
    peak_db: float
    phase_margin_deg: float
    score: float
    peak_frequency: float = math.nan


@dataclass(frozen=True)
class Verification:
    """The report of :func:`verify_requirements`.

    Attributes
    ----------
    checks : tuple of RequirementCheck
    modes : tuple of ModeVerdict
        The nominal loop's classification of each flexible mode.
    coverage : str
        How the uncertainty was searched.
    loop : control.LTI
        The nominal loop transfer.
    """

    checks: tuple
    modes: tuple
    coverage: str
    loop: object

    @property
    def passed(self) -> bool:
        """Whether every requirement passes."""
        return all(check.passed for check in self.checks)

    def as_list(self) -> list:
        """One dict per requirement (:meth:`RequirementCheck.as_dict`)."""
        return [check.as_dict() for check in self.checks]


# ------------------------------------------------------------------ one loop's figures
class _Response:
    """A loop's complex frequency response ``C (p I - A)^-1 B + D`` at ``p = j w`` (or
    ``exp(j w T)``), by back substitution on the complex Schur form of ``A``, computed once
    (``n^2`` operations a point, all points at once)."""

    def __init__(self, loop):
        import scipy.linalg

        self.dt = float(loop.dt) if loop.dt else 0.0
        a = np.asarray(loop.A, dtype=float)
        self.t, z = scipy.linalg.schur(a, output="complex")
        self.b = z.conj().T @ np.asarray(loop.B, dtype=float)[:, 0]
        self.c = np.asarray(loop.C, dtype=float)[0] @ z
        self.d = float(np.asarray(loop.D)[0, 0])

    def __call__(self, w: np.ndarray) -> np.ndarray:
        points = 1j * w if not self.dt else np.exp(1j * w * self.dt)
        t, n = self.t, self.t.shape[0]
        y = np.zeros((n, points.size), dtype=complex)
        for i in range(n - 1, -1, -1):
            y[i] = (self.b[i] + t[i, i + 1:] @ y[i + 1:]) / (points - t[i, i])
        return self.c @ y + self.d


def _phase_distance(response) -> np.ndarray:
    """Distance of the phase from -180 deg (mod 360), deg."""
    angle = np.degrees(np.angle(response))
    return np.abs((angle + 360.0) % 360.0 - 180.0)


def _flexible_frequencies(model) -> np.ndarray:
    """The plant's flexible frequencies (imaginary parts of its open-loop poles), rad/s."""
    a, _ = model.linear_matrices(0.0)
    poles = np.linalg.eigvals(np.asarray(a, dtype=float))
    scale = max(float(np.max(np.abs(poles))), 1.0)
    return np.sort(np.abs(poles[poles.imag > 1e-9 * scale]))


def _crossings(w: np.ndarray, response: np.ndarray) -> tuple:
    """``(gain, phase)``: the unit-gain crossings ``(w, phase margin deg)`` and the -180 deg
    crossings ``(w, gain margin dB)`` of a response on the grid ``w``, each located between
    two grid points by linear interpolation in ``log w``."""
    log_gain = np.log(np.maximum(np.abs(response), 1e-300))
    turns = (np.unwrap(np.angle(response)) / math.pi + 1.0) / 2.0     # -180 deg: integers
    gain, phase = [], []
    for j in np.flatnonzero(np.sign(log_gain[1:]) != np.sign(log_gain[:-1])):
        r = log_gain[j] / (log_gain[j] - log_gain[j + 1])
        wc = math.exp(math.log(w[j]) + r * (math.log(w[j + 1]) - math.log(w[j])))
        t = turns[j] + r * (turns[j + 1] - turns[j])
        gain.append((wc, 360.0 * abs(t - round(t))))       # whole turns are -180 deg
    levels = np.floor(turns)
    for j in np.flatnonzero(levels[1:] != levels[:-1]):
        level = max(levels[j], levels[j + 1])
        r = (level - turns[j]) / (turns[j + 1] - turns[j])
        g = log_gain[j] + r * (log_gain[j + 1] - log_gain[j])
        wc = math.exp(math.log(w[j]) + r * (math.log(w[j + 1]) - math.log(w[j])))
        phase.append((wc, abs(20.0 * g / math.log(10.0))))
    return gain, phase


def aliased_frequency(omega, dt: float):
    """Where a sampled loop sees frequencies: folded into ``(0, pi / dt]`` (at least 1e-6 of
    it).

    Parameters
    ----------
    omega : float or ndarray
        Frequencies, rad/s.
    dt : float
        Sample time, s; 0 for a continuous loop (``omega`` returned as given).

    Returns
    -------
    float or ndarray
        rad/s.

    Examples
    --------
    >>> float(aliased_frequency(220.35, 0.03))       # 2 pi / 0.03 = 209.4 rad/s
    10.91...
    """
    if not dt:
        return omega
    sampling = 2.0 * math.pi / dt
    folded = np.abs((np.asarray(omega) + 0.5 * sampling) % sampling - 0.5 * sampling)
    return np.maximum(folded, 1e-6 * 0.5 * sampling)


def _rigid_figures(response: _Response, flexible: np.ndarray) -> dict:
    """Gain margin (dB), phase margin (deg), delay margin (s) and bandwidth (rad/s) of the
    rigid-body loop: its crossings outside every flexible mode's window."""
    top = math.pi / response.dt if response.dt else 3.0 * float(np.max(flexible, initial=1.0))
    low = 1e-3 * float(np.min(flexible, initial=1.0))
    w = np.geomspace(low, top * (1.0 - 1e-9), RIGID_POINTS)
    gain, phase = _crossings(w, response(w))

    judged = aliased_frequency(flexible, response.dt)

    def rigid(wc):
        return not np.any(np.abs(wc / judged - 1.0) <= MODE_WINDOW)

    gain = [(wc, m) for wc, m in gain if rigid(wc)]
    phase = [(wc, m) for wc, m in phase if rigid(wc)]
    return {"gain_margin_db": min((m for _, m in phase), default=math.inf),
            "phase_margin_deg": min((m for _, m in gain), default=math.inf),
            "delay_margin": min((math.radians(m) / wc for wc, m in gain), default=math.inf),
            "bandwidth": max((wc for wc, _ in gain), default=0.0)}


def _mode_verdict(loop_response: _Response, mode: int, omega: float,
                  req: Requirements) -> ModeVerdict:
    """How the loop of ``loop_response`` stabilises the mode at ``omega`` (module Notes)."""
    w = aliased_frequency(omega, loop_response.dt) * np.geomspace(1.0 - MODE_WINDOW, 1.0 + MODE_WINDOW,
                                                       WINDOW_POINTS)
    response = loop_response(w)
    k = int(np.argmax(np.abs(response)))
    fine = w[k] * np.linspace(1.0 - PEAK_SPAN, 1.0 + PEAK_SPAN, PEAK_POINTS)
    w = np.concatenate((w, fine))
    order = np.argsort(w, kind="stable")
    w, response = w[order], np.concatenate((response, loop_response(fine)))[order]
    gain_db = 20.0 * np.log10(np.maximum(np.abs(response), 1e-300))
    distance = _phase_distance(response)
    crossings, _ = _crossings(w, response)
    score = float(np.min(np.maximum(np.abs(gain_db) / req.flexible_attenuation_db,
                                    distance / req.flexible_phase_margin_deg)))
    top = int(np.argmax(gain_db))
    peak_db = float(gain_db[top])
    kind = "gain" if peak_db <= -req.flexible_attenuation_db else "phase"
    margin = min((m for _, m in crossings), default=math.inf)
    return ModeVerdict(mode, float(omega), kind, peak_db, margin, score, float(w[top]))


# ------------------------------------------------------------------ plants of the uncertainty
@dataclass(frozen=True)
class UncertainPlant:
    """One plant of the uncertainty: the nominal structure with its stiffness, point masses
    and hub inertia scaled, then its coupled modes' frequencies scaled and damping ratios set
    (:func:`flexctl.model.modal_uncertainty.with_modes`).

    Attributes
    ----------
    stiffness, point_masses, hub_inertia : float
        Factors on every beam's Young's modulus, every point mass and the hub's inertia.
    frequency_factors : tuple of float
        Factor on each coupled mode's frequency (empty: all 1).
    damping_ratios : tuple of float or None
        Each coupled mode's damping ratio; None keeps the plant's own damping.
    """

    stiffness: float = 1.0
    point_masses: float = 1.0
    hub_inertia: float = 1.0
    frequency_factors: tuple = ()
    damping_ratios: tuple | None = None

    def describe(self) -> str:
        """One line: the factors that are not 1 and the damping ratios."""
        parts = [f"{name.replace('_', ' ')} x{value:.4g}" for name, value in
                 (("stiffness", self.stiffness), ("point_masses", self.point_masses),
                  ("hub_inertia", self.hub_inertia)) if value != 1.0]
        if self.frequency_factors:
            parts.append("frequency factors " + ", ".join(f"{f:.4g}"
                                                          for f in self.frequency_factors))
        if self.damping_ratios is not None:
            parts.append("damping ratios " + ", ".join(f"{z:.3g}" for z in self.damping_ratios))
        return "; ".join(parts) or "the nominal plant"


def _point(stiffness=1.0, point_masses=1.0, hub_inertia=1.0, factors=(), dampings=None):
    rounded = lambda values: tuple(round(float(v), 12) for v in values)  # noqa: E731
    return UncertainPlant(round(float(stiffness), 12), round(float(point_masses), 12),
                          round(float(hub_inertia), 12), rounded(factors),
                          None if dampings is None else rounded(dampings))


def _beam_damping(system) -> float:
    beams = [system.beam] if isinstance(system, HubBeam) else [a.beam for a in system.appendages]
    return max(b.damping_ratio for b in beams)


def _ends(uncertainty: float) -> tuple:
    return (1.0 - uncertainty, 1.0 + uncertainty) if uncertainty > 0.0 else (1.0,)


class _Search:
    """The figures of the loop on each plant of the uncertainty asked for, each evaluated once;
    a structure (stiffness, masses, inertia) built once."""

    def __init__(self, plant, controller, req: Requirements, spin_rate: float):
        self.plant, self.controller, self.req, self.spin = plant, controller, req, spin_rate
        self.cache, self.structures = {}, {}
        source = getattr(plant, "source", None)
        self.base = plant.system if source is None else source
        # at rest the exact variant's linearisation is first_order's, which builds at once
        self.variant = "first_order" if plant.variant.exact and spin_rate == 0.0 else None
        self.n_modes = plant.n_modes
        above = req.gain_stabilised_above
        self.gain_only = frozenset() if above is None else frozenset(
            k for k, omega in enumerate(_flexible_frequencies(self.model(_point())))
            if omega > above)

    def model(self, point: UncertainPlant):
        """The plant at ``point``."""
        key = (point.stiffness, point.point_masses, point.hub_inertia)
        if key not in self.structures:
            system = None if key == (1.0, 1.0, 1.0) else disperse(
                self.base, youngs_modulus_scale=key[0], point_mass_scale=key[1],
                hub_inertia_scale=key[2])
            self.structures[key] = self.plant if system is None and self.variant is None \
                else rebuild(self.plant, variant=self.variant, system=system)
        model = self.structures[key]
        if not point.frequency_factors and point.damping_ratios is None:
            return model
        return with_modes(model, point.frequency_factors or 1.0, point.damping_ratios,
                          self.spin)

    def loop(self, point: UncertainPlant):
        model = self.model(point)
        return model, loop_transfer(model, self.controller, self.spin)

    def _entry(self, point: UncertainPlant) -> dict:
        if point not in self.cache:
            model, loop = self.loop(point)
            self.cache[point] = {"loop": loop, "response": _Response(loop),
                                 "flexible": _flexible_frequencies(model)}
        return self.cache[point]

    def verdict(self, point: UncertainPlant, k: int):
        """Mode ``k``'s (from 0) :class:`ModeVerdict` at ``point``, or None past the plant's
        flexible modes."""
        entry = self._entry(point)
        key = ("mode", k)
        if key not in entry:
            flexible = entry["flexible"]
            entry[key] = None if k >= len(flexible) else \
                _mode_verdict(entry["response"], k + 1, flexible[k], self.req)
        return entry[key]

    def value(self, point: UncertainPlant, name: str) -> float:
        """The figure ``name`` (a requirement's) at ``point``, computed once."""
        entry = self._entry(point)
        if name not in entry:
            if name == "closed_loop_stable":
                entry[name] = 1.0 if closed_loop_verdict(entry["loop"])[0] else 0.0
            elif name.startswith("flexible mode "):
                k = int(name.split()[-1]) - 1
                verdict = self.verdict(point, k)
                entry[name] = math.inf if verdict is None else verdict.score \
                    if k not in self.gain_only \
                    else -verdict.peak_db / self.req.flexible_attenuation_db
            else:
                entry.update(_rigid_figures(entry["response"], entry["flexible"]))
        return entry[name]

    def loop_at(self, point: UncertainPlant):
        """The loop transfer at ``point``, built once."""
        return self._entry(point)["loop"]

    def modes(self, point: UncertainPlant) -> list:
        """Every flexible mode's :class:`ModeVerdict` at ``point``."""
        return [self.verdict(point, k) for k in range(len(self._entry(point)["flexible"]))]


def _grid(req: Requirements, n_modes: int) -> list:
    """The search's first plants: every frequency factor (all modes together) by the ends and
    middle of the damping range, and each corner of the structure's ranges at both ends of the
    damping range."""
    u = req.frequency_uncertainty
    low, high = req.damping_range
    factors = np.linspace(1.0 - u, 1.0 + u, FREQUENCY_POINTS) if u > 0 else np.array([1.0])
    dampings = sorted({low, math.sqrt(low * high) if low > 0 else 0.5 * high, high})
    points = [_point(factors=(f,) * n_modes, dampings=(z,) * n_modes)
              for f in factors for z in dampings]
    corners = [(s, m, j) for s in _ends(req.stiffness_uncertainty)
               for m in _ends(req.mass_uncertainty) for j in _ends(req.hub_inertia_uncertainty)]
    points += [_point(s, m, j, (1.0,) * n_modes, (z,) * n_modes)
               for s, m, j in corners if (s, m, j) != (1.0, 1.0, 1.0) for z in (low, high)]
    return points


def _improve(search: _Search, name: str, point: UncertainPlant, candidates) -> tuple:
    """``(point, value)``: the worst of ``point`` and each candidate plant, in turn."""
    best = search.value(point, name)
    for candidate in candidates:
        value = search.value(candidate, name)
        if value < best:
            point, best = candidate, value
    return point, best


def _moved(point: UncertainPlant, k: int, factor=None, zeta=None) -> UncertainPlant:
    """``point`` with mode ``k``'s frequency factor or damping ratio changed."""
    factors, dampings = list(point.frequency_factors), list(point.damping_ratios)
    if factor is not None:
        factors[k] = factor
    if zeta is not None:
        dampings[k] = zeta
    return _point(point.stiffness, point.point_masses, point.hub_inertia, factors, dampings)


def _damping_grid(req: Requirements) -> np.ndarray:
    low, high = req.damping_range
    if low > 0.0:
        return np.geomspace(low, high, DAMPING_POINTS)
    return np.linspace(low, high, DAMPING_POINTS)


def _own_mode(search: _Search, name: str, point: UncertainPlant, k: int) -> tuple:
    """``(point, value)``: the worst over mode ``k``'s frequency factor and damping ratio,
    the others as in ``point``: a grid, then a Nelder-Mead search from its worst (the
    damping on a logarithmic scale when the range starts above 0)."""
    from scipy.optimize import minimize

    req = search.req
    u = req.frequency_uncertainty
    low, high = req.damping_range
    factors = np.linspace(1.0 - u, 1.0 + u, FREQUENCY_POINTS) if u > 0 else np.array([1.0])
    point, value = _improve(search, name, point, [_moved(point, k, f, z) for f in factors
                                                 for z in _damping_grid(req)])
    if high == low and u == 0.0:
        return point, value
    logarithmic = low > 0.0

    def unit(zeta):
        if high == low:
            return 0.0
        return (math.log(zeta / low) / math.log(high / low)) if logarithmic \
            else (zeta - low) / (high - low)

    def plant(x):
        f = min(max(x[0], 1.0 - u), 1.0 + u)
        s = min(max(x[1], 0.0), 1.0)
        zeta = low * (high / low) ** s if logarithmic else low + s * (high - low)
        return _moved(point, k, f, zeta)

    start = np.array([point.frequency_factors[k], unit(point.damping_ratios[k])])
    step = np.array([max(u, 1e-3) / (FREQUENCY_POINTS - 1), 1.0 / (DAMPING_POINTS - 1)])
    found = minimize(lambda x: search.value(plant(x), name), start, method="Nelder-Mead",
                     options={"initial_simplex": [start, start + [step[0], 0.0],
                                                  start + [0.0, step[1]]],
                              "maxfev": REFINE_EVALUATIONS, "xatol": 1e-4, "fatol": 1e-6})
    if found.fun < value:
        point, value = plant(found.x), float(found.fun)
    return point, value


def _coordinate_pass(search: _Search, name: str, start: UncertainPlant, own: int) -> tuple:
    """``(point, value)``: the worst found from ``start`` (module Notes): the structure's
    ranges at their ends, the ``own`` mode over its frequency and damping (``_own_mode``),
    then sweeps of every other mode's frequency (on :data:`OTHER_POINTS` factors) and damping
    (the ends), one at a time, each followed by the own mode again, until a sweep finds
    nothing worse (at most :data:`SWEEPS`)."""
    req = search.req
    u = req.frequency_uncertainty
    low, high = req.damping_range
    point = start
    for field, uncertainty in (("stiffness", req.stiffness_uncertainty),
                               ("point_masses", req.mass_uncertainty),
                               ("hub_inertia", req.hub_inertia_uncertainty)):
        point, _ = _improve(search, name, point, [dataclasses.replace(point, **{field: v})
                                                  for v in _ends(uncertainty)])
    others = np.linspace(1.0 - u, 1.0 + u, OTHER_POINTS) if u > 0 else np.array([1.0])
    point, value = _own_mode(search, name, point, own)
    for _ in range(SWEEPS):
        before = value
        for k in range(search.n_modes):
            if k != own:
                point, _ = _improve(search, name, point, [_moved(point, k, factor=f)
                                                          for f in others])
                point, _ = _improve(search, name, point, [_moved(point, k, zeta=z)
                                                          for z in (low, high)])
        point, value = _own_mode(search, name, point, own)
        if not value < before:
            break
    return point, value


def _draws(req: Requirements, n_modes: int, samples: int, seed: int) -> list:
    """Random plants of the uncertainty: the structure's factors and every mode's frequency
    factor uniform in their ranges, every damping ratio log-uniform (uniform when the range
    starts at 0)."""
    rng = np.random.default_rng(seed)
    low, high = req.damping_range
    u = req.frequency_uncertainty
    points = []
    for _ in range(samples):
        scales = [rng.uniform(1.0 - r, 1.0 + r) for r in
                  (req.stiffness_uncertainty, req.mass_uncertainty, req.hub_inertia_uncertainty)]
        dampings = np.exp(rng.uniform(math.log(low), math.log(high), n_modes)) if low > 0 \
            else rng.uniform(low, high, n_modes)
        points.append(_point(*scales, rng.uniform(1.0 - u, 1.0 + u, n_modes), dampings))
    return points


def _worst_cases(search: _Search, names: list, nominal: UncertainPlant,
                 thorough: bool = True) -> tuple:
    """``(points, values)``: each requirement's worst plant and value (module Notes); not
    ``thorough``, the first stage's grid only."""
    points = _grid(search.req, search.n_modes)
    if thorough:
        points += _draws(search.req, search.n_modes, RANDOM_POINTS, RANDOM_SEED)
    worst_at, worst = [], []
    for name in names:
        values = [search.value(p, name) for p in points]
        point, value = points[int(np.argmin(values))], min(values)
        own = int(name.split()[-1]) - 1 if name.startswith("flexible mode") else 0
        if thorough:
            point, value = _coordinate_pass(search, name, point, own)
        at_nominal = search.value(nominal, name)
        if at_nominal <= value:
            point, value = nominal, at_nominal
        worst_at.append(point)
        worst.append(float(value))
    return worst_at, worst


def verify_requirements(plant, controller, requirements: Requirements,
                        spin_rate: float = 0.0, *, thorough: bool = True) -> Verification:
    """Measure each requirement on the loop of ``controller`` on ``plant`` and over the
    uncertainty (module Notes).

    Parameters
    ----------
    plant : flexctl.Model
        The nominal plant (any variant; its linearisation at ``spin_rate`` is judged).
    controller : object
        Any law :func:`~controllers.analysis.loops.loop_transfer` takes (held, observed or
        filtered laws as they fly).
    requirements : Requirements
        What the loop must meet.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.
    thorough : bool, optional
        Search each requirement's worst case locally after the first stage's grid and random
        plants (module Notes). Default True; False is a quicker screen on the first stage's
        grid alone, whose worst cases may be optimistic.

    Returns
    -------
    Verification
    """
    search = _checked_search("verify_requirements", plant, controller, requirements, spin_rate)
    req = search.req
    own = _beam_damping(plant.system)
    nominal_point = _point() if own > 0.0 else \
        _point(factors=(1.0,) * search.n_modes, dampings=(req.damping_range[0],) * search.n_modes)
    modes = search.modes(nominal_point)
    names = ["closed_loop_stable", "gain_margin_db", "phase_margin_deg"]
    names += [n for n in ("delay_margin", "bandwidth") if getattr(req, n) is not None]
    names += [f"flexible mode {v.mode}" for v in modes]
    worst_at, worst = _worst_cases(search, names, nominal_point, bool(thorough))
    required = {"closed_loop_stable": 1.0, "gain_margin_db": req.gain_margin_db,
                "phase_margin_deg": req.phase_margin_deg, "delay_margin": req.delay_margin,
                "bandwidth": req.bandwidth}
    units = {"closed_loop_stable": "", "gain_margin_db": "dB", "phase_margin_deg": "deg",
             "delay_margin": "s", "bandwidth": "rad/s"}
    checks = []
    for j, name in enumerate(names):
        where = f"worst at {worst_at[j].describe()}"
        value = float(search.value(nominal_point, name))
        if name.startswith("flexible mode"):
            k = int(name.split()[-1]) - 1
            v = modes[k]
            measure = (f"must be gain-stabilised (above {req.gain_stabilised_above:g} rad/s): "
                       f"its attenuation over {req.flexible_attenuation_db:g} dB"
                       if k in search.gain_only else
                       f"distance from the exclusion zone (+-{req.flexible_attenuation_db:g} "
                       f"dB, +-{req.flexible_phase_margin_deg:g} deg about -180 deg)")
            detail = (f"nominal {v.frequency:.4g} rad/s, {v.kind}-stabilised (peak "
                      f"{v.peak_db:.3g} dB, phase margin {v.phase_margin_deg:.3g} deg at its "
                      f"crossings); {measure}, 1 at its edge; {where}")
            checks.append(RequirementCheck(name, 1.0, value, worst[j], "", detail,
                                           worst_at[j]))
        else:
            checks.append(RequirementCheck(name, float(required[name]), value, worst[j],
                                           units[name], where, worst_at[j]))
    coverage = _coverage(search) if thorough else \
        f"a screen: the first stage's grid only, {len(search.cache)} plants evaluated"
    return Verification(tuple(checks), tuple(modes), coverage,
                        search.loop_at(nominal_point))


def _checked_search(owner, plant, controller, requirements, spin_rate) -> _Search:
    if not isinstance(requirements, Requirements):
        raise InputTypeError(f"{owner}.requirements must be a Requirements; got "
                             f"{type(requirements).__name__}")
    if not isinstance(plant, Model) or not isinstance(plant.system, (HubBeam, Structure)):
        raise InputTypeError(f"{owner}.plant must be a planar flexctl Model; got "
                             f"{type(plant).__name__}")
    spin_rate = check_real(owner, "spin_rate", spin_rate)
    return _Search(plant, controller, requirements, spin_rate)


def _coverage(search: _Search) -> str:
    req = search.req
    u = req.frequency_uncertainty
    low, high = req.damping_range
    ranges = [f"each of the {search.n_modes} modal frequencies x{1 - u:.3g} to x{1 + u:.3g} "
              f"on its own, each damping ratio {low:.3g} to {high:.3g}"]
    ranges += [f"{name} +-{value:.3g}" for name, value in
               (("stiffness", req.stiffness_uncertainty), ("point masses", req.mass_uncertainty),
                ("hub inertia", req.hub_inertia_uncertainty)) if value > 0.0]
    return (f"over {'; '.join(ranges)}: a grid of {FREQUENCY_POINTS if u > 0 else 1} common "
            "frequency factors by the ends and middle of the damping range, the corners of "
            f"the structure's ranges and {RANDOM_POINTS} random plants, then for each "
            "requirement from the worst of these one coordinate at a time (the structure's "
            "ends; its own mode, or the first for a rigid-body requirement, on a grid of "
            f"{FREQUENCY_POINTS} frequencies by {DAMPING_POINTS} damping ratios refined by a "
            "Nelder-Mead search; sweeps of every other mode's frequency and damping until one "
            f"finds nothing worse), {len(search.cache)} plants evaluated")


def monte_carlo_requirements(plant, controller, requirements: Requirements, samples: int = 200,
                             *, seed: int = 0, spin_rate: float = 0.0) -> dict:
    """The worst value of each requirement over random plants of the uncertainty: a check of
    :func:`verify_requirements`' search, which should report no better worst case.

    Each plant draws the structure's factors and every mode's frequency factor uniformly in
    their ranges, and every mode's damping ratio log-uniformly (uniformly when the range
    starts at 0).

    Parameters
    ----------
    plant : flexctl.Model
        The nominal plant, as for :func:`verify_requirements`.
    controller : object
        The law, as for :func:`verify_requirements`.
    requirements : Requirements
        What the loop must meet, and the ranges of the uncertainty.
    samples : int, optional
        Plants drawn, 1 to 100000. Default 200.
    seed : int, optional
        Seed of NumPy's default generator. Default 0.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.

    Returns
    -------
    dict
        ``{name: (worst value, UncertainPlant)}`` for every requirement the verification
        lists.
    """
    search = _checked_search("monte_carlo_requirements", plant, controller, requirements,
                             spin_rate)
    samples = check_integer("monte_carlo_requirements", "samples", samples, minimum=1,
                            maximum=100_000)
    seed = check_integer("monte_carlo_requirements", "seed", seed, minimum=0)
    worst = {}
    for point in _draws(search.req, search.n_modes, samples, seed):
        names = ["closed_loop_stable", "gain_margin_db", "phase_margin_deg", "delay_margin",
                 "bandwidth"] + [f"flexible mode {k + 1}" for k in range(len(search.modes(point)))]
        for name in names:
            value = search.value(point, name)
            if name not in worst or value < worst[name][0]:
                worst[name] = (float(value), point)
    return worst
