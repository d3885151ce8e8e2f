"""Controllers for flexctl plants: one module per controller family.

=====================  ==========================================================
module                 contents
=====================  ==========================================================
``reference``          smooth rest-to-rest slew profiles (poly7, cycloidal)
``pd``                 collocated PD on hub angle and rate
``lqr``                LQR with Bryson-style physical weights, state truncation
``plant_state``        the plant's state layout, design state and hub state a law reads
``lqg``                Kalman filter on hub angle and root moment plus LQR
``scheduling``         LQR gains scheduled on the spin rate
``shaping``            rigid bang-bang torque and ZV / ZVD input shaping
``trajopt``            CasADi/IPOPT slew optimisation
``tracking``           feedforward plus LQR feedback about an optimal slew
``spec``               the kinds and settings a scene's [controller] table may hold
``factory``            the controller a slew scene's [controller] table asks for
``analysis``           loop transfer functions, stability margins, poles against spin
``robustness``         Monte Carlo dispersion of stiffness, point masses, hub inertia
``actuated``           laws through an actuator: wheel-lag LQR, DC-motor voltage, limits
``observer``           a sampled discrete Kalman filter of noisy sensor readings
``lqg_sampled``        LQG with its estimator discretised at a sample time
``iosys``              the laws as python-control I/O systems for ``control.interconnect``
``codegen``            a designed law as self-contained C99 (package)
=====================  ==========================================================

The package depends on :mod:`flexctl.model` and :mod:`flexctl.sim` (models and the simulation
protocol); only the application layer :mod:`flexctl.app` imports it.
"""

from .reference import SlewProfile, minimum_slew_duration
from .pd import PD, design_pd, pd_gains
from .lqr import (LQR, LQRWeights, closed_loop_poles, design_lqr, lqr_weight_matrices,
                  reference_state, truncate_state, truncation_matrix)
from .lqg import LQG, NoiseLevels, SumOfSines, design_lqg, estimator_gain
from .scheduling import ScheduledLQR, design_scheduled_lqr
from .shaping import (BangBang, ShapedReference, ShapedTorque, Shaper, bang_bang,
                      design_shaper, shape, zv_shaper, zvd_shaper)
from .trajopt import (SlewProblem, SlewSolution, TrajectoryOptimizationError,
                      rigid_minimum_time, solve_slew)
from .tracking import TrajectoryTracker
from .nmpc import NMPC, NMPCSession
from .factory import BuiltController, DesignChangedWarning, OpenLoop, from_spec
from .feedback import ReferenceSaturationWarning
from .stability import LoopStability, LoopStabilityWarning, check_loop
from .analysis import (LoopMargins, PlantChannels, PolesVsSpin, loop_margins, loop_transfer,
                       plant_channels, poles_vs_spin)
from .actuated import (LaggedLQR, MotorVoltage, check_reference_fits, design_wheel_lqr,
                       through_actuator)
from .observer import Observed, kalman_step
from .iosys import to_iosys
from .lqg_sampled import SampledLQG
from .robustness import (Dispersion, RobustnessSummary, RobustnessTask, disperse,
                         robustness_summary)

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
]
