"""The fault matrix: SIGKILL and a 0.6 s SIGSTOP of every node, in the topic graph and the CAN graph, in the middle
of an evasive maneuver (moose_ros.faults).  In every case the car stays inside the field and either comes to a
controlled stop (the minimum-risk maneuver) or completes the maneuver, and the run is reported as degraded with a
non-zero exit status; a killed simulator (the world itself) is an incomplete run.

Set ``MOOSE_FAULT_RATE`` to run the graph faster than real time where the machine holds that pace (the runs report
a rate that is not held).  docs/design.md carries the matrix this code generates
(``python -m moose_ros.faults --write docs/design.md``)."""
from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from isolation import claim_udp_port
from moose_ros.faults import (
    MATRIX_BEGIN,
    MATRIX_END,
    MATRIX_GRAPHS,
    WEAKEST_BEGIN,
    WEAKEST_CASES,
    WEAKEST_DURATION,
    WEAKEST_END,
    Fault,
    matrix_cases,
    run_case,
    weakest_parameters,
)

ROOT = Path(__file__).resolve().parents[1]
RATE = float(os.environ.get("MOOSE_FAULT_RATE", "1.0"))
CASES = [(graph, fault) for graph in MATRIX_GRAPHS for fault in matrix_cases(graph)]
STOPS = {"observer", "obstacle_detector", "weight_fbl", "motion_controller"}
"""Killing one of these leaves nothing that can drive: the minimum-risk maneuver stops the car."""


@pytest.fixture(scope="module")
def can_bus() -> dict[str, object]:
    pid = os.getpid()
    return {"can_interface": "udp_multicast", "can_channel": f"239.76.{pid % 250}.{1 + pid % 199}",
            "can_port": claim_udp_port()}


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.parametrize("graph, fault", CASES, ids=[f"{g}-{f.node}-{f.action}" for g, f in CASES])
def test_fault(graph: str, fault: Fault, can_bus: dict[str, object]) -> None:
    summary = run_case(graph, fault, rate=RATE, params=can_bus if graph == "can" else None)
    log = summary["log"][-4000:]
    kinds = {i["kind"] for i in summary["incidents"]}
    assert summary["faults"] == [str(fault)] and "fault_injected" in kinds
    assert summary["degraded"] and summary["exit_status"] != 0, log
    if fault.node == "vehicle_simulator" and fault.action == "kill":  # the world ended: nothing to judge after it
        assert summary["outcome"] == "incomplete" and summary["exit_status"] == 3
        assert {"died", "cut_short"} <= kinds
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
    if fault.action == "stall":
        assert summary["node_exits"][fault.node] == 0  # it resumed and ended normally


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.parametrize("graph, fault", WEAKEST_CASES, ids=[f"{g}-{f.node}-{f.action}" for g, f in WEAKEST_CASES])
def test_the_weakest_accepted_maneuver_still_stops_the_car(graph: str, fault: Fault,
                                                          can_bus: dict[str, object]) -> None:
    """The probe's hostile file (``stop_speed`` and ``straight_tolerance`` of 1000) is refused now; the most
    permissive one accepted must still stop the car inside the field when the stack is killed."""
    params = {**(can_bus if graph == "can" else {}), **weakest_parameters()}
    summary = run_case(graph, fault, rate=RATE, params=params, duration=WEAKEST_DURATION)
    log = summary["log"][-4000:]
    assert summary["outcome"] in ("clear", "stopped_short"), f"{summary['outcome']}: {summary['reason']}\n{log}"
    assert not summary["left_field"] and not summary["collided"] and not summary["lost_control"]
    assert "minimum_risk" in {i["kind"] for i in summary["incidents"]}
    assert summary["final_speed_mps"] < 0.1, summary["final_speed_mps"]


def test_docs_carry_the_generated_matrix() -> None:
    design = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    assert MATRIX_BEGIN in design and MATRIX_END in design
    table = design.split(MATRIX_BEGIN, 1)[1].split(MATRIX_END, 1)[0]
    rows = re.findall(r"^\| (full|can) \| (\w+) \| (kill|stall) \|", table, re.M)
    assert sorted(rows) == sorted((g, f.node, f.action) for g, f in CASES)
    assert WEAKEST_BEGIN in design and WEAKEST_END in design
    weakest = design.split(WEAKEST_BEGIN, 1)[1].split(WEAKEST_END, 1)[0]
    rows = re.findall(r"^\| (full|can) \| (\w+) \| (kill|stall) \|", weakest, re.M)
    assert sorted(rows) == sorted((g, f.node, f.action) for g, f in WEAKEST_CASES)
