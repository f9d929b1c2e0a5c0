"""Latency and drops through the node graph (separate processes, loopback), on both runtimes in one run.

For each runtime — our Cyclone DDS runtime, and rclpy on Fast DDS from the ROS 2 prefix of ``make ros``
(skipped, saying why, without it) — a process of that runtime runs the full graph on a 30 s moose
test at real-time pace (``moose_ros.launch.launch``, every node and the launcher's monitor on that
runtime) and, from a latency monitor node of the same runtime, timestamps the arrival of each IMU
sample, the state estimate the observer derives from it (same stamp) and the actuator command of the
same 10 ms tick.  Printed: p50/p99 of IMU→estimate latency (transport both ways plus the observer's
compute) and IMU→actuator latency (until the first actuator command sent after that estimate
existed: it includes the 100 Hz controller's timer phase, up to 10 ms by design), the share of
messages that never arrived against the designed rates, and the one-way latency of one hop between
two otherwise idle processes (no compute).  Both vendors discover on loopback only, in a DDS domain
claimed with ``tests/isolation.py``.  Run: ``python bench/bench_graph.py``.

``--lockstep``: the lockstep graph's throughput instead (``moose launch --lockstep``, :mod:`moose_ros.lockstep`):
per runtime, simulated seconds per wall-clock second of the extreme case (:data:`LOCKSTEP_SCENARIO`) between the
first and the last odometry sample, against a baseline measured in the same process just before and after: the
closed loop (``moose simulate``) on the same case, whose result the lockstep graph reproduces (the better of three
runs before and three after the graph's, each printed: on a shared machine they can differ several times over).  The
ratio is what the graph's processes and their messages cost per simulated second against one process computing the
same.
"""
from __future__ import annotations

import argparse
import dataclasses
import io
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SIM_SECONDS = 30.0
LOCKSTEP_SCENARIO = "paper_v7_tau1.4"
"""The extreme case (7 m/s, τ = 1.4 s): the lockstep graph's reference case."""
PINGS = 1000
CYCLONE_LOOPBACK = ('<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
                    "</Interfaces><AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>")

PINGER = """
import sys, time
from moose_ros.runtime import create_node, QOS_SENSOR
node = create_node("transport_pinger")
pub = node.publisher("sensor_msgs/msg/Imu", "/bench/ping", QOS_SENSOR)
deadline = time.monotonic() + 30
while pub.subscription_count() == 0 and time.monotonic() < deadline:
    node.spin_once(0.05)
for k in range(int(sys.argv[1])):
    msg = node.make("sensor_msgs/msg/Imu")
    now = time.monotonic()  # CLOCK_MONOTONIC: one clock for every process of this machine
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
    pub(msg)
    node.spin_once(0.01)
node.shutdown()
"""


def transport(count: int) -> list[float]:
    """One-way latency (s) of an IMU message between two processes, nothing computed on either side."""
    from moose_ros import convert as cv
    from moose_ros.runtime import QOS_SENSOR, create_node

    node = create_node("transport_bench")
    latencies: list[float] = []
    node.subscription("sensor_msgs/msg/Imu", "/bench/ping",
                      lambda m: latencies.append(time.monotonic() - cv.time_of(m)), QOS_SENSOR)
    proc = subprocess.Popen([sys.executable, "-c", PINGER, str(count)])
    try:
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:
            node.spin_once(0.01)
        node.spin_once(0.2)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        node.shutdown()
    return latencies


def measure() -> dict[str, Any]:
    """The graph and transport figures on this process's runtime (MOOSE_RUNTIME)."""
    from moose.scenario import load_scenario
    from moose_ros import convert as cv
    from moose_ros.graph import ACTUATOR_COMMAND, IMU, STATE
    from moose_ros.launch import launch
    from moose_ros.runtime import create_node

    scenario = dataclasses.replace(load_scenario("paper_v5_tau3"), duration=SIM_SECONDS - 1.0)
    arrivals: dict[str, dict[int, float]] = {"imu": {}, "state": {}, "command": {}}

    def record(kind: str):
        def callback(msg) -> None:
            arrivals[kind].setdefault(round(cv.time_of(msg) * 100), time.monotonic())
        return callback

    monitor = create_node("latency_monitor")
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
    return {"runtime": result.get("runtime"), "collided": result.get("collided"), "estimate": estimate,
            "actuator": actuator, "received": {k: len(v) for k, v in arrivals.items()},
            "transport": transport(PINGS)}


def measure_lockstep() -> dict[str, Any]:
    """The lockstep graph's pace on this process's runtime and the closed loop's on the same case, in this process
    (the loop's best of the runs before and after the graph's)."""
    from moose.config import load_config
    from moose.scenario import load_scenario
    from moose.simulation import simulate
    from moose_ros.launch import launch

    scenario = load_scenario(LOCKSTEP_SCENARIO)
    simulated = scenario.lead_time + scenario.duration

    def loop() -> float:
        start = time.perf_counter()
        simulate(load_config(), scenario, "combined")
        return simulated / (time.perf_counter() - start)

    before = max(loop() for _ in range(3))
    summary = launch(scenario, {"scenario": LOCKSTEP_SCENARIO}, lockstep=True, out=io.StringIO())
    after = max(loop() for _ in range(3))
    return {"runtime": summary.get("runtime"), "outcome": summary["outcome"],
            "clearance": summary["min_clearance_m"], "graph": summary["real_time_factor"]["achieved"],
            "loop": max(before, after), "loop_spread": [before, after], "simulated": simulated}


def report_lockstep(name: str, figures: dict[str, Any]) -> float:
    """Print one runtime's lockstep pace against the loop's; returns the ratio."""
    ratio = figures["graph"] / figures["loop"]
    print(f"\n{name}: lockstep graph of {LOCKSTEP_SCENARIO} ({figures['simulated']:g} simulated s): "
          f"{figures['outcome']}, clearance {figures['clearance']:.4f} m")
    print(f"  graph {figures['graph']:.3f} simulated s per wall s; closed loop in the same process "
          f"{figures['loop']:.1f} (before {figures['loop_spread'][0]:.1f}, after {figures['loop_spread'][1]:.1f}); "
          f"graph / loop = {ratio:.4f} (1 / {1 / ratio:.0f})")
    return ratio


def report(name: str, figures: dict[str, Any]) -> dict[str, float]:
    """Print one runtime's table; returns its p50/p99 (ms)."""
    expected = int(SIM_SECONDS * 100)
    runtimes = sorted(set(figures["runtime"].values())) if figures["runtime"] else ["?"]
    print(f"\n{name}: graph of {SIM_SECONDS:.0f} s at real-time pace (nodes and monitor on {', '.join(runtimes)}); "
          f"collided={figures['collided']}")
    print(f"{'hop':>18} {'p50 ms':>8} {'p99 ms':>8} {'received':>10} {'dropped':>8}")
    out = {}
    rows = (("IMU -> estimate", figures["estimate"], figures["received"]["state"], expected),
            ("IMU -> actuator", figures["actuator"], figures["received"]["command"], expected),
            ("IMU samples", None, figures["received"]["imu"], expected),
            ("transport only", figures["transport"], len(figures["transport"]), PINGS))
    for hop, latencies, received, wanted in rows:
        dropped = f"{100 * max(0, wanted - received) / wanted:7.1f}%"
        if latencies is None:
            print(f"{hop:>18} {'':>8} {'':>8} {received:>10} {dropped}")
            continue
        lat = np.array(latencies) * 1e3
        p50, p99 = np.percentile(lat, 50), np.percentile(lat, 99)
        out[hop] = (p50, p99)
        print(f"{hop:>18} {p50:8.2f} {p99:8.2f} {received:>10} {dropped}")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--measure", action="store_true", help="(internal) measure on this process's runtime")
    parser.add_argument("--lockstep", action="store_true",
                        help="the lockstep graph's throughput against the closed loop's, per runtime")
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure_lockstep() if args.lockstep else measure()))
        return
    sys.path.insert(0, str(REPO / "tests"))
    from isolation import claim_domain
    from moose.params import ParamError
    from moose_ros.runtime import process

    config = Path(tempfile.mkdtemp()) / "cyclonedds.xml"
    config.write_text(CYCLONE_LOOPBACK)
    base = {**os.environ, "ROS_DOMAIN_ID": str(claim_domain()), "CYCLONEDDS_URI": config.as_uri(),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}  # rmw_fastrtps on loopback; Cyclone by the file
    load = os.getloadavg()[0]
    print(f"bench_graph: DDS domain {base['ROS_DOMAIN_ID']}, loopback only; {os.cpu_count()} cores, "
          f"load average {load:.1f}")
    figures: dict[str, Any] = {}
    for name in ("dds", "rclpy"):
        try:
            python, env = process(name, base)
        except ParamError as exc:
            print(f"\n{name}: not measured: {exc}")
            continue
        command = [python, __file__, "--measure"] + (["--lockstep"] if args.lockstep else [])
        result = subprocess.run(command, env=env, capture_output=True, text=True, timeout=1800)
        if result.returncode != 0:
            print(f"\n{name}: failed (exit {result.returncode}): {result.stderr[-2000:]}")
            continue
        title = {"dds": "Cyclone DDS runtime", "rclpy": "rclpy on Fast DDS"}[name]
        measured = json.loads(result.stdout.strip().splitlines()[-1])
        figures[name] = report_lockstep(title, measured) if args.lockstep else report(title, measured)
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    if args.lockstep and len(figures) == 2:
        print(f"\nrclpy / Cyclone, lockstep pace against the loop, same run: {figures['rclpy'] / figures['dds']:.2f}x")
    elif len(figures) == 2:
        print("\nrclpy / Cyclone, same run (p50, p99):")
        for hop in figures["dds"]:
            (a50, a99), (b50, b99) = figures["dds"][hop], figures["rclpy"][hop]
            print(f"{hop:>18} {b50 / a50:6.1f}x {b99 / a99:6.1f}x")


if __name__ == "__main__":
    main()
