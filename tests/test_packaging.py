"""Dependencies the right way up: the core never imports moose_ros; moose_ros adds its commands and the bag
recorder of ``moose simulate`` as plugins (entry points)."""
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


def test_moose_ros_registers_its_commands_and_the_recorder() -> None:
    commands = {ep.name: ep.value for ep in entry_points(group="moose.commands")}
    assert commands == {"node": "moose_ros.cli.node:add_subparser", "launch": "moose_ros.cli.launch:add_subparser",
                        "bag": "moose_ros.cli.bag:add_subparser"}
    assert [ep.value for ep in entry_points(group="moose.recorders")] == ["moose_ros.bag.record:record_simulation"]
    choices = build_parser()._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert set(choices) == {"simulate", "reproduce", "sweep", "can", "node", "launch", "bag"}


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
