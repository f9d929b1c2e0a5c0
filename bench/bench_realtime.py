"""The extreme case at real time, under load, on both runtimes: how often the real-time graph keeps the outcome the
lockstep loop predicts, and why not when it does not (issue 22, point 6).

For each runtime — our Cyclone DDS runtime, and rclpy on Fast DDS from the ROS 2 prefix of ``make ros`` (skipped,
saying why, without it) — and each of ``timing.compensate`` false and true, a process of that runtime runs the
extreme case (paper_v7_tau1.4: 7 m/s, τ = 1.4 s, ν = 0.95) ``--runs`` times (default 20) at real time
(``moose_ros.launch.launch``, rate 1, every node and the monitor on that runtime), while ``--load`` busy processes
(default 2, started and stopped here: ``while True: pass``) compete for the machine's cores.  A latency monitor
node of the same runtime timestamps the arrival of each IMU sample and of the actuator command of the same 10 ms
tick (CLOCK_MONOTONIC, one clock for every process): from the sample's arrival to the arrival of the command
computed from it (the command carries its estimate's stamp, the sample's), the graph's sensing-to-command
latency, which the lockstep graph (and the timing model) does not have beyond its designed delays.

Reported per configuration: the outcome distribution, the spread of the minimum clearance, the p50/p99 latency
over every tick of every run, and the lockstep prediction at that latency: ``moose simulate`` with the same timing
and the command path's delay raised by 0, 10 and 20 ms (the grid of ``moose budget``; the extreme case's budget is
0 ms, docs/architecture.md "Latency budget").  Written: ``bench/results/realtime.json`` (``--out``) and, with
``--write docs/graph.md``, the generated table between ``<!-- BEGIN realtime -->`` and ``<!-- END realtime -->``.
Every process is on loopback, in a DDS domain claimed with ``tests/isolation.py``.  About 30 min on 2 cores.
Run: ``python bench/bench_realtime.py [--runs 20] [--load 2] [--write docs/graph.md]``.
"""
from __future__ import annotations

import argparse
import dataclasses
import io
import json
import os
import platform
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENARIO = "paper_v7_tau1.4"
ADDED_MS = (0, 10, 20)
"""Latency added to the command path for the lockstep prediction (ms, the motion-control grid)."""
CYCLONE_LOOPBACK = ('<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
                    "</Interfaces><AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>")
BEGIN, END = "<!-- BEGIN realtime -->", "<!-- END realtime -->"
RUN_LIMIT = 240.0
"""Wall-clock seconds one configuration's process may take per run."""


def measure(runs: int, compensate: bool) -> list[dict[str, Any]]:
    """``runs`` real-time runs of the extreme case on this process's runtime (MOOSE_RUNTIME)."""
    from moose.scenario import load_scenario
    from moose_ros import convert as cv
    from moose_ros.graph import ACTUATOR_COMMAND, IMU
    from moose_ros.launch import launch
    from moose_ros.runtime import create_node

    scenario = load_scenario(SCENARIO)
    out = []
    for _ in range(runs):
        arrivals: dict[str, dict[int, float]] = {"imu": {}, "command": {}}

        def record(kind: str, arrivals: dict[str, dict[int, float]] = arrivals) -> Any:
            def callback(msg: Any) -> None:
                arrivals[kind].setdefault(round(cv.time_of(msg) * 100), time.monotonic())
            return callback

        monitor = create_node("latency_monitor")
        IMU.tool_subscription(monitor, record("imu"))
        ACTUATOR_COMMAND.tool_subscription(monitor, record("command"))
        result: dict = {}
        runner = threading.Thread(target=lambda result=result: result.update(launch(
            scenario, {"scenario": SCENARIO, "timing.compensate": compensate}, out=io.StringIO(), bag=None)))
        runner.start()
        while runner.is_alive():
            monitor.spin_once(0.01)
        monitor.shutdown()
        # a command carries its estimate's stamp, the stamp of the IMU sample that estimate was made from
        latency = [arrivals["command"][k] - t for k, t in arrivals["imu"].items() if k in arrivals["command"]]
        out.append({"outcome": result.get("outcome"), "min_clearance_m": result.get("min_clearance_m"),
                    "exit_status": result.get("exit_status"), "incidents": len(result.get("incidents", [])),
                    "latency_ms": [1e3 * x for x in latency]})
    return out


def prediction(compensate: bool) -> dict[str, dict[str, Any]]:
    """The lockstep loop's outcome and clearance with ``ADDED_MS`` more on the command path."""
    from moose.config import load_config, with_overrides
    from moose.metrics import summarize
    from moose.scenario import load_scenario
    from moose.simulation import simulate

    config = with_overrides(load_config(), {"timing.compensate": compensate})
    out = {}
    for added in ADDED_MS:
        timing = dataclasses.replace(config.timing, command_delay_s=config.timing.command_delay_s + added / 1e3)
        summary = summarize(simulate(dataclasses.replace(config, timing=timing), load_scenario(SCENARIO)))
        out[str(added)] = {"outcome": summary["outcome"], "min_clearance_m": summary["min_clearance_m"]}
    return out


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Outcome counts, clearance spread and pooled latency percentiles of one configuration."""
    outcomes: dict[str, int] = {}
    for run in runs:
        outcomes[run["outcome"]] = outcomes.get(run["outcome"], 0) + 1
    clearance = [r["min_clearance_m"] for r in runs if r["min_clearance_m"] is not None]
    latency = np.array([x for r in runs for x in r["latency_ms"]])
    return {"runs": len(runs), "outcomes": outcomes,
            "clearance_m": {"min": min(clearance), "median": float(np.median(clearance)), "max": max(clearance)}
            if clearance else None,
            "latency_ms": {"p50": float(np.percentile(latency, 50)), "p99": float(np.percentile(latency, 99)),
                           "ticks": int(latency.size)} if latency.size else None,
            "degraded_runs": sum(1 for r in runs if r["exit_status"] == 4)}


def table(results: dict[str, Any]) -> str:
    """The generated Markdown table of docs/graph.md."""
    meta = results["machine"]
    lines = [f"{results['runs']} real-time runs of {SCENARIO} per row, `car` timing, {meta['load']} busy processes "
             f"started by the benchmark on {meta['cores']} cores (load average {meta['loadavg_start']:.1f} at the "
             f"start, {meta['loadavg_end']:.1f} at the end); `python bench/bench_realtime.py --write "
             "docs/graph.md`. Latency: IMU sample → the actuator command of its tick, over every tick of every "
             "run. Lockstep: `moose simulate` with the command path's delay raised by 0 / 10 / 20 ms.", "",
             *([f"Load: {meta['note']}.", ""] if meta.get("note") else []),
             *([f"Rows of {', '.join(results['kept']['runtimes'])} from an earlier run (load average "
                f"{results['kept']['from']['loadavg_start']:.1f} at its start, "
                f"{results['kept']['from']['loadavg_end']:.1f} at its end; {results['kept']['from'].get('note', '')})."
                , ""] if results.get("kept") else []),
             *(line for row in results["rows"] if row.get("source")
               for line in (f"Rows of {row['runtime']}, compensate {str(row['compensate']).lower()}: "
                            f"{row['source']}.", "")),
             "| runtime | compensate | outcomes | clearance min / median / max (m) | latency p50 / p99 (ms) | "
             "degraded runs | lockstep +0 / +10 / +20 ms (m) |",
             "|---|---|---|---|---|---|---|"]
    for row in results["rows"]:
        s = row["summary"]
        outcomes = ", ".join(f"{n} {k}" for k, n in sorted(s["outcomes"].items()))
        c = s["clearance_m"]
        clearance = "–" if c is None else f"{c['min']:.3f} / {c['median']:.3f} / {c['max']:.3f}"
        lat = s["latency_ms"]
        latency = "–" if lat is None else f"{lat['p50']:.1f} / {lat['p99']:.1f}"
        predicted = " / ".join(f"{p['min_clearance_m']:.3f} ({p['outcome']})" for p in row["lockstep"].values())
        lines.append(f"| {row['runtime']} | {str(row['compensate']).lower()} | {outcomes} | {clearance} | {latency} "
                     f"| {s['degraded_runs']} | {predicted} |")
    return "\n".join(lines)


def write_docs(path: Path, text: str) -> None:
    doc = path.read_text(encoding="utf-8")
    if BEGIN not in doc or END not in doc:
        raise SystemExit(f"bench_realtime: error: {path} has no {BEGIN} … {END} section")
    doc = re.sub(re.escape(BEGIN) + r".*?" + re.escape(END), lambda _m: f"{BEGIN}\n{text}\n{END}", doc, flags=re.S)
    path.write_text(doc, encoding="utf-8")


def busy(count: int) -> list[subprocess.Popen]:
    """``count`` processes that spin a core each until stopped."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
            for _ in range(count)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20, help="runs per runtime and compensation (default 20)")
    parser.add_argument("--load", type=int, default=2, help="busy processes started meanwhile (default 2)")
    parser.add_argument("--runtimes", nargs="+", default=["dds", "rclpy"], choices=["dds", "rclpy"])
    parser.add_argument("--out", default=str(REPO / "bench" / "results" / "realtime.json"))
    parser.add_argument("--write", help="regenerate the table in this Markdown file (docs/graph.md)")
    parser.add_argument("--from-json", help="regenerate the table from this result file, without running")
    parser.add_argument("--keep", help="an earlier result file whose rows of the runtimes not measured now are kept")
    parser.add_argument("--measure", nargs=2, metavar=("RUNS", "COMPENSATE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(int(args.measure[0]), args.measure[1] == "true")))
        return
    if args.runs < 1 or args.load < 0:
        raise SystemExit(f"bench_realtime: error: --runs {args.runs} / --load {args.load} is invalid: expected "
                         "at least one run and no negative load")
    if args.from_json:
        results = json.loads(Path(args.from_json).read_text(encoding="utf-8"))
    else:
        results = run_all(args)
        if args.keep:
            earlier = json.loads(Path(args.keep).read_text(encoding="utf-8"))
            kept = [row for row in earlier["rows"] if row["runtime"] not in args.runtimes]
            results["rows"] = sorted(kept + results["rows"], key=lambda r: (r["runtime"] != "dds", r["compensate"]))
            results["kept"] = {"from": earlier.get("machine"), "runtimes": sorted({r["runtime"] for r in kept})}
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
        print(f"bench_realtime: wrote {args.out}")
    print(table(results))
    if args.write:
        write_docs(Path(args.write), table(results))
        print(f"bench_realtime: wrote the table into {args.write}")


def run_all(args: argparse.Namespace) -> dict[str, Any]:
    sys.path.insert(0, str(REPO / "tests"))
    from isolation import claim_domain
    from moose.params import ParamError
    from moose_ros.runtime import process

    config = Path(tempfile.mkdtemp()) / "cyclonedds.xml"
    config.write_text(CYCLONE_LOOPBACK)
    base = {**os.environ, "ROS_DOMAIN_ID": str(claim_domain()), "CYCLONEDDS_URI": config.as_uri(),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}  # rmw_fastrtps on loopback; Cyclone by the file
    print(f"bench_realtime: DDS domain {base['ROS_DOMAIN_ID']}, loopback only; {os.cpu_count()} cores; "
          f"{args.load} busy processes", flush=True)
    results: dict[str, Any] = {"scenario": SCENARIO, "runs": args.runs, "rows": [], "machine": {
        "cores": os.cpu_count(), "load": args.load, "loadavg_start": os.getloadavg()[0],
        "python": platform.python_version()}}
    loaders = busy(args.load)
    try:
        for name in args.runtimes:
            try:
                python, env = process(name, base)
            except ParamError as exc:
                print(f"\n{name}: not measured: {exc}", flush=True)
                continue
            for compensate in (False, True):
                started = time.monotonic()
                result = subprocess.run([python, __file__, "--measure", str(args.runs), str(compensate).lower()],
                                        env=env, capture_output=True, text=True, timeout=RUN_LIMIT * args.runs)
                if result.returncode != 0:
                    print(f"\n{name} compensate={compensate}: failed (exit {result.returncode}): "
                          f"{result.stderr[-2000:]}", flush=True)
                    continue
                runs = json.loads(result.stdout.strip().splitlines()[-1])
                row = {"runtime": name, "compensate": compensate, "summary": summarise(runs),
                       "lockstep": prediction(compensate), "runs": [{k: v for k, v in r.items() if k != "latency_ms"}
                                                                    for r in runs],
                       "wall_s": time.monotonic() - started}
                results["rows"].append(row)
                print(f"{name} compensate={compensate}: {json.dumps(row['summary'])}", flush=True)
    finally:
        for proc in loaders:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    results["machine"]["loadavg_end"] = os.getloadavg()[0]
    return results


if __name__ == "__main__":
    main()
