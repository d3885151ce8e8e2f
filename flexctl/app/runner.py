"""One scene, end to end: design its controller (if any), simulate, and write its files.

:func:`execute` runs a loaded scene: a scene without a ``[controller]`` table through
:func:`~flexctl.app.scenes.run_scene`, a slew with a controller through
:func:`~flexctl.app.scenes.run_slew` with :func:`controllers.from_spec`, whose design facts
and slew metrics go into the run's summary. :func:`write_complete` writes the run's files
(:func:`~flexctl.app.report.write_run`) into a temporary directory and moves them into place
only once every one is written (:func:`flexctl.sim.atomic_files.staged_folder`). ``flexctl
run`` and ``flexctl demo`` are these two steps.
"""

from __future__ import annotations

from pathlib import Path

from ..model.errors import InputValueError
from ..sim.atomic_files import staged_folder
from .report import BODE_PLOT, NICHOLS_PLOT, RESPONSE_PLOT, SUMMARY, TIMESERIES, write_run
from .scenes import run_scene, run_slew

__all__ = ["execute", "write_complete"]


def _run_controlled(scene, progress=None):
    """Design the controller of a slew scene, run it, and measure the slew."""
    from controllers.factory import from_spec

    result, built, metrics = run_slew(scene, from_spec, progress=progress)
    slew = metrics.as_dict()
    slew.update({"controller": built.kind, "design_modes": built.design_modes,
                 "maneuver_end": built.maneuver_end, **built.info})
    extra = {"slew": slew}
    if result.controller_report is not None:
        extra["controller_report"] = result.controller_report
    if scene.requirements is not None:
        from controllers.analysis.requirements import verify_requirements

        extra["verification"] = verify_requirements(result.model, built.controller,
                                                    scene.requirements)
    return result, extra, built.reference_angle


def execute(scene, progress=None) -> tuple:
    """Run a loaded scene.

    Parameters
    ----------
    scene : Scene
        The scene: its model, manoeuvre, controller, actuator, sensors and integrator.
    progress : bool or callable, optional
        As for :func:`flexctl.simulate`. Default none.

    Returns
    -------
    result : SimulationResult
    extra : dict
        Entries for the run's ``summary.json`` beside the scene and the result: ``slew`` (the
        controller kind, design modes and slew metrics) and ``controller_report`` for a
        controlled slew; empty otherwise.
    reference : callable or None
        The hub-angle reference ``angle(t)`` (rad) the controller tracked
        (:attr:`controllers.factory.BuiltController.reference_angle`); None without one.
    """
    from .spatial_scene import SpatialScene
    if isinstance(scene, SpatialScene):
        from .spatial_report import run_spatial_scene
        return run_spatial_scene(scene), {}, None
    if scene.controller is None:
        return run_scene(scene, progress=progress), {}, None
    return _run_controlled(scene, progress)


def write_complete(scene, result, out, overrides: dict, extra: dict,
                   reference=None, animate: bool = False) -> dict:
    """:func:`~flexctl.app.report.write_run` into a temporary directory next to ``out``; the
    files are moved into ``out`` only once every one is written, so a failure leaves ``out``
    as it was.

    Parameters
    ----------
    scene : Scene
        The scene run.
    result : SimulationResult
        The run of ``scene``.
    out : str or path-like
        Output directory, created (with its parents) if missing.
    overrides : dict
        The overrides the scene was loaded with, ``{"dotted.key": value}``.
    extra : dict
        More entries for ``summary.json`` (as :func:`execute` returns them).
    reference : callable, optional
        The hub-angle reference ``angle(t)`` (rad) drawn on ``response.png`` (as
        :func:`execute` returns it).
    animate : bool, optional
        Also write ``animation.gif`` (:func:`flexctl.app.spatial_animation.animate_spatial`;
        spatial scenes only). Default False.

    Returns
    -------
    dict
        The run's summary, with ``files`` naming the files in ``out``.

    Raises
    ------
    flexctl.model.errors.InputValueError
        If ``out`` is a file, or a folder stands at one of the files' names (``out`` is then
        unchanged).
    OSError
        If ``out`` cannot be created or written (``out`` is then unchanged).
    """
    out = Path(out)
    from .spatial_scene import SpatialScene
    spatial = isinstance(scene, SpatialScene)
    if animate and not spatial:
        raise InputValueError(f"animate draws spatial scenes (a 3 x 3 hub.inertia); "
                              f"{scene.name} is planar")
    if animate:
        from .spatial_animation import ANIMATION
    names = (TIMESERIES, SUMMARY, RESPONSE_PLOT) + ((ANIMATION,) if animate else ()) + (
        (NICHOLS_PLOT, BODE_PLOT) if (extra or {}).get("verification") is not None else ())
    with staged_folder(out, names=names) as stage:
        if spatial:
            from .spatial_report import write_spatial_run
            summary = write_spatial_run(scene, result, stage, overrides=overrides,
                                        animate=animate)
        else:
            summary = write_run(scene, result, stage, overrides=overrides, extra=extra,
                                reference=reference)
    summary["files"] = {kind: str(out / Path(path).name)
                        for kind, path in summary.get("files", {}).items()}
    return summary
