"""Physical parameters of a hub-beam-mass system.

Frozen, keyword-friendly dataclasses validated on construction. SI units throughout.
Derive variants with ``dataclasses.replace``, which re-runs the validation.

Examples
--------
>>> from flexctl import Hub, Beam, PointMass, HubBeam
>>> system = HubBeam(
...     hub=Hub(inertia=1.16, radius=0.06),
...     beam=Beam(length=1.8, density=2766.0, area=2.5e-4,
...               second_moment=1.3021e-10, youngs_modulus=6.9e10),
...     masses=(PointMass(mass=0.085, position=1.62),),
... )
>>> round(system.beam.linear_density, 4)
0.6915
>>> Hub(inertia=-1.0, radius=0.0)
Traceback (most recent call last):
...
flexctl.model.errors.InputValueError: hub.inertia must be finite and >= 0; got -1.0
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .checks import KeywordOnly, check_real
from .errors import InputTypeError, InputValueError

__all__ = ["Hub", "Beam", "PointMass", "HubBeam", "check_real", "RATIO_LIMIT",
           "MASS_RATIO_LIMIT", "RADIUS_RATIO_LIMIT", "SUPPORTS",
           "carried_masses"]

#: Products and ratios of beam parameters (mass per length, bending stiffness, EI / rhoA l^4)
#: must lie within [1 / RATIO_LIMIT, RATIO_LIMIT]: the modal matrices multiply and square them.
RATIO_LIMIT = 1e100
#: Largest ratio of the point masses to the beam mass: the condition number of the modal mass
#: matrix grows with it (about 3 times the ratio), and so do the rounding errors of the model.
MASS_RATIO_LIMIT = 1e6
#: Largest ratio of the hub radius to the beam length: the free-hub mass matrix holds
#: ``J_0 ~ rhoA l b^2`` beside modal masses ``~ rhoA l``, and its condition number grows as
#: ``(b / l)^2``; past 1e6 the free-hub frequencies lose digits (at 1e16 they were 10 % off,
#: at 1e17 the mass matrix was no longer positive definite, at 1e250 J_0 overflowed).
RADIUS_RATIO_LIMIT = 1e6
#: How a hub is held: its centre pinned, or floating free in the plane.
SUPPORTS = ("pinned", "free")


@dataclass(frozen=True, kw_only=True)
class Hub(KeywordOnly):
    """Rigid hub rotating about its centre O, which is pinned or floats free in the plane.

    Parameters
    ----------
    inertia : float
        Moment of inertia ``J_h`` of the hub alone about O, kg m^2. May be 0 (massless hub).
    radius : float
        Radius ``b`` at which the beam is clamped, m. May be 0.
    friction : float, optional
        Viscous friction coefficient ``c_h`` of the hub bearing, N m s/rad. Default 0.
    mass : float, optional
        Mass ``m_h`` of the hub alone, kg (>= 0). Default 0; it matters only when the hub
        floats free.
    support : {"pinned", "free"}, optional
        ``"pinned"`` (default, the papers' case): the centre O is fixed and the hub rotates
        about it. ``"free"``: the hub also translates in the plane (a spacecraft in orbit).
    """

    inertia: float
    radius: float
    friction: float = 0.0
    mass: float = 0.0
    support: str = "pinned"

    def __post_init__(self):
        for name in ("inertia", "radius", "friction", "mass"):
            object.__setattr__(self, name,
                               check_real("hub", name, getattr(self, name), minimum=0.0))
        if not isinstance(self.support, str) or self.support not in SUPPORTS:
            raise (InputValueError if isinstance(self.support, str) else InputTypeError)(
                f"hub.support must be one of {', '.join(SUPPORTS)}; got {self.support!r}")

    @property
    def free(self) -> bool:
        """True when the hub floats free (translates as well as rotates)."""
        return self.support == "free"


@dataclass(frozen=True, kw_only=True)
class Beam(KeywordOnly):
    """Uniform Euler-Bernoulli cantilever clamped radially to the hub.

    Parameters
    ----------
    length : float
        Length ``l``, m (> 0).
    density : float
        Material density ``rho``, kg/m^3 (> 0).
    area : float
        Cross-section area ``A``, m^2 (> 0).
    second_moment : float
        Second moment of area ``I`` about the bending axis, m^4 (> 0).
    youngs_modulus : float
        Young's modulus ``E``, Pa (> 0).
    damping_ratio : float, optional
        Modal damping ratio ``zeta`` of every clamped mode, in ``[0, 1)``. Default 0.
    """

    length: float
    density: float
    area: float
    second_moment: float
    youngs_modulus: float
    damping_ratio: float = 0.0

    def __post_init__(self):
        for name in ("length", "density", "area", "second_moment", "youngs_modulus"):
            object.__setattr__(self, name, check_real("beam", name, getattr(self, name),
                                                 minimum=0.0, strict=True))
        zeta = check_real("beam", "damping_ratio", self.damping_ratio, minimum=0.0)
        if zeta >= 1.0:
            raise InputValueError(f"beam.damping_ratio must be finite and in [0, 1); got {zeta!r}")
        object.__setattr__(self, "damping_ratio", zeta)
        self._check_ratios()

    def _check_ratios(self):
        """Products and the stiffness-to-mass ratio must stay far from under- and overflow:
        the modal matrices square them (a density and area of 1e-300 give a mass per length
        of 0 and frequencies of inf)."""
        low, high = 1.0 / RATIO_LIMIT, RATIO_LIMIT
        for label, value in (("beam.density * beam.area (mass per length, kg/m)",
                              self.density * self.area),
                             ("beam.youngs_modulus * beam.second_moment (bending stiffness, "
                              "N m^2)", self.youngs_modulus * self.second_moment)):
            if not low <= value <= high:
                raise InputValueError(f"{label} must lie in [{low:g}, {high:g}] to be "
                                      f"represented in floating point; got {value!r}")
        with np.errstate(all="ignore"):    # an overflow is an out-of-range ratio, said below
            ratio = float(np.float64(self.bending_stiffness)
                          / (self.linear_density * np.float64(self.length) ** 4))
        if not low <= ratio <= high:
            raise InputValueError(
                "the ratio EI / (rho A l^4) of beam.youngs_modulus * beam.second_moment to "
                "beam.density * beam.area * beam.length^4 (the squared first clamped frequency "
                f"/ 12.4, 1/s^2) must lie in [{low:g}, {high:g}]; got {ratio!r}")

    @property
    def linear_density(self) -> float:
        """Mass per unit length ``rhoA``, kg/m."""
        return self.density * self.area

    @property
    def bending_stiffness(self) -> float:
        """Flexural rigidity ``EI``, N m^2."""
        return self.youngs_modulus * self.second_moment

    @property
    def mass(self) -> float:
        """Total beam mass ``rhoA l``, kg."""
        return self.linear_density * self.length


@dataclass(frozen=True, kw_only=True)
class PointMass(KeywordOnly):
    """Point mass carried by the beam.

    Parameters
    ----------
    mass : float
        Mass ``m_k``, kg (>= 0).
    position : float
        Distance ``d_k`` from the beam root, m, in ``[0, length]``. Its holder
        (:class:`HubBeam`, an appendage) checks it against the beam length.
    """

    mass: float
    position: float

    def __post_init__(self):
        object.__setattr__(self, "mass", check_real("mass", "mass", self.mass, minimum=0.0))
        object.__setattr__(self, "position",
                           check_real("mass", "position", self.position, minimum=0.0))


def carried_masses(owner: str, beam, masses, radius: float) -> tuple:
    """Check a beam, its point masses and its root radius; the masses sorted by position.

    Parameters
    ----------
    owner : str
        Name of the holder in messages (``system``, ``appendages[1]``).
    beam : Beam
        The cantilever the masses sit on.
    masses : iterable of PointMass
        Its point masses, each at a position in ``[0, beam.length]``.
    radius : float
        Radius of the beam's root from the hub centre, m.

    Returns
    -------
    tuple of PointMass
    """
    if not isinstance(beam, Beam):
        raise InputTypeError(f"{owner}.beam must be a Beam; got {type(beam).__name__}")
    if isinstance(masses, (str, bytes, dict)):
        raise InputTypeError(f"{owner}.masses must be an iterable of PointMass; got "
                             f"{type(masses).__name__}")
    try:
        masses = tuple(masses)
    except TypeError:
        raise InputTypeError(f"{owner}.masses must be an iterable of PointMass; got "
                             f"{type(masses).__name__}") from None
    length_key = "beam.length" if owner == "system" else f"{owner}.beam.length"
    for k, m in enumerate(masses):
        if not isinstance(m, PointMass):
            raise InputTypeError(f"{owner}.masses[{k}] must be a PointMass; got "
                                 f"{type(m).__name__}")
        if m.position > beam.length:
            raise InputValueError(f"{owner}.masses[{k}].position must lie in [0, {length_key} = "
                                  f"{beam.length:g}]; got {m.position!r}")
    if radius > RADIUS_RATIO_LIMIT * beam.length:
        raise InputValueError(
            f"{'hub.radius' if owner == 'system' else owner + '.radius'} must be at most "
            f"{RADIUS_RATIO_LIMIT:g} times {length_key} = {beam.length:g} m: beyond it the "
            "free-hub mass matrix is too ill conditioned for the model to keep its accuracy; "
            f"got {radius!r}")
    ratio = sum(m.mass for m in masses) / beam.mass
    if ratio > MASS_RATIO_LIMIT:
        raise InputValueError(
            f"the ratio of the point masses to the beam mass ({beam.mass:.4g} kg) of {owner} "
            f"must be <= {MASS_RATIO_LIMIT:g}: beyond it the modal mass matrix is too ill "
            f"conditioned for the model to keep its accuracy; got {ratio:.4g}")
    return tuple(sorted(masses, key=lambda m: m.position))


@dataclass(frozen=True, kw_only=True)
class HubBeam(KeywordOnly):
    """A hub carrying a cantilever beam with any number of point masses.

    Parameters
    ----------
    hub : Hub
        The rigid hub, pinned or free, at whose rim the beam is clamped.
    beam : Beam
        The cantilever.
    masses : tuple of PointMass, optional
        Point masses on the beam, each at a position in ``[0, beam.length]``. Any iterable is
        accepted and stored as a tuple sorted by position.
    """

    hub: Hub
    beam: Beam
    masses: tuple = field(default=())

    def __post_init__(self):
        if not isinstance(self.hub, Hub):
            raise InputTypeError(f"system.hub must be a Hub; got {type(self.hub).__name__}")
        object.__setattr__(self, "masses",
                           carried_masses("system", self.beam, self.masses, self.hub.radius))

    @property
    def total_point_mass(self) -> float:
        """Sum of the point masses, kg."""
        return sum(m.mass for m in self.masses)

    @property
    def rigid_inertia(self) -> float:
        """Inertia ``J_0`` of the undeformed system about O, kg m^2 (:ref:`section 2 of the
        model <sec-continuous>`)."""
        b, l = self.hub.radius, self.beam.length
        # ((b + l)^3 - b^3) / 3 without the cancellation that lost digits for b >> l
        return (self.hub.inertia + self.beam.linear_density * l * (b * b + b * l + l * l / 3.0)
                + sum(m.mass * (b + m.position) ** 2 for m in self.masses))
