"""The C real type of an export (``double`` or ``float``), and CasADi's code made single precision.

An export's precision is the type of every real in its C: the step's interface
(``flexctl_real`` in the header), the law's memory, the work arrays, the constants and the
arithmetic of CasADi's code, the QP's included. In ``float`` no operation may fall back to
double precision (which a Cortex-M4's FPU does not have, so it would run in software): every
floating literal of the generated code gets the ``f`` suffix, every call of a math function its
float form (``sqrt`` becomes ``sqrtf``; not ``<tgmath.h>``, whose ``sin`` and ``cos`` name the
``long double complex`` functions newlib lacks), and the build adds
``-Wdouble-promotion`` at ``-Werror`` (:data:`PRECISION_FLAGS`), so that a promotion left over
fails the build rather than slowing the step.

The QP solver's thresholds are written by CasADi for double precision: its stopping tolerances
(``1e-8``, options of the solver) and the magnitudes below which it treats a pivot, a step or
a multiplier as zero (``1e-12``, ``1e-14``, constants of its code). In ``float`` both are set
at the float's resolution (:data:`FLOAT_QP_TOLERANCE`, :data:`FLOAT_QP_ZERO`): a tolerance
under float rounding is never met, and a zero test under it never fires.
"""

from __future__ import annotations

import re

import numpy as np

from flexctl.model.errors import InputTypeError, InputValueError

__all__ = ["PRECISIONS", "EPSILON", "PRECISION_FLAGS", "FLOAT_QP_TOLERANCE", "FLOAT_QP_ZERO",
           "FLOAT_MIN", "check_precision", "single_precision_code", "qp_options"]

#: The C real types an export can be written in.
PRECISIONS = ("double", "float")
#: Machine epsilon of each precision (the gap from 1 to the next number).
EPSILON = {"double": float(np.finfo(np.float64).eps), "float": float(np.finfo(np.float32).eps)}
#: Flags added to the checking flags for each precision: in float, a promotion to double is
#: an error.
PRECISION_FLAGS = {"double": (), "float": ("-Wdouble-promotion",)}
#: qrqp's constraint-violation and dual-infeasibility tolerances in float (absolute, on the
#: KKT residuals). Double keeps CasADi's own (1e-8). Measured on slew-90's NMPC (first_order,
#: 2 modes, N = 20) over 120 steps on random states near rest: at 1e-5, 54 QPs failed (float's
#: rounding of the residuals stays above the tolerance); at 3e-5, 13; at 1e-4 none, the
#: commands within 2e-5 N m of the double export's.
FLOAT_QP_TOLERANCE = 1e-4
#: Float's smallest normal number: a literal smaller in magnitude is written as zero.
FLOAT_MIN = float(np.finfo(np.float32).tiny)
#: The magnitude under which qrqp's code treats a pivot, a step or a multiplier as zero in
#: float (CasADi writes 1e-12 and 1e-14 for double): about 8 float epsilons.
FLOAT_QP_ZERO = 1e-6

_DOUBLE_ZEROS = ("1e-12", "1e-14")
# a floating literal of C: digits with a point and/or an exponent, not part of a name or of
# another number; CasADi writes no hexadecimal floats
_LITERAL = re.compile(r"(?<![\w.])((?:\d+\.\d*|\.\d+)(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+)"
                      r"(?![\w.])")
_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')
#: C99's math functions of one double that CasADi's code may call; in float each becomes its
#: ``f`` form.
MATH_FUNCTIONS = ("sqrt", "cbrt", "fabs", "fmin", "fmax", "floor", "ceil", "round", "trunc",
                  "fmod", "remainder", "copysign", "sin", "cos", "tan", "asin", "acos", "atan",
                  "atan2", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "exp", "expm1",
                  "exp2", "log", "log1p", "log2", "log10", "pow", "hypot", "erf", "erfc")
_CALL = re.compile(r"(?<![\w.>])(" + "|".join(MATH_FUNCTIONS) + r")(?=\s*\()")


def check_precision(value, owner: str = "export") -> str:
    """``value`` as one of :data:`PRECISIONS`, or a clear error.

    Parameters
    ----------
    value : str
        ``"double"`` or ``"float"``.
    owner : str, optional
        What the precision is of, for the message. Default ``"export"``.

    Raises
    ------
    InputTypeError
        If ``value`` is not a string.
    InputValueError
        If it is not one of :data:`PRECISIONS`.
    """
    if not isinstance(value, str):
        raise InputTypeError(f"{owner} precision must be a string, one of {PRECISIONS}; "
                             f"got {type(value).__name__}")
    if value not in PRECISIONS:
        raise InputValueError(f"{owner} precision must be one of {PRECISIONS}; got {value!r}")
    return value


def qp_options(precision: str) -> dict:
    """qrqp's options for ``precision``: the tolerances of :data:`FLOAT_QP_TOLERANCE` in
    float, none (CasADi's) in double.

    Parameters
    ----------
    precision : {"double", "float"}
        The export's real type.
    """
    if check_precision(precision) == "double":
        return {}
    return {"constr_viol_tol": FLOAT_QP_TOLERANCE, "dual_inf_tol": FLOAT_QP_TOLERANCE}


def single_precision_code(code: str) -> str:
    """CasADi's C (written with ``casadi_real`` float) with no double left in it.

    Every floating literal outside string literals gets the ``f`` suffix (one below
    :data:`FLOAT_MIN` in magnitude is written as zero), every call of one
    of :data:`MATH_FUNCTIONS` its float form, and qrqp's double zero thresholds (``1e-12``,
    ``1e-14``) become :data:`FLOAT_QP_ZERO`.

    Parameters
    ----------
    code : str
        The C text CasADi's ``CodeGenerator`` dumped.

    Examples
    --------
    >>> single_precision_code('w[0]=2.5e-01*sin(x); if (d<1e-12) s="1.5";')
    'w[0]=2.5e-01f*sinf(x); if (d<1e-06f) s="1.5";'
    """
    zero = f"{FLOAT_QP_ZERO:.0e}"
    pieces, start = [], 0
    for match in _STRING.finditer(code):
        pieces.append(_suffixed(code[start:match.start()], zero))
        pieces.append(match.group(0))
        start = match.end()
    pieces.append(_suffixed(code[start:], zero))
    return "".join(pieces)


def _suffixed(text: str, zero: str) -> str:
    def suffix(match):
        literal = match.group(1)
        if literal in _DOUBLE_ZEROS:
            return zero + "f"
        # below float's smallest normal number (a coupling of 1e-50 in a matrix): zero, as
        # float would hold it (and as a Cortex-M's flush-to-zero FPU computes it)
        return ("0.0" if 0.0 < abs(float(literal)) < FLOAT_MIN else literal) + "f"

    return _CALL.sub(r"\1f", _LITERAL.sub(suffix, text))
