"""The example notebooks on the site: executed, cleaned, and shown in a gallery.

Each notebook of ``examples/`` is shown with its outputs. Its executed copy is kept in
``examples/_executed`` with the digest of the notebook it was made from; a build uses a copy
whose digest matches (``tests/app/test_examples.py`` writes them as it runs the notebooks),
and executes the notebook itself otherwise, so a site built as the README says shows every
plot. Outputs are cleaned for readers: a warning printed by Python's ``warnings`` module (its
file, line and source line) becomes one line, ``Category: message``, without the machine's
paths. The cells tagged ``remove-cell`` (the notebooks' own checks) are left out of the pages
by myst-nb.

``.. notebook-gallery::`` draws the thumbnails: the last figure of each notebook, linked to its
page.
"""

import base64
import hashlib
import os
import re
import shutil
import sys
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
EXECUTED = EXAMPLES / "_executed"
#: Seconds one cell may run.
CELL_TIMEOUT = 240
#: Where the executed copy records the notebook it was made from.
DIGEST_KEY = "flexctl_source_sha256"
#: A warning as ``warnings.showwarning`` prints it: ``file:line: Category: message`` and,
#: indented, the source line that raised it.
_WARNING = re.compile(r"^[^\n]*?:\d+: (\w+(?:Warning|Error)): ([^\n]*)\n(?:[ \t]+[^\n]*\n)?",
                      re.M)


def notebooks():
    """The example notebooks, sorted: ``examples/NN_name.ipynb``."""
    return sorted(EXAMPLES.glob("[0-9][0-9]_*.ipynb"))


def digest(notebook):
    """SHA-256 of a notebook file's bytes: what its executed copy must have been made from."""
    return hashlib.sha256(Path(notebook).read_bytes()).hexdigest()


def clean_warnings(text):
    """``text`` with each printed warning reduced to one line without paths."""
    return _WARNING.sub(lambda m: f"{m.group(1)}: {m.group(2)}\n", text)


#: The note of a compile into the persistent cache (``flexctl.sim.compile_cache``): about the
#: state of the build machine's cache, not the example.
_COMPILING = re.compile(r"^flexctl: compiling [^\n]*\n?", re.M)


def clean(notebook):
    """Clean the outputs of an executed notebook in place (see :func:`clean_warnings`); the
    notes of compiles into the build machine's cache are left out."""
    for cell in notebook.cells:
        outputs = []
        for output in cell.get("outputs", ()):
            if output.get("output_type") == "stream" and output.get("name") == "stderr":
                output["text"] = clean_warnings(_COMPILING.sub("", output["text"]))
                if not output["text"]:
                    continue
            outputs.append(output)
        if "outputs" in cell:
            cell["outputs"] = outputs
    return notebook


def execute(path, timeout=CELL_TIMEOUT):
    """Run a notebook top to bottom and return it executed and cleaned.

    The kernel runs the package of this checkout, with Jupyter's inline backend (each figure
    stored as it would be in Jupyter) and the notebook's folder as working directory.

    Parameters
    ----------
    path : str or pathlib.Path
        The notebook (``examples/NN_name.ipynb``).
    timeout : float, optional
        Seconds one cell may run. Default :data:`CELL_TIMEOUT`.

    Returns
    -------
    nbformat.NotebookNode
        The notebook with its outputs, its digest recorded in its metadata.

    Raises
    ------
    nbclient.exceptions.CellExecutionError
        A cell failed (an ``assert`` of the notebook included).
    """
    import nbclient

    path = Path(path)
    notebook = nbformat.read(path, as_version=4)
    saved = {key: os.environ.get(key) for key in ("MPLBACKEND", "PYTHONPATH")}
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT)] + [p for p in (saved["PYTHONPATH"] or "").split(os.pathsep) if p])
    try:
        client = nbclient.NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                                         resources={"metadata": {"path": str(path.parent)}})
        client.execute()
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    notebook.metadata[DIGEST_KEY] = digest(path)
    return clean(notebook)


def save_executed(notebook, name):
    """Write an executed notebook to ``examples/_executed/<name>`` whole (never half-written
    for a build that reads it at the same moment); returns its path."""
    EXECUTED.mkdir(exist_ok=True)
    target = EXECUTED / name
    partial = target.with_suffix(f".{os.getpid()}.partial")
    nbformat.write(notebook, partial)
    os.replace(partial, target)
    return target


def executed_copy(path):
    """The executed copy of a notebook, made now if there is none of its current version."""
    path = Path(path)
    copy = EXECUTED / path.name
    if copy.is_file():
        try:
            stored = nbformat.read(copy, as_version=4)
        except Exception:           # noqa: BLE001 - unreadable: made again
            stored = None
        if stored is not None and stored.metadata.get(DIGEST_KEY) == digest(path):
            return copy
    print(f"executing {path.name} for the site (its outputs are kept in "
          f"{EXECUTED.relative_to(ROOT)})", file=sys.stderr)
    return save_executed(execute(path), path.name)


def thumbnail(notebook):
    """The PNG bytes of a notebook's last figure, or None."""
    found = None
    for cell in notebook.cells:
        for output in cell.get("outputs", ()):
            data = output.get("data", {})
            if "image/png" in data:
                found = data["image/png"]
    return base64.b64decode(found) if found else None


def title(notebook):
    """A notebook's first heading, without its number."""
    for cell in notebook.cells:
        if cell.cell_type == "markdown":
            for line in cell.source.splitlines():
                if line.startswith("# "):
                    return re.sub(r"^\d+\.\s*", "", line[2:].strip())
    return ""


def prepare(app):
    """Put each executed notebook and its thumbnail into the site's sources."""
    source = Path(app.srcdir)
    rendered = source / "examples" / "notebooks"
    thumbs = source / "examples" / "thumbnails"
    for folder in (rendered, thumbs):
        folder.mkdir(parents=True, exist_ok=True)
    for notebook in notebooks():
        copy = executed_copy(notebook)
        target = rendered / notebook.name
        if not target.is_file() or target.read_bytes() != copy.read_bytes():
            shutil.copyfile(copy, target)
        picture = thumbnail(nbformat.read(copy, as_version=4))
        if picture is not None:
            png = thumbs / f"{notebook.stem}.png"
            if not png.is_file() or png.read_bytes() != picture:
                png.write_bytes(picture)


def gallery_nodes(docname):
    """The gallery's nodes on page ``docname``: per notebook a card with its linked thumbnail
    and title."""
    from docutils import nodes
    from sphinx.addnodes import pending_xref

    gallery = nodes.container(classes=["notebook-gallery"])
    for notebook in notebooks():
        stem = notebook.stem
        heading = title(nbformat.read(notebook, as_version=4)) or stem
        card = nodes.container(classes=["notebook-card"])
        image = nodes.image(uri=f"/examples/thumbnails/{stem}.png", alt=heading)
        card += nodes.reference("", "", image, refuri=f"notebooks/{stem}.html")
        link = pending_xref("", nodes.inline(heading, heading), refdomain="std",
                            reftype="doc", reftarget=f"notebooks/{stem}", refexplicit=True,
                            refwarn=True, refdoc=docname)
        card += nodes.paragraph("", "", link)
        gallery += card
    return gallery


def setup(app):
    from sphinx.util.docutils import SphinxDirective

    class NotebookGallery(SphinxDirective):
        """``.. notebook-gallery::``: the example notebooks as linked thumbnails."""

        def run(self):
            return [gallery_nodes(self.env.docname)]

    app.add_directive("notebook-gallery", NotebookGallery)
    app.connect("builder-inited", prepare)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
