"""Test-run isolation: a DDS domain of our own on loopback only, and a private compile cache."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from isolation import claim_domain
from ros2_prefix import dds_env, ros_env  # noqa: F401 - fixtures of the ROS 2 prefix tests


@pytest.fixture(scope="session", autouse=True)
def dds_loopback(tmp_path_factory: pytest.TempPathFactory) -> None:
    """A ROS_DOMAIN_ID claimed for this test run (tests/isolation.py); Cyclone DDS bound to the loopback interface."""
    config = tmp_path_factory.mktemp("dds") / "cyclonedds.xml"
    config.write_text(
        '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
        "<AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>"
    )
    os.environ["ROS_DOMAIN_ID"] = str(claim_domain())
    os.environ["CYCLONEDDS_URI"] = config.as_uri()
    os.environ["MOOSE_RUNTIME"] = "dds"
    os.environ.setdefault("MOOSE_CACHE_DIR", str(Path.home() / ".cache" / "moose"))
