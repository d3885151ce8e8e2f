"""``flexctl export`` of a spatial scene: its three-axis law as C, and its attitude filter.

The law of the scene's ``[controller]`` (quaternion feedback, an LQR or an LQG, following an
eigenaxis slew or not; :func:`controllers.codegen.spatial_program.spatial_program`) is
written in the export folder as a planar scene's law is; with ``[sensors]``, the attitude
filter the law reads through (:func:`controllers.codegen.filter_program.filter_program`) in
its subfolder ``filter/``. Each is compiled and checked against its program, built for the
target, and with ``loop_check`` both are flown compiled, in double and in float, in the scene's
loop on its own plant against the Python law and filter: ``precision_in_the_loop`` gives the
largest attitude, rate and command differences and the final pointing error of each.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..sim.atomic_files import staged_folder
from ..sim.quaternions import error_angles
from .export_check import SUMMARY_FILE, compiled_check, float_conditioning

__all__ = ["export_spatial_scene", "format_spatial_loop_check", "FILTER_FOLDER"]

#: Subfolder of the attitude filter's C files.
FILTER_FOLDER = "filter"


def _refuse(scene, sample_time):
    from controllers.spec import SceneError

    if scene.loop is None:
        raise SceneError(f"export: {scene.name} has no [controller]: a spatial scene's "
                         "export writes its attitude law")
    if sample_time is not None:
        raise SceneError(f"export: {scene.name}'s three-axis law keeps its own sample time "
                         f"({scene.loop.sample_time:g} s); give no --sample-time")
    kind = type(scene.loop.law).__name__
    if kind not in ("QuaternionFeedback", "SpatialLQR", "SpatialLQG", "SpatialNMPC",
                    "ScheduledSpatialLQR"):
        raise SceneError(f"export: {scene.name}'s {kind} has no C form; the quaternion "
                         "feedback, the LQR, the LQG, the NMPC and the scheduled LQR of a "
                         "spatial scene have")


def _pointing(scene, result) -> float:
    from .spatial_control import pointing_target

    return float(np.linalg.norm(error_angles(pointing_target(scene.loop.law, result.t[-1]),
                                             result.quaternion[:, -1])))


def _loop_differences(scene, compiled: dict, precision: str, python) -> dict:
    """The scene's loop flown with the compiled law and filter against Python's run."""
    from controllers.codegen.filter_program import compiled_attitude_filter
    from controllers.codegen.spatial_program import compiled_spatial_law

    from .spatial_report import fly_spatial_loop

    law = compiled_spatial_law(compiled["law"])
    estimator = (compiled_attitude_filter(compiled["filter"]) if "filter" in compiled
                 else None)
    flown = fly_spatial_loop(scene, law=law, estimator=estimator).result
    c = flown.layout.n_coordinates
    done = min(flown.t.size, python.t.size)
    return {"precision": precision, "status": flown.status,
            "max_attitude_difference": float(np.max(np.abs(
                flown.states[0:4, :done] - python.states[0:4, :done]))),
            "max_rate_difference": float(np.max(np.abs(
                flown.states[c:c + 3, :done] - python.states[c:c + 3, :done]))),
            "max_command_difference": float(np.max(np.abs(
                flown.torque[:, :done] - python.torque[:, :done]))),
            "final_pointing_error": _pointing(scene, flown),
            "python_final_pointing_error": _pointing(scene, python)}


def export_spatial_scene(scene, out, *, sample_time: float | None = None,
                         compile: bool = True, cc: str | None = None,
                         precision: str = "double", loop_check: bool = False,
                         target: str = "host") -> dict:
    """Write a spatial scene's three-axis law (and its attitude filter) as C in ``out``
    (module description).

    Parameters
    ----------
    scene : SpatialScene
        A spatial scene with a ``[controller]``.
    out : str or pathlib.Path
        Directory of the files (created if missing).
    sample_time : None
        Must be None: the law keeps its own.
    compile : bool
        Compile and check against the programs.
    cc : str, optional
        The C compiler.
    precision : {"double", "float"}, optional
        The C type of every real. Default ``"double"``.
    loop_check : bool, optional
        Also fly the scene's loop with the compiled law and filter, in double and in float,
        against Python (``precision_in_the_loop``). Default False.
    target : {"host", "cortex-m4", "cortex-m7"}, optional
        Also build each for this processor (``target_build``). Default ``"host"``.

    Returns
    -------
    dict
        As :func:`~flexctl.app.export.export_scene`'s, for the law; with sensors, ``filter``:
        the same for the filter (its files in :data:`FILTER_FOLDER`).
    """
    from controllers.codegen import C_FILES, CompileError, export_c, find_compiler
    from controllers.codegen.targets import build_for_target, check_target, \
        find_target_compiler

    _refuse(scene, sample_time)
    chosen = check_target(target)
    if compile and chosen.embedded:
        find_target_compiler(chosen)
    loop = scene.loop
    parts = {"law": loop.law}
    if loop.sensors is not None:
        parts["filter"] = loop.estimator(scene.quaternion)
    names = [*C_FILES, *(f"{FILTER_FOLDER}/{n}" for n in C_FILES if "filter" in parts)]
    out = Path(out)
    with staged_folder(out, names=(*names, SUMMARY_FILE)) as stage:
        summaries = {}
        for part, law in parts.items():
            folder = stage if part == "law" else stage / FILTER_FOLDER
            exported = export_c(law, None, folder, precision=precision)
            where = out if part == "law" else out / FILTER_FOLDER
            summary = {**exported.describe(), "files": [str(where / n) for n in C_FILES],
                       "compiled": False}
            summary.update(float_conditioning(exported))
            if compile:
                try:
                    summary.update(compiled_check(exported, cc))
                    if chosen.embedded:
                        summary["target_build"] = build_for_target(exported, chosen).as_dict()
                except CompileError as exc:
                    raise CompileError(f"{scene.name}: nothing written to {out}: {exc}") \
                        from None
            summaries[part] = summary
        summary = {"scene": scene.name, "controller": type(loop.law).__name__,
                   **summaries["law"]}
        if "filter" in summaries:
            summary["filter"] = summaries["filter"]
        if loop_check and summary.get("compiled"):
            from .spatial_report import fly_spatial_loop

            find_compiler(cc)
            checks, python = {}, fly_spatial_loop(scene).result
            for chosen_precision in ("double", "float"):
                compiled = {part: (export_c(law, None, stage / f".loop-{chosen_precision}"
                                            f"-{part}", precision=chosen_precision)
                                   .compile(cc))
                            for part, law in parts.items()}
                checks[chosen_precision] = _loop_differences(scene, compiled,
                                                              chosen_precision, python)
            for part in parts:
                for chosen_precision in ("double", "float"):
                    _remove(stage / f".loop-{chosen_precision}-{part}")
            summary["precision_in_the_loop"] = checks
        (stage / SUMMARY_FILE).write_text(json.dumps(summary, indent=2, default=str) + "\n",
                                          encoding="utf-8")
    return summary


def _remove(folder: Path) -> None:
    import shutil

    shutil.rmtree(folder, ignore_errors=True)


def format_spatial_loop_check(checks: dict) -> list:
    """The console lines of a spatial export's ``precision_in_the_loop``.

    Parameters
    ----------
    checks : dict
        ``double`` and ``float``: what the loop flown with the compiled law (and filter)
        differs from Python by.

    Returns
    -------
    list of str
    """
    lines = []
    for precision, check in checks.items():
        lines.append(
            f"  in the loop, {precision}: {check['status']}; largest difference from Python: "
            f"attitude {check['max_attitude_difference']:.1e}, rate "
            f"{check['max_rate_difference']:.1e} rad/s, command "
            f"{check['max_command_difference']:.1e} N m; final pointing error "
            f"{check['final_pointing_error']:.2e} rad (Python "
            f"{check['python_final_pointing_error']:.2e})")
    return lines
