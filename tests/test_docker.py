"""The Docker image and compose file stay consistent with the workspace (they cannot be run here)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
WORKSPACE = ROOT / "ros2_ws" / "src"


def packages() -> set[str]:
    return {p.parent.name for p in WORKSPACE.glob("*/package.xml")}


def test_dockerfile_builds_every_workspace_package_on_jazzy() -> None:
    text = (ROOT / "docker" / "Dockerfile").read_text()
    assert re.search(r"^FROM ros:jazzy", text, re.M)
    selected = set(re.search(r"--packages-select ([\w ]+)", text).group(1).split())
    assert selected == packages() == {"moose_msgs", "moose_ros"}
    assert "COPY ros2_ws/src" in text and "colcon build" in text
    for path in re.findall(r"^COPY (\S+) ", text, re.M):
        assert (ROOT / path).exists(), path
    # the install path of tests/test_install.py: wheels of both packages, installed with their dependencies; the
    # data files ship inside the core's wheel (no COPY config)
    assert "COPY src ./src" in text and "COPY config" not in text
    assert "pip wheel --no-cache-dir --no-deps -w /tmp/wheels . ros2_ws/src/moose_ros" in text
    assert re.search(r"pip install --no-cache-dir /tmp/wheels/moose_avoidance-\*\.whl .*moose_ros-\*\.whl", text)


def test_compose_services_launch_existing_groups_and_executables() -> None:
    from moose_ros.graph import GROUPS, NODES

    compose = yaml.safe_load((ROOT / "docker" / "compose.yaml").read_text())
    setup = (WORKSPACE / "moose_ros" / "setup.py").read_text()
    executables = set(ast.literal_eval(re.search(r"NODES = (\[.*?\])", setup, re.S).group(1)))
    assert {n for g in GROUPS.values() for n in g} == executables == set(NODES)
    services = compose["services"]
    assert set(services) == set(GROUPS)
    for name, service in services.items():
        assert service["command"][:4] == ["ros2", "launch", "moose_ros", "moose_graph.launch.py"]
        assert service["command"][4] == f"group:={name}"
    assert services["bridge"]["profiles"] == ["car"] and "with_simulator:=false" in services["bridge"]["command"]


def test_containers_keep_dds_on_the_host_unless_the_user_opts_in() -> None:
    """Host networking shares the network, not the graph: discovery defaults to LOCALHOST in the image and in
    every service, and the opt-ins (range, static peers, CYCLONEDDS_URI) pass through from the caller."""
    text = (ROOT / "docker" / "Dockerfile").read_text()
    assert re.search(r"^\s+ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST\s*$", text, re.M)
    compose = yaml.safe_load((ROOT / "docker" / "compose.yaml").read_text())
    for name, service in compose["services"].items():
        env = service["environment"]
        assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}", name
        assert env["ROS_STATIC_PEERS"] == "${ROS_STATIC_PEERS:-}" and env["CYCLONEDDS_URI"] == "${CYCLONEDDS_URI:-}"


def test_msg_package_lists_every_message_file() -> None:
    cmake = (WORKSPACE / "moose_msgs" / "CMakeLists.txt").read_text()
    listed = set(re.findall(r'"msg/(\w+)\.msg"', cmake))
    assert listed == {p.stem for p in (WORKSPACE / "moose_msgs" / "msg").glob("*.msg")}
