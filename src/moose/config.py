"""The whole parameter set of the system, read from one ROS 2 parameter file.

``config/moose.yaml`` has one group per block under the ``/**`` wildcard (so
every node of the graph sees the same values) and may be overridden per node.
Missing groups or keys take the dataclass defaults (the paper's values).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Literal, Mapping

from .detector import DetectorParams
from .fbl import FblParams
from .maneuver import ManeuverParams
from .motion import MotionParams
from .mpc import MpcParams
from .msf import MsfParams
from .observer import ObserverParams
from .resources import PARAMETER_FILE
from .params import ParamError, VehicleParams, build, check, positive, read_ros_params, to_mapping
from .sensors import SensorParams
from .weight import WeightParams

PlannerMode = Literal["combined", "mpc", "msf"]


@dataclasses.dataclass(frozen=True)
class SimulationParams:
    """Rates of the lockstep closed loop (Fig. 3)."""

    plant_dt: float = 1e-3
    """Plant integration step (s): 1 kHz."""
    motion_rate_hz: float = 100.0
    """Motion control, observer and detector rate (Hz)."""
    planning_rate_hz: float = 5.0
    """Planner, weight function and FBL rate (Hz): the MicroLabBox's 5 Hz."""
    planner: PlannerMode = "combined"
    """Which planner drives the car: the paper's blend, MPC alone, or MSF alone."""
    steering_fbl_at_motion_rate: bool = True
    """Re-evaluate the FBL's δ* at the motion-control rate on the held planned acceleration."""

    def __post_init__(self) -> None:
        check("plant_dt", self.plant_dt, lambda v: 1e-5 <= v <= 1e-2, "a step in [1e-5, 1e-2] s")
        check("motion_rate_hz", self.motion_rate_hz, positive, "a positive rate (Hz)")
        check("planning_rate_hz", self.planning_rate_hz, positive, "a positive rate (Hz)")
        plant_per_motion = 1.0 / (self.plant_dt * self.motion_rate_hz)
        motion_per_plan = self.motion_rate_hz / self.planning_rate_hz
        for name, ratio in (("motion_rate_hz", plant_per_motion), ("planning_rate_hz", motion_per_plan)):
            if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
                raise ParamError(f"{name} = {getattr(self, name)!r} is invalid: rates must divide the faster loop's rate")

    @property
    def plant_steps_per_motion(self) -> int:
        return round(1.0 / (self.plant_dt * self.motion_rate_hz))

    @property
    def motion_steps_per_plan(self) -> int:
        return round(self.motion_rate_hz / self.planning_rate_hz)


@dataclasses.dataclass(frozen=True)
class Config:
    """Every block's parameters."""

    vehicle: VehicleParams = VehicleParams()
    sensors: SensorParams = SensorParams()
    observer: ObserverParams = ObserverParams()
    detector: DetectorParams = DetectorParams()
    maneuver: ManeuverParams = ManeuverParams()
    mpc: MpcParams = MpcParams()
    msf: MsfParams = MsfParams()
    weight: WeightParams = WeightParams()
    fbl: FblParams = FblParams()
    motion: MotionParams = MotionParams()
    simulation: SimulationParams = SimulationParams()


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
