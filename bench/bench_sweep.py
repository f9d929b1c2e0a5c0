"""Sweep throughput: a 1,000-case ``moose sweep`` on 2 worker processes (target ≤ 60 s wall, start-up and
writing the results included), parallel efficiency from 1 to 2 workers (target ≥ 80 %), and the peak
memory of each worker.

Every figure is the ``moose sweep`` command as a user runs it, timed from outside (a subprocess, wall
clock).  Baselines measured in the same run: the 1-worker sweep of the same cases (efficiency
= T₁ / (2 T₂), the best of interleaved repeats of each, since other work on the machine varies), and
the cases' own time (the sum of ``wall_s`` over the rows), which shows what start-up, scheduling and
writing cost on top.  Cases: Latin-hypercube samples of the paper region
(v 4–8 m/s, τ 1–5 s, ν 0.1–1.0) at the paper calibration, combined planner, 9 simulated seconds each.

Run: ``python bench/bench_sweep.py`` (``--cases N`` to change the big sweep's size).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

AXES = ["--speed", "4:8", "--tau", "1:5", "--nu", "0.1:1.0", "--mu", "paper", "--planner", "combined",
        "--sampling-seed", "1", "--quiet"]


def sweep(cases: int, workers: int, folder: Path) -> tuple[float, list[dict]]:
    """Wall time of one ``moose sweep`` command and its rows."""
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "moose.cli", "sweep", *AXES, "--samples", str(cases),
                          "--workers", str(workers), "-o", str(folder)], capture_output=True, text=True)
    wall = time.perf_counter() - start
    if run.returncode != 0:
        raise SystemExit(f"moose sweep failed ({run.returncode}): {run.stderr[-2000:]}")
    rows = [json.loads(line) for line in (folder / "cases.jsonl").read_text().splitlines()]
    if len(rows) != cases or not (folder / "results.parquet").exists():
        raise SystemExit(f"expected {cases} rows and results.parquet in {folder}")
    return wall, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=1000)
    parser.add_argument("--efficiency-cases", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3, help="runs of each efficiency sweep (best is used)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        subprocess.run([sys.executable, "-m", "moose.cli", "sweep", *AXES, "--samples", "2", "--workers", "1",
                        "-o", str(root / "warm")], capture_output=True, check=True)  # compile caches, as after install
        ones, twos = [], []
        for i in range(args.repeats):  # interleaved, so a change of the machine's load hits both alike
            ones.append(sweep(args.efficiency_cases, 1, root / f"one{i}")[0])
            twos.append(sweep(args.efficiency_cases, 2, root / f"two{i}")[0])
        big, rows = sweep(args.cases, 2, root / "big")
    t1, t2 = min(ones), min(twos)
    simulated = sum(r["duration_s"] for r in rows)
    busy = sum(r["wall_s"] for r in rows)
    print(f"sweep of {args.cases} cases (combined planner, {simulated / len(rows):.0f} simulated s each) on 2 workers")
    print(f"  wall, start-up and writing included: {big:.1f} s  (target <= 60 s)  "
          f"{len(rows) / big:.1f} cases/s")
    print(f"  the cases' own time: {busy:.1f} s, {busy / len(rows) * 1e3:.0f} ms per case "
          f"(real-time factor per worker {simulated / busy:.0f}x); overhead {big - busy / 2:.1f} s of the wall time")
    print(f"parallel efficiency, {args.efficiency_cases} cases, best of {args.repeats} (wall, start-up included): "
          f"1 worker {t1:.1f} s, 2 workers {t2:.1f} s -> {t1 / (2 * t2) * 100:.0f} %  (target >= 80 %); "
          f"all runs: 1 worker {', '.join(f'{t:.1f}' for t in ones)} s, "
          f"2 workers {', '.join(f'{t:.1f}' for t in twos)} s")
    peaks: dict[str, float] = {}
    for row in rows:
        peaks[row["worker"]] = max(peaks.get(row["worker"], 0.0), row["worker_max_rss_mb"] or 0.0)
    print(f"peak memory per worker (max RSS): {', '.join(f'{v:.0f} MB' for v in sorted(peaks.values()))}; "
          f"median case {statistics.median(r['wall_s'] for r in rows) * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
