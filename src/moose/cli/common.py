"""Arguments and helpers that several commands share (this package's and plugins')."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..params import ParamError

DEFAULT_SCENARIO = "paper_v7_tau1.4"
"""The paper's extreme case (7 m/s, τ = 1.4 s, ν ≈ 0.95): the main job."""


EXIT_CLEAR = 0
"""The run was ``clear`` (and, for other commands, everything worked)."""
EXIT_FAILED = 1
"""The run failed: ``collision``, ``left_field``, ``lost_control`` or ``stopped_short``.  Bag tools: the command
ran, but some data could not be read (each loss is reported on stderr)."""
EXIT_BAD_INPUT = 2
"""Bad input (``moose: error: …``): nothing was run."""
EXIT_INCOMPLETE = 3
"""The run is ``incomplete``: its data do not cover it (cut short, a stalled simulator)."""
EXIT_INTERRUPTED = 130
"""Ctrl-C (128 + SIGINT)."""

OUTCOME_EXIT: dict[str, int] = {"clear": EXIT_CLEAR, "collision": EXIT_FAILED, "left_field": EXIT_FAILED,
                                "lost_control": EXIT_FAILED, "stopped_short": EXIT_FAILED,
                                "incomplete": EXIT_INCOMPLETE}
"""The exit status of each outcome of :data:`moose.verdict.OUTCOMES` (``moose simulate``, ``moose launch``)."""

EXIT_DEGRADED = 4
"""``moose launch``: the outcome was ``clear``, but the run was degraded — a node failed to start, died, stalled
or was stopped by a fault, or the graph fell back (a planner replaced, a minimum-risk maneuver): the car came
through, the system did not (:mod:`moose_ros.incidents`)."""


def positive_float(text: str) -> float:
    """argparse type: a positive number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} must be positive")
    return value


def add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    """Scenario selection shared by ``simulate`` and ``launch``."""
    group = parser.add_argument_group("scenario (a file or an ad-hoc moose test)")
    group.add_argument("--scenario", help=f"name in config/scenarios or a YAML path (default {DEFAULT_SCENARIO})")
    group.add_argument("--speed", type=positive_float, help="ad-hoc test: speed at detection and desired speed (m/s)")
    group.add_argument("--tau", type=positive_float, help="ad-hoc test: time to collision at appearance (s)")
    group.add_argument("--obstacle-half-width", type=positive_float, help="ad-hoc test: danger-zone half width (m)")
    group.add_argument("--obstacle-length", type=positive_float, default=2.0, help="ad-hoc test: length (m)")
    group.add_argument("--duration", type=positive_float, help="simulated seconds after the obstacle appears")
    group.add_argument("--config", help="ROS 2 parameter file (default config/moose.yaml)")
    group.add_argument("--planner", choices=["combined", "mpc", "msf"], help="planner driving the car")
    group.add_argument("--mu", type=positive_float, help="friction coefficient of the plant")
    group.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")


def scenario_from_args(args: Any) -> Any:
    """The scenario named by ``args`` (file, or ad-hoc flags): any object with the attributes of
    :func:`add_scenario_arguments` (``scenario``, ``speed``, ``tau``, ``obstacle_half_width``,
    ``obstacle_length``, ``duration``, ``mu``), such as parsed arguments or a node's parameters."""
    import dataclasses

    from ..scenario import adhoc_scenario, load_scenario

    adhoc = [args.speed, args.tau, args.obstacle_half_width]
    if any(v is not None for v in adhoc):
        if args.scenario:
            raise ParamError("--scenario cannot be combined with the ad-hoc flags --speed/--tau/--obstacle-half-width")
        if any(v is None for v in adhoc):
            raise ParamError("an ad-hoc moose test needs --speed, --tau and --obstacle-half-width")
        scenario = adhoc_scenario(args.speed, args.tau, args.obstacle_half_width, args.obstacle_length)
    else:
        scenario = load_scenario(args.scenario or DEFAULT_SCENARIO)
    changes: dict[str, Any] = {}
    if args.duration is not None:
        changes["duration"] = args.duration
    if args.mu is not None:
        changes["mu"] = args.mu
    return dataclasses.replace(scenario, **changes) if changes else scenario


def run_folder(scenario: str, planner: str) -> Path:
    """A new folder under runs/ for this run's outputs."""
    import time

    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = Path("runs") / f"{stamp}_{scenario}_{planner}"
    path, n = base, 1
    while path.exists():
        n += 1
        path = Path(f"{base}_{n}")
    return path
