"""The demo's structure section: what a second array and a free hub change.

:func:`structures` runs one torque (the ``two-array-free`` scene's) on four structures built
from the same panel: one beam on a pinned hub (the papers' model), two arrays on a pinned
hub, two arrays on a free hub and a single wing on a free hub, all on the exact variant with
the same modes per appendage. It tabulates the rigid inertia the torque turns, the lowest
hub-free frequency, the modes the torque cannot move, each tip's peak and residual vibration,
and the free hub's travel, and plots the tip histories (one trace per appendage).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..model import Appendage, HubBeam, Structure, build_model
from ..sim.simulation import simulate
from .scenes import load_scene
from .section import Section, save_figure

__all__ = ["structures", "structure_cases"]


def structure_cases(scene) -> dict:
    """``{label: system}``: the four structures of :func:`structures` from ``scene`` (a
    two-appendage scene on a free hub).

    Parameters
    ----------
    scene : Scene
        A scene whose system is a two-appendage structure on a free hub; its first
        appendage is the single wing.
    """
    craft = scene.system
    wing = craft.appendages[0]
    pinned_hub = dataclasses.replace(craft.hub, support="pinned")
    return {
        "one beam, pinned hub": HubBeam(hub=dataclasses.replace(pinned_hub, mass=0.0),
                                        beam=wing.beam, masses=wing.masses),
        "two arrays, pinned hub": dataclasses.replace(craft, hub=pinned_hub),
        "two arrays, free hub": craft,
        "single wing, free hub": Structure(hub=craft.hub, appendages=(
            Appendage(name=wing.name, beam=wing.beam, masses=wing.masses),)),
    }


def _row(label, model, result, push):
    after = result.t > push.duration
    tips = result.tip_deflections
    report = model.modal_visibility()
    flexible = [w for w in report.frequencies if w > 0.0]
    hidden = [w for j, w in enumerate(report.frequencies)
              if w > 0.0 and j in report.uncontrollable("torque")]
    travel = "pinned"
    if model.layout.hub_position is not None:
        out = result.outputs
        travel = f"{1e3 * float(np.max(np.hypot(out['hub_x'], out['hub_y']))):.3g}"
    peaks = ", ".join(f"{float(np.max(np.abs(v))):.4g}" for v in tips.values())
    residual = ", ".join(f"{float(np.max(np.abs(v[after]))):.4g}" for v in tips.values())
    return (label, f"{model.rigid_inertia:.4g}", f"{flexible[0]:.4g}",
            ", ".join(f"{w:.4g}" for w in hidden) or "none", peaks, residual, travel)


def structures(out: Path, scene_name: str = "two-array-free"):
    """The :class:`~flexctl.app.section.Section` comparing the four structures.

    Parameters
    ----------
    out : Path
        Demo directory: ``structures.png`` is written there.
    scene_name : str, optional
        A two-appendage scene on a free hub under a sine torque, whose panel and torque the
        four structures share (:func:`structure_cases`). Default ``"two-array-free"``.
    """
    from .plotting import new_figure

    scene = load_scene(scene_name)
    push = scene.maneuver
    modes = scene.model.modes
    fig, axes = new_figure((9.0, 9.0), nrows=4, sharex=True)
    rows = []
    for ax, (label, system) in zip(axes, structure_cases(scene).items()):
        model = build_model(system, n_modes=modes, variant=scene.variant)
        result = simulate(model, scene.simulation.t_final, torque=push,
                          output_step=scene.simulation.output_step)
        rows.append(_row(label, model, result, push))
        for name, tip in result.tip_deflections.items():
            ax.plot(result.t, tip, label=name or "beam")
        ax.set_title(label, fontsize="medium")
        ax.set_ylabel("tip (m)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{push.peak_torque:g} N m sine torque for {push.duration:g} s, "
                 f"{scene.variant} variant, {modes} modes per appendage")
    image = save_figure(fig, out / "structures.png")
    return Section(
        title="Several appendages and a free hub",
        paragraphs=(
            f"The {scene_name} torque on four structures built from its panel. A second array "
            "raises the inertia the torque turns, so each tip bends less; on a free hub the "
            "body turns about the centre of mass instead of its own centre, which lowers "
            "that inertia by |S_0|^2 / m and raises the lowest hub-free frequency. Two "
            "identical arrays bending against each other form modes the torque cannot move "
            "(the table's hidden modes): they stay at rest, and the two tips move together. "
            "A single wing drags the free hub sideways as it bends (hub travel, mm).",),
        table=(("structure", "rigid inertia (kg m^2)", "lowest hub-free frequency (rad/s)",
                "modes the torque cannot move (rad/s)", "peak tips (m)",
                "residual tips after the torque (m)", "hub travel (mm)"), rows),
        images=(("Tip deflections, one trace per appendage", image),))

