"""DDS discovery settings: ROS 2's variables mapped to Cyclone DDS as rmw_cyclonedds maps them, confined by default.

The behaviour on the network is tested from a second network namespace in tests/test_network_confinement.py;
these tests pin the mapping itself (rmw_cyclonedds' check_create_domain, Jazzy) and the error messages.
"""
from __future__ import annotations

import ast
import os
import shlex
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from isolation import claim_domain
from moose.params import ParamError
from moose_ros.runtime.discovery import FASTDDS_PROFILE, Discovery, names_interface, udp_bindings

LO_XML = ('<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces></General></Domain>'
          '</CycloneDDS>')


def parts(config: str) -> list[ET.Element]:
    return [ET.fromstring(p) for p in config.split(",") if p]


def test_unset_means_this_host_bound_to_loopback() -> None:
    d = Discovery.from_environ({})
    assert d.range == "LOCALHOST" and d.cyclone_loopback
    root = parts(d.cyclone_config())[0]
    assert [e.get("address") for e in root.iter("NetworkInterface")] == ["127.0.0.1"]
    assert root.findtext("Domain/General/AllowMulticast") == "false"
    assert [p.get("address") for p in root.iter("Peer")] == ["127.0.0.1"]
    assert root.findtext("Domain/Discovery/ParticipantIndex") == "auto"
    assert root.findtext("Domain/Discovery/MaxAutoParticipantIndex") == "32"
    assert Discovery.from_environ({"ROS_AUTOMATIC_DISCOVERY_RANGE": ""}).range == "LOCALHOST"


def test_each_range_maps_like_rmw_cyclonedds() -> None:
    subnet = Discovery.from_environ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
                                     "ROS_STATIC_PEERS": "10.0.0.7;car2.lan"})
    root = parts(subnet.cyclone_config())[0]
    assert list(root.iter("NetworkInterface")) == [] and root.find("Domain/General") is None  # multicast, any interface
    assert [p.get("address") for p in root.iter("Peer")] == ["10.0.0.7", "car2.lan"]
    assert root.findtext("Domain/Discovery/ParticipantIndex") == "auto"
    off = Discovery.from_environ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": "10.0.0.7"})
    root = parts(off.cyclone_config(pid=4242))[0]
    assert root.findtext("Domain/Discovery/Tag") == "ros_discovery_off_4242" and list(root.iter("Peer")) == []
    assert root.findtext("Domain/Discovery/ParticipantIndex") == "none" and off.ignored_peers == ("10.0.0.7",)
    system = Discovery.from_environ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SYSTEM_DEFAULT", "ROS_STATIC_PEERS": "h"})
    assert system.cyclone_config() is None and system.ignored_peers == ("h",)
    # LOCALHOST with static peers: localhost and the peers, multicast off; no loopback binding (the peers are elsewhere)
    peers = Discovery.from_environ({"ROS_STATIC_PEERS": " 10.0.0.7 ; ;fd00::2"})
    root = parts(peers.cyclone_config())[0]
    assert [p.get("address") for p in root.iter("Peer")] == ["127.0.0.1", "10.0.0.7", "fd00::2"]
    assert not peers.cyclone_loopback and list(root.iter("NetworkInterface")) == []


def test_deprecated_localhost_only_prevails_and_drops_the_peers() -> None:
    d = Discovery.from_environ({"ROS_LOCALHOST_ONLY": "1", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
                                "ROS_STATIC_PEERS": "10.0.0.7"})
    assert d.range == "LOCALHOST" and d.static_peers == () and d.cyclone_loopback and d.ignored_peers == ("10.0.0.7",)
    environ = {"ROS_LOCALHOST_ONLY": "0", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert Discovery.from_environ(environ).range == "SUBNET"


@pytest.mark.parametrize(("env", "match"), [
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "subnet"}, "ROS_AUTOMATIC_DISCOVERY_RANGE = 'subnet' is invalid"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "ALL"}, "expected one of LOCALHOST, SUBNET, SYSTEM_DEFAULT, OFF"),
    ({"ROS_STATIC_PEERS": '10.0.0.7"/><Peer address="evil'}, "ROS_STATIC_PEERS: .* is invalid"),
    ({"ROS_LOCALHOST_ONLY": "yes"}, "ROS_LOCALHOST_ONLY = 'yes' is invalid"),
    # the probe's rerun: a profiles file that does not exist left Fast DDS on its defaults, the bridge reachable
    ({"FASTRTPS_DEFAULT_PROFILES_FILE": "/nonexistent.xml"}, "FASTRTPS_DEFAULT_PROFILES_FILE = '/nonexistent.xml' "
                                                             "names no file"),
])
def test_bad_values_are_refused_with_the_variable_named(env: dict, match: str) -> None:
    with pytest.raises(ParamError, match=match):
        Discovery.from_environ(env)


def test_the_users_uri_comes_last_and_its_interfaces_replace_the_loopback_binding(tmp_path: Path) -> None:
    tracing = "<CycloneDDS><Domain><Tracing><Verbosity>config</Verbosity></Tracing></Domain></CycloneDDS>"
    d = Discovery.from_environ({"CYCLONEDDS_URI": tracing})
    assert d.cyclone_loopback and d.cyclone_config().endswith("," + tracing)  # read after the range: it wins
    inline = Discovery.from_environ({"CYCLONEDDS_URI": LO_XML})
    assert not inline.cyclone_loopback and inline.cyclone_config().count("NetworkInterface") == 1
    file = tmp_path / "dds.xml"
    file.write_text(LO_XML)
    assert names_interface(file.as_uri()) and names_interface(str(file))
    assert names_interface("file:///nonexistent/dds.xml")  # unreadable: never add a second interface to it
    assert not names_interface(tracing) and not names_interface("")
    assert "names network interfaces" in Discovery.from_environ({"CYCLONEDDS_URI": file.as_uri()}).describe()


def test_ros_environment_gives_ros2_tools_the_same_settings() -> None:
    env = Discovery.from_environ({}).ros_environment()
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST" and "127.0.0.1" in env["CYCLONEDDS_URI"]
    again = Discovery.from_environ(env)  # idempotent: the binding is not added twice
    assert "CYCLONEDDS_URI" not in again.ros_environment() and not again.cyclone_loopback  # left as it is
    assert again.cyclone_config().count("NetworkInterface") == 1
    subnet = Discovery.from_environ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "10.0.0.7"})
    assert subnet.ros_environment() == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "10.0.0.7",
                                        "CYCLONEDDS_URI": subnet.fragment()}  # the peers for a plain tool too
    off = Discovery.from_environ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}).ros_environment()
    assert off == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}  # nothing outside a process sees its graph
    mine = Discovery.from_environ({"CYCLONEDDS_URI": LO_XML})  # the user's interface: no loopback binding added
    assert mine.ros_environment()["CYCLONEDDS_URI"] == mine.fragment() + "," + LO_XML
    assert "CYCLONEDDS_URI" not in Discovery.from_environ(mine.ros_environment()).ros_environment()
    out = subprocess.run([sys.executable, "-m", "moose_ros.runtime"], capture_output=True, text=True, timeout=60,
                         env={"PATH": "/usr/bin:/bin"})
    assert out.returncode == 0 and out.stderr == ""
    assert out.stdout.splitlines()[0] == "export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"


PROBE_NODE = """
import sys
from moose_ros.runtime import DdsNode
rt = DdsNode("discovery_probe")
rt.publisher("rosgraph_msgs/msg/Clock", "/probe_clock")
print("ready", flush=True)
sys.stdin.read()  # until the test closes stdin
rt.shutdown()
"""
PLAIN_READER = """
import sys, time
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.domain import DomainParticipant
participant = DomainParticipant(int(sys.argv[1]))  # kept: the reader dies with it
reader = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
seen, deadline = set(), time.monotonic() + 30.0
while "rt/probe_clock" not in seen and time.monotonic() < deadline:
    seen.update(sample.topic_name for sample in reader.take(N=100))
    time.sleep(0.05)
print(sorted(seen))
"""


def test_a_plain_cyclone_dds_participant_with_the_printed_settings_discovers_a_running_node() -> None:
    """``eval "$(python -m moose_ros.runtime)"`` is all a plain Cyclone DDS tool needs to see a graph confined to this
    host: a cyclonedds-python participant (no rmw_cyclonedds to add the range's settings) finds a node's writer."""
    clean = {k: v for k, v in os.environ.items()
             if k not in ("CYCLONEDDS_URI", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY")}
    clean.update(ROS_DOMAIN_ID=str(claim_domain()), MOOSE_RUNTIME="dds")  # the default: LOCALHOST, on loopback
    printed = subprocess.run([sys.executable, "-m", "moose_ros.runtime"], env=clean, capture_output=True, text=True,
                             timeout=60)
    assert printed.returncode == 0, printed.stderr
    tool = dict(clean)
    for line in printed.stdout.splitlines():
        export, assignment = shlex.split(line)
        key, value = assignment.split("=", 1)
        assert export == "export"
        tool[key] = value
    node = subprocess.Popen([sys.executable, "-c", PROBE_NODE], env=clean, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert node.stdout is not None and node.stdout.readline().strip() == "ready"
        seen = subprocess.run([sys.executable, "-c", PLAIN_READER, clean["ROS_DOMAIN_ID"]], env=tool,
                              capture_output=True, text=True, timeout=90)
        assert "rt/probe_clock" in ast.literal_eval(seen.stdout.strip() or "[]"), seen.stderr
    finally:
        assert node.stdin is not None
        node.stdin.close()
        try:
            node.wait(timeout=30)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()


def test_the_generated_configuration_is_accepted_by_cyclone_dds() -> None:
    """Every range's configuration creates a domain (in a child process, in domains of this test run's own)."""
    domains = [claim_domain() for _ in range(4)]
    script = ("import sys\nfrom cyclonedds.domain import Domain, DomainParticipant\n"
              "from moose_ros.runtime.discovery import Discovery\n"
              "ids = [int(a) for a in sys.argv[1:]]\n"
              "for i, r in enumerate(['LOCALHOST', 'SUBNET', 'OFF']):\n"
              "    d = Discovery.from_environ({'ROS_AUTOMATIC_DISCOVERY_RANGE': r, 'ROS_STATIC_PEERS': '127.0.0.2'})\n"
              "    Domain(ids[i], d.cyclone_config()); DomainParticipant(ids[i])\n"
              "Domain(ids[3], Discovery.from_environ({}).cyclone_config()); DomainParticipant(ids[3])\n"
              "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", script, *map(str, domains)], capture_output=True, text=True,
                         timeout=60)
    assert out.stdout.strip() == "ok", out.stderr


def test_fast_dds_gets_the_loopback_profile_and_the_range_in_it(tmp_path: Path) -> None:
    """rmw_fastrtps' LOCALHOST adds a UDP transport on every interface to any profile's: an rclpy node on Fast DDS
    asks it for SYSTEM_DEFAULT, and the profile (loopback UDP, 127.0.0.1 as the peer, no multicast) is the range."""
    env = Discovery.from_environ({}).rclpy_environment()
    assert Discovery.from_environ({"ROS_LOCALHOST_ONLY": "1"}).rclpy_environment() == {**env, "ROS_LOCALHOST_ONLY": "0"}
    assert env == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SYSTEM_DEFAULT",
                   "SKIP_DEFAULT_XML_FILE": "1", "FASTRTPS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILE),
                   "FASTDDS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILE)}
    ns = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    profile = ET.parse(FASTDDS_PROFILE).getroot()
    assert [a.text for a in profile.iterfind(".//f:interfaceWhiteList/f:address", ns)] == ["127.0.0.1"]
    assert profile.findtext(".//f:useBuiltinTransports", namespaces=ns) == "false"
    assert profile.find(".//f:metatrafficMulticastLocatorList", ns) is None
    assert [a.text for a in profile.iterfind(".//f:initialPeersList//f:address", ns)] == ["127.0.0.1"]
    assert profile.find(".//f:participant", ns).get("is_default_profile") == "true"
    # the opt-ins, a profile of the user's and other RMWs keep ROS 2's own settings
    for environ in ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, {"ROS_STATIC_PEERS": "10.0.0.7"},
                    {"FASTRTPS_DEFAULT_PROFILES_FILE": str(mine(tmp_path))},
                    {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}, {"RMW_IMPLEMENTATION": "rmw_zenoh_cpp"}):
        d = Discovery.from_environ(environ)
        assert d.rclpy_environment() == d.ros_environment(), environ


def mine(folder: Path) -> Path:
    """A Fast DDS profiles file of the user's."""
    path = folder / "mine.xml"
    path.write_text('<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"/>')
    return path


def test_the_log_line_says_how_each_runtime_holds_the_range(tmp_path: Path) -> None:
    here = "LOCALHOST: this host only, "
    d = Discovery.from_environ({})
    assert d.describe() == here + "Cyclone DDS on the loopback interface"
    assert d.describe("rmw_fastrtps_cpp") == here + "Fast DDS bound to loopback (fastdds_loopback.xml)"
    assert d.describe("rmw_cyclonedds_cpp") == d.describe()
    assert d.describe("rmw_zenoh_cpp") == here + "ROS 2's own on rmw_zenoh_cpp (not bound to loopback by moose)"
    users = Discovery.from_environ({"FASTRTPS_DEFAULT_PROFILES_FILE": str(mine(tmp_path))})
    assert users.describe("rmw_fastrtps_cpp") == (here + f"then the Fast DDS profiles of {mine(tmp_path)} (not bound "
                                                  "to loopback by moose)")
    peers = Discovery.from_environ({"ROS_STATIC_PEERS": "10.0.0.7"})
    # the probe: "this host only" while a host not named reached the bridge; static peers open the graph
    for rmw in ("rmw_fastrtps_cpp", None):
        assert peers.describe(rmw) == ("LOCALHOST: this host and the static peers, static peers 10.0.0.7 (not "
                                       "confined: bound to every interface, the graph can be reached by any host "
                                       "that knows its address)")


def test_udp_bindings_reads_this_process_sockets() -> None:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as a, socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as b:
        a.bind(("127.0.0.1", 0))
        b.bind(("::1", 0))
        found = set((udp_bindings() or {}).values())
        assert ("127.0.0.1", a.getsockname()[1]) in found and ("[::1]", b.getsockname()[1]) in found


def test_an_rclpy_node_refuses_to_run_when_fast_dds_did_not_apply_the_profile(ros_env: dict[str, str],
                                                                            tmp_path: Path) -> None:
    """The check after the participant is made: a profile that does not bind to loopback (here: Fast DDS's
    built-in transports) leaves sockets on every address, and the node refuses to start, naming them."""
    loose = tmp_path / "loose.xml"
    loose.write_text('<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"><profiles>'
                     '<participant profile_name="loose" is_default_profile="true"><rtps/></participant>'
                     "</profiles></dds>")
    script = ("import sys\nfrom pathlib import Path\nimport moose_ros.runtime.discovery as d\n"
              "d.FASTDDS_PROFILE = Path(sys.argv[1])\nfrom moose.params import ParamError\n"
              "from moose_ros.runtime import create_node\n"
              "try:\n    create_node('probe')\nexcept ParamError as exc:\n    print(exc)\n")
    env = {k: v for k, v in ros_env.items() if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "CYCLONEDDS_URI")}
    out = subprocess.run([env["MOOSE_ROS_PYTHON"], "-c", script, str(loose)], capture_output=True, text=True,
                         timeout=120, env={**env, "MOOSE_RUNTIME": "rclpy"})
    assert f"Fast DDS did not apply {loose}: UDP sockets bound to 0.0.0.0:" in out.stdout, out.stdout + out.stderr
    assert "refusing to run a node that the network can reach" in out.stdout


def test_ros_localhost_only_keeps_an_rclpy_node_on_loopback(ros_env: dict[str, str]) -> None:
    """The probe's rerun: with the deprecated ``ROS_LOCALHOST_ONLY=1`` rmw_fastrtps set up transports of its own on
    every interface beside the profile's, and every rclpy node refused to start.  The switch means LOCALHOST, so
    the profile holds it: the node runs, bound to loopback only."""
    script = ("from moose_ros.runtime import create_node\nfrom moose_ros.runtime.discovery import udp_bindings\n"
              "node = create_node('localhost_only')\n"
              "print(sorted({a for a, _ in (udp_bindings() or {}).values()}))\nprint(node.describe_discovery())\n"
              "node.shutdown()\n")
    env = {k: v for k, v in ros_env.items() if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "CYCLONEDDS_URI")}
    out = subprocess.run([env["MOOSE_ROS_PYTHON"], "-c", script], capture_output=True, text=True, timeout=120,
                         env={**env, "MOOSE_RUNTIME": "rclpy", "ROS_LOCALHOST_ONLY": "1"})
    assert out.returncode == 0, out.stdout + out.stderr
    addresses, line = out.stdout.splitlines()[-2:]
    assert addresses == "['127.0.0.1']", out.stdout
    assert line.startswith("LOCALHOST: this host only, Fast DDS bound to loopback"), line
