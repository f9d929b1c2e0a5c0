"""``weight_fbl``: the weight function and the FBL — blends the plans of one planning instant, emits the references
and the markers of the instant (danger zone, predicted paths).

The mode switch, the blend, the FBL reference and the next initial guess are the core's planning
step (:class:`moose.planning.PlanningStep`), the code the lockstep loop runs.
"""
from __future__ import annotations

import math
from typing import Any, Optional

from moose.planning import PlanningStep, blend_path
from moose.signals import PlanResult, StateEstimate, Threat

from .. import convert as cv
from ..graph import BLEND, MARKERS, PLAN_MPC, PLAN_MSF, REFERENCE, STATE, THREAT
from .base import OK, WARN, GraphNode


class WeightFbl(GraphNode):
    """Weight function and FBL: combines the plans of one planning instant through the core's planning
    step (:class:`moose.planning.PlanningStep`, as the lockstep loop does) and emits the references."""

    name = "weight_fbl"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        self.step = PlanningStep(self.config, planners=False)
        self.mode = self.step.mode
        self.mpc_timeout = self.params.mpc_timeout
        self.estimate: Optional[StateEstimate] = None
        self.threat: Optional[Threat] = None
        self.pending: dict[str, tuple[float, bool, Any]] = {}
        """The newest plan of each planner: (stamp, planned against a threat, plan)."""
        self.blended = -math.inf
        """Stamp of the last blended instant."""
        self.pub_blend = BLEND.publisher(rt)
        self.pub_ref = REFERENCE.publisher(rt)
        self.pub_markers = MARKERS.publisher(rt)
        self.subscribe(STATE, self.on_state)
        self.subscribe(THREAT, lambda threat: setattr(self, "threat", threat))
        self.subscribe(PLAN_MPC, lambda plan: self.on_plan("mpc", plan))
        self.subscribe(PLAN_MSF, lambda plan: self.on_plan("msf", plan))

    def on_plan(self, kind: str, plan: tuple[float, bool, PlanResult]) -> None:
        """(instant, planned against a threat, plan) of one planner."""
        if plan[0] < self.blended - 1e-6:
            return  # a plan for an instant already blended without it (it came too late)
        self.pending[kind] = plan
        self.try_blend()

    def try_blend(self) -> None:
        """Combine when the mode's plans of one instant are here; in ``combined`` mode, without the MPC's when
        it has not come ``mpc_timeout`` after the MSF plan's instant (late, failed or silent: weight 0)."""
        if self.estimate is None:
            return
        mpc, msf = self.pending.get("mpc"), self.pending.get("msf")
        silent = False
        if self.mode == "mpc" and mpc:
            t, plans = mpc[0], (mpc[2], None)
        elif self.mode == "msf" and msf:
            t, plans = msf[0], (None, msf[2])
        elif self.mode == "combined" and msf and mpc and abs(mpc[0] - msf[0]) < 1e-6 and mpc[1] == msf[1]:
            # the two plans of one instant, made against the same threat (a planner that planned on its
            # timer just before the threat arrived re-plans at the same stamp: wait for that plan)
            t, plans = msf[0], (mpc[2], msf[2])
        elif self.mode == "combined" and msf and self.rt.now() >= msf[0] + self.mpc_timeout - 1e-9:
            t, plans, silent = msf[0], (None, msf[2]), True  # no MPC plan for this instant in time: weight 0
        else:
            return
        record = self.step.combine(t, self.estimate, self.threat, *plans)
        self.level, self.message = (WARN, "mpc_planner late or silent: MSF only") if silent else (OK, "running")
        self.pending.clear()
        self.blended = t
        self.values = {"weight_mpc": f"{record.blend.weight_mpc:.3f}"}
        self.pub_blend(cv.blend_to_msg(self.rt, t, record.blend, record.reference, record.delta_mpc))
        self.pub_ref(cv.reference_to_msg(self.rt, t, record.reference))
        self.pub_markers(cv.markers_to_msg(self.rt, t, record.threat, record.mpc, record.msf,
                                           blend_path(record.blend, self.estimate, self.step.grid.t_s)))

    def on_state(self, estimate: StateEstimate) -> None:
        self.estimate = estimate
        if "msf" in self.pending and self.mode == "combined":
            self.try_blend()
        reference = self.step.reference_between(self.estimate)
        if reference is not None and self.config.simulation.steering_fbl_at_motion_rate:
            self.pub_ref(cv.reference_to_msg(self.rt, self.estimate.t, reference))
