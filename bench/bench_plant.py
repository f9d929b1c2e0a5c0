"""Plant speed: µs of wall time per simulated second (1 kHz RK4), chunked vs per-step calls.

Run: ``.venv/bin/python bench/bench_plant.py``.  Not a test: the numbers depend on the
machine; the ratios are what matters (CasADi's Python call overhead is tens of µs, so a
simulated second of 1000 one-step calls costs far more than 100 calls of ten steps).
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

from moose.params import VehicleParams
from moose.vehicle import CHUNK, VehiclePlant, initial_state, rk4_step_function, vehicle_vector

REPEATS = 5
U = np.array([0.2, 40.0, 30.0])


def best_of(fn) -> float:
    """Best wall time (s) of REPEATS runs of ``fn`` (each one simulated second)."""
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    params = VehicleParams()
    x0 = initial_state(params, vx=7.0)
    plant = VehiclePlant(params)

    def compiled(n: int):
        def run() -> None:
            plant.reset(x0)
            for _ in range(1000 // n):
                plant.step(U, n)
        return run

    rk4 = rk4_step_function()
    pv, dt = vehicle_vector(params), plant.dt
    accum = rk4.mapaccum(CHUNK)

    def vm_per_step() -> None:
        x = ca.DM(x0)
        for _ in range(1000):
            x = rk4(x, U, pv, dt)

    def vm_mapaccum() -> None:
        x = ca.DM(x0)
        for _ in range(1000 // CHUNK):
            x = accum(x, U, pv, dt)[:, -1]

    rows = [
        (f"compiled C, {CHUNK} steps per call (VehiclePlant.step(u, {CHUNK}))", compiled(CHUNK)),
        ("compiled C, 1 step per call (VehiclePlant.step(u, 1))", compiled(1)),
        (f"CasADi VM, mapaccum of {CHUNK} steps per call", vm_mapaccum),
        ("CasADi VM, 1 step per call", vm_per_step),
    ]
    results = [(name, best_of(fn) * 1e6) for name, fn in rows]
    base = results[0][1]
    print(f"plant: RK4 at {1 / plant.dt:.0f} Hz, best of {REPEATS}; µs of wall time per simulated second")
    for name, us in results:
        print(f"  {name:<58s} {us:10.0f} µs   ×{us / base:5.1f}   {1e6 / us:7.0f}× real time")
    # the chunked and per-step paths integrate the same steps
    plant.reset(x0)
    chunked = plant.step(U, 1000)
    plant.reset(x0)
    for _ in range(1000):
        single = plant.step(U, 1)
    print(f"  max |chunked − per-step| state difference after 1 s: {np.max(np.abs(chunked - single)):.1e}")


if __name__ == "__main__":
    main()
