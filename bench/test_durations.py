"""Where the test suite's time goes: a table per test file from the JUnit XML reports of a ``make test`` run.

    python bench/test_durations.py                 # print the table of the last make test
    python bench/test_durations.py --docs          # ... and write it into docs/testing.md ("Testing")
    python bench/test_durations.py a.xml b.xml     # the table of other reports

``make test`` writes one report per phase to ``runs/tests/`` (the parallel phase, ``pytest -n 2``, and the serial
real-time phase).  Each test case carries its wall time (setup, call and teardown) and two properties that
tests/conftest.py records: ``cpu_s``, the CPU seconds of the test process, and ``child_cpu_s``, those of the
child processes it waited for (node graphs, CLI runs, inner pytest runs, and their children), and ``worker``, the
xdist worker that ran it.  The table sums them per file, the most expensive first; a phase's elapsed time is its
report's ``time``, beside the sum of its tests' wall time per worker.
"""
from __future__ import annotations

import argparse
import sys
import xml.etree.ElementTree as ET
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPORTS = ROOT / "runs" / "tests"
DOCS = ROOT / "docs" / "testing.md"
BLOCK = "test-durations"


@dataclass
class FileCost:
    """The tests of one file in one phase: how many, and their seconds (wall, CPU here, CPU in children)."""

    phase: str
    tests: int = 0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    child_cpu_s: float = 0.0
    outcomes: dict[str, int] = field(default_factory=lambda: defaultdict(int))


@dataclass
class Phase:
    """One report: its elapsed time, its tests, and the sum of their wall time per xdist worker (how even the
    workers' loads were: the busiest bounds the phase)."""

    name: str
    elapsed_s: float
    tests: int
    workers: dict[str, float] = field(default_factory=lambda: defaultdict(float))


def outcome(case: ET.Element) -> str:
    for kind in ("failure", "error", "skipped"):
        if case.find(kind) is not None:
            return kind
    return "passed"


def read(paths: list[Path]) -> tuple[list[Phase], dict[tuple[str, str], FileCost]]:
    """Phases and per-(file, phase) costs of the JUnit XML reports ``paths`` (the phase is the report's stem)."""
    phases: list[Phase] = []
    files: dict[tuple[str, str], FileCost] = {}
    for path in paths:
        try:
            root = ET.parse(path).getroot()
        except (OSError, ET.ParseError) as exc:
            raise SystemExit(f"moose: error: report {str(path)!r} is not a JUnit XML file ({exc})") from None
        suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
        for suite in suites:
            cases = suite.findall("testcase")
            phase = Phase(path.stem, float(suite.get("time", "0")), len(cases))
            phases.append(phase)
            for case in cases:
                name = case.get("classname", "").rsplit(".", 1)[-1] + ".py"
                cost = files.setdefault((name, path.stem), FileCost(path.stem))
                props = {p.get("name"): p.get("value") for p in case.iter("property")}
                phase.workers[props.get("worker") or "?"] += float(case.get("time", "0"))
                cost.tests += 1
                cost.wall_s += float(case.get("time", "0"))
                cost.cpu_s += float(props.get("cpu_s") or 0.0)
                cost.child_cpu_s += float(props.get("child_cpu_s") or 0.0)
                cost.outcomes[outcome(case)] += 1
    return phases, files


def table(phases: list[Phase], files: dict[tuple[str, str], FileCost], top: int) -> str:
    """Markdown: the phases, then the ``top`` most expensive files (by the sum of wall time) and the rest in one row."""
    lines = ["| phase | tests | elapsed (s) | test time per worker (s) |", "|---|---:|---:|---|"]
    lines += [f"| {p.name} | {p.tests} | {p.elapsed_s:.0f} | "
              f"{', '.join(f'{w} {t:.0f}' for w, t in sorted(p.workers.items()))} |" for p in phases]
    total_wall = sum(c.wall_s for c in files.values())
    total_cpu = sum(c.cpu_s for c in files.values())
    total_child = sum(c.child_cpu_s for c in files.values())
    lines += ["", "| file | phase | tests | test time (s) | share | CPU in the test process (s) | "
                  "CPU in child processes (s) |", "|---|---|---:|---:|---:|---:|---:|"]
    ranked = sorted(files.items(), key=lambda kv: -kv[1].wall_s)
    for (name, phase), c in ranked[:top]:
        share = c.wall_s / total_wall if total_wall else 0.0
        lines.append(f"| `{name}` | {phase} | {c.tests} | {c.wall_s:.1f} | {100 * share:.1f} % | {c.cpu_s:.1f} | "
                     f"{c.child_cpu_s:.1f} |")
    rest = [c for _, c in ranked[top:]]
    if rest:
        wall = sum(c.wall_s for c in rest)
        lines.append(f"| {len(rest)} other files | | {sum(c.tests for c in rest)} | {wall:.1f} | "
                     f"{100 * wall / total_wall if total_wall else 0.0:.1f} % | {sum(c.cpu_s for c in rest):.1f} | "
                     f"{sum(c.child_cpu_s for c in rest):.1f} |")
    lines.append(f"| **all** | | {sum(c.tests for c in files.values())} | {total_wall:.1f} | 100 % | "
                 f"{total_cpu:.1f} | {total_child:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("reports", nargs="*", type=Path, help=f"JUnit XML reports (default: {REPORTS}/*.xml)")
    parser.add_argument("--top", type=int, default=20, help="files listed one by one (default 20)")
    parser.add_argument("--docs", action="store_true", help=f"write the table into {DOCS.relative_to(ROOT)}")
    args = parser.parse_args(argv)
    if args.top < 1:
        parser.error(f"--top = {args.top} is invalid: at least 1")
    paths = args.reports or sorted(REPORTS.glob("*.xml"))
    if not paths:
        parser.error(f"no reports in {REPORTS}: run make test first, or name the reports")
    text = table(*read(paths), top=args.top)
    print(text, end="")
    if args.docs:
        sys.path.insert(0, str(ROOT / "src"))
        from moose.reproduce.render import update_document

        update_document(DOCS, {BLOCK: text})
    return 0


if __name__ == "__main__":
    sys.exit(main())
