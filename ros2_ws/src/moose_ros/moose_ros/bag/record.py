"""Record bags: the topics of a running graph (:class:`Recorder`), or a lockstep run (:func:`record_result`)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from ..graph import (
    ACTUATOR_COMMAND,
    BLEND,
    CLOCK,
    DIAGNOSTICS,
    MARKERS,
    OBSTACLES,
    ODOM,
    PLANS,
    REFERENCE,
    STATE,
    TF,
    TF_STATIC,
    THREAT,
    TOPICS,
)
from ..runtime.base import NodeBase
from .errors import BagError
from .params import RunParameters
from .writer import BagWriter


class Recorder:
    """Records topics of a running graph through a runtime node, with the QoS of a tool (the publishers'
    reliability and durability, :attr:`moose_ros.graph.Topic.tool_qos`).

    Messages are stamped on reception with the wall clock, never earlier than the previous one (a step
    of the clock back would otherwise put them out of order).  A timer of the node closes the open chunk once
    it has been open :data:`~moose_ros.bag.writer.CHUNK_SPAN_S`, so a recorder killed with SIGKILL loses at most
    that much, and what it had not yet taken from its subscriptions (:mod:`moose_ros.bag.writer`).  A write
    that fails (a full disk) stops the recording, not the graph: :attr:`error` says why and what the bag
    holds.  ``parameters``: the run's (:class:`~moose_ros.bag.params.RunParameters`), kept in the bag.
    """

    POLL_PERIOD = 0.05
    """Period of the timer that closes chunks (s, wall clock)."""

    def __init__(self, node: NodeBase, path: str | Path, topics: Optional[Sequence[str]] = None,
                 parameters: Optional[RunParameters] = None) -> None:
        chosen = list(topics) if topics else list(TOPICS)
        unknown = [t for t in chosen if t not in TOPICS]
        if unknown:
            raise BagError(f"--topics {unknown[0]!r} is not a topic of the graph; topics: {', '.join(TOPICS)}")
        self.writer = BagWriter(path, custom_data=parameters.as_strings() if parameters is not None else None)
        self.error: Optional[str] = None
        """Why recording stopped before :meth:`close` (a write failed), None while it works."""
        self._serialize = node.serialize  # the runtime's CDR: the same bytes on both runtimes
        self._last_ns = 0
        for topic in chosen:
            TOPICS[topic].tool_subscription(node, self._callback(topic))
        node.timer(self.POLL_PERIOD, lambda: self._guarded(self.writer.poll))

    def _guarded(self, action: Callable[[], None]) -> None:
        """Run a write of the bag; a failure stops the recording and is kept in :attr:`error`."""
        if self.error is not None:
            return
        try:
            action()
        except BagError as exc:
            self.error = str(exc)

    def _callback(self, topic: str) -> Callable[[Any], None]:
        type_name, serialize = TOPICS[topic].type, self._serialize

        def record(msg: Any) -> None:
            self._last_ns = max(time.time_ns(), self._last_ns)
            self._guarded(lambda: self.writer.write(topic, type_name, self._last_ns, serialize(msg)))

        return record

    def close(self) -> None:
        """Close the bag; a failure is kept in :attr:`error` (the bag then ends at its last checkpoint)."""
        self._guarded(self.writer.close)
        if self.error is not None:
            self.writer.close()  # the file, after a failure


def record_result(result: Any, path: str | Path) -> dict[str, int]:
    """Write a lockstep run (``moose simulate``) as a bag on the graph's topics, stamped in simulated time:
    what the graph's nodes would have published (sensor samples, ground truth and /tf, estimates and their
    /tf, threats, plans, blends, markers, references, actuator commands, /clock), a 1 Hz status of the run on
    /diagnostics, the sensor frames on /tf_static, and the run's parameters."""
    from types import SimpleNamespace

    import numpy as np

    from moose.planner.step import blend_path
    from moose.signals import Reference
    from moose.state import INPUT_NAMES, N_MOTION, STATE_NAMES

    from .. import convert as cv
    from ..interfaces import make

    factory = SimpleNamespace(make=make)
    parameters = RunParameters(result.config, result.scenario, result.planner, result.seed)
    writer = BagWriter(path, custom_data=parameters.as_strings())
    entries: list[tuple[int, int, str, Any]] = []

    def add(t: float, topic: str, msg: Any) -> None:
        entries.append((int(round(t * 1e9)), len(entries), topic, msg))

    trace = result.trace
    add(0.0, TF_STATIC.name, cv.static_tf(factory, 0.0))
    for k, t in enumerate(trace["t"]):
        t = float(t)
        clock = make(CLOCK.type)
        clock.clock.sec, clock.clock.nanosec = divmod(int(round(t * 1e9)), 1_000_000_000)
        add(t, CLOCK.name, clock)
        state = np.array([trace[name][k] for name in STATE_NAMES[:N_MOTION]])
        add(t, ODOM.name, cv.odometry_to_msg(factory, t, state))
        add(t, TF.name, cv.truth_tf(factory, t, state))
        reference = Reference(float(trace["delta_ref"][k]), float(trace["vx_ref"][k]))
        add(t, REFERENCE.name, cv.reference_to_msg(factory, t, reference))
        u = np.array([trace[name][k] for name in INPUT_NAMES])
        add(t, ACTUATOR_COMMAND.name, cv.actuator_to_msg(factory, t, reference, u))
    # logged when the stack had them (moose.timing): a sample reaches the observer timing.sensor_delay_s after the
    # sensors handed it over, an estimate is published at its tick; each keeps its own stamp in its header
    for sample in result.samples:
        topic, convert = cv.SENSOR_SAMPLES[type(sample)]
        add(sample.t + result.config.timing.sensor_delay_s, topic.name, convert(factory, sample))
    for t, estimate in zip(trace["t"], result.estimates):
        add(float(t), STATE.name, cv.estimate_to_msg(factory, estimate))
        add(float(t), TF.name, cv.estimate_tf(factory, estimate))
    appeared = next((t for t, threat in result.threats if threat is not None), None)
    if appeared is not None:
        add(appeared, OBSTACLES.name, cv.obstacles_to_msg(factory, appeared, [result.scenario.danger_zone]))
    for t, threat in result.threats:
        add(t, THREAT.name, cv.threat_to_msg(factory, t, threat))
    status = "idle"
    for record in result.planning:
        for kind, plan in (("mpc", record.mpc), ("msf", record.msf)):
            if plan is not None:
                add(record.t, PLANS[kind].name,
                    cv.plan_to_msg(factory, record.t, kind, plan, record.threat is not None))
        add(record.t, BLEND.name, cv.blend_to_msg(factory, record.t, record.blend, record.reference,
                                                     record.delta_mpc))
        estimate = result.estimates[int(round(record.t * result.config.simulation.motion_rate_hz))]  # one per tick
        path_ = blend_path(record.blend, estimate, result.config.grid.t_s)
        add(record.t, MARKERS.name, cv.markers_to_msg(factory, record.t, record.threat, record.mpc, record.msf, path_))
    plans = iter(result.planning)
    record = next(plans, None)
    for k, t in enumerate(trace["t"]):
        t = float(t)
        while record is not None and record.t <= t + 1e-9:
            status = record.mpc.status if record.mpc is not None else "-"
            record = next(plans, None)
        last = k == len(trace["t"]) - 1
        if abs(t - round(t)) < 1e-9 or last:  # 1 Hz, and the end of the run
            values = {"t": f"{t:.2f}", "x": f"{trace['x'][k]:.2f}", "y": f"{trace['y'][k]:.2f}",
                      "weight_mpc": f"{trace['weight_mpc'][k]:.3f}", "mpc_status": status}
            add(t, DIAGNOSTICS.name, cv.diagnostic_to_msg(factory, t, "moose_simulate", 0,
                                                           "finished" if last else "running", values))
    entries.sort(key=lambda e: (e[0], e[1]))
    try:
        for stamp_ns, _order, name, msg in entries:
            writer.write(name, TOPICS[name].type, stamp_ns, bytes(msg.serialize()))
    finally:
        writer.close()
    return dict(writer.counts)


def record_simulation(result: Any, path: str | Path) -> dict[str, int]:
    """``moose simulate``'s bag recorder (entry point group ``moose.recorders``): :func:`record_result`, with
    a bag that cannot be written (its path was checked before the run: a full disk) reported as an
    :class:`~moose.files.OutputError`."""
    from moose.files import OutputError

    try:
        return record_result(result, path)
    except BagError as exc:
        raise OutputError(str(exc)) from None
