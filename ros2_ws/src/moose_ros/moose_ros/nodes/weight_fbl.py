"""``weight_fbl``: the weight function and the FBL — blends the plans of one planning instant, emits the references
and the markers of the instant (danger zone, predicted paths).

The mode switch, the blend, the FBL reference and the next initial guess are the core's planning
step (:class:`moose.planner.step.PlanningStep`), the code the lockstep loop runs.

Supervision: a planner whose plan topic is past its deadline (:attr:`moose_ros.graph.Topic.deadline`, two
planning periods) is *silent*; in ``combined`` mode the other planner's plan is applied alone (WARN
``mpc_planner silent: MSF only`` or ``msf_planner silent: MPC only``).  With no live planner of the mode,
or a stale estimate or threat, the node publishes no reference and reports ERROR: the motion controller
then runs the minimum-risk maneuver.
"""
from __future__ import annotations

import math
from typing import Any, Optional

from moose.planner import MODE_PLANNERS
from moose.planner.step import PlanningStep, blend_path
from moose.signals import PlanResult, StateEstimate, Threat

from .. import convert as cv
from ..graph import BLEND, MARKERS, PLAN_MPC, PLAN_MSF, PLANS, REFERENCE, STATE, THREAT
from ..runtime.base import NodeBase
from .base import ERROR, WARN, GraphNode


class WeightFbl(GraphNode):
    """Weight function and FBL: combines the plans of one planning instant through the core's planning
    step (:class:`moose.planner.step.PlanningStep`, as the lockstep loop does) and emits the references."""

    name = "weight_fbl"

    def __init__(self, rt: NodeBase) -> None:
        super().__init__(rt)
        self.step = PlanningStep(self.config, planners=False)
        self.mode = self.step.mode
        self.planners = MODE_PLANNERS[self.mode]
        self.live: tuple[str, ...] = self.planners
        """The mode's planners whose plans are within their deadline."""
        self.blocked = False
        """No reference can be made: a stale estimate or threat, or no live planner."""
        self.mpc_timeout = self.params.mpc_timeout
        self.estimate: Optional[StateEstimate] = None
        self.threat: Optional[Threat] = None
        self.pending: dict[str, tuple[float, bool, Any]] = {}
        """The newest plan of each planner: (stamp, planned against a threat, plan)."""
        self.blended = -math.inf
        """Stamp of the last blended instant."""
        self.pub_blend = self.publisher(BLEND)
        self.pub_ref = self.publisher(REFERENCE)
        self.pub_markers = self.publisher(MARKERS)
        self.subscribe(STATE, self.on_state)
        self.subscribe(THREAT, lambda threat: setattr(self, "threat", threat))
        self.subscribe(PLAN_MPC, lambda plan: self.on_plan("mpc", plan))
        self.subscribe(PLAN_MSF, lambda plan: self.on_plan("msf", plan))

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        plans = [PLANS[k].name for k in self.planners]
        self.live = tuple(k for k in self.planners if PLANS[k].name not in stale)
        silent = [k for k in self.planners if k not in self.live]
        self.report_stale(stale, ERROR, {name: WARN if self.live else ERROR for name in plans},
                          names=[STATE.name, THREAT.name, *plans])
        if silent and self.live:
            self.problem("fallback", WARN, f"{silent[0]}_planner silent: {self.live[0].upper()} only")
        else:
            self.problem("fallback", None)
        self.blocked = STATE.name in stale or THREAT.name in stale or not self.live
        if self.pending:
            self.try_blend()

    def on_plan(self, kind: str, plan: tuple[float, bool, PlanResult]) -> None:
        """(instant, planned against a threat, plan) of one planner."""
        if plan[0] < self.blended - 1e-6:
            return  # a plan for an instant already blended without it (it came too late)
        self.pending[kind] = plan
        self.try_blend()

    def try_blend(self) -> None:
        """Combine when the live planners' plans of one instant are here.  In ``combined`` mode with both
        planners live, an instant whose MPC plan has not come ``mpc_timeout`` after it is blended from the
        MSF plan alone (weight 0: the MPC was late or failed); a silent planner's plans are not waited for."""
        if self.estimate is None or self.blocked:
            return
        mpc, msf = (self.pending.get(k) if k in self.live else None for k in ("mpc", "msf"))
        late = False
        if self.live == ("mpc", "msf"):
            if mpc and msf and abs(mpc[0] - msf[0]) < 1e-6 and mpc[1] == msf[1]:
                pass  # the two plans of one instant, made against the same threat (a planner that planned on
                # its timer just before the threat arrived re-plans at the same stamp: wait for that plan)
            elif msf and self.now() >= msf[0] + self.mpc_timeout - 1e-9:
                mpc, late = None, True  # no MPC plan for this instant in time: weight 0
            else:
                return
        elif not (mpc or msf):
            return
        t = (msf or mpc)[0]  # type: ignore[index]
        inp = self.step.planner_input(t, self.estimate, self.threat, self.estimate.vx)  # what the planners had
        record = self.step.combine(t, inp.estimate, inp.threat, mpc[2] if mpc else None, msf[2] if msf else None)
        if late:
            self.problem("late", WARN, "mpc_planner late: MSF only for this instant")
        else:
            self.problem("late", None)
        self.pending.clear()
        self.blended = t
        self.values = {"weight_mpc": f"{record.blend.weight_mpc:.3f}", "planners": ",".join(self.live)}
        self.pub_blend(cv.blend_to_msg(self.rt, t, record.blend, record.reference, record.delta_mpc))
        if not self.lockstep:  # in lockstep the tick publishes the reference once, after the tick's plans
            reference = self.step.reference_at(t, self.estimate)  # the plan acts from t + timing.planning_delay_s
            if reference is not None:
                self.pub_ref(cv.reference_to_msg(self.rt, t, reference))
        self.pub_markers(cv.markers_to_msg(self.rt, t, record.threat, record.mpc, record.msf,
                                           blend_path(record.blend, self.estimate, self.step.grid.t_s)))

    def on_state(self, estimate: StateEstimate) -> None:
        self.estimate = estimate
        if self.pending:
            self.try_blend()
        if not self.lockstep:
            self.publish_reference(self.now())

    def on_tick(self, t: float) -> None:
        """Lockstep: the reference of the tick, after the plans of its instant (as the lockstep loop's)."""
        if self.estimate is not None:
            self.publish_reference(t)

    def publish_reference(self, t: float) -> None:
        """δ* re-evaluated with the newest estimate at ``t`` (the topic's designed rate, per estimate or tick)."""
        assert self.estimate is not None
        reference = self.step.reference_at(t, self.estimate)
        if reference is not None and not self.blocked:
            self.pub_ref(cv.reference_to_msg(self.rt, t, reference))
