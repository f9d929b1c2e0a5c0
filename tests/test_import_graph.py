"""The import graph of ``moose`` and ``moose_ros`` has no cycle, and the core never imports the ROS package.

Every module of ``src/moose`` and ``moose_ros`` is parsed with :mod:`ast` (nothing is imported), and every import in
it counts: at module level, in a function, under ``if TYPE_CHECKING:`` (a type-only cycle is still two modules that
cannot be understood one without the other), and ``importlib.import_module("a.literal.name")``.  A name computed at
run time (``moose_ros.nodes`` loads a node's module by its name) cannot be read from the source and is not counted.

What an import points to:

- ``import a.b.c`` and ``from a.b import c`` where ``a/b/c`` is a module or package of ours: the module ``a.b.c``.
- ``from a.b import name`` where ``name`` is not a module (a class, a function, a constant): ``a.b`` (its
  ``__init__`` when ``a.b`` is a package).
- Relative imports resolve against the importing module's package (a package's ``__init__`` is in that package).

How a package's ``__init__`` counts: as one module of its own, named by the package (``moose.planner``).  An import
of ``a.b.c`` is an edge to ``a.b.c`` only, not to the ``__init__`` of ``a.b`` that Python runs first.  Why: an
``__init__`` that gathers its package's API (``from .mpc import MpcPlanner``) would otherwise form a cycle with every
one of its modules that imports a sibling; that pattern is safe, since the package is already being initialised
when its modules run.  What is not safe is still caught: a module that imports *from the package itself*
(``from moose.planner import MODE_PLANNERS`` in a module that the ``__init__`` of ``moose.planner`` imports) is an
edge to that ``__init__``, and so part of a cycle.
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Iterator

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"moose": ROOT / "src" / "moose", "moose_ros": ROOT / "ros2_ws" / "src" / "moose_ros" / "moose_ros"}


def module_files() -> dict[str, Path]:
    """Dotted module name → source file, for every module and package ``__init__`` of ``moose`` and ``moose_ros``."""
    found: dict[str, Path] = {}
    for top, folder in PACKAGES.items():
        for path in sorted(folder.rglob("*.py")):
            parts = [top, *path.relative_to(folder).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def imported_names(module: str, path: Path, known: set[str]) -> Iterator[str]:
    """Every absolute name ``module`` imports (module, or module plus the name taken from it), at any depth."""
    is_package = path.name == "__init__.py"
    package = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                assert base, f"{path}: relative import beyond the top package"
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                assert node.module is not None
                source = node.module
            for alias in node.names:
                submodule = f"{source}.{alias.name}"
                yield submodule if submodule in known else source
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            yield node.args[0].value


def import_graph() -> dict[str, set[str]]:
    """Module → the modules of ours it imports (see the module docstring for what counts)."""
    files = module_files()
    known = set(files)
    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        targets = set()
        for name in imported_names(module, path, known):
            while name and name not in known:  # ``import a.b.name`` of an attribute: the module that holds it
                name = name.rpartition(".")[0]
            if name:
                targets.add(name)
        graph[module] = targets
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module, and the modules that import themselves (Tarjan's
    algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, edges = work[-1]
            for target in edges:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(graph[target]))))
                    break
                if target in on_stack:
                    low[node] = min(low[node], index[target])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1 or node in graph[node]:
                        found.append(sorted(component))
    return found


def test_the_graph_is_read_from_every_module() -> None:
    """The graph covers both packages and resolves relative and function-level imports (a parser that saw nothing
    would find no cycle)."""
    graph = import_graph()
    assert "moose.planner.mpc.planner" in graph and "moose_ros.nodes.base" in graph
    assert "moose_ros.faults" in graph["moose_ros.launch"]  # from .faults import … (relative, module level)
    assert "moose_ros.incidents" in graph["moose_ros.faults"]
    assert "moose.canbus.bus" in graph["moose_ros.launch"]  # imported inside node_overrides
    assert sum(len(targets) for targets in graph.values()) > 300


def test_there_is_no_import_cycle() -> None:
    found = cycles(import_graph())
    assert not found, "import cycles (each list: modules that import one another, directly or not): " + \
        "; ".join(" ↔ ".join(c) for c in found)


@pytest.mark.parametrize("graph, expected", [
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, [["a", "b", "c"]]),
    ({"a": {"a"}, "b": set()}, [["a"]]),
    ({"a": {"b", "c"}, "b": {"c"}, "c": set()}, []),
])
def test_cycles_are_found(graph: dict[str, set[str]], expected: list[list[str]]) -> None:
    assert cycles(graph) == expected


def test_the_core_never_imports_the_ros_package() -> None:
    graph = import_graph()
    crossing = sorted(f"{m} → {t}" for m, targets in graph.items() if m.split(".")[0] == "moose"
                      for t in targets if t.split(".")[0] == "moose_ros")
    assert not crossing
    files = module_files()
    raw = sorted(m for m, path in files.items() if m.split(".")[0] == "moose"
                 for name in imported_names(m, path, set(files)) if name.split(".")[0] == "moose_ros")
    assert not raw, f"moose modules importing moose_ros (even a module that does not exist): {raw}"
