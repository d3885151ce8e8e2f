"""The documentation site: built offline and strictly, complete, and rendered as a reader sees it.

One HTML build (``sphinx-build -W --keep-going``: any warning fails it) and one doctest build
of the pages' ``doctest`` blocks, into a temporary folder; then the checks read what was built.
The docstrings' own examples run under pytest's ``--doctest-modules``, not here. The example
notebooks are never executed by the build: it renders the copies that ``test_examples.py``
executed (this file runs after it), or the notebooks without outputs when there are none.
"""

import importlib
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

pytest.importorskip("sphinx")
pytest.importorskip("myst_nb")
pytest.importorskip("numpydoc")
from sphinx.util.inventory import InventoryFile  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
EXAMPLES = ROOT / "examples"
#: Seconds a build may take (about 90 s of processor time for the HTML).
BUILD_TIMEOUT = 600
#: Packages whose every ``__all__`` name the API reference documents under the package's name.
DOCUMENTED_AS_IS = ("flexctl", "controllers", "controllers.codegen")
#: Layers whose names are documented under their own name, or under ``flexctl`` when
#: ``import flexctl`` gives the same object.
LAYERS = ("flexctl.model", "flexctl.sim")

#: After the notebooks, on their worker under pytest-xdist (tests/app/test_examples.py).
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("notebooks")]


def _sphinx(builder, out, doctrees):
    # every 20th page's navigation tree also rendered by Sphinx and compared with the one
    # docs/_ext/nav_cache.py marks on its folder's tree (the build fails where they differ)
    path = [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    env = dict(os.environ, MPLBACKEND="Agg", FLEXCTL_DOCS_NAV_CHECK="20",
               PYTHONPATH=os.pathsep.join(path))
    command = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", builder,
               "-d", str(doctrees), str(DOCS), str(out)]
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=BUILD_TIMEOUT)
    assert done.returncode == 0, (
        f"sphinx-build -b {builder} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    # docutils errors that bypass Sphinx's logging (and so -W) still print 'ERROR/'.
    assert "(ERROR/" not in done.stderr, done.stderr
    return done


@pytest.fixture(scope="session")
def site(tmp_path_factory):
    # built once per test run: session-scoped (the worker that runs the "notebooks" group
    # interleaves this module's tests with the notebooks', and a module-scoped build was made
    # again each time), and shared by pytest-xdist's workers through a lock in the run's
    # common temporary folder (xdist may still hand a test of the group to another worker)
    shared = os.environ.get("PYTEST_XDIST_WORKER") is not None
    root = tmp_path_factory.getbasetemp().parent if shared else tmp_path_factory.getbasetemp()
    base = root / "shared-site"
    with open(root / "shared-site.lock", "w") as lock:
        try:
            import fcntl
            fcntl.flock(lock, fcntl.LOCK_EX)
        except ImportError:             # no fcntl: each worker builds its own
            base = tmp_path_factory.mktemp("site")
        if not (base / "built").exists():
            base.mkdir(exist_ok=True)
            _sphinx("html", base / "html", base / "doctrees")
            (base / "built").write_text("ok\n")
    return base


@pytest.fixture(scope="session")
def html(site):
    return site / "html"


@pytest.fixture(scope="session")
def inventory(html):
    with open(html / "objects.inv", "rb") as stream:
        data = InventoryFile.load(stream, "", lambda base, uri: uri)
    names = set()
    for domain_role, objects in data.items():
        if domain_role.startswith("py:"):
            names.update(objects)
    return names


def test_pages_doctests_pass(site):
    done = _sphinx("doctest", site / "doctest", site / "doctrees")
    report = (site / "doctest" / "output.txt").read_text()
    tests = int(re.search(r"^\s*(\d+) tests", report, re.M).group(1))
    assert tests >= 5, report
    assert re.search(r"^\s*0 failures in tests", report, re.M), report + done.stdout


@pytest.mark.parametrize("package", DOCUMENTED_AS_IS)
def test_every_public_name_is_in_the_api_reference(inventory, package):
    module = importlib.import_module(package)
    missing = [name for name in module.__all__ if f"{package}.{name}" not in inventory]
    assert not missing, f"add to docs/api/*.rst (autosummary) the names of {package}: {missing}"


@pytest.mark.parametrize("package", LAYERS)
def test_every_public_name_of_the_layers_is_in_the_api_reference(inventory, package):
    import flexctl
    module = importlib.import_module(package)
    missing = [name for name in module.__all__
               if f"{package}.{name}" not in inventory
               and not (f"flexctl.{name}" in inventory
                        and getattr(flexctl, name, None) is getattr(module, name))]
    assert not missing, f"add to docs/api/*.rst (autosummary) the names of {package}: {missing}"


class _Page(HTMLParser):
    """The links, images and scripts of one HTML page."""

    def __init__(self):
        super().__init__()
        self.links, self.images, self.scripts = [], [], []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "a" and attrs.get("href"):
            self.links.append(attrs["href"])
        elif tag == "img" and attrs.get("src"):
            self.images.append(attrs["src"])
        elif tag == "script" and attrs.get("src"):
            self.scripts.append(attrs["src"])


def _page(path):
    parser = _Page()
    parser.feed(path.read_text(encoding="utf-8"))
    return parser


def _local(page_path, url):
    parts = urlsplit(url)
    if parts.scheme or parts.netloc or not parts.path:
        return None
    return (page_path.parent / unquote(parts.path)).resolve()


@pytest.fixture(scope="session")
def pages(html):
    """Every page of the site, parsed once: ``{path: _Page}``."""
    return {path: _page(path) for path in sorted(html.rglob("*.html"))}


def test_every_internal_link_image_and_script_resolves(pages, html):
    broken, found = [], {}
    for path, page in pages.items():
        for url in page.links + page.images + page.scripts:
            # the pages of a folder share most links (the navigation tree): each resolved once
            key = (path.parent, url)
            if key not in found:
                target = _local(path, url)
                found[key] = target is None or target.exists()
            if not found[key]:
                broken.append(f"{path.relative_to(html)} -> {url}")
    assert len(pages) > 100 and found
    assert not broken, "\n".join(broken[:20])


def test_math_is_served_by_the_site_itself(html):
    page = _page(html / "theory" / "model.html")
    mathjax = [src for src in page.scripts if "mathjax" in src.lower()]
    assert mathjax and all(_local(html / "theory" / "model.html", s) for s in mathjax), mathjax
    text = (html / "theory" / "model.html").read_text(encoding="utf-8")
    assert text.count('class="math') >= 20
    assert r"\dot\theta^2" in text


def test_guide_and_api_pages_cross_reference_each_other(html):
    start = _page(html / "getting_started.html")
    assert any("api/generated/flexctl.build_model.html" in link for link in start.links)
    assert any("theory/model.html" in link for link in start.links)
    api = (html / "api" / "generated" / "flexctl.Model.html").read_text(encoding="utf-8")
    assert 'id="flexctl.Model.linearize"' in api


def test_guide_draws_its_plot(html):
    page = _page(html / "guide" / "simulate.html")
    assert any(src.endswith(".png") for src in page.images), page.images


def test_cli_reference_has_every_command(html):
    from flexctl.app.cli import _parser
    text = (html / "cli.html").read_text(encoding="utf-8")
    commands = next(a for a in _parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    for name in commands.choices:
        assert f"usage: flexctl {name}" in text, name


def test_notebooks_are_rendered_with_their_outputs(html):
    # the build executes a notebook whose executed copy is missing or stale, so every page
    # shows its figures, whatever ran before the build
    notebooks = sorted(EXAMPLES.glob("[0-9][0-9]_*.ipynb"))
    assert notebooks
    for notebook in notebooks:
        path = html / "examples" / "notebooks" / f"{notebook.stem}.html"
        page = _page(path)
        assert [src for src in page.images if src.endswith(".png")], (
            f"{notebook.stem}: rendered without a figure")
        text = path.read_text(encoding="utf-8")
        # the notebooks' own checks (cells tagged remove-cell) are not shown to readers
        assert not re.search(r"\bassert\b", text), f"{notebook.stem} shows an assert"


def test_warnings_in_the_examples_are_one_clean_line(html):
    pages = list((html / "examples" / "notebooks").glob("*.html"))
    shown = [line for path in pages
             for line in path.read_text(encoding="utf-8").splitlines() if "Warning: " in line]
    assert shown, "no warning is shown: this test checks nothing"
    for line in shown:
        assert ".py:" not in line, line


def test_no_page_shows_a_path_of_the_build_machine(html):
    roots = {str(ROOT), str(Path.home()), "/tmp/", "/work/", "/home/"}
    found = []
    for path in html.rglob("*.html"):
        text = path.read_text(encoding="utf-8")
        found += [f"{path.relative_to(html)}: {root}" for root in roots if root in text]
    assert not found, "\n".join(found[:20])


def test_gallery_shows_a_thumbnail_per_notebook(html):
    page = _page(html / "examples" / "index.html")
    notebooks = sorted(EXAMPLES.glob("[0-9][0-9]_*.ipynb"))
    assert notebooks
    for notebook in notebooks:
        # the notebook's last figure (written by the build from the executed copy)
        assert any(src.endswith(f"/{notebook.stem}.png") for src in page.images), notebook
        assert any(link.endswith(f"notebooks/{notebook.stem}.html") for link in page.links)


def test_references_are_links_to_other_projects(pages):
    # intersphinx from the inventories in docs/inventories: no download at build time
    links = {link for page in pages.values() for link in page.links
             if link.startswith("https://")}
    for site in ("https://docs.python.org/3/", "https://numpy.org/doc/stable/",
                 "https://docs.scipy.org/doc/scipy/", "https://matplotlib.org/stable/",
                 "https://python-control.readthedocs.io/", "https://web.casadi.org/python-api/"):
        assert any(link.startswith(site) for link in links), site


def test_api_pages_link_their_source(html):
    page = _page(html / "api" / "generated" / "flexctl.Model.html")
    source = [link for link in page.links if "_modules/" in link]
    assert source
    assert _local(html / "api" / "generated" / "flexctl.Model.html", source[0]).is_file()


def test_long_names_in_the_sidebar_break_at_dots(html):
    text = (html / "api" / "generated" / "flexctl.Model.html").read_text(encoding="utf-8")
    sidebar = text[text.index('class="sidebar-tree"'):]
    names = re.findall(r'<a class="reference[^"]*"[^>]*>([^<\s]*(?:<wbr>[^<\s]*)+)</a>', sidebar)
    assert names, "no long name of the sidebar has a break"
    whole = re.findall(r'<a class="reference[^"]*"[^>]*>([^<\s]{24,})</a>', sidebar)
    assert not whole, whole[:5]


def test_code_blocks_have_a_copy_button(html):
    page = _page(html / "getting_started.html")
    assert any("clipboard" in src or "copybutton" in src for src in page.scripts), page.scripts


def test_build_is_nitpicky():
    # -W with nitpicky: every cross-reference of the site resolves (an unresolved one is a
    # warning, and the build above fails on any warning)
    conf = (DOCS / "conf.py").read_text()
    assert re.search(r"^nitpicky = True$", conf, re.M)


def test_theory_numbers_its_sections_and_equations(html):
    text = (html / "theory" / "model.html").read_text(encoding="utf-8")
    numbers = re.findall(r'<span class="eqno">\((\d+)\)', text)
    assert len(numbers) >= 15 and numbers == [str(i + 1) for i in range(len(numbers))]
    for section in range(1, 9):
        assert re.search(rf"<h2>{section}\. ", text), section


def test_theory_cites_the_papers(html):
    text = (html / "theory" / "model.html").read_text(encoding="utf-8")
    assert text.count("Journal of Beijing Institute of") >= 2
    for label in ("paper-000", "paper-001"):
        assert f'id="{label}"' in text


def test_pages_render_in_a_headless_browser(html, tmp_path):
    browser = next((shutil.which(name) for name in
                    ("chromium", "chromium-browser", "google-chrome", "chrome")
                    if shutil.which(name)), None)
    if browser is None:
        pytest.skip("no headless browser (chromium) installed: the pages were not rendered")
    pytest.importorskip("PIL")
    from PIL import Image, ImageStat
    for page in ("index.html", "guide/spatial.html", "examples/notebooks/13_three_axes.html"):
        shot = tmp_path / (page.replace("/", "_") + ".png")
        done = subprocess.run(
            [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             "--window-size=1280,1600", f"--screenshot={shot}", (html / page).as_uri()],
            capture_output=True, text=True, timeout=120)
        assert shot.is_file(), done.stderr
        image = Image.open(shot).convert("L")
        spread = ImageStat.Stat(image).stddev[0]
        assert spread > 10, f"{page}: a blank render (grey spread {spread:.1f})"


def test_readme_says_how_to_build_the_site():
    readme = (ROOT / "README.md").read_text()
    assert "sphinx -W" in readme and "docs/_build/html" in readme
    assert 'pip install -e ".[test,docs]"' in readme


def test_readme_example_runs():
    readme = (ROOT / "README.md").read_text()
    code = re.search(r"## Example\n\n```python\n(.*?)```", readme, re.S).group(1)
    assert len(code.strip().splitlines()) <= 10
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=BUILD_TIMEOUT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == "ok 0.42"
    assert done.stdout.splitlines()[1].startswith("ok ")
    assert "Warning" not in done.stderr          # the example runs where its models hold
