"""A bird's-eye view of a bag (``moose bag view``): what the markers and TF of the run show, drawn from the bag
alone: the true path (/vehicle/odom), the estimated path (odom → base_link on /tf), the danger zone and
the MPC, MSF and blended predicted paths of every planning instant with a threat (/planning/markers),
the first one after detection drawn bold."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

from ..convert import MARKER_COLOURS
from ..graph import FRAME_BASE, MARKERS, ODOM, TF
from .errors import BagError
from .reader import BagReader, ReadReport

_LABELS = {"mpc": "MPC prediction", "msf": "MSF prediction", "blend": "blended plan"}


def plot_birdseye(path: str | Path, out: str | Path, title: str = "", report: Optional[ReadReport] = None) -> Path:
    """Draw the bird's-eye view of bag ``path`` into ``out`` (PNG); returns ``out``.  Pass a
    :class:`~moose_ros.bag.reader.ReadReport` to learn what could not be read (a truncated bag is drawn as far
    as it goes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    truth: list[tuple[float, float]] = []
    estimate: list[tuple[float, float]] = []
    instants: list[Any] = []
    reader = BagReader(path, report)
    try:
        needed = (ODOM.name, MARKERS.name)
        if not set(needed) <= set(reader.topics):
            raise BagError(f"bag {str(path)!r} has no {ODOM.name} or no {MARKERS.name} to draw")
        messages = list(reader.messages([t for t in (*needed, TF.name) if t in reader.topics]))
    finally:
        reader.close()
    for m in messages:
        if m.topic == ODOM.name:
            truth.append((m.msg.pose.pose.position.x, m.msg.pose.pose.position.y))
        elif m.topic == TF.name:
            estimate.extend((x.transform.translation.x, x.transform.translation.y) for x in m.msg.transforms
                            if x.child_frame_id == FRAME_BASE)
        else:
            markers = {mk.ns: mk for mk in m.msg.markers if mk.action == 0}
            if "danger_zone" in markers:
                instants.append(markers)
    if not truth or not instants:
        raise BagError(f"bag {str(path)!r} has no {ODOM.name} or no {MARKERS.name} with a danger zone to draw")
    zone = instants[0]["danger_zone"]
    cx, cy, sx, sy = zone.pose.position.x, zone.pose.position.y, zone.scale.x, zone.scale.y
    x_lo, x_hi = max(min(x for x, _ in truth), cx - 20.0), min(max(x for x, _ in truth), cx + 32.0)
    ys = [y for x, y in truth if x_lo <= x <= x_hi] + [cy - sy / 2, cy + sy / 2]
    y_lo, y_hi = min(ys) - 1.5, max(ys) + 1.5
    fig, ax = plt.subplots(figsize=(10.0, 1.6 + 10.0 * (y_hi - y_lo) / (x_hi - x_lo)))
    ax.add_patch(Rectangle((cx - sx / 2, cy - sy / 2), sx, sy, color=MARKER_COLOURS["danger_zone"][:3], alpha=0.6,
                           label="danger zone"))
    for k, markers in enumerate(instants):
        for ns in ("mpc", "msf", "blend"):
            if ns in markers:
                px, py = zip(*((p.x, p.y) for p in markers[ns].points))
                ax.plot(px, py, color=MARKER_COLOURS[ns][:3], linewidth=2.2 if k == 0 else 0.8,
                        alpha=1.0 if k == 0 else 0.35, label=f"{_LABELS[ns]} (first after detection bold)" if k == 0
                        else None, marker="o" if k == 0 else None, markersize=3)
    ax.plot(*zip(*truth), color="0.2", linewidth=1.6, label="path (ground truth)")
    if estimate:
        ax.plot(*zip(*estimate), color="tab:orange", linewidth=1.0, linestyle="--", label="path (estimate)")
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_lo, y_hi)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x in odom (m)")
    ax.set_ylabel("y in odom (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.22), frameon=False, ncol=3)
    ax.set_title(title or f"{Path(path).name}: bird's-eye view from /vehicle/odom, /tf and /planning/markers",
                 fontsize=9)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return Path(out)
