"""ROS 2 bags (MCAP storage) of the graph: record, read (also after a crash), play, info, export.

Bags are ROS 2 bag directories (``metadata.yaml`` + ``.mcap``) written with rosbags'
rosbag2 writer, CDR messages with their definitions embedded, so ``ros2 bag info/play``
and Foxglove open them.  Crash safety: the recorder closes the pending MCAP chunk and
flushes the file every ``flush_period`` seconds, so a recorder killed with SIGKILL leaves
a file whose completed chunks :func:`read_bag` recovers (no ``metadata.yaml`` and no
MCAP footer are needed then).  SIGINT/SIGTERM close the bag cleanly.
"""
from __future__ import annotations

import csv
import math
import os
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Optional, Sequence

from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from .graph import TOPICS
from .interfaces import from_rosbags, typestore

TOPIC_TYPES = {name: topic.type for name, topic in TOPICS.items()}
"""Every topic of the graph and its type (:mod:`moose_ros.graph`)."""


class BagError(RuntimeError):
    """A bag cannot be written or read; the message says which path and why."""


class BagWriter:
    """A ROS 2 bag directory with MCAP storage, flushed chunk by chunk."""

    def __init__(self, path: str | Path, flush_period: float = 1.0) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"bag {str(self.path)!r} exists already: choose another output directory")
        parent = self.path.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise BagError(f"bag {str(self.path)!r} cannot be written: {exc.strerror or exc}") from None
        if not os.access(parent, os.W_OK):
            raise BagError(f"bag {str(self.path)!r} cannot be written: {str(parent)!r} is not writable")
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except OSError as exc:
            raise BagError(f"bag {str(self.path)!r} cannot be written: {exc.strerror}") from None
        self._connections: dict[str, Any] = {}
        self._store = typestore()
        self.flush_period = flush_period
        self._last_flush = time.monotonic()
        self.counts: dict[str, int] = defaultdict(int)

    def write(self, topic: str, type_name: str, timestamp_ns: int, cdr: bytes) -> None:
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._writer.add_connection(topic, type_name, typestore=self._store)
            self._connections[topic] = connection
        try:
            self._writer.write(connection, int(timestamp_ns), cdr)
        except OSError as exc:
            raise BagError(f"bag {str(self.path)!r}: write failed ({exc.strerror}); the bag is readable up to here") from None
        self.counts[topic] += 1
        if time.monotonic() - self._last_flush >= self.flush_period:
            self.flush()

    def flush(self) -> None:
        """Close the pending MCAP chunk and push it to the disk (what survives a SIGKILL)."""
        storage = self._writer.storage
        if storage is not None and storage.chunk.bio.tell():
            storage.close_chunk()
        if storage is not None:
            storage.bio.flush()
            os.fsync(storage.bio.fileno())
        self._last_flush = time.monotonic()

    def close(self) -> None:
        self._writer.close()


class Recorder:
    """Records topics of a running graph through a DDS node of the runtime."""

    def __init__(self, node: Any, path: str | Path, topics: Optional[Sequence[str]] = None) -> None:
        chosen = list(topics) if topics else list(TOPIC_TYPES)
        unknown = [t for t in chosen if t not in TOPIC_TYPES]
        if unknown:
            raise BagError(f"--topics {unknown[0]!r} is not a topic of the graph; topics: {', '.join(TOPIC_TYPES)}")
        self.writer = BagWriter(path)
        for topic in chosen:
            TOPICS[topic].subscription(node, self._callback(topic))  # the subscribers' QoS of the contract

    def _callback(self, topic: str):
        type_name = TOPIC_TYPES[topic]

        def record(msg: Any) -> None:
            self.writer.write(topic, type_name, time.time_ns(), bytes(msg.serialize()))

        return record

    def close(self) -> None:
        self.writer.close()


@dataclass(frozen=True)
class BagMessage:
    topic: str
    type_name: str
    timestamp_ns: int
    msg: Any
    """The rosbags message (fields by their .msg names)."""


def read_bag(path: str | Path, topics: Optional[Sequence[str]] = None) -> Iterator[BagMessage]:
    """Messages of a bag in time order; a bag without metadata (a crashed recorder) is recovered."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"bag {str(path)!r} does not exist")
    store = typestore()
    wanted = set(topics) if topics else None
    if (path / "metadata.yaml").is_file():
        try:
            with Reader(path) as reader:
                connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
                for connection, timestamp, raw in reader.messages(connections=connections):
                    yield BagMessage(connection.topic, connection.msgtype, timestamp,
                                     store.deserialize_cdr(raw, connection.msgtype))
            return
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds; recover or explain below
            files = sorted(path.glob("*.mcap"))
            if not files:
                raise BagError(f"bag {str(path)!r} is unreadable: {exc}") from None
    yield from _recover(path, wanted)


def _recover(path: Path, wanted: Optional[set[str]]) -> Iterator[BagMessage]:
    """Read the complete chunks of an unfinished MCAP file (stream reading, no footer needed)."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    if not files:
        raise BagError(f"bag {str(path)!r} has neither metadata.yaml nor an .mcap file")
    store = typestore()
    found = False
    for file in files:
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        messages: list[BagMessage] = []
        with open(file, "rb") as stream:
            try:
                for record in StreamReader(stream, skip_magic=False).records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record.name
                    elif isinstance(record, Channel):
                        channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                    elif isinstance(record, Message) and record.channel_id in channels:
                        topic, type_name = channels[record.channel_id]
                        if wanted is None or topic in wanted:
                            messages.append(BagMessage(topic, type_name, record.log_time,
                                                       store.deserialize_cdr(record.data, type_name)))
            except (McapError, EOFError, ValueError, KeyError, AssertionError) as exc:
                if not messages and not channels:
                    raise BagError(f"bag file {str(file)!r} is not a readable MCAP file: {exc}") from None
            found = found or bool(channels)
        messages.sort(key=lambda m: m.timestamp_ns)
        yield from messages
    if not found:
        raise BagError(f"bag {str(path)!r} holds no complete chunk")


def bag_info(path: str | Path) -> dict[str, Any]:
    """Topics, types, counts, rates (Hz) and duration (s)."""
    stats: dict[str, dict[str, Any]] = {}
    first = last = None
    for m in read_bag(path):
        entry = stats.setdefault(m.topic, {"type": m.type_name, "count": 0, "first": m.timestamp_ns, "last": m.timestamp_ns})
        entry["count"] += 1
        entry["last"] = m.timestamp_ns
        first = m.timestamp_ns if first is None else min(first, m.timestamp_ns)
        last = m.timestamp_ns if last is None else max(last, m.timestamp_ns)
    duration = (last - first) * 1e-9 if first is not None else 0.0
    topics = {}
    for topic, e in sorted(stats.items()):
        span = (e["last"] - e["first"]) * 1e-9
        topics[topic] = {"type": e["type"], "count": e["count"], "rate_hz": (e["count"] - 1) / span if span > 0 else math.nan}
    return {"path": str(path), "duration_s": duration, "messages": sum(e["count"] for e in stats.values()), "topics": topics}


def flatten(msg: Any, prefix: str = "") -> dict[str, Any]:
    """Message fields as ``a.b.c`` columns (sequences as ``name[i]``)."""
    out: dict[str, Any] = {}
    fields = getattr(msg, "__dataclass_fields__", None)
    if fields is None:
        return {prefix.rstrip("."): msg}
    for name in fields:
        if name == "__msgtype__":
            continue
        value = getattr(msg, name)
        key = f"{prefix}{name}"
        if hasattr(value, "__dataclass_fields__"):
            out.update(flatten(value, key + "."))
        elif hasattr(value, "__len__") and not isinstance(value, (str, bytes)):
            for i, item in enumerate(value):
                if hasattr(item, "__dataclass_fields__"):
                    out.update(flatten(item, f"{key}[{i}]."))
                else:
                    out[f"{key}[{i}]"] = item.item() if hasattr(item, "item") else item
        else:
            out[key] = value.item() if hasattr(value, "item") else value
    return out


def export(path: str | Path, out_dir: str | Path, topics: Optional[Sequence[str]] = None,
           fmt: str = "csv") -> list[Path]:
    """One file per topic (CSV or Parquet): ``timestamp_ns`` and the flattened fields."""
    if fmt not in ("csv", "parquet"):
        raise BagError(f"format = {fmt!r} is invalid: expected 'csv' or 'parquet'")
    rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for m in read_bag(path, topics):
        rows[m.topic].append({"timestamp_ns": m.timestamp_ns, **flatten(m.msg)})
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for topic, items in rows.items():
        columns: list[str] = []
        for row in items:
            columns.extend(k for k in row if k not in columns)
        target = out_dir / (topic.strip("/").replace("/", "__") + "." + fmt)
        if fmt == "csv":
            with open(target, "w", newline="", encoding="utf-8") as handle:
                writer = csv.DictWriter(handle, fieldnames=columns)
                writer.writeheader()
                writer.writerows(items)
        else:
            import pyarrow as pa
            import pyarrow.parquet as pq

            table = pa.Table.from_pylist([{c: row.get(c) for c in columns} for row in items])
            pq.write_table(table, target)
        written.append(target)
    return written


def play(path: str | Path, node: Any, rate: float = 1.0, topics: Optional[Sequence[str]] = None, loop: bool = False,
         start: float = 0.0, clock: bool = False, stop: Optional[Any] = None) -> int:
    """Publish a bag's messages with their original timing (scaled by ``rate``); returns the count sent."""
    from .graph import CLOCK
    from .runtime import QOS_DEFAULT

    messages = list(read_bag(path, topics))
    if not messages:
        raise BagError(f"bag {str(path)!r} has no messages on {list(topics) if topics else 'any topic'}")
    publishers: dict[str, Any] = {}
    clock_pub = CLOCK.publisher(node) if clock else None
    t0 = messages[0].timestamp_ns + int(start * 1e9)
    sent = 0
    while True:
        wall0 = time.monotonic()
        for m in messages:
            if m.timestamp_ns < t0:
                continue
            if stop is not None and stop.is_set():
                return sent
            delay = (m.timestamp_ns - t0) * 1e-9 / rate - (time.monotonic() - wall0)
            if delay > 0:
                time.sleep(delay)
            if m.topic not in publishers:
                # reliable, so the player drops nothing (a reliable writer matches best-effort readers too); latched
                # topics keep their durability (a volatile writer never matches a transient-local reader)
                contract = TOPICS.get(m.topic)
                latched = contract is not None and contract.qos.transient_local
                publishers[m.topic] = node.publisher(m.type_name, m.topic, contract.qos if latched else QOS_DEFAULT)
            if clock_pub is not None:
                c = node.make(CLOCK.type)
                c.clock.sec, c.clock.nanosec = divmod(m.timestamp_ns, 1_000_000_000)
                clock_pub(c)
            publishers[m.topic](from_rosbags(m.msg, m.type_name))
            sent += 1
        if not loop:
            return sent


def record_result(result: Any, path: str | Path) -> dict[str, int]:
    """Write a lockstep run (``moose simulate``) as a bag on the graph's topics, stamped in simulated time."""
    from types import SimpleNamespace

    import numpy as np

    from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

    from . import convert as cv
    from .interfaces import make

    factory = SimpleNamespace(make=make)
    writer = BagWriter(path)
    entries: list[tuple[int, str, Any]] = []

    def add(t: float, topic: str, msg: Any) -> None:
        entries.append((int(round(t * 1e9)), topic, msg))

    kinds = {ImuSample: ("/vehicle/imu", cv.imu_to_msg), GpsSample: ("/vehicle/gps", cv.gps_to_msg),
             WheelSpeedSample: ("/vehicle/wheel_speeds", cv.wheels_to_msg), EpsSample: ("/vehicle/steering", cv.steering_to_msg)}
    for sample in result.samples:
        topic, convert = kinds[type(sample)]
        add(sample.t, topic, convert(factory, sample))
    trace = result.trace
    columns = ("x", "y", "theta", "vx", "vy", "gamma")
    for k, t in enumerate(trace["t"]):
        add(float(t), "/vehicle/odom", cv.odometry_to_msg(factory, float(t), np.array([trace[c][k] for c in columns])))
    for estimate in result.estimates:
        add(estimate.t, "/perception/state", cv.estimate_to_msg(factory, estimate))
    appeared = next((t for t, threat in result.threats if threat is not None), None)
    if appeared is not None:
        add(appeared, "/perception/obstacles", cv.obstacles_to_msg(factory, appeared, [result.scenario.danger_zone]))
    for t, threat in result.threats:
        add(t, "/perception/threat", cv.threat_to_msg(factory, t, threat))
    for record in result.planning:
        if record.mpc is not None:
            add(record.t, "/planning/mpc", cv.plan_to_msg(factory, record.t, "mpc", record.mpc))
        if record.msf is not None:
            add(record.t, "/planning/msf", cv.plan_to_msg(factory, record.t, "msf", record.msf))
        add(record.t, "/planning/blend", cv.blend_to_msg(factory, record.t, record.blend, record.reference))
    entries.sort(key=lambda e: e[0])
    try:
        for stamp_ns, topic, msg in entries:
            writer.write(topic, TOPIC_TYPES[topic], stamp_ns, bytes(msg.serialize()))
    finally:
        writer.close()
    return dict(writer.counts)


def record_simulation(result: Any, path: str | Path) -> dict[str, int]:
    """``moose simulate``'s bag recorder (entry point group ``moose.recorders``): :func:`record_result`, with
    a bag that cannot be written reported as a :class:`~moose.params.ParamError`."""
    from moose.params import ParamError

    try:
        return record_result(result, path)
    except BagError as exc:
        raise ParamError(str(exc)) from None


def replan(path: str | Path, config: Any, planner: str = "combined", v_des: Optional[float] = None) -> dict[str, Any]:
    """Run the planners open-loop on a bag's recorded state/threat stream at its planning instants.

    Each instant (a recorded /planning/blend) gets the latest recorded estimate and threat;
    the MPC's initial guess is the *re-computed* previous blend, shifted; ``v_des`` defaults
    to the speed at the first recorded estimate.  Returns per-step
    rows (recorded vs re-computed first accelerations, weights, statuses) and a summary.
    """
    import numpy as np

    from moose.fbl import FeedbackLinearization
    from moose.maneuver import MaxSteeringTable
    from moose.mpc import MpcPlanner
    from moose.msf import MsfPlanner
    from moose.signals import Blend, PlannerInput
    from moose.weight import WeightFunction

    from . import convert as cv

    table = MaxSteeringTable.build(config.vehicle, config.maneuver)
    mpc = MpcPlanner(config.mpc, config.vehicle) if planner != "msf" else None
    msf = MsfPlanner(config.msf, table, config.vehicle) if planner != "mpc" else None
    weight = WeightFunction(config.weight, config.vehicle)
    fbl = FeedbackLinearization(config.fbl, config.vehicle)
    estimate = threat = guess = None
    recorded_plans: dict[str, dict[float, Any]] = {"mpc": {}, "msf": {}}
    rows = []
    for m in read_bag(path, ["/perception/state", "/perception/threat", "/planning/mpc", "/planning/msf", "/planning/blend"]):
        msg = from_rosbags(m.msg, m.type_name)
        if m.topic == "/perception/state":
            estimate = cv.estimate_from_msg(msg)
            v_des = round(estimate.vx, 1) if v_des is None else v_des
        elif m.topic == "/perception/threat":
            threat = cv.threat_from_msg(msg)
        elif m.topic in ("/planning/mpc", "/planning/msf"):
            recorded_plans[msg.planner][round(cv.time_of(msg), 6)] = cv.plan_from_msg(msg)
        elif estimate is not None:
            t = cv.time_of(msg)
            inp = PlannerInput(t, estimate, threat, float(v_des), guess)
            new_mpc = mpc.plan(inp) if mpc is not None else None
            new_msf = msf.plan(inp) if msf is not None else None
            if planner == "combined":
                blend = weight.blend(new_mpc, new_msf, threat, estimate)
            elif planner == "mpc":
                blend = Blend(1.0, new_mpc.accel)
            else:
                blend = Blend(0.0, new_msf.accel)
            guess = weight.next_initial_guess(blend)
            old_mpc = recorded_plans["mpc"].get(round(t, 6))
            rows.append({
                "t": t,
                "recorded_weight": msg.weight_mpc, "weight": blend.weight_mpc,
                "recorded_ax": msg.accel_x[0], "ax": float(blend.accel[0, 0]),
                "recorded_ay": msg.accel_y[0], "ay": float(blend.accel[0, 1]),
                "recorded_delta": msg.delta_ref, "delta": fbl.reference(blend.accel[0], estimate).delta,
                "recorded_mpc_status": old_mpc.status if old_mpc is not None else "",
                "mpc_status": new_mpc.status if new_mpc is not None else "",
                "mpc_solve_ms": new_mpc.solve_time_s * 1e3 if new_mpc is not None else math.nan,
            })
    if not rows:
        raise BagError(f"bag {str(path)!r} has no planning instants (/planning/blend with /perception/state)")
    diff = lambda a, b: float(np.sqrt(np.mean([(r[a] - r[b]) ** 2 for r in rows])))  # noqa: E731
    same = [r for r in rows if r["recorded_mpc_status"]]
    summary = {
        "steps": len(rows), "planner": planner,
        "rms_ax": diff("recorded_ax", "ax"), "rms_ay": diff("recorded_ay", "ay"),
        "rms_weight": diff("recorded_weight", "weight"), "rms_delta": diff("recorded_delta", "delta"),
        "mpc_status_agreement": (sum(r["recorded_mpc_status"] == r["mpc_status"] for r in same) / len(same)) if same else None,
    }
    return {"summary": summary, "rows": rows}


def plot_replan(rows: list[dict[str, Any]], path: str | Path) -> Path:
    """Recorded vs re-computed blend acceleration, weight and steering reference over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = [r["t"] for r in rows]
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 7.0), sharex=True)
    for ax, (key, label) in zip(axes, (("ay", "v̇_Y* (m/s²)"), ("weight", "w_MPC"), ("delta", "δ* (rad)"))):
        ax.step(t, [r[f"recorded_{key}"] for r in rows], where="post", label="recorded")
        ax.step(t, [r[key] for r in rows], where="post", label="re-computed", linestyle="--")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, frameon=False)
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
