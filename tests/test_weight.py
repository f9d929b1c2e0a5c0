"""Weight function: bounds, monotonic factors, failure handling, convex blend, shift."""
from __future__ import annotations

import numpy as np
import pytest

from moose.params import VehicleParams
from moose.signals import Obstacle, PlanResult, StateEstimate, Threat
from moose.weight import WeightFunction, WeightParams

EST = StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0)
WF = WeightFunction(WeightParams(), VehicleParams())


def plan(ay: float, status: str = "converged") -> PlanResult:
    accel = np.tile([0.0, ay], (10, 1))
    return PlanResult(accel, status, 5, 1e-3, 1.0, np.zeros((11, 4)))


def threat(tau: float = 3.0, nu: float = 0.3) -> Threat:
    return Threat(0.0, Obstacle(20.0, 22.0, -2.0, 2.0), tau, 2.0, nu, 1, 0.0)


def test_status_factor() -> None:
    w = {s: WF.weight(plan(1.0, s), threat(), EST) for s in ("converged", "capped", "failed", "over_budget")}
    assert w["converged"] > w["capped"] > 0.0 and w["failed"] == w["over_budget"] == 0.0


def test_monotonic_in_steering_demand_tau_and_nu() -> None:
    demand = [WF.weight(plan(a), threat(), EST) for a in (0.5, 2.0, 3.5, 5.0, 6.0)]
    assert all(a >= b for a, b in zip(demand, demand[1:])) and demand[0] > 0.9 > 0.1 > demand[-1]
    taus = [WF.weight(plan(0.5), threat(tau=t), EST) for t in (0.5, 1.4, 2.0, 4.0)]
    assert all(a <= b for a, b in zip(taus, taus[1:]))
    nus = [WF.weight(plan(0.5), threat(nu=n), EST) for n in (0.2, 0.5, 0.8, 1.2)]
    assert all(a >= b for a, b in zip(nus, nus[1:]))
    assert all(0.0 <= w <= 1.0 for w in demand + taus + nus)


def test_blend_is_convex_and_failure_falls_back_to_msf() -> None:
    mpc, msf = plan(1.0), plan(3.0)
    blend = WF.blend(mpc, msf, threat(), EST)
    np.testing.assert_allclose(blend.accel, blend.weight_mpc * mpc.accel + (1 - blend.weight_mpc) * msf.accel)
    nan_plan = PlanResult(np.full((10, 2), np.nan), "failed", 0, 0.0, np.inf, np.zeros((11, 4)))
    fallback = WF.blend(nan_plan, msf, threat(), EST)
    assert fallback.weight_mpc == 0.0
    np.testing.assert_array_equal(fallback.accel, msf.accel)
    assert WF.blend(mpc, msf, None, EST).weight_mpc == 0.0  # lane keeping is the MSF law


def test_next_initial_guess_shifts_by_one_step() -> None:
    blend = WF.blend(plan(1.0), plan(3.0), threat(), EST)
    accel = blend.accel.copy()
    accel[:, 0] = np.arange(10)
    from moose.signals import Blend
    guess = WF.next_initial_guess(Blend(0.5, accel))
    assert guess[:, 0].tolist() == [1, 2, 3, 4, 5, 6, 7, 8, 9, 9]


@pytest.mark.parametrize("field", ["rho_0", "tau_slope"])
def test_bad_parameters_name_the_field(field: str) -> None:
    from moose.params import ParamError
    with pytest.raises(ParamError, match=field):
        WeightParams(**{field: -1.0})
