"""A spatial scene with a cluster of reaction wheels (``[actuator] kind = "wheels"``): the
scene form of the issue, the columns it writes, the arrangements, and refusals by key."""

import csv
import json
import textwrap
from pathlib import Path

import numpy as np
import pytest
from spatial_craft import CRAFT_TOML

from flexctl.app.cli import main
from flexctl.app.scenes import load_scene
from flexctl.app.spatial_scene import SpatialScene
from flexctl.model.errors import InputError

SCENE = CRAFT_TOML + textwrap.dedent("""\
    [model]
    modes = 1

    [actuator]
    kind = "wheels"
    distribution = "pseudo_inverse"
    [[actuator.wheels]]
    axis = [1.0, 0.0, 0.0]
    inertia = 0.01
    torque_limit = 0.2
    speed_limit = 314.16
    time_constant = 0.0
    coulomb_friction = 2e-3
    viscous_friction = 2e-5
    [[actuator.wheels]]
    axis = [0.0, 1.0, 0.0]
    inertia = 0.01
    torque_limit = 0.2
    speed_limit = 314.16
    time_constant = 0.0
    coulomb_friction = 2e-3
    viscous_friction = 2e-5
    [[actuator.wheels]]
    axis = [0.0, 0.0, 1.0]
    inertia = 0.01
    torque_limit = 0.2
    speed_limit = 314.16
    time_constant = 0.0
    coulomb_friction = 2e-3
    viscous_friction = 2e-5

    [initial]
    wheel_speeds = [10.0, 0.0, -20.0]

    [maneuver]
    kind = "torque_samples"
    file = "torque.csv"
    interpolation = "hold"

    [simulation]
    t_final = 1.0
    output_step = 0.01
    """)

TORQUE = "t, tx, ty, tz\n0.0, 0.05, 0.0, 0.3\n0.5, -0.05, 0.1, -0.3\n"


def write_scene(folder: Path, text: str = SCENE) -> Path:
    (folder / "torque.csv").write_text(TORQUE)
    path = folder / "craft.toml"
    path.write_text(text)
    return path


def test_a_wheel_scene_runs_and_writes_the_wheel_columns(tmp_path, capsys):
    """The issue's scene form: the torque samples are commanded of the wheels (the z wheel
    saturates at its limit), ``wheel<k>.speed``, ``wheel<k>.torque`` and ``wheels.power``
    follow the tips, and the craft's angular momentum stays what it was."""
    path = write_scene(tmp_path)
    scene = load_scene(path)
    assert isinstance(scene, SpatialScene) and scene.wheels.count == 3
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 0
    with open(out / "timeseries.csv") as handle:
        rows = list(csv.reader(handle))
    header = rows[0]
    assert header[-7:] == ["wheel1.speed", "wheel2.speed", "wheel3.speed", "wheel1.torque",
                           "wheel2.torque", "wheel3.torque", "wheels.power"]
    column = dict(zip(header, np.array(rows[1:], dtype=float).T))
    assert column["wheel1.speed"][0] == 10.0 and column["wheel3.speed"][0] == -20.0
    first = column["t"] < 0.5
    np.testing.assert_allclose(column["wheel1.torque"][first], -0.05, atol=1e-12)
    np.testing.assert_allclose(column["wheel3.torque"][first], -0.2, atol=1e-12)
    np.testing.assert_allclose(column["wheel2.torque"][~first], -0.1, atol=1e-12)
    speeds = np.vstack([column[f"wheel{k}.speed"] for k in (1, 2, 3)])
    torques = np.vstack([column[f"wheel{k}.torque"] for k in (1, 2, 3)])
    np.testing.assert_allclose(column["wheels.power"],
                               np.sum(np.maximum(torques * speeds, 0), axis=0), atol=1e-12)
    half = np.argmin(np.abs(column["t"] - 0.5))
    # spun up by the saturated z wheel (less its friction) for 0.5 s, then back
    assert speeds[2, half] < -20.0 - 0.19 / 0.01 * 0.5 * 0.95 < speeds[2, -1]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["wheels"] == 3
    assert summary["peak_wheel_torque"] == pytest.approx([0.05, 0.1, 0.2], abs=1e-12)
    momentum = np.array(summary["final_angular_momentum"])
    initial = 0.01 * np.array([10.0, 0.0, -20.0])              # all of it in the wheels
    np.testing.assert_allclose(momentum, initial, atol=1e-9)


def test_the_arrangements_place_their_wheels():
    orthogonal = SCENE.split("[actuator]")[0] + textwrap.dedent("""\
        [actuator]
        kind = "wheels"
        arrangement = "{arrangement}"
        {extra}
        [actuator.wheel]
        inertia = 0.01
        torque_limit = 0.2
        speed_limit = 314.16

        [simulation]
        t_final = 1.0
        """)
    from flexctl.app.spatial_scene import parse_spatial_scene
    import tomllib

    scene = parse_spatial_scene(tomllib.loads(orthogonal.format(arrangement="orthogonal",
                                                                extra="")))
    np.testing.assert_array_equal(scene.wheels.axes, np.eye(3))
    scene = parse_spatial_scene(tomllib.loads(orthogonal.format(
        arrangement="pyramid", extra="pyramid_angle = 30.0\npyramid_axis = [1.0, 0.0, 0.0]")))
    assert scene.wheels.count == 4
    np.testing.assert_allclose(scene.wheels.axes[0], np.cos(np.radians(30.0)), rtol=1e-12)


@pytest.mark.parametrize("old, new, pattern", [
    ('kind = "wheels"', 'kind = "reaction_wheel"', r"actuator\.kind"),
    ("axis = [0.0, 1.0, 0.0]", "axis = [0.0, 0.0, 0.0]", r"actuator\.wheels\.1\.axis"),
    ("inertia = 0.01\n", "inertia = 0.01\nmass = 1.0\n", r"actuator\.wheels\.0.*mass"),
    ("speed_limit = 314.16\n", "", r"actuator\.wheels\.0\.speed_limit is required"),
    ('distribution = "pseudo_inverse"', 'distribution = "null_motion"',
     r"actuator.*null space"),
    ('distribution = "pseudo_inverse"', 'distribution = "least_squares"',
     r"actuator\.distribution"),
    ("wheel_speeds = [10.0, 0.0, -20.0]", "wheel_speeds = [10.0, 0.0]",
     r"initial\.wheel_speeds"),
    ("wheel_speeds = [10.0, 0.0, -20.0]", "wheel_speeds = [10.0, 0.0, -400.0]",
     r"initial\.wheel_speeds\[2\].*speed_limit"),
    ('kind = "wheels"', 'kind = "wheels"\narrangement = "pyramid"', r"not both"),
    ("coulomb_friction = 2e-3", "coulomb_friction = 0.5", r"actuator\.wheels\.0\."
                                                           r"coulomb_friction"),
], ids=["planar kind", "zero axis", "unknown wheel key", "missing key", "no null space",
        "unknown law", "short speeds", "speed beyond limit", "two forms", "friction too large"])
def test_a_bad_wheel_scene_is_refused_by_its_key(tmp_path, old, new, pattern):
    assert old in SCENE
    path = write_scene(tmp_path, SCENE.replace(old, new, 1))
    with pytest.raises(InputError, match=pattern):
        load_scene(path)
