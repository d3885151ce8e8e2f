"""The example notebooks: in sync with their scripts, listed on the site, and executed.

Each notebook in ``examples/`` has a percent-format script twin (the source of truth, edited
by hand; the paired ``.ipynb`` is updated with ``jupytext --sync``). The notebooks assert their
key numbers (the papers' amplitudes and trends) in their own cells, so executing them here is
what keeps the examples correct.
"""

import os
import re
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")
nbformat = pytest.importorskip("nbformat")

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
SCRIPTS = sorted(EXAMPLES.glob("[0-9][0-9]_*.py"))
#: Where each executed notebook is saved with its outputs (git-ignored): the documentation site
#: renders these copies, so it shows the plots without executing anything itself.
EXECUTED = EXAMPLES / "_executed"
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
def test_notebook_executes(script, monkeypatch):
    # The kernel inherits this environment: no display (Jupyter's inline backend, so that
    # plt.show() stores each figure in the executed copy as it would in Jupyter), and the
    # package from this checkout.
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    notebook = jupytext.read(script.with_suffix(".ipynb"))
    client = nbclient.NotebookClient(notebook, timeout=CELL_TIMEOUT, kernel_name="python3",
                                     resources={"metadata": {"path": str(EXAMPLES)}})
    client.execute()       # raises CellExecutionError, with the cell, on a failed assert
    errors = [out for cell in notebook.cells if cell.cell_type == "code"
              for out in cell.get("outputs", []) if out.get("output_type") == "error"]
    assert not errors
    EXECUTED.mkdir(exist_ok=True)
    # written whole, then moved into place: the site's build may read it at any moment
    target = EXECUTED / script.with_suffix(".ipynb").name
    partial = target.with_suffix(f".{os.getpid()}.partial")
    nbformat.write(notebook, partial)
    os.replace(partial, target)
