"""A feedback law as one CasADi step function: what :mod:`controllers.codegen` turns into C.

Every exportable law becomes a :class:`ControllerProgram`: a CasADi function

    step(t, v, m) -> (u, m_next)

of the time ``t`` (s), the law's input ``v`` (the plant state, or the sensor readings of an
output-feedback law) and its memory ``m`` (estimator states, the NMPC's warm start, the last
command), giving the command ``u`` and the memory after the sample. A static law has no memory
and may be evaluated at any time (``sample_time = 0``); a sampled law is called once per
sample, at ``t = t_0, t_0 + T, ...``. A law whose step can fail (the NMPC's QP) carries a
``recover`` function of the same signature, which the C code calls when ``step`` reports a
failure or gives a non-finite number: it applies the previous plan, shifted one sample.

:func:`controllers.codegen.laws.program_for` builds the program of a designed law.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexctl.model.errors import InputValueError

__all__ = ["ControllerProgram", "ProgramSession", "ExportRefused"]


class ExportRefused(InputValueError):
    """A controller that cannot be written as self-contained C, with the reason."""


@dataclass(frozen=True, eq=False)
class ControllerProgram:
    """A feedback law as CasADi step functions (module docstring).

    Attributes
    ----------
    kind : str
        The law (``"pd"``, ``"lqr"``, ``"scheduled_lqr"``, ``"tracker"``, ``"lqg"``,
        ``"nmpc"``, ...).
    step : casadi.Function
        ``(t (1), v (n_in), m (n_mem)) -> (u (n_out), m_next (n_mem))``: ``n_out`` 1, or 3
        for a three-axis law (a torque in the hub frame).
    recover : casadi.Function or None
        Same signature; what a failed ``step`` is replaced by.
    input_names : tuple of str
        Names of ``v``'s entries, in order.
    input_kind : {"state", "measurement"}
        ``v`` is the plant state (in the plant's state order) or sensor readings.
    output_name, output_unit : str
        ``u``: ``"torque"`` (N m on the hub), ``"torque_command"`` (N m asked of a reaction
        wheel) or ``"voltage"`` (V on a DC motor).
    memory_init : ndarray, shape (n_mem,)
        ``m`` before the first step.
    sample_time : float
        s; 0 for a static law evaluated whenever it is called.
    measurement_matrix : ndarray or None, shape (n_in, n_plant)
        For a measurement law: the readings ``v = C x`` of the plant state (noise aside).
    description : str
        One line naming the law and its settings.
    info : dict
        Numbers worth reporting (design modes, horizon, QP size...).
    """

    kind: str
    step: object
    recover: object
    input_names: tuple
    input_kind: str
    output_name: str
    output_unit: str
    memory_init: np.ndarray
    sample_time: float
    measurement_matrix: np.ndarray | None = None
    description: str = ""
    info: dict = field(default_factory=dict)

    @property
    def n_in(self) -> int:
        """Entries of the input ``v``."""
        return len(self.input_names)

    @property
    def n_out(self) -> int:
        """Entries of the command ``u``: 1, or 3 for a three-axis law."""
        return int(self.step.size1_out(0))

    @property
    def n_memory(self) -> int:
        """Entries of the memory ``m``."""
        return int(self.memory_init.size)

    def session(self) -> "ProgramSession":
        """Steps of this program evaluated by CasADi (the reference the C code is checked
        against)."""
        return ProgramSession(self)


class ProgramSession:
    """The program stepped in Python, with the C code's failure handling.

    Parameters
    ----------
    program : ControllerProgram
        The law's program; its memory starts at ``program.memory_init``.
    """

    def __init__(self, program: ControllerProgram):
        self.program, self.memory = program, program.memory_init.copy()
        self.failures = 0

    def step(self, t: float, v):
        """Command at time ``t`` for the input ``v``, in :attr:`ControllerProgram.output_unit`
        (a float, or an array of :attr:`ControllerProgram.n_out` entries).

        Parameters
        ----------
        t : float
            Time, s.
        v : array_like, shape (n_in,)
            The law's input: the plant state, or the sensor readings of a measurement law
            (:attr:`ControllerProgram.input_names`).
        """
        args = (float(t), np.asarray(v, dtype=float).reshape(-1), self.memory)
        program = self.program
        try:
            u, m_next = program.step(*args)
            ok = True
        except RuntimeError:        # the QP failed inside the step
            ok = False
        if ok:
            u, m_next = _command(u, program), np.array(m_next, dtype=float).reshape(-1)
            ok = bool(np.all(np.isfinite(u))) and bool(np.all(np.isfinite(m_next)))
        if not ok and program.recover is not None:
            self.failures += 1
            u, m_next = program.recover(*args)
            u, m_next = _command(u, program), np.array(m_next, dtype=float).reshape(-1)
        self.memory = m_next
        return u


def _command(u, program):
    """A step's command: a float, or an array of :attr:`ControllerProgram.n_out` entries."""
    u = np.array(u, dtype=float).reshape(-1)
    return float(u[0]) if program.n_out == 1 else u


def plant_output(plant, voltage: bool = False) -> tuple:
    """(name, unit) of the command a law gives ``plant``.

    Parameters
    ----------
    plant : flexctl.Model
        The plant (a reaction wheel's command is named ``"torque_command"``).
    voltage : bool, optional
        The law gives a DC motor's voltage. Default False.
    """
    if voltage:
        return "voltage", "V"
    actuator = getattr(plant, "actuator", None)
    if actuator is not None and actuator.kind == "reaction_wheel":
        return "torque_command", "N m"
    return "torque", "N m"
