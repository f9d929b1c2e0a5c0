"""QoS profiles of the runtime: the subset of ROS 2's QoS that the graph uses, and its named profiles."""
from __future__ import annotations

import dataclasses

from moose.params import check


@dataclasses.dataclass(frozen=True)
class Qos:
    """A ROS 2 QoS profile (the subset the graph uses): reliability, keep-last depth, durability."""

    reliable: bool = True
    depth: int = 10
    transient_local: bool = False

    def __post_init__(self) -> None:
        check("qos.depth", self.depth, lambda d: isinstance(d, int) and not isinstance(d, bool) and d >= 1,
              "an integer >= 1")


QOS_DEFAULT = Qos()
"""rclpy's default: reliable, volatile, keep last 10."""
QOS_SENSOR = Qos(reliable=False, depth=5)
"""rclpy's qos_profile_sensor_data: best effort, keep last 5."""
QOS_LATCHED = Qos(reliable=True, depth=1, transient_local=True)
"""Reliable, transient local, keep last 1 (late joiners get the last sample)."""
QOS_LATCHED_READER = Qos(reliable=True, depth=100, transient_local=True)
"""Reader side of latched topics with many writers (``/diagnostics``): keyless topics share one
history, so a depth of 1 would keep only one writer's late-joiner sample."""
QOS_CLOCK = Qos(reliable=True, depth=1)
"""Writer of ``/clock`` (the simulator)."""
QOS_CLOCK_READER = Qos(reliable=False, depth=1)
"""Reader of ``/clock`` with ``use_sim_time``: best effort, keep last 1 like rclpy's TimeSource, so it
matches reliable and best-effort clock writers (``ros2 bag play --clock``) alike."""
