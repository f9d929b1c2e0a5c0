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
  ``barrier_violated_factor`` for a plan whose predicted path crosses y_safe
  (status ``barrier_violated``: the paper's "fails to provide a solution"),
  0 for a failed or late (over budget) one or non-finite accelerations;
* ρ = max_k |δ_k| / δ_max over the first ``n_rho`` steps of the MPC's plan:
  δ_k (k ≥ 1) is the kinematic steering L a_⊥,k / v_k² for the acceleration
  normal to the MPC's predicted velocity; δ_0 is read as ``rho_reading`` says:
  ``fbl``, the FBL's δ* for the MPC's first acceleration at the current
  estimate (the paper's δ_MPC; its tyre inversion saturates at the peak slip,
  so ρ → 1 also flags friction-limited demands, and from straight running the
  front axle alone carries the force: ρ = 1 above (l_r / L) μ g), or
  ``kinematic``, the kinematic steering of the first acceleration too;
* short τ and ν → 1 (little time, little steering reserve) shift the weight to
  the MSF planner, the maneuver built for that case.  Which τ and ν
  (``nu_reading``): ``current``, the detector's now; ``at_detection``, those of
  the threat as first reported for this obstacle; ``remaining``,
  ν_rem = ν (w − ỹ)⁺ / w — the displacement still needed over y_max of the time
  left (ν = w / y_max(τ, v) now, ỹ the offset toward the evasion side) — with
  T at the τ of detection, so that the time left is not counted twice.

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
from .logistic import logistic

STATUS_FACTOR = {"converged": 1.0}
"""S(status) for statuses other than ``capped`` (which uses ``capped_factor``); every other status gives 0."""


class WeightFunction:
    """Blends MPC and MSF accelerations and produces the MPC's next initial guess."""

    def __init__(self, params: WeightParams, fbl: FeedbackLinearization) -> None:
        self.params = params
        self.vehicle = fbl.vehicle
        self._fbl = fbl
        """The configured FBL: ρ uses the δ* it computes for the MPC's first acceleration."""
        self._previous: Optional[float] = None
        self._detected: Optional[Threat] = None
        """The threat as first reported for the current obstacle (``nu_reading``: ``at_detection``, ``remaining``)."""

    def reset(self) -> None:
        self._previous = None
        self._detected = None

    def status_factor(self, mpc: PlanResult) -> float:
        """S: 1 converged, ``capped_factor`` capped, ``barrier_violated_factor`` barrier violated, 0 failed, over
        budget, non-finite or anything else."""
        if not np.all(np.isfinite(mpc.accel)):
            return 0.0
        if mpc.status == "capped":
            return self.params.capped_factor
        if mpc.status == "barrier_violated":
            return self.params.barrier_violated_factor
        return STATUS_FACTOR.get(mpc.status, 0.0)

    def steering_usage(self, mpc: PlanResult, estimate: StateEstimate) -> float:
        """ρ: the largest |δ| / δ_max the MPC's first ``n_rho`` accelerations need (the first as ``rho_reading``
        says)."""
        v = self.vehicle
        first = 1
        if self.params.rho_reading == "fbl":
            rho = abs(self._fbl.steering(mpc.accel[0], estimate)) / v.delta_max
        else:
            rho, first = 0.0, 0
        n = min(self.params.n_rho, len(mpc.accel), len(mpc.predicted))
        for k in range(first, n):
            vX, vY = float(mpc.predicted[k, 2]), float(mpc.predicted[k, 3])
            speed = math.hypot(vX, vY)
            if not math.isfinite(speed):
                return math.inf
            a_normal = (vX * mpc.accel[k, 1] - vY * mpc.accel[k, 0]) / speed if speed > 1e-9 else mpc.accel[k, 1]
            delta = v.wheelbase * abs(a_normal) / max(speed, v.v_low) ** 2  # kinematic: curvature = tan δ / L
            rho = max(rho, delta / v.delta_max)
        return rho

    def _latch(self, threat: Optional[Threat]) -> None:
        """Remember the first threat of each obstacle (the detection)."""
        if threat is not None and (self._detected is None or self._detected.obstacle != threat.obstacle):
            self._detected = threat

    def threat_reading(self, threat: Threat, estimate: StateEstimate) -> tuple[float, float]:
        """(τ, ν) that T and N see, as ``nu_reading`` says (the threat of detection is latched per obstacle by
        :meth:`weight`)."""
        reading = self.params.nu_reading
        if reading == "current":
            return threat.tau, threat.nu
        detected = self._detected if self._detected is not None else threat
        if reading == "at_detection":
            return detected.tau, detected.nu
        needed = threat.w - threat.side * (estimate.y - threat.y_path)  # w − ỹ
        return detected.tau, (threat.nu * needed / threat.w if needed > 0.0 and threat.w > 0.0 else 0.0)

    def weight(self, mpc: PlanResult, threat: Optional[Threat], estimate: StateEstimate) -> float:
        """Unfiltered w_MPC in [0, 1]."""
        p = self.params
        self._latch(threat)
        status = self.status_factor(mpc)
        if threat is None or status == 0.0:
            return 0.0
        tau, nu = self.threat_reading(threat, estimate)
        w = status * logistic((p.rho_0 - self.steering_usage(mpc, estimate)) / p.rho_slope)
        w *= logistic((tau - p.tau_0) / p.tau_slope) if not math.isnan(tau) else 0.0
        w *= logistic((p.nu_0 - nu) / p.nu_slope) if not math.isnan(nu) else 0.0
        return float(min(max(w, 0.0), 1.0))

    def blend(self, mpc: Optional[PlanResult], msf: PlanResult, threat: Optional[Threat],
              estimate: StateEstimate) -> Blend:
        """Filtered w_MPC and the row-wise convex combination of the two acceleration sequences.

        ``mpc`` None (no MPC plan in time) counts as a failed solve: weight 0 at once."""
        self._latch(threat)
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
