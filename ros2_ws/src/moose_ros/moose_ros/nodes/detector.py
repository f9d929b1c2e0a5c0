"""``obstacle_detector``: state + visible danger zones → /perception/threat (τ, w, ν)."""
from __future__ import annotations

from typing import Optional

from moose.detector import ObstacleDetector
from moose.signals import StateEstimate

from .. import convert as cv
from ..graph import OBSTACLES, STATE, THREAT
from ..runtime.base import NodeBase
from .base import ERROR, GraphNode


class Detector(GraphNode):
    """Obstacle detector: state + visible danger zones → /perception/threat."""

    name = "obstacle_detector"

    def __init__(self, rt: NodeBase) -> None:
        super().__init__(rt)
        self.detector = ObstacleDetector(self.config.detector, self.table())
        self.obstacles: list = []
        self.pub = self.publisher(THREAT)
        self.subscribe(OBSTACLES, lambda obstacles: setattr(self, "obstacles", obstacles))
        self.subscribe(STATE, self.on_state)

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        """Threats follow the estimate (one per state): a stale estimate leaves no threat to publish (ERROR)."""
        self.report_stale(stale, ERROR)

    def on_state(self, estimate: StateEstimate) -> None:
        """The threat at the node's time (in lockstep the tick's; with a sensor delay the estimate is of an earlier
        sample), as the lockstep loop detects at its tick."""
        t = self.now()
        self.pub(cv.threat_to_msg(self.rt, t, self.detector.update(t, estimate, self.obstacles)))
