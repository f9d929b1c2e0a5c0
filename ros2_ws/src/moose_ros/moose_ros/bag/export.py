"""Export a bag's topics to CSV or Parquet, one file per topic, fields flattened (``twist.twist.linear.x``,
``accel_y[3]``)."""
from __future__ import annotations

import csv
from collections import defaultdict
from pathlib import Path
from typing import Any, Optional, Sequence

from .errors import BagError
from .reader import ReadReport, read_bag


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
           fmt: str = "csv", report: Optional[ReadReport] = None) -> list[Path]:
    """One file per topic (CSV or Parquet): ``timestamp_ns`` and the flattened fields.

    ``topics`` must be topics of the bag; ``out_dir`` is checked (created) before the bag is read.  Pass a
    :class:`~moose_ros.bag.reader.ReadReport` to learn what could not be read."""
    if fmt not in ("csv", "parquet"):
        raise BagError(f"format = {fmt!r} is invalid: expected 'csv' or 'parquet'")
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise BagError(f"output {str(out_dir)!r} is not a directory: export writes one file per topic into a folder")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BagError(f"output folder {str(out_dir)!r} cannot be created: {exc.strerror or exc}") from None
    rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for m in read_bag(path, topics, report):
        rows[m.topic].append({"timestamp_ns": m.timestamp_ns, **flatten(m.msg)})
    try:
        return _write(rows, out_dir, fmt)
    except OSError as exc:
        raise BagError(f"export into {str(out_dir)!r} failed: {exc.strerror or exc}") from None


def _write(rows: dict[str, list[dict[str, Any]]], out_dir: Path, fmt: str) -> list[Path]:
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
            try:
                import pyarrow as pa
                import pyarrow.parquet as pq
            except ImportError:
                raise BagError("--format parquet needs pyarrow: pip install 'moose_ros[parquet]'") from None

            table = pa.Table.from_pylist([{c: row.get(c) for c in columns} for row in items])
            pq.write_table(table, target)
        written.append(target)
    return written
