"""What every node shares: the runtime node, its typed parameters, and the 1 Hz diagnostics heartbeat."""
from __future__ import annotations

from typing import Any, Callable

from .. import convert as cv
from ..graph import DIAGNOSTICS, TF_STATIC
from ..parameters import node_parameters

OK, WARN, ERROR = 0, 1, 2
"""diagnostic_msgs/DiagnosticStatus levels."""


class GraphNode:
    """Runtime node ``rt``, the core's configuration and the node's own parameters (both validated:
    :func:`moose_ros.parameters.node_parameters`), and a 1 Hz diagnostics heartbeat."""

    name = "node"

    def __init__(self, rt: Any) -> None:
        self.rt = rt
        self.config, self.params = node_parameters(self.name, rt.parameters)
        if hasattr(self.params, "load_scenario"):  # the simulated road: the scenario's μ, when it sets one
            self.config = self.params.load_scenario().configure(self.config)
        # transient local: a late joiner (the simulator waiting for the graph) sees each node's last status
        self._diag = DIAGNOSTICS.publisher(rt)
        self.level, self.message, self.values = OK, "running", {}
        rt.timer(1.0, self.publish_diagnostics)

    def close(self) -> None:
        """Release what the node holds beyond its runtime entities (a bus, a thread); called once at shutdown."""

    def publish_diagnostics(self) -> None:
        self._diag(cv.diagnostic_to_msg(self.rt, self.rt.now(), self.name, self.level, self.message, self.values))

    def table(self) -> Any:
        """The maximum steering table of the vehicle the stack believes in (the planning μ; detector, MSF planner)."""
        from moose.maneuver import MaxSteeringTable

        return MaxSteeringTable.build(self.config.model_vehicle, self.config.maneuver)


def sensor_publishers(rt: Any, t0: float) -> dict[type, tuple[Callable[[Any], None], Callable[[Any, Any], Any]]]:
    """Publisher and converter of each sensor sample type: the vehicle's sensor topics.  The sensor frames
    go on /tf_static once, stamped ``t0`` (transient local: late joiners get them)."""
    TF_STATIC.publisher(rt)(cv.static_tf(rt, t0))
    return {kind: (topic.publisher(rt), convert) for kind, (topic, convert) in cv.SENSOR_SAMPLES.items()}
