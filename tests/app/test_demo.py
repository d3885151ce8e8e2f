"""The demo's report sections: the papers' figures and the controller comparison.

Each section is run on a small size (the demo's full run is in ``test_cli.py``) and checked
against the papers' numbers (MODEL.md section 6) and for the files it links.
"""

import csv
import re

import pytest

from flexctl.app import demo
from flexctl.app.report import write_demo_report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: The papers' figures were read off plots: a few percent.
PAPER_TOLERANCE = 0.03


def _cells(section, row):
    return dict(zip(section.table[0], section.table[1][row]))


def _assert_files(section):
    for _, image in section.images:
        assert image.read_bytes()[:8] == PNG_MAGIC
    for path in section.files:
        assert path.read_text().count("\n") >= 2


def test_kane_spinup_section_reproduces_paper_001_fig_4(tmp_path):
    section = demo.kane_spinup(tmp_path)
    _assert_files(section)
    by_rate = {row[0]: dict(zip(section.table[0], row)) for row in section.table[1]}
    assert set(by_rate) == {"0.5", "2", "4"}
    assert float(by_rate["2"]["first_order peak tip (m)"]) == pytest.approx(
        0.28, rel=PAPER_TOLERANCE)
    assert float(by_rate["2"]["zero_order peak tip (m)"]) == pytest.approx(
        0.34, rel=PAPER_TOLERANCE)
    assert by_rate["4"]["first_order status"] == "ok"
    assert by_rate["4"]["zero_order status"].startswith("diverged")


def test_spacecraft_section_reproduces_paper_001_fig_5(tmp_path):
    section = demo.spacecraft_torque(tmp_path)
    _assert_files(section)
    peak = _cells(section, 0)
    assert float(peak["flexctl"]) == pytest.approx(0.42, rel=PAPER_TOLERANCE)
    assert float(_cells(section, 1)["flexctl"]) == pytest.approx(0.07, rel=0.05)


def test_hub_beam_mass_section_reproduces_paper_000(tmp_path):
    section = demo.hub_beam_mass(tmp_path, points=4)
    _assert_files(section)
    for row in range(4):
        cells = _cells(section, row)
        assert float(cells["flexctl"]) == pytest.approx(float(cells["paper 000"]),
                                                        rel=PAPER_TOLERANCE), cells["quantity"]
    fig5 = [_cells(section, row)["flexctl"].split(" / ") for row in (4, 5)]
    assert all(float(near_tip) > float(near_root) for near_root, near_tip in fig5)
    with open(tmp_path / "paper000-fig8.csv") as handle:
        rows = list(csv.DictReader(handle))
    peaks = [float(r["peak_amplitude"]) for r in rows]
    assert len(rows) == 4 and peaks == sorted(peaks)


def test_slew_comparison_section_has_one_row_per_controller(tmp_path):
    section = demo.slew_comparison(tmp_path, kinds=["zvd", "bang_bang"])
    _assert_files(section)
    rows = {row[0]: dict(zip(section.table[0], row)) for row in section.table[1]}
    assert set(rows) == {"zvd", "bang_bang"}
    assert all(r["status"] == "ok" for r in rows.values())
    # each metric shown with its error (or as a bound below it)
    assert all(r["residual vibration"].endswith(" mm") for r in rows.values())
    # Input shaping cancels most of the residual vibration of the rigid bang-bang torque.
    with open(tmp_path / "controller-comparison.csv") as handle:
        residual = {r["controller.kind"]: float(r["residual_vibration"])
                    for r in csv.DictReader(handle)}
    assert residual["zvd"] < 0.1 * residual["bang_bang"]


def test_report_renders_sections_as_markdown(tmp_path):
    image = tmp_path / "figure.png"
    image.write_bytes(PNG_MAGIC)
    section = demo.Section(title="A case", paragraphs=("First.", "Second."),
                           table=(("a", "b"), [("1", "2"), ("3", "4")]),
                           images=(("the figure", image),))
    text = write_demo_report(tmp_path, [], sections=[section]).read_text()
    assert "## A case\n\nFirst.\n\nSecond.\n\n| a | b |\n|---|---|\n| 1 | 2 |\n| 3 | 4 |" in text
    assert re.search(r"!\[the figure\]\(figure\.png\)", text)
    assert text.index("## A case") < text.index("## Responses")


def test_structures_section_shows_what_a_second_array_and_a_free_hub_change(tmp_path):
    from flexctl.app.demo_structures import structures

    section = structures(tmp_path)
    _assert_files(section)
    rows = {cells[0]: dict(zip(section.table[0], cells)) for cells in section.table[1]}
    one, pinned = rows["one beam, pinned hub"], rows["two arrays, pinned hub"]
    free, wing = rows["two arrays, free hub"], rows["single wing, free hub"]
    peak = lambda row: [float(v) for v in row["peak tips (m)"].split(", ")]  # noqa: E731
    # a second array: more inertia to turn, each tip bends less, the two tips alike
    assert float(pinned["rigid inertia (kg m^2)"]) > float(one["rigid inertia (kg m^2)"])
    assert max(peak(pinned)) < 0.6 * peak(one)[0] and len(set(peak(pinned))) == 1
    # identical arrays hide modes from the torque; one beam has none
    assert one["modes the torque cannot move (rad/s)"] == "none"
    assert pinned["modes the torque cannot move (rad/s)"] != "none"
    # a single wing turns a free hub about the centre of mass (less inertia) and drags it
    assert float(wing["rigid inertia (kg m^2)"]) < float(one["rigid inertia (kg m^2)"])
    assert float(wing["hub travel (mm)"]) > 1.0 and float(free["hub travel (mm)"]) < 1e-6



def _fine_section(out):
    return demo.Section(title="fine")


def _refused_section(out):
    from flexctl.model.errors import InputValueError
    raise InputValueError("refused.value must be positive; got -1")


def _broken_section(out):
    raise ZeroDivisionError("a genuine bug")


@pytest.mark.parametrize("workers", [1, 2])
def test_sections_keep_the_report_order_and_list_refusals(tmp_path, monkeypatch, workers):
    # sent longest first, reported as they finish, returned in the report's order; a section
    # refused on bad input becomes a surprise, the others still come
    monkeypatch.setattr(demo, "SECTIONS", (("a", _fine_section), ("b", _refused_section),
                                           ("c", _fine_section)))
    monkeypatch.setattr(demo, "SECTION_ORDER", ("c", "b", "a"))
    surprises, lines = [], []
    made = demo.sections(tmp_path / "new", workers, surprises, lines.append)
    assert [s.title for s in made] == ["fine", "fine"]
    assert surprises == ["b failed: refused.value must be positive; got -1"]
    assert sorted(lines) == ["a: done", "c: done"]
    assert (tmp_path / "new").is_dir()


def test_a_section_with_a_bug_keeps_its_traceback(tmp_path, monkeypatch):
    monkeypatch.setattr(demo, "SECTIONS", (("a", _broken_section),))
    monkeypatch.setattr(demo, "SECTION_ORDER", ("a",))
    with pytest.raises(ZeroDivisionError, match="a genuine bug"):
        demo.sections(tmp_path, 1, [], print)


def test_every_section_and_long_scene_is_scheduled_once():
    from flexctl.app.scenes import builtin_scenes

    assert sorted(demo.SECTION_ORDER) == sorted(label for label, _ in demo.SECTIONS)
    assert set(demo.LONG_SCENES) <= set(builtin_scenes())


@pytest.mark.parametrize("workers", [0, -1, 1.5, "2", float("nan"), 10 ** 9, True])
def test_demo_refuses_a_worker_count_by_name(tmp_path, workers):
    from flexctl.model.errors import InputError

    with pytest.raises(InputError, match="demo.workers must be an integer in"):
        demo.sections(tmp_path, workers, [], print)
    with pytest.raises(InputError, match="demo.workers must be an integer in"):
        demo.run_demo(tmp_path, print, workers=workers)
