"""``.. cli-help:: module:function``: the help of an argparse parser and its subcommands.

Renders ``format_help()`` of the parser the function returns and of each subcommand, one
section per command, as the terminal shows it: the page cannot drift from the parser, and the
help text is never parsed as reStructuredText (its tables and indented epilogs are not).
"""

import argparse
import importlib
import os

from docutils import nodes
from sphinx.util.docutils import SphinxDirective

#: Width the help is wrapped to, as in an 80-column terminal.
COLUMNS = "88"


def _subcommands(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices.items())
    return []


class CliHelp(SphinxDirective):
    required_arguments = 1

    def run(self):
        module_name, _, function_name = self.arguments[0].partition(":")
        previous = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = COLUMNS
        try:
            parser = getattr(importlib.import_module(module_name), function_name)()
            sections = [(parser.prog, parser.format_help())]
            sections += [(sub.prog, sub.format_help()) for _, sub in _subcommands(parser)]
        finally:
            if previous is None:
                os.environ.pop("COLUMNS", None)
            else:
                os.environ["COLUMNS"] = previous
        out = []
        for prog, text in sections:
            section = nodes.section(ids=[nodes.make_id(prog)], names=[nodes.fully_normalize_name(prog)])
            section += nodes.title(text=prog)
            section += nodes.literal_block(text, text, language="text")
            self.state.document.note_implicit_target(section, section)
            out.append(section)
        return out


def setup(app):
    app.add_directive("cli-help", CliHelp)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
