"""A lockstep run computes the same whatever the wall clock does (issue 22: "this holds under background load,
because the result no longer depends on speed").  The extreme of a loaded machine is a process that gets no CPU at
all for a while: here ``moose launch --lockstep`` runs as a user runs it, and in the middle of the evasive maneuver
either every node of the graph or the launcher itself is stopped (SIGSTOP) for longer than any deadline of the graph
(:data:`PAUSE`), then continued.  The run must still be the loop's (tests/lockstep_reference.py), with every
odometry sample, no incident and the exit status of its outcome.

Found on a fresh clone's CI beside four other jobs (load average 50 on 2 cores): the launcher took the nodes of a
lockstep run for stalled (it judged their silence on /diagnostics on the wall clock), its monitor fell more than its
queue's depth behind the graph and lost odometry (a gap: an incomplete run), and nodes needing more than 5 s to end
after SIGTERM were killed (moose_ros.launch.STOP_GRACE).
"""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Literal

import pytest

from lockstep_reference import assert_reproduces, reference
from moose.scenario import load_scenario
from moose.verdict import OUTCOME_EXIT
from moose_ros import convert as cv
from moose_ros.graph import DIAGNOSTICS, ODOM
from moose_ros.lockstep import DEPTH
from moose_ros.process import descendants
from moose_ros.runtime import create_node

pytestmark = [pytest.mark.graph, pytest.mark.slow]

SCENARIO = "paper_v6_w2.0"
DURATION = 3.0
"""Simulated seconds after the obstacle appears (at t = 1 s): the pause comes at :data:`PAUSE_AT`, 1 s into the
maneuver, with 2 s (200 ticks, twice the monitor's queue depth) still to run."""
PAUSE_AT = 2.0
"""Simulated time (s) at which the processes are stopped, as a reader of /vehicle/odom in this test sees it."""
PAUSE = 5.0
"""Wall-clock seconds the processes stay stopped: more than the deadline of /diagnostics (3 s), long enough for a graph
left running to play the rest of the run (the launcher's pause) at 40 ticks per second (lockstep on Cyclone DDS goes
at about 95, bench/bench_graph.py --lockstep), and well within DDS's lease (10 s): a participant silent for longer
is gone for its peers, which no lockstep protocol can hide."""
LIMIT = 300.0
"""Wall-clock bound of one run (start-up on a loaded machine included)."""

assert DIAGNOSTICS.deadline is not None and PAUSE > DIAGNOSTICS.deadline
assert (1.0 + DURATION - PAUSE_AT) * 100 >= 2 * DEPTH


def run_paused(tmp_path: Path, who: Literal["graph", "launcher"]) -> tuple[dict[str, Any], str]:
    """``moose launch --lockstep`` of :data:`SCENARIO`, with ``who`` stopped for :data:`PAUSE` seconds once the run
    reached :data:`PAUSE_AT`; its summary and its output."""
    out, log = tmp_path / "summary.json", tmp_path / "launch.log"
    cmd = [sys.executable, "-m", "moose.cli", "launch", "--scenario", SCENARIO, "--duration", f"{DURATION:g}",
           "--lockstep", "--no-bag", "--json", str(out)]
    probe = create_node("pause_probe", runtime="dds")
    seen: list[float] = []
    ODOM.tool_subscription(probe, lambda msg: seen.append(cv.time_of(msg)))
    with log.open("w") as sink:
        proc = subprocess.Popen(cmd, stdout=sink, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + LIMIT
            while not (seen and seen[-1] >= PAUSE_AT):
                assert proc.poll() is None, f"the run ended before t = {PAUSE_AT} s:\n{log.read_text()[-3000:]}"
                assert time.monotonic() < deadline, f"t = {PAUSE_AT} s not reached in {LIMIT} s"
                probe.spin_once(0.02)
            nodes = descendants(proc.pid)
            assert len(nodes) >= 7, nodes  # the graph's node processes are up
            stopped = nodes if who == "graph" else [proc.pid]
            for pid in stopped:
                os.kill(pid, signal.SIGSTOP)
            try:
                time.sleep(PAUSE)
            finally:
                for pid in stopped:
                    os.kill(pid, signal.SIGCONT)
            proc.wait(timeout=LIMIT)
        finally:
            probe.shutdown()
            if proc.poll() is None:
                for pid in [proc.pid, *descendants(proc.pid)]:
                    os.kill(pid, signal.SIGCONT)
                proc.kill()
                proc.wait()
    text = log.read_text()
    assert out.is_file(), text[-3000:]
    return json.loads(out.read_text()), text


@pytest.mark.parametrize("who", ["graph", "launcher"])
def test_a_paused_lockstep_run_is_the_loops_run(tmp_path: Path, who: Literal["graph", "launcher"]) -> None:
    """``graph``: every node stopped (simulated time stands still): no node is taken for stalled.  ``launcher``: the
    monitor stopped while the graph could run on: the graph waits for it (moose_ros.lockstep.MONITOR_LAG) and
    nothing it judges is lost."""
    summary, log = run_paused(tmp_path, who)
    scenario = load_scenario(SCENARIO)
    expected = reference(dataclasses.replace(scenario, duration=DURATION))
    assert summary["incidents"] == [], summary["incidents"]
    assert summary["odom_samples"] == round((scenario.lead_time + DURATION) * 100) + 1, log[-3000:]
    assert summary["node_exits"] == {name: 0 for name in summary["node_exits"]}, summary["node_exits"]
    assert_reproduces(summary, expected)
    assert not summary["degraded"] and summary["exit_status"] == OUTCOME_EXIT[expected["outcome"]]
