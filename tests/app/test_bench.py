"""Speed-against-error bench: files written, errors that fall with modes, stopped runs kept."""

import csv
import math

import numpy as np
import pytest

from flexctl import load_scene
from flexctl.app.bench import (CSV_COLUMNS, BenchConfig, BenchRow, bench_scene, runs_on_front,
                               run_bench)
from flexctl.app.cli import EXIT_BAD_INPUT, EXIT_OK, main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: The Kane spin-up converges with modes: each doubling cuts the truncation error by at least
#: this factor (1 -> 2 -> 4 modes: 7e-3, 4e-3, 2e-4 over 10 s).
CONVERGENCE_FACTOR = 1.5
#: Integration error of a run at rtol 1e-8 against the same model at the reference tolerance.
INTEGRATION_ERROR_BOUND = 1e-5
#: error (run vs reference) <= truncation + integration, up to round-off (triangle inequality).
TRIANGLE_SLACK = 1e-9

SMALL = BenchConfig(scenes=("kane-spinup",), modes=(1, 2, 4), variants=("first_order",),
                    methods=("cvodes",), rtols=(1e-8,), reference_modes=8,
                    reference_rtol=1e-10, t_final=10.0)


@pytest.fixture(scope="module")
def small_bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    return run_bench(SMALL, out, progress=False)[0], out


def test_files_are_written(small_bench):
    bench, out = small_bench
    for name in ("kane-spinup.csv", "kane-spinup.md", "kane-spinup-pareto.png", "report.md"):
        assert (out / name).is_file(), name
    assert (out / "kane-spinup-pareto.png").read_bytes()[:8] == PNG_MAGIC
    with open(out / "kane-spinup.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert len(rows) == len(bench.rows) == 3
    text = (out / "kane-spinup.md").read_text()
    assert "## Pareto front" in text and "| first_order | 4 | cvodes |" in text
    assert "kane-spinup.md" in (out / "report.md").read_text()


def test_actual_errors_fall_with_modes(small_bench):
    bench, _ = small_bench
    truncation = [bench.truncation[n] for n in (1, 2, 4)]
    assert truncation[0] > CONVERGENCE_FACTOR * truncation[1] > 0
    assert truncation[1] > CONVERGENCE_FACTOR * truncation[2] > 0
    for row in bench.rows:
        assert row.status == "ok" and row.method_used == "cvodes"
        assert row.integration_error < INTEGRATION_ERROR_BOUND
        assert row.error <= row.truncation_error + row.integration_error + TRIANGLE_SLACK
        assert row.wall_time_s > 0 and row.n_evaluations > 0


def test_mode_choice_is_reported_against_its_actual_error(small_bench):
    bench, out = small_bench
    choice = bench.choice
    assert choice.t_final == 10.0
    assert math.isfinite(bench.choice_actual_error)
    # the estimate and the nonlinear truncation error agree within a factor of a few
    assert bench.choice_actual_error / 4 < choice.estimated_error < 4 * bench.choice_actual_error
    assert f"**{choice.n_modes} mode" in (out / "kane-spinup.md").read_text()


def test_diverging_variant_and_slow_runs_are_recorded_not_raised():
    config = BenchConfig(scenes=("kane-spinup",), modes=(1, 2), variants=("zero_order",),
                         methods=("cvodes", "DOP853"), rtols=(1e-6,), reference_modes=3,
                         reference_rtol=1e-9, time_limit=1e-6)
    bench = bench_scene(load_scene("kane-spinup"), config, progress=False)
    by_method = {(r.method, r.n_modes): r for r in bench.rows}
    for n in (1, 2):
        stopped = by_method["cvodes", n]
        assert stopped.status == "diverged"
        assert "stiffening" in stopped.note
        assert 0 < stopped.t_end < 30.0 and np.isfinite(stopped.error)
    assert by_method["DOP853", 1].status == "timeout"
    assert by_method["DOP853", 2].status == "skipped"
    assert bench.references["zero_order"]["status"] == "diverged"
    assert runs_on_front(bench.rows) == []


def _row(time_s, error, n=1, status="ok", method="cvodes"):
    return BenchRow("s", "first_order", n, method, method, 1e-6, status, 1.0, time_s, 1,
                    error, error, 0.0)


def test_runs_on_front_keeps_only_undominated_finished_runs():
    rows = [_row(1.0, 1e-2, 1), _row(2.0, 1e-3, 2), _row(3.0, 5e-3, 3),
            _row(0.5, 1e-6, 4, status="diverged"), _row(4.0, 1e-4, 5)]
    front = runs_on_front(rows)
    assert [r.n_modes for r in front] == [1, 2, 5]
    times = [r.wall_time_s for r in front]
    errors = [r.error for r in front]
    assert times == sorted(times) and errors == sorted(errors, reverse=True)


@pytest.mark.parametrize("changes, pattern", [
    ({"modes": (0,)}, "modes"),
    ({"variants": ("second_order",)}, "variants"),
    ({"methods": ("euler",)}, "methods"),
    ({"rtols": (1.5,)}, "rtols"),
    ({"reference_modes": 4, "modes": (1, 8)}, "reference_modes"),
    ({"reference_rtol": 1e-3}, "reference_rtol"),
    ({"time_limit": 0.0}, "time_limit"),
    ({"tolerance": 2.0}, "tolerance"),
], ids=["modes", "variants", "methods", "rtols", "reference_modes", "reference_rtol",
        "time_limit", "tolerance"])
def test_config_rejects_bad_values_by_name(changes, pattern):
    with pytest.raises(ValueError, match=pattern):
        BenchConfig(**changes)


def test_cli_bench_runs_and_rejects_bad_input(tmp_path, capsys):
    out = tmp_path / "bench"
    code = main(["bench", "--quick", "--scene", "kane-spinup", "--modes", "1-2",
                 "--methods", "cvodes", "--rtols", "1e-6", "--reference-modes", "4",
                 "--t-final", "5", "--no-progress", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == EXIT_OK
    assert (out / "kane-spinup.csv").is_file() and "kane-spinup:" in printed
    assert main(["bench", "--modes", "0", "--out", str(out)]) == EXIT_BAD_INPUT
    assert main(["bench", "--scene", "slew-90", "--out", str(out)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.startswith("flexctl: error:") and "slew" in err


def test_exact_variant_is_benched_against_its_own_reference(tmp_path):
    config = BenchConfig(scenes=("kane-spinup",), modes=(1, 2), variants=("first_order", "exact"),
                         methods=("cvodes",), rtols=(1e-8,), reference_modes=4,
                         reference_rtol=1e-10, t_final=10.0)
    bench = run_bench(config, tmp_path, progress=False)[0]
    assert bench.references["exact"]["status"] == "ok"
    exact = sorted((r for r in bench.rows if r.variant == "exact"), key=lambda r: r.n_modes)
    assert [r.status for r in exact] == ["ok", "ok"]
    assert exact[1].error < exact[0].error            # truncation falls with modes
    assert runs_on_front(exact)
    assert (tmp_path / "kane-spinup-pareto.png").read_bytes()[:8] == PNG_MAGIC
