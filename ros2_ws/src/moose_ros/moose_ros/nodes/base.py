"""What every node shares: the runtime node, its typed parameters, validated subscriptions and the 1 Hz
diagnostics heartbeat."""
from __future__ import annotations

import time
from collections import Counter
from typing import Any, Callable

from .. import convert as cv
from ..graph import DIAGNOSTICS, TF_STATIC, Topic
from ..parameters import node_parameters

OK, WARN, ERROR = 0, 1, 2
"""diagnostic_msgs/DiagnosticStatus levels."""


class GraphNode:
    """Runtime node ``rt``, the core's configuration and the node's own parameters (both validated:
    :func:`moose_ros.parameters.node_parameters`), validated subscriptions (:meth:`subscribe`) and a 1 Hz
    diagnostics heartbeat."""

    name = "node"

    def __init__(self, rt: Any) -> None:
        self.rt = rt
        self.config, self.params = node_parameters(self.name, rt.parameters)
        if hasattr(self.params, "load_scenario"):  # the simulated road: the scenario's μ, when it sets one
            self.config = self.params.load_scenario().configure(self.config)
        # transient local: a late joiner (the simulator waiting for the graph) sees each node's last status
        self._diag = DIAGNOSTICS.publisher(rt)
        self.level, self.message = OK, "running"
        self.values: dict[str, Any] = {}
        self.invalid: Counter[str] = Counter()
        """Invalid messages dropped, by topic."""
        self._invalid_reason = ""
        self._invalid_new = 0
        self._invalid_logged: dict[str, float] = {}
        rt.timer(1.0, self.publish_diagnostics)

    def close(self) -> None:
        """Release what the node holds beyond its runtime entities (a bus, a thread); called once at shutdown."""

    def subscribe(self, topic: Topic, handler: Callable[[Any], None]) -> Any:
        """Subscribe to ``topic``; ``handler`` gets the validated record (:data:`moose_ros.convert.RECORDS`).

        An invalid message never reaches ``handler`` and never raises: it is dropped, counted per topic
        (:attr:`invalid`), logged (at most once a second per topic) and reported on /diagnostics."""
        convert = cv.RECORDS[topic.name]

        def on_message(msg: Any) -> None:
            now = self.rt.now()
            clock_known = not (self.rt.use_sim_time and now == 0.0)  # ROS 2: time 0 is "no /clock yet"
            try:
                record = convert(msg, now if clock_known else None)
            except cv.InvalidMessage as exc:
                self.reject(topic.name, str(exc))
                return
            handler(record)

        return topic.subscription(self.rt, on_message)

    def reject(self, topic: str, reason: str) -> None:
        """Count a dropped message on ``topic`` and say why (log and the next diagnostics)."""
        self.invalid[topic] += 1
        self._invalid_new += 1
        self._invalid_reason = f"{topic}: {reason}"
        last = self._invalid_logged.get(topic)
        if last is None or time.monotonic() - last >= 1.0:
            self._invalid_logged[topic] = time.monotonic()
            self.rt.log_warn(f"dropped an invalid message on {topic} ({self.invalid[topic]} so far): {reason}")

    def publish_diagnostics(self) -> None:
        """The node's status; WARN while invalid messages are being dropped, with the counts per topic."""
        level, message, values = self.level, self.message, dict(self.values)
        if self.invalid:
            values.update({f"invalid {topic}": count for topic, count in sorted(self.invalid.items())})
            values["last invalid"] = self._invalid_reason
            if self._invalid_new:
                level = max(level, WARN)
                message = f"{message}; dropped {self._invalid_new} invalid message(s)"
            self._invalid_new = 0
        self._diag(cv.diagnostic_to_msg(self.rt, self.rt.now(), self.name, level, message, values))

    def table(self) -> Any:
        """The maximum steering table of the vehicle the stack believes in (the planning μ; detector, MSF planner)."""
        from moose.maneuver import MaxSteeringTable

        return MaxSteeringTable.build(self.config.model_vehicle, self.config.maneuver)


def sensor_publishers(rt: Any, t0: float) -> dict[type, tuple[Callable[[Any], None], Callable[[Any, Any], Any]]]:
    """Publisher and converter of each sensor sample type: the vehicle's sensor topics.  The sensor frames
    go on /tf_static once, stamped ``t0`` (transient local: late joiners get them)."""
    TF_STATIC.publisher(rt)(cv.static_tf(rt, t0))
    return {kind: (topic.publisher(rt), convert) for kind, (topic, convert) in cv.SENSOR_SAMPLES.items()}
