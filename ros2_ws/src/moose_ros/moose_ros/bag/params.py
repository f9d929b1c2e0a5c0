"""The parameters of a recorded run, kept in its bag: the core's configuration as a ROS 2 parameter file,
the scenario, the planner mode and the seed.

They go into the bag twice, as plain strings: rosbag2's ``custom_data`` in ``metadata.yaml`` (what
``ros2 bag info`` and rosbag2's readers expose) and an MCAP metadata record named ``moose``, written when
the bag is opened, so a bag left without ``metadata.yaml`` by a killed recorder keeps them too.
``moose bag replan`` re-plans with them unless told otherwise.
"""
from __future__ import annotations

import dataclasses
import struct
from pathlib import Path
from typing import Any, Optional, cast, get_args

import yaml

from moose.files import dump_yaml
from moose.schema import PlannerMode

from .errors import BagError

METADATA_NAME = "moose"
"""Name of the MCAP metadata record."""
KEYS = ("moose.config", "moose.scenario", "moose.planner", "moose.seed")
"""The ``custom_data`` keys (also the fields of the ``moose`` MCAP metadata record)."""


@dataclasses.dataclass(frozen=True)
class RunParameters:
    """What a run was made with."""

    config: Any
    """:class:`moose.schema.Config`, with the road's μ of the run."""
    scenario: Any
    """:class:`moose.scenario.Scenario`."""
    planner: PlannerMode
    seed: int

    def as_strings(self) -> dict[str, str]:
        """The ``custom_data`` of the bag: the configuration as a ROS 2 parameter file (``/**``), the scenario
        as a scenario file, the planner mode and the seed."""
        from moose.config import config_as_ros_params

        return {
            "moose.config": dump_yaml(config_as_ros_params(self.config)),
            "moose.scenario": dump_yaml(dataclasses.asdict(self.scenario)),
            "moose.planner": self.planner,
            "moose.seed": str(self.seed),
        }

    @classmethod
    def from_strings(cls, data: dict[str, str], where: str) -> "RunParameters":
        """Parse what :meth:`as_strings` wrote; a damaged entry is a :class:`BagError` naming it."""
        from moose.config import config_from_mapping
        from moose.params import ParamError
        from moose.scenario import scenario_from_mapping

        missing = [k for k in KEYS if k not in data]
        if missing:
            raise BagError(f"{where}: run parameters lack {missing[0]!r}")
        try:
            document = yaml.safe_load(data["moose.config"])
            config = config_from_mapping(document["/**"]["ros__parameters"], where=f"{where} moose.config")
            scenario = scenario_from_mapping(yaml.safe_load(data["moose.scenario"]), where=f"{where} moose.scenario")
            planner = data["moose.planner"]
            if planner not in get_args(PlannerMode):
                raise ParamError(f"moose.planner = {planner!r} is invalid: "
                                 f"expected one of {list(get_args(PlannerMode))}")
            return cls(config, scenario, cast(PlannerMode, planner), int(data["moose.seed"]))
        except (ParamError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
            raise BagError(f"{where}: run parameters are unreadable: {exc}") from None


def read_run_parameters(path: str | Path) -> Optional[RunParameters]:
    """The run parameters of a bag (``metadata.yaml``'s ``custom_data``, else the MCAP ``moose`` metadata
    record of its file, also of an unfinished one); ``None`` for a bag recorded without them."""
    path = Path(path)
    meta = path / "metadata.yaml"
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        except (yaml.YAMLError, KeyError, TypeError) as exc:
            raise BagError(f"bag {str(path)!r}: metadata.yaml is unreadable: {exc}") from None
        custom = info.get("custom_data") or {}
        if any(k in custom for k in KEYS):
            return RunParameters.from_strings(custom, f"bag {str(path)!r}")
    from mcap.exceptions import McapError
    from mcap.records import Metadata
    from mcap.stream_reader import StreamReader

    for file in sorted(path.glob("*.mcap")) if path.is_dir() else [path]:
        with open(file, "rb") as stream:
            try:
                for record in StreamReader(stream, skip_magic=False).records:
                    if isinstance(record, Metadata) and record.name == METADATA_NAME:
                        return RunParameters.from_strings(dict(record.metadata), f"bag file {str(file)!r}")
            except (McapError, EOFError, ValueError, AssertionError, struct.error):  # a cut record
                continue
    return None
