"""The live view: the running graph served over the Foxglove WebSocket protocol (``moose launch --foxglove``).

Every topic of the graph contract becomes a channel of the official ``foxglove-sdk`` server, with the
ROS 2 conventions Foxglove decodes natively: message encoding ``cdr`` and the ``ros2msg`` definition
of its type (rosbags' type store, as in the bags).  The messages are the CDR bytes received from the
graph, forwarded unchanged and stamped with their reception time.  ``/clock`` is also broadcast as
the server's time (the Time capability), so Foxglove's timeline follows simulated time.  Foxglove
Studio connects to ``ws://HOST:PORT`` without ROS 2.  The server binds to localhost unless told
otherwise: it has no authentication, and anyone who reaches the port sees the whole graph.
"""
from __future__ import annotations

import time
from typing import Any, Callable

from moose.params import ParamError

from .graph import CLOCK, TOPICS, Topic
from .runtime.base import NodeBase

DEFAULT_PORT = 8765
"""Foxglove's default WebSocket port."""
DEFAULT_HOST = "127.0.0.1"


class LiveView:
    """A Foxglove WebSocket server fed by runtime node ``node`` (its subscriptions use the tools' QoS)."""

    def __init__(self, node: NodeBase, port: int = DEFAULT_PORT, host: str = DEFAULT_HOST) -> None:
        import foxglove

        from .interfaces import typestore

        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise ParamError(f"--foxglove {port!r} is invalid: expected a TCP port 0..65535 (0: any free port)")
        self._context = foxglove.Context()
        try:
            self.server = foxglove.start_server(name="moose", host=host, port=port, context=self._context,
                                                capabilities=[foxglove.Capability.Time])
        except Exception as exc:  # noqa: BLE001 - the SDK raises its own error types for bind failures
            raise ParamError(f"--foxglove {port}: cannot serve on {host}:{port}: {exc}") from None
        self.port = self.server.port
        self.host = host
        self._channels: dict[str, Any] = {}
        self._serialize = node.serialize  # the runtime's CDR (Cyclone or rclpy)
        for topic in TOPICS.values():
            msgdef, _ = typestore().generate_msgdef(topic.type, ros_version=2)
            schema = foxglove.Schema(name=topic.type, encoding="ros2msg", data=msgdef.encode())
            self._channels[topic.name] = foxglove.Channel(topic.name, schema=schema, message_encoding="cdr",
                                                          context=self._context)
            topic.tool_subscription(node, self._forward(topic))

    def _forward(self, topic: Topic) -> Callable[[Any], None]:
        channel, serialize = self._channels[topic.name], self._serialize
        is_clock = topic.name == CLOCK.name

        def forward(msg: Any) -> None:
            channel.log(serialize(msg), log_time=time.time_ns())
            if is_clock:
                self.server.broadcast_time(msg.clock.sec * 1_000_000_000 + msg.clock.nanosec)

        return forward

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def close(self) -> None:
        """Stop the server (clients are disconnected)."""
        self.server.stop()
