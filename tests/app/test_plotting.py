"""Plot helpers for sweeps, Pareto fronts, tip deflections and controller comparisons.

The plots compute nothing physical, so the tests check that what is drawn is the data given:
line coordinates against the table columns, bar lengths against the metrics, the front against
:func:`flexctl.app.sweep.pareto_front`, and that stopped runs are marked as such.
"""

import io

import numpy as np
import pytest

import flexctl
from flexctl.app import plotting, plotting_sweeps
from flexctl.sim.metrics import slew_metrics
from flexctl.app.plotting import (plot_controller_comparison, plot_pareto, plot_sweep,
                              plot_tip_deflections)
from flexctl.app.sweep import SweepResult, pareto_front

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _png(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=40)
    return buffer.getvalue()


@pytest.fixture(scope="module")
def table():
    rows = tuple({"ratio": r, "variant": v, "peak": (1.0 + r) * k, "residual": r * k}
                 for v, k in (("a", 1.0), ("b", 2.0)) for r in (0.5, 0.0, 1.0))
    return SweepResult(rows=rows, parameters=("ratio", "variant"),
                       outputs=("peak", "residual"))


@pytest.fixture(scope="module")
def runs(hub_beam_mass_system, kane_system):
    """Two finished runs and one that diverges (zero_order spin-up above omega_1)."""
    model = flexctl.build_model(hub_beam_mass_system, n_modes=2)
    push = flexctl.SineTorque(peak_torque=2.0, duration=2.0)
    gentle = flexctl.SineTorque(peak_torque=1.0, duration=2.0)
    zero = flexctl.build_model(kane_system, n_modes=2, variant="zero_order")
    first = flexctl.build_model(kane_system, n_modes=2)
    spin = flexctl.SpinUp(spin_rate=4.0, ramp_time=15.0)
    return {"push": flexctl.simulate(model, 4.0, torque=push),
            "gentle": flexctl.simulate(model, 4.0, torque=gentle),
            "kane first_order": flexctl.simulate(first, 20.0, hub_motion=spin),
            "kane zero_order": flexctl.simulate(zero, 20.0, hub_motion=spin)}


def test_sweep_plots_are_reexported_from_plotting():
    assert plotting.plot_sweep is plotting_sweeps.plot_sweep
    assert plotting.plot_pareto is plotting_sweeps.plot_pareto
    assert {"plot_sweep", "plot_pareto", "plot_tip_deflections",
            "plot_controller_comparison"} <= set(plotting.__all__)


# ---------------------------------------------------------------------------- sweep curves
def test_sweep_curves_are_the_columns_sorted_by_x(table):
    fig = plot_sweep(table.where(variant="a"), "ratio", ["peak", "residual"])
    ax = fig.axes[0]
    lines = ax.get_lines()
    assert [line.get_label() for line in lines] == ["peak", "residual"]
    assert lines[0].get_xdata().tolist() == [0.0, 0.5, 1.0]
    assert lines[0].get_ydata().tolist() == [1.0, 1.5, 2.0]
    assert lines[1].get_ydata().tolist() == [0.0, 0.5, 1.0]
    assert ax.get_xlabel() == "ratio"
    assert _png(fig)[:8] == PNG_MAGIC


def test_sweep_by_column_and_reference_points(table):
    fig = plot_sweep(table, "ratio", "peak", by="variant",
                     reference={"paper": [(0.9, 0.263), (0.9, 0.141)], "one": (0.5, 1.0)})
    lines = fig.axes[0].get_lines()
    labels = [line.get_label() for line in lines]
    assert labels == ["variant = a", "variant = b", "paper", "one"]
    assert lines[1].get_ydata().tolist() == [2.0, 3.0, 4.0]
    assert lines[2].get_ydata().tolist() == [0.263, 0.141]
    assert fig.axes[0].get_ylabel() == "peak"


@pytest.mark.parametrize("source", ["rows", "columns"])
def test_sweep_accepts_plain_tables(source):
    rows = [{"x": 2.0, "y": 4.0}, {"x": 1.0, "y": 1.0}]
    data = rows if source == "rows" else {"x": [2.0, 1.0], "y": [4.0, 1.0]}
    fig = plot_sweep(data, "x", "y", logx=True, logy=True)
    (line,) = fig.axes[0].get_lines()
    assert line.get_xdata().tolist() == [1.0, 2.0] and line.get_ydata().tolist() == [1.0, 4.0]
    assert fig.axes[0].get_xscale() == fig.axes[0].get_yscale() == "log"


@pytest.mark.parametrize("call, error, match", [
    pytest.param(lambda t: plot_sweep(t, "ratio", "nope"), KeyError, "column must be one of",
                 id="unknown-column"),
    pytest.param(lambda t: plot_sweep(t, "ratio", "variant"), TypeError, "must hold numbers",
                 id="text-y"),
    pytest.param(lambda t: plot_sweep(t, "ratio", []), TypeError, "y must be", id="no-y"),
    pytest.param(lambda t: plot_sweep(t, "ratio", "peak", reference={"p": (1, 2, 3)}),
                 ValueError, r"reference\['p'\]", id="bad-reference"),
    pytest.param(lambda t: plot_sweep(42, "ratio", "peak"), TypeError, "table must be",
                 id="not-a-table"),
    pytest.param(lambda t: plot_pareto(t.where(ratio=0.0), "ratio", "residual"), ValueError,
                 "at least one point", id="pareto-no-positive-points"),
    pytest.param(lambda t: plot_pareto(t, "ratio", "variant"), TypeError,
                 "must hold numbers", id="pareto-text-column"),
])
def test_sweep_plots_reject_bad_arguments(table, call, error, match):
    with pytest.raises(error, match=match):
        call(table)


# ---------------------------------------------------------------------------- Pareto
def test_sweep_with_several_outputs_and_groups_names_both(table):
    fig = plot_sweep(table, "ratio", ["peak", "residual"], by="variant",
                     labels={"peak": "peak amplitude"})
    labels = [line.get_label() for line in fig.axes[0].get_lines()]
    assert labels == ["peak amplitude, variant = a", "peak amplitude, variant = b",
                      "residual, variant = a", "residual, variant = b"]


def test_pareto_labels_numbers_compactly():
    fig = plot_pareto({"t": [1.0, 2.0], "e": [2.0, 1.0], "n": [4, 8]}, "t", "e", label="n")
    assert [t.get_text() for t in fig.axes[0].texts] == ["4", "8"]


def test_pareto_front_line_goes_through_the_non_dominated_points():
    data = {"time": [1.0, 2.0, 3.0, 2.5, 0.5, 4.0],
            "error": [3.0, 1.0, 0.5, 2.0, 10.0, 0.5],
            "method": ["a", "b", "c", "d", "e", "f"]}
    fig = plot_pareto(data, "time", "error", label="method")
    ax = fig.axes[0]
    (front_line,) = [line for line in ax.get_lines() if line.get_label() == "Pareto front"]
    on_front = pareto_front(data["time"], data["error"])
    assert sorted(front_line.get_xdata().tolist()) == sorted(np.array(data["time"])[on_front])
    assert [t.get_text() for t in ax.texts] == ["e", "a", "b", "c"]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"


def test_pareto_groups_by_column_and_skips_nonpositive_on_log_axes():
    rows = [{"t": 1.0, "e": 1.0, "m": "x"}, {"t": 2.0, "e": 0.5, "m": "y"},
            {"t": 3.0, "e": 0.0, "m": "y"}]
    fig = plot_pareto(rows, "t", "e", by="m")
    ax = fig.axes[0]
    sizes = [len(c.get_offsets()) for c in ax.collections]
    assert sizes[:2] == [1, 1]                      # the point with e = 0 is left out
    assert {t.get_text() for t in ax.get_legend().get_texts()} >= {"m = x", "m = y"}


# ---------------------------------------------------------------------------- tip deflection
def test_tip_deflections_mark_the_stopped_run_and_keep_the_finished_ones_in_view(runs):
    kane = {k: runs[k] for k in ("kane first_order", "kane zero_order")}
    assert kane["kane zero_order"].status == "diverged"
    fig = plot_tip_deflections(kane)
    ax = fig.axes[0]
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels[0] == "kane first_order"
    assert labels[1].startswith("kane zero_order: diverged at t = ")
    peak = kane["kane first_order"].peak_tip_deflection
    assert ax.get_ylim()[1] == pytest.approx(1.3 * peak)
    unclipped = plot_tip_deflections(kane, clip_stopped=False).axes[0]
    assert max(np.abs(unclipped.get_ylim())) > 1.0     # the 8 m of the diverged run


def test_tip_deflections_draw_each_run(runs):
    fig = plot_tip_deflections([runs["push"], runs["gentle"]], title="two")
    lines = fig.axes[0].get_lines()
    assert [line.get_label() for line in lines[:2]] == ["run 0", "run 1"]
    np.testing.assert_array_equal(lines[0].get_ydata(), runs["push"].tip_deflection)
    assert fig.axes[0].get_title() == "two"


# ---------------------------------------------------------------------------- controllers
def test_controller_comparison_draws_histories_and_metric_bars(runs):
    results = {"push": runs["push"], "gentle": runs["gentle"]}
    metrics = {k: slew_metrics(r, angle=r.theta[-1], duration=2.0) for k, r in results.items()}
    metrics["gentle"] = {**metrics["gentle"].as_dict(), "settling_time": None}
    fig = plot_controller_comparison(results, metrics, target_angle=0.5, maneuver_end=2.0,
                                     torque_bound=2.0, title="compare")
    angle, torque, tip, residual, settling, peak_torque = fig.axes
    assert [ax.get_ylabel() for ax in (angle, torque, tip)] == \
        ["hub angle (rad)", "torque (N m)", "tip deflection (m)"]
    np.testing.assert_array_equal(torque.get_lines()[0].get_ydata(), runs["push"].torque)
    np.testing.assert_array_equal(tip.get_lines()[1].get_ydata(), runs["gentle"].tip_deflection)
    widths = [bar.get_width() for bar in residual.patches]
    assert widths == pytest.approx([metrics["push"].residual_vibration,
                                    metrics["gentle"]["residual_vibration"]])
    # A log axis only when the residuals span a decade (see the test below).
    assert residual.get_xscale() == ("log" if max(widths) / min(widths) >= 10 else "linear")
    # Not settled: a hatched bar to the end of the run.
    unsettled = settling.patches[1]
    assert unsettled.get_hatch() == "//" and unsettled.get_width() == runs["gentle"].t[-1]
    assert [bar.get_width() for bar in peak_torque.patches] == pytest.approx(
        [np.max(np.abs(runs["push"].torque)), np.max(np.abs(runs["gentle"].torque))])
    assert _png(fig)[:8] == PNG_MAGIC


def test_controller_comparison_without_metrics_has_three_axes(runs):
    fig = plot_controller_comparison({"push": runs["push"]})
    assert len(fig.axes) == 3


@pytest.mark.parametrize("call, error, match", [
    pytest.param(lambda r: plot_controller_comparison({"push": r}, {"other": {}}), ValueError,
                 "missing", id="metrics-missing-label"),
    pytest.param(lambda r: plot_controller_comparison({"push": r}, [1]), TypeError,
                 "metrics must be", id="metrics-not-dict"),
    pytest.param(lambda r: plot_controller_comparison({"push": 3}), TypeError,
                 "SimulationResult", id="not-a-result"),
    pytest.param(lambda r: plot_controller_comparison({}), ValueError, "at least one",
                 id="empty"),
    pytest.param(lambda r: plot_tip_deflections(r), TypeError, "results must be",
                 id="single-result"),
])
def test_comparison_plots_reject_bad_arguments(runs, call, error, match):
    with pytest.raises(error, match=match):
        call(runs["push"])


def _tick_labels_overlap(fig, ax) -> bool:
    """Whether any two visible, non-empty x tick labels of ``ax`` overlap once drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    boxes = [label.get_window_extent(renderer)
             for label in ax.get_xticklabels(which="both")
             if label.get_visible() and label.get_text()]
    return any(a.overlaps(b) for k, a in enumerate(boxes) for b in boxes[k + 1:])


@pytest.mark.parametrize("residuals, scale", [
    pytest.param((7.7e-4, 8.4e-4), "linear", id="close-values-linear"),
    pytest.param((2.0e-5, 1.9e-4), "linear", id="just-under-a-decade-linear"),
    pytest.param((3.0e-6, 8.4e-4), "log", id="decades-apart-log"),
])
def test_controller_comparison_residual_axis_is_log_only_across_a_decade(runs, residuals,
                                                                          scale):
    results = {"push": runs["push"], "gentle": runs["gentle"]}
    metrics = {label: {"residual_vibration": value, "settling_time": 1.0, "peak_torque": 2.0}
               for label, value in zip(results, residuals)}
    fig = plot_controller_comparison(results, metrics)
    residual = fig.axes[3]
    assert residual.get_xlabel() == "residual tip vibration (m)"
    assert residual.get_xscale() == scale
    if scale == "linear":
        assert residual.get_xlim()[0] == 0.0
    assert not _tick_labels_overlap(fig, residual)


def test_a_response_draws_every_appendage_and_no_rounding_as_hub_travel():
    """Twin arrays under a hub torque deflect alike and leave a free hub where it was (its
    travel is rounding, ~1e-16 m): both traces stay visible, the travel is drawn as none.
    Turned a quarter turn apart, the arrays push the hub about: its travel is drawn."""
    import dataclasses

    from flexctl.sim.maneuvers import SineTorque

    system = flexctl.load_scene("two-array-free").system
    torque = SineTorque(peak_torque=1.0, duration=2.0)
    twin = dataclasses.replace(system.appendages[1], angle=0.5 * np.pi)
    skew = dataclasses.replace(system, appendages=(system.appendages[0], twin))
    figures = {}
    for name, structure in (("twins", system), ("skew", skew)):
        result = flexctl.simulate(flexctl.build_model(structure, 1), 2.0, torque=torque,
                                  check_accuracy=False, check_validity=False)
        figures[name] = {ax.get_ylabel(): ax for ax in plotting.plot_response(result).axes}
    tips = [line for line in figures["twins"]["tip deflection (m)"].get_lines()
            if not line.get_label().startswith("_")]
    assert len({line.get_linestyle() for line in tips}) == len(tips) == 2
    flat = figures["twins"]["hub centre travel (mm): none"].get_lines()[0].get_ydata()
    assert np.all(flat == 0.0)
    moved = figures["skew"]["hub centre travel (mm)"].get_lines()[0].get_ydata()
    assert np.max(moved) > 0.0
