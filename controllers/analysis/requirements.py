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
  :data:`PEAK_POINTS` more about the loop's peak in it.
- **Uncertainty.** Every modal frequency scaled by one factor in
  ``1 +- frequency_uncertainty`` (Young's modulus of every beam by its square) and every
  beam's modal damping ratio in ``damping_range``. The worst case of each requirement is
  searched on a grid of :data:`FREQUENCY_POINTS` frequency factors and the ends and middle of
  the damping range, then refined by a bounded scalar search on the frequency factor at the
  worst grid point's damping: the report states this coverage. The frequencies scale
  together; a mode's frequency on its own is not varied here.
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

from .loops import closed_loop_verdict, loop_transfer

__all__ = ["Requirements", "RequirementCheck", "ModeVerdict", "Verification", "FilterDesign",
           "design_filters",
           "verify_requirements", "MODE_WINDOW", "FREQUENCY_POINTS", "RIGID_POINTS"]

#: Half-width of the window a flexible mode is judged in, relative to its frequency.
MODE_WINDOW = 0.15
#: Frequency factors of the uncertainty grid (the ends included).
FREQUENCY_POINTS = 9
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
        Relative uncertainty of every modal frequency, in [0, 0.5]. Default 0.
    damping_range : (float, float), optional
        Modal damping ratios, ``0 <= low <= high < 1``. Default (0.001, 0.01).
    """

    gain_margin_db: float = 6.0
    phase_margin_deg: float = 30.0
    delay_margin: float | None = None
    bandwidth: float | None = None
    flexible_attenuation_db: float = 6.0
    flexible_phase_margin_deg: float = 30.0
    frequency_uncertainty: float = 0.0
    damping_range: tuple = (0.001, 0.01)

    def __post_init__(self):
        owner = "requirements"
        put = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        for name in ("gain_margin_db", "flexible_attenuation_db"):
            put(name, check_real(owner, name, getattr(self, name), minimum=0.0, strict=True))
        for name in ("phase_margin_deg", "flexible_phase_margin_deg"):
            put(name, check_real(owner, name, getattr(self, name), minimum=0.0, maximum=180.0,
                                 strict=True))
        for name in ("delay_margin", "bandwidth"):
            put(name, check_real(owner, name, getattr(self, name), minimum=0.0, strict=True,
                                 optional=True))
        put("frequency_uncertainty", check_real(owner, "frequency_uncertainty",
                                                self.frequency_uncertainty, minimum=0.0,
                                                maximum=0.5))
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
        How the worst case was reached (its frequency factor and damping), and for a flexible
        mode how it is stabilised.
    """

    name: str
    required: float
    nominal: float
    worst: float
    unit: str
    detail: str = ""

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
def _response(loop, w: np.ndarray) -> np.ndarray:
    """The loop's complex frequency response at ``w`` (rad/s): ``C (p I - A)^-1 B + D`` at
    ``p = j w`` (or ``exp(j w T)``), by back substitution on the complex Schur form of ``A``
    (``n^2`` operations a point, all points at once)."""
    import scipy.linalg

    dt = loop.dt
    points = 1j * w if not dt else np.exp(1j * w * float(dt))
    a = np.asarray(loop.A, dtype=float)
    t, z = scipy.linalg.schur(a, output="complex")
    b = z.conj().T @ np.asarray(loop.B, dtype=float)[:, 0]
    c = np.asarray(loop.C, dtype=float)[0] @ z
    n = a.shape[0]
    y = np.zeros((n, points.size), dtype=complex)
    for i in range(n - 1, -1, -1):
        y[i] = (b[i] + t[i, i + 1:] @ y[i + 1:]) / (points - t[i, i])
    return c @ y + float(np.asarray(loop.D)[0, 0])


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


def _rigid_figures(loop, flexible: np.ndarray, stable: bool) -> dict:
    """Gain margin (dB), phase margin (deg), delay margin (s) and bandwidth (rad/s) of the
    rigid-body loop: its crossings outside every flexible mode's window."""
    top = math.pi / float(loop.dt) if loop.dt else 3.0 * float(np.max(flexible, initial=1.0))
    low = 1e-3 * float(np.min(flexible, initial=1.0))
    w = np.geomspace(low, top * (1.0 - 1e-9), RIGID_POINTS)
    gain, phase = _crossings(w, _response(loop, w))

    def rigid(wc):
        return not np.any(np.abs(wc / flexible - 1.0) <= MODE_WINDOW)

    gain = [(wc, m) for wc, m in gain if rigid(wc)]
    phase = [(wc, m) for wc, m in phase if rigid(wc)]
    return {"stable": stable,
            "gain_margin_db": min((m for _, m in phase), default=math.inf),
            "phase_margin_deg": min((m for _, m in gain), default=math.inf),
            "delay_margin": min((math.radians(m) / wc for wc, m in gain), default=math.inf),
            "bandwidth": max((wc for wc, _ in gain), default=0.0)}


def _mode_verdict(loop, mode: int, omega: float, req: Requirements) -> ModeVerdict:
    """How ``loop`` stabilises the mode at ``omega`` (module Notes)."""
    w = omega * np.geomspace(1.0 - MODE_WINDOW, 1.0 + MODE_WINDOW, WINDOW_POINTS)
    gain = np.abs(_response(loop, w))
    k = int(np.argmax(gain))
    fine = w[k] * np.linspace(1.0 - PEAK_SPAN, 1.0 + PEAK_SPAN, PEAK_POINTS)
    w = np.sort(np.concatenate((w, fine)))
    response = _response(loop, w)
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
def _with_beams(system, scale: float, zeta: float):
    """``system`` with every beam's Young's modulus times ``scale`` and damping ``zeta``."""
    def beam(b):
        return dataclasses.replace(b, youngs_modulus=b.youngs_modulus * scale,
                                   damping_ratio=zeta)

    if isinstance(system, HubBeam):
        return dataclasses.replace(system, beam=beam(system.beam))
    return dataclasses.replace(system, appendages=tuple(
        dataclasses.replace(a, beam=beam(a.beam)) for a in system.appendages))


def _beam_damping(system) -> float:
    beams = [system.beam] if isinstance(system, HubBeam) else [a.beam for a in system.appendages]
    return max(b.damping_ratio for b in beams)


class _Search:
    """The figures of the loop on the plant at each (frequency factor, damping) asked for,
    each plant built once."""

    def __init__(self, plant, controller, req: Requirements, spin_rate: float):
        self.plant, self.controller, self.req, self.spin = plant, controller, req, spin_rate
        self.cache = {}
        self.base = getattr(plant, "source", plant.system)
        # at rest the exact variant's linearisation is first_order's, which builds at once
        self.variant = "first_order" if plant.variant.exact and spin_rate == 0.0 else None

    def loop(self, factor: float, zeta: float):
        system = _with_beams(self.base, factor ** 2, zeta)
        model = rebuild(self.plant, variant=self.variant, system=system)
        return model, loop_transfer(model, self.controller, self.spin)

    def figures(self, factor: float, zeta: float) -> dict:
        key = (round(factor, 12), round(zeta, 12))
        if key not in self.cache:
            model, loop = self.loop(factor, zeta)
            flexible = _flexible_frequencies(model)
            stable = closed_loop_verdict(loop)[0]
            figures = _rigid_figures(loop, flexible, stable)
            verdicts = [_mode_verdict(loop, k + 1, omega, self.req)
                        for k, omega in enumerate(flexible)]
            figures["modes"] = verdicts
            figures["scores"] = [v.score for v in verdicts]
            self.cache[key] = figures
        return self.cache[key]


def _values(figures: dict, names: list) -> list:
    out = []
    for name in names:
        if name.startswith("flexible mode "):
            k = int(name.split()[-1]) - 1
            scores = figures["scores"]
            out.append(scores[k] if k < len(scores) else math.inf)
        elif name == "closed_loop_stable":
            out.append(1.0 if figures["stable"] else 0.0)
        else:
            out.append(figures[name])
    return out


def verify_requirements(plant, controller, requirements: Requirements,
                        spin_rate: float = 0.0) -> Verification:
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

    Returns
    -------
    Verification
    """
    from scipy.optimize import minimize_scalar

    if not isinstance(requirements, Requirements):
        raise InputTypeError("verify_requirements.requirements must be a Requirements; got "
                             f"{type(requirements).__name__}")
    if not isinstance(plant, Model) or not isinstance(plant.system, (HubBeam, Structure)):
        raise InputTypeError("verify_requirements.plant must be a planar flexctl Model; got "
                             f"{type(plant).__name__}")
    spin_rate = check_real("verify_requirements", "spin_rate", spin_rate)
    req = requirements
    search = _Search(plant, controller, req, spin_rate)
    own = _beam_damping(plant.system)
    low, high = req.damping_range
    zeta0 = own if own > 0.0 else low
    nominal = search.figures(1.0, zeta0)
    names = ["closed_loop_stable", "gain_margin_db", "phase_margin_deg"]
    names += [n for n in ("delay_margin", "bandwidth") if getattr(req, n) is not None]
    names += [f"flexible mode {v.mode}" for v in nominal["modes"]]
    u = req.frequency_uncertainty
    factors = np.linspace(1.0 - u, 1.0 + u, FREQUENCY_POINTS) if u > 0 else np.array([1.0])
    dampings = sorted({low, math.sqrt(low * high) if low > 0 else 0.5 * high, high, zeta0})
    points = [(float(f), float(z)) for f in factors for z in dampings]
    table = np.array([_values(search.figures(f, z), names) for f, z in points])
    worst_at = [points[int(np.argmin(table[:, j]))] for j in range(len(names))]
    worst = [float(np.min(table[:, j])) for j in range(len(names))]
    step = 2.0 * u / max(FREQUENCY_POINTS - 1, 1)
    for j, (f, z) in enumerate(worst_at if u > 0 else ()):
        found = minimize_scalar(lambda x: _values(search.figures(x, z), names)[j],
                                bounds=(max(1.0 - u, f - step), min(1.0 + u, f + step)),
                                method="bounded", options={"xatol": 1e-3 * step})
        if found.fun < worst[j]:
            worst[j], worst_at[j] = float(found.fun), (float(found.x), z)
    required = {"closed_loop_stable": 1.0, "gain_margin_db": req.gain_margin_db,
                "phase_margin_deg": req.phase_margin_deg, "delay_margin": req.delay_margin,
                "bandwidth": req.bandwidth}
    units = {"closed_loop_stable": "", "gain_margin_db": "dB", "phase_margin_deg": "deg",
             "delay_margin": "s", "bandwidth": "rad/s"}
    checks = []
    for j, name in enumerate(names):
        f, z = worst_at[j]
        where = f"worst at frequency factor {f:.4g}, damping {z:.3g}"
        if name.startswith("flexible mode"):
            k = int(name.split()[-1]) - 1
            v = nominal["modes"][k]
            detail = (f"nominal {v.frequency:.4g} rad/s, {v.kind}-stabilised (peak "
                      f"{v.peak_db:.3g} dB, phase margin {v.phase_margin_deg:.3g} deg at its "
                      f"crossings); distance from the exclusion zone (+-"
                      f"{req.flexible_attenuation_db:g} dB, +-"
                      f"{req.flexible_phase_margin_deg:g} deg about -180 deg), 1 at its edge; "
                      f"{where}")
            checks.append(RequirementCheck(name, 1.0, float(_values(nominal, [name])[0]),
                                           worst[j], "", detail))
        else:
            checks.append(RequirementCheck(name, float(required[name]),
                                           float(_values(nominal, [name])[0]), worst[j],
                                           units[name], where))
    coverage = (f"{len(points)} plants: frequency factors {factors[0]:.3g} to "
                f"{factors[-1]:.3g} ({factors.size} points) by damping ratios "
                f"{', '.join(f'{z:.3g}' for z in dampings)}, each requirement's worst refined "
                "by a bounded scalar search on the frequency factor; the frequencies scale "
                f"together ({len(search.cache)} loops evaluated)")
    return Verification(tuple(checks), tuple(nominal["modes"]), coverage,
                        search.loop(1.0, zeta0)[1])


# ------------------------------------------------------------------ filter design
@dataclass(frozen=True)
class FilterDesign:
    """What :func:`design_filters` found.

    Attributes
    ----------
    controller : object
        The law with the filters placed (a :class:`~controllers.Filtered`), or the law given
        when it met every requirement as it was.
    added : tuple
        The filters placed, in the order they were added.
    verification : Verification
        The verification of :attr:`controller`.
    unmet : tuple of (str, float, float)
        ``(name, worst, required)`` of each requirement still missed (empty on success).
    tried : int
        Candidate designs verified.
    """

    controller: object
    added: tuple
    verification: Verification
    unmet: tuple
    tried: int

    @property
    def met(self) -> bool:
        """Whether every requirement is met."""
        return not self.unmet


def _shortfall(verification: Verification) -> tuple:
    """``(unstable, total shortfall, -least ratio)``, smaller is better: whether the loop is
    unstable somewhere in the uncertainty, the sum over the requirements of how far each
    worst value falls short of its required one (relative), and the least ratio of worst to
    required."""
    ratios = [check.worst / check.required for check in verification.checks
              if check.name != "closed_loop_stable" and math.isfinite(check.worst)]
    unstable = any(c.name == "closed_loop_stable" and not c.passed
                   for c in verification.checks)
    return (unstable, sum(max(0.0, 1.0 - r) for r in ratios), -min(ratios, default=0.0))


def _candidates(omega: float, req: Requirements, sample_time: float):
    """Notches at ``omega`` (depths and widths that cover the frequency uncertainty) and a
    roll-off below it, each within the sampled loop's reach."""
    from ..feedback.structural_filters import NYQUIST_FRACTION, Notch, RollOff

    limit = NYQUIST_FRACTION * math.pi / sample_time
    width = max(req.frequency_uncertainty, 0.05)
    found = []
    if omega < limit:
        for depth in (req.flexible_attenuation_db + 6.0, req.flexible_attenuation_db + 14.0):
            for zeta in (width, 2.0 * width):
                found.append(Notch(frequency=omega, depth_db=depth, width=min(zeta, 1.0)))
    if 0.5 * omega < limit:
        found.append(RollOff(frequency=0.5 * omega, damping=0.7))
    return found


def _better_filter(plant, base, filters, report, req, spin_rate) -> tuple:
    """``(tried, filter, verification, law)``: the first failing flexible mode (worst first)
    whose best candidate lowers the loop's shortfall (:func:`_shortfall`); ``filter`` None
    when no candidate for any mode does."""
    from ..feedback.structural_filters import Filtered

    failing = sorted((c for c in report.checks if c.name.startswith("flexible mode")
                      and not c.passed), key=lambda c: c.worst)
    tried = 0
    for check in failing:
        mode = report.modes[int(check.name.split()[-1]) - 1]
        best = None
        for candidate in _candidates(mode.frequency, req, base.sample_time):
            trial = Filtered(law=base, filters=[*filters, candidate])
            result = verify_requirements(plant, trial, req, spin_rate)
            tried += 1
            if best is None or _shortfall(result) < _shortfall(best[1]):
                best = (candidate, result, trial)
        if best is not None and _shortfall(best[1]) < _shortfall(report):
            return tried, *best
    return tried, None, None, None


def design_filters(plant, controller, requirements: Requirements, *,
                   max_filters: int = 3, spin_rate: float = 0.0) -> FilterDesign:
    """Place notch or roll-off filters on a sampled law's command until the loop meets the
    requirements over the uncertainty, or say which it cannot meet and by how much.

    Greedy: while flexible modes miss their requirement, the candidates for each (worst
    first; notches at its nominal frequency, of two depths and two widths covering the
    frequency uncertainty, and a roll-off at half its frequency) are verified
    (:func:`verify_requirements`), and the best of the first mode whose best lowers the
    loop's total shortfall (the sum over the requirements of how far each worst value falls
    short of its required one, relative; a loop unstable anywhere in the uncertainty ranks
    last) is kept.

    Parameters
    ----------
    plant : flexctl.Model
        The nominal plant.
    controller : ZeroOrderHold, Observed or Filtered
        A sampled law (its filters, if any, kept).
    requirements : Requirements
        What the loop must meet.
    max_filters : int, optional
        Most filters to add. Default 3.
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.

    Returns
    -------
    FilterDesign
    """
    from ..feedback.structural_filters import Filtered

    max_filters = check_integer("design_filters", "max_filters", max_filters, minimum=1,
                                maximum=10)
    base = controller.law if isinstance(controller, Filtered) else controller
    kept = list(controller.filters) if isinstance(controller, Filtered) else []
    if getattr(base, "sample_time", None) is None:
        raise InputTypeError("design_filters.controller must be a sampled law (a "
                             "ZeroOrderHold, Observed or Filtered law); got "
                             f"{type(controller).__name__}")
    law = controller
    report = verify_requirements(plant, law, requirements, spin_rate)
    tried, added = 1, []
    while len(added) < max_filters:
        better = _better_filter(plant, base, [*kept, *added], report, requirements, spin_rate)
        tried += better[0]
        if better[1] is None:
            break
        added.append(better[1])
        report, law = better[2], better[3]
    unmet = tuple((c.name, c.worst, c.required) for c in report.checks if not c.passed)
    return FilterDesign(law, tuple(added), report, unmet, tried)
