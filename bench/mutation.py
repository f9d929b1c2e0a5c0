"""Mutation score of the safety- and verdict-critical modules (mutmut), per module.

    python bench/mutation.py                    # every module of MODULES (about 12 min on 2 cores)
    python bench/mutation.py canbus.codec planner.fbl   # some of them
    python bench/mutation.py --table            # only print the table from the stored results
    python bench/mutation.py --docs             # ... and write it into docs/testing.md

Each module is mutated in a temporary copy of the working tree (so the tree itself never holds a
mutant), with ``mutmut run`` over the module's tests (:data:`MODULES`, without the ``graph`` and
``slow`` ones, which run subprocesses that import the unmutated package); mutmut maps every mutant to
the tests that execute its function and runs only those.  The result of each module — counts and
every surviving mutant's diff — is stored in ``bench/results/mutation/<module>.json``; the table is
made from those files, so a module can be re-run alone.  A survivor is either killed by a test or
listed in ``bench/mutation_equivalent.yaml`` with the reason it cannot be killed (an equivalent
mutant: no input tells it from the original); a survivor that is neither is an ``unexplained`` one
and makes the exit status 1.

Score = killed / (mutants − equivalent), killed including timeouts (a mutant that makes a test hang
is detected).  An entry of the list with ``kind: accepted`` is a survivor that is *not* equivalent
but is not killed, with the reason (e.g. a floating-point boundary no realistic input reaches); it
stays in the score's denominator, so only proven equivalents raise the score.  Module-level
constants and dataclass defaults are not mutated by mutmut (it mutates function bodies); those are
checked by the parameter tests.

Caches: a function cached with ``functools.lru_cache`` (the plant's compiled RK4, the EKF's, the
DBC) would keep the first test's result — built from unmutated code — for the rest of the process,
and mutmut would also record only the first test as covering the cached function.  The copy's
``tests/conftest.py`` therefore clears every ``moose`` cache before each test (mutation runs only).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results" / "mutation"
EQUIVALENT = ROOT / "bench" / "mutation_equivalent.yaml"
DOCS = ROOT / "docs" / "testing.md"
TARGET = 0.85
BEGIN, END = "<!-- mutation-table:begin (bench/mutation.py --docs) -->", "<!-- mutation-table:end -->"

MODULES: dict[str, list[str]] = {
    "verdict": ["test_verdict.py", "test_conventions.py"],
    "metrics": ["test_verdict.py", "test_metrics.py", "test_conventions.py"],
    "signals": ["test_signals.py", "test_verdict.py", "test_scenario.py", "test_detector.py"],
    "vehicle": ["test_vehicle.py", "test_conventions.py", "test_can_plant.py"],
    "motion": ["test_motion.py", "test_conventions.py", "test_can_plant.py"],
    "canbus.codec": ["test_can_codec.py", "test_can.py", "test_can_dbc.py", "test_can_bridge.py",
                     "test_conventions.py"],
    "canbus.safety": ["test_can_guard.py", "test_can_safety.py", "test_can_bridge.py", "test_can.py"],
    "minimum_risk": ["test_minimum_risk.py", "test_can_guard.py", "test_can_safety.py", "test_can_ecu.py",
                     "test_can_plant.py"],
    "canbus.bridge": ["test_can_bridge_core.py", "test_can_bridge.py", "test_can.py", "test_can_dbc.py",
                      "test_conventions.py"],
    "canbus.ecu": ["test_can_ecu.py", "test_can.py", "test_can_plant.py", "test_can_bridge.py", "test_conventions.py"],
    "planner.weight": ["test_weight.py"],
    "planner.fbl": ["test_fbl.py", "test_weight.py"],
}
"""Module (under src/moose) → the test files (under tests/) run against its mutants."""

CACHE_CLEARING = '''

@pytest.fixture(autouse=True)
def _mutation_fresh_caches():
    """Mutation runs only (bench/mutation.py): no test sees a cache filled from another mutant or test."""
    import functools
    import sys as _sys

    for name, module in list(_sys.modules.items()):
        if name == "moose" or name.startswith("moose."):
            for value in list(vars(module).values()):
                if isinstance(value, functools._lru_cache_wrapper):
                    value.cache_clear()
    yield
'''


def copy_tree(dest: Path) -> None:
    """The working tree's files that git knows or would add (tracked, or untracked and not ignored)."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                            check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        src, target = ROOT / name, dest / name
        if src.is_symlink():  # kept as a link (moose_ros/msg → moose_msgs/msg)
            target.parent.mkdir(parents=True, exist_ok=True)
            os.symlink(os.readlink(src), target)
        elif src.is_file():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)


def configure(dest: Path, module: str, tests: list[str]) -> None:
    path = "src/moose/" + module.replace(".", "/") + ".py"
    missing = [t for t in tests if not (dest / "tests" / t).exists()]
    if missing:
        raise SystemExit(f"mutation: error: tests of {module} not found: {missing}")
    # in-process tests only: a node or CLI subprocess imports the unmutated package (and takes seconds)
    selection = [f"tests/{t}" for t in tests] + ["-m", "not graph and not slow"]
    config = (
        "\n[tool.mutmut]\n"
        'source_paths = ["src/"]\n'
        f"only_mutate = [{json.dumps(path)}]\n"
        'also_copy = ["config/", "bags/", "ros2_ws/", "docs/", "docker/", "Makefile", "README.md"]\n'
        f"pytest_add_cli_args_test_selection = {json.dumps(selection)}\n"
        'pytest_add_cli_args = ["-p", "no:randomly", "-p", "no:cacheprovider", "-x", "-q"]\n'
        "use_git_change_detection = false\n"
    )
    pyproject = dest / "pyproject.toml"
    pyproject.write_text(pyproject.read_text() + config)
    conftest = dest / "tests" / "conftest.py"
    conftest.write_text(conftest.read_text() + CACHE_CLEARING)


def mutant_diff(workdir: Path, name: str, env: dict[str, str]) -> list[str]:
    """The changed lines (``-`` original, ``+`` mutant) of one mutant, stripped of indentation."""
    out = subprocess.run([str(Path(sys.executable).parent / "mutmut"), "show", name], cwd=workdir, env=env,
                         capture_output=True, text=True).stdout
    return [line[0] + line[1:].strip() for line in out.splitlines()
            if line[:1] in "+-" and not line.startswith(("+++", "---"))]


def function_of(name: str) -> str:
    """``moose.planner.fbl.xǁFeedbackLinearizationǁreference__mutmut_3`` → ``FeedbackLinearization.reference``."""
    tail = name.rsplit("__mutmut_", 1)[0]
    if "ǁ" in tail:
        parts = [p for p in tail.split("ǁ")[1:] if p]
        return ".".join(parts)
    return re.sub(r"^.*\.x_", "", tail)


STATUS = {1: "killed", 3: "killed", 0: "survived", 5: "no tests", 33: "no tests", 34: "skipped", 36: "timeout",
          -24: "timeout", 24: "timeout", 152: "timeout", 255: "timeout", None: "not checked"}


def run_module(module: str, jobs: int, keep: bool) -> dict[str, Any]:
    tests = MODULES[module]
    work = Path(tempfile.mkdtemp(prefix=f"moose-mutation-{module}-"))
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.pop("MUTANT_UNDER_TEST", None)
    env["MOOSE_CACHE_DIR"] = str(work / "cache")  # the mutants' compiled plants stay out of the user's cache
    started = time.monotonic()
    try:
        copy_tree(work)
        configure(work, module, tests)
        log = work / "mutmut.log"
        with open(log, "w") as out:
            code = subprocess.run([str(Path(sys.executable).parent / "mutmut"), "run", "--max-children", str(jobs)],
                                  cwd=work, env=env, stdout=out, stderr=subprocess.STDOUT).returncode
        meta = work / "mutants" / ("src/moose/" + module.replace(".", "/") + ".py.meta")
        if code != 0 or not meta.exists():
            tail = log.read_text(errors="replace")[-3000:]
            raise SystemExit(f"mutation: error: mutmut run failed for {module} (exit {code}):\n{tail}")
        exit_codes = json.loads(meta.read_text())["exit_code_by_key"]
        statuses = {name: STATUS.get(code, "suspicious") for name, code in exit_codes.items()}
        survivors = [{"name": name, "function": function_of(name), "diff": mutant_diff(work, name, env),
                      "status": status}
                     for name, status in sorted(statuses.items()) if status not in ("killed", "timeout")]
    finally:
        if keep:
            print(f"kept {work}", file=sys.stderr)
        else:
            shutil.rmtree(work, ignore_errors=True)
    counts: dict[str, int] = {}
    for status in statuses.values():
        counts[status] = counts.get(status, 0) + 1
    commit = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True, text=True)
    return {"module": module, "commit": commit.stdout.strip(), "mutmut": version("mutmut"), "tests": tests,
            "total": len(statuses), "counts": counts, "survivors": survivors,
            "seconds": round(time.monotonic() - started, 1)}


def load_equivalent() -> list[dict[str, Any]]:
    entries = yaml.safe_load(EQUIVALENT.read_text()) if EQUIVALENT.exists() else None
    return entries or []


def classify(result: dict[str, Any], equivalent: list[dict[str, Any]]) -> tuple[list, list]:
    """Survivors listed as equivalent (with their reasons) and unexplained survivors."""
    listed, unexplained = [], []
    for survivor in result["survivors"]:
        match = next((e for e in equivalent if e["module"] == result["module"]
                      and e["function"] == survivor["function"] and list(e["diff"]) == survivor["diff"]), None)
        (listed if match else unexplained).append((survivor, match))
    return listed, unexplained


def row(result: dict[str, Any], equivalent: list[dict[str, Any]]) -> dict[str, Any]:
    c = result["counts"]
    killed = c.get("killed", 0) + c.get("timeout", 0)
    listed, unexplained = classify(result, equivalent)
    proven = sum(1 for _, entry in listed if entry.get("kind", "equivalent") == "equivalent")
    judged = result["total"] - proven
    score = killed / judged if judged else 1.0
    return {"module": result["module"], "total": result["total"], "killed": killed, "timeout": c.get("timeout", 0),
            "equivalent": proven, "accepted": len(listed) - proven, "unexplained": len(unexplained), "score": score,
            "ok": score >= TARGET and not unexplained, "seconds": result["seconds"]}


def table(rows: list[dict[str, Any]]) -> str:
    lines = ["| module | mutants | killed | equivalent | not killed, reason given | unexplained | score "
             "| killed of all |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| `moose/{r['module'].replace('.', '/')}.py` | {r['total']} | {r['killed']} | {r['equivalent']} "
                     f"| {r['accepted']} | {r['unexplained']} | {100 * r['score']:.1f} % "
                     f"| {100 * r['killed'] / r['total']:.1f} % |")
    return "\n".join(lines)


def write_docs(text: str) -> None:
    design = DOCS.read_text()
    if BEGIN not in design or END not in design:
        raise SystemExit(f"mutation: error: {DOCS} has no {BEGIN} … {END} markers")
    head, rest = design.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    DOCS.write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("modules", nargs="*", metavar="MODULE", help=f"some of: {', '.join(MODULES)}")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="mutants run at once")
    parser.add_argument("--table", action="store_true", help="no run: the table from the stored results")
    parser.add_argument("--docs", action="store_true", help="write the table into docs/testing.md")
    parser.add_argument("--keep", action="store_true", help="keep the temporary tree (to inspect mutants)")
    args = parser.parse_args(argv)
    unknown = [m for m in args.modules if m not in MODULES]
    if unknown:
        parser.error(f"unknown module {unknown[0]!r}: expected one of {', '.join(MODULES)}")
    if not args.table:
        RESULTS.mkdir(parents=True, exist_ok=True)
        for module in args.modules or list(MODULES):
            print(f"mutating moose/{module.replace('.', '/')}.py against {', '.join(MODULES[module])} ...", flush=True)
            result = run_module(module, args.jobs, args.keep)
            (RESULTS / f"{module}.json").write_text(json.dumps(result, indent=1, ensure_ascii=False) + "\n")
    equivalent = load_equivalent()
    results = [json.loads((RESULTS / f"{m}.json").read_text()) for m in MODULES if (RESULTS / f"{m}.json").exists()]
    rows = [row(r, equivalent) for r in results]
    text = table(rows)
    commits = sorted({r.get("commit", "?") for r in results})
    text += f"\n\nRun on {', '.join(commits)} with mutmut {', '.join(sorted({r.get('mutmut', '?') for r in results}))}."
    print(text)
    for result in results:
        for survivor, _ in classify(result, equivalent)[1]:
            diff = "\n  ".join(survivor["diff"])
            print(f"\nunexplained survivor {survivor['name']} ({survivor['status']}):\n  {diff}")
    survivors = {(r["module"], s["function"], tuple(s["diff"])) for r in results for s in r["survivors"]}
    for entry in equivalent:
        if (entry["module"], entry["function"], tuple(entry["diff"])) not in survivors:
            print(f"\nlisted as equivalent but no longer a survivor (killed, or the code changed): {entry['module']}."
                  f"{entry['function']}: {entry['diff'][-1]}")
    missing = [m for m in MODULES if not (RESULTS / f"{m}.json").exists()]
    if missing:
        print(f"\nnot run yet: {', '.join(missing)}")
    if args.docs:
        write_docs(text)
    return 0 if rows and all(r["ok"] for r in rows) and not missing else 1


if __name__ == "__main__":
    sys.exit(main())
