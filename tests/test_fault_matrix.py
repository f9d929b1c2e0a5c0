"""The fault matrix: SIGKILL and a 0.6 s SIGSTOP of every node, in the topic graph and the CAN graph, in the middle
of an evasive maneuver (moose_ros.fault_matrix).  In every case the car stays inside the field and either comes to a
controlled stop (the minimum-risk maneuver) or completes the maneuver, the fault's consequence is reported by the
node that must detect it (``moose_ros.fault_matrix.DETECTORS``: not the injected fault itself, which is always an
incident), and the run is reported as degraded with a non-zero exit status; a killed simulator (the world itself)
is an incomplete run.

Every case runs in lockstep: a fault is exact in simulated time (``moose_ros.lockstep.left_out``: a killed node runs
no tick from the fault's on, a stalled one none until its stall ends, and then gets what its queues kept), so what
happens does not depend on the machine's load.  A stalled node reports its own stall when it runs again; a stalled
simulator stops simulated time with it, so its run is the fault-free run, the loop's.
docs/graph.md carries the matrix this code generates (``python -m moose_ros.fault_matrix --write docs/graph.md``)."""
from __future__ import annotations

import dataclasses
import functools
import os
import re
from pathlib import Path

import pytest

from isolation import claim_udp_port
from lockstep_reference import assert_reproduces, reference
from moose.scenario import load_scenario
from moose_ros.fault_matrix import (
    MATRIX_BEGIN,
    MATRIX_DURATION,
    MATRIX_END,
    MATRIX_GRAPHS,
    MATRIX_SCENARIO,
    WEAKEST_BEGIN,
    WEAKEST_CASES,
    WEAKEST_DURATION,
    WEAKEST_END,
    matrix_cases,
    reported,
    row,
    run_case,
    weakest_parameters,
    write_matrix,
)
from moose_ros.faults import Fault

ROOT = Path(__file__).resolve().parents[1]
CASES = [(graph, fault) for graph in MATRIX_GRAPHS for fault in matrix_cases(graph)]
STOPS = {"observer", "obstacle_detector", "weight_fbl", "motion_controller"}
"""Killing one of these leaves nothing that can drive: the minimum-risk maneuver stops the car."""


@functools.cache
def documented(weakest: bool = False) -> dict[tuple[str, str, str], list[str]]:
    """The cells of each row of the matrix docs/graph.md carries (``weakest``: of the weakest minimum_risk's)."""
    begin, end = (WEAKEST_BEGIN, WEAKEST_END) if weakest else (MATRIX_BEGIN, MATRIX_END)
    table = (ROOT / "docs" / "graph.md").read_text(encoding="utf-8").split(begin, 1)[1].split(end, 1)[0]
    rows = [[cell.strip() for cell in line.strip("|").split(" | ")] for line in table.splitlines()
            if re.match(r"\| (full|can) \|", line)]
    return {(cells[0], cells[1], cells[2]): cells for cells in rows}


def assert_documented(graph: str, fault: Fault, summary: dict[str, object], weakest: bool = False) -> None:
    """The run is its row of the documented matrix (``python -m moose_ros.fault_matrix --write docs/graph.md``):
    in lockstep every number is the same on any machine; of the incidents, a node killed after the run for not
    ending within the launcher's grace (``stop_timeout``) is the machine's speed, not the run's."""
    cells = [c.strip() for c in row(graph, fault, summary).strip("|").split(" | ")]
    doc = documented(weakest)[(graph, fault.node, fault.action)]
    assert cells[:-1] == doc[:-1], f"docs/graph.md is stale or the run differs:\n{cells}\n{doc}"
    incidents = [set(c.split(", ")) - {"stop_timeout"} for c in (cells[-1], doc[-1])]
    odd = [i for i in summary["incidents"] if i["kind"] in incidents[0] ^ incidents[1]]  # type: ignore[attr-defined]
    assert incidents[0] == incidents[1], (incidents, odd)  # which node reported the odd one, when and why


@pytest.fixture(scope="module")
def can_bus() -> dict[str, object]:
    pid = os.getpid()
    return {"can_interface": "udp_multicast", "can_channel": f"239.76.{pid % 250}.{1 + pid % 199}",
            "can_port": claim_udp_port()}


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.parametrize("graph, fault", CASES, ids=[f"{g}-{f.node}-{f.action}" for g, f in CASES])
def test_fault(graph: str, fault: Fault, can_bus: dict[str, object]) -> None:
    summary = run_case(graph, fault, params=can_bus if graph == "can" else None, lockstep=True)
    log = summary["log"][-4000:]
    kinds = {i["kind"] for i in summary["incidents"]}
    assert summary["faults"] == [str(fault)] and "fault_injected" in kinds, (summary["incidents"], log)
    assert summary["degraded"] and summary["exit_status"] != 0, log
    assert reported(fault, summary), (fault, summary["incidents"])  # by the node that must detect it
    # no other node died during the run (how fast each one ends after SIGTERM is the machine's speed:
    # tests/test_dds_linger.py)
    assert not [n for n, s in summary["node_status"].items() if n != fault.node and s.startswith("died")], summary
    assert_documented(graph, fault, summary)
    if fault.node == "vehicle_simulator" and fault.action == "kill":  # the world ended: nothing to judge after it
        # review: a simulator killed at 2.6 s gave a 2.6 s run reported as collision-free, exit status 0; in
        # lockstep the world ends exactly at the fault's tick
        assert summary["outcome"] == "incomplete" and summary["exit_status"] == 3, summary["reason"]
        assert summary["node_exits"]["vehicle_simulator"] == -9
        assert {("vehicle_simulator", "died"), ("launch", "cut_short")} <= {(i["node"], i["kind"])
                                                                           for i in summary["incidents"]}
        assert summary["duration_s"] == pytest.approx(fault.at, abs=1e-9)
        return
    assert summary["outcome"] in ("clear", "stopped_short"), f"{summary['outcome']}: {summary['reason']}\n{log}"
    assert not summary["left_field"] and not summary["collided"] and not summary["lost_control"]
    if fault.action == "kill":
        assert "died" in kinds and summary["node_status"][fault.node].startswith("died")
    if fault.action == "kill" and fault.node in STOPS:
        assert "minimum_risk" in kinds
        assert summary["final_speed_mps"] < 0.1, summary["final_speed_mps"]  # a controlled stop
    if fault.action == "kill" and fault.node == "can_bridge":
        # nothing of the stack reaches the car: the vehicle ECUs' own minimum-risk maneuver stops it
        assert "ecu_timeout" in kinds
        assert summary["final_speed_mps"] < 0.1, summary["final_speed_mps"]
    if fault.action == "kill" and fault.node in ("mpc_planner", "msf_planner"):
        assert "planner_fallback" in kinds and summary["outcome"] == "clear"  # the other planner completes it
        # the graph went on without it: every tick of the run, and the weight function says what it blends now
        ticks = round((load_scenario(MATRIX_SCENARIO).lead_time + MATRIX_DURATION) * 100) + 1  # the odometry's 100 Hz
        assert summary["complete"] and summary["odom_samples"] == ticks, summary["odom_samples"]
        assert f"node {fault.node} exited with status -9" in summary["log"]
        assert summary["diagnostics"]["weight_fbl"]["level"] == 1
        other = "MSF" if fault.node == "mpc_planner" else "MPC"
        assert f"{fault.node} silent: {other} only" in summary["diagnostics"]["weight_fbl"]["message"], summary
    if fault.action == "stall":
        assert summary["node_exits"][fault.node] == 0  # it resumed and ended normally
    if fault.action == "stall" and fault.node == "vehicle_simulator":  # simulated time stood still with it
        scenario = dataclasses.replace(load_scenario(MATRIX_SCENARIO), duration=MATRIX_DURATION)
        assert_reproduces(summary, reference(scenario))
    elif fault.action == "stall":  # it noticed its own stall of the fault's length when it ran again
        own = [i for i in summary["incidents"] if i["node"] == fault.node and i["kind"] == "stalled"]
        assert own and summary["stalls"][fault.node] == 1, summary["incidents"]
        assert own[0]["t"] == pytest.approx(fault.at + fault.duration), own
        assert f"{1e3 * (fault.duration + 0.01):.0f} ms" in own[0]["message"], own  # the last tick before it, too


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.parametrize("graph, fault", WEAKEST_CASES, ids=[f"{g}-{f.node}-{f.action}" for g, f in WEAKEST_CASES])
def test_the_weakest_accepted_maneuver_still_stops_the_car(graph: str, fault: Fault,
                                                          can_bus: dict[str, object]) -> None:
    """The probe's hostile file (``stop_speed`` and ``straight_tolerance`` of 1000) is refused now; the most
    permissive one accepted must still stop the car inside the field when the stack is killed."""
    params = {**(can_bus if graph == "can" else {}), **weakest_parameters()}
    summary = run_case(graph, fault, params=params, duration=WEAKEST_DURATION, lockstep=True)
    log = summary["log"][-4000:]
    assert summary["outcome"] in ("clear", "stopped_short"), f"{summary['outcome']}: {summary['reason']}\n{log}"
    assert not summary["left_field"] and not summary["collided"] and not summary["lost_control"]
    assert "minimum_risk" in {i["kind"] for i in summary["incidents"]}
    assert summary["final_speed_mps"] < 0.1, summary["final_speed_mps"]
    assert_documented(graph, fault, summary, weakest=True)


def test_docs_carry_the_generated_matrix() -> None:
    design = (ROOT / "docs" / "graph.md").read_text(encoding="utf-8")
    assert MATRIX_BEGIN in design and MATRIX_END in design
    table = design.split(MATRIX_BEGIN, 1)[1].split(MATRIX_END, 1)[0]
    rows = re.findall(r"^\| (full|can) \| (\w+) \| (kill|stall) \|", table, re.M)
    assert sorted(rows) == sorted((g, f.node, f.action) for g, f in CASES)
    assert WEAKEST_BEGIN in design and WEAKEST_END in design
    weakest = design.split(WEAKEST_BEGIN, 1)[1].split(WEAKEST_END, 1)[0]
    rows = re.findall(r"^\| (full|can) \| (\w+) \| (kill|stall) \|", weakest, re.M)
    assert sorted(rows) == sorted((g, f.node, f.action) for g, f in WEAKEST_CASES)


def test_the_reported_check_can_fail() -> None:
    """The check is on the consequence, not on the injected fault: a run whose only incidents are the fault and the
    faulted node's death reports nothing."""
    fault = Fault("observer", "kill", 2.5)
    quiet = {"incidents": [{"node": "observer", "kind": "fault_injected"}, {"node": "observer", "kind": "died"}]}
    assert not reported(fault, quiet)
    assert not reported(fault, {"incidents": [{"node": "weight_fbl", "kind": "minimum_risk"}]})  # not its detector
    assert reported(fault, {"incidents": [*quiet["incidents"], {"node": "motion_controller", "kind": "minimum_risk"}]})


@pytest.mark.parametrize("weakest", [False, True], ids=["matrix", "weakest"])
def test_the_generator_finds_its_markers_on_its_page_and_writes_it_back(tmp_path: Path, weakest: bool) -> None:
    """``python -m moose_ros.fault_matrix [--weakest] --write PAGE`` on the page its marker names: given the table
    the page holds, the generator writes the page back byte for byte (the marker lookup and the note around the
    table)."""
    begin, end = (WEAKEST_BEGIN, WEAKEST_END) if weakest else (MATRIX_BEGIN, MATRIX_END)
    match = re.search(r"--write (\S+)`", begin)
    assert match
    page = ROOT / match.group(1)
    text = page.read_text(encoding="utf-8")
    body = text.split(begin, 1)[1].split(end, 1)[0]
    assert "in lockstep" in body  # as the tests run the cases
    copy = tmp_path / page.name
    copy.write_text(text, encoding="utf-8")
    write_matrix(str(copy), "\n".join(line for line in body.splitlines() if line.startswith("|")), weakest)
    assert copy.read_text(encoding="utf-8") == text
