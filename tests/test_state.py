"""The plant's state and input vectors are read by name (moose.state), never by a number."""
from __future__ import annotations

import ast
from pathlib import Path

from moose.simulation import TRACE_FIELDS
from moose.state import INPUT_NAMES, N_INPUT, N_STATE, STATE_NAMES

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = (ROOT / "src" / "moose", ROOT / "ros2_ws" / "src" / "moose_ros" / "moose_ros")
VECTORS = {"state", "true", "truth", "start", "x0", "u", "command", "x", "x_pred", "xdot", "s", "sdot", "states"}
"""The names the code gives a plant state or input, an observer state or a maneuver state."""


def test_no_state_or_input_vector_is_indexed_by_a_number() -> None:
    found = []
    for package in PACKAGES:
        for path in sorted(package.rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in VECTORS
                        and isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, int)):
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
    assert found == [], "index by the names of moose.state (or the module's own state names):\n" + "\n".join(found)


def test_the_names_are_the_trace_columns() -> None:
    assert len(STATE_NAMES) == N_STATE and len(INPUT_NAMES) == N_INPUT
    assert set(STATE_NAMES) | set(INPUT_NAMES) <= set(TRACE_FIELDS)
