"""Monte Carlo robustness of a flexible loop: dispersed beam stiffness, point masses, hub inertia.

A controller designed once on the nominal system meets plants whose Young's modulus, point
masses and hub inertia are off by random factors, for the whole structure or appendage by
appendage. :class:`Dispersion` (:mod:`.dispersion`) draws the factors,
:class:`RobustnessTask` judges the loop on one dispersed plant (stability and margins from
:mod:`controllers.analysis.loops`, optionally the slew it flies on the nonlinear plant), and
:func:`robustness_summary` condenses the rows. The task is a picklable frozen dataclass, so
the samples run through :func:`flexctl.app.sweep.sweep` on any ``concurrent.futures``-style
executor, a Dask cluster's included. Given a dispersion, the task draws each sample's factors
from the seed the sweep derives from the sample's key, so a study kept in a store resumes after
a crash, or grows from 200 to 400 samples, with exactly the rows of one uninterrupted run::

    dispersion = Dispersion(youngs_modulus=0.1, point_mass=0.2, hub_inertia=0.1)
    task = RobustnessTask(system=system, controller=lqr, dispersion=dispersion)
    table = sweep(task, {"sample": range(200)}, executor=executor, seed=1,
                  store="robustness.sqlite", resume=True)
    summary = robustness_summary(table)

A slew scene's study (:meth:`RobustnessTask.from_scene`) designs the scene's controller once,
estimator included, and flies it on each dispersed plant with the scene's actuator and
sensors; the summary gives the spread of each metric (:func:`spread_statistics`).

Examples
--------
>>> import flexctl
>>> from controllers import design_pd
>>> system = flexctl.load_scene("slew-90").system
>>> pd = design_pd(flexctl.build_model(system, 2), bandwidth=2.0, damping_ratio=0.9)
>>> task = RobustnessTask(system=system, controller=pd, n_modes=3)
>>> rows = [task(**sample) for sample in Dispersion().samples(3, seed=1)]
>>> summary = robustness_summary(rows)
>>> summary.n_samples, summary.stable_fraction, summary.worst_gain_margin
(3, 1.0, inf)
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from flexctl.model import VARIANTS, HubBeam, Structure, build_model
from flexctl.model.checks import check_real
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.metrics import slew_metrics
from flexctl.sim.simulation import simulate

from .dispersion import (APPENDAGE_PARAMETERS, DISTRIBUTIONS, NORMAL_CLIP, SCALES, Dispersion,
                         disperse)
from .loops import LoopMargins, loop_margins, loop_transfer
from ..design.stability import check_loop
from ..feedback.lqg import LQG

__all__ = ["SCALES", "APPENDAGE_PARAMETERS", "DISTRIBUTIONS", "Dispersion", "disperse",
           "RobustnessTask", "RobustnessSummary", "robustness_summary", "spread_statistics",
           "SPREAD_COLUMNS", "NORMAL_CLIP"]


def _slew_reference(controller):
    """``(angle, end)`` of a controller's slew reference (rad, s), or None without one."""
    reference = getattr(controller, "reference", None)
    if reference is None or not hasattr(reference, "slew_angle"):
        return None
    return float(reference.slew_angle), float(reference.start_time + reference.duration)


def _worst_pole(model, loop, spin_rate: float):
    """The closed loop's least damped pole, named by the plant mode it lies on (a sampled
    loop's as a rate, ``log(z) / T``)."""
    import control

    from ..design.stability import least_damped_pole

    sample_time = None if loop.isctime() else float(loop.dt)
    return least_damped_pole(model, control.feedback(loop).A, spin_rate, sample_time)


@dataclass(frozen=True, kw_only=True, eq=False)
class RobustnessTask:
    """Sweep task: a fixed controller on one dispersed plant, judged by its loop.

    Called as ``task(youngs_modulus_scale=..., point_mass_scale=..., hub_inertia_scale=...)``
    (:data:`SCALES`, each default 1), or with a ``dispersion`` as ``task(sample=k, seed=s)``
    (the factors drawn from ``s``): builds the dispersed plant (:func:`disperse`), its loop
    with the controller (:func:`~controllers.analysis.loops.loop_transfer`) and the margins
    (:func:`~controllers.analysis.loops.loop_margins`); with ``slew_time``, also flies the
    controller's slew on the nonlinear plant. The controller is the one given, designed
    once: an observed law (:class:`~controllers.Observed`) built with a ``model`` keeps its
    nominal Kalman filter on every dispersed plant, as a flight computer would.

    Parameters
    ----------
    system : HubBeam or Structure
        The nominal system.
    controller : object
        Any controller :func:`~controllers.analysis.loops.loop_transfer` takes (an observed
        law's loop as it flies, sampled and through its filter), or else any
        :func:`~controllers.check_loop` takes (its loop then judged by
        :func:`~controllers.check_loop`, margins NaN), designed on the nominal system (an
        LQG reads the dispersed plant's sensors).
    n_modes : int, dict or sequence of int, optional
        Modes of the plant, as :func:`flexctl.build_model` takes them. Default 4.
    variant : str, optional
        Model variant. Default ``"first_order"`` (every variant linearises to its stiffness;
        the variant matters for the slew only).
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.
    sensor : str, optional
        For a PD law (:data:`~controllers.analysis.loops.SENSORS`).
    slew_time : float, optional
        Simulated time of the slew, s (> the reference's end); needs a controller with a slew
        reference (:class:`~controllers.slew.reference.SlewProfile`) or ``slew``. Default: no
        simulation.
    dispersion : Dispersion, optional
        Draw the factors of each call from its ``seed`` (:meth:`Dispersion.draw`): a Monte
        Carlo study is then a sweep over ``{"sample": range(n)}``, each sample seeded by the
        sweep from its key, so that a resumed or redistributed study gives the same rows.
        Default: the factors are the call's arguments.
    actuator : ReactionWheel or DCMotor, optional
        The plant's actuator (:func:`flexctl.build_model`); the controller then commands it.
        Default: an ideal hub torque.
    slew : tuple of float, optional
        ``(angle, end)``: the slew's angle (rad) and the time its residual vibration is
        measured from (s), for a controller whose reference is not a SlewProfile (a
        :class:`~controllers.BuiltController`'s ``maneuver_end``). Default: the reference's.

    Notes
    -----
    A call returns a dict: the factors (:attr:`Dispersion.factor_names`), the
    :class:`~controllers.analysis.loops.LoopMargins` fields,
    ``first_frequency`` (lowest hub-free flexible frequency, rad/s) and, with ``slew_time``,
    ``status`` and the :class:`~flexctl.sim.metrics.SlewMetrics` fields.
    """

    system: HubBeam | Structure
    controller: object
    n_modes: object = 4
    variant: str = "first_order"
    spin_rate: float = 0.0
    sensor: str | None = None
    slew_time: float | None = None
    dispersion: Dispersion | None = None
    actuator: object = None
    slew: tuple | None = None

    def __post_init__(self):
        if self.dispersion is not None and not isinstance(self.dispersion, Dispersion):
            raise InputTypeError(f"robustness_task.dispersion must be a Dispersion; got "
                                 f"{type(self.dispersion).__name__}")
        if not isinstance(self.system, (HubBeam, Structure)):
            raise InputTypeError(f"robustness_task.system must be a HubBeam or a Structure; "
                                 f"got {type(self.system).__name__}")
        if isinstance(self.n_modes, bool) or (isinstance(self.n_modes, (int, np.integer))
                                              and not 1 <= self.n_modes <= 200):
            raise InputValueError(f"robustness_task.n_modes must be an integer in [1, 200]; "
                                  f"got {self.n_modes!r}")
        if self.variant not in VARIANTS:
            raise InputValueError(f"robustness_task.variant must be one of "
                                  f"{', '.join(VARIANTS)}; got {self.variant!r}")
        object.__setattr__(self, "spin_rate",
                           check_real("robustness_task", "spin_rate", self.spin_rate))
        # the nominal loop: a controller, sensor or mode count the analysis cannot take
        # fails here, once, rather than at every sample
        nominal = self._model(self.system)
        object.__setattr__(self, "_by_transfer", True)
        try:
            self._loop_row(nominal)
        except InputTypeError as exc:
            # a law with no linear loop transfer (a DC motor's voltage, an NMPC behind a
            # filter) is judged by check_loop, when check_loop takes it
            object.__setattr__(self, "_by_transfer", False)
            try:
                self._loop_row(nominal)
            except InputTypeError:
                raise exc from None
        if self.slew_time is not None:
            reference = self._slew_reference()
            if reference is None:
                raise InputValueError("robustness_task.slew_time needs a controller with a "
                                      "slew reference (a SlewProfile) or slew=(angle, end); "
                                      f"got {type(self.controller).__name__} without one")
            object.__setattr__(self, "slew_time", check_real(
                "robustness_task", "slew_time", self.slew_time, minimum=reference[1],
                strict=True))

    @classmethod
    def from_scene(cls, scene, controller_factory,
                   dispersion: Dispersion | None = None) -> "RobustnessTask":
        """The Monte Carlo of a slew scene: its controller designed once on the nominal
        scene (estimator included) and flown, to the scene's final time, on each dispersed
        plant with the scene's actuator and sensors.

        Parameters
        ----------
        scene : flexctl.Scene
            A slew scene with a ``[controller]`` table (and ``[actuator]``, ``[sensors]`` if
            it has them).
        controller_factory : callable
            ``factory(scene, plant)`` returning a :class:`~controllers.BuiltController`
            (:func:`controllers.from_spec`). Called once, on the nominal plant.
        dispersion : Dispersion, optional
            The factors' spreads; default :class:`Dispersion` ``()``.

        Returns
        -------
        RobustnessTask
            Its ``controller`` is the nominal design; call it as ``task(sample=k, seed=s)``
            or sweep it over ``{"sample": range(n)}``.
        """
        plant = scene.build_model()
        built = controller_factory(scene, plant)
        return cls(system=scene.system, controller=built.controller,
                   n_modes=getattr(plant, "mode_spec", plant.n_modes),
                   variant=scene.variant, slew_time=scene.simulation.t_final,
                   dispersion=Dispersion() if dispersion is None else dispersion,
                   actuator=scene.actuator,
                   slew=(float(scene.maneuver.angle), float(built.maneuver_end)))

    def _model(self, system):
        hardware = {} if self.actuator is None else {"actuator": self.actuator}
        return build_model(system, self.n_modes, self.variant, **hardware)

    def _slew_reference(self):
        return self.slew if self.slew is not None else _slew_reference(self.controller)

    def _loop_row(self, model) -> dict:
        """The loop's margins and least damped pole on ``model``: by its transfer function
        when the analysis takes the law, else by :func:`~controllers.check_loop`."""
        if self._by_transfer:
            loop = loop_transfer(model, self.controller, self.spin_rate, sensor=self.sensor)
            worst = _worst_pole(model, loop, self.spin_rate)
            return {**loop_margins(loop).as_dict(), "worst_mode": worst.mode,
                    "worst_mode_frequency": worst.frequency,
                    "worst_growth_rate": worst.growth_rate}
        check = check_loop(model, self.controller, self.spin_rate)
        margins = dict.fromkeys((f.name for f in dataclasses.fields(LoopMargins)
                                 if f.name != "crossings"), math.nan)
        found = check.as_dict()
        return {**margins, **{key: found[key] for key in (
            "closed_loop_stable", "spectral_abscissa", "worst_mode", "worst_mode_frequency",
            "worst_growth_rate")}}

    def __call__(self, youngs_modulus_scale: float | None = None,
                 point_mass_scale: float | None = None, hub_inertia_scale: float | None = None,
                 *, sample: int | None = None, seed: int | None = None,
                 appendage_scales: dict | None = None) -> dict:
        """One dispersed plant judged (class Notes).

        Parameters
        ----------
        youngs_modulus_scale, point_mass_scale, hub_inertia_scale : float, optional
            The factors, without a dispersion (default 1 each).
        sample : int, optional
            The Monte Carlo sample's number (with a dispersion); not read otherwise.
        seed : int, optional
            The seed its factors are drawn from (with a dispersion).
        appendage_scales : dict, optional
            Without a dispersion: single appendages' factors, as :func:`disperse` takes
            them (``{"wing_b": {"youngs_modulus_scale": 0.8}}``); in the row as
            ``"wing_b.youngs_modulus_scale"``. Default none.
        """
        factors = self._factors(youngs_modulus_scale, point_mass_scale, hub_inertia_scale,
                                sample, seed)
        if appendage_scales:
            if self.dispersion is not None:
                raise InputValueError("robustness_task appendage_scales are given without a "
                                      "dispersion (with one, the draw gives them); got "
                                      f"{appendage_scales!r}")
            factors.update({f"{app}.{name}": float(value)
                            for app, scales in appendage_scales.items()
                            for name, value in scales.items()})
        own = {}
        for name, value in factors.items():
            if name not in SCALES:
                app, scale = name.rsplit(".", 1)
                own.setdefault(app, {})[scale] = value
        system = disperse(self.system, **{n: factors[n] for n in SCALES},
                          appendage_scales=own)
        model = self._model(system)
        row = {**factors, **self._loop_row(model)}
        row["first_frequency"] = float(model.natural_frequencies(self.spin_rate, "free")[0])
        if self.slew_time is not None:
            row.update(self._flown(model))
        return row

    def _flown(self, model) -> dict:
        """Status and slew metrics of the controller flown on ``model``."""
        controller, drive = self.controller, {}
        if isinstance(controller, LQG):
            controller = controller.for_plant(model)
        if getattr(controller, "measures", False):
            drive["sensors"] = controller.sensors
        result = simulate(model, self.slew_time, controller=controller, **drive)
        angle, end = self._slew_reference()
        metrics = dataclasses.asdict(slew_metrics(result, angle, end))
        metrics.pop("errors", None)
        return {"status": result.status, **metrics}

    def _factors(self, youngs_modulus_scale, point_mass_scale, hub_inertia_scale, sample,
                 seed) -> dict:
        """The factors of a call: given (default 1), or drawn by the dispersion from the
        seed of a Monte Carlo sample."""
        given = (youngs_modulus_scale, point_mass_scale, hub_inertia_scale)
        if self.dispersion is None:
            if sample is not None:
                raise InputValueError(f"robustness_task sample={sample!r} needs a dispersion "
                                      "to draw it from; got dispersion=None")
            return {name: float(1.0 if v is None else v) for name, v in zip(SCALES, given)}
        if seed is None or any(v is not None for v in given):
            raise InputValueError("robustness_task with a dispersion draws its factors from "
                                  "the seed a sweep gives each sample: call it as "
                                  f"task(sample=k, seed=s); got seed={seed!r}, factors "
                                  f"{given!r}")
        return self.dispersion.draw(seed)


@dataclass(frozen=True, kw_only=True)
class RobustnessSummary:
    """A Monte Carlo robustness study in a few numbers (:func:`robustness_summary`).

    Attributes
    ----------
    n_samples : int
    n_stable : int
        Samples whose closed loop is stable.
    stable_fraction : float
        ``n_stable / n_samples``.
    worst_gain_margin : float
        Smallest upward gain margin over the stable samples (``inf`` if none is finite; NaN
        without stable samples).
    worst_phase_margin : float
        Smallest ``|phase margin|`` over the stable samples, deg.
    worst_stability_margin : float
        Smallest ``min |1 + L|`` over the stable samples.
    worst_spectral_abscissa : float
        Largest closed-loop pole real part over all samples, 1/s.
    spread : dict
        ``{column: {"n", "mean", "std", "min", "p05", "median", "p95", "max"}}`` over all
        samples' finite values of each column of :data:`SPREAD_COLUMNS` the rows hold (in
        the column's unit; ``std`` the sample standard deviation, 0 for one value).
    """

    n_samples: int
    n_stable: int
    stable_fraction: float
    worst_gain_margin: float
    worst_phase_margin: float
    worst_stability_margin: float
    worst_spectral_abscissa: float
    spread: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if not 0 <= self.n_stable <= self.n_samples or self.n_samples < 1:
            raise InputValueError(f"robustness_summary.n_stable must lie in [0, n_samples = "
                                  f"{self.n_samples}] with n_samples >= 1; got "
                                  f"{self.n_stable!r}")


def _rows(table) -> list:
    rows = getattr(table, "rows", table)        # a SweepResult holds its rows
    if isinstance(rows, (str, bytes)) or not isinstance(rows, Sequence):
        raise InputTypeError("robustness_summary.table must be a SweepResult or a sequence "
                             f"of row dicts; got {type(table).__name__}")
    rows = list(rows)
    needed = ("closed_loop_stable", "spectral_abscissa")
    for k, row in enumerate(rows):
        if isinstance(row, Mapping) and "failure" in row:
            raise InputValueError(f"robustness_summary.table row {k} is a failed sample "
                                  f"({row['failure']}): summarise table.without_failures() "
                                  "and report the failures apart")
        if not isinstance(row, Mapping) or any(name not in row for name in needed):
            raise InputValueError(f"robustness_summary.table row {k} must hold the columns "
                                  f"{', '.join(needed)} (a RobustnessTask row); got {row!r}")
    if not rows:
        raise InputValueError("robustness_summary.table must hold at least one row; got none")
    return rows


def robustness_summary(table) -> RobustnessSummary:
    """Summarise the rows of a :class:`RobustnessTask` sweep.

    Parameters
    ----------
    table : SweepResult or sequence of dict
        Rows with the :class:`~controllers.analysis.loops.LoopMargins` columns.

    Returns
    -------
    RobustnessSummary
    """
    rows = _rows(table)
    stable = [row for row in rows if row["closed_loop_stable"]]

    def worst(name, transform=float):
        values = [transform(row[name]) for row in stable
                  if not math.isnan(row.get(name, math.nan))]
        return min(values) if values else math.nan

    return RobustnessSummary(
        n_samples=len(rows), n_stable=len(stable), stable_fraction=len(stable) / len(rows),
        worst_gain_margin=worst("gain_margin"),
        worst_phase_margin=worst("phase_margin", lambda v: abs(float(v))),
        worst_stability_margin=worst("stability_margin"),
        worst_spectral_abscissa=max(float(row["spectral_abscissa"]) for row in rows),
        spread=spread_statistics(rows))


#: Columns of a robustness row whose spread :func:`spread_statistics` gives, when present.
SPREAD_COLUMNS = ("spectral_abscissa", "gain_margin", "phase_margin", "stability_margin",
                  "first_frequency", "settling_time", "overshoot", "final_error",
                  "peak_torque", "peak_tip_deflection", "residual_vibration")


def spread_statistics(rows, columns=SPREAD_COLUMNS) -> dict:
    """Spread of each column over the rows: count, mean, standard deviation, extremes and
    percentiles of its finite values.

    Parameters
    ----------
    rows : sequence of dict
        The rows of a study (a :class:`RobustnessTask` sweep's).
    columns : sequence of str, optional
        The columns summarised; those no row holds a finite number of are left out.
        Default :data:`SPREAD_COLUMNS`.

    Returns
    -------
    dict
        ``{column: {"n", "mean", "std", "min", "p05", "median", "p95", "max"}}``, Python
        numbers in the column's unit (``std`` with one degree of freedom removed; 0 for a
        single value).
    """
    out = {}
    for name in columns:
        values = np.array([float(row[name]) for row in rows
                           if isinstance(row.get(name), (int, float, np.floating))
                           and not isinstance(row.get(name), bool)], dtype=float)
        values = values[np.isfinite(values)]
        if not values.size:
            continue
        p05, median, p95 = np.percentile(values, [5.0, 50.0, 95.0])
        out[name] = {"n": int(values.size), "mean": float(values.mean()),
                     "std": float(values.std(ddof=1)) if values.size > 1 else 0.0,
                     "min": float(values.min()), "p05": float(p05), "median": float(median),
                     "p95": float(p95), "max": float(values.max())}
    return out
