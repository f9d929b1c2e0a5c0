"""Weight function (Sec. IV): the situation-assessment unit that blends the MPC and MSF references.

The paper states its inputs (MPC status and solve time, nearness of the MPC
solution to the steering limits, τ and ν) but no formula.  Ours is a product
of smooth factors in [0, 1]:

    w_MPC = s(status) · L(ρ) · T(τ) · N(ν),
    L(ρ) = σ((ρ₀ − ρ)/s_ρ),  T(τ) = σ((τ − τ₀)/s_τ),  N(ν) = σ((ν₀ − ν)/s_ν),  σ(z) = 1/(1 + e^(−z)),

where s(status) is 1 for a converged solve, ``capped_factor`` for an
iteration-capped one and 0 for a failed or late one; ρ = |δ*|/δ_max is the
steering the FBL would command for the MPC's first acceleration (its tyre
inversion saturates at the peak slip, so ρ → 1 also flags friction-limited
demands).  With no threat the weight is 0: outside an emergency the reference
is the MSF planner's lane-keeping law (the MPC's barrier problem has nothing
to avoid, and its iteration-capped lane-keeping solutions only add noise).  The blend
[v̇_X*, v̇_Y*] = w_MPC·MPC + (1 − w_MPC)·MSF is applied row by row over the
horizon; shifted by one step it is the MPC's next initial guess (Fig. 3).
Capped solutions of a 10-iteration solver jump between planning steps, so a
usable MPC's weight is low-pass filtered across steps (``smoothing``); a failed
or late solve still drops to 0 at once.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional

import numpy as np

from .fbl import FblParams, FeedbackLinearization
from .params import VehicleParams, check, positive, unit_interval
from .signals import Blend, PlanResult, StateEstimate, Threat


@dataclasses.dataclass(frozen=True)
class WeightParams:
    """Thresholds (value at which a factor is ½) and slopes of the weight function."""

    capped_factor: float = 0.7
    rho_0: float = 0.85
    rho_slope: float = 0.05
    tau_0: float = 1.6
    tau_slope: float = 0.2
    nu_0: float = 0.7
    nu_slope: float = 0.08
    smoothing: float = 0.5
    """Share of the new value in the first-order filter of w_MPC across planning steps (1: no filter)."""

    def __post_init__(self) -> None:
        check("capped_factor", self.capped_factor, unit_interval, "a factor in [0, 1]")
        check("smoothing", self.smoothing, lambda v: 0.0 < v <= 1.0, "a share in (0, 1]")
        for name in ("rho_0", "rho_slope", "tau_0", "tau_slope", "nu_0", "nu_slope"):
            check(name, getattr(self, name), positive, "a positive number")


STATUS_FACTOR_ZERO = ("failed", "over_budget")


def _sigma(z: float) -> float:
    return 0.5 * (1.0 + math.tanh(0.5 * z))


class WeightFunction:
    """Blends MPC and MSF accelerations and produces the MPC's next initial guess."""

    def __init__(self, params: WeightParams, vehicle: VehicleParams) -> None:
        self.params = params
        self.vehicle = vehicle
        self._fbl = FeedbackLinearization(FblParams(), vehicle)
        self._previous: Optional[float] = None

    def reset(self) -> None:
        self._previous = None

    def weight(self, mpc: PlanResult, threat: Optional[Threat], estimate: StateEstimate) -> float:
        """w_MPC in [0, 1]."""
        p = self.params
        if threat is None or mpc.status in STATUS_FACTOR_ZERO or not np.all(np.isfinite(mpc.accel)):
            return 0.0
        status = p.capped_factor if mpc.status == "capped" else 1.0
        rho = abs(self._fbl.reference(mpc.accel[0], estimate).delta) / self.vehicle.delta_max
        w = status * _sigma((p.rho_0 - rho) / p.rho_slope)
        w *= _sigma((threat.tau - p.tau_0) / p.tau_slope) if math.isfinite(threat.tau) else 1.0
        w *= _sigma((p.nu_0 - threat.nu) / p.nu_slope) if math.isfinite(threat.nu) else 0.0
        return float(min(max(w, 0.0), 1.0))

    def blend(self, mpc: PlanResult, msf: PlanResult, threat: Optional[Threat], estimate: StateEstimate) -> Blend:
        w = self.weight(mpc, threat, estimate)
        if w > 0.0 and self._previous is not None:
            # a usable MPC solution's share changes gradually; a failed one drops out at once
            w = self._previous + self.params.smoothing * (w - self._previous)
        self._previous = w
        mpc_accel = np.nan_to_num(mpc.accel) if w > 0.0 else np.zeros_like(msf.accel)
        return Blend(weight_mpc=w, accel=w * mpc_accel + (1.0 - w) * msf.accel)

    @staticmethod
    def next_initial_guess(blend: Blend) -> np.ndarray:
        """The blend shifted by one planning step, its last row repeated."""
        return np.vstack([blend.accel[1:], blend.accel[-1:]])
