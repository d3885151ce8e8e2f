"""The layers import downwards only, and no modules import each other in a cycle.

Layers, lowest first: ``flexctl.model`` (physics) < ``flexctl.sim`` (simulation) <
``controllers`` < ``flexctl.app`` (scenes, CLI, reports, plots). The top-level ``flexctl``
package re-exports the application layer's scene functions, so it counts as ``app``: a lower
layer imports ``flexctl.model`` or ``flexctl.sim``, never ``flexctl`` itself.

Imports are read from the source with :mod:`ast`, including the ones inside functions, so an
import hidden in a function body to dodge a cycle still counts.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("flexctl", "controllers")
#: Layers from the lowest; a module may import its own layer and the ones before it.
LAYERS = ("model", "sim", "controllers", "app")
LAYER_PREFIXES = {"flexctl.model": "model", "flexctl.sim": "sim", "controllers": "controllers",
                  "flexctl.app": "app", "flexctl": "app"}


def module_files() -> dict:
    """Module name -> source file, for every module of the project's packages."""
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


def _known(name: str, modules) -> str | None:
    """The project module a dotted name refers to (its longest known prefix), or None."""
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        candidate = ".".join(parts[:end])
        if candidate in modules:
            return candidate
    return None


def imported_modules(module: str, path: Path, modules) -> set:
    """Project modules that ``module`` imports anywhere in its source (functions included)."""
    is_package = path.name == "__init__.py"
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = module if is_package else module.rpartition(".")[0]
                base_parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module
            # "from package import submodule" imports the submodule
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base
                       for alias in node.names]
        else:
            continue
        for target in targets:
            known = _known(target, modules)
            if known is not None and known != module:
                found.add(known)
    return found


def import_graph() -> dict:
    modules = module_files()
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def layer(module: str) -> str:
    for prefix, name in sorted(LAYER_PREFIXES.items(), key=lambda item: -len(item[0])):
        if module == prefix or module.startswith(prefix + "."):
            return name
    raise ValueError(f"module {module!r} belongs to no layer; add it to LAYER_PREFIXES")


def upward_imports(graph: dict) -> list:
    """``(importer, imported)`` pairs where a lower layer imports a higher one."""
    rank = {name: i for i, name in enumerate(LAYERS)}
    return sorted((src, dst) for src, targets in graph.items() for dst in targets
                  if rank[layer(dst)] > rank[layer(src)])


def import_cycles(graph: dict) -> list:
    """Strongly connected groups of more than one module (Tarjan's algorithm), sorted."""
    index, low, on_stack, stack, cycles = {}, {}, set(), [], []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for succ in graph.get(node, ()):
            if succ not in index:
                visit(succ)
                low[node] = min(low[node], low[succ])
            elif succ in on_stack:
                low[node] = min(low[node], index[succ])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                cycles.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(cycles)


GRAPH = import_graph()


def test_every_layer_has_modules():
    assert {layer(module) for module in GRAPH} == set(LAYERS)


@pytest.mark.parametrize("module", sorted(GRAPH), ids=sorted(GRAPH))
def test_module_imports_only_its_layer_and_lower(module):
    upward = [dst for src, dst in upward_imports({module: GRAPH[module]})]
    assert not upward, (f"{module} (layer {layer(module)}) imports "
                        + ", ".join(f"{dst} (layer {layer(dst)})" for dst in upward))


def test_no_import_cycles():
    cycles = import_cycles(GRAPH)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_only_the_app_layer_imports_controllers():
    importers = {src for src, targets in GRAPH.items() for dst in targets
                 if layer(dst) == "controllers" and layer(src) != "controllers"}
    assert all(layer(src) == "app" for src in importers), importers


def test_hidden_imports_inside_functions_are_found(tmp_path):
    source = tmp_path / "mod.py"
    source.write_text("def f():\n    from ..app import cli\n    import controllers.feedback.pd\n")
    modules = {"flexctl.sim.mod": source, "flexctl.app.cli": None, "flexctl.app": None,
               "controllers.feedback.pd": None, "controllers": None}
    assert imported_modules("flexctl.sim.mod", source, modules) == {"flexctl.app.cli",
                                                                    "controllers.feedback.pd"}
    source.write_text("from ..model import Model\nfrom . import maneuvers\n")
    modules = {"flexctl.sim.mod": source, "flexctl.model": None, "flexctl.sim.maneuvers": None}
    assert imported_modules("flexctl.sim.mod", source, modules) == {"flexctl.model",
                                                                    "flexctl.sim.maneuvers"}


def test_checks_catch_an_upward_import_and_a_cycle():
    graph = {"flexctl.model.variants": {"flexctl.sim.simulation"},
             "flexctl.sim.simulation": {"flexctl.model.variants"},
             "flexctl.app.cli": {"flexctl.app.bench"}, "flexctl.app.bench": {"flexctl.app.cli"},
             "controllers.feedback.pd": {"flexctl.model.variants"}}
    assert upward_imports(graph) == [("flexctl.model.variants", "flexctl.sim.simulation")]
    assert import_cycles(graph) == [["flexctl.app.bench", "flexctl.app.cli"],
                                    ["flexctl.model.variants", "flexctl.sim.simulation"]]


#: Longest function (``def`` to its last line, its docstring left out: every parameter is
#: documented there) in flexctl/ and controllers/.
MAX_FUNCTION_LINES = 80


def _code_lines(node) -> int:
    """Lines of a function from its ``def`` to its end, less its docstring's."""
    lines = node.end_lineno - node.lineno + 1
    first = node.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
            and isinstance(first.value.value, str):
        lines -= first.end_lineno - first.lineno + 1
    return lines


def long_functions(path: Path) -> list:
    """``(name, lines)`` of every function in ``path`` longer than :data:`MAX_FUNCTION_LINES`."""
    tree = ast.parse(path.read_text(), filename=str(path))
    return [(node.name, _code_lines(node)) for node in ast.walk(tree)
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and _code_lines(node) > MAX_FUNCTION_LINES]


@pytest.mark.parametrize("module", sorted(module_files()), ids=sorted(module_files()))
def test_functions_fit_on_a_screen(module):
    long = long_functions(module_files()[module])
    assert not long, f"{module}: functions over {MAX_FUNCTION_LINES} lines: {long}"


def test_long_function_check_catches_one(tmp_path):
    source = tmp_path / "mod.py"
    source.write_text("def f():\n" + "    x = 1\n" * MAX_FUNCTION_LINES)
    assert long_functions(source) == [("f", MAX_FUNCTION_LINES + 1)]
    source.write_text('def f():\n    """Doc.\n\n    More.\n    """\n' + "    x = 1\n" * 10)
    assert long_functions(source) == []


@pytest.mark.parametrize("lower", ["flexctl.model", "flexctl.sim", "flexctl"])
def test_importing_a_lower_layer_loads_nothing_above_it(lower):
    # run in a fresh interpreter: this one has loaded every layer already
    import subprocess
    import sys

    code = (f"import sys, {lower}\n"
            "print(' '.join(sorted(m for m in sys.modules\n"
            "      if m.startswith(('flexctl.app', 'controllers')) or m == 'controllers')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, check=True)
    assert done.stdout.split() == [], f"import {lower} loaded {done.stdout}"


def test_top_level_names_load_on_first_use():
    import flexctl

    assert set(flexctl.__all__) <= set(dir(flexctl))
    assert flexctl.load_scene.__module__ == "flexctl.app.scenes"
    assert flexctl.sim.simulate is flexctl.simulate and "sim" in dir(flexctl)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        flexctl.nothing


def private_imports(path: Path) -> list:
    """``(module, name)`` of every ``_private`` name that ``path`` imports from another module
    (a name one module shares with another is a public name of the lower one)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    return [("." * node.level + (node.module or ""), alias.name) for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom) for alias in node.names
            if alias.name.startswith("_") and not alias.name.startswith("__")]


@pytest.mark.parametrize("module", sorted(module_files()), ids=sorted(module_files()))
def test_no_private_name_is_imported_across_modules(module):
    found = private_imports(module_files()[module])
    assert not found, f"{module} imports private names: {found}"


def test_private_import_check_catches_one(tmp_path):
    source = tmp_path / "mod.py"
    source.write_text("from .compiled import _cached, public\nfrom os import path\n")
    assert private_imports(source) == [(".compiled", "_cached")]


#: The parts of :mod:`controllers` from the lowest; each imports only itself and those before it.
CONTROLLER_PARTS = ("spec", "design", "slew", "feedback", "mpc", "analysis", "factory",
                    "codegen")


def controller_part(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "controllers" and len(parts) > 1 else None


def test_every_controllers_module_has_a_part():
    parts = {controller_part(m) for m in GRAPH if m.startswith("controllers.")}
    assert parts <= set(CONTROLLER_PARTS), parts - set(CONTROLLER_PARTS)


@pytest.mark.parametrize("module", sorted(m for m in GRAPH if controller_part(m)))
def test_controllers_parts_import_downwards(module):
    rank = {name: i for i, name in enumerate(CONTROLLER_PARTS)}
    own = rank[controller_part(module)]
    upward = [dst for dst in GRAPH[module]
              if controller_part(dst) and rank[controller_part(dst)] > own]
    assert not upward, f"{module} imports {upward}, above its part"


def test_former_flat_paths_name_the_moved_modules():
    import importlib

    import controllers

    for former, current in controllers.FORMER_PATHS.items():
        module = importlib.import_module(f"controllers.{current}")
        assert importlib.import_module(f"controllers.{former}") is module
        assert getattr(controllers, former) is module
    from controllers.feedback import ReferenceFeedback
    from controllers.analysis import loop_margins
    assert ReferenceFeedback.__module__ == "controllers.feedback.reference_feedback"
    assert loop_margins.__module__ == "controllers.analysis.loops"
