"""Maximum-Steering Feed-forward (MSF) planner (Sec. IV-A): the human-like evasive reference.

On detection a driver steers to the side as fast as possible, then counter-steers so that the car
arrives beside the obstacle moving straight again.  The MSF planner builds that as a lateral
reference from the maximum steering maneuver y_max of eq. (ymax) (at the speed v at detection):

* **Evasion** (an S-curve to the target offset W = w + m, m a margin beyond the far edge):

      ỹ_ref(s) = κ y_max(s)                       for s ≤ s₁  (steer),
      ỹ_ref(s) = W_end − κ y_max(2 s₁ − s)        for s₁ < s < 2 s₁  (counter-steer),
      ỹ_ref(s) = W_end                            afterwards,

  with ỹ = side·(y − y_path) the offset toward the evasion side and s the time since detection.
  The counter-steer phase is the steer phase mirrored in time and offset, so position and lateral
  velocity are continuous, and the car arrives at W_end = 2 κ y_max(s₁) with no lateral velocity.
  When the scaled maneuver can arrive at W by f τ (the reach fraction f of the time to
  collision), κ = W / (2 y_max(f τ / 2)) ≤ 1 and s₁ = f τ / 2: the maneuver is scaled down to what
  the threat needs (κ ≥ ν for the early, near-quadratic part of y_max).  Otherwise κ = 1 (the full
  maneuver) and the counter-steer starts at the earliest s₁ with ỹ_ref(τ) ≥ W (the reference is
  beside the zone's far edge, with the margin, when the car reaches the near edge), which makes
  W_end larger than W: a car that has to steer hard cannot stop its lateral motion any sooner.
  If even the full maneuver reaches less than W by τ (ν close to 1 and beyond), s₁ = τ: steer
  fully until the near edge.
* **Return** (once the detector has cleared the threat, the CoG past the obstacle): a cosine
  S-curve from the offset ỹ_c at that instant back to the lane, y_c (1 + cos(π s / T)) / 2, its
  duration T = π √(|ỹ_c| / (2 a_ret)) set so that its lateral acceleration peaks at
  a_ret = ``return_share`` · μ g (a calm lane change, far from the tyres' limit).
* Without a threat and no return under way: lane keeping on y_lane.

Each planning instant re-plans from the current estimate: the reference is tracked over the
horizon by the critically damped law a_Y = ÿ_ref + 2ω (ẏ_ref − v_Y) + ω² (ỹ_ref − ỹ) (ω =
``omega_track``; lane keeping ``omega_lane``), rolled out on the kinematic model eq. (skin) with
exact zero-order hold, so the output is a whole input sequence (blendable, and usable as the MPC's
initial guess).  The feed-forward ÿ_ref is the reference's mean acceleration over each step
(what a zero-order hold reproduces exactly).  Longitudinally the maneuver is "without braking":
the speed |v| of the CoG is regulated, d|v|/dt = k_v (v_des − |v|), so that the lateral
acceleration adds no speed of its own (regulating the global v_X instead would let the car speed
up as its heading turns).  Both accelerations are clipped to the planning grid's bounds (the
rear motors' and the tyres' limits at the planning μ).
"""
from __future__ import annotations

import dataclasses
import math
import time
from typing import Optional

import numpy as np

from ..maneuver import MaxSteeringTable
from ..schema import MsfParams, PlanningGrid
from ..signals import Obstacle, PlannerInput, PlanResult, PlanStatus
from .kinematics import kinematic_rollout


def _quintic(left: tuple[float, float, float], right: tuple[float, float, float], length: float,
             x: float) -> tuple[float, float]:
    """Position and velocity at ``x`` ∈ [0, 1] of the quintic Hermite curve over an interval of ``length``
    seconds that matches (position, velocity, acceleration) ``left`` at its start and ``right`` at its end."""
    (p0, v0, a0), (p1, v1, a1), h = left, right, length
    x2, x3, x4, x5 = x * x, x ** 3, x ** 4, x ** 5
    position = (p0 * (1 - 10 * x3 + 15 * x4 - 6 * x5) + h * v0 * (x - 6 * x3 + 8 * x4 - 3 * x5)
                + h * h * a0 * 0.5 * (x2 - 3 * x3 + 3 * x4 - x5) + h * h * a1 * 0.5 * (x3 - 2 * x4 + x5)
                + h * v1 * (-4 * x3 + 7 * x4 - 3 * x5) + p1 * (10 * x3 - 15 * x4 + 6 * x5))
    slope = (p0 * (-30 * x2 + 60 * x3 - 30 * x4) + h * v0 * (1 - 18 * x2 + 32 * x3 - 15 * x4)
             + h * h * a0 * 0.5 * (2 * x - 9 * x2 + 12 * x3 - 5 * x4) + h * h * a1 * 0.5 * (3 * x2 - 8 * x3 + 5 * x4)
             + h * v1 * (-12 * x2 + 28 * x3 - 15 * x4) + p1 * (30 * x2 - 60 * x3 + 30 * x4))
    return position, slope / h


def arrival_time(tau: float, v0: float, v_des: float, k_speed: float) -> float:
    """When the car reaches the near edge, τ v₀ ahead at detection, with its speed following the MSF's law
    dv/dt = k_v (v_des − v) from v₀ (s): τ itself when v₀ = v_des; shorter when the car speeds up (the paper's
    4.5 m/s detection with a desired 6 m/s), longer when it slows; inf if it stops short of the edge."""
    distance = tau * v0
    if not (math.isfinite(distance) and distance > 0.0) or v0 == v_des:
        return tau

    def travelled(t: float) -> float:
        return v_des * t + (v0 - v_des) * (1.0 - math.exp(-k_speed * t)) / k_speed

    if v_des <= 0.0 and v0 / k_speed <= distance:
        return math.inf
    lo, hi = 0.0, tau
    while travelled(hi) < distance:
        lo, hi = hi, 2.0 * hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if travelled(mid) < distance else (lo, mid)
    return hi


@dataclasses.dataclass(frozen=True)
class Ramps:
    """A lateral motion whose acceleration is piecewise linear in time: from (``p0``, ``v0``) at u = 0 through the
    (time, acceleration) ``knots`` (the first at u = 0), then 0 (the ``nu_scaled`` counter-steer)."""

    p0: float
    v0: float
    knots: tuple[tuple[float, float], ...]

    def at(self, u: float) -> tuple[float, float, float]:
        """(position, velocity, acceleration) ``u`` seconds after the start (exact: cubic positions)."""
        p, v = self.p0, self.v0
        for (t0, a0), (t1, a1) in zip(self.knots, self.knots[1:]):
            span = t1 - t0
            du = min(max(u - t0, 0.0), span)
            slope = (a1 - a0) / span if span > 0.0 else 0.0
            p_end = p + v * du + 0.5 * a0 * du * du + slope * du ** 3 / 6.0
            v_end = v + a0 * du + 0.5 * slope * du * du
            if u <= t1:
                return p_end, v_end, a0 + slope * du
            p, v = p_end, v_end
        last = self.knots[-1][0] if self.knots else 0.0
        return p + v * max(u - last, 0.0), v, 0.0

    @property
    def end(self) -> float:
        """The offset where the motion stops (m)."""
        return self.at(self.knots[-1][0] if self.knots else 0.0)[0]


def counter_steer(p1: float, v1: float, a1: float, a_brake: float, swing: float, release: float) -> Ramps:
    """Stop a lateral motion (position ``p1``, velocity ``v1`` > 0, acceleration ``a1``) as a car can: the lateral
    acceleration swings linearly from ``a1`` to −``a_brake`` over ``swing`` seconds (the steering from its lock
    to the opposite), is held, and returns to 0 over ``release`` seconds (the steering back to straight), the
    hold chosen so that the velocity ends at 0.  Too little velocity to hold for: a lower ``a_brake`` without a
    hold; none at all (v1 ≤ 0): no counter-steer."""
    if v1 <= 0.0:
        return Ramps(p1, v1, ())
    hold = (v1 + 0.5 * swing * (a1 - a_brake) - 0.5 * a_brake * release) / a_brake
    if hold < 0.0:
        hold, a_brake = 0.0, (v1 + 0.5 * swing * a1) / (0.5 * (swing + release))
        if a_brake <= 0.0:  # the acceleration returning to 0 already stops it
            return Ramps(p1, v1, ((0.0, a1), (-2.0 * v1 / a1, 0.0)))
    return Ramps(p1, v1, ((0.0, a1), (swing, -a_brake), (swing + hold, -a_brake), (swing + hold + release, 0.0)))


@dataclasses.dataclass(frozen=True)
class Evasion:
    """The evasion reference latched at detection for one obstacle: the S-curve (``stop`` None) or the ν-scaled
    maneuver and its counter-steer."""

    obstacle: Obstacle
    t0: float
    """Time of detection (s)."""
    vx: float
    """Speed the maneuver y_max is evaluated at (m/s): the speed at detection."""
    kappa: float
    """Scale of the maximum steering maneuver, in (0, 1]."""
    s1: float
    """Time after detection at which the counter-steer starts (s)."""
    target: float
    """Offset W_end the S-curve arrives at, at 2 s₁ (m)."""
    swing: float
    """Duration of the counter-steer transition (s): the steering's time from κ-lock to the opposite,
    2 κ δ_max / δ̇_max, centred on s₁ (:meth:`MsfPlanner.evasion_reference`)."""
    stop: Optional[Ramps] = None
    """``nu_scaled``: the counter-steer from s₁ on (time measured from s₁); None for the S-curve."""


@dataclasses.dataclass(frozen=True)
class LaneReturn:
    """The cosine S-curve latched when the threat cleared."""

    t0: float
    offset: float
    """Offset ỹ_c from the lane at the start (m)."""
    duration: float
    """T (s)."""
    side: float
    y_path: float


class MsfPlanner:
    """Maximum steering feed-forward (a :class:`moose.planner.Planner`); remembers the current evasion or return
    it is flying."""

    def __init__(self, params: MsfParams, grid: PlanningGrid, table: MaxSteeringTable) -> None:
        self.params = params
        self.grid = grid
        self.table = table
        self._evasion: Optional[Evasion] = None
        self._side = 1.0
        self._y_path = 0.0
        self._return: Optional[LaneReturn] = None

    def reset(self) -> None:
        """Forget the evasion or return under way: the next plan keeps the lane or starts a new evasion."""
        self._evasion = None
        self._return = None

    # -- the evasion S-curve -------------------------------------------------------------------------
    def evasion(self, obstacle: Obstacle, t0: float, w: float, tau: float, vx: float) -> Evasion:
        """The evasion (``params.profile``) for a threat of width ``w`` at time to collision ``tau``, at the
        speed ``vx``.

        Its position at the near edge is that of the reference the car is given, the counter-steer's
        transition included (:meth:`evasion_reference`).
        """
        if self.params.profile == "nu_scaled":
            return self.nu_scaled_evasion(obstacle, t0, w, tau, vx)
        p, y = self.params, self.table.y_max
        target = w + p.margin
        v = max(vx, 0.0)
        tau = max(tau, 0.0)
        swing = 2.0 * self.table.t_lock
        arrive = p.reach_fraction * tau
        half = float(y(0.5 * arrive, v))
        kappa = target / (2.0 * half) if half > 1e-9 else math.inf
        if kappa <= 1.0:
            return Evasion(obstacle, t0, v, kappa, 0.5 * arrive, target, kappa * swing)

        def at_tau(s1: float) -> float:  # the reference at τ for κ = 1 and the counter-steer from s1
            return self.evasion_reference(tau, Evasion(obstacle, t0, v, 1.0, s1, 2.0 * float(y(s1, v)), swing))[0]

        # past half a turn y_max falls again: the counter-steer starts by its peak at the latest
        profile = np.asarray(y(self.table.t, v))
        lo, hi = 0.5 * tau, min(tau, float(self.table.t[int(np.argmax(profile))]))
        lo = min(lo, hi)
        if at_tau(hi) <= target:
            s1 = hi
        else:
            for _ in range(30):  # ỹ_ref(τ) grows with s1 while y_max is convex (its early part)
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if at_tau(mid) < target else (lo, mid)
            s1 = hi
        return Evasion(obstacle, t0, v, 1.0, s1, 2.0 * float(y(s1, v)), swing)

    def nu_scaled_evasion(self, obstacle: Obstacle, t0: float, w: float, tau: float, vx: float) -> Evasion:
        """The ν-scaled evasion: ỹ_ref = κ y_max(s) with κ = W / y_max(τ) (eq. (nudef) for the target W = w + m,
        at most 1), arriving at W at τ; then the counter-steer (:func:`counter_steer`) at the full maneuver's
        peak lateral acceleration, so the steering's largest swing comes at and after the near edge.

        The steer phase ends at s₁ = τ, at the peak of y_max if that comes first (ẏ_max = 0 there: nothing to
        stop), and with κ = 1 (W beyond y_max(τ)) where the full maneuver reaches W, at the latest at its peak."""
        table, y = self.table, self.table.y_max
        target = w + self.params.margin
        v = max(vx, 0.0)
        profile = np.asarray(y(table.t, v))
        peak = float(table.t[int(np.argmax(profile))])
        s1 = min(max(tau, 0.0), peak)
        reach = float(y(s1, v))
        kappa = min(target / reach, 1.0) if reach > 1e-9 else 1.0
        if kappa == 1.0 and reach < target and s1 < peak:
            lo, hi = s1, peak  # y_max rises on [τ, peak]: the first time it reaches W, or its peak
            if float(y(hi, v)) >= target:
                for _ in range(30):
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if float(y(mid, v)) < target else (lo, mid)
            s1 = hi
        stop = counter_steer(kappa * float(y(s1, v)), kappa * float(table.v_Y_max(s1, v)),
                             kappa * float(table.a_Y_max(s1, v)), float(np.max(table.a_Y_max(table.t, v))),
                             (kappa + 1.0) * table.t_lock, table.t_lock)
        return Evasion(obstacle, t0, v, kappa, s1, stop.end, (kappa + 1.0) * table.t_lock, stop)

    def evasion_reference(self, s: float, e: Evasion) -> tuple[float, float, float]:
        """(ỹ_ref, ẏ_ref, mean ÿ_ref over the coming step) ``s`` seconds after detection.

        The mirror flips the lateral acceleration at s₁, which the car can only do as fast as its
        steering swings from κ-lock to the other side (``e.swing``): over that window, centred on
        s₁, the curve is a quintic that matches position, velocity and acceleration at both ends,
        so the acceleration passes through zero smoothly; start, end and arrival are unchanged.
        """
        ts = self.grid.t_s
        y, yd, ydd = self.table.y_max, self.table.v_Y_max, self.table.a_Y_max
        k, half = e.kappa, min(0.5 * e.swing, e.s1)

        def raw(u: float) -> tuple[float, float, float]:
            if u <= 0.0:
                return 0.0, 0.0, 0.0
            if u <= e.s1:
                return k * float(y(u, e.vx)), k * float(yd(u, e.vx)), k * float(ydd(u, e.vx))
            if u < 2.0 * e.s1:
                m = 2.0 * e.s1 - u
                return e.target - k * float(y(m, e.vx)), k * float(yd(m, e.vx)), -k * float(ydd(m, e.vx))
            return e.target, 0.0, 0.0

        def position(u: float) -> tuple[float, float]:
            if e.stop is not None:  # ν-scaled: the scaled maneuver, then the counter-steer
                if u <= e.s1:
                    p, v, _ = raw(u)
                    return p, v
                p, v, _ = e.stop.at(u - e.s1)
                return p, v
            if half <= 0.0 or abs(u - e.s1) >= half:
                p, v, _ = raw(u)
                return p, v
            a, length = e.s1 - half, 2.0 * half
            left, right = raw(a), raw(e.s1 + half)
            return _quintic(left, right, length, (u - a) / length)

        y_ref, v_ref = position(s)
        return y_ref, v_ref, (position(s + ts)[1] - v_ref) / ts

    def return_reference(self, s: float, r: LaneReturn) -> tuple[float, float, float]:
        """(ỹ_ref, ẏ_ref, mean ÿ_ref over the coming step) ``s`` seconds into the return."""
        ts = self.grid.t_s

        def position(u: float) -> tuple[float, float]:
            if u >= r.duration:
                return 0.0, 0.0
            phase = math.pi * max(u, 0.0) / r.duration
            return 0.5 * r.offset * (1.0 + math.cos(phase)), -0.5 * r.offset * math.pi / r.duration * math.sin(phase)

        y_ref, v_ref = position(s)
        return y_ref, v_ref, (position(s + ts)[1] - v_ref) / ts

    # -- planning ------------------------------------------------------------------------------------
    def plan(self, inp: PlannerInput) -> PlanResult:
        """Accelerations over the horizon: evasion with a threat ("ok"), the return or lane keeping without ("idle")."""
        start = time.perf_counter()
        p, g, est, threat = self.params, self.grid, inp.estimate, inp.threat
        if threat is not None:
            if self._evasion is None or self._evasion.obstacle != threat.obstacle:
                arrive = arrival_time(threat.tau, est.vx, inp.v_des, p.k_speed)
                self._evasion = self.evasion(threat.obstacle, inp.t, threat.w, arrive, est.vx)
            self._return = None
            self._side, self._y_path = float(threat.side), threat.y_path
        elif self._evasion is not None:  # the threat has cleared: fly back to the lane
            offset = self._side * (est.y - inp.y_lane)
            a_ret = p.return_share * g.a_y_max
            duration = math.pi * math.sqrt(abs(offset) / (2.0 * a_ret)) if offset else 0.0
            self._return = LaneReturn(inp.t, offset, duration, self._side, inp.y_lane)
            self._evasion = None
        if self._return is not None and inp.t - self._return.t0 >= self._return.duration + g.N_p * g.t_s:
            self._return = None
        evasion, lane_return = self._evasion, self._return
        if evasion is not None:
            side, y_path, omega = self._side, self._y_path, p.omega_track
        elif lane_return is not None:
            side, y_path, omega = lane_return.side, lane_return.y_path, p.omega_track
        else:
            side, y_path, omega = 1.0, inp.y_lane, p.omega_lane
        k_p, k_v = omega * omega, 2.0 * omega
        state = np.array([est.x, est.y, est.vX, est.vY], dtype=float)
        accel = np.zeros((g.N_p, 2))
        ts = g.t_s
        y, vX, vY = float(est.y), est.vX, est.vY
        for k in range(g.N_p):
            s = inp.t + k * ts
            if evasion is not None:
                y_ref, v_ref, a_ref = self.evasion_reference(s - evasion.t0, evasion)
            elif lane_return is not None:
                y_ref, v_ref, a_ref = self.return_reference(s - lane_return.t0, lane_return)
            else:
                y_ref = v_ref = a_ref = 0.0
            offset, v_lat = side * (y - y_path), side * vY
            a_lat = side * (a_ref + k_v * (v_ref - v_lat) + k_p * (y_ref - offset))
            a_lat = min(max(a_lat, -g.a_y_max), g.a_y_max)
            speed = math.hypot(vX, vY)
            if vX > 1.0:  # d|v|/dt = k_v (v_des − |v|): v_X a_X + v_Y a_Y = |v| k_v (v_des − |v|)
                a_lon = (p.k_speed * (inp.v_des - speed) * speed - vY * a_lat) / vX
            else:  # crawling or turned across: plain speed control
                a_lon = p.k_speed * (inp.v_des - speed)
            a_lon = min(max(a_lon, -g.a_x_max), g.a_x_max)
            accel[k, 0], accel[k, 1] = a_lon, a_lat
            # eq. (skin), exact zero-order hold (x does not enter the law)
            y += ts * vY + 0.5 * ts * ts * a_lat
            vX += ts * a_lon
            vY += ts * a_lat
        predicted = kinematic_rollout(state, accel, ts)
        status: PlanStatus = "ok" if evasion is not None else "idle"
        return PlanResult(accel=accel, status=status, iterations=0, solve_time_s=time.perf_counter() - start,
                          cost=0.0, predicted=predicted)
