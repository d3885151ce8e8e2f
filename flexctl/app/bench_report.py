"""The bench's files: per scene a CSV, a Markdown page and a plot, and ``report.md``.

Writes what :func:`flexctl.app.bench.bench_scene` measured (a
:class:`flexctl.app.bench.SceneBench`); the Markdown tables go through
:func:`flexctl.app.markdown.markdown_table`. Every file is written whole or not at all
(:mod:`flexctl.sim.atomic_files`): a scene's three files together, ``report.md`` alone.
"""

from __future__ import annotations

import csv
import math
from dataclasses import asdict
from pathlib import Path

from ..sim.atomic_files import staged_folder, write_atomic
from .bench_plot import plot_speed_error
from .markdown import markdown_table

__all__ = ["CSV_COLUMNS", "SUMMARY_LEVELS", "fastest_within", "summary_line", "write_index",
           "write_scene"]

#: Error levels at which the report names the fastest run.
SUMMARY_LEVELS = (1e-2, 1e-4, 1e-6)
CSV_COLUMNS = ("scene", "variant", "n_modes", "method", "method_used", "rtol", "status", "t_end",
               "wall_time_s", "n_evaluations", "error", "truncation_error", "integration_error",
               "note")


def _g(value, digits=2) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) \
        else f"{value:.{digits}g}"


def _table(rows, columns) -> list:
    """Markdown lines of ``rows`` by ``columns``: (heading, cell function, right-aligned)."""
    return markdown_table([c[0] for c in columns], [[c[1](r) for c in columns] for r in rows],
                          right=[c[2] for c in columns])


_RUN_COLUMNS = [  # (heading, cell, right-aligned)
    ("variant", lambda r: r.variant, False), ("modes", lambda r: r.n_modes, True),
    ("method", lambda r: r.method + ("" if r.method == r.method_used else
                                     f" -> {r.method_used}"), False),
    ("rtol", lambda r: _g(r.rtol, 1), True), ("wall time (s)", lambda r: _g(r.wall_time_s, 3),
                                              True),
    ("error", lambda r: _g(r.error), True), ("truncation", lambda r: _g(r.truncation_error),
                                             True),
    ("integration", lambda r: _g(r.integration_error), True),
    ("status", lambda r: r.status, False)]


def fastest_within(bench, level: float, variant: str | None = None):
    """Fastest finished run with ``error <= level`` (of ``variant``, default the scene's).

    Parameters
    ----------
    bench : SceneBench
        What :func:`flexctl.app.bench.bench_scene` measured on one scene.
    level : float
        Largest error allowed, relative tip error (:attr:`BenchRow.error`).
    variant : str, optional
        Model variant of the runs; default the scene's.

    Returns
    -------
    BenchRow or None
        None when no run on the variant's Pareto front is within ``level``.
    """
    variant = variant or bench.scene.variant
    runs = [r for r in bench.front(variant) if r.error <= level]
    return runs[0] if runs else None


def _fastest_text(bench, level) -> str:
    r = fastest_within(bench, level)
    return "" if r is None else f"{r.wall_time_s:.3g} s: N{r.n_modes} {r.method_used} {r.rtol:g}"


def write_scene(bench, out_dir) -> dict:
    """Write ``<scene>.csv``, ``<scene>.md`` and ``<scene>-pareto.png``; return their paths.

    Parameters
    ----------
    bench : SceneBench
        What :func:`flexctl.app.bench.bench_scene` measured on one scene.
    out_dir : str or path-like
        Directory, created if missing; the three files are moved in together once all are
        written (:func:`flexctl.sim.atomic_files.staged_folder`), files of other names kept.
    """
    out = Path(out_dir)
    name = bench.scene.name
    names = {"csv": f"{name}.csv", "markdown": f"{name}.md", "plot": f"{name}-pareto.png"}
    with staged_folder(out, names=tuple(names.values())) as stage:
        with open(stage / names["csv"], "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=CSV_COLUMNS)
            writer.writeheader()
            for r in bench.rows:
                writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v)
                                 for k, v in asdict(r).items()})
        plot_speed_error(bench).savefig(stage / names["plot"], dpi=100)
        (stage / names["markdown"]).write_text(_scene_page(bench, names["plot"]))
    return {k: str(out / v) for k, v in names.items()}


def _scene_page(bench, plot: str) -> str:
    """The Markdown page of a scene's bench; ``plot`` names its speed-against-error plot."""
    name, cfg, choice = bench.scene.name, bench.config, bench.choice
    lines = [f"# Bench: {name}", "", bench.scene.description, "",
             f"Horizon {bench.t_final:g} s. Errors are relative tip errors, max |tip - tip_ref| "
             "/ max |tip_ref|: *truncation* is the N-mode model at the reference tolerance "
             "against the reference, *integration* the run against that same N-mode run, "
             "*error* the run against the reference. Wall time: `flexctl.simulate` end to end, "
             "one run each on a shared machine.", "",
             f"## References: {cfg.reference_modes} modes at rtol {cfg.reference_rtol:g}", ""]
    lines += [f"- {v}: {i['status']} at t = {i['t_end']:.4g} s ({i['wall_time_s']:.3g} s); "
              f"differs from first_order by {_g(i['difference_from_first_order'])}"
              for v, i in bench.references.items()]
    lines += ["", f"## Modes chosen for a tolerance of {cfg.tolerance:g}", "",
              f"`choose_modes` ({choice.variant}): **{choice.n_modes} mode"
              f"{'s' if choice.n_modes > 1 else ''}**, estimated error "
              f"{_g(choice.estimated_error)}, actual {_g(bench.choice_actual_error)}. "
              + choice.explanation, ""]
    lines += _table(sorted(bench.truncation.items()), [
        ("modes", lambda kv: kv[0], True),
        ("estimated error", lambda kv: _g(choice.error_by_modes[kv[0] - 1])
         if kv[0] <= len(choice.error_by_modes) else "-", True),
        ("actual truncation error", lambda kv: _g(kv[1]), True)])
    lines += ["", "## Pareto front", "", f"![speed against error]({plot})", "",
              "Runs that no other run of the variant beats on both wall time and error, "
              "fastest first.", ""]
    for variant in cfg.variants:
        lines += [f"### {variant}", ""]
        front = bench.front(variant)
        lines += _table(front, _RUN_COLUMNS) if front else ["No run of this variant finished."]
        lines.append("")
    stopped = [r for r in bench.rows if r.status != "ok"]
    lines += ["## Runs that did not finish", ""]
    lines += (_table(stopped, _RUN_COLUMNS[:4] + [("status", lambda r: r.status, False),
                                                   ("note", lambda r: r.note[:160], False)])
              if stopped else ["None."])
    lines += ["", f"Every run: [{name}.csv]({name}.csv)", ""]
    return "\n".join(lines)


def write_index(out: Path, benches: list) -> Path:
    """Write ``report.md``: one line per scene bench, linking its page.

    Parameters
    ----------
    out : Path
        Directory of the scene pages (:func:`write_scene`); ``report.md`` is written there.
    benches : list of SceneBench
        One per scene, in the report's order.
    """
    lines = ["# flexctl bench", "", "Modes picked by `flexctl.sim.fidelity.choose_modes` with "
             "the estimated and actual truncation error; the fastest finished run of the "
             "scene's variant within each error level.", ""]
    lines += _table(benches, [
        ("scene", lambda b: f"[{b.scene.name}]({b.scene.name}.md)", False),
        ("chosen modes", lambda b: b.choice.n_modes, True),
        ("estimated", lambda b: _g(b.choice.estimated_error), True),
        ("actual", lambda b: _g(b.choice_actual_error), True),
        ("stiffening", lambda b: "matters" if b.choice.stiffening_matters else "negligible",
         False)] + [(f"fastest within {lv:g}", lambda b, lv=lv: _fastest_text(b, lv) or "-",
                     False) for lv in SUMMARY_LEVELS])
    return write_atomic(Path(out) / "report.md", "\n".join(lines) + "\n")


def summary_line(bench) -> str:
    """One line per scene: the modes chosen, their errors, and the fastest run per level.

    Parameters
    ----------
    bench : SceneBench
        The runs of one scene (:func:`~flexctl.app.bench.bench_scene`); the levels are
        :data:`SUMMARY_LEVELS` of relative tip error.
    """
    text = ", ".join(f"within {lv:g}: {_fastest_text(bench, lv) or 'none'}"
                     for lv in SUMMARY_LEVELS)
    return (f"{bench.scene.name}: {bench.choice.n_modes} modes chosen (estimated error "
            f"{_g(bench.choice.estimated_error)}, actual {_g(bench.choice_actual_error)}); "
            f"fastest {text}")
