"""Bridge core: actuator commands → guarded command frames; vehicle frames → sensor samples.

Pure logic, time passed in (a monotonic time: the runner's ``time.monotonic()``, or simulated
time in lockstep).  ``on_command`` takes the motion controller's command; ``tick(t)``
returns the frames due at t: CMD_STEER and CMD_TORQUE every command period through the
:class:`~moose.canbus.safety.CommandGuard`, BRIDGE_HEARTBEAT and BRIDGE_STATUS every
status period (both periods are the DBC's ``GenMsgCycleTime``).  ``on_frame`` validates a
received frame and returns the core's sample record, or ``None`` — a dropped frame is
counted in ``codec.stats``, an error frame goes to ``health`` — and never raises.
Nothing a caller passes makes ``tick`` raise: the guard's output is finite and inside
limits that :func:`check_limits_encodable` proved encodable at start-up.

The heartbeat says ``commanding`` only while the guard follows a fresh command *and* the
command frames go out on time: a gap between two command ticks longer than the guard's
timeout less one command period (the sender was stalled; the vehicle's ECUs, whose timeout
is at least the guard's, may have timed out by the time the frames land) makes the heartbeat
of that tick or the next say ``fault`` and sets TxLate in BRIDGE_STATUS; so does such a gap
between two hand-overs of command frames to the bus (:meth:`note_sent`), which the I/O shell
reports before it asks for the status frames of the same cycle.  A receive path that hit its
per-cycle bound (a flood, :meth:`note_rx_overflow`) sets RxOverflow.

The python-can I/O around the core is :class:`moose.canbus.runner.BridgeRunner`.
"""
from __future__ import annotations

import math
from typing import Any, Optional

import can

from moose.params import ParamError
from moose.signals import EpsSample, GpsSample, ImuSample, Sample, WheelSpeedSample

from .codec import Codec, cycle_time
from .health import BusHealth, BusState, HealthParams
from .safety import Command, CommandGuard, GuardParams

HEARTBEAT_STATE = {"commanding": 0, "safe_state": 1, "fault": 2}
GPS_PAIR_WINDOW = 0.1
"""Longest time between a fix's GPS_POSITION and GPS_VELOCITY frames (s); they are sent back to back."""
LIMIT_SIGNALS = {("CMD_STEER", "SteerAngleCmd"): "delta_max", ("CMD_STEER", "SteerRateCmd"): "steer_rate_limit",
                 ("CMD_TORQUE", "TorqueRL"): "torque_max", ("CMD_TORQUE", "TorqueRR"): "torque_max"}
"""Each command signal and the guard limit its range must contain."""
_EPS = 1e-9
DEFAULT_GUARD = GuardParams()
DEFAULT_HEALTH = HealthParams()


def check_limits_encodable(db: Any, params: GuardParams) -> None:
    """ParamError unless every command signal can carry ±(its guard limit): the DBC's ranges contain the limits."""
    for (frame, signal_name), limit_name in LIMIT_SIGNALS.items():
        limit = getattr(params, limit_name)
        message = db.get_message_by_name(frame)
        signal = message.get_signal_by_name(signal_name)
        for value in (-limit, limit):
            values = {s.name: 0 for s in message.signals}
            values[signal_name] = value
            try:
                message.encode(values, strict=True)
            except Exception as exc:  # noqa: BLE001 - cantools raises several types for a value it cannot carry
                raise ParamError(
                    f"{limit_name} = {limit!r} is invalid: {frame}.{signal_name} (range [{signal.minimum}, "
                    f"{signal.maximum}]) cannot carry {value!r}: {exc}") from None


class BridgeCore:
    """The bridge between the motion controller and the vehicle bus (config/kanon.dbc)."""

    def __init__(self, guard: GuardParams = DEFAULT_GUARD, codec: Optional[Codec] = None,
                 health: HealthParams = DEFAULT_HEALTH) -> None:
        self.codec = codec or Codec(node="BRIDGE")
        self.command_period = cycle_time(self.codec.db, "CMD_STEER", "CMD_TORQUE")
        self.status_period = cycle_time(self.codec.db, "BRIDGE_HEARTBEAT", "BRIDGE_STATUS")
        check_limits_encodable(self.codec.db, guard)
        self.guard = CommandGuard(guard, self.command_period)
        self.health = BusHealth(health)
        self._external_bus_error = False
        self._next: dict[str, Optional[float]] = {"command": None, "status": None}
        self._alive = 0
        self._gps_position: Optional[tuple[int, float, float, float]] = None
        self._last_command_tick: Optional[float] = None
        self._last_command_sent: Optional[float] = None
        self.max_command_gap = 0.0
        """Longest time between two command ticks or hand-overs to the bus (s, caller's clock)."""
        self.late_commands = 0
        """Command ticks or hand-overs later than :attr:`late_after` after the previous one."""
        self.late_after = self.guard.params.timeout - self.command_period
        """A gap between command frames beyond which they are late (s): the timeout less one period."""
        self.rx_overflows = 0
        """Receive cycles that hit the per-cycle frame bound (:meth:`note_rx_overflow`)."""
        self._late = False
        self._overflow = False

    @property
    def bus_error(self) -> bool:
        """The bus is failing: bus-off or a failing bus object (from ``health``, or set by a node shell)."""
        return self._external_bus_error or self.health.fault

    @bus_error.setter
    def bus_error(self, value: bool) -> None:
        self._external_bus_error = bool(value)

    def on_command(self, command: Command, t: Optional[float] = None) -> None:
        """A command from the motion controller.  ``t`` is not needed: the guard ages commands itself."""
        self.guard.receive(command)

    def note_rx_overflow(self) -> None:
        """The receive path read its per-cycle bound of frames and left the rest (a flood)."""
        self.rx_overflows += 1
        self._overflow = True

    def heartbeat_state(self) -> str:
        if self.bus_error or self._late:
            return "fault"
        return "safe_state" if self.guard.timed_out else "commanding"

    def _due(self, name: str, t: float, period: float) -> bool:
        """Whether the frames ``name`` are due at t.

        Due from half a command period before the scheduled time (a sender that wakes a little
        early keeps the phase); a caller more than a period late restarts the schedule from t, and
        so does a clock that stepped back.
        """
        due, slack = self._next[name], 0.5 * self.command_period
        if due is not None and t < due - period:  # the caller's clock went back
            due = None
        if due is not None and t + slack < due:
            return False
        nxt = t + period if due is None else due + period
        self._next[name] = nxt if nxt > t + slack else t + period
        return True

    def tick(self, t: float) -> list[can.Message]:
        """The frames due at ``t``: :meth:`command_frames`, then :meth:`status_frames`."""
        return self.command_frames(t) + self.status_frames(t)

    def command_frames(self, t: float) -> list[can.Message]:
        """CMD_STEER and CMD_TORQUE if a command period is due at ``t`` (the guard's output), else []."""
        if not math.isfinite(t) or not self._due("command", t, self.command_period):
            return []
        previous, self._last_command_tick = self._last_command_tick, t
        if previous is not None and t > previous:
            self._gap(t - previous)
        out = self.guard.output(t)
        return [self.codec.encode("CMD_STEER", {"SteerAngleCmd": out.steering_angle,
                                                "SteerRateCmd": out.steering_rate}, t),
                self.codec.encode("CMD_TORQUE", {"TorqueRL": out.torque_rl, "TorqueRR": out.torque_rr}, t)]

    def note_sent(self, t: float) -> None:
        """The command frames were handed to the bus at ``t``: a gap since the previous hand-over counts as
        late like a gap between ticks (a send delayed after its tick is caught before the status frames
        are built)."""
        previous, self._last_command_sent = self._last_command_sent, t
        if previous is not None and t > previous:
            self._gap(t - previous)

    def _gap(self, gap: float) -> None:
        self.max_command_gap = max(self.max_command_gap, gap)
        if gap > self.late_after + _EPS:
            self.late_commands += 1
            self._late = True

    def status_frames(self, t: float) -> list[can.Message]:
        """BRIDGE_HEARTBEAT and BRIDGE_STATUS if a status period is due at ``t``, else []."""
        if not math.isfinite(t) or not self._due("status", t, self.status_period):
            return []
        self._alive = (self._alive + 1) & 0xFF
        s, h = self.codec.stats, self.health
        frames = [
            self.codec.encode("BRIDGE_HEARTBEAT", {"Alive": self._alive,
                                                   "State": HEARTBEAT_STATE[self.heartbeat_state()]}, t),
            self.codec.encode("BRIDGE_STATUS", {
                "CommandTimeout": int(self.guard.timed_out), "LimitClamp": int(self.guard.clamped),
                "BusError": int(h.report() or self._external_bus_error),
                "InvalidCommand": int(self.guard.pop_invalid()),
                "BusState": min(int(h.state), int(BusState.BUS_OFF)),
                "TxLate": int(self._late), "RxOverflow": int(self._overflow),
                "ErrorFrames": min(s.error_frames, 255), "BadCounter": min(s.bad_counter, 65535),
                "BadChecksum": min(s.bad_checksum, 65535),
                "BadFrame": min(s.unknown_id + s.bad_length + s.undecodable + s.out_of_range, 65535),
            }, t),
        ]
        self._late = self._overflow = False
        return frames

    def on_frame(self, frame: can.Message, t: float, stamp: Optional[float] = None) -> Optional[Sample]:
        """A received frame at ``t`` (the core's clock); a sample is stamped ``stamp`` (default ``t``)."""
        if frame.is_error_frame:
            self.health.on_error_frame(frame, t)
        decoded = self.codec.decode(frame)
        if decoded is None:
            return None
        self.health.on_traffic(t)
        stamp = t if stamp is None else stamp
        name, v = decoded
        if name == "IMU":
            return ImuSample(stamp, v["AccelX"], v["AccelY"], v["YawRate"])
        if name == "WHEEL_SPEEDS":
            self.guard.observe_wheel_speeds(v["OmegaRL"], v["OmegaRR"])
            return WheelSpeedSample(stamp, v["OmegaRL"], v["OmegaRR"])
        if name == "EPS_STATUS":
            self.guard.observe_angle(v["SteerAngle"])
            return EpsSample(stamp, v["SteerAngle"])
        if name == "GPS_POSITION":
            self._gps_position = (int(v["Counter"]), t, v["PosX"], v["PosY"])
            return None
        if name == "GPS_VELOCITY" and self._gps_position is not None:
            counter, t_position, x, y = self._gps_position
            self._gps_position = None
            if counter == int(v["Counter"]) and abs(t - t_position) <= GPS_PAIR_WINDOW:
                return GpsSample(stamp, stamp - v["FixAge"], x, y, v["VelX"], v["VelY"])
        return None

