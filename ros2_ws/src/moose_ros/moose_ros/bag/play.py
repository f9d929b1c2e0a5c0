"""Publish a bag into the graph with its original timing."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Optional, Sequence

from ..graph import CLOCK, TOPICS
from ..interfaces import UnknownMessageType, from_rosbags
from ..runtime import QOS_DEFAULT
from .errors import BagError
from .reader import BagReader, ReadReport


def play(path: str | Path, node: Any, rate: float = 1.0, topics: Optional[Sequence[str]] = None, loop: bool = False,
         start: float = 0.0, clock: bool = False, stop: Optional[Any] = None,
         report: Optional[ReadReport] = None) -> int:
    """Publish a bag's messages with their original timing (scaled by ``rate``); returns the count sent.

    The whole bag is read before the first message goes out, and checked: ``topics`` must be topics of the bag
    (a typo never publishes every topic), and a topic of the graph must carry the graph's type.  Messages of
    types this installation cannot publish are not sent, and are counted in ``report`` with what could not be
    read (:class:`~moose_ros.bag.reader.ReadReport`)."""
    report = report if report is not None else ReadReport(str(path))
    reader = BagReader(path, report)
    try:
        reader.check(topics, {name: topic.type for name, topic in TOPICS.items()})
        messages = list(reader.messages(topics))
    finally:
        reader.close()
    prepared = []  # converted before the first message goes out, so a failure never cuts the playback short
    for m in messages:
        try:
            prepared.append((m, from_rosbags(m.msg, m.type_name)))
        except (UnknownMessageType, KeyError, AttributeError, TypeError) as exc:
            report.skip(m.topic, m.type_name, f"not published: this installation cannot send it ({exc})")
    if not prepared:
        raise BagError(f"bag {str(path)!r} has no messages on {list(topics) if topics else 'any topic'} "
                       "that can be played")
    publishers: dict[str, Any] = {}
    clock_pub = CLOCK.publisher(node) if clock else None
    t0 = prepared[0][0].timestamp_ns + int(start * 1e9)
    sent = 0
    while True:
        wall0 = time.monotonic()
        for m, dds in prepared:
            if m.timestamp_ns < t0:
                continue
            if stop is not None and stop.is_set():
                return sent
            delay = (m.timestamp_ns - t0) * 1e-9 / rate - (time.monotonic() - wall0)
            if delay > 0:
                time.sleep(delay)
            if m.topic not in publishers:
                # reliable, so the player drops nothing (a reliable writer matches best-effort readers too); latched
                # topics keep their durability (a volatile writer never matches a transient-local reader)
                contract = TOPICS.get(m.topic)
                qos = contract.qos if contract is not None and contract.qos.transient_local else QOS_DEFAULT
                publishers[m.topic] = node.publisher(m.type_name, m.topic, qos)
            if clock_pub is not None:
                c = node.make(CLOCK.type)
                c.clock.sec, c.clock.nanosec = divmod(m.timestamp_ns, 1_000_000_000)
                clock_pub(c)
            publishers[m.topic](dds)
            sent += 1
        if not loop:
            return sent
