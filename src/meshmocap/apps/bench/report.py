"""Report files of ``meshmocap bench`` (:mod:`meshmocap.apps.bench.run`):
``results.csv``, ``results.md``, ``frame_errors.csv``, ``bone_lengths.csv``,
``keep_fraction.csv`` and the plots of :mod:`meshmocap.apps.bench.plots`.

CSV values are unrounded in the units named by each header (``_mm``, ``_ratio``,
``_s``); not-applicable rows leave their values empty and say why in ``note``.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

from meshmocap._atomic import write_bytes_atomic, write_text_atomic
from meshmocap.apps.bench.plots import (
    plot_bone_spread,
    plot_frame_curves,
    plot_mean_errors,
    plot_tradeoff,
)
from meshmocap.apps.bench.rows import BenchRow, TradeoffPoint

#: results.csv columns: (header, row attribute)
COLUMNS = (
    ("capture", "capture"),
    ("method", "method"),
    ("status", "status"),
    ("metric", "metric"),
    ("frames", "frames"),
    ("mean_mm", "mean_mm"),
    ("median_mm", "median_mm"),
    ("std_mm", "std_mm"),
    ("worst_frame_mm", "worst_frame_mm"),
    ("silhouette_error_ratio", "silhouette_error"),
    ("bone_std_max_mm", "bone_std_max_mm"),
    ("seconds_per_frame_s", "seconds_per_frame"),
    ("flagged", "flagged"),
    ("note", "note"),
)


def _inits(rows) -> str:
    """How the rows' first poses were found, in words, from their start records (a row
    whose track records none counts as from ground truth)."""
    from_capture = {r.capture for r in rows if r.status == "ok" and r.start in CAPTURE_STARTS}
    from_truth = {r.capture for r in rows if r.status == "ok" and r.start not in CAPTURE_STARTS}
    if from_capture and not from_truth:
        return "from the capture alone (automatic initialisation)"
    if from_capture:
        return f"from ground truth ({', '.join(sorted(from_capture))}: from the capture alone)"
    return "from ground truth"


#: Start sources (:attr:`~meshmocap.io.start.Start.source`) found from the capture alone.
CAPTURE_STARTS = ("search", "subject-rest", "subject-fit")


def _csv(path: Path, headers: Sequence[str], rows: Sequence[Sequence[object]]) -> Path:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(headers)
    w.writerows([["" if isinstance(x, float) and math.isnan(x) else x for x in r] for r in rows])
    return write_bytes_atomic(path, buf.getvalue().encode())


def _num(x: float, digits: int, scale: float = 1.0) -> str:
    return "n/a" if math.isnan(x) else f"{x * scale:.{digits}f}"


def markdown_table(rows: Sequence[BenchRow]) -> str:
    """The results as a markdown table (errors in mm, silhouette error in %)."""
    head = [
        "capture",
        "method",
        "frames",
        "mean mm",
        "median",
        "std",
        "worst frame",
        "silhouette %",
        "bone std max",
        "s/frame",
        "flagged",
        "template",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * 2 + "--:|" * (len(head) - 2)]
    for r in rows:
        if r.status != "ok":
            cells = [r.capture, r.method, "n/a", f"not applicable: {r.note}"] + [""] * 8
        else:
            unit = " (vertices)" if r.metric == "vertices" else ""
            cells = [
                r.capture,
                r.method + unit,
                str(r.frames),
                _num(r.mean_mm, 1),
                _num(r.median_mm, 1),
                _num(r.std_mm, 1),
                _num(r.worst_frame_mm, 1),
                _num(r.silhouette_error, 2, 100),
                _num(r.bone_std_max_mm, 1),
                _num(r.seconds_per_frame, 2),
                str(r.flagged),
                r.template,
            ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def ablation_table(
    rows: Sequence[BenchRow], base: str = "patch", ablations: dict[str, str] | None = None
) -> str:
    """A tracker's ablations as a table like the papers': one row per variant of
    ``ablations`` (method → what it changes against ``base``; default the patch tracker's,
    :data:`~meshmocap.trackers.registry.PATCH_ABLATIONS`), one column per capture, each
    cell the variant's mean error and its change against ``base`` (mm); empty when no
    capture has both."""
    if ablations is None:
        from meshmocap.trackers.registry import PATCH_ABLATIONS as ablations
    ok = {(r.capture, r.method): r.mean_mm for r in rows if r.status == "ok"}
    caps = [c for c in dict.fromkeys(r.capture for r in rows) if (c, base) in ok]
    methods = [m for m in ablations if any((c, m) in ok for c in caps)]
    if not methods:
        return ""
    lines = ["| method | change | " + " | ".join(caps) + " |", "|---|---|" + "--:|" * len(caps)]
    lines.append(f"| {base} | — | " + " | ".join(_num(ok[c, base], 1) for c in caps) + " |")
    for m in methods:
        cells = [
            f"{_num(ok[c, m], 1)} ({ok[c, m] - ok[c, base]:+.1f})" if (c, m) in ok else ""
            for c in caps
        ]
        lines.append(f"| {m} | {ablations[m]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def baseline_losses(
    rows: Sequence[BenchRow], method: str = "patch", baseline: str = "articulated_icp"
) -> str:
    """One line saying plainly on which captures ``method`` has a larger mean error than
    ``baseline`` (the papers claim it never does), with both means and worst frames, mm;
    empty when it wins everywhere both ran."""
    ok = {(r.capture, r.method): r for r in rows if r.status == "ok"}
    lost = [
        (c, ok[c, method], ok[c, baseline])
        for c in dict.fromkeys(r.capture for r in rows)
        if (c, method) in ok
        and (c, baseline) in ok
        and ok[c, method].mean_mm > ok[c, baseline].mean_mm
    ]
    if not lost:
        return ""
    cells = [
        f"`{c}` ({_num(a.mean_mm, 1)} against {_num(b.mean_mm, 1)} mm, worst frame "
        f"{_num(a.worst_frame_mm, 1)} against {_num(b.worst_frame_mm, 1)})"
        for c, a, b in lost
    ]
    return f"**`{method}` is worse than `{baseline}` on:** " + "; ".join(cells) + "."


def _ablation_sections(rows: Sequence[BenchRow]) -> list[str]:
    """One ablation table per tracker that registers its ablations (``registry``'s
    ``<TRACKER>_ABLATIONS``)."""
    from meshmocap.trackers import registry

    md = []
    for base in ("patch", "cage"):
        table = ablation_table(rows, base, getattr(registry, f"{base.upper()}_ABLATIONS", {}))
        if table:
            md += ["", f"## Ablations of `{base}` (mean mm; change against `{base}`)", "", table]
    return md


def tradeoff_table(points: Sequence[TradeoffPoint]) -> str:
    """Fig. 8's numbers as a markdown table."""
    lines = ["| kept fraction | s/frame | mean mm | silhouette % | flagged |"]
    lines.append("|--:|--:|--:|--:|--:|")
    for p in points:
        r = p.row
        cells = [
            f"{p.keep_fraction:g}",
            _num(r.seconds_per_frame, 2),
            _num(r.mean_mm, 1),
            _num(r.silhouette_error, 2, 100),
            str(r.flagged),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in name)


def write_report(
    out: str | os.PathLike,
    rows: Sequence[BenchRow],
    tradeoff: Sequence[TradeoffPoint],
    tradeoff_capture: str | None,
    *,
    skipped: Sequence[tuple[str, str]] = (),
    template: str = "neutral_5k",
) -> list[Path]:
    """Write the CSV tables, plots and ``results.md`` into the folder ``out``; return the
    files written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ok = [r for r in rows if r.status == "ok"]
    files = [
        _csv(
            out / "results.csv",
            [h for h, _ in COLUMNS],
            [[getattr(r, a) for _, a in COLUMNS] for r in rows],
        )
    ]
    frame_rows = [
        [r.capture, r.method, r.metric, int(f), float(e)]
        for r in ok
        for f, e in zip(r.frame_numbers, r.per_frame_mm, strict=True)
    ]
    heads = ["capture", "method", "metric", "frame", "error_mm"]
    files.append(_csv(out / "frame_errors.csv", heads, frame_rows))
    bone_rows = [
        [r.capture, r.method, b, m, s]
        for r in ok
        for b, m, s in zip(
            r.bone_names, r.bone_mean_mm.tolist(), r.bone_std_mm.tolist(), strict=True
        )
    ]
    heads = ["capture", "method", "bone", "mean_mm", "std_mm"]
    files.append(_csv(out / "bone_lengths.csv", heads, bone_rows))
    captures = list(dict.fromkeys(r.capture for r in rows))
    plots: list[tuple[str, Path]] = []
    if ok:
        plots.append(
            ("Mean error per method and capture", plot_mean_errors(ok, out / "mean_error.png"))
        )
    for c in captures:
        mine = [r for r in ok if r.capture == c]
        if any(r.bone_names for r in mine):
            p = plot_bone_spread(mine, out / f"bone_std_{_slug(c)}.png", capture=c)
            plots.append((f"Fig. 6: bone-length spread, {c}", p))
        if mine:
            p = plot_frame_curves(mine, out / f"frame_errors_{_slug(c)}.png", capture=c)
            plots.append((f"Error per frame, {c}", p))
    if tradeoff:
        files.append(
            _csv(
                out / "keep_fraction.csv",
                [
                    "capture",
                    "keep_fraction",
                    "seconds_per_frame_s",
                    "mean_mm",
                    "silhouette_error_ratio",
                    "flagged",
                ],
                [
                    [
                        tradeoff_capture,
                        p.keep_fraction,
                        p.row.seconds_per_frame,
                        p.row.mean_mm,
                        p.row.silhouette_error,
                        p.row.flagged,
                    ]
                    for p in tradeoff
                ],
            )
        )
        ref = [r for r in ok if r.capture == tradeoff_capture and r.method == "patch_noclf"]
        p = plot_tradeoff(
            tradeoff,
            out / "keep_fraction.png",
            capture=tradeoff_capture,
            reference=ref[0] if ref else None,
        )
        plots.append((f"Fig. 8: kept fraction of the body-part classifier, {tradeoff_capture}", p))
    files += [p for _, p in plots]
    md = [
        "# meshmocap bench",
        "",
        f"Protocol: tracking template `{template}`; synthetic captures at 60 fps from the "
        "studio (humaneva4 rig unless the capture names another), first frame initialised "
        f"{_inits(rows)}, visual hulls carved at 1 cm. Errors in mm over all (frame, "
        "joint) pairs of the 15 evaluation joints (crane: per-vertex correspondence error); "
        "silhouette overlap error = XOR pixels / input silhouette pixels, mean over frames "
        "and cameras; bone std max = largest standard deviation of a tracked bone length; "
        "s/frame = tracking time per frame after the first, on the machine that ran it.",
        "",
        markdown_table(rows),
    ]
    losses = baseline_losses(rows)
    md += ["", losses] if losses else []
    md += _ablation_sections(rows)
    if skipped:
        md += ["", "Left out: " + "; ".join(f"`{c}` ({why})" for c, why in skipped) + "."]
    if tradeoff:
        md += [
            "",
            f"## Fig. 8: kept fraction of on-bone points (patch, `{tradeoff_capture}`)",
            "",
            tradeoff_table(tradeoff),
        ]
    md += ["", "## Plots", ""] + [f"- {what}: ![{p.name}]({p.name})" for what, p in plots]
    write_text_atomic(out / "results.md", "\n".join(md) + "\n")
    files.insert(1, out / "results.md")
    return files
