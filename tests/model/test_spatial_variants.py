"""The spatial model's first_order and zero_order variants (MODEL.md sections 4 and 8): the exact
equations expanded to first order in the deflections.

- Moving in one plane they are MODEL.md section 4's equations (docs/theory/free_hub.md's on a
  free hub): to round-off with the matrices summed on the spatial model's own quadrature (each
  rod's ``PanelRule``), and to that quadrature's accuracy against flexctl's planar models, whose
  matrices are integrated to round-off by another rule (Gauss-Legendre per piece).
- Linearised about the straight structure, at rest or spinning, first_order is the exact model
  to round-off; zero_order is too at rest, and spinning about an axis perpendicular to a rod
  faster than its first clamped bending frequency it diverges where the others do not.
- Simulated, first_order's tips follow the exact model's for a small manoeuvre and leave them
  for a large one.

Run with ``-s`` to see the measured agreements.
"""

import functools
import math

import casadi as ca
import numpy as np
import pytest

import flexctl
from flexctl.model.errors import InputError
from flexctl.model.exact import PANEL_TOLERANCE
from flexctl.model.parameters import PointMass
from flexctl.model.spatial_dynamics import spatial_equations
from flexctl.model.spatial_plant import linearize_spatial, nonlinear_spatial
from flexctl.model.spatial_rod import Rod, elastic_matrices, rod_rule, rod_shapes
from flexctl.model.spatial_structure import SpatialHub, SpatialStructure
from flexctl.model.structure import as_structure
from flexctl.sim.spatial_run import VectorTorque, simulate_spatial
from tests.model.test_spatial_model import (PLANAR_CASES, TILTED_INERTIA, _planar_to_spatial,
                                            _spatial_name, wing)

VARIANTS = ("first_order", "zero_order")
#: Spatial accelerations against MODEL.md section 4's on the same quadrature, relative to the
#: largest (round-off: measured at most 3e-14, on the massless hub).
ROUND_OFF = 1e-12
#: Spatial accelerations against flexctl's planar first_order and zero_order, relative to the
#: largest: the planar matrices are integrated to round-off (Gauss-Legendre, N + 24 points per
#: piece between point masses), the spatial ones on the exact model's panels, chosen to agree
#: with a converged rule to PANEL_TOLERANCE (1e-5) of the exact accelerations. The matrices
#: then differ by up to 2.4e-7 (M_ff) and 8e-6 (K_g, with the tip mass) relative, the
#: accelerations by 1.8e-6 at most (measured, at spins to 6 rad/s).
QUADRATURE = PANEL_TOLERANCE
#: The linear plants of first_order and exact (and zero_order's at rest), entry by entry
#: relative to the largest entry of the exact plant's matrix (round-off: measured 1.2e-15).
LINEAR_ROUND_OFF = 1e-12
PINNED = sorted(name for name, system in PLANAR_CASES.items()
                if as_structure(system).hub.support == "pinned")


def _draw_state(names, rng, spin: float) -> np.ndarray:
    """A planar state (flexctl's layout): strongly deflected, hub rate ``spin`` plus noise."""
    x = rng.normal(size=len(names))
    for k, name in enumerate(names):
        field = name.rpartition(".")[2]
        if field.startswith("q") and not field.endswith("_dot"):
            x[k] *= 0.3 / int(field[1:]) ** 2
    x[list(names).index("theta_dot")] += spin
    return x


def _rule_matrices(appendage, hub, n_modes: int) -> dict:
    """MODEL.md section 3's matrices of a rod's normal bending, summed on the spatial model's
    quadrature: the rod's nodes (weights ``rhoA w``) and point masses, the lateral deflection
    and the foreshortening as the rule's cumulative integrals of the slopes, as the exact
    rod integrates them. ``K_a`` is the geometric stiffness per unit axial acceleration (the
    mass outboard of each point, in place of ``n(x)``)."""
    rule = rod_rule(appendage, hub, n_modes)
    rod = Rod(appendage, rule, n_modes, appendage.root_point(hub))
    cumulative = np.array(rod.integrate(ca.DM.eye(rule.nodes.size)))   # (n + K, n)
    slope = rod_shapes(appendage.length, n_modes, tuple(map(float, rule.nodes)))["slope"]
    shape = cumulative @ slope                                        # (n + K, N)
    mu = np.concatenate([appendage.linear_density * rule.weights,
                         [m.mass for m in appendage.masses]])
    radius = np.linalg.norm(appendage.root_point(hub)) + cumulative.sum(axis=1)
    block = slice(0, n_modes)                                         # qn
    return dict(J=mu @ radius ** 2, m_tf=shape.T @ (mu * radius),
                M_ff=shape.T @ (mu[:, None] * shape), first=mu @ radius, s=shape.T @ mu,
                K_g=slope.T @ ((cumulative.T @ (mu * radius))[:, None] * slope),
                K_a=slope.T @ ((cumulative.T @ mu)[:, None] * slope),
                K=elastic_matrices(appendage, n_modes)[0][block, block],
                e1=appendage.direction[:2], normal=appendage.normal[:2])


def _section_4(structure, n_modes: int, variant: str, theta_t: float, q, q_t,
               torque: float, axial: bool = True) -> np.ndarray:
    """``(theta_tt, [a_x, a_y], q_tt...)`` of MODEL.md section 4's equations (free hub:
    docs/theory/free_hub.md section 3, ``a`` the centre's acceleration in hub axes) with
    :func:`_rule_matrices`; ``axial`` adds the tension of a free hub's own
    acceleration, ``-(a . e1) K_a q``, to first_order's rods."""
    parts = [_rule_matrices(a, structure.hub, n_modes) for a in structure.appendages]
    free, n = structure.hub.free, n_modes
    h = 3 if free else 1
    size = h + n * len(parts)
    mass, force = np.zeros((size, size)), np.zeros(size)
    mass[0, 0] = structure.hub.inertia[2, 2] + sum(p["J"] for p in parts)
    force[0] = torque
    first = sum(p["first"] * p["e1"] + (p["s"] @ q[k]) * p["normal"]     # S, hub axes
                for k, p in enumerate(parts))
    if free:
        mass[1:3, 1:3] = structure.total_mass * np.eye(2)
        mass[0, 1:3] = mass[1:3, 0] = [-first[1], first[0]]           # e_z x S
        velocity = sum((p["s"] @ q_t[k]) * p["normal"] for k, p in enumerate(parts))
        force[1:3] = theta_t ** 2 * first - 2 * theta_t * np.array([-velocity[1], velocity[0]])
    for k, p in enumerate(parts):
        rows = slice(h + k * n, h + (k + 1) * n)
        mass[0, rows] = mass[rows, 0] = p["m_tf"]
        mass[rows, rows] = p["M_ff"]
        spin = p["M_ff"] - p["K_g"] if variant == "first_order" else p["M_ff"]
        force[rows] = -(p["K"] - theta_t ** 2 * spin) @ q[k]
        if free:
            mass[1:3, rows] = np.outer(p["normal"], p["s"])
            mass[rows, 1:3] = np.outer(p["s"], p["normal"])
            if axial and variant == "first_order":
                mass[rows, 1:3] -= np.outer(p["K_a"] @ q[k], p["e1"])
    return np.linalg.solve(mass, force)


def _spatial_rates(equations, names, x, torque: float) -> tuple:
    """The spatial model's accelerations at planar state ``x`` (flexctl's layout) in the
    unknowns of :func:`_section_4`, and the rates that would leave the plane."""
    layout = equations.layout
    index = dict(zip(layout.state_names, range(layout.n_states)))
    state = _planar_to_spatial(names, layout, x)
    rate = equations.rhs(state, [0.0, 0.0, torque]).full().ravel()
    wz = state[index["wz"]]
    picked = [rate[index["wz"]]]
    if layout.free:                     # a = v_t + w x v, hub axes
        vx, vy = state[index["hub_vx"]], state[index["hub_vy"]]
        picked += [rate[index["hub_vx"]] - wz * vy, rate[index["hub_vy"]] + wz * vx]
    picked += [rate[index[_spatial_name(n)]] for n in names
               if n.endswith("_dot") and n.rpartition(".")[2].startswith("q")]
    out_of_plane = [index[n] for n in layout.state_names if ".ql" in n or ".qt" in n]
    out_of_plane += [index["wx"], index["wy"]]
    return np.array(picked), rate[out_of_plane]


def _planar_parts(names, x, n_modes: int) -> tuple:
    """``(theta_t, q, q_t)`` of a planar state ``x`` (flexctl's layout), ``q`` and ``q_t``
    one array per appendage."""
    value = dict(zip(names, x))
    modal = [n for n in names if n.rpartition(".")[2].startswith("q") and "_dot" not in n]
    q = np.array([value[n] for n in modal]).reshape(-1, n_modes)
    q_t = np.array([value[f"{n}_dot"] for n in modal]).reshape(-1, n_modes)
    return value["theta_dot"], q, q_t


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("case", sorted(PLANAR_CASES))
def test_in_one_plane_the_variants_are_section_4_on_the_same_quadrature(case, variant):
    """Accelerations of the spatial variant, built from a planar structure at strongly
    deflected, fast states, equal MODEL.md section 4's (free hub: with the tension of its own
    acceleration) with the matrices summed on the rods' own quadrature, to round-off; nothing
    leaves the plane."""
    system = PLANAR_CASES[case]
    n_modes = 3
    structure = SpatialStructure.from_planar(system)
    equations = spatial_equations(structure, n_modes, variant)
    names = flexctl.build_model(system, n_modes=n_modes, variant=variant).layout.names
    rng = np.random.default_rng(4)
    worst = 0.0
    for spin in (0.0, 3.0, 6.0):
        x = _draw_state(names, rng, spin)
        torque = float(rng.normal())
        got, leaving = _spatial_rates(equations, names, x, torque)
        theta_t, q, q_t = _planar_parts(names, x, n_modes)
        expected = _section_4(structure, n_modes, variant, theta_t, q, q_t, torque)
        scale = np.max(np.abs(expected))
        worst = max(worst, np.max(np.abs(got - expected)) / scale)
        assert np.max(np.abs(leaving)) <= 1e-12 * scale
    print(f"\n{variant}, {case}: section 4 on the same quadrature within {worst:.2g}")
    assert worst <= ROUND_OFF


def _planar_rates(model, x, torque: float) -> np.ndarray:
    """flexctl's planar accelerations at ``x`` in the unknowns of :func:`_section_4`."""
    names = model.layout.names
    value = dict(zip(names, np.asarray(model.dynamics(0.0, x, torque)).ravel()))
    picked = [value["theta_dot"]]
    if "hub_x_dot" in value:            # the centre's inertial acceleration, in hub axes
        theta = x[list(names).index("theta")]
        c, s = math.cos(theta), math.sin(theta)
        ax, ay = value["hub_x_dot"], value["hub_y_dot"]
        picked += [c * ax + s * ay, -s * ax + c * ay]
    picked += [value[n] for n in names if n.endswith("_dot")
               and n.rpartition(".")[2].startswith("q")]
    return np.array(picked)


def _against_planar(case: str, variant: str, n_modes: int = 3):
    """``(spatial, planar, section 4 without the axial term)`` accelerations at a few states."""
    system = PLANAR_CASES[case]
    structure = SpatialStructure.from_planar(system)
    equations = spatial_equations(structure, n_modes, variant)
    planar = flexctl.build_model(system, n_modes=n_modes, variant=variant)
    names = planar.layout.names
    rng = np.random.default_rng(5)
    rows = []
    for spin in (0.0, 3.0, 6.0):
        x = _draw_state(names, rng, spin)
        torque = float(rng.normal())
        theta_t, q, q_t = _planar_parts(names, x, n_modes)
        rows.append((_spatial_rates(equations, names, x, torque)[0],
                     _planar_rates(planar, x, torque),
                     _section_4(structure, n_modes, variant, theta_t, q, q_t, torque,
                                axial=False)))
    return rows


def _relative(pairs) -> float:
    return max(np.max(np.abs(a - b)) / np.max(np.abs(b)) for a, b in pairs)


@pytest.mark.parametrize("variant, case", [(v, c) for v in VARIANTS for c in sorted(PLANAR_CASES)
                                           if v == "zero_order" or c in PINNED])
def test_in_one_plane_the_variants_are_the_planar_models(case, variant):
    """The spatial variant's accelerations, built from a planar structure, are flexctl's planar
    first_order's or zero_order's, to the accuracy of the spatial model's quadrature."""
    rows = _against_planar(case, variant)
    worst = _relative([(spatial, planar) for spatial, planar, _ in rows])
    print(f"\n{variant}, {case}: the planar model within {worst:.2g}")
    assert worst <= QUADRATURE


def test_a_free_hubs_own_acceleration_stiffens_first_orders_rods():
    """On a free hub the centre's acceleration along a rod loads it axially (``-(a . e1) K_a
    q``): the first-order expansion of the exact equations keeps that stiffening, flexctl's
    planar free-hub first_order (docs/theory/free_hub.md section 3) leaves it out. Without it,
    section 4 on the spatial quadrature is the planar model; the spatial first_order, which
    equals section 4 with it to round-off, then differs from the planar model by far more than
    the quadrature."""
    rows = _against_planar("free hub, two beams", "first_order")
    without = _relative([(reduced, planar) for _, planar, reduced in rows])
    spatial = _relative([(spatial, planar) for spatial, planar, _ in rows])
    print(f"\nfree hub: planar first_order within {without:.2g} of section 4 without the "
          f"axial term, {spatial:.2g} of the spatial first_order")
    assert without <= QUADRATURE
    assert spatial > 1e3 * QUADRATURE


def _spinner(support: str = "pinned") -> SpatialStructure:
    """Two arrays along +-y (soft along z, tip masses) and two booms along +-z (soft along x)
    on a hub whose x axis is the structure's major principal axis: a steady spin about x
    keeps every rod straight, its centre of mass at the hub's centre."""
    tip = (PointMass(mass=0.085, position=1.62),)
    hub = SpatialHub(inertia=np.diag([2.5, 1.2, 1.3]), radius=0.06, mass=3.0, support=support)
    return SpatialStructure(hub=hub, appendages=(
        wing("a", masses=tip), wing("b", direction=(0.0, -1.0, 0.0), masses=tip),
        wing("c", direction=(0.0, 0.0, 1.0), normal=(1.0, 0.0, 0.0), length=1.0),
        wing("d", direction=(0.0, 0.0, -1.0), normal=(1.0, 0.0, 0.0), length=1.0)))


def _first_frequency(appendage) -> float:
    """The first clamped frequency of the bare rod's bending along its normal, rad/s (its tip
    mass lowers it)."""
    return 1.8751040687 ** 2 * math.sqrt(appendage.beam_normal.bending_stiffness / (
        appendage.linear_density * appendage.length ** 4))


@functools.lru_cache(maxsize=8)
def _plants(support: str, ratio: float) -> tuple:
    """``(spin, {variant: plant})`` of :func:`_spinner` about its x axis at ``ratio`` times
    the arrays' first clamped frequency (2 modes per field)."""
    structure = _spinner(support)
    spin = ratio * _first_frequency(structure.appendages[0])
    return spin, {v: linearize_spatial(structure, 2, (spin, 0.0, 0.0), variant=v)
                  for v in ("exact", *VARIANTS)}


@pytest.mark.parametrize("support", ["pinned", "free"])
@pytest.mark.parametrize("ratio", [0.0, 0.5, 1.5], ids=["at rest", "slow spin", "fast spin"])
def test_first_orders_linear_plant_is_the_exact_ones(support, ratio):
    """About the straight structure, at rest or spinning about its major axis (below and above
    the arrays' first clamped frequency), first_order's plant is the exact model's to round-off
    (both are the exact equations to first order); zero_order's is too at rest, and differs
    spinning (no centrifugal stiffening)."""
    spin, plants = _plants(support, ratio)
    exact = plants["exact"]

    def difference(variant):
        return max(np.max(np.abs(getattr(plants[variant], m) - getattr(exact, m)))
                   / np.max(np.abs(getattr(exact, m))) for m in ("A", "B", "C", "D")
                   if np.any(getattr(exact, m)))

    print(f"\n{support}, spin {spin:.3g} rad/s: first_order's plant within "
          f"{difference('first_order'):.2g} of the exact one, zero_order's "
          f"{difference('zero_order'):.2g}")
    assert difference("first_order") <= LINEAR_ROUND_OFF
    assert plants["first_order"].state_labels == exact.state_labels
    assert plants["first_order"].output_labels == exact.output_labels
    if spin == 0.0:
        assert difference("zero_order") <= LINEAR_ROUND_OFF
    else:
        assert difference("zero_order") > 1e3 * LINEAR_ROUND_OFF


@pytest.mark.parametrize("ratio, zero_order_diverges", [(0.5, False), (1.5, True)],
                         ids=["below", "above"])
def test_zero_order_diverges_spinning_above_the_first_clamped_frequency(ratio,
                                                                       zero_order_diverges):
    """Spinning about an axis perpendicular to the arrays (in their soft bending plane) at 1.5
    times the bare arrays' first clamped bending frequency, zero_order's plant has an
    eigenvalue of positive real part (its stiffness ``K - w^2 M`` has turned indefinite),
    first_order's and the exact one's stay on the imaginary axis (to round-off); at half that
    frequency all three do."""
    spin, plants = _plants("pinned", ratio)
    growth = {}
    for variant, plant in plants.items():
        eigenvalues = np.linalg.eigvals(plant.A)
        growth[variant] = np.max(eigenvalues.real) / np.max(np.abs(eigenvalues))
    print(f"\nspin {spin:.3g} rad/s: largest real part / largest modulus {growth}")
    assert growth["exact"] <= 1e-12 and growth["first_order"] <= 1e-12
    assert (growth["zero_order"] > 1e-4) == zero_order_diverges
    assert zero_order_diverges or growth["zero_order"] <= 1e-12


def _manoeuvre(scale: float, variant: str):
    """The tilted three-appendage structure under a half sine of the hub torque about all
    three axes over 1 s, ``scale`` times (1e-3, -2e-3, 1.5e-3) N m (2 modes per field)."""
    from tests.model.test_spatial_model import _tumbling

    times = np.linspace(0.0, 1.0, 101)
    push = scale * np.outer(np.sin(np.pi * times), [1e-3, -2e-3, 1.5e-3])
    result = simulate_spatial(_tumbling(), 1.0, VectorTorque(times, push), n_modes=2,
                              output_step=0.01, rtol=1e-10, check_accuracy=False,
                              variant=variant)
    assert result.status == "ok", result.message
    assert result.variant == variant
    return result


def _tip_difference(scale: float) -> tuple:
    """``(largest tip difference of first_order from exact relative to each tip's peak,
    largest peak tip displacement relative to the rod's length)``."""
    exact, first = _manoeuvre(scale, "exact"), _manoeuvre(scale, "first_order")
    lengths = {a.name: a.length for a in exact.structure.appendages}
    worst = max(np.max(np.abs(first.tips[n] - exact.tips[n])) / np.max(np.abs(exact.tips[n]))
                for n in exact.structure.names)
    reach = max(np.max(np.abs(exact.tips[n])) / lengths[n] for n in exact.structure.names)
    return worst, reach


#: first_order's tips against the exact model's for the small manoeuvre (tips to 1e-5 of the
#: length), relative to each tip's peak: measured 3.0e-8, the integration's error at rtol
#: 1e-10 (the models' own difference, second order in the deflection, extrapolates to 3e-10).
SMALL_MANOEUVRE = 1e-7


@pytest.mark.slow
def test_first_orders_tips_follow_the_exact_ones_for_a_small_manoeuvre():
    worst, reach = _tip_difference(1.0)
    print(f"\nsmall manoeuvre (tips to {reach:.2g} of the length): first_order within "
          f"{worst:.2g} of the exact tips")
    assert reach < 2e-5
    assert worst <= SMALL_MANOEUVRE


@pytest.mark.slow
def test_first_orders_tips_leave_the_exact_ones_for_a_large_manoeuvre():
    """3000 times the torque bends the tips to 3 % of the length: first_order's tips then
    differ from the exact model's by 2.3e-3 of their peak (measured; 2.8e-5 at 0.3 % and
    2.8e-4 at 1 %: second order in the deflection), far beyond the small manoeuvre's."""
    worst, reach = _tip_difference(3000.0)
    print(f"\nlarge manoeuvre (tips to {reach:.2g} of the length): first_order "
          f"{worst:.2g} from the exact tips")
    assert reach > 0.02
    assert worst > 1e3 * SMALL_MANOEUVRE


@pytest.mark.parametrize("call, pattern", [
    (lambda s: spatial_equations(s, 1, "consistent"),
     r"spatial_equations\.variant must be one of 'exact', 'first_order', 'zero_order'; got "
     r"'consistent'"),
    (lambda s: spatial_equations(s, 1, 1),
     r"spatial_equations\.variant must be one of .*; got 1 of type int"),
    (lambda s: linearize_spatial(s, 1, variant="Exact"),
     r"linearize_spatial\.variant must be one of .*; got 'Exact'"),
    (lambda s: nonlinear_spatial(s, 1, variant="zero-order"),
     r"nonlinear_spatial\.variant must be one of .*; got 'zero-order'"),
    (lambda s: simulate_spatial(s, 1.0, variant=None),
     r"variant must be one of 'exact', 'first_order', 'zero_order'; got None"),
], ids=["planar only", "not a string", "capitalised", "hyphen", "None"])
def test_a_bad_variant_is_refused_by_name(call, pattern):
    structure = SpatialStructure(hub=SpatialHub(inertia=TILTED_INERTIA, radius=0.06),
                                 appendages=(wing(),))
    with pytest.raises(InputError, match=pattern):
        call(structure)


def test_the_variants_are_kept_apart():
    """Each variant's functions are built once and kept under their own key."""
    structure = _spinner()
    built = {v: spatial_equations(structure, 1, v) for v in ("exact", *VARIANTS)}
    assert len({id(e) for e in built.values()}) == 3
    assert all(e.variant == v and spatial_equations(structure, 1, v) is e
               for v, e in built.items())
    assert nonlinear_spatial(structure, 1, "zero_order").name == "spatial_nonlinear_zero_order_N1"
