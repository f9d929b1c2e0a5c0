"""Dependencies the right way up: the core never imports moose_ros and has no import cycle; moose_ros adds its
commands and the bag recorder of ``moose simulate`` as plugins (entry points)."""
from __future__ import annotations

import ast
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

from moose.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]


def test_the_core_never_imports_moose_ros() -> None:
    offenders = []
    for path in sorted((ROOT / "src" / "moose").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                    "import_module", "__import__"):
                names = [a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)]
            offenders += [f"{path.relative_to(ROOT)}:{node.lineno}: {n}"
                          for n in names if n.split(".")[0] == "moose_ros"]
    assert offenders == []


def core_modules() -> dict[str, Path]:
    """Dotted name → file of every module and package of src/moose."""
    found = {}
    for path in sorted((ROOT / "src" / "moose").rglob("*.py")):
        parts = path.relative_to(ROOT / "src").with_suffix("").parts
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _type_checking(node: ast.If) -> bool:
    """``if TYPE_CHECKING:`` or ``if typing.TYPE_CHECKING:``."""
    test = node.test
    return isinstance(test, ast.Name) and test.id == "TYPE_CHECKING" or \
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"


def imported(name: str, path: Path, known: set[str]) -> set[str]:
    """The core modules that module ``name`` imports, at import time or inside a function (a lazy import is an
    import too); what a ``TYPE_CHECKING`` block imports is not.  ``from X import y`` imports the module X.y when
    that exists, else X."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[:len(package.split(".")) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            targets.update(f"{module}.{a.name}" if f"{module}.{a.name}" in known else module for a in node.names)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text(encoding="utf-8")))
    return {t for t in targets if t in known and t != name}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return found


def test_cycles_finds_a_loop_and_only_a_loop() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set(), "c": {"b"}}) == []


def test_imports_resolve_relative_lazy_and_type_checking_imports(tmp_path: Path) -> None:
    pkg = tmp_path / "moose" / "planner"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "step.py").write_text("from typing import TYPE_CHECKING\nfrom .. import signals\nfrom .fbl import F\n"
                                 "if TYPE_CHECKING:\n    from .msf import M\nelse:\n    import moose.schema\n"
                                 "def f():\n    from ..maneuver import T\n")
    known = {"moose", "moose.planner", "moose.planner.step", "moose.planner.fbl", "moose.planner.msf",
             "moose.signals", "moose.schema", "moose.maneuver"}
    assert imported("moose.planner.step", pkg / "step.py", known) == {
        "moose.signals", "moose.planner.fbl", "moose.schema", "moose.maneuver"}


def test_the_core_has_no_import_cycle() -> None:
    modules = core_modules()
    graph = {name: imported(name, path, set(modules)) for name, path in modules.items()}
    assert cycles(graph) == []


def test_moose_ros_registers_its_commands_and_the_recorder() -> None:
    commands = {ep.name: ep.value for ep in entry_points(group="moose.commands")}
    assert commands == {"node": "moose_ros.cli.node:add_subparser", "launch": "moose_ros.cli.launch:add_subparser",
                        "bag": "moose_ros.cli.bag:add_subparser"}
    assert [ep.value for ep in entry_points(group="moose.recorders")] == ["moose_ros.bag.record:record_simulation"]
    choices = build_parser()._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert set(choices) == {"simulate", "reproduce", "sweep", "budget", "benchmark", "can", "node", "launch", "bag"}


def test_simulate_records_a_bag_by_default_through_the_plugin(tmp_path: Path, monkeypatch, capsys) -> None:
    from moose_ros.bag import bag_info

    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--scenario", "paper_v5_tau3", "--duration", "0.5"]) == 1  # stopped_short: too short
    (bag,) = (tmp_path / "runs").glob("*/bag")
    assert f"bag             {bag.relative_to(tmp_path)}" in capsys.readouterr().out
    info = bag_info(bag)
    assert info["topics"]["/perception/state"]["count"] > 100 and "/planning/blend" in info["topics"]
    assert main(["simulate", "--scenario", "paper_v5_tau3", "--duration", "0.5", "--bag", str(bag)]) == 2
    assert "exists already" in capsys.readouterr().err


def test_a_broken_plugin_leaves_the_other_commands_working(tmp_path: Path) -> None:
    """A plugin that raises at load time is reported; the built-in commands still run."""
    dist = tmp_path / "broken_plugin-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-plugin\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[moose.commands]\nbroken = broken_plugin_module:add_subparser\n")
    result = subprocess.run([sys.executable, "-m", "moose.cli", "--help"], capture_output=True, text=True, timeout=60,
                            env={**__import__("os").environ, "PYTHONPATH": str(tmp_path)})
    assert result.returncode == 0 and "simulate" in result.stdout and "launch" in result.stdout
    assert "command 'broken' of broken_plugin_module:add_subparser cannot be loaded" in result.stderr
