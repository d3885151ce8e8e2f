"""Several appendages on one hub, pinned or floating free (``docs/theory/free_hub.md``).

A :class:`Structure` is a :class:`~flexctl.model.parameters.Hub` carrying any number of
:class:`Appendage` objects: each a cantilever beam with its own point masses, clamped radially
at its own radius and mounting angle in the hub frame. :class:`~flexctl.model.HubBeam` is the
one-appendage, pinned case, and :meth:`Structure.from_hub_beam` turns one into the other.

Examples
--------
>>> from flexctl import Hub, Beam, PointMass, Appendage, Structure
>>> panel = Beam(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
...              youngs_modulus=6.9e10)
>>> craft = Structure(hub=Hub(inertia=1.16, radius=0.06, mass=3.0, support="free"),
...                   appendages=(Appendage(name="wing_a", beam=panel),
...                               Appendage(name="wing_b", beam=panel, angle=3.141592653589793)))
>>> craft.names, round(craft.total_mass, 4)
(('wing_a', 'wing_b'), 5.4894)
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .checks import KeywordOnly, check_real
from .errors import InputTypeError, InputValueError
from .parameters import Beam, Hub, HubBeam, carried_masses

__all__ = ["Appendage", "Structure", "MAX_APPENDAGES", "as_structure"]

#: Most appendages one hub carries.
MAX_APPENDAGES = 32
#: Largest mounting angle magnitude, rad (a few turns: larger ones are typing slips).
MAX_ANGLE = 8.0 * math.pi
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


@dataclass(frozen=True, kw_only=True)
class Appendage(KeywordOnly):
    """A cantilever beam with its point masses, clamped radially to the hub.

    Parameters
    ----------
    name : str
        An identifier (letters, digits, underscores; not starting with a digit), unique on its
        hub. It prefixes the appendage's states and outputs (``wing_a.q1``,
        ``wing_a.tip_deflection``). The empty name is kept for the single appendage of a
        :class:`~flexctl.model.HubBeam`.
    beam : Beam
        The cantilever.
    masses : tuple of PointMass, optional
        Point masses on the beam, positions from its root in ``[0, beam.length]``; stored
        sorted by position.
    angle : float, optional
        Mounting angle ``alpha`` of the beam's axis in the hub frame, rad. Default 0.
    radius : float or None, optional
        Radius ``b_k`` of the root from the hub centre, m (>= 0). ``None`` (default): the hub
        radius.
    """

    name: str
    beam: Beam
    masses: tuple = field(default=())
    angle: float = 0.0
    radius: float | None = None

    def __post_init__(self):
        if not isinstance(self.name, str):
            raise InputTypeError(f"appendage.name must be a string; got "
                                 f"{type(self.name).__name__}")
        if self.name and not _NAME.match(self.name):
            raise InputValueError(
                "appendage.name must be an identifier (letters, digits and underscores, not "
                f"starting with a digit); got {self.name[:80]!r}")
        owner = f"appendage {self.name!r}" if self.name else "appendage"
        angle = check_real(owner, "angle", self.angle, minimum=-MAX_ANGLE, maximum=MAX_ANGLE)
        object.__setattr__(self, "angle", angle)
        radius = check_real(owner, "radius", self.radius, minimum=0.0, optional=True)
        object.__setattr__(self, "radius", radius)
        object.__setattr__(self, "masses", carried_masses(
            owner, self.beam, self.masses, 0.0 if radius is None else radius))

    @property
    def direction(self) -> np.ndarray:
        """Unit vector ``e_k`` of the beam's axis in the hub frame, shape (2,)."""
        return np.array([math.cos(self.angle), math.sin(self.angle)])

    @property
    def normal(self) -> np.ndarray:
        """Unit vector ``n_k = e_z x e_k``, the direction of positive deflection, shape (2,)."""
        return np.array([-math.sin(self.angle), math.cos(self.angle)])

    @property
    def mass(self) -> float:
        """Beam plus point masses, kg."""
        return self.beam.mass + sum(m.mass for m in self.masses)


@dataclass(frozen=True, kw_only=True)
class Structure(KeywordOnly):
    """A hub carrying any number of appendages.

    Parameters
    ----------
    hub : Hub
        ``hub.support`` says whether its centre is pinned or floats free; ``hub.mass``
        counts for a free hub.
    appendages : tuple of Appendage
        At least one, at most :data:`MAX_APPENDAGES`, with unique names (the empty name only
        for a single appendage). Their order is the order of their states.
    """

    hub: Hub
    appendages: tuple

    def __post_init__(self):
        if not isinstance(self.hub, Hub):
            raise InputTypeError(f"structure.hub must be a Hub; got {type(self.hub).__name__}")
        if isinstance(self.appendages, (str, bytes, dict, Appendage)):
            raise InputTypeError("structure.appendages must be a sequence of Appendage; got "
                                 f"{type(self.appendages).__name__}")
        try:
            apps = tuple(self.appendages)
        except TypeError:
            raise InputTypeError("structure.appendages must be a sequence of Appendage; got "
                                 f"{type(self.appendages).__name__}") from None
        if not 1 <= len(apps) <= MAX_APPENDAGES:
            raise InputValueError(f"structure.appendages must hold 1 to {MAX_APPENDAGES} "
                                  f"appendages; got {len(apps)}")
        names = []
        for k, app in enumerate(apps):
            if not isinstance(app, Appendage):
                raise InputTypeError(f"structure.appendages[{k}] must be an Appendage; got "
                                     f"{type(app).__name__}")
            if app.name in names:
                raise InputValueError(f"structure.appendages[{k}].name must be unique; "
                                      f"{app.name!r} is already taken")
            if not app.name and len(apps) > 1:
                raise InputValueError(f"structure.appendages[{k}].name must not be empty when "
                                      "the hub carries several appendages")
            names.append(app.name)
            carried_masses(f"appendage {app.name!r}" if app.name else "appendage", app.beam,
                           app.masses, self.root_radius(app))
        object.__setattr__(self, "appendages", apps)

    @classmethod
    def from_hub_beam(cls, system: HubBeam, name: str = "") -> "Structure":
        """The one-appendage structure of a :class:`~flexctl.model.HubBeam` (angle 0).

        Parameters
        ----------
        system : HubBeam
            The hub, beam and point masses.
        name : str, optional
            Name of the one appendage; default ``""`` (unprefixed state and output names).
        """
        if not isinstance(system, HubBeam):
            raise InputTypeError(f"system must be a HubBeam; got {type(system).__name__}")
        return cls(hub=system.hub, appendages=(Appendage(name=name, beam=system.beam,
                                                         masses=system.masses),))

    def root_radius(self, appendage: Appendage) -> float:
        """Radius of an appendage's root from the hub centre, m.

        Parameters
        ----------
        appendage : Appendage
            One of :attr:`appendages`: its own ``radius``, else the hub's.
        """
        return self.hub.radius if appendage.radius is None else appendage.radius

    def appendage_system(self, index: int) -> HubBeam:
        """Appendage ``index`` alone on a pinned, massless hub at its root radius: the
        one-beam system whose modal matrices are its blocks of the structure's.

        Parameters
        ----------
        index : int
            Position of the appendage in :attr:`appendages`.
        """
        app = self.appendages[index]
        return HubBeam(hub=Hub(inertia=0.0, radius=self.root_radius(app)), beam=app.beam,
                       masses=app.masses)

    @property
    def names(self) -> tuple:
        """The appendages' names, in order."""
        return tuple(a.name for a in self.appendages)

    @property
    def free(self) -> bool:
        """True when the hub floats free."""
        return self.hub.free

    @property
    def total_mass(self) -> float:
        """Hub, beams and point masses, kg."""
        return self.hub.mass + sum(a.mass for a in self.appendages)

    @property
    def rigid_inertia(self) -> float:
        """Inertia ``J_0`` of the undeformed structure about the hub centre, kg m^2."""
        return self.hub.inertia + sum(self.appendage_system(k).rigid_inertia
                                      for k in range(len(self.appendages)))

    @property
    def reach(self) -> float:
        """Largest distance of an undeformed tip from the hub centre, m."""
        return max(self.root_radius(a) + a.beam.length for a in self.appendages)


def as_structure(system) -> Structure:
    """A :class:`Structure` as it is; a :class:`~flexctl.model.HubBeam` as its one-appendage
    structure.

    Parameters
    ----------
    system : Structure or HubBeam
        The system; anything else raises ``InputTypeError``.
    """
    if isinstance(system, Structure):
        return system
    if isinstance(system, HubBeam):
        return _one_appendage(system)
    raise InputTypeError(f"system must be a HubBeam or a Structure; got {type(system).__name__}")


@lru_cache(maxsize=64)
def _one_appendage(system: HubBeam) -> Structure:
    """:meth:`Structure.from_hub_beam`, kept: a model asks for its structure on every run
    (both are frozen)."""
    return Structure.from_hub_beam(system)
