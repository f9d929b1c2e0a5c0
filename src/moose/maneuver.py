"""Maximum steering maneuver y_max(t, v_x), eq. (ymax), and the threat measures τ and ν, eq. (nudef).

y_max is the lateral position reached ``t`` seconds after steering as fast as
possible (δ(φ) = min(δ̇_max φ, δ_max)) at the constant speed v_x, without
braking, from straight running (v_y = θ = γ = 0).  It is integrated once on a
grid with the single-track dynamics of eq. (eomdyn), the Pacejka law eq. (fy)
and the slip angles eq. (alphas), and then interpolated bilinearly.

The paper does not state the friction its y_max used; ``ManeuverParams.mu_ymax``
is calibrated against the paper's own polynomial fit of Fig. 4 and the ν values
printed in Figs. 5–7 (docs/design.md, "y_max calibration").
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from .params import VehicleParams, check, positive
from .tire import pacejka


@dataclasses.dataclass(frozen=True)
class ManeuverParams:
    """Grid and friction of the y_max table."""

    mu_ymax: float = 0.3
    """Friction used for y_max (calibrated, see docs/design.md)."""
    t_max: float = 6.0
    """Longest tabulated time (s)."""
    dt_table: float = 0.01
    """Time resolution of the table (s)."""
    v_min: float = 0.5
    """Lowest tabulated speed (m/s)."""
    v_max: float = 12.0
    """Highest tabulated speed (m/s)."""
    dv_table: float = 0.25
    """Speed resolution of the table (m/s)."""
    dt_integration: float = 1e-3
    """RK4 step used to build the table (s)."""

    def __post_init__(self) -> None:
        for name in ("mu_ymax", "t_max", "dt_table", "v_min", "dv_table", "dt_integration"):
            check(name, getattr(self, name), positive, "a positive number")
        check("v_max", self.v_max, lambda v: v > self.v_min, f"a speed above v_min = {self.v_min}")
        check("dt_integration", self.dt_integration, lambda v: v <= self.dt_table, "at most dt_table")


def paper_y_max_fit(vx: float | np.ndarray, t: float | np.ndarray) -> float | np.ndarray:
    """The paper's polynomial fit of y_max (function ``yego(v, t)`` declared in the code of Fig. 4).

    Reference data only: first argument v_x (m/s), second t (s).  The fit goes
    negative near t = 0; it is meaningful for t ≳ 1 s.
    """
    v, y = vx, t
    return (
        -0.8001 + 0.4752 * v + 2.1603 * y - 0.0481 * v**2 - 1.1421 * v * y - 1.3265 * y**2
        + 0.0846 * v**2 * y + 0.6708 * v * y**2 + 0.2326 * y**3 - 0.0183 * v**2 * y**2
        - 0.0592 * v * y**3 - 0.0134 * y**4
    )


def integrate_y_max(vehicle: VehicleParams, mu: float, speeds: np.ndarray, t_max: float, dt: float,
                    every: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integrate eq. (ymax) for each speed at once with RK4.

    Returns (t, y, v_Y, a_Y), each row a time sample (every ``every`` steps),
    each column a speed; a_Y = v̇_Y is the global lateral acceleration.
    """
    v = np.asarray(speeds, dtype=float)
    p = vehicle
    fzf, fzr = mu * p.Fzf, mu * p.Fzr

    def f(t: float, s: np.ndarray) -> np.ndarray:
        vy, gamma, theta, _ = s
        delta = min(p.delta_rate_max * t, p.delta_max)
        alpha_f = delta - vy / v - p.lf * gamma / v
        alpha_r = p.lr * gamma / v - vy / v
        fyf = pacejka(alpha_f, fzf, p.By, p.Cy)
        fyr = pacejka(alpha_r, fzr, p.By, p.Cy)
        vy_dot = (fyf + fyr) / p.m - v * gamma  # eq. (dvynl)
        gamma_dot = (fyf * p.lf - fyr * p.lr) / p.Izz  # eq. (dgammanl)
        vY = v * np.sin(theta) + vy * np.cos(theta)
        return np.array([vy_dot, gamma_dot, gamma, vY])

    n = int(round(t_max / dt))
    s = np.zeros((4, v.size))
    ts, ys, vYs, aYs = [0.0], [s[3].copy()], [np.zeros_like(v)], []
    t = 0.0
    for i in range(n):
        k1 = f(t, s)
        if i % every == 0:
            aYs.append(_lateral_acceleration(k1, s, v))
        k2 = f(t + 0.5 * dt, s + 0.5 * dt * k1)
        k3 = f(t + 0.5 * dt, s + 0.5 * dt * k2)
        k4 = f(t + dt, s + dt * k3)
        s = s + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        t = (i + 1) * dt
        if (i + 1) % every == 0:
            ts.append(t)
            ys.append(s[3].copy())
            vYs.append(v * np.sin(s[2]) + s[0] * np.cos(s[2]))
    aYs.append(_lateral_acceleration(f(t, s), s, v))
    return np.array(ts), np.array(ys), np.array(vYs), np.array(aYs[: len(ts)])


def _lateral_acceleration(sdot: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v̇_Y = d/dt (v sin θ + v_y cos θ) at constant v."""
    vy, gamma, theta = s[0], s[1], s[2]
    return v * np.cos(theta) * gamma + sdot[0] * np.cos(theta) - vy * np.sin(theta) * gamma


class MaxSteeringTable:
    """y_max(t, v_x) and its time derivatives, tabulated and interpolated bilinearly."""

    def __init__(self, t: np.ndarray, v: np.ndarray, y: np.ndarray, vY: np.ndarray, aY: np.ndarray,
                 mu: float) -> None:
        self.t, self.v = t, v
        self._y, self._vY, self._aY = y, vY, aY
        self.mu = mu
        self._dt = float(t[1] - t[0])
        self._dv = float(v[1] - v[0])

    @classmethod
    def build(cls, vehicle: VehicleParams, params: ManeuverParams | None = None) -> "MaxSteeringTable":
        params = params or ManeuverParams()
        speeds = np.arange(params.v_min, params.v_max + 0.5 * params.dv_table, params.dv_table)
        every = int(round(params.dt_table / params.dt_integration))
        t, y, vY, aY = integrate_y_max(vehicle, params.mu_ymax, speeds, params.t_max, params.dt_integration, every)
        return cls(t, speeds, y, vY, aY, params.mu_ymax)

    def _lookup(self, grid: np.ndarray, t: float, vx: float) -> float:
        t = min(max(t, 0.0), float(self.t[-1]))
        vx = min(max(vx, float(self.v[0])), float(self.v[-1]))
        fi = t / self._dt
        fj = (vx - float(self.v[0])) / self._dv
        i = min(int(fi), len(self.t) - 2)
        j = min(int(fj), len(self.v) - 2)
        a, b = fi - i, fj - j
        return float(
            (1 - a) * ((1 - b) * grid[i, j] + b * grid[i, j + 1]) + a * ((1 - b) * grid[i + 1, j] + b * grid[i + 1, j + 1])
        )

    def y_max(self, t: float, vx: float) -> float:
        """eq. (ymax): lateral position of the maximum steering maneuver (m); t and v_x clamped to the grid."""
        return self._lookup(self._y, t, vx)

    def v_Y_max(self, t: float, vx: float) -> float:
        """Lateral velocity ẏ_max of the maneuver (m/s)."""
        return self._lookup(self._vY, t, vx)

    def a_Y_max(self, t: float, vx: float) -> float:
        """Lateral acceleration ÿ_max of the maneuver (m/s²)."""
        return self._lookup(self._aY, t, vx)


def time_to_collision(distance: float, vx: float) -> float:
    """τ = distance / v_x (s); infinite when the car is not closing in."""
    return distance / vx if vx > 1e-6 else math.inf


def lateral_steering_index(w: float, tau: float, vx: float, table: MaxSteeringTable) -> float:
    """eq. (nudef): ν = w / y_max(τ, v_x); infinite when no lateral motion is possible in time."""
    reach = table.y_max(max(tau, 0.0), vx)
    return w / reach if reach > 1e-9 else math.inf
