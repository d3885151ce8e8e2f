"""Whether single precision can carry a law: the condition numbers its float rounding meets.

A law in float carries about seven significant digits. Where the law solves a linear system,
the relative error of the solution is bounded, to first order, by the system's condition
number times the machine epsilon (``kappa * eps``); the two places a built-in law solves one
at every sample are checked:

- the NMPC's QP: the condition number of its condensed Hessian at the first sample (with the
  state read then, the reference and the first plan), which bounds the relative error of the
  plan qrqp returns;
- a Kalman filter's covariance (the sensors' filter of an ``Observed`` law, an NMPC's
  extended Kalman filter) once settled (the program stepped :data:`SETTLE_STEPS` samples on
  readings at rest): the condition number of its correlation matrix
  ``D^-1 P D^-1`` (``D`` the standard deviations). Float rounds each entry relative to itself,
  so the states' units (rad against m against rad/s) cost nothing; what float cannot carry is
  a correlation so close to one that the rounding makes ``P`` indefinite, and the filter then
  diverges. (flexible-link's filter: ``kappa(P)`` 9.9e7 from its units alone, its correlation
  matrix's 17; in the loop float changes its slew's residual vibration by 0.09 %.)

A sampled law whose command jumps at given times (the trajectory tracker's held feedforward)
meets a third limit: where a jump falls on a sample instant, float's rounding of the time
``k T`` decides which side of the jump the sample sees, and that sample applies the
neighbouring hold, a step of up to the full torque (:class:`SwitchFinding`, a warning).

A loss ``kappa * eps`` of :data:`FLOAT_REFUSE_LOSS` or more (at most one correct digit) is
refused (:class:`~controllers.codegen.program.ExportRefused`, the reason in its message); of
:data:`FLOAT_WARN_LOSS` or more (three digits or fewer), a :class:`PrecisionWarning`. The static
laws solve nothing at run time: their float error is the rounding of ``K x`` and of the
reference tables, measured in the closed loop (:func:`flexctl.app.export_precision`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .precision import EPSILON
from .program import ControllerProgram, ExportRefused

__all__ = ["PrecisionWarning", "ConditionFinding", "SwitchFinding", "float_findings",
           "check_float",
           "FLOAT_WARN_LOSS", "FLOAT_REFUSE_LOSS", "SETTLE_STEPS"]

#: ``kappa * eps`` of float at and above which an export warns (three digits or fewer left).
FLOAT_WARN_LOSS = 1e-3
#: ``kappa * eps`` of float at and above which an export is refused (one digit or none left).
FLOAT_REFUSE_LOSS = 0.1
#: Samples a filter's covariance is stepped (readings at rest) before its condition is read.
SETTLE_STEPS = 200


class PrecisionWarning(UserWarning):
    """Single precision leaves a law few correct digits (:data:`FLOAT_WARN_LOSS`)."""


@dataclass(frozen=True)
class ConditionFinding:
    """One condition number of a law and what float's rounding makes of it.

    Attributes
    ----------
    quantity : str
        What was measured (``"QP Hessian"``, ``"filter covariance's correlation"``).
    condition : float
        Its 2-norm condition number.
    loss : float
        ``condition * eps`` of float: the first-order bound on the relative error.
    verdict : {"ok", "warn", "refuse"}
        Against :data:`FLOAT_WARN_LOSS` and :data:`FLOAT_REFUSE_LOSS`.
    """

    quantity: str
    condition: float
    loss: float
    verdict: str

    @property
    def reason(self) -> str:
        """The finding in one sentence."""
        return (f"the {self.quantity}'s condition number is {self.condition:.3g}: in float "
                f"(eps {EPSILON['float']:.3g}) its solution's relative error may reach "
                f"{self.loss:.3g}")

    def as_dict(self) -> dict:
        """Plain dictionary (JSON-ready), with the :attr:`reason`."""
        return {"quantity": self.quantity, "condition": self.condition, "loss": self.loss,
                "verdict": self.verdict, "reason": self.reason}


@dataclass(frozen=True)
class SwitchFinding:
    """Jumps of a sampled law's command that fall on sample instants, within float's
    rounding of the time.

    Attributes
    ----------
    count : int
        Jumps within ``4 eps t`` of a multiple of the sample time.
    first : float
        The first of them, s.
    sample_time : float
        The law's sample time, s.
    """

    count: int
    first: float
    sample_time: float
    quantity = "held feedforward"
    verdict = "warn"

    @property
    def reason(self) -> str:
        """The finding in one sentence."""
        return (f"{self.count} of its feedforward's jumps fall on samples (the first at "
                f"{self.first:g} s, sampled every {self.sample_time:g} s): float's rounding "
                "of the sample time decides which hold such a sample applies")

    def as_dict(self) -> dict:
        """Plain dictionary (JSON-ready), with the :attr:`reason`."""
        return {"quantity": self.quantity, "count": self.count, "first": self.first,
                "verdict": self.verdict, "reason": self.reason}


def _switches_on_samples(program: ControllerProgram) -> SwitchFinding | None:
    period, times = program.sample_time, np.asarray(program.info.get("switch_times", ()))
    if not period or times.size == 0:
        return None
    gap = np.abs(times - period * np.round(times / period))
    tied = times[gap <= 4 * EPSILON["float"] * np.maximum(np.abs(times), period)]
    return SwitchFinding(int(tied.size), float(tied[0]), period) if tied.size else None


def _finding(quantity: str, condition: float) -> ConditionFinding:
    loss = float(condition) * EPSILON["float"]
    verdict = ("refuse" if not np.isfinite(loss) or loss >= FLOAT_REFUSE_LOSS else
               "warn" if loss >= FLOAT_WARN_LOSS else "ok")
    return ConditionFinding(quantity, float(condition), loss, verdict)


def _settled_correlation(program: ControllerProgram, start: int, n: int) -> np.ndarray:
    """The correlation matrix of the covariance block ``m[start:start + n*n]``
    (column-major) after :data:`SETTLE_STEPS` samples of readings at rest."""
    session = program.session()
    period = program.sample_time or 0.01
    v = np.zeros(program.n_in)
    for k in range(SETTLE_STEPS):
        session.step(k * period, v)
    block = session.memory[start:start + n * n].reshape(n, n, order="F")
    block = 0.5 * (block + block.T)
    deviation = np.sqrt(np.clip(np.diag(block), np.finfo(float).tiny, None))
    return block / np.outer(deviation, deviation)


def float_findings(program: ControllerProgram) -> tuple:
    """The condition numbers of ``program`` that single precision meets (module docstring).

    Parameters
    ----------
    program : ControllerProgram
        A law's program; its ``info`` holds ``qp_hessian_condition`` (an NMPC),
        ``filter_states`` (a law on the sensors' filter) or ``ekf_states`` (an NMPC with an
        extended Kalman filter).

    Returns
    -------
    tuple of ConditionFinding or SwitchFinding
        Empty for a law that solves nothing at run time and has no jump on a sample.
    """
    info, found = program.info, []
    switches = _switches_on_samples(program)
    if switches is not None:
        found.append(switches)
    if "qp_hessian_condition" in info:
        found.append(_finding("QP Hessian", info["qp_hessian_condition"]))
    if "filter_states" in info:
        n = int(info["filter_states"])
        found.append(_finding("filter covariance's correlation", np.linalg.cond(
            _settled_correlation(program, n, n))))
    if "ekf_states" in info:
        n, start = int(info["ekf_states"]), int(info["ekf_offset"]) + int(info["ekf_states"])
        found.append(_finding("extended Kalman filter covariance's correlation",
                              np.linalg.cond(_settled_correlation(program, start, n))))
    return tuple(found)


def check_float(program: ControllerProgram) -> tuple:
    """Refuse ``program`` in float where its conditioning breaks it, warn where it is poor.

    Parameters
    ----------
    program : ControllerProgram
        The law's program (:func:`float_findings`).

    Returns
    -------
    tuple of ConditionFinding or SwitchFinding

    Raises
    ------
    ExportRefused
        If a finding's loss is :data:`FLOAT_REFUSE_LOSS` or more, with the reason.

    Warns
    -----
    PrecisionWarning
        If one is :data:`FLOAT_WARN_LOSS` or more.
    """
    found = float_findings(program)
    refused = [f for f in found if f.verdict == "refuse"]
    if refused:
        raise ExportRefused(f"export precision 'float' breaks the {program.kind} law: "
                            + "; ".join(f.reason for f in refused)
                            + f" (refused at {FLOAT_REFUSE_LOSS:g}); export it in double")
    for finding in found:
        if finding.verdict == "warn":
            limit = (f" (warned at {FLOAT_WARN_LOSS:g})"
                     if isinstance(finding, ConditionFinding) else "")
            warnings.warn(f"export precision 'float' for the {program.kind} law: "
                          f"{finding.reason}{limit}", PrecisionWarning, stacklevel=3)
    return found
