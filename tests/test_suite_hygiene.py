"""The suite's own rules, checked on its source: every expected failure names the exception it expects and the
paper claim it records, and no test is skipped or expected to fail without saying why."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path
from typing import Optional

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent


def markers(name: str) -> list[tuple[str, int, Optional[ast.Call]]]:
    """Every ``pytest.mark.<name>`` in the test files: (file, line, the call, or None for a bare marker)."""
    found = []
    for path in sorted(TESTS.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        calls = {id(n.func): n for n in ast.walk(tree) if isinstance(n, ast.Call)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr == name and isinstance(node.value, ast.Attribute) \
                    and node.value.attr == "mark":
                found.append((path.name, node.lineno, calls.get(id(node))))
    return found


def test_every_xfail_names_its_exception_and_the_paper_claim_or_the_bug() -> None:
    for file, line, call in markers("xfail"):
        where = f"{file}:{line}"
        assert call is not None, f"{where}: a bare xfail marker (no raises=, no reason=)"
        keywords = {k.arg: k.value for k in call.keywords}
        assert "raises" in keywords, f"{where}: xfail without raises= counts any crash as the expected failure"
        reason = keywords.get("reason")
        text = "".join(c.value for c in ast.walk(reason) if isinstance(c, ast.Constant) and isinstance(c.value, str)) \
            if reason is not None else ""
        assert ("paper claim" in text and "Dodging the Moose" in text) or text.startswith("known bug: "), \
            f"{where}: the reason must name the paper claim, or the known bug it pins"
        assert not (keywords.get("strict") is not None and isinstance(keywords["strict"], ast.Constant)
                    and keywords["strict"].value is False), f"{where}: a non-strict xfail hides a claim that is met"


def test_no_unconditional_skip() -> None:
    for file, line, call in markers("skip"):
        assert call is not None and any(k.arg == "reason" for k in call.keywords), f"{file}:{line}: skip without reason"
    for file, line, call in markers("skipif"):
        has_reason = call is not None and any(k.arg == "reason" for k in call.keywords)
        assert has_reason, f"{file}:{line}: skipif without reason"


def test_every_test_using_a_shared_fixture_is_in_that_fixtures_parallel_group(request: pytest.FixtureRequest) -> None:
    """The groups of ``make test``'s parallel phase (tests/conftest.py) come from the source: the collected tests
    say which really use a shared session fixture, and each of those is in the fixture's group, as every test of
    its file."""
    from conftest import SHARED_FIXTURES, files_sharing_fixtures, xdist_group

    shared = files_sharing_fixtures()
    users = [item for item in request.session.items if set(getattr(item, "fixturenames", ())) & set(SHARED_FIXTURES)]
    if not users:
        pytest.skip("no test of this selection uses a shared fixture")
    for item in users:
        fixture = next(f for f in SHARED_FIXTURES if f in getattr(item, "fixturenames", ()))
        assert xdist_group(item.nodeid, shared) == fixture, item.nodeid
    others = [item for item in request.session.items if item.path.name not in shared]
    for item in others:
        assert xdist_group(item.nodeid, shared) == item.nodeid.split("::", 1)[0]
    assert xdist_group("tests/test_tire.py::test_a[1-2]@mine", shared) == "mine"  # a group named by a marker


@pytest.mark.slow
def test_the_parallel_run_keeps_each_file_in_one_worker() -> None:
    """``pytest -n 2 --dist loadgroup`` with the suite's scheduler: every test of a file runs in the same worker
    (with xdist's own loadgroup on pytest 9.2 each test was scheduled alone)."""
    files = ("tests/test_tire.py", "tests/test_kinematics.py")
    out = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "--dist", "loadgroup", "-p", "no:randomly",
                          "-p", "no:cacheprovider", "-v", *files], cwd=TESTS.parent, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    workers: dict[str, set[str]] = {f: set() for f in files}
    for line in out.stdout.splitlines():
        found = re.match(r"\[(gw\d+)\] \[\s*\d+%\] PASSED (\S+?)::", line)
        if found:
            workers[found.group(2)].add(found.group(1))
    assert all(len(w) == 1 for w in workers.values()), workers


def test_the_parallel_phase_hands_out_the_slowest_groups_first() -> None:
    """The groups with the most tests marked ``slow`` go first, then those with the most tests (tests/conftest.py):
    read from the source, a parametrized slow test counting once per case."""
    from conftest import slow_tests, slowest_first

    slow = slow_tests()
    assert "test_wheels_install_into_a_fresh_environment_and_run_from_anywhere" in slow["test_install.py"]  # pytestmark
    assert "test_failing_cases_are_recorded_and_the_sweep_goes_on" in slow["test_sweep.py"]  # a decorator
    assert "test_an_unreachable_cluster_is_refused_before_any_case" not in slow["test_sweep.py"]
    failing, bad = "test_failing_cases_are_recorded_and_the_sweep_goes_on", "test_bad_input_is_refused_before_any_case"
    groups = {"tests/test_tire.py": [f"tests/test_tire.py::test_{i}" for i in range(5)],
              "paper_runs": [f"tests/test_sweep.py::{bad}[a]"],
              "tests/test_sweep.py": [f"tests/test_sweep.py::{failing}[0]", f"tests/test_sweep.py::{failing}[1]",
                                      f"tests/test_sweep.py::{bad}"],
              "tests/test_install.py": ["tests/test_install.py::"
                                        "test_wheels_install_into_a_fresh_environment_and_run_from_anywhere"]}
    assert slowest_first(groups, slow) == ["tests/test_sweep.py", "tests/test_install.py", "tests/test_tire.py",
                                           "paper_runs"]


@pytest.mark.slow
def test_the_parallel_run_hands_out_groups_in_that_order() -> None:
    """One worker runs the groups in the order it is handed them: the file of more tests first, although it is
    named last and xdist's own reordering is off."""
    files = ("tests/test_kinematics.py", "tests/test_tire.py")  # 5 and 7 tests, none slow
    out = subprocess.run([sys.executable, "-m", "pytest", "-n", "1", "--dist", "loadgroup", "--no-loadscope-reorder",
                          "-p", "no:randomly", "-p", "no:cacheprovider", "-v", *files], cwd=TESTS.parent,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    ran = [found.group(1) for found in re.finditer(r"\[gw0\] \[\s*\d+%\] PASSED (\S+?)::", out.stdout)]
    assert ran == ["tests/test_tire.py"] * 7 + ["tests/test_kinematics.py"] * 5, ran


def test_a_graph_tests_processes_measure_the_packages_only_they_run() -> None:
    """The configuration coverage.py gives child processes, as it serialises it, with only the graph's packages to
    measure and every other setting kept; one it no longer recognises is an error."""
    import base64
    import json

    from coverage.config import CoverageConfig

    from conftest import GRAPH_COVERAGE_PACKAGES, children_measuring

    config = CoverageConfig()
    config.source_pkgs, config.parallel, config.sigterm = ["moose", "moose_ros"], True, True
    narrowed = CoverageConfig.deserialize(children_measuring(GRAPH_COVERAGE_PACKAGES, config.serialize()))
    assert narrowed.source_pkgs == GRAPH_COVERAGE_PACKAGES == ["moose_ros", "moose.canbus"]
    assert (narrowed.parallel, narrowed.sigterm) == (True, True)
    with pytest.raises(RuntimeError, match="holds no source_pkgs"):
        children_measuring(GRAPH_COVERAGE_PACKAGES, base64.b64encode(json.dumps({"parallel": True}).encode()).decode())



def test_unmeasured_graph_processes_are_those_of_the_listed_files_but_the_listed_cases(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """tests/conftest.py's choice of graph tests whose processes coverage does not measure: the files of
    UNMEASURED_CHILDREN, but the tests of MEASURED_CASES, and the tests of UNMEASURED_CASES (each listed test one the
    suite collects), and no test marked realtime; with
    MOOSE_COVERAGE_CONTEXTS=1 every graph test's processes are measured, in a context named after the test."""
    import base64
    import json
    from types import SimpleNamespace

    from coverage.config import CoverageConfig

    from conftest import CONTEXTS, MEASURED_CASES, UNMEASURED_CASES, UNMEASURED_CHILDREN, children_config

    assert {Path(case.split("::")[0]).name for case in MEASURED_CASES} <= UNMEASURED_CHILDREN
    assert not {Path(case.split("::")[0]).name for case in UNMEASURED_CASES} & UNMEASURED_CHILDREN
    files = sorted({case.split("::")[0] for case in MEASURED_CASES | UNMEASURED_CASES})
    collected = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:randomly", *files],
                               capture_output=True, text=True, timeout=120, cwd=ROOT).stdout.splitlines()
    listed = MEASURED_CASES | UNMEASURED_CASES
    assert listed <= set(collected), listed - set(collected)
    config = CoverageConfig()
    config.source_pkgs = ["moose", "moose_ros"]
    serialised = config.serialize()

    def item(nodeid: str, *marks: str) -> object:
        return SimpleNamespace(nodeid=nodeid, path=ROOT / nodeid.split("::")[0],
                               get_closest_marker=lambda name: name if name in marks else None)

    case = sorted(MEASURED_CASES)[0]
    unmeasured = case.split("[")[0] + "[another]"
    monkeypatch.delenv(CONTEXTS, raising=False)
    assert children_config(item(unmeasured), serialised) is None  # type: ignore[arg-type]
    assert children_config(item(case), serialised) is not None  # type: ignore[arg-type]
    assert children_config(item("tests/test_ros_graph.py::test_x"), serialised) is not None  # type: ignore[arg-type]
    skipped = sorted(UNMEASURED_CASES)[0]
    assert children_config(item(skipped), serialised) is None  # type: ignore[arg-type]
    assert children_config(item(skipped + "_too"), serialised) is not None  # type: ignore[arg-type]  # its file's others
    assert children_config(item("tests/test_ros_graph.py::test_x", "realtime"), serialised) is None  # type: ignore[arg-type]
    monkeypatch.setenv(CONTEXTS, "1")
    labelled = children_config(item(unmeasured), serialised)  # type: ignore[arg-type]
    assert labelled is not None and json.loads(base64.b64decode(labelled))["context"] == f"child:{unmeasured}"
