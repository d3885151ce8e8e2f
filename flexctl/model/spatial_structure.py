"""A hub that turns about any axis, with appendages that bend in two planes and twist.

A :class:`SpatialStructure` is a rigid :class:`SpatialHub` (a full inertia tensor about its
centre, pinned or floating free) carrying :class:`SpatialAppendage` objects: each an
inextensible rod clamped at a root point of the hub, along its ``direction``, whose section is
most flexible along its ``normal``, with two bending stiffnesses, torsion and point masses
(:doc:`the spatial model </guide/spatial>`). The planar :class:`~flexctl.model.Structure` is the
case of a diagonal inertia with motion about one axis; :meth:`SpatialStructure.from_planar`
turns one into the other.

Examples
--------
>>> import numpy as np
>>> from flexctl.model.spatial_structure import SpatialHub, SpatialAppendage, SpatialStructure
>>> wing = SpatialAppendage(name="wing_a", direction=(0, 1, 0), normal=(0, 0, 1), length=1.8,
...                         density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
...                         second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
...                         shear_modulus=2.6e10, torsion_constant=1.9531e-9)
>>> craft = SpatialStructure(hub=SpatialHub(inertia=np.diag([1.3, 1.16, 1.45]), radius=0.06),
...                          appendages=(wing,))
>>> craft.names, craft.appendages[0].root_point(craft.hub).tolist()
(('wing_a',), [0.0, 0.06, 0.0])
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from .checks import KeywordOnly, check_array, check_direction, check_real
from .errors import InputTypeError, InputValueError
from .parameters import RADIUS_RATIO_LIMIT, SUPPORTS, Beam, Hub, carried_masses

__all__ = ["SpatialHub", "SpatialAppendage", "SpatialStructure", "PERPENDICULAR_TOLERANCE",
           "MAX_SPATIAL_APPENDAGES"]

#: Largest ``|direction . normal|`` (after normalising both) accepted as perpendicular.
PERPENDICULAR_TOLERANCE = 1e-9
#: Most appendages one spatial hub carries.
MAX_SPATIAL_APPENDAGES = 16
#: Largest entry of a hub inertia tensor, kg m^2, and largest hub mass, kg: beyond them the
#: mass matrix's products leave the floating-point range.
MAX_HUB_INERTIA = 1e15
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


@dataclass(frozen=True, kw_only=True)
class SpatialHub(KeywordOnly):
    """The rigid hub of a spatial structure.

    Parameters
    ----------
    inertia : array_like, shape (3, 3)
        Inertia tensor ``J_h`` of the hub alone about its centre, in the hub frame, kg m^2:
        symmetric and positive semi-definite (0 allowed: a massless hub, the appendages carry
        the inertia).
    radius : float
        Default distance of an appendage's root from the centre, m (>= 0): its root is
        ``radius * direction`` unless it gives its own ``root``.
    mass : float, optional
        Hub mass, kg (>= 0); counts for a ``free`` hub. Default 0.
    support : {"pinned", "free"}, optional
        ``pinned``: the centre is fixed and the hub turns freely about it; ``free``: six
        degrees of freedom. Default ``pinned``.
    """

    inertia: np.ndarray
    radius: float
    mass: float = 0.0
    support: str = "pinned"

    def __post_init__(self):
        inertia = np.array(check_array("hub", "inertia", self.inertia, shape=(3, 3)))
        if np.max(np.abs(inertia)) > MAX_HUB_INERTIA:
            raise InputValueError(f"hub.inertia entries must be at most {MAX_HUB_INERTIA:g} "
                                  f"kg m^2 in magnitude; got {inertia.tolist()}")
        scale = max(float(np.max(np.abs(inertia))), 1e-300)
        if np.max(np.abs(inertia - inertia.T)) > 1e-9 * scale:
            raise InputValueError(f"hub.inertia must be symmetric; got {inertia.tolist()}")
        inertia = 0.5 * (inertia + inertia.T)
        eigen = np.linalg.eigvalsh(inertia)
        if eigen[0] < -1e-12 * scale:
            raise InputValueError("hub.inertia must be positive semi-definite (a physical "
                                  f"inertia tensor); its eigenvalues are {eigen.tolist()}")
        if eigen.size and eigen[-1] > 0 and eigen[0] > 0 and (
                eigen[2] > eigen[0] + eigen[1] + 1e-9 * scale):
            raise InputValueError(
                "hub.inertia must satisfy the triangle inequality of a rigid body's principal "
                f"moments (each at most the sum of the other two); got {eigen.tolist()}")
        inertia.setflags(write=False)
        object.__setattr__(self, "inertia", inertia)
        for name in ("radius", "mass"):
            object.__setattr__(self, name, check_real("hub", name, getattr(self, name),
                                                      minimum=0.0, maximum=MAX_HUB_INERTIA))
        if not isinstance(self.support, str) or self.support not in SUPPORTS:
            raise (InputValueError if isinstance(self.support, str) else InputTypeError)(
                f"hub.support must be one of {', '.join(SUPPORTS)}; got {self.support!r}")

    @property
    def free(self) -> bool:
        """Whether the centre floats free."""
        return self.support == "free"

    def __eq__(self, other):
        return (isinstance(other, SpatialHub) and np.array_equal(self.inertia, other.inertia)
                and (self.radius, self.mass, self.support)
                == (other.radius, other.mass, other.support))

    def __hash__(self):
        return hash((self.inertia.tobytes(), self.radius, self.mass, self.support))


@dataclass(frozen=True, kw_only=True)
class SpatialAppendage(KeywordOnly):
    """An inextensible rod clamped to the hub, bending in two planes and twisting.

    Parameters
    ----------
    name : str
        An identifier, unique on its hub; it prefixes the appendage's states and outputs.
    direction : array_like, shape (3,)
        The rod's axis ``e1`` in the hub frame (normalised here).
    normal : array_like, shape (3,)
        The section's most flexible direction ``e3``, perpendicular to ``direction``
        (normalised here). The lateral direction is ``e2 = e3 x e1``.
    length, density, area, youngs_modulus : float
        ``l`` (m), ``rho`` (kg/m^3), ``A`` (m^2), ``E`` (Pa); all > 0.
    second_moment : float
        ``I_n``, m^4 (> 0): bending along the normal, stiffness ``E I_n``.
    second_moment_lateral : float
        ``I_l``, m^4 (> 0): bending along the lateral direction, stiffness ``E I_l``.
    shear_modulus, torsion_constant : float
        ``G`` (Pa) and ``J`` (m^4), > 0: torsional stiffness ``G J``.
    polar_moment : float or None, optional
        Polar second moment of the section ``I_p``, m^4 (> 0): the twist's inertia per length
        is ``rho I_p``. Default ``I_n + I_l``.
    masses : tuple of PointMass, optional
        Point masses at arc lengths in ``[0, length]``.
    root : array_like, shape (3,), or None, optional
        The root point in the hub frame, m. Default ``hub.radius * direction``.
    damping_ratio : float, optional
        Modal damping ratio of every clamped mode, in ``[0, 1)``. Default 0.
    """

    name: str
    direction: np.ndarray
    normal: np.ndarray
    length: float
    density: float
    area: float
    youngs_modulus: float
    second_moment: float
    second_moment_lateral: float
    shear_modulus: float
    torsion_constant: float
    polar_moment: float | None = None
    masses: tuple = field(default=())
    root: np.ndarray | None = None
    damping_ratio: float = 0.0

    def __post_init__(self):
        if not isinstance(self.name, str):
            raise InputTypeError(f"appendage.name must be a string; got "
                                 f"{type(self.name).__name__}")
        if not _NAME.match(self.name):
            raise InputValueError(
                "appendage.name must be an identifier (letters, digits and underscores, not "
                f"starting with a digit); got {self.name[:80]!r}")
        owner = f"appendage {self.name!r}"
        direction = check_direction(owner, "direction", self.direction)
        normal = check_direction(owner, "normal", self.normal)
        if abs(float(direction @ normal)) > PERPENDICULAR_TOLERANCE:
            raise InputValueError(
                f"{owner}.normal must be perpendicular to its direction; got direction "
                f"{direction.tolist()} and normal {normal.tolist()} (cosine "
                f"{float(direction @ normal):.3g})")
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "normal", normal)
        for name in ("length", "density", "area", "youngs_modulus", "second_moment",
                     "second_moment_lateral", "shear_modulus", "torsion_constant"):
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name),
                                                      minimum=0.0, strict=True))
        polar = self.second_moment + self.second_moment_lateral if self.polar_moment is None \
            else check_real(owner, "polar_moment", self.polar_moment, minimum=0.0, strict=True)
        object.__setattr__(self, "polar_moment", polar)
        if self.root is not None:
            object.__setattr__(self, "root", check_array(owner, "root", self.root, shape=(3,)))
        # the bending planes' beams check the ratios and the masses as the planar model does
        beam = self.beam_normal
        _ = self.beam_lateral
        object.__setattr__(self, "masses", carried_masses(owner, beam, self.masses, 0.0))
        torsion = self.torsion_frequency(1)
        if not (math.isfinite(torsion) and 1e-12 < torsion < 1e12):
            raise InputValueError(
                f"{owner}: the first torsion frequency sqrt(G J / (rho I_p)) pi / (2 l) must lie "
                f"in [1e-12, 1e12] rad/s to be represented; got {torsion:.3g}")
        zeta = check_real(owner, "damping_ratio", self.damping_ratio, minimum=0.0)
        if zeta >= 1.0:
            raise InputValueError(f"{owner}.damping_ratio must be in [0, 1); got {zeta!r}")
        object.__setattr__(self, "damping_ratio", zeta)

    @property
    def lateral(self) -> np.ndarray:
        """The lateral direction ``e2 = e3 x e1`` in the hub frame, shape (3,)."""
        return np.cross(self.normal, self.direction)

    @property
    def frame(self) -> np.ndarray:
        """``[e1 e2 e3]`` as columns, shape (3, 3): the root section's frame in the hub's."""
        return np.column_stack([self.direction, self.lateral, self.normal])

    @property
    def beam_normal(self) -> Beam:
        """The rod as a planar beam bending along its normal (``E I_n``)."""
        return Beam(length=self.length, density=self.density, area=self.area,
                    second_moment=self.second_moment, youngs_modulus=self.youngs_modulus,
                    damping_ratio=self.damping_ratio)

    @property
    def beam_lateral(self) -> Beam:
        """The rod as a planar beam bending along its lateral direction (``E I_l``)."""
        return Beam(length=self.length, density=self.density, area=self.area,
                    second_moment=self.second_moment_lateral,
                    youngs_modulus=self.youngs_modulus, damping_ratio=self.damping_ratio)

    @property
    def linear_density(self) -> float:
        """``rho A``, kg/m."""
        return self.density * self.area

    @property
    def polar_density(self) -> float:
        """``rho I_p``, the twist's inertia per length, kg m."""
        return self.density * self.polar_moment

    @property
    def torsional_stiffness(self) -> float:
        """``G J``, N m^2."""
        return self.shear_modulus * self.torsion_constant

    def torsion_frequency(self, k: int) -> float:
        """The ``k``-th clamped-free torsion frequency of the bare rod, rad/s.

        Parameters
        ----------
        k : int
            Mode number, from 1.

        Returns
        -------
        float
            ``(2 k - 1) pi / (2 l) sqrt(G J / (rho I_p))``.
        """
        return ((2 * k - 1) * math.pi / (2 * self.length)
                * math.sqrt(self.torsional_stiffness / self.polar_density))

    @property
    def mass(self) -> float:
        """Rod plus point masses, kg."""
        return self.linear_density * self.length + sum(m.mass for m in self.masses)

    def root_point(self, hub: SpatialHub) -> np.ndarray:
        """The root in the hub frame, m, shape (3,).

        Parameters
        ----------
        hub : SpatialHub
            The hub it is clamped to (its radius is the default distance).
        """
        return np.array(self.root) if self.root is not None else hub.radius * self.direction

    def __eq__(self, other):
        if not isinstance(other, SpatialAppendage):
            return False
        return all(np.array_equal(getattr(self, n), getattr(other, n)) if isinstance(
            getattr(self, n), np.ndarray) else getattr(self, n) == getattr(other, n)
            for n in self.__dataclass_fields__)

    def __hash__(self):
        return hash((self.name, self.direction.tobytes(), self.normal.tobytes(), self.length,
                     self.second_moment, self.second_moment_lateral, self.masses))


@dataclass(frozen=True, kw_only=True)
class SpatialStructure(KeywordOnly):
    """A spatial hub carrying appendages.

    Parameters
    ----------
    hub : SpatialHub
        The rigid hub: its inertia tensor, pinned or free.
    appendages : tuple of SpatialAppendage
        At least one, at most :data:`MAX_SPATIAL_APPENDAGES`, with unique names; their order
        is the order of their states.
    """

    hub: SpatialHub
    appendages: tuple

    def __post_init__(self):
        if not isinstance(self.hub, SpatialHub):
            raise InputTypeError(f"structure.hub must be a SpatialHub; got "
                                 f"{type(self.hub).__name__}")
        if isinstance(self.appendages, (str, bytes, dict)) or not hasattr(self.appendages,
                                                                          "__iter__"):
            raise InputTypeError("structure.appendages must be a sequence of SpatialAppendage; "
                                 f"got {type(self.appendages).__name__}")
        appendages = tuple(self.appendages)
        if not 1 <= len(appendages) <= MAX_SPATIAL_APPENDAGES:
            raise InputValueError(f"structure.appendages must hold 1 to "
                                  f"{MAX_SPATIAL_APPENDAGES} appendages; got {len(appendages)}")
        for k, a in enumerate(appendages):
            if not isinstance(a, SpatialAppendage):
                raise InputTypeError(f"structure.appendages[{k}] must be a SpatialAppendage; "
                                     f"got {type(a).__name__}")
        names = [a.name for a in appendages]
        for k, name in enumerate(names):
            if name in names[:k]:
                raise InputValueError(f"structure.appendages[{k}].name must be unique; "
                                      f"{name!r} is already taken")
        object.__setattr__(self, "appendages", appendages)
        for k, a in enumerate(appendages):
            root = a.root_point(self.hub)
            largest = float(np.max(np.abs(root)))
            distance = largest * float(np.linalg.norm(root / largest)) if largest > 0 else 0.0
            if distance > RADIUS_RATIO_LIMIT * a.length:
                where = f"appendages[{k}].root" if a.root is not None else "hub.radius"
                raise InputValueError(
                    f"{where} must put the root at most {RADIUS_RATIO_LIMIT:g} times "
                    f"appendages[{k}].length = {a.length:g} m from the centre: beyond it the mass "
                    f"matrix is too ill conditioned to keep the model's accuracy; got "
                    f"{distance:g} m")
        if self.hub.free and self.total_mass <= 0:
            raise InputValueError("a free hub needs mass: hub.mass plus the appendages' must "
                                  "be > 0")

    @property
    def names(self) -> tuple:
        """The appendages' names, in order."""
        return tuple(a.name for a in self.appendages)

    @property
    def total_mass(self) -> float:
        """Hub plus appendages, kg."""
        return self.hub.mass + sum(a.mass for a in self.appendages)

    def appendage_inertia(self, k: int) -> np.ndarray:
        """Inertia tensor of appendage ``k`` straight and rigid (its line mass and point
        masses; the section's polar inertia about its axis), about the hub's centre, in the hub
        frame, kg m^2.

        Parameters
        ----------
        k : int
            Appendage index.

        Returns
        -------
        ndarray, shape (3, 3)
        """
        a = self.appendages[k]
        root, e1, length = a.root_point(self.hub), a.direction, a.length
        # the second moment sum m p p^T: the rod's p = root + s e1 integrated over [0, l]
        second = a.linear_density * (length * np.outer(root, root) + length ** 2 / 2 * (
            np.outer(root, e1) + np.outer(e1, root)) + length ** 3 / 3 * np.outer(e1, e1))
        for point in a.masses:
            p = root + point.position * e1
            second = second + point.mass * np.outer(p, p)
        inertia = np.trace(second) * np.eye(3) - second
        return inertia + a.polar_density * a.length * np.outer(e1, e1)

    @property
    def first_moment(self) -> np.ndarray:
        """First mass moment of the whole structure straight and rigid about the hub's centre
        (the hub's own centre is its centre of mass), hub frame, kg m, shape (3,): the
        centre of mass is ``first_moment / total_mass``."""
        moment = np.zeros(3)
        for a in self.appendages:
            root, e1, length = a.root_point(self.hub), a.direction, a.length
            moment = moment + a.linear_density * length * (root + length / 2 * e1)
            for point in a.masses:
                moment = moment + point.mass * (root + point.position * e1)
        return moment

    @property
    def rigid_inertia(self) -> np.ndarray:
        """Inertia tensor of the whole structure straight and rigid about the hub's centre,
        hub frame, kg m^2, shape (3, 3)."""
        return self.hub.inertia + sum(self.appendage_inertia(k)
                                      for k in range(len(self.appendages)))

    def to_planar(self):
        """The planar structure that turns about the hub's ``z`` axis as this one would if it
        moved only in the ``x-y`` plane: the hub's ``J_zz`` (and mass), each rod at its
        mounting angle with the bending stiffness of that plane (``E I_n`` where the normal
        lies in it, ``E I_l`` where the normal is along ``z``) and its masses.

        Returns
        -------
        Structure

        Raises
        ------
        InputValueError
            When an appendage does not lie in the ``x-y`` plane (its direction, its root off
            the plane or off its own axis through the centre, its normal neither along ``z``
            nor in the plane), or the hub's ``z`` axis is not principal.
        """
        from .structure import Appendage, Structure

        tol = 1e-12
        hub = self.hub
        if abs(hub.inertia[0, 2]) > tol * np.max(np.abs(hub.inertia)) or \
                abs(hub.inertia[1, 2]) > tol * np.max(np.abs(hub.inertia)):
            raise InputValueError("SpatialStructure.to_planar: the hub's z axis must be "
                                  f"principal (J_xz = J_yz = 0); got {hub.inertia[0:2, 2]}")
        appendages = []
        for a in self.appendages:
            root = a.root_point(hub)
            radius = float(root @ a.direction)
            if abs(a.direction[2]) > tol or np.linalg.norm(root - radius * a.direction) > \
                    tol * max(1.0, a.length) or radius < 0.0:
                raise InputValueError(f"SpatialStructure.to_planar: appendage {a.name!r} must "
                                      "lie in the x-y plane with its root on its own axis "
                                      f"through the centre; got direction {a.direction}, "
                                      f"root {root}")
            if abs(a.normal[2]) > 1.0 - tol:
                beam = a.beam_lateral
            elif abs(a.normal[2]) <= tol:
                beam = a.beam_normal
            else:
                raise InputValueError(f"SpatialStructure.to_planar: appendage {a.name!r} has a "
                                      f"tilted section (normal {a.normal}): neither bending "
                                      "plane is the x-y plane")
            appendages.append(Appendage(
                name=a.name, beam=beam, masses=a.masses, radius=radius,
                angle=float(np.arctan2(a.direction[1], a.direction[0]))))
        return Structure(hub=Hub(inertia=float(hub.inertia[2, 2]), radius=hub.radius,
                                 mass=hub.mass, support=hub.support),
                         appendages=tuple(appendages))

    @classmethod
    def from_planar(cls, structure, *, lateral_ratio: float = 100.0,
                    torsion_ratio: float = 100.0) -> "SpatialStructure":
        """The planar ``structure`` (:class:`~flexctl.model.Structure` or
        :class:`~flexctl.model.HubBeam`) in three dimensions: the hub turns about ``z`` with
        its planar inertia (``J_h`` about every axis), each beam lies in the ``x-y`` plane at
        its mounting angle, its normal the planar deflection direction.

        Parameters
        ----------
        structure : Structure or HubBeam
            The planar structure: its hub, beams, masses and mounting angles.
        lateral_ratio : float, optional
            ``I_l / I_n`` of the rods (the planar model has no lateral bending). Default 100.
        torsion_ratio : float, optional
            ``G J / (E I_n)``. Default 100.

        Returns
        -------
        SpatialStructure
        """
        from .structure import as_structure

        planar = as_structure(structure)
        hub = planar.hub
        appendages = []
        for k, a in enumerate(planar.appendages):
            beam = a.beam
            d = np.array([math.cos(a.angle), math.sin(a.angle), 0.0])
            n = np.array([-math.sin(a.angle), math.cos(a.angle), 0.0])
            radius = hub.radius if a.radius is None else a.radius
            appendages.append(SpatialAppendage(
                name=a.name or f"beam{k}", direction=d, normal=n, length=beam.length,
                density=beam.density, area=beam.area, youngs_modulus=beam.youngs_modulus,
                second_moment=beam.second_moment,
                second_moment_lateral=lateral_ratio * beam.second_moment,
                shear_modulus=torsion_ratio * beam.youngs_modulus * beam.second_moment,
                torsion_constant=1.0, masses=a.masses, root=radius * d,
                damping_ratio=beam.damping_ratio))
        return cls(hub=SpatialHub(inertia=hub.inertia * np.eye(3), radius=hub.radius,
                                  mass=hub.mass, support=hub.support),
                   appendages=tuple(appendages))

