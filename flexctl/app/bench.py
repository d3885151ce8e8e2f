"""Speed against error: sweeps of mode count, model variant, integrator and tolerance.

For each scene, :func:`bench_scene` runs the scene's manoeuvre on every combination of number
of modes ``N`` (default 1 to 12), model variant, integrator (``cvodes``, ``DOP853``, ``LSODA``,
...) and relative tolerance, and measures the end-to-end wall time of :func:`flexctl.simulate`
and the tip error against a converged reference: the same variant on ``reference_modes`` modes
(default 20) at a tight tolerance. The error of a run is kept apart in two parts:

- ``truncation_error``: the ``N``-mode model integrated at the reference tolerance, against
  the reference (what the model leaves out);
- ``integration_error``: the run against that same ``N``-mode tight run (what the integrator
  adds);

each a relative tip error ``max_t |tip - tip_ref| / max_t |tip_ref|``; ``error`` is the run
against the reference. A run that diverges or turns singular keeps its status and message and is
measured over the time it lasted; a SciPy run past ``time_limit`` is stopped as ``"timeout"``
(and not tried on more modes). ``method_used`` tells when :func:`flexctl.simulate` moved an
explicit method to cvodes for stiffness.

Each scene also gets the modes :func:`flexctl.sim.fidelity.choose_modes` picks, its estimated error
next to the actual truncation error for every ``N`` swept. :func:`run_bench` writes per scene
``<scene>.csv``, ``<scene>.md`` and ``<scene>-pareto.png``, and ``report.md`` linking them
(:mod:`flexctl.app.bench_report`, figure by :mod:`flexctl.app.bench_plot`); the command line
is ``flexctl bench``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import math
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..model import VARIANTS, build_model
from ..model.errors import InputValueError
from ..sim.fidelity import choose_modes
from ..sim.maneuvers import SineTorque, SpinUp
from ..sim.simulation import METHODS, simulate
# the figure and the files live in their own modules, importable from here too
from .bench_plot import plot_speed_error
from .bench_report import (CSV_COLUMNS, SUMMARY_LEVELS, fastest_within, summary_line,
                           write_index, write_scene)
from .scenes import builtin_scenes, load_scene
from .sweep import pareto_front
from .sweep_store import OK, StoreError, SweepStore, TaskOutcome, task_key
from .task_fingerprint import task_fingerprint

__all__ = ["BenchConfig", "BenchRow", "SceneBench", "bench_scene", "run_bench", "finished_runs",
           "runs_on_front", "plot_speed_error", "write_scene", "summary_line", "BENCH_KINDS"]

#: Manoeuvres the bench can drive a model with (inputs, not goals for a controller).
BENCH_KINDS = (SpinUp, SineTorque)


def _ints(name, values, low, high):
    values = tuple(values)
    if not values or any(isinstance(v, bool) or not isinstance(v, (int, np.integer))
                         or not low <= v <= high for v in values):
        raise InputValueError(f"{name} must be integers in [{low}, {high}]; got {values!r}")
    return tuple(sorted(set(int(v) for v in values)))


def _positive(name, value, below=math.inf):
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not 0.0 < value < below:
        raise InputValueError(f"{name} must be a number in (0, {below:g}); got {value!r}")
    return float(value)


@dataclass(frozen=True, kw_only=True)
class BenchConfig:
    """What :func:`bench_scene` sweeps.

    Parameters
    ----------
    scenes : tuple of str
        Scene names or TOML paths; empty (default) for every built-in scene driven by a torque
        or a hub motion.
    modes, variants, methods, rtols : tuple
        Numbers of modes (1 to 200; default 1 to 12), model variants (default all three),
        integrators (:data:`flexctl.sim.simulation.METHODS`; default cvodes, rk4, DOP853,
        LSODA; rk4's tolerance is its target tip error relative to the peak) and
        relative tolerances (in (0, 1); default 1e-4, 1e-6, 1e-8).
    reference_modes : int
        Modes of the converged reference, >= every entry of ``modes``. Default 20.
    reference_rtol : float
        Tolerance of the reference and of the truncation runs, <= every entry of ``rtols``.
    time_limit : float
        Wall time (s) after which a SciPy run is stopped and recorded as a timeout.
    tolerance : float
        Relative tip error for the mode choice check. Default 1e-2.
    t_final : float or None
        Horizon (s) instead of each scene's own.
    """

    scenes: tuple = ()
    modes: tuple = tuple(range(1, 13))
    variants: tuple = VARIANTS
    methods: tuple = ("cvodes", "rk4", "DOP853", "LSODA")
    rtols: tuple = (1e-4, 1e-6, 1e-8)
    reference_modes: int = 20
    reference_rtol: float = 1e-10
    time_limit: float = 30.0
    tolerance: float = 1e-2
    t_final: float | None = None

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        set_("scenes", tuple(str(s) for s in self.scenes))
        set_("modes", _ints("modes", self.modes, 1, 200))
        for name, allowed in (("variants", VARIANTS), ("methods", METHODS)):
            values = tuple(dict.fromkeys(getattr(self, name)))
            bad = [v for v in values if v not in allowed]
            if not values or bad:
                raise InputValueError(f"{name} must be taken from {', '.join(allowed)}; got "
                                      f"{values!r}")
            set_(name, values)
        set_("rtols", tuple(sorted({_positive("rtols", r, 1.0) for r in self.rtols},
                                   reverse=True)))
        if not self.rtols:
            raise InputValueError("rtols must hold at least one tolerance; got ()")
        set_("reference_modes", _ints("reference_modes", (self.reference_modes,),
                                      max(self.modes), 200)[0])
        set_("reference_rtol", _positive("reference_rtol", self.reference_rtol,
                                         min(self.rtols) * (1 + 1e-12)))
        set_("time_limit", _positive("time_limit", self.time_limit))
        set_("tolerance", _positive("tolerance", self.tolerance, 1.0))
        if self.t_final is not None:
            set_("t_final", _positive("t_final", self.t_final))

    @classmethod
    def quick(cls, **changes) -> "BenchConfig":
        """A small sweep (about two minutes for the built-in scenes): 1, 2, 4, 8 modes,
        first_order, cvodes, rk4 and DOP853 at 1e-5 and 1e-8, a 12-mode reference at 1e-9.

        Parameters
        ----------
        **changes
            Fields of :class:`BenchConfig` to set otherwise (e.g. ``scenes``, ``t_final``).
        """
        return replace(cls(modes=(1, 2, 4, 8), variants=("first_order",), rtols=(1e-5, 1e-8),
                           methods=("cvodes", "rk4", "DOP853"), reference_modes=12,
                           reference_rtol=1e-9, time_limit=10.0), **changes)


@dataclass(frozen=True)
class BenchRow:
    """One run of the sweep; errors are relative tip errors (see the module docstring).

    Attributes
    ----------
    scene : str
        The scene's name.
    variant : str
        The model variant.
    n_modes : int
        Modes of the model, ``N`` (of each appendage).
    method : str
        The integrator asked for.
    method_used : str
        The integrator that ran (:func:`flexctl.simulate` may move an explicit method to
        cvodes for stiffness).
    rtol : float
        Relative tolerance asked for.
    status : str
        ``"ok"``, the run's own status when it stopped early, ``"timeout"``, ``"error"``, or
        ``"skipped"`` (not tried after a timeout on fewer modes).
    t_end : float
        Time the run reached, s.
    wall_time_s : float
        Wall time of the run, s.
    n_evaluations : int
        Right-hand-side evaluations.
    error : float
        Relative tip error against the reference (NaN when not measured).
    truncation_error : float
        Relative tip error of the ``N``-mode model at the reference tolerance.
    integration_error : float
        Relative tip error of the run against that tight ``N``-mode run.
    note : str
        What happened to a run that did not simply finish; empty otherwise.
    """

    scene: str
    variant: str
    n_modes: int
    method: str
    method_used: str
    rtol: float
    status: str
    t_end: float
    wall_time_s: float
    n_evaluations: int
    error: float
    truncation_error: float
    integration_error: float
    note: str = ""


@dataclass(frozen=True, eq=False)
class SceneBench:
    """Everything measured on one ``scene`` over ``t_final`` (s); made by :func:`bench_scene`.

    Attributes
    ----------
    scene : Scene
        The scene benched.
    config : BenchConfig
        The sweep run on it.
    t_final : float
        Horizon of every run, s.
    rows : tuple of BenchRow
        One per run.
    references : dict
        Per variant the reference's ``status``, ``t_end`` (s), ``wall_time_s``, ``message``
        and ``difference_from_first_order`` (relative tip difference of the references).
    choice : ModeChoice
        :func:`~flexctl.sim.fidelity.choose_modes` for the scene's variant.
    truncation : dict
        ``{N: actual truncation error}`` of that variant for the modes swept and the mode
        choice (relative tip errors).
    """

    scene: object
    config: BenchConfig
    t_final: float
    rows: tuple
    references: dict
    choice: object
    truncation: dict = field(default_factory=dict)

    @property
    def choice_actual_error(self) -> float:
        """Truncation error of the chosen number of modes against the reference."""
        return self.truncation.get(self.choice.n_modes, math.nan)

    def finished(self) -> list:
        """The finished runs (:func:`finished_runs`), fastest first."""
        return finished_runs(self.rows)

    def front(self, variant: str) -> list:
        """Pareto front of a variant's finished runs (:func:`runs_on_front`).

        Parameters
        ----------
        variant : str
            A model variant among the config's ``variants``.
        """
        return runs_on_front([r for r in self.rows if r.variant == variant])


def finished_runs(rows) -> list:
    """Runs that reached their end with a finite error, fastest first; runs with the same
    variant, modes, integrator used and rtol count once (an explicit method moved to cvodes
    repeats the cvodes run).

    Parameters
    ----------
    rows : iterable of BenchRow
        The runs of a sweep.
    """
    unique = {}
    for r in sorted((r for r in rows if r.status == "ok" and math.isfinite(r.error)),
                    key=lambda r: (r.wall_time_s, r.error)):
        unique.setdefault((r.variant, r.n_modes, r.method_used, r.rtol), r)
    return list(unique.values())


def runs_on_front(rows) -> list:
    """The :func:`finished_runs` that no other beats on both wall time and error (the
    dominance of :func:`flexctl.app.sweep.pareto_front`), fastest first.

    Parameters
    ----------
    rows : iterable of BenchRow
        The runs of a sweep (of one variant, for a front of that variant).
    """
    done = finished_runs(rows)
    if not done:
        return []
    on_front = pareto_front([r.wall_time_s for r in done], [r.error for r in done])
    return [r for r, keep in zip(done, on_front) if keep]


class _TimeUp(Exception):
    """A SciPy run passed its time limit."""


class _Deadline:
    """A manoeuvre whose torque or hub rate, evaluated by SciPy runs at every step, raises
    ``_TimeUp`` after ``deadline``; the rest (CasADi form included) is passed through."""

    def __init__(self, inner, deadline: float):
        self._inner, self._deadline = inner, deadline

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def _check(self):
        if time.perf_counter() > self._deadline:
            raise _TimeUp

    def __call__(self, t):
        self._check()
        return self._inner(t)

    def rate(self, t):
        self._check()
        return self._inner.rate(t)


def _relative_tip_error(result, reference) -> float:
    """``max |tip - tip_ref| / max |tip_ref|`` over the outputs both runs reached.

    Both runs share the output grid; a stopped run ends with its stop time, off the grid.
    """
    n = min(result.t.size, reference.t.size)
    same = np.abs(result.t[:n] - reference.t[:n]) <= 1e-9
    if n == 0 or not same[:-1].all():
        return math.nan
    peak = float(np.max(np.abs(reference.tip_deflection)))
    diff = float(np.max(np.abs(result.tip_deflection[:n][same]
                               - reference.tip_deflection[:n][same])))
    return diff / peak if peak > 0 else diff


def _run(model, scene, t_final, method, rtol, time_limit=None):
    """``(result or None, wall time s, note)``; never raises for a failed run."""
    maneuver = scene.maneuver
    if time_limit is not None and method not in ("cvodes", "rk4", "auto"):
        maneuver = _Deadline(maneuver, time.perf_counter() + time_limit)
    drive = ({"hub_motion": maneuver} if isinstance(scene.maneuver, SpinUp)
             else {"torque": maneuver})
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")          # the stiffness note is in the message
            # timed as a run alone: the model's range is the validity columns' business
            result = simulate(model, t_final, method=method, rtol=rtol,
                              output_step=scene.simulation.output_step,
                              check_validity=False, **drive)
    except _TimeUp:
        return None, time.perf_counter() - start, f"stopped after {time_limit:g} s"
    except Exception as exc:                         # a benchmark records, it does not crash
        return None, time.perf_counter() - start, f"{type(exc).__name__}: {exc}"
    return result, time.perf_counter() - start, ""


def _drivable(scene):
    if not isinstance(scene.maneuver, BENCH_KINDS):
        raise InputValueError(f"scene {scene.name!r} has a {type(scene.maneuver).__name__} "
                              "manoeuvre, a goal for a controller: the bench drives models with a "
                              "torque or a hub motion (spin_up or sine_torque scenes)")
    return scene


def bench_scene(scene, config: BenchConfig, progress: bool = True, *,
                store: SweepStore | None = None) -> SceneBench:
    """Run the sweep of ``config`` on one scene (see the module docstring).

    Parameters
    ----------
    scene : Scene
        Driven by a spin-up or a torque (:data:`BENCH_KINDS`).
    config : BenchConfig
        The sweep: modes, variants, integrators, tolerances and the reference's settings.
    progress : bool, optional
        Show a tqdm progress bar on stderr. Default True.
    store : SweepStore, optional
        Where each run's row is committed as it finishes, and taken from when it is there
        already (a resumed bench runs the references and the tight runs again, the yardsticks
        of every error, and only the rows the store lacks).

    Returns
    -------
    SceneBench
    """
    from tqdm import tqdm

    _drivable(scene)
    t_final = config.t_final or scene.simulation.t_final
    choice = choose_modes(scene.system, scene.maneuver, config.tolerance, variant=scene.variant,
                          t_final=t_final)
    if not isinstance(choice.n_modes, int):
        # several appendages: the bench sweeps one mode count for every appendage
        choice = dataclasses.replace(choice, n_modes=max(choice.n_modes))
    chosen_extra = () if choice.n_modes in config.modes else (choice.n_modes,)
    n_runs = len(config.variants) * (1 + len(config.modes) * (
        1 + len(config.methods) * len(config.rtols))) + len(chosen_extra)
    bar = tqdm(total=n_runs, desc=scene.name, unit="run", disable=not progress, leave=True)

    def tight(variant, n):
        bar.update()
        return _run(build_model(scene.system, n, variant), scene, t_final, "auto",
                    config.reference_rtol)

    references, tight_runs = _tight_runs(tight, scene.name, config)
    truncation = _truncation_errors(tight, references, tight_runs, scene.variant, config.modes,
                                    chosen_extra)
    rows = _sweep_rows(scene, config, t_final, references, tight_runs, bar, store)
    bar.close()
    return SceneBench(scene=scene, config=config, t_final=float(t_final), rows=tuple(rows),
                      references=_reference_summary(references), choice=choice,
                      truncation=truncation)


def _tight_runs(tight, scene_name: str, config: BenchConfig) -> tuple:
    """The references and the runs at the reference tolerance.

    ``tight(variant, n)`` runs ``n`` modes of ``variant`` at the reference tolerance and
    returns ``_run``'s triple.

    Returns
    -------
    references : dict
        ``{variant: SimulationResult}`` on ``config.reference_modes`` modes.
    tight_runs : dict
        ``{(variant, n): SimulationResult or None}`` for every ``n`` of ``config.modes``.

    Raises
    ------
    RuntimeError
        If a reference run fails.
    """
    references, tight_runs = {}, {}
    for variant in config.variants:
        ref, wall, note = tight(variant, config.reference_modes)
        if ref is None:
            raise RuntimeError(f"the {variant} reference of {scene_name} failed: {note}")
        references[variant] = ref
        for n in config.modes:
            tight_runs[variant, n] = tight(variant, n)[0]
    return references, tight_runs


def _truncation_errors(tight, references, tight_runs, variant: str, modes, chosen_extra) -> dict:
    """``{N: relative tip error against the reference}`` of ``variant`` at the reference
    tolerance, for the ``modes`` swept and the mode choice's ``chosen_extra`` (run here)."""
    truncation = {n: _relative_tip_error(tight_runs[variant, n], references[variant])
                  for n in modes if (variant, n) in tight_runs
                  and tight_runs[variant, n] is not None}
    for n in chosen_extra:
        run = tight(variant, n)[0] if variant in references else None
        if run is not None:
            truncation[n] = _relative_tip_error(run, references[variant])
    return truncation


def _sweep_rows(scene, config: BenchConfig, t_final: float, references, tight_runs,
                bar, store=None) -> list:
    """A :class:`BenchRow` for every variant, mode count, integrator and tolerance.

    A method that failed or timed out on fewer modes is skipped on more (it would cost
    more); ``bar`` advances once a row. With a ``store`` (a
    :class:`~flexctl.app.sweep_store.SweepStore`), a row it holds is taken from it, and every
    row run is committed to it as it finishes.
    """
    rows, given_up = [], {}
    done = {} if store is None else store.outcomes()
    for variant, n, method, rtol in itertools.product(config.variants, config.modes,
                                                      config.methods, config.rtols):
        bar.update()
        key = task_key({"scene": scene.name, "variant": variant, "n_modes": n,
                        "method": method, "rtol": rtol})
        if key in done:
            row = _stored_row(store, key, done[key])
        else:
            row = _bench_row(scene, config, t_final, references[variant],
                             tight_runs[variant, n], (variant, n, method, rtol),
                             given_up.get((variant, method, rtol)))
            if store is not None:
                store.record(key, TaskOutcome(status=OK, outputs=dataclasses.asdict(row)))
        if row.status in ("timeout", "error"):     # more modes would cost more
            given_up.setdefault((variant, method, rtol),
                                f"{method} at rtol {rtol:g}: {row.status} on {n} modes")
        rows.append(row)
    return rows


def _stored_row(store: SweepStore, key: str, outcome: TaskOutcome) -> BenchRow:
    """The :class:`BenchRow` ``store`` holds under ``key``; a row that is not one is refused
    by name."""
    try:
        return BenchRow(**outcome.outputs)
    except TypeError as exc:
        raise StoreError(f"sweep store {str(store.path)!r} holds under task {key} a row that is "
                         f"not a bench row ({exc}); forget that task (SweepStore.forget) to run "
                         "it again, or use a new store") from None


def _bench_row(scene, config: BenchConfig, t_final: float, reference, base, run: tuple,
               given_up: str | None) -> BenchRow:
    """The row of ``run`` = ``(variant, n_modes, method, rtol)`` against ``reference`` and
    ``base`` (the same model at the reference tolerance, or None); ``"skipped"`` with the
    reason ``given_up`` when the method failed on fewer modes."""
    variant, n, method, rtol = run
    nan = math.nan
    trunc = _relative_tip_error(base, reference) if base is not None else nan
    head = (scene.name, variant, n, method)
    if given_up is not None:
        return BenchRow(*head, method, rtol, "skipped", 0.0, nan, 0, nan, trunc, nan, given_up)
    result, wall, note = _run(build_model(scene.system, n, variant), scene, t_final, method,
                              rtol, config.time_limit)
    if result is None:
        status = "timeout" if note.startswith("stopped") else "error"
        return BenchRow(*head, method, rtol, status, 0.0, wall, 0, nan, trunc, nan, note)
    return BenchRow(
        *head, result.method, rtol, result.status, float(result.t[-1]), wall,
        result.n_evaluations, _relative_tip_error(result, reference), trunc,
        _relative_tip_error(result, base) if base is not None else nan,
        "" if result.ok and result.method == method else result.message)


def _reference_summary(references) -> dict:
    """Per variant the reference's ``status``, ``t_end`` (s), ``wall_time_s``, ``message`` and
    ``difference_from_first_order`` (relative tip difference; NaN without a first_order
    reference)."""
    first = references.get("first_order")
    return {v: {"status": r.status, "t_end": float(r.t[-1]), "wall_time_s": r.wall_time,
                "message": r.message, "difference_from_first_order":
                _relative_tip_error(r, first) if first is not None else math.nan}
            for v, r in references.items()}


def run_bench(config: BenchConfig, out_dir, progress: bool = True, *, store=None,
              resume: bool = False) -> list:
    """Bench every scene of ``config`` and write its files and ``report.md`` to ``out_dir``.

    Parameters
    ----------
    config : BenchConfig
        The sweep, its ``scenes`` included (empty: every built-in scene the bench can drive).
    out_dir : str or path-like
        Folder the scenes' ``.csv``, ``.md`` and ``-pareto.png`` files and ``report.md`` are
        written to.
    progress : bool, optional
        Show a tqdm progress bar per scene on stderr. Default True.
    store : str or path-like, optional
        SQLite file that every run is committed to as it finishes
        (:class:`~flexctl.app.sweep_store.SweepStore`, one key per scene, variant, modes,
        method and rtol), so that a bench stopped by a crash or a Ctrl-C can resume. The store
        records the reference settings and horizon, and the fingerprint of the bench's code
        (:func:`bench_scene` and the helpers of this module it calls).
    resume : bool, optional
        Take the runs the store already holds (from a bench with the same reference settings,
        horizon and code); False (default) refuses a store that holds runs.

    Returns
    -------
    list of SceneBench
    """
    scenes = [load_scene(name) for name in config.scenes or builtin_scenes()]
    if config.scenes:            # every scene named is checked before the first long run
        scenes = [_drivable(s) for s in scenes]
    else:                        # every built-in scene the bench can drive
        scenes = [s for s in scenes if isinstance(s.maneuver, BENCH_KINDS)]
    benches = []
    with contextlib.ExitStack() as stack:
        kept = None if store is None else stack.enter_context(SweepStore(
            store, task=_store_task(config), seed=None, resume=resume,
            fingerprint=task_fingerprint(bench_scene, _store_task(config))))
        for scene in scenes:
            benches.append(bench_scene(scene, config, progress=progress, store=kept))
            write_scene(benches[-1], out_dir)
    write_index(Path(out_dir), benches)
    return benches


def _store_task(config: BenchConfig) -> str:
    """What a bench store is for: the settings a row's values depend on besides its key (a
    resume may add scenes, modes, methods or tolerances)."""
    return (f"flexctl.app.bench reference_modes={config.reference_modes} "
            f"reference_rtol={config.reference_rtol!r} time_limit={config.time_limit!r} "
            f"t_final={config.t_final!r}")
