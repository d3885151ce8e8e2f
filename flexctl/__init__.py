"""flexctl: control design for rigid-flexible hub-beam-mass structures.

The flow is one way: physical parameters (:mod:`flexctl.parameters`) -> cantilever modes
(:mod:`flexctl.modes`) -> modal matrices (:mod:`flexctl.matrices`) -> a model of one variant
(:mod:`flexctl.model`, exported by :mod:`flexctl.exports`) -> simulation
(:mod:`flexctl.simulation`) -> scenes, CLI, plots and reports on top.
"""

from .parameters import Beam, Hub, HubBeam, PointMass
from .model import VARIANTS, Model, SingularMassMatrixError, build_model
from .maneuvers import SineTorque, SpinUp
from .simulation import Controller, SimulationResult, simulate
from .scenes import Scene, SceneError, builtin_scenes, load_scene, run_scene, run_slew

__all__ = [
    "Beam", "Hub", "HubBeam", "PointMass", "VARIANTS", "Model", "SingularMassMatrixError",
    "build_model", "SineTorque", "SpinUp", "Controller", "SimulationResult", "simulate",
    "Scene", "SceneError", "builtin_scenes", "load_scene", "run_scene", "run_slew",
]
__version__ = "0.1.0"
