"""``weight_fbl``: the weight function and the FBL — blends the plans of one planning instant, emits the references.

The planning instant is decided here as in the lockstep loop (``moose.simulation``); the core's
planning-step object is meant to replace :meth:`WeightFbl.try_blend` (the mode switch, blend and FBL
reference) so that both run the same code.
"""
from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

from moose.fbl import FeedbackLinearization
from moose.signals import Blend, Reference, StateEstimate
from moose.weight import WeightFunction

from .. import convert as cv
from ..graph import BLEND, PLAN_MPC, PLAN_MSF, REFERENCE, STATE, THREAT
from .base import OK, WARN, GraphNode


class WeightFbl(GraphNode):
    """Weight function and FBL: blends the plans of one planning instant, emits the references."""

    name = "weight_fbl"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        cfg = self.config
        self.mode = cfg.simulation.planner
        self.weight = WeightFunction(cfg.weight, cfg.vehicle)
        self.fbl = FeedbackLinearization(cfg.fbl, cfg.vehicle)
        self.mpc_timeout = self.params.mpc_timeout
        self.estimate: Optional[StateEstimate] = None
        self.threat = None
        self.pending: dict[str, tuple[float, Any]] = {}
        self.applied: Optional[np.ndarray] = None
        self.reference: Optional[Reference] = None
        self.last_mpc = -math.inf
        self.pub_blend = BLEND.publisher(rt)
        self.pub_ref = REFERENCE.publisher(rt)
        STATE.subscription(rt, self.on_state)
        THREAT.subscription(rt, lambda m: setattr(self, "threat", cv.threat_from_msg(m)))
        PLAN_MPC.subscription(rt, lambda m: self.on_plan("mpc", m))
        PLAN_MSF.subscription(rt, lambda m: self.on_plan("msf", m))

    def on_plan(self, kind: str, msg: Any) -> None:
        self.pending[kind] = (cv.time_of(msg), cv.plan_from_msg(msg))
        if kind == "mpc":
            self.last_mpc = self.rt.now()
        self.try_blend()

    def try_blend(self) -> None:
        if self.estimate is None:
            return
        mpc, msf = self.pending.get("mpc"), self.pending.get("msf")
        if self.mode == "mpc" and mpc:
            t, blend = mpc[0], Blend(1.0, mpc[1].accel)
        elif self.mode == "msf" and msf:
            t, blend = msf[0], Blend(0.0, msf[1].accel)
        elif self.mode == "combined" and msf and mpc and abs(mpc[0] - msf[0]) < 1e-6:
            t, blend = msf[0], self.weight.blend(mpc[1], msf[1], self.threat, self.estimate)
        elif self.mode == "combined" and msf and self.rt.now() - self.last_mpc > self.mpc_timeout + 0.2:
            # MPC silent: blend with a failed MPC (weight 0) and say so
            t, blend = msf[0], Blend(0.0, msf[1].accel)
            self.level, self.message = WARN, "mpc_planner silent: MSF only"
        else:
            return
        if self.mode != "combined" or not self.message.startswith("mpc_planner silent") or blend.weight_mpc > 0.0:
            self.level, self.message = OK, "running"
        self.pending.clear()
        self.applied = blend.accel[0]
        self.reference = self.fbl.reference(self.applied, self.estimate)
        self.values = {"weight_mpc": f"{blend.weight_mpc:.3f}"}
        self.pub_blend(cv.blend_to_msg(self.rt, t, blend, self.reference))
        self.pub_ref(cv.reference_to_msg(self.rt, t, self.reference))

    def on_state(self, msg: Any) -> None:
        self.estimate = cv.estimate_from_msg(msg)
        if "msf" in self.pending and self.mode == "combined":
            self.try_blend()
        if self.applied is not None and self.reference is not None and self.config.simulation.steering_fbl_at_motion_rate:
            delta = self.fbl.reference(self.applied, self.estimate).delta
            self.pub_ref(cv.reference_to_msg(self.rt, self.estimate.t, Reference(delta, self.reference.vx)))

