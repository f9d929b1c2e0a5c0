"""The whole parameter set of the system, read from one ROS 2 parameter file.

``config/moose.yaml`` has one group per block under the ``/**`` wildcard (so
every node of the graph sees the same values) and may be overridden per node.
Missing groups or keys take the dataclass defaults (the paper's values).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from .params import ParamError, build, read_ros_params, to_mapping
from .resources import PARAMETER_FILE
from .schema import Config


def config_from_mapping(params: Mapping[str, Any], where: str = "parameters") -> Config:
    """Build a :class:`Config` from merged ``ros__parameters``."""
    return build(Config, params, where)


def load_config(path: str | Path | None = None, reader: str | None = "this command") -> Config:
    """Read the ``/**`` section of ``path`` (default: the shipped ``config/moose.yaml``,
    :data:`moose.resources.PARAMETER_FILE`).

    ``reader`` names the command that reads it (``moose simulate``): it applies only ``/**``, so any
    other section is a :class:`ParamError` naming it.  ``None``: other sections are left to their
    readers (the node graph, whose launcher checks them against its nodes)."""
    if path is None:
        path = PARAMETER_FILE
    return config_from_mapping(read_ros_params(path, reader=reader), where=str(Path(path).name))


def config_as_ros_params(config: Config) -> dict[str, Any]:
    """The parameter-file document (``/**: ros__parameters: …``) for ``config``."""
    return {"/**": {"ros__parameters": to_mapping(config)}}


def with_overrides(config: Config, overrides: Mapping[str, Any], where: str = "--set") -> Config:
    """``config`` with dotted parameters replaced, e.g. ``{"planning.N_p": 20, "sensors.gps_lag_s": 0.5}``.

    Validated like a parameter file (:func:`moose.params.build`): an unknown group or key, a wrong
    type or an out-of-range value raises :class:`~moose.params.ParamError` naming ``where``, the key
    and the value; a key that exists in another group says so (``mpc.N_p`` → ``planning.N_p``).
    """
    mapping = to_mapping(config)
    for key, value in overrides.items():
        path = key.split(".")
        node: Any = mapping
        for i, part in enumerate(path[:-1]):
            if not isinstance(node, dict) or not isinstance(node.get(part), dict):
                prefix = ".".join(path[: i + 1])
                raise ParamError(f"{where} {key}={value!r}: {prefix!r} is not a parameter group"
                                 f"{_elsewhere(mapping, path[-1])}")
            node = node[part]
        if path[-1] not in node or isinstance(node[path[-1]], dict):
            raise ParamError(f"{where} {key}={value!r}: {key!r} is not a parameter{_elsewhere(mapping, path[-1])}")
        node[path[-1]] = value
    return config_from_mapping(mapping, where=where)


def _elsewhere(mapping: Mapping[str, Any], name: str, prefix: str = "") -> str:
    """``" (did you mean a.b?)"`` when parameters named ``name`` exist elsewhere, else ``""``."""
    found = []

    def walk(node: Mapping[str, Any], path: str) -> None:
        for key, value in node.items():
            if isinstance(value, dict):
                walk(value, f"{path}{key}.")
            elif key == name:
                found.append(path + key)

    walk(mapping, prefix)
    return f" (did you mean {' or '.join(found)}?)" if found else ""
