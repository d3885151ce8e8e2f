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
# Object descriptions add no entries to the tables of contents: each API object has its
# own page already, and with them every page's navigation tree carried every method of
# every class (a third of the build's time: 73 s instead of 110-120 s).
toc_object_entries = False
autosummary_imported_members = True
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
add_module_names = True

# -- Docstring validation -----------------------------------------------------------------------
# numpydoc checks the Parameters section of every docstring the API pages render and logs a
# warning for each finding, which ``sphinx-build -W`` turns into a failed build:
# PR01 a parameter not documented, PR02 a documented name that is no parameter, PR03 the
# parameters out of the signature's order, PR04 no type, PR05 a type ending in a period, PR06
# ``integer``/``boolean``/``string`` for ``int``/``bool``/``str``, PR07 no description, PR08
# a description not starting with a capital letter, PR09 one not ending with a period, PR10
# no space before the colon. tests/test_docstrings.py checks the same (PR01 to PR04, PR07,
# PR10) in every public module from the source, rendered or not.
numpydoc_validation_checks = {"PR01", "PR02", "PR03", "PR04", "PR05", "PR06", "PR07", "PR08",
                              "PR09", "PR10"}
numpydoc_validation_exclude = {
    # The class docstrings (not their methods) of the typing.Protocol and Enum classes: the
    # signature numpydoc reads from them is typing's placeholder ``(*args, **kwargs)`` of a
    # class that cannot be instantiated, or EnumType's functional API ``(value, names, module,
    # qualname, type, start, boundary)``, not parameters of flexctl's API.
    r"^flexctl(\.sim)?\.(Controller|ControllerSession|SampledController|StopReason)$",
}
numpydoc_validation_overrides = {
    # A record class (dataclass, named tuple) that documents its fields, its constructor's
    # parameters, under Attributes and has no Parameters section: numpydoc counts only
    # Parameters; tests/test_docstrings.py checks that every field is listed under Attributes.
    "PR01": [r"(?ms)\A(?!.*^Parameters\n-{3,}$).*^Attributes\n-{3,}$"],
}

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
