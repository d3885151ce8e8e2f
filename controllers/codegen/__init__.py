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
``export``             writing (all files or none), compiling and loading an export; the
                       compiled law
=====================  ==========================================================
"""

from .program import ControllerProgram, ExportRefused
from .laws import program_for
from .export import (C_FILES, C_FLAGS, CExport, CompileError, CompiledController, CompiledLaw,
                     export_c, find_compiler)

__all__ = ["ControllerProgram", "ExportRefused", "program_for", "export_c", "CExport",
           "CompiledLaw", "CompiledController", "CompileError", "C_FLAGS", "C_FILES",
           "find_compiler"]
