"""Hypothesis strategies for hostile input to the CAN bridge: wild values, clock steps, valid-but-hostile
configurations."""
from __future__ import annotations

import dataclasses

from hypothesis import strategies as st

from moose.canbus.safety import GuardParams
from moose.params import VEHICLE_LIMITS
from moose.schema import MINIMUM_RISK_BOUNDS, MinimumRiskParams

DT = 0.01

wild = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e3, 1e3),
                 st.sampled_from([0.0, 0.3, -0.3]), st.integers(-10**400, 10**400),
                 st.sampled_from([True, None, "0.1", 1e308]))
"""Anything a command field or a measurement could be: NaN, ±inf, huge, integers beyond a float, non-numbers."""

clock_step = st.one_of(st.just(DT), st.floats(0.0, 0.03), st.sampled_from([1.0, -5.0, 0.0, 1e9, -1e9, float("nan")]))
"""The caller's clock between two calls: the command period, jitter, a stop, steps of +1 s / -5 s, absurd jumps, NaN."""


@st.composite
def hostile_guard_params(draw: st.DrawFn, timeout_min: float = 0.02) -> GuardParams:
    """Any guard configuration that passes validation (limits anywhere in (0, hard limit], the maneuver anywhere
    within its hard bounds)."""

    def share(bound: float) -> float:
        return draw(st.floats(1e-6, 1.0)) * bound

    return GuardParams(
        delta_max=share(VEHICLE_LIMITS.delta_max), steer_rate_limit=share(VEHICLE_LIMITS.delta_rate_max),
        torque_max=share(VEHICLE_LIMITS.T_max), torque_rate_limit=share(VEHICLE_LIMITS.torque_rate_max),
        timeout=draw(st.floats(timeout_min, 0.05)), maneuver=MinimumRiskParams(**{
            f.name: draw(st.floats(max(low, 1e-6), high))
            for f in dataclasses.fields(MinimumRiskParams)
            for low, high in [getattr(MINIMUM_RISK_BOUNDS, f.name)]}))
