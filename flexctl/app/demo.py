"""``flexctl demo``: every built-in scene, the papers' figures and the controller comparisons.

:func:`run_demo` is the whole demo: it runs every built-in scene (and the comparisons of
:data:`DEMO_COMPARISONS`), draws the frequency plot, makes every section below and
writes ``report.md``. Each section function runs one case, saves its figures (PNG) and
tables (CSV) into the demo directory, and returns a :class:`Section` that
:func:`flexctl.app.report.write_demo_report` turns into Markdown; its sweeps go through
:func:`flexctl.app.sweep.sweep` on the executor given, if any. The demo sends every section
and every scene to one process pool at once, the longest first (:data:`SECTION_ORDER`,
:data:`LONG_SCENES`), so that its processes are busy to the end; each reports as it finishes,
and the report keeps its own order. Sizes are chosen to finish in well under a minute on two
cores.

==============================  =================================================================
section                         content
==============================  =================================================================
:func:`kane_spinup`             paper 001 Fig. 4: spin-up to 0.5, 2, 4 rad/s, first vs zero_order
:func:`spacecraft_torque`       paper 001 Fig. 5: 50 N m on a massless hub
:func:`hub_beam_mass`           paper 000 Figs. 5 to 8: the point mass, sweeps of d/l and R_M
:func:`slew_comparison`         every controller kind on ``slew-90`` and on ``two-array-slew``
:func:`structures`              one beam against two arrays, pinned and free hub (its own module)
:func:`three_axes`              the built-in spatial scenes against their planar counterparts, an
                                animation (its own module)
:func:`three_axis_control`      every three-axis controller kind on ``spatial-pyramid-slew``
                                (its own module)
:func:`model_error`             trajopt+lqr against NMPC when the design model is 20 % off
:func:`large_deflection`        the optimal slew designed on first_order and on exact geometry
:func:`hardware`                a reaction wheel and a DC motor, exact state and noisy sensors
                                (its own module)
:func:`requirements_section`    a PD that misses a flexible-mode requirement and its filtered
                                redesign, on slew-90 and on two-array-slew (its own module)
==============================  =================================================================

Like the command line, this module sits on top of both packages: it imports
:mod:`controllers` (inside :func:`slew_comparison`); flexctl's physics never does.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import time
import warnings
from pathlib import Path

import numpy as np

from controllers.spec import CONTROLLER_KEYS

from ..model.errors import InputError
from ..sim.atomic_files import atomic_file, staged_folder, write_atomic
from ..sim.validity import ModelValidityWarning
from .report import write_demo_report
from .run_cache import remembered
from .task_fingerprint import task_fingerprint
from .verdict import summary_verdict
from .demo_hardware import hardware
from .demo_requirements import requirements_section
from .demo_spatial import SPATIAL_SCENES, three_axes
from .demo_spatial_control import SCENE as CONTROL_SCENE
from .demo_spatial_control import three_axis_control
from .demo_structures import structures
from .section import Section, save_figure as _save
from .scenes import builtin_scenes, load_scene, run_slew
from .sweep import PointMassAmplitudes, SceneTask, response_amplitudes, sweep

__all__ = ["Section", "kane_spinup", "spacecraft_torque", "hub_beam_mass", "slew_comparison",
           "model_error", "large_deflection", "frequency_plot", "sections", "run_demo",
           "SECTIONS", "SECTION_ORDER", "LONG_SCENES",
           "PAPER_VALUES", "SWEEP_POINTS", "DEMO_COMPARISONS", "DEMO_INTRO", "DEMO_WORKERS",
           "DEMO_FREQUENCY_NOTE"]

#: Published values (the theory page, section 7), m.
PAPER_VALUES = {
    "kane_peak_w2": {"first_order": 0.28, "zero_order": 0.34},
    "spacecraft": {"peak": 0.42, "residual": 0.07},
    "hub_beam_mass": {"with": (0.263, 0.141), "without": (0.223, 0.081)},
}
#: Points of each paper-000 sweep (d/l and R_M in [0, 1]).
SWEEP_POINTS = 8
#: Controller kinds compared on the free-hub slew: all but the spin-scheduled LQR, whose
#: linearisations at a steady spin a free hub does not have (its centre circles the centre
#: of mass).
FREE_HUB_KINDS = tuple(k for k in CONTROLLER_KEYS if k != "scheduled")
#: Kane spin-up final rates of paper 001 Fig. 4, rad/s.
KANE_SPIN_RATES = (0.5, 2.0, 4.0)


def _percent(value: float, reference: float) -> str:
    return f"{100.0 * (value / reference - 1.0):+.1f} %"


def kane_spinup(out: Path, executor=None) -> Section:
    """Paper 001 Fig. 4: the Kane spin-up, first_order against zero_order.

    Parameters
    ----------
    out : Path
        Demo directory: ``paper001-fig4.png`` and ``paper001-fig4.csv`` are written there.
    executor : concurrent.futures.Executor-like or callable, optional
        Runs the sweep's points (:func:`flexctl.app.sweep.sweep`); default None: here, in
        order.
    """
    from matplotlib.figure import Figure

    from .plotting import plot_tip_deflections

    table = sweep(SceneTask(scene="kane-spinup", keep_result=True),
                  {"maneuver.spin_rate": KANE_SPIN_RATES,
                   "model.variant": ["first_order", "zero_order"]},
                  executor=executor, progress=False, on_error="raise")
    fig = Figure(figsize=(8.0, 8.0), layout="constrained")
    rows, verdicts = [], []
    for ax, w_s in zip(fig.subplots(3, 1, sharex=True), KANE_SPIN_RATES):
        runs = {r["model.variant"]: r for r in table.where(**{"maneuver.spin_rate": w_s})}
        plot_tip_deflections({k: r["result"] for k, r in runs.items()}, ax=ax,
                             title=f"w_s = {w_s:g} rad/s")
        first, zero = runs["first_order"], runs["zero_order"]
        paper = (f"{PAPER_VALUES['kane_peak_w2']['first_order']:g} / "
                 f"{PAPER_VALUES['kane_peak_w2']['zero_order']:g}" if w_s == 2.0 else
                 "ZDM diverges" if w_s == 4.0 else "models agree")
        rows.append((f"{w_s:g}", first["status"], f"{first['peak_tip_deflection']:.4f}",
                     f"{zero['status']} (t = {zero['t_end']:.4g} s)",
                     f"{zero['peak_tip_deflection']:.4f}", paper))
        if zero["status"] != "ok":
            verdicts.append(f"stops {zero['status']} at {w_s:g} rad/s (t = {zero['t_end']:.3g} s)")
        else:
            gap = abs(zero["peak_tip_deflection"] / first["peak_tip_deflection"] - 1.0)
            verdicts.append(f"peaks {100.0 * gap:.2g} % away at {w_s:g} rad/s")
    scene = load_scene("kane-spinup")
    ramp = scene.maneuver.ramp_time
    fig.suptitle(f"Paper 001 Fig. 4: Kane spin-up, T_s = {ramp:g} s")
    image = _save(fig, out / "paper001-fig4.png")
    csv = out / "paper001-fig4.csv"
    write_atomic(csv, table.to_csv())
    w_1 = scene.build_model().first_clamped_frequency
    return Section(
        title="Paper 001 Fig. 4: Kane spin-up, first_order against zero_order",
        paragraphs=(f"The hub of the {scene.system.beam.length:g} m Kane beam is spun up to w_s "
                    f"in {ramp:g} s (prescribed motion). The zero_order model drops dynamic "
                    f"stiffening; against first_order it {', '.join(verdicts)}. The first "
                    f"clamped frequency is {w_1:.3g} rad/s: spun faster, the beam without "
                    "stiffening has no restoring stiffness left in its first mode. A diverged "
                    "run's peak is the beam length, where the run stops.",),
        table=(("w_s (rad/s)", "first_order status", "first_order peak tip (m)",
                "zero_order status", "zero_order peak tip (m)", "paper 001"), rows),
        images=(("Kane spin-up: tip deflection", image),), files=(csv,))


def spacecraft_torque(out: Path) -> Section:
    """Paper 001 Fig. 5: the spacecraft under one period of 50 N m sine torque.

    Parameters
    ----------
    out : pathlib.Path
        Folder the figure ``paper001-fig5.png`` is written to.
    """
    from .plotting import plot_response
    from .scenes import run_scene

    scene = load_scene("spacecraft-torque")
    result = run_scene(scene)
    push = scene.maneuver
    peak, residual = response_amplitudes(result, push.duration)
    after = result.t > push.duration
    q1_part = float(np.max(np.abs(result.model.mode_tips[0] * result.q[0][after])))
    image = _save(plot_response(result, title=f"Paper 001 Fig. 5: spacecraft, "
                                              f"{push.peak_torque:g} N m"),
                  out / "paper001-fig5.png")
    hub = scene.system.hub
    hub_text = "Massless hub" if hub.inertia == 0.0 else f"Hub of {hub.inertia:g} kg m^2"
    paper = PAPER_VALUES["spacecraft"]
    rows = [("peak tip deflection (m)", f"{peak:.4f}", f"{paper['peak']:g}",
             _percent(peak, paper["peak"])),
            ("residual, q_1 part (m)", f"{q1_part:.4f}", f"about {paper['residual']:g}",
             _percent(q1_part, paper["residual"])),
            ("residual, total (m)", f"{residual:.4f}", f"about {paper['residual']:g}",
             _percent(residual, paper["residual"]))]
    return Section(
        title=f"Paper 001 Fig. 5: flexible spacecraft under {push.peak_torque:g} N m",
        paragraphs=(f"{hub_text}, {scene.system.beam.length:g} m beam, one period of "
                    f"{push.peak_torque:g} N m sine torque over {push.duration:g} s, "
                    f"{result.model.variant} with {result.model.n_modes} modes: "
                    f"{result.status}. The residual vibration is mostly the first modal "
                    "coordinate; the paper's \"about 0.07 m\" matches that part.",),
        table=(("quantity", "flexctl", "paper 001", "difference"), rows),
        images=(("Spacecraft response", image),))


def hub_beam_mass(out: Path, executor=None, points: int = SWEEP_POINTS) -> Section:
    """Paper 000 Figs. 5 to 8: the point mass, and sweeps of its position and mass ratios.

    Parameters
    ----------
    out : Path
        Demo directory: ``paper000-figs5-8.png``, ``paper000-fig6.csv`` and
        ``paper000-fig8.csv`` are written there.
    executor : concurrent.futures.Executor-like or callable, optional
        Runs the sweep's points (:func:`flexctl.app.sweep.sweep`); default None: here, in
        order.
    points : int, optional
        Points of each sweep, evenly spaced on ``[0, 1]``. Default :data:`SWEEP_POINTS`.
    """
    task = PointMassAmplitudes.from_scene("hub-beam-mass")
    ratios = np.round(np.linspace(0.0, 1.0, points), 4)
    by_position = sweep(task, {"mass_position_ratio": ratios}, executor=executor,
                        progress=False, description="d/l", on_error="raise")
    by_mass = sweep(task, {"mass_ratio": ratios}, executor=executor, progress=False,
                    description="R_M", on_error="raise")
    write_atomic(out / "paper000-fig6.csv", by_position.to_csv())
    write_atomic(out / "paper000-fig8.csv", by_mass.to_csv())

    # Figs. 5 and 7: time histories (four short runs, here).
    fig5, fig7 = _point_mass_histories(task)
    at_02, at_08, loaded, bare = (_amplitudes(r, task.torque.duration)
                                  for r in (*fig5.values(), *fig7.values()))
    fig = _draw_figs_5_to_8(task, fig5, fig7, by_position, by_mass)
    image = _save(fig, out / "paper000-figs5-8.png")

    m_t, d_ratio = _point_mass_labels(task.system)
    torque = task.torque
    return Section(
        title="Paper 000 Figs. 5 to 8: a point mass softens the beam",
        paragraphs=(f"Hub-beam-mass system ({m_t} at {d_ratio}), {torque.peak_torque:g} N m "
                    f"sine torque for {torque.duration:g} s. Peak: largest |tip deflection| "
                    "while the torque acts; residual: largest after it.",
                    _point_mass_sweep_text(by_position, by_mass, bare, points)),
        table=(("quantity", "flexctl", "paper 000", "difference"),
               _point_mass_table(at_02, at_08, loaded, bare)),
        images=(("Paper 000 Figs. 5 to 8", image),),
        files=(out / "paper000-fig6.csv", out / "paper000-fig8.csv"))


def _point_mass_labels(system) -> tuple:
    """Legend text of the point mass: ``("m_t = ... kg", "d = ... l")``."""
    mass, length = system.masses[0], system.beam.length
    return f"m_t = {mass.mass:g} kg", f"d = {mass.position / length:.3g} l"


def _point_mass_histories(task) -> tuple:
    """The time histories of Figs. 5 and 7.

    Returns
    -------
    fig5, fig7 : dict of {str: SimulationResult}
        The mass at 0.2 l and 0.8 l; the system with and without its mass.
    """
    from ..model import build_model
    from ..model.parameters import PointMass
    from ..sim.simulation import simulate

    system = task.system

    def history(masses):
        model = build_model(dataclasses.replace(system, masses=masses), n_modes=task.n_modes)
        return simulate(model, task.t_final, torque=task.torque, output_step=task.output_step)

    def mass_at(ratio):
        return (PointMass(mass=system.masses[0].mass, position=ratio * system.beam.length),)

    m_t, _ = _point_mass_labels(system)
    fig5 = {"d = 0.2 l": history(mass_at(0.2)), "d = 0.8 l": history(mass_at(0.8))}
    fig7 = {m_t: history(system.masses), "m_t = 0": history(())}
    return fig5, fig7


def _amplitudes(result, torque_end: float) -> dict:
    """``{"peak_amplitude": m, "residual_amplitude": m}`` of a torque response."""
    return dict(zip(("peak_amplitude", "residual_amplitude"),
                    response_amplitudes(result, torque_end)))


def _draw_figs_5_to_8(task, fig5, fig7, by_position, by_mass):
    """Figs. 5 and 7 (time histories) over Figs. 6 and 8 (sweeps, with the paper's values)."""
    from matplotlib.figure import Figure

    from .plotting import plot_sweep, plot_tip_deflections

    m_t, d_ratio = _point_mass_labels(task.system)
    fig = Figure(figsize=(11.0, 8.0), layout="constrained")
    (ax5, ax7), (ax6, ax8) = fig.subplots(2, 2)
    plot_tip_deflections(fig5, ax=ax5, title=f"Fig. 5: {m_t} at 0.2 l and 0.8 l")
    plot_tip_deflections(fig7, ax=ax7, title=f"Fig. 7: with and without the mass ({d_ratio})")
    paper_with = PAPER_VALUES["hub_beam_mass"]["with"]
    labels = {"peak_amplitude": "peak", "residual_amplitude": "residual"}
    plot_sweep(by_position, "mass_position_ratio", list(labels), ax=ax6, labels=labels,
               xlabel="R_d = d/l", ylabel="tip amplitude (m)", title="Fig. 6: position ratio",
               reference={"paper 000": [(0.9, paper_with[0]), (0.9, paper_with[1])]})
    plot_sweep(by_mass, "mass_ratio", list(labels), ax=ax8, labels=labels,
               xlabel="R_M = m_t/(rhoA l)", ylabel="tip amplitude (m)",
               title=f"Fig. 8: mass ratio ({d_ratio})",
               reference={"paper 000": [(task.default_ratios[1], paper_with[0]),
                                        (task.default_ratios[1], paper_with[1])]})
    return fig


def _point_mass_table(at_02, at_08, loaded, bare) -> list:
    """Rows of the section's table: Fig. 7's amplitudes against the paper's, and Fig. 5's
    comparison of the two mass positions (amplitudes as ``_amplitudes``)."""
    paper_with, paper_without = PAPER_VALUES["hub_beam_mass"]["with"], \
        PAPER_VALUES["hub_beam_mass"]["without"]
    rows = [("Fig. 7, with mass: peak (m)", loaded["peak_amplitude"], paper_with[0]),
            ("Fig. 7, with mass: residual (m)", loaded["residual_amplitude"], paper_with[1]),
            ("Fig. 7, without mass: peak (m)", bare["peak_amplitude"], paper_without[0]),
            ("Fig. 7, without mass: residual (m)", bare["residual_amplitude"], paper_without[1])]
    table_rows = [(label, f"{value:.4f}", f"{paper:g}", _percent(value, paper))
                  for label, value, paper in rows]
    table_rows += [("Fig. 5, d = 0.2 l / 0.8 l: peak (m)",
                    f"{at_02['peak_amplitude']:.4f} / {at_08['peak_amplitude']:.4f}",
                    "larger at 0.8 l", ""),
                   ("Fig. 5, d = 0.2 l / 0.8 l: residual (m)",
                    f"{at_02['residual_amplitude']:.4f} / {at_08['residual_amplitude']:.4f}",
                    "larger at 0.8 l", "")]
    return table_rows


def _point_mass_sweep_text(by_position, by_mass, bare, points: int) -> str:
    """The paragraph on the sweeps of Figs. 6 and 8, against the beam without mass
    (``bare``, amplitudes as ``_amplitudes``)."""
    position = by_position.column("mass_position_ratio")
    low = position <= 0.3 + 1e-9
    change = max(np.max(np.abs(by_position.column(c)[low] / bare[c] - 1))
                 for c in ("peak_amplitude", "residual_amplitude"))
    return ("Sweeps on %d points each, run through flexctl.app.sweep on the demo's process "
            "pool (%.2g s and %.2g s). Fig. 6: for d/l <= 0.3 the amplitudes stay within "
            "%.2g %% of the beam without mass (the paper: negligible); at d/l = 1 the "
            "peak is %+.0f %% and the residual %+.0f %%. Fig. 8: from R_M = 0 to 1 the "
            "peak grows from %.3f m to %.3f m and the residual from %.3f m to %.3f m, "
            "ever more slowly. Tables: [paper000-fig6.csv](paper000-fig6.csv), "
            "[paper000-fig8.csv](paper000-fig8.csv)." % (
                points, by_position.wall_time, by_mass.wall_time, 100 * change,
                100 * (by_position.column("peak_amplitude")[-1] / bare["peak_amplitude"] - 1),
                100 * (by_position.column("residual_amplitude")[-1]
                       / bare["residual_amplitude"] - 1),
                *by_mass.column("peak_amplitude")[[0, -1]],
                *by_mass.column("residual_amplitude")[[0, -1]]))


def slew_comparison(out: Path, executor=None, kinds=None,
                    scene_name: str = "slew-90") -> Section:
    """Every controller kind on a slew scene (``slew-90``, or ``two-array-slew``), in closed
    loop on the nonlinear plant.

    Parameters
    ----------
    out : Path
        Demo directory: ``controller-comparison.png`` and ``controller-comparison.csv`` are
        written there (``controller-comparison-<scene_name>.*`` for another scene).
    executor : concurrent.futures.Executor-like or callable, optional
        Runs the sweep's points (:func:`flexctl.app.sweep.sweep`); default None: here, in
        order.
    kinds : sequence of str, optional
        Controller kinds compared (among :data:`controllers.spec.CONTROLLER_KEYS`); default
        every kind.
    scene_name : str, optional
        The slew scene. Default ``"slew-90"``.
    """
    from controllers import from_spec

    from .plotting import plot_controller_comparison

    kinds = list(CONTROLLER_KEYS) if kinds is None else list(kinds)
    scene = load_scene(scene_name)
    slew = scene.maneuver
    table = sweep(SceneTask(scene=scene_name, controller_factory=from_spec, keep_result=True),
                  {"controller.kind": kinds}, executor=executor, progress=False,
                  on_error="raise")
    stem = "controller-comparison" + ("" if scene_name == "slew-90" else f"-{scene_name}")
    csv = write_atomic(out / f"{stem}.csv", table.to_csv())
    rows_by_kind = {r["controller.kind"]: r for r in table}
    plant = next(iter(rows_by_kind.values()))["result"].model
    n_plant = plant.n_modes
    fig = plot_controller_comparison(
        {k: r["result"] for k, r in rows_by_kind.items()}, rows_by_kind,
        target_angle=slew.angle, maneuver_end=slew.duration, torque_bound=slew.torque_bound,
        title=f"{scene_name}: {np.degrees(slew.angle):g} deg in {slew.duration:g} s, "
              f"{slew.torque_bound:g} N m bound, {n_plant}-mode {plant.variant} plant")
    image = _save(fig, out / f"{stem}.png")
    rows = []
    for kind, r in rows_by_kind.items():
        rows.append((kind, r["verdict"], r["residual_vibration_shown"],
                     r["settling_time_shown"], f"{r['peak_torque']:.3g}",
                     r["peak_tip_deflection_shown"], r["final_error_shown"],
                     f"{r['wall_time_s']:.2g}"))
    return Section(
        title=f"Controller comparison on {scene_name}",
        paragraphs=(f"{scene.description}. {_which_kinds(kinds)}, designed on a "
                    f"{scene.model.design_modes}-mode {scene.design_variant} model by "
                    f"controllers.from_spec and run against the {n_plant}-mode "
                    f"{scene.variant} plant. Residual "
                    "vibration: largest |tip deflection| after the manoeuvre's nominal end; "
                    "settling: 2 % band of the hub angle. Each metric carries its error (twice "
                    "its difference from the same loop on the plant with two more modes per "
                    "appendage, plus the run's integration error); a metric below its error "
                    "is shown as an upper bound. Table: "
                    f"[{stem}.csv]({stem}.csv).",),
        table=(("controller", "status", "residual vibration", "settling time",
                "peak torque (N m)", "peak tip", "final error", "wall time (s)"),
               rows),
        images=(("Controller comparison", image),), files=(csv,))


def _which_kinds(kinds) -> str:
    """"Every controller kind", or "Every controller kind but ..." for a subset."""
    left = sorted(set(CONTROLLER_KEYS) - set(kinds))
    if not left:
        return "Every controller kind"
    why = (" (a free hub has no linearisation at a steady spin to schedule on)"
           if left == ["scheduled"] else "")
    return f"Every controller kind but {', '.join(left)}{why}"


def model_error(out: Path, executor=None, kinds=("trajopt+lqr", "nmpc")) -> Section:
    """Controllers designed on a model that is off (``slew-90-model-error``), run against the
    true plant (the same controllers on the nominal ``slew-90`` are in
    :func:`slew_comparison`).

    Parameters
    ----------
    out : Path
        Demo directory: ``model-error.csv`` is written there.
    executor : concurrent.futures.Executor-like or callable, optional
        Runs the sweep's points (:func:`flexctl.app.sweep.sweep`); default None: here, in
        order.
    kinds : sequence of str, optional
        Controller kinds compared. Default ``("trajopt+lqr", "nmpc")``.
    """
    from controllers import from_spec

    base = load_scene("slew-90-model-error")
    rows, csv_rows = [], ["scene,controller,residual_vibration_m,final_error_rad,"
                          "settling_time_s,solve_time_median_ms,solve_time_p99_ms"]
    for name in ("slew-90-model-error",):
        table = sweep(SceneTask(scene=name, controller_factory=from_spec, keep_result=True),
                      {"controller.kind": list(kinds)}, executor=executor, progress=False,
                      on_error="raise")
        for r in table:
            n_plant = r["result"].model.n_modes
            report = r["result"].controller_report or {}
            median = report.get("solve_time_median_s")
            p99 = report.get("solve_time_p99_s")
            timing = "" if median is None else f"{1e3 * median:.3g} / {1e3 * p99:.3g}"
            settle = r["settling_time"]
            rows.append((name, r["controller.kind"], f"{1e3 * r['residual_vibration']:.3g}",
                         f"{np.degrees(r['final_error']):.2g}",
                         "not settled" if not np.isfinite(settle) else f"{settle:.3g}",
                         timing))
            ms = ["" if v is None else f"{1e3 * v:.6g}" for v in (median, p99)]
            csv_rows.append(f"{name},{r['controller.kind']},{r['residual_vibration']:.6g},"
                            f"{r['final_error']:.6g},{settle:.6g},{ms[0]},{ms[1]}")
    csv = write_atomic(out / "model-error.csv", "\n".join(csv_rows) + "\n")
    model = base.model
    return Section(
        title="Design-model error: trajopt+lqr against NMPC",
        paragraphs=(
            f"{base.description}. Both controllers track the optimal slew planned on the "
            f"{model.design_modes}-mode {base.design_variant} design model, whose beam "
            f"stiffness is scaled by {model.design_stiffness_factor:g} and point mass by "
            f"{model.design_mass_factor:g}; the plant is the true {n_plant}-mode "
            f"{base.variant} beam. trajopt+lqr adds LQR feedback about the plan; NMPC "
            "re-solves the plan from the measured state at every sample (real-time "
            "iteration), within the torque bound. Solve times are per sample, median / 99th "
            "percentile. The same controllers on the true model are in the controller "
            "comparison above. Table: [model-error.csv](model-error.csv).",),
        table=(("scene", "controller", "residual vibration (mm)", "final error (deg)",
                "settling time (s)", "NMPC solve (ms)"), rows),
        files=(csv,))


def large_deflection(out: Path, executor=None) -> Section:
    """What exact geometry changes on ``slew-90``: the optimal slew designed on first_order and
    on exact (few modes each), each judged on first_order and exact plants.

    Parameters
    ----------
    out : Path
        Demo directory: ``large-deflection.csv`` is written there.
    executor : concurrent.futures.Executor-like or callable, optional
        Not used (the runs share one optimisation per design model, in this process); taken as
        the other sections take it.
    """
    from controllers import from_spec

    base = load_scene("slew-90")
    runs = {}
    rows, csv_rows = [], ["design_variant,plant_variant,residual_vibration_m,final_error_rad,"
                          "peak_tip_deflection_m,geometric_error"]
    for design in ("first_order", "exact"):
        designed = None                      # one optimisation per design model
        for plant in ("first_order", "exact"):
            scene = load_scene("slew-90", overrides={
                "controller.kind": "trajopt", "model.variant": plant,
                "model.design_variant": design})
            designed = designed or from_spec(scene)
            with warnings.catch_warnings():      # first_order out of range is the point here:
                warnings.simplefilter("ignore", ModelValidityWarning)   # the table shows it
                result, built, metrics = run_slew(scene, lambda *_: designed)
            error = result.validity.geometric_error
            runs[design, plant] = metrics
            n_plant = result.model.n_modes
            rows.append((design, plant, f"{1e3 * metrics.residual_vibration:.3g}",
                         f"{np.degrees(metrics.final_error):.3g}",
                         f"{metrics.peak_tip_deflection:.3g}",
                         "exact" if plant == "exact" else f"{error:.2g}"))
            csv_rows.append(f"{design},{plant},{metrics.residual_vibration:.6g},"
                            f"{metrics.final_error:.6g},{metrics.peak_tip_deflection:.6g},"
                            f"{error:.6g}")
    csv = write_atomic(out / "large-deflection.csv", "\n".join(csv_rows) + "\n")
    bend = max(runs[d, "exact"].peak_tip_deflection for d in ("first_order", "exact")) \
        / base.system.beam.length

    def mm(design, plant):
        return f"{1e3 * runs[design, plant].residual_vibration:.3g}"

    def deg(design, plant):
        return f"{np.degrees(runs[design, plant].final_error):.2g}"

    return Section(
        title="Large deflection: what exact geometry changes on slew-90",
        paragraphs=(
            f"{base.description}. The tip bends by up to {100.0 * bend:.0f} % of the beam "
            "length on the exact plant. The minimum-effort slew "
            f"(trajopt, {base.model.design_modes} design modes, "
            f"{base.maneuver.torque_bound:g} N m bound) is "
            "optimised on each variant and played open loop on a "
            f"{n_plant}-mode plant of each variant. Designed on first_order, it leaves "
            f"{mm('first_order', 'first_order')} mm of residual vibration on first_order and "
            f"{mm('first_order', 'exact')} mm on the exact beam, with a final hub error of "
            f"{deg('first_order', 'exact')} deg there; designed on exact, it leaves "
            f"{mm('exact', 'exact')} mm on the exact beam. The last column is the run's "
            "estimated geometric model error (flexctl.sim.validity), the warning that a "
            "small-deflection model is out of range. "
            "Table: [large-deflection.csv](large-deflection.csv).",),
        table=(("design model", "plant", "residual vibration (mm)", "final error (deg)",
                "peak tip (m)", "geometric error of the plant model"), rows),
        files=(csv,))


#: Demo runs besides the built-in scenes: (label, scene, overrides, expected status).
DEMO_COMPARISONS = (
    ("kane-spinup-zero_order", "kane-spinup", {"model.variant": "zero_order"}, "diverged"),
)
DEMO_INTRO = (
    "Every built-in scene run with its default settings, and the Kane spin-up once more with "
    "the zero_order model. zero_order leaves out dynamic stiffening (the centrifugal tension "
    "of the beam), so once the hub rate passes the first clamped frequency of the beam its "
    "stiffness K_ff - Omega^2 M_ff is no longer positive and the deflection grows without "
    "bound: that run is expected to diverge. After the frequency plot: the papers' figures "
    "(paper 001 Figs. 4 and 5, paper 000 Figs. 5 to 8) against their published numbers, and "
    "every controller kind on slew-90.")
#: Processes of the demo's pool (sweeps and controller comparison).
DEMO_WORKERS = 2
DEMO_FREQUENCY_NOTE = (
    "Kane beam, hub clamped at a steady spin rate. first_order and consistent share the beam "
    "stiffness K_ff - Omega^2 (M_ff - K_g), so their curves lie on each other and rise with "
    "the spin (dynamic stiffening); zero_order softens and its first frequency reaches zero "
    "where the spin equals the first clamped frequency. Values below zero are modes without "
    "stiffness, drawn as minus their growth rate (1/s).")


def frequency_plot(out: Path, source: str = "kane-spinup") -> Path:
    """Clamped natural frequencies of a scene's beam against the spin rate, every variant;
    written to ``out / "frequencies-vs-spin.png"``.

    Parameters
    ----------
    out : Path
        Demo directory.
    source : str, optional
        Built-in scene name or TOML file path of the system drawn. Default ``"kane-spinup"``.
    """
    from ..model import VARIANTS
    from .plotting import plot_frequencies_vs_spin

    scene = load_scene(source)
    top = 1.5 * max(abs(getattr(scene.maneuver, "spin_rate", 0.0)), 1.0)
    fig = plot_frequencies_vs_spin(scene.system, np.linspace(0.0, top, 151), variants=VARIANTS,
                                   n_modes=scene.build_model().n_modes, n_frequencies=2)
    fig.axes[0].set_title(f"{source}: clamped natural frequencies against spin rate")
    path = out / "frequencies-vs-spin.png"
    with atomic_file(path) as partial:
        fig.savefig(partial, dpi=100)
    return path


def _two_array_comparison(out: Path, executor=None) -> Section:
    """:func:`slew_comparison` on the free-hub ``two-array-slew``."""
    return slew_comparison(out, executor, kinds=FREE_HUB_KINDS, scene_name="two-array-slew")


def _requirements_slew_90(out: Path, executor=None) -> Section:
    """:func:`~flexctl.app.demo_requirements.requirements_section` on ``slew-90``."""
    return requirements_section(out, executor, scenes=("slew-90",))


def _requirements_two_arrays(out: Path, executor=None) -> Section:
    """:func:`~flexctl.app.demo_requirements.requirements_section` on ``two-array-slew``."""
    return requirements_section(out, executor, scenes=("two-array-slew",))


#: The sections, in the report's order: (label, function ``f(out) -> Section``).
SECTIONS = (("paper 001 Fig. 4", kane_spinup),
            ("paper 001 Fig. 5", spacecraft_torque),
            ("paper 000 Figs. 5-8", hub_beam_mass),
            ("controller comparison", slew_comparison),
            ("structures", structures),
            ("three axes", three_axes),
            ("three-axis control", three_axis_control),
            ("controller comparison, two arrays", _two_array_comparison),
            ("design-model error", model_error),
            ("large deflection", large_deflection),
            ("actuators and sensors", hardware),
            ("requirements, slew-90", _requirements_slew_90),
            ("requirements, two arrays", _requirements_two_arrays))
#: The order in which the sections go to the pool: longest first (CPU seconds of each, measured
#: one after the other in one process on this project's 2-core machine, in the comments), so
#: that the short ones and the scenes fill the processes' ends.
SECTION_ORDER = ("three-axis control",                   # 38 (five loops on the exact rod)
                 "requirements, two arrays",             # 27 (verified, filtered, flown)
                 "three axes",                           # 23 (two spatial runs)
                 "actuators and sensors",                # 18.5
                 "requirements, slew-90",                # 17
                 "controller comparison, two arrays",    # 9.3
                 "controller comparison",                # 9.0
                 "design-model error",                   # 4.5
                 "large deflection",                     # 3.2
                 "paper 000 Figs. 5-8",                  # 2.7
                 "structures",                           # 1.1
                 "paper 001 Fig. 5",                     # 0.8
                 "paper 001 Fig. 4")                     # 0.7


#: The scenes that take longest (a sampled loop with sensors, an optimised slew), sent to the
#: pool before the others.
LONG_SCENES = ("wheel-slew", "flexible-link", "slew-90-model-error", "two-array-slew",
               "bus-slew")


def sections(out: Path, workers: int, surprises: list, progress=print, *,
             executor=None) -> list:
    """Every section of :data:`SECTIONS`, each whole on ``executor`` or else a pool of
    ``workers`` processes, the longest first; a section that fails on bad input or in a sweep
    is listed in ``surprises`` (a genuine bug keeps its traceback).

    Parameters
    ----------
    out : Path
        Demo directory, created if missing.
    workers : int
        Processes of the pool made when no ``executor`` is given, 1 to 1024 (1: every section
        in this process).
    surprises : list of str
        Appended to: one line per section that failed.
    progress : callable, optional
        Called with one line per finished section. Default :func:`print`.
    executor : concurrent.futures.Executor, optional
        Runs each section (its ``submit``) instead of a pool of ``workers``.

    Returns
    -------
    list of Section
        The sections made, in the order of :data:`SECTIONS`.
    """
    Path(out).mkdir(parents=True, exist_ok=True)
    with _pool(workers, executor) as pool:
        pending = _submit_sections(pool, out)
        made = {}
        for label in _finished(pending):
            made.update(_section_outcome(label, pending[label], surprises, progress))
    return [made[label] for label, _ in SECTIONS if label in made]


def _submit_sections(pool, out: Path) -> dict:
    """Every section on ``pool``, longest first (:data:`SECTION_ORDER`): label -> its
    pending result (``_submit``)."""
    return {label: _submit(pool, remembered_section, label, out) for label in SECTION_ORDER}


def remembered_section(label: str, out: Path) -> Section:
    """The section ``label`` of :data:`SECTIONS`, made into ``out`` or replayed from the run
    cache (:func:`~flexctl.app.run_cache.remembered`).

    Parameters
    ----------
    label : str
        A label of :data:`SECTIONS`.
    out : Path
        The demo folder the section writes its figures and data into.
    """
    function = dict(SECTIONS)[label]
    return remembered("section", [label, task_fingerprint(function)], out, function)


def remembered_scene(run_one, source, overrides: dict, out: Path) -> dict:
    """``run_one(source, overrides, out)``'s summary, made or replayed from the run cache
    (:func:`~flexctl.app.run_cache.remembered`; a scene file's bytes are part of the key).

    Parameters
    ----------
    run_one : callable
        ``run_one(source, overrides, out_dir) -> summary`` (:func:`run_demo`'s).
    source : str or Path
        A built-in scene's name or a scene file.
    overrides : dict
        Scene keys set over the file's.
    out : Path
        The scene's folder.
    """
    inputs = [str(source), overrides, task_fingerprint(run_one)]
    path = Path(str(source))
    if path.is_file():
        inputs.append(hashlib.sha256(path.read_bytes()).hexdigest())
    return remembered("scene", inputs, out,
                      lambda folder: run_one(source, overrides, folder), create=False)


def _section_outcome(label: str, pending, surprises: list, progress, start=None) -> dict:
    """``{label: Section}`` of a finished section, or ``{}`` with the failure in
    ``surprises``."""
    from .sweep import SweepError

    try:
        section = pending.result()
    except (SweepError, InputError) as exc:
        surprises.append(f"{label} failed: {exc}")
        return {}
    when = "" if start is None else f" {time.perf_counter() - start:.1f} s after the start"
    progress(f"{label}: done{when}")
    return {label: section}


def _finished(pending: dict):
    """The keys of ``pending`` (results of ``_submit``) as their work finishes."""
    from concurrent.futures import as_completed

    futures = {value: key for key, value in pending.items()
               if not isinstance(value, _Done)}
    yield from (key for key, value in pending.items() if isinstance(value, _Done))
    for future in as_completed(futures):
        yield futures[future]


@contextlib.contextmanager
def _pool(workers: int, executor=None):
    """``executor`` as it is, or a pool of ``workers`` processes for the block (None for
    one worker: everything runs in this process)."""
    if executor is None:
        workers = _checked_workers(workers)
    if executor is not None or workers <= 1:
        yield executor
        return
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=workers) as pool:
        yield pool


def _checked_workers(workers) -> int:
    """``workers`` as a process count from 1 to 1024, or a clear error naming it."""
    from ..model.checks import check_integer

    return check_integer("demo", "workers", workers, minimum=1, maximum=1024)


def _import_before_fork() -> None:
    """Import what every worker needs (the controllers, python-control, matplotlib's Agg
    figures: about a second each) once, here, before the pool's processes start: where they
    are forked (Linux's default), they inherit the modules instead of importing them."""
    import control  # noqa: F401
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401

    import controllers  # noqa: F401


class _Done:
    """A result computed here, with the ``result()`` of a pool's future."""

    def __init__(self, function, *args):
        self._value, self._error = None, None
        try:
            self._value = function(*args)
        except Exception as exc:          # raised where the result is asked for, as a pool's
            self._error = exc

    def result(self):
        if self._error is not None:
            raise self._error
        return self._value


def _submit(pool, function, *args):
    """``function(*args)`` on ``pool`` (a future), or here and now when ``pool`` is None (a
    ``_Done``); either gives its result, or raises its exception, from ``result()``."""
    if pool is None:
        return _Done(function, *args)
    return pool.submit(function, *args)


def run_demo(out: Path, run_one, *, workers: int = DEMO_WORKERS, progress=print) -> tuple:
    """The whole demo: every built-in scene and :data:`DEMO_COMPARISONS`, the frequency plot,
    every section, and ``report.md``.

    Parameters
    ----------
    out : Path
        Output directory; each run writes into ``out / label``.
    run_one : callable
        ``run_one(source, overrides, out_dir) -> summary``: loads, runs and writes one scene
        (the command line's, which holds the run's output and maps its errors). With more
        than one worker the scenes run side by side in the pool's processes, so it must be
        picklable (a module-level function).
    workers : int
        Processes for the sweeps and comparisons.
    progress : callable
        Called with one line per finished run or section.

    Returns
    -------
    report : Path
    surprises : list of str
        Runs that did not end as expected and sections that failed.

    Notes
    -----
    The demo is written whole or not at all: every file goes into a temporary folder beside
    (or inside) ``out`` and is moved into ``out`` once ``report.md`` is written
    (:func:`flexctl.sim.atomic_files.staged_folder`); a demo that fails or is interrupted
    leaves ``out`` as it was. Files of other names in ``out`` are kept.
    """
    workers = _checked_workers(workers)
    with staged_folder(out, names=("report.md",)) as stage:
        surprises = _demo_into(stage, run_one, workers, progress)
    return Path(out) / "report.md", surprises


def _demo_into(out: Path, run_one, workers: int, progress) -> list:
    """:func:`run_demo`'s work, every file written into ``out``; return the surprises."""
    # the spatial scenes run in their section, beside their planar counterparts
    sectioned = (*SPATIAL_SCENES, CONTROL_SCENE)     # their sections run them
    plan = [(name, name, {}, "ok") for name in builtin_scenes() if name not in sectioned]
    for extra in DEMO_COMPARISONS:
        after = next((k for k, p in enumerate(plan) if p[1] == extra[1]), len(plan) - 1)
        plan.insert(after + 1, extra)
    surprises, runs, made = [], {}, {}
    start = time.perf_counter()
    if workers > 1:
        _import_before_fork()
    with _pool(workers) as pool:
        # everything goes to the pool at once, the long sections first and the scenes (each
        # writes its own folder) after them, so that no process waits; each is reported as
        # it finishes, and the report keeps the order of the plan
        pending = {("section", label): call
                   for label, call in _submit_sections(pool, out).items()}
        expected = {}
        for label, source, overrides, status in sorted(
                plan, key=lambda p: p[0] not in LONG_SCENES):
            pending["scene", label] = _submit(pool, remembered_scene, run_one, source,
                                              overrides, out / label)
            expected[label] = status
        for kind, label in _finished(pending):
            if kind == "section":
                made.update(_section_outcome(label, pending[kind, label], surprises, progress,
                                             start))
                continue
            summary = runs[label] = pending[kind, label].result()
            note = "" if summary["status"] == expected[label] else \
                f" (expected {expected[label]})"
            progress(f"{label}: {summary_verdict(summary)}{note}, peak tip deflection "
                     f"{summary['peak_tip_deflection']:.4g} m, t = {summary['t_end']:.4g} s, "
                     f"{summary['wall_time_s']:.2f} s")
            if note:
                surprises.append(f"{label} ended {summary['status']}{note}: "
                                 f"{summary['message']}")
        freq_plot = frequency_plot(out)
    runs = [(label, runs[label]) for label, *_ in plan]
    made = [made[label] for label, _ in SECTIONS if label in made]
    write_demo_report(out, runs, freq_plot, intro=DEMO_INTRO,
                      frequency_note=DEMO_FREQUENCY_NOTE, sections=made)
    return surprises
