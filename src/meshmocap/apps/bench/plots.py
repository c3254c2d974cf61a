"""Plots of ``meshmocap bench`` (PNG, matplotlib's Agg canvas, written atomically).

Each function takes rows of :class:`~meshmocap.apps.bench.rows.BenchRow` (results
that are ``ok``) and a ``.png`` path, and returns the path:

* :func:`plot_mean_errors` — mean error per method per capture, grouped bars (±1 std);
* :func:`plot_bone_spread` — Fig. 6 of the patch-tracking paper: the standard deviation of
  each bone's length over the sequence, one bar per method;
* :func:`plot_tradeoff` — Fig. 8: seconds per frame against mean joint error for each kept
  fraction of the patch tracker's body-part classifier, and the paper's view (kept
  fraction against seconds per frame and silhouette overlap error);
* :func:`plot_frame_curves` — the error of every frame, one curve per method.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.ticker import MaxNLocator

from meshmocap.apps.bench.rows import BenchRow, TradeoffPoint
from meshmocap.apps.figures.evaluation import new_figure, save_figure


def _methods(rows: Sequence[BenchRow]) -> list[str]:
    return list(dict.fromkeys(r.method for r in rows))


def _colours(n: int) -> list:
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def plot_mean_errors(rows: Sequence[BenchRow], path: str | os.PathLike) -> Path:
    """Grouped bars: captures along x, one bar per method, height = mean error (mm), error
    bar = its standard deviation over (frame, joint) pairs."""
    captures, methods = list(dict.fromkeys(r.capture for r in rows)), _methods(rows)
    by = {(r.capture, r.method): r for r in rows}
    fig = new_figure(max(6, 0.35 * len(captures) * len(methods) + 2), 4.5)
    ax = fig.add_subplot()
    x, width = np.arange(len(captures)), 0.8 / len(methods)
    for i, (m, colour) in enumerate(zip(methods, _colours(len(methods)), strict=True)):
        got = [by.get((c, m)) for c in captures]
        mean = [r.mean_mm if r else np.nan for r in got]
        std = [r.std_mm if r else np.nan for r in got]
        ax.bar(
            x + (i - (len(methods) - 1) / 2) * width,
            mean,
            width,
            yerr=std,
            capsize=2,
            color=colour,
            alpha=0.85,
            label=m,
        )
    vertices = {r.capture for r in rows if r.metric == "vertices"}
    ax.set_xticks(
        x,
        [f"{c}\n(vertices)" if c in vertices else c for c in captures],
        rotation=30 if len(captures) > 4 else 0,
        ha="right" if len(captures) > 4 else "center",
    )
    ax.set_ylabel("mean error (mm), bars: ±1 std")
    ax.set_ylim(0, ax.get_ylim()[1] * 1.15)  # room for the legend
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize="small", ncols=min(4, len(methods)))
    ax.set_title("Mean joint error per method and capture")
    return save_figure(fig, path)


def plot_bone_spread(rows: Sequence[BenchRow], path: str | os.PathLike, *, capture: str) -> Path:
    """Fig. 6: standard deviation of each bone's length over the sequence (mm), one bar per
    method (0 for a rigid skeleton; the spread shows how much a tracker stretches bones)."""
    rows = [r for r in rows if r.bone_names]
    names = rows[0].bone_names
    rows = [r for r in rows if r.bone_names == names]
    fig = new_figure(max(7, 0.25 * len(names) * len(rows) + 2), 4.5)
    ax = fig.add_subplot()
    x, width = np.arange(len(names)), 0.8 / len(rows)
    for i, (r, colour) in enumerate(zip(rows, _colours(len(rows)), strict=True)):
        bars = ax.bar(
            x + (i - (len(rows) - 1) / 2) * width,
            r.bone_std_mm,
            width,
            color=colour,
            alpha=0.85,
            label=r.method,
        )
        if len(rows) <= 3:  # the paper prints each bar's value on it
            ax.bar_label(bars, labels=[f"{s:.1f}" for s in r.bone_std_mm], fontsize=6, padding=1)
    ax.set_xticks(x, names, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("bone length std over frames (mm)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize="small", ncols=min(4, len(rows)))
    ax.set_title(f"Bone-length spread (Fig. 6), {capture}")
    return save_figure(fig, path)


def plot_frame_curves(rows: Sequence[BenchRow], path: str | os.PathLike, *, capture: str) -> Path:
    """Error of every frame (mean over joints, or vertices), one curve per method."""
    fig = new_figure(8, 3.8)
    ax = fig.add_subplot()
    for r, colour in zip(rows, _colours(len(rows)), strict=True):
        ax.plot(
            r.frame_numbers,
            r.per_frame_mm,
            linewidth=1,
            color=colour,
            label=f"{r.method} (mean {r.mean_mm:.1f} mm)",
        )
    what = "vertex" if rows and rows[0].metric == "vertices" else "joint"
    ax.set_xlabel("frame")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel(f"mean {what} error (mm)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small", ncols=2)
    ax.set_title(f"Error per frame, {capture}")
    return save_figure(fig, path)


def plot_tradeoff(
    points: Sequence[TradeoffPoint],
    path: str | os.PathLike,
    *,
    capture: str | None,
    reference: BenchRow | None = None,
) -> Path:
    """Fig. 8: left, seconds per frame (x) against mean joint error (y), each point labelled
    with its kept fraction; right, the paper's view: kept fraction against seconds per frame
    and silhouette overlap error. ``reference`` (the tracker without classification) is a
    star on the left and dashed lines on the right."""
    pts = sorted(points, key=lambda p: p.keep_fraction)
    f = np.array([p.keep_fraction for p in pts])
    spf = np.array([p.row.seconds_per_frame for p in pts])
    err = np.array([p.row.mean_mm for p in pts])
    sil = np.array([p.row.silhouette_error for p in pts]) * 100
    fig = new_figure(11, 4.2)
    ax, bx = fig.subplots(1, 2)
    ax.plot(spf, err, "-o", color="tab:red", label="patch (classifier)")
    for xi, yi, fi in zip(spf, err, f, strict=True):
        ax.annotate(f"{fi:g}", (xi, yi), textcoords="offset points", xytext=(5, 5), fontsize=8)
    if reference is not None:
        ax.plot(
            reference.seconds_per_frame,
            reference.mean_mm,
            "*",
            ms=12,
            color="tab:blue",
            label=f"{reference.method} (no classification)",
        )
    ax.set_xlabel("seconds per frame")
    ax.set_ylabel("mean joint error (mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    ax.set_title("Accuracy / time, labels: kept fraction")
    bx.plot(f, spf, "-o", color="tab:red", label="s/frame")
    bx.set_xlabel("kept fraction of on-bone points")
    bx.set_ylabel("seconds per frame", color="tab:red")
    cx = bx.twinx()
    cx.plot(f, sil, "-s", color="tab:green", label="silhouette error")
    cx.set_ylabel("silhouette overlap error (%)", color="tab:green")
    if reference is not None:
        bx.axhline(reference.seconds_per_frame, color="tab:red", linestyle="--", linewidth=1)
        cx.axhline(reference.silhouette_error * 100, color="tab:green", linestyle="--", linewidth=1)
    bx.grid(alpha=0.3)
    bx.set_title("Paper's view (dashed: no classification)")
    fig.suptitle(f"Kept fraction of the body-part classifier (Fig. 8), {capture}")
    return save_figure(fig, path)
