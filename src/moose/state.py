"""The layout of the plant's state and input vectors, by name (no CasADi: graph nodes read them too).

State X = [x, y, θ, v_x, v_y, γ, ω_rl, ω_rr, δ]: global position and yaw, eq. (trajdef); body velocities
and yaw rate, eq. (eom); rear wheel speeds; steering angle.  Input U = [δ̇_cmd, T_rl, T_rr]: the EPS motor's
rate command and the rear in-wheel motor torques.  The observer's state x̂ = [x, y, θ, v_x, v_y, γ] is the
first :data:`N_MOTION` entries of X, in the same order.  Every module that indexes one of these vectors
uses these names.
"""
from __future__ import annotations

STATE_NAMES = ("x", "y", "theta", "vx", "vy", "gamma", "omega_rl", "omega_rr", "delta")
"""The entries of X, as the closed loop's trace names its columns (:data:`moose.simulation.TRACE_FIELDS`)."""
X, Y, THETA, VX, VY, GAMMA, OMEGA_RL, OMEGA_RR, DELTA = range(len(STATE_NAMES))
"""Indices of the plant state vector X."""
N_STATE = len(STATE_NAMES)
N_MOTION = GAMMA + 1
"""Entries X … GAMMA: the rigid-body motion, which the observer's state shares."""
INPUT_NAMES = ("u_delta_rate", "u_T_rl", "u_T_rr")
"""The entries of U, as the trace names its columns."""
STEER_RATE, TORQUE_RL, TORQUE_RR = range(len(INPUT_NAMES))
"""Indices of the plant input vector U."""
N_INPUT = len(INPUT_NAMES)
