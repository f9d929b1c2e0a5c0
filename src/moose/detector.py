"""Obstacle detector (Sec. III): from visible danger zones and the state estimate to τ, w and ν.

* τ = (x_min − x̂) / v̂_x: time to reach the obstacle's near edge, eq. (nudef)'s τ.
* Evasion side: the side needing the smaller lateral displacement from the ego
  path; near-ties (within ``side_tie``, so estimation noise cannot flip it) go
  to the left (+1) as in all the paper's tests; latched with the
  ego path ŷ at first detection so w does not shrink as the car moves aside.
* w: lateral distance from the ego path to the obstacle's far edge on the
  evasion side (the ν values printed in Figs. 5–7 use exactly this width).
* ν = w / y_max(τ, v̂_x), eq. (nudef).
The threat is reported until the CoG has passed the far end x_max by
``pass_margin``; then ``None`` and the planners return to the lane.
"""
from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

from .maneuver import MaxSteeringTable, lateral_steering_index, time_to_collision
from .params import check, non_negative, positive
from .signals import Obstacle, StateEstimate, Threat


@dataclasses.dataclass(frozen=True)
class DetectorParams:
    """Detector parameters."""

    pass_margin: float = 2.0
    """Distance past the obstacle's far end after which the threat is cleared (m)."""
    range_m: float = 80.0
    """Perception range ahead of the CoG (m)."""
    side_tie: float = 0.25
    """Displacements to either side closer than this count as a tie: evade left (m)."""

    def __post_init__(self) -> None:
        check("pass_margin", self.pass_margin, non_negative, "a non-negative distance (m)")
        check("range_m", self.range_m, positive, "a positive distance (m)")
        check("side_tie", self.side_tie, non_negative, "a non-negative distance (m)")


class ObstacleDetector:
    """Tracks the nearest relevant danger zone and reports its threat measures."""

    def __init__(self, params: DetectorParams, table: MaxSteeringTable) -> None:
        self.params = params
        self.table = table
        self._latched: dict[Obstacle, tuple[int, float]] = {}

    def reset(self) -> None:
        self._latched.clear()

    def update(self, t: float, estimate: StateEstimate, obstacles: Sequence[Obstacle]) -> Optional[Threat]:
        relevant = [o for o in obstacles
                    if o.x_max + self.params.pass_margin >= estimate.x and o.x_min - estimate.x <= self.params.range_m]
        if not relevant:
            return None
        obstacle = min(relevant, key=lambda o: o.x_min)
        if obstacle not in self._latched:
            up = obstacle.y_max - estimate.y
            down = estimate.y - obstacle.y_min
            self._latched[obstacle] = (1, estimate.y) if up <= down + self.params.side_tie else (-1, estimate.y)
        side, y_path = self._latched[obstacle]
        w = obstacle.y_max - y_path if side > 0 else y_path - obstacle.y_min
        tau = time_to_collision(obstacle.x_min - estimate.x, estimate.vx)
        nu = lateral_steering_index(w, tau, estimate.vx, self.table)
        return Threat(t=t, obstacle=obstacle, tau=tau, w=w, nu=nu, side=side, y_path=y_path)
