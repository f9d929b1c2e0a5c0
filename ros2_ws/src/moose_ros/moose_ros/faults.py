"""Fault injection for ``moose launch --fault`` and the fault matrix of docs/graph.md.

A fault is ``NODE:kill@T`` (SIGKILL at simulated time T) or ``NODE:stall@T:D`` (SIGSTOP at T, SIGCONT D
simulated seconds later, i.e. D / rate wall-clock seconds: a stalled simulator stops simulated time
itself).  Without a simulator (the ``car`` graph) T counts wall-clock seconds from the start.  In lockstep
(``moose launch --lockstep``) T is simulated time and the fault is exact in it (:func:`moose_ros.lockstep.left_out`):
the faulted node runs no tick from T on, whenever the signal lands; the graph goes on without it; a stalled node gets
SIGCONT at T + D simulated, where the graph waits for it to run again, with what its queues kept meanwhile
(:meth:`moose_ros.lockstep.TickJoin.take`); a stalled simulator stops simulated time and gets SIGCONT after D
wall-clock seconds, which no node can tell.  Every fault is recorded as an incident
(``fault_injected``), so a run with a fault is always degraded; whether its *consequence* was reported, by the node
that should detect it, is :func:`reported` (:data:`DETECTORS`).

The fault matrix that runs these faults on every node is :mod:`moose_ros.fault_matrix`.
"""
from __future__ import annotations

import dataclasses
import re
import signal
import time
from typing import Callable, Literal, Optional, Sequence

from moose.params import ParamError

from .incidents import IncidentLog
from .process import Child

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

    def __init__(self, faults: Sequence[Fault], procs: dict[str, Child], rate: float, log: IncidentLog,
                 say: Callable[[str], None], tick: Optional[float] = None) -> None:
        self.pending = sorted(faults, key=lambda f: f.at)
        self.procs, self.rate, self.log, self.say = procs, rate, log, say
        self.tick = tick
        """Lockstep: the graph's tick (s).  The faulted node runs no tick from the fault's on
        (:func:`moose_ros.lockstep.left_out`), so the signal goes out one tick later, when the graph has taken every
        message the node published before (a killed writer cannot resend one lost on the way); a stall ends at its
        simulated end, where the graph waits for the node.  A killed simulator steps no further than its fault's tick;
        a stalled one, which stops simulated time itself, gets SIGCONT after D wall-clock seconds."""
        self.stopped: dict[str, tuple[float, bool]] = {}
        """Node → (time at which it gets SIGCONT, on the simulated clock rather than the wall clock)."""
        self.killed: set[str] = set()

    def due(self, fault: Fault) -> float:
        """The simulated time from which ``fault`` is signalled: in lockstep the tick after its own, or for the
        simulator its own (it steps no further when killed, and simulated time stands still when stalled)."""
        if self.tick is None:
            return fault.at
        from .lockstep import ROOT, tick_of

        return (tick_of(fault.at, self.tick) + (fault.node != ROOT)) * self.tick - 1e-9

    def poll(self, t: float) -> None:
        """Apply what is due at simulated time ``t``, and resume stalls whose time is up."""
        now = time.monotonic()
        for node, (until, simulated) in list(self.stopped.items()):
            if (t if simulated else now) >= until:
                self._signal(node, signal.SIGCONT)
                del self.stopped[node]
                self.say(f"fault: {node} continued (SIGCONT)")
        while self.pending and t >= self.due(self.pending[0]):
            fault = self.pending.pop(0)
            proc = self.procs.get(fault.node)
            if proc is None or proc.poll() is not None:
                self.say(f"fault {fault}: {fault.node} is not running")
                continue
            at = t if self.tick is None else fault.at
            if fault.action == "kill":
                self._signal(fault.node, signal.SIGKILL)
                self.killed.add(fault.node)
                text = f"SIGKILL at t = {at:.2f} s"
            else:
                self._signal(fault.node, signal.SIGSTOP)
                self.stopped[fault.node] = self._resume(fault, now)
                text = f"SIGSTOP at t = {at:.2f} s for {fault.duration:g} s"
            self.log.add(at, fault.node, "fault_injected", f"{fault}: {text}")
            self.say(f"fault {fault}: {text}")

    def _resume(self, fault: Fault, now: float) -> tuple[float, bool]:
        """When a stall ends: (time, on the simulated clock)."""
        if self.tick is None:  # real time: D simulated seconds are D / rate on the wall clock
            return now + fault.duration / self.rate, False
        if fault.node == "vehicle_simulator":  # simulated time stands still with it
            return now + fault.duration, False
        from .lockstep import tick_of

        return tick_of(fault.at + fault.duration, self.tick) * self.tick - 1e-9, True

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
