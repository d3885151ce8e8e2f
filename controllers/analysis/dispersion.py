"""Dispersed systems for Monte Carlo studies: the spreads of the uncertain parameters, their
draws, and the system a draw gives.

:class:`Dispersion` holds the relative spreads (Young's modulus, point masses, hub inertia,
and, per appendage of a structure, its own stiffness and masses) and draws the factors of a
sample from its own seed; :func:`disperse` applies factors to a
:class:`~flexctl.model.HubBeam` or a :class:`~flexctl.model.Structure`.
:mod:`controllers.analysis.robustness` flies a design on the systems they give.

Examples
--------
>>> import flexctl
>>> system = flexctl.load_scene("two-array-slew").system
>>> dispersion = Dispersion(youngs_modulus=0.1, appendages={"wing_b": {"youngs_modulus": 0.3}})
>>> factors = dispersion.draw(seed=3)
>>> sorted(factors)
['hub_inertia_scale', 'point_mass_scale', 'wing_b.youngs_modulus_scale', 'youngs_modulus_scale']
>>> dispersed = disperse(system, appendage_scales={"wing_b": {"youngs_modulus_scale": 0.5}})
>>> dispersed.appendages[1].beam.youngs_modulus / system.appendages[1].beam.youngs_modulus
0.5
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from flexctl.model import HubBeam, Structure
from flexctl.model.checks import check_real
from flexctl.model.errors import InputTypeError, InputValueError

__all__ = ["SCALES", "APPENDAGE_PARAMETERS", "DISTRIBUTIONS", "NORMAL_CLIP", "Dispersion",
           "disperse"]

#: The parameters of a sample: factors on Young's modulus, every point mass and the hub
#: inertia (1 is the nominal system).
SCALES = ("youngs_modulus_scale", "point_mass_scale", "hub_inertia_scale")
#: The parameters an appendage may be dispersed in on its own (:attr:`Dispersion.appendages`).
APPENDAGE_PARAMETERS = ("youngs_modulus", "point_mass")
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
    appendages : dict, optional
        Appendages of a :class:`~flexctl.model.Structure` dispersed on their own:
        ``{name: {"youngs_modulus": d, "point_mass": d}}`` (either key or both), each
        parameter listed drawn independently with its own spread ``d`` (same rule as
        above), as the factor ``"<name>.youngs_modulus_scale"`` or
        ``"<name>.point_mass_scale"`` of a sample; the parameters and appendages not
        listed take the common factor. Default: every appendage takes the common factors.
    """

    youngs_modulus: float = 0.1
    point_mass: float = 0.2
    hub_inertia: float = 0.1
    distribution: str = "uniform"
    appendages: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if self.distribution not in DISTRIBUTIONS:
            raise InputValueError(f"dispersion.distribution must be one of "
                                  f"{', '.join(DISTRIBUTIONS)}; got {self.distribution!r}")
        for name in ("youngs_modulus", "point_mass", "hub_inertia"):
            object.__setattr__(self, name, self._spread(name, getattr(self, name)))
        if not isinstance(self.appendages, Mapping):
            raise InputTypeError("dispersion.appendages must be a dict {name: {parameter: "
                                 f"spread}}; got {type(self.appendages).__name__}")
        own = {}
        for app, spreads in self.appendages.items():
            if not isinstance(app, str) or not isinstance(spreads, Mapping) or not spreads:
                raise InputValueError(f"dispersion.appendages[{app!r}] must be a non-empty "
                                      "dict {parameter: spread} under an appendage's name; "
                                      f"got {spreads!r}")
            for name in spreads:
                if name not in APPENDAGE_PARAMETERS:
                    raise InputValueError(f"dispersion.appendages[{app!r}] parameter must be "
                                          f"one of {', '.join(APPENDAGE_PARAMETERS)}; got "
                                          f"{name!r}")
            own[app] = {name: self._spread(f"appendages[{app!r}].{name}", spreads[name])
                        for name in APPENDAGE_PARAMETERS if name in spreads}
        object.__setattr__(self, "appendages", own)

    def _spread(self, name: str, value) -> float:
        """``value`` checked as the spread called ``name`` of this distribution."""
        limit = 1.0 if self.distribution == "uniform" else 1.0 / NORMAL_CLIP
        value = check_real("dispersion", name, value, minimum=0.0)
        if value >= limit:
            raise InputValueError(f"dispersion.{name} must be < {limit:.4g} for a "
                                  f"{self.distribution} draw (the factor must stay "
                                  f"positive); got {value!r}")
        return value

    @property
    def factor_names(self) -> tuple:
        """Names of a sample's factors: :data:`SCALES`, then ``"<name>.<parameter>_scale"``
        for each appendage dispersed on its own."""
        return SCALES + tuple(f"{app}.{name}_scale" for app, spreads in
                              self.appendages.items() for name in spreads)

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
        # the common factors are drawn first, so a dispersion without per-appendage spreads
        # draws what it always drew
        factors = self._unit(rng, n_samples, 3) * np.array(
            [self.youngs_modulus, self.point_mass, self.hub_inertia]) + 1.0
        own = [spread for spreads in self.appendages.values() for spread in spreads.values()]
        if own:
            factors = np.hstack((factors, 1.0 + self._unit(rng, n_samples, len(own))
                                 * np.array(own)))
        return [dict(zip(self.factor_names, map(float, row))) for row in factors]

    def _unit(self, rng, n_samples: int, n_factors: int) -> np.ndarray:
        """Draws of zero mean and unit spread, shape (n_samples, n_factors)."""
        if self.distribution == "uniform":
            return rng.uniform(-1.0, 1.0, (n_samples, n_factors))
        return np.clip(rng.standard_normal((n_samples, n_factors)), -NORMAL_CLIP, NORMAL_CLIP)


def disperse(system, *, youngs_modulus_scale: float = 1.0, point_mass_scale: float = 1.0,
             hub_inertia_scale: float = 1.0, appendage_scales: Mapping | None = None):
    """The system with its Young's modulus, point masses and hub inertia scaled.

    Parameters
    ----------
    system : HubBeam or Structure
        The nominal system: one beam on a hub, or any structure of appendages.
    youngs_modulus_scale : float, optional
        Factor on every beam's ``youngs_modulus`` (> 0): the bending stiffness.
    point_mass_scale : float, optional
        Factor on every point mass (>= 0).
    hub_inertia_scale : float, optional
        Factor on ``hub.inertia`` (>= 0).
    appendage_scales : dict, optional
        Factors of single appendages of a Structure, ``{name: {"youngs_modulus_scale": f,
        "point_mass_scale": f}}`` (either key), in place of the common ones for that
        appendage. Default none.

    Returns
    -------
    HubBeam or Structure
        Validated like any other (a factor that leaves the physical range raises its error).
    """
    if not isinstance(system, (HubBeam, Structure)):
        raise InputTypeError(f"disperse.system must be a HubBeam or a Structure; got "
                             f"{type(system).__name__}")
    common = {"youngs_modulus_scale": check_real("disperse", "youngs_modulus_scale",
                                                 youngs_modulus_scale, minimum=0.0, strict=True),
              "point_mass_scale": check_real("disperse", "point_mass_scale", point_mass_scale,
                                             minimum=0.0)}
    j = check_real("disperse", "hub_inertia_scale", hub_inertia_scale, minimum=0.0)
    own = _appendage_scales(system, appendage_scales or {})
    hub = dataclasses.replace(system.hub, inertia=j * system.hub.inertia)
    if isinstance(system, HubBeam):
        return dataclasses.replace(_scaled(system, common), hub=hub)
    appendages = tuple(_scaled(app, {**common, **own.get(app.name, {})})
                       for app in system.appendages)
    return dataclasses.replace(system, hub=hub, appendages=appendages)


def _appendage_scales(system, scales: Mapping) -> dict:
    """``scales`` checked against ``system``'s appendages and the factor rules."""
    names = system.names if isinstance(system, Structure) else ()
    out = {}
    for app, factors in scales.items():
        if app not in names or not isinstance(factors, Mapping):
            raise InputValueError(f"disperse.appendage_scales must name appendages of the "
                                  f"structure ({', '.join(map(repr, names)) or 'none'}) with a "
                                  f"dict of factors; got {app!r}: {factors!r}")
        out[app] = {}
        for name, value in factors.items():
            if name not in ("youngs_modulus_scale", "point_mass_scale"):
                raise InputValueError(f"disperse.appendage_scales[{app!r}] factor must be "
                                      f"youngs_modulus_scale or point_mass_scale; got {name!r}")
            out[app][name] = check_real("disperse", f"appendage_scales[{app!r}].{name}", value,
                                        minimum=0.0, strict=name == "youngs_modulus_scale")
    return out


def _scaled(holder, factors: dict):
    """A HubBeam or an Appendage with its beam's stiffness and its point masses scaled."""
    beam = dataclasses.replace(holder.beam, youngs_modulus=factors["youngs_modulus_scale"]
                               * holder.beam.youngs_modulus)
    masses = tuple(dataclasses.replace(mass, mass=factors["point_mass_scale"] * mass.mass)
                   for mass in holder.masses)
    return dataclasses.replace(holder, beam=beam, masses=masses)
