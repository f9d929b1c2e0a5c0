"""Publish a bag into the graph: with its original timing, or in lockstep with the nodes it drives."""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from ..graph import CLOCK, TOPICS
from ..interfaces import UnknownMessageType, from_rosbags
from ..lockstep import (
    PIPELINE,
    QOS_DATA,
    QOS_MARKER,
    ROOT,
    STUCK_TIMEOUT,
    TICK_TYPE,
    TickJoin,
    marker_message,
    marker_time,
    marker_topic,
    readers,
    tick_of,
)
from ..runtime import QOS_DEFAULT
from .errors import BagError
from .reader import BagMessage, BagReader, ReadReport

DRIVEN: tuple[str, ...] = tuple(n for n in PIPELINE if n != ROOT)
"""The nodes a lockstep replay can drive: every node of the lockstep graph but the simulator, whose place (the root of
every tick, :mod:`moose_ros.lockstep`) the player takes."""


class LockstepStuck(Exception):
    """A lockstep replay gave up: a node did not report a tick (or its readers did not connect) within the timeout.
    ``sent``: the messages published before."""

    def __init__(self, message: str, sent: int) -> None:
        super().__init__(message)
        self.sent = sent


def play(path: str | Path, node: Any, rate: Optional[float] = None, topics: Optional[Sequence[str]] = None,
         loop: bool = False, start: float = 0.0, clock: bool = False, stop: Optional[Any] = None,
         report: Optional[ReadReport] = None, lockstep: Sequence[str] = (),
         timeout: float = STUCK_TIMEOUT) -> int:
    """Publish a bag's messages; returns the count sent.

    By default with their original timing, scaled by ``rate`` (1 when ``None``): what a late subscriber misses is
    lost, as from a live sensor.  With ``lockstep`` (node names of :data:`DRIVEN`, each started with
    ``lockstep_nodes`` = the simulator and these nodes) the player takes the simulator's place in the lockstep
    protocol (:mod:`moose_ros.lockstep`): it waits until those nodes read its topics, then publishes the bag tick by
    tick (tick k: the messages stamped within half a motion period of k periods after the first one played, then
    the root marker announcing them) and publishes tick k + 1 only once every node has reported tick k on its
    marker.  The nodes then compute from exactly the bag's messages, as fast as they can, whatever the machine's
    load.  :class:`LockstepStuck` when a node does not report a tick, or the nodes do not connect, within
    ``timeout`` seconds of wall-clock time.

    The whole bag is read before the first message goes out, and checked: ``topics`` must be topics of the bag
    (a typo never publishes every topic), and a topic of the graph must carry the graph's type.  Messages of
    types this installation cannot publish are not sent, and are counted in ``report`` with what could not be
    read (:class:`~moose_ros.bag.reader.ReadReport`)."""
    if lockstep:
        check_lockstep(lockstep, rate, loop, timeout)
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
    clock_pub = CLOCK.publisher(node) if clock else None
    t0 = prepared[0][0].timestamp_ns + int(start * 1e9)
    if lockstep:
        played = [(m, dds) for m, dds in prepared if m.timestamp_ns >= t0]
        if not played:
            raise BagError(f"bag {str(path)!r} has no message to play after --start {start:g} s")
        return _play_lockstep(node, played, tuple(lockstep), clock_pub, timeout, stop)
    publishers: dict[str, Any] = {}
    sent = 0
    while True:
        wall0 = time.monotonic()
        for m, dds in prepared:
            if m.timestamp_ns < t0:
                continue
            if stop is not None and stop.is_set():
                return sent
            delay = (m.timestamp_ns - t0) * 1e-9 / (rate or 1.0) - (time.monotonic() - wall0)
            if delay > 0:
                time.sleep(delay)
            if m.topic not in publishers:
                publishers[m.topic] = _publisher(node, m, lockstep=False)
            if clock_pub is not None:
                clock_pub(_clock(node, m.timestamp_ns))
            publishers[m.topic](dds)
            sent += 1
        if not loop:
            return sent


def check_lockstep(nodes: Sequence[str], rate: Optional[float], loop: bool, timeout: float) -> None:
    """A :class:`BagError` (bad input: ``moose: error:``, exit status 2) for a lockstep replay of :func:`play` the
    player cannot do, before anything joins the graph."""
    for name in nodes:
        if name not in DRIVEN:
            raise BagError(f"--lockstep {name!r} is invalid: expected nodes of the lockstep graph other than the "
                           f"simulator, whose place the player takes: {', '.join(DRIVEN)}")
    if len(set(nodes)) != len(nodes):
        raise BagError(f"--lockstep {' '.join(nodes)} is invalid: a node is named twice")
    if rate is not None:
        raise BagError(f"--rate {rate:g} does not apply with --lockstep: the nodes pace the replay")
    if loop:
        raise BagError("--loop does not apply with --lockstep: the nodes' ticks run once, from 0")
    if not (timeout > 0.0 and math.isfinite(timeout)):
        raise BagError(f"--lockstep-timeout {timeout!r} is invalid: expected a finite positive number of seconds")


def _publisher(node: Any, m: BagMessage, lockstep: bool) -> Any:
    """The player's publisher of ``m``'s topic: reliable, so the player drops nothing (a reliable writer matches
    best-effort readers too); latched topics keep their durability (a volatile writer never matches a
    transient-local reader); in lockstep what a lockstep reader requests (:data:`moose_ros.lockstep.QOS_DATA`)."""
    if lockstep:
        return node.publisher(m.type_name, m.topic, QOS_DATA)
    contract = TOPICS.get(m.topic)
    if contract is not None and contract.qos.transient_local:
        return node.publisher(m.type_name, m.topic, contract.qos)
    return node.publisher(m.type_name, m.topic, QOS_DEFAULT)


def _clock(node: Any, stamp_ns: int) -> Any:
    """A /clock message at ``stamp_ns``."""
    c = node.make(CLOCK.type)
    c.clock.sec, c.clock.nanosec = divmod(stamp_ns, 1_000_000_000)
    return c


def _play_lockstep(node: Any, played: list[tuple[BagMessage, Any]], nodes: tuple[str, ...], clock_pub: Any,
                   timeout: float, stop: Optional[Any]) -> int:
    """The lockstep replay of :func:`play` (see there); returns the count sent."""
    from moose.config import load_config

    period = load_config().motion_period  # the nodes' tick (their configuration's, as the simulator's)
    graph = (ROOT, *nodes)
    join = TickJoin(ROOT, graph)  # the player waits for every driven node's marker of the tick, as the simulator
    for name in join.waits:
        node.subscription(TICK_TYPE, marker_topic(name), lambda msg: join.marker(
            msg.node, tick_of(marker_time(msg), period), tuple(msg.topics), None), QOS_MARKER)
    marker = node.publisher(TICK_TYPE, marker_topic(ROOT), QOS_MARKER)
    publishers: dict[str, Any] = {}
    needed: dict[str, int] = {}
    for m, _dds in played:
        if m.topic not in publishers:
            publishers[m.topic] = _publisher(node, m, lockstep=True)
            needed[m.topic] = readers(TOPICS[m.topic], nodes) if m.topic in TOPICS else 0
    first = played[0][0].timestamp_ns
    ticks: dict[int, list[tuple[BagMessage, Any]]] = {}
    for m, dds in played:
        ticks.setdefault(tick_of((m.timestamp_ns - first) * 1e-9, period), []).append((m, dds))
    sent = 0

    def stopped() -> bool:
        return stop is not None and stop.is_set()

    def wait(done: Callable[[], bool], what: Callable[[], str]) -> bool:
        """Spin until ``done()`` (checked after every callback, so a tick goes out as soon as the last marker is in);
        False when stopped; :class:`LockstepStuck` after ``timeout``."""
        deadline = time.monotonic() + timeout
        node.spin(until=lambda: done() or stopped() or time.monotonic() > deadline)
        if done():
            return True
        if stopped():
            return False
        raise LockstepStuck(f"{what()} for {timeout:g} s (wall clock); {sent} messages played (are the nodes running "
                            f"with lockstep_nodes = [{', '.join(graph)}]?)", sent)

    def unconnected() -> list[str]:
        return [f"{topic} ({publishers[topic].subscription_count()} of {n} readers)" for topic, n in needed.items()
                if publishers[topic].subscription_count() < n]

    if not wait(lambda: not unconnected(), lambda: f"lockstep replay: {', '.join(nodes)} did not connect: "
                                                   f"{', '.join(unconnected())}"):
        return sent
    for k in range(max(ticks) + 1):
        if clock_pub is not None:
            clock_pub(_clock(node, first + round(k * period * 1e9)))
        announced = []
        for m, dds in ticks.get(k, []):
            publishers[m.topic](dds)
            announced.append(m.topic)
            sent += 1
        join.marker(ROOT, k, (), nodes)
        marker(marker_message(node.make, ROOT, round(k * period, 9), announced, nodes))

        def taken(k: int = k) -> bool:  # join.next passes k once the tick is taken: true again, nothing else taken
            return join.next > k or join.take() is not None

        def late(k: int = k) -> str:
            missing = ", ".join(n for n in join.waits if k not in join.markers[n]) or "the nodes"
            return f"lockstep replay stuck at tick {k} (t = {k * period:.2f} s after the first message): no tick " \
                   f"from {missing}"

        if not wait(taken, late):
            return sent
    return sent
