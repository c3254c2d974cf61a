"""Plots of evaluation results, written as PNG files.

Figures are drawn with matplotlib's object API on the Agg canvas (no pyplot, no window, no
global state; safe in worker processes and headless machines) and written atomically.
Each function takes a result of :mod:`meshmocap.analysis` (metrics) and a ``.png`` path and
returns the path; gait plots are in :mod:`meshmocap.apps.files.gait`.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from meshmocap._atomic import write_bytes_atomic
from meshmocap.analysis.metrics import (
    BoneLengths,
    CorrespondenceErrors,
    JointErrors,
    SilhouetteErrors,
)
from meshmocap.errors import InputError

_DPI = 100


def new_figure(width: float, height: float) -> Figure:
    """A constrained-layout figure of ``width`` × ``height`` inches on an Agg canvas (no GUI)."""
    fig = Figure(figsize=(width, height), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike) -> Path:
    """Write ``fig`` to the PNG file ``path`` atomically and return the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise InputError(f"plot path must end in .png, found {path.name!r}")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    return write_bytes_atomic(path, buf.getvalue())


def _check(result: object, types: tuple[type, ...], func: str) -> None:
    if not isinstance(result, types):
        names = " or ".join(t.__name__ for t in types)
        raise InputError(f"{func}: expected {names}, found {type(result).__name__}")


def _mark_failures(ax, failed: np.ndarray, skipped: np.ndarray) -> None:
    for frames, colour, label in ((failed, "tab:red", "failed"), (skipped, "0.6", "skipped")):
        if len(frames):
            ax.vlines(
                frames,
                0,
                1,
                transform=ax.get_xaxis_transform(),
                colors=colour,
                alpha=0.4,
                linewidth=1,
                label=f"{label} ({len(frames)})",
            )


def plot_frame_errors(
    result: JointErrors | CorrespondenceErrors | SilhouetteErrors,
    path: str | os.PathLike,
    *,
    title: str | None = None,
) -> Path:
    """Plot the error of every frame: mean joint or vertex error (mm), or the silhouette
    error of each camera (%). Failed frames are red ticks, skipped frames grey ticks."""
    _check(result, (JointErrors, CorrespondenceErrors, SilhouetteErrors), "plot_frame_errors")
    fig = new_figure(8, 3.5)
    ax = fig.add_subplot()
    if isinstance(result, SilhouetteErrors):
        for c, name in enumerate(result.cameras):
            ax.plot(result.errors[:, c] * 100, linewidth=1, label=name)
        ax.set_ylabel("silhouette overlap error (%)")
        default = f"Silhouette error per frame (mean {result.overall * 100:.2f} %)"
    else:
        what = "joint" if isinstance(result, JointErrors) else "vertex"
        n = len(result.frames) + len(result.failed) + len(result.skipped)
        x, gaps = np.arange(n), np.full(n, np.nan)  # NaN breaks the line at missing frames

        def full(values: np.ndarray) -> np.ndarray:
            out = gaps.copy()
            out[result.frames] = values
            return out

        ax.plot(
            x,
            full(result.per_frame),
            linewidth=1,
            color="tab:blue",
            marker=".",
            ms=3,
            label=f"mean {what} error",
        )
        if isinstance(result, JointErrors) and result.errors.size:
            lo, hi = full(result.errors.min(axis=1)), full(result.errors.max(axis=1))
            ax.fill_between(x, lo, hi, alpha=0.2, color="tab:blue", label="min–max over joints")
        _mark_failures(ax, result.failed, result.skipped)
        ax.set_ylabel(f"{what} error (mm)")
        default = f"{what.capitalize()} error per frame (mean {result.overall.mean:.1f} mm)"
    ax.set_xlabel("frame")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize="small")
    ax.set_title(title if title is not None else default)
    return save_figure(fig, path)


def plot_joint_errors(
    result: JointErrors, path: str | os.PathLike, *, title: str | None = None
) -> Path:
    """Bar chart of the mean error of each joint (mm) with its standard deviation."""
    _check(result, (JointErrors,), "plot_joint_errors")
    stats = result.per_joint
    fig = new_figure(max(6, 0.5 * len(stats) + 2), 4)
    ax = fig.add_subplot()
    x = np.arange(len(stats))
    ax.bar(
        x,
        [s.mean for s in stats],
        yerr=[s.std for s in stats],
        capsize=3,
        color="tab:blue",
        alpha=0.8,
    )
    ax.axhline(
        result.overall.mean,
        color="tab:red",
        linestyle="--",
        linewidth=1,
        label=f"mean {result.overall.mean:.1f} mm",
    )
    ax.set_xticks(x, result.names, rotation=45, ha="right")
    ax.set_ylabel("joint error (mm)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize="small")
    ax.set_title(title if title is not None else f"Error per joint ({len(result.frames)} frames)")
    return save_figure(fig, path)


def plot_bone_lengths(
    result: BoneLengths,
    path: str | os.PathLike,
    *,
    reference: BoneLengths | None = None,
    title: str | None = None,
) -> Path:
    """Bar chart of mean bone lengths (mm) with standard-deviation error bars (Fig. 6 style).

    ``reference`` (e.g. the ground-truth skeleton) is drawn as a second bar per bone; its
    bones must match ``result``'s.
    """
    _check(result, (BoneLengths,), "plot_bone_lengths")
    if reference is not None and tuple(reference.names) != tuple(result.names):
        raise InputError("plot_bone_lengths: reference must have the same bones as result")
    fig = new_figure(max(6, 0.55 * len(result.names) + 2), 4.5)
    ax = fig.add_subplot()
    x = np.arange(len(result.names))
    sets = [("tracked", result, "tab:blue")]
    if reference is not None:
        sets.append(("reference", reference, "0.55"))
    width = 0.8 / len(sets)
    for i, (label, r, colour) in enumerate(sets):
        bars = ax.bar(
            x + (i - (len(sets) - 1) / 2) * width,
            r.mean,
            width,
            yerr=r.std,
            capsize=3,
            color=colour,
            alpha=0.85,
            label=label,
        )
        if i == 0:  # the paper prints each bar's standard deviation on it
            ax.bar_label(bars, labels=[f"{s:.1f}" for s in r.std], fontsize=7, padding=2)
    ax.set_xticks(x, result.names, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("bone length (mm), bars: ±1 std")
    ax.grid(axis="y", alpha=0.3)
    if reference is not None:
        ax.legend(fontsize="small")
    ax.set_title(title if title is not None else f"Bone lengths ({len(result.frames)} frames)")
    return save_figure(fig, path)


def plot_silhouette_errors(
    result: SilhouetteErrors, path: str | os.PathLike, *, title: str | None = None
) -> Path:
    """Bar chart of the mean silhouette overlap error of each camera (%), with its std."""
    _check(result, (SilhouetteErrors,), "plot_silhouette_errors")
    fig = new_figure(max(5, 0.6 * len(result.cameras) + 2), 3.5)
    ax = fig.add_subplot()
    x = np.arange(len(result.cameras))
    ax.bar(
        x,
        result.per_camera * 100,
        yerr=result.errors.std(axis=0) * 100,
        capsize=3,
        color="tab:green",
        alpha=0.8,
    )
    ax.axhline(
        result.overall * 100,
        color="tab:red",
        linestyle="--",
        linewidth=1,
        label=f"mean {result.overall * 100:.2f} %",
    )
    ax.set_xticks(x, result.cameras)
    ax.set_ylabel("silhouette overlap error (%)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize="small")
    default = f"Silhouette error per camera ({len(result.errors)} frames)"
    ax.set_title(title if title is not None else default)
    return save_figure(fig, path)
