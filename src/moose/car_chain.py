"""The FPEV2-Kanon's latency chain, read from config/kanon.dbc: the CAN hops of its sensor and command frames and the
planning computer's solve time (docs/architecture.md, "Closed loop and rates").

The ``car`` timing profile (:func:`moose.timing.profile`) and the defaults of :class:`moose.schema.TimingParams` are
these numbers.  The module is light on purpose (no schema, no CasADi; the DBC's parser only when the hops are not in
the machine's cache), so that the parameter schema can take its defaults from it and :mod:`moose.timing` can build
its profiles on it without either importing the other.
"""
from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import json
import math
import os
import tempfile
from functools import lru_cache
from pathlib import Path

from .resources import DBC_FILE, cache_dir

GRID_S = 0.01
"""The grid the car's chain is rounded to (s): the motion-control tick of the shipped configuration and the period
of the DBC's control frames."""
PAPER_SQP_SOLVE_S = 1.5e-3
"""The paper baseline's time per plan at Table II's caps on this project's reference host (s): the 99th percentile of
``MpcPlanner.plan`` with ``mpc.solver: paper_sqp`` over the nine paper cases, combined planner, 10 s each, three
times (1,512 plans; p99 1.40–1.52 ms, median 0.64–0.67 ms, load average 0.7; the few slower plans, up to 17 ms, are
the shared host's scheduling, which the planning computer's real-time OS does not have)."""
HOST_CLOCK_HZ = 2.596e9
"""The clock of the host :data:`PAPER_SQP_SOLVE_S` was measured on (AMD EPYC, /proc/cpuinfo)."""
MICROLABBOX_CLOCK_HZ = 2.0e9
"""The paper's planning computer: dSPACE MicroLabBox, NXP QorIQ P5020 at 2 GHz (the paper, Sec. VI)."""


@dataclasses.dataclass(frozen=True)
class Hop:
    """One asynchronous periodic CAN hop: a frame period plus the frame's time on the wire."""

    frames: tuple[str, ...]
    period_s: float
    """The frames' common ``GenMsgCycleTime`` (s)."""
    wire_s: float
    """The longest of the frames' worst-case transmission times at the bus's ``Baudrate`` (s)."""

    @property
    def latency_s(self) -> float:
        """Expected latency (s): the wait for the sender's next frame (uniform over a period, mean half of it), the
        wire, and the wait for the receiver's next cycle (another half period on average)."""
        return self.period_s + self.wire_s


@dataclasses.dataclass(frozen=True)
class CarChain:
    """Where the car profile's delays come from (:func:`car_chain`)."""

    sensors: Hop
    """IMU, wheel speeds and EPS angle to the observer."""
    commands: Hop
    """The steering and torque commands to the EPS and the motor ECUs."""
    solve_s: float
    """The paper baseline's solve time scaled to the MicroLabBox's clock (s)."""
    sensor_delay_s: float
    """d_s: one hop of the sensor frames, on the grid."""
    command_delay_s: float
    """d_c: one hop of the command frames, on the grid."""
    planning_delay_s: float
    """d_p: the solve on the MicroLabBox rounded up to the grid, plus the plan's hop."""


def on_grid(value: float, up: bool = False) -> float:
    """``value`` (s) on the :data:`GRID_S` grid: rounded to the nearest point, or up."""
    steps = value / GRID_S
    return round(math.ceil(steps - 1e-9) if up else round(steps)) * GRID_S


@lru_cache(maxsize=1)
def car_chain() -> CarChain:
    """The FPEV2-Kanon's chain from config/kanon.dbc (its frames' ``GenMsgCycleTime`` and the bus's ``Baudrate``):

    * d_s = one hop of the sensor frames (IMU, WHEEL_SPEEDS, EPS_STATUS), to the nearest grid point;
    * d_c = one hop of the command frames (CMD_STEER, CMD_TORQUE), to the nearest grid point;
    * d_p = the paper baseline's solve time on the MicroLabBox (:data:`PAPER_SQP_SOLVE_S` scaled by the clocks),
      rounded up to the grid (the plan is ready at the next tick), plus the hop of the plan to the motion-control
      computer (the AutoBox, on the same bus: the DBC holds no frame for it, so it is given the command frames'
      period).
    """
    sensors, commands = car_hops()
    solve = PAPER_SQP_SOLVE_S * HOST_CLOCK_HZ / MICROLABBOX_CLOCK_HZ
    return CarChain(sensors, commands, solve, sensor_delay_s=on_grid(sensors.latency_s),
                    command_delay_s=on_grid(commands.latency_s),
                    planning_delay_s=on_grid(solve, up=True) + on_grid(commands.latency_s))


SENSOR_FRAMES = ("IMU", "WHEEL_SPEEDS", "EPS_STATUS")
COMMAND_FRAMES = ("CMD_STEER", "CMD_TORQUE")
HOP_SOURCES = ("car_chain.py", "canbus/busload.py", "canbus/codec.py")
"""The modules whose code turns the DBC into the hops: their text is part of the cached hops' key."""


def dbc_hops() -> tuple[Hop, Hop]:
    """The sensor and the command hop, read from config/kanon.dbc with its parser (cantools, python-can)."""
    from .canbus.busload import worst_case_frame_bits
    from .canbus.codec import cycle_time, default_database

    db = default_database()
    baud = int(db.dbc.attributes["Baudrate"].value)

    def hop(names: tuple[str, ...]) -> Hop:
        wire = max(worst_case_frame_bits(db.get_message_by_name(n).length) for n in names) / baud
        return Hop(names, cycle_time(db, *names), wire)

    return hop(SENSOR_FRAMES), hop(COMMAND_FRAMES)


def hops_cache_path() -> Path:
    """Where the hops of the DBC are cached: ``$MOOSE_CACHE_DIR/timing/<key>.json``, the key a SHA-256 of the DBC's
    bytes, the text of :data:`HOP_SOURCES` and the parser's version, so a changed file or code never finds another's
    hops."""
    digest = hashlib.sha256(DBC_FILE.read_bytes() + importlib.metadata.version("cantools").encode())
    here = Path(__file__).parent
    for name in HOP_SOURCES:
        digest.update((here / name).read_bytes())
    return cache_dir() / "timing" / f"{digest.hexdigest()[:32]}.json"


def car_hops() -> tuple[Hop, Hop]:
    """:func:`dbc_hops`, from the disk cache when it holds them: a node process that only needs the delays of the
    ``car`` profile then loads neither cantools nor python-can (about 6 MB of each process's memory; docs/graph.md,
    "Processes").  The cached numbers are the parsed ones bit for bit (JSON keeps a float's every digit); an
    unreadable or malformed entry is read from the DBC again and replaced, written whole (a temporary file renamed)."""
    path = hops_cache_path()
    try:
        cached = json.loads(path.read_text(encoding="utf-8"))
        hops = tuple(Hop(tuple(cached[k]["frames"]), cached[k]["period_s"], cached[k]["wire_s"])
                     for k in ("sensors", "commands"))
        if all(_valid_hop(h, frames) for h, frames in zip(hops, (SENSOR_FRAMES, COMMAND_FRAMES))):
            return hops[0], hops[1]
    except (OSError, ValueError, KeyError, TypeError):  # none yet, or not what this code writes: read the DBC
        pass
    sensors, commands = dbc_hops()
    text = json.dumps({"sensors": dataclasses.asdict(sensors), "commands": dataclasses.asdict(commands)})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, suffix=".json.partial", delete=False,
                                         encoding="utf-8") as handle:
            handle.write(text)
        os.replace(handle.name, path)
    except OSError:
        pass  # a read-only or full cache costs the next process the DBC's parser, nothing else
    return sensors, commands


def _valid_hop(hop: Hop, frames: tuple[str, ...]) -> bool:
    return (hop.frames == frames and all(type(v) is float and 0.0 < v < math.inf for v in (hop.period_s, hop.wire_s)))
