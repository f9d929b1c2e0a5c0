"""How far DDS discovery reaches: ROS 2's ``ROS_AUTOMATIC_DISCOVERY_RANGE`` and ``ROS_STATIC_PEERS`` as
Cyclone DDS settings, confined to this host unless the user opts in.

The variables mean what they mean to ROS 2 Jazzy (rcl reads them, rmw_cyclonedds maps them to a
configuration fragment that it puts *before* ``CYCLONEDDS_URI``), with two differences that keep a
graph that can steer a car off the network by default:

- **The default is ``LOCALHOST``**, not ROS 2's ``SUBNET``: an unset or empty variable confines
  discovery to this host.  ``SUBNET`` (multicast discovery on the local network), ``SYSTEM_DEFAULT``
  (Cyclone DDS's own defaults, i.e. only ``CYCLONEDDS_URI``) and ``OFF`` (no discovery at all, not
  even between processes of this host) are explicit opt-ins.  A value ROS 2 does not know is an
  error here (rcl warns and assumes ``LOCALHOST``).  The deprecated ``ROS_LOCALHOST_ONLY=1`` still
  forces ``LOCALHOST`` and drops the static peers, as in rcl.
- **``LOCALHOST`` also binds Cyclone DDS to the loopback interface** (``127.0.0.1``) when there
  are no static peers and ``CYCLONEDDS_URI`` names no interface.  rmw_cyclonedds' ``LOCALHOST``
  only turns multicast off and adds ``localhost`` as a peer, so a participant on another host that
  names this host as its peer is still discovered and matched; bound to loopback it is not (both
  are tested from a second network namespace in tests/test_network_confinement.py).

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
``eth0`` opens it to that network — which is then the user's explicit choice.

The Cyclone DDS backend passes :meth:`Discovery.cyclone_config` to its domain; the rclpy backend sets
:meth:`Discovery.ros_environment` before ``rclpy.init`` (ROS 2 applies the range itself, and
rmw_cyclonedds gets the loopback binding through ``CYCLONEDDS_URI``).  ``python -m
moose_ros.runtime`` prints the same settings as shell ``export`` lines, for ROS 2 tools
(``ros2 topic echo``) that should see a confined graph.
"""
from __future__ import annotations

import dataclasses
import os
import re
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
        return cls(chosen, peers, environ.get("CYCLONEDDS_URI", "").strip(), ignored)

    @property
    def loopback_only(self) -> bool:
        """Whether Cyclone DDS is bound to the loopback interface (``LOCALHOST`` without static peers, and
        no interface named in ``CYCLONEDDS_URI``)."""
        return self.range == "LOCALHOST" and not self.static_peers and not names_interface(self.user_uri)

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
            if self.loopback_only:
                body = self._loopback() + body
        return f"<CycloneDDS><Domain>{body}</Domain></CycloneDDS>"

    def cyclone_config(self, pid: Optional[int] = None) -> Optional[str]:
        """The configuration of the Cyclone DDS domain: the range's fragment, then ``CYCLONEDDS_URI``
        (``None``: Cyclone's defaults, for ``SYSTEM_DEFAULT`` without a URI)."""
        parts = [p for p in (self.fragment(pid), self.user_uri) if p]
        return ",".join(parts) if parts else None

    def ros_environment(self) -> dict[str, str]:
        """The environment a ROS 2 process (rclpy, ``ros2`` tools) needs for the same settings: the range,
        and ``CYCLONEDDS_URI`` with the loopback binding in front of the user's (rmw_cyclonedds reads it
        after its own fragment for the range; other RMWs ignore it)."""
        env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": self.range}
        if self.static_peers:
            env["ROS_STATIC_PEERS"] = ";".join(self.static_peers)
        if self.loopback_only:
            loopback = f"<CycloneDDS><Domain>{self._loopback()}</Domain></CycloneDDS>"
            env["CYCLONEDDS_URI"] = ",".join(p for p in (loopback, self.user_uri) if p)
        return env

    def describe(self) -> str:
        """One line for the log: the range, where it reaches, and what ``CYCLONEDDS_URI`` adds."""
        reach = {"LOCALHOST": "this host only", "SUBNET": "the local network (multicast)",
                 "SYSTEM_DEFAULT": "Cyclone DDS defaults", "OFF": "this process only"}[self.range]
        text = f"{self.range}: {reach}"
        if self.loopback_only:
            text += ", bound to loopback"
        if self.static_peers:
            text += f", static peers {', '.join(self.static_peers)}"
        if self.ignored_peers:
            text += f" (static peers {', '.join(self.ignored_peers)} ignored)"
        if self.user_uri:
            text += ", then CYCLONEDDS_URI" + (" (names network interfaces)" if names_interface(self.user_uri) else "")
        return text


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
