"""Reading a node process's output in tests: up to the line with which a node announces it has started."""
from __future__ import annotations

import subprocess
import time


def read_until_started(proc: subprocess.Popen, name: str, limit: float = 60.0) -> list[str]:
    """The lines ``proc`` (text output, stderr merged) wrote up to and including ``NAME started``; an AssertionError
    with that output if the process ended, or ``limit`` seconds passed between lines, before it."""
    assert proc.stdout is not None
    deadline = time.monotonic() + limit
    lines: list[str] = []
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        lines.append(line)
        if f"{name} started" in line or not line:
            break
    assert any(f"{name} started" in line for line in lines), "".join(lines)
    return lines
