"""CPU time of a lockstep graph launched from this checkout against one launched from an earlier revision, alternating.

The host's speed moves by up to 2x within an hour (docs/testing.md), so a change to the node graph is measured
against its revision in the same run: ``REV``'s ``src/moose`` and ``moose_ros`` (``git archive``) go to a temporary
folder, and ``moose launch full --lockstep`` (the command line: launcher, fork server, nodes) runs alternately from
that folder and from this checkout (``PYTHONPATH`` first), one warm-up run each (the sources compile to bytecode)
and then ``--runs`` pairs.  CPU seconds are every process's of the run: this process is the launcher's child
subreaper, so the fork server and the nodes, which outlive their parents by a moment, are reaped here too
(``RUSAGE_CHILDREN``).  Both arms must compute the same run (outcome, clearance, odometry samples); a run that differs
is an error.  The DDS domain is claimed with ``tests/isolation.py``; discovery stays on this host.
Run: ``python bench/bench_graph_against_revision.py REV [--runs 5] [--duration 7] [--graph full]``.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Optional

from bench_against_revision import extract_revision  # this folder is on sys.path when run as a script

REPO = Path(__file__).resolve().parents[1]
SCENARIO = "paper_v6_w2.0"
"""The fault matrix's case."""
SOURCES = ("src/moose", "ros2_ws/src/moose_ros/moose_ros", "ros2_ws/src/moose_msgs/msg")


def extract(rev: str, folder: Path) -> dict[str, str]:
    """``REV``'s packages in ``folder``; the environment that imports them first (and reads its messages)."""
    extract_revision(rev, SOURCES, folder)
    return {"PYTHONPATH": os.pathsep.join(str(folder / p) for p in ("src", "ros2_ws/src/moose_ros")),
            "MOOSE_MSG_DIR": str(folder / "ros2_ws/src/moose_msgs/msg")}


def reap_orphans(limit: float = 30.0) -> None:
    """Wait for every process of the run that outlived the launcher (given to this subreaper), at most ``limit`` s."""
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        try:
            pid, _status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            time.sleep(0.05)
    raise SystemExit("bench_graph_against_revision: processes of the run still alive after the launcher ended")


def children_cpu() -> float:
    """CPU seconds of the children this process has reaped (and of what they reaped)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def one_run(revision: Optional[dict[str, str]], args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    """One launch from the command line (``revision``: the environment of :func:`extract`, ``None``: this
    checkout); its CPU seconds, wall time and what it computed."""
    env = dict(os.environ)
    if revision is not None:
        path = revision["PYTHONPATH"] + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        env.update({**revision, "PYTHONPATH": path})
    summary = folder / "summary.json"
    cmd = [sys.executable, "-m", "moose.cli", "launch", args.graph, "--lockstep", "--scenario", SCENARIO,
           "--duration", str(args.duration), "--no-bag", "--json", str(summary)]
    before, start = children_cpu(), time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600, check=False)
    reap_orphans()
    wall, cpu = time.perf_counter() - start, children_cpu() - before
    if done.returncode not in (0, 4):
        raise SystemExit(f"bench_graph_against_revision: launch ended with {done.returncode}: {done.stderr[-2000:]}")
    result = json.loads(summary.read_text(encoding="utf-8"))
    return {"cpu": cpu, "wall": wall, "computed": (result["outcome"], result["min_clearance_m"],
                                                   result["odom_samples"], result["degraded"])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("rev", help="the revision to compare with (git rev-parse syntax)")
    parser.add_argument("--runs", type=int, default=5, help="pairs after one warm-up run of each arm")
    parser.add_argument("--duration", type=float, default=7.0, help="simulated seconds after the obstacle appears")
    parser.add_argument("--graph", default="full", choices=("full", "can"))
    args = parser.parse_args()
    import ctypes

    if ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) != 0:  # PR_SET_CHILD_SUBREAPER (Linux)
        raise SystemExit("bench_graph_against_revision: cannot become a child subreaper (Linux only)")
    sys.path.insert(0, str(REPO / "tests"))
    from isolation import claim_domain

    os.environ.update({"ROS_DOMAIN_ID": str(claim_domain()), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
    head = subprocess.run(["git", "-C", str(REPO), "describe", "--always", "--dirty"], capture_output=True,
                          text=True, check=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="moose-bench-") as tmp:
        folder = Path(tmp)
        rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", args.rev], capture_output=True,
                             text=True, check=True).stdout.strip()
        arms: dict[str, Optional[dict[str, str]]] = {rev: extract(args.rev, folder / "rev"), head: None}
        print(f"bench_graph_against_revision: {args.graph} graph in lockstep, {SCENARIO} with {args.duration:g} s "
              f"after the obstacle; {rev} against {head}; DDS domain {os.environ['ROS_DOMAIN_ID']}; "
              f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
        for name, path in arms.items():
            warm = one_run(path, args, folder)
            print(f"  {name:24} warm-up {warm['cpu']:6.2f} CPU-s {warm['wall']:6.2f} s")
        runs: dict[str, list[dict[str, Any]]] = {name: [] for name in arms}
        for _ in range(args.runs):
            for name, path in arms.items():
                run = one_run(path, args, folder)
                runs[name].append(run)
                print(f"  {name:24} {run['cpu']:6.2f} CPU-s {run['wall']:6.2f} s  {run['computed']}")
    computed = {r["computed"] for arm in runs.values() for r in arm}
    if len(computed) != 1:
        raise SystemExit(f"bench_graph_against_revision: the arms computed different runs: "
                         f"{sorted(map(str, computed))}")
    cpu = {name: statistics.median(r["cpu"] for r in arm) for name, arm in runs.items()}
    pairs = [new["cpu"] / old["cpu"] for old, new in zip(runs[rev], runs[head])]
    print(f"median of {args.runs}: {rev} {cpu[rev]:.2f} CPU-s, {head} {cpu[head]:.2f} CPU-s; "
          f"{head} / {rev} = {cpu[head] / cpu[rev]:.3f} (pairs: {', '.join(f'{p:.2f}' for p in pairs)}); "
          f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
