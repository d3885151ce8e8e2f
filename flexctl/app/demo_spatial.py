"""The demo's three-axis section: what a planar model misses.

:func:`three_axes` runs the built-in spatial scenes (:data:`SPATIAL_SCENES`) on the exact
spatial model and, beside each, the planar structure that turns about the hub's ``z`` axis
(:meth:`flexctl.model.spatial_structure.SpatialStructure.to_planar`) on the planar exact model
with the same modes, under the ``z`` component of the same torque and from the same spin about
``z``. Its table gives each tip's peak in-plane deflection (in the ``x-y`` plane, across the
rod) from both models and the spatial model's peak out-of-plane deflection (along ``z``),
which the planar model cannot have; its figure plots them, and the first scene is drawn as an
animation (:func:`flexctl.app.spatial_animation.animate_spatial`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model import build_model
from ..sim.inputs import SampledTorque
from ..sim.simulation import simulate
from .scenes import load_scene
from .section import Section, save_figure, save_table
from .spatial_animation import animate_spatial
from .spatial_report import run_spatial_scene

__all__ = ["three_axes", "planar_counterpart", "SPATIAL_SCENES"]

#: The built-in spatial scenes the section runs, the first also drawn as an animation.
SPATIAL_SCENES = ("spatial-tilted-slew", "spatial-spin")


def planar_counterpart(scene):
    """The planar run of a spatial scene: its structure turning about ``z``
    (:meth:`~flexctl.model.spatial_structure.SpatialStructure.to_planar`) on the planar exact
    model with the scene's modes, under the ``z`` component of the scene's torque samples and
    from its initial spin about ``z``.

    Parameters
    ----------
    scene : SpatialScene
        A spatial scene whose structure lies in the ``x-y`` plane, its torque given by samples
        (``torque_samples``) and its initial attitude the identity.

    Returns
    -------
    SimulationResult
    """
    model = build_model(scene.structure.to_planar(), scene.n_modes, "exact")
    torque = scene.maneuver
    times, values = torque.times, torque.values[:, 2]
    if times[-1] < scene.t_final:       # the last value holds on, as the spatial run's does
        times, values = np.append(times, scene.t_final), np.append(values, values[-1])
    planar_torque = SampledTorque(times, values, interpolation=torque.interpolation)
    x0 = model.rest_state()
    x0[model.n_states // 2] = scene.angular_velocity[2]
    return simulate(model, scene.t_final, planar_torque, x0=x0, rtol=scene.rtol,
                    output_step=scene.output_step, check_validity=False)


def _split(scene, result) -> dict:
    """Each appendage's tip: in-plane (across the rod, in the x-y plane) and out-of-plane
    (z) components of the spatial run, m, shape (P,) each."""
    out = {}
    for appendage in scene.structure.appendages:
        across = np.cross([0.0, 0.0, 1.0], appendage.direction)
        tip = result.tips[appendage.name]
        out[appendage.name] = (across @ tip, tip[2])
    return out


def three_axes(out: Path, executor=None) -> Section:
    """The built-in spatial scenes against their planar counterparts
    (:func:`planar_counterpart`), with an animation of the first.

    Parameters
    ----------
    out : Path
        Directory of the figures, the animation and the table (CSV).
    executor : object, optional
        Unused: the runs are few (the demo's signature for sections).

    Returns
    -------
    Section
    """
    import matplotlib.pyplot as plt

    rows, images = [], []
    fig, axes = plt.subplots(len(SPATIAL_SCENES), 1, figsize=(7.5, 3.2 * len(SPATIAL_SCENES)),
                             squeeze=False)
    animation = None
    for k, name in enumerate(SPATIAL_SCENES):
        scene = load_scene(name)
        spatial = run_spatial_scene(scene)
        planar = planar_counterpart(scene)
        flat = planar.tip_deflections
        ax = axes[k, 0]
        for appendage in scene.structure.appendages:
            in_plane, out_of_plane = _split(scene, spatial)[appendage.name]
            rows.append([name, appendage.name] + [
                f"{1e3 * np.max(np.abs(v)):.4g}"
                for v in (flat[appendage.name], in_plane, out_of_plane)])
            ax.plot(spatial.t, 1e3 * out_of_plane,
                    label=f"{appendage.name}: out of plane (3-D)")
            ax.plot(planar.t, 1e3 * flat[appendage.name], ls="--",
                    label=f"{appendage.name}: in plane (planar)")
        ax.set_title(f"{name}: {spatial.status}, integration error "
                     f"{spatial.integration_error or 0.0:.2g}", fontsize=9)
        ax.set_ylabel("tip (mm)")
        ax.legend(fontsize=7, ncol=2)
        if k == 0:
            animation = animate_spatial(spatial, out / f"{name}.gif", frames=80, title=name)
    axes[-1, 0].set_xlabel("t (s)")
    fig.tight_layout()
    images.append(("Out-of-plane tip deflection (3-D model) against the planar model's "
                   "in-plane deflection", save_figure(fig, out / "three_axes.png")))
    plt.close(fig)
    images.append((f"{SPATIAL_SCENES[0]}: the structure turning and bending", animation))
    header = ["scene", "appendage", "planar: in plane (mm)", "3-D: in plane (mm)",
              "3-D: out of plane (mm)"]
    table_path = save_table(header, rows, out / "three_axes.csv")
    return Section(
        title="Three axes: what a planar model misses",
        paragraphs=(
            "Each built-in spatial scene runs on the exact spatial model and, beside it, on "
            "the planar exact model of the same structure turning about z, under the z "
            "component of the same torque. The planar model sees only the bending in the "
            "x-y plane; a tilted slew and a transverse pulse on a spinning hub also bend the "
            "arrays out of that plane (along their soft direction), which only the spatial "
            "model shows.",),
        table=(header, rows), images=tuple(images), files=(table_path,))
