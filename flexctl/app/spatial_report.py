"""A spatial scene run end to end: simulate, then ``timeseries.csv``, ``summary.json`` and
``response.png``.

``timeseries.csv`` carries ``t, qw, qx, qy, qz`` (hub to inertial, scalar first), ``wx, wy,
wz`` (rad/s, hub frame), ``hub_x, hub_y, hub_z`` (m, inertial frame) for a free hub, the torque
``tx, ty, tz`` (N m, hub frame) and for each appendage ``<name>.tip_dx, <name>.tip_dy,
<name>.tip_dz``: the tip's displacement from where the rigidly moving, undeformed tip would be,
in the hub frame (m). With a wheel cluster (``[actuator] kind = "wheels"``) the torque is the
one commanded of the wheels and ``wheel<k>.speed`` (rad/s, relative to the hub),
``wheel<k>.torque`` (N m, the motor torque on the rotor about its spin axis; the hub feels its
opposite) for ``k`` from 1, and ``wheels.power`` (W, drawn by the motors) follow.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..model.errors import InputValueError
from ..sim.spatial_run import SpatialResult, simulate_spatial
from .report import CSV_DIGITS, RESPONSE_PLOT, SUMMARY, TIMESERIES, json_safe
from .spatial_scene import SpatialScene

__all__ = ["run_spatial_scene", "fly_spatial_loop", "spatial_columns", "write_spatial_run",
           "format_spatial_summary", "spatial_summary"]


def run_spatial_scene(scene: SpatialScene, progress=None) -> SpatialResult:
    """Simulate a spatial scene as it is written.

    Parameters
    ----------
    scene : SpatialScene
        The spatial scene: structure, manoeuvre, initial attitude and integrator settings.
    progress : object, optional
        Accepted for the same call as a planar scene's run; not used.

    Returns
    -------
    SpatialResult
    """
    if scene.loop is not None:
        return fly_spatial_loop(scene).result
    return simulate_spatial(scene.structure, scene.t_final, scene.maneuver,
                            n_modes=scene.n_modes, angular_velocity=scene.angular_velocity,
                            quaternion=scene.quaternion, rtol=scene.rtol,
                            output_step=scene.output_step, variant=scene.variant,
                            wheels=scene.wheels, wheel_speeds=scene.wheel_speeds)


def fly_spatial_loop(scene: SpatialScene, law=None, estimator=None):
    """Fly a spatial scene's attitude loop (its ``[controller]`` and ``[sensors]``).

    Parameters
    ----------
    scene : SpatialScene
        A spatial scene with a loop.
    law : object, optional
        The law flown instead of the scene's (a compiled one, for example), as
        :func:`~flexctl.sim.spatial_loop.simulate_spatial_loop` takes it.
    estimator : object, optional
        The estimator used instead of the scene's attitude filter (with its sensors).

    Returns
    -------
    SpatialLoopResult
    """
    from ..sim.spatial_loop import simulate_spatial_loop

    loop = scene.loop
    if loop is None:
        raise InputValueError(f"{scene.name} has no [controller]: no attitude loop to fly")
    if estimator is None:
        estimator = loop.estimator(scene.quaternion)
    return simulate_spatial_loop(
        scene.structure, scene.t_final, loop.law if law is None else law,
        sample_time=loop.sample_time, n_modes=scene.n_modes, variant=scene.variant,
        wheels=scene.wheels, wheel_speeds=scene.wheel_speeds,
        angular_velocity=scene.angular_velocity, quaternion=scene.quaternion,
        sensors=loop.sensors, estimator=estimator if loop.sensors is not None else None,
        rtol=scene.rtol)


def spatial_columns(result: SpatialResult) -> list:
    """The columns of a spatial run's ``timeseries.csv``.

    Parameters
    ----------
    result : SpatialResult
        A spatial run; a free hub adds its position columns.
    """
    columns = ["t", "qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    if result.layout.free:
        columns += ["hub_x", "hub_y", "hub_z"]
    columns += ["tx", "ty", "tz"]
    for name in result.structure.names:
        columns += [f"{name}.tip_dx", f"{name}.tip_dy", f"{name}.tip_dz"]
    cluster = result.equations.cluster
    if cluster is not None:
        columns += [f"{n}.speed" for n in cluster.names]
        columns += [f"{n}.torque" for n in cluster.names]
        columns.append("wheels.power")
    return columns


def _table(result: SpatialResult) -> np.ndarray:
    parts = [result.t[None, :], result.quaternion, result.angular_velocity]
    if result.layout.free:
        parts.append(result.hub_position)
    parts.append(result.torque)
    tips = result.tips
    parts += [tips[name] for name in result.structure.names]
    if result.equations.cluster is not None:
        parts += [result.wheel_speeds, result.wheel_torques, result.wheel_power[None, :]]
    return np.vstack(parts).T


def spatial_summary(scene: SpatialScene, result: SpatialResult,
                    overrides: dict | None = None) -> dict:
    """The facts of a spatial run for ``summary.json``.

    Parameters
    ----------
    scene : SpatialScene
        The scene run.
    result : SpatialResult
        The run of scene.
    overrides : dict, optional
        The overrides the scene was loaded with.

    Returns
    -------
    dict
    """
    tips = result.tips
    peaks = {name: np.max(np.abs(tip), axis=1).tolist() if tip.size else [0.0, 0.0, 0.0]
             for name, tip in tips.items()}
    energy = result.energy() if result.t.size else np.zeros(0)
    angular, _ = result.momentum() if result.t.size else (np.zeros((3, 0)), None)
    return {
        "scene": scene.name, "spatial": True, "variant": result.variant,
        "n_modes": scene.n_modes, "support": scene.structure.hub.support,
        "status": result.status, "message": result.message,
        "t_final": scene.t_final, "t_end": float(result.t[-1]) if result.t.size else 0.0,
        "wall_time_s": result.wall_time, "rtol": result.rtol,
        "integration_error": result.integration_error,
        "quaternion_drift": result.quaternion_drift,
        "peak_tip_displacement": peaks,
        "peak_tip_deflection": max((max(p) for p in peaks.values()), default=0.0),
        "final_angular_momentum": angular[:, -1].tolist() if angular.size else None,
        "final_energy": float(energy[-1]) if energy.size else None,
        **_wheel_summary(result),
        **_loop_margins(scene),
        "overrides": dict(overrides or {}), "description": scene.description,
        "scene_table": scene.data,
    }


def _loop_margins(scene: SpatialScene) -> dict:
    """The disk margins of a scene's attitude law about its target at rest, on the linear
    plant with every mode of the run, loop at a time and all axes at once; none without a
    loop. Quaternion feedback's are the continuous law's, without delay
    (:func:`controllers.analysis.spatial_loops.quaternion_disk_margins`: on these undamped
    structures any delay of a rate feedback eventually destabilises the highest modes of the
    linear plant; the sampled run is the judge of the loop that flies). An LQR's or LQG's are
    the loop as it flies, held at its sample time, its filter in it
    (:func:`~controllers.analysis.spatial_loops.lq_loop`), with what its design left out; an
    NMPC's the held gain it is about rest at the target with no constraint active
    (:meth:`controllers.mpc.spatial_nmpc.SpatialNMPC.linear_law`)."""
    if scene.loop is None:
        return {}
    from controllers.analysis.spatial_loops import (loop_disk_margins, lq_loop,
                                                    quaternion_disk_margins)

    law = scene.loop.law
    if hasattr(law, "linear_law"):              # an NMPC: its gain about rest, no limit active
        law = law.linear_law()
    if hasattr(law, "spin_rates"):
        return {"loop_margins": _scheduled_margins(scene, law)}
    if hasattr(law, "loop_poles"):
        from ..model.spatial_plant import linearize_spatial

        margins = loop_disk_margins(lq_loop(law, linearize_spatial(scene.structure,
                                                                   scene.n_modes)))
        extra = {"held_at": law.sample_time, "design_note": law.note}
    else:
        margins = quaternion_disk_margins(law, scene.structure, n_modes=scene.n_modes)
        extra = {"held_at": None}
    return {"loop_margins": {**_margin_fields(margins), **extra}}


def _margin_fields(margins) -> dict:
    """A :class:`~controllers.analysis.spatial_loops.DiskMargins` as summary fields."""
    multiloop = margins.multiloop
    return {"closed_loop_stable": margins.closed_loop_stable,
            "spectral_abscissa": margins.spectral_abscissa,
            "disk_margin": margins.disk_margin.tolist(),
            "gain_margin_db": margins.gain_margin_db.tolist(),
            "phase_margin_deg": margins.phase_margin_deg.tolist(),
            "multiloop": None if multiloop is None else list(multiloop)}


def _scheduled_margins(scene: SpatialScene, law) -> dict:
    """A scheduled LQR's disk margins at each design spin, about that spin on the plant with
    every mode of the run: the worst (an unstable one first, then the smallest disk) with
    each spin's stability and smallest disk."""
    from controllers.analysis.spatial_loops import loop_disk_margins, lq_loop

    from ..model.spatial_plant import linearize_spatial

    spins = []
    for rate in law.spin_rates:
        plant = linearize_spatial(scene.structure, scene.n_modes,
                                  angular_velocity=rate * law.spin_axis, variant=law.variant)
        spins.append((float(rate), loop_disk_margins(lq_loop(law, plant, spin=rate))))
    rate, worst = min(spins, key=lambda item: (item[1].closed_loop_stable,
                                               float(np.min(item[1].disk_margin))))
    return {**_margin_fields(worst), "held_at": law.sample_time, "at_spin": rate,
            "per_spin": [{"spin": r, "closed_loop_stable": m.closed_loop_stable,
                          "spectral_abscissa": m.spectral_abscissa,
                          "disk_margin": float(np.min(m.disk_margin))} for r, m in spins]}


def _wheel_summary(result: SpatialResult) -> dict:
    """A wheel cluster's peaks (none without one)."""
    if result.equations.cluster is None:
        return {}
    if not result.t.size:
        return {"wheels": result.equations.cluster.count}
    return {"wheels": result.equations.cluster.count,
            "peak_wheel_speed": np.max(np.abs(result.wheel_speeds), axis=1).tolist(),
            "peak_wheel_torque": np.max(np.abs(result.wheel_torques), axis=1).tolist(),
            "peak_wheel_power": float(np.max(result.wheel_power)),
            "final_wheel_speed": result.wheel_speeds[:, -1].tolist()}


def write_spatial_run(scene: SpatialScene, result: SpatialResult, out_dir,
                      overrides: dict | None = None, animate: bool = False) -> dict:
    """Write ``timeseries.csv``, ``summary.json`` and ``response.png`` of a spatial run
    (and ``animation.gif``).

    Parameters
    ----------
    scene : SpatialScene
        The scene run.
    result : SpatialResult
        Its run.
    out_dir : str or path-like
        Directory, created if missing.
    overrides : dict, optional
        Recorded in the summary.
    animate : bool, optional
        Also write ``animation.gif`` (:func:`~flexctl.app.spatial_animation.animate_spatial`,
        when the run has two output times or more). Default False.

    Returns
    -------
    dict
        The summary with ``files``: the paths written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = spatial_summary(scene, result, overrides)
    np.savetxt(out / TIMESERIES, _table(result), delimiter=",", fmt=f"%.{CSV_DIGITS}g",
               header=",".join(spatial_columns(result)), comments="")
    (out / SUMMARY).write_text(json.dumps(json_safe(summary), indent=2, allow_nan=False)
                               + "\n")
    figure = plot_spatial_response(result, title=f"{scene.name}: {scene.variant}, "
                                                 f"{scene.n_modes} modes per field, "
                                                 f"{result.status}")
    figure.savefig(out / RESPONSE_PLOT, dpi=100)
    import matplotlib.pyplot as plt
    plt.close(figure)
    summary["files"] = {"timeseries": str(out / TIMESERIES), "summary": str(out / SUMMARY),
                        "response_plot": str(out / RESPONSE_PLOT)}
    if animate and result.t.size >= 2:
        from .spatial_animation import ANIMATION, animate_spatial
        animate_spatial(result, out / ANIMATION, title=scene.name)
        summary["files"]["animation"] = str(out / ANIMATION)
    return summary


def plot_spatial_response(result: SpatialResult, title: str = ""):
    """Attitude (3-2-1 Euler angles), angular velocity and every tip's three components.

    Parameters
    ----------
    result : SpatialResult
        The run drawn.
    title : str, optional
        Figure title. Default none.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    figure = Figure(figsize=(9, 8), layout="constrained")
    axes = figure.subplots(3, 1, sharex=True)
    euler = np.degrees(result.euler_angles()) if result.t.size else np.zeros((3, 0))
    for row, label in zip(euler, ("yaw", "pitch", "roll")):
        axes[0].plot(result.t, row, label=label)
    axes[0].set_ylabel("attitude, deg")
    for row, label in zip(result.angular_velocity, ("wx", "wy", "wz")):
        axes[1].plot(result.t, row, label=label)
    axes[1].set_ylabel("angular velocity, rad/s")
    for name, tip in result.tips.items():
        for row, axis in zip(tip, "xyz"):
            axes[2].plot(result.t, 1e3 * row, label=f"{name} d{axis}")
    axes[2].set_ylabel("tip displacement, mm (hub frame)")
    axes[2].set_xlabel("t, s")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, ncol=3)
    figure.suptitle(title)
    return figure


def format_spatial_summary(summary: dict) -> str:
    """A few lines for people: status, peak tip displacements, accuracy.

    Parameters
    ----------
    summary : dict
        As :func:`spatial_summary` gives it.

    Returns
    -------
    str
    """
    lines = [f"{summary['scene']} (spatial, {summary['variant']}, {summary['n_modes']} modes "
             "per field): "
             f"{summary['status']}, t = {summary['t_end']:.4g} of {summary['t_final']:.4g} s",
             f"  {summary['message']}"]
    error = summary.get("integration_error")
    lines.append(f"  integration wall time {summary['wall_time_s']:.3g} s"
                 + ("" if error is None else
                    f", estimated integration error {error:.2g} of each tip's peak")
                 + f", quaternion drift {summary['quaternion_drift']:.2g}")
    for name, peak in summary["peak_tip_displacement"].items():
        lines.append(f"  {name}: peak tip displacement (dx, dy, dz) = "
                     + ", ".join(f"{1e3 * p:.4g}" for p in peak) + " mm")
    margins = summary.get("loop_margins")
    if margins:
        held = margins.get("held_at")
        law = "continuous law" if held is None else f"law held at {held:g} s"
        about = ("the target" if "at_spin" not in margins else
                 f"the spin at {margins['at_spin']:g} rad/s (the worst of "
                 f"{len(margins['per_spin'])} design spins)")
        if not margins["closed_loop_stable"]:
            lines.append(f"  {law} about {about} UNSTABLE on the linear plant (spectral "
                         f"abscissa {margins['spectral_abscissa']:.3g} 1/s)")
        else:
            lines.append(f"  disk margins of the {law} about {about} (x, y, z): gain "
                         + ", ".join(f"{g:.3g}" for g in margins["gain_margin_db"])
                         + " dB, phase " + ", ".join(f"{p:.3g}" for p in
                                                    margins["phase_margin_deg"]) + " deg"
                         + ("" if margins["multiloop"] is None else
                            f"; all axes at once {margins['multiloop'][1]:.3g} dB, "
                            f"{margins['multiloop'][2]:.3g} deg"))
        if margins.get("design_note"):
            lines.append(f"  design: {margins['design_note']}")
    files = summary.get("files")
    if files:
        folder = Path(files["summary"]).parent
        lines.append(f"  wrote {', '.join(Path(p).name for p in files.values())} in {folder}")
    return "\n".join(lines)
