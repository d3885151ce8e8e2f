"""Spatial scenes (a 3 x 3 hub inertia) through ``flexctl run``: the scene format of MODEL.md
section 8 and the issue, its files, and its refusals by key."""

import csv
import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from flexctl.app.cli import main
from flexctl.app.scenes import load_scene
from flexctl.app.spatial_scene import SpatialScene
from flexctl.model.errors import InputError

SCENE = textwrap.dedent("""\
    [hub]
    inertia = [[1.30, 0.05, -0.02], [0.05, 1.16, 0.03], [-0.02, 0.03, 1.45]]
    radius = 0.06
    mass = 3.0
    support = "{support}"

    [[appendages]]
    name = "wing_a"
    direction = [0.0, 1.0, 0.0]
    normal = [0.0, 0.0, 1.0]
    length = 1.8
    density = 2766.0
    area = 2.5e-4
    youngs_modulus = 6.9e10
    second_moment = 5.2083e-10
    second_moment_lateral = 5.2083e-8
    shear_modulus = 2.6e10
    torsion_constant = 1.9531e-9
    [[appendages.masses]]
    mass = 0.085
    position = 1.62

    [[appendages]]
    name = "boom"
    direction = [0.0, 0.0, 1.0]
    normal = [1.0, 0.0, 0.0]
    length = 1.0
    density = 2766.0
    area = 2.5e-4
    youngs_modulus = 6.9e10
    second_moment = 5.2083e-10
    second_moment_lateral = 5.2083e-10
    shear_modulus = 2.6e10
    torsion_constant = 1.9531e-9

    [model]
    variant = "exact"
    modes = 2

    [initial]
    angular_velocity = [0.0, 0.0, 0.5]

    [maneuver]
    kind = "torque_samples"
    file = "torque.csv"
    interpolation = "{interpolation}"

    [simulation]
    t_final = 1.0
    output_step = 0.01
    rtol = 1e-8
    """)

TORQUE = "t, tx, ty, tz\n0.0, 0.0, 0.0, 0.0\n0.2, 0.4, -0.2, 0.6\n0.6, 0.4, -0.2, 0.6\n0.8, 0.0, 0.0, 0.0\n"


def write_scene(folder: Path, support="pinned", interpolation="linear") -> Path:
    text = SCENE.format(support=support, interpolation=interpolation)
    (folder / "torque.csv").write_text(TORQUE)
    path = folder / "craft.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("support", ["pinned", "free"])
def test_a_spatial_scene_runs_and_writes_the_named_columns(tmp_path, support, capsys):
    path = write_scene(tmp_path, support=support)
    scene = load_scene(path)
    assert isinstance(scene, SpatialScene) and scene.n_modes == 2
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "spatial, exact" in printed and "wing_a" in printed
    with open(out / "timeseries.csv") as handle:
        rows = list(csv.reader(handle))
    header = rows[0]
    expected = ["t", "qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    expected += ["hub_x", "hub_y", "hub_z"] if support == "free" else []
    expected += ["tx", "ty", "tz"]
    expected += [f"{a}.tip_{c}" for a in ("wing_a", "boom") for c in ("dx", "dy", "dz")]
    assert header == expected
    table = np.array(rows[1:], dtype=float)
    assert table[0, 0] == 0.0 and table[-1, 0] == pytest.approx(1.0)
    np.testing.assert_allclose(np.linalg.norm(table[:, 1:5], axis=1), 1.0, atol=1e-12)
    column = dict(zip(header, table.T))
    # the torque file's line, read back at the output times
    np.testing.assert_allclose(column["tz"], np.interp(column["t"], [0, 0.2, 0.6, 0.8, 1.0],
                                                       [0, 0.6, 0.6, 0, 0]), atol=1e-12)
    # the structure moved and bent in all three directions of both appendages
    for name in ("wing_a", "boom"):
        for c in ("dx", "dy", "dz"):
            assert np.max(np.abs(column[f"{name}.tip_{c}"])) > 0, (name, c)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["spatial"] is True
    assert summary["peak_tip_deflection"] == pytest.approx(max(
        np.max(np.abs(column[f"{a}.tip_{c}"])) for a in ("wing_a", "boom")
        for c in ("dx", "dy", "dz")), rel=1e-9)
    assert summary["integration_error"] < 1e-4
    # the run's summary is a scene that runs again, to the same numbers
    again = tmp_path / "again"
    assert main(["run", str(out / "summary.json"), "--out", str(again)]) == 0
    assert (again / "timeseries.csv").read_text() == (out / "timeseries.csv").read_text()


@pytest.mark.slow
def test_a_spatial_scene_runs_the_variant_it_names(tmp_path, capsys):
    """``model.variant = "zero_order"`` runs the zero_order model, and says so."""
    path = write_scene(tmp_path)
    path.write_text(path.read_text().replace('variant = "exact"', 'variant = "zero_order"')
                    .replace("t_final = 1.0", "t_final = 0.3"))
    scene = load_scene(path)
    assert scene.variant == "zero_order"
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 0
    assert "spatial, zero_order" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["variant"] == "zero_order"
    assert summary["scene_table"]["model"]["variant"] == "zero_order"


@pytest.mark.parametrize("old, new, pattern", [
    ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.5, 1.0]", r"appendages\.0\.normal"),
    ("modes = 2", "modes = 0", r"model\.modes"),
    ('variant = "exact"', 'variant = "consistent"',
     r"model\.variant must be one of 'exact', 'first_order', 'zero_order'.*'consistent'"),
    ("radius = 0.06", "radius = 0.06\nspin = 1", r"hub\.spin"),
    ("length = 1.0", "length = -1.0", r"appendages\.1\.length"),
    ("angular_velocity = [0.0, 0.0, 0.5]", "angular_velocity = [0.0, 0.5]",
     r"initial\.angular_velocity"),
    ('file = "torque.csv"', 'file = "missing.csv"', r"maneuver\.file"),
    ("[0.05, 1.16, 0.03]", "[0.05, 1.16, 0.3]", r"hub\.inertia.*symmetric"),
    ("t_final = 1.0", "t_final = 0.0", r"simulation\.t_final"),
    ('kind = "torque_samples"', 'kind = "slew"', r"maneuver\.kind"),
], ids=["normal not perpendicular", "no modes", "another variant", "unknown hub key",
        "negative length", "short angular velocity", "missing torque file",
        "asymmetric inertia", "no time", "unknown manoeuvre"])
def test_a_bad_spatial_scene_is_refused_by_its_key(tmp_path, old, new, pattern):
    path = write_scene(tmp_path)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(InputError, match=pattern):
        load_scene(path)


@pytest.mark.parametrize("content, pattern", [
    ("t, torque\n0, 1\n", "header"),
    ("t, tx, ty, tz\n0, 1, 2\n", "four finite numbers"),
    ("t, tx, ty, tz\n0, 1, 2, nan\n", "four finite numbers"),
    ("t, tx, ty, tz\n0, 1, 2, 3\n0, 1, 2, 3\n", "strictly increasing"),
    ("t, tx, ty, tz\n", "no samples"),
], ids=["planar header", "three columns", "NaN", "repeated time", "empty"])
def test_a_bad_torque_file_is_refused_by_name(tmp_path, content, pattern):
    path = write_scene(tmp_path)
    (tmp_path / "torque.csv").write_text(content)
    with pytest.raises(InputError, match=pattern):
        load_scene(path)


def test_a_held_table_holds_each_value_until_the_next_sample(tmp_path):
    from flexctl.sim.spatial_run import VectorTorque

    path = write_scene(tmp_path, interpolation="hold")
    torque = load_scene(path).maneuver
    assert isinstance(torque, VectorTorque) and torque.interpolation == "hold"
    np.testing.assert_array_equal(torque(0.1), [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(torque(0.2), [0.4, -0.2, 0.6])
    np.testing.assert_array_equal(torque(0.79), [0.4, -0.2, 0.6])
    np.testing.assert_array_equal(torque(5.0), [0.0, 0.0, 0.0])


EXAMPLE_SCENES = sorted((Path(__file__).resolve().parents[2] / "examples" / "scenes")
                        .glob("spatial-*.toml"))


@pytest.mark.parametrize("path", EXAMPLE_SCENES, ids=lambda p: p.stem)
def test_the_example_spatial_scenes_load(path):
    scene = load_scene(path)
    assert isinstance(scene, SpatialScene) and scene.t_final > 0
    assert len(scene.structure.appendages) >= 2


def test_there_are_example_spatial_scenes():
    assert len(EXAMPLE_SCENES) >= 2
