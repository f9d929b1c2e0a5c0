"""Calibration of the friction against the paper: which μ makes eq. (ymax) reproduce its fit and its ν.

``moose reproduce`` and ``tests/test_maneuver.py`` use it; :data:`moose.paper.PAPER_FRICTION` is its result.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .maneuver import ArrayLike, maneuver_profile
from .paper import PAPER_EXPERIMENTS, paper_y_max_fit
from .params import VehicleParams


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


def calibrate(vehicle: VehicleParams, bounds: tuple[float, float] = (0.2, 0.6), tol: float = 1e-3) -> CalibrationErrors:
    """The μ in ``bounds`` with the least RMS error of ν over the nine experiments: a golden-section search down
    to ``tol`` (the error is unimodal in μ over the bounds: y_max grows with μ, so ν falls; see the calibration
    table in docs/modelling.md, "Friction")."""
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    lo, hi = bounds

    def error(mu: float) -> float:
        return calibration_errors(vehicle, mu).nu_rms

    a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    fa, fb = error(a), error(b)
    while hi - lo > tol:
        if fa <= fb:
            hi, b, fb = b, a, fa
            a = hi - ratio * (hi - lo)
            fa = error(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + ratio * (hi - lo)
            fb = error(b)
    return calibration_errors(vehicle, a if fa <= fb else b)
