"""Maximum-Steering Feed-forward (MSF) planner (Sec. IV-A): the human-like evasive reference.

On detection a driver steers to the side as fast as possible.  The MSF
planner follows the maximum steering maneuver y_max of eq. (ymax), scaled so
that the lateral offset reaches the danger-zone width w plus a margin m a
little before the car reaches the obstacle, and then holds that offset:

    ỹ_ref(t) = min(κ y_max(t − t_0, v_x), w + m),   κ = min(1, (w + m) / y_max(f τ, v_x)),

where ỹ = side·(y − y_path) is the lateral offset toward the evasion side, t_0
the first planning instant after detection and τ, v_x those of that instant
(κ, t_0 and v_x are latched per obstacle; past the peak of y_max, half a turn,
after 4.8 s at the earliest with μ = 0.3, the reference holds the peak).
Because y_max(f τ) ≤ y_max(τ), κ ≥ ν (eq. (nudef)): the reference is never
below the maneuver scaled by the lateral steering index, ν·y_max, which
reaches w exactly at the near edge; for ν ≳ f² (the early part of y_max is
about quadratic) κ = 1, the full maneuver.

Each planning instant re-plans from the current estimate: the reference is
tracked over the horizon by a critically damped lateral law

    a_Y = ÿ_ref + 2ω (ẏ_ref − ṽ_Y) + ω² (ỹ_ref − ỹ),

rolled out on the kinematic model eq. (skin) with exact zero-order hold, so
the output is a whole input sequence (blendable, and usable as the MPC's
initial guess).  The feed-forward ÿ_ref is the maneuver's mean acceleration
over each step, (ẏ_ref(s + t_s) − ẏ_ref(s)) / t_s, which a zero-order hold
reproduces exactly.  Once the detector clears the threat (the CoG is past the
obstacle) or without a threat, the same law with ω_return and zero reference
returns the car to the lane y_lane.  Longitudinally the maneuver is "without
braking": v̇_X = k_v (v_des − v_X).  Both accelerations are clipped to
±a_x_max, ±a_y_max (the MPC's input bounds).
"""
from __future__ import annotations

import dataclasses
import time
from typing import Optional

import numpy as np

from .maneuver import MaxSteeringTable
from .schema import MsfParams, PlanningGrid
from .signals import Obstacle, PlannerInput, PlanResult


def zoh_rollout(state: np.ndarray, accel: np.ndarray, t_s: float) -> np.ndarray:
    """eq. (skin) with exact zero-order hold: (N + 1, 4) states [x, y, v_X, v_Y] from (N, 2) accelerations.

    p⁺ = p + t_s v + t_s²/2 a,  v⁺ = v + t_s a (exact for a double integrator).
    """
    state = np.asarray(state, dtype=float)
    accel = np.asarray(accel, dtype=float).reshape(-1, 2)
    out = np.empty((len(accel) + 1, 4))
    out[0] = state
    out[1:, 2:] = state[2:] + t_s * np.cumsum(accel, axis=0)
    out[1:, :2] = state[:2] + np.cumsum(t_s * out[:-1, 2:] + 0.5 * t_s**2 * accel, axis=0)
    return out


@dataclasses.dataclass(frozen=True)
class _Evasion:
    """The latched plan for one obstacle."""

    obstacle: Obstacle
    t0: float
    kappa: float
    vx: float
    """Speed the maneuver profile is evaluated at (m/s): the speed at detection."""
    s_peak: float
    """Time at which y_max(·, vx) peaks within the table (s): past half a turn it falls, the reference holds."""


class MsfPlanner:
    """Maximum steering feed-forward; remembers the current obstacle's detection time and scale κ."""

    def __init__(self, params: MsfParams, grid: PlanningGrid, table: MaxSteeringTable) -> None:
        self.params = params
        self.table = table
        self.grid = grid
        self._evasion: Optional[_Evasion] = None

    def reset(self) -> None:
        self._evasion = None

    def scale(self, w: float, tau: float, vx: float) -> float:
        """κ = min(1, (w + m) / y_max(f τ, v_x)): the share of the maximum steering maneuver needed."""
        p = self.params
        reach = self.table.y_max(p.reach_fraction * max(tau, 0.0), max(vx, 0.0))
        return min(1.0, (w + p.margin) / reach) if reach > 1e-9 else 1.0

    def _reference(self, s: float, evasion: _Evasion, target: float) -> tuple[float, float, float]:
        """(ỹ_ref, ẏ_ref, mean ÿ_ref over the coming step) at ``s`` seconds after t_0."""
        table, k, v = self.table, evasion.kappa, evasion.vx
        if s >= evasion.s_peak:
            return min(k * table.y_max(evasion.s_peak, v), target), 0.0, 0.0
        y_ref = k * table.y_max(s, v)
        if y_ref >= target:
            return target, 0.0, 0.0
        v_ref = k * table.v_Y_max(s, v)
        a_ref = (k * table.v_Y_max(s + self.grid.t_s, v) - v_ref) / self.grid.t_s
        return y_ref, v_ref, a_ref

    def plan(self, inp: PlannerInput) -> PlanResult:
        """Accelerations over the horizon: evasion when ``inp.threat`` is set ("ok"), else lane keeping ("idle")."""
        start = time.perf_counter()
        p, est, threat = self.params, inp.estimate, inp.threat
        if threat is not None:
            if self._evasion is None or self._evasion.obstacle != threat.obstacle:
                vx = max(est.vx, 0.0)
                profile = np.asarray(self.table.y_max(self.table.t, vx))
                s_peak = float(self.table.t[int(np.argmax(profile))])
                self._evasion = _Evasion(threat.obstacle, inp.t, self.scale(threat.w, threat.tau, vx), vx, s_peak)
            evasion: Optional[_Evasion] = self._evasion
            side, y_path, target = float(threat.side), threat.y_path, threat.w + p.margin
        else:
            self._evasion = evasion = None
            side, y_path, target = 1.0, inp.y_lane, 0.0
        if evasion is not None:
            k_p, k_v = p.omega_evade**2, 2.0 * p.omega_evade
        else:
            k_p, k_v = p.omega_return**2, 2.0 * p.omega_return
        state = np.array([est.x, est.y, est.vX, est.vY], dtype=float)
        g = self.grid
        accel = np.zeros((g.N_p, 2))
        ts = g.t_s
        y, vX, vY = float(est.y), float(state[2]), float(state[3])
        for k in range(g.N_p):
            offset, v_lat = side * (y - y_path), side * vY
            if evasion is not None:
                y_ref, v_ref, a_ref = self._reference(inp.t + k * ts - evasion.t0, evasion, target)
            else:
                y_ref = v_ref = a_ref = 0.0
            a_lat = side * (a_ref + k_v * (v_ref - v_lat) + k_p * (y_ref - offset))
            a_lon = p.k_speed * (inp.v_des - vX)
            a_lon = min(max(a_lon, -g.a_x_max), g.a_x_max)
            a_lat = min(max(a_lat, -g.a_y_max), g.a_y_max)
            accel[k, 0], accel[k, 1] = a_lon, a_lat
            # eq. (skin), exact zero-order hold (lateral part; x does not enter the law)
            y += ts * vY + 0.5 * ts * ts * a_lat
            vX += ts * a_lon
            vY += ts * a_lat
        predicted = zoh_rollout(state, accel, ts)
        return PlanResult(accel=accel, status="ok" if evasion is not None else "idle", iterations=0,
                          solve_time_s=time.perf_counter() - start, cost=0.0, predicted=predicted)
