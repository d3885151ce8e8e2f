"""Running a model: manoeuvres, simulation, metrics and fidelity estimates.

Imports :mod:`flexctl.model` only.

======================  =======================================================================
module                  contents
======================  =======================================================================
``maneuvers``           ``SpinUp``, ``SineTorque``, ``Slew``: what drives the hub
``simulation``          ``simulate``: a thin driver over the parts below
``request``             the validated run request and its integration plan (stiffness guard)
``drives``              what drives a run: prescribed hub, torque and continuous ``Controller``
``strategies``          one integration strategy per method family (CVODES, the pair, rk4, SciPy)
``stops``               stopping conditions and their physical reasons (``StopReason``)
``result``              ``SimulationResult`` and its assembly
``inputs``              argument checks, ``SampledTorque`` (a torque given as samples)
``tracing``             Python torque functions traced into CasADi (``trace_torque``)
``function_samples``    untraceable torque functions of time sampled into a piecewise cubic
``compiled``            the CasADi/CVODES integration of a symbolic drive
``fixed_step``          compiled fixed-step RK4 with a step-doubling error estimate (``rk4``)
``digital``             sampled controllers: ``ZeroOrderHold``, the ``SampledController`` protocol
``embedded_rk``         compiled Dormand-Prince steps: 5(4) (``RK45``) sample to sample, 5(4)
                        and 8(5,3) (``dop853``) over continuous runs with dense output
``sensors``             noisy, quantised, late sensor readings (``Sensors``)
``energy``              energy balance of small-deflection runs (``energy_balance``)
``validity``            geometric model error of a run, the variant a manoeuvre needs
``metrics``             slew metrics and settling time
``fidelity``            how many modes a manoeuvre needs (``choose_modes``)
======================  =======================================================================
"""

from .maneuvers import SineTorque, Slew, SpinUp
from .inputs import SampledTorque
from .simulation import (METHODS, AccuracyWarning, Controller, SimulationResult, StaticLaw,
                         StiffnessWarning, StopReason, simulate)
from .digital import ControllerSession, SampledController, ZeroOrderHold
from .sensors import Sensors
from .metrics import SlewMetrics, settling_time, slew_metrics
from .fidelity import ModeChoice, choose_modes

__all__ = [
    "SineTorque", "Slew", "SpinUp", "SampledTorque",
    "METHODS", "AccuracyWarning", "Controller", "SimulationResult", "StiffnessWarning",
    "simulate", "StopReason", "StaticLaw",
    "ControllerSession", "SampledController", "ZeroOrderHold", "Sensors",
    "SlewMetrics", "settling_time", "slew_metrics",
    "ModeChoice", "choose_modes",
]

from .blas_threads import threads_from_environment as _blas_threads  # noqa: E402

_blas_threads()                 # FLEXCTL_BLAS_THREADS, if set
