"""Closed-loop CPU time of this checkout against an earlier revision, both in one process, alternating.

A machine shared with other work changes speed by tens of per cent between hours, so two figures
taken at different times cannot show a 10 % gain.  This script loads ``src/moose`` of ``REV``
(``git archive``) as the package ``moose_base`` next to the working tree's ``moose``, runs the same
10 s paper case with both, alternating, and prints the best CPU time of each and their ratio.
Run: ``python bench/bench_against_revision.py REV [--planner combined] [--runs 15]``.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import io
import re
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Sequence

from bench_closed_loop import (  # the same case (this folder is on sys.path when run as a script)
    DURATION,
    LEAD_TIME,
    SCENARIO,
)

ROOT = Path(__file__).resolve().parents[1]


def extract_revision(rev: str, paths: Sequence[str], folder: Path) -> None:
    """Extract ``paths`` of ``rev`` (``git archive``) into ``folder``, keeping their place in the tree."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, *paths], check=True,
                             capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        if hasattr(tarfile, "data_filter"):  # Python ≥ 3.10.12: refuse links and paths out of the folder
            tar.extractall(folder, filter="data")
        else:
            tar.extractall(folder)  # our own repository's archive


def load_revision(rev: str, folder: Path) -> str:
    """Extract ``src/moose`` of ``rev`` into ``folder``/moose_base; returns the package name."""
    extract_revision(rev, ["src/moose"], folder)
    package = folder / "moose_base"
    (folder / "src" / "moose").rename(package)
    for path in package.rglob("*.py"):  # absolute imports of the package itself, and its data folder
        text = path.read_text(encoding="utf-8")
        text = re.sub(r"\b(from|import) moose\b", r"\1 moose_base", text)
        path.write_text(text.replace('package_folder("moose",', 'package_folder("moose_base",'), encoding="utf-8")
    return "moose_base"


def case(package: str, planner: str) -> Callable[[], Any]:
    """One run of the benchmark's case (``bench_closed_loop.py``) with ``package``."""
    config = importlib.import_module(f"{package}.config").load_config()
    scenario = importlib.import_module(f"{package}.scenario").load_scenario(SCENARIO)
    scenario = dataclasses.replace(scenario, lead_time=LEAD_TIME, duration=DURATION)
    simulate = importlib.import_module(f"{package}.simulation").simulate
    return lambda: simulate(config, scenario, planner, seed=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rev", help="the earlier revision (a commit, tag or branch)")
    parser.add_argument("--planner", default="combined", choices=("combined", "mpc", "msf"))
    parser.add_argument("--runs", type=int, default=15, help="runs of each version (alternating)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sys.path.insert(0, tmp)
        base = case(load_revision(args.rev, Path(tmp)), args.planner)
        runs = {args.rev: base, "this checkout": case("moose", args.planner)}
        best = dict.fromkeys(runs, float("inf"))
        for run in runs.values():
            run()  # warm-up: the maneuver table, CasADi set-up, compiled libraries
        for _ in range(args.runs):
            for name, run in runs.items():
                start = time.process_time()
                run()
                best[name] = min(best[name], time.process_time() - start)
    print(f"{args.planner}, 10 s simulated, best CPU time of {args.runs} alternating runs each")
    for name, seconds in best.items():
        print(f"{name:>15} {seconds * 1e3:8.1f} ms {10.0 / seconds:8.1f}x real time")
    print(f"{'ratio':>15} {best[args.rev] / best['this checkout']:8.3f} (above 1: this checkout is faster)")


if __name__ == "__main__":
    main()
