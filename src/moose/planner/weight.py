"""Weight function (Sec. IV): the situation-assessment unit that blends the MPC and MSF references.

The paper names its inputs (the MPC's outcome and timing, the nearness of the
MPC solution to the steering limits, τ and ν) and its behaviour ("in cases
where the solution of the MPC planner is close to the steering limits or if it
fails to provide a solution in time, the weight function assigns a higher
weight to the MSF solution"), but no formula.  Ours is a product of smooth
factors in [0, 1]:

    w_MPC = S(status) · L(ρ) · T(τ) · N(ν),   σ(z) = 1 / (1 + e^(−z)),
    L(ρ) = σ((ρ₀ − ρ)/s_ρ),  T(τ) = σ((τ − τ₀)/s_τ),  N(ν) = σ((ν₀ − ν)/s_ν),

* S = 1 for a converged solve, ``capped_factor`` for an iteration-capped one,
  0 for a failed or late (over budget) one or non-finite accelerations;
* ρ = max_k |δ_k| / δ_max over the first ``n_rho`` steps of the MPC's plan:
  δ_0 is the FBL's δ* for the MPC's first acceleration at the current estimate
  (the paper's δ_MPC; its tyre inversion saturates at the peak slip, so ρ → 1
  also flags friction-limited demands), δ_k (k ≥ 1) the kinematic steering
  L a_⊥,k / v_k² for the acceleration normal to the MPC's predicted velocity;
* short τ and ν → 1 (little time, little steering reserve) shift the weight to
  the MSF planner, the maneuver built for that case.

With no threat the weight is 0: outside an emergency the reference is the MSF
planner's lane-keeping law (the MPC's barrier problem has nothing to avoid,
and its iteration-capped lane-keeping solutions only add noise).  The blend
[v̇_X*, v̇_Y*] = w_MPC·MPC + (1 − w_MPC)·MSF is applied row by row over the
horizon; shifted by one step it is the MPC's next initial guess (Fig. 3).
Capped solutions of a 10-iteration solver jump between planning steps, so a
usable MPC's weight is low-pass filtered across steps (``smoothing``, the share
of the new value); a failed or late solve, or no threat, drops it to 0 at once.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from ..schema import WeightParams
from ..signals import Blend, PlanResult, StateEstimate, Threat
from .fbl import FeedbackLinearization

STATUS_FACTOR = {"converged": 1.0}
"""S(status) for statuses other than ``capped`` (which uses ``capped_factor``); every other status gives 0."""


def _sigma(z: float) -> float:
    """Logistic function, overflow-free."""
    return 0.5 * (1.0 + math.tanh(0.5 * z))


class WeightFunction:
    """Blends MPC and MSF accelerations and produces the MPC's next initial guess."""

    def __init__(self, params: WeightParams, fbl: FeedbackLinearization) -> None:
        self.params = params
        self.vehicle = fbl.vehicle
        self._fbl = fbl
        """The configured FBL: ρ uses the δ* it computes for the MPC's first acceleration."""
        self._previous: Optional[float] = None

    def reset(self) -> None:
        self._previous = None

    def status_factor(self, mpc: PlanResult) -> float:
        """S: 1 converged, ``capped_factor`` capped, 0 failed, over budget, non-finite or anything else."""
        if not np.all(np.isfinite(mpc.accel)):
            return 0.0
        if mpc.status == "capped":
            return self.params.capped_factor
        return STATUS_FACTOR.get(mpc.status, 0.0)

    def steering_usage(self, mpc: PlanResult, estimate: StateEstimate) -> float:
        """ρ: the largest |δ| / δ_max the MPC's first ``n_rho`` accelerations need."""
        v = self.vehicle
        rho = abs(self._fbl.steering(mpc.accel[0], estimate)) / v.delta_max
        n = min(self.params.n_rho, len(mpc.accel), len(mpc.predicted))
        for k in range(1, n):
            vX, vY = float(mpc.predicted[k, 2]), float(mpc.predicted[k, 3])
            speed = math.hypot(vX, vY)
            if not math.isfinite(speed):
                return math.inf
            a_normal = (vX * mpc.accel[k, 1] - vY * mpc.accel[k, 0]) / speed if speed > 1e-9 else mpc.accel[k, 1]
            delta = v.wheelbase * abs(a_normal) / max(speed, v.v_low) ** 2  # kinematic: curvature = tan δ / L
            rho = max(rho, delta / v.delta_max)
        return rho

    def weight(self, mpc: PlanResult, threat: Optional[Threat], estimate: StateEstimate) -> float:
        """Unfiltered w_MPC in [0, 1]."""
        p = self.params
        status = self.status_factor(mpc)
        if threat is None or status == 0.0:
            return 0.0
        w = status * _sigma((p.rho_0 - self.steering_usage(mpc, estimate)) / p.rho_slope)
        w *= _sigma((threat.tau - p.tau_0) / p.tau_slope) if not math.isnan(threat.tau) else 0.0
        w *= _sigma((p.nu_0 - threat.nu) / p.nu_slope) if not math.isnan(threat.nu) else 0.0
        return float(min(max(w, 0.0), 1.0))

    def blend(self, mpc: Optional[PlanResult], msf: PlanResult, threat: Optional[Threat],
              estimate: StateEstimate) -> Blend:
        """Filtered w_MPC and the row-wise convex combination of the two acceleration sequences.

        ``mpc`` None (no MPC plan in time) counts as a failed solve: weight 0 at once."""
        w = self.weight(mpc, threat, estimate) if mpc is not None else 0.0
        if w > 0.0 and self._previous is not None:
            # a usable MPC solution's share changes gradually; a failed one drops out at once
            w = self._previous + self.params.smoothing * (w - self._previous)
        self._previous = w
        if w == 0.0 or mpc is None:
            return Blend(weight_mpc=0.0, accel=np.array(msf.accel, dtype=float, copy=True))
        return Blend(weight_mpc=w, accel=w * mpc.accel + (1.0 - w) * msf.accel)

    @staticmethod
    def next_initial_guess(blend: Blend) -> np.ndarray:
        """The blend shifted by one planning step, its last row repeated."""
        return np.vstack([blend.accel[1:], blend.accel[-1:]])
