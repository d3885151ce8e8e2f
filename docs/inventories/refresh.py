"""Refresh the intersphinx inventories that the documentation links other projects with.

The site is built offline, so the inventories (``objects.inv`` files, Sphinx's index of a
project's documented objects) of the projects that flexctl's pages refer to are kept here, one
file per project, and read by ``docs/conf.py`` through ``intersphinx_mapping``.

Usage::

    python docs/inventories/refresh.py             # download every project's objects.inv
    python docs/inventories/refresh.py --generate  # write control.inv and casadi.inv offline

``--download`` (the default) replaces each file by the project's published inventory and keeps
the stored file when a download fails. ``--generate`` writes the inventories of python-control
and CasADi from the installed packages instead: every public class and function (and the public
methods of the classes), each pointing at the page its project's documentation gives it
(python-control: one page per object under ``generated/``; CasADi: anchors of the Python API
page, ``#casadi.casadi.<name>``). The stored ``python``, ``numpy``, ``scipy`` and
``matplotlib`` files are those projects' own published inventories.
"""

import argparse
import inspect
import sys
import urllib.request
import zlib
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: Each project's documentation root (the base of its inventory's addresses) and inventory.
PROJECTS = {
    "python": "https://docs.python.org/3/",
    "numpy": "https://numpy.org/doc/stable/",
    "scipy": "https://docs.scipy.org/doc/scipy/reference/",
    "matplotlib": "https://matplotlib.org/stable/",
    "control": "https://python-control.readthedocs.io/en/latest/",
    "casadi": "https://web.casadi.org/python-api/",
}


def download(name):
    """Replace ``<name>.inv`` by the project's published inventory; True when it was."""
    url = PROJECTS[name] + "objects.inv"
    try:
        with urllib.request.urlopen(url, timeout=30) as response:
            data = response.read()
    except OSError as error:
        print(f"{name}: kept the stored inventory ({url}: {error})")
        return False
    if not data.startswith(b"# Sphinx inventory version 2"):
        print(f"{name}: kept the stored inventory ({url} is no Sphinx inventory)")
        return False
    (HERE / f"{name}.inv").write_bytes(data)
    print(f"{name}: {len(data)} bytes from {url}")
    return True


def _write(name, project, version, entries):
    """Write a version-2 inventory: ``entries`` are (name, role, address) triples."""
    header = (f"# Sphinx inventory version 2\n# Project: {project}\n# Version: {version}\n"
              "# The remainder of this file is compressed using zlib.\n").encode()
    lines = "".join(f"{entry} py:{role} 1 {address} -\n"
                    for entry, role, address in sorted(set(entries)))
    (HERE / f"{name}.inv").write_bytes(header + zlib.compress(lines.encode()))
    print(f"{name}: {len(set(entries))} objects generated from {project} {version}")


def _members(cls):
    for attribute, value in vars(cls).items():
        if attribute.startswith("_"):
            continue
        if callable(value) or isinstance(value, (staticmethod, classmethod)):
            yield attribute, "method"
        elif isinstance(value, property):
            yield attribute, "attribute"


def generate_control():
    """Inventory of python-control: each object on its page ``generated/control.<name>``."""
    import control
    entries = [("control", "module", "index.html#module-control")]
    for attribute in dir(control):
        value = getattr(control, attribute)
        if attribute.startswith("_") or not getattr(value, "__module__", "").startswith(
                "control"):
            continue
        if inspect.isclass(value):
            page = f"generated/control.{attribute}.html"
            entries.append((f"control.{attribute}", "class", f"{page}#control.{attribute}"))
            for member, role in _members(value):
                full = f"control.{attribute}.{member}"
                entries.append((full, role, f"{page}#{full}"))
        elif inspect.isfunction(value):
            entries.append((f"control.{attribute}", "function",
                            f"generated/control.{attribute}.html#control.{attribute}"))
    _write("control", "python-control", control.__version__, entries)


def generate_casadi():
    """Inventory of CasADi's Python API: each object an anchor of its one API page."""
    import casadi
    entries = [("casadi", "module", "#module-casadi.casadi")]
    for attribute in dir(casadi):
        value = getattr(casadi, attribute)
        if attribute.startswith("_") or getattr(value, "__module__", None) != "casadi.casadi":
            continue
        anchor = f"#casadi.casadi.{attribute}"
        if inspect.isclass(value):
            entries.append((f"casadi.{attribute}", "class", anchor))
            for member, role in _members(value):
                entries.append((f"casadi.{attribute}.{member}", role,
                                f"#casadi.casadi.{attribute}.{member}"))
        elif callable(value):
            entries.append((f"casadi.{attribute}", "function", anchor))
    _write("casadi", "CasADi", casadi.__version__, entries)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generate", action="store_true",
                        help="write control.inv and casadi.inv from the installed packages")
    arguments = parser.parse_args(argv)
    if arguments.generate:
        generate_control()
        generate_casadi()
        return 0
    failed = [name for name in PROJECTS if not download(name)]
    return 1 if failed and len(failed) == len(PROJECTS) else 0


if __name__ == "__main__":
    sys.exit(main())
