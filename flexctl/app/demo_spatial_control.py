"""The demo's three-axis control section: every controller kind flies the same slew.

:func:`three_axis_control` flies the built-in ``spatial-pyramid-slew`` (two arrays and a boom
on a pinned bus, a biased pyramid of four wheels with motor lag and friction, a star tracker
and a gyro) on the exact spatial model with each controller kind of :data:`CONTROLLERS`: the
scene's quaternion feedback through the attitude filter, the LQG on an eigenaxis slew through
the same sensors, and, reading the plant's state, the LQR on an eigenaxis slew, the LQR on the
optimal slew planned within the wheels' limits and the NMPC on that plan. Its table gives what
an attitude engineer reads off a slew: the pointing error at the slew's end and at the run's,
the residual tip vibration after the slew, the peak wheel speed and power, and the torque
used (the integral of every wheel's motor torque).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from ..sim.quaternions import error_angles
from .scenes import load_scene
from .section import Section, save_figure, save_table
from .spatial_report import run_spatial_scene
from .spatial_scene import parse_spatial_scene

__all__ = ["three_axis_control", "CONTROLLERS", "SCENE", "SLEW_DURATION"]

#: The scene every controller flies.
SCENE = "spatial-pyramid-slew"
#: The planned and eigenaxis slews' length, s (the step laws get no profile).
SLEW_DURATION = 15.0

_WEIGHTS = {"hub_angle": 0.05, "hub_rate": 0.05, "tip_deflection": 0.005, "torque": 0.1,
            "torque_limit": 0.1, "design_modes": 1}
_SLEW = {"slew_duration": SLEW_DURATION}
#: Each row: its label, whether it reads the sensors (else the plant's state), and the
#: ``[controller]`` keys over the scene's own (``None``: the scene's quaternion feedback).
CONTROLLERS = (
    ("quaternion feedback, step (sensors, filter)", True, None),
    ("LQG, eigenaxis slew (sensors, filter)", True,
     {"kind": "lqg", **_WEIGHTS, **_SLEW, "angle_noise": 1e-4, "rate_noise": 1e-4,
      "process_torque": 1e-3}),
    ("LQR, eigenaxis slew (state)", False, {"kind": "lqr", **_WEIGHTS, **_SLEW}),
    ("LQR, optimal slew (state)", False,
     {"kind": "lqr", **_WEIGHTS, **_SLEW, "slew_shape": "optimal", "slew_smoothness": 1.0}),
    ("NMPC, optimal slew (state)", False,
     {"kind": "nmpc", **_WEIGHTS, **_SLEW, "slew_shape": "optimal", "slew_smoothness": 1.0}),
)


def _scene_for(base, sensors: bool, keys):
    """The base scene with the controller ``keys`` (and without its sensors for a law that
    reads the state)."""
    if keys is None:
        return base
    data = copy.deepcopy(base.data)
    common = {k: data["controller"][k] for k in ("sample_time", "slew_axis", "slew_angle")}
    data["controller"] = {**common, **keys}
    if not sensors:
        data.pop("sensors", None)
    return parse_spatial_scene(data, name=base.name)


def _metrics(scene, result) -> dict:
    """What the table reports of one run."""
    target = scene.loop.law.target
    end = int(np.argmin(np.abs(result.t - SLEW_DURATION)))
    after = result.t > SLEW_DURATION
    tips = list(result.tips.values())
    motor = np.abs(result.wheel_torques)
    return {
        "status": result.status,
        "pointing_end": float(np.linalg.norm(error_angles(target, result.quaternion[:, end]))),
        "pointing_final": float(np.linalg.norm(error_angles(target,
                                                            result.quaternion[:, -1]))),
        "residual": max(float(np.max(np.abs(tip[:, after]))) for tip in tips),
        "speed": float(np.max(np.abs(result.wheel_speeds))),
        "power": float(np.max(result.wheel_power)),
        "torque_used": float(np.sum(np.trapezoid(motor, result.t, axis=1))),
        "pointing": np.array([np.linalg.norm(error_angles(target, q))
                              for q in result.quaternion.T]),
    }


def three_axis_control(out: Path, executor=None) -> Section:
    """Every controller kind of :data:`CONTROLLERS` flying :data:`SCENE` (module description).

    Parameters
    ----------
    out : Path
        Directory of the figure and the table (CSV).
    executor : object, optional
        Unused: five runs (the demo's signature for sections).

    Returns
    -------
    Section
    """
    import matplotlib.pyplot as plt

    base = load_scene(SCENE)
    runs = []
    for label, sensors, keys in CONTROLLERS:
        scene = _scene_for(base, sensors, keys)
        result = run_spatial_scene(scene)
        runs.append((label, result, _metrics(scene, result)))
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    for label, result, found in runs:
        ax.semilogy(result.t, np.maximum(found["pointing"], 1e-9), label=label)
    ax.axvline(SLEW_DURATION, color="0.6", lw=0.8, ls=":")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("pointing error (rad)")
    ax.set_title(f"{SCENE}: 30 degrees about (0.6, 0, 0.8), exact model", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    image = save_figure(fig, out / "three_axis_control.png")
    plt.close(fig)
    header = ["controller", "status", "pointing at 15 s (rad)", "pointing at 25 s (rad)",
              "residual tip after 15 s (m)", "peak wheel speed (rad/s)", "peak power (W)",
              "torque used (N m s)"]
    rows = [[label, f["status"], f"{f['pointing_end']:.2e}", f"{f['pointing_final']:.2e}",
             f"{f['residual']:.2e}", f"{f['speed']:.4g}", f"{f['power']:.3g}",
             f"{f['torque_used']:.4g}"]
            for label, _, f in runs]
    table_path = save_table(header, rows, out / "three_axis_control.csv")
    return Section(
        title="Three-axis control: every controller kind on the same slew",
        paragraphs=(
            f"{SCENE} slews two solar arrays and a boom 30 degrees about a tilted axis "
            "through a biased pyramid of four wheels (20 ms motor lag, Coulomb and viscous "
            "friction) on the exact spatial model with two modes per field. The quaternion "
            "feedback steps to the target; the LQG follows a "
            f"{SLEW_DURATION:g} s eigenaxis slew; both read the star tracker and gyro through "
            "the attitude filter. The LQR follows the eigenaxis slew or the slew planned on "
            "the arrays' modes within the wheels' limits, and the NMPC follows that plan with "
            "the wheels' torque and speed limits as its constraints; these three read the "
            "plant's state. The step law is still turning at 15 s; the laws that follow the "
            "plan end the slew nearest the target, with the wheels slower. The loops run at "
            "rtol 1e-8 and do not estimate their integration error (an open-loop run's "
            "accuracy check repeats it at a tenth of the tolerance; a sampled loop's noise "
            "and filter would need the same draws).",),
        table=(header, rows),
        images=((f"Pointing error of each controller on {SCENE}", image),),
        files=(table_path,))
