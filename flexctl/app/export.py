"""``flexctl export``: a slew scene's designed controller written as C, compiled and checked.

:func:`export_scene` designs the scene's controller (:func:`controllers.from_spec`), writes
it with :func:`controllers.codegen.export_c`, and, where a C compiler is present, compiles it
with the checking flags and steps the compiled law against its CasADi program on states (or
readings) near the scene's start, reporting the largest difference. ``export.json`` in the
output directory records what was written and measured.

The export is written whole or not at all: its files are gathered in a temporary folder and
moved into the output directory only once the law is designed, written, compiled and checked
(:func:`flexctl.sim.atomic_files.staged_folder`). A design that fails, a compiler that refuses
the code or a folder standing where a file goes leaves the output directory as it was;
files of other names in it are kept.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..sim.atomic_files import staged_folder
from .export_check import SUMMARY_FILE, compiled_check, float_conditioning

__all__ = ["export_scene", "format_export"]



def _sample_time(scene, given):
    """The rate an LQG's estimator is discretised at: given, else the scene's sensors' or
    controller's, else the sensors' default."""
    if given is not None:
        return given
    if scene.controller is not None and scene.controller.kind == "lqg":
        from flexctl.sim.sensors import DEFAULT_SAMPLE_TIME
        sensors = getattr(scene, "sensors", None)
        return (getattr(sensors, "sample_time", None)
                or scene.controller.settings.get("sample_time") or DEFAULT_SAMPLE_TIME)
    return None


def export_scene(scene, out, *, sample_time: float | None = None, compile: bool = True,
                 cc: str | None = None, precision: str = "double",
                 loop_check: bool = False, target: str = "host") -> dict:
    """Design ``scene``'s controller, write it as C in ``out``, compile and check it.

    Parameters
    ----------
    scene : flexctl.Scene or SpatialScene
        A slew scene with a ``[controller]`` table; a spatial scene's three-axis law (and its
        attitude filter) goes to :func:`~flexctl.app.export_spatial.export_spatial_scene`.
    out : str or pathlib.Path
        Directory of the files (created with its parents if missing; files of other names
        in it are kept).
    sample_time : float, optional
        Sample time, s: the rate an LQG's estimator is discretised at (default: the sensors', else
        0.01 s), or a static law is sampled at.
    compile : bool
        Compile with :data:`controllers.codegen.C_FLAGS` and check against the program.
    cc : str, optional
        The C compiler (default ``$CC``, ``cc``, ``gcc`` or ``clang``).
    precision : {"double", "float"}, optional
        The C type of every real of the law (:func:`controllers.codegen.export_c`); in
        float, ``float_conditioning`` lists the condition numbers checked. Default
        ``"double"``.
    loop_check : bool, optional
        Also fly the slew with the law compiled in double and in float and record the
        differences (``precision_in_the_loop``,
        :func:`~flexctl.app.export_precision.compare_precisions`). Default False.
    target : {"host", "cortex-m4", "cortex-m7"}, optional
        Also build the law for this processor
        (:func:`controllers.codegen.targets.build_for_target`) and record its sizes and stack
        (``target_build``); the host's compiler still checks it against the program. Default
        ``"host"``.

    Returns
    -------
    dict
        :meth:`~controllers.codegen.CExport.describe` (``files`` in ``out``), with
        ``compiled`` (False when no compiler was found, with the ``note``),
        ``struct_bytes``, ``code_bytes``, ``compile_time_s`` and ``check_max_difference``.

    Raises
    ------
    flexctl.model.errors.InputError
        Bad input: the scene's controller, ``sample_time``, or a folder standing at one of
        the files' names in ``out`` (refused before the design starts).
    controllers.codegen.CompileError
        If the compiler fails: its name, exit status and messages, and that nothing was
        written.
    OSError
        If ``out`` cannot be made or written.
    """
    from controllers import from_spec
    from controllers.codegen import C_FILES, CompileError, export_c
    from controllers.codegen.targets import build_for_target, check_target, \
        find_target_compiler

    out = Path(out)
    from .spatial_scene import SpatialScene

    if isinstance(scene, SpatialScene):
        from .export_spatial import export_spatial_scene

        return export_spatial_scene(scene, out, sample_time=sample_time, compile=compile,
                                    cc=cc, precision=precision, loop_check=loop_check,
                                    target=target)
    chosen = check_target(target)
    if compile and chosen.embedded:
        find_target_compiler(chosen)            # missing cross tools: before the design
    with staged_folder(out, names=(*C_FILES, SUMMARY_FILE)) as stage:
        plant = scene.build_model()
        built = from_spec(scene, plant)
        rate = _sample_time(scene, sample_time)
        exported = export_c(built.controller, plant, stage, sample_time=rate,
                            precision=precision)
        summary = {"scene": scene.name, "controller": built.kind, **exported.describe(),
                   "files": [str(out / name) for name in C_FILES], "compiled": False}
        summary.update(float_conditioning(exported))
        if compile:
            try:
                summary.update(compiled_check(exported, cc))
                if chosen.embedded:
                    summary["target_build"] = build_for_target(exported, chosen).as_dict()
                if loop_check and summary["compiled"]:
                    from .export_precision import compare_precisions
                    summary["precision_in_the_loop"] = compare_precisions(
                        scene, sample_time=rate, cc=cc, built=built)
            except CompileError as exc:
                raise CompileError(f"{scene.name}: nothing written to {out}: {exc}") from None
        (stage / SUMMARY_FILE).write_text(json.dumps(summary, indent=2, default=str) + "\n",
                                          encoding="utf-8")
    return summary


def _part_lines(summary: dict) -> list:
    """The lines of one exported program: its interface, sizes, compiled check and build."""
    lines = [f"  input: {summary['input']} ({len(summary['input_names'])} entries), output: "
             f"{summary['output']}, sample time: {summary['sample_time_s']:g} s",
             f"  precision: {summary['precision']}; memory: {summary['memory_reals']} reals; "
             f"work: {summary['work_reals']} reals, {summary['work_ints']} integers"]
    if summary.get("compiled"):
        lines.append(f"  compiled: struct {summary['struct_bytes']} bytes, code "
                     f"{summary['code_bytes']} bytes, {summary['compile_time_s']:.2f} s; "
                     f"{summary['check_steps']} steps against the program: largest "
                     f"difference {summary['check_max_difference']:.2e}")
    elif summary.get("note"):
        lines.append(f"  {summary['note']}")
    for finding in summary.get("float_conditioning", ()):
        lines.append(f"  float: {finding['reason']} ({finding['verdict']})")
    if "target_build" in summary:
        build = summary["target_build"]
        lines.append(f"  {build['target']} ({build['precision']}): code {build['code_bytes']} "
                     f"bytes, constants {build['constant_bytes']} bytes, static RAM "
                     f"{build['static_ram_bytes']} bytes, struct {build['struct_bytes']} "
                     f"bytes, stack {build['stack_bytes']} bytes per step"
                     + ("; double arithmetic in software" if build["software_double"]
                        else ""))
    return lines


def format_export(summary: dict) -> str:
    """The console lines of an export.

    Parameters
    ----------
    summary : dict
        What :func:`export_scene` returns: the scene, the law's sizes and files, and the
        compiled check or the note why there is none.
    """
    lines = [f"{summary['scene']}: {summary['description']}", *_part_lines(summary)]
    if "filter" in summary:
        part = summary["filter"]
        lines += [f"  filter: {part['description']}",
                  *("  " + line for line in _part_lines(part))]
    if "precision_in_the_loop" in summary:
        checks = summary["precision_in_the_loop"]
        if "max_attitude_difference" in checks.get("double", {}):
            from .export_spatial import format_spatial_loop_check
            lines += format_spatial_loop_check(checks)
        else:
            from .export_precision import format_comparison
            lines.append(format_comparison(checks))
    lines.append("  files: " + ", ".join(Path(f).name for f in summary["files"])
                 + f" in {Path(summary['files'][0]).parent}")
    return "\n".join(lines)
