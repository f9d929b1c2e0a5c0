"""Weight function: bounds, monotonic factors, failure handling, convex blend, filter, shift."""
from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest

from moose.params import ParamError, VehicleParams
from moose.planner.fbl import FeedbackLinearization
from moose.planner.kinematics import kinematic_rollout
from moose.planner.logistic import logistic as sigma
from moose.planner.weight import WeightFunction
from moose.schema import FblParams, WeightParams
from moose.signals import Blend, Obstacle, PlanResult, StateEstimate, Threat
from moose.tire import peak_slip

VEHICLE = VehicleParams()
EST = StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0)


def wf(**changes: float) -> WeightFunction:
    return WeightFunction(WeightParams(**changes), FeedbackLinearization(FblParams(), VEHICLE, 0.2))


def plan(ay: float, status: str = "converged", ax: float = 0.0, v: float = 7.0) -> PlanResult:
    accel = np.tile([ax, ay], (10, 1))
    return PlanResult(accel, status, 5, 1e-3, 1.0, kinematic_rollout(np.array([0.0, 0.0, v, 0.0]), accel, 0.2))


def threat(tau: float = 3.0, nu: float = 0.3) -> Threat:
    return Threat(0.0, Obstacle(20.0, 22.0, -2.0, 2.0), tau, 2.0, nu, 1, 0.0)


def test_status_factor() -> None:
    f = wf()
    w = {s: f.weight(plan(0.5, s), threat(), EST)
         for s in ("converged", "capped", "failed", "over_budget", "ok", "barrier_violated")}
    assert w["converged"] > 0.9 and w["capped"] == pytest.approx(0.7 * w["converged"])
    assert w["failed"] == w["over_budget"] == w["ok"] == w["barrier_violated"] == 0.0
    nan = PlanResult(np.full((10, 2), np.nan), "converged", 3, 1e-3, 1.0, np.zeros((11, 4)))
    assert f.weight(nan, threat(), EST) == 0.0


def test_monotonic_in_steering_demand_tau_and_nu() -> None:
    f = wf()
    demand = [f.weight(plan(a), threat(), EST) for a in (0.5, 1.0, 2.0, 3.5, 5.0, 6.0)]
    assert all(a >= b for a, b in zip(demand, demand[1:])) and demand[0] > 0.9 and demand[-1] < 0.1
    taus = [f.weight(plan(0.5), threat(tau=t), EST) for t in (0.0, 0.5, 1.4, 1.6, 2.0, 4.0, math.inf)]
    assert all(a <= b for a, b in zip(taus, taus[1:])) and taus[0] < 0.01 and taus[-1] > 0.9
    assert taus[3] == pytest.approx(0.5 * taus[-1], rel=1e-3)  # tau_0 = 1.6 s: half
    nus = [f.weight(plan(0.5), threat(nu=n), EST) for n in (0.0, 0.2, 0.5, 0.7, 0.95, 1.2, math.inf)]
    assert all(a >= b for a, b in zip(nus, nus[1:])) and nus[0] > 0.9 and nus[-1] == 0.0
    assert nus[3] == pytest.approx(0.5 * nus[0], rel=0.01)  # nu_0 = 0.7: half
    assert all(0.0 <= w <= 1.0 for w in demand + taus + nus)


def test_steering_usage_of_the_first_steps() -> None:
    f = wf(n_rho=3)
    # straight ahead: no steering
    assert f.steering_usage(plan(0.0, ax=2.0), EST) == 0.0
    # later rows count: a plan that steers hard only in its second step is near the limits too
    accel = np.zeros((10, 2))
    accel[1, 1] = 6.0
    late = PlanResult(accel, "converged", 5, 1e-3, 1.0, kinematic_rollout(np.array([0.0, 0.0, 5.0, 0.0]), accel, 0.2))
    est5 = StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
    # 6 m/s² at 5 m/s needs 0.408 rad of kinematic steering (curvature a / v² = tan δ / L): beyond δ_max
    assert f.steering_usage(late, est5) > 1.3
    assert wf(n_rho=1).steering_usage(late, est5) == 0.0
    assert f.weight(late, threat(), est5) < 0.01 < wf(n_rho=1).weight(late, threat(), est5)
    # row 0 is the FBL's delta* (the paper's delta_MPC): 6 m/s^2 from straight running needs more front
    # force than mu F_zf, so the tyre inversion saturates at the peak slip angle
    assert wf(n_rho=1).steering_usage(plan(6.0), EST) == pytest.approx(peak_slip(VEHICLE.By, VEHICLE.Cy) / 0.3)


def test_blend_is_convex_and_failure_falls_back_to_msf() -> None:
    f = wf(smoothing=1.0)
    rng = np.random.default_rng(1)
    mpc = PlanResult(rng.uniform(-1, 1, (10, 2)), "converged", 5, 1e-3, 1.0,
                     kinematic_rollout(np.array([0, 0, 7.0, 0]), np.zeros((10, 2)), 0.2))
    msf = plan(3.0, "ok")
    blend = f.blend(mpc, msf, threat(), EST)
    assert 0.0 < blend.weight_mpc < 1.0
    np.testing.assert_allclose(blend.accel, blend.weight_mpc * mpc.accel + (1 - blend.weight_mpc) * msf.accel)
    lo, hi = np.minimum(mpc.accel, msf.accel), np.maximum(mpc.accel, msf.accel)
    assert np.all((blend.accel >= lo - 1e-12) & (blend.accel <= hi + 1e-12))
    nan_plan = PlanResult(np.full((10, 2), np.nan), "failed", 0, 0.0, math.inf, np.full((11, 4), np.nan))
    fallback = f.blend(nan_plan, msf, threat(), EST)
    assert fallback.weight_mpc == 0.0
    np.testing.assert_array_equal(fallback.accel, msf.accel)
    assert f.blend(mpc, msf, None, EST).weight_mpc == 0.0  # no threat: lane keeping is the MSF law


def test_weight_is_filtered_across_steps_and_drops_at_once_on_failure() -> None:
    f = wf(smoothing=0.5)
    msf = plan(3.0, "ok")
    raw = f.weight(plan(0.5), threat(), EST)
    w1 = f.blend(plan(0.5), msf, threat(), EST).weight_mpc
    assert w1 == pytest.approx(raw)  # the first blend has no history
    assert f.blend(plan(0.5, "failed"), msf, threat(), EST).weight_mpc == 0.0
    w3 = f.blend(plan(0.5), msf, threat(), EST).weight_mpc
    w4 = f.blend(plan(0.5), msf, threat(), EST).weight_mpc
    assert w3 == pytest.approx(0.5 * raw) and w4 == pytest.approx(0.75 * raw)
    f.reset()
    assert f.blend(plan(0.5), msf, threat(), EST).weight_mpc == pytest.approx(raw)


def test_next_initial_guess_shifts_by_one_step() -> None:
    accel = np.column_stack([np.arange(10.0), -np.arange(10.0)])
    guess = WeightFunction.next_initial_guess(Blend(0.5, accel))
    assert guess[:, 0].tolist() == [1, 2, 3, 4, 5, 6, 7, 8, 9, 9]
    assert guess[:, 1].tolist() == [-1, -2, -3, -4, -5, -6, -7, -8, -9, -9]
    assert guess.shape == accel.shape


def test_a_plan_through_the_barrier_is_weighted_by_its_own_factor() -> None:
    """Sec. IV: a solution the MPC "fails to provide" gives the MSF planner the weight; ``barrier_violated`` (the plan
    crosses y_safe) counts as that with ``barrier_violated_factor`` (0 by default: all of it to the MSF)."""
    converged = wf().weight(plan(0.5), threat(), EST)
    assert wf().weight(plan(0.5, "barrier_violated"), threat(), EST) == 0.0
    assert wf(barrier_violated_factor=0.4).weight(plan(0.5, "barrier_violated"), threat(), EST) == pytest.approx(
        0.4 * converged)
    f = wf()
    blend = f.blend(plan(0.5, "barrier_violated"), plan(-1.0, "ok"), threat(), EST)
    assert blend.weight_mpc == 0.0 and np.all(blend.accel[:, 1] == -1.0)


def test_the_first_step_is_read_as_rho_reading_says() -> None:
    """``fbl``: the FBL's δ* for the first acceleration at the current estimate (from straight running the front axle
    alone carries the force, so above (l_r / L) μ g = 3.3 m/s² at μ = 0.8 it needs the steering limit);
    ``kinematic``: L a_⊥ / v², as for the later steps."""
    first_only = plan(4.0)
    first_only.accel[1:] = 0.0
    assert wf(rho_reading="fbl", n_rho=1).steering_usage(first_only, EST) > 0.95  # the front tyre's peak slip
    kinematic = VEHICLE.wheelbase * 4.0 / 7.0**2 / VEHICLE.delta_max
    assert wf(rho_reading="kinematic", n_rho=1).steering_usage(first_only, EST) == pytest.approx(kinematic, rel=1e-12)
    assert wf(rho_reading="kinematic", n_rho=3).steering_usage(first_only, EST) == pytest.approx(kinematic, rel=1e-12)
    assert wf(rho_reading="kinematic").weight(first_only, threat(tau=50.0, nu=0.0), EST) > 0.9
    assert wf(rho_reading="fbl").weight(first_only, threat(tau=50.0, nu=0.0), EST) < 0.1


def test_tau_and_nu_are_read_as_nu_reading_says() -> None:
    """The same obstacle first at τ = 3 s, ν = 0.3 (detection), then at τ = 0.5 s, ν = 3 (the car is near it):
    ``current`` sees the latter, ``at_detection`` the former, ``remaining`` ν scaled by the displacement still
    needed (w − ỹ) / w, with T at the τ of detection."""
    p = WeightParams()
    detection, near = threat(tau=3.0, nu=0.3), threat(tau=0.5, nu=3.0)

    def reading(name: str, y: float) -> tuple[float, float]:
        f = wf(nu_reading=name)
        f.weight(plan(0.5), detection, EST)
        return f.threat_reading(near, StateEstimate(0.0, 14.0, y, 0.0, 7.0, 0.0, 0.0, 0.0))

    assert reading("current", 1.5) == (0.5, 3.0)
    assert reading("at_detection", 1.5) == (3.0, 0.3)
    assert reading("remaining", 1.5) == (3.0, pytest.approx(3.0 * 0.5 / 2.0))  # w = 2, ỹ = 1.5: a quarter left
    assert reading("remaining", 2.5) == (3.0, 0.0)  # beyond w: nothing left to do
    mirrored = Threat(0.0, Obstacle(20.0, 22.0, -2.0, 2.0), 0.5, 2.0, 3.0, -1, 0.0)
    f = wf(nu_reading="remaining")
    f.weight(plan(0.5), dataclasses.replace(mirrored, tau=3.0, nu=0.3), EST)
    assert f.threat_reading(mirrored, StateEstimate(0.0, 14.0, -1.5, 0.0, 7.0, 0.0, 0.0, 0.0))[1] == pytest.approx(
        0.75)  # ỹ is the offset toward the evasion side
    # the weight uses the reading: near the obstacle only at_detection and remaining leave the MPC a share
    for name, share in (("current", False), ("at_detection", True), ("remaining", True)):
        f = wf(nu_reading=name)
        f.weight(plan(0.5), detection, EST)
        w = f.weight(plan(0.5), near, StateEstimate(0.0, 14.0, 2.5, 0.0, 7.0, 0.0, 0.0, 0.0))
        assert (w > 0.5) == share, name
    # a new obstacle is a new detection; reset forgets it
    f = wf(nu_reading="at_detection")
    f.weight(plan(0.5), detection, EST)
    other = Threat(0.0, Obstacle(40.0, 42.0, -2.0, 2.0), 2.0, 2.0, 0.6, 1, 0.0)
    f.weight(plan(0.5), other, EST)
    assert f.threat_reading(dataclasses.replace(other, tau=0.1, nu=5.0), EST) == (2.0, 0.6)
    f.reset()
    assert f.threat_reading(near, EST) == (0.5, 3.0)
    assert p.nu_reading == "current" and p.rho_reading == "fbl"


@pytest.mark.parametrize("field, value", [("rho_0", -1.0), ("tau_slope", 0.0), ("capped_factor", 1.5),
                                          ("smoothing", 0.0), ("n_rho", 0), ("barrier_violated_factor", -0.1),
                                          ("rho_reading", "steady"), ("nu_reading", "latched")])
def test_bad_parameters_name_the_field(field: str, value: object) -> None:
    with pytest.raises(ParamError, match=field):
        WeightParams(**{field: value})


def test_steering_usage_is_the_steering_the_car_needs_for_the_planned_acceleration() -> None:
    """Independent reference: the plant itself.  Hold a small steering angle at 5 m/s, measure the steady lateral
    acceleration it gives, and scale (linear range): a plan asking for a_y in its second step must report the
    angle the car needs for it, |δ| / δ_max."""
    from moose.vehicle import VY, VehiclePlant, initial_state

    plant = VehiclePlant(VEHICLE)
    state = initial_state(VEHICLE, vx=5.0)
    state[-1] = 0.01  # δ
    plant.reset(state)
    plant.step(np.zeros(3), 4000)
    a_per_rad = plant.specific_force[1] / 0.01  # steady a_y per radian of steering at 5 m/s
    for a_y in (0.5, -0.8, 1.0):
        accel = np.zeros((10, 2))
        accel[1, 1] = a_y
        ahead = PlanResult(accel, "converged", 5, 1e-3, 1.0,
                           kinematic_rollout(np.array([0.0, 0.0, 5.0, 0.0]), np.zeros((10, 2)), 0.2))
        est5 = StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
        assert wf(n_rho=3).steering_usage(ahead, est5) == pytest.approx(abs(a_y) / a_per_rad / VEHICLE.delta_max,
                                                                        rel=0.02)
        assert abs(plant.state[VY]) < 0.1  # the steady state it was measured in


def logistic(z: float) -> float:
    return 1.0 / (1.0 + math.exp(-z))


def test_each_factor_is_the_logistic_function_of_its_scaled_distance() -> None:
    """Away from the half-points: T(τ₀ + s_τ) = 1 / (1 + e⁻¹), N(ν₀ + s_ν) = 1 / (1 + e), L likewise."""
    p = WeightParams()
    f = wf()
    base = f.weight(plan(0.0), threat(tau=50.0, nu=0.0), EST)  # straight on, τ far, ν = 0: the product of the tails
    expected = (logistic(p.rho_0 / p.rho_slope) * logistic((50.0 - p.tau_0) / p.tau_slope)
                * logistic(p.nu_0 / p.nu_slope))
    assert base == pytest.approx(expected, rel=1e-9)
    tau = f.weight(plan(0.0), threat(tau=p.tau_0 + p.tau_slope, nu=0.0), EST)
    assert tau / base == pytest.approx(logistic(1.0) / logistic((50.0 - p.tau_0) / p.tau_slope), rel=1e-9)
    nu = f.weight(plan(0.0), threat(tau=50.0, nu=p.nu_0 + 2 * p.nu_slope), EST)
    assert nu / base == pytest.approx(logistic(-2.0) / logistic(p.nu_0 / p.nu_slope), rel=1e-9)


def test_the_planners_one_logistic_is_overflow_free_and_the_same_on_floats_and_casadi() -> None:
    # the weight's rising factors and the MPC barrier's falling sigmoid σ(−a) = 1 / (1 + e^a) are this one function
    z_sym = ca.SX.sym("z")
    compiled = ca.Function("sigma", [z_sym], [sigma(z_sym, ca)])
    for z in (-30.0, -3.0, -0.5, 0.0, 0.5, 3.0, 30.0):
        assert sigma(z) == pytest.approx(logistic(z), abs=1e-15)  # the tanh form is exact to ~1e-16, not relative
        assert sigma(-z) == pytest.approx(1.0 - sigma(z), abs=1e-16)
        assert float(compiled(z)) == pytest.approx(sigma(z), rel=1e-15)
    assert sigma(-1e6) == 0.0 and sigma(1e6) == 1.0 and sigma(0.0) == 0.5  # e^z would overflow


def test_an_unknown_tau_or_nu_gives_the_mpc_no_weight() -> None:
    f = wf()
    assert f.weight(plan(0.5), threat(tau=math.nan), EST) == 0.0
    assert f.weight(plan(0.5), threat(nu=math.nan), EST) == 0.0
    assert f.weight(plan(0.5), threat(), EST) > 0.9


def test_no_mpc_plan_counts_as_a_failure_and_the_weight_restarts_from_zero() -> None:
    f = wf(smoothing=0.5)
    msf = plan(3.0, "ok")
    raw = f.weight(plan(0.5), threat(), EST)
    assert f.blend(plan(0.5), msf, threat(), EST).weight_mpc == pytest.approx(raw)
    missing = f.blend(None, msf, threat(), EST)
    assert missing.weight_mpc == 0.0 and np.array_equal(missing.accel, msf.accel)
    assert f.blend(plan(0.5), msf, threat(), EST).weight_mpc == pytest.approx(0.5 * raw)  # from 0, filtered


def test_the_msf_fallback_is_a_float_copy() -> None:
    f = wf()
    msf = PlanResult(np.tile([1, 2], (10, 1)), "ok", 0, 0.0, 0.0, np.zeros((11, 4)))  # an integer plan
    blend = f.blend(None, msf, threat(), EST)
    assert blend.accel.dtype == np.float64 and np.array_equal(blend.accel, msf.accel)
    floats = plan(3.0, "ok")
    copy = f.blend(None, floats, threat(), EST).accel
    copy[0, 0] = 99.0
    assert floats.accel[0, 0] == 0.0  # the blend does not alias the MSF plan


def rotated_plan(heading: float, speed: float, along: float, normal: float, n: int = 10) -> PlanResult:
    """A plan flying at ``heading`` with the accelerations ``along`` and ``normal`` to the velocity from row 1 on."""
    c, s = math.cos(heading), math.sin(heading)
    accel = np.zeros((n, 2))
    accel[1:] = [c * along - s * normal, s * along + c * normal]
    predicted = np.zeros((n + 1, 4))
    predicted[:, 2:] = [speed * c, speed * s]  # the velocity the plan predicts (held, for the check)
    return PlanResult(accel, "converged", 5, 1e-3, 1.0, predicted)


@pytest.mark.parametrize("heading", [0.0, math.pi / 4, 2.0, -math.pi / 2])
def test_steering_usage_takes_the_acceleration_normal_to_the_predicted_velocity(heading: float) -> None:
    """Curvature a_⊥ / v² = tan δ / L in the car's own frame: the same at any heading; the component along the
    velocity (braking, driving) needs no steering."""
    f = wf(n_rho=3)
    est = StateEstimate(0.0, 0.0, 0.0, heading, 5.0, 0.0, 0.0, 0.0)
    steering = f.steering_usage(rotated_plan(heading, 5.0, along=4.0, normal=1.5), est)
    assert steering == pytest.approx(VEHICLE.wheelbase * 1.5 / 25.0 / VEHICLE.delta_max, rel=1e-9)
    assert f.steering_usage(rotated_plan(heading, 5.0, along=-6.0, normal=0.0), est) == pytest.approx(0.0, abs=1e-12)


def test_steering_usage_at_a_crawl_and_at_rest() -> None:
    f = wf(n_rho=3)
    est = StateEstimate(0.0, 0.0, 0.0, math.pi / 2, 0.5, 0.0, 0.0, 0.0)
    # heading +y at 0.5 m/s: a global −x acceleration is a left turn; speeds below v_low count as v_low
    crawl = f.steering_usage(rotated_plan(math.pi / 2, 0.5, along=0.0, normal=2.0), est)
    assert crawl == pytest.approx(VEHICLE.wheelbase * 2.0 / VEHICLE.v_low**2 / VEHICLE.delta_max, rel=1e-9)
    rest = rotated_plan(0.0, 0.0, along=0.0, normal=0.0)
    rest.accel[1:] = [3.0, 0.5]  # no velocity to be normal to: the lateral (global y) acceleration counts
    usage = f.steering_usage(rest, StateEstimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert usage >= VEHICLE.wheelbase * 0.5 / VEHICLE.v_low**2 / VEHICLE.delta_max - 1e-12


def test_steering_usage_looks_at_most_at_the_plan_it_has() -> None:
    f = wf(n_rho=50)  # beyond the horizon: every row, no more
    p = rotated_plan(0.0, 5.0, along=0.0, normal=1.0)
    assert f.steering_usage(p, StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)) == pytest.approx(
        VEHICLE.wheelbase * 1.0 / 25.0 / VEHICLE.delta_max)


def test_the_first_step_counts_with_the_fbl_steering_not_the_kinematic_one() -> None:
    """Row 0 is the δ* the FBL computes (the paper's δ_MPC): at straight running (v_y = γ = 0) the rear tyre has no
    slip, so the front tyre alone gives the lateral force m a_y, and δ* is the slip angle at which Table I's magic
    formula F_yf = μ F_zf sin(C atan(B α)), F_zf = m g l_r / (l_f + l_r), gives it — less than the kinematic
    L a_y / v² of later rows at this speed.  The expected value is solved here from Table I, not asked of the FBL."""
    v, a_y = VEHICLE, 1.0
    first_only = plan(a_y)
    first_only.accel[1:] = 0.0
    mu_fzf = v.mu * v.m * v.g * v.lr / (v.lf + v.lr)
    alpha = math.tan(math.asin(v.m * a_y / mu_fzf) / v.Cy) / v.By
    assert mu_fzf * math.sin(v.Cy * math.atan(v.By * alpha)) == pytest.approx(v.m * a_y, rel=1e-12)
    expected = alpha / v.delta_max
    assert wf(n_rho=3).steering_usage(first_only, EST) == pytest.approx(expected, rel=1e-9)
    assert expected < VEHICLE.wheelbase * 1.0 / 7.0**2 / VEHICLE.delta_max  # the kinematic value would be larger


def test_remaining_reads_the_offset_from_the_ego_path_at_any_width() -> None:
    """``remaining``: ỹ is the offset from the ego path y_path (here y = 3 m, not 0); a narrow danger zone (w < 1 m)
    is read like any other; w = 0 (nothing to evade) reads ν = 0, not a division by zero."""
    f = wf(nu_reading="remaining")
    shifted = Threat(0.0, Obstacle(20.0, 22.0, 1.0, 5.0), 3.0, 2.0, 0.4, 1, 3.0)
    f.weight(plan(0.5), shifted, EST)
    at = StateEstimate(0.0, 14.0, 4.0, 0.0, 7.0, 0.0, 0.0, 0.0)  # 1 m toward the evasion side of the path
    assert f.threat_reading(shifted, at) == (3.0, pytest.approx(0.4 * (2.0 - 1.0) / 2.0))
    narrow = Threat(0.0, Obstacle(20.0, 22.0, -2.0, 0.8), 3.0, 0.8, 0.3, 1, 0.0)
    f = wf(nu_reading="remaining")
    f.weight(plan(0.5), narrow, EST)
    assert f.threat_reading(narrow, StateEstimate(0.0, 14.0, 0.2, 0.0, 7.0, 0.0, 0.0, 0.0)) == (
        3.0, pytest.approx(0.3 * 0.6 / 0.8))
    nothing = Threat(0.0, Obstacle(20.0, 22.0, -2.0, 0.0), 3.0, 0.0, 0.0, 1, 0.0)
    f = wf(nu_reading="remaining")
    f.weight(plan(0.5), nothing, EST)
    assert f.threat_reading(nothing, StateEstimate(0.0, 14.0, -0.5, 0.0, 7.0, 0.0, 0.0, 0.0)) == (3.0, 0.0)


def test_the_detection_is_latched_even_when_no_mpc_plan_came() -> None:
    """A blend without an MPC plan (a failed or late solve) still records the obstacle's detection: ``at_detection``
    then reads the τ and ν of that first instant, not of a later one."""
    f = wf(nu_reading="at_detection")
    f.blend(None, plan(0.5), threat(tau=3.0, nu=0.3), EST)
    assert f.threat_reading(threat(tau=0.5, nu=3.0), EST) == (3.0, 0.3)
