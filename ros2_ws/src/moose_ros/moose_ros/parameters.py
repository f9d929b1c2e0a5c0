"""Node parameters: one frozen dataclass per node, built by the core's validating builder.

A node takes, at the top level of its ``ros__parameters``:

- the core's parameter groups (``vehicle``, ``mpc``, … — :class:`moose.schema.Config`), normally from
  the ``/**`` section of config/moose.yaml;
- its own parameters: the fields of its dataclass in :data:`NODE_PARAMETERS` (``scenario``, ``seed``,
  ``rate``, ``can_interface``, …);
- the parameters the middleware owns (:data:`RUNTIME_PARAMETERS`, e.g. ``use_sim_time``).

Anything else — a misspelt group such as ``vehicel:`` included — is a :class:`~moose.params.ParamError`
naming the node, the key and the value, as ``moose simulate`` refuses it; so is a parameter-file section
named after no node of the graph.  Values are checked by :func:`moose.params.build` (types) and by each
field's ``check`` (ranges).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Collection, Literal, Mapping, Optional

from moose.params import WILDCARD, ParamError, build, check, non_negative, positive
from moose.scenario import Scenario
from moose.scenario.args import scenario_from_args

from .graph import COMMAND_TIMEOUT, NODES
from .lockstep import STUCK_TIMEOUT

RUNTIME_PARAMETERS = frozenset({"use_sim_time", "start_type_description_service", "qos_overrides"})
"""Parameters of the middleware (ROS 2 declares them on every node): accepted on every node."""


def _checked(default: Any, predicate: Any, what: str) -> Any:
    return dataclasses.field(default=default, metadata={"check": (predicate, what)})


@dataclasses.dataclass(frozen=True)
class NodeParams:
    """Parameters of a node without parameters of its own; the base of the others: each field with a
    ``check`` in its metadata is range-checked when given (``None`` means not given)."""

    lockstep_nodes: tuple[str, ...] = ()
    """The nodes of the graph when it runs in lockstep (``moose launch --lockstep``, :mod:`moose_ros.lockstep`);
    empty: real time."""
    faults: tuple[str, ...] = ()
    """Lockstep: the faults of the run (``NODE:kill@T``, ``NODE:stall@T:D``; ``moose launch --lockstep --fault``):
    from T on the graph no longer waits for NODE (:func:`moose_ros.lockstep.expected_at`)."""
    monitored: bool = False
    """A launcher's monitor reads the graph (:data:`moose_ros.lockstep.MONITORED`): the node's publishers of those
    topics wait for it as for the graph's readers (in lockstep every node's; in real time the simulator's, before
    simulated time starts)."""

    def __post_init__(self) -> None:
        unknown = [n for n in self.lockstep_nodes if n not in NODES]
        if unknown:
            raise ParamError(f"lockstep_nodes = {list(self.lockstep_nodes)!r} is invalid: {unknown[0]!r} is no node; "
                             f"nodes: {', '.join(NODES)}")
        for f in dataclasses.fields(self):
            rule = f.metadata.get("check")
            value = getattr(self, f.name)
            if rule is not None and value is not None:
                check(f.name, value, *rule)


@dataclasses.dataclass(frozen=True)
class ScenarioParams(NodeParams):
    """The moose test a node assumes: a scenario by name or path, or an ad-hoc test (``speed``, ``tau`` and
    ``obstacle_half_width``); ``duration`` and ``mu`` change either.  Read as ``moose simulate`` reads its
    flags (:func:`moose.scenario.args.scenario_from_args`)."""

    scenario: Optional[str] = None
    """Name in config/scenarios or a YAML path; ``None``: the default scenario of ``moose simulate``."""
    speed: Optional[float] = _checked(None, positive, "a positive speed (m/s)")
    tau: Optional[float] = _checked(None, positive, "a positive time to collision (s)")
    obstacle_half_width: Optional[float] = _checked(None, positive, "a positive half width (m)")
    obstacle_length: float = _checked(2.0, positive, "a positive length (m)")
    duration: Optional[float] = _checked(None, positive, "a positive duration (s)")
    mu: Optional[float] = _checked(None, positive, "a positive friction coefficient")
    field_margin: Optional[float] = _checked(None, non_negative, "a non-negative distance (m)")
    """Ad-hoc tests: the field reaches this far beside the obstacle (``--field-margin``); ``None``: the paper's."""

    def load_scenario(self) -> Scenario:
        """The :class:`moose.scenario.Scenario` these parameters name."""
        return scenario_from_args(self)


@dataclasses.dataclass(frozen=True)
class CanBusParams(NodeParams):
    """The vehicle bus (python-can): ``udp_multicast`` here, ``socketcan`` on the car, ``virtual`` in tests."""

    can_interface: str = "udp_multicast"
    can_channel: Optional[str] = None
    """Multicast group or socketcan device; ``None``: the group of :mod:`moose.canbus.bus`."""
    can_port: Optional[int] = _checked(None, lambda p: 0 < p < 65536, "a UDP port in 1..65535")
    """UDP port of ``udp_multicast``; ``None``: the port of :mod:`moose.canbus.bus`."""

    def open_bus(self, node: str) -> Any:
        """Open the bus; a wrong interface or channel is a :class:`ParamError` naming ``node``'s parameter."""
        from moose.canbus.bus import DEFAULT_GROUP, open_bus

        try:
            return open_bus(self.can_interface, self.can_channel or DEFAULT_GROUP, port=self.can_port)
        except ValueError as exc:
            raise ParamError(f"{node}.can_{exc}") from None


@dataclasses.dataclass(frozen=True)
class SimulatorParams(ScenarioParams, CanBusParams):
    """``vehicle_simulator``."""

    seed: int = _checked(0, non_negative, "a non-negative integer")
    """Seed of the sensor noise."""
    rate: float = _checked(1.0, positive, "a positive rate (simulated seconds per wall-clock second)")
    vehicle_bus: Literal["topics", "can"] = "topics"
    """``topics``: the simulator publishes the sensor topics; ``can``: it is the vehicle-side ECU emulator
    behind config/kanon.dbc and the ``can_bridge`` node makes the topics."""
    wait_for: tuple[str, ...] = ()
    """Nodes that must report on /diagnostics before simulated time starts."""
    startup_timeout: float = _checked(60.0, positive, "a positive time (s)")
    """Start without the missing ``wait_for`` nodes after this long (s, wall clock)."""
    command_timeout: float = _checked(COMMAND_TIMEOUT, positive, "a positive time (s)")
    """Actuator commands older than this (s) are ignored (zero torque and EPS rate)."""
    lockstep_timeout: float = _checked(STUCK_TIMEOUT, positive, "a positive time (s)")
    """Lockstep: wall-clock seconds the simulator waits for one tick (or, at the start, for the graph to connect)
    before it ends the run with ``lockstep_stuck``."""
    ecu_minimum_risk: bool = True
    """``can`` bus: the emulated vehicle ECUs run the minimum-risk maneuver themselves when the commands stop
    (level 2 of :class:`moose.canbus.ecu.VehicleEcu`'s timeout, a requirement on the car's ECUs); ``false``
    emulates ECUs that only stop applying commands (the car coasts on an arc when the bridge dies)."""


@dataclasses.dataclass(frozen=True)
class ObserverNodeParams(ScenarioParams):
    """``observer``: the scenario gives the initial state."""


@dataclasses.dataclass(frozen=True)
class MotionNodeParams(ScenarioParams):
    """``motion_controller``: the scenario gives the approach speed, the reference until the first plan acts."""


@dataclasses.dataclass(frozen=True)
class PlannerNodeParams(ScenarioParams):
    """``mpc_planner``, ``msf_planner``."""

    v_des: Optional[float] = _checked(None, positive, "a positive speed (m/s)")
    """Desired speed (m/s); ``None``: the scenario's."""


@dataclasses.dataclass(frozen=True)
class WeightFblParams(NodeParams):
    """``weight_fbl``; the planner mode is the core's ``simulation.planner``."""

    mpc_timeout: float = _checked(0.05, positive, "a positive time (s)")
    """Without the MPC's plan of an instant this long after it (simulated or wall time, as the node runs),
    blend the MSF plan alone (weight 0) and report the MPC late; a quarter of the planning period: the MPC
    solves in well under a millisecond, and every millisecond waited holds the previous reference."""


@dataclasses.dataclass(frozen=True)
class CanBridgeParams(CanBusParams):
    """``can_bridge``."""

    command_timeout: float = _checked(COMMAND_TIMEOUT, positive, "a positive time (s)")
    """Command guard: older commands lead to the safe state."""
    can_log: Optional[str] = None
    """Log all traffic to this file (python-can's Logger: ``.log`` candump, ``.asc``, ``.blf``, …)."""


NODE_PARAMETERS: dict[str, type[NodeParams]] = {
    "vehicle_simulator": SimulatorParams,
    "observer": ObserverNodeParams,
    "obstacle_detector": NodeParams,
    "mpc_planner": PlannerNodeParams,
    "msf_planner": PlannerNodeParams,
    "weight_fbl": WeightFblParams,
    "motion_controller": MotionNodeParams,
    "can_bridge": CanBridgeParams,
}
"""The parameter dataclass of every node of the graph (:data:`moose_ros.graph.NODES`)."""


def parameter_names(node: str) -> frozenset[str]:
    """The names of ``node``'s own parameters."""
    return frozenset(f.name for f in dataclasses.fields(NODE_PARAMETERS[node]))


def node_parameters(node: str, params: Mapping[str, Any]) -> tuple[Any, Any]:
    """``(Config, node parameters)`` of ``node`` from its merged ``ros__parameters``, strictly."""
    from moose.config import config_from_mapping
    from moose.schema import Config

    groups = {f.name for f in dataclasses.fields(Config)}
    own = parameter_names(node)
    unknown = sorted(set(params) - groups - own - RUNTIME_PARAMETERS)
    if unknown:
        key = unknown[0]
        raise ParamError(f"{node}.{key} = {params[key]!r} is unknown; {node} takes the groups {sorted(groups)}"
                         f" and {sorted(own) if own else 'no parameters of its own'}")
    config = config_from_mapping({k: v for k, v in params.items() if k in groups}, where=node)
    return config, build(NODE_PARAMETERS[node], {k: v for k, v in params.items() if k in own}, where=node)


def check_parameter_file(path: str | Path, nodes: Collection[str] = tuple(NODES), graph: str = "") -> None:
    """Refuse a ROS 2 parameter file with a section other than ``/**`` that names none of ``nodes`` (default:
    every node of any graph; ``graph``: the name of the graph they make, for the message) — a misspelt node name,
    a wildcard such as ``/*``, or a node the graph does not run would otherwise be ignored, its values never
    checked."""
    from moose.files import load_yaml, read_input

    # a FIFO, a device, bytes that are not text, invalid YAML, a section or key given twice: an error here
    document = load_yaml(read_input(path, "parameter file"), f"parameter file {str(path)!r}")
    if not isinstance(document, Mapping):
        return
    for section in document:
        if section != WILDCARD and str(section).lstrip("/") not in nodes:
            where = f"the graph {graph!r}" if graph else "the graph"
            raise ParamError(f"parameter file {str(path)!r}: section {section!r} names no node of {where}; "
                             f"sections: {WILDCARD!r} and {', '.join(nodes)}")
