"""A run is not "ok" when the design's own loop check finds its loop unstable on the plant.

slew-90-model-error's NMPC has a terminal LQR whose loop grows on the 6-mode exact plant (a
slow growth of an upper mode: the run reaches its final time); its verdict, in the console
summary and in every report table, says so.
"""

import warnings

import pytest

import flexctl
from controllers import from_spec
from flexctl.app.report import write_demo_report
from flexctl.app.verdict import run_verdict, summary_verdict


@pytest.fixture(scope="module")
def unstable_check():
    scene = flexctl.load_scene("slew-90-model-error", overrides={"controller.kind": "nmpc"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        built = from_spec(scene)
    return built.info["loop_stability"]


def test_an_ok_run_with_an_unstable_loop_is_not_called_ok(unstable_check):
    assert unstable_check["closed_loop_stable"] is False
    assert summary_verdict({"status": "ok", "slew": {"loop_stability": unstable_check}}) \
        == "ok, loop unstable"
    assert run_verdict("diverged", unstable_check) == "diverged"
    assert summary_verdict({"status": "ok", "slew": {"loop_stability": {
        **unstable_check, "closed_loop_stable": True}}}) == "ok"


def test_the_demo_report_lists_the_unstable_loop(tmp_path, unstable_check):
    run = {"scene": "slew-90-model-error", "variant": "exact", "n_modes": 6, "status": "ok",
           "t_end": 7.0, "peak_tip_deflection": 0.1, "wall_time_s": 1.0, "message": "done",
           "files": {"response_plot": str(tmp_path / "a" / "response.png")},
           "slew": {"loop_stability": unstable_check}}
    report = write_demo_report(tmp_path, [("a", run)]).read_text()
    assert "| ok, loop unstable |" in report
    assert unstable_check["message"] in report
