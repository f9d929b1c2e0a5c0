"""Record bags: the topics of a running graph (:class:`Recorder`), or a lockstep run (:func:`record_result`)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from ..graph import BLEND, OBSTACLES, ODOM, PLANS, STATE, THREAT, TOPICS
from .errors import BagError
from .writer import BagWriter


class Recorder:
    """Records topics of a running graph through a runtime node, with the contract's subscriber QoS.

    Messages are stamped on reception with the wall clock, never earlier than the previous one (a step
    of the clock back would otherwise put them out of order).  A recorder killed with SIGKILL loses only
    what it had not yet taken from its subscriptions (:mod:`moose_ros.bag.writer`).
    """

    def __init__(self, node: Any, path: str | Path, topics: Optional[Sequence[str]] = None) -> None:
        chosen = list(topics) if topics else list(TOPICS)
        unknown = [t for t in chosen if t not in TOPICS]
        if unknown:
            raise BagError(f"--topics {unknown[0]!r} is not a topic of the graph; topics: {', '.join(TOPICS)}")
        self.writer = BagWriter(path)
        self._serialize = node.serialize  # the runtime's CDR: the same bytes on both runtimes
        self._last_ns = 0
        for topic in chosen:
            TOPICS[topic].subscription(node, self._callback(topic))

    def _callback(self, topic: str) -> Callable[[Any], None]:
        type_name, serialize = TOPICS[topic].type, self._serialize

        def record(msg: Any) -> None:
            self._last_ns = max(time.time_ns(), self._last_ns)
            self.writer.write(topic, type_name, self._last_ns, serialize(msg))

        return record

    def close(self) -> None:
        self.writer.close()


def record_result(result: Any, path: str | Path) -> dict[str, int]:
    """Write a lockstep run (``moose simulate``) as a bag on the graph's topics, stamped in simulated time."""
    from types import SimpleNamespace

    import numpy as np

    from .. import convert as cv
    from ..interfaces import make

    factory = SimpleNamespace(make=make)
    writer = BagWriter(path)
    entries: list[tuple[int, str, Any]] = []

    def add(t: float, topic: str, msg: Any) -> None:
        entries.append((int(round(t * 1e9)), topic, msg))

    for sample in result.samples:
        topic, convert = cv.SENSOR_SAMPLES[type(sample)]
        add(sample.t, topic.name, convert(factory, sample))
    trace = result.trace
    columns = ("x", "y", "theta", "vx", "vy", "gamma")
    for k, t in enumerate(trace["t"]):
        add(float(t), ODOM.name, cv.odometry_to_msg(factory, float(t), np.array([trace[c][k] for c in columns])))
    for estimate in result.estimates:
        add(estimate.t, STATE.name, cv.estimate_to_msg(factory, estimate))
    appeared = next((t for t, threat in result.threats if threat is not None), None)
    if appeared is not None:
        add(appeared, OBSTACLES.name, cv.obstacles_to_msg(factory, appeared, [result.scenario.danger_zone]))
    for t, threat in result.threats:
        add(t, THREAT.name, cv.threat_to_msg(factory, t, threat))
    for record in result.planning:
        for kind, plan in (("mpc", record.mpc), ("msf", record.msf)):
            if plan is not None:
                add(record.t, PLANS[kind].name, cv.plan_to_msg(factory, record.t, kind, plan))
        add(record.t, BLEND.name, cv.blend_to_msg(factory, record.t, record.blend, record.reference))
    entries.sort(key=lambda e: e[0])
    try:
        for stamp_ns, topic, msg in entries:
            writer.write(topic, TOPICS[topic].type, stamp_ns, bytes(msg.serialize()))
    finally:
        writer.close()
    return dict(writer.counts)


def record_simulation(result: Any, path: str | Path) -> dict[str, int]:
    """``moose simulate``'s bag recorder (entry point group ``moose.recorders``): :func:`record_result`, with
    a bag that cannot be written reported as a :class:`~moose.params.ParamError`."""
    from moose.params import ParamError

    try:
        return record_result(result, path)
    except BagError as exc:
        raise ParamError(str(exc)) from None
