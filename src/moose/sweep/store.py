"""The run folder of a sweep: manifest, exact configuration, journal of finished cases, results table.

::

    DIR/manifest.json    the spec (axes, sampling and its seed, configuration), its hash, the code's
                         version, the backend, case counts and the state (running, interrupted, complete)
    DIR/config.yaml      the exact base configuration (ROS 2 parameter file; the cases' --set are columns)
    DIR/cases.jsonl      one JSON row per finished case, appended and flushed as each case ends
    DIR/results.parquet  the same rows as a table (written at the end, on Ctrl-C and on --resume)

The journal is the record: a row is in it as soon as its case ends, so an interrupted or killed
sweep loses only the cases that were running.  ``results.parquet`` is rebuilt from it.  A line that is
not a row (the last one cut short by a kill, or a corrupt one) is skipped and reported, and its case runs
again on ``--resume``.  A folder that holds another sweep (another spec hash) is refused; one where no file
can be created is refused before any case runs; a row that cannot be written (a full disk) ends the sweep
with an :class:`~moose.files.OutputError`, the rows before it kept.
"""
from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import IO, Any, Iterable, Optional

from ..files import OutputError, dump_yaml
from ..params import ParamError
from .spec import SweepSpec

MANIFEST = "manifest.json"
CONFIG = "config.yaml"
JOURNAL = "cases.jsonl"
RESULTS = "results.parquet"


def code_version() -> dict[str, str]:
    """The moose version and a hash of its source files: equal hashes, equal code."""
    import hashlib
    from importlib.metadata import PackageNotFoundError, version

    import moose

    try:
        release = version("moose-avoidance")
    except PackageNotFoundError:
        release = "not installed"
    root = Path(moose.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        if path.suffix in (".py", ".c", ".yaml", ".dbc") and "__pycache__" not in path.parts:
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return {"moose": release, "source_sha256": digest.hexdigest()[:16]}


def pyarrow_or_error() -> Any:
    """pyarrow.parquet, or a :class:`ParamError` saying how to install it."""
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise ParamError("moose sweep writes parquet and needs pyarrow: pip install 'moose-avoidance[sweep]'") from None
    return pq


class RunFolder:
    """A sweep's folder; :meth:`open` checks it against the spec before anything is written."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._journal: Optional[IO[str]] = None
        self.damaged: list[int] = []
        """Line numbers of the journal that are not rows (found by the last :meth:`rows`)."""

    @classmethod
    def open(cls, path: Path, spec: SweepSpec, resume: bool) -> "RunFolder":
        """The folder for ``spec``: new, or (with ``resume``) one that holds the same sweep."""
        folder = cls(path)
        manifest = folder.manifest()
        if path.exists() and not path.is_dir():
            raise ParamError(f"-o {str(path)!r} is invalid: it is a file, not a folder")
        if manifest is not None:
            theirs = manifest.get("spec_hash")
            if theirs != spec.hash:
                raise ParamError(f"-o {str(path)!r} holds a different sweep (spec {theirs}, this one {spec.hash}): "
                                 "choose another folder")
            if not resume:
                raise ParamError(f"-o {str(path)!r} holds this sweep already ({len(folder.done_ids())} cases done): "
                                 "--resume continues it")
        elif path.exists() and any(path.iterdir()):
            raise ParamError(f"-o {str(path)!r} is invalid: the folder is not empty and holds no sweep ({MANIFEST})")
        folder._check_writable()
        return folder

    def _check_writable(self) -> None:
        """:class:`ParamError` unless files can be created in the folder (a new one is created, tried and removed
        again; its parents are kept)."""
        import tempfile

        new = not self.path.exists()
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=self.path):
                pass
            if new:
                self.path.rmdir()
        except OSError as exc:
            raise ParamError(f"-o {str(self.path)!r} cannot be written: {exc.strerror or exc}") from None

    def manifest(self) -> Optional[dict[str, Any]]:
        path = self.path / MANIFEST
        if not path.exists():
            return None
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ParamError(f"{str(path)!r} is not a readable sweep manifest: {exc}") from None

    def write_manifest(self, manifest: dict[str, Any]) -> None:
        self.path.mkdir(parents=True, exist_ok=True)
        tmp = self.path / (MANIFEST + ".tmp")
        tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True, default=repr) + "\n", encoding="utf-8")
        os.replace(tmp, self.path / MANIFEST)

    def start(self, spec: SweepSpec, n_cases: int, backend: str) -> dict[str, Any]:
        """Write the manifest and the configuration (keeping a resumed sweep's creation time)."""
        from ..config import config_as_ros_params

        old = self.manifest() or {}
        manifest = {
            "format": 1,
            "spec": spec.describe(),
            "spec_hash": spec.hash,
            "cases": n_cases,
            "created": old.get("created", time.strftime("%Y-%m-%dT%H:%M:%S%z")),
            "code": code_version(),
            "python": sys.version.split()[0],
            "host": platform.node(),
            "backend": backend,
            "state": "running",
        }
        if old and old.get("code") != manifest["code"]:
            manifest["code_history"] = old.get("code_history", []) + [old.get("code")]
        self.write_manifest(manifest)
        (self.path / CONFIG).write_text(dump_yaml(config_as_ros_params(spec.config)),
                                        encoding="utf-8")
        return manifest

    # -- the journal -------------------------------------------------------------------------------
    def rows(self) -> list[dict[str, Any]]:
        """Every recorded row, the last of each case id.  A line that is not a row (cut short by a kill, or
        corrupt) is skipped and counted in :attr:`damaged`: its case is not done, so ``--resume`` runs it again."""
        path = self.path / JOURNAL
        if not path.exists():
            return []
        rows: dict[str, dict[str, Any]] = {}
        self.damaged = []
        with open(path, encoding="utf-8", errors="replace") as handle:
            for number, line in enumerate(handle, 1):
                try:
                    row = json.loads(line)
                    rows[_case_id(row)] = row
                except ValueError:
                    self.damaged.append(number)
        return list(rows.values())

    def done_ids(self) -> set[str]:
        return {row["case_id"] for row in self.rows()}

    def append(self, row: dict[str, Any]) -> None:
        """Record one finished case (flushed to the operating system at once).  A write that fails (a full disk)
        is an :class:`~moose.files.OutputError` saying what the journal holds."""
        try:
            if self._journal is None:
                self.path.mkdir(parents=True, exist_ok=True)
                path = self.path / JOURNAL
                cut = path.exists() and path.stat().st_size > 0 and not path.read_bytes().endswith(b"\n")
                self._journal = open(path, "a", encoding="utf-8")  # noqa: SIM115 - kept open across cases, closed by close()
                if cut:  # a line cut short by a kill: end it, so that the next row starts a line of its own
                    self._journal.write("\n")
            self._journal.write(json.dumps(row, allow_nan=False) + "\n")
            self._journal.flush()
        except OSError as exc:
            raise OutputError(f"-o {str(self.path)!r}: case {row.get('case_id')} cannot be recorded "
                              f"({exc.strerror or exc}); the cases recorded before it are kept in {JOURNAL}: "
                              f"make room, then run the same moose sweep command again with --resume") from None

    def close(self) -> None:
        """Close the journal; what a failed write left unwritten is not recorded (its case runs again)."""
        if self._journal is not None:
            journal, self._journal = self._journal, None
            try:
                journal.close()
            except OSError:  # the buffered rest of a failed write: that case is not recorded
                pass

    def write_results(self) -> Path:
        """results.parquet from the journal (atomically replaced)."""
        pq = pyarrow_or_error()
        import pyarrow as pa

        rows = self.rows()
        columns = _column_order(rows)
        table = pa.Table.from_pylist([{c: row.get(c) for c in columns} for row in rows]) if rows else pa.table({})
        target = self.path / RESULTS
        tmp = self.path / (RESULTS + ".tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, target)
        return target


def _case_id(row: Any) -> str:
    """The case id of a journal row (ValueError when ``row`` is not one)."""
    if not isinstance(row, dict) or not isinstance(row.get("case_id"), str):
        raise ValueError("not a row of a case")
    return row["case_id"]


def _column_order(rows: Iterable[dict[str, Any]]) -> list[str]:
    """Columns in first-seen order (inputs first, as the rows have them)."""
    seen: dict[str, None] = {}
    for row in rows:
        for key in row:
            seen.setdefault(key, None)
    return list(seen)


def read_results(path: Path) -> Any:
    """The results table of a sweep folder (or a parquet file) as a pyarrow table."""
    pq = pyarrow_or_error()
    path = Path(path)
    target = path / RESULTS if path.is_dir() else path
    if not target.exists():
        if path.is_dir() and (path / JOURNAL).exists():
            return pq.read_table(RunFolder(path).write_results())
        raise ParamError(f"{str(path)!r} holds no sweep results ({RESULTS})")
    import pyarrow as pa

    try:
        return pq.read_table(target)
    except (pa.ArrowException, OSError) as exc:
        rebuild = (" (moose sweep --resume -o DIR with the sweep's flags rebuilds it from its cases.jsonl)"
                   if path.is_dir() and (path / JOURNAL).exists() else "")
        raise ParamError(f"sweep results {str(target)!r} are unreadable: {exc}{rebuild}") from None
