"""The live view (``moose launch --foxglove``, :class:`moose_ros.live.LiveView`) in this process, fed by a DDS node
of its own, seen by a plain WebSocket client speaking the Foxglove WebSocket protocol: every channel of the graph
contract advertised with its ROS 2 schema, the CDR bytes a publisher wrote forwarded unchanged (decoded by rosbags),
``/clock`` broadcast as the server's time, a bad or taken port refused.  What it computes, not how fast: the
real-time graph behind the live view is tests/test_ros_tools.py's."""
from __future__ import annotations

import json
import struct
import time
from typing import Any, Iterator

import pytest

from moose.params import ParamError
from moose_ros.convert import odometry_to_msg
from moose_ros.graph import CLOCK, ODOM, TOPICS
from moose_ros.interfaces import typestore
from moose_ros.runtime import create_node
from moose_ros.runtime.base import NodeBase

pytestmark = [pytest.mark.graph]

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA, TIME = 0x01, 0x02
"""Binary opcodes of the server: a message of a subscription, the server's time."""


@pytest.fixture
def nodes() -> Iterator[tuple[NodeBase, NodeBase]]:
    view, source = create_node("live_view_test"), create_node("live_source_test")
    try:
        yield view, source
    finally:
        view.shutdown()
        source.shutdown()


def test_the_live_view_forwards_the_graphs_messages_and_its_time(nodes: tuple[NodeBase, NodeBase]) -> None:
    import numpy as np
    import websocket

    from moose_ros.live import LiveView

    view_node, source = nodes
    live = LiveView(view_node, port=0)
    ws = websocket.create_connection(live.url, subprotocols=SUBPROTOCOLS, timeout=10)
    try:
        assert live.url == f"ws://127.0.0.1:{live.port}" and live.port > 0
        channels: dict[int, dict[str, Any]] = {}
        capabilities: list[str] = []
        deadline = time.monotonic() + 20
        while {c["topic"] for c in channels.values()} != set(TOPICS) and time.monotonic() < deadline:
            message = json.loads(ws.recv())
            if message.get("op") == "serverInfo":
                capabilities = message["capabilities"]
            elif message.get("op") == "advertise":
                channels.update({c["id"]: c for c in message["channels"]})
        assert "time" in capabilities
        assert {c["topic"]: (c["encoding"], c["schemaName"], c["schemaEncoding"]) for c in channels.values()} == {
            t.name: ("cdr", t.type, "ros2msg") for t in TOPICS.values()}
        odom_schema = next(c["schema"] for c in channels.values() if c["topic"] == ODOM.name)
        assert "geometry_msgs/PoseWithCovariance pose" in odom_schema  # the ros2msg definition, with its dependencies
        wanted = {cid: c["topic"] for cid, c in channels.items() if c["topic"] in (ODOM.name, CLOCK.name)}
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": cid, "channelId": cid} for cid in wanted]}))

        publish_odom, publish_clock = ODOM.publisher(source), CLOCK.publisher(source)
        received: dict[str, list[Any]] = {ODOM.name: [], CLOCK.name: []}
        times: list[int] = []
        ws.settimeout(0.02)
        k = 0
        deadline = time.monotonic() + 30
        while (len(received[ODOM.name]) < 20 or len(times) < 20) and time.monotonic() < deadline:
            k += 1
            clock = source.make(CLOCK.type)
            clock.clock.sec, clock.clock.nanosec = k, 250_000_000
            publish_clock(clock)
            publish_odom(odometry_to_msg(source, k + 0.25, np.array([float(k), -1.5, 0.3, 7.0, 0.1, 0.2])))
            view_node.spin_once(0.02)  # the live view's subscriptions forward what arrived
            try:
                while True:
                    frame = ws.recv()
                    if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:  # op, subscription, time, payload
                        subscription, _stamp = struct.unpack_from("<IQ", frame, 1)
                        topic = wanted[subscription]
                        received[topic].append(typestore().deserialize_cdr(frame[13:], TOPICS[topic].type))
                    elif isinstance(frame, bytes) and frame[0] == TIME:
                        times.append(struct.unpack_from("<Q", frame, 1)[0])
            except websocket.WebSocketTimeoutException:
                pass
    finally:
        ws.close()
        live.close()
    odom, clocks = received[ODOM.name], received[CLOCK.name]
    assert len(odom) >= 20 and len(times) >= 20 and clocks, ({k: len(v) for k, v in received.items()}, len(times))
    for msg in odom:  # the publisher's message, field by field
        x = msg.pose.pose.position.x
        assert x == int(x) and 1 <= x <= k and msg.pose.pose.position.y == -1.5
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (int(x), 250_000_000)
        assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link_truth")
        assert msg.twist.twist.linear.x == 7.0 and msg.twist.twist.angular.z == 0.2
    assert [m.pose.pose.position.x for m in odom] == sorted(m.pose.pose.position.x for m in odom)
    assert all(c.clock.nanosec == 250_000_000 for c in clocks)
    # the server's time is /clock's simulated time, in nanoseconds
    assert set(times) <= {n * 1_000_000_000 + 250_000_000 for n in range(1, k + 1)} and times == sorted(times)


def test_a_bad_or_taken_port_is_refused(nodes: tuple[NodeBase, NodeBase]) -> None:
    from moose_ros.live import LiveView

    view_node, _ = nodes
    for port in (-1, 65536, 8765.0):
        with pytest.raises(ParamError, match=rf"--foxglove {port!r} is invalid: expected a TCP port 0..65535"):
            LiveView(view_node, port=port)  # type: ignore[arg-type]
    first = LiveView(view_node, port=0)
    try:
        with pytest.raises(ParamError, match=rf"--foxglove {first.port}: cannot serve on 127.0.0.1:{first.port}"):
            LiveView(view_node, port=first.port)
    finally:
        first.close()
