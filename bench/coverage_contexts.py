"""Which lines only the processes of one graph test file, or of one test, ran: how ``tests/conftest.py`` chooses
the graph tests whose processes are not measured (``UNMEASURED_CHILDREN``, ``MEASURED_CASES``).

    MOOSE_COVERAGE_CONTEXTS=1 make test
    python bench/coverage_contexts.py .coverage-data/.coverage [--unmeasured FILE ...]

With ``MOOSE_COVERAGE_CONTEXTS=1`` every graph test's processes are measured, each in a coverage context named
``child:NODEID``; the test processes' own lines are in the empty context.  This prints, per test file, the lines
that only its tests' processes ran (no other file's, nor any test process), and with ``--unmeasured`` the lines the
suite would lose if the processes of those files were not measured, with the tests of those files whose processes
ran each such line (keep one of them measured to keep the line).
"""
from __future__ import annotations

import argparse
import collections
import sqlite3
from pathlib import Path
from typing import Optional, Sequence

from coverage.numbits import numbits_to_nums

Line = tuple[str, int]


def line_contexts(data_file: Path) -> dict[Line, set[str]]:
    """Every measured line (file, number) and the contexts that ran it."""
    with sqlite3.connect(data_file) as db:
        contexts = dict(db.execute("select id, context from context"))
        files = dict(db.execute("select id, path from file"))
        out: dict[Line, set[str]] = collections.defaultdict(set)
        for file_id, context_id, bits in db.execute("select file_id, context_id, numbits from line_bits"):
            for number in numbits_to_nums(bits):
                out[(files[file_id], number)].add(contexts[context_id])
    return out


def test_file(context: str) -> Optional[str]:
    """The test file of a ``child:NODEID`` context (None for a test process's own lines)."""
    return context[len("child:"):].split("::")[0].rsplit("/", 1)[-1] if context.startswith("child:") else None


def lost_lines(lines: dict[Line, set[str]], unmeasured: set[str]) -> dict[Line, set[str]]:
    """The lines only the processes of tests in ``unmeasured`` files ran, with those tests."""
    return {line: contexts for line, contexts in lines.items()
            if all(test_file(c) in unmeasured for c in contexts)}


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data_file", type=Path)
    parser.add_argument("--unmeasured", nargs="*", default=[], help="test files (basename) not to measure")
    args = parser.parse_args(argv)
    lines = line_contexts(args.data_file)
    print(f"{len(lines)} lines measured")
    files = sorted({f for cs in lines.values() for c in cs if (f := test_file(c))})
    for name in files:
        only = lost_lines(lines, {name})
        print(f"{name}: {len(only)} lines only its processes ran")
    if args.unmeasured:
        lost = lost_lines(lines, set(args.unmeasured))
        print(f"\nnot measuring {', '.join(args.unmeasured)} loses {len(lost)} lines:")
        for (path, number), contexts in sorted(lost.items()):
            text = Path(path).read_text(encoding="utf-8").splitlines()[number - 1].strip()
            tests = sorted(c[len("child:"):].split("::", 1)[1] for c in contexts)
            print(f"  {path}:{number}  {text[:80]}\n      run by {len(tests)}: {', '.join(tests[:6])}"
                  + (" …" if len(tests) > 6 else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
