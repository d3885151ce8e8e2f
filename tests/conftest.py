"""Shared fixtures: the systems of the built-in scenes (MODEL.md section 6) and helpers.

The built-in scenes are checked against the numbers of MODEL.md in ``test_scenes.py``; the
physics tests take their systems from the scenes so that the two cannot drift apart.
"""

import atexit
import dataclasses
import os
import shutil
import tempfile

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# one BLAS thread per test worker, as under the command line (flexctl.sim.blas_threads)
os.environ.setdefault("FLEXCTL_BLAS_THREADS", "1")
# the demo's remembered runs of a test process in a folder of their own, not the user's cache
if "FLEXCTL_RUN_CACHE_DIR" not in os.environ:
    os.environ["FLEXCTL_RUN_CACHE_DIR"] = tempfile.mkdtemp(prefix="flexctl-test-runs-")
    atexit.register(shutil.rmtree, os.environ["FLEXCTL_RUN_CACHE_DIR"], True)

import flexctl  # noqa: E402


def scene_system(name: str) -> flexctl.HubBeam:
    """The ``HubBeam`` of a built-in scene."""
    return flexctl.load_scene(name).system


@pytest.fixture(scope="session")
def kane_system():
    """Kane, Ryan and Banerjee's 8 m beam (hub radius 0), built-in scene ``kane-spinup``."""
    return scene_system("kane-spinup")


@pytest.fixture(scope="session")
def spacecraft_system():
    """Paper 001 sec. 3.2: massless hub, 5 m beam (``spacecraft-torque``)."""
    return scene_system("spacecraft-torque")


@pytest.fixture(scope="session")
def hub_beam_mass_system():
    """Paper 000 sec. 3.2: heavy hub, 1.8 m beam, 0.085 kg at 0.9 l (``hub-beam-mass``)."""
    return scene_system("hub-beam-mass")


@pytest.fixture(scope="session")
def bare_hub_beam_system(hub_beam_mass_system):
    """The paper-000 system without its point mass."""
    return dataclasses.replace(hub_beam_mass_system, masses=())


@pytest.fixture(scope="session")
def lossy_hub_beam_mass_system(hub_beam_mass_system):
    """The paper-000 system with beam damping and hub friction, to exercise every term."""
    return dataclasses.replace(
        hub_beam_mass_system,
        hub=dataclasses.replace(hub_beam_mass_system.hub, friction=0.05),
        beam=dataclasses.replace(hub_beam_mass_system.beam, damping_ratio=0.02))


@pytest.fixture
def rng():
    """A seeded random generator (fresh per test, so tests do not depend on order)."""
    return np.random.default_rng(20240611)


def gauss_legendre(a: float, b: float, n_panels: int = 16, n_points: int = 80):
    """Composite Gauss-Legendre nodes and weights on ``[a, b]`` (independent of flexctl)."""
    g, w = np.polynomial.legendre.leggauss(n_points)
    edges = np.linspace(a, b, n_panels + 1)
    nodes = np.concatenate([0.5 * (hi - lo) * g + 0.5 * (hi + lo)
                            for lo, hi in zip(edges[:-1], edges[1:])])
    weights = np.concatenate([0.5 * (hi - lo) * w for lo, hi in zip(edges[:-1], edges[1:])])
    return nodes, weights


def random_states(model, rng, count: int, deflection: float = 0.02):
    """``count`` random plant states (columns) of physically moderate size.

    Modal coordinates are a fraction ``deflection`` of the beam length, rates a few rad/s.
    """
    n, l = model.n_modes, model.system.beam.length
    x = np.empty((model.n_states, count))
    x[0] = rng.uniform(-np.pi, np.pi, count)
    x[1:n + 1] = deflection * l * rng.standard_normal((n, count)) / np.arange(1, n + 1)[:, None]
    x[n + 1] = rng.uniform(-3.0, 3.0, count)
    x[n + 2:] = 0.5 * deflection * l * rng.standard_normal((n, count))
    return x


def in_threads(call, count: int = 3) -> list:
    """``call(k)`` for ``k`` in ``range(count)``, each in a thread of its own, all at once;
    their results in order."""
    import threading

    results = [None] * count

    def work(k):
        results[k] = call(k)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return results
