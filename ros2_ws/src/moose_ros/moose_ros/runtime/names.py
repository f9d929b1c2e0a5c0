"""ROS 2 names: topic and namespace resolution and validation, rmw_cyclonedds' DDS topic names."""
from __future__ import annotations

import re
from typing import Optional

TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
"""A ROS 2 name token (also a valid node name when it has no ``__``)."""

CLOCK_TOPIC = "/clock"
"""The topic of ROS 2's time source (``use_sim_time``)."""
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"


def check_tokens(what: str, name: str, tokens: list[str]) -> None:
    """Raise ``ValueError`` naming ``what`` and ``name`` unless every token is a ROS 2 name token."""
    for token in tokens:
        if not TOKEN.match(token) or "__" in token:
            raise ValueError(f"{what} {name!r} is invalid: {token!r} is not a name token "
                             "(letters, digits, single underscores; not starting with a digit)")


def check_node_name(name: str) -> None:
    """Raise ``ValueError`` unless ``name`` is a valid ROS 2 node name."""
    if not isinstance(name, str) or not TOKEN.match(name) or "__" in name:
        raise ValueError(f"node name {name!r} is invalid: expected letters, digits and single underscores")


def resolve_topic(topic: str, namespace: str = "/", node_name: str = "") -> str:
    """Fully qualified ROS name of ``topic``: absolute names stay, relative ones go under ``namespace``,
    ``~`` is the node's private namespace (``namespace/node_name``)."""
    if not isinstance(topic, str) or not topic:
        raise ValueError(f"topic name {topic!r} is invalid: expected a non-empty string")
    ns = normalise_namespace(namespace)
    if topic.startswith("~"):
        if topic not in ("~",) and not topic.startswith("~/"):
            raise ValueError(f"topic name {topic!r} is invalid: '~' must be followed by '/'")
        base = ns.rstrip("/") + "/" + node_name
        rest = topic[2:]
        full = base + ("/" + rest if rest else "")
    elif topic.startswith("/"):
        full = topic
    else:
        full = ns.rstrip("/") + "/" + topic
    if full.endswith("/") or "//" in full:
        raise ValueError(f"topic name {topic!r} is invalid: empty name token")
    check_tokens("topic name", topic, full.strip("/").split("/"))
    return full


def normalise_namespace(namespace: Optional[str]) -> str:
    """``None``/``""`` → ``/``; ``car1`` → ``/car1``; validated like ROS 2 namespaces."""
    if not namespace or namespace == "/":
        return "/"
    ns = namespace if namespace.startswith("/") else "/" + namespace
    if ns.endswith("/") or "//" in ns:
        raise ValueError(f"namespace {namespace!r} is invalid: empty name token")
    check_tokens("namespace", namespace, ns.strip("/").split("/"))
    return ns


def dds_topic_name(full_name: str) -> str:
    """rmw_cyclonedds' DDS topic of a fully qualified ROS topic: ``/x/y`` → ``rt/x/y``."""
    return "rt" + full_name
