"""``moose sweep``: many moose tests over axes of speed, τ, width or ν, friction, planner, seed and any
parameter, locally or on a Dask cluster; ``moose sweep plot DIR`` draws the maps.

Every input is checked before the first case runs; see :mod:`moose.sweep`.  Exit status: 0 when every
case ran and was judged, 3 when some case of the sweep ended in ``error``, ``timeout`` or ``crashed``
(its row says why), 130 when interrupted (``--resume`` continues), 2 for bad input, 5 when a row could not be
recorded (a full disk: the rows before it are kept, ``--resume`` continues).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from ..files import OutputError
from ..params import ParamError
from .common import add_timing_argument, positive_float, with_timing

EXAMPLE = ("moose sweep --speed 4:8:1 --tau 1:5:0.5 --nu 0.1:1.0:0.1 --mu paper,0.8 "
           "--planner combined,mpc,msf -o runs/paper_region")


def add_subparser(subparsers: Any) -> None:
    sweep = subparsers.add_parser(
        "sweep", help="sweep moose tests over axes (speed, tau, width or nu, mu, planner, seeds, parameters)",
        description="Run the moose test over the cross product (or a sample) of its axes and write one row per "
                    "case to DIR/results.parquet.  'moose sweep plot DIR' draws the maps.  An axis is a list "
                    "'4,5,6', a range 'LO:HI:STEP' (inclusive), or an open range 'LO:HI' sampled with --samples.",
        epilog=f"example: {EXAMPLE}", formatter_class=argparse.RawDescriptionHelpFormatter)
    sweep.add_argument("action", nargs="?", choices=["plot"], help="plot: draw the maps of the sweep in FOLDER")
    sweep.add_argument("folder", nargs="?", help="(plot) the sweep's folder")
    axes = sweep.add_argument_group("axes")
    axes.add_argument("--speed", metavar="VALUES", help="speed at detection, m/s")
    axes.add_argument("--tau", metavar="VALUES", help="time to collision at which the obstacle appears, s")
    axes.add_argument("--obstacle-half-width", metavar="VALUES", help="danger-zone half width, m (or --nu)")
    axes.add_argument("--nu", metavar="VALUES",
                      help="target lateral steering index: half width = nu * y_max(tau, v) at the road's mu")
    axes.add_argument("--mu", metavar="VALUES",
                      help="road friction; 'paper' is the calibration that reproduces the paper's nu "
                           "(default: the configuration's vehicle.mu)")
    axes.add_argument("--planner", metavar="VALUES",
                      help="combined, mpc, msf, or the baselines aeb, max_steer (default combined)")
    axes.add_argument("--seeds", type=int, default=1, help="sensor-noise seeds 0..N-1 (default 1)")
    axes.add_argument("--obstacle-length", metavar="VALUES", help="danger-zone length, m (default 2)")
    axes.add_argument("--duration", metavar="VALUES", help="simulated seconds after the obstacle appears (default 8)")
    axes.add_argument("--field-margin", metavar="VALUES", help="room beside the obstacle, m (default 5): the field is "
                                             "|y| <= half width + margin, at least the paper's")
    axes.add_argument("--set", action="append", default=[], metavar="GROUP.KEY=VALUES",
                      help="a parameter of config/moose.yaml as an axis, e.g. planning.N_p=10,20 or "
                           "sensors.gps_lag_s=0:0.6:0.2 (repeatable)")
    add_timing_argument(axes)
    sampling = sweep.add_argument_group("sampling")
    sampling.add_argument("--samples", type=int, help="draw N points of the open ranges LO:HI (default: full grid)")
    sampling.add_argument("--sampling", choices=["lhs", "random"], default="lhs",
                          help="Latin hypercube (default) or uniform random")
    sampling.add_argument("--sampling-seed", type=int, default=0, help="seed of the draw (recorded)")
    run = sweep.add_argument_group("run")
    run.add_argument("-o", "--output", help="the sweep's folder (default: a new folder under runs/)")
    run.add_argument("--config", help="ROS 2 parameter file (default config/moose.yaml)")
    run.add_argument("--resume", action="store_true", help="continue the sweep in -o, skipping recorded cases")
    run.add_argument("--backend", choices=["local", "dask"],
                     help="local worker processes (default), or an existing Dask cluster (the default with --address)")
    run.add_argument("--workers", type=int, help="local worker processes (default: the number of cores)")
    run.add_argument("--address", help="Dask scheduler, tcp://host:8786 (implies --backend dask)")
    run.add_argument("--connect-timeout", type=positive_float, default=10.0,
                     help="seconds to wait for the Dask scheduler and a first worker (default 10)")
    run.add_argument("--timeout", type=positive_float, default=300.0,
                     help="time limit of one case, s (default 300); a case over it is recorded as timeout")
    run.add_argument("--criticality", action="store_true",
                     help="add commonroad-crime's TTC, TTB, TTS, TTK, TTR of each case's situation to its row "
                          "(criticality.*; about 5 s per worker to import and 0.5-1.5 s per situation)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    plot = sweep.add_argument_group("plot")
    plot.add_argument("--plot-output", help="(plot) folder of the PNGs and index.html (default: FOLDER/maps)")
    plot.add_argument("--x", help="(plot) axis across the panels: speed, tau, nu, half_width, mu, or set.KEY")
    plot.add_argument("--y", help="(plot) axis up the panels")
    sweep.set_defaults(func=cmd_sweep)


def _axes(args: argparse.Namespace) -> list[Any]:
    from ..sweep.axes import Axis, parse_axis
    from ..sweep.spec import FLAGS

    axes = []
    for name, text in (("speed", args.speed), ("tau", args.tau), ("half_width", args.obstacle_half_width),
                       ("nu", args.nu), ("mu", args.mu), ("planner", args.planner),
                       ("length", args.obstacle_length), ("duration", args.duration),
                       ("field_margin", args.field_margin)):
        if text is not None:
            axes.append(parse_axis(name, text, FLAGS[name]))
    if args.seeds < 1:
        raise ParamError(f"--seeds {args.seeds!r} is invalid: expected at least 1 seed")
    axes.append(Axis("seed", tuple(range(args.seeds))))
    keys = set()
    for item in args.set:
        key, sep, values = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ParamError(f"--set {item!r} is invalid: expected GROUP.KEY=VALUES")
        if key in keys:
            raise ParamError(f"--set {key} is given twice")
        keys.add(key)
        axes.append(parse_axis(f"set.{key}", values, f"--set {key}"))
    return axes


AXIS_OPTIONS = ("speed", "tau", "obstacle_half_width", "nu", "mu", "planner", "obstacle_length", "duration",
                "field_margin", "samples", "output", "config", "address", "workers", "backend", "timing")
"""Options of a sweep that ``moose sweep plot`` refuses (``--criticality`` too)."""


def cmd_sweep(args: argparse.Namespace) -> int:
    if args.action == "plot":
        given = ([name for name in AXIS_OPTIONS if getattr(args, name) is not None] + (["set"] if args.set else [])
                 + (["criticality"] if args.criticality else []))
        if given:
            flag = "--" + given[0].replace("_", "-")
            raise ParamError(f"{flag} is an option of the sweep, not of 'moose sweep plot DIR' "
                             "(--x, --y, --plot-output)")
        return cmd_plot(args)
    if args.x is not None or args.y is not None or args.plot_output is not None:
        raise ParamError("--x, --y and --plot-output are options of 'moose sweep plot DIR'")
    if args.folder is not None:
        raise ParamError(f"{args.folder!r}: the sweep's folder is -o DIR ('moose sweep plot DIR' draws one)")
    from ..config import load_config
    from ..sweep.backends import DaskBackend, LocalBackend
    from ..sweep.runner import run_sweep
    from ..sweep.spec import SweepSpec
    from ..sweep.store import RunFolder, pyarrow_or_error

    pyarrow_or_error()
    if args.criticality:
        from ..commonroad import require

        require("--criticality")
    config = with_timing(load_config(args.config, "moose sweep"), args)
    spec = SweepSpec(tuple(_axes(args)), config, samples=args.samples, sampling=args.sampling,
                     sampling_seed=args.sampling_seed, criticality=args.criticality)
    if args.mu is not None and ":" in args.mu and args.mu.count(":") == 1:
        print("moose: warning: a sampled --mu builds a maneuver table (about 0.4 s) for every distinct mu, in this "
              "process for --nu and in every worker; a list of frictions is much faster", file=sys.stderr)
    cases = spec.cases()
    short = sum(1 for c in cases if c.duration < c.tau + c.length / c.speed + 0.5)
    if short:
        print(f"moose: warning: {short} of {len(cases)} cases end (--duration) less than 0.5 s after a car at "
              "constant speed would pass the obstacle: they may end stopped_short", file=sys.stderr)
    output = Path(args.output) if args.output else Path("runs") / f"sweep-{time.strftime('%Y%m%d-%H%M%S')}"
    folder = RunFolder.open(output, spec, args.resume)
    folder.rows()
    if folder.damaged:
        lines = ", ".join(map(str, folder.damaged))
        print(f"moose: warning: {output / 'cases.jsonl'}: line(s) {lines} are not rows of a case (cut short by a kill, "
              "or corrupt) and are skipped; a case without a row runs again", file=sys.stderr)
    if (args.backend or ("dask" if args.address else "local")) == "dask":
        if not args.address:
            raise ParamError("--backend dask needs --address tcp://HOST:PORT of the scheduler")
        if args.workers is not None:
            raise ParamError("--workers is for the local backend; a Dask cluster has its own workers")
        backend: Any = DaskBackend(spec.config, args.address, args.timeout, args.connect_timeout,
                                   criticality=spec.criticality)
    else:
        if args.address:
            raise ParamError("--address is for a Dask cluster, not --backend local")
        import os

        backend = LocalBackend(spec.config, args.workers or os.cpu_count() or 1, args.timeout,
                               criticality=spec.criticality)
    try:
        folder.start(spec, len(cases), backend.name)
        print(f"sweep           {len(cases)} cases -> {output}  (backend {backend.name})", file=sys.stderr)
        report = run_sweep(cases, folder, backend, progress=not args.quiet)
    finally:
        close = getattr(backend, "close", None)
        if close is not None:
            close()
    rows = folder.rows()
    failed = [r for r in rows if r["status"] != "done"]
    manifest = folder.manifest() or {}
    manifest["state"] = "interrupted" if report.interrupted or len(rows) < len(cases) else "complete"
    manifest["recorded"] = len(rows)
    folder.write_manifest(manifest)
    rate = report.ran / report.wall_s if report.wall_s > 0 else 0.0
    counts = ", ".join(f"{k} {v}" for k, v in report.outcomes.most_common()) or "none"
    print(f"ran             {report.ran} cases in {report.wall_s:.1f} s ({rate:.1f} cases/s); "
          f"{report.skipped} recorded before")
    print(f"outcomes        {counts}")
    print(f"results         {output / 'results.parquet'}  ({len(rows)} of {len(cases)} cases)")
    if report.interrupted:
        print(f"moose: interrupted: {len(cases) - len(rows)} cases left; rerun the same command with --resume "
              f"(-o {output})", file=sys.stderr)
        return 130
    print(f"maps            moose sweep plot {output}")
    if failed:
        print(f"moose: warning: {len(failed)} cases ended in error, timeout or crashed (their rows say why)",
              file=sys.stderr)
        return 3
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from ..sweep.maps import draw_maps

    if args.folder is None:
        raise ParamError("moose sweep plot needs the sweep's folder: moose sweep plot DIR")
    folder = Path(args.folder)
    out = Path(args.plot_output) if args.plot_output else folder / "maps"
    flag = "--plot-output" if args.plot_output else "the maps folder"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParamError(f"{flag} {str(out)!r} cannot be created: {exc.strerror or exc}") from None
    try:
        report = draw_maps(folder, out, x=args.x, y=args.y)
    except OSError as exc:  # a full disk, a folder made read-only meanwhile: what was drawn stays
        raise OutputError(f"{flag} {str(out)!r}: writing failed ({exc.strerror or exc}); the maps drawn before "
                          "it are there") from None
    print(f"report          {report}")
    return 0
