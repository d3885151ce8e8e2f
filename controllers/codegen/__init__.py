"""Controllers as embeddable C: from a designed law to code that runs on a flight computer.

=====================  ==========================================================
module                 contents
=====================  ==========================================================
``program``            a law as CasADi step functions ``(t, v, m) -> (u, m_next)``
``laws``               the program of each built-in law (static laws, a motor's voltage)
``nmpc_program``       the NMPC's real-time iteration (EKF and qrqp QP) as a step
``lqg_program``        LQG with its estimator discretised at the sample time
``observed_program``   a state law on the sensors' discrete Kalman filter
``c_source``           the C99 source, header, example main and Makefile
``precision``          the C real type (double or float) and CasADi's code made single
``conditioning``       whether float carries a law: the condition numbers it meets
``compiler``           the checking flags, finding and running the C compiler
``export``             writing (all files or none), compiling and loading an export; the
                       compiled law
``targets``            freestanding builds for Cortex-M4F and Cortex-M7, their sizes and stack
``pil``                the step under QEMU on an MPS2 board: processor in the loop
=====================  ==========================================================
"""

from .program import ControllerProgram, ExportRefused
from .laws import program_for
from .export import (C_FILES, C_FLAGS, CExport, CompileError, CompiledController, CompiledLaw,
                     export_c, find_compiler)
from .precision import PRECISIONS
from .conditioning import PrecisionWarning, float_findings
from .targets import TARGETS, TargetBuild, build_for_target
from .pil import EmulatedLaw, EmulationError, PILRun, run_on_target

__all__ = ["ControllerProgram", "ExportRefused", "program_for", "export_c", "CExport",
           "CompiledLaw", "CompiledController", "CompileError", "C_FLAGS", "C_FILES",
           "find_compiler", "PRECISIONS", "PrecisionWarning", "float_findings", "TARGETS",
           "TargetBuild", "build_for_target", "EmulationError", "PILRun", "run_on_target",
           "EmulatedLaw"]
