"""The ROS 2 Jazzy prefix of ``make ros`` for tests: is it there and current, and the environments of
processes that talk over it on this host only.

Tests that need rclpy take the ``ros_env`` fixture (import it into the test module): skipped, saying
why, when the prefix has not been made; with ``MOOSE_REQUIRE_ROS=1`` (CI) that is a failure, and so is
a prefix built from other sources (a changed ``.msg`` file, other wheels): ``make ros`` brings it up
to date.  Both vendors discover on this host only: rclpy by Jazzy's
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (rmw_fastrtps reads it), our Cyclone runtime by the
configuration rmw_cyclonedds makes of it (``dds_env``), in the test's own domain (conftest.py).
"""
from __future__ import annotations

import functools
import importlib.util
import os
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]

CYCLONE_LOCALHOST = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
    '<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex><Peers><Peer address="localhost"/></Peers>'
    "</Discovery></Domain></CycloneDDS>"
)
"""What rmw_cyclonedds (Jazzy) makes of ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (no multicast, localhost
as the only peer, participant indices for unicast discovery), bound to the loopback interface."""


def _load_ros_prefix() -> Any:
    spec = importlib.util.spec_from_file_location("ros_prefix", REPO / "ros2_ws" / "ros_prefix.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


ros_prefix = _load_ros_prefix()


@functools.lru_cache(maxsize=None)
def prefix_problem(prefix: Path) -> tuple[str, str]:
    """('skip' | 'fail' | '', reason) for the prefix at ``prefix``."""
    if not (prefix / ros_prefix.ENV_FILE).is_file():
        return "skip", (f"the ROS 2 Jazzy prefix is not built ({prefix / ros_prefix.ENV_FILE} is missing): "
                        "`make ros` installs rclpy from wheels and builds moose_msgs (README, 'ROS 2 client')")
    stamp = prefix / ros_prefix.INSTALL_KEY_FILE
    if not stamp.is_file() or stamp.read_text(encoding="utf-8").strip() != ros_prefix.install_key():
        return "fail", (f"{prefix} was installed from other requirements, another checkout or another Python: "
                        "run `make ros`")
    info = ros_prefix.query(prefix)
    built = prefix / "install" / ros_prefix.BUILD_KEY_FILE
    if not built.is_file() or built.read_text(encoding="utf-8").strip() != ros_prefix.build_key(info):
        return "fail", f"moose_msgs in {prefix} is not built from the current sources: run `make ros`"
    return "", ""


@pytest.fixture
def ros_env() -> dict[str, str]:
    """The environment of an rclpy process: the prefix's variables, on this host only, in the test's own domain
    (made for each test: conftest.py's ``dds_domain`` claims a domain per test)."""
    prefix = ros_prefix.default_prefix()
    verdict, reason = prefix_problem(prefix)
    if verdict == "skip" and os.environ.get("MOOSE_REQUIRE_ROS") != "1":
        pytest.skip(reason)
    if verdict:
        pytest.fail(reason)
    return ros_prefix.environment(prefix, {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})


@pytest.fixture(scope="session")
def cyclone_localhost(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The URI of a Cyclone DDS configuration file of :data:`CYCLONE_LOCALHOST`."""
    config = tmp_path_factory.mktemp("dds-localhost") / "cyclonedds.xml"
    config.write_text(CYCLONE_LOCALHOST)
    return config.as_uri()


@pytest.fixture
def dds_env(cyclone_localhost: str) -> dict[str, str]:
    """The environment of a process on our Cyclone DDS runtime that is to meet rclpy on this host, in the test's
    own domain."""
    return {**os.environ, "CYCLONEDDS_URI": cyclone_localhost, "MOOSE_RUNTIME": "dds"}
