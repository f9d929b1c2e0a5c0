"""A bag as a CommonRoad scenario (``moose bag export --format commonroad``): the run's true path from
/vehicle/odom, its scenario and configuration from the bag's run parameters, the detection instant from the first
threat on /perception/threat, written by :func:`moose.commonroad.scenario.export_run` as ``moose simulate
--commonroad-out`` writes a lockstep run."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np

from .. import convert as cv
from ..graph import ODOM, THREAT
from .errors import BagError
from .params import read_run_parameters
from .reader import ReadReport, read_bag

FILE_NAME = "commonroad.xml"
"""The file ``moose bag export --format commonroad`` writes into its output folder."""


def export_commonroad(path: str | Path, out_dir: str | Path, report: Optional[ReadReport] = None) -> Path:
    """Write bag ``path`` as ``out_dir/commonroad.xml``; a bag without run parameters or odometry is a
    :class:`BagError`.  The CommonRoad packages must be installed (:func:`moose.commonroad.require`)."""
    from moose.commonroad import require

    require("--format commonroad")
    from moose.commonroad.scenario import export_run, write

    run = read_run_parameters(path)
    if run is None:
        raise BagError(f"bag {str(path)!r} has no run parameters (scenario, configuration): "
                       "it cannot be written as a CommonRoad scenario")
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise BagError(f"output {str(out_dir)!r} is not a directory: export writes into a folder")
    rows: list[tuple[float, ...]] = []
    detected: Optional[float] = None
    for m in read_bag(path, [ODOM.name, THREAT.name], report):
        if m.topic == ODOM.name:
            p, q, v = m.msg.pose.pose.position, m.msg.pose.pose.orientation, m.msg.twist.twist.linear
            yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
            rows.append((cv.time_of(m.msg), p.x, p.y, yaw, v.x, v.y))
        elif detected is None:
            try:
                threat = cv.threat_from_msg(m.msg)
            except cv.InvalidMessage:
                continue
            if threat is not None:
                detected = threat.t
    if not rows:
        raise BagError(f"bag {str(path)!r} has no {ODOM.name}: no path to export")
    table = np.array(sorted(rows))
    trace = {name: table[:, i] for i, name in enumerate(("t", "x", "y", "theta", "vx", "vy"))}
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        return write(export_run(trace, run.scenario, run.config.vehicle, detected), out_dir / FILE_NAME)
    except OSError as exc:
        raise BagError(f"export into {str(out_dir)!r} failed: {exc.strerror or exc}") from None
