"""Latency and drops through the node graph (separate processes, Cyclone DDS, loopback).

Runs the full graph on a 30 s moose test at real-time pace and, from an independent
monitor process-side node, timestamps the arrival of each IMU sample, the state estimate
the observer derives from it (same stamp) and the actuator command of the same 10 ms tick.
Prints p50/p99 of IMU→estimate latency (transport both ways plus the observer's compute)
and IMU→actuator latency (until the first actuator command sent after that estimate
existed: it includes the 100 Hz controller's timer phase, up to 10 ms by design), and the
share of messages that never arrived against the designed rates.  Run: ``python bench/bench_graph.py``.
"""
from __future__ import annotations

import dataclasses
import io
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from moose.scenario import load_scenario
from moose_ros import convert as cv
from moose_ros.graph import ACTUATOR_COMMAND, IMU, STATE
from moose_ros.launch import launch
from moose_ros.runtime import QOS_SENSOR, DdsNode

SIM_SECONDS = 30.0

PINGER = """
import sys, time
from moose_ros.runtime import create_node, QOS_SENSOR
node = create_node("transport_pinger")
pub = node.publisher("sensor_msgs/msg/Imu", "/bench/ping", QOS_SENSOR)
time.sleep(1.0)
for k in range(int(sys.argv[1])):
    msg = node.make("sensor_msgs/msg/Imu")
    now = time.monotonic()  # CLOCK_MONOTONIC: one clock for every process of this machine
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    pub(msg)
    time.sleep(0.01)
time.sleep(0.3)
"""


def transport(count: int = 1000) -> np.ndarray:
    """One-way latency (s) of an IMU message between two processes, nothing computed on either side."""
    import subprocess
    import sys

    node = DdsNode("transport_bench")
    latencies: list[float] = []
    node.subscription("sensor_msgs/msg/Imu", "/bench/ping",
                      lambda m: latencies.append(time.monotonic() - cv.time_of(m)), QOS_SENSOR)
    proc = subprocess.Popen([sys.executable, "-c", PINGER, str(count)])
    try:
        while proc.poll() is None:
            node.spin_once(0.01)
        node.spin_once(0.2)
    finally:
        proc.kill()
        proc.wait()
        node.shutdown()
    return np.array(latencies)


def main() -> None:
    os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 200))
    if "CYCLONEDDS_URI" not in os.environ:
        config = Path(tempfile.mkdtemp()) / "cyclonedds.xml"
        config.write_text('<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
                          "</Interfaces><AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>")
        os.environ["CYCLONEDDS_URI"] = config.as_uri()
    os.environ.setdefault("MOOSE_RUNTIME", "dds")
    scenario = dataclasses.replace(load_scenario("paper_v5_tau3"), duration=SIM_SECONDS - 1.0)
    arrivals: dict[str, dict[int, float]] = {"imu": {}, "state": {}, "command": {}}

    def record(kind: str):
        def callback(msg) -> None:
            arrivals[kind].setdefault(round(cv.time_of(msg) * 100), time.monotonic())
        return callback

    monitor = DdsNode("latency_monitor")
    IMU.subscription(monitor, record("imu"))
    STATE.subscription(monitor, record("state"))
    ACTUATOR_COMMAND.subscription(monitor, record("command"))
    result: dict = {}
    runner = threading.Thread(target=lambda: result.update(
        launch(scenario, {"scenario": "paper_v5_tau3", "duration": SIM_SECONDS - 1.0}, out=io.StringIO())))
    runner.start()
    while runner.is_alive():
        monitor.spin_once(0.01)
    monitor.shutdown()
    expected = int(SIM_SECONDS * 100)
    print(f"graph run: {SIM_SECONDS:.0f} s simulated at real-time pace; outcome collided={result.get('collided')}")
    print(f"{'hop':>18} {'p50 ms':>8} {'p99 ms':>8} {'received':>10} {'dropped':>8}")
    commands = np.array(sorted(arrivals["command"].values()))
    estimate, actuator = [], []
    for k, t_imu in arrivals["imu"].items():
        t_state = arrivals["state"].get(k)
        if t_state is None:
            continue
        estimate.append(t_state - t_imu)
        i = np.searchsorted(commands, t_state)
        if i < len(commands):
            actuator.append(commands[i] - t_imu)  # first command sent after the estimate existed
    for name, lat, kind in (("IMU -> estimate", estimate, "state"), ("IMU -> actuator", actuator, "command")):
        lat_ms = np.array(lat) * 1e3
        print(f"{name:>18} {np.percentile(lat_ms, 50):8.2f} {np.percentile(lat_ms, 99):8.2f} "
              f"{len(arrivals[kind]):>10} {100 * max(0, expected - len(arrivals[kind])) / expected:7.1f}%")
    print(f"{'IMU samples':>18} {'':>8} {'':>8} {len(arrivals['imu']):>10} "
          f"{100 * max(0, expected - len(arrivals['imu'])) / expected:7.1f}%")
    lat = transport() * 1e3
    print(f"{'transport only':>18} {np.percentile(lat, 50):8.2f} {np.percentile(lat, 99):8.2f} {len(lat):>10} "
          f"{100 * max(0, 1000 - len(lat)) / 1000:7.1f}%   (one hop between two processes, 100 Hz, no compute)")


if __name__ == "__main__":
    main()
