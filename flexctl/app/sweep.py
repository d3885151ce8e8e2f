"""Parameter sweeps through any ``concurrent.futures``-style executor, as tidy tables.

:func:`sweep` evaluates a task at every point of a parameter grid and returns a
:class:`SweepResult`: one row per point, with the point's parameters and the task's outputs as
columns. Where the points run is the caller's choice:

- ``executor=None``: one after the other in this process;
- a :class:`concurrent.futures.ProcessPoolExecutor` (or a thread pool): the cores of this
  machine;
- the executor of a Dask distributed client, ``Client(...).get_executor()``: the workers of a
  cluster, the way past one machine.

Anything with ``submit(fn, *args)`` returning futures with ``result()`` will do, or a factory
of executors (the sweep then replaces a process pool that a dying worker breaks). A long sweep
keeps going: a task that raises becomes a row with its error (``on_error="record"``), a task
lost with its worker is submitted again (``retries``), and with ``store="runs.sqlite"`` each
finished task is committed to disk as it arrives, so that ``resume=True`` after a crash or a
Ctrl-C runs only the rest (:mod:`flexctl.app.sweep_store`). A task with a ``seed`` parameter
gets its own, derived from the sweep's ``seed`` and the point: the rows do not depend on the
workers, the order, or an interruption. Tasks go to
other processes by pickling, so a task must be a module-level function or an instance of a
module-level class such as the frozen dataclasses here:

- :class:`PointMassAmplitudes`: peak and residual tip amplitude of a torque response with one
  point mass placed by its position ratio ``d/l`` and mass ratio ``m/(rhoA l)`` (paper 000,
  Figs. 6 and 8);
- :class:`SceneTask`: a scene run with overrides (``{"maneuver.spin_rate": 2.0}``), summarised
  in numbers; slew scenes take the controller factory (``controllers.from_spec``).

Examples
--------
>>> from flexctl.app.sweep import PointMassAmplitudes, sweep
>>> task = PointMassAmplitudes.from_scene("hub-beam-mass", t_final=6.0)
>>> table = sweep(task, {"mass_ratio": [0.0, 0.5]}, progress=False)
>>> table.columns[:3]
('mass_ratio', 'peak_amplitude', 'residual_amplitude')
>>> bool(table.column("peak_amplitude")[1] > table.column("peak_amplitude")[0])
True
"""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..sim.maneuvers import SineTorque
from ..model.parameters import HubBeam, PointMass
from ..model.errors import InputTypeError, InputValueError
from .sweep_runner import SweepError, is_executor, outcomes
from .sweep_store import task_key
from .verdict import run_verdict

__all__ = ["sweep", "parameter_grid", "SweepResult", "SweepError", "pareto_front",
           "response_amplitudes", "PointMassAmplitudes", "SceneTask"]


# --------------------------------------------------------------------------- grids
def parameter_grid(**axes) -> list:
    """Every combination of the given parameter values, as a list of dicts.

    Parameters
    ----------
    **axes : sequence
        ``name=values``; the first name varies slowest.

    Returns
    -------
    list of dict
        ``len = prod(len(values))`` points ``{name: value}``, values as given (NumPy scalars
        turned into Python numbers).

    Examples
    --------
    >>> parameter_grid(variant=["first_order", "zero_order"], spin_rate=[0.5, 2.0])
    ... # doctest: +NORMALIZE_WHITESPACE
    [{'variant': 'first_order', 'spin_rate': 0.5}, {'variant': 'first_order', 'spin_rate': 2.0},
     {'variant': 'zero_order', 'spin_rate': 0.5}, {'variant': 'zero_order', 'spin_rate': 2.0}]
    """
    if not axes:
        raise InputValueError("parameter_grid needs at least one axis, e.g. "
                              "mass_ratio=[0, 0.5, 1]")
    names, columns = [], []
    for name, values in axes.items():
        if isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray)):
            raise InputTypeError(f"parameter_grid axis {name!r} must be a sequence of values; got "
                                 f"{type(values).__name__}")
        if len(values) == 0:
            raise InputValueError(f"parameter_grid axis {name!r} must hold at least one value; "
                                  "got none")
        names.append(name)
        columns.append([_plain(v) for v in values])
    return [dict(zip(names, combo)) for combo in itertools.product(*columns)]


def _plain(value):
    """NumPy scalars as Python scalars (clean tables, CSV and TOML overrides)."""
    return value.item() if isinstance(value, np.generic) else value


def _points(grid) -> list:
    if isinstance(grid, Mapping):
        return parameter_grid(**grid)
    if isinstance(grid, (str, bytes)) or not isinstance(grid, Sequence):
        raise InputTypeError("parameter_grid must be a dict {name: values} or a sequence of dicts "
                             f"{{name: value}}; got {type(grid).__name__}")
    points = []
    for k, point in enumerate(grid):
        if not isinstance(point, Mapping):
            raise InputTypeError(f"parameter_grid[{k}] must be a dict {{name: value}}; got "
                                 f"{type(point).__name__}")
        points.append({str(key): _plain(v) for key, v in point.items()})
    if not points:
        raise InputValueError("parameter_grid must hold at least one point; got none")
    return points


# --------------------------------------------------------------------------- table
@dataclass(frozen=True, eq=False)
class SweepResult:
    """A sweep as a tidy table: one row per grid point, one column per parameter or output.

    Attributes
    ----------
    rows : tuple of dict
        In the order of the grid; each holds the point's parameters, then the task's outputs.
    parameters : tuple of str
        Names of the parameter columns.
    outputs : tuple of str
        Names of the output columns (the union over rows, in order of first appearance).
    wall_time : float
        Wall time of the whole sweep, s.
    failed : tuple of int
        Indices of the rows whose task failed (their ``failure`` column holds the error).
    resumed : int
        Tasks taken from the store rather than run.
    """

    rows: tuple
    parameters: tuple
    outputs: tuple
    wall_time: float = 0.0
    failed: tuple = ()
    resumed: int = 0

    @property
    def columns(self) -> tuple:
        """Parameter columns, then output columns."""
        return self.parameters + tuple(c for c in self.outputs if c not in self.parameters)

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self):
        return iter(self.rows)

    def __repr__(self):
        failed = f", {len(self.failed)} failed" if self.failed else ""
        return (f"SweepResult({len(self.rows)} rows{failed}, parameters="
                f"{list(self.parameters)}, outputs={list(self.outputs)}, "
                f"wall_time={self.wall_time:.3g} s)")

    def column(self, name: str) -> np.ndarray:
        """The values of one column, shape (rows,): float when all are numbers, else object.

        A row without the column (a task that returned fewer outputs there) gives NaN.

        Parameters
        ----------
        name : str
            One of :attr:`columns`.
        """
        if name not in self.columns:
            raise KeyError(f"column must be one of {', '.join(self.columns)}; got {name!r}")
        values = [row.get(name, math.nan) for row in self.rows]
        if all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool)
               for v in values):
            return np.array(values, dtype=float)
        return np.array(values, dtype=object)

    def where(self, **equal) -> "SweepResult":
        """The rows whose columns equal the given values, e.g. ``where(variant="zero_order")``.

        Parameters
        ----------
        **equal
            ``column=value`` for each column to match; every column must be one of
            :attr:`columns`.
        """
        for name in equal:
            if name not in self.columns:
                raise KeyError(f"where: column must be one of {', '.join(self.columns)}; "
                               f"got {name!r}")
        kept = [k for k, r in enumerate(self.rows)
                if all(r.get(name) == v for name, v in equal.items())]
        failed = set(self.failed)
        return dataclasses.replace(self, rows=tuple(self.rows[k] for k in kept),
                                   failed=tuple(i for i, k in enumerate(kept) if k in failed))

    def without_failures(self) -> "SweepResult":
        """The rows whose task succeeded (:attr:`failed` left out)."""
        failed = set(self.failed)
        return dataclasses.replace(self, failed=(), rows=tuple(
            r for k, r in enumerate(self.rows) if k not in failed))

    def scalar_columns(self) -> tuple:
        """Columns whose every value is a number, string, bool or None (CSV-ready)."""
        scalar = (int, float, str, bool, np.number, type(None))
        return tuple(c for c in self.columns
                     if all(isinstance(r.get(c), scalar) for r in self.rows))

    def to_csv(self, path=None) -> str:
        """Write the scalar columns (:meth:`scalar_columns`) as CSV; return the text.

        Parameters
        ----------
        path : str or path-like, optional
            File to write; default none (only the text is returned).
        """
        names = self.scalar_columns()
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(names)
        for row in self.rows:
            writer.writerow(["" if row.get(c) is None else _csv_value(row.get(c))
                             for c in names])
        text = buffer.getvalue()
        if path is not None:
            with open(path, "w", newline="") as handle:
                handle.write(text)
        return text

    def to_pandas(self):
        """The table as a ``pandas.DataFrame`` (pandas is optional: install it to use this)."""
        try:
            import pandas
        except ImportError:
            raise ImportError("SweepResult.to_pandas needs pandas, which flexctl does not "
                              "require; install it (pip install pandas) or use to_csv() "
                              "or column()") from None
        return pandas.DataFrame(list(self.rows), columns=list(self.columns))


def _csv_value(value):
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return _plain(value)


def pareto_front(*objectives) -> np.ndarray:
    """Which points no other point beats in every objective (all minimised).

    Parameters
    ----------
    *objectives : array_like, each shape (P,)
        Two or more objectives, e.g. wall time and error; NaN points are never on the front.

    Returns
    -------
    ndarray of bool, shape (P,)
        True for the non-dominated points.

    Examples
    --------
    >>> pareto_front([1.0, 2.0, 3.0, 2.5], [3.0, 1.0, 0.5, 2.0]).tolist()
    [True, True, True, False]
    """
    if len(objectives) < 2:
        raise InputValueError(f"pareto_front needs at least two objectives; got {len(objectives)}")
    costs = np.column_stack([np.asarray(o, dtype=float).reshape(-1) for o in objectives])
    finite = np.all(np.isfinite(costs), axis=1)
    front = finite.copy()
    for i in np.nonzero(finite)[0]:
        others = costs[finite]
        beaten = np.all(others <= costs[i], axis=1) & np.any(others < costs[i], axis=1)
        front[i] = not beaten.any()
    return front


# --------------------------------------------------------------------------- engine
ON_ERROR = ("record", "raise")


def sweep(task: Callable, parameter_grid, executor=None, progress=True, *,
          description: str | None = None, store=None, resume: bool = False, seed: int = 0,
          on_error: str = "record", retries: int = 2) -> SweepResult:
    """Evaluate ``task(**point)`` at every point of a grid; return a tidy table.

    Parameters
    ----------
    task : callable
        Called as ``task(**point)``, plus ``seed=`` when it has a ``seed`` parameter (and the
        point none); returns a dict of outputs ``{name: value}`` (or one value, stored in the
        column ``value``). With an executor that runs in other processes it must be
        picklable: a module-level function or an instance of a module-level class.
    parameter_grid : dict or sequence of dict
        ``{name: values}``: every combination (:func:`parameter_grid`); or the points
        themselves, ``[{name: value, ...}, ...]``. Values: numbers, strings, bools, None or
        lists of them. A point given twice runs once.
    executor : concurrent.futures.Executor-like or callable, optional
        Anything with ``submit(fn, *args)`` returning futures with ``result()``: a
        ``ProcessPoolExecutor``, a ``ThreadPoolExecutor``, or ``dask.distributed``'s
        ``Client.get_executor()``; the caller owns it (the sweep does not shut it down). Or
        a factory of them (``lambda: ProcessPoolExecutor(4)``): the sweep owns what it
        builds, and builds a fresh one when a worker is lost (a process pool breaks as a
        whole). Default ``None``: run the points here, in order.
    progress : bool, optional
        Show a progress bar (tqdm, on stderr) with done, failed and remaining. Default True.
    description : str, optional
        Label of the progress bar; default the task's name.
    store : str or path-like, optional
        SQLite file that every finished task is committed to as it arrives
        (:class:`~flexctl.app.sweep_store.SweepStore`); a crash, a lost worker or a Ctrl-C
        loses only the tasks running. The store records the task's name and fingerprint, its
        code and inputs (:func:`~flexctl.app.task_fingerprint.task_fingerprint`), and the
        seed. Default none (the table lives in memory only).
    resume : bool, optional
        Take the tasks the store already holds (``ok`` or ``failed``) and run only the
        others; the store must hold the same task (same fingerprint: not another lambda, nor
        a function redefined under the same name) and seed. False (default) refuses a store
        that holds tasks.
    seed : int, optional
        The sweep's seed, >= 0 (default 0). A task with a ``seed`` parameter gets its own,
        :func:`~flexctl.app.sweep_store.task_seed` of this seed and the point's key, so its
        row does not depend on the worker, the order, or an interruption.
    on_error : {"record", "raise"}, optional
        ``"record"`` (default): a task that raises gives a row with its parameters and its
        error in the column ``failure`` (outputs missing, NaN in :meth:`SweepResult.column`),
        the sweep goes on and warns at the end. ``"raise"``: :class:`SweepError` at the first
        failure, the points not started cancelled.
    retries : int, optional
        Times a task lost with its worker is submitted again, >= 0 (default 2); past that it
        is recorded as failed. Dask reschedules such tasks by itself first.

    Returns
    -------
    SweepResult
        Rows in the order of the grid, whatever order the points finished in.

    Raises
    ------
    SweepError
        With ``on_error="raise"``, when the task raises at a point (named; the exception is
        the ``__cause__``); when an executor given (not a factory) breaks.
    StoreError
        When ``store`` is not a sweep store, is damaged, holds another task's or seed's
        results, or holds tasks and ``resume`` is False
        (:class:`~flexctl.app.sweep_store.StoreError`, a ``ValueError``; the message names
        the file).
    KeyboardInterrupt
        After cancelling the points not started; the finished ones are in the store.

    Notes
    -----
    ``on_error="record"`` is the default: a study of thousands of runs should neither stop at
    its first bad point nor lose the others; the warning and :attr:`SweepResult.failed` keep
    the failures in sight. Give ``"raise"`` where any failure is a bug (the demo's figures).
    """
    _check_task(task, executor)
    _check_options(store, resume, seed, on_error, retries)
    points = _points(parameter_grid)
    keys = [task_key(p) for p in points]
    index = {}                          # key: (first grid index, point)
    for k, (key, point) in enumerate(zip(keys, points)):
        index.setdefault(key, (k, point))
    name = description or getattr(task, "__name__", type(task).__name__)
    start = time.perf_counter()
    done, fresh = outcomes(task, index, executor, name, store=store, resume=resume,
                           seed=seed, progress=progress, on_error=on_error, retries=retries)
    table = _sweep_table(points, keys, {**done, **fresh}, start, len(done))
    _warn_of_failures(table, name)
    return table


def _warn_of_failures(table: SweepResult, name: str) -> None:
    """A RuntimeWarning (at the caller of :func:`sweep`) when points of ``table`` failed."""
    if table.failed:
        k = table.failed[0]
        warnings.warn(f"sweep {name}: {len(table.failed)} of {len(table)} points failed (their "
                      f"rows' 'failure' column says why); the first, point {k}: "
                      f"{table.rows[k]['failure']}", RuntimeWarning, stacklevel=3)


def _check_task(task, executor) -> None:
    """Raise unless ``task`` is callable and ``executor`` an executor or a factory."""
    if not callable(task):
        raise InputTypeError(f"task must be callable as task(**point); got {type(task).__name__}")
    if executor is not None and not (is_executor(executor) or callable(executor)):
        raise InputTypeError("executor must have a submit(fn, *args) method (a "
                             "concurrent.futures executor or a Dask Client.get_executor()), "
                             f"or be a factory of one; got {type(executor).__name__}")


def _check_options(store, resume, seed, on_error, retries) -> None:
    """Raise unless the store, resume, seed, on_error and retries options are valid."""
    if on_error not in ON_ERROR:
        raise InputValueError(f"sweep on_error must be one of {', '.join(ON_ERROR)}; got "
                              f"{on_error!r}")
    if isinstance(retries, bool) or not isinstance(retries, (int, np.integer)) or retries < 0:
        raise InputValueError(f"sweep retries must be an integer >= 0; got {retries!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputValueError(f"sweep seed must be an integer >= 0; got {seed!r}")
    if not isinstance(resume, bool):
        raise InputTypeError(f"sweep resume must be True or False; got {resume!r}")
    if resume and store is None:
        raise InputValueError("sweep resume=True needs a store (the file of the sweep to "
                              "resume); got store=None")


def _sweep_table(points: list, keys: list, outcomes: dict, start: float,
                 resumed: int) -> SweepResult:
    """The table of a sweep: one row per point, its parameters then the task's other
    outputs (or ``failure``, the error of a failed task); the wall time (s) runs from
    ``start`` (:func:`time.perf_counter`) to now."""
    parameters = tuple(dict.fromkeys(k for p in points for k in p))
    rows, failed = [], []
    for k, (point, key) in enumerate(zip(points, keys)):
        outcome = outcomes[key]
        out = outcome.outputs if outcome.ok else {"failure": outcome.error}
        failed.extend([k] if not outcome.ok else [])
        rows.append({**point, **{n: v for n, v in out.items() if n not in point}})
    names = tuple(dict.fromkeys(n for row in rows for n in row if n not in parameters))
    return SweepResult(rows=tuple(rows), parameters=parameters, outputs=names,
                       wall_time=time.perf_counter() - start, failed=tuple(failed),
                       resumed=resumed)


# --------------------------------------------------------------------------- tasks
def response_amplitudes(result, torque_end: float) -> tuple:
    """Peak and residual tip amplitude of a response to a torque that ends at ``torque_end``.

    Parameters
    ----------
    result : SimulationResult
        The run, its tip deflection over time.
    torque_end : float
        Time the torque stops, s (``T_m`` of a one-period sine torque).

    Returns
    -------
    peak : float
        Largest ``|tip deflection|`` while the torque acts (``t <= torque_end``), m: the
        papers' "maximum response amplitude".
    residual : float
        Largest ``|tip deflection|`` after it (``t > torque_end``), m: the papers' "steady
        state response amplitude" of the free vibration left behind. NaN if the run ended
        before ``torque_end``.
    """
    t, tip = result.t, np.abs(result.tip_deflection)
    during, after = t <= torque_end, t > torque_end
    peak = float(tip[during].max()) if during.any() else math.nan
    residual = float(tip[after].max()) if after.any() else math.nan
    return peak, residual


@dataclass(frozen=True, kw_only=True)
class PointMassAmplitudes:
    """Sweep task: tip amplitudes of a torque response with one point mass (paper 000).

    Called as ``task(mass_position_ratio=..., mass_ratio=...)``: the system's point masses are
    replaced by one mass ``m = mass_ratio * rhoA l`` at ``d = mass_position_ratio * l``, and the
    model is driven by ``torque``. A ratio left out keeps the value of the system's first
    point mass (0 when it has none).

    Parameters
    ----------
    system : HubBeam
        The hub and beam (its point masses give the default ratios).
    torque : SineTorque
        The torque, N m; the peak amplitude is measured while it acts, the residual after.
    t_final : float
        Simulated time, s (> ``torque.duration``).
    n_modes : int
        Modes of the model. Default 4.
    variant : str
        Model variant. Default ``"first_order"``.
    output_step : float
        Output spacing, s (the amplitudes are maxima over these samples). Default 0.005.

    Notes
    -----
    A call returns a dict: ``peak_amplitude``, ``residual_amplitude`` (m,
    :func:`response_amplitudes`), ``mass`` (kg), ``position`` (m), ``first_frequency``
    (lowest hub-free natural frequency, rad/s) and ``status``.
    """

    system: HubBeam
    torque: SineTorque
    t_final: float = 20.0
    n_modes: int = 4
    variant: str = "first_order"
    output_step: float = 0.005

    def __post_init__(self):
        if not isinstance(self.system, HubBeam):
            raise InputTypeError(f"PointMassAmplitudes.system must be a HubBeam; got "
                                 f"{type(self.system).__name__}")
        if not isinstance(self.torque, SineTorque):
            raise InputTypeError(f"PointMassAmplitudes.torque must be a SineTorque; got "
                                 f"{type(self.torque).__name__}")
        if not (isinstance(self.t_final, (int, float)) and self.t_final > self.torque.duration):
            raise InputValueError("PointMassAmplitudes.t_final must exceed the torque duration "
                                  f"{self.torque.duration:g} s; got {self.t_final!r}")

    @classmethod
    def from_scene(cls, name: str = "hub-beam-mass", **kwargs) -> "PointMassAmplitudes":
        """The task of a sine-torque scene (default paper 000's ``hub-beam-mass``).

        Parameters
        ----------
        name : str, optional
            A scene whose maneuver is a sine torque: built-in name or TOML file path. Default
            ``"hub-beam-mass"``.
        **kwargs : object
            Fields of the task that override the scene's settings (``t_final``, ``n_modes``,
            ``output_step``, ...).
        """
        from .scenes import load_scene

        scene = load_scene(name)
        if not isinstance(scene.maneuver, SineTorque):
            raise InputValueError(f"PointMassAmplitudes.from_scene needs a sine_torque scene; "
                                  f"{name!r} has {type(scene.maneuver).__name__}")
        settings = {"system": scene.system, "torque": scene.maneuver,
                    "t_final": scene.simulation.t_final, "n_modes": scene.model.modes,
                    "variant": scene.variant}
        settings.update(kwargs)
        return cls(**settings)

    @property
    def default_ratios(self) -> tuple:
        """``(mass_position_ratio, mass_ratio)`` of the system's first point mass."""
        beam = self.system.beam
        if not self.system.masses:
            return 0.0, 0.0
        first = self.system.masses[0]
        return first.position / beam.length, first.mass / (beam.density * beam.area
                                                           * beam.length)

    def __call__(self, mass_position_ratio: float | None = None,
                 mass_ratio: float | None = None) -> dict:
        from ..model import build_model
        from ..sim.simulation import simulate

        default_position, default_mass = self.default_ratios
        position = default_position if mass_position_ratio is None else mass_position_ratio
        ratio = default_mass if mass_ratio is None else mass_ratio
        for name, value in (("mass_position_ratio", position), ("mass_ratio", ratio)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not 0.0 <= value <= 1.0:
                raise InputValueError(f"{name} must be a number in [0, 1]; got {value!r}")
        beam = self.system.beam
        mass = PointMass(mass=ratio * beam.density * beam.area * beam.length,
                         position=position * beam.length)
        system = dataclasses.replace(self.system, masses=(mass,) if mass.mass > 0 else ())
        model = build_model(system, n_modes=self.n_modes, variant=self.variant)
        result = simulate(model, self.t_final, torque=self.torque,
                          output_step=self.output_step)
        peak, residual = response_amplitudes(result, self.torque.duration)
        return {"peak_amplitude": peak, "residual_amplitude": residual,
                "mass": mass.mass, "position": mass.position,
                "first_frequency": float(model.natural_frequencies(0.0, hub="free")[0]),
                "status": result.status}


@dataclass(frozen=True, kw_only=True)
class SceneTask:
    """Sweep task: run a scene with the point's values as overrides; summarise in numbers.

    Called as ``task(**{"maneuver.spin_rate": 2.0, "model.variant": "zero_order"})``: each
    parameter is a dotted scene key (:func:`flexctl.load_scene` overrides).

    Parameters
    ----------
    scene : str
        Built-in scene name or TOML file path.
    controller_factory : callable, optional
        For slew scenes: ``factory(scene, plant)`` returning an object with ``controller``
        and ``maneuver_end`` (``controllers.from_spec``).
    keep_result : bool
        Also return the :class:`~flexctl.SimulationResult` (column ``result``; it travels back
        from worker processes by pickling). Default False.

    Notes
    -----
    A call returns a dict: ``status``, ``verdict`` (the status, or ``"ok, loop unstable"``
    when the design's loop check finds the loop unstable on the plant:
    :func:`flexctl.app.verdict.run_verdict`), ``t_end`` (s), ``peak_tip_deflection`` (m),
    ``wall_time_s`` (s, design and simulation); for slews also the
    :class:`~flexctl.sim.metrics.SlewMetrics` fields and ``maneuver_end`` (s); ``result`` when
    ``keep_result``.
    """

    scene: str
    controller_factory: Callable | None = None
    keep_result: bool = False

    def __call__(self, **overrides) -> dict:
        from ..sim.maneuvers import Slew
        from ..sim.metrics import ERROR_METRICS
        from .scenes import SceneError, load_scene, run_scene, run_slew

        start = time.perf_counter()
        scene = load_scene(self.scene, overrides=overrides)
        out = {}
        if isinstance(scene.maneuver, Slew):
            if self.controller_factory is None:
                raise SceneError(f"scene {scene.name!r} is a slew: give SceneTask a "
                                 "controller_factory (controllers.from_spec)")
            result, built, metrics = run_slew(scene, self.controller_factory)
            out.update({k: v for k, v in dataclasses.asdict(metrics).items() if k != "errors"})
            for name in ERROR_METRICS:
                error = metrics.error(name)
                out[f"{name}_error"] = math.nan if error is None else error
                out[f"{name}_shown"] = metrics.shown(name)
            out["maneuver_end"] = float(built.maneuver_end)
            info = getattr(built, "info", None) or {}
            out["verdict"] = run_verdict(result.status, info.get("loop_stability"))
        else:
            result = run_scene(scene)
        out = {"status": result.status, "verdict": result.status, "t_end": float(result.t[-1]),
               "peak_tip_deflection": result.peak_tip_deflection, **out,
               "wall_time_s": time.perf_counter() - start}
        if self.keep_result:
            out["result"] = result
        return out
