"""A compiled law checked against its program, and the summary file of an export."""

from __future__ import annotations

import numpy as np

__all__ = ["compiled_check", "float_conditioning", "CHECK_STEPS", "SUMMARY_FILE"]

#: Steps of the compiled law checked against its program.
CHECK_STEPS = 20
#: What was written and measured, beside the C files.
SUMMARY_FILE = "export.json"


def _check(program, law, seed: int = 0) -> float:
    """Largest difference, relative to ``max(1, |u|)``, between the compiled law and its
    program over :data:`CHECK_STEPS` samples of inputs near rest."""
    rng = np.random.default_rng(seed)
    reference = program.session()
    law.init()
    period = program.sample_time or 0.01
    worst = 0.0
    for k in range(CHECK_STEPS):
        v = 1e-2 * rng.standard_normal(program.n_in)
        expected = np.asarray(reference.step(k * period, v), dtype=float)
        got, _ = law.step(k * period, v)
        worst = max(worst, float(np.max(np.abs(np.asarray(got) - expected)))
                    / max(1.0, float(np.max(np.abs(expected)))))
    law.init()
    return float(worst)


def compiled_check(exported, cc) -> dict:
    """Compile an export and check it against its program: its sizes, compile time and
    largest difference (:data:`CHECK_STEPS` steps); or the ``note`` that no compiler was
    found.

    Parameters
    ----------
    exported : CExport
        The written law.
    cc : str or None
        The C compiler (default ``$CC``, ``cc``, ``gcc`` or ``clang``).

    Returns
    -------
    dict
        ``compiled``, and ``struct_bytes``, ``code_bytes``, ``compile_time_s``,
        ``check_steps``, ``check_max_difference``; or ``note``.
    """
    from controllers.codegen import CompileError, find_compiler

    try:
        find_compiler(cc)
    except CompileError as exc:
        return {"note": f"{exc}: the files are written but not compiled"}
    law = exported.compile(cc)
    return {"compiled": True, "struct_bytes": law.struct_bytes, "code_bytes": law.code_bytes,
            "compile_time_s": law.compile_time_s, "check_steps": CHECK_STEPS,
            "check_max_difference": _check(exported.program, law)}


def float_conditioning(exported) -> dict:
    """``float_conditioning``: the condition numbers checked of a law exported in float
    (:func:`controllers.codegen.conditioning.float_findings`); nothing in double.

    Parameters
    ----------
    exported : CExport
        The written law.

    Returns
    -------
    dict
    """
    if exported.precision != "float":
        return {}
    from controllers.codegen.conditioning import float_findings

    return {"float_conditioning": [f.as_dict() for f in float_findings(exported.program)]}
