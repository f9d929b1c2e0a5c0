"""One planning instant of Fig. 3: the MPC and MSF plans, the weight function's blend, the FBL
reference, the MPC's next initial guess, and the re-plan trigger.

Every place that plans goes through :class:`PlanningStep`: the lockstep loop
(:mod:`moose.simulation`), the ``weight_fbl`` node of the graph (whose planners run in their own
processes and hand their plans to :meth:`PlanningStep.combine`) and ``moose bag replan``.  So the
node graph reproduces the lockstep loop by construction, not by care.

* Mode: ``combined`` blends the two plans with the weight function (a missing MPC plan — failed,
  late or silent — blends as weight 0, i.e. the MSF plan; a missing MSF plan — a dead or silent MSF
  planner in the node graph — as weight 1, the MPC plan alone); ``mpc`` and ``msf`` apply one planner,
  and so do the baselines ``aeb`` and ``max_steer`` (:mod:`moose.planner.baseline`), which run in the MSF
  planner's slot and command part of the reference themselves: ``max_steer`` full lock in place of the
  FBL's δ* (:func:`~moose.planner.commanded_steering`), ``aeb`` v_x* = 0 in place of its v_x*
  (:func:`~moose.planner.commanded_speed`).
* The blended first acceleration goes to the FBL (δ*, v_x*); between planning instants δ* is
  re-evaluated at the motion-control rate on the held acceleration with the newest estimate
  (``simulation.steering_fbl_at_motion_rate``), v_x* is held.
* Timing (:mod:`moose.timing`): the plan of the instant t acts from t + ``timing.planning_delay_s``
  (the previous plan's held acceleration until then), and in lockstep the MPC's budget is charged
  that delay, never the wall clock.  With ``timing.compensate`` the planners plan from the state
  predicted to t + d_p + d_c, when their first acceleration reaches the car, and the FBL commands
  from the state predicted to now + d_c, when its command acts (:func:`moose.timing.predict`).
* The blend shifted by one step is the MPC's next initial guess (Fig. 3, dashed arrow).
* Re-plan trigger (:func:`new_obstacle`): a threat from an obstacle that was not the threat at the
  previous tick re-plans at once and restarts the planning period.
"""
from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Optional

import numpy as np

from ..schema import Config, PlannerMode, TimingParams
from ..signals import Blend, PlannerInput, PlanResult, Reference, StateEstimate, Threat
from ..timing import AccelSchedule, DelayLine, compensated_input, predict
from . import MODE_PLANNERS, Planner, commanded_speed, commanded_steering
from .fbl import FeedbackLinearization
from .kinematics import kinematic_rollout
from .weight import WeightFunction

if TYPE_CHECKING:  # the planners (CasADi) are imported only where they run, not in the weight_fbl node
    from ..maneuver import MaxSteeringTable


@dataclasses.dataclass(frozen=True)
class PlanningRecord:
    """What one planning instant produced."""

    t: float
    threat: Optional[Threat]
    mpc: Optional[PlanResult]
    msf: Optional[PlanResult]
    blend: Blend
    reference: Reference
    delta_mpc: float
    """δ* the FBL computes from the MPC's own first acceleration (the paper's δ_MPC); NaN without an MPC plan."""


def blend_path(blend: Blend, estimate: StateEstimate, t_s: float) -> np.ndarray:
    """(N_p + 1, 4) kinematic states [x, y, v_X, v_Y] the blended plan predicts from ``estimate``: eq. (skin)
    under :func:`~moose.planner.kinematics.kinematic_rollout` (what the MPC's and MSF's ``PlanResult.predicted`` are
    for their own plans)."""
    return kinematic_rollout(np.array([estimate.x, estimate.y, estimate.vX, estimate.vY]), blend.accel, t_s)


def new_obstacle(previous: Optional[Threat], current: Optional[Threat]) -> bool:
    """The re-plan trigger: ``current`` is a threat from another obstacle than ``previous`` (or the first)."""
    return current is not None and (previous is None or previous.obstacle != current.obstacle)


def acts_from(t: float, timing: TimingParams) -> float:
    """When the first acceleration of a plan made at ``t`` reaches the car: t + d_p + d_c."""
    return t + timing.planning_delay_s + timing.command_delay_s


def compensated(inp: PlannerInput, timing: TimingParams, in_flight: AccelSchedule) -> PlannerInput:
    """The planners' input of the instant ``inp.t``: with ``timing.compensate`` predicted to when the plan acts
    (:func:`acts_from`, :func:`moose.timing.compensated_input`) through the blends ``in_flight``; else ``inp``.
    The planning step and the graph's planner nodes (which hear the blends on /planning/blend) both use it."""
    if not timing.compensate:
        return inp
    return compensated_input(inp, acts_from(inp.t, timing), in_flight)


class PlanningStep:
    """The planners, the weight function and the FBL of one configuration, and what a planning instant
    leaves for the next: the held acceleration, the reference and the MPC's initial guess.

    ``planners=False`` builds only the combining part (weight function and FBL): the ``weight_fbl``
    node, whose planners are other processes.
    """

    def __init__(self, config: Config, mode: PlannerMode | None = None, table: Optional["MaxSteeringTable"] = None,
                 planners: bool = True) -> None:
        self.mode: PlannerMode = mode or config.simulation.planner
        self.grid = config.grid
        model = config.model_vehicle
        self.fbl = FeedbackLinearization(config.fbl, model, self.grid.t_s)
        self.weight = WeightFunction(config.weight, self.fbl)
        self.delta_max = model.delta_max
        self.mpc: Optional[Planner] = None
        self.msf: Optional[Planner] = None
        """The feed-forward slot: the MSF planner, or the baseline of a baseline mode."""
        if planners and "mpc" in MODE_PLANNERS[self.mode]:
            from .mpc import MpcPlanner

            self.mpc = MpcPlanner(config.mpc, self.grid, compute_time_s=config.timing.planning_delay_s)
        if planners and "msf" in MODE_PLANNERS[self.mode]:
            from ..maneuver import MaxSteeringTable
            from .baseline import feed_forward_planner

            self.msf = feed_forward_planner(self.mode, config, table or MaxSteeringTable.build(model, config.maneuver))
        self.fbl_at_motion_rate = config.simulation.steering_fbl_at_motion_rate
        self.timing = config.timing
        self._plans: DelayLine[PlanningRecord] = DelayLine(self.timing.planning_delay_s, config.motion_period)
        self._in_flight = AccelSchedule()
        """The blends' first accelerations from when they reach the car (t + d_p + d_c): what compensation predicts
        with."""
        self.guess: Optional[np.ndarray] = None
        """(N_p, 2) initial guess of the next MPC solve: the last blend shifted by one step."""
        self.acting: Optional[PlanningRecord] = None
        """The plan acting now (the latest whose planning delay has passed), None before the first."""

    def planner_input(self, t: float, estimate: StateEstimate, threat: Optional[Threat], v_des: float) -> PlannerInput:
        """What both planners receive at ``t`` (the MPC's guess is the shifted previous blend); with
        ``timing.compensate`` predicted to t + d_p + d_c (:func:`moose.timing.compensated_input`)."""
        inp = PlannerInput(t=t, estimate=estimate, threat=threat, v_des=v_des, initial_guess=self.guess, y_lane=0.0)
        return compensated(inp, self.timing, self._in_flight)

    def plan(self, t: float, estimate: StateEstimate, threat: Optional[Threat], v_des: float) -> PlanningRecord:
        """Run the mode's planners at ``t`` and :meth:`combine` their plans."""
        inp = self.planner_input(t, estimate, threat, v_des)
        mpc = self.mpc.plan(inp) if self.mpc is not None else None
        msf = self.msf.plan(inp) if self.msf is not None else None
        return self.combine(t, inp.estimate, inp.threat, mpc, msf)

    def combine(self, t: float, estimate: StateEstimate, threat: Optional[Threat], mpc: Optional[PlanResult],
                msf: Optional[PlanResult]) -> PlanningRecord:
        """The blend of the mode, the FBL reference and the next initial guess from the plans of one instant
        (``estimate`` and ``threat`` as the planners had them, :meth:`planner_input`); the plan acts from
        t + ``timing.planning_delay_s`` (:meth:`reference_at`).

        ``combined`` needs one plan: without an MPC plan it blends with weight 0, without an MSF plan it
        applies the MPC plan (weight 1: the other planner is dead or silent).  ``mpc`` and ``msf`` need
        their own plan.  A missing plan that the mode needs raises ``ValueError``.
        """
        if self.mode == "mpc" or (self.mode == "combined" and msf is None and mpc is not None):
            if mpc is None:
                raise ValueError("mode mpc needs an MPC plan")
            blend = Blend(weight_mpc=1.0, accel=np.array(mpc.accel, dtype=float, copy=True))
        elif msf is None:
            raise ValueError(f"mode {self.mode} needs an MSF plan")
        elif self.mode != "combined":  # the feed-forward slot's planner alone (the MSF planner or a baseline)
            blend = Blend(weight_mpc=0.0, accel=np.array(msf.accel, dtype=float, copy=True))
        else:
            blend = self.weight.blend(mpc, msf, threat, estimate)
        reference = self.fbl.reference(blend.accel[0], estimate)
        steering, speed = commanded_steering(self.mode, msf, threat, self.delta_max), commanded_speed(self.mode, msf)
        if steering is not None or speed is not None:  # a baseline's own reference (moose.planner.baseline)
            reference = Reference(delta=reference.delta if steering is None else steering,
                                  vx=reference.vx if speed is None else speed)
        delta_mpc = self.fbl.steering(mpc.accel[0], estimate) if mpc is not None else float("nan")
        self.guess = self.weight.next_initial_guess(blend)
        record = PlanningRecord(t, threat, mpc, msf, blend, reference, delta_mpc)
        self._plans.push(t, record)
        self._in_flight.add(acts_from(t, self.timing), blend.accel[0])
        return record

    def reference_at(self, t: float, estimate: StateEstimate) -> Optional[Reference]:
        """The FBL reference at ``t``: the plans due by ``t`` take over (:attr:`acting`); δ* of the acting plan's
        first acceleration at ``estimate`` (when ``steering_fbl_at_motion_rate``; with ``timing.compensate`` at the
        estimate predicted to t + d_c), v_x* of that plan; None before the first plan acts."""
        due = self._plans.pop_due(t)
        if due:
            self.acting = due[-1]
        acting = self.acting
        if acting is None:
            return None
        if not self.fbl_at_motion_rate or commanded_steering(self.mode, acting.msf, acting.threat,
                                                             self.delta_max) is not None:
            return acting.reference
        if self.timing.compensate:
            estimate = predict(estimate, t + self.timing.command_delay_s, self._in_flight)
        return Reference(delta=self.fbl.steering(acting.blend.accel[0], estimate), vx=acting.reference.vx)
