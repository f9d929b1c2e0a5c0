"""Supervision of the graph without processes: deadlines from the contract, input freshness, who the motion
controller depends on, fault specs, incidents from /diagnostics and the launcher's exit statuses."""
from __future__ import annotations

import pytest

from moose.canbus.ecu import ECU_TIMEOUT
from moose.params import ParamError
from moose.verdict import EXIT_DEGRADED, EXIT_FAILED, EXIT_INCOMPLETE, EXIT_INTERRUPTED, exit_status
from moose_ros.fault_matrix import matrix_cases
from moose_ros.faults import Fault
from moose_ros.graph import (
    ACTUATOR_COMMAND,
    COMMAND_TIMEOUT,
    GRAPHS,
    NODES,
    PLAN_MPC,
    STATE,
    TOPICS,
    essential_upstream,
)
from moose_ros.incidents import DEGRADING, KINDS, IncidentLog
from moose_ros.nodes.base import InputWatch


def test_deadlines_come_from_the_designed_rates() -> None:
    for topic in TOPICS.values():
        if topic.rate_hz is None:
            assert topic.deadline is None, topic.name
        else:
            assert topic.deadline == pytest.approx(topic.tolerance / topic.rate_hz), topic.name
    # the command deadline is the vehicle ECU's timeout (the core's constant), the one of the guard and the simulator
    assert COMMAND_TIMEOUT == ACTUATOR_COMMAND.deadline == ECU_TIMEOUT == 0.05
    assert STATE.deadline == 0.1 and PLAN_MPC.deadline == 0.4


def test_an_input_is_stale_past_its_deadline_or_never_received_after_the_grace() -> None:
    watch = InputWatch([STATE, PLAN_MPC], grace=1.0)
    assert watch.stale(0.0) == {}  # supervision starts: nothing expected yet
    watch.seen(STATE.name, 0.05)
    assert watch.stale(0.15) == {}  # 0.10 s: exactly the deadline
    assert watch.stale(0.16) == {STATE.name: pytest.approx(0.11)}
    assert watch.stale(1.01) == {STATE.name: pytest.approx(0.96), PLAN_MPC.name: None}  # never received, grace over
    watch.seen(PLAN_MPC.name, 1.02)
    assert PLAN_MPC.name not in watch.stale(1.40) and PLAN_MPC.name in watch.stale(1.43)


def test_the_motion_controller_depends_on_perception_and_weight_fbl_not_on_a_planner() -> None:
    assert essential_upstream("motion_controller") == ("vehicle_simulator", "observer", "obstacle_detector",
                                                       "weight_fbl", "can_bridge")
    assert all(NODES[n].redundant for n in ("mpc_planner", "msf_planner"))


def test_fault_specs() -> None:
    assert Fault.parse("observer:kill@2.5") == Fault("observer", "kill", 2.5)
    assert Fault.parse("motion_controller:stall@2.5:0.6") == Fault("motion_controller", "stall", 2.5, 0.6)
    assert str(Fault("motion_controller", "stall", 2.5, 0.6)) == "motion_controller:stall@2.5:0.6"
    for bad in ("observer", "observer:kill", "observer:kill@x", "observer:stall@2", "observer:kill@2:1",
                "observer:stall@2:0", "observer:pause@2", "Observer:kill@2"):
        with pytest.raises(ParamError, match=f"--fault '{bad}' is invalid"):
            Fault.parse(bad)
    # the matrix: kill and stall of every node of both simulated graphs
    for graph in ("full", "can"):
        cases = matrix_cases(graph)
        assert {(f.node, f.action) for f in cases} == {(n, a) for n in GRAPHS[graph] for a in ("kill", "stall")}


def test_incidents_come_from_new_problems_and_counters() -> None:
    log = IncidentLog()
    ok = {"problems": "", "deadline_misses": "0", "stalls": "0", "longest_gap_ms": "10"}
    log.on_status(1.0, "motion_controller", 0, "running", ok)
    assert log.incidents == [] and not log.degraded
    stale = {**ok, "problems": "minimum_risk,stale:/perception/state",
             "minimum_risk": "running the minimum-risk maneuver: /perception/state stale",
             "stale:/perception/state": "/perception/state stale (0.11 s > 0.1 s)"}
    log.on_status(2.6, "motion_controller", 2, "whatever the text", stale)
    log.on_status(3.6, "motion_controller", 2, "whatever the text, later", stale)  # the same problems: no new incident
    assert [(i.t, i.kind, i.message) for i in log.incidents] == [
        (2.6, "minimum_risk", "running the minimum-risk maneuver: /perception/state stale"),
        (2.6, "input_stale", "/perception/state stale (0.11 s > 0.1 s)")]
    log.on_status(4.0, "observer", 0, "running", {**ok, "stalls": "1", "longest_gap_ms": "610", "deadline_misses": "3"})
    assert log.incidents[-1].kind == "stalled" and "610 ms" in log.incidents[-1].message
    log.on_status(4.1, "can_bridge", 1, "receive flood: 3 cycles hit the 100-frame bound", ok)  # no problem keys
    assert log.incidents[-1].kind == "warning"
    assert log.counters["observer"]["deadline_misses"] == 3 and log.degraded
    assert DEGRADING <= set(KINDS)


def test_exit_statuses() -> None:
    assert exit_status("clear", False, None) == 0
    assert exit_status("clear", True, None) == EXIT_DEGRADED == 4  # the car came through, the system did not
    assert exit_status("stopped_short", True, None) == exit_status("collision", False, None) == EXIT_FAILED
    assert exit_status("incomplete", True, "SIGTERM") == EXIT_INCOMPLETE == 3
    assert exit_status("collision", True, "SIGINT") == EXIT_INTERRUPTED == 130
