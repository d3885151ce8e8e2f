"""Sphinx configuration of the flexctl documentation.

Built offline and strictly: ``python -m sphinx -W --keep-going -b html docs docs/_build/html``.
No extension downloads anything at build time (no intersphinx), MathJax is served from the
site itself (``sphinx-mathjax-offline``), and the example notebooks are rendered, never
executed: the executed copies that ``tests/app/test_examples.py`` writes to ``examples/_executed``
are used when present, the notebooks without outputs otherwise.
"""

import os
import shutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")

import flexctl  # noqa: E402

project = "flexctl"
author = "the flexctl authors"
copyright = "the flexctl authors"
release = version = flexctl.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.doctest",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",
    "numpydoc",
    "myst_nb",
    "cli_help",
    "matplotlib.sphinxext.plot_directive",
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
templates_path = ["_templates"]
exclude_patterns = ["_build", "_templates", "Thumbs.db", ".DS_Store", "**.ipynb_checkpoints"]
root_doc = "index"
nitpicky = False

# -- HTML ---------------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"flexctl {release}"
html_static_path = []

# -- API reference ------------------------------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = True
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks = set()
add_module_names = True

# -- Notebooks and MyST -------------------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
nb_execution_mode = "off"
nb_merge_streams = True

# -- Plots drawn at build time (a few small simulations, seconds) ---------------------------------
plot_include_source = True
plot_html_show_source_link = False
plot_html_show_formats = False
plot_formats = [("png", 100)]

# -- Doctests of the guide pages ----------------------------------------------------------------
# Only the pages' own ``doctest`` blocks: the docstrings' examples need their module's namespace
# and run under pytest's --doctest-modules.
doctest_test_doctest_blocks = ""
doctest_global_setup = "import os\nos.environ.setdefault('MPLBACKEND', 'Agg')"

EXAMPLES = ROOT / "examples"
EXECUTED = EXAMPLES / "_executed"
RENDERED = DOCS / "examples" / "notebooks"


def copy_notebooks():
    """Put each example notebook into the site, its executed copy when there is one."""
    RENDERED.mkdir(parents=True, exist_ok=True)
    for stale in RENDERED.glob("*.ipynb"):
        stale.unlink()
    executed = 0
    for notebook in sorted(EXAMPLES.glob("[0-9][0-9]_*.ipynb")):
        copy = EXECUTED / notebook.name
        if copy.is_file() and copy.stat().st_mtime >= notebook.stat().st_mtime:
            shutil.copyfile(copy, RENDERED / notebook.name)
            executed += 1
        else:
            shutil.copyfile(notebook, RENDERED / notebook.name)
    return executed


EXECUTED_NOTEBOOKS = copy_notebooks()
