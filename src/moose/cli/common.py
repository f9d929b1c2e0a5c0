"""Arguments and helpers that several commands share (this package's and plugins'): scenario flags, output paths
checked before a run starts.  The exit statuses live with the verdicts (:mod:`moose.verdict`)."""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from ..params import ParamError
from ..scenario import DEFAULT_SCENARIO
from ..schema import PLANNER_MODES
from ..timing import PROFILES


class Interrupts:
    """Ctrl-C that cannot be lost.  Python raises KeyboardInterrupt wherever the main thread is; inside a C
    extension's call (CasADi's ``__array__`` under ``numpy.asarray``) it can surface as a SystemError or be
    swallowed, and the run went on to print a verdict and exit 0.  While installed, every SIGINT is also
    remembered, and :meth:`check` raises it again before anything claims to be a complete result."""

    def __init__(self) -> None:
        self.count = 0
        self._previous: Any = None

    def _on_sigint(self, signum: int, frame: Any) -> None:
        self.count += 1
        raise KeyboardInterrupt

    def install(self) -> None:
        """Take SIGINT over when it has Python's default handler (not when the parent ignores it)."""
        import signal
        import threading

        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._on_sigint)

    def uninstall(self) -> None:
        import signal

        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None

    def check(self) -> None:
        """KeyboardInterrupt if Ctrl-C came since :meth:`install`, even if something swallowed it."""
        if self.count:
            raise KeyboardInterrupt


INTERRUPTS = Interrupts()
"""The ``moose`` command's (installed by :func:`moose.cli.main`)."""


def positive_float(text: str) -> float:
    """argparse type: a finite positive number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite positive number")
    return value


def non_negative_float(text: str) -> float:
    """argparse type: a number ≥ 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value >= 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} must not be negative")
    return value


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0 (a seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be a non-negative integer")
    return value


def planner_list(text: str) -> list[str]:
    """argparse type: planner modes separated by commas, each one of :data:`moose.schema.PLANNER_MODES`."""
    names = [name.strip() for name in text.split(",")]
    for name in names:
        if name not in PLANNER_MODES:
            raise argparse.ArgumentTypeError(f"{name!r} is not a planner: expected one of {', '.join(PLANNER_MODES)}")
    return names


def check_output_file(flag: str, path: Optional[str], suffixes: Optional[Sequence[str]] = None) -> Optional[Path]:
    """``path`` as the output file of ``flag``, checked before any work starts (so nothing is lost at the end of a
    run): not empty, not a directory, a known suffix (when ``suffixes`` are given), and actually writable — its
    folder is created and the file itself created and removed again (an existing file is opened for appending,
    which leaves it unchanged).  ``None`` stays ``None``; a problem is a :class:`ParamError` naming the flag."""
    if path is None:
        return None
    if not path.strip():
        raise ParamError(f"{flag} {path!r} is invalid: expected a file path")
    target = Path(path)
    if suffixes is not None and target.suffix.lower().lstrip(".") not in suffixes:
        raise ParamError(f"{flag} {path!r} is invalid: expected a file ending in one of "
                         f"{', '.join('.' + s for s in suffixes)}")
    try:
        if target.is_dir():
            raise ParamError(f"{flag} {path!r} is invalid: it is a directory, expected a file")
        if target.exists():
            if not target.is_file():
                raise ParamError(f"{flag} {path!r} is invalid: not a regular file")
            with open(target, "ab"):
                pass
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            with open(target, "xb"):
                pass
            target.unlink()
    except OSError as exc:
        raise ParamError(f"{flag} {path!r} cannot be written: {exc.strerror or exc}") from None
    return target


def write_output(flag: str, path: Path, write: Callable[[Path], Any]) -> Optional[str]:
    """Write the output file ``path`` of finished work through ``write(tmp)``, whole or not at all
    (:func:`moose.files.replaced_atomically`); ``None`` when written, else why not (a full disk), naming ``flag``."""
    from ..files import replaced_atomically

    try:
        with replaced_atomically(path) as tmp:
            write(tmp)
    except OSError as exc:
        return f"{flag} {str(path)!r}: writing failed ({exc.strerror or exc}); nothing was written there"
    return None


def check_output_dir(flag: str, path: Optional[str | Path]) -> Optional[Path]:
    """``path`` as a new output directory of ``flag`` (a bag), checked before any work starts: it must not exist,
    and it can be created (it is created and removed again, its parents are kept).  ``None`` stays ``None``."""
    if path is None:
        return None
    if not str(path).strip():
        raise ParamError(f"{flag} {str(path)!r} is invalid: expected a directory path")
    target = Path(path)
    try:
        if target.exists() or target.is_symlink():
            raise ParamError(f"{flag} {str(path)!r} exists already: choose another output directory")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.mkdir()
        target.rmdir()
    except OSError as exc:
        raise ParamError(f"{flag} {str(path)!r} cannot be created: {exc.strerror or exc}") from None
    return target


def plot_suffixes() -> list[str]:
    """The file types the figure can be written as (matplotlib's)."""
    from matplotlib.figure import Figure

    return sorted(Figure().canvas.get_supported_filetypes())


def add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    """Scenario selection shared by ``simulate`` and ``launch``."""
    group = parser.add_argument_group("scenario (a file or an ad-hoc moose test)")
    group.add_argument("--scenario", help=f"name in config/scenarios or a YAML path (default {DEFAULT_SCENARIO})")
    group.add_argument("--commonroad", metavar="FILE.xml",
                       help="a CommonRoad scenario (one static obstacle ahead on a straight road) as the moose test")
    group.add_argument("--speed", type=positive_float, help="ad-hoc test: speed at detection and desired speed (m/s)")
    group.add_argument("--tau", type=positive_float, help="ad-hoc test: time to collision at appearance (s)")
    group.add_argument("--obstacle-half-width", type=positive_float, help="ad-hoc test: danger-zone half width (m)")
    group.add_argument("--obstacle-length", type=positive_float, default=2.0, help="ad-hoc test: length (m)")
    group.add_argument("--field-margin", type=non_negative_float,
                       help="ad-hoc test: widen the field to |y| <= half width + this (m; default: the paper's field)")
    group.add_argument("--duration", type=positive_float, help="simulated seconds after the obstacle appears")
    group.add_argument("--config", help="ROS 2 parameter file (default config/moose.yaml)")
    group.add_argument("--planner", choices=PLANNER_MODES, help="planner driving the car")
    group.add_argument("--mu", type=positive_float, help="friction coefficient of the road (the plant's)")
    group.add_argument("--mu-estimate", type=positive_float,
                       help="friction the stack assumes, when it differs from the road's (a robustness experiment)")
    group.add_argument("--seed", type=non_negative_int, default=0, help="seed of the sensor noise (an integer >= 0)")


def add_timing_argument(parser: Any) -> None:
    """``--timing PROFILE``: the latency chain of ``simulate``, ``sweep`` and ``reproduce``."""
    parser.add_argument("--timing", choices=PROFILES,
                        help="the latency chain: ideal (none) or car (the FPEV2-Kanon's, from config/kanon.dbc); "
                             "replaces the configuration's timing delays (docs/architecture.md, "
                             "'Closed loop and rates'); "
                             "--set timing.KEY=VALUE changes one of them after it")


def with_timing(config: Any, args: Any) -> Any:
    """``config`` with the delays of ``--timing`` (its ``compensate`` kept), or unchanged without the flag."""
    import dataclasses

    from ..timing import profile

    if getattr(args, "timing", None) is None:
        return config
    return dataclasses.replace(config, timing=profile(args.timing, config.timing.compensate))


def run_config(args: Any, reader: str) -> Any:
    """The configuration of a run of the command ``reader``: ``--config`` (or the shipped file), then ``--timing``,
    then every ``--set``, then ``--mu-estimate``."""
    from ..config import load_config, with_overrides

    config = with_timing(load_config(args.config, reader), args)
    settings = getattr(args, "set", None)
    if settings:
        config = with_overrides(config, parse_settings(settings))
    return configure(config, args)


def parse_settings(items: list[str]) -> dict[str, Any]:
    """``GROUP.KEY=VALUE`` items as a mapping (values are YAML scalars: numbers, true/false, names)."""
    import yaml

    settings: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ParamError(f"--set {item!r} is invalid: expected GROUP.KEY=VALUE")
        try:
            settings[key.strip()] = yaml.safe_load(text)
        except yaml.YAMLError:
            settings[key.strip()] = text
    return settings


def configure(config: Any, args: Any) -> Any:
    """``config`` with the arguments that change it: ``--mu-estimate`` sets ``planning.mu_estimate``."""
    import dataclasses

    if getattr(args, "mu_estimate", None) is None:
        return config
    return dataclasses.replace(config, planning=dataclasses.replace(config.planning, mu_estimate=args.mu_estimate))


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
