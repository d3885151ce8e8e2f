"""Files written for a run of a scene, and the Markdown report of the demo.

A run directory holds

==================  ===================================================================
``timeseries.csv``  columns ``t,theta,theta_dot,torque,tip_deflection,q1,...,qN`` (s, rad,
                    rad/s, N m, m, m); one row per output time, up to the stop time. For a
                    :class:`~flexctl.model.Structure`: ``t,theta,theta_dot,torque``, then
                    ``hub_x,hub_y`` (m) for a free hub, then ``<name>.tip_deflection`` (m)
                    of each appendage (:func:`structure_columns`). Then every other
                    named output of the model (``root_moment`` N m, ``tip_angle`` rad, ...:
                    :attr:`flexctl.Model.output_names`). With an actuator, then
                    ``wheel_speed,wheel_torque`` (rad/s, N m) for a reaction wheel or
                    ``motor_voltage,motor_current`` (V, A) for a DC motor, and ``torque``
                    is the torque the actuator puts on the hub. With ``[simulation]
                    states = true``, then every state not written yet (modal coordinates
                    and rates, m and m/s; a free hub's velocity, m/s)
``summary.json``    scene, variant, modes, status, message, peak tip deflection, clamped
                    natural frequencies, overrides, wall time, and ``scene_table``: the
                    scene as run (see :func:`summarize`; ``flexctl run summary.json``
                    runs it again)
``response.png``    :func:`flexctl.app.plotting.plot_response`
==================  ===================================================================

Nothing here computes physics; the numbers come from the result and the model. The files are
written whole or not at all (:mod:`flexctl.sim.atomic_files`): a run's three files go into a
temporary folder and are moved into the run directory once all three are complete, and
``report.md`` goes through a temporary file.

Examples
--------
>>> from flexctl.app.report import timeseries_columns
>>> timeseries_columns(2)
['t', 'theta', 'theta_dot', 'torque', 'tip_deflection', 'q1', 'q2']
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..model.layout import StateLayout
from ..model.structure import Structure
from ..sim.atomic_files import staged_folder, write_atomic
from ..sim.maneuvers import Slew, SpinUp, TorqueSamples
from .markdown import markdown_table
from .verdict import loop_unstable, summary_verdict

__all__ = ["TIMESERIES", "SUMMARY", "RESPONSE_PLOT", "NICHOLS_PLOT", "BODE_PLOT", "timeseries_columns", "structure_columns",
           "summarize",
           "json_safe",
           "write_run", "format_summary", "write_demo_report"]

TIMESERIES = "timeseries.csv"
SUMMARY = "summary.json"
RESPONSE_PLOT = "response.png"
#: The Nichols chart and the Bode plot of a scene with ``[requirements]``.
NICHOLS_PLOT = "nichols.png"
BODE_PLOT = "bode.png"
#: Significant digits written to the CSV file.
CSV_DIGITS = 12

_UNITS = {"integration_error": "m (estimated largest tip error of the integration; null where "
          "no check ran)", "t_end": "s", "t_final": "s", "peak_tip_deflection": "m",
          "appendages": "peak_tip_deflection m (in the appendage's own frame)",
          "peak_hub_travel": "m", "center_of_mass_drift": "m", "wall_time_s": "s",
          "spin_rate": "rad/s", "clamped_frequencies": "rad/s (negative: lost stiffness, "
          "value = -growth rate in 1/s)", "clamped_frequencies_at_spin": "rad/s (negative: lost "
          "stiffness, value = -growth rate in 1/s)",
          "slew": "settling_time s, overshoot fraction of the angle, final_error rad, "
          "peak_torque N m, peak_tip_deflection m, residual_vibration m (max |tip| after the "
          "manoeuvre), solve_time_s s",
          "model_validity": "deflection_ratio: peak tip deflection / beam length; "
          "geometric_error, tolerance: relative tip error against exact geometry (estimated on "
          "2 modes, flexctl.sim.validity)",
          "controller_report": "a sampled controller's run: samples, sample_time s, "
          "controller_time s (wall time in the controller), solve_time_median_s, "
          "solve_time_p99_s, solve_time_max_s s per sample (NMPC), iterations (QP or NLP), "
          "failed_steps",
          "actuator": "peak_command N m (wheel) or V (motor); peak_wheel_speed, "
          "final_wheel_speed rad/s; peak_wheel_torque N m; peak_motor_voltage V; "
          "peak_motor_current A",
          "sensors": "largest_error: largest |reading - true value| of each sensor (rad, "
          "rad/s, N m, m/s^2)"}


def timeseries_columns(n_modes: int) -> list:
    """Column names of ``timeseries.csv`` for ``n_modes`` modal coordinates.

    Parameters
    ----------
    n_modes : int
        Modes of a one-beam model, ``N``: columns ``q1`` to ``qN`` after the hub's.
    """
    return _columns(StateLayout.single(n_modes))


def _columns(layout) -> list:
    """Column names of ``timeseries.csv`` for a model's state layout (its hub angle and rate,
    then its modal coordinates, named as the layout names them)."""
    names = layout.names
    return ["t", names[layout.theta], names[layout.theta_dot], "torque", "tip_deflection",
            *names[layout.q]]


def structure_columns(structure: Structure) -> list:
    """Column names of ``timeseries.csv`` for a :class:`~flexctl.model.Structure`: the hub's
    angle, rate and torque, its position for a free hub, each appendage's tip deflection
    (named as the model's outputs are: ``<name>.tip_deflection``, ``tip_deflection`` for an
    unnamed one).

    Parameters
    ----------
    structure : Structure
        The hub and its appendages.

    Examples
    --------
    >>> from flexctl import load_scene
    >>> structure_columns(load_scene("two-array-free").system)  # doctest: +NORMALIZE_WHITESPACE
    ['t', 'theta', 'theta_dot', 'torque', 'hub_x', 'hub_y', 'wing_a.tip_deflection',
     'wing_b.tip_deflection']
    """
    hub = ["hub_x", "hub_y"] if structure.free else []
    tips = [f"{name}.tip_deflection" if name else "tip_deflection" for name in structure.names]
    return ["t", "theta", "theta_dot", "torque", *hub, *tips]


def _timeseries(result, states: bool = False) -> tuple:
    """``(columns, table)`` of ``timeseries.csv``: a HubBeam's states, a Structure's named
    outputs, then every other named output (``root_moment``, ``tip_angle``, ...), the
    actuator's signals, and with ``states`` every state not yet written (modal rates, a free
    hub's velocity, an actuator's states)."""
    columns, table = _mechanical_timeseries(result)
    extra = {name: values for name, values in result.outputs.items() if name not in columns}
    extra.update({name: v for name, v in result.actuator_signals.items() if name not in extra})
    if states:
        names = result.model.state_names
        extra.update({name: result.states[k] for k, name in enumerate(names)
                      if name not in columns and name not in extra})
    if not extra:
        return columns, table
    return columns + list(extra), np.column_stack(
        [table] + [np.asarray(v, dtype=float).reshape(-1) for v in extra.values()])


def _mechanical_timeseries(result) -> tuple:
    system = result.model.system
    if not isinstance(system, Structure):
        return _columns(result.model.layout), np.column_stack(
            (result.t, result.theta, result.theta_dot, result.torque, result.tip_deflection,
             result.q.T))
    columns = structure_columns(system)
    outputs = result.outputs
    missing = [name for name in columns if name not in ("t", "torque") and name not in outputs]
    if missing:
        raise LookupError(f"the model has no output {missing[0]!r} for timeseries.csv; its "
                       f"outputs are {', '.join(result.model.output_names)}")
    series = {"t": result.t, "torque": result.torque, **outputs}
    return columns, np.column_stack([np.asarray(series[name], dtype=float).reshape(-1)
                                     for name in columns])


def _hardware_summary(scene, result) -> dict:
    """``actuator`` and ``sensors`` entries of the summary (none without them): the
    actuator's kind, its command's peak and each signal's peak magnitude (``wheel_speed``
    rad/s, ``wheel_torque`` N m; ``motor_voltage`` V, ``motor_current`` A) and a wheel's
    ``final_wheel_speed``; the sensors' readings count and the largest reading error of each
    (reading minus the true value)."""
    out = {}
    signals = result.actuator_signals
    if signals:
        entry = {"kind": scene.actuator.kind if scene.actuator is not None
                 else result.model.actuator.kind,
                 "peak_command": float(np.max(np.abs(result.command))) if result.t.size
                 else 0.0}
        entry.update({f"peak_{name}": float(np.max(np.abs(v))) if v.size else 0.0
                      for name, v in signals.items()})
        if "wheel_speed" in signals and signals["wheel_speed"].size:
            entry["final_wheel_speed"] = float(signals["wheel_speed"][-1])
        out["actuator"] = entry
    if result.measurements is not None:
        readings = result.measurements
        out["sensors"] = {"samples": int(readings["t"].size), "largest_error": {
            name: float(np.max(np.abs(readings[name] - truth))) if truth.size else 0.0
            for name, truth in readings["true"].items()}}
    return out


def _maneuver_table(maneuver) -> dict:
    """The manoeuvre under the keys and units of a scene's ``[maneuver]`` table (a slew's
    angle in degrees, ``angle_deg``; a free duration as ``"free"``; torque samples as lists);
    a slew without a torque bound gives ``torque_bound`` null."""
    if isinstance(maneuver, TorqueSamples):
        return {"kind": "torque_samples", "times": maneuver.times.tolist(),
                "values": maneuver.values.tolist(), "interpolation": maneuver.interpolation}
    kind = {SpinUp: "spin_up", Slew: "slew"}.get(type(maneuver), "sine_torque")
    fields = {k: (None if v is None else float(v)) for k, v in vars(maneuver).items()}
    if kind == "slew":
        # 12 digits: the degrees the scene was written in, not their round trip through rad
        fields = {"angle_deg": float(f"{math.degrees(fields.pop('angle')):.12g}"), **fields}
        fields["duration"] = "free" if fields["duration"] is None else fields["duration"]
    return {"kind": kind, **fields}


def json_safe(value):
    """``value`` with JSON types only: a NaN or infinite number becomes null (strict JSON has
    neither), numpy scalars and arrays become numbers and lists, anything else its text.

    Parameters
    ----------
    value : object
        A summary value: dicts, lists and tuples are converted entry by entry.

    Examples
    --------
    >>> json_safe({"a": float("inf"), "b": (1, np.float64(2.5)), "c": np.arange(2)})
    {'a': None, 'b': [1, 2.5], 'c': [0, 1]}
    """
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        return json_safe(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (str, bool, int)):
        return value
    return str(value)


def _n_modes(n_modes):
    """A model's number of modes as JSON: an int, or one per appendage as given."""
    return int(n_modes) if isinstance(n_modes, (int, np.integer)) else json_safe(n_modes)


def _floats(values) -> list:
    return [float(v) for v in np.asarray(values, dtype=float).reshape(-1)]


def summarize(scene, result, overrides: dict | None = None, extra: dict | None = None) -> dict:
    """The summary of a run, as written to ``summary.json`` (JSON types only).

    Parameters
    ----------
    scene : Scene
        The scene run.
    result : SimulationResult
        The run of ``scene``.
    overrides : dict, optional
        The overrides the scene was loaded with, ``{"dotted.key": value}``.
    extra : dict, optional
        More entries for the summary, e.g. the ``slew`` metrics and ``controller_report`` of
        a controlled slew (:func:`flexctl.app.runner.execute`).

    Returns
    -------
    dict
        Keys ``scene``, ``description``, ``variant``, ``n_modes``, ``maneuver`` (under the
        keys and units of the scene's ``[maneuver]`` table: a slew's ``angle_deg``), ``status``
        (``ok``, ``diverged`` or ``singular``), ``message``, ``peak_tip_deflection`` (m),
        ``t_end`` and ``t_final`` (s), ``n_points``, ``wall_time_s`` (integration wall time,
        s), ``method`` and ``rtol`` of the integrator, ``overrides``, ``clamped_frequencies``
        (rad/s, at rest, hub clamped) and, for a spin-up, ``spin_rate`` (rad/s) with
        ``clamped_frequencies_at_spin`` at that rate; ``units`` names the units; the
        entries of ``extra`` are added as given.
        A scene with ``modes = "auto"`` adds ``mode_choice``: the number of modes chosen, the
        estimated relative tip error against the tolerance, the error estimated for each number
        of modes, the stiffening verdict and why (:meth:`flexctl.sim.fidelity.ModeChoice.to_dict`).
        ``model_validity`` gives the largest tip deflection relative to the beam length and the
        estimated geometric model error of the run (:class:`flexctl.sim.validity.ModelValidity`);
        a scene with ``variant = "auto"`` adds ``variant_choice``. ``scene_table`` holds the
        scene's tables after overrides (:attr:`flexctl.Scene.data`), from which
        :func:`flexctl.load_scene` rebuilds the scene. ``actuator`` and ``sensors``: see
        ``_hardware_summary``. A verification of the scene's ``[requirements]``
        (``extra["verification"]``) gives ``requirements`` (one entry per requirement:
        ``name``, ``required``, ``nominal``, ``worst``, ``pass``, ``unit``, ``detail``),
        ``requirements_passed``, ``requirements_coverage`` and ``flexible_modes`` (each
        mode's frequency, how it is stabilised, its peak and phase margin).
    """
    model = result.model
    summary = {
        "scene": scene.name,
        "description": scene.description,
        "variant": model.variant,
        "n_modes": _n_modes(model.n_modes),
        "maneuver": _maneuver_table(scene.maneuver),
        "status": result.status,
        "message": result.message,
        "peak_tip_deflection": float(result.peak_tip_deflection),
        "t_end": float(result.t[-1]) if result.t.size else 0.0,
        "t_final": float(scene.simulation.t_final),
        "n_points": int(result.t.size),
        "wall_time_s": float(result.wall_time),
        "integration_error": (None if result.integration_error is None
                              else float(result.integration_error)),
        "method": str(result.method),
        "rtol": float(result.rtol),
        "overrides": dict(overrides or {}),
        # the scene's tables after overrides: load_scene(summary.json) rebuilds the scene
        "scene_table": scene.data,
        "clamped_frequencies": _floats(model.natural_frequencies(0.0, hub="clamped")),
    }
    if isinstance(scene.maneuver, SpinUp):
        spin = float(scene.maneuver.spin_rate)
        summary["spin_rate"] = spin
        summary["clamped_frequencies_at_spin"] = _floats(
            model.natural_frequencies(spin, hub="clamped"))
    summary.update(_structure_summary(model, result))
    summary.update(_hardware_summary(scene, result))
    choice = scene.mode_choice()
    if choice is not None:
        summary["mode_choice"] = choice.to_dict()
    if result.validity is not None:
        summary["model_validity"] = result.validity.to_dict()
    variant_choice = scene.variant_choice()
    if variant_choice is not None:
        summary["variant_choice"] = variant_choice.to_dict()
    extra = dict(extra or {})
    verification = extra.pop("verification", None)
    summary.update(extra)
    if verification is not None:
        summary["requirements"] = verification.as_list()
        summary["requirements_passed"] = verification.passed
        summary["requirements_coverage"] = verification.coverage
        summary["flexible_modes"] = [
            {"mode": v.mode, "frequency": v.frequency, "stabilised_by": v.kind,
             "peak_db": v.peak_db, "peak_frequency": v.peak_frequency,
             "phase_margin_deg": v.phase_margin_deg,
             "exclusion_zone_distance": v.score} for v in verification.modes]
    summary["units"] = {k: v for k, v in _UNITS.items() if k in summary}
    if choice is not None:
        summary["units"]["mode_choice"] = (
            "estimated_error, error_by_modes, tolerance: relative tip deflection error (largest "
            "difference from a converged model / largest tip deflection); max_spin_rate: rad/s; "
            "stiffening_effect: relative shift of the first clamped frequency; t_final: s")
    return summary


def _structure_summary(model, result) -> dict:
    """For several appendages or a free hub: ``appendages`` (each one's modes and peak tip
    deflection in its own frame, m), ``hub_support`` and a free hub's ``peak_hub_travel`` (m)
    and centre-of-mass drift (m); empty for one beam on a pinned hub."""
    names = model.structure.names
    if names == ("",) and model.layout.hub_position is None:
        return {}
    tips = result.tip_deflections
    out = {"hub_support": model.structure.hub.support,
           "appendages": {name: {"modes": int(n),
                                 "peak_tip_deflection": float(np.max(np.abs(tips[name])))
                                 if result.t.size else 0.0}
                          for name, n in zip(names, model.modes)}}
    if model.layout.hub_position is not None and result.t.size:
        hub = result.states[model.layout.hub_position]
        center = model.center_of_mass(result.states)
        out["peak_hub_travel"] = float(np.max(np.hypot(hub[0], hub[1])))
        out["center_of_mass_drift"] = float(np.max(np.hypot(*(center - center[:, :1]))))
    return out


def write_run(scene, result, out_dir, overrides: dict | None = None,
              extra: dict | None = None, reference=None) -> dict:
    """Write ``timeseries.csv``, ``summary.json`` and ``response.png`` of a run.

    A stopped run (``diverged`` or ``singular``) is written like any other, up to its stop time.
    For a slew, ``response.png`` shows the hub-angle reference (or else the target angle) and
    the torque bound, if any.

    Parameters
    ----------
    scene : Scene
        The scene run.
    result : SimulationResult
        The run of ``scene``.
    out_dir : str or path-like
        Directory, created if missing; existing files of the same names are replaced, all
        three or none (:func:`flexctl.sim.atomic_files.staged_folder`), and files of other
        names are kept.
    overrides : dict, optional
        Recorded in the summary.
    extra : dict, optional
        More summary entries (see :func:`summarize`).
    reference : callable, optional
        The hub-angle reference the controller tracked, ``angle(t)`` (rad; e.g.
        :attr:`controllers.factory.BuiltController.reference_angle`), drawn on
        ``response.png``.

    Returns
    -------
    dict
        The summary (:func:`summarize`) with ``files``: the paths written, by kind.

    Raises
    ------
    flexctl.model.errors.InputValueError
        If ``out_dir`` is a file, or a folder stands at one of the files' names.
    OSError
        If the files cannot be written (``out_dir`` is then as it was).
    """
    out = Path(out_dir)
    summary = summarize(scene, result, overrides, extra)
    verification = (extra or {}).get("verification")
    names = (TIMESERIES, SUMMARY, RESPONSE_PLOT) + (
        (NICHOLS_PLOT, BODE_PLOT) if verification else ())
    with staged_folder(out, names=names) as stage:
        _write_run_files(stage, scene, result, summary, reference)
        if verification is not None:
            _write_nichols(stage / NICHOLS_PLOT, scene, verification)
            _write_bode(stage / BODE_PLOT, scene, verification)
    summary["files"] = {"timeseries": str(out / TIMESERIES), "summary": str(out / SUMMARY),
                        "response_plot": str(out / RESPONSE_PLOT)}
    if verification is not None:
        summary["files"]["nichols_plot"] = str(out / NICHOLS_PLOT)
        summary["files"]["bode_plot"] = str(out / BODE_PLOT)
    return summary


def _write_bode(path: Path, scene, verification) -> None:
    """The Bode plot of the verified loop: each flexible mode's peak marked with how it is
    stabilised, the required attenuation drawn."""
    from .plotting_loops import plot_bode

    req = scene.requirements
    fig = plot_bode({"loop": verification.loop},
                    natural_frequencies=[v.frequency for v in verification.modes],
                    title=f"{scene.name}: each flexible mode's peak and how it is stabilised")
    ax = fig.axes[0]
    ax.axhline(10.0 ** (-req.flexible_attenuation_db / 20.0), color="tab:red", linestyle=":",
               linewidth=1.0, label=f"-{req.flexible_attenuation_db:g} dB")
    for v in verification.modes:
        peak = 10.0 ** (v.peak_db / 20.0)
        ax.plot([v.peak_frequency], [peak], marker="v", color="tab:red", linestyle="none")
        ax.annotate(f"{v.mode}: {v.kind}", (v.peak_frequency, peak), xytext=(0, 6),
                    textcoords="offset points", ha="center", fontsize=7)
    fig.savefig(path, dpi=100)


def _write_nichols(path: Path, scene, verification) -> None:
    """The Nichols chart of the verified loop, each flexible mode marked, the exclusion zone
    of the rigid-body margins drawn."""
    from .plotting_loops import plot_nichols

    req = scene.requirements
    verdict = "meets every requirement" if verification.passed else "misses a requirement"
    fig = plot_nichols({"loop": verification.loop},
                       natural_frequencies=[v.frequency for v in verification.modes],
                       margins=(req.gain_margin_db, req.phase_margin_deg),
                       title=f"{scene.name}: the loop as it flies ({verdict})")
    fig.savefig(path, dpi=100)



def _write_run_files(out: Path, scene, result, summary: dict, reference) -> None:
    """``timeseries.csv``, ``summary.json`` and ``response.png`` of :func:`write_run`."""
    columns, table = _timeseries(result, scene.simulation.states)
    np.savetxt(out / TIMESERIES, table, delimiter=",", fmt=f"%.{CSV_DIGITS}g",
               header=",".join(columns), comments="")
    (out / SUMMARY).write_text(json.dumps(json_safe(summary), indent=2, allow_nan=False)
                               + "\n")

    from .plotting import plot_response
    goal = ({"target_angle": scene.maneuver.angle, "torque_bound": scene.maneuver.torque_bound}
            if isinstance(scene.maneuver, Slew) else {})
    fig = plot_response(result, title=f"{scene.name}: {result.model.variant}, "
                                      f"{result.model.n_modes} modes, {result.status}",
                        reference=reference, **goal)
    fig.savefig(out / RESPONSE_PLOT, dpi=100)


def format_summary(summary: dict) -> str:
    """A few lines for people: status, stop reason, peak tip deflection, first frequency.

    Parameters
    ----------
    summary : dict
        A run's summary, as :func:`summarize` gives it.
    """
    status = summary_verdict(summary)
    head = (f"{summary['scene']} ({summary['variant']}, {summary['n_modes']} modes): {status}, "
            f"t = {summary['t_end']:.4g} of {summary['t_final']:.4g} s")
    lines = [head, f"  {summary['message']}",
             f"  peak tip deflection {summary['peak_tip_deflection']:.4g} m, "
             f"integration wall time {summary['wall_time_s']:.3g} s"
             + ("" if summary.get("integration_error") is None else
                f", estimated integration error {summary['integration_error']:.2g} m"),
             f"  first clamped frequency {summary['clamped_frequencies'][0]:.4g} rad/s at rest"]
    if "clamped_frequencies_at_spin" in summary:
        w = summary["clamped_frequencies_at_spin"][0]
        note = " (negative: stiffness lost)" if w < 0 else ""
        lines[-1] += f", {w:.4g} at {summary['spin_rate']:.4g} rad/s{note}"
    choice = summary.get("mode_choice")
    if choice:
        lines.append(f"  modes chosen automatically: {choice['n_modes']} (estimated truncation "
                     f"error {choice['estimated_error']:.2g} of the peak, tolerance "
                     f"{choice['tolerance']:.2g}); stiffening "
                     f"{'matters' if choice['stiffening_matters'] else 'does not matter'}")
    validity = summary.get("model_validity")
    if validity:
        lines.append(f"  model: {validity['message']}")
    if summary.get("variant_choice"):
        lines.append(f"  variant chosen automatically: {summary['variant_choice']['explanation']}")
    slew = summary.get("slew")
    if slew:
        shown = slew.get("shown") or {}
        settle = slew["settling_time"]
        settle = ("not settled" if settle is None
                  else f"settled (2 %) at {shown.get('settling_time', f'{settle:.3g} s')}")
        residual = shown.get("residual_vibration", f"{slew['residual_vibration']:.3g} m")
        filters = (f" through {slew['structural_filters']}"
                   if slew.get("structural_filters") else "")
        lines.append(f"  slew by {slew['controller']}{filters} (designed on "
                     f"{slew['design_modes']} modes): {settle}, overshoot {100 * slew['overshoot']:.2g} %, peak torque "
                     f"{slew['peak_torque']:.3g} N m, residual tip vibration "
                     f"{residual} after {slew['maneuver_end']:.3g} s")
        if "solve_time_s" in slew:
            what = "reference trajectory " if slew["controller"] == "nmpc" else ""
            lines[-1] += (f", {what}solved in {slew['solve_time_s']:.3g} s "
                          f"({slew['ipopt_status']})")
        if slew.get("errors"):
            lines.append(f"  metric errors: against the loop on the {slew['errors']['reference']}"
                         " plant (twice the difference, a run of "
                         f"{slew['errors'].get('reference_wall_time', 0.0):.2g} s) and the "
                         "run's accuracy check")
        stability = slew.get("loop_stability")
        if stability:
            lines.append(f"  loop on the plant: {stability['message']}")
    checks = summary.get("requirements")
    if checks:
        missed = [c["name"] for c in checks if not c["pass"]]
        lines.append(f"  requirements: {len(checks) - len(missed)} of {len(checks)} met over "
                     "the uncertainty" + (f"; missed: {', '.join(missed)}" if missed else ""))
    sampled = summary.get("controller_report")
    if sampled:
        line = (f"  sampled every {1e3 * sampled['sample_time']:.3g} ms "
                f"({sampled['samples']} samples)")
        if "solve_time_median_s" in sampled:
            line += (f"; {sampled['mode']} ({sampled['qp_solver']}) per sample: median "
                     f"{1e3 * sampled['solve_time_median_s']:.3g} ms, 99th percentile "
                     f"{1e3 * sampled['solve_time_p99_s']:.3g} ms, max "
                     f"{1e3 * sampled['solve_time_max_s']:.3g} ms, "
                     f"{sampled['failed_steps']} failed")
        lines.append(line)
    lines += _hardware_lines(summary)
    files = summary.get("files")
    if files:
        folder = Path(files["summary"]).parent
        names = ", ".join(Path(p).name for p in files.values())
        lines.append(f"  wrote {names} in {folder}")
    return "\n".join(lines)


def _hardware_lines(summary: dict) -> list:
    """The console lines of the actuator's peaks and the sensors' errors."""
    lines = []
    actuator = summary.get("actuator")
    if actuator and actuator["kind"] == "reaction_wheel":
        lines.append(f"  reaction wheel: peak speed {actuator['peak_wheel_speed']:.4g} rad/s, "
                     f"final {actuator['final_wheel_speed']:.3g} rad/s, peak motor torque "
                     f"{actuator['peak_wheel_torque']:.3g} N m")
    elif actuator:
        lines.append(f"  DC motor: peak voltage {actuator['peak_motor_voltage']:.3g} V, peak "
                     f"current {actuator['peak_motor_current']:.3g} A")
    sensors = summary.get("sensors")
    if sensors:
        worst = ", ".join(f"{name} {err:.2g}" for name, err in
                          sensors["largest_error"].items())
        lines.append(f"  sensors: {sensors['samples']} readings, largest errors {worst}")
    return lines


def _relative(path, base: Path) -> str:
    try:
        return Path(path).resolve().relative_to(base.resolve()).as_posix()
    except ValueError:
        return Path(path).resolve().as_posix()


def _section_lines(section, out: Path) -> list:
    """Markdown of one :class:`flexctl.app.demo.Section`: heading, text, table, figures."""
    lines = ["", f"## {section.title}", ""]
    for paragraph in section.paragraphs:
        lines += [paragraph, ""]
    if section.table:
        header, rows = section.table
        lines += markdown_table(header, rows)
        lines.append("")
    for caption, image in section.images:
        lines += [f"![{caption}]({_relative(image, out)})", ""]
    return lines


def write_demo_report(out_dir, runs: list, frequency_plot=None, *, title: str = "flexctl demo",
                      intro: str = "", frequency_note: str = "", sections=()) -> Path:
    """Write ``report.md`` for a set of runs.

    Parameters
    ----------
    out_dir : str or path-like
        Directory of the report; links are relative to it.
    runs : list of (str, dict)
        ``(label, summary)`` with each summary as returned by :func:`write_run`.
    frequency_plot : str or path-like, optional
        A frequency-against-spin plot (:func:`flexctl.app.plotting.plot_frequencies_vs_spin`)
        to include.
    title, intro : str, optional
        Heading and the paragraph under it.
    frequency_note : str, optional
        Paragraph above the frequency plot.
    sections : sequence of flexctl.app.demo.Section, optional
        Further sections (the papers' figures, the controller comparison), written after the
        frequency plot, each with its text, table and figures.

    Returns
    -------
    pathlib.Path
        The report written (whole or not at all: through a temporary file).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lines = [f"# {title}", ""] + ([intro, ""] if intro else [])
    lines += markdown_table(
        ["run", "scene", "variant", "modes", "status", "t end (s)", "peak tip deflection (m)",
         "wall time (s)", "plot"],
        [[label, s["scene"], s["variant"], s["n_modes"], summary_verdict(s),
          f"{s['t_end']:.4g}",
          f"{s['peak_tip_deflection']:.4g}", f"{s['wall_time_s']:.3g}",
          f"[response]({_relative(s['files']['response_plot'], out)})"] for label, s in runs],
        right=[False, False, False, True, False, True, True, True, False])
    stopped = [(label, s) for label, s in runs if s["status"] != "ok"]
    lines += ["", "## Stopped runs", ""]
    if stopped:
        for label, s in stopped:
            lines.append(f"- **{label}** ({s['status']} at t = {s['t_end']:.4g} s): "
                         f"{s['message']}")
    else:
        lines.append("None: every run reached its final time.")
    unstable = [(label, s) for label, s in runs if s["status"] == "ok"
                and loop_unstable((s.get("slew") or {}).get("loop_stability"))]
    if unstable:
        lines += ["", "## Runs whose loop is unstable", "",
                  "They reached their final time, but the design's own loop check finds the "
                  "loop unstable on the plant it flew (a growth slower than the run):", ""]
        lines += [f"- **{label}**: {s['slew']['loop_stability']['message']}"
                  for label, s in unstable]
    if frequency_plot is not None:
        rel = _relative(frequency_plot, out)
        lines += ["", "## Clamped natural frequencies against spin rate", ""]
        lines += [frequency_note, ""] if frequency_note else []
        lines.append(f"![frequencies against spin rate]({rel})")
    for section in sections:
        lines += _section_lines(section, out)
    lines += ["", "## Responses", ""]
    for label, s in runs:
        plot = _relative(s["files"]["response_plot"], out)
        lines += [f"### {label}", ""]
        lines += [s["description"], ""] if s.get("description") else []
        lines += [f"![{label} response]({plot})", ""]
    return write_atomic(out / "report.md", "\n".join(lines).rstrip() + "\n")
