"""The node graph reproduces the lockstep loop's planning steps.

The ``weight_fbl`` node combines the plans with the core's planning step, the code the lockstep loop
runs (``moose.planner.step.PlanningStep``), and the planner nodes keep its schedule (every t_s, restarted
at a new obstacle).  One run of the graph on a relaxed case is recorded; its bag is read back (an
independent reader of what the nodes published) and compared with the lockstep run of the same
scenario, aligned at the detection: the graph detects
   the obstacle a tick or two later (the obstacle message and the estimate travel between
   processes) and its commands act one observer hop late, so while the obstacle is ahead the blended
   accelerations agree within what that delay changes (``ACCEL_TOLERANCE``, ``ACCEL_RMS_TOLERANCE``).
   Beyond the obstacle the two closed loops have drifted apart by the accumulated latency; the
   outcome and the clearance are compared instead.
"""
from __future__ import annotations

import io
from pathlib import Path

import pytest

from isolation import realtime_slot
from moose.config import load_config
from moose.metrics import summarize
from moose.scenario import load_scenario
from moose.simulation import simulate
from moose_ros import convert as cv
from moose_ros.bag import read_bag
from moose_ros.interfaces import from_rosbags
from moose_ros.launch import launch

pytestmark = [pytest.mark.graph, pytest.mark.slow, pytest.mark.realtime]

SCENARIO = "paper_v6_w2.4"
ACCEL_TOLERANCE = 0.6
"""m/s², at any instant: the lateral jerk of the S-curve (up to ~20 m/s³) times two ticks of detection
latency is 0.4 m/s²; over the 2 s of the maneuver the extra loop delay (10–30 ms) also moves the state
the MSF's feedback sees (measured up to 0.41 m/s² in three runs on a loaded machine)."""
ACCEL_RMS_TOLERANCE = 0.25
"""m/s², over the instants with the obstacle ahead (measured 0.1–0.2)."""
RATE = 0.25
"""Simulated seconds per wall-clock second.  What is compared is what the graph computes, not how fast: at real
time on two cores shared with other jobs (the suite, other graphs), each tick of scheduling delay is a tick of
simulated latency, and once (load average above 5, with supervision in every node) the detection came late
enough to meet the MSF's counter-steer phase where the MPC's solution changes branch: RMS 0.28 m/s².  At half
speed the same load cost half the simulated latency; CI then measures every node under coverage.py's tracer,
which slows each node's Python about twofold, and the same branch change gave RMS 0.26 m/s² at half speed.  A
quarter of real time keeps a node's latency in simulated time where it was without the tracer (speed is the
benchmarks' business: bench/bench_graph.py)."""


@pytest.fixture(scope="module")
def graph_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    path = tmp_path_factory.mktemp("equivalence") / "bag"
    with realtime_slot():
        summary = launch(load_scenario(SCENARIO), {"scenario": SCENARIO}, out=io.StringIO(), bag=path, rate=RATE)
    return path, summary


def recorded(path: Path) -> list[tuple[str, object]]:
    topics = ["/perception/state", "/perception/threat", "/planning/mpc", "/planning/msf", "/planning/blend"]
    return [(m.topic, from_rosbags(m.msg, m.type_name)) for m in read_bag(path, topics)]


def test_the_blends_agree_with_the_lockstep_loop_while_the_obstacle_is_ahead(graph_bag: tuple[Path, dict]) -> None:
    path, summary = graph_bag
    scenario = load_scenario(SCENARIO)
    lockstep_run = simulate(load_config(), scenario, "combined")
    lockstep = [r for r in lockstep_run.planning if r.threat is not None]
    assert summary["outcome"] == "clear", summary["reason"]
    threatened, blends = set(), []
    for topic, msg in recorded(path):
        if topic == "/planning/msf" and msg.with_threat:
            threatened.add(round(cv.time_of(msg), 6))
        elif topic == "/planning/blend":
            blends.append(msg)
    # the planning instants with a threat (the MSF planned against it), and the newest blend of each: a plan
    # made on a planner's tick just before the threat arrived is superseded by the re-plan it triggers
    latest = {round(cv.time_of(b), 6): b for b in blends}
    graph = [latest[t] for t in sorted(threatened) if t in latest]
    assert len(lockstep) >= 15 and len(graph) >= 0.9 * len(lockstep)
    delay = cv.time_of(graph[0]) - lockstep[0].t
    assert 0.0 <= delay <= 0.03  # the detection arrives one to three ticks later, never earlier
    ahead = [(g, r) for g, r in zip(graph, lockstep) if r.threat.tau > 0.0]
    assert len(ahead) >= 10
    squares = [(g.accel_y[0] - r.blend.accel[0, 1]) ** 2 for g, r in ahead]
    assert (sum(squares) / len(squares)) ** 0.5 <= ACCEL_RMS_TOLERANCE
    for g, r in ahead:
        t = cv.time_of(g)
        assert t - r.t == pytest.approx(delay, abs=1e-6), t  # the same schedule, restarted at detection
        assert g.accel_y[0] == pytest.approx(r.blend.accel[0, 1], abs=ACCEL_TOLERANCE), t
        assert g.accel_x[0] == pytest.approx(r.blend.accel[0, 0], abs=ACCEL_TOLERANCE), t
    lockstep_summary = summarize(lockstep_run)
    assert summary["outcome"] == lockstep_summary["outcome"]
    assert summary["min_clearance_m"] == pytest.approx(lockstep_summary["min_clearance_m"], abs=0.3)
