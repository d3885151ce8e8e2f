"""Parameters: validation on construction, immutability, derived quantities (MODEL.md 1-2)."""

import dataclasses
import math
import re

import numpy as np
import pytest
from scipy.integrate import quad

from flexctl import Beam, Hub, HubBeam, PointMass

#: Relative tolerance for derived quantities computed two ways in floating point.
DERIVED_RTOL = 1e-12

HUB = dict(inertia=1.16, radius=0.06, friction=0.1)
BEAM = dict(length=1.8, density=2766.0, area=2.5e-4, second_moment=1.3021e-10,
            youngs_modulus=6.9e10, damping_ratio=0.02)
MASS = dict(mass=0.085, position=1.62)

# (class, prefix used in messages, valid keyword arguments, fields that must be > 0 strictly)
CLASSES = {
    "hub": (Hub, "hub", HUB, ()),
    "beam": (Beam, "beam", BEAM, ("length", "density", "area", "second_moment",
                                  "youngs_modulus")),
    "mass": (PointMass, "mass", MASS, ()),
}

# Bad values every numeric field must reject: (id, value, exception type).
ALWAYS_BAD = [
    ("negative", -1.0, ValueError),
    ("nan", math.nan, ValueError),
    ("inf", math.inf, ValueError),
    ("minus-inf", -math.inf, ValueError),
    ("bool", True, TypeError),
    ("string", "1.0", TypeError),
    ("none", None, TypeError),
    ("complex", 1 + 0j, TypeError),
]


def _bad_cases():
    cases = []
    for key, (cls, prefix, valid, strict) in CLASSES.items():
        for name in valid:
            bad = list(ALWAYS_BAD)
            if name in strict:
                bad.append(("zero", 0.0, ValueError))
            if name == "damping_ratio":
                bad += [("one", 1.0, ValueError), ("above-one", 1.5, ValueError)]
            for label, value, exc in bad:
                cases.append(pytest.param(cls, prefix, valid, name, value, exc,
                                          id=f"{prefix}.{name}-{label}"))
    return cases


@pytest.mark.parametrize("cls, prefix, valid, name, value, exc", _bad_cases())
def test_bad_field_value_is_rejected_with_its_name(cls, prefix, valid, name, value, exc):
    """Every field rejects bad values; the message names the field and the value received."""
    kwargs = dict(valid, **{name: value})
    pattern = re.escape(f"{prefix}.{name}") + ".*" + re.escape(repr(value))
    with pytest.raises(exc, match=pattern):
        cls(**kwargs)


def _zero_allowed_cases():
    cases = []
    for key, (cls, prefix, valid, strict) in CLASSES.items():
        for name in valid:
            if name not in strict:
                cases.append(pytest.param(cls, valid, name, id=f"{prefix}.{name}"))
    return cases


@pytest.mark.parametrize("cls, valid, name", _zero_allowed_cases())
def test_zero_is_accepted_where_allowed(cls, valid, name):
    """Massless hub, zero radius, no friction or damping, zero mass at the root: all legal."""
    obj = cls(**dict(valid, **{name: 0}))
    value = getattr(obj, name)
    assert value == 0.0 and isinstance(value, float)


@pytest.mark.parametrize("value", [2, np.float64(2.0), np.int64(2)], ids=["int", "np-float",
                                                                         "np-int"])
def test_real_numbers_are_stored_as_float(value):
    hub = Hub(inertia=value, radius=value)
    assert type(hub.inertia) is float and hub.inertia == 2.0
    assert type(hub.radius) is float


@pytest.mark.parametrize("cls, valid", [(Hub, HUB), (Beam, BEAM), (PointMass, MASS)],
                         ids=["hub", "beam", "mass"])
def test_parameters_are_frozen(cls, valid):
    obj = cls(**valid)
    first = next(iter(valid))
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(obj, first, 1.0)


def test_system_is_frozen():
    system = HubBeam(hub=Hub(**HUB), beam=Beam(**BEAM))
    with pytest.raises(dataclasses.FrozenInstanceError):
        system.masses = (PointMass(**MASS),)


@pytest.mark.parametrize("cls, valid", [(Hub, HUB), (Beam, BEAM), (PointMass, MASS)],
                         ids=["hub", "beam", "mass"])
def test_parameters_are_keyword_only(cls, valid):
    with pytest.raises(TypeError):
        cls(*valid.values())


@pytest.mark.parametrize("obj, change, pattern", [
    (Hub(**HUB), {"inertia": -1.0}, r"hub\.inertia"),
    (Beam(**BEAM), {"length": 0.0}, r"beam\.length"),
    (Beam(**BEAM), {"damping_ratio": 1.0}, r"beam\.damping_ratio"),
    (PointMass(**MASS), {"position": -0.1}, r"mass\.position"),
], ids=["hub.inertia", "beam.length", "beam.damping_ratio", "mass.position"])
def test_replace_revalidates(obj, change, pattern):
    with pytest.raises(ValueError, match=pattern):
        dataclasses.replace(obj, **change)


def test_replace_system_revalidates_mass_positions():
    system = HubBeam(hub=Hub(**HUB), beam=Beam(**BEAM), masses=(PointMass(**MASS),))
    with pytest.raises(ValueError, match=r"masses\[0\]\.position"):
        dataclasses.replace(system, beam=dataclasses.replace(system.beam, length=1.0))


@pytest.mark.parametrize("position", [0.0, 0.9, BEAM["length"]], ids=["root", "mid", "tip"])
def test_mass_anywhere_on_the_beam_is_accepted(position):
    system = HubBeam(hub=Hub(**HUB), beam=Beam(**BEAM),
                     masses=(PointMass(mass=0.1, position=position),))
    assert system.masses[0].position == position


@pytest.mark.parametrize("position", [BEAM["length"] * (1 + 1e-9), BEAM["length"] + 1.0],
                         ids=["just-past-tip", "far-past-tip"])
def test_mass_beyond_the_tip_is_rejected(position):
    masses = (PointMass(mass=0.1, position=0.5), PointMass(mass=0.1, position=position))
    with pytest.raises(ValueError, match=r"masses\[1\]\.position.*beam\.length"):
        HubBeam(hub=Hub(**HUB), beam=Beam(**BEAM), masses=masses)


def test_mass_before_the_root_is_rejected():
    with pytest.raises(ValueError, match=r"mass\.position.*-0\.1"):
        PointMass(mass=0.1, position=-0.1)


@pytest.mark.parametrize("field, value, pattern", [
    ("hub", "hub", r"system\.hub"),
    ("beam", Hub(**HUB), r"system\.beam"),
    ("masses", 0.085, r"system\.masses"),
    ("masses", [0.085], r"system\.masses\[0\]"),
], ids=["hub-not-Hub", "beam-not-Beam", "masses-not-iterable", "masses-item-not-PointMass"])
def test_system_rejects_wrong_types(field, value, pattern):
    kwargs = dict(hub=Hub(**HUB), beam=Beam(**BEAM), masses=())
    kwargs[field] = value
    with pytest.raises(TypeError, match=pattern):
        HubBeam(**kwargs)


def test_masses_are_sorted_by_position_and_stored_as_tuple():
    positions = [1.5, 0.2, 1.8, 0.9]
    system = HubBeam(hub=Hub(**HUB), beam=Beam(**BEAM),
                     masses=[PointMass(mass=0.01 * (k + 1), position=p)
                             for k, p in enumerate(positions)])
    assert isinstance(system.masses, tuple)
    assert [m.position for m in system.masses] == sorted(positions)
    # each mass keeps its own value when reordered
    assert {(m.mass, m.position) for m in system.masses} == {
        (0.01 * (k + 1), p) for k, p in enumerate(positions)}


def test_beam_derived_quantities():
    beam = Beam(**BEAM)
    rho_a = BEAM["density"] * BEAM["area"]
    assert beam.linear_density == pytest.approx(rho_a, rel=DERIVED_RTOL)
    assert beam.bending_stiffness == pytest.approx(
        BEAM["youngs_modulus"] * BEAM["second_moment"], rel=DERIVED_RTOL)
    assert beam.mass == pytest.approx(rho_a * BEAM["length"], rel=DERIVED_RTOL)


def test_rigid_inertia_is_the_inertia_of_the_undeformed_system():
    """J_0 = J_h + int_0^l rhoA (b + x)^2 dx + sum m_k (b + d_k)^2 (MODEL.md section 2)."""
    masses = (PointMass(mass=0.085, position=1.62), PointMass(mass=0.3, position=0.4))
    system = HubBeam(hub=Hub(**HUB), beam=Beam(**BEAM), masses=masses)
    b, rho_a = HUB["radius"], system.beam.linear_density
    beam_part, _ = quad(lambda x: rho_a * (b + x) ** 2, 0.0, BEAM["length"], epsabs=0,
                        epsrel=1e-13)
    expected = HUB["inertia"] + beam_part + sum(m.mass * (b + m.position) ** 2 for m in masses)
    assert system.rigid_inertia == pytest.approx(expected, rel=DERIVED_RTOL)
    assert system.total_point_mass == pytest.approx(0.385, rel=DERIVED_RTOL)


def _parameter_classes():
    """The keyword-only parameter dataclasses users build by hand."""
    from controllers.feedback.lqg import NoiseLevels
    from controllers.feedback.lqr import LQRWeights
    from controllers.slew.reference import SlewProfile
    from controllers.slew.trajopt import SlewProblem
    from flexctl.model.actuators import DCMotor, ReactionWheel
    from flexctl.model.structure import Appendage, Structure
    from flexctl.sim.maneuvers import SineTorque, Slew, SpinUp, TorqueSamples
    from flexctl.sim.sensors import Sensors

    return [Hub, Beam, PointMass, HubBeam, Appendage, Structure, ReactionWheel, DCMotor,
            Sensors, SpinUp, SineTorque, Slew, TorqueSamples, LQRWeights, NoiseLevels,
            SlewProfile, SlewProblem]


@pytest.mark.parametrize("cls", _parameter_classes(), ids=lambda cls: cls.__name__)
def test_a_positional_call_says_keywords_only_and_shows_the_keyword_form(cls):
    from flexctl.model.errors import InputTypeError

    required = [f.name for f in dataclasses.fields(cls)
                if f.init and f.default is dataclasses.MISSING
                and f.default_factory is dataclasses.MISSING]
    with pytest.raises(InputTypeError) as caught:
        cls(2.5, 0.1)
    message = str(caught.value)
    assert message.startswith(f"{cls.__name__} takes keyword arguments only: {cls.__name__}(")
    assert message.endswith("got 2 positional: 2.5, 0.1"), message
    for name in required:
        assert f"{name}=..." in message, message
    assert "__init__" not in message and "were given" not in message


def test_keyword_only_parameters_still_copy_replace_and_pickle():
    import copy
    import pickle

    hub = Hub(**HUB)
    assert pickle.loads(pickle.dumps(hub)) == hub
    assert copy.deepcopy(hub) == hub
    assert dataclasses.replace(hub, radius=0.2).radius == 0.2
    with pytest.raises(ValueError, match=r"hub\.radius"):
        dataclasses.replace(hub, radius=-1.0)
