"""Every public function, method and constructor with a parameter documents each of them in a
numpydoc ``Parameters`` section: name, type, then what it is (and the unit, shape and default
where they apply), in the order of the signature, and nothing that is not in it. The rules are
numpydoc's PR01 (a parameter missing), PR02 (a name that is no parameter), PR03 (order), PR04
(no type), PR07 (no description) and PR10 (no space before the colon).

Public: reachable without a leading underscore in the module path, the class and the function
name. Functions and methods are read from the source with :mod:`ast`, so the check covers what
the API pages of the documentation do not show too; constructors (explicit ``__init__``,
dataclass fields, named-tuple fields) are read from the imported classes, whose signatures
include inherited fields. The documentation build validates the rendered docstrings with
numpydoc as well (``numpydoc_validation_checks`` in ``docs/conf.py``, a warning that fails
``sphinx-build -W``).

A record class (dataclass or named tuple) without a ``Parameters`` section may list its fields
under ``Attributes`` instead: they are the constructor's parameters. Classes built through
Python's own constructors (``Enum`` members, ``Protocol`` placeholders, exceptions and plain
classes without an ``__init__`` of their own) have no parameters of theirs to document.
"""

import ast
import dataclasses
import enum
import importlib
import inspect
import re

import pytest

from tests.test_architecture import ROOT, module_files

#: A numpydoc section heading and its underline.
_SECTION = re.compile(r"^\s*([A-Z][A-Za-z ]+)\n\s*-{3,}\s*$", re.M)
#: Sections whose entries are parameters (numpydoc counts both).
PARAMETER_SECTIONS = ("Parameters", "Other Parameters")
#: Decorators of functions that take no call parameters (read as attributes) or only declare.
_NOT_CALLED = ("property", "cached_property", "setter", "deleter", "overload")


def section_entries(doc: str, titles=PARAMETER_SECTIONS) -> list | None:
    """The entries of a docstring's sections ``titles``, or None without any of them.

    Parameters
    ----------
    doc : str
        A cleaned docstring (as :func:`ast.get_docstring` or :func:`inspect.getdoc` give).
    titles : tuple of str, optional
        Section headings to read, in any order of the docstring. Default: ``Parameters`` and
        ``Other Parameters``.

    Returns
    -------
    list of tuple or None
        ``(name, type, description)`` of each documented name, in the docstring's order; a
        header ``a, b : float`` gives two entries. ``type`` is ``""`` when the header has no
        `` : `` (numpydoc then reads ``name: float`` as a name with a colon).
    """
    headings = list(_SECTION.finditer(doc))
    entries, found = [], False
    for k, heading in enumerate(headings):
        if heading.group(1).strip() not in titles:
            continue
        found = True
        end = headings[k + 1].start() if k + 1 < len(headings) else len(doc)
        lines = doc[heading.end():end].splitlines()
        indent = min((len(line) - len(line.lstrip()) for line in lines if line.strip()),
                     default=0)
        for i, line in enumerate(lines):
            if not line.strip() or len(line) - len(line.lstrip()) != indent:
                continue
            header = line.strip()
            names, _, kind = header.partition(" : ")
            description = []
            for follow in lines[i + 1:]:
                if follow.strip() and len(follow) - len(follow.lstrip()) <= indent:
                    break
                description.append(follow.strip())
            text = " ".join(d for d in description if d)
            for name in names.split(","):
                entries.append((name.strip(), kind.strip(), text))
    return entries if found else None


def problems(names: list, doc: str, record: bool = False) -> list:
    """What a docstring's parameter sections get wrong about the parameters ``names``.

    Parameters
    ----------
    names : list of str
        The signature's parameters in order, ``*args`` and ``**kwargs`` with their stars (as
        numpydoc writes them), without a method's ``self`` or ``cls``.
    doc : str
        The cleaned docstring.
    record : bool, optional
        Whether the object is a record class whose fields a ``Parameters``-less docstring may
        list under ``Attributes``. Default False.

    Returns
    -------
    list of str
        One message per problem (numpydoc's code in brackets); empty when all is documented.
    """
    entries = section_entries(doc)
    if entries is None:
        attributes = section_entries(doc, ("Attributes",)) if record else None
        if attributes is None:
            return ["no Parameters section"]
        lacking = [n for n in names if n not in {name for name, _, _ in attributes}]
        return [f"lacks {', '.join(lacking)} (PR01)"] if lacking else []
    documented = [name for name, _, _ in entries]
    found = []
    lacking = [n for n in names if n not in documented]
    unknown = [n for n in documented if n not in names]
    if lacking:
        found.append(f"lacks {', '.join(lacking)} (PR01)")
    if unknown:
        found.append(f"documents {', '.join(unknown)}, not parameters (PR02)")
    if not lacking and not unknown and documented != list(names):
        found.append(f"documents them in the order {', '.join(documented)} (PR03)")
    for name, kind, description in entries:
        if ":" in name:
            found.append(f"{name.split(':')[0]}: a space before the colon (PR10)")
        elif not kind and not name.startswith("*"):
            found.append(f"{name}: no type (PR04)")
        if not description:
            found.append(f"{name}: no description (PR07)")
    return found


def _signature_names(arguments: ast.arguments, method: bool) -> list:
    """Parameter names of an :mod:`ast` signature, a method's first one left out."""
    positional = arguments.posonlyargs + arguments.args
    if method and positional:
        positional = positional[1:]
    names = [a.arg for a in positional + arguments.kwonlyargs]
    if arguments.vararg is not None:
        names.insert(len(positional), "*" + arguments.vararg.arg)
    if arguments.kwarg is not None:
        names.append("**" + arguments.kwarg.arg)
    return names


def _decorator_names(node) -> set:
    names = set()
    for decorator in node.decorator_list:
        if isinstance(decorator, ast.Call):
            decorator = decorator.func
        names.add(getattr(decorator, "id", getattr(decorator, "attr", "")))
    return names


def undocumented(source: str) -> list:
    """``(qualified name, problems)`` of the public functions and methods of ``source`` with at
    least one parameter (besides a method's ``self`` or ``cls``) whose docstrings do not
    document them all, in order, with a type and a description.

    Parameters
    ----------
    source : str
        The text of a Python module.

    Returns
    -------
    list of tuple
        ``(name, problems)``, ``problems`` a list of messages as :func:`problems` gives.
    """
    found = []

    def visit(node, owner=""):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef) and not child.name.startswith("_"):
                visit(child, f"{owner}{child.name}.")
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                    and not child.name.startswith("_"):
                decorators = _decorator_names(child)
                if decorators & set(_NOT_CALLED):
                    continue
                method = bool(owner) and "staticmethod" not in decorators
                names = _signature_names(child.args, method)
                if not names:
                    continue
                wrong = problems(names, ast.get_docstring(child) or "")
                if wrong:
                    found.append((owner + child.name, wrong))

    visit(ast.parse(source))
    return found


def _public(module: str) -> bool:
    return not any(part.startswith("_") for part in module.split("."))


def _constructor_is_own(cls) -> bool:
    """Whether ``cls`` is built through an ``__init__`` or ``__new__`` of this project (its
    own, a generated dataclass one, a named tuple's), not one of Python's (``object``,
    exceptions, a ``Protocol``'s placeholder, an ``Enum``'s member lookup)."""
    if issubclass(cls, enum.Enum) or getattr(cls, "_is_protocol", False):
        return False
    if issubclass(cls, tuple) and hasattr(cls, "_fields"):
        return True                     # a named tuple's __new__ is made by collections
    for base in cls.__mro__:
        for method in ("__init__", "__new__"):
            if method in vars(base):
                function = inspect.unwrap(getattr(vars(base)[method], "__func__",
                                                  vars(base)[method]))
                module = getattr(function, "__module__", None) or ""
                return module.split(".")[0] in ("flexctl", "controllers")
    return False


def undocumented_constructors(module: str) -> list:
    """``(class name, problems)`` of the public classes defined in ``module`` whose
    constructors take parameters their docstrings do not document.

    Parameters
    ----------
    module : str
        Dotted name of a module of the project, imported here.

    Returns
    -------
    list of tuple
        ``(name, problems)``, ``problems`` a list of messages as :func:`problems` gives.
    """
    found = []
    for name, cls in sorted(vars(importlib.import_module(module)).items()):
        if name.startswith("_") or not inspect.isclass(cls) or cls.__module__ != module \
                or not _constructor_is_own(cls):
            continue
        names = []
        for parameter in inspect.signature(cls).parameters.values():
            star = {parameter.VAR_POSITIONAL: "*", parameter.VAR_KEYWORD: "**"}
            names.append(star.get(parameter.kind, "") + parameter.name)
        if not names:
            continue
        record = dataclasses.is_dataclass(cls) or hasattr(cls, "_fields")
        wrong = problems(names, inspect.cleandoc(cls.__doc__ or ""), record=record)
        if wrong:
            found.append((name, wrong))
    return found


def _report(module, found):
    return f"{module}: " + "; ".join(f"{name}: {', '.join(wrong)}" for name, wrong in found)


PUBLIC_MODULES = sorted(m for m in module_files() if _public(m))


@pytest.mark.parametrize("module", PUBLIC_MODULES)
def test_every_parameter_is_documented(module):
    found = undocumented(module_files()[module].read_text())
    assert not found, _report(module, found)


@pytest.mark.parametrize("module", PUBLIC_MODULES)
def test_every_constructor_parameter_is_documented(module):
    found = undocumented_constructors(module)
    assert not found, _report(module, found)


def test_the_check_finds_what_numpydoc_would():
    source = ('def f(a, b):\n    """Sum."""\n\n'
              'def g(a, b):\n    """Sum.\n\n    Parameters\n    ----------\n    a : float\n'
              '        First.\n\n    Returns\n    -------\n    float\n    """\n\n'
              'def h(a, *, b, **c):\n    """Sum.\n\n    Parameters\n    ----------\n'
              '    a, b : float\n        Terms.\n    **c : dict\n        More.\n    """\n\n'
              'def one(a):\n    """One parameter: prose is not enough."""\n\n'
              'def extra(a):\n    """One.\n\n    Parameters\n    ----------\n    a : float\n'
              '        It.\n    b : float\n        Gone.\n    """\n\n'
              'def order(a, b):\n    """Two.\n\n    Parameters\n    ----------\n    b : float\n'
              '        Second.\n    a : float\n        First.\n    """\n\n'
              'def typeless(a, b, c):\n    """Three.\n\n    Parameters\n    ----------\n'
              '    a\n        No type.\n    b: float\n        No space.\n    c : float\n    """\n\n'
              'class K:\n    def m(self, x):\n        """M."""\n\n'
              '    @staticmethod\n    def s(x):\n        """S.\n\n        Parameters\n'
              '        ----------\n        x : int\n            Count.\n        """\n\n'
              '    @property\n    def p(self):\n        """P."""\n\n'
              'def _private(a):\n    """Not checked."""\n\n'
              'def none():\n    """No parameters."""\n')
    assert undocumented(source) == [
        ("f", ["no Parameters section"]),
        ("g", ["lacks b (PR01)"]),
        ("one", ["no Parameters section"]),
        ("extra", ["documents b, not parameters (PR02)"]),
        ("order", ["documents them in the order b, a (PR03)"]),
        ("typeless", ["lacks b (PR01)", "documents b: float, not parameters (PR02)",
                      "a: no type (PR04)", "b: a space before the colon (PR10)",
                      "c: no description (PR07)"]),
        ("K.m", ["no Parameters section"]),
    ]


def test_a_record_may_list_its_fields_as_attributes():
    doc = "A record.\n\nAttributes\n----------\na : float\n    First.\n"
    assert problems(["a"], doc, record=True) == []
    assert problems(["a", "b"], doc, record=True) == ["lacks b (PR01)"]
    assert problems(["a"], doc) == ["no Parameters section"]


def test_the_documentation_build_validates_the_parameter_sections():
    """``docs/conf.py`` has numpydoc check the same rules (and more) on the rendered pages, where
    ``sphinx-build -W`` (tests/app/test_site.py) turns each finding into a failed build."""
    tree = ast.parse((ROOT / "docs" / "conf.py").read_text())
    settings = {target.id: node.value for node in tree.body if isinstance(node, ast.Assign)
                for target in node.targets if isinstance(target, ast.Name)}
    checks = ast.literal_eval(settings["numpydoc_validation_checks"])
    assert {"PR01", "PR02", "PR03", "PR04", "PR07", "PR10"} <= checks, checks
    assert "numpydoc" in ast.literal_eval(settings["extensions"])
