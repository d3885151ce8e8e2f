"""A run's summary.json holds the scene it ran (``scene_table``): ``load_scene`` on it, or
``flexctl run summary.json``, rebuilds that scene and reproduces the run."""

import json

import numpy as np
import pytest

from flexctl import SceneError, load_scene
from flexctl.app.scenes import parse_scene
from flexctl.app.cli import main

#: Two runs of one scene with one model and integrator agree to rounding of the integrator.
RUN_TOLERANCE = 1e-12

CASES = {
    "spinup": ("kane-spinup", {"simulation.t_final": "2.0", "model.modes": "2",
                               "maneuver.spin_rate": "3.5", "model.variant": "consistent"}),
    "slew": ("slew-90", {}),    # made a short PD slew in a scene file by the test
}


def _overrides(case):
    return dict(CASES[case][1])


def _run(tmp_path, source, overrides, out):
    argv = ["run", str(source), "--out", str(tmp_path / out)]
    argv += [arg for k, v in overrides.items() for arg in ("--set", f"{k}={v}")]
    assert main(argv) in (0, 3)
    return json.loads((tmp_path / out / "summary.json").read_text())


@pytest.mark.parametrize("case", ["spinup", "slew"])
def test_summary_gives_back_the_scene_and_the_run(tmp_path, case):
    source, overrides = CASES[case][0], _overrides(case)
    if case == "slew":
        # a pd slew: the scene's trajopt settings do not apply to pd, so start from its tables
        base = load_scene(source).data
        base["controller"] = {"kind": "pd", "bandwidth": 3.0}
        base["simulation"]["t_final"] = 4.0
        scene_file = tmp_path / "slew-pd.toml"
        scene_file.write_text(_toml(base))
        source, overrides = scene_file, {"controller.damping_ratio": "0.8"}
    first = _run(tmp_path, source, overrides, "first")
    scene = load_scene(source, overrides=overrides)
    again = load_scene(tmp_path / "first" / "summary.json")
    assert again == scene
    assert again.data == scene.data
    assert again.name == scene.name
    # the maneuver table is written under the scene's own keys and units (a slew's angle_deg)
    maneuver = {k: v for k, v in first["maneuver"].items() if v is not None}
    assert parse_scene({**scene.data, "maneuver": maneuver}, name=scene.name) == scene
    second = _run(tmp_path, tmp_path / "first" / "summary.json", {}, "second")
    assert second["scene_table"] == first["scene_table"]
    assert second["status"] == first["status"]
    for key in ("peak_tip_deflection", "t_end"):
        assert second[key] == pytest.approx(first[key], rel=RUN_TOLERANCE, abs=RUN_TOLERANCE)
    for name in ("first", "second"):
        assert (tmp_path / name / "timeseries.csv").is_file()
    a = np.loadtxt(tmp_path / "first" / "timeseries.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "second" / "timeseries.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(b, a, rtol=RUN_TOLERANCE, atol=RUN_TOLERANCE)


def test_summary_overrides_apply_on_top(tmp_path):
    _run(tmp_path, "kane-spinup", _overrides("spinup"), "first")
    scene = load_scene(tmp_path / "first" / "summary.json",
                       overrides={"maneuver.spin_rate": "4.0"})
    assert scene.maneuver.spin_rate == 4.0
    assert scene.model.variant == "consistent"


def test_a_summary_without_its_scene_is_refused(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text(json.dumps({"scene": "old"}))
    with pytest.raises(SceneError, match="has no scene_table"):
        load_scene(path)
    path.write_text("{not json")
    with pytest.raises(SceneError, match="is not valid JSON"):
        load_scene(path)


def _toml(data: dict) -> str:
    """A scene's tables as TOML (numbers, strings, booleans and tables of them)."""
    def value(v):
        if isinstance(v, bool):
            return str(v).lower()
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)
    lines = [f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, (dict, list))]
    for key, table in data.items():
        items = table if isinstance(table, list) else [table] if isinstance(table, dict) else []
        for item in items:
            lines.append(f"[[{key}]]" if isinstance(table, list) else f"[{key}]")
            lines += [f"{k} = {value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"
