"""The summary of a batch (``meshmocap batch``): one row per capture, as CSV, markdown and
a ``result.json`` per capture (what a rerun reads to skip finished captures)."""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from meshmocap._atomic import write_bytes_atomic, write_text_atomic

__all__ = [
    "SUMMARY_COLUMNS",
    "CaptureSummary",
    "read_summary",
    "summary_line",
    "write_result",
    "write_summary",
]


@dataclass(frozen=True)
class CaptureSummary:
    """The outcome of one capture: ``status`` is ``ok`` or ``failed`` (``error`` says why in
    one line); errors are NaN where the capture has no truth. ``attempts`` > 1 means a
    worker died and the capture was retried."""

    name: str
    capture: str
    method: str
    template: str
    status: str
    error: str = ""
    frames: int = 0
    flagged: int = 0
    lost: int = 0
    missing: int = 0
    seconds_per_frame: float = math.nan
    mean_mm: float = math.nan
    worst_frame_mm: float = math.nan
    attempts: int = 0


#: summary.csv columns, in order (the :class:`CaptureSummary` fields).
SUMMARY_COLUMNS = tuple(CaptureSummary.__dataclass_fields__)


def write_result(path: Path, s: CaptureSummary) -> None:
    """Write one capture's summary to ``path`` (``result.json``; NaN as null)."""
    d = {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(s).items()}
    write_text_atomic(path, json.dumps(d, indent=2) + "\n")


def read_summary(path: Path) -> CaptureSummary | None:
    """A finished capture's summary (None when absent or unreadable: redo it)."""
    try:
        d = json.loads(path.read_text())
        return CaptureSummary(**{k: (math.nan if v is None else v) for k, v in d.items()})
    except (OSError, ValueError, TypeError):
        return None


def summary_line(s: CaptureSummary) -> str:
    """One line for the log when a capture finishes."""
    if s.status != "ok":
        return f"failed {s.name}: {s.error}"
    text = f"done {s.name}: {s.frames} frames, {s.flagged} flagged, "
    text += f"{s.seconds_per_frame:.2f} s/frame"
    if not math.isnan(s.mean_mm):
        text += f", {s.mean_mm:.1f} mm mean"
    if s.attempts > 1:
        text += f" (attempt {s.attempts}: a worker died and the track resumed)"
    return text


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.4g}"
    return str(v)


def write_summary(out: Path, summaries: Sequence[CaptureSummary]) -> tuple[Path, ...]:
    """Write summary.csv (unrounded; empty where not applicable) and summary.md."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(SUMMARY_COLUMNS)
    for s in summaries:
        w.writerow(
            ["" if isinstance(v, float) and math.isnan(v) else v for v in asdict(s).values()]
        )
    write_bytes_atomic(out / "summary.csv", buf.getvalue().encode())
    head = (
        "capture",
        "method",
        "template",
        "status",
        "frames",
        "flagged",
        "lost",
        "missing",
        "s/frame",
        "mean mm",
        "worst frame mm",
        "attempts",
        "error",
    )
    keys = (
        "name",
        "method",
        "template",
        "status",
        "frames",
        "flagged",
        "lost",
        "missing",
        "seconds_per_frame",
        "mean_mm",
        "worst_frame_mm",
        "attempts",
        "error",
    )
    lines = [
        "# meshmocap batch",
        "",
        f"{sum(s.status == 'ok' for s in summaries)} of {len(summaries)} captures "
        "tracked. Errors are the mean over all (frame, joint) pairs of the 15 evaluation "
        "joints (per-vertex error for captures without joints), against the capture's "
        "ground truth where it has one; worst frame = the frame with the largest mean "
        "error; flagged = frames flagged failed, missing or lost; attempts > 1: a worker "
        "died and the capture was resumed elsewhere.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for s in summaries:
        d = asdict(s)
        lines.append("| " + " | ".join(_fmt(d[k]).replace("|", "/") for k in keys) + " |")
    write_text_atomic(out / "summary.md", "\n".join(lines) + "\n")
    return out / "summary.csv", out / "summary.md"
