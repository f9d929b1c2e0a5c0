"""Maximum-Steering Feed-forward (MSF) planner (Sec. IV-A): the human-like evasive reference.

On detection a driver steers to the side as fast as possible.  The MSF
planner follows the maximum steering maneuver y_max of eq. (ymax), scaled so
that the lateral offset reaches the danger-zone width w (plus a margin) when
the car reaches the obstacle:

    ỹ_ref(t) = min(κ y_max(t − t_0, v_x), w + m),   κ = min(1, (w + m) / y_max(f τ, v_x)),

i.e. κ = ν (1 + m/w) y_max(τ)/y_max(fτ) — the maneuver scaled by the lateral
steering index, arriving a little early (f = ``reach_fraction``), with t_0 the
detection time, τ the time to collision at detection and ỹ
the lateral offset from the ego path toward the evasion side.  The feed-forward
is the maneuver's mean acceleration over the coming planning step,
(ẏ_ref(τ + t_s) − ẏ_ref(τ)) / t_s, which a zero-order hold reproduces exactly.  When ν ≥ 1 the
full maneuver is the best steering can do.  The reference is tracked over the
horizon by a critically damped lateral law, a_Y = ÿ_ref + k_v (ẏ_ref − ṽ_Y) +
k_p (ỹ_ref − ỹ), rolled out on the kinematic model eq. (skin) so the result is
a whole input sequence (blendable, and usable as the MPC's initial guess).
Once the threat is cleared (past the obstacle) or absent, the same law with
softer gains returns the car to its lane.  Longitudinally the maneuver is
"without braking": the speed tracks v_des with a first-order law.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Optional

import numpy as np

from .maneuver import MaxSteeringTable
from .mpc import kinematic_rollout
from .params import VehicleParams, check, non_negative, positive
from .signals import Obstacle, PlannerInput, PlanResult


@dataclasses.dataclass(frozen=True)
class MsfParams:
    """MSF planner parameters."""

    N_p: int = 10
    t_s: float = 0.2
    a_x_max: float = 6.0
    a_y_max: float = 6.0
    margin: float = 0.5
    """Lateral margin beyond the far edge (m)."""
    omega_evade: float = 2.5
    """Natural frequency of the lateral tracking law while evading (rad/s)."""
    omega_return: float = 1.0
    """Natural frequency of the lane return (rad/s)."""
    k_speed: float = 0.5
    """Speed-tracking gain (1/s)."""
    reach_fraction: float = 0.6
    """The scaled maneuver reaches w + margin after this fraction of τ (early, like a driver)."""

    def __post_init__(self) -> None:
        check("N_p", self.N_p, lambda v: 1 <= v <= 100, "an integer in [1, 100]")
        for name in ("t_s", "a_x_max", "a_y_max", "omega_evade", "omega_return", "k_speed"):
            check(name, getattr(self, name), positive, "a positive number")
        check("margin", self.margin, non_negative, "a non-negative distance (m)")
        check("reach_fraction", self.reach_fraction, lambda v: 0.0 < v <= 1.0, "a fraction in (0, 1]")


class MsfPlanner:
    """Maximum steering feed-forward; remembers each obstacle's detection time and ν."""

    def __init__(self, params: MsfParams, table: MaxSteeringTable, vehicle: VehicleParams) -> None:
        self.params = params
        self.table = table
        self.vehicle = vehicle
        self._detections: dict[Obstacle, tuple[float, float]] = {}

    def _lateral(self, t: float, offset: float, v_lat: float, vx: float, evade: Optional[tuple[float, float, float]]) -> float:
        p = self.params
        if evade is None:
            k_p, k_v = p.omega_return**2, 2.0 * p.omega_return
            return -k_p * offset - k_v * v_lat
        t0, kappa, target = evade
        ts = p.t_s
        tau = max(t - t0, 0.0)
        y_ref = kappa * self.table.y_max(tau, vx)
        if y_ref >= target:
            y_ref, v_ref, a_ref = target, 0.0, 0.0
        else:
            # mean acceleration of the maneuver over the coming step (exact for a zero-order hold)
            v_ref = kappa * self.table.v_Y_max(tau, vx)
            a_ref = (kappa * self.table.v_Y_max(tau + ts, vx) - v_ref) / ts
        k_p, k_v = p.omega_evade**2, 2.0 * p.omega_evade
        return a_ref + k_v * (v_ref - v_lat) + k_p * (y_ref - offset)

    def plan(self, inp: PlannerInput) -> PlanResult:
        start = time.perf_counter()
        p, est, threat = self.params, inp.estimate, inp.threat
        if threat is not None:
            if threat.obstacle not in self._detections:
                reach = self.table.y_max(p.reach_fraction * max(threat.tau, 0.0), max(est.vx, 0.0))
                target = threat.w + p.margin
                self._detections[threat.obstacle] = (inp.t, min(1.0, target / reach) if reach > 1e-9 else 1.0)
            t0, kappa = self._detections[threat.obstacle]
            evade: Optional[tuple[float, float, float]] = (t0, kappa, threat.w + p.margin)
            side, y_path = float(threat.side), threat.y_path
        else:
            evade, side, y_path = None, 1.0, inp.y_lane
        state = np.array([est.x, est.y, est.vX, est.vY])
        accel = np.zeros((p.N_p, 2))
        s = state.copy()
        for k in range(p.N_p):
            t = inp.t + k * p.t_s
            a_lat = side * self._lateral(t, side * (s[1] - y_path), side * s[3], max(s[2], 0.0), evade)
            a_lon = p.k_speed * (inp.v_des - s[2])
            accel[k] = (np.clip(a_lon, -p.a_x_max, p.a_x_max), np.clip(a_lat, -p.a_y_max, p.a_y_max))
            s = kinematic_rollout(s, accel[k:k + 1], p.t_s)[1]
        predicted = kinematic_rollout(state, accel, p.t_s)
        status = "ok" if threat is not None else "idle"
        return PlanResult(accel=accel, status=status, iterations=0, solve_time_s=time.perf_counter() - start,
                          cost=0.0, predicted=predicted)
