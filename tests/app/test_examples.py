"""The example notebooks: in sync with their scripts, listed on the site, and executed.

Each notebook in ``examples/`` has a percent-format script twin (the source of truth, edited
by hand; the paired ``.ipynb`` is updated with ``jupytext --sync``). The notebooks assert their
key numbers (the papers' amplitudes and trends) in their own cells, so executing them here is
what keeps the examples correct.
"""

import re
import sys
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")
nbformat = pytest.importorskip("nbformat")

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))
import notebook_pages  # noqa: E402

EXAMPLES = ROOT / "examples"
SCRIPTS = sorted(EXAMPLES.glob("[0-9][0-9]_*.py"))
#: With pytest-xdist, the notebooks run on one worker, before the site that renders them
#: (``--dist loadgroup``; tests/app/test_site.py is in the same group).
pytestmark = pytest.mark.xdist_group("notebooks")
#: Seconds a notebook may run (they take 3 to 20 s alone on 2 cores).
CELL_TIMEOUT = 240
#: Notebooks that take more than about 10 s (marked slow; CI still runs them).
SLOW = {"06_slew_controllers", "07_speed_vs_error", "08_large_deflection", "12_c_export",
        "13_three_axes", "14_three_axis_control", "15_loop_requirements",
        "16_three_axis_planning"}


def _cells(notebook):
    return [(cell.cell_type, cell.source.strip()) for cell in notebook.cells]


def _param(script):
    marks = [pytest.mark.slow] if script.stem in SLOW else []
    return pytest.param(script, id=script.stem, marks=marks)


def test_there_are_examples():
    assert len(SCRIPTS) >= 7


def test_every_notebook_has_a_script_and_every_script_a_notebook():
    notebooks = {p.stem for p in EXAMPLES.glob("*.ipynb")}
    assert notebooks == {p.stem for p in SCRIPTS}


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_notebook_is_in_sync_with_its_script(script):
    from_script = jupytext.read(script)
    from_notebook = jupytext.read(script.with_suffix(".ipynb"))
    assert _cells(from_notebook) == _cells(from_script), (
        f"{script.name} and its notebook differ: update the notebook with "
        f"jupytext --sync examples/{script.name}")
    assert from_notebook.metadata["kernelspec"]["name"] == "python3"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_notebook_asserts_its_numbers_and_has_no_stored_outputs(script):
    notebook = jupytext.read(script.with_suffix(".ipynb"))
    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert any(re.search(r"^\s*assert ", cell.source, re.M) for cell in code)
    assert all(not cell.get("outputs") for cell in code)


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_notebook_checks_are_hidden_from_readers(script):
    # the site leaves out the cells tagged remove-cell: the notebook's own checks, which
    # show nothing a reader needs (no plot, no print)
    notebook = jupytext.read(script.with_suffix(".ipynb"))
    for cell in notebook.cells:
        if cell.cell_type != "code":
            continue
        hidden = "remove-cell" in cell.metadata.get("tags", ())
        if re.search(r"^\s*assert ", cell.source, re.M):
            assert hidden, f"{script.name}: a cell with an assert is not tagged remove-cell"
        if hidden:
            assert not re.search(r"\b(plt|print|display|fig|ax)\b\s*[.(]", cell.source), (
                f"{script.name}: a hidden cell shows something:\n{cell.source}")


def test_site_lists_every_notebook():
    listing = (ROOT / "docs" / "examples" / "index.md").read_text()
    for script in SCRIPTS:
        assert f"{{doc}}`notebooks/{script.stem}`" in listing, script.stem


@pytest.mark.parametrize("script", [_param(s) for s in SCRIPTS])
def test_notebook_executes(script):
    # executed as the site's build executes it (docs/_ext/notebook_pages.py): the package
    # of this checkout, Jupyter's inline backend, warnings printed as one line
    notebook = notebook_pages.execute(script.with_suffix(".ipynb"), timeout=CELL_TIMEOUT)
    errors = [out for cell in notebook.cells if cell.cell_type == "code"
              for out in cell.get("outputs", []) if out.get("output_type") == "error"]
    assert not errors
    figures = [out for cell in notebook.cells for out in cell.get("outputs", [])
               if "image/png" in out.get("data", {})]
    assert figures, f"{script.name} draws no figure for its page"
    # the site renders this copy (its digest names the notebook it was made from)
    notebook_pages.save_executed(notebook, script.with_suffix(".ipynb").name)
