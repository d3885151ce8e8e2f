"""Monte Carlo robustness of a flexible loop: dispersed beam stiffness, point masses, hub inertia.

A controller designed once on the nominal system meets plants whose Young's modulus, point
masses and hub inertia are off by random factors. :class:`Dispersion` draws the factors,
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

from flexctl.model import VARIANTS, HubBeam, build_model
from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.model.checks import check_real
from flexctl.sim.metrics import slew_metrics
from flexctl.sim.simulation import simulate

from .loops import loop_margins, loop_transfer
from ..feedback.lqg import LQG

__all__ = ["SCALES", "DISTRIBUTIONS", "Dispersion", "disperse", "RobustnessTask",
           "RobustnessSummary", "robustness_summary"]

#: The parameters of a sample: factors on Young's modulus, every point mass and the hub
#: inertia (1 is the nominal system).
SCALES = ("youngs_modulus_scale", "point_mass_scale", "hub_inertia_scale")
DISTRIBUTIONS = ("uniform", "normal")
#: Normal draws are clipped at this many standard deviations (a factor must stay positive).
NORMAL_CLIP = 3.0


@dataclass(frozen=True, kw_only=True)
class Dispersion:
    """Relative dispersion of the uncertain parameters.

    Parameters
    ----------
    youngs_modulus, point_mass, hub_inertia : float, optional
        Relative spread of each factor: the half-width of a uniform draw on
        ``[1 - d, 1 + d]``, or the standard deviation of a normal draw about 1 clipped at
        ``NORMAL_CLIP`` deviations. Defaults 0.1, 0.2 and 0.1. In ``[0, 1)`` for uniform,
        ``[0, 1/3)`` for normal (a factor must stay positive).
    distribution : {"uniform", "normal"}, optional
        Default ``"uniform"``.
    """

    youngs_modulus: float = 0.1
    point_mass: float = 0.2
    hub_inertia: float = 0.1
    distribution: str = "uniform"

    def __post_init__(self):
        if self.distribution not in DISTRIBUTIONS:
            raise InputValueError(f"dispersion.distribution must be one of "
                                  f"{', '.join(DISTRIBUTIONS)}; got {self.distribution!r}")
        limit = 1.0 if self.distribution == "uniform" else 1.0 / NORMAL_CLIP
        for name in ("youngs_modulus", "point_mass", "hub_inertia"):
            value = check_real("dispersion", name, getattr(self, name), minimum=0.0)
            if value >= limit:
                raise InputValueError(f"dispersion.{name} must be < {limit:.4g} for a "
                                      f"{self.distribution} draw (the factor must stay "
                                      f"positive); got {value!r}")
            object.__setattr__(self, name, value)

    def samples(self, n_samples: int, seed: int = 0) -> list:
        """``n_samples`` draws of the factors :data:`SCALES`, as sweep points.

        Parameters
        ----------
        n_samples : int
            >= 1.
        seed : int, optional
            Seed of :func:`numpy.random.default_rng`. Default 0.

        Returns
        -------
        list of dict
            ``{"youngs_modulus_scale": ..., "point_mass_scale": ..., "hub_inertia_scale":
            ...}`` (Python floats), a point list for :func:`flexctl.app.sweep.sweep`.
        """
        if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) \
                or n_samples < 1:
            raise InputValueError(f"dispersion.samples n_samples must be an integer >= 1; got "
                                  f"{n_samples!r}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputValueError(f"dispersion.samples seed must be an integer >= 0; got "
                                  f"{seed!r}")
        return self._factors(np.random.default_rng(int(seed)), int(n_samples))

    def draw(self, seed: int) -> dict:
        """One draw of the factors :data:`SCALES` from its own seed.

        The draw of a Monte Carlo sample that a sweep seeds by the sample's key
        (:class:`RobustnessTask` with a ``dispersion``): it depends on ``seed`` alone, not on
        how many samples there are or in which order they run.

        Parameters
        ----------
        seed : int
            Seed of :func:`numpy.random.default_rng`, >= 0.

        Returns
        -------
        dict
            ``{"youngs_modulus_scale": ..., "point_mass_scale": ..., "hub_inertia_scale":
            ...}`` (Python floats).
        """
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputValueError(f"dispersion.draw seed must be an integer >= 0; got "
                                  f"{seed!r}")
        return self._factors(np.random.default_rng(int(seed)), 1)[0]

    def _factors(self, rng, n_samples: int) -> list:
        """``n_samples`` draws from ``rng``, as dicts of :data:`SCALES`."""
        spread = np.array([self.youngs_modulus, self.point_mass, self.hub_inertia])
        if self.distribution == "uniform":
            unit = rng.uniform(-1.0, 1.0, (n_samples, 3))
        else:
            unit = np.clip(rng.standard_normal((n_samples, 3)), -NORMAL_CLIP, NORMAL_CLIP)
        factors = 1.0 + unit * spread
        return [dict(zip(SCALES, map(float, row))) for row in factors]


def disperse(system, *, youngs_modulus_scale: float = 1.0, point_mass_scale: float = 1.0,
             hub_inertia_scale: float = 1.0) -> HubBeam:
    """The system with its Young's modulus, point masses and hub inertia scaled.

    Parameters
    ----------
    system : HubBeam
        The nominal hub-beam-mass system.
    youngs_modulus_scale : float, optional
        Factor on ``beam.youngs_modulus`` (> 0): the bending stiffness.
    point_mass_scale : float, optional
        Factor on every point mass (>= 0).
    hub_inertia_scale : float, optional
        Factor on ``hub.inertia`` (>= 0).

    Returns
    -------
    HubBeam
        Validated like any other (a factor that leaves the physical range raises its error).
    """
    if not isinstance(system, HubBeam):
        raise InputTypeError(f"disperse.system must be a HubBeam; got {type(system).__name__}")
    e = check_real("disperse", "youngs_modulus_scale", youngs_modulus_scale, minimum=0.0,
                   strict=True)
    m = check_real("disperse", "point_mass_scale", point_mass_scale, minimum=0.0)
    j = check_real("disperse", "hub_inertia_scale", hub_inertia_scale, minimum=0.0)
    beam = dataclasses.replace(system.beam, youngs_modulus=e * system.beam.youngs_modulus)
    hub = dataclasses.replace(system.hub, inertia=j * system.hub.inertia)
    masses = tuple(dataclasses.replace(mass, mass=m * mass.mass) for mass in system.masses)
    return dataclasses.replace(system, hub=hub, beam=beam, masses=masses)


def _slew_reference(controller):
    """``(angle, end)`` of a controller's slew reference (rad, s), or None without one."""
    reference = getattr(controller, "reference", None)
    if reference is None or not hasattr(reference, "slew_angle"):
        return None
    return float(reference.slew_angle), float(reference.start_time + reference.duration)


def _worst_pole(model, loop, spin_rate: float):
    """The closed loop's least damped pole, named by the plant mode it lies on."""
    import control

    from ..design.stability import least_damped_pole

    return least_damped_pole(model, control.feedback(loop).A, spin_rate)


@dataclass(frozen=True, kw_only=True, eq=False)
class RobustnessTask:
    """Sweep task: a fixed controller on one dispersed plant, judged by its loop.

    Called as ``task(youngs_modulus_scale=..., point_mass_scale=..., hub_inertia_scale=...)``
    (:data:`SCALES`, each default 1), or with a ``dispersion`` as ``task(sample=k, seed=s)``
    (the factors drawn from ``s``): builds the dispersed plant (:func:`disperse`), its loop
    with the controller (:func:`~controllers.analysis.loops.loop_transfer`) and the margins
    (:func:`~controllers.analysis.loops.loop_margins`); with ``slew_time``, also flies the
    controller's slew on the nonlinear plant.

    Parameters
    ----------
    system : HubBeam
        The nominal system.
    controller : object
        Any controller :func:`~controllers.analysis.loops.loop_transfer` takes, designed on the
        nominal system (an LQG reads the dispersed plant's sensors).
    n_modes : int, optional
        Modes of the plant. Default 4.
    variant : str, optional
        Model variant. Default ``"first_order"`` (every variant linearises to its stiffness;
        the variant matters for the slew only).
    spin_rate : float, optional
        Steady hub rate of the linearisation, rad/s. Default 0.
    sensor : str, optional
        For a PD law (:data:`~controllers.analysis.loops.SENSORS`).
    slew_time : float, optional
        Simulated time of the slew, s (> the reference's end); needs a controller with a slew
        reference (:class:`~controllers.slew.reference.SlewProfile`). Default: no simulation.
    dispersion : Dispersion, optional
        Draw the factors of each call from its ``seed`` (:meth:`Dispersion.draw`): a Monte
        Carlo study is then a sweep over ``{"sample": range(n)}``, each sample seeded by the
        sweep from its key, so that a resumed or redistributed study gives the same rows.
        Default: the factors are the call's arguments.

    Notes
    -----
    A call returns a dict: the factors :data:`SCALES`, the
    :class:`~controllers.analysis.loops.LoopMargins` fields,
    ``first_frequency`` (lowest hub-free flexible frequency, rad/s) and, with ``slew_time``,
    ``status`` and the :class:`~flexctl.sim.metrics.SlewMetrics` fields.
    """

    system: HubBeam
    controller: object
    n_modes: int = 4
    variant: str = "first_order"
    spin_rate: float = 0.0
    sensor: str | None = None
    slew_time: float | None = None
    dispersion: Dispersion | None = None

    def __post_init__(self):
        if self.dispersion is not None and not isinstance(self.dispersion, Dispersion):
            raise InputTypeError(f"robustness_task.dispersion must be a Dispersion; got "
                                 f"{type(self.dispersion).__name__}")
        if not isinstance(self.system, HubBeam):
            raise InputTypeError(f"robustness_task.system must be a HubBeam; got "
                                 f"{type(self.system).__name__}")
        if isinstance(self.n_modes, bool) or not isinstance(self.n_modes, (int, np.integer)) \
                or not 1 <= self.n_modes <= 200:
            raise InputValueError(f"robustness_task.n_modes must be an integer in [1, 200]; "
                                  f"got {self.n_modes!r}")
        if self.variant not in VARIANTS:
            raise InputValueError(f"robustness_task.variant must be one of "
                                  f"{', '.join(VARIANTS)}; got {self.variant!r}")
        object.__setattr__(self, "spin_rate",
                           check_real("robustness_task", "spin_rate", self.spin_rate))
        # the nominal loop: a controller, sensor or mode count the analysis cannot take
        # fails here, once, rather than at every sample
        loop_transfer(build_model(self.system, self.n_modes), self.controller, self.spin_rate,
                      sensor=self.sensor)
        if self.slew_time is not None:
            reference = _slew_reference(self.controller)
            if reference is None:
                raise InputValueError("robustness_task.slew_time needs a controller with a "
                                      "slew reference (a SlewProfile); got "
                                      f"{type(self.controller).__name__} without one")
            object.__setattr__(self, "slew_time", check_real(
                "robustness_task", "slew_time", self.slew_time, minimum=reference[1],
                strict=True))

    def __call__(self, youngs_modulus_scale: float | None = None,
                 point_mass_scale: float | None = None, hub_inertia_scale: float | None = None,
                 *, sample: int | None = None, seed: int | None = None) -> dict:
        scales = self._scales(youngs_modulus_scale, point_mass_scale, hub_inertia_scale,
                              sample, seed)
        youngs_modulus_scale, point_mass_scale, hub_inertia_scale = scales
        system = disperse(self.system, youngs_modulus_scale=youngs_modulus_scale,
                          point_mass_scale=point_mass_scale,
                          hub_inertia_scale=hub_inertia_scale)
        model = build_model(system, self.n_modes, self.variant)
        loop = loop_transfer(model, self.controller, self.spin_rate, sensor=self.sensor)
        worst = _worst_pole(model, loop, self.spin_rate)
        row = {"youngs_modulus_scale": float(youngs_modulus_scale),
               "point_mass_scale": float(point_mass_scale),
               "hub_inertia_scale": float(hub_inertia_scale), **loop_margins(loop).as_dict(),
               "worst_mode": worst.mode, "worst_mode_frequency": worst.frequency,
               "worst_growth_rate": worst.growth_rate}
        row["first_frequency"] = float(model.natural_frequencies(self.spin_rate, "free")[0])
        if self.slew_time is not None:
            controller = self.controller
            if isinstance(controller, LQG):
                controller = controller.for_plant(model)
            result = simulate(model, self.slew_time, controller=controller)
            angle, end = _slew_reference(self.controller)
            row["status"] = result.status
            row.update(dataclasses.asdict(slew_metrics(result, angle, end)))
        return row

    def _scales(self, youngs_modulus_scale, point_mass_scale, hub_inertia_scale, sample,
                seed) -> tuple:
        """The factors of a call: given (default 1), or drawn by the dispersion from the
        seed of a Monte Carlo sample."""
        given = (youngs_modulus_scale, point_mass_scale, hub_inertia_scale)
        if self.dispersion is None:
            if sample is not None:
                raise InputValueError(f"robustness_task sample={sample!r} needs a dispersion "
                                      "to draw it from; got dispersion=None")
            return tuple(1.0 if v is None else v for v in given)
        if seed is None or any(v is not None for v in given):
            raise InputValueError("robustness_task with a dispersion draws its factors from "
                                  "the seed a sweep gives each sample: call it as "
                                  f"task(sample=k, seed=s); got seed={seed!r}, factors "
                                  f"{given!r}")
        drawn = self.dispersion.draw(seed)
        return tuple(drawn[name] for name in SCALES)


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
    """

    n_samples: int
    n_stable: int
    stable_fraction: float
    worst_gain_margin: float
    worst_phase_margin: float
    worst_stability_margin: float
    worst_spectral_abscissa: float

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
    needed = ("closed_loop_stable", "gain_margin", "phase_margin", "stability_margin",
              "spectral_abscissa")
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
        values = [transform(row[name]) for row in stable]
        return min(values) if values else math.nan

    return RobustnessSummary(
        n_samples=len(rows), n_stable=len(stable), stable_fraction=len(stable) / len(rows),
        worst_gain_margin=worst("gain_margin"),
        worst_phase_margin=worst("phase_margin", lambda v: abs(float(v))),
        worst_stability_margin=worst("stability_margin"),
        worst_spectral_abscissa=max(float(row["spectral_abscissa"]) for row in rows))
