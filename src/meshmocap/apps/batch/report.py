"""The report of a batch folder: the summary table, then each capture's evaluation plots."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

from meshmocap.apps.batch.summary import CaptureSummary, read_summary
from meshmocap.apps.report.page import Section, Table, write_report
from meshmocap.errors import FormatError, MeshmocapFileNotFoundError

__all__ = ["build_batch_report", "is_batch_folder"]


def is_batch_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a folder written by ``meshmocap batch`` (it holds batch.json)."""
    return (Path(path) / "batch.json").is_file()


def build_batch_report(out: str | os.PathLike, batch: str | os.PathLike) -> Path:
    """Write an HTML report (``out``, ``.html``) of the batch folder ``batch``: one row per
    capture (status, frames, flags, speed, errors where the capture has truth, the error
    of a failed one), then each tracked capture's evaluation plots."""
    batch = Path(batch)
    try:
        meta = json.loads((batch / "batch.json").read_text())
        names = [item["name"] for item in meta["items"]]
    except FileNotFoundError:
        raise MeshmocapFileNotFoundError(f"report: {batch} has no batch.json") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise FormatError(f"report: {batch / 'batch.json'}: not a batch file ({exc})") from None
    rows, sections = [], []
    for name in names:
        s = read_summary(batch / name / "result.json")
        if s is None:
            rows.append((name, "", "", "not run", 0, 0, 0, math.nan, math.nan, math.nan, ""))
            continue
        rows.append(_row(s))
        pngs = sorted((batch / name / "eval").glob("*.png"))
        if pngs:
            images = tuple((f"{name}: {p.stem.replace('_', ' ')}", p) for p in pngs)
            sections.append(Section(f"{name} ({s.method}, {s.template})", images=images))
    headers = (
        "capture",
        "method",
        "template",
        "status",
        "frames",
        "flagged",
        "lost",
        "s/frame",
        "mean mm",
        "worst frame mm",
        "error",
    )
    table = Table(f"{len(names)} captures", headers, tuple(rows), digits=1)
    ok = sum(r[3] == "ok" for r in rows)
    intro = (
        f"batch {batch}: {ok} of {len(names)} captures tracked; errors against each "
        "capture's ground truth where it has one (mean over all frame-joint pairs; "
        "worst frame = the frame with the largest mean error)"
    )
    return write_report(
        out, title=f"meshmocap batch: {batch.name}", tables=[table], sections=sections, intro=intro
    )


def _row(s: CaptureSummary) -> tuple:
    retry = f" (attempt {s.attempts})" if s.attempts > 1 else ""
    return (
        s.name,
        s.method,
        s.template,
        s.status + retry,
        s.frames,
        s.flagged,
        s.lost,
        s.seconds_per_frame,
        s.mean_mm,
        s.worst_frame_mm,
        s.error,
    )
