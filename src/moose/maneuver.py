"""Maximum steering maneuver y_max(t, v_x), eq. (ymax), and the threat measures τ and ν, eq. (nudef).

y_max is the lateral position reached ``t`` seconds after steering as fast as
possible, δ(φ) = min(δ̇_max φ, δ_max), at the constant speed v_x, without
braking, from straight running (v_y = θ = γ = 0).  It is integrated once with
RK4 on a grid of speeds using the single-track dynamics eq. (eomdyn) (v̇_x = 0
imposed), the Pacejka law eq. (fy) and the slip angles eq. (alphas); then it is
interpolated bilinearly.  The table also holds ẏ_max = v_Y and ÿ_max = v̇_Y
(the global lateral velocity and acceleration of the maneuver), and the
running maximum max_{φ ≤ t} y_max(φ) used for ν (see
:func:`lateral_steering_index`).  Interpolation between speeds uses the
kinematic similarity of slow cornering (see :class:`MaxSteeringTable`), which
also extends the table below its lowest speed down to y_max(t, 0) = 0.

The paper does not state the friction its y_max used; ``ManeuverParams.mu_ymax``
is calibrated against the paper's polynomial fit of Fig. 4 and the ν printed
in Figs. 5–7 (:data:`PAPER_EXPERIMENTS`, :func:`calibration_errors`).
"""
from __future__ import annotations

import dataclasses
import math
from types import ModuleType
from typing import Any, NamedTuple, Sequence, Union

import casadi as ca
import numpy as np

from .params import VehicleParams, check, positive
from .tire import pacejka

ArrayLike = Union[float, np.ndarray]

_EPS_V = 1e-9


@dataclasses.dataclass(frozen=True)
class ManeuverParams:
    """Friction and grid of the y_max table.

    Interpolation error of the default grid (10 ms × 0.25 m/s) in y_max,
    measured against direct integration at off-grid points over 0.5–12 m/s:
    < 7 mm for t < 3 s, < 0.6 % for t ∈ [0.5, 5) s, 1.6 % beyond (where the
    low-friction maneuver spins the car and y_max bends sharply in v_x around
    4–5 m/s).  The time step hardly matters (10 → 50 ms changes nothing
    visible); 0.125 m/s steps give < 2.2 mm and 0.15 %, 0.5 m/s steps four
    times the error.
    """

    mu_ymax: float = 0.3
    """Friction used for y_max: calibrated against the paper's fit and ν values."""
    t_max: float = 6.0
    """Longest time answered (s); later times are clamped."""
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
        check("mu_ymax", self.mu_ymax, lambda v: 0.0 < v <= 2.0, "a friction coefficient in (0, 2]")
        for name in ("t_max", "dt_table", "v_min", "dv_table"):
            check(name, getattr(self, name), positive, "a positive number")
        check("dt_integration", self.dt_integration, lambda v: 0.0 < v <= 1e-3, "an RK4 step in (0, 1e-3] s")
        check("v_max", self.v_max, lambda v: v > self.v_min, f"a speed above v_min = {self.v_min}")
        check("dt_table", self.dt_table, lambda v: _is_multiple(v, self.dt_integration),
              f"a multiple of dt_integration = {self.dt_integration}")
        check("t_max", self.t_max, lambda v: v >= 2 * self.dt_table, f"at least two table steps of {self.dt_table} s")


def _is_multiple(value: float, unit: float) -> bool:
    ratio = value / unit
    return abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1


# --- the paper's own fit (reference data) -----------------------------------------------------

PAPER_FIT_TERMS: tuple[tuple[float, int, int], ...] = (
    (-0.8001, 0, 0), (0.4752, 1, 0), (2.1603, 0, 1), (-0.0481, 2, 0), (-1.1421, 1, 1),
    (-1.3265, 0, 2), (0.0846, 2, 1), (0.6708, 1, 2), (0.2326, 0, 3), (-0.0183, 2, 2),
    (-0.0592, 1, 3), (-0.0134, 0, 4),
)
"""(coefficient, power of v_x, power of t) of the polynomial ``yego(v, t)`` declared by
``declare function`` in the TikZ code of the paper's Fig. "Maximum steering maneuver"
(label ``fig:path``), copied verbatim."""


def paper_y_max_fit(vx: ArrayLike, t: ArrayLike) -> ArrayLike:
    """The paper's polynomial fit of y_max (m): ``yego(v, t)`` of Fig. "Maximum steering maneuver".

    First argument v_x (m/s), second t (s): with this order the fit gives the ν
    printed in Figs. 5–7 to two decimals (ν = w / yego(v_des, τ)).  Reference
    data, not used by the planners: the quartic is not 0 at t = 0, dips below 0
    around t = 0.5 s (yego(7, 0.5) < 0) and is flat (non-physical) at
    v_x = 1 m/s; it is meaningful for t ∈ [1, 5] s, v_x ∈ [3, 7] m/s.
    """
    v = np.asarray(vx, dtype=float)
    s = np.asarray(t, dtype=float)
    out = sum(c * v**i * s**j for c, i, j in PAPER_FIT_TERMS)
    return float(out) if np.ndim(out) == 0 else out


class PaperExperiment(NamedTuple):
    """One experiment of Figs. 5–7: speed, τ, far-edge width w of the drawn box, printed ν."""

    vx: float
    tau: float
    w: float
    nu: float
    v_detect: float
    """Speed at detection (m/s): 4.5 in the third 6 m/s case (the text), else vx."""
    figure: str


PAPER_EXPERIMENTS: tuple[PaperExperiment, ...] = (
    PaperExperiment(5.0, 5.0, 4.0, 0.25, 5.0, "fig:exptx5"),
    PaperExperiment(5.0, 4.0, 3.2, 0.26, 5.0, "fig:exptx5"),
    PaperExperiment(5.0, 3.0, 2.4, 0.32, 5.0, "fig:exptx5"),
    PaperExperiment(6.0, 3.0, 2.0, 0.21, 6.0, "fig:exptx6"),
    PaperExperiment(6.0, 3.0, 2.4, 0.26, 6.0, "fig:exptx6"),
    PaperExperiment(6.0, 3.0, 3.2, 0.34, 4.5, "fig:exptx6"),
    PaperExperiment(7.0, 2.8, 2.0, 0.19, 7.0, "fig:exptx7"),
    PaperExperiment(7.0, 2.0, 2.0, 0.40, 7.0, "fig:exptx7"),
    PaperExperiment(7.0, 1.4, 2.0, 0.95, 7.0, "fig:exptx7"),
)
"""The nine experiments of the paper (Figs. 5–7).  The printed ν equals
w / yego(vx, τ) in all nine (the 4.5 m/s case too: its ν was computed at 6 m/s)."""


# --- integration of eq. (ymax) -----------------------------------------------------------------

class ManeuverProfile(NamedTuple):
    """Sampled maximum steering maneuver: rows are times, columns speeds."""

    t: np.ndarray
    y: np.ndarray
    """Lateral position y_max (m)."""
    vY: np.ndarray
    """Global lateral velocity ẏ_max = v_Y (m/s)."""
    aY: np.ndarray
    """Global lateral acceleration ÿ_max = v̇_Y (m/s²)."""
    theta: np.ndarray
    """Yaw angle (rad)."""


def _rates(s: Any, v: Any, delta: Any, q: Sequence[Any], ops: ModuleType) -> tuple[Any, Any, Any, Any]:
    """Right-hand side of eq. (ymax) for the state [v_y, γ, θ, y] at the constant speed ``v``.

    ``q`` = (m, I_zz, l_f, l_r, B_y, C_y, μ F_zf, μ F_zr); NumPy arrays (one
    column per speed) or CasADi symbols alike (``ops`` = numpy or casadi):

        α_f = δ − (v_y + l_f γ)/v_x,  α_r = (l_r γ − v_y)/v_x       eq. (alphas), β ≈ v_y/v_x
        F_y = μ F_z sin(C_y atan(B_y α))                            eq. (fy)
        v̇_y = (F_yf + F_yr)/m − v_x γ,  γ̇ = (F_yf l_f − F_yr l_r)/I_zz   eq. (eomdyn)
        θ̇ = γ,  ẏ = v_Y = v_x sin θ + v_y cos θ                     eq. (trajdef)
    """
    m, izz, lf, lr, b, c, fzf, fzr = q
    vy, gamma, theta = s[0], s[1], s[2]
    fyf = pacejka(delta - (vy + lf * gamma) / v, fzf, b, c, ops)
    fyr = pacejka((lr * gamma - vy) / v, fzr, b, c, ops)
    return ((fyf + fyr) / m - v * gamma, (fyf * lf - fyr * lr) / izz, gamma,
            v * ops.sin(theta) + vy * ops.cos(theta))


def _lateral_acceleration(s: Any, sdot: Any, v: Any, ops: ModuleType) -> Any:
    """ÿ = d/dt (v_x sin θ + v_y cos θ) with v_x constant."""
    vy, gamma, theta = s[0], s[1], s[2]
    return (v * gamma + sdot[0]) * ops.cos(theta) - vy * gamma * ops.sin(theta)


def _coefficients(vehicle: VehicleParams, mu: float) -> tuple[float, ...]:
    p = vehicle
    return (p.m, p.Izz, p.lf, p.lr, p.By, p.Cy, mu * p.Fzf, mu * p.Fzr)


def integrate_y_max(vehicle: VehicleParams, mu: float, speeds: Sequence[float] | np.ndarray, t_max: float,
                    dt: float, every: int = 1, side: int = 1) -> ManeuverProfile:
    """Integrate eq. (ymax) for every speed at once with RK4 (step ``dt``) in NumPy, sampled every ``every`` steps.

    The reference integrator (the table is built by :func:`maneuver_profile`,
    which gives the same numbers faster).  ``side`` = −1 steers to the right.
    The step containing the end of the steering ramp φ = δ_max / δ̇_max is split
    there, so RK4 never straddles the kink of δ(φ).
    """
    v = np.asarray(speeds, dtype=float)
    if v.ndim != 1 or np.any(v <= 0.0):
        raise ValueError(f"speeds = {speeds!r}: expected a vector of positive speeds")
    n = int(round(t_max / dt))
    prof, _ = _integrate_numpy(vehicle, mu, v, n, dt, every, side)
    return prof


def _integrate_numpy(vehicle: VehicleParams, mu: float, v: np.ndarray, n: int, dt: float, every: int,
                     side: int) -> tuple[ManeuverProfile, np.ndarray]:
    """``n`` RK4 steps from rest; the profile sampled every ``every`` steps and the final state."""
    p = vehicle
    q = _coefficients(vehicle, mu)
    t_ramp = p.delta_max / p.delta_rate_max
    sgn = -1.0 if side < 0 else 1.0

    def f(phi: float, s: np.ndarray) -> np.ndarray:
        return np.array(_rates(s, v, sgn * min(p.delta_rate_max * phi, p.delta_max), q, np))

    def rk4(phi: float, s: np.ndarray, h: float) -> np.ndarray:
        k1 = f(phi, s)
        k2 = f(phi + 0.5 * h, s + 0.5 * h * k1)
        k3 = f(phi + 0.5 * h, s + 0.5 * h * k2)
        k4 = f(phi + h, s + h * k3)
        return s + h / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)

    n_out = n // every + 1
    ts = np.arange(n_out) * (every * dt)
    ys, vYs, aYs, thetas = (np.zeros((n_out, v.size)) for _ in range(4))

    def record(row: int, phi: float, state: np.ndarray) -> None:
        # at φ = 0 the acceleration is the right limit (after the ramp): what the maneuver starts with
        sdot = f(t_ramp if phi == 0.0 else phi, state)
        ys[row], thetas[row], vYs[row] = state[3], state[2], sdot[3]
        aYs[row] = _lateral_acceleration(state, sdot, v, np)

    s = np.zeros((4, v.size))
    record(0, 0.0, s)
    for i in range(n):
        phi = i * dt
        if phi < t_ramp < phi + dt:
            s = rk4(phi, s, t_ramp - phi)
            s = rk4(t_ramp, s, phi + dt - t_ramp)
        else:
            s = rk4(phi, s, dt)
        if (i + 1) % every == 0:
            record((i + 1) // every, (i + 1) * dt, s)
    return ManeuverProfile(ts, ys, vYs, aYs, thetas), s


def maneuver_profile(vehicle: VehicleParams, mu: float, speeds: Sequence[float] | np.ndarray, t_max: float,
                     dt: float, every: int = 1, side: int = 1) -> ManeuverProfile:
    """Same numbers as :func:`integrate_y_max`, about twice as fast.

    The steering ramp (up to the first sample after φ = δ_max / δ̇_max) is
    integrated in NumPy; from there δ = δ_max is constant and the same RK4
    steps run in one call of a CasADi function mapped over the speeds.
    """
    v = np.asarray(speeds, dtype=float)
    if v.ndim != 1 or np.any(v <= 0.0):
        raise ValueError(f"speeds = {speeds!r}: expected a vector of positive speeds")
    n = int(round(t_max / dt))
    n_out = n // every + 1
    t_ramp = vehicle.delta_max / vehicle.delta_rate_max
    head = min(n_out - 1, max(1, math.ceil(t_ramp / (every * dt) - 1e-9)))
    prof, state = _integrate_numpy(vehicle, mu, v, head * every, dt, every, side)
    n_chunks = n_out - 1 - head
    if n_chunks <= 0:
        return prof
    sgn = -1.0 if side < 0 else 1.0
    s = ca.SX.sym("s", 4)
    vs = ca.SX.sym("v")
    qs = ca.SX.sym("q", 9)
    q, delta = [qs[i] for i in range(8)], qs[8]

    def f(x: ca.SX) -> ca.SX:
        return ca.vertcat(*_rates(x, vs, delta, q, ca))

    x = s
    for _ in range(every):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)
    xdot = f(x)
    chunk = ca.Function("ymax_chunk", [s, vs, qs], [x, ca.vertcat(xdot[3], _lateral_acceleration(x, xdot, vs, ca))])
    run_steps = chunk.mapaccum("ymax_steps", n_chunks, [0], [0])
    s0, v0, q0 = ca.MX.sym("s0", 4), ca.MX.sym("v0"), ca.MX.sym("q0", 9)
    states, rates = run_steps(s0, ca.repmat(v0, 1, n_chunks), ca.repmat(q0, 1, n_chunks))
    run = ca.Function("ymax_run", [s0, v0, q0], [states, rates]).map("ymax_map", "serial", v.size, [2], [])
    q_value = np.array(_coefficients(vehicle, mu) + (sgn * vehicle.delta_max,))
    # the map concatenates the speeds' (rows × n_chunks) blocks horizontally
    states, rates = (np.asarray(a).reshape(-1, v.size, n_chunks) for a in run(state, v.reshape(1, -1), q_value))
    ys, vYs, aYs, thetas = (np.vstack([a, np.zeros((n_chunks, v.size))]) for a in (prof.y, prof.vY, prof.aY, prof.theta))
    ys[head + 1:] = states[3].T
    thetas[head + 1:] = states[2].T
    vYs[head + 1:] = rates[0].T
    aYs[head + 1:] = rates[1].T
    return ManeuverProfile(np.arange(n_out) * (every * dt), ys, vYs, aYs, thetas)


# --- the table -----------------------------------------------------------------------------------

class MaxSteeringTable:
    """y_max(t, v_x), its time derivatives and its running maximum, tabulated; bilinear queries.

    Interpolation in v_x compares the two neighbouring speeds v_j at the same
    travelled distance, t_j = t v_x / v_j, rather than at the same time: slow
    cornering is kinematic (the path depends on the distance only), so this is
    exact in the slow-speed limit (at 0.5–1 m/s it cuts the error of plain
    bilinear interpolation from 30 mm to 1 mm; accuracy of the default grid in
    :class:`ManeuverParams`).  Time derivatives scale with
    (v_x / v_j)^k accordingly.  Below the lowest speed the same similarity
    extrapolates to y_max(t, 0) = 0; above the highest speed and beyond
    ``t_max`` queries are clamped.  Scalar queries (floats) take about a
    microsecond; arrays broadcast.
    """

    def __init__(self, t: np.ndarray, v: np.ndarray, y: np.ndarray, vY: np.ndarray, aY: np.ndarray,
                 mu: float, t_max: float | None = None) -> None:
        grid_t = np.asarray(t, dtype=float)
        self.t_max = float(grid_t[-1] if t_max is None else t_max)
        """Longest time answered (s); later times are clamped."""
        self.t = grid_t[grid_t <= self.t_max + 1e-9]
        """Tabulated times up to ``t_max`` (s); the grid extends further for the similarity interpolation."""
        self.v = np.asarray(v, dtype=float)
        """Tabulated speeds (m/s)."""
        self.mu = float(mu)
        """Friction the maneuver was integrated with."""
        y = np.asarray(y, dtype=float)
        self._grids = {"y": y, "vY": np.asarray(vY, dtype=float), "aY": np.asarray(aY, dtype=float),
                       "reach": np.maximum.accumulate(y, axis=0)}
        self._nt, self._nv = len(grid_t), len(self.v)
        self._v0, self._v1 = float(self.v[0]), float(self.v[-1])
        self._dv = float(self.v[1] - self.v[0])
        self._inv_dt = 1.0 / float(grid_t[1] - grid_t[0])
        self._inv_dv = 1.0 / self._dv
        # flat Python lists: the scalar path indexes them without NumPy overhead
        self._flat = {name: grid.ravel().tolist() for name, grid in self._grids.items()}

    @classmethod
    def build(cls, vehicle: VehicleParams, params: ManeuverParams | None = None) -> "MaxSteeringTable":
        """Integrate eq. (ymax) on the grid of ``params`` (a few tenths of a second)."""
        params = params or ManeuverParams()
        n_v = math.ceil((params.v_max - params.v_min) / params.dv_table - 1e-9) + 1  # the last speed ≥ v_max
        speeds = params.v_min + params.dv_table * np.arange(n_v)
        every = int(round(params.dt_table / params.dt_integration))
        # the lowest speed is also read at t (v_min + dv) / v_min by the similarity interpolation
        stretch = (params.v_min + params.dv_table) / params.v_min
        t_end = params.dt_table * math.ceil(params.t_max * stretch / params.dt_table - 1e-9)
        prof = maneuver_profile(vehicle, params.mu_ymax, speeds, t_end, params.dt_integration, every)
        return cls(prof.t, speeds, prof.y, prof.vY, prof.aY, params.mu_ymax, params.t_max)

    # -- interpolation ---------------------------------------------------------------------------
    def _scalar(self, name: str, t: float, vx: float, power: int) -> float:
        if t != t or vx != vx:
            return math.nan
        if vx <= 0.0:
            return 0.0
        if t > self.t_max:
            t = self.t_max
        elif t < 0.0:
            t = 0.0
        if vx > self._v1:
            vx = self._v1
        if vx < self._v0:
            j, b = 0, 0.0
        else:
            fj = (vx - self._v0) * self._inv_dv
            j = int(fj)
            if j > self._nv - 2:
                j = self._nv - 2
            b = fj - j
        g = self._flat[name]
        out = 0.0
        for node, weight in ((j, 1.0 - b), (j + 1, b)):
            if weight == 0.0:
                continue
            ratio = vx / (self._v0 + node * self._dv)
            ft = t * ratio * self._inv_dt
            i = int(ft)
            if i > self._nt - 2:
                i = self._nt - 2
            a = ft - i
            k = i * self._nv + node
            value = g[k] + a * (g[k + self._nv] - g[k])
            out += weight * (value * ratio**power if power else value)
        return out

    def _array(self, name: str, t: ArrayLike, vx: ArrayLike, power: int) -> np.ndarray:
        t, vx = np.broadcast_arrays(np.asarray(t, dtype=float), np.asarray(vx, dtype=float))
        moving = vx > 0.0
        invalid = np.isnan(t) | np.isnan(vx)
        t = np.where(invalid, 0.0, t)
        vx = np.where(invalid, 1.0, vx)
        tt = np.clip(t, 0.0, self.t_max)
        vv = np.clip(vx, 1e-12, self._v1)
        fj = np.clip((vv - self._v0) * self._inv_dv, 0.0, None)
        j = np.minimum(fj.astype(int), self._nv - 2)
        b = fj - j
        g = self._grids[name]
        out = np.zeros(np.shape(vv))
        for node, weight in ((j, 1.0 - b), (j + 1, b)):
            ratio = vv / (self._v0 + node * self._dv)
            ft = tt * ratio * self._inv_dt
            i = np.minimum(ft.astype(int), self._nt - 2)
            a = ft - i
            value = g[i, node] + a * (g[i + 1, node] - g[i, node])
            out += weight * (value * ratio**power if power else value)
        return np.where(invalid, np.nan, np.where(moving, out, 0.0))

    def _query(self, name: str, t: ArrayLike, vx: ArrayLike, power: int) -> ArrayLike:
        if isinstance(t, (float, int)) and isinstance(vx, (float, int)):
            return self._scalar(name, float(t), float(vx), power)
        out = self._array(name, t, vx, power)
        return float(out) if out.ndim == 0 else out

    def y_max(self, t: ArrayLike, vx: ArrayLike) -> ArrayLike:
        """eq. (ymax): lateral position of the maximum steering maneuver after ``t`` s at ``vx`` (m)."""
        return self._query("y", t, vx, 0)

    def v_Y_max(self, t: ArrayLike, vx: ArrayLike) -> ArrayLike:
        """ẏ_max: global lateral velocity of the maneuver (m/s)."""
        return self._query("vY", t, vx, 1)

    def a_Y_max(self, t: ArrayLike, vx: ArrayLike) -> ArrayLike:
        """ÿ_max: global lateral acceleration of the maneuver (m/s²)."""
        return self._query("aY", t, vx, 2)

    def reach(self, t: ArrayLike, vx: ArrayLike) -> ArrayLike:
        """max_{φ ≤ t} y_max(φ, v_x): the largest lateral displacement reachable by ``t`` (m).

        Equal to y_max wherever y_max increases in t (the whole domain of the
        paper's Fig. 4); past half a turn y_max decreases while the reachable
        displacement does not (steering can stop at the peak).
        """
        return self._query("reach", t, vx, 0)


def time_to_collision(distance: float, vx: float) -> float:
    """τ = distance / v_x (s), eq. (nudef)'s τ.

    Negative once the near edge is behind the CoG; infinite when the car is not
    closing in (v_x ≤ 0) on an obstacle ahead, 0 when it is not moving but already there.
    """
    if vx > _EPS_V:
        return distance / vx
    return math.inf if distance > 0.0 else 0.0


def lateral_steering_index(w: float, tau: float, vx: float, table: MaxSteeringTable) -> float:
    """eq. (nudef): ν = w / y_max(τ, v_x).

    y_max is taken as the reachable displacement :meth:`MaxSteeringTable.reach`
    (identical to y_max where the paper plots it).  ν = 0 for w ≤ 0 (nothing to
    avoid) or τ = ∞ (not closing in), and ∞ when no lateral displacement is
    possible in time (τ ≤ 0 or v_x ≤ 0).
    """
    if w <= 0.0 or tau == math.inf:
        return 0.0
    reach = float(table.reach(tau, vx)) if tau > 0.0 else 0.0
    return w / reach if reach > 1e-9 else math.inf


# --- calibration of μ -----------------------------------------------------------------------------

class CalibrationErrors(NamedTuple):
    """How well the maneuver with a given μ reproduces the paper."""

    mu: float
    fit_rms: float
    """RMS of y_max − yego over v ∈ {3, 5, 7} m/s (the plotted curves where the fit is meaningful), t ∈ [1, 5] s (m)."""
    nu_rms: float
    """RMS of ν − ν_paper over the nine experiments, ν at the speed the paper used (v_x)."""
    nu: tuple[float, ...]
    """ν of the nine experiments at the paper's v_x."""
    nu_detect: tuple[float, ...]
    """ν at the speed at detection (differs only for the 4.5 m/s case)."""


def calibration_errors(vehicle: VehicleParams, mu: float, dt: float = 1e-3) -> CalibrationErrors:
    """Compare eq. (ymax) integrated with friction ``mu`` to the paper's fit and printed ν."""
    speeds = sorted({3.0, 5.0, 7.0} | {e.vx for e in PAPER_EXPERIMENTS} | {e.v_detect for e in PAPER_EXPERIMENTS})
    every = max(1, int(round(0.01 / dt)))
    prof = maneuver_profile(vehicle, mu, speeds, 5.0, dt, every)

    def y_at(t: ArrayLike, v: float) -> np.ndarray:
        return np.interp(t, prof.t, prof.y[:, speeds.index(v)])

    def reach_at(t: float, v: float) -> float:
        return float(np.interp(t, prof.t, np.maximum.accumulate(prof.y[:, speeds.index(v)])))

    ts = np.arange(1.0, 5.0 + 1e-9, 0.1)
    errors = np.concatenate([y_at(ts, v) - paper_y_max_fit(v, ts) for v in (3.0, 5.0, 7.0)])
    nu = tuple(e.w / reach_at(e.tau, e.vx) for e in PAPER_EXPERIMENTS)
    nu_detect = tuple(e.w / reach_at(e.tau, e.v_detect) for e in PAPER_EXPERIMENTS)
    nu_rms = math.sqrt(sum((a - e.nu) ** 2 for a, e in zip(nu, PAPER_EXPERIMENTS)) / len(nu))
    return CalibrationErrors(mu, float(np.sqrt(np.mean(errors**2))), nu_rms, nu, nu_detect)
