"""flexctl: control design for rigid-flexible hub-beam-mass structures.

Three layers, each a subpackage, and the flow is one way:

- :mod:`flexctl.model`: physical parameters -> cantilever modes -> modal matrices -> a model of
  one variant, exported to python-control and CasADi;
- :mod:`flexctl.sim`: manoeuvres, simulation (compiled and SciPy paths), metrics, fidelity;
- :mod:`flexctl.app`: scenes, sweeps, bench, reports, plots, the CLI and the demo (the only
  layer that imports :mod:`controllers`).

A lower layer never imports a higher one (``tests/test_architecture.py``).
"""

import importlib

#: Each top-level name and the module that defines it, imported on first use, so that
#: ``import flexctl.model`` or ``import flexctl.sim`` loads neither the application layer nor
#: :mod:`controllers` (PEP 562).
_SOURCES = {
    **dict.fromkeys(("Beam", "Hub", "HubBeam", "PointMass", "Appendage", "Structure",
                     "ReactionWheel", "DCMotor", "VARIANTS", "Model", "SingularMassMatrixError",
                     "build_model"), "flexctl.model"),
    **dict.fromkeys(("SineTorque", "SpinUp", "Controller", "SimulationResult", "simulate"),
                    "flexctl.sim"),
    **dict.fromkeys(("SpatialHub", "SpatialAppendage", "SpatialStructure"),
                    "flexctl.model.spatial_structure"),
    **dict.fromkeys(("linearize_spatial", "nonlinear_spatial"), "flexctl.model.spatial_plant"),
    "spatial_modal_visibility": "flexctl.model.spatial_visibility",
    **dict.fromkeys(("simulate_spatial", "SpatialResult", "VectorTorque"),
                    "flexctl.sim.spatial_run"),
    **dict.fromkeys(("Scene", "SceneError", "builtin_scenes", "load_scene", "run_scene",
                     "run_slew"), "flexctl.app.scenes"),
}
__all__ = list(_SOURCES)
#: The layers, also loaded on first use (``flexctl.sim.simulate`` after ``import flexctl``).
_LAYERS = ("model", "sim", "app")


def __getattr__(name):
    if name in _LAYERS:
        return importlib.import_module(f"{__name__}.{name}")
    if name not in _SOURCES:
        raise AttributeError(f"module 'flexctl' has no attribute {name!r}")
    value = getattr(importlib.import_module(_SOURCES[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_SOURCES) | set(_LAYERS))


__version__ = "0.1.0"
