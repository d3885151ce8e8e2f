"""``.. cli-help:: module:function``: the help of an argparse parser and its subcommands.

Renders ``format_help()`` of the parser the function returns and of each subcommand, one
section per command, as the terminal shows it: the page cannot drift from the parser, and the
help text is never parsed as reStructuredText (its tables and indented epilogs are not).

The directive's content holds one ``.. cli-example:: COMMAND`` per subcommand (reStructuredText,
typically a console block and a sentence on what it writes); each is placed under an "Example"
heading after its command's help. A subcommand without an example, or an example naming no
subcommand, is a warning (an error under ``sphinx-build -W``): a new command cannot reach the
page without one.
"""

import argparse
import importlib
import os

from docutils import nodes
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)

#: Width the help is wrapped to, as in an 80-column terminal.
COLUMNS = "88"


def _subcommands(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices.items())
    return []


class CliExample(SphinxDirective):
    """``.. cli-example:: COMMAND``: the example of one subcommand, inside ``cli-help`` only."""

    required_arguments = 1
    has_content = True

    def run(self):
        box = nodes.container(classes=["cli-example"])
        box["cli_command"] = self.arguments[0]
        self.state.nested_parse(self.content, self.content_offset, box)
        return [box]


class CliHelp(SphinxDirective):
    required_arguments = 1
    has_content = True

    def _examples(self):
        """``{command: [nodes]}`` from the ``cli-example`` blocks of the content."""
        holder = nodes.container()
        if self.content:
            self.state.nested_parse(self.content, self.content_offset, holder)
        examples = {}
        for child in holder.children:
            command = child.get("cli_command") if isinstance(child, nodes.container) else None
            if command is None:
                logger.warning("cli-help: only cli-example blocks belong in its content",
                               location=child)
                continue
            if command in examples:
                logger.warning(f"cli-help: a second example of {command!r}", location=child)
            examples[command] = child.children
        return examples

    def run(self):
        module_name, _, function_name = self.arguments[0].partition(":")
        previous = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = COLUMNS
        try:
            parser = getattr(importlib.import_module(module_name), function_name)()
            sections = [(None, parser.prog, parser.format_help())]
            sections += [(name, sub.prog, sub.format_help())
                         for name, sub in _subcommands(parser)]
        finally:
            if previous is None:
                os.environ.pop("COLUMNS", None)
            else:
                os.environ["COLUMNS"] = previous
        examples = self._examples()
        location = self.get_location()
        for name in sorted(set(examples) - {n for n, _, _ in sections if n}):
            logger.warning(f"cli-help: an example of {name!r}, which is no command of "
                           f"{parser.prog}", location=location)
        out = []
        for name, prog, text in sections:
            section = nodes.section(ids=[nodes.make_id(prog)], names=[nodes.fully_normalize_name(prog)])
            section += nodes.title(text=prog)
            section += nodes.literal_block(text, text, language="text")
            if name is not None:
                if name in examples:
                    section += nodes.rubric(text="Example")
                    section.extend(examples[name])
                else:
                    logger.warning(f"cli-help: {prog!r} has no example (add a "
                                   f"'.. cli-example:: {name}' block)", location=location)
            self.state.document.note_implicit_target(section, section)
            out.append(section)
        return out


def setup(app):
    app.add_directive("cli-help", CliHelp)
    app.add_directive("cli-example", CliExample)
    return {"version": "2", "parallel_read_safe": True, "parallel_write_safe": True}
