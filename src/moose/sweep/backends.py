"""Where the cases run: worker processes on this machine (default), or an existing Dask cluster.

Both backends take the same cases and call :func:`moose.sweep.case.run_case` on them, so a sweep
gives the same rows on either (``tests/test_sweep.py`` checks it on a local two-worker cluster).

Both pass ``criticality`` (``moose sweep --criticality``) on to every case.

* :class:`LocalBackend` — ``workers`` processes of its own (spawned, so nothing of the parent's
  threads is inherited), one case each at a time over a pipe.  The parent knows which case every
  worker holds: a worker that dies (a segfault in compiled code, the OOM killer) has its case
  recorded as ``crashed`` and is replaced; one that outlives the case's time limit by ``grace``
  seconds (stuck in compiled code, where the in-thread timeout cannot reach it) is killed and its
  case recorded as ``timeout``.  Workers ignore SIGINT: Ctrl-C reaches the parent, which stops them.
* :class:`DaskBackend` — a ``distributed`` client on ``address``.  Before any case it checks that a
  scheduler answers within ``connect_timeout`` (and that what answers speaks Dask's protocol at all,
  :func:`speaks_dask`) and that every worker runs the same moose source
  (:func:`moose.sweep.store.code_version`).  A worker lost under a case twice is Dask's
  ``KilledWorker``: that case is recorded as ``crashed``.  The cluster is the user's: it is never
  shut down, only the client is closed.
"""
from __future__ import annotations

import gc
import multiprocessing
import signal
import time
from multiprocessing.connection import Connection, wait
from typing import Any, Callable, Iterable, Optional, Protocol

from ..params import ParamError
from ..schema import Config
from .axes import Case
from .case import failed_row, run_case

OnRow = Callable[[dict[str, Any]], None]


class Backend(Protocol):
    name: str

    def run(self, cases: Iterable[Case], on_row: OnRow) -> None:
        """Run every case, passing each row to ``on_row`` as it arrives (in the calling thread)."""


def _worker(conn: Connection, base: Config, timeout: Optional[float], criticality: bool) -> None:
    """Run the cases the pipe brings until it closes or brings None.  After the first case, whose run imported
    the modules and built the tables and compiled functions the worker keeps, that long-lived heap is frozen out of
    the garbage collector's generations (``gc.freeze``): each case's collections then traverse the case's own
    objects only (in a worker, collections took 6 % of a case, 3.5 % frozen)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    frozen = False
    while True:
        try:
            case = conn.recv()
        except EOFError:
            return
        if case is None:
            return
        conn.send(run_case(case, base, timeout, criticality))
        if not frozen:
            gc.collect()
            gc.freeze()
            frozen = True


class _Process:
    """One worker process and the case it holds."""

    def __init__(self, context: Any, base: Config, timeout: Optional[float], criticality: bool) -> None:
        self.conn, child = context.Pipe()
        self.process = context.Process(target=_worker, args=(child, base, timeout, criticality), daemon=True)
        self.process.start()
        child.close()
        self.case: Optional[Case] = None
        self.started = 0.0

    def give(self, case: Case) -> None:
        self.case, self.started = case, time.monotonic()
        self.conn.send(case)

    def stop(self, kill: bool = False) -> None:
        if kill:
            self.process.kill()
        else:
            try:
                self.conn.send(None)
            except OSError:
                pass
        self.process.join(timeout=5.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.conn.close()


class LocalBackend:
    """Worker processes on this machine."""

    name = "local"

    def __init__(self, base: Config, workers: int, timeout: Optional[float], grace: float = 10.0,
                 criticality: bool = False) -> None:
        if not (isinstance(workers, int) and workers >= 1):
            raise ParamError(f"--workers {workers!r} is invalid: expected a positive number of processes")
        self.base, self.workers, self.timeout, self.grace = base, workers, timeout, grace
        self.criticality = criticality
        self._context = multiprocessing.get_context("spawn")

    def _spawn(self) -> _Process:
        return _Process(self._context, self.base, self.timeout, self.criticality)

    def run(self, cases: Iterable[Case], on_row: OnRow) -> None:
        queue = list(cases)
        queue.reverse()
        pool = [self._spawn() for _ in range(min(self.workers, len(queue)))]
        try:
            for worker in pool:
                if queue:
                    worker.give(queue.pop())
            while any(w.case is not None for w in pool):
                busy = [w for w in pool if w.case is not None]
                ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy], timeout=0.5))
                for i, worker in enumerate(pool):
                    if worker.case is None:
                        continue
                    row = None
                    if worker.conn in ready or worker.process.sentinel in ready:
                        row = self._collect(worker)
                    elif self.timeout is not None and time.monotonic() - worker.started > self.timeout + self.grace:
                        row = failed_row(worker.case, "timeout",
                                         f"killed: no answer {self.timeout + self.grace:g} s after the start "
                                         f"(time limit {self.timeout:g} s + {self.grace:g} s grace)",
                                         time.monotonic() - worker.started, f"pid {worker.process.pid}")
                        worker.stop(kill=True)
                    if row is None:
                        continue
                    worker.case = None
                    if not worker.process.is_alive():
                        worker.stop(kill=True)
                        worker = pool[i] = self._spawn()
                    on_row(row)
                    if queue:
                        case = queue.pop()
                        try:
                            worker.give(case)
                        except OSError:  # it died between two cases: a new one takes the case
                            worker.stop(kill=True)
                            worker = pool[i] = self._spawn()
                            worker.give(case)
        finally:
            for worker in pool:
                worker.stop(kill=worker.case is not None)

    @staticmethod
    def _collect(worker: _Process) -> Optional[dict[str, Any]]:
        """The worker's row, or a ``crashed`` row if it died without one; None if not ready after all."""
        case = worker.case
        assert case is not None
        try:
            if worker.conn.poll():
                return worker.conn.recv()
        except (EOFError, OSError):
            pass
        if worker.process.is_alive():
            return None
        worker.process.join()
        code = worker.process.exitcode
        how = (f"signal {-code} ({signal.Signals(-code).name})" if code is not None and code < 0
               else f"exit status {code}")
        return failed_row(case, "crashed", f"the worker process died under this case: {how}",
                          time.monotonic() - worker.started, f"pid {worker.process.pid}")


HANDSHAKE_LIMIT = 1 << 20
"""Largest first message accepted from a scheduler (bytes); Dask's handshake is a few hundred."""


def speaks_dask(address: str, timeout: float) -> None:
    """:class:`ParamError` unless the TCP service at ``address`` opens as a Dask scheduler does: with a message
    whose 8-byte length (native byte order, as ``distributed.comm.tcp`` frames it) is small.  Another service
    (SSH, HTTP) would otherwise have its first bytes taken as a length and allocated: exabytes, or gigabytes
    filled while waiting.  Addresses other than ``tcp://`` are left to ``distributed``."""
    import socket
    import struct

    from distributed.comm import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        host, port = parse_host_port(location)
    except ValueError as exc:
        raise ParamError(f"--address {address!r} is invalid: {exc}") from None
    if scheme != "tcp":
        return
    def receive(sock: socket.socket, size: int) -> bytes:
        data = b""
        while len(data) < size:
            more = sock.recv(size - len(data))
            if not more:
                break
            data += more
        return data

    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            head = receive(sock, 8)
            length = struct.unpack("Q", head)[0] if len(head) == 8 else 0
            message = receive(sock, length) if 0 < length <= HANDSHAKE_LIMIT else b""
    except OSError as exc:  # refused, unreachable, timed out: nothing answers
        raise ParamError(f"--address {address!r}: no Dask scheduler answers ({type(exc).__name__}: "
                         f"{exc.strerror or exc})") from None
    if len(head) < 8:
        raise ParamError(f"--address {address!r}: no Dask scheduler answers (the service closed the connection "
                         f"after {len(head)} bytes)")
    if not 0 < length <= HANDSHAKE_LIMIT:
        raise ParamError(f"--address {address!r}: the service there is not a Dask scheduler (it opened with "
                         f"{head!r})")
    if not _is_handshake(message, length):
        raise ParamError(f"--address {address!r}: the service there is not a Dask scheduler (its first message, "
                         f"{len(message)} of {length} bytes, is not Dask's handshake)")


def _is_handshake(message: bytes, length: int) -> bool:
    """Whether ``message`` is the first message a Dask scheduler sends: ``distributed.comm.tcp``'s frames (an
    8-byte count, an 8-byte length per frame, the frames) whose first frame is the msgpack mapping of its
    handshake, with the scheduler's ``python`` version."""
    import struct

    import msgpack

    if len(message) != length or length < 16:
        return False
    (count,) = struct.unpack_from("Q", message)
    if not 0 < count <= 64 or length < 8 * (1 + count):
        return False
    sizes = struct.unpack_from(f"{count}Q", message, 8)
    start = 8 * (1 + count)
    if start + sum(sizes) != length:
        return False
    try:
        info = msgpack.unpackb(message[start:start + sizes[0]], raw=False)
    except Exception:  # noqa: BLE001 - whatever a stranger sends: not a handshake
        return False
    return isinstance(info, dict) and "python" in info


class DaskBackend:
    """An existing Dask distributed cluster (``tcp://host:port`` of its scheduler)."""

    name = "dask"

    def __init__(self, base: Config, address: str, timeout: Optional[float], connect_timeout: float = 10.0,
                 criticality: bool = False) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ParamError("--backend dask needs dask.distributed: pip install 'moose-avoidance[dask]'") from None
        from .store import code_version

        self.base, self.timeout, self.criticality = base, timeout, criticality
        speaks_dask(address, connect_timeout)
        try:
            self.client = Client(address, timeout=f"{connect_timeout}s", set_as_default=False)
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError, MemoryError from a bad peer
            raise ParamError(f"--address {address!r}: no Dask scheduler answers "
                             f"({type(exc).__name__}: {exc})") from None
        try:
            try:
                self.client.wait_for_workers(1, timeout=connect_timeout)
            except (TimeoutError, OSError):
                raise ParamError(f"--address {address!r}: the scheduler has no workers "
                                 f"(waited {connect_timeout:g} s)") from None
            ours = code_version()
            theirs = self.client.run(code_version)
            different = {worker: v for worker, v in theirs.items() if v != ours}
            if different:
                worker, version = next(iter(different.items()))
                raise ParamError(f"--address {address!r}: worker {worker} runs other moose code ({version}, "
                                 f"here {ours}); install the same version on every worker")
        except BaseException:
            self.client.close()
            raise

    def run(self, cases: Iterable[Case], on_row: OnRow) -> None:
        from distributed import as_completed

        cases = list(cases)
        if not cases:
            return
        import uuid

        token = uuid.uuid4().hex[:8]
        base = self.client.scatter(self.base, broadcast=True)
        futures = self.client.map(run_case, cases, base=base, timeout=self.timeout, criticality=self.criticality,
                                  key=[f"moose-case-{c.id}-{token}" for c in cases], pure=False)
        by_key = {f.key: c for f, c in zip(futures, cases)}
        try:
            for future in as_completed(futures, loop=self.client.loop):
                case = by_key[future.key]
                try:
                    row = future.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker and the like: the case is lost, not the sweep
                    row = failed_row(case, "crashed", f"{type(exc).__name__}: {exc}", None, "dask")
                on_row(row)
        finally:
            self.client.cancel(futures)

    def close(self) -> None:
        self.client.close()
