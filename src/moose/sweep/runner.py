"""Run a sweep: skip what is done, run the rest on a backend, record each case as it ends, show progress.

Ctrl-C stops the backend (the cases in flight are dropped, not recorded), and the rows recorded so far
are written to ``results.parquet``; :class:`Interrupted` carries the counts, and ``--resume`` runs the
rest.
"""
from __future__ import annotations

import dataclasses
import time
from collections import Counter
from typing import Any

from .axes import Case
from .backends import Backend
from .store import RunFolder


@dataclasses.dataclass
class SweepReport:
    """What one invocation did."""

    total: int
    """Cases of the sweep."""
    skipped: int
    """Cases already recorded (``--resume``)."""
    ran: int
    """Cases recorded by this invocation."""
    outcomes: Counter
    """Outcome (or status, for a case without one) of the cases recorded by this invocation."""
    wall_s: float
    interrupted: bool = False

    @property
    def remaining(self) -> int:
        return self.total - self.skipped - self.ran


class Progress:
    """A rich progress bar on stderr: cases done, rate, ETA, and the outcomes so far."""

    def __init__(self, total: int, done: int, enabled: bool = True) -> None:
        self.enabled = enabled
        self._progress: Any = None
        if not enabled:
            return
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeRemainingColumn
        from rich.progress import Progress as RichProgress

        self._progress = RichProgress(
            TextColumn("sweep"), BarColumn(bar_width=24), MofNCompleteColumn(), TextColumn("{task.fields[rate]}"),
            TextColumn("ETA"), TimeRemainingColumn(), TextColumn("{task.fields[outcomes]}"),
            console=Console(stderr=True), refresh_per_second=4)
        self._task = self._progress.add_task("sweep", total=total, completed=done, rate="", outcomes="")
        self._start = time.monotonic()
        self._ran = 0

    def __enter__(self) -> "Progress":
        if self._progress is not None:
            self._progress.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._progress is not None:
            self._progress.stop()

    def advance(self, outcomes: Counter) -> None:
        if self._progress is None:
            return
        self._ran += 1
        rate = self._ran / max(time.monotonic() - self._start, 1e-9)
        text = " ".join(f"{k} {v}" for k, v in outcomes.most_common())
        self._progress.update(self._task, advance=1, rate=f"{rate:.1f} cases/s", outcomes=text)


def row_label(row: dict[str, Any]) -> str:
    """The outcome of a finished case, or its status when it has none (error, timeout, crashed)."""
    return str(row.get("outcome")) if row["status"] == "done" else row["status"]


def run_sweep(cases: list[Case], folder: RunFolder, backend: Backend, progress: bool = True) -> SweepReport:
    """Run the cases not yet in ``folder``'s journal on ``backend``; write ``results.parquet`` at the end,
    also when interrupted (then ``report.interrupted`` is set and KeyboardInterrupt is not re-raised)."""
    done = folder.done_ids()
    todo = [c for c in cases if c.id not in done]
    skipped = len(cases) - len(todo)
    outcomes: Counter = Counter()
    start = time.monotonic()
    interrupted = False

    def record(row: dict[str, Any]) -> None:
        folder.append(row)
        outcomes[row_label(row)] += 1
        bar.advance(outcomes)

    bar = Progress(len(cases), skipped, enabled=progress)
    try:
        with bar:
            backend.run(todo, record)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        folder.close()
    folder.write_results()
    return SweepReport(len(cases), skipped, sum(outcomes.values()), outcomes, time.monotonic() - start, interrupted)
