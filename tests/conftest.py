"""Test-run isolation: a DDS domain of each test's own on loopback only, a private compile cache, and no process that
outlives the run."""
from __future__ import annotations

import ast
import contextlib
import os
import resource
import subprocess
import sys
import threading
import uuid
from pathlib import Path
from typing import Any, Iterator, Optional

import pytest

from isolation import claim_domain, realtime_slot, release_domain
from ros2_prefix import cyclone_localhost, dds_env, ros_env  # noqa: F401 - fixtures of the ROS 2 prefix tests

SESSION_MARK = "MOOSE_TEST_SESSION"
"""Environment variable every process a test run starts inherits: the run's own mark."""

REAPER = r'''
import os, signal, sys, time
mark = sys.argv[1].encode()
sys.stdin.buffer.read()  # end of file: the test run ended, normally or killed (the kernel closes the pipe)
me = os.getpid()

def marked():
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit() and int(entry) != me:
            try:
                with open(f"/proc/{entry}/environ", "rb") as f:
                    if mark in f.read().split(b"\0"):
                        pids.append(int(entry))
            except OSError:
                pass
    return pids

for sig, grace in ((signal.SIGTERM, 3.0), (signal.SIGKILL, 1.0)):
    pids = marked()
    for pid in pids:
        try:
            os.kill(pid, sig)
        except OSError:
            pass
    deadline = time.monotonic() + grace
    while pids and time.monotonic() < deadline:
        time.sleep(0.05)
        pids = marked()
'''


def pytest_configure(config: pytest.Config) -> None:
    """The tests play Ctrl-C as a terminal sends it to its foreground job.  A test run started as a background job
    of a script (``.ci/run &``, ``nohup``: job control off) inherits SIGINT ignored, and so does every process it
    starts; ``moose sweep`` rightly leaves an ignored SIGINT ignored (:class:`moose.cli.common.Interrupts`) and ran
    to its end under the Ctrl-C test (ci4; the test passed when run at a terminal).  Python's own handler is put
    back here, in the controller and every xdist worker: the processes the tests start then get SIGINT's default
    disposition, as at a terminal."""
    import signal

    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session", autouse=True)
def reaper() -> Iterator[None]:
    """Every process started by this test run (and its children, whatever process group they chose) carries
    :data:`SESSION_MARK` in its environment; a reaper outside the run's process group waits for the run to end —
    also a SIGKILLed one — and then ends every process with the mark still running (SIGTERM, then SIGKILL)."""
    mark = f"{SESSION_MARK}={uuid.uuid4().hex}"
    key, value = mark.split("=", 1)
    os.environ[key] = value
    proc = subprocess.Popen([sys.executable, "-c", REAPER, mark], stdin=subprocess.PIPE, start_new_session=True)
    yield
    assert proc.stdin is not None
    proc.stdin.close()  # the run is over: end what it left behind
    proc.wait(timeout=30)


CPU_AT_SETUP = pytest.StashKey[tuple[float, float]]()


def _cpu_seconds() -> tuple[float, float]:
    """CPU seconds (user + system) of this process and of the child processes it waited for (and theirs)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> Iterator[None]:
    item.stash[CPU_AT_SETUP] = _cpu_seconds()
    return (yield)


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_teardown(item: pytest.Item) -> Iterator[None]:
    """The CPU seconds a test took, setup to teardown, in the test process and in the child processes it waited
    for (nodes, CLI runs, and their children), and the xdist worker that ran it, as properties of its report:
    ``--junitxml`` writes them and bench/test_durations.py tabulates them (docs/testing.md, "Testing")."""
    result = yield
    if CPU_AT_SETUP in item.stash:
        (own0, children0), (own1, children1) = item.stash[CPU_AT_SETUP], _cpu_seconds()
        item.user_properties += [("cpu_s", f"{own1 - own0:.3f}"), ("child_cpu_s", f"{children1 - children0:.3f}"),
                                 ("worker", os.environ.get("PYTEST_XDIST_WORKER", "main"))]
    return result


COVERAGE_CHILDREN = "COVERAGE_PROCESS_CONFIG"
"""How coverage.py (``patch = subprocess``) gives its configuration to the Python processes a test starts: the
base64 of its JSON."""
GRAPH_COVERAGE_PACKAGES = ["moose_ros", "moose.canbus"]
"""What the processes of a graph test measure: the node shells, runtimes, bag code and the CAN bridge's loop, which
only node processes run (measured: of the lines only child processes ran, those of the core were the CAN bridge's,
but for a few).  The core's planners, plant and observer run in the test processes' own tests too, and tracing them
in the nodes doubled a graph's CPU time (the lockstep full graph: 14-16 CPU-seconds untraced, 32-35 traced)."""


def children_measuring(packages: list[str], config: str, context: Optional[str] = None) -> str:
    """coverage.py's configuration for child processes (``config``, as coverage serialises it) measuring only
    ``packages`` (in the coverage context ``context``, if given); a configuration without ``source_pkgs`` is an
    error, not silently left as it was."""
    import base64
    import json

    values = json.loads(base64.b64decode(config))
    if "source_pkgs" not in values:
        raise RuntimeError(f"{COVERAGE_CHILDREN} holds no source_pkgs: coverage.py changed how it passes its "
                           "configuration to child processes (tests/conftest.py)")
    values["source_pkgs"] = packages
    if context is not None:
        values["context"] = context
    return base64.b64encode(json.dumps(values).encode()).decode()


UNMEASURED_CHILDREN = {"test_fault_matrix.py", "test_baselines.py", "test_graph_equivalence.py",
                       "test_lockstep_pauses.py", "test_network_confinement.py", "test_isolation.py"}
"""Graph test files whose processes measure nothing, but for the tests of :data:`MEASURED_CASES`.  Measured with
:data:`CONTEXTS` (2026-12-02): of the 14,028 lines the suite ran, only 6 were run by these files' processes
alone, and the tests of :data:`MEASURED_CASES` run all 6; the six files' processes took about 800 of the suite's
1,330 child CPU-seconds, traced.  Not measuring a process can only make coverage look lower, never higher: a line
that only unmeasured processes run shows as missed."""
MEASURED_CASES = {
    "tests/test_fault_matrix.py::test_fault[full-mpc_planner-stall]",  # a node's own stall; a planner's stale plan
    "tests/test_fault_matrix.py::test_fault[full-observer-kill]",  # a node silent on /diagnostics
    "tests/test_fault_matrix.py::test_fault[can-motion_controller-kill]",  # the ECUs' command timeout
    "tests/test_lockstep_pauses.py::test_a_paused_lockstep_run_is_the_loops_run[launcher]",  # the monitor behind
}
"""Tests of :data:`UNMEASURED_CHILDREN` whose processes are measured after all: they run the lines that no other
test's processes run (bench/coverage_contexts.py names the tests that run each line)."""
UNMEASURED_CASES = {"tests/test_rclpy_graph.py::test_full_graph_on_rclpy_reproduces_the_lockstep_loop"}
"""Graph tests in measured files whose processes measure nothing: the full graph on rclpy in lockstep took 83 child
CPU-seconds traced (ci22), and a contexts run on ci24's clone found 2 lines only its processes ran
(``RclpyNode.node_names`` and the launcher's domain check on rclpy), which ``tests/test_rclpy_runtime.py`` runs."""
CONTEXTS = "MOOSE_COVERAGE_CONTEXTS"
"""``MOOSE_COVERAGE_CONTEXTS=1 make test``: every graph test's processes are measured, each in a coverage context
named after the test (``child:NODEID``); ``python bench/coverage_contexts.py .coverage-data/.coverage`` then says
which lines only the processes of each file and test ran (how :data:`UNMEASURED_CHILDREN` was chosen)."""


def children_config(item: pytest.Item, config: str) -> Optional[str]:
    """What the processes a graph or real-time test starts measure under coverage: :data:`GRAPH_COVERAGE_PACKAGES`,
    nothing (None) for :data:`UNMEASURED_CHILDREN`, :data:`UNMEASURED_CASES` and for a test marked ``realtime`` (its
    verdict is the wall clock's: tracing doubled a process's CPU time, and the CAN flood's bridge, a core busy decoding
    the flood, sent a command late in two CI runs of 2026-12-03), and with :data:`CONTEXTS` set, everything of those
    packages in a context of the test's own."""
    if os.environ.get(CONTEXTS) == "1":
        return children_measuring(GRAPH_COVERAGE_PACKAGES, config, context=f"child:{item.nodeid}")
    if item.get_closest_marker("realtime") is not None:
        return None  # judged against the wall clock: the processes run as they would, not under a tracer
    if item.nodeid in UNMEASURED_CASES or (item.path.name in UNMEASURED_CHILDREN and item.nodeid not in MEASURED_CASES):
        return None
    return children_measuring(GRAPH_COVERAGE_PACKAGES, config)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: Any) -> Iterator[None]:
    """Under coverage (``make test``), the processes a ``graph`` or ``realtime`` test starts (its nodes, launchers,
    tools: setup and module fixtures included) measure what :func:`children_config` says."""
    config = os.environ.get(COVERAGE_CHILDREN)
    if config is None or (item.get_closest_marker("graph") is None and item.get_closest_marker("realtime") is None):
        return (yield)
    children = children_config(item, config)
    if children is None:
        del os.environ[COVERAGE_CHILDREN]
    else:
        os.environ[COVERAGE_CHILDREN] = children
    try:
        return (yield)
    finally:
        os.environ[COVERAGE_CHILDREN] = config


@pytest.fixture(autouse=True)
def realtime(request: pytest.FixtureRequest) -> Iterator[None]:
    """A test marked ``realtime`` holds the machine's real-time slot (tests/isolation.py) while it runs;
    ``realtime(slot=False)``: it runs in the serial phase without it (it starts test runs whose own real-time tests
    take the slot, one at a time)."""
    marker = request.node.get_closest_marker("realtime")
    if marker is None or not marker.kwargs.get("slot", True):
        yield
        return
    with realtime_slot():
        yield


@pytest.fixture(scope="session", autouse=True)
def dds_loopback(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Cyclone DDS bound to the loopback interface, for every process of the test run, and a domain of the run's
    own outside the tests' (which :func:`dds_domain` gives each)."""
    config = tmp_path_factory.mktemp("dds") / "cyclonedds.xml"
    config.write_text(
        '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
        "<AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>"
    )
    os.environ["CYCLONEDDS_URI"] = config.as_uri()
    os.environ["MOOSE_RUNTIME"] = "dds"
    os.environ["ROS_DOMAIN_ID"] = str(claim_domain())  # session fixtures' (none starts a graph today); held to the end
    os.environ.setdefault("MOOSE_CACHE_DIR", str(Path.home() / ".cache" / "moose"))


CLOSE_WAIT = 5.0
"""Seconds a test's end waits for Cyclone DDS to delete the domain the test's process used (a deletion still running
then goes on in its thread; the domain's discovery port stays bound meanwhile, so no test claims it)."""


def close_cyclone_domain(domain: int) -> None:
    """Delete this process's Cyclone DDS domain ``domain`` if a node of moose_ros's runtime made it here and none is
    left in it (``moose_ros.runtime.dds.close_domain``): else a test process keeps every domain it ever used, with
    its threads, sockets and discovery port."""
    dds = sys.modules.get("moose_ros.runtime.dds")
    if dds is None:
        return
    closing = threading.Thread(target=dds.close_domain, args=(domain,), name=f"close-domain-{domain}", daemon=True)
    closing.start()
    closing.join(CLOSE_WAIT)


@contextlib.contextmanager
def own_domain() -> Iterator[int]:
    """ROS_DOMAIN_ID set to a domain claimed for the block (tests/isolation.py), and released after it."""
    before = os.environ.get("ROS_DOMAIN_ID")
    domain = claim_domain()
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    try:
        yield domain
    finally:
        if before is None:
            del os.environ["ROS_DOMAIN_ID"]
        else:
            os.environ["ROS_DOMAIN_ID"] = before
        close_cyclone_domain(domain)
        release_domain(domain)


@pytest.fixture(scope="module", autouse=True)
def dds_module_domain() -> Iterator[int]:
    """A DDS domain of the test file's own, for what its module fixtures start (autouse: made before them)."""
    with own_domain() as domain:
        yield domain


@pytest.fixture(autouse=True)
def dds_domain(request: pytest.FixtureRequest, dds_module_domain: int) -> Iterator[int]:
    """A DDS domain of the test's own: no participant of another test, earlier or at once, meets its processes
    (a writer left behind by an earlier test is never matched by this one's readers).  A file marked
    ``dds_module_domain`` keeps its file's domain for its tests: a module fixture's graph they all talk to."""
    if request.node.get_closest_marker("dds_module_domain") is not None:
        yield dds_module_domain
        return
    with own_domain() as domain:
        yield domain


@pytest.fixture(scope="session")
def paper_runs() -> Any:
    """The runs of the paper's cases with the default configuration and seed 0, each made once for the whole test
    session (:class:`moose.reproduce.RunCache`): the claims, the tables and the closed-loop tests share them."""
    from moose.config import load_config
    from moose.reproduce import RunCache

    return RunCache(load_config())



SHARED_FIXTURES = ("paper_runs",)
"""Session fixtures too costly to make twice: in a parallel run (``make test``: ``pytest -n 2 --dist loadgroup``)
every file whose tests use one runs in the same xdist worker, so the fixture is made once, as in a serial run."""


def xdist_group(nodeid: str, shared: dict[str, str]) -> str:
    """The group of a test for ``--dist loadgroup``: the group it names (``pytest.mark.xdist_group``, as xdist
    appends it to the test's id), else the shared fixture its file uses (``shared``: file name → fixture), else its
    file.  A file is one group: its module-scoped fixtures are made once, and its processes and temporary names
    never meet their twins in another worker."""
    if "@" in nodeid.rsplit("::", 1)[-1]:
        return nodeid.rsplit("@", 1)[-1]
    path = nodeid.split("::", 1)[0]
    return shared.get(Path(path).name, path)


def files_sharing_fixtures(tests: Path = Path(__file__).parent) -> dict[str, str]:
    """Test file name → the fixture of :data:`SHARED_FIXTURES` that one of its functions (a test or a fixture)
    takes as a parameter: read from the source, since the xdist controller does not collect the tests."""
    found = {}
    for path in sorted(tests.glob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                names = [a.arg for a in (*node.args.posonlyargs, *node.args.args, *node.args.kwonlyargs)]
                for fixture in SHARED_FIXTURES:
                    if fixture in names:
                        found.setdefault(path.name, fixture)
    return found


def _is_slow_mark(node: ast.expr) -> bool:
    """``pytest.mark.slow``, bare or called."""
    node = node.func if isinstance(node, ast.Call) else node
    return isinstance(node, ast.Attribute) and node.attr == "slow" and isinstance(node.value, ast.Attribute) \
        and node.value.attr == "mark"


def slow_tests(tests: Path = Path(__file__).parent) -> dict[str, set[str]]:
    """Test file name → the names of its test functions marked ``slow`` (by a decorator, or every one of them by
    the file's ``pytestmark``), read from the source as :func:`files_sharing_fixtures`."""
    found: dict[str, set[str]] = {}
    for path in sorted(tests.glob("test_*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        file_marks = [mark for node in tree.body if isinstance(node, ast.Assign)
                      and any(isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets)
                      for mark in (node.value.elts if isinstance(node.value, (ast.List, ast.Tuple)) else [node.value])]
        every = any(_is_slow_mark(mark) for mark in file_marks)
        functions = [node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]
        found[path.name] = {f.name for f in functions if f.name.startswith("test")
                            and (every or any(_is_slow_mark(d) for d in f.decorator_list))}
    return found


def slowest_first(groups: dict[str, list[str]], slow: dict[str, set[str]]) -> list[str]:
    """The groups of the parallel phase in the order they are handed out: most tests marked ``slow`` first (then the
    most tests).  The workers take the next group whenever they finish one, so the longest groups start at once and
    the short ones fill in at the end (xdist's own order, most tests first, left a file of two graph runs for last,
    one worker running it while the other had nothing left)."""

    def slow_count(nodeids: list[str]) -> int:
        def function(nodeid: str) -> str:
            return nodeid.split("::")[-1].split("[", 1)[0].split("@", 1)[0]

        return sum(function(n) in slow.get(Path(n.split("::", 1)[0]).name, ()) for n in nodeids)

    return sorted(groups, key=lambda group: (-slow_count(groups[group]), -len(groups[group]), group))


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``--dist loadgroup`` with the groups of :func:`xdist_group`, handed out slowest first
    (:func:`slowest_first`).  xdist's own loadgroup marks a test's group by rewriting its id, which pytest 9.2 no
    longer lets it do (every test would be scheduled alone, silently): the groups are therefore given to the
    scheduler here, from the ids it is sent."""
    if config.getoption("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    shared, slow = files_sharing_fixtures(), slow_tests()

    class GroupScheduling(LoadScopeScheduling):
        ordered = False

        def _split_scope(self, nodeid: str) -> str:
            return xdist_group(nodeid, shared)

        def _assign_work_unit(self, node: Any) -> None:
            if not self.ordered:  # the queue is complete when the first group is handed out
                queue = {group: self.workqueue[group] for group in slowest_first(
                    {group: list(tests) for group, tests in self.workqueue.items()}, slow)}
                self.workqueue.clear()
                self.workqueue.update(queue)
                self.ordered = True
            super()._assign_work_unit(node)

    return GroupScheduling(config, log)
