"""flexctl: control design for rigid-flexible hub-beam-mass structures.

Three layers, each a subpackage, and the flow is one way:

- :mod:`flexctl.model`: physical parameters -> cantilever modes -> modal matrices -> a model of
  one variant, exported to python-control and CasADi;
- :mod:`flexctl.sim`: manoeuvres, simulation (compiled and SciPy paths), metrics, fidelity;
- :mod:`flexctl.app`: scenes, sweeps, bench, reports, plots, the CLI and the demo (the only
  layer that imports :mod:`controllers`).

A lower layer never imports a higher one (``tests/test_architecture.py``).
"""

from .model import (VARIANTS, Appendage, Beam, DCMotor, Hub, HubBeam, Model, PointMass,
                    ReactionWheel, SingularMassMatrixError, Structure, build_model)
from .sim import Controller, SimulationResult, SineTorque, SpinUp, simulate
from .app.scenes import Scene, SceneError, builtin_scenes, load_scene, run_scene, run_slew

__all__ = [
    "Beam", "Hub", "HubBeam", "PointMass", "Appendage", "Structure", "ReactionWheel", "DCMotor", "VARIANTS", "Model", "SingularMassMatrixError",
    "build_model", "SineTorque", "SpinUp", "Controller", "SimulationResult", "simulate",
    "Scene", "SceneError", "builtin_scenes", "load_scene", "run_scene", "run_slew",
]
__version__ = "0.1.0"
