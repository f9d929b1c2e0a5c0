"""Obstacle detector (Sec. III): from the visible danger zones and the state estimate to τ, w and ν.

For the nearest danger zone ahead that lies in the ego path:

* τ = (x_min − x̂) / v̂_x: time to reach the zone's near edge at the current
  speed (the τ of eq. (nudef)); it turns negative once the CoG is beside the
  zone and the threat is still reported then, until the CoG has passed the far
  end x_max by ``pass_margin`` (the planners then return to the lane).
* Ego path: the lateral position ŷ at first detection, latched per obstacle
  together with the evasion side, so w does not shrink as the car moves aside.
* Evasion side: the side needing the smaller lateral displacement from the
  ego path (y_max − ŷ to the left, ŷ − y_min to the right); displacements that
  differ by less than ``side_tie`` count as a tie and go left (+1), as in all
  the paper's tests, so estimation noise cannot flip the decision.
* w: lateral distance from the ego path to the zone's far edge on the evasion
  side (the ν printed in Figs. 7–9 use exactly this width), never negative.
* ν = w / y_max(τ, v̂_x), eq. (nudef); 0 when the car is not closing in (τ = ∞).

A zone is in the ego path when ŷ lies within ``lateral_margin`` of its lateral
extent (the zone is what the CoG must avoid, so the margin defaults to 0), and
within ``range_m`` ahead.  Zones that are not reported by the perception
sensor any more are dropped.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

from .maneuver import MaxSteeringTable, lateral_steering_index
from .schema import DetectorParams
from .signals import Obstacle, StateEstimate, Threat, time_to_collision


def evasion_side(obstacle: Obstacle, y_path: float, side_tie: float) -> int:
    """+1 (left) when the displacement to the left edge is not larger than to the right one by ``side_tie`` or more."""
    up = obstacle.y_max - y_path
    down = y_path - obstacle.y_min
    return 1 if up <= down + side_tie else -1


def danger_zone_width(obstacle: Obstacle, y_path: float, side: int) -> float:
    """w: lateral distance from the ego path to the far edge on the evasion side (m), at least 0."""
    w = obstacle.y_max - y_path if side > 0 else y_path - obstacle.y_min
    return max(w, 0.0)


class ObstacleDetector:
    """Tracks the nearest danger zone in the ego path and reports its threat measures."""

    def __init__(self, params: DetectorParams, table: MaxSteeringTable) -> None:
        self.params = params
        self.table = table
        self._latched: dict[Obstacle, tuple[int, float]] = {}
        """Per obstacle: (side, y_path) at first detection."""

    def reset(self) -> None:
        self._latched.clear()

    def _relevant(self, obstacle: Obstacle, estimate: StateEstimate) -> bool:
        p = self.params
        if obstacle.x_max + p.pass_margin < estimate.x or obstacle.x_min - estimate.x > p.range_m:
            return False
        if obstacle in self._latched:
            return True
        return obstacle.y_min - p.lateral_margin <= estimate.y <= obstacle.y_max + p.lateral_margin

    def update(self, t: float, estimate: StateEstimate, obstacles: Sequence[Obstacle]) -> Optional[Threat]:
        """The threat of the nearest relevant visible zone at time ``t``, or None."""
        if not obstacles and not self._latched:  # nothing seen, nothing to forget (most ticks of a run)
            return None
        visible = set(obstacles)
        for gone in [o for o in self._latched if o not in visible or o.x_max + self.params.pass_margin < estimate.x]:
            del self._latched[gone]
        relevant = [o for o in obstacles if self._relevant(o, estimate)]
        if not relevant:
            return None
        obstacle = min(relevant, key=lambda o: o.x_min)
        if obstacle not in self._latched:
            self._latched[obstacle] = (evasion_side(obstacle, estimate.y, self.params.side_tie), estimate.y)
        side, y_path = self._latched[obstacle]
        w = danger_zone_width(obstacle, y_path, side)
        tau = time_to_collision(obstacle.x_min - estimate.x, estimate.vx)
        # not closing in (τ = ∞): no steering is needed, ν = 0
        nu = 0.0 if tau == math.inf else lateral_steering_index(w, tau, estimate.vx, self.table)
        return Threat(t=t, obstacle=obstacle, tau=tau, w=w, nu=nu, side=side, y_path=y_path)
