"""The bridge as a service: one bus, a dedicated command sender, a bounded receive, re-open with back-off, diagnostics.

:class:`BridgeRunner` owns a :class:`~moose.canbus.bridge.BridgeCore` and the
:class:`~moose.canbus.bus.BusLink` around its bus; a node shell only forwards commands
(:meth:`~BridgeRunner.command`), publishes the samples :meth:`~BridgeRunner.receive`
returns, and publishes :meth:`~BridgeRunner.diagnostics`.

* **Sender.**  :meth:`~BridgeRunner.start` runs a thread that wakes on absolute deadlines of
  the clock (``time.monotonic()`` by default), one command period apart, and sends the
  frames due (:meth:`~BridgeRunner.send_due`).  It shares nothing with the receive path but
  one lock, which neither side holds during socket I/O, so incoming traffic cannot hold the
  command frames back.  A deadline missed by more than a period is skipped, not made up in
  a burst (the core reports the gap).  There is deliberately no kernel-side periodic
  sending (SocketCAN BCM): a hung bridge process must fall silent, so that the vehicle's
  ECUs time out, instead of the kernel repeating its last command.
* **Receiving.**  :meth:`~BridgeRunner.receive` reads at most ``max_frames_per_cycle``
  frames per call (the node calls it once per command period).  The default bound is what
  a saturated 500 kbit/s bus can carry in one command period, so on the car it never cuts;
  only a software bus (``udp_multicast``, ``virtual``) can deliver more.  What is left waits
  in the socket, whose buffer drops the excess; each cut cycle is counted and flagged
  (RxOverflow in BRIDGE_STATUS, WARN on /diagnostics).
* **Priority.**  :meth:`~BridgeRunner.start` puts the calling thread and the sender under
  SCHED_FIFO at ``realtime_priority`` until :meth:`~BridgeRunner.close` (reset on fork: no
  other thread or child process inherits it).  Both must be real-time: a real-time sender
  alone waits for the GIL held by a preempted normal thread.
* **Time.**  The core, the guard and the bus health run on ``clock``; samples are stamped
  with the ``stamp`` the caller passes (the node's ROS time).  With simulated time, pass
  ``clock=<the node's sim clock>``, do not call :meth:`start`, and call :meth:`send_due`
  from a timer every command period instead.
"""
from __future__ import annotations

import dataclasses
import math
import os
import threading
import time
from typing import Any, Callable, Optional

import can

from moose.params import ParamError, check
from moose.signals import Sample

from .bridge import BridgeCore
from .bus import BITRATE, BusLink, BusParams
from .health import BusState, HealthParams
from .safety import Command, GuardParams, GuardState

OK, WARN, ERROR = 0, 1, 2
"""diagnostic_msgs/DiagnosticStatus levels."""

MIN_FRAME_BITS = 47 + 3
"""Shortest classic CAN frame on the wire: 11-bit identifier, no data, no stuff bits (47), plus interframe space (3)."""


def frames_per_period(period: float, bitrate: int = BITRATE) -> int:
    """Most frames a saturated bus of ``bitrate`` carries in ``period`` seconds."""
    return math.ceil(period * bitrate / MIN_FRAME_BITS)


@dataclasses.dataclass(frozen=True)
class BridgeParams:
    """Everything the bridge is configured with."""

    guard: GuardParams = GuardParams()
    bus: BusParams = BusParams()
    health: HealthParams = HealthParams()
    max_frames_per_cycle: Optional[int] = None
    """Frames read per receive call (one call per command period); ``None``: what a saturated bus carries in
    one command period (100 at 500 kbit/s and 10 ms)."""

    realtime_priority: int = 10
    """SCHED_FIFO priority (1–99) of the threads that run the bridge while it is started — the one that calls
    :meth:`BridgeRunner.start` (call it from the thread that calls :meth:`~BridgeRunner.receive` and
    :meth:`~BridgeRunner.command`) and the sender; 0 keeps the normal scheduler.  Other
    processes then cannot hold the command frames back, and since the work per cycle is bounded
    (``max_frames_per_cycle``) the bridge cannot starve them.  Needs CAP_SYS_NICE or an RLIMIT_RTPRIO at
    least this high; if refused, the bridge runs on the normal scheduler and /diagnostics warns."""

    def __post_init__(self) -> None:
        check("realtime_priority", self.realtime_priority,
              lambda v: isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 99, "an integer in 0..99")
        if self.max_frames_per_cycle is not None:
            check("max_frames_per_cycle", self.max_frames_per_cycle,
                  lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1, "a positive integer")


@dataclasses.dataclass(frozen=True)
class BridgeDiagnostics:
    """What the node publishes on /diagnostics."""

    level: int
    message: str
    values: dict[str, str]


class BridgeRunner:
    """The bridge's I/O around :class:`BridgeCore`; see the module doc for threads and time."""

    def __init__(self, params: BridgeParams = BridgeParams(), *, log: Optional[str] = None,
                 clock: Callable[[], float] = time.monotonic,
                 opener: Optional[Callable[[], can.BusABC]] = None) -> None:
        self.params = params
        self.clock = clock
        self.core = BridgeCore(params.guard, health=params.health)
        self.max_frames = params.max_frames_per_cycle or frames_per_period(self.core.command_period)
        self._lock = threading.Lock()
        self._logger = open_log(log) if log else None
        self.link = BusLink(opener or params.bus.open, self.core.health, self._logger, self._lock)
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.rx_frames = 0
        """Frames read from the bus."""
        self.send_failures = 0
        """Sender cycles whose frames could not all be sent (bus closed or failing)."""
        self.sender_error: Optional[str] = None
        """Why the sender thread ended, if it did on its own (then no frames go out and the ECUs time out)."""
        self.realtime_error: Optional[str] = None
        """Why ``realtime_priority`` could not be applied."""
        self._scheduler: Optional[tuple[int, int, Any]] = None
        """(thread id, policy, parameters) of the thread that called :meth:`start`, to restore at :meth:`close`."""
        self._reported_overflows = 0
        self._reported_late = 0
        self.link.ensure_open(clock())  # a failure is reported and retried after the back-off

    @property
    def open_error(self) -> Optional[str]:
        """Why the bus is closed (its last open or I/O failure), ``None`` while it is open."""
        return None if self.link.bus is not None else self.core.health.last_error or "closed"

    # -- the node's calls -----------------------------------------------------------------

    def start(self) -> None:
        """Raise the calling thread to ``realtime_priority`` and start the sender thread (real time)."""
        if self._thread is not None:
            return
        if self.params.realtime_priority:
            self._enter_realtime(self.params.realtime_priority)
        self._thread = threading.Thread(target=self._send_loop, name="can-bridge-sender", daemon=True)
        self._thread.start()

    def command(self, command: Command) -> None:
        """A command from the motion controller (any values: the guard checks them)."""
        with self._lock:
            self.core.on_command(command)

    def receive(self, stamp: Optional[float] = None) -> list[Sample]:
        """Read at most ``max_frames_per_cycle`` frames; the sensor samples among them, stamped ``stamp``."""
        t = self.clock()
        samples = []
        for frame in self.read(t):
            sample = self.decode(frame, t, stamp)
            if sample is not None:
                samples.append(sample)
        return samples

    def read(self, t: float) -> list[can.Message]:
        """Read at most ``max_frames_per_cycle`` frames at ``t``, undecoded (:meth:`decode` each, in order)."""
        frames, full = self.link.receive(t, self.max_frames)
        with self._lock:
            self.rx_frames += len(frames)
            if full:
                self.core.note_rx_overflow()
        return frames

    def decode(self, frame: can.Message, t: float, stamp: Optional[float] = None) -> Optional[Sample]:
        """One frame read at ``t``: the sensor sample it carries, stamped ``stamp`` (default ``t``), if any."""
        with self._lock:
            return self.core.on_frame(frame, t, stamp)

    def send_due(self, t: Optional[float] = None) -> int:
        """Send the frames due at ``t`` (default: now on the clock); the sender thread's cycle.  Returns how many
        frames went to the bus.

        The command frames go first; the time they were handed to the bus is reported to the core
        before it builds the heartbeat, so a send that lands late is never followed by "commanding".
        """
        t = self.clock() if t is None else t
        with self._lock:
            commands = self.core.command_frames(t)
        sent = self.link.send(commands, t) if commands else True
        count = len(commands) if commands and sent else 0
        with self._lock:
            if commands and sent:
                self.core.note_sent(self.clock())
            status = self.core.status_frames(t)
        if status:
            status_sent = self.link.send(status, t)
            count += len(status) if status_sent else 0
            sent = status_sent and sent
        if not sent:
            with self._lock:
                self.send_failures += 1
        return count

    def diagnostics(self) -> BridgeDiagnostics:
        """Level, message and values for /diagnostics; a flood is reported since the previous call."""
        with self._lock:
            core, guard, health, stats = self.core, self.core.guard, self.core.health, self.core.codec.stats
            overflows, self._reported_overflows = core.rx_overflows - self._reported_overflows, core.rx_overflows
            late, self._reported_late = core.late_commands - self._reported_late, core.late_commands
            values = {
                "state": guard.state.value, "heartbeat": core.heartbeat_state(),
                "command_timeout": str(guard.timed_out), "bus_state": health.state.name.lower(),
                "rx_frames": str(self.rx_frames), "dropped_frames": str(stats.dropped),
                "bad_checksum": str(stats.bad_checksum), "bad_counter": str(stats.bad_counter),
                "rx_overflow_cycles": str(core.rx_overflows), "late_commands": str(core.late_commands),
                "max_command_gap_ms": f"{1e3 * core.max_command_gap:.1f}", "invalid_commands": str(guard.invalid),
                "malformed_datagrams": str(getattr(self.link.bus, "malformed", 0)),
                "send_failures": str(self.send_failures), "io_failures": str(health.io_failures),
                "reopens": str(health.reopens),
            }
            if self.sender_error is not None:
                return BridgeDiagnostics(ERROR, f"command sender stopped: {self.sender_error}", values)
            if health.state == BusState.IO_FAILURE:
                return BridgeDiagnostics(ERROR, f"bus error: {health.last_error}; re-opening after the back-off",
                                         values)
            if core.bus_error:
                return BridgeDiagnostics(ERROR, f"bus error: {health.last_error or health.state.name.lower()}", values)
            problems = [self.realtime_error] if self.realtime_error else []
            if guard.state == GuardState.MINIMUM_RISK:
                problems.append("command timeout: minimum-risk maneuver (steering to straight, braking)")
            elif guard.state == GuardState.STOPPED:
                problems.append("command timeout: stopped by the minimum-risk maneuver")
            if overflows:
                problems.append(f"receive flood: {overflows} cycles hit the {self.max_frames}-frame "
                                "bound, the excess was dropped")
            if late:
                problems.append(f"command frames late {late} times: longest gap {1e3 * core.max_command_gap:.0f} ms")
            if problems:
                return BridgeDiagnostics(WARN, "; ".join(problems), values)
            return BridgeDiagnostics(OK, "idle: no command yet" if guard.state == GuardState.IDLE else "commanding",
                                     values)

    def close(self) -> None:
        """Stop the sender, close the bus and the log, give the starting thread its scheduler back."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        if self._scheduler is not None:
            tid, policy, param = self._scheduler
            self._scheduler = None
            try:
                os.sched_setscheduler(tid, policy, param)
            except OSError:  # the thread has ended
                pass
        self.link.close()
        if self._logger is not None:
            with self._lock:
                self._logger.stop()

    def __enter__(self) -> "BridgeRunner":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- the sender thread ----------------------------------------------------------------

    def _enter_realtime(self, priority: int, restore: bool = True) -> None:
        """SCHED_FIFO for the calling thread; with reset-on-fork, so no thread or process it creates inherits it."""
        try:
            saved = (threading.get_native_id(), os.sched_getscheduler(0), os.sched_getparam(0))
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
            if restore:
                self._scheduler = saved
        except (OSError, AttributeError) as exc:  # no permission, or not Linux
            self.realtime_error = f"not real-time (SCHED_FIFO {priority} refused: {exc})"

    def _send_loop(self) -> None:
        if self.params.realtime_priority:
            self._enter_realtime(self.params.realtime_priority, restore=False)
        try:
            self._send_periodically()
        except Exception as exc:  # noqa: BLE001 - reported on /diagnostics; the silence times the ECUs out
            self.sender_error = f"{type(exc).__name__}: {exc}"

    def _send_periodically(self) -> None:
        period = self.core.command_period
        deadline = self.clock()
        while True:
            wait = deadline - self.clock()
            if self._stop.wait(wait) if wait > 0.0 else self._stop.is_set():
                return
            now = self.clock()
            self.send_due(now)
            deadline += period
            if deadline <= now:  # more than a period behind: skip, do not burst
                deadline = now + period


def open_log(path: str) -> can.io.generic.MessageWriter:
    """python-can's Logger for ``path`` (its suffix picks the format); ParamError naming a bad path."""
    try:
        return can.Logger(str(path))
    except ValueError as exc:  # unknown suffix
        raise ParamError(f"can_log = {str(path)!r} is invalid: {exc}") from None
    except OSError as exc:
        raise ParamError(f"can_log = {str(path)!r} cannot be written: {exc.strerror or exc}") from None
