"""The state layout owns the names and slices of the state; nothing else slices it by index
arithmetic."""

import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from flexctl import build_model, load_scene
from flexctl.model.errors import InputValueError
from flexctl.model.layout import StateLayout

ROOT = Path(__file__).resolve().parents[2]

#: Index arithmetic on a state vector: a subscript or ``np.r_`` that offsets a mode count by
#: the hub's one or two entries (``x[1:n + 1]``, ``x[n + 2:]``, ``np.r_[0:m + 1, ...]``), a
#: state size written as ``2 n + 2``, or a plant/controller split at ``nx``.
STATE_ARITHMETIC = [
    re.compile(r"\[[^\]\n]*\b(n|nm|nd|m|n_modes|n_design|n_plant|\w+\.n_modes)\s*\+\s*[12]\b"),
    re.compile(r"\b2\s*\*\s*(n|n_modes|\w+\.n_modes)\s*\+\s*2\b"),
    re.compile(r"\[\s*:\s*nx\s*\]|\[\s*nx\s*:\s*\]"),
]
#: The one module allowed to do it.
OWNER = ROOT / "flexctl" / "model" / "layout.py"


def arithmetic_lines(path: Path) -> list:
    """``(line number, text)`` of the lines of ``path`` that slice a state by arithmetic
    (comments and docstring text included: an example there is code a reader copies)."""
    found = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if any(p.search(line) for p in STATE_ARITHMETIC):
            found.append((number, line.strip()))
    return found


SOURCES = sorted(p for package in ("flexctl", "controllers")
                 for p in (ROOT / package).rglob("*.py") if p != OWNER)


@pytest.mark.parametrize("path", SOURCES, ids=[str(p.relative_to(ROOT)) for p in SOURCES])
def test_no_module_slices_the_state_by_index_arithmetic(path):
    lines = arithmetic_lines(path)
    assert not lines, f"{path.relative_to(ROOT)} slices the state itself: {lines}"


def test_the_arithmetic_check_catches_the_old_forms(tmp_path):
    source = tmp_path / "mod.py"
    source.write_text("q = x[1:n + 1]\nw = x[model.n_modes + 1]\nrows = np.r_[0:m + 1, n + 1:]\n"
                      "a = np.zeros(2 * n + 2)\nz = y[nx:]\nk = range(1, n + 1)\n")
    assert [n for n, _ in arithmetic_lines(source)] == [1, 2, 3, 4, 5]


def test_single_appendage_names_and_slices_are_the_models():
    model = build_model(load_scene("hub-beam-mass").system, n_modes=3)
    layout = model.layout
    assert layout.names == model.state_names == (
        "theta", "q1", "q2", "q3", "theta_dot", "q1_dot", "q2_dot", "q3_dot")
    x = np.arange(8.0)
    theta, q, rate, q_dot = layout.split(x)
    assert theta == 0.0 and rate == 4.0
    np.testing.assert_array_equal(q, [1, 2, 3])
    np.testing.assert_array_equal(q_dot, [5, 6, 7])
    np.testing.assert_array_equal(layout.join(theta=theta, q=q, theta_dot=rate, q_dot=q_dot), x)


def test_blocks_partition_the_state():
    layout = StateLayout(appendages=(("wing_a", 3), ("wing_b", 2)), free_hub=True) \
        .with_block("wheel", ("wheel_speed", "wheel_torque"))
    covered = np.zeros(layout.n_states, dtype=int)
    for part in (layout.theta, layout.hub_position, layout.q, layout.theta_dot,
                 layout.hub_velocity, layout.q_dot, layout.block("wheel")):
        covered[part] += 1
    assert np.all(covered == 1)
    assert layout.names[layout.modal_slice("wing_b")] == ("wing_b.q1", "wing_b.q2")
    assert layout.names[layout.modal_rate_slice("wing_a")][0] == "wing_a.q1_dot"
    assert layout.names[layout.hub_velocity] == ("hub_x_dot", "hub_y_dot")
    assert len(set(layout.names)) == layout.n_states


def test_without_rotation_keeps_every_other_mechanical_state():
    layout = StateLayout(appendages=(("a", 2), ("b", 1)), free_hub=True)
    beam = layout.without_rotation()
    assert tuple(layout.names[i] for i in layout.beam) == beam.names
    y = np.arange(float(beam.n_states))
    full = layout.from_beam(y, theta=7.0, theta_dot=8.0)
    np.testing.assert_array_equal(full[layout.beam], y)
    assert full[layout.theta] == 7.0 and full[layout.theta_dot] == 8.0


def test_projection_takes_each_appendages_first_modes():
    plant = StateLayout(appendages=(("a", 4), ("b", 3)))
    design = plant.with_modes((2, 1))
    rows = plant.projection(design)
    assert tuple(plant.names[i] for i in rows) == design.names
    with pytest.raises(InputValueError, match="modes"):
        design.projection(plant)


def test_accessors_work_on_batches_and_casadi_symbols():
    layout = StateLayout.single(2)
    batch = np.arange(18.0).reshape(6, 3)
    np.testing.assert_array_equal(layout.modal(batch), batch[1:3])
    symbol = ca.SX.sym("x", 6)
    rebuilt = layout.join(theta=layout.hub_angle(symbol), q=layout.modal(symbol),
                          theta_dot=layout.hub_rate(symbol), q_dot=layout.modal_rates(symbol))
    assert ca.is_equal(ca.simplify(rebuilt - symbol), ca.SX.zeros(6), 1)


@pytest.mark.parametrize("appendages, match", [
    ((), "at least one"),
    ((("a", 2), ("a", 1)), "unique"),
    ((("", 2), ("b", 1)), "identifiers"),
    ((("a", 0),), "n_modes"),
], ids=["none", "duplicate", "unnamed-among-several", "no-modes"])
def test_bad_layouts_are_refused_by_name(appendages, match):
    with pytest.raises(InputValueError, match=match):
        StateLayout(appendages=appendages)


@pytest.mark.parametrize("kwargs", [
    dict(appendages="abc"), dict(appendages=None), dict(appendages=(("a", 2.0),)),
    dict(appendages=(("a", 10 ** 30),)), dict(appendages=(("a.b", 1),)), dict(extra=5),
    dict(extra=(("w", 5),)), dict(extra=(("w", ("theta",)),)), dict(free_hub="yes"),
], ids=["string", "none", "float-modes", "huge-modes", "dotted-name", "extra-number",
        "extra-labels-number", "clashing-label", "free-hub-string"])
def test_hostile_layouts_get_a_clear_error(kwargs):
    from flexctl.model.errors import InputError
    with pytest.raises(InputError, match="StateLayout"):
        StateLayout(**kwargs)


@pytest.mark.parametrize("call", [
    lambda layout: layout.embed(np.ones(5)),
    lambda layout: layout.from_beam(np.ones(3)),
    lambda layout: layout.projection("design"),
    lambda layout: layout.join(q=np.ones(5)),
    lambda layout: layout.modal_slice(["wing"]),
], ids=["embed-size", "from-beam-size", "projection-type", "join-size", "unhashable-name"])
def test_layout_accessors_refuse_misuse_by_name(call):
    from flexctl.model.errors import InputError
    with pytest.raises(InputError):
        call(StateLayout.single(2))
