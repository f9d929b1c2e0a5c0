"""Per-core sweep throughput against the closed loop's, measured in one run (target: the sweep ≥ 90 %, issue 26).

What a sweep adds to the runs it makes — the worker's start-up (imports, the maneuver table, the compiled
functions), each case's summary and independent verdict, its row over the pipe, the journal, the parquet file —
is what this ratio measures.  Both sides run the same cases (Latin-hypercube samples of the paper region at the
paper calibration, combined planner, 9 simulated seconds each, as ``bench_sweep.py``):

* the closed loop: :func:`moose.simulation.simulate` of the cases in this process, over and over for as long as
  the sweep runs (the figure ``bench_closed_loop.py`` gives, on these cases): simulated seconds per CPU second;
* the sweep: ``moose sweep --workers 1`` on the same cases as a user runs it (a subprocess: start-up, the rows and
  results.parquet included): simulated seconds per CPU second of the command and its worker together (the
  command's own work, the journal and the parquet file, counts against the sweep).

Both per CPU second, and at the same time, each on a core of its own: the host's speed changes by tens of per
cent between minutes (two runs of the closed loop on 300 of these cases, three minutes apart: 15.0 and 19.8 CPU s),
and a process sharing a core with other work gets a varying share of it, which a wall clock would measure (at a
load average of 9 on 2 cores a 120-case sweep took 4.5 times its CPU time).  Run side by side, the two meet the
same host.  The wall clock is printed too.

Run: ``python bench/bench_sweep_per_core.py [--cases N]`` (default 720).
"""
from __future__ import annotations

import argparse
import itertools
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

from bench_sweep import AXES

from moose.config import load_config
from moose.sweep.case import case_scenario
from moose.sweep.spec import SweepSpec


def cases(n: int) -> list:
    """The sweep's cases, as ``moose sweep`` builds them from :data:`bench_sweep.AXES`."""
    from moose.cli import build_parser

    args = build_parser().parse_args(["sweep", *AXES, "--samples", str(n)])
    from moose.cli.sweep import _axes

    return SweepSpec(tuple(_axes(args)), load_config(), samples=n, sampling_seed=args.sampling_seed).cases()


def closed_loop(todo: list, until: Optional[subprocess.Popen] = None) -> tuple[float, float]:
    """(simulated s, CPU s) of simulating every case in this process, and with ``until`` the cases again and again
    until that process has ended."""
    from moose.simulation import simulate

    config = load_config()
    simulated = cpu = 0.0
    for k in itertools.count():
        if k >= len(todo) and (until is None or until.poll() is not None):
            break
        case = todo[k % len(todo)]
        scenario = case_scenario(case)
        start = time.process_time()
        simulate(config, scenario, case.planner, case.seed)
        cpu += time.process_time() - start
        simulated += scenario.lead_time + scenario.duration
    return simulated, cpu


def children_cpu() -> float:
    """CPU seconds (user + system) of every finished child process of this one and of their finished children."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=720)
    n = parser.parse_args().cases
    todo = cases(n)
    closed_loop(todo[:3])  # warm-up: CasADi, the maneuver table, the compiled functions
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "moose.cli", "sweep", *AXES, "--samples", "2", "--workers", "1",
                        "-o", str(Path(tmp) / "warm")], capture_output=True, check=True)  # the caches, as installed
        folder = Path(tmp) / "sweep"
        start, start_cpu = time.perf_counter(), children_cpu()
        with open(Path(tmp) / "sweep.log", "w") as log:
            run = subprocess.Popen([sys.executable, "-m", "moose.cli", "sweep", *AXES, "--samples", str(n),
                                    "--workers", "1", "-o", str(folder)], stdout=log, stderr=subprocess.STDOUT)
            loop_simulated, loop_cpu = closed_loop(todo, until=run)
            code = run.wait()
        wall, cpu = time.perf_counter() - start, children_cpu() - start_cpu
        if code != 0:
            raise SystemExit(f"moose sweep failed ({code}): {(Path(tmp) / 'sweep.log').read_text()[-2000:]}")
        rows = [json.loads(line) for line in (folder / "cases.jsonl").read_text().splitlines()]
        if len(rows) != n or not (folder / "results.parquet").exists():
            raise SystemExit(f"expected {n} rows and results.parquet in {folder}")
    simulated = sum(r["duration_s"] for r in rows)
    loop = loop_simulated / loop_cpu
    own = sum(r["wall_s"] for r in rows)
    print(f"{n} cases (combined planner, paper region at the paper calibration, {simulated / n:.0f} simulated s each)")
    print(f"  closed loop in-process, beside the sweep: {loop_simulated / simulated:.1f} passes over the cases, "
          f"{loop:.0f}x (simulated s per CPU second)")
    print(f"  moose sweep --workers 1: {cpu:.1f} CPU s (command and worker, start-up and results.parquet "
          f"included): {simulated / cpu:.0f}x per core; {wall:.1f} s wall ({simulated / wall:.0f}x); the cases' own "
          f"time {own:.1f} s wall ({own / n * 1e3:.0f} ms per case)")
    print(f"  ratio sweep / closed loop, per CPU second: {simulated / cpu / loop * 100:.0f} %  (target >= 90 %)")


if __name__ == "__main__":
    main()
