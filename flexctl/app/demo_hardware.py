"""The demo's hardware section: what the actuator and the sensors change in a slew.

:func:`hardware` runs the best controllers of the two hardware scenes (``wheel-slew``: a
spacecraft turned by a reaction wheel; ``flexible-link``: a lab rig turned by a geared DC
motor) three times each: on an ideal hub torque reading the exact state, through the scene's
actuator reading the exact state, and through the actuator reading the scene's noisy,
quantised, late sensors behind a Kalman filter. It tabulates the residual vibration,
settling, final error, the actuator's peak demand (wheel speed or motor voltage) and the hub
torque, and plots the tip deflection of each setup.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np

from ..sim.validity import ModelValidityWarning
from .figures import new_figure
from .scenes import load_scene, run_slew
from .section import Section, save_figure

__all__ = ["hardware", "HARDWARE_CASES", "SETUPS", "hardware_run"]

#: ``(scene, controller tables)`` compared: each scene's best controllers.
HARDWARE_CASES = (
    ("wheel-slew", ({"kind": "lqr"}, {"kind": "pd", "bandwidth": 0.3})),
    ("flexible-link", ({"kind": "lqr", "hub_angle": 0.01, "hub_rate": 1.0,
                        "tip_deflection": 0.002, "torque": 0.2}, {"kind": "trajopt+lqr"})),
)
#: The three setups: what the scene keeps of its hardware.
SETUPS = ("ideal torque, exact state", "actuator, exact state", "actuator and sensors")


def hardware_run(scene_name: str, table: dict, setup: str) -> dict:
    """One slew of ``scene_name`` with the ``[controller]`` ``table`` in one of
    :data:`SETUPS`: its metrics, the actuator's peak demand and the tip history.

    Parameters
    ----------
    scene_name : str
        A slew scene with an actuator and sensors (those of :data:`HARDWARE_CASES`).
    table : dict
        The scene's ``[controller]`` table, e.g. ``{"kind": "lqr"}``.
    setup : str
        One of :data:`SETUPS`: what the scene keeps of its actuator and sensors.
    """
    from controllers import from_spec

    scene = load_scene(scene_name, {"controller": dict(table)})
    if setup == SETUPS[0]:
        scene = dataclasses.replace(scene, actuator=None, sensors=None)
    elif setup == SETUPS[1]:
        scene = dataclasses.replace(scene, sensors=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ModelValidityWarning)
        result, built, metrics = run_slew(scene, from_spec)
    signals = result.actuator_signals
    demand = ("wheel_speed" if "wheel_speed" in signals else
              "motor_voltage" if "motor_voltage" in signals else None)
    return {"scene": scene_name, "kind": table["kind"], "setup": setup,
            "status": result.status, "residual": metrics.residual_vibration,
            "settling": metrics.settling_time, "final_error": metrics.final_error,
            "peak_torque": metrics.peak_torque,
            "demand": None if demand is None else float(np.max(np.abs(signals[demand]))),
            "demand_name": demand, "t": result.t, "tip": result.tip_deflection,
            "samples": (result.measurements or {}).get("t", np.zeros(0)).size}


def _cells(run: dict) -> tuple:
    settle = run["settling"]
    demand = "-" if run["demand"] is None else (
        f"{run['demand']:.4g} rad/s" if run["demand_name"] == "wheel_speed"
        else f"{run['demand']:.3g} V")
    return (f"{run['scene']}: {run['kind']}", run["setup"], run["status"],
            f"{run['residual']:.3g}",
            "not settled" if not np.isfinite(settle) else f"{settle:.3g}",
            f"{run['final_error']:.2e}", f"{run['peak_torque']:.3g}", demand)


def hardware(out: Path, executor=None) -> Section:
    """The :class:`~flexctl.app.section.Section` of the hardware comparison.

    Parameters
    ----------
    out : Path
        Demo directory: ``hardware.png`` is written there.
    executor : concurrent.futures.Executor, optional
        Runs the slews (its ``map``), e.g. a process pool; default None: here, in order.
    """
    jobs = [(name, table, setup) for name, tables in HARDWARE_CASES for table in tables
            for setup in SETUPS]
    mapper = map if executor is None else executor.map
    runs = list(mapper(hardware_run, *zip(*jobs)))
    fig, axes = new_figure((9.0, 7.0), nrows=len(HARDWARE_CASES))
    for ax, (name, tables) in zip(axes, HARDWARE_CASES):
        for run in runs:
            if run["scene"] == name and run["kind"] == tables[0]["kind"]:
                ax.plot(run["t"], 1e3 * run["tip"], label=run["setup"], lw=1.0)
        ax.set_title(f"{name}, {tables[0]['kind']}", fontsize="medium")
        ax.set_ylabel("tip deflection (mm)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("time (s)")
    image = save_figure(fig, out / "hardware.png")
    wheel, link = (load_scene(name) for name, _ in HARDWARE_CASES)
    return Section(
        title="Actuators and sensors in the loop",
        paragraphs=(
            f"The best controllers of two scenes, each run on an ideal hub torque reading the "
            f"exact state, then through the scene's actuator, then through the actuator "
            f"reading the scene's sensors behind a discrete Kalman filter "
            f"(controllers.Observed). wheel-slew: {wheel.description}; the wheel's torque "
            f"limit {wheel.actuator.torque_limit:g} N m and speed limit "
            f"{wheel.actuator.speed_limit:g} rad/s, its sensors read every "
            f"{wheel.sensors.sample_time:g} s. flexible-link: {link.description}; its "
            f"sensors read every {link.sensors.sample_time:g} s. Residual vibration: largest "
            "|tip deflection| after the manoeuvre's nominal end; settling: 2 % band of the "
            "hub angle; demand: the wheel's peak speed or the motor's peak voltage.",),
        table=(("scene: controller", "setup", "status", "residual vibration (m)",
                "settling time (s)", "final error (rad)", "peak hub torque (N m)",
                "peak demand"), [_cells(run) for run in runs]),
        images=(("Tip deflection of the first controller of each scene, per setup", image),))
