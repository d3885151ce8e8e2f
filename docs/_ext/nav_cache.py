"""The site's navigation tree rendered once per folder, not once per page.

Furo draws the whole site's navigation, every branch expanded, in each page's sidebar: Sphinx
resolves and renders the full tree again for each of the site's some 500 pages (the API
reference's generated pages and the highlighted sources included), about half of the HTML
build's time. Within one folder the tree differs from page to page only by the ``current``
marks on the page's own branch. So the tree is rendered once per folder, for a name no page
has (its links are then those of every page of the folder, and no branch is marked), and each
page's branch is marked on that HTML as Sphinx marks it: ``current`` added to the classes of
each enclosing ``li`` and ``ul``, and the page's own link ``class="current reference
internal" href="#"``. Any other call of the ``toctree`` template function goes to Sphinx.

``FLEXCTL_DOCS_NAV_CHECK=N`` renders the tree of every N-th page both ways too and fails the
build where they differ (``tests/app/test_site.py`` builds with N = 20; N = 1 checks every
page).
"""

from __future__ import annotations

import os
import posixpath
import re

#: Furo's call of the ``toctree`` template function: the one this module answers.
FURO_CALL = {"collapse": False, "titles_only": True, "maxdepth": -1, "includehidden": True}
#: A document name no page has: the tree rendered for it marks no branch.
NOBODY = "flexctl-navigation-of-this-folder"
_TAG = re.compile(r"<(/?)(ul|li|a)\b[^>]*>")
_CLASS = re.compile(r'class="([^"]*)"')
#: The rendered tree of each folder, and the pages seen, for the build under way.
_TREES: dict = {}
_SEEN = {"pages": 0}


def setup(app):
    app.connect("builder-inited", _reset)
    # before furo's own handler (priority 500), which calls ``toctree``
    app.connect("html-page-context", _page_context, priority=400)
    return {"parallel_read_safe": True, "parallel_write_safe": True}


def _reset(app):
    _TREES.clear()
    _SEEN["pages"] = 0


def _check_every() -> int:
    value = os.environ.get("FLEXCTL_DOCS_NAV_CHECK", "").strip()
    return int(value) if value.isdigit() and int(value) > 0 else 0


def _page_context(app, pagename, templatename, context, doctree):
    sphinx_tree = context.get("toctree")
    builder = app.builder
    if sphinx_tree is None or not hasattr(builder, "_get_local_toctree"):
        return
    _SEEN["pages"] += 1
    check = _check_every()
    checked = check and _SEEN["pages"] % check == 1 % check

    def toctree(**kwargs):
        if kwargs != FURO_CALL:
            return sphinx_tree(**kwargs)
        folder = posixpath.dirname(pagename)
        nobody = posixpath.join(folder, NOBODY)
        if folder not in _TREES:
            _TREES[folder] = builder._get_local_toctree(nobody, **kwargs)
        marked = mark_branch(_TREES[folder], builder.get_relative_uri(nobody, pagename))
        if checked:
            expected = sphinx_tree(**kwargs)
            if marked != expected:
                raise RuntimeError(f"nav_cache: the navigation tree of {pagename} differs "
                                   f"from Sphinx's:\n{marked}\n--- Sphinx's:\n{expected}")
        return marked

    context["toctree"] = toctree


def _with_current(tag: str) -> str:
    found = _CLASS.search(tag)
    if found is None:
        return f'{tag[:-1]} class="current">'
    classes = found.group(1).split()
    if "current" in classes:
        return tag
    return f'{tag[:found.start()]}class="{" ".join([*classes, "current"])}"{tag[found.end():]}'


def mark_branch(html: str, href: str) -> str:
    """``html``, a rendered toctree, with the branch of the link to ``href`` marked current.

    Parameters
    ----------
    html : str
        The tree as Sphinx renders it for a page of the same folder that is not in it.
    href : str
        The page's link in that tree (relative to the folder, no anchor).

    Returns
    -------
    str
        The tree as Sphinx renders it for the page; ``html`` itself when no link of the tree
        goes to ``href`` (a page outside every toctree).
    """
    link = f'<a class="reference internal" href="{href}">'
    if link not in html:
        return html
    edits, open_tags, ancestors = [], [], set()
    for match in _TAG.finditer(html):
        closing, name = match.group(1), match.group(2)
        if name == "a":
            if match.group(0) == link:
                edits.append((match.start(), match.end(),
                              '<a class="current reference internal" href="#">'))
                ancestors.update(open_tags)
        elif closing:
            open_tags.pop()
        else:
            open_tags.append(match.start())
    for start in ancestors:
        end = html.index(">", start) + 1
        edits.append((start, end, _with_current(html[start:end])))
    pieces, last = [], 0
    for start, end, replacement in sorted(edits):
        pieces += [html[last:start], replacement]
        last = end
    return "".join(pieces + [html[last:]])
