"""Single against double precision in the closed loop: a slew scene's law compiled both ways.

:func:`compare_precisions` designs the scene's controller once, exports and compiles it in
``double`` and in ``float`` (:func:`controllers.codegen.export_c`), flies the scene's slew on
the scene's own plant (the exact variant in the built-in slew scenes) with each compiled law
(:func:`flexctl.app.scenes.run_slew`), and reports what single precision changed: the residual
vibration, the pointing error after the manoeuvre (largest ``|theta - angle|`` from the
manoeuvre's end on) and the final error of each run, their differences, and the largest
difference between the two runs' commands.
"""

from __future__ import annotations

import dataclasses
import tempfile

import numpy as np

__all__ = ["compare_precisions", "format_comparison"]


def _pointing_error(result, plant, angle: float, end: float) -> float:
    """Largest ``|theta - angle|`` (rad) from ``end`` (s) on."""
    after = result.t >= end
    theta = result.states[plant.layout.theta]
    return float(np.max(np.abs(theta[after] - angle))) if after.any() else float("nan")


def compare_precisions(scene, *, sample_time: float | None = None, cc: str | None = None,
                       built=None) -> dict:
    """Fly ``scene``'s slew with its law compiled in double and in float (module docstring).

    Parameters
    ----------
    scene : flexctl.Scene
        A slew scene with a ``[controller]`` table.
    sample_time : float, optional
        Sample time, s, of an LQG's estimator or a static law (as for
        :func:`controllers.codegen.export_c`). Default: the law's own, or none.
    cc : str, optional
        The C compiler (:func:`controllers.codegen.find_compiler`). Default ``$CC``, else
        ``cc``, ``gcc`` or ``clang``.
    built : object, optional
        The scene's designed controller (what :func:`controllers.from_spec` returns for the
        scene's plant), to save designing it again. Default: designed here.

    Returns
    -------
    dict
        ``double`` and ``float``: ``residual_vibration`` (m), ``pointing_error`` (rad),
        ``final_error`` (rad), ``status``, ``recovered_steps``; ``difference``: the float run
        less the double run for the three metrics and ``max_command`` (largest
        ``|u_float - u_double|`` over the run, in the law's output unit); ``plant_variant``
        and ``plant_modes``.

    Raises
    ------
    controllers.codegen.CompileError
        If there is no C compiler or it fails.
    controllers.codegen.ExportRefused
        If the law has no C form, or single precision breaks it.
    """
    from controllers import from_spec
    from controllers.codegen import export_c

    from .scenes import run_slew

    plant = scene.build_model()
    built = built if built is not None else from_spec(scene, plant)
    angle = scene.maneuver.angle
    runs = {}
    for precision in ("double", "float"):
        with tempfile.TemporaryDirectory(prefix=f"flexctl-{precision}-") as folder:
            law = export_c(built.controller, plant, folder, sample_time=sample_time,
                           precision=precision).compile(cc)
            compiled = dataclasses.replace(built, controller=law.controller())
            result, _, metrics = run_slew(scene, lambda s, p, c=compiled: c,
                                          error_estimate=False)
        runs[precision] = (result, metrics)
    out = {"plant_variant": plant.variant.name if hasattr(plant.variant, "name")
           else str(plant.variant), "plant_modes": plant.n_modes}
    for precision, (result, metrics) in runs.items():
        report = result.controller_report or {}
        out[precision] = {
            "residual_vibration": metrics.residual_vibration,
            "pointing_error": _pointing_error(result, plant, angle, built.maneuver_end),
            "final_error": metrics.final_error, "status": result.status,
            "recovered_steps": int(report.get("recovered_steps", 0))}
    (r_double, _), (r_float, _) = runs["double"], runs["float"]
    out["difference"] = {key: out["float"][key] - out["double"][key] for key in
                         ("residual_vibration", "pointing_error", "final_error")}
    same_grid = r_double.t.shape == r_float.t.shape and np.allclose(r_double.t, r_float.t)
    out["difference"]["max_command"] = (float(np.max(np.abs(r_float.torque - r_double.torque)))
                                        if same_grid else float("nan"))
    return out


def format_comparison(comparison: dict) -> str:
    """The console lines of :func:`compare_precisions`'s result.

    Parameters
    ----------
    comparison : dict
        What :func:`compare_precisions` returns.
    """
    lines = [f"  float against double in the loop ({comparison['plant_variant']} plant, "
             f"{comparison['plant_modes']} modes):"]
    for precision in ("double", "float"):
        run = comparison[precision]
        lines.append(f"    {precision:<6}: residual vibration {run['residual_vibration']:.4e} m, "
                     f"pointing error {run['pointing_error']:.4e} rad, final error "
                     f"{run['final_error']:.4e} rad ({run['status']}, "
                     f"{run['recovered_steps']} recovered steps)")
    diff = comparison["difference"]
    lines.append(f"    float - double: residual vibration {diff['residual_vibration']:+.3e} m, "
                 f"pointing error {diff['pointing_error']:+.3e} rad, largest command "
                 f"difference {diff['max_command']:.3e}")
    return "\n".join(lines)
