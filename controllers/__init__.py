"""Controllers for flexctl plants, in subpackages by what they do.

======================  ========================================================================
subpackage or module    contents
======================  ========================================================================
``design``              what every design shares: the plant state a law reads, controllability,
                        the loop-stability check, actuator limits, holds, compiled dynamics
``slew``                reference profiles, input shaping, trajectory optimisation
``feedback``            PD, LQR, LQG, gain scheduling, tracking, observers, actuator-aware laws,
                        the laws as python-control I/O systems
``mpc``                 nonlinear MPC
``analysis``            loop transfer functions, margins, poles against spin, robustness
``spec``                the kinds and settings a scene's [controller] table may hold (imported
                        by the parts above for their choices)
``factory``             the controller a slew scene's [controller] table asks for
``codegen``             a designed law as self-contained C99
======================  ========================================================================

Each part imports only the ones listed before it, and ``spec`` (``tests/test_architecture.py``). Every
public name is importable from ``controllers`` itself; the modules' former flat paths
(``controllers.lqr``, ``controllers.trajopt``, ...) name the same modules
(``FORMER_PATHS``).

The package depends on :mod:`flexctl.model` and :mod:`flexctl.sim` (models and the simulation
protocol); only the application layer :mod:`flexctl.app` imports it.
"""

from .slew.reference import SlewProfile, minimum_slew_duration
from .feedback.pd import PD, design_pd, pd_gains
from .feedback.lqr import (LQR, LQRWeights, closed_loop_poles, design_lqr, lqr_weight_matrices,
                           reference_state, truncate_state, truncation_matrix)
from .feedback.lqg import LQG, NoiseLevels, SumOfSines, design_lqg, estimator_gain
from .feedback.scheduling import ScheduledLQR, design_scheduled_lqr
from .slew.shaping import (BangBang, ShapedReference, ShapedTorque, Shaper, bang_bang,
                           design_shaper, shape, zv_shaper, zvd_shaper)
from .slew.trajopt import (SlewProblem, SlewSolution, TrajectoryOptimizationError,
                           rigid_minimum_time, solve_slew)
from .feedback.tracking import TrajectoryTracker
from .mpc.nmpc import NMPC, NMPCSession
from .factory import BuiltController, DesignChangedWarning, OpenLoop, from_spec
from .feedback.reference_feedback import ReferenceSaturationWarning
from .design.stability import LoopStability, LoopStabilityWarning, check_loop
from .analysis.loops import (LoopMargins, PlantChannels, PolesVsSpin, loop_margins,
                             loop_transfer, plant_channels, poles_vs_spin)
from .feedback.actuated import (LaggedLQR, MotorVoltage, check_reference_fits, design_wheel_lqr,
                                through_actuator)
from .feedback.observer import Observed, kalman_step
from .feedback.iosys import to_iosys
from .feedback.lqg_sampled import SampledLQG
from .analysis.robustness import (Dispersion, RobustnessSummary, RobustnessTask, disperse,
                                  robustness_summary, spread_statistics)
from .feedback.observer import FilterModel
from .feedback.structural_filters import Filtered, LeadLag, Notch, RollOff
from .analysis.filter_design import FilterDesign, design_filters
from .analysis.requirements import Requirements, Verification, verify_requirements

__all__ = [
    "SlewProfile", "minimum_slew_duration",
    "PD", "design_pd", "pd_gains",
    "LQR", "LQRWeights", "closed_loop_poles", "design_lqr", "lqr_weight_matrices",
    "reference_state", "truncate_state", "truncation_matrix",
    "LQG", "NoiseLevels", "SumOfSines", "design_lqg", "estimator_gain",
    "ScheduledLQR", "design_scheduled_lqr",
    "BangBang", "ShapedReference", "ShapedTorque", "Shaper", "bang_bang", "design_shaper",
    "shape", "zv_shaper", "zvd_shaper",
    "SlewProblem", "SlewSolution", "TrajectoryOptimizationError", "TrajectoryTracker",
    "rigid_minimum_time", "solve_slew",
    "NMPC", "NMPCSession",
    "BuiltController", "DesignChangedWarning", "OpenLoop", "from_spec",
    "ReferenceSaturationWarning", "LoopStability", "LoopStabilityWarning", "check_loop",
    "LoopMargins", "PlantChannels", "PolesVsSpin", "loop_margins", "loop_transfer",
    "plant_channels", "poles_vs_spin",
    "LaggedLQR", "MotorVoltage", "check_reference_fits", "design_wheel_lqr",
    "through_actuator", "Observed", "kalman_step", "to_iosys", "SampledLQG",
    "Dispersion", "RobustnessSummary", "RobustnessTask", "disperse", "robustness_summary",
    "spread_statistics", "FilterModel", "Filtered", "Notch", "RollOff", "LeadLag",
    "Requirements", "Verification", "verify_requirements", "FilterDesign", "design_filters",
]

#: Each module's former path (the flat package of earlier releases) and the module it names now.
FORMER_PATHS = {
    "plant_state": "design.plant_state", "controllable": "design.controllable",
    "actuator_limits": "design.actuator_limits", "native_dynamics": "design.native_dynamics",
    "stability": "design.stability", "hold_grid": "design.hold_grid",
    "reference": "slew.reference", "shaping": "slew.shaping", "trajopt": "slew.trajopt",
    "slew_nlp": "slew.slew_nlp", "slew_checks": "slew.slew_checks",
    "pd": "feedback.pd", "lqr": "feedback.lqr", "lqg": "feedback.lqg",
    "lqg_sampled": "feedback.lqg_sampled", "scheduling": "feedback.scheduling",
    "tracking": "feedback.tracking", "observer": "feedback.observer",
    "actuated": "feedback.actuated", "iosys": "feedback.iosys", "nmpc": "mpc.nmpc",
    "robustness": "analysis.robustness",
}


def _keep_former_paths():
    """``import controllers.lqr`` and ``from controllers import lqr`` name the module that
    lives at ``controllers.feedback.lqr`` now (``controllers.feedback`` and
    ``controllers.analysis``, once modules, are packages holding their names)."""
    import importlib
    import sys

    for former, current in FORMER_PATHS.items():
        module = importlib.import_module(f"{__name__}.{current}")
        sys.modules[f"{__name__}.{former}"] = module
        globals()[former] = module


_keep_former_paths()
