"""Evaluation results as plain-text tables for the terminal and as CSV files.

:func:`table` renders any result of :mod:`meshmocap.analysis.metrics` as aligned text
(millimetres for joints, bones, vertices and surfaces; percent for silhouettes);
:func:`write_csv` writes the same summary, or one row per frame, atomically. CSV values
are unrounded, in the units named in each header (``_mm``, ``_m``, ``_ratio``).
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from meshmocap._atomic import write_bytes_atomic
from meshmocap.analysis.metrics import (
    BoneLengths,
    CorrespondenceErrors,
    JointErrors,
    SilhouetteErrors,
    Stats,
    SurfaceDistance,
)
from meshmocap.errors import InputError

Result = JointErrors | CorrespondenceErrors | SilhouetteErrors | BoneLengths | SurfaceDistance
_TYPES = (JointErrors, CorrespondenceErrors, SilhouetteErrors, BoneLengths, SurfaceDistance)


def format_table(
    headers: Sequence[str], rows: Sequence[Sequence[object]], *, digits: int = 1, title: str = ""
) -> str:
    """Return rows as aligned plain text: text left-aligned, numbers right-aligned.

    Floats are printed with ``digits`` decimals, NaN as ``n/a``; ``title`` goes above.
    """

    def cell(x: object) -> str:
        if isinstance(x, float | np.floating):
            return "n/a" if math.isnan(x) else f"{x:.{digits}f}"
        return str(x)

    text = [[cell(x) for x in row] for row in rows]
    numeric = [
        all(isinstance(r[c], int | float | np.number) for r in rows) if rows else False
        for c in range(len(headers))
    ]
    width = [max([len(h)] + [len(r[c]) for r in text]) for c, h in enumerate(headers)]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(
            s.rjust(w) if num else s.ljust(w)
            for s, w, num in zip(cells, width, numeric, strict=True)
        ).rstrip()

    out = [title] if title else []
    out += [line(headers), "  ".join("-" * w for w in width)] + [line(r) for r in text]
    return "\n".join(out)


def _stats_row(label: object, s: Stats) -> list[object]:
    return [label, s.mean, s.median, s.std, s.max]


def _finite_stat(f, x: np.ndarray) -> float:
    x = np.asarray(x, dtype=np.float64)
    x = x[~np.isnan(x)]
    return float(f(x)) if x.size else math.nan


def _counts(r: JointErrors | CorrespondenceErrors) -> str:
    return f"{len(r.frames)} frames, {len(r.failed)} failed, {len(r.skipped)} skipped"


def summary_table(r: Result) -> tuple[str, list[str], list[list[object]], float]:
    """Return (title, headers, rows, display scale) of a result's summary in CSV units."""
    if isinstance(r, JointErrors):
        rows = [_stats_row(n, s) for n, s in zip(r.names, r.per_joint, strict=True)]
        rows.append(_stats_row("all", r.overall))
        title = f"3D joint error, mm ({len(r.names)} joints; {_counts(r)})"
        return title, ["joint", "mean_mm", "median_mm", "std_mm", "max_mm"], rows, 1.0
    if isinstance(r, CorrespondenceErrors):
        title = f"Per-vertex error, mm ({r.errors.shape[1]} vertices; {_counts(r)})"
        heads = ["vertices", "mean_mm", "median_mm", "std_mm", "max_mm"]
        return title, heads, [_stats_row(r.errors.shape[1], r.overall)], 1.0
    if isinstance(r, SilhouetteErrors):
        E = r.errors  # NaN where a camera does not see the subject: not scored
        rows = [
            [c, *(_finite_stat(f, E[:, i]) for f in (np.mean, np.median, np.max))]
            for i, c in enumerate(r.cameras)
        ]
        rows.append(["all", r.overall, _finite_stat(np.median, E), _finite_stat(np.max, E)])
        rows.append(["pooled", r.pooled, math.nan, math.nan])
        title = f"Silhouette overlap error, % of true pixels ({len(E)} frames)"
        return title, ["camera", "mean_ratio", "median_ratio", "max_ratio"], rows, 100.0
    if isinstance(r, BoneLengths):
        rows = [[n, m, s] for n, m, s in zip(r.names, r.mean, r.std, strict=True)]
        title = f"Bone lengths, mm ({len(r.frames)} frames, {len(r.failed)} failed)"
        return title, ["bone", "mean_mm", "std_mm"], rows, 1.0
    if isinstance(r, SurfaceDistance):
        rows = [
            [name, d.mean, d.rms, d.p95, d.max, d.n]
            for name, d in (("A to B", r.a_to_b), ("B to A", r.b_to_a))
        ]
        title = f"Surface distance, mm (each sampled distance ≤ exact + {r.bound * 1e3:.2g} mm)"
        return title, ["direction", "mean_m", "rms_m", "p95_m", "max_m", "samples"], rows, 1e3
    raise InputError(f"expected one of {[t.__name__ for t in _TYPES]}, found {type(r).__name__}")


def table(result: Result, *, digits: int = 1) -> str:
    """Return a result's summary as an aligned plain-text table (for the terminal).

    Joint, vertex and bone values in millimetres, surface distances in millimetres,
    silhouette errors in percent; ``digits`` decimals.
    """
    title, headers, rows, scale = summary_table(result)
    shown = [[x * scale if isinstance(x, float) else x for x in row] for row in rows]
    unit = "%" if scale == 100.0 else "mm"
    heads = [h.rsplit("_", 1)[0] if h.endswith(("_mm", "_m", "_ratio")) else h for h in headers]
    heads = [f"{h} ({unit})" if h != o else h for h, o in zip(heads, headers, strict=True)]
    return format_table(heads, shown, digits=digits, title=title)


def _per_frame(r: Result) -> tuple[list[str], list[list[object]]]:
    """Headers and one row per input frame: frame, status, values (empty unless ok)."""
    if isinstance(r, SilhouetteErrors):
        rows = [[t, *row] for t, row in enumerate(r.errors.tolist())]
        return ["frame", *(f"{c}_ratio" for c in r.cameras)], rows
    if isinstance(r, BoneLengths):
        heads, values, skipped = [f"{b}_mm" for b in r.names], r.lengths, np.zeros(0, int)
    elif isinstance(r, JointErrors):
        heads = [*(f"{j}_mm" for j in r.names), "mean_mm"]
        values, skipped = np.column_stack([r.errors, r.per_frame]), r.skipped
    elif isinstance(r, CorrespondenceErrors):
        heads, values, skipped = ["mean_mm"], r.per_frame[:, None], r.skipped
    else:
        raise InputError(f"{type(r).__name__} has no per-frame values")
    n = len(r.frames) + len(r.failed) + len(skipped)
    status = np.full(n, "ok", dtype=object)
    status[r.failed], status[skipped] = "failed", "skipped"
    rows: list[list[object]] = [[t, status[t], *[""] * len(heads)] for t in range(n)]
    for t, row in zip(r.frames.tolist(), values.tolist(), strict=True):
        rows[t][2:] = row
    return ["frame", "status", *heads], rows


def write_csv(path: str | os.PathLike, result: Result, *, per_frame: bool = False) -> Path:
    """Write a result as CSV, atomically (temporary file, then ``os.replace``).

    Parameters
    ----------
    path : str or path, the ``.csv`` file
    result : a result of :mod:`meshmocap.analysis.metrics`
    per_frame : bool
        False: the summary of :func:`table` (unrounded, units in the headers). True: one row
        per input frame with a ``status`` column (``ok``, ``failed``, ``skipped``; values
        empty where not ok) for joint, vertex and bone results, per camera for silhouettes.

    Returns
    -------
    Path : ``path``
    """
    if per_frame:
        headers, rows = _per_frame(result)
    else:
        _, headers, rows, _ = summary_table(result)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(headers)
    writer.writerows(
        [["" if isinstance(x, float) and math.isnan(x) else x for x in row] for row in rows]
    )
    return write_bytes_atomic(path, buf.getvalue().encode())
