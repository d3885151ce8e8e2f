"""The installed package is the product: the wheel, installed the ordinary way (not editable) in
a fresh virtual environment, imports every public module and runs the command line.

An editable install finds modules in the source tree, so it hides a package or a data file that
the wheel leaves out (``controllers.codegen`` once was: ``flexctl export`` failed with
``ModuleNotFoundError`` from a wheel). The fresh environment takes the dependencies of the one
running the tests through ``PYTHONPATH``, which reads no ``.pth`` file, so the editable install of
the source tree stays out of it; the commands run outside the source tree.
"""

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

from tests.test_architecture import module_files

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("wheel")]


def _public_modules() -> list:
    return sorted(name for name in module_files()
                  if not any(part.startswith("_") for part in name.split(".")))


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """``(bin folder, environment, work folder, wheel)`` of a fresh virtual environment
    holding the wheel and nothing else."""
    tmp = tmp_path_factory.mktemp("wheel")
    # built from a copy of the project's own files: a build/ folder left in the tree by an
    # earlier build would otherwise lend the wheel files that the project does not list
    source = tmp / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md", "flexctl", "controllers"):
        copy = shutil.copytree if (ROOT / name).is_dir() else shutil.copy
        copy(ROOT / name, source / name, **({"ignore": shutil.ignore_patterns("__pycache__")}
                                            if (ROOT / name).is_dir() else {}))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                    str(tmp / "dist"), str(source)], check=True)
    wheel = next((tmp / "dist").glob("flexctl-*.whl"))
    venv.EnvBuilder(with_pip=False).create(tmp / "venv")
    bin_dir = tmp / "venv" / "bin"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(bin_dir / "python"), "install",
                    "-q", "--no-deps", str(wheel)], check=True)
    paths = sysconfig.get_paths()
    env = {**os.environ, "MPLBACKEND": "Agg",
           "PYTHONPATH": os.pathsep.join(dict.fromkeys((paths["purelib"], paths["platlib"])))}
    work = tmp / "work"
    work.mkdir()
    return bin_dir, env, work, wheel


def _run(installed, program, *args):
    bin_dir, env, work, _ = installed
    return subprocess.run([str(bin_dir / program), *args], cwd=work, env=env,
                          capture_output=True, text=True, timeout=600)


def test_the_wheel_holds_every_module_and_data_file(installed):
    names = set(zipfile.ZipFile(installed[3]).namelist())
    sources = {path.relative_to(ROOT).as_posix() for package in ("flexctl", "controllers")
               for path in (ROOT / package).rglob("*")
               if path.is_file() and path.suffix in (".py", ".toml", ".c")
               and "__pycache__" not in path.parts}
    assert sources - names == set()


def test_every_public_module_imports_from_the_wheel(installed):
    modules = _public_modules()
    code = ("import importlib, json\n"
            f"modules = {modules!r}\n"
            "print(json.dumps({m: importlib.import_module(m).__file__ for m in modules}))\n")
    done = _run(installed, "python", "-c", code)
    assert done.returncode == 0, done.stderr
    files = json.loads(done.stdout)
    assert set(files) == set(modules)
    outside = {m: f for m, f in files.items() if not f.startswith(str(installed[0].parent))}
    assert not outside, f"modules imported from outside the fresh environment: {outside}"


def test_flexctl_run_and_export_from_the_wheel(installed):
    work = installed[2]
    run = _run(installed, "flexctl", "run", "hub-beam-mass", "--out", "run")
    assert run.returncode == 0, run.stderr
    assert json.loads((work / "run" / "summary.json").read_text())["status"] == "ok"
    export = _run(installed, "flexctl", "export", "slew-90", "--out", "c")
    assert export.returncode == 0, export.stderr
    assert {"flexctl_ctrl.c", "flexctl_ctrl.h"} <= {p.name for p in (work / "c").iterdir()}


def test_a_spatial_scene_runs_from_the_wheel(installed):
    """A structure that turns about any axis (a 3 x 3 hub inertia): the example scene, shortened,
    runs from the installed package and writes its named columns."""
    work = installed[2]
    scene = work / "spatial-spin.toml"
    scene.write_text((ROOT / "examples" / "scenes" / "spatial-spin.toml").read_text())
    run = _run(installed, "flexctl", "run", str(scene), "--set", "simulation.t_final=0.2",
               "--set", "model.modes=1", "--out", "spatial")
    assert run.returncode == 0, run.stderr
    summary = json.loads((work / "spatial" / "summary.json").read_text())
    assert summary["status"] == "ok" and summary["spatial"] is True
    header = (work / "spatial" / "timeseries.csv").read_text().splitlines()[0].split(",")
    assert header[:8] == ["t", "qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    assert "wing_a.tip_dz" in header
