"""What went wrong in a run of the graph, as the launcher saw it: incidents, each node's end, the exit status.

Incidents come from two sources, both recorded by ``moose launch``:

* **/diagnostics** (:meth:`IncidentLog.on_status`): every node publishes its status once a second and at
  once when its level changes (:mod:`moose_ros.nodes.base`); a new *problem* key in its ``problems``
  value becomes an incident (``stale:TOPIC`` → ``input_stale``, ``minimum_risk``/``commands_lost`` →
  ``minimum_risk``, ``fallback`` → ``planner_fallback``, ``ecu_timeout``, ``invalid:TOPIC`` → ``input_dropped``,
  ``lockstep_stuck``), a
  rise of its ``stalls`` counter a ``stalled``
  incident, any other new WARN or ERROR message a ``warning`` or ``error``; the counters
  ``deadline_misses`` and ``stalls`` are kept per node.
* **the processes and the clock**: a node that exits before it announced itself ``failed_to_start``, one
  that exits during the run (or does not stop on SIGTERM) ``died``, a node silent on /diagnostics for
  longer than the topic's deadline ``stalled``, each ``--fault`` ``fault_injected``, a real-time factor
  below :data:`RATE_TOLERANCE` of the requested one ``rate_not_held``, a run ended early ``cut_short``.

A run is *degraded* when it had an incident of a :data:`DEGRADING` kind; deadline misses, a rate not held,
dropped inputs and plain warnings are reported but do not degrade it.  :func:`moose.verdict.exit_status` maps a run to
the exit status of ``moose launch`` (:func:`moose.verdict.exit_status`: the statuses of ``moose simulate``, plus
:data:`moose.verdict.EXIT_DEGRADED`).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Optional

KINDS = {
    "failed_to_start": "a node exited before it announced itself on /diagnostics",
    "died": "a node exited during the run, or did not stop on SIGTERM",
    "fault_injected": "the launcher killed or stopped a node (--fault)",
    "stalled": "a node ran no executor cycle for longer than STALL_TIME, or fell silent on /diagnostics",
    "input_stale": "an input of a node passed its deadline",
    "minimum_risk": "a minimum-risk maneuver ran (motion controller, the simulator's or the CAN bridge's guard)",
    "planner_fallback": "weight_fbl applied one planner's plan alone",
    "ecu_timeout": "the vehicle-side ECUs received no commands (the CAN graph without a bridge): they run their "
                   "own minimum-risk maneuver (or, with ecu_minimum_risk false, zero torque and the steering held) "
                   "— nothing of the stack controls the car",
    "deadline_missed": "executor cycles, planning slots or control cycles over their deadline (counted)",
    "input_dropped": "invalid samples dropped by a node",
    "rate_not_held": "the achieved real-time factor fell below the requested one",
    "cut_short": "the run ended before the simulator finished (Ctrl-C, SIGTERM, the time limit)",
    "lockstep_stuck": "a lockstep graph stopped reporting its ticks: the simulator gave up waiting and ended the run",
    "warning": "another WARN status of a node",
    "error": "another ERROR status of a node",
}
"""Every kind of incident and what it means."""

DEGRADING = frozenset({"failed_to_start", "died", "fault_injected", "stalled", "input_stale", "minimum_risk",
                       "planner_fallback", "ecu_timeout", "cut_short", "lockstep_stuck", "error"})
"""Kinds that make a run degraded."""

RATE_TOLERANCE = 0.9
"""A run whose achieved real-time factor is below this share of the requested ``--rate`` did not hold it."""

MAX_PER_KIND = 20
"""Incidents recorded per node and kind; more are counted in the last one's ``repeats``."""

_PROBLEM_KINDS = {"stale": "input_stale", "minimum_risk": "minimum_risk", "commands_lost": "minimum_risk",
                  "fallback": "planner_fallback", "ecu_timeout": "ecu_timeout", "invalid": "input_dropped",
                  "lockstep_stuck": "lockstep_stuck"}
"""Problem key (before ``:``) → incident kind."""


@dataclasses.dataclass
class Incident:
    t: Optional[float]
    """Simulated time (s) when the launcher saw it (``None``: before the clock ran)."""
    node: str
    kind: str
    message: str
    repeats: int = 0
    """Further incidents of this node and kind past :data:`MAX_PER_KIND`."""

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclasses.dataclass
class IncidentLog:
    """The incidents of one run and the counters the nodes reported."""

    incidents: list[Incident] = dataclasses.field(default_factory=list)
    announced: set = dataclasses.field(default_factory=set)
    """Nodes that published a status."""
    counters: dict = dataclasses.field(default_factory=dict)
    """node → {"deadline_misses": n, "stalls": n, "longest_gap_ms": n, ...} from its last status."""
    _problems: dict = dataclasses.field(default_factory=dict)
    _last: dict = dataclasses.field(default_factory=dict)

    def add(self, t: Optional[float], node: str, kind: str, message: str) -> None:
        assert kind in KINDS, kind
        same = [i for i in self.incidents if i.node == node and i.kind == kind]
        if len(same) >= MAX_PER_KIND:
            same[-1].repeats += 1
            return
        self.incidents.append(Incident(None if t is None else round(t, 3), node, kind, message))

    def on_status(self, t: Optional[float], node: str, level: int, message: str, values: dict[str, str]) -> None:
        """One status of ``node`` on /diagnostics."""
        self.announced.add(node)
        problems = {p for p in values.get("problems", "").split(",") if p}
        new = problems - self._problems.get(node, set())
        self._problems[node] = problems
        for key in sorted(new):
            self.add(t, node, _PROBLEM_KINDS.get(key.split(":", 1)[0], "warning"), values.get(key) or message)
        previous = self.counters.get(node, {})
        counters = {k: _number(values[k]) for k in ("deadline_misses", "stalls", "longest_gap_ms") if k in values}
        if counters.get("stalls", 0) > previous.get("stalls", 0):
            self.add(t, node, "stalled", f"no executor cycle for up to {counters.get('longest_gap_ms', 0):.0f} ms "
                                         "(stalled or starved)")
        self.counters[node] = {**previous, **counters}
        if (not problems and level >= 1 and (level, message) != self._last.get(node)  # a status without problem keys
                and not message.startswith("stopped")):  # (a node's last status, at its end, says "stopped")
            kind = "minimum_risk" if "minimum-risk" in message else ("error" if level >= 2 else "warning")
            self.add(t, node, kind, message)
        self._last[node] = (level, message)

    def count(self, kind: str) -> int:
        return sum(1 + i.repeats for i in self.incidents if i.kind == kind)

    @property
    def degraded(self) -> bool:
        return any(i.kind in DEGRADING for i in self.incidents)


def _number(text: str) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return 0.0
