"""Baselines: the simple strategies any evasion planner must beat (docs/modelling.md, "Baselines").

Both run in the feed-forward planner's slot of Fig. 3 (the MSF planner's: the ``msf_planner`` node of the
graph, :attr:`moose.planner.step.PlanningStep.msf` in lockstep) and drive the car alone, through the
chain's FBL and motion control.  Before the first threat they keep the lane as the MSF planner does (the
approach every planner of the feed-forward slot shares).

* :class:`AebPlanner` (``aeb``): brake-only emergency braking from the first threat on, latched until
  standstill and held there.  The reference is v_x* = 0 (:func:`moose.planner.commanded_speed`, applied by
  the planning step in place of the FBL's v_x*): the motion controller's reference ramp runs down at its
  steepest slope and its torque saturates at the motors' full braking torque T_max (their ramp Ṫ_max
  included).  δ* is the FBL's for the plan, the braking limit against the velocity,

      [v̇_X, v̇_Y] = −min(a_x,max, |v| / t_s) · v / |v|,

  a_x,max = ``Config.grid.a_x_max`` (:attr:`moose.params.VehicleParams.longitudinal_accel_limit`): along the
  velocity the FBL's body-lateral acceleration is −a sin β ≈ 0, so the car brakes on its course without
  steering aside, and the plan predicts the stop.
* :class:`MaxSteerPlanner` (``max_steer``): the panic reaction the MSF planner refines.  From the first
  threat on, full lock toward the evasion side, δ* = side · δ_max (:func:`moose.planner.commanded_steering`, applied
  by the planning step in place of the FBL's δ*), which the EPS loop reaches at δ̇_max: the maximum steering
  maneuver of eq. (ymax) itself, "without braking" (the speed along the path held, the MSF planner's law),
  for as long as the detector reports the threat; then the MSF planner's return to the lane.  Its plan (the
  predicted path) is the MSF planner's tracking of ỹ_ref = y_max(s, v): the S-curve without the two
  refinements, κ = 1 (no scaling down to the threat) and no counter-steer.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..maneuver import MaxSteeringTable
from ..schema import Config, MsfParams, PlannerMode, PlanningGrid
from ..signals import Obstacle, PlannerInput, PlanResult
from .kinematics import kinematic_rollout
from .msf import Evasion, MsfPlanner


class MaxSteerPlanner(MsfPlanner):
    """Full lock toward the evasion side while the threat lasts (a :class:`moose.planner.Planner`): the MSF
    planner's evasion with κ = 1 and no counter-steer; the steering itself is
    :func:`moose.planner.commanded_steering`."""

    def evasion(self, obstacle: Obstacle, t0: float, w: float, tau: float, vx: float) -> Evasion:
        """The unscaled maneuver from ``t0`` on: ỹ_ref(s) = y_max(s, v) for every s (s₁ = ∞)."""
        return Evasion(obstacle, t0, max(vx, 0.0), 1.0, math.inf, math.inf, 0.0)


class AebPlanner(MsfPlanner):
    """Brake-only emergency braking from the first threat to standstill (a :class:`moose.planner.Planner`);
    lane keeping before it."""

    def __init__(self, params: MsfParams, grid: PlanningGrid, table: MaxSteeringTable) -> None:
        super().__init__(params, grid, table)
        self._braking = False
        """A threat has been reported: braking to standstill, latched until :meth:`reset`."""

    def reset(self) -> None:
        """Forget the braking under way (and the MSF planner's state): the next plan keeps the lane."""
        super().reset()
        self._braking = False

    def plan(self, inp: PlannerInput) -> PlanResult:
        """The braking plan once a threat has been reported ("ok"), else the MSF planner's lane keeping."""
        if not self._braking and inp.threat is None:
            return super().plan(inp)
        self._braking = True
        start = time.perf_counter()
        g, est = self.grid, inp.estimate
        state = np.array([est.x, est.y, est.vX, est.vY], dtype=float)
        accel = np.zeros((g.N_p, 2))
        vX, vY = est.vX, est.vY
        for k in range(g.N_p):
            speed = math.hypot(vX, vY)
            if speed < 1e-9:
                break  # at standstill: held (the rows left are zero)
            decel = min(g.a_x_max, speed / g.t_s)  # the last step ends at rest, not reversing
            accel[k, 0], accel[k, 1] = -decel * vX / speed, -decel * vY / speed
            vX += g.t_s * accel[k, 0]
            vY += g.t_s * accel[k, 1]
        return PlanResult(accel=accel, status="ok", iterations=0, solve_time_s=time.perf_counter() - start,
                          cost=0.0, predicted=kinematic_rollout(state, accel, g.t_s))


def feed_forward_planner(mode: PlannerMode, config: Config, table: MaxSteeringTable) -> MsfPlanner:
    """The planner of the feed-forward slot in ``mode`` (:data:`moose.planner.MODE_PLANNERS`): the baseline of a
    baseline mode, else the MSF planner; on ``config``'s planning grid and MSF parameters."""
    kind = {"aeb": AebPlanner, "max_steer": MaxSteerPlanner}.get(mode, MsfPlanner)
    return kind(config.msf, config.grid, table)
