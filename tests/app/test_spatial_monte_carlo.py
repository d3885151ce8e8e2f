"""A Monte Carlo of a spatial loop (issue 44, item 6): the design made once, flown on
dispersed structures and sensor noise, in this process or on Dask."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from flexctl import load_scene
from flexctl.app.spatial_monte_carlo import (SpatialLoopTask, dispersed_structure,
                                             spatial_monte_carlo)
from flexctl.model.errors import InputError

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scenes" / "spatial-lqg-slew.toml"


@pytest.fixture(scope="module")
def scene():
    return load_scene(EXAMPLE, overrides={"simulation.t_final": 8.0, "model.modes": 1})


def test_a_dispersed_structure_scales_what_it_says(scene):
    nominal = scene.structure
    soft = dispersed_structure(nominal, stiffness=0.8, inertia=1.1)
    assert soft.appendages[0].youngs_modulus == pytest.approx(
        0.8 * nominal.appendages[0].youngs_modulus)
    assert soft.appendages[1].shear_modulus == pytest.approx(
        0.8 * nominal.appendages[1].shear_modulus)
    np.testing.assert_allclose(soft.hub.inertia, 1.1 * np.asarray(nominal.hub.inertia))
    # the first clamped bending frequency goes as sqrt(E)
    from flexctl.model.spatial_plant import linearize_spatial

    def first(structure):
        big = dataclasses.replace(structure, hub=dataclasses.replace(
            structure.hub, inertia=np.eye(3) * 1e12))
        w = np.abs(np.linalg.eigvals(linearize_spatial(big, 1).A).imag)
        return np.min(w[w > 1e-3])
    assert first(soft) / first(nominal) == pytest.approx(np.sqrt(0.8), rel=1e-9)


def test_the_task_flies_the_nominal_design_on_the_dispersed_plant(scene):
    task = SpatialLoopTask(scene)
    nominal = task(seed=scene.loop.sensors.seed)
    soft = task(stiffness=0.7, seed=scene.loop.sensors.seed)
    assert nominal["status"] == soft["status"] == "ok"
    # the same law on another plant: another response, still a slew
    assert soft["residual_vibration"] != nominal["residual_vibration"]
    assert soft["pointing_error"] < 0.01 and nominal["pointing_error"] < 0.01
    assert task.scene.loop.law is scene.loop.law          # not redesigned
    # another sensor seed, another noise
    assert task(seed=123)["pointing_error"] != nominal["pointing_error"]


def test_the_monte_carlo_is_the_same_on_dask_as_here(scene):
    distributed = pytest.importorskip("distributed")
    here = spatial_monte_carlo(scene, 3, seed=7)
    assert len(here.rows) == 3 and not here.failed
    assert all(0.9 <= row["stiffness"] <= 1.1 for row in here.rows)
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=2,
                            dashboard_address=None) as client:
        there = spatial_monte_carlo(scene, 3, seed=7, executor=client.get_executor())
    for a, b in zip(here.rows, there.rows):
        assert a["seed"] == b["seed"]
        assert a["pointing_error"] == b["pointing_error"]
        assert a["residual_vibration"] == b["residual_vibration"]


@pytest.mark.parametrize("call, match", [
    (lambda s: spatial_monte_carlo(s, 0), "samples"),
    (lambda s: spatial_monte_carlo(s, 2, stiffness_spread=1.5), "stiffness_spread"),
    (lambda s: spatial_monte_carlo(s, 2, seed=-1), "seed"),
    (lambda s: dispersed_structure(s.structure, stiffness=0.0), "stiffness"),
    (lambda s: dispersed_structure(s.structure, inertia=float("nan")), "inertia"),
    (lambda s: SpatialLoopTask(dataclasses.replace(s, loop=None)), "controller"),
    (lambda s: SpatialLoopTask(s, settle_window=-1.0), "settle_window"),
])
def test_bad_monte_carlo_inputs_are_refused_by_name(scene, call, match):
    with pytest.raises((InputError, TypeError, ValueError), match=match):
        call(scene)
