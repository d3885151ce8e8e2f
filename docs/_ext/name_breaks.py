"""Long dotted names in the sidebar break at their dots, never in the middle of a word.

furo lets a sidebar entry break anywhere (``overflow-wrap: anywhere``), so an API name such as
``flexctl.sim.spatial_loop.simulate_spatial_loop`` was cut mid-word. Each entry that is one
long name gets a line-break opportunity (``<wbr>``) after each dot and underscore, and the
site's stylesheet (``_static/flexctl.css``) breaks sidebar entries only there.
"""

import re

#: Entries shorter than this fit the sidebar as they are.
MIN_LENGTH = 24
_LINK_TEXT = re.compile(r'(<a class="reference[^"]*"[^>]*>)([^<\s]{%d,})(</a>)' % MIN_LENGTH)


def with_breaks(tree):
    """``tree`` (the sidebar's HTML) with ``<wbr>`` after the dots and underscores of each
    long one-word entry."""
    return _LINK_TEXT.sub(
        lambda m: m.group(1) + re.sub(r"([._])", r"\1<wbr>", m.group(2)) + m.group(3), tree)


def add_breaks(app, pagename, templatename, context, doctree):
    tree = context.get("furo_navigation_tree")
    if tree:
        context["furo_navigation_tree"] = with_breaks(tree)


def setup(app):
    # after furo's own handler, which computes the tree
    app.connect("html-page-context", add_breaks, priority=900)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
