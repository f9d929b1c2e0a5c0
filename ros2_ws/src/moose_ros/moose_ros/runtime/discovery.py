"""How far DDS discovery reaches: ROS 2's ``ROS_AUTOMATIC_DISCOVERY_RANGE`` and ``ROS_STATIC_PEERS`` as
Cyclone DDS settings and as a Fast DDS profile, confined to this host unless the user opts in.

The variables mean what they mean to ROS 2 Jazzy (rcl reads them, rmw_cyclonedds maps them to a
configuration fragment that it puts *before* ``CYCLONEDDS_URI``, rmw_fastrtps to participant settings),
with two differences that keep a graph that can steer a car off the network by default:

- **The default is ``LOCALHOST``**, not ROS 2's ``SUBNET``: an unset or empty variable confines
  discovery to this host.  ``SUBNET`` (multicast discovery on the local network), ``SYSTEM_DEFAULT``
  (the middleware's own defaults, for Cyclone DDS only ``CYCLONEDDS_URI``) and ``OFF`` (no discovery at
  all, not even between processes of this host) are explicit opt-ins.  A value ROS 2 does not know is an
  error here (rcl warns and assumes ``LOCALHOST``).  The deprecated ``ROS_LOCALHOST_ONLY=1`` still
  forces ``LOCALHOST`` and drops the static peers, as in rcl.
- **``LOCALHOST`` without static peers is bound to loopback**, on every runtime.  ROS 2's ``LOCALHOST``
  only turns multicast off and adds ``localhost`` as a peer, so a participant on another host that names
  this host as its peer is still discovered and matched (both are tested from a second network namespace
  in tests/test_network_confinement.py):

  - Cyclone DDS (our DDS backend, and rmw_cyclonedds through ``CYCLONEDDS_URI``) is bound to the loopback
    *interface* (``127.0.0.1``) when ``CYCLONEDDS_URI`` names no interface: it ignores participants whose
    addresses are not on loopback, but its sockets still listen on all addresses.
  - Fast DDS (rmw_fastrtps, the rclpy of the Jazzy wheels) gets :data:`FASTDDS_PROFILE`, one UDP transport
    allow-listed to ``127.0.0.1``: every socket is bound to 127.0.0.1.  rmw_fastrtps' own ``LOCALHOST`` adds
    a UDP transport on every interface and shared memory to whatever the profile gives, so the node asks
    rmw_fastrtps for ``SYSTEM_DEFAULT`` and the profile carries the range (:meth:`Discovery.rclpy_environment`),
    unless ``FASTRTPS_DEFAULT_PROFILES_FILE`` names a profile of the user's.

Settings per range (the fragment that comes first; rmw_cyclonedds' values):

========================  ==================================================================================
``LOCALHOST``             loopback interface, no multicast, peers ``127.0.0.1`` and the static peers,
                          participant index ``auto`` up to 32 (at most 33 processes per domain on a host)
``SUBNET``                Cyclone's interface choice and multicast, the static peers, participant index
                          ``auto`` up to 32
``SYSTEM_DEFAULT``        nothing (static peers are ignored, as rmw_cyclonedds does)
``OFF``                   no multicast, no peers, participant index ``none``, a per-process domain tag
========================  ==================================================================================

``CYCLONEDDS_URI`` wins: it is read after the fragment (as rmw_cyclonedds reads it), so any setting it
makes overrides the range's, and the interfaces and peers it lists are added.  A URI that names a
network interface replaces the loopback binding: naming ``lo`` keeps the graph on this host, naming
``eth0`` opens it to that network — which is then the user's explicit choice.  So does a Fast DDS
profile of the user's (``FASTRTPS_DEFAULT_PROFILES_FILE``) for rmw_fastrtps.

The Cyclone DDS backend passes :meth:`Discovery.cyclone_config` to its domain; the rclpy backend sets
:meth:`Discovery.rclpy_environment` while it initialises rclpy and creates its node, and checks afterwards
that Fast DDS bound no new socket elsewhere (:func:`udp_bindings`).  ``python -m moose_ros.runtime`` prints
:meth:`Discovery.ros_environment` as shell ``export`` lines, for ROS 2 tools (``ros2 topic echo``) and plain
Cyclone DDS tools (``cyclonedds ls``) that should see a confined graph: the range, and the range's Cyclone DDS
settings in ``CYCLONEDDS_URI`` (a plain Cyclone DDS participant has no rmw_cyclonedds to add them; Fast DDS
tools keep ROS 2's ``LOCALHOST``, not the loopback binding).
"""
from __future__ import annotations

import dataclasses
import ipaddress
import os
import re
import struct
from pathlib import Path
from typing import Mapping, Optional
from urllib.parse import unquote, urlparse

from moose.params import ParamError

RANGES = ("LOCALHOST", "SUBNET", "SYSTEM_DEFAULT", "OFF")
"""The values of ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (ROS 2 Jazzy)."""
DEFAULT_RANGE = "LOCALHOST"
"""The range when the variable is unset or empty (ROS 2's own default is ``SUBNET``)."""
MAX_PARTICIPANT_INDEX = 32
"""rmw_cyclonedds' ``MaxAutoParticipantIndex``: processes per domain and host that unicast discovery reaches."""
LOOPBACK = "127.0.0.1"
FASTDDS_PROFILE = Path(__file__).with_name("fastdds_loopback.xml")
"""The Fast DDS profile of ``LOCALHOST`` bound to loopback (shipped with the package)."""
FASTDDS_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
"""Where Fast DDS reads its default profiles file: 2.x (ROS 2 Jazzy) and 3.x."""
FASTDDS_RMWS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")
DEFAULT_RMW = "rmw_fastrtps_cpp"
"""The RMW implementation of ROS 2 Jazzy when ``RMW_IMPLEMENTATION`` is unset."""

_PEER = re.compile(r"^[A-Za-z0-9._:%\[\]-]+$")
"""A host name or an IPv4/IPv6 address (no characters that could leave the XML attribute)."""


@dataclasses.dataclass(frozen=True)
class Discovery:
    """The discovery settings of this process, from its environment (:meth:`from_environ`)."""

    range: str = DEFAULT_RANGE
    static_peers: tuple[str, ...] = ()
    user_uri: str = ""
    """``CYCLONEDDS_URI`` as given (``""``: unset)."""
    ignored_peers: tuple[str, ...] = ()
    """Static peers the range ignores (``OFF``, ``SYSTEM_DEFAULT``, ``ROS_LOCALHOST_ONLY=1``)."""
    user_fastdds_profiles: str = ""
    """``FASTRTPS_DEFAULT_PROFILES_FILE`` (Fast DDS 3: ``FASTDDS_DEFAULT_PROFILES_FILE``) as given; ``""``: unset."""
    rmw: str = DEFAULT_RMW
    """The RMW implementation an rclpy node of this process loads (``RMW_IMPLEMENTATION``)."""
    localhost_only: bool = False
    """``ROS_LOCALHOST_ONLY=1`` (deprecated) was set: the range is ``LOCALHOST`` whatever else says."""

    @classmethod
    def from_environ(cls, environ: Mapping[str, str] = os.environ) -> "Discovery":
        """Read ``ROS_AUTOMATIC_DISCOVERY_RANGE``, ``ROS_STATIC_PEERS``, ``ROS_LOCALHOST_ONLY`` and
        ``CYCLONEDDS_URI``; a value ROS 2 would not accept is a :class:`ParamError` naming it."""
        raw = environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "")
        if raw and raw not in RANGES:
            raise ParamError(f"ROS_AUTOMATIC_DISCOVERY_RANGE = {raw!r} is invalid: expected one of {', '.join(RANGES)} "
                             f"(unset: {DEFAULT_RANGE})")
        chosen = raw or DEFAULT_RANGE
        peers = tuple(p.strip() for p in environ.get("ROS_STATIC_PEERS", "").split(";") if p.strip())
        for peer in peers:
            if not _PEER.match(peer):
                raise ParamError(f"ROS_STATIC_PEERS: {peer!r} is invalid: expected a host name or an IP address")
        localhost_only = environ.get("ROS_LOCALHOST_ONLY", "")
        if localhost_only not in ("", "0", "1"):
            raise ParamError(f"ROS_LOCALHOST_ONLY = {localhost_only!r} is invalid: expected 0 or 1 (deprecated: use "
                             "ROS_AUTOMATIC_DISCOVERY_RANGE)")
        if localhost_only == "1":  # rcl: the deprecated switch prevails and drops the static peers
            chosen, peers, ignored = "LOCALHOST", (), peers
        elif chosen in ("OFF", "SYSTEM_DEFAULT"):
            peers, ignored = (), peers
        else:
            ignored = ()
        profiles = next((environ[v].strip() for v in FASTDDS_PROFILE_VARIABLES if environ.get(v, "").strip()), "")
        if profiles and not Path(profiles).is_file():  # Fast DDS would run on its defaults, open to the network
            name = next(v for v in FASTDDS_PROFILE_VARIABLES if environ.get(v, "").strip())
            raise ParamError(f"{name} = {profiles!r} names no file: Fast DDS would ignore it and run on its defaults "
                             "(every interface); unset it to stay on this host")
        return cls(chosen, peers, environ.get("CYCLONEDDS_URI", "").strip(), ignored, profiles,
                   environ.get("RMW_IMPLEMENTATION", "").strip() or DEFAULT_RMW, localhost_only == "1")

    @property
    def cyclone_loopback(self) -> bool:
        """Whether Cyclone DDS is bound to the loopback interface (``LOCALHOST`` without static peers, and
        no interface named in ``CYCLONEDDS_URI``)."""
        return self.range == "LOCALHOST" and not self.static_peers and not names_interface(self.user_uri)

    @property
    def fastdds_loopback(self) -> bool:
        """Whether an rclpy node on Fast DDS gets :data:`FASTDDS_PROFILE` (``LOCALHOST`` without static peers, and
        no profiles file of the user's)."""
        return self.range == "LOCALHOST" and not self.static_peers and not self.user_fastdds_profiles

    def _loopback(self) -> str:
        return f'<General><Interfaces><NetworkInterface address="{LOOPBACK}"/></Interfaces></General>'

    def fragment(self, pid: Optional[int] = None) -> str:
        """The Cyclone DDS configuration of the range (without ``CYCLONEDDS_URI``); ``""`` for ``SYSTEM_DEFAULT``."""
        if self.range == "SYSTEM_DEFAULT":
            return ""
        if self.range == "OFF":
            tag = f"ros_discovery_off_{os.getpid() if pid is None else pid}"
            body = ("<General><AllowMulticast>false</AllowMulticast></General>"
                    f"<Discovery><ParticipantIndex>none</ParticipantIndex><Tag>{tag}</Tag></Discovery>")
        else:
            peers = ([LOOPBACK] if self.range == "LOCALHOST" else []) + list(self.static_peers)
            general = "<General><AllowMulticast>false</AllowMulticast></General>" if self.range == "LOCALHOST" else ""
            listed = "".join(f'<Peer address="{p}"/>' for p in peers)
            body = (general + f"<Discovery><ParticipantIndex>auto</ParticipantIndex>"
                    f"<MaxAutoParticipantIndex>{MAX_PARTICIPANT_INDEX}</MaxAutoParticipantIndex>"
                    + (f"<Peers>{listed}</Peers>" if listed else "") + "</Discovery>")
            if self.cyclone_loopback:
                body = self._loopback() + body
        return f"<CycloneDDS><Domain>{body}</Domain></CycloneDDS>"

    def cyclone_config(self, pid: Optional[int] = None) -> Optional[str]:
        """The configuration of the Cyclone DDS domain: the range's fragment, then ``CYCLONEDDS_URI``
        (``None``: Cyclone's defaults, for ``SYSTEM_DEFAULT`` without a URI)."""
        parts = [p for p in (self.fragment(pid), self.user_uri) if p]
        return ",".join(parts) if parts else None

    def ros_environment(self) -> dict[str, str]:
        """The environment a tool needs to see a graph with these settings: the range for a ROS 2 tool (``ros2 topic
        echo``), and ``CYCLONEDDS_URI`` with the range's whole fragment (the loopback binding, multicast off and
        127.0.0.1 as a peer for ``LOCALHOST``) in front of the user's, so that a plain Cyclone DDS participant
        (``cyclonedds ls``, cyclonedds-python) has the settings a node has.  rmw_cyclonedds reads the URI after its
        own fragment for the range, which says the same again; other RMWs ignore it.  ``OFF`` gets no fragment
        (nothing outside a process sees its graph), and neither does a URI that starts with this range's fragment
        already (an environment made by this method: printing it again changes nothing)."""
        env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": self.range}
        if self.static_peers:
            env["ROS_STATIC_PEERS"] = ";".join(self.static_peers)
        fragment = self.fragment() if self.range != "OFF" else ""
        printed = (fragment, dataclasses.replace(self, user_uri="").fragment())  # ours, as this URI or none made it
        if fragment and not self.user_uri.startswith(printed):
            env["CYCLONEDDS_URI"] = ",".join(p for p in (fragment, self.user_uri) if p)
        return env

    def rclpy_environment(self) -> dict[str, str]:
        """The environment under which an rclpy node of this project initialises rclpy and creates its node: on
        Fast DDS, confined to loopback, the range ``SYSTEM_DEFAULT`` (rmw_fastrtps adds nothing) with
        :data:`FASTDDS_PROFILE` as the default profile and no ``DEFAULT_FASTRTPS_PROFILES.xml`` of the working
        directory (``SKIP_DEFAULT_XML_FILE``); otherwise :meth:`ros_environment`."""
        if self.rmw not in FASTDDS_RMWS or not self.fastdds_loopback:
            return self.ros_environment()
        # ROS_LOCALHOST_ONLY=1 (read above as LOCALHOST) would make rmw_fastrtps set up transports of its own over
        # the profile's loopback binding: the profile holds it instead
        return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SYSTEM_DEFAULT", "SKIP_DEFAULT_XML_FILE": "1",
                **({"ROS_LOCALHOST_ONLY": "0"} if self.localhost_only else {}),
                **dict.fromkeys(FASTDDS_PROFILE_VARIABLES, str(FASTDDS_PROFILE))}

    def describe(self, rmw: Optional[str] = None) -> str:
        """One line for the log: the range, where it reaches, and how it is held: on the Cyclone DDS backend
        (``rmw`` ``None``) or on an rclpy node's RMW implementation ``rmw``."""
        reach = {"LOCALHOST": "this host only", "SUBNET": "the local network (multicast)",
                 "SYSTEM_DEFAULT": "the middleware's defaults", "OFF": "this process only"}[self.range]
        if self.static_peers:
            reach = "this host and the static peers"
        text = f"{self.range}: {reach}"
        if rmw in FASTDDS_RMWS:
            if self.fastdds_loopback:
                text += f", Fast DDS bound to loopback ({FASTDDS_PROFILE.name})"
            elif self.user_fastdds_profiles:
                text += (f", then the Fast DDS profiles of {self.user_fastdds_profiles} (not bound to loopback "
                         "by moose)")
        elif rmw in (None, "rmw_cyclonedds_cpp"):
            if self.cyclone_loopback:
                text += ", Cyclone DDS on the loopback interface"
            if self.user_uri:
                text += ", then CYCLONEDDS_URI" + (" (names network interfaces)" if names_interface(self.user_uri)
                                                   else "")
        elif self.range == "LOCALHOST":
            text += f", ROS 2's own on {rmw} (not bound to loopback by moose)"
        if self.static_peers:
            text += (f", static peers {', '.join(self.static_peers)} (not confined: bound to every interface, the "
                     "graph can be reached by any host that knows its address)")
        if self.ignored_peers:
            text += f" (static peers {', '.join(self.ignored_peers)} ignored)"
        return text


def udp_bindings() -> Optional[dict[str, tuple[str, int]]]:
    """The UDP sockets of this process (Linux): socket inode → (local address, port), IPv6 addresses in
    brackets; ``None`` where ``/proc`` does not tell."""
    try:
        inodes = set()
        for fd in os.listdir("/proc/self/fd"):
            try:
                target = os.readlink(f"/proc/self/fd/{fd}")
            except OSError:  # closed meanwhile
                continue
            if target.startswith("socket:["):
                inodes.add(target[len("socket:["):-1])
        found: dict[str, tuple[str, int]] = {}
        for table, size in (("udp", 4), ("udp6", 16)):
            with open(f"/proc/self/net/{table}", encoding="ascii") as lines:
                next(lines)
                for line in lines:
                    fields = line.split()
                    if fields[9] in inodes:
                        address, port = fields[1].split(":")
                        # /proc prints each 32-bit word of the address as a number in host byte order
                        packed = b"".join(struct.pack("=I", int(address[i:i + 8], 16)) for i in range(0, 2 * size, 8))
                        found[fields[9]] = (str(ipaddress.ip_address(packed)) if size == 4
                                            else f"[{ipaddress.ip_address(packed)}]", int(port, 16))
        return found
    except (OSError, StopIteration, IndexError, ValueError):
        return None


def names_interface(uri: str) -> bool:
    """Whether a ``CYCLONEDDS_URI`` value (inline XML and ``file://`` URIs, comma-separated) selects network
    interfaces (``NetworkInterface`` or the older ``NetworkInterfaceAddress``); an unreadable file counts as
    naming one, so the loopback binding never collides with it (Cyclone DDS refuses an interface given twice)."""
    for item in (part.strip() for part in uri.split(",")):
        if not item:
            continue
        if item.startswith("<"):
            text = item
        else:
            location = unquote(urlparse(item).path) if item.startswith("file:") else item
            try:
                text = Path(location).read_text(encoding="utf-8", errors="replace")
            except OSError:
                return True
        if "NetworkInterface" in text:
            return True
    return False
