"""What the launcher's tools (its monitor, the bag recorder) request of a lockstep graph's topics
(``moose_ros.lockstep.tool_qos``), checked on Cyclone DDS in this process."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from moose.config import load_config
from moose.scenario import load_scenario
from moose_ros import convert as cv
from moose_ros.bag import Recorder, read_bag
from moose_ros.graph import CLOCK, ODOM, TF, TOPICS
from moose_ros.interfaces import from_rosbags
from moose_ros.lockstep import DEPTH, MONITORED, QOS_DATA, tool_qos
from moose_ros.monitor import Monitor
from moose_ros.runtime import create_node


def test_the_launchers_tools_read_tick_0_of_a_lockstep_writer_they_match_late(tmp_path: Path) -> None:
    """ci45: the monitor of a lockstep graph (an rclpy simulator, the rest on Cyclone) counted 900 of its 901
    odometry samples.  A lockstep writer counts a reader as matched before that reader has matched the writer, and a
    volatile reader that matches late starts after what was already sent; in lockstep the monitor and the recorder
    read the monitored topics as a lockstep node does (reliable, transient local: :func:`tool_qos`), so a sample
    sent before they matched, here before they existed, still reaches them.  The clock and the TF, which lockstep
    writers publish with their own QoS, keep the tool's QoS (a transient-local request would not match them)."""
    for name in MONITORED:
        qos = tool_qos(TOPICS[name], lockstep=True)
        assert qos.reliable and qos.transient_local and qos.depth >= DEPTH, name
        assert tool_qos(TOPICS[name], lockstep=False) == TOPICS[name].tool_qos
    assert tool_qos(CLOCK, lockstep=True) == CLOCK.tool_qos and tool_qos(TF, lockstep=True) == TF.tool_qos
    graph = create_node("late_tools_graph", runtime="dds")
    tools = None
    try:
        odom = graph.publisher(ODOM.type, ODOM.name, QOS_DATA)  # what a lockstep simulator offers
        odom(cv.odometry_to_msg(graph, 0.0, np.array([0.0, 0.0, 0.0, 7.0, 0.0, 0.0])))  # tick 0, before any reader
        tools = create_node("late_tools", runtime="dds")
        scenario = load_scenario("paper_v5_tau3")
        monitor = Monitor(scenario, scenario.configure(load_config()))
        monitor.attach(tools, lockstep=True)
        recorder = Recorder(tools, tmp_path / "bag", lockstep=True)
        deadline = time.monotonic() + 20.0
        while not monitor.odom and time.monotonic() < deadline:
            tools.spin_once(0.05)
        for _ in range(10):  # the recorder's reader: the same sample, taken in the same spin or the next ones
            tools.spin_once(0.05)
        recorder.close()
    finally:
        graph.shutdown()
        if tools is not None:
            tools.shutdown()
    assert [row[0] for row in monitor.odom] == [0.0]
    assert [cv.time_of(from_rosbags(m.msg, m.type_name)) for m in read_bag(tmp_path / "bag", [ODOM.name])] == [0.0]
