"""The parameter schema: every block's parameters as frozen dataclasses (SI units, paper defaults).

This module is light on purpose (no CasADi, no planners): reading a parameter file builds a
:class:`Config` with :func:`moose.params.build`, which refuses unknown keys, wrong types and
out-of-range values with an error naming the field and the value.  Facts that several blocks
share are declared once here and derived, never repeated:

* the **planning grid** N_p, t_s (:class:`PlanningParams`); the planning rate is 1 / t_s, and the
  motion-control period must divide t_s;
* the **planning μ** (:attr:`Config.mu_planning`): the friction every block of the stack assumes —
  the maneuver table (y_max and so ν), the FBL's tyre inversion, the observer's model, the MPC's ε
  and the planners' acceleration bounds.  It equals the road's μ (``vehicle.mu``, the plant's)
  unless ``planning.mu_estimate`` sets a deliberate mismatch;
* the **acceleration bounds** of both planners (:attr:`Config.grid`), from the vehicle and the
  planning μ (:meth:`moose.params.VehicleParams.longitudinal_accel_limit`, ``lateral_accel_limit``);
* the vehicle's hard limits (:data:`moose.params.VEHICLE_LIMITS`).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from typing import Literal, get_args

from .params import ParamError, VehicleParams, check, non_negative, positive, replace, unit_interval


def _within(low: float, high: float, value: float) -> bool:
    return low <= value <= high


def _positive_finite(value: object) -> bool:
    """A real number (not a bool) in (0, ∞)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and 0.0 < float(value) < math.inf


def _divides(period: float, step: float) -> bool:
    """Whether ``period`` is a whole, positive number of ``step``s (to round-off)."""
    ratio = period / step
    return abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1


@dataclasses.dataclass(frozen=True)
class PlanningParams:
    """The planning grid both planners, the weight function and the FBL share, and the planning μ."""

    N_p: int = 10
    """Prediction horizon (steps) of the MPC and the MSF planner (the paper does not give it)."""
    t_s: float = 0.2
    """Planning sampling time (s), Table I; the planners run every t_s (the MicroLabBox's 5 Hz)."""
    mu_estimate: float = 0.0
    """Friction the stack assumes; 0 (the default) means the road's μ, ``vehicle.mu``.  A positive
    value is a deliberate mismatch between the car's belief and the road (robustness experiments,
    ``--mu-estimate``)."""

    def __post_init__(self) -> None:
        check("N_p", self.N_p, lambda v: isinstance(v, int) and 1 <= v <= 100, "an integer in [1, 100]")
        check("t_s", self.t_s, lambda v: 0.01 <= v <= 2.0, "a sampling time in [0.01, 2] s")
        check("mu_estimate", self.mu_estimate, lambda v: v == 0.0 or 0.05 <= v <= 1.5,
              "0 (the road's μ) or a friction coefficient in [0.05, 1.5]")


@dataclasses.dataclass(frozen=True)
class PlanningGrid:
    """What both planners share, derived once from the configuration (:attr:`Config.grid`)."""

    N_p: int
    """Prediction horizon (steps)."""
    t_s: float
    """Planning sampling time (s)."""
    a_x_max: float
    """Bound of v̇_X (m/s²): what the rear motors and the rear tyres can give at the planning μ."""
    a_y_max: float
    """Bound of v̇_Y (m/s²): μ g at the planning μ."""
    mu: float
    """The planning μ (ε of eq. (ysafe))."""

SolverName = Literal["projected_newton", "sqp_lbfgs", "sqp_exact", "ipopt", "paper_sqp"]
"""The MPC's solver (:mod:`moose.planner.mpc.solver`; docs/modelling.md, "MPC"): ``projected_newton``: exact
Hessian, compiled C (the default); ``sqp_lbfgs``: CasADi's sqpmethod with a BFGS Hessian;
``sqp_exact``: sqpmethod with the exact Hessian, regularised to be positive definite; ``ipopt``:
interior point (a reference); ``paper_sqp``: the paper's baseline, fmincon's SQP algorithm with
finite-difference gradients, every evaluation counted against Table II's cap."""
SOLVERS: tuple[SolverName, ...] = ("projected_newton", "sqp_lbfgs", "sqp_exact", "ipopt", "paper_sqp")

QpSolverName = Literal["qrqp", "qpoases"]
"""QP solver of ``sqpmethod`` (the other solvers ignore it)."""

BarrierName = Literal["paper", "clipped"]
"""``paper``: J_safe = −log d, which keeps rewarding distance from y_safe; ``clipped``: 0 beyond a clearance."""

SpeedFloor = Literal["penalty", "constraint"]
"""How v_X ≥ 0 enters the NLP."""


@dataclasses.dataclass(frozen=True)
class SolverCaps:
    """Stopping criteria of the NLP solver (Table II of the paper)."""

    max_iter: int = 10
    """Maximum number of SQP iterations."""
    max_fun_evals: int = 100
    """Maximum number of cost evaluations (``projected_newton``: enough for every Newton search through
    ``MpcParams.max_iter_ls``, its projected-gradient fallback may reach it; ``paper_sqp``: every evaluation counted,
    finite differences included)."""
    constraint_tol: float = 1e-3
    """Primal infeasibility tolerance."""
    optimality_tol: float = 1e-3
    """Tolerance on the inf-norm of the gradient of the Lagrangian."""
    step_tol: float = 1e-3
    """Stop when the inf-norm of the step (normalised inputs) falls below this."""

    def __post_init__(self) -> None:
        check("max_iter", self.max_iter, lambda v: isinstance(v, int) and v >= 1, "an integer ≥ 1")
        check("max_fun_evals", self.max_fun_evals, lambda v: isinstance(v, int) and v > self.max_iter,
              "an integer above max_iter")
        for name in ("constraint_tol", "optimality_tol", "step_tol"):
            check(name, getattr(self, name), positive, "a positive tolerance")


PAPER_CAPS = SolverCaps()
"""Table II: 10 iterations, 100 function evaluations, tolerances 1e-3."""


@dataclasses.dataclass(frozen=True)
class MpcParams:
    """MPC planner parameters (paper defaults where the paper gives them)."""

    eta: tuple[float, float, float, float] = (0.5, 0.25, 0.05, 0.2)
    """Weights η of J_safe, J_stable, J_brake, J_steer, eq. (jcaldef) (Example 2's second set)."""
    eta_return: float = 0.1
    """Weight of the lane-keeping term η_return |ỹ| (not in the paper)."""
    barrier_margin: float = 0.3
    """d₀ (m): below it the barrier is continued by its second-order Taylor polynomial."""
    barrier: BarrierName = "paper"
    """J_safe's shape (:func:`j_safe`): ``paper`` −log d, or ``clipped`` at ``barrier_clearance``."""
    barrier_clearance: float = 1.0
    """c (m): clearance above y_safe beyond which the ``clipped`` J_safe is 0."""
    pass_margin: float = 1.0
    """Distance past the obstacle's far edge where J_safe has fallen to half (m); it falls over a
    quarter of this (2 % left at the far edge)."""
    reverse_penalty: float = 100.0
    """Weight of min(v_X, 0)² when ``speed_floor`` is ``penalty``."""
    caps: SolverCaps = PAPER_CAPS
    """Stopping criteria (Table II)."""
    max_iter_ls: int = 8
    """Backtracking steps per iteration (each evaluates the cost once) of ``projected_newton`` and
    the sqpmethod solvers; ``paper_sqp`` backtracks as fmincon does, within the evaluation cap."""
    ls_beta: float = 0.3
    """Line-search backtracking factor of ``projected_newton`` and the sqpmethod solvers (0.5 left
    line searches without decrease on the benchmark's problems with ``projected_newton``);
    ``paper_sqp`` halves the step."""
    active_set_tol: float = 0.1
    """ε of ``projected_newton``'s ε-active set (normalised inputs): an input this close to its bound,
    the gradient pushing outward, is held there for the Newton step."""
    time_budget_s: float = 0.2
    """Wall-clock budget of one plan (s), one planning period; above it the status is ``over_budget``."""
    solver: SolverName = "projected_newton"
    """NLP solver (docs/modelling.md, "MPC": chosen by bench/bench_mpc.py)."""
    qpsol: QpSolverName = "qrqp"
    """QP solver of ``sqpmethod``."""
    speed_floor: SpeedFloor = "penalty"
    """How v_X ≥ 0 enters the NLP; the returned plan is projected onto v_X ≥ 0 either way.
    ``constraint`` (linear constraints on the inputs) needs sqpmethod with ``qpsol = qpoases``, or IPOPT."""
    v_reg: float = 0.5
    """Speed regularising |v_Y / v_X| and √(w v_X²) at v_X → 0 (m/s)."""
    abs_eps: float = 0.05
    """Smoothing of |·|: √(x² + abs_eps²) − abs_eps."""

    def __post_init__(self) -> None:
        for name in ("barrier_margin", "pass_margin", "time_budget_s",
                     "v_reg", "abs_eps", "active_set_tol"):
            check(name, getattr(self, name), positive, "a positive number")
        for name in ("eta_return", "reverse_penalty"):
            check(name, getattr(self, name), non_negative, "a non-negative number")
        check("barrier", self.barrier, lambda v: v in ("paper", "clipped"), "paper or clipped")
        check("barrier_clearance", self.barrier_clearance, lambda v: v > self.barrier_margin,
              "a clearance above barrier_margin")
        check("eta", self.eta, lambda e: len(e) == 4 and all(0.0 <= v <= 1.0 for v in e) and abs(sum(e) - 1.0) < 1e-9,
              "a convex combination: four weights in [0, 1] summing to 1")
        check("ls_beta", self.ls_beta, lambda v: 0.0 < v < 1.0, "a factor in (0, 1)")
        check("solver", self.solver, lambda v: v in SOLVERS, "one of " + ", ".join(SOLVERS))
        check("qpsol", self.qpsol, lambda v: v in ("qrqp", "qpoases"), "qrqp or qpoases")
        check("speed_floor", self.speed_floor, lambda v: v in ("penalty", "constraint"), "penalty or constraint")
        check("speed_floor", self.speed_floor,
              lambda v: v == "penalty" or self.solver == "ipopt"
              or (self.solver.startswith("sqp") and self.qpsol == "qpoases"),
              "penalty with projected_newton or paper_sqp (bounds only) or with qrqp (qrqp stalls on the linear "
              "speed constraints: 220 ms measured); constraint needs an sqp solver with qpsol = qpoases, or "
              "solver = ipopt")
        check("max_iter_ls", self.max_iter_ls,
              lambda v: isinstance(v, int) and v >= 0 and self.caps.max_iter * (1 + v) + 1 <= self.caps.max_fun_evals,
              "an integer ≥ 0 with max_iter (1 + max_iter_ls) + 1 ≤ caps.max_fun_evals "
              "(a line search evaluates the cost at most 1 + max_iter_ls times)")


MsfProfile = Literal["scurve", "nu_scaled"]
"""The MSF planner's evasion reference (docs/modelling.md, "MSF planner"): ``scurve``, the maximum steering maneuver
scaled to arrive at w + m by the near edge, then mirrored (the counter-steer before the obstacle); ``nu_scaled``,
ν y_max(t) with ν of the target w + m (eq. (nudef)), arriving there at τ, the counter-steer from the near edge on."""
MSF_PROFILES: tuple[MsfProfile, ...] = get_args(MsfProfile)


@dataclasses.dataclass(frozen=True)
class MsfParams:
    """MSF planner parameters."""

    profile: MsfProfile = "nu_scaled"
    """The evasion reference (:data:`MsfProfile`)."""
    margin: float = 0.5
    """Lateral margin m beyond the far edge (m): the S-curve's target is w + m."""
    reach_fraction: float = 1.0
    """f: a scaled S-curve arrives at w + m, moving straight again, after this fraction of τ."""
    omega_track: float = 0.7
    """Natural frequency of the law tracking the evasion and return S-curves (rad/s)."""
    omega_lane: float = 1.0
    """Natural frequency of lane keeping (rad/s)."""
    return_share: float = 0.3
    """Peak lateral acceleration of the return S-curve as a share of μ g."""
    k_speed: float = 0.5
    """Speed-tracking gain k_v (1/s)."""

    def __post_init__(self) -> None:
        for name in ("omega_track", "omega_lane", "k_speed"):
            check(name, getattr(self, name), positive, "a positive number")
        check("profile", self.profile, lambda v: v in MSF_PROFILES, " or ".join(MSF_PROFILES))
        check("margin", self.margin, non_negative, "a non-negative distance (m)")
        check("reach_fraction", self.reach_fraction, lambda v: 0.0 < v <= 1.0, "a fraction in (0, 1]")
        check("return_share", self.return_share, lambda v: 0.0 < v <= 1.0, "a share in (0, 1]")


RhoReading = Literal["fbl", "kinematic"]
"""How the weight function reads the steering the MPC's first acceleration needs (ρ, docs/modelling.md, "Weight
function"): ``fbl``, the FBL's δ* at the current estimate (the front axle alone carries the lateral force until
yaw builds); ``kinematic``, L a_⊥ / v², the steering of a car already turning (as for the later steps)."""
RHO_READINGS: tuple[RhoReading, ...] = get_args(RhoReading)

NuReading = Literal["current", "at_detection", "remaining"]
"""Which threat the factors T(τ) and N(ν) see: ``current``, the detector's τ and ν now (w latched at detection);
``at_detection``, τ and ν as the obstacle was detected; ``remaining``, ν of the lateral displacement still needed
(w − ỹ) over y_max of the time left, with T at the τ of detection (the time left is in that ν)."""
NU_READINGS: tuple[NuReading, ...] = get_args(NuReading)


@dataclasses.dataclass(frozen=True)
class WeightParams:
    """Thresholds (where a factor is ½) and slopes of the weight function, and its readings of what the paper
    leaves open."""

    capped_factor: float = 0.7
    """S for an iteration-capped MPC solution."""
    barrier_violated_factor: float = 0.0
    """S for a plan whose predicted path crosses the barrier y_safe (status ``barrier_violated``): the paper's
    "fails to provide a solution" gives the MSF planner the weight."""
    rho_reading: RhoReading = "fbl"
    """How ρ reads the steering of the MPC's first acceleration (:data:`RhoReading`)."""
    nu_reading: NuReading = "current"
    """Which τ and ν the factors T and N see (:data:`NuReading`)."""
    rho_0: float = 0.85
    """Steering-limit usage ρ at which L = ½."""
    rho_slope: float = 0.05
    tau_0: float = 1.6
    """Time to collision at which T = ½ (s)."""
    tau_slope: float = 0.2
    """(s)"""
    nu_0: float = 0.7
    """Lateral steering index at which N = ½."""
    nu_slope: float = 0.08
    smoothing: float = 0.5
    """Share of the new value in the first-order filter of w_MPC across planning steps (1: no filter)."""
    n_rho: int = 3
    """Steps of the MPC's plan whose steering demand enters ρ (≥ 1; 1: δ_MPC only)."""

    def __post_init__(self) -> None:
        check("capped_factor", self.capped_factor, unit_interval, "a factor in [0, 1]")
        check("barrier_violated_factor", self.barrier_violated_factor, unit_interval, "a factor in [0, 1]")
        check("rho_reading", self.rho_reading, lambda v: v in RHO_READINGS, " or ".join(RHO_READINGS))
        check("nu_reading", self.nu_reading, lambda v: v in NU_READINGS, ", ".join(NU_READINGS))
        check("smoothing", self.smoothing, lambda v: 0.0 < v <= 1.0, "a share in (0, 1]")
        for name in ("rho_0", "rho_slope", "tau_0", "tau_slope", "nu_0", "nu_slope"):
            check(name, getattr(self, name), positive, "a positive number")
        check("n_rho", self.n_rho, lambda v: isinstance(v, int) and v >= 1, "an integer of at least 1")


@dataclasses.dataclass(frozen=True)
class FblParams:
    """FBL parameters."""

    v_min_ref: float = 0.0
    """Lowest speed reference (m/s): the car never reverses."""

    def __post_init__(self) -> None:
        check("v_min_ref", self.v_min_ref, non_negative, "a non-negative speed (m/s)")


@dataclasses.dataclass(frozen=True)
class DetectorParams:
    """Detector parameters."""

    pass_margin: float = 2.0
    """Distance past the zone's far end x_max after which the threat is cleared (m)."""
    range_m: float = 80.0
    """Perception range ahead of the CoG (m)."""
    side_tie: float = 0.25
    """Displacements to either side closer than this count as a tie: evade left (m)."""
    lateral_margin: float = 0.0
    """A zone whose lateral extent is within this distance of the ego path is in the path (m)."""

    def __post_init__(self) -> None:
        check("pass_margin", self.pass_margin, non_negative, "a non-negative distance (m)")
        check("range_m", self.range_m, positive, "a positive distance (m)")
        check("side_tie", self.side_tie, non_negative, "a non-negative distance (m)")
        check("lateral_margin", self.lateral_margin, non_negative, "a non-negative distance (m)")


@dataclasses.dataclass(frozen=True)
class ObserverParams:
    """Noise model (SI units, standard deviations), history length and the optional μ estimation."""

    q_position: float = 0.05
    q_yaw: float = 0.002
    q_vx: float = 0.3
    q_vy: float = 0.3
    q_yaw_rate: float = 0.3
    """Process noise densities (per √s) of x/y, θ, v_x, v_y, γ."""
    r_yaw_rate: float = 0.003
    r_lateral_accel: float = 0.3
    """IMU a_y against the model: sensor noise plus tyre-model error (m/s²)."""
    r_wheel_speed: float = 0.1
    r_gps_position: float = 0.03
    r_gps_velocity: float = 0.05
    history_s: float = 1.5
    """How far back a late GPS fix can be fused (s)."""
    replay_late_gps: bool = True
    """Fuse a late GPS fix at its measurement time and replay the samples since (exact); False fuses it on
    arrival as if it were current, as a filter without a history does (Observation 2 is measured both ways)."""
    estimate_mu: bool = False
    """Augment the state with μ (random walk, started at the planning μ) instead of trusting it."""
    q_mu: float = 0.02
    """Process noise density of μ (per √s), used with ``estimate_mu``."""
    mu_std0: float = 0.2
    """Initial standard deviation of μ, used with ``estimate_mu``."""
    mu_min: float = 0.1
    mu_max: float = 1.2
    """Range the estimated μ is kept in."""

    def __post_init__(self) -> None:
        for name in ("q_position", "q_yaw", "q_vx", "q_vy", "q_yaw_rate", "r_yaw_rate", "r_lateral_accel",
                     "r_wheel_speed", "r_gps_position", "r_gps_velocity", "history_s", "q_mu", "mu_std0",
                     "mu_min", "mu_max"):
            check(name, getattr(self, name), positive, "a positive number")
        if not self.mu_min < self.mu_max:
            raise ParamError(f"mu_min = {self.mu_min!r} is invalid: expected below mu_max = {self.mu_max!r}")


@dataclasses.dataclass(frozen=True)
class SensorParams:
    """Rates (Hz), GPS lag (s) and noise standard deviations (SI units); see the module docstring."""

    imu_rate_hz: float = 100.0
    wheel_rate_hz: float = 100.0
    eps_rate_hz: float = 100.0
    gps_rate_hz: float = 1.0
    """Paper, Sec. V: GPS updated at 1 Hz."""
    gps_lag_s: float = 0.2
    """Delay between a GPS fix and its delivery (s)."""
    accel_std: float = 0.05
    """Accelerometer noise, each axis (m/s^2)."""
    gyro_std: float = 0.002
    """Yaw-rate gyro noise (rad/s)."""
    wheel_std: float = 0.05
    """Wheel-speed noise, each wheel (rad/s)."""
    eps_std: float = 0.001
    """Steering-angle noise (rad)."""
    gps_pos_std: float = 0.02
    """GPS position noise, each axis (m)."""
    gps_vel_std: float = 0.03
    """GPS velocity noise, each axis (m/s)."""

    def __post_init__(self) -> None:
        for name in ("imu_rate_hz", "wheel_rate_hz", "eps_rate_hz", "gps_rate_hz"):
            check(name, getattr(self, name), positive, "a positive rate (Hz)")
        for name in ("gps_lag_s", "accel_std", "gyro_std", "wheel_std", "eps_std", "gps_pos_std", "gps_vel_std"):
            check(name, getattr(self, name), non_negative, "a non-negative number")


@dataclasses.dataclass(frozen=True)
class MotionParams:
    """Motion-controller parameters."""

    pole: float = 1.0
    """ω_c (rad/s): both closed-loop poles of the speed loop at −ω_c (paper: −1 rad/s)."""
    slip_nominal: float = 0.05
    """λ_n of the nominal plant P_n(s) (paper: 0.05)."""
    t_ramp: float = 0.2
    """Duration of the reference ramp to each new v_x* (s): the planning period t_s."""
    feed_forward: bool = True
    """Ramp the reference and feed the nominal plant's inverse forward (C_v,ff); False leaves the bare PI."""
    accel_margin: float = 1.0
    """Share of T_max the feed-forward ramp may ask for (1: the full torque; below 1 leaves feedback headroom)."""
    k_delta: float = 20.0
    """EPS feedback gain K_δ (1/s)."""

    def __post_init__(self) -> None:
        for name in ("pole", "t_ramp", "k_delta"):
            check(name, getattr(self, name), positive, "a positive number")
        check("slip_nominal", self.slip_nominal, lambda v: 0.0 <= v < 1.0, "a slip ratio in [0, 1)")
        check("accel_margin", self.accel_margin, lambda v: unit_interval(v) and v > 0.0, "a share in (0, 1]")


@dataclasses.dataclass(frozen=True)
class MinimumRiskBounds:
    """Hard bounds of the minimum-risk maneuver's parameters, ``(low, high)`` inclusive (``low`` 0: any positive
    value): constants of the fallback, not configuration, as :data:`moose.params.VEHICLE_LIMITS` are the car's.

    A parameter file may choose a value within them, never outside: outside, the fallback would be disarmed
    (no braking, no steering back, a "stop" declared at speed) or would ask more than the 10 ms command loop
    (config/kanon.dbc's command cycle T) can follow.  docs/vehicle-bus.md, "Command guard", derives each bound from
    Table I (m = 925 kg, r = 0.301 m, J_wr = 1.24 kg m², T_max = 200 N m) and measures its effect."""

    brake_fraction: tuple[float, float] = (0.8, 1.0)
    """T_brake / T_max: at 0.8 the stop from 7 m/s takes 22 m instead of 18 m; lower, every metre more along
    the heading at the loss carries the car further sideways."""
    brake_gain: tuple[float, float] = (100.0, 1000.0)
    """k_ω (N m s/rad): the time constant τ = (m r² + 2 J_wr) / (2 k_ω) of the braking near standstill is at most
    0.43 s (k_ω ≥ 100: full torque down to T_max / k_ω = 2 rad/s, 0.6 m/s, and from there to a stop in about two τ)
    and at least 4 command periods (k_ω ≤ 1000: T/τ ≤ 1/4, so the braking on one period old wheel speeds neither
    oscillates nor reverses the car)."""
    stop_speed: tuple[float, float] = (0.0, 0.3)
    """|ω̄| (rad/s) that counts as stopped: at most 0.09 m/s at Table I's r, where releasing the torque leaves a
    car that rolling resistance stops within centimetres (our plant has none: it keeps that speed)."""
    stop_time: tuple[float, float] = (0.1, 1.0)
    """s within ``stop_speed`` before the torque is released: at least 10 command periods, so that a dip of the
    wheel speeds (a wheel locking for a moment, noise) cannot end the braking for good; at most 1 s, so that the
    stop is reported."""
    eps_gain: tuple[float, float] = (10.0, 25.0)
    """K_δ (1/s): at 10 the wheels are straight from full lock within 0.5 s; at most K_δ T = 1/4, so the EPS loop
    on one period old angles does not overshoot through straight ahead."""
    straight_tolerance: tuple[float, float] = (0.0, 0.01)
    """|δ| (rad) that counts as straight: a wheel left at 0.01 rad turns the car by d · 0.01 / (l_f + l_r), 0.1 rad
    over the 18 m stop from 7 m/s."""

    def weakest(self) -> dict[str, float]:
        """The most permissive values the bounds accept: the least braking (lowest T_brake and k_ω), the earliest
        release (highest stop speed, shortest stop time) and the laziest steering back (lowest K_δ, widest
        tolerance)."""
        return {"brake_fraction": self.brake_fraction[0], "brake_gain": self.brake_gain[0],
                "stop_speed": self.stop_speed[1], "stop_time": self.stop_time[0], "eps_gain": self.eps_gain[0],
                "straight_tolerance": self.straight_tolerance[1]}


MINIMUM_RISK_BOUNDS = MinimumRiskBounds()
"""The bounds every :class:`MinimumRiskParams` is held to."""


@dataclasses.dataclass(frozen=True)
class MinimumRiskParams:
    """The minimum-risk maneuver (:mod:`moose.minimum_risk`): steer back to straight, brake to a stop.

    One set for every place that runs it: the CAN bridge's guard, the motion controller, the simulator's
    topic-side vehicle I/O.  Every value lies within :data:`MINIMUM_RISK_BOUNDS`: configuration cannot disarm
    the fallback."""

    brake_fraction: float = 1.0
    """T_brake as a share of T_max: the largest braking torque per rear motor."""
    brake_gain: float = 150.0
    """k_ω (N m per rad/s of mean rear wheel speed).  Below T_brake the car slows exponentially with the
    time constant m r² / (2 k_ω) ≈ 0.28 s (Table I's m and r)."""
    stop_speed: float = 0.1
    """|ω̄| (rad/s) at or below which the car counts as stopped (0.03 m/s at r = 0.301 m)."""
    stop_time: float = 0.2
    """How long ω̄ must stay within ``stop_speed`` before the braking torque is released (s)."""
    eps_gain: float = MotionParams().k_delta
    """K_δ (1/s) of the steering-back loop: the motion controller's FB-EPS gain."""
    straight_tolerance: float = 0.005
    """|δ_meas| (rad) within which the steering counts as straight and the EPS rests (rate 0) instead of
    chasing the angle sensor's noise (0.3°, five times its standard deviation in ``SensorParams``)."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            check(f.name, value, _positive_finite, "a positive finite number")
            low, high = getattr(MINIMUM_RISK_BOUNDS, f.name)
            bound = (f"a value in [{low:g}, {high:g}], the hard bounds" if low > 0
                     else f"at most {high:g}, the hard bound")
            check(f.name, value, functools.partial(_within, low, high),
                  f"{bound} of the minimum-risk maneuver (configuration cannot disarm it)")


@dataclasses.dataclass(frozen=True)
class ManeuverParams:
    """Grid of the y_max table (its friction is the planning μ, :attr:`Config.mu_planning`).

    Interpolation error of the default grid (10 ms × 0.125 m/s) in y_max at μ = 0.3, measured
    against direct integration at off-grid points over 0.6–12 m/s (``tests/test_maneuver.py``):
    < 0.4 mm for t < 3 s, < 0.03 % for t ∈ [0.5, 5) s, < 8 mm up to 6 s (where the low-friction
    maneuver spins the car and y_max bends sharply in v_x around 4 m/s).  With the steering
    rate limited (δ̇_max = 1 rad/s) the kinematic similarity the interpolation uses is no longer
    exact, and 0.25 m/s steps give 9 mm and 17 cm there; building the finer table takes about
    0.4 s per planning μ.
    """

    t_max: float = 6.0
    """Longest time answered (s); later times are clamped."""
    dt_table: float = 0.01
    """Time resolution of the table (s)."""
    v_min: float = 0.5
    """Lowest tabulated speed (m/s)."""
    v_max: float = 12.0
    """Highest tabulated speed (m/s)."""
    dv_table: float = 0.125
    """Speed resolution of the table (m/s)."""
    dt_integration: float = 1e-3
    """RK4 step used to build the table (s)."""

    def __post_init__(self) -> None:
        for name in ("t_max", "dt_table", "v_min", "dv_table"):
            check(name, getattr(self, name), positive, "a positive number")
        check("dt_integration", self.dt_integration, lambda v: 0.0 < v <= 1e-3, "an RK4 step in (0, 1e-3] s")
        check("v_max", self.v_max, lambda v: v > self.v_min, f"a speed above v_min = {self.v_min}")
        check("dt_table", self.dt_table, lambda v: _divides(v, self.dt_integration),
              f"a multiple of dt_integration = {self.dt_integration}")
        check("t_max", self.t_max, lambda v: v >= 2 * self.dt_table, f"at least two table steps of {self.dt_table} s")


PlannerMode = Literal["combined", "mpc", "msf", "aeb", "max_steer"]
PLANNER_MODES: tuple[str, ...] = get_args(PlannerMode)
"""The planner modes, for command-line choices."""


@dataclasses.dataclass(frozen=True)
class VerdictParams:
    """Thresholds of :func:`moose.verdict.judge` (on the true state)."""

    sideslip_max: float = 0.35
    """|β| above which control is lost (rad): 20°, far beyond the few degrees a car keeps in an
    emergency maneuver it still steers (production stability control intervenes well below)."""
    sideslip_speed_min: float = 2.0
    """β is judged only above this speed (m/s): at a crawl atan2(v_y, v_x) is meaningless."""
    heading_max: float = 1.5707963267948966
    """|θ| above which control is lost (rad): the car points across the road (π/2)."""
    max_gap: float = 0.2
    """Longest stretch without a state sample (s) for a run to count as complete."""

    def __post_init__(self) -> None:
        for name in ("sideslip_max", "sideslip_speed_min", "heading_max", "max_gap"):
            check(name, getattr(self, name), positive, "a positive number")


@dataclasses.dataclass(frozen=True)
class SimulationParams:
    """Rates of the lockstep closed loop (Fig. 3)."""

    plant_dt: float = 1e-3
    """Plant integration step (s): 1 kHz."""
    motion_rate_hz: float = 100.0
    """Motion control, observer and detector rate (Hz)."""
    planner: PlannerMode = "combined"
    """Which planner drives the car: the paper's blend, MPC alone, MSF alone, or a baseline (``aeb``: emergency
    braking; ``max_steer``: full lock; :mod:`moose.planner.baseline`)."""
    steering_fbl_at_motion_rate: bool = True
    """Re-evaluate the FBL's δ* at the motion-control rate on the held planned acceleration."""

    def __post_init__(self) -> None:
        check("plant_dt", self.plant_dt, lambda v: 1e-5 <= v <= 1e-2, "a step in [1e-5, 1e-2] s")
        check("motion_rate_hz", self.motion_rate_hz, positive, "a positive rate (Hz)")
        if not _divides(1.0 / self.motion_rate_hz, self.plant_dt):
            raise ParamError(f"motion_rate_hz = {self.motion_rate_hz!r} is invalid: its period must be a multiple "
                             f"of plant_dt = {self.plant_dt!r}")

    @property
    def plant_steps_per_motion(self) -> int:
        return round(1.0 / (self.plant_dt * self.motion_rate_hz))


def _car(name: str) -> float:
    """A delay of the ``car`` profile (:func:`moose.car_chain.car_chain`: config/kanon.dbc, read when first needed)."""
    from .car_chain import car_chain  # the DBC's parser (cantools) only where a default is taken

    return float(getattr(car_chain(), name))


@dataclasses.dataclass(frozen=True)
class TimingParams:
    """The car's latency chain (s): what the lockstep loop and the node graph delay, and whether the stack
    compensates it (:mod:`moose.timing`; docs/architecture.md, "Closed loop and rates").

    Each delay is a whole number of motion-control periods (checked by :class:`Config`).  The defaults are the
    ``car`` profile (:func:`moose.timing.profile`): the FPEV2-Kanon's chain, from the CAN periods of
    config/kanon.dbc and the planning computer's solve time (docs/architecture.md, "Closed loop and rates": why
    ``car``); ``ideal`` is all zero."""

    sensor_delay_s: float = dataclasses.field(default_factory=lambda: _car("sensor_delay_s"))
    """d_s: a sample handed over by the sensors at t reaches the observer at t + d_s (stamped t)."""
    planning_delay_s: float = dataclasses.field(default_factory=lambda: _car("planning_delay_s"))
    """d_p: the plan of the instant t acts from t + d_p (the previous plan until then); also the simulated
    compute time the MPC's ``time_budget_s`` is checked against in lockstep."""
    command_delay_s: float = dataclasses.field(default_factory=lambda: _car("command_delay_s"))
    """d_c: a command computed at t acts on the actuators from t + d_c (CAN frame period and phase included)."""
    compensate: bool = False
    """The planners and the FBL predict the state forward over the known latency before they plan or command."""

    def __post_init__(self) -> None:
        for name in ("sensor_delay_s", "planning_delay_s", "command_delay_s"):
            check(name, getattr(self, name), lambda v: 0.0 <= v <= 2.0, "a delay in [0, 2] s")
        check("compensate", self.compensate, lambda v: isinstance(v, bool), "true or false")


@dataclasses.dataclass(frozen=True)
class Config:
    """Every block's parameters."""

    vehicle: VehicleParams = VehicleParams()
    sensors: SensorParams = SensorParams()
    observer: ObserverParams = ObserverParams()
    detector: DetectorParams = DetectorParams()
    maneuver: ManeuverParams = ManeuverParams()
    planning: PlanningParams = PlanningParams()
    mpc: MpcParams = MpcParams()
    msf: MsfParams = MsfParams()
    weight: WeightParams = WeightParams()
    fbl: FblParams = FblParams()
    motion: MotionParams = MotionParams()
    minimum_risk: MinimumRiskParams = MinimumRiskParams()
    simulation: SimulationParams = SimulationParams()
    verdict: VerdictParams = VerdictParams()
    timing: TimingParams = dataclasses.field(default_factory=TimingParams)

    def __post_init__(self) -> None:
        motion_period = 1.0 / self.simulation.motion_rate_hz
        if not _divides(self.planning.t_s, motion_period):
            raise ParamError(f"planning.t_s = {self.planning.t_s!r} is invalid: expected a multiple of the "
                             f"motion-control period 1 / simulation.motion_rate_hz = {motion_period!r} s")
        for name in ("sensor_delay_s", "planning_delay_s", "command_delay_s"):
            value = getattr(self.timing, name)
            if not (value == 0.0 or _divides(value, motion_period)):
                raise ParamError(f"timing.{name} = {value!r} is invalid: expected a whole number of motion-control "
                                 f"periods 1 / simulation.motion_rate_hz = {motion_period!r} s (the resolution of "
                                 "every delay)")

    @property
    def mu_planning(self) -> float:
        """The friction the whole stack assumes: ``planning.mu_estimate`` if set, else the road's ``vehicle.mu``."""
        return self.planning.mu_estimate if self.planning.mu_estimate > 0.0 else self.vehicle.mu

    @property
    def model_vehicle(self) -> VehicleParams:
        """The vehicle as the stack believes it: ``vehicle`` with the planning μ (observer, detector's
        maneuver table, planners, FBL).  The plant uses :attr:`vehicle`."""
        return replace(self.vehicle, mu=self.mu_planning)

    @property
    def grid(self) -> PlanningGrid:
        """The planning grid and the acceleration bounds of both planners."""
        model = self.model_vehicle
        return PlanningGrid(self.planning.N_p, self.planning.t_s, model.longitudinal_accel_limit,
                            model.lateral_accel_limit, model.mu)

    @property
    def planning_rate_hz(self) -> float:
        """The planning rate 1 / t_s (Hz)."""
        return 1.0 / self.planning.t_s

    @property
    def motion_period(self) -> float:
        """The motion-control period 1 / ``simulation.motion_rate_hz`` (s): the tick of the lockstep loop and the
        resolution of every delay of ``timing``."""
        return 1.0 / self.simulation.motion_rate_hz

    @property
    def motion_steps_per_plan(self) -> int:
        """Motion-control ticks per planning period."""
        return round(self.planning.t_s * self.simulation.motion_rate_hz)
