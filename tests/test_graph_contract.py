"""The graph contract (moose_ros.graph) is the one definition of the graph: the nodes create exactly its
endpoints, and the launch files, setup.py's entry points, docker/compose.yaml and the docs agree with it."""
from __future__ import annotations

import ast
import dataclasses
import importlib.util
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from moose.canbus.bus import DEFAULT_GROUP
from moose.canbus.ecu import VehicleEcu
from moose.canbus.safety import GuardParams
from moose.params import ParamError
from moose.planner import MODE_PLANNERS
from moose.scenario import load_scenario
from moose_ros.graph import COMMAND_TIMEOUT, GRAPHS, GROUPS, NODES, TOPICS, publishes, subscribes, topic_table
from moose_ros.launch import node_overrides
from moose_ros.nodes import node_class
from moose_ros.parameters import NODE_PARAMETERS, node_parameters
from moose_ros.runtime import DdsNode

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "ros2_ws" / "src" / "moose_ros"
TOPIC_LITERAL = re.compile(
    r"""["'](/(?:clock|diagnostics|tf|tf_static|vehicle/\w+|perception/\w+|planning/\w+|control/\w+))["']""")


def test_topic_names_are_written_once_in_the_package() -> None:
    """Outside the contract (and the runtime's time source, /clock) no module names a topic of the graph."""
    found: dict[str, list[str]] = {}
    for path in sorted((PACKAGE / "moose_ros").rglob("*.py")):
        for name in TOPIC_LITERAL.findall(path.read_text(encoding="utf-8")):
            found.setdefault(name, []).append(str(path.relative_to(PACKAGE)))
    assert found.pop("/clock") == ["moose_ros/runtime/names.py"]
    assert found == {name: ["moose_ros/graph.py"] for name in TOPICS if name != "/clock"}


def test_contract_is_consistent() -> None:
    for topic in TOPICS.values():
        assert set(topic.publishers) | set(topic.subscribers) <= set(NODES), topic.name
        assert topic.publishers, topic.name
    for graph, nodes in GRAPHS.items():
        assert set(nodes) <= set(NODES), graph
    assert [n for g in GROUPS.values() for n in g] == list(NODES)
    assert set(NODE_PARAMETERS) == set(NODES)
    for name in NODES:
        assert node_class(name).name == name
    # one command timeout for the bridge's guard, the ECU emulator and the simulator, equal to the core's defaults
    assert COMMAND_TIMEOUT == GuardParams().timeout == VehicleEcu().timeout == 0.05
    assert {cls().command_timeout for cls in NODE_PARAMETERS.values() if hasattr(cls(), "command_timeout")} == {0.05}


@pytest.mark.parametrize("mode", ["msf", "aeb", "max_steer"])
def test_the_msf_planner_node_runs_the_planner_of_its_mode(mode: str) -> None:
    """The feed-forward slot of the graph: the MSF planner, or the baseline of a baseline mode."""
    rt = DdsNode("msf_planner", overrides={"use_sim_time": True, "scenario": "paper_v5_tau3",
                                           "simulation.planner": mode})
    node = None
    try:
        node = node_class("msf_planner")(rt)
        assert type(node.planner).__name__ == {"aeb": "AebPlanner", "max_steer": "MaxSteerPlanner"}.get(mode,
                                                                                                     "MsfPlanner")
    finally:
        if node is not None:
            node.close()
        rt.shutdown()


def _node_endpoints(name: str, tmp_path: Path) -> set[tuple[str, str, str, object]]:
    overrides = {"use_sim_time": name != "vehicle_simulator", "scenario": "paper_v5_tau3"}
    if name == "can_bridge":
        overrides = {"use_sim_time": True, "can_interface": "virtual", "can_channel": f"contract-{tmp_path.name}"}
    if name in ("obstacle_detector", "weight_fbl", "motion_controller"):
        overrides.pop("scenario")
    rt = DdsNode(name, overrides=overrides)
    node = None
    try:
        node = node_class(name)(rt)
        return {(e.kind, e.topic, e.type, e.qos) for e in rt.endpoints()}
    finally:
        if node is not None:
            node.close()
        rt.shutdown()


@pytest.mark.parametrize("name", list(NODES))
def test_each_node_creates_exactly_the_endpoints_of_the_contract(name: str, tmp_path: Path) -> None:
    expected = {("publisher", t.name, t.type, t.qos) for t in publishes(name)}
    expected |= {("subscription", t.name, t.type, t.subscription_qos) for t in subscribes(name)}
    assert _node_endpoints(name, tmp_path) == expected


def _launch_file(name: str) -> Any:
    """A ROS 2 launch file of the package as a module (it imports ``launch`` only when ROS 2 runs it)."""
    spec = importlib.util.spec_from_file_location(name.replace(".", "_"), PACKAGE / "launch" / name)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("with_simulator", [True, False])
@pytest.mark.parametrize("planner", list(MODE_PLANNERS))
def test_ros2_launch_file_starts_what_moose_launch_starts(with_simulator: bool, planner: str) -> None:
    """``ros2 launch moose_ros moose_graph.launch.py``, whole or one ECU group per launch (docker compose):
    the nodes of ``moose launch``'s graph (``full``, or ``car`` without the simulator) with its parameters."""
    graph_launch = _launch_file("moose_graph.launch.py")
    scenario = "paper_v7_tau2"
    graph = "full" if with_simulator else "car"
    started = {group: graph_launch.node_parameters(group, with_simulator, scenario, planner)
               for group in ["all", *GROUPS]}
    unused = {"mpc": "msf_planner", "msf": "mpc_planner", "aeb": "mpc_planner", "max_steer": "mpc_planner"}
    expected = [n for n in GRAPHS[graph] if n != unused.get(planner)]  # a baseline runs in the MSF planner's slot
    assert list(started["all"]) == expected
    by_group = [name for group in GROUPS for name in started[group]]
    assert sorted(by_group) == sorted(expected)  # every node once, whichever way the groups are launched
    assert all(set(started[group]) <= set(GROUPS[group]) for group in GROUPS)
    mu = load_scenario(scenario).mu
    for name, parameters in started["all"].items():
        (given,) = parameters
        assert given == node_overrides(graph, planner, {"scenario": scenario, "vehicle.mu": mu})[name]
        assert given["use_sim_time"] is (with_simulator and name != "vehicle_simulator")
        assert given["vehicle.mu"] == mu and given["simulation.planner"] == planner  # one road, one mode
    if with_simulator:  # it starts the clock once every other node of the graph has announced itself
        assert (started["vehicle"]["vehicle_simulator"][0]["wait_for"]
                == [n for n in expected if n != "vehicle_simulator"])
    params_file = str(ROOT / "config" / "moose.yaml")
    with_file = graph_launch.node_parameters("all", with_simulator, scenario, planner, params_file)
    assert all(p[0] == params_file and p[1] == started["all"][n][0] for n, p in with_file.items())
    if with_simulator:  # lockstep:=true gives what moose launch --lockstep gives
        lockstep = graph_launch.node_parameters("all", True, scenario, planner, lockstep=True)
        assert lockstep == {n: [v] for n, v in node_overrides(graph, planner, {"scenario": scenario, "vehicle.mu": mu},
                                                               lockstep=True).items()}
        assert all(v[0]["lockstep_nodes"] == expected and v[0]["use_sim_time"] is False for v in lockstep.values())
    else:
        with pytest.raises(ParamError, match="--lockstep needs the vehicle simulator"):
            graph_launch.node_parameters("all", False, scenario, planner, lockstep=True)


def test_ros2_launch_files_start_the_package_executables() -> None:
    """The Node actions run the console scripts of setup.py under their own names; the car's launch is the
    graph's without the simulator."""
    tree = ast.parse((PACKAGE / "launch" / "moose_graph.launch.py").read_text(encoding="utf-8"))
    calls = [c for c in ast.walk(tree) if isinstance(c, ast.Call) and getattr(c.func, "id", "") == "Node"]
    assert len(calls) == 1
    keywords = {k.arg: ast.unparse(k.value) for k in calls[0].keywords}
    assert keywords == {"package": "'moose_ros'", "executable": "name", "name": "name", "output": "'screen'",
                        "parameters": "parameters"}
    car = (PACKAGE / "launch" / "moose_car.launch.py").read_text(encoding="utf-8")
    assert '"moose_graph.launch.py"' in car and 'launch_arguments={"with_simulator": "false"}' in car


def test_setup_entry_points_and_compose_follow_the_contract() -> None:
    setup = (PACKAGE / "setup.py").read_text(encoding="utf-8")
    assert ast.literal_eval(re.search(r"NODES = (\[.*?\])", setup, re.S).group(1)) == list(NODES)
    import yaml

    compose = yaml.safe_load((ROOT / "docker" / "compose.yaml").read_text(encoding="utf-8"))
    assert set(compose["services"]) == set(GROUPS)


def test_docs_topic_table_is_the_contracts() -> None:
    graph = (ROOT / "docs" / "graph.md").read_text(encoding="utf-8")
    assert topic_table() in graph, \
        "regenerate with: python -c 'from moose_ros.graph import topic_table; print(topic_table())'"


def test_can_defaults_have_one_definition() -> None:
    """The multicast group and port are moose.canbus.bus's: no other module writes them."""
    for path in [*sorted((PACKAGE / "moose_ros").rglob("*.py")),
                 *sorted((ROOT / "src" / "moose" / "cli").glob("*.py"))]:
        text = path.read_text(encoding="utf-8")
        assert DEFAULT_GROUP not in text and "43113" not in text, path
    for cls in NODE_PARAMETERS.values():
        fields = {f.name: f.default for f in dataclasses.fields(cls)}
        assert fields.get("can_channel") is None and fields.get("can_port") is None
    assert node_parameters("can_bridge", {})[1].can_interface == "udp_multicast"


LEAN = ("motion_controller", "can_bridge", "weight_fbl")
HEAVY = ("casadi", "moose.planner.mpc", "moose.planner.msf", "moose.maneuver", "scipy")


def _loaded_after(code: str, heavy: tuple[str, ...] = HEAVY) -> list[str]:
    probe = code + f"\nimport sys\nprint(sorted(m for m in {heavy!r} if m in sys.modules))"
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    return ast.literal_eval(result.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("name", LEAN)
def test_a_lean_node_module_imports_neither_casadi_nor_the_planners(name: str) -> None:
    assert _loaded_after(f"from moose_ros.nodes import node_class\nnode_class({name!r})") == []


OFF_THE_BUS = ("cantools", "can")
"""The DBC's parser and python-can: about 6 MB of each process that loads them (bench/bench_memory.py)."""


@pytest.mark.parametrize("name, absent", [
    ("observer", OFF_THE_BUS), ("mpc_planner", OFF_THE_BUS), ("weight_fbl", OFF_THE_BUS),
    ("motion_controller", OFF_THE_BUS), ("obstacle_detector", ("casadi", *OFF_THE_BUS)),
    ("msf_planner", ("casadi", *OFF_THE_BUS)),
])
def test_a_running_node_off_the_bus_loads_neither_the_dbc_parser_nor_casadi_for_a_cached_table(
        name: str, absent: tuple[str, ...]) -> None:
    """Once the car's CAN hops (moose.car_chain.car_hops) and the maneuver table are in the machine's cache, a node that
    does not talk to the bus reads the delays without cantools, and the detector and the MSF planner read the table
    without CasADi: the first start fills the cache, the second is what every later start is."""
    code = (f"from moose_ros.nodes import node_class\nfrom moose_ros.runtime import DdsNode\n"
            f"rt = DdsNode({name!r})\nnode = node_class({name!r})(rt)\nrt.shutdown()")
    _loaded_after(code, absent)
    assert _loaded_after(code, absent) == []


@pytest.mark.parametrize("name", ["motion_controller", "can_bridge", "weight_fbl"])
def test_a_running_lean_node_has_not_loaded_casadi(name: str) -> None:
    overrides = {"can_interface": "virtual", "can_channel": "lean-probe"} if name == "can_bridge" else {}
    code = (f"from moose_ros.nodes import node_class\nfrom moose_ros.runtime import DdsNode\n"
            f"rt = DdsNode({name!r}, overrides={overrides!r})\nnode = node_class({name!r})(rt)\nrt.shutdown()")
    assert _loaded_after(code) == []
