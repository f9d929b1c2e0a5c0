"""Fault injection for ``moose launch --fault`` and the fault matrix of docs/graph.md.

A fault is ``NODE:kill@T`` (SIGKILL at simulated time T) or ``NODE:stall@T:D`` (SIGSTOP at T, SIGCONT D
simulated seconds later, i.e. D / rate wall-clock seconds: a stalled simulator stops simulated time
itself).  Without a simulator (the ``car`` graph) T counts wall-clock seconds from the start.  In lockstep
(``moose launch --lockstep``) T is simulated time and the graph stops waiting for the faulted node from T on; a
stall ends at T + D simulated, but the stalled node catches up in less simulated time than that (a stall is a
wall-clock fault: the fault matrix runs stalls at real time).  Every fault is recorded as an incident
(``fault_injected``), so a run with a fault is always degraded; whether its *consequence* was reported, by the node
that should detect it, is :func:`reported` (:data:`DETECTORS`).

The **fault matrix** (:func:`run_matrix`, ``python -m moose_ros.faults --write docs/graph.md``) runs
the kill and the stall of every node of the ``full`` and the ``can`` graph on :data:`MATRIX_SCENARIO`, and
(``--weakest``) the cases of :data:`WEAKEST_CASES` with the most permissive ``minimum_risk`` values accepted,
and writes one row per case: the outcome, the minimum clearance, how far the car went sideways, where it
ended, its final speed, whether it stopped, the exit status and the incidents the run reported.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import re
import signal
import socket
import subprocess
import time
from typing import Any, Callable, Literal, Optional, Sequence

from moose.params import ParamError

from .incidents import IncidentLog

FAULT_SYNTAX = re.compile(r"^(?P<node>[a-z_]+):(?P<action>kill|stall)@(?P<at>[0-9.]+)(?::(?P<duration>[0-9.]+))?$")


@dataclasses.dataclass(frozen=True)
class Fault:
    """One injected fault."""

    node: str
    action: Literal["kill", "stall"]
    at: float
    """Simulated time (s) of the fault."""
    duration: float = 0.0
    """How long a stall lasts (simulated s)."""

    @classmethod
    def parse(cls, text: str) -> "Fault":
        """``NODE:kill@T`` or ``NODE:stall@T:D``; a :class:`ParamError` naming the value otherwise."""
        match = FAULT_SYNTAX.match(text.strip())
        expected = "expected NODE:kill@T or NODE:stall@T:DURATION (simulated seconds)"
        if match is None:
            raise ParamError(f"--fault {text!r} is invalid: {expected}")
        try:
            at = float(match["at"])
            duration = float(match["duration"]) if match["duration"] is not None else 0.0
        except ValueError:
            raise ParamError(f"--fault {text!r} is invalid: {expected}") from None
        action = match["action"]
        if (action == "stall") != (match["duration"] is not None) or (action == "stall" and not duration > 0.0):
            raise ParamError(f"--fault {text!r} is invalid: {expected}; a stall needs a positive duration, "
                             "a kill none")
        return cls(match["node"], action, at, duration)  # type: ignore[arg-type]

    def __str__(self) -> str:
        return f"{self.node}:{self.action}@{self.at:g}" + (f":{self.duration:g}" if self.action == "stall" else "")


class FaultInjector:
    """Applies faults to the node processes at their times; records each one."""

    def __init__(self, faults: Sequence[Fault], procs: dict[str, subprocess.Popen], rate: float, log: IncidentLog,
                 say: Callable[[str], None], lockstep: bool = False) -> None:
        self.pending = sorted(faults, key=lambda f: f.at)
        self.procs, self.rate, self.log, self.say = procs, rate, log, say
        self.lockstep = lockstep
        """Stalls end at a simulated time (the lockstep graph has no rate); a stalled simulator, which stops simulated
        time itself, after D wall-clock seconds."""
        self.stopped: dict[str, tuple[float, bool]] = {}
        """Node → (time at which it gets SIGCONT, on the simulated clock rather than the wall clock)."""
        self.killed: set[str] = set()

    def poll(self, t: float) -> None:
        """Apply what is due at simulated time ``t``, and resume stalls whose time is up."""
        now = time.monotonic()
        for node, (until, simulated) in list(self.stopped.items()):
            if (t if simulated else now) >= until:
                self._signal(node, signal.SIGCONT)
                del self.stopped[node]
                self.say(f"fault: {node} continued (SIGCONT)")
        while self.pending and t >= self.pending[0].at:
            fault = self.pending.pop(0)
            proc = self.procs.get(fault.node)
            if proc is None or proc.poll() is not None:
                self.say(f"fault {fault}: {fault.node} is not running")
                continue
            if fault.action == "kill":
                self._signal(fault.node, signal.SIGKILL)
                self.killed.add(fault.node)
                text = f"SIGKILL at t = {t:.2f} s"
            else:
                self._signal(fault.node, signal.SIGSTOP)
                simulated = self.lockstep and fault.node != "vehicle_simulator"
                self.stopped[fault.node] = ((t + fault.duration, True) if simulated
                                            else (now + fault.duration / (1.0 if self.lockstep else self.rate), False))
                text = f"SIGSTOP at t = {t:.2f} s for {fault.duration:g} s"
            self.log.add(t, fault.node, "fault_injected", f"{fault}: {text}")
            self.say(f"fault {fault}: {text}")

    def release(self) -> None:
        """SIGCONT to every node still stopped (the end of the run)."""
        for node in list(self.stopped):
            self._signal(node, signal.SIGCONT)
        self.stopped.clear()

    def _signal(self, node: str, sig: int) -> None:
        try:
            self.procs[node].send_signal(sig)
        except ProcessLookupError:
            pass


# -- the fault matrix ------------------------------------------------------------------------------------

MATRIX_SCENARIO = "paper_v6_w2.0"
"""A moose test with room to spare (6 m/s, τ = 3 s, w = 2 m; lockstep clearance 0.62 m fault-free), so that the
fault, not the case's marginality, decides the result (the extreme case keeps 0.05–0.13 m)."""
MATRIX_AT = 2.5
"""Fault time (s): 1.5 s after the obstacle appeared, in the middle of the evasive maneuver."""
MATRIX_STALL = 0.6
"""Stall length (simulated s): the review's 0.6 s stop of the motion controller."""
MATRIX_DURATION = 7.0
"""Simulated seconds after the obstacle appears: long enough for the minimum-risk maneuver to stop the car."""
MATRIX_GRAPHS = ("full", "can")
MATRIX_BEGIN = "<!-- fault matrix: generated by `python -m moose_ros.faults --write docs/graph.md` -->"
MATRIX_END = "<!-- end of the fault matrix -->"
WEAKEST_CASES: tuple[tuple[str, Fault], ...] = (("full", Fault("observer", "kill", MATRIX_AT)),
                                                 ("can", Fault("motion_controller", "kill", MATRIX_AT)))
"""Cases run again with the most permissive ``minimum_risk`` values accepted (:func:`weakest_parameters`): the
probe's two cases of a hostile file (``stop_speed`` and ``straight_tolerance`` of 1000 left the field at 5 m/s)."""
WEAKEST_DURATION = 10.0
"""Simulated seconds after the obstacle appears in those cases: the weakest braking (0.8 T_max, 1.1 m/s²) needs
about 6 s to stop the car from 6 m/s, 3 s more than the fault leaves in :data:`MATRIX_DURATION`."""
WEAKEST_BEGIN = ("<!-- fault matrix, weakest minimum_risk: generated by "
                 "`python -m moose_ros.faults --weakest --write docs/graph.md` -->")
WEAKEST_END = "<!-- end of the fault matrix, weakest minimum_risk -->"


def weakest_parameters() -> dict[str, float]:
    """The ``minimum_risk`` group at the weakest end of every hard bound (:data:`moose.schema.MINIMUM_RISK_BOUNDS`),
    as dotted parameters for every node: the most permissive file the graph accepts."""
    from moose.schema import MINIMUM_RISK_BOUNDS

    return {f"minimum_risk.{name}": value for name, value in MINIMUM_RISK_BOUNDS.weakest().items()}


def matrix_cases(graph: str) -> list[Fault]:
    """Kill and stall of every node of ``graph`` (the combined planner mode: both planners run)."""
    from .graph import GRAPHS

    return [Fault(node, action, MATRIX_AT, MATRIX_STALL if action == "stall" else 0.0)
            for node in GRAPHS[graph] for action in ("kill", "stall")]


DETECTORS: dict[str, tuple[tuple[str, str], ...]] = {
    "observer": (("motion_controller", "minimum_risk"),),
    "obstacle_detector": (("weight_fbl", "input_stale"),),
    "mpc_planner": (("weight_fbl", "planner_fallback"),),
    "msf_planner": (("weight_fbl", "planner_fallback"),),
    "weight_fbl": (("motion_controller", "minimum_risk"),),
    "motion_controller": (("vehicle_simulator", "minimum_risk"), ("can_bridge", "minimum_risk")),
    "can_bridge": (("vehicle_simulator", "ecu_timeout"),),
    "vehicle_simulator": (("launch", "cut_short"),),
}
"""The consequence of losing each node, as (the node that must detect it, the incident it reports): the motion
controller runs the minimum-risk maneuver without the estimate or the reference; weight_fbl reports the threat
stale, or a planner's plan missing (fallback); the actuators' guard (the simulator's topic input, or the CAN
bridge's) runs it without commands; the vehicle ECUs time out without the bridge; a killed simulator cuts the run
short.  The fault's own ``fault_injected`` and the ``died`` of the faulted node are no detection.  A stalled
simulator stops simulated time with it: nothing of the graph can notice, and nothing has to."""


def reported(fault: Fault, summary: dict[str, Any]) -> bool:
    """Whether the run reported the fault's consequence from a node that detects it (:data:`DETECTORS`); a stall of
    the simulator has nothing to report."""
    if fault.node == "vehicle_simulator" and fault.action == "stall":
        return True
    seen = {(i["node"], i["kind"]) for i in summary["incidents"]}
    return any(detector in seen for detector in DETECTORS[fault.node])


def run_case(graph: str, fault: Fault, rate: float = 1.0, seed: int = 0,
             params: Optional[dict[str, Any]] = None, duration: float = MATRIX_DURATION,
             lockstep: bool = False) -> dict[str, Any]:
    """One run of the matrix: the launcher's summary of ``graph`` on :data:`MATRIX_SCENARIO` with ``fault``,
    ``duration`` simulated seconds after the obstacle appears (``lockstep``: in lockstep, ``rate`` not used)."""
    import io

    from moose.scenario import load_scenario

    from .launch import launch

    scenario = load_scenario(MATRIX_SCENARIO)
    scenario = dataclasses.replace(scenario, duration=duration)
    out = io.StringIO()
    given = {"scenario": MATRIX_SCENARIO, "duration": duration, **(params or {})}
    summary = launch(scenario, given, graph=graph, seed=seed, rate=rate, faults=[fault], out=out, lockstep=lockstep)
    summary["log"] = out.getvalue()
    return summary


def row(graph: str, fault: Fault, summary: dict[str, Any]) -> str:
    """The matrix row of one case."""
    kinds = sorted({i["kind"] for i in summary["incidents"]} - {"fault_injected"})
    stopped = summary.get("final_speed_mps") is not None and summary["final_speed_mps"] < 0.1
    final = summary.get("final_position_m")
    where = f"({final[0]:.1f}, {final[1]:.1f})" if final else "n/a"
    clearance = summary["min_clearance_m"]
    return (f"| {graph} | {fault.node} | {fault.action} | {summary['outcome']} | "
            f"{'n/a' if clearance is None else f'{clearance:.2f}'} | "
            f"{_fmt(summary.get('max_lateral_offset_m'))} | {where} | {_fmt(summary.get('final_speed_mps'))} | "
            f"{'yes' if stopped else 'no'} | {'yes' if summary['degraded'] else 'no'} | {summary['exit_status']} | "
            f"{', '.join(kinds) or '—'} |")


def _fmt(value: Optional[float]) -> str:
    return "n/a" if value is None else f"{value:.2f}"


MATRIX_HEADER = ("| graph | node | fault | outcome | min clearance (m) | max \\|y\\| (m) | end (x, y) (m) "
                 "| final speed (m/s) "
                 "| stopped | degraded | exit | incidents (besides the fault) |\n"
                 "|---|---|---|---|---|---|---|---|---|---|---|---|")


def run_matrix(rate: float = 1.0, graphs: Sequence[str] = MATRIX_GRAPHS,
               say: Callable[[str], None] = print, params: Optional[dict[str, Any]] = None,
               weakest: bool = False) -> str:
    """Run every case of :func:`matrix_cases` for ``graphs`` (``weakest``: the cases of :data:`WEAKEST_CASES`
    with :func:`weakest_parameters`); the Markdown table.  ``params`` (the CAN bus of the ``can`` graph) go to the
    ``can`` graph's runs."""
    cases = ([(g, f) for g, f in WEAKEST_CASES if g in graphs] if weakest
             else [(g, f) for g in graphs for f in matrix_cases(g)])
    rows = [MATRIX_HEADER]
    for graph, fault in cases:
        given = {**(params if graph == "can" and params else {}), **(weakest_parameters() if weakest else {})}
        summary = run_case(graph, fault, rate=rate, params=given or None,
                           duration=WEAKEST_DURATION if weakest else MATRIX_DURATION)
        rows.append(row(graph, fault, summary))
        say(rows[-1])
    return "\n".join(rows)


def write_matrix(path: str, table: str, rate: float, weakest: bool = False) -> None:
    """Replace the generated matrix between :data:`MATRIX_BEGIN` and :data:`MATRIX_END` in ``path`` (``weakest``:
    between :data:`WEAKEST_BEGIN` and :data:`WEAKEST_END`)."""
    from pathlib import Path

    begin, end = (WEAKEST_BEGIN, WEAKEST_END) if weakest else (MATRIX_BEGIN, MATRIX_END)
    text = Path(path).read_text(encoding="utf-8")
    if begin not in text or end not in text:
        raise ParamError(f"--write {path!r}: no fault-matrix markers ({begin} … {end})")
    head, rest = text.split(begin, 1)
    _old, tail = rest.split(end, 1)
    duration = WEAKEST_DURATION if weakest else MATRIX_DURATION
    note = (f"\n{MATRIX_SCENARIO}, faults at t = {MATRIX_AT:g} s (stall {MATRIX_STALL:g} s), "
            f"{duration:g} s after the obstacle appears, --rate {rate:g}, seed 0"
            + (", minimum_risk: " + ", ".join(f"{k.split('.')[1]} {v:g}" for k, v in weakest_parameters().items())
               if weakest else "") + ".\n\n")
    Path(path).write_text(head + begin + note + table + "\n" + end + tail, encoding="utf-8")


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m moose_ros.faults",
                                     description="run the fault matrix (kill and stall of every node)")
    parser.add_argument("--rate", type=float, default=1.0, help="simulated seconds per wall-clock second")
    parser.add_argument("--graph", action="append", choices=MATRIX_GRAPHS, help="graphs (default: all)")
    parser.add_argument("--write", help="replace the matrix in this Markdown file (docs/graph.md)")
    parser.add_argument("--weakest", action="store_true",
                        help="run the cases of a hostile minimum_risk file with the most permissive values accepted")
    args = parser.parse_args(argv)
    pid = os.getpid()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:  # a bus of our own: a free port, a group by pid
        sock.bind(("127.0.0.1", 0))
        bus = {"can_interface": "udp_multicast", "can_channel": f"239.77.{pid % 250}.{1 + pid % 199}",
               "can_port": sock.getsockname()[1]}
    table = run_matrix(args.rate, args.graph or MATRIX_GRAPHS, params=bus, weakest=args.weakest)
    if args.write:
        write_matrix(args.write, table, args.rate, args.weakest)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
