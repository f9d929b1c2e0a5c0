"""Each node module's docstring opens with its Inputs / Outputs / Parameters, as :mod:`moose_ros.nodedocs` generates
them from the graph contract and the node's parameter dataclass (``python -m moose_ros.nodedocs --write``)."""
from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from moose.params import ParamError
from moose_ros import nodedocs
from moose_ros.graph import NODES


def test_every_node_modules_docstring_holds_its_current_interface() -> None:
    assert nodedocs.stale() == [], "stale node docstrings: run python -m moose_ros.nodedocs --write"


@pytest.mark.parametrize("node", list(NODES))
def test_the_block_opens_the_docstring_of_the_module_that_runs_the_node(node: str) -> None:
    """In the docstring (``__doc__``, what ``help()`` and the API docs show), after its first paragraph only; and it
    names the node's topics and parameters with their values from the contract."""
    module = importlib.import_module(f"moose_ros.nodes.{NODES[node].implementation.split(':')[0]}")
    doc = module.__doc__
    assert doc is not None
    summary, _, rest = doc.partition("\n\n")
    assert rest.startswith(nodedocs.BEGIN) and nodedocs.END in rest
    assert f"    {node} ({NODES[node].group}): " in rest


def test_the_interface_states_the_contract() -> None:
    """What a reader of the observer's and the simulator's docstrings learns, checked against values known here."""
    observer = nodedocs.interface("observer")
    inputs, outputs = observer.split("Inputs:")[1].split("Outputs:")
    assert "- /vehicle/imu (sensor_msgs/msg/Imu): 100 Hz, deadline 0.1 s; best effort, keep last 5" in inputs
    assert "- /vehicle/gps (nav_msgs/msg/Odometry): 1 Hz, deadline 3 s; reliable, keep last 10" in inputs
    assert "/perception/state" in outputs.split("Parameters")[0] and "/perception/state" not in inputs
    simulator = nodedocs.interface("vehicle_simulator")
    assert "- seed: int = 0 (a non-negative integer) — Seed of the sensor noise." in simulator
    assert "- startup_timeout: float = 60.0 (a positive time (s)) — Start without the missing ``wait_for`` nodes" \
        in simulator
    assert "- v_des:" in nodedocs.interface("msf_planner") and "- v_des:" not in simulator


def test_a_stale_block_is_rewritten_and_a_module_without_one_is_refused(tmp_path: Path) -> None:
    source = nodedocs.module_path("obstacle_detector")
    copy = tmp_path / "detector.py"
    shutil.copy(source, copy)
    copy.write_text(copy.read_text(encoding="utf-8").replace("100 Hz, deadline 0.1 s", "50 Hz, deadline 0.2 s"),
                    encoding="utf-8")
    assert nodedocs.write(copy, ["obstacle_detector"]) is True
    assert copy.read_text(encoding="utf-8") == source.read_text(encoding="utf-8")
    assert nodedocs.write(copy, ["obstacle_detector"]) is False
    bare = tmp_path / "bare.py"
    bare.write_text('"""A node module without the block."""\n', encoding="utf-8")
    with pytest.raises(ParamError, match="no generated interface block"):
        nodedocs.write(bare, ["obstacle_detector"])


def test_the_command_in_the_markers_and_in_the_docs_is_this_generator() -> None:
    command = "python -m moose_ros.nodedocs --write"
    assert f"``{command}``" in nodedocs.BEGIN
    assert f"`{command}`" in (Path(__file__).resolve().parents[1] / "docs" / "graph.md").read_text(encoding="utf-8")


def test_the_command_prints_every_block() -> None:
    done = subprocess.run([sys.executable, "-m", "moose_ros.nodedocs"], capture_output=True, text=True, timeout=120,
                          check=True)
    for path, nodes in nodedocs.node_modules().items():
        assert f"# {path.name}\n{nodedocs.module_block(nodes)}\n" in done.stdout
