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

The friction is the planning μ (the vehicle given to :meth:`MaxSteeringTable.build`), so ν is the
lateral steering index of the car the stack believes it drives; the table is built once per μ.
The paper does not state the friction its y_max used: :data:`moose.paper.PAPER_FRICTION` is the
μ that reproduces its fit and its ν (:mod:`moose.calibration`).
"""
from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import math
import os
import tempfile
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any, NamedTuple, Sequence, Union

import numpy as np

from .params import VehicleParams
from .resources import cache_dir
from .schema import ManeuverParams
from .tire import Axles, lateral_forces

ArrayLike = Union[float, np.ndarray]
M_VY, M_GAMMA, M_THETA, M_Y = range(4)
"""Indices of the maneuver's state [v_y, γ, θ, y] (eq. (ymax) at constant v_x)."""
N_MANEUVER = 4


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

    ``q`` = (m, I_zz, *:class:`~moose.tire.Axles`); NumPy arrays (one column per speed) or
    CasADi symbols alike (``ops`` = numpy or casadi):

        F_yf, F_yr at the slip angles with β ≈ v_y/v_x             eqs. (fy), (alphas): moose.tire
        v̇_y = (F_yf + F_yr)/m − v_x γ,  γ̇ = (F_yf l_f − F_yr l_r)/I_zz   eq. (eomdyn)
        θ̇ = γ,  ẏ = v_Y = v_x sin θ + v_y cos θ                     eq. (trajdef)
    """
    m, izz, *tyres = q
    axles = Axles(*tyres)
    vy, gamma, theta = s[M_VY], s[M_GAMMA], s[M_THETA]
    fyf, fyr = lateral_forces(vy, gamma, delta, v, axles, ops)
    return ((fyf + fyr) / m - v * gamma, (fyf * axles.lf - fyr * axles.lr) / izz, gamma,
            v * ops.sin(theta) + vy * ops.cos(theta))


def _lateral_acceleration(s: Any, sdot: Any, v: Any, ops: ModuleType) -> Any:
    """ÿ = d/dt (v_x sin θ + v_y cos θ) with v_x constant."""
    vy, gamma, theta = s[M_VY], s[M_GAMMA], s[M_THETA]
    return (v * gamma + sdot[M_VY]) * ops.cos(theta) - vy * gamma * ops.sin(theta)


def _coefficients(vehicle: VehicleParams, mu: float) -> tuple[float, ...]:
    """The ``q`` of :func:`_rates`: (m, I_zz, *axles)."""
    return (vehicle.m, vehicle.Izz, *Axles.of(vehicle, mu))


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
        sdot = f(phi, state)
        ys[row], thetas[row], vYs[row] = state[M_Y], state[M_THETA], sdot[M_Y]
        aYs[row] = _lateral_acceleration(state, sdot, v, np)

    s = np.zeros((N_MANEUVER, v.size))
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
    import casadi as ca  # here: a process that reads its table from the cache never loads CasADi

    sgn = -1.0 if side < 0 else 1.0
    s = ca.SX.sym("s", N_MANEUVER)
    vs = ca.SX.sym("v")
    q_value = np.array(_coefficients(vehicle, mu) + (sgn * vehicle.delta_max,))  # the q of _rates, then δ
    n_q = q_value.size - 1
    qs = ca.SX.sym("q", n_q + 1)
    q, delta = [qs[i] for i in range(n_q)], qs[n_q]

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
    chunk = ca.Function("ymax_chunk", [s, vs, qs], [x, ca.vertcat(xdot[M_Y], _lateral_acceleration(x, xdot, vs, ca))])
    run_steps = chunk.mapaccum("ymax_steps", n_chunks, [0], [0])
    s0, v0, q0 = ca.MX.sym("s0", N_MANEUVER), ca.MX.sym("v0"), ca.MX.sym("q0", n_q + 1)
    states_sym, rates_sym = run_steps(s0, ca.repmat(v0, 1, n_chunks), ca.repmat(q0, 1, n_chunks))
    run = ca.Function("ymax_run", [s0, v0, q0], [states_sym, rates_sym]).map("ymax_map", "serial", v.size, [2], [])
    # the map concatenates the speeds' (rows × n_chunks) blocks horizontally
    states, rates = (np.asarray(a).reshape(-1, v.size, n_chunks) for a in run(state, v.reshape(1, -1), q_value))
    ys, vYs, aYs, thetas = (np.vstack([a, np.zeros((n_chunks, v.size))])
                            for a in (prof.y, prof.vY, prof.aY, prof.theta))
    ys[head + 1:] = states[M_Y].T
    thetas[head + 1:] = states[M_THETA].T
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
                 mu: float, t_max: float | None = None, t_lock: float = 0.0) -> None:
        grid_t = self._grid_t = np.asarray(t, dtype=float)
        self.t_max = float(grid_t[-1] if t_max is None else t_max)
        """Longest time answered (s); later times are clamped."""
        self.t = grid_t[grid_t <= self.t_max + 1e-9]
        """Tabulated times up to ``t_max`` (s); the grid extends further for the similarity interpolation."""
        self.v = np.asarray(v, dtype=float)
        """Tabulated speeds (m/s)."""
        self.mu = float(mu)
        """Friction the maneuver was integrated with."""
        self.t_lock = float(t_lock)
        """Time the steering takes from straight to full lock, δ_max / δ̇_max (s)."""
        y = np.asarray(y, dtype=float)
        self._grids = {"y": y, "vY": np.asarray(vY, dtype=float), "aY": np.asarray(aY, dtype=float),
                       "reach": np.maximum.accumulate(y, axis=0)}
        self._nt, self._nv = len(grid_t), len(self.v)
        self._v0, self._v1 = float(self.v[0]), float(self.v[-1])
        self._dv = float(self.v[1] - self.v[0])
        self._inv_dt = 1.0 / float(grid_t[1] - grid_t[0])
        self._inv_dv = 1.0 / self._dv
        # flat views of the grids: the scalar path indexes them without NumPy overhead, and without a Python float
        # object per entry (a list of them took 9 MB more in each process that holds a table)
        self._flat = {name: np.ascontiguousarray(grid).reshape(-1).data for name, grid in self._grids.items()}

    @classmethod
    def build(cls, vehicle: VehicleParams, params: ManeuverParams | None = None) -> "MaxSteeringTable":
        """eq. (ymax) for ``vehicle`` (its μ, δ_max and δ̇_max) on the grid of ``params``, built once per
        process for each (vehicle, grid): a few tenths of a second the first time."""
        return _build_table(vehicle, params or ManeuverParams())

    @classmethod
    def _integrate(cls, vehicle: VehicleParams, params: ManeuverParams) -> "MaxSteeringTable":
        n_v = math.ceil((params.v_max - params.v_min) / params.dv_table - 1e-9) + 1  # the last speed ≥ v_max
        speeds = params.v_min + params.dv_table * np.arange(n_v)
        every = int(round(params.dt_table / params.dt_integration))
        # the lowest speed is also read at t (v_min + dv) / v_min by the similarity interpolation
        stretch = (params.v_min + params.dv_table) / params.v_min
        t_end = params.dt_table * math.ceil(params.t_max * stretch / params.dt_table - 1e-9)
        prof = maneuver_profile(vehicle, vehicle.mu, speeds, t_end, params.dt_integration, every)
        return cls(prof.t, speeds, prof.y, prof.vY, prof.aY, vehicle.mu, params.t_max,
                   vehicle.delta_max / vehicle.delta_rate_max)

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


TABLE_SOURCES = ("maneuver.py", "tire.py", "params.py", "schema.py")
"""The modules whose code decides a table's numbers: their text is part of its cache key."""


def table_cache_path(vehicle: VehicleParams, params: ManeuverParams) -> Path:
    """Where the table of (``vehicle``, ``params``) is cached: ``$MOOSE_CACHE_DIR/tables/<key>.npz``, the key a
    SHA-256 of every field of both, the text of :data:`TABLE_SOURCES` and the NumPy and CasADi versions (the
    integration's arithmetic), so a changed input or code never finds another's table."""
    digest = hashlib.sha256(repr((dataclasses.astuple(vehicle), dataclasses.astuple(params), np.__version__,
                                  importlib.metadata.version("casadi"))).encode())
    here = Path(__file__).parent
    for name in TABLE_SOURCES:
        digest.update((here / name).read_bytes())
    return cache_dir() / "tables" / f"{digest.hexdigest()[:32]}.npz"


@lru_cache(maxsize=32)
def _build_table(vehicle: VehicleParams, params: ManeuverParams) -> MaxSteeringTable:
    """The table, from the disk cache when it holds it (bit for bit the integrated arrays: a worker of a sweep, a
    ``moose simulate`` run need not integrate eq. (ymax) again, 0.4 s each), else integrated and cached (written
    to a temporary file and renamed, so a concurrent reader sees a whole file or none).  An unreadable cached file
    (truncated, corrupted: the archive's checksums) is integrated again and replaced."""
    path = table_cache_path(vehicle, params)
    try:
        with np.load(path) as cached:
            return MaxSteeringTable(cached["t"], cached["v"], cached["y"], cached["vY"], cached["aY"],
                                    float(cached["mu"]), float(cached["t_max"]), float(cached["t_lock"]))
    except Exception:  # noqa: BLE001 - no usable cached table (none, unreadable, another format): integrate
        pass
    table = MaxSteeringTable._integrate(vehicle, params)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz.partial", delete=False) as handle:
            np.savez(handle, t=table._grid_t, v=table.v, y=table._grids["y"], vY=table._grids["vY"],
                     aY=table._grids["aY"], mu=table.mu, t_max=table.t_max, t_lock=table.t_lock)
        os.replace(handle.name, path)
    except OSError:
        pass  # a read-only or full cache costs the next process the integration, nothing else
    return table


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
