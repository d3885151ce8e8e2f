"""A spatial run drawn as an animation (flexctl.app.spatial_animation) and written by
``flexctl run --animate``."""

import numpy as np
import pytest
from PIL import Image

from flexctl import SpatialAppendage, SpatialHub, SpatialStructure, VectorTorque
from flexctl.app.cli import main
from flexctl.app.spatial_animation import animate_spatial, centrelines
from flexctl.model.errors import InputError
from flexctl.sim.spatial_run import simulate_spatial

WING = SpatialAppendage(name="wing", direction=(0.0, 1.0, 0.0), normal=(0.0, 0.0, 1.0),
                        length=1.8, density=2766.0, area=2.5e-4, youngs_modulus=6.9e10,
                        second_moment=5.2083e-10, second_moment_lateral=5.2083e-8,
                        shear_modulus=2.6e10, torsion_constant=1.9531e-9)


@pytest.fixture(scope="module")
def run():
    craft = SpatialStructure(hub=SpatialHub(inertia=np.diag([1.3, 1.16, 1.45]), radius=0.06,
                                            support="free", mass=3.0), appendages=(WING,))
    push = VectorTorque([0.0, 0.25, 0.5], [[0, 0, 0], [0.3, 0.0, 0.5], [0, 0, 0]])
    return simulate_spatial(craft, 0.5, push, n_modes=2, output_step=0.01,
                            check_accuracy=False)


def test_the_centreline_ends_at_the_tip_and_starts_at_the_root(run):
    (line,) = centrelines(run)
    assert line.shape[:2] == (run.t.size, 3)
    rigid_tip = np.array([0.0, 0.06 + 1.8, 0.0])
    np.testing.assert_allclose(line[:, :, -1] - rigid_tip, run.tips["wing"].T, atol=1e-12)
    np.testing.assert_allclose(line[:, :, 0], np.tile([0.0, 0.06, 0.0], (run.t.size, 1)),
                               atol=1e-15)
    # inextensible: the polyline through root, nodes and tip is never longer than the rod
    lengths = np.sum(np.linalg.norm(np.diff(line, axis=2), axis=1), axis=1)
    assert np.all(lengths <= 1.8 + 1e-9) and np.all(lengths >= 1.8 * (1 - 1e-3))


def test_the_gif_has_the_frames_asked_for(run, tmp_path):
    path = animate_spatial(run, tmp_path / "a.gif", frames=8, fps=10, title="wing")
    with Image.open(path) as image:
        assert image.format == "GIF" and image.n_frames == 8
    assert [p.name for p in tmp_path.iterdir()] == ["a.gif"]


@pytest.mark.parametrize("bad, match", [({"frames": 1}, "frames"), ({"fps": 0.0}, "fps"),
                                        ({"exaggeration": 0.5}, "exaggeration"),
                                        ({"frames": float("nan")}, "frames")])
def test_bad_arguments_are_refused_by_name_and_nothing_is_written(run, tmp_path, bad, match):
    with pytest.raises(InputError, match=match):
        animate_spatial(run, tmp_path / "a.gif", **bad)
    assert not list(tmp_path.iterdir())


def test_a_planar_scene_cannot_be_animated(tmp_path, capsys):
    assert main(["run", "hub-beam-mass", "--animate", "--out", str(tmp_path / "r")]) == 2
    assert "planar" in capsys.readouterr().err and not (tmp_path / "r").exists()
