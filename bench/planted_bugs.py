"""Plant known bugs one at a time in a copy of the tree and check that the default test run catches each.

    python bench/planted_bugs.py              # every bug of BUGS against its tests
    python bench/planted_bugs.py plant-torque-swap crc-dropped
    python bench/planted_bugs.py --list       # the bugs, their patches and tests

The nine bugs of the audit in issue 14 (five it caught, four it missed) are the table below, and one for each
assertion issue 25 found too weak to fail on a wrong result (the bug passed the old assertion), and one
for each bug found since.  Each is a
text replacement in one source file; the script copies the working tree to a temporary folder, runs the
bug's tests there unpatched first (they must pass: a failing baseline would count every bug as caught),
then applies the patch, runs them again, and reports ``caught`` (the tests fail) or ``MISSED``.  A patch
that no longer applies (the code moved on) is reported as ``stale``, never as caught.  The tests are
files of the default run (``make test``), so a caught bug is caught by it.  Exit status 0 when every bug
is caught.  Not part of CI (each bug costs a test run); run it after changing the code or the tests below.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mutation import copy_tree


@dataclasses.dataclass(frozen=True)
class Bug:
    name: str
    description: str
    path: str
    """File under the tree's root."""
    patch: tuple[tuple[str, str], ...]
    """(original text, buggy text) replacements; each original must occur exactly once."""
    tests: tuple[str, ...]
    """pytest arguments (test files or node ids under tests/)."""


PKG = "ros2_ws/src/moose_ros/moose_ros"
NODES = f"{PKG}/nodes"
BUGS = (
    Bug("plant-torque-swap", "rear-left / rear-right torque swapped in the plant", "src/moose/vehicle.py",
        (("t_rl = ca.fmin(ca.fmax(u[TORQUE_RL],", "t_rl = ca.fmin(ca.fmax(u[TORQUE_RR],"),
         ("t_rr = ca.fmin(ca.fmax(u[TORQUE_RR],", "t_rr = ca.fmin(ca.fmax(u[TORQUE_RL],")),
        ("tests/test_vehicle.py", "tests/test_conventions.py")),
    Bug("bridge-frame-swap", "rear-left / rear-right swapped in the bridge's CAN frame", "src/moose/canbus/bridge.py",
        (('{"TorqueRL": out.torque_rl, "TorqueRR": out.torque_rr}',
          '{"TorqueRL": out.torque_rr, "TorqueRR": out.torque_rl}'),),
        ("tests/test_can_bridge.py", "tests/test_conventions.py")),
    Bug("clearance-wrong-edge", "clearance computed from the wrong edge of the obstacle", "src/moose/signals.py",
        (("dy = np.maximum(self.y_min - y, y - self.y_max)", "dy = np.maximum(self.y_max - y, y - self.y_min)"),),
        ("tests/test_signals.py", "tests/test_verdict.py", "tests/test_metrics.py")),
    Bug("simulator-timeout-ignored", "simulator ignores its actuator-command timeout", f"{NODES}/simulator.py",
        # the simulator's topic input applies the newest command it received, however old, instead of the guard's
        # output (which times it out into the minimum-risk maneuver)
        (("        out = self.guard.output(t)\n",
          "        out = self.guard.output(t)\n        out = self.guard._latest or out\n"),),
        ("tests/test_simulator_node.py",)),
    Bug("barrier-sign", "barrier sign flipped in the MPC cost", "src/moose/planner/mpc/cost.py",
        (("    d = y_tilde - ysafe\n", "    d = ysafe - y_tilde\n"),),
        ("tests/test_mpc.py",)),
    Bug("crc-dropped", "CRC check dropped in the CAN codec", "src/moose/canbus/codec.py",
        (("if protected and command_checksum(message.frame_id, data) != data[CHECKSUM_BYTE]:",
          "if False and command_checksum(message.frame_id, data) != data[CHECKSUM_BYTE]:"),),
        ("tests/test_can.py", "tests/test_can_dbc.py")),
    Bug("observer-ignores-gps", "observer ignores GPS", "src/moose/observer.py",
        (("            self._fuse_late_gps(sample)\n            return\n", "            return\n"),),
        ("tests/test_observer.py",)),
    Bug("crc-without-id", "CRC no longer covers the frame id", "src/moose/canbus/codec.py",
        (("return crc8_j1850(bytes((frame_id & 0xFF, (frame_id >> 8) & 0xFF)) + bytes(payload[:CHECKSUM_BYTE]))",
          "return crc8_j1850(bytes(payload[:CHECKSUM_BYTE]))"),),
        ("tests/test_can.py", "tests/test_can_dbc.py")),
    Bug("ecu-torque-timeout-ignored", "ECU ignores its torque timeout", "src/moose/canbus/ecu.py",
        (("steering, torque = self.steering_alive(t), self.torque_alive(t)",
          "steering, torque = self.steering_alive(t), True"),),
        ("tests/test_can.py", "tests/test_can_plant.py")),
    # issue 25: weak assertions made strong, each with the bug it now catches
    Bug("solver-returns-its-start", "the MPC's default solver returns its start (cost and status as computed)",
        "src/moose/planner/mpc/projected_newton.py",
        (("return NewtonResult(u=self._u.copy(), f=float(info[0]),",
          "return NewtonResult(u=np.clip(self._u0, self._lb, self._ub), f=float(info[1]),"),),
        ("tests/test_mpc_solvers.py",)),
    Bug("fbl-fixed-friction", "the FBL's tyres at a fixed μ = 0.9, not the vehicle's planning μ (0.8 by default)",
        "src/moose/planner/fbl.py",
        (("self._axles = Axles.of(vehicle, vehicle.mu)", "self._axles = Axles.of(vehicle, 0.9)"),),
        ("tests/test_weight.py",)),
    # the fault matrix's "reported" check asked only for the injected fault, always an incident; it now asks for the
    # consequence at the node that must detect it: this bug left every kill's old checks (minimum_risk, fallback,
    # ecu_timeout anywhere) passing
    Bug("stale-filed-as-warning", "the launcher files a node's stale input as a plain warning, not input_stale",
        f"{PKG}/incidents.py",
        (('_PROBLEM_KINDS = {"stale": "input_stale", "minimum_risk"', '_PROBLEM_KINDS = {"minimum_risk"'),),
        ("tests/test_fault_matrix.py::test_fault[full-obstacle_detector-kill]",)),
    # the rate check asked only for an achieved factor below the requested one: the inverse ratio (0.08 at --rate 25,
    # with the run's own lower bound 1.5) passed it
    Bug("rate-factor-inverted", "the achieved real-time factor as wall-clock seconds per simulated second",
        f"{PKG}/monitor.py",
        (("return (self.pace[1][1] - self.pace[0][1]) / (self.pace[1][0] - self.pace[0][0])",
          "return (self.pace[1][0] - self.pace[0][0]) / (self.pace[1][1] - self.pace[0][1])"),),
        ("tests/test_launch_supervision.py::test_a_rate_that_cannot_be_held_and_deadline_misses_are_reported",)),
    # the full graph's outcome was compared by its flags and ν to ±0.05: with the threat stamped 10 ms early (the
    # estimate's sensor delay) the extreme case is still clear with the same τ and ν, but at 0.056 m of clearance
    # against the loop's 0.019 m and with 47 MPC solves against 46
    Bug("threat-at-estimate-time", "the obstacle detector stamps the threat with the estimate's time, not its own",
        f"{NODES}/detector.py",
        (("        t = self.now()\n        self.pub(", "        t = estimate.t\n        self.pub("),),
        ("tests/test_ros_graph.py::test_full_graph_reproduces_the_lockstep_outcome",)),
    # the equivalence test allowed 0.6 m/s² per instant (0.25 RMS) and 0.3 m of clearance: planners that plan on the
    # estimate one sample old (as when a planner's tick runs before the tick's estimate is in) move the first
    # accelerations by up to 0.05 m/s² (RMS 0.016) and the clearance by 0.022 m (0.671 m against the loop's 0.649 m)
    Bug("planner-estimate-one-sample-old", "the planner nodes plan on the estimate before the newest",
        f"{NODES}/planner.py",
        (('        self.subscribe(STATE, lambda estimate: setattr(self, "estimate", estimate))\n',
          '        self.subscribe(STATE, lambda estimate: setattr(self, "estimate", self.__dict__.setdefault("_next", '
          'estimate)) or setattr(self, "_next", estimate))\n'),),
        ("tests/test_graph_equivalence.py",)),
    # a run must be the same bits on every CPU: OpenBLAS's kernels, chosen by the CPU, sum in different orders (caught
    # where this CPU's kernels are not the SSE ones the test compares with: any x86-64 with AVX)
    Bug("sqp-blas-solve", "the paper's SQP solves its QP's systems with LAPACK (np.linalg.solve)",
        "src/moose/planner/mpc/paper_sqp.py",
        (("target[free] = solve_spd(rows[:, free], -(g[free] + _matvec(rows[:, working], d[working])))",
          "target[free] = np.linalg.solve(rows[:, free], -(g[free] + rows[:, working] @ d[working]))"),),
        ("tests/test_paper_sqp.py",)),
    # a Ctrl-C that surfaced as another error than CasADi's SystemError (a class being made: RuntimeError) is 130
    Bug("interrupt-only-as-system-error", "a Ctrl-C is recognised inside a SystemError only",
        "src/moose/cli/__init__.py",
        (("        if _interrupted(exc):", "        if isinstance(exc, SystemError) and _interrupted(exc):"),),
        ("tests/test_cli_errors.py",)),
    # the compiled CDR of the DDS messages: every message of the graph goes through it
    Bug("cdr-xcdr2-alignment", "the compiled CDR aligns 8-byte fields to 4 (XCDR2's rule, not XCDR1's)",
        f"{PKG}/cdr.py",
        (("                align = min(_size(code), 8)\n", "                align = min(_size(code), 4)\n"),),
        ("tests/test_cdr.py",)),
)


def apply(bug: Bug, tree: Path) -> bool:
    """Patch the copy; False if the patch does not apply (its original text is not there exactly once)."""
    path = tree / bug.path
    text = path.read_text()
    for old, new in bug.patch:
        if text.count(old) != 1:
            return False
        text = text.replace(old, new)
    path.write_text(text)
    return True


def pytest(tree: Path, tests: tuple[str, ...], env: dict[str, str], log: Path) -> tuple[int, float]:
    started = time.monotonic()
    with open(log, "w") as out:
        command = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-p", "no:randomly", *tests]
        code = subprocess.run(command, cwd=tree, env=env, stdout=out, stderr=subprocess.STDOUT).returncode
    return code, time.monotonic() - started


def run(bugs: list[Bug], keep: bool) -> list[tuple[Bug, str, str]]:
    tree = Path(tempfile.mkdtemp(prefix="moose-planted-"))
    env = dict(os.environ)
    # the copy's packages first (the venv's editable installs point at the working tree)
    env["PYTHONPATH"] = os.pathsep.join([str(tree / "src"), str(tree / "ros2_ws/src/moose_ros"),
                                         env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["MOOSE_CACHE_DIR"] = str(tree / ".cache")  # a patched plant's compiled code stays out of the user's cache
    results = []
    try:
        copy_tree(tree)
        pristine = {bug.path: (tree / bug.path).read_text() for bug in bugs}
        baseline: dict[tuple[str, ...], int] = {}
        for bug in bugs:
            log = tree / f"{bug.name}.log"
            if bug.tests not in baseline:
                baseline[bug.tests] = pytest(tree, bug.tests, env, tree / f"{bug.name}.baseline.log")[0]
            if baseline[bug.tests] != 0:
                results.append((bug, "BASELINE FAILS", f"the unpatched tests fail (exit {baseline[bug.tests]}), "
                                                       f"see {bug.name}.baseline.log (--keep)"))
                print(f"{bug.name:28s} {results[-1][1]}", flush=True)
                continue
            if not apply(bug, tree):
                results.append((bug, "stale", "the patch no longer applies: update BUGS"))
                continue
            try:
                code, seconds = pytest(tree, bug.tests, env, log)
            finally:
                (tree / bug.path).write_text(pristine[bug.path])
            failed = [line for line in log.read_text(errors="replace").splitlines() if line.startswith("FAILED")]
            # 1: tests failed; 2: the patched code broke collection (the default run fails as well)
            verdict = {0: "MISSED", 1: "caught", 2: "caught"}.get(code, f"error (pytest exit {code})")
            results.append((bug, verdict, (failed[0][7:] if failed else "") + f" [{seconds:.0f} s]"))
            print(f"{bug.name:28s} {verdict:8s} {results[-1][2]}", flush=True)
    finally:
        if keep:
            print(f"kept {tree}", file=sys.stderr)
        else:
            shutil.rmtree(tree, ignore_errors=True)
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("bugs", nargs="*", metavar="BUG", help="some of: " + ", ".join(b.name for b in BUGS))
    parser.add_argument("--list", action="store_true", help="print the bugs and exit")
    parser.add_argument("--keep", action="store_true", help="keep the temporary tree and the test logs")
    args = parser.parse_args(argv)
    by_name = {b.name: b for b in BUGS}
    unknown = [n for n in args.bugs if n not in by_name]
    if unknown:
        parser.error(f"unknown bug {unknown[0]!r}: expected one of {', '.join(by_name)}")
    chosen = [by_name[n] for n in args.bugs] or list(BUGS)
    if args.list:
        for bug in chosen:
            print(f"{bug.name}: {bug.description}\n  {bug.path}")
            for old, new in bug.patch:
                print(f"  - {old.strip()}\n  + {new.strip()}")
            print(f"  tests: {' '.join(bug.tests)}")
        return 0
    results = run(chosen, args.keep)
    print("\n| planted bug | tests | result |\n|---|---|---|")
    for bug, verdict, detail in results:
        print(f"| {bug.description} | {', '.join(Path(t).name for t in bug.tests)} | {verdict}: {detail} |")
    return 0 if all(verdict == "caught" for _, verdict, _ in results) else 1


if __name__ == "__main__":
    sys.exit(main())
