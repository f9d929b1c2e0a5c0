"""Fault injection for ``moose launch --fault`` and the fault matrix of docs/graph.md.

A fault is ``NODE:kill@T`` (SIGKILL at simulated time T) or ``NODE:stall@T:D`` (SIGSTOP at T, SIGCONT D
simulated seconds later, i.e. D / rate wall-clock seconds: a stalled simulator stops simulated time
itself).  Without a simulator (the ``car`` graph) T counts wall-clock seconds from the start.  In lockstep
(``moose launch --lockstep``) T is simulated time and the graph stops waiting for the faulted node from T on; a
stall ends at T + D simulated, but the stalled node catches up in less simulated time than that (a stall is a
wall-clock fault: the fault matrix runs stalls at real time).  Every fault is recorded as an incident
(``fault_injected``), so a run with a fault is always degraded; whether its *consequence* was reported, by the node
that should detect it, is :func:`reported` (:data:`DETECTORS`).

The fault matrix that runs these faults on every node is :mod:`moose_ros.fault_matrix`.
"""
from __future__ import annotations

import dataclasses
import re
import signal
import subprocess
import time
from typing import Callable, Literal, Sequence

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
