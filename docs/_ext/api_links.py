"""Resolve the API's cross-references to the page where each object is documented.

The docstrings name objects by the module that defines them (``flexctl.model.variants.Model``,
``controllers.feedback.lqr.design_lqr``), the way a reader of the source finds them; the API
reference documents each object once, under the public name a program imports it by
(``flexctl.Model``, ``controllers.design_lqr``). This extension joins the two: a reference that
Sphinx's Python domain cannot find is imported, and when the object it names is documented
under another name the reference points there. Relative names (``layout`` in a method of
``Model``) are looked up from the class and the module the reference is written in.

The targets it adds: a record class's fields, listed in its numpydoc "Attributes" section,
become attribute entries of the class (:func:`attribute_targets`), and ``.. module-index::``
(the API's Modules page) describes every module with the members that no other API page
documents, its constants with their values. A class's bases that the API does not document
(private helpers such as ``KeywordOnly``) are left out of its "Bases" line, so that every name
the site shows as a link is one.

Everything else stays unresolved, and the nitpicky build (``-n -W``) fails on it.
"""

import functools
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

from sphinx.errors import PycodeError
from sphinx.pycode import ModuleAnalyzer
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import make_refnode

_ROLES = {"class": ("class", "exception", "data", "attribute"),
          "exc": ("exception", "class"),
          "func": ("function", "method", "classmethod", "staticmethod"),
          "meth": ("method", "classmethod", "staticmethod", "function", "property"),
          "attr": ("attribute", "property", "data"),
          "data": ("data", "attribute"),
          "const": ("data", "attribute"),
          "mod": ("module",),
          "obj": ()}


@functools.lru_cache(maxsize=None)
def _imported(path):
    """The object a dotted path names (a module, then attributes), or None."""
    parts = path.split(".")
    for split in range(len(parts), 0, -1):
        try:
            value = importlib.import_module(".".join(parts[:split]))
        except Exception:       # noqa: BLE001 - any failure: not this prefix
            continue
        try:
            for attribute in parts[split:]:
                value = inspect.getattr_static(value, attribute)
        except AttributeError:
            return None
        return value
    return None


def _has_identity(value):
    """Whether an object's identity names it (not a number, a string or an empty tuple,
    which the interpreter shares between unrelated names)."""
    return value is not None and not isinstance(value, (int, float, str, bool, bytes)) and (
        not isinstance(value, tuple) or len(value) > 0)


def _key(value):
    """What identifies an object across its names (functions wrapped in descriptors too)."""
    for wrapped in ("__func__", "fget"):
        value = getattr(value, wrapped, value) if not inspect.isclass(value) else value
    return id(value)


class _Index:
    """The documented name of each documented object, by the object's identity."""

    def __init__(self, domain):
        self.domain = domain
        self.names = {}
        for name, entry in domain.objects.items():
            value = _imported(name)
            if _has_identity(value):
                self.names.setdefault(_key(value), []).append((name, entry))

    def find(self, path, role):
        """The documented (name, entry) of what ``path`` names, or None."""
        value = _imported(path)
        kinds = _ROLES.get(role, ())
        found = self.names.get(_key(value), []) if _has_identity(value) else []
        for name, entry in found:
            if not kinds or entry.objtype in kinds:
                return name, entry
        if found:
            return found[0]
        # a number or a string: the documented constant of the same name and value
        last = path.rpartition(".")[2]
        if value is not None and not _has_identity(value):
            same = [(name, entry) for name, entry in self.domain.objects.items()
                    if name.rpartition(".")[2] == last and entry.objtype in ("data", "attribute")
                    and type(_imported(name)) is type(value) and _imported(name) == value]
            if len(same) == 1:
                return same[0]
        # a value known only by the place it is documented at
        owner, _, attribute = path.rpartition(".")
        owner_value = _imported(owner) if owner else None
        if owner_value is not None:
            for name, entry in self.names.get(_key(owner_value), []):
                candidate = f"{name}.{attribute}"
                if candidate in self.domain.objects:
                    return candidate, self.domain.objects[candidate]
        return None


def _candidates(target, node):
    """The full paths a possibly relative target may mean, nearest context first: the class
    and module the reference is written in, as documented and where they are defined."""
    target = target.lstrip("~.")
    module = node.get("py:module")
    cls = node.get("py:class")
    contexts = []
    if module and cls:
        contexts.append(f"{module}.{cls}")
        owner = _imported(f"{module}.{cls}")
        if inspect.isclass(owner):
            contexts.append(f"{owner.__module__}.{owner.__qualname__}")
            contexts.append(owner.__module__)
    if module:
        contexts.append(module)
        documented = node.get("refdoc", "").rpartition("/")[2]
        value = _imported(documented) if documented.startswith(module + ".") else None
        defined = getattr(value, "__module__", None)
        if isinstance(defined, str):
            contexts.append(defined)
    return [f"{context}.{target}" for context in contexts] + [target]


def missing_reference(app, env, node, contnode):
    """Sphinx's ``missing-reference`` event: the reference node to where the object named by
    ``node`` is documented, or None (the reference stays unresolved)."""
    if node.get("refdomain") != "py":
        return None
    domain = env.get_domain("py")
    index = getattr(env, "_api_links_index", None)
    if index is None or index.domain is not domain or len(index.domain.objects) != getattr(
            env, "_api_links_count", -1):
        index = env._api_links_index = _Index(domain)
        env._api_links_count = len(domain.objects)
    role = node.get("reftype")
    for path in _candidates(node["reftarget"], node):
        if path in domain.objects:
            name, entry = path, domain.objects[path]
        else:
            found = index.find(path, role)
            if found is None:
                continue
            name, entry = found
        return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id,
                            contnode, name)
    # an attribute that the class documents as a parameter of its constructor (a record
    # class's fields): the class's own entry
    if role in ("attr", "obj"):
        for path in _candidates(node["reftarget"], node):
            owner, _, attribute = path.rpartition(".")
            cls = _imported(owner) if owner else None
            if inspect.isclass(cls) and attribute in _parameters(cls):
                found = index.find(owner, "class")
                if found is not None:
                    name, entry = found
                    return make_refnode(app.builder, node["refdoc"], entry.docname,
                                        entry.node_id, contnode, f"{name}.{attribute}")
    # last, as Sphinx does for ``.name``: the one documented object whose name ends so
    suffix = "." + node["reftarget"].lstrip("~.")
    kinds = _ROLES.get(role, ())
    matches = [(name, entry) for name, entry in domain.objects.items()
               if name.endswith(suffix) and (not kinds or entry.objtype in kinds)]
    if len(matches) == 1:
        name, entry = matches[0]
        return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id,
                            contnode, name)
    return None


#: The packages with an API page of their own (whose module docstring that page shows).
_PUBLIC_PACKAGES = ("flexctl", "flexctl.model", "flexctl.sim", "controllers",
                    "controllers.codegen")


def _parameters(cls):
    """The names a class is constructed with (its dataclass fields included)."""
    names = set(getattr(cls, "__dataclass_fields__", {}))
    names |= set(getattr(cls, "_fields", ()))
    try:
        names |= set(inspect.signature(cls).parameters)
    except (TypeError, ValueError):
        pass
    return names


def process_bases(app, name, obj, options, bases):
    """Leave out of a class's bases those that are private (named with an underscore or
    defined in a module of the project that does not export them)."""
    kept = []
    for base in bases:
        module = getattr(base, "__module__", "") or ""
        project = module.split(".")[0] in ("flexctl", "controllers")
        if base is object or (project and _is_private(base)):
            continue
        kept.append(base)
    bases[:] = kept


def _is_private(base):
    if base.__name__.startswith("_"):
        return True
    for package in _PUBLIC_PACKAGES + ("flexctl.app",):
        exported = getattr(importlib.import_module(package), "__all__", ())
        if base.__name__ in exported and getattr(
                importlib.import_module(package), base.__name__, None) is base:
            return False
    return True


_ENTRY = re.compile(r"^    (?:\*\*(?P<plain>[^*]+)\*\*|:obj:`(?P<linked>[^`<]+?)\s*<[^`]*>`)"
                    r"(?:\s*:\s*(?P<type>.*))?$")


def attribute_targets(app, what, name, obj, options, lines):
    """Render a class's numpydoc "Attributes" section as attribute descriptions.

    numpydoc renders the fields of a record class (a dataclass field has no docstring of its
    own) as a table without anchors, so ``:attr:`layout``` could not point at them; as
    ``py:attribute`` entries each field is a target of its class (``flexctl.Model.layout``).
    Attributes that have their own documented entry (properties) keep that entry as the target.
    """
    if what != "class" or ":Attributes:" not in lines:
        return
    documented = {attribute for attribute in dir(obj) if not attribute.startswith("_") and (
        isinstance(inspect.getattr_static(obj, attribute, None), property)
        or inspect.isdatadescriptor(inspect.getattr_static(obj, attribute, None)))}
    try:                                # attributes with a ``#:`` comment: autodoc's own
        comments = ModuleAnalyzer.for_module(obj.__module__).find_attr_docs()
        documented |= {attribute for (owner, attribute) in comments
                       if owner == obj.__qualname__}
    except PycodeError:
        pass
    start = lines.index(":Attributes:")
    end = start + 1
    while end < len(lines) and (not lines[end].strip() or lines[end].startswith(" ")):
        end += 1
    entries, current = [], None
    for line in lines[start + 1:end]:
        match = _ENTRY.match(line)
        if match:
            names = match.group("plain") or match.group("linked")
            names = [n.strip() for n in names.split(",")]
            current = {"names": names, "type": (match.group("type") or "").strip(),
                       "linked": match.group("linked") is not None
                       or any(n in documented for n in names), "text": []}
            entries.append(current)
        elif current is not None:
            current["text"].append(line[8:] if line.startswith(" " * 8) else line.strip())
        elif line.strip():
            return                      # a layout this does not know: left as numpydoc made it
    out = [".. rubric:: Attributes", ""]
    for entry in entries:
        first, *others = entry["names"]
        out.append(f".. py:attribute:: {first}")
        out += [f"                  {other}" for other in others]
        if entry["linked"]:
            out.append("   :no-index:")
        out.append("")
        text = [t for t in entry["text"] if t.strip() != ".."]
        if entry["type"]:
            text = [f"*{entry['type']}*" + (": " + text[0] if text else "")] + text[1:]
        out += ["   " + t if t.strip() else "" for t in text]
        out.append("")
    lines[start:end] = out


class ModuleIndex(SphinxDirective):
    """``.. module-index:: flexctl controllers``: every module of the packages, its docstring.

    The API pages document each public object once, under the name programs import it by;
    this page is where the modules that define them are described, one section per module
    (sorted), so that ``:mod:`flexctl.model.layout``` and the ``[source]`` links have a page.
    """

    required_arguments = 1
    final_argument_whitespace = True

    def run(self):
        pages = Path(self.env.srcdir, "api").glob("*.rst")
        public = _public_objects(pages)
        lines = []
        for package in self.arguments[0].split():
            for name, module in project_modules(package):
                if name in _PUBLIC_PACKAGES:
                    continue                  # described on its own API page
                shown = [attribute for attribute, value in vars(module).items()
                         if id(value) in public or f"{name}.{attribute}" in public
                         or _imported_here(value, name)]
                lines += [name, "-" * len(name), "", f".. automodule:: {name}",
                          "   :members:", "   :undoc-members:", "   :ignore-module-all:"]
                if shown:
                    lines.append(f"   :exclude-members: {', '.join(sorted(shown))}")
                lines.append("")
        return self.parse_text_to_nodes("\n".join(lines), allow_section_headings=True)


def project_modules(package):
    """``(name, module)`` of a package and of each of its modules whose name has no leading
    underscore, the package first, then sorted by name."""
    root = importlib.import_module(package)
    names = [package] + sorted(
        info.name for info in pkgutil.walk_packages(root.__path__, package + ".")
        if not info.name.rpartition(".")[2].startswith("_"))
    return [(name, importlib.import_module(name)) for name in names]


def _imported_here(value, module):
    """Whether a module's attribute is a function, class or module defined elsewhere."""
    if inspect.ismodule(value):
        return True
    defined = getattr(value, "__module__", None)
    return (inspect.isclass(value) or callable(value)) and defined != module


def _public_objects(pages):
    """The objects that the API pages list (``autosummary`` entries): their identities, and
    their full names (a number or a string has no identity of its own)."""
    found = set()
    for page in pages:
        module = None
        for line in page.read_text().splitlines():
            current = re.match(r"\.\. currentmodule:: (\S+)", line)
            if current:
                module = current.group(1)
            elif module and re.match(r"   [A-Za-z_][\w.]*$", line):
                full = f"{module}.{line.strip()}"
                found.add(full)
                value = _imported(full)
                if _has_identity(value):
                    found.add(id(value))
    return found


def skip_class_data(app, what, name, obj, skip, options):
    """On the modules page (``undoc-members``: a module's constants are listed with their
    values), a class's plain data members stay out: its docstring's Attributes section
    describes them (:func:`attribute_targets`)."""
    undocumented = getattr(options, "undoc_members", None) or (
        isinstance(options, dict) and options.get("undoc-members"))
    if what == "class" and undocumented and not (
            callable(obj) or isinstance(obj, (property, classmethod, staticmethod))
            or inspect.isdatadescriptor(obj)):
        return True
    return None


def setup(app):
    app.connect("autodoc-skip-member", skip_class_data)
    app.add_directive("module-index", ModuleIndex)
    app.connect("autodoc-process-docstring", attribute_targets, priority=600)
    app.connect("missing-reference", missing_reference, priority=900)
    app.connect("autodoc-process-bases", process_bases)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
