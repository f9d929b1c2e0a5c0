"""``mpc_planner`` and ``msf_planner``: a planner at the planning rate, and at once on a new obstacle (the
``msf_planner`` node hosts the feed-forward slot: the MSF planner, or a baseline)."""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from moose.planner import Planner
from moose.planner.step import acts_from, compensated, new_obstacle
from moose.planner.weight import WeightFunction
from moose.signals import Blend, PlannerInput, StateEstimate, Threat
from moose.timing import AccelSchedule

from .. import convert as cv
from ..graph import BLEND, PLANS, STATE, THREAT
from ..runtime.base import NodeBase
from .base import ERROR, OK, WARN, GraphNode


class PlannerNode(GraphNode):
    """MPC or MSF planner at the planning rate (5 Hz), and at once on a new obstacle, which restarts the
    planning period (:func:`moose.planner.step.new_obstacle`, as in the lockstep loop)."""

    kind = ""

    def __init__(self, rt: NodeBase) -> None:
        super().__init__(rt)
        self.planner = self.make_planner()
        self.scenario = self.params.load_scenario()
        self.estimate: Optional[StateEstimate] = None
        self.threat: Optional[Threat] = None
        self.detected = False
        self.guess: Optional[np.ndarray] = None
        self.blocked = False
        """The estimate or the threat is stale: no plan (the plan topic falls silent, weight_fbl applies the
        other planner's)."""
        self.pub = self.publisher(PLANS[self.kind])
        self.in_flight = AccelSchedule()
        """The blends' first accelerations from when they reach the car: what ``timing.compensate`` predicts with
        (the planning step's, heard on /planning/blend)."""
        self.subscribe(STATE, lambda estimate: setattr(self, "estimate", estimate))
        self.subscribe(THREAT, self.on_threat)
        self.subscribe(BLEND, self.on_blend)
        self.period = self.config.planning.t_s
        self.next_plan = 0.0
        """Time of the next planning instant: every t_s, restarted by a new obstacle (as the lockstep loop)."""
        if not self.lockstep:  # in lockstep the tick comes from the graph (GraphNode.on_tick)
            rt.timer(1.0 / self.config.simulation.motion_rate_hz, lambda: self.on_tick(self.rt.now()))

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        """No plan on a stale estimate or threat (ERROR); a stale blend only costs the MPC its warm start (WARN)."""
        self.report_stale(stale, ERROR, {BLEND.name: WARN})
        self.blocked = STATE.name in stale or THREAT.name in stale

    def make_planner(self) -> Planner:
        """The planner this node runs (built once, at start)."""
        raise NotImplementedError

    def on_blend(self, stamped: tuple[float, Blend]) -> None:
        """A blend of weight_fbl (the planning step's) of the instant t: in flight from when it reaches the car."""
        t, blend = stamped
        self.in_flight.add(acts_from(t, self.config.timing), blend.accel[0])

    def on_threat(self, threat: Optional[Threat]) -> None:
        replan = new_obstacle(self.threat, threat)
        self.threat = threat
        self.detected = self.detected or threat is not None
        if replan and threat is not None:  # at the detection's instant (the threat's); the period restarts there
            self.plan(threat.t)
            self.next_plan = threat.t + self.period

    def on_tick(self, now: float) -> None:
        """The motion-rate tick: plan when the planning instant is due, stamped with the instant itself, so
        that both planners' plans of one instant carry one stamp even when a tick runs late (instants a
        stalled node missed entirely are skipped, not made up)."""
        if now >= self.next_plan - 1e-6:
            instant = self.next_plan
            self.next_plan += self.period * (math.floor((now + 1e-6 - instant) / self.period) + 1)  # the next due
            self.plan(instant if now - instant < self.period else now)

    @property
    def v_des(self) -> float:
        """The ``v_des`` parameter, else the scenario's: the approach speed until detection, then its v_des."""
        return self.params.v_des if self.params.v_des is not None else self.scenario.desired_speed(self.detected)

    def plan(self, t: Optional[float] = None) -> None:
        """Plan at ``t`` (default: now) from the newest estimate."""
        if self.estimate is None or self.blocked:
            return
        t = self.now() if t is None else t
        inp = compensated(PlannerInput(t, self.estimate, self.threat, self.v_des, self.guess, y_lane=0.0),
                          self.config.timing, self.in_flight)
        result = self.planner.plan(inp)
        if result.solve_time_s > self.config.planning.t_s:  # the planning slot is over before the plan exists
            self.deadline_misses += 1
        self.values = {"status": result.status, "solve_ms": f"{result.solve_time_s * 1e3:.2f}"}
        self.level = OK if result.status in ("converged", "capped", "barrier_violated", "ok", "idle") else WARN
        self.pub(cv.plan_to_msg(self.rt, t, self.kind, result, self.threat is not None))


class MpcPlannerNode(PlannerNode):
    """The MPC planner, warm-started from the last blend (/planning/blend)."""

    name, kind = "mpc_planner", "mpc"

    def on_blend(self, stamped: tuple[float, Blend]) -> None:
        super().on_blend(stamped)
        self.guess = WeightFunction.next_initial_guess(stamped[1])

    def make_planner(self) -> Planner:
        from moose.planner.mpc import MpcPlanner

        return MpcPlanner(self.config.mpc, self.config.grid)


class MsfPlannerNode(PlannerNode):
    """The feed-forward planner's slot (no initial guess): the maximum-steering feed-forward planner, or in a
    baseline mode (``simulation.planner`` ``aeb`` or ``max_steer``) the baseline, which then drives the car alone
    (:data:`moose.planner.MODE_PLANNERS`)."""

    name, kind = "msf_planner", "msf"

    def make_planner(self) -> Planner:
        from moose.planner.baseline import feed_forward_planner

        return feed_forward_planner(self.config.simulation.planner, self.config, self.table())
