"""Every public function and method with two or more parameters documents each of them in a
numpydoc ``Parameters`` section (name, type, and the unit and shape where they apply).

Read from the source with :mod:`ast`, so it covers what the API pages of the documentation do
not show too; the documentation build validates the rendered ones with numpydoc
(``numpydoc_validation_checks`` in ``docs/conf.py``).
"""

import ast
import re

import pytest

from tests.test_architecture import module_files

#: A numpydoc section heading and its underline.
_SECTION = re.compile(r"^\s*([A-Z][A-Za-z ]+)\n\s*-{3,}\s*$", re.M)


def documented_parameters(doc: str) -> set | None:
    """The names a docstring's Parameters section documents, or None without one."""
    headings = list(_SECTION.finditer(doc))
    for k, heading in enumerate(headings):
        if heading.group(1).strip() == "Parameters":
            end = headings[k + 1].start() if k + 1 < len(headings) else len(doc)
            body = doc[heading.end():end]
            indent = min((len(line) - len(line.lstrip()) for line in body.splitlines()
                          if line.strip()), default=0)
            names = set()
            for line in body.splitlines():
                if line.strip() and len(line) - len(line.lstrip()) == indent:
                    names.update(n.strip().lstrip("*") for n in line.split(":")[0].split(","))
            return names
    return None


def undocumented(source: str) -> list:
    """``(qualified name, missing parameters or None)`` of the public functions and methods of
    ``source`` with two or more parameters whose docstrings do not document them all."""
    found = []

    def visit(node, owner=""):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef) and not child.name.startswith("_"):
                visit(child, f"{child.name}.")
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                    and not child.name.startswith("_") \
                    and not any(getattr(d, "id", getattr(d, "attr", "")) in
                                ("property", "cached_property", "setter")
                                for d in child.decorator_list):
                arguments = child.args
                names = [a.arg for a in arguments.posonlyargs + arguments.args
                         + arguments.kwonlyargs if a.arg not in ("self", "cls")]
                names += [a.arg for a in (arguments.vararg, arguments.kwarg) if a is not None]
                if len(names) < 2:
                    continue
                documented = documented_parameters(ast.get_docstring(child) or "")
                missing = None if documented is None else [n for n in names
                                                          if n not in documented]
                if documented is None or missing:
                    found.append((owner + child.name, missing))

    visit(ast.parse(source))
    return found


@pytest.mark.parametrize("module", sorted(module_files()), ids=sorted(module_files()))
def test_every_parameter_is_documented(module):
    missing = undocumented(module_files()[module].read_text())
    assert not missing, f"{module}: " + "; ".join(
        f"{name}: {'no Parameters section' if lacking is None else 'lacks ' + ', '.join(lacking)}"
        for name, lacking in missing)


def test_the_check_finds_a_missing_section_and_a_missing_name():
    source = ('def f(a, b):\n    """Sum."""\n\n'
              'def g(a, b):\n    """Sum.\n\n    Parameters\n    ----------\n    a : float\n'
              '        First.\n\n    Returns\n    -------\n    float\n    """\n\n'
              'def h(a, *, b, **c):\n    """Sum.\n\n    Parameters\n    ----------\n'
              '    a, b : float\n        Terms.\n    **c : dict\n        More.\n    """\n\n'
              'def one(a):\n    """One parameter: prose is enough."""\n')
    assert undocumented(source) == [("f", None), ("g", ["b"])]
