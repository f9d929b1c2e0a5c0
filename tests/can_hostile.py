"""Hypothesis strategies for hostile input to the CAN bridge: wild values, clock steps, valid-but-hostile
configurations."""
from __future__ import annotations

from hypothesis import strategies as st

from moose.canbus.safety import GuardParams
from moose.params import VEHICLE_LIMITS
from moose.schema import MinimumRiskParams

DT = 0.01

wild = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e3, 1e3),
                 st.sampled_from([0.0, 0.3, -0.3]), st.integers(-10**400, 10**400),
                 st.sampled_from([True, None, "0.1", 1e308]))
"""Anything a command field or a measurement could be: NaN, ±inf, huge, integers beyond a float, non-numbers."""

clock_step = st.one_of(st.just(DT), st.floats(0.0, 0.03), st.sampled_from([1.0, -5.0, 0.0, 1e9, -1e9, float("nan")]))
"""The caller's clock between two calls: the command period, jitter, a stop, steps of +1 s / -5 s, absurd jumps, NaN."""


@st.composite
def hostile_guard_params(draw: st.DrawFn, timeout_min: float = 0.02) -> GuardParams:
    """Any guard configuration that passes validation (limits anywhere in (0, hard limit])."""

    def share(bound: float) -> float:
        return draw(st.floats(1e-6, 1.0)) * bound

    return GuardParams(
        delta_max=share(VEHICLE_LIMITS.delta_max), steer_rate_limit=share(VEHICLE_LIMITS.delta_rate_max),
        torque_max=share(VEHICLE_LIMITS.T_max), torque_rate_limit=share(VEHICLE_LIMITS.torque_rate_max),
        timeout=draw(st.floats(timeout_min, 0.05)), maneuver=MinimumRiskParams(
            brake_fraction=draw(st.floats(1e-6, 1.0)), brake_gain=draw(st.floats(1e-6, 1e9)),
            stop_speed=draw(st.floats(1e-6, 1e3)), stop_time=draw(st.floats(1e-6, 10.0)),
            eps_gain=draw(st.floats(1e-6, 1e9))))
