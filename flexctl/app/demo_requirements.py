"""The demo's requirements section: a PD slew law that misses a flexible-mode requirement,
and its filtered redesign that meets every one over the structure's uncertainty.

:func:`requirements_section` takes the held PD of :data:`FIRST_DESIGN` on ``slew-90`` and on
``two-array-slew``, verifies it against :data:`DEMO_REQUIREMENTS` (rigid-body margins, every
flexible mode out of the Nichols exclusion zone, the modes above 30 rad/s gain-stabilised,
each modal frequency within +-20 % on its own and each damping ratio 0.1 to 1 %), lets
:func:`controllers.design_filters` place structural filters on its command, and flies both
laws on each scene's exact plant. It tabulates every requirement's worst case before and
after, the filters placed, the time each analysis took and the slews' residual vibration,
and draws the Nichols charts and the tip deflections.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from pathlib import Path

import numpy as np

from ..sim.validity import ModelValidityWarning
from .figures import new_figure
from .scenes import load_scene, run_slew
from .section import Section, save_figure

__all__ = ["requirements_section", "requirements_case", "REQUIREMENT_SCENES", "FIRST_DESIGN",
           "DEMO_REQUIREMENTS"]

#: The scenes whose slew the PD flies.
REQUIREMENT_SCENES = ("slew-90", "two-array-slew")
#: The first design: a PD on the hub angle, run every 10 ms with its torque held.
FIRST_DESIGN = {"kind": "pd", "bandwidth": 2.0, "damping_ratio": 0.9, "sample_time": 0.01}
#: What the loop must meet (a scene's ``[requirements]`` table).
DEMO_REQUIREMENTS = {"gain_margin_db": 6.0, "phase_margin_deg": 30.0,
                     "flexible_attenuation_db": 6.0, "flexible_phase_margin_deg": 30.0,
                     "frequency_uncertainty": 0.2, "damping_range": [0.001, 0.01],
                     "gain_stabilised_above": 30.0}


def _filter_table(item) -> dict:
    """A filter as the scene's ``controller.filters`` entry."""
    from controllers.feedback.structural_filters import FILTER_KINDS

    kind = next(name for name, cls in FILTER_KINDS.items() if isinstance(item, cls))
    return {"kind": kind, **dataclasses.asdict(item)}


def _fly(scene_name: str, controller: dict) -> tuple:
    scene = load_scene(scene_name, {"controller": controller})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelValidityWarning)
        result, _, metrics = run_slew(scene, error_estimate=False)
    return result, metrics


def requirements_case(scene_name: str) -> dict:
    """The first design of ``scene_name`` verified, its filters designed, both flown.

    Parameters
    ----------
    scene_name : str
        One of :data:`REQUIREMENT_SCENES` (any slew scene).

    Returns
    -------
    dict
        ``scene``, ``first`` and ``filtered``
        (:class:`~controllers.analysis.requirements.Verification`), ``design``
        (``FilterDesign``), ``design_seconds``, and per
        law (``"first"``, ``"filtered"``) its run's ``status``, ``residual`` (m), ``t`` and
        ``tip`` (m).
    """
    from controllers import design_filters, from_spec

    scene = load_scene(scene_name, {"controller": dict(FIRST_DESIGN),
                                    "requirements": dict(DEMO_REQUIREMENTS)})
    plant = scene.build_model()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        built = from_spec(scene, plant)
    start = time.perf_counter()
    design = design_filters(plant, built.controller, scene.requirements)
    seconds = time.perf_counter() - start
    filtered = dict(FIRST_DESIGN)
    if design.added:
        filtered["filters"] = [_filter_table(f) for f in design.added]
    runs = {}
    for label, table in (("first", dict(FIRST_DESIGN)), ("filtered", filtered)):
        result, metrics = _fly(scene_name, table)
        runs[label] = {"status": result.status, "residual": metrics.residual_vibration,
                       "t": result.t, "tip": result.tip_deflection}
    return {"scene": scene_name, "first": design.initial, "filtered": design.verification,
            "design": design, "design_seconds": seconds, "runs": runs}


def _rows(case: dict) -> list:
    first = {c.name: c for c in case["first"].checks}
    rows = []
    for check in case["filtered"].checks:
        before = first[check.name]
        rows.append((case["scene"], check.name, f"{check.required:g}",
                     f"{before.worst:.3g} ({'pass' if before.passed else 'FAIL'})",
                     f"{check.worst:.3g} ({'pass' if check.passed else 'FAIL'})"))
    return rows


def _filters_text(design) -> str:
    if not design.added:
        return "none (the first design met every requirement)"
    return "; ".join(", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                               for k, v in _filter_table(f).items()) for f in design.added)


def requirements_section(out: Path, executor=None, scenes=REQUIREMENT_SCENES) -> Section:
    """The :class:`~flexctl.app.section.Section` of the requirements demo.

    Parameters
    ----------
    out : Path
        Demo directory: ``requirements-<scenes>-nichols.png`` and
        ``requirements-<scenes>-tips.png`` go there.
    executor : concurrent.futures.Executor, optional
        Runs the scenes (its ``map``), e.g. a process pool; default None: here, in order.
    scenes : tuple of str, optional
        The slew scenes. Default :data:`REQUIREMENT_SCENES`.
    """
    from .plotting_loops import plot_nichols

    mapper = map if executor is None else executor.map
    cases = list(mapper(requirements_case, scenes))
    stem = f"requirements-{'-'.join(scenes)}"
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 4.6 * len(cases)), layout="constrained")
    axes = fig.subplots(len(cases), 2, squeeze=False)
    for row, case in zip(axes, cases):
        for ax, label in zip(row, ("first", "filtered")):
            report = case[label]
            plot_nichols({label: report.loop},
                         natural_frequencies=[v.frequency for v in report.modes],
                         margins=(DEMO_REQUIREMENTS["gain_margin_db"],
                                  DEMO_REQUIREMENTS["phase_margin_deg"]), ax=ax,
                         title=f"{case['scene']}, {label} design: "
                               f"{'meets' if report.passed else 'misses'} the requirements")
    nichols = save_figure(fig, out / f"{stem}-nichols.png")
    fig, axes = new_figure((9.0, 3.4 * len(cases)), nrows=len(cases))
    for ax, case in zip(np.atleast_1d(axes), cases):
        for label, run in case["runs"].items():
            ax.plot(run["t"], 1e3 * run["tip"], lw=1.0,
                    label=f"{label} design (residual {1e3 * run['residual']:.3g} mm)")
        ax.set_title(f"{case['scene']}: the exact plant", fontsize="medium")
        ax.set_ylabel("tip deflection (mm)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    np.atleast_1d(axes)[-1].set_xlabel("time (s)")
    tips = save_figure(fig, out / f"{stem}-tips.png")
    notes = [f"{case['scene']}: filters placed: {_filters_text(case['design'])}; "
             f"design_filters took {case['design_seconds']:.1f} s ({case['design'].tried} "
             f"candidates screened); the filtered loop's search: {case['filtered'].coverage}."
             for case in cases]
    return Section(
        title=f"Loop requirements and structural filters: {', '.join(scenes)}",
        paragraphs=(
            f"A PD on the hub angle (bandwidth {FIRST_DESIGN['bandwidth']:g} rad/s, run every "
            f"{FIRST_DESIGN['sample_time']:g} s with its torque held) on {', '.join(scenes)}, "
            "verified against written requirements "
            "(controllers.verify_requirements): rigid-body gain margin 6 dB and phase margin "
            "30 deg, every flexible mode out of the Nichols exclusion zone (6 dB, 30 deg) and "
            "the modes above 30 rad/s gain-stabilised (attenuated by 6 dB), each modal "
            "frequency within +-20 % on its own and each damping ratio from 0.1 to 1 %. "
            "A flexible mode's figure is 1 at the edge of what it must meet. The first design "
            "misses a mode; controllers.design_filters places notches on its command until "
            "every requirement holds over the uncertainty, and both laws fly the slew on the "
            "scene's exact plant. The beams of these scenes have no damping of their own: "
            "the requirements judge them damped at 0.1 % at least, while the run's loop check "
            "(controllers.check_loop), on the undamped plant, may warn of a mode that grows "
            "over hours.",
            *notes),
        table=(("scene", "requirement", "required", "first design: worst",
                "filtered: worst"), [row for case in cases for row in _rows(case)]),
        images=(("Nichols charts of the loops as they fly, the exclusion zone drawn", nichols),
                ("Tip deflection of both designs on the exact plant", tips)))
