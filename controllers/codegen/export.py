"""Export a designed law as C files, compile them, and run the compiled law from Python.

:func:`export_c` writes ``flexctl_ctrl.h``, ``flexctl_ctrl.c``, ``main.c`` and a ``Makefile``
for a law bound to its plant (:func:`~controllers.codegen.laws.program_for`), all four or none
(:func:`flexctl.sim.atomic_files.staged_folder`). :meth:`CExport.compile` builds them with the
system C compiler at ``-std=c99 -Wall -Wextra -Werror`` into a shared library, in a temporary
folder removed once the library is loaded (the export folder gets no objects), and loads it
through :mod:`ctypes` (:class:`CompiledLaw`); a compiler that refuses the code raises
:class:`CompileError` with the compiler's messages. :meth:`CompiledLaw.controller` is the
compiled law as a flexctl controller, to close the loop on a plant with it.

Examples
--------
>>> import numpy as np, flexctl, tempfile
>>> from controllers import design_pd
>>> from controllers.codegen import export_c
>>> model = flexctl.build_model(flexctl.load_scene("hub-beam-mass").system, n_modes=2)
>>> pd = design_pd(model, bandwidth=3.0, damping_ratio=0.9)
>>> exported = export_c(pd, model, tempfile.mkdtemp())
>>> law = exported.compile()                                        # doctest: +SKIP
>>> law.step(0.0, np.r_[0.1, 0, 0, 0, 0, 0])[0] == pd.torque(0.0, np.r_[0.1, 0, 0, 0, 0, 0])
... # doctest: +SKIP
True
"""

from __future__ import annotations

import atexit
import ctypes
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flexctl.model.errors import InputTypeError, InputValueError
from flexctl.sim.atomic_files import staged_folder

from .c_source import RETURN_CODES, c_sources
from .compiler import (C_FLAGS, MESSAGE_LINES, CompileError, compiler_of, find_compiler,
                       run_compiler)
from .laws import program_for
from .precision import PRECISION_FLAGS, check_precision
from .program import ControllerProgram

__all__ = ["export_c", "CExport", "CompiledLaw", "CompiledController", "CompileError",
           "C_FLAGS", "C_FILES", "find_compiler", "MESSAGE_LINES"]     # the compiler's: re-exported

PREFIX = "flexctl_ctrl"
#: The files :func:`export_c` writes, in the order of :attr:`CExport.files`.
C_FILES = (f"{PREFIX}.h", f"{PREFIX}.c", "main.c", "Makefile")
_CODES = {value: name for name, value, _ in RETURN_CODES}


@dataclass(frozen=True, eq=False)
class CExport:
    """The files of an exported law.

    Attributes
    ----------
    directory : pathlib.Path
    program : ControllerProgram
    sizes : dict
        The struct's arrays, in entries (:class:`~controllers.codegen.c_source.CSources`).
    files : tuple of pathlib.Path
        Header, source, example main, Makefile.
    plant_names : tuple of str
        The plant's state names (what a state law reads).
    precision : {"double", "float"}
        The C type of every real of the law.
    """

    directory: Path
    program: ControllerProgram
    sizes: dict
    files: tuple
    plant_names: tuple = ()
    precision: str = "double"

    @property
    def source(self) -> Path:
        """``flexctl_ctrl.c``."""
        return self.directory / f"{PREFIX}.c"

    @property
    def header(self) -> Path:
        """``flexctl_ctrl.h``."""
        return self.directory / f"{PREFIX}.h"

    def compile(self, cc: str | None = None, flags=C_FLAGS) -> "CompiledLaw":
        """Compile to a shared library and load it.

        The object is built in a temporary folder, removed at once, and the library in a
        folder of this process's, removed when it exits: :attr:`directory` is only read.

        Parameters
        ----------
        cc : str, optional
            The C compiler (:func:`find_compiler`). Default ``$CC``, else ``cc``, ``gcc`` or
            ``clang`` on the path.
        flags : sequence of str, optional
            Flags of the compilation of the source. Default :data:`C_FLAGS`, and in float
            :data:`~controllers.codegen.precision.PRECISION_FLAGS` (a promotion to double
            is an error).

        Raises
        ------
        CompileError
            No compiler, or it failed: its name, exit status and messages are in the error
            (the first and last lines of long messages, :data:`MESSAGE_LINES`).
        """
        name, compiler = compiler_of(cc)
        flags = [str(flag) for flag in flags]
        flags += [f for f in PRECISION_FLAGS[self.precision] if f not in flags]
        library = _library_folder() / f"lib{PREFIX}-{os.urandom(6).hex()}.so"
        with tempfile.TemporaryDirectory(prefix="flexctl-build-") as build:
            obj = Path(build, f"{PREFIX}.o")
            started = time.perf_counter()
            # run in the export folder on the source's own name: the messages name the file
            # as the user knows it, not a path of the build
            run_compiler(name, [compiler, *flags, "-fPIC", "-c", self.source.name, "-o",
                                str(obj)],
                         f"compiling {self.source.name} with {' '.join(flags)}", self.directory)
            run_compiler(name, [compiler, "-shared", str(obj), "-o", str(library), "-lm"],
                 "linking the shared library", build)
            elapsed = time.perf_counter() - started
            code_bytes = _text_size(obj)
        return CompiledLaw(self, library, compile_time_s=elapsed, code_bytes=code_bytes)

    def describe(self) -> dict:
        """What was written: the law, its input, sample time and the struct's sizes."""
        program = self.program
        return {"kind": program.kind, "description": program.description,
                "input": program.input_kind, "input_names": list(program.input_names),
                "output": f"{program.output_name} ({program.output_unit})",
                "precision": self.precision,
                "sample_time_s": program.sample_time,
                **{k: int(v) for k, v in self.sizes.items()}, **program.info,
                "files": [str(f) for f in self.files]}


_LIBRARIES: dict = {}


def _library_folder() -> Path:
    """This process's folder of compiled laws, removed when it exits.

    A loaded library's file is kept as long as the process runs: the dynamic loader knows a
    library by its file's device and inode, and a new library given the inode of a removed
    one would be taken for the one already loaded.
    """
    pid = os.getpid()
    if pid not in _LIBRARIES:
        folder = Path(tempfile.mkdtemp(prefix="flexctl-laws-"))
        _LIBRARIES[pid] = folder
        atexit.register(_remove_library_folder, pid, folder)
    return _LIBRARIES[pid]


def _remove_library_folder(pid: int, folder: Path) -> None:
    if os.getpid() == pid:      # not in a forked child that inherited the hook
        shutil.rmtree(folder, ignore_errors=True)


def _text_size(obj: Path) -> int | None:
    """Bytes of code and constant data in the object (``size``'s text column)."""
    tool = shutil.which("size")
    if tool is None:
        return None
    done = subprocess.run([tool, str(obj)], capture_output=True, text=True)
    try:
        return int(done.stdout.splitlines()[1].split()[0])
    except (IndexError, ValueError):
        return None


def export_c(controller, plant, directory, *, sample_time: float | None = None,
             initial_state=None, precision: str = "double") -> CExport:
    """Write ``controller`` (bound to ``plant``) as C files in ``directory``.

    Parameters
    ----------
    controller : object
        A designed built-in law (see :func:`~controllers.codegen.laws.program_for`), a
        three-axis :class:`~controllers.feedback.spatial_lqr.SpatialLQR`,
        :class:`~controllers.feedback.spatial_lqr.SpatialLQG`,
        :class:`~controllers.feedback.quaternion.QuaternionFeedback` or
        :class:`~controllers.feedback.spatial_scheduling.ScheduledSpatialLQR`
        (:func:`~controllers.codegen.spatial_program.spatial_program`: three torques), an
        attitude filter (:class:`~controllers.feedback.mekf.AttitudeFilter`,
        :func:`~controllers.codegen.filter_program.filter_program`: the estimate), or a
        :class:`~controllers.codegen.program.ControllerProgram`.
    plant : flexctl.Model or None
        The plant the law runs on (its state order, sensors and actuator); a three-axis law
        names the entries it reads itself (None).
    directory : str or pathlib.Path
        Created if missing; the four files (:data:`C_FILES`) are written there, replacing
        earlier ones and keeping files of other names. All four are written or none: they go
        into a temporary folder first, moved into place once complete.
    sample_time : float, optional
        Sample time, s: to discretise an LQG's estimator at, or to sample a static law at.
    initial_state : array_like, optional
        Plant state where an estimator starts, shape (n,); default zero.
    precision : {"double", "float"}, optional
        The C type of every real: the interface, the memory, the constants and the
        arithmetic, the QP's included (:mod:`~controllers.codegen.precision`). In float the
        law's conditioning is checked first
        (:func:`~controllers.codegen.conditioning.check_float`): refused where single precision
        breaks it, a :class:`~controllers.codegen.conditioning.PrecisionWarning` where it loses
        much of its accuracy. A ``ControllerProgram`` given as ``controller`` keeps the QP
        tolerances it was built with. Default ``"double"``.

    Returns
    -------
    CExport

    Raises
    ------
    flexctl.model.errors.InputValueError
        If ``directory`` is a file, or a folder stands at one of the files' names (the
        folder is left as it was), or ``precision`` is not a precision.
    ExportRefused
        If the law has no C form, or single precision breaks it.
    """
    if isinstance(directory, bool) or not isinstance(directory, (str, os.PathLike)):
        raise InputTypeError(f"export directory must be a path; got {type(directory).__name__}")
    from flexctl.model import Model
    from ..feedback.mekf import AttitudeFilter
    from ..feedback.quaternion import QuaternionFeedback
    from ..feedback.spatial_lqr import SpatialLQG, SpatialLQR
    from ..feedback.spatial_scheduling import ScheduledSpatialLQR

    from ..mpc.spatial_nmpc import SpatialNMPC

    precision = check_precision(precision)
    if isinstance(controller, SpatialNMPC):
        if sample_time is not None or initial_state is not None:
            raise InputValueError("export: a three-axis NMPC keeps its own sample time and "
                                  "starts from the first state it reads; give neither "
                                  "sample_time nor initial_state")
        from .spatial_nmpc_program import spatial_nmpc_program
        program = spatial_nmpc_program(controller, precision)
    elif isinstance(controller, (SpatialLQR, SpatialLQG, QuaternionFeedback, AttitudeFilter,
                                 ScheduledSpatialLQR)):
        if sample_time is not None or initial_state is not None:
            raise InputValueError("export: a three-axis law or filter keeps its own sample "
                                  "time and starts from its own state or the first reading; "
                                  "give neither sample_time nor initial_state")
        from .filter_program import filter_program
        from .spatial_program import spatial_program
        program = (filter_program(controller) if isinstance(controller, AttitudeFilter)
                   else spatial_program(controller))
    elif not isinstance(plant, Model):
        raise InputTypeError(f"export plant must be a flexctl Model; got {type(plant).__name__}")
    else:
        program = controller if isinstance(controller, ControllerProgram) else program_for(
            controller, plant, sample_time=sample_time, initial_state=initial_state,
            precision=precision)
    plant_names = (tuple(plant.state_names) if isinstance(plant, Model)
                   else tuple(program.input_names))
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise InputValueError(f"export directory {str(directory)!r} is a file")
    if precision == "float":
        from .conditioning import check_float
        check_float(program)
    sources = c_sources(program, PREFIX, plant_states=len(plant_names), precision=precision)
    texts = (sources.header, sources.source, sources.main, sources.makefile)
    with staged_folder(directory, names=C_FILES) as stage:
        for name, text in zip(C_FILES, texts):
            (stage / name).write_text(text, encoding="utf-8")
    return CExport(directory, program, sources.sizes,
                   tuple(directory / name for name in C_FILES), plant_names, precision)


class CompiledLaw:
    """An exported law compiled and loaded through :mod:`ctypes`; made by
    :meth:`CExport.compile`.

    Parameters
    ----------
    export : CExport
        The exported files and the law's program.
    library : pathlib.Path
        The shared library loaded (by :meth:`CExport.compile`: in a temporary folder of the
        process, removed when it exits).
    compile_time_s : float
        Wall time the compilation took, s.
    code_bytes : int or None
        Code and constant data of the compiled object, bytes (``size``'s text column); None
        where ``size`` is not available.

    Attributes
    ----------
    struct_bytes : int
        ``flexctl_ctrl_size()``: the caller's memory for one controller, bytes.
    """

    def __init__(self, export: CExport, library: Path, compile_time_s: float,
                 code_bytes: int | None):
        self.export, self.library = export, library
        self.compile_time_s, self.code_bytes = compile_time_s, code_bytes
        lib = ctypes.CDLL(str(library))
        real, dtype = ((ctypes.c_float, np.float32) if export.precision == "float"
                       else (ctypes.c_double, np.float64))
        lib.flexctl_ctrl_size.restype = ctypes.c_size_t
        lib.flexctl_ctrl_size.argtypes = []
        lib.flexctl_ctrl_init.restype = ctypes.c_int
        lib.flexctl_ctrl_init.argtypes = [ctypes.c_void_p]
        lib.flexctl_ctrl_step.restype = ctypes.c_int
        lib.flexctl_ctrl_step.argtypes = [ctypes.c_void_p, real, ctypes.POINTER(real),
                                          ctypes.POINTER(real)]
        self._lib, self._real = lib, real
        self.struct_bytes = int(lib.flexctl_ctrl_size())
        # doubles: aligned for every member of the struct
        self._memory = np.zeros(-(-self.struct_bytes // 8) + 1)
        self._input = np.zeros(max(export.program.n_in, 1), dtype=dtype)
        self._u = np.zeros(export.program.n_out, dtype=dtype)
        # the buffers live as long as the law: their pointers are made once, not per step
        self._pointers = (self._memory.ctypes.data,
                          self._input.ctypes.data_as(ctypes.POINTER(real)),
                          self._u.ctypes.data_as(ctypes.POINTER(real)))
        self.init()

    @property
    def program(self) -> ControllerProgram:
        """The law's program."""
        return self.export.program

    def init(self) -> None:
        """``flexctl_ctrl_init``: the law's memory back to its start."""
        code = self._lib.flexctl_ctrl_init(self._memory.ctypes.data)
        if code != 0:
            raise RuntimeError(f"flexctl_ctrl_init returned {code}")

    def step(self, t: float, v) -> tuple:
        """``flexctl_ctrl_step``: ``(u, code)`` at time ``t`` for the input ``v`` (``u`` a
        float, or a new array of ``program.n_out`` entries).

        Parameters
        ----------
        t : float
            Time, s.
        v : array_like, shape (n_in,)
            The law's input: the plant state, or the sensor readings of a measurement law
            (``program.input_names``).

        Raises
        ------
        InputValueError
            If ``v`` has not ``n_in`` entries.
        """
        v = np.asarray(v, dtype=float).reshape(-1)
        if v.size != self.program.n_in:
            raise InputValueError(f"compiled law input must have {self.program.n_in} entries "
                                  f"({self.program.input_kind}); got {v.size}")
        self._input[:v.size] = v
        memory, inputs, command = self._pointers
        code = self._lib.flexctl_ctrl_step(memory, self._real(float(t)), inputs, command)
        u = float(self._u[0]) if self._u.size == 1 else self._u.astype(float)
        return u, int(code)

    def controller(self, measure=None) -> "CompiledController":
        """This compiled law as a flexctl controller for :func:`flexctl.simulate`.

        Parameters
        ----------
        measure : callable, optional
            ``measure(t, x) -> y``: the readings of a measurement law from time (s) and
            plant state. Default ``program.measurement_matrix @ x``.
        """
        return CompiledController(self, measure)


@dataclass(frozen=True, eq=False)
class CompiledController:
    """A :class:`CompiledLaw` as a flexctl controller: sampled at the law's sample time (a
    continuous static law, sample time 0, is evaluated whenever the integrator asks).

    Parameters
    ----------
    law : CompiledLaw
        The compiled law.
    measure : callable, optional
        ``measure(t, x) -> y``: the readings of a measurement law from time (s) and plant
        state. Default None: ``program.measurement_matrix @ x``.
    breakpoints : tuple of float, optional
        Times (s) where the integration restarts. Default none.
    """

    law: CompiledLaw
    measure: object = None
    breakpoints: tuple = field(default=())

    @property
    def sample_time(self):
        """s, or None for a continuous law."""
        return self.law.program.sample_time or None

    n_states = 0

    @property
    def fixed_plant(self) -> bool:
        """True for a state law: it reads exactly the exported plant's state, so a run's
        validity estimate (:func:`flexctl.sim.validity.geometric_error`) keeps the plant's
        modes."""
        return not self.measures

    @property
    def measures(self) -> bool:
        """True when the law reads the sensors' readings (handed over by the simulation,
        ``simulate(..., sensors=)``), as :class:`controllers.feedback.observer.Observed` does."""
        program = self.law.program
        return program.input_kind == "measurement" and program.measurement_matrix is None

    def initial_state(self, x0):
        """No states the integrator carries: shape (0,).

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Initial plant state (not read).
        """
        return np.zeros(0)

    def derivative(self, t, x, z=None):
        """No states the integrator carries.

        Parameters
        ----------
        t : float
            Time, s (not read).
        x : array_like, shape (n,)
            Plant state (not read).
        z : array_like, shape (0,), optional
            Internal state (none; not read).
        """
        return np.zeros(0)

    def _input(self, t, x):
        program = self.law.program
        if program.input_kind == "state" or self.measures:
            return x
        if self.measure is not None:
            return self.measure(t, x)
        return program.measurement_matrix @ np.asarray(x, dtype=float)

    def torque(self, t, x, z=None) -> float:
        """The command at ``t`` for plant state ``x`` (a continuous law).

        Parameters
        ----------
        t : float
            Time, s.
        x : array_like, shape (n,)
            Plant state, in the order of the plant the law was exported for.
        z : array_like, shape (0,), optional
            Internal state (none; not read).

        Raises
        ------
        RuntimeError
            If the compiled step returns an error code.
        """
        u, code = self.law.step(t, self._input(t, x))
        if code not in (0, 1):
            raise RuntimeError(f"compiled law at t = {t:g} s returned {_CODES.get(code, code)}")
        return u

    def start(self, model, x0) -> "CompiledSession":
        """A session: the law's memory reset (``flexctl_ctrl_init``).

        Parameters
        ----------
        model : flexctl.Model
            The plant of the run (a state law's must have the exported plant's state count).
        x0 : array_like, shape (n,)
            Plant state at the start (not read: the memory starts as exported).

        Raises
        ------
        InputValueError
            If a state law's plant has another number of states.
        """
        if not self.measures and model.n_states != len(self.law.export.plant_names):
            raise InputValueError(f"compiled law was exported for a plant of "
                                  f"{len(self.law.export.plant_names)} states; got "
                                  f"{model.n_states}")
        self.law.init()
        return CompiledSession(self)


class CompiledSession:
    """A closed-loop run of a :class:`CompiledController`: per-step CPU times and codes.

    Parameters
    ----------
    owner : CompiledController
        The controller run (:meth:`CompiledController.start` resets its law's memory).
    """

    def __init__(self, owner: CompiledController):
        self.owner = owner
        self.cpu_times, self.codes = [], []

    def step(self, t, x) -> float:
        """The command to hold from ``t`` for plant state ``x``.

        Parameters
        ----------
        t : float
            Sample time, s.
        x : array_like
            Plant state, shape (n,); or the sensors' readings, shape (n_in,), for a law
            that :attr:`~CompiledController.measures`.

        Raises
        ------
        RuntimeError
            If the compiled step returns an error code.
        """
        v = self.owner._input(t, x)
        started = time.process_time()
        u, code = self.owner.law.step(t, v)
        self.cpu_times.append(time.process_time() - started)
        self.codes.append(code)
        if code not in (0, 1):
            raise RuntimeError(f"compiled law at t = {t:g} s returned {_CODES.get(code, code)}")
        return u

    def report(self) -> dict:
        """Steps, recovered steps and CPU time per step (s: median, 99th percentile)."""
        times = np.array(self.cpu_times) if self.cpu_times else np.zeros(1)
        return {"steps": len(self.codes), "recovered_steps": int(sum(c == 1 for c in
                                                                     self.codes)),
                "cpu_time_median_s": float(np.median(times)),
                "cpu_time_p99_s": float(np.percentile(times, 99))}
