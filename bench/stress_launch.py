"""Run health under concurrency: ``moose launch`` at real time, several graphs at once, tallied by how each run ended.

The real-time tests run one graph at a time; a graph on a loaded machine meets what they rarely do.  This starts
``--runs`` launches (default 24) of ``--scenario`` (default paper_v7_tau2, the real-time rclpy test's case),
``--at-once`` of them (default 4) running together on ``--runtime`` (``rclpy``, from ``make ros``'s prefix, or
``dds``), each in a DDS domain of its own (claimed with ``tests/isolation.py``), on loopback, and prints one line per
run (exit status, wall time, nodes that did not end with 0 or SIGTERM, the reason of a run judged ``incomplete``)
and the tally.  A healthy graph ends every run with 0, 1 or 4 (4: degraded, which load may cause: a node late, a
rate not held); 3 (incomplete) or a node killed at the launcher's grace is a bug of ours or of the middleware.

Found with it (2026-12-03, 2 cores, four at once on rclpy): an rclpy node SIGKILLed because its teardown hung
holding the interpreter lock, and runs judged incomplete because the launcher's monitor matched the odometry late or
lost the simulator's ``finished`` status (docs/testing.md).  About 6 min for the defaults.
Run: ``python bench/stress_launch.py [--runs 24] [--at-once 4] [--runtime rclpy] [--scenario paper_v7_tau2]``.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
RUN_LIMIT = 400.0
"""Wall-clock seconds one launch may take (it normally takes 40-80 s four at once on 2 cores)."""
CYCLONE_LOOPBACK = ('<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
                    "<AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>")


def one_run(index: int, python: str, env: dict[str, str], runtime: str, scenario: str, out: Path) -> dict[str, Any]:
    """One launch in its own domain; what the summary says of how it ended."""
    from isolation import claim_domain

    run_dir = out / f"run{index:03d}"
    run_dir.mkdir()
    env = {**env, "ROS_DOMAIN_ID": str(claim_domain())}
    started = time.monotonic()
    result = subprocess.run([python, "-m", "moose.cli", "launch", "--runtime", runtime, "--scenario", scenario,
                             "--json", str(run_dir / "summary.json"), "--bag", str(run_dir / "bag")],
                            env=env, capture_output=True, text=True, timeout=RUN_LIMIT)
    (run_dir / "output.txt").write_text(result.stdout + result.stderr, encoding="utf-8")
    row: dict[str, Any] = {"run": index, "exit": result.returncode, "wall_s": round(time.monotonic() - started)}
    try:
        summary = json.loads((run_dir / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return {**row, "problem": f"no summary: {exc}"}
    row["odd_exits"] = {n: c for n, c in summary["node_exits"].items() if c not in (0, -15)}
    if summary["outcome"] == "incomplete":
        row["problem"] = summary["reason"]
    return row


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=24)
    parser.add_argument("--at-once", type=int, default=4)
    parser.add_argument("--runtime", choices=("rclpy", "dds"), default="rclpy")
    parser.add_argument("--scenario", default="paper_v7_tau2")
    args = parser.parse_args(argv)
    if args.runs < 1 or args.at_once < 1:
        print(f"stress_launch: error: --runs {args.runs} / --at-once {args.at_once} is invalid: expected at least 1",
              file=sys.stderr)
        return 2
    sys.path.insert(0, str(REPO / "tests"))
    from moose.params import ParamError
    from moose_ros.runtime import process

    config = Path(tempfile.mkdtemp()) / "cyclonedds.xml"
    config.write_text(CYCLONE_LOOPBACK)
    base = {**os.environ, "CYCLONEDDS_URI": config.as_uri(), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "MOOSE_RUNTIME": args.runtime}
    try:
        python, env = process(args.runtime, base)
    except ParamError as exc:
        print(f"stress_launch: error: --runtime {args.runtime}: {exc}", file=sys.stderr)
        return 2
    out = Path(tempfile.mkdtemp(prefix="moose-stress-"))
    print(f"stress_launch: {args.runs} launches of {args.scenario} on {args.runtime}, {args.at_once} at once, "
          f"{os.cpu_count()} cores; output in {out}", flush=True)
    rows = []
    with ThreadPoolExecutor(args.at_once) as pool:
        for row in pool.map(lambda i: one_run(i, python, env, args.runtime, args.scenario, out),
                                 range(args.runs)):
            rows.append(row)
            print(json.dumps(row), flush=True)
    tally = collections.Counter(r["exit"] for r in rows)
    bad = [r for r in rows if r["exit"] not in (0, 1, 4) or r.get("odd_exits") or r.get("problem")]
    print(f"exit statuses: {dict(sorted(tally.items()))}; runs with a problem: {len(bad)} of {len(rows)}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
