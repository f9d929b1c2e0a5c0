"""What one lockstep graph costs, its nodes forked by the fork server against started by ``exec``, in one run.

The suite launches dozens of graphs (the fault matrix alone 36), so a graph's fixed cost (start-up, discovery,
shutdown) is much of its time (docs/testing.md).  This launches the full graph in lockstep
(``moose_ros.launch.launch``, as the tests do: the launcher is this process) on a short case, alternately with
its nodes forked from this process's fork server (:mod:`moose_ros.forkserver`, kept from run to run, as in a test
process) and started by ``exec`` (the launcher's path for nodes it cannot fork), and prints each run's CPU seconds
and wall time, then the medians and their ratio.  The first forked run starts the server (its preload is counted
in that run) and is printed apart; the medians are of the runs after it.

CPU seconds are those of every process of the run: this process (the launcher and its monitor), the nodes and the
fork server.  The nodes started by ``exec`` are this process's children, reaped by the launcher
(``RUSAGE_CHILDREN``); the forked ones are the server's, reaped by it, so their CPU is read from the server's
``/proc/PID/stat`` (its own and its waited-for children's, before and after the run).  Both arms must compute the
same run (outcome and clearance); a run that differs is an error.  The DDS domain is claimed with
``tests/isolation.py``; discovery stays on this host.
Run: ``python bench/bench_graph_start.py [--runs 3] [--duration 0.2]``.
"""
from __future__ import annotations

import argparse
import dataclasses
import io
import os
import resource
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Optional

REPO = Path(__file__).resolve().parents[1]
SCENARIO = "paper_v6_w2.0"
"""The fault matrix's case."""


def server_cpu(pid: Optional[int]) -> float:
    """CPU seconds of the fork server ``pid`` and of the children it has reaped (0 without one)."""
    from moose_ros.process import stat_fields

    fields = stat_fields(pid) if pid is not None else None
    if fields is None:
        return 0.0
    return sum(int(f) for f in fields[11:15]) / os.sysconf("SC_CLK_TCK")  # utime, stime, cutime, cstime


def settled(pid: Optional[int], limit: float = 5.0) -> None:
    """Wait until the fork server ``pid`` has reaped every node it forked (it does when the launcher says so, just
    after a node ended): their CPU is then in the server's counters."""
    from moose_ros.process import stat_fields

    deadline = time.monotonic() + limit
    while pid is not None and time.monotonic() < deadline:
        children = [e.name for e in Path("/proc").iterdir() if e.name.isdigit()
                    and (stat_fields(e.name) or ["", ""])[1] == str(pid)]
        if not children:
            return
        time.sleep(0.01)


def own_cpu() -> float:
    """CPU seconds of this process and of the children it has reaped."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def one_run(duration: float, fork: bool) -> dict[str, Any]:
    """One lockstep launch of the full graph; its CPU seconds, wall time and what it computed."""
    from moose.scenario import load_scenario
    from moose_ros import forkserver
    from moose_ros.launch import Supervisor, launch

    scenario = dataclasses.replace(load_scenario(SCENARIO), duration=duration)
    original = Supervisor.fork_server
    if not fork:
        Supervisor.fork_server = lambda self: None  # type: ignore[method-assign]  # the launcher's exec path
    server = forkserver._shared[0].proc.pid if forkserver._shared else None
    before, server_before, start = own_cpu(), server_cpu(server), time.perf_counter()
    try:
        summary = launch(scenario, {"scenario": SCENARIO, "duration": duration}, lockstep=True, out=io.StringIO())
    finally:
        Supervisor.fork_server = original  # type: ignore[method-assign]
    wall = time.perf_counter() - start
    after = forkserver._shared[0].proc.pid if forkserver._shared else None
    settled(after)
    if after != server:  # started (or replaced) during this run: all of its CPU is this run's
        server_before = 0.0
    cpu = own_cpu() - before + server_cpu(after) - server_before
    return {"cpu": cpu, "wall": wall, "outcome": summary["outcome"], "clearance": summary["min_clearance_m"],
            "odometry": summary["odom_samples"], "degraded": summary["degraded"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="runs of each arm after the first forked one")
    parser.add_argument("--duration", type=float, default=0.2,
                        help="simulated seconds after the obstacle appears (short: the fixed cost)")
    args = parser.parse_args()
    sys.path.insert(0, str(REPO / "tests"))
    from isolation import claim_domain

    os.environ.update({"ROS_DOMAIN_ID": str(claim_domain()), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
    print(f"bench_graph_start: full graph in lockstep, {SCENARIO} with {args.duration:g} s after the obstacle; "
          f"DDS domain {os.environ['ROS_DOMAIN_ID']}; {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    first = one_run(args.duration, fork=True)
    print(f"  fork (server started)  {first['cpu']:6.2f} CPU-s {first['wall']:6.2f} s  {first['outcome']}")
    runs: dict[str, list[dict[str, Any]]] = {"exec": [], "fork": []}
    for _ in range(args.runs):
        for arm in ("exec", "fork"):
            run = one_run(args.duration, fork=arm == "fork")
            runs[arm].append(run)
            print(f"  {arm:22} {run['cpu']:6.2f} CPU-s {run['wall']:6.2f} s  {run['outcome']}")
    computed = {(r["outcome"], r["clearance"], r["odometry"], r["degraded"]) for r in [first, *runs["exec"],
                                                                                        *runs["fork"]]}
    if len(computed) != 1:
        raise SystemExit(f"bench_graph_start: the runs computed different things: {sorted(map(str, computed))}")
    cpu = {arm: statistics.median(r["cpu"] for r in arm_runs) for arm, arm_runs in runs.items()}
    wall = {arm: statistics.median(r["wall"] for r in arm_runs) for arm, arm_runs in runs.items()}
    print(f"median of {args.runs}: exec {cpu['exec']:.2f} CPU-s ({wall['exec']:.2f} s), "
          f"fork {cpu['fork']:.2f} CPU-s ({wall['fork']:.2f} s); fork / exec = {cpu['fork'] / cpu['exec']:.2f} "
          f"in CPU, {wall['fork'] / wall['exec']:.2f} in wall time; load average at the end "
          f"{os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
