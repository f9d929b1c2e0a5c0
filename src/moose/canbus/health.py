"""Bus health: the controller's error state from error frames and I/O failures, and the re-open back-off.

Pure logic, time passed in; the I/O shell (:class:`moose.canbus.bus.BusLink`) feeds it.

How bus errors are detected with python-can:

* **Error frames** (``Message.is_error_frame``).  SocketCAN delivers them by default in
  python-can (``ignore_rx_error_frames=False`` sets ``CAN_RAW_ERR_FILTER`` to all classes);
  the error class is in the identifier and the details in the data, as in
  ``linux/can/error.h``: bus-off (class 0x040), controller problems (0x004, byte 1:
  error warning / error passive / back to error active), restarted (0x100), protocol,
  ACK, transceiver and lost-arbitration errors.
* **Exceptions** from ``send``/``recv`` (``can.CanError`` or ``OSError``: a full transmit
  queue while bus-off, an unplugged adapter, an interface taken down, a closed socket).
  An exception means the bus object is unusable: the shell shuts it down and re-opens it
  after a back-off that doubles from ``backoff_initial`` to ``backoff_max`` and is reset
  once the re-opened bus has carried traffic for ``backoff_reset`` seconds.

A bus-off the kernel reports is left to the controller's automatic restart (SocketCAN
``restart-ms``); the state stays ``bus_off`` until a "restarted" or "error active" error
frame or valid traffic shows the controller is back.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from typing import Optional

import can

from moose.params import ParamError, check, positive

# linux/can/error.h: error classes in the identifier of an error frame
CAN_ERR_TX_TIMEOUT = 0x001
CAN_ERR_LOSTARB = 0x002
CAN_ERR_CRTL = 0x004
CAN_ERR_PROT = 0x008
CAN_ERR_TRX = 0x010
CAN_ERR_ACK = 0x020
CAN_ERR_BUSOFF = 0x040
CAN_ERR_BUSERROR = 0x080
CAN_ERR_RESTARTED = 0x100
# controller status in data[1] of a CAN_ERR_CRTL frame
CAN_ERR_CRTL_RX_WARNING = 0x04
CAN_ERR_CRTL_TX_WARNING = 0x08
CAN_ERR_CRTL_RX_PASSIVE = 0x10
CAN_ERR_CRTL_TX_PASSIVE = 0x20
CAN_ERR_CRTL_ACTIVE = 0x40


class BusState(enum.IntEnum):
    """Error state of the CAN controller (ISO 11898-1 fault confinement) plus the I/O failure of the shell.

    The values 0–3 are the ``BusState`` signal of BRIDGE_STATUS.
    """

    ERROR_ACTIVE = 0
    ERROR_WARNING = 1
    ERROR_PASSIVE = 2
    BUS_OFF = 3
    IO_FAILURE = 4
    """The bus object raised: it is closed and waits to be re-opened (reported as bus-off on the bus)."""


def error_frame_state(frame: can.Message) -> Optional[BusState]:
    """The controller state an error frame announces, or ``None`` if it announces no change.

    (Protocol, ACK, transceiver, lost-arbitration and TX-timeout errors are counted but do not
    change the state by themselves: the controller's error counters do, and it reports them
    through the controller-problem class.)
    """
    err_class = frame.arbitration_id
    data = bytes(frame.data)
    if err_class & CAN_ERR_BUSOFF:
        return BusState.BUS_OFF
    if err_class & CAN_ERR_CRTL and len(data) > 1:
        status = data[1]
        if status & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE):
            return BusState.ERROR_PASSIVE
        if status & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING):
            return BusState.ERROR_WARNING
        if status & CAN_ERR_CRTL_ACTIVE:
            return BusState.ERROR_ACTIVE
    if err_class & CAN_ERR_RESTARTED:
        return BusState.ERROR_ACTIVE
    return None


@dataclasses.dataclass(frozen=True)
class HealthParams:
    """Re-open back-off (s)."""

    backoff_initial: float = 0.1
    """First wait before re-opening a failed bus: ten command cycles."""
    backoff_max: float = 2.0
    """Longest wait between re-open attempts."""
    backoff_reset: float = 1.0
    """Traffic-free-of-failures time after which the back-off starts again from ``backoff_initial``."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check(f.name, getattr(self, f.name), positive, "a positive number of seconds")
        if self.backoff_max < self.backoff_initial:
            raise ParamError(f"backoff_max = {self.backoff_max!r} is invalid: expected at least "
                             f"backoff_initial = {self.backoff_initial!r}")


class BusHealth:
    """Bus state from error frames and I/O failures, a latched error flag for the status frame, and the back-off."""

    def __init__(self, params: HealthParams = HealthParams()) -> None:
        self.params = params
        self.state = BusState.ERROR_ACTIVE
        self.error_frames = 0
        """Error frames received (any class)."""
        self.io_failures = 0
        """Exceptions from the bus (send, receive or open)."""
        self.reopens = 0
        """Successful re-opens after a failure."""
        self.last_error = ""
        self._latched = False
        self._backoff = params.backoff_initial
        self._reopen_at: Optional[float] = None
        self._healthy_since: Optional[float] = None

    @property
    def bus_error(self) -> bool:
        """Not error active now, or a bus error since the last :meth:`report`."""
        return self._latched or self.state != BusState.ERROR_ACTIVE

    @property
    def fault(self) -> bool:
        """The bus cannot carry frames (bus-off or a closed bus object)."""
        return self.state in (BusState.BUS_OFF, BusState.IO_FAILURE)

    def report(self) -> bool:
        """The bus-error flag for a status frame; clears the latch."""
        flag = self.bus_error
        self._latched = False
        return flag

    def on_error_frame(self, frame: can.Message, t: float) -> None:
        self.error_frames += 1
        state = error_frame_state(frame)
        if state is None:
            return
        if state != BusState.ERROR_ACTIVE:
            self._latched = True
            self._healthy_since = None
            self.last_error = f"error frame: {state.name.lower()}"
        if self.state != BusState.IO_FAILURE:
            self.state = state

    def on_traffic(self, t: float) -> None:
        """A frame was sent or received: the controller is on the bus."""
        if self.state == BusState.BUS_OFF:
            self.state = BusState.ERROR_ACTIVE
        if self._healthy_since is None:
            self._healthy_since = t
        elif t - self._healthy_since >= self.params.backoff_reset:
            self._backoff = self.params.backoff_initial

    def on_io_failure(self, reason: str, t: float) -> None:
        """The bus object raised: it must be closed; the next open is due after the back-off."""
        self.io_failures += 1
        self.last_error = reason
        self._latched = True
        self._healthy_since = None
        self.state = BusState.IO_FAILURE
        self._reopen_at = t + self._backoff
        self._backoff = min(2.0 * self._backoff, self.params.backoff_max)

    def reopen_due(self, t: float) -> bool:
        reopen_at = self._reopen_at if self._reopen_at is not None else -math.inf
        return self.state == BusState.IO_FAILURE and t >= reopen_at

    @property
    def reopen_at(self) -> Optional[float]:
        return self._reopen_at if self.state == BusState.IO_FAILURE else None

    def on_open(self, t: float) -> None:
        """The bus was (re-)opened."""
        if self.state == BusState.IO_FAILURE:
            self.reopens += 1
        self.state = BusState.ERROR_ACTIVE
        self._reopen_at = None
        self._healthy_since = t
