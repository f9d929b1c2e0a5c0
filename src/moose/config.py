"""The whole parameter set of the system, read from one ROS 2 parameter file.

``config/moose.yaml`` has one group per block under the ``/**`` wildcard (so
every node of the graph sees the same values) and may be overridden per node.
Missing groups or keys take the dataclass defaults (the paper's values).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from .params import build, read_ros_params, to_mapping
from .resources import PARAMETER_FILE
from .schema import Config


def config_from_mapping(params: Mapping[str, Any], where: str = "parameters") -> Config:
    """Build a :class:`Config` from merged ``ros__parameters``."""
    return build(Config, params, where)


def load_config(path: str | Path | None = None, node: str | None = None) -> Config:
    """Read ``path`` (default: the shipped ``config/moose.yaml``, :data:`moose.resources.PARAMETER_FILE`)."""
    if path is None:
        path = PARAMETER_FILE
    return config_from_mapping(read_ros_params(path, node), where=str(Path(path).name))


def config_as_ros_params(config: Config) -> dict[str, Any]:
    """The parameter-file document (``/**: ros__parameters: …``) for ``config``."""
    return {"/**": {"ros__parameters": to_mapping(config)}}
