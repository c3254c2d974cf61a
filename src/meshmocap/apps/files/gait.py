"""Gait analysis written to a folder (``meshmocap gait``): CSV tables and PNG plots.

Files (:func:`write_gait`):

* ``gait.csv`` — one row per cycle (side, cycle number, event frames, stride and step time
  and length, speed, stance and swing %, cadence), then one summary row per side and one
  for both (``cycle`` = ``all``; its ``cadence_steps_per_min`` is the clip's cadence, from
  every step); empty cells where a value is not measured;
* ``gait_events.csv`` — every foot strike and foot off (fractional frame, seconds, side);
* ``gait_curves.csv`` — hip and knee flexion per cycle at 0…100 % (long format);
* ``gait_frames.csv`` — per frame: ankle heights and speeds, wrists in the sagittal plane,
  hip and knee flexion;
* ``gait.png`` — the seed paper's Fig. 11 (ankle heights, wrists in the sagittal plane),
  with the events; ``gait_flexion.png`` — hip and knee flexion over the cycle.

A ``reference`` gait (the ground truth) is drawn dashed in the plots. Figures use
matplotlib's object API on the Agg canvas, as :mod:`meshmocap.apps.figures.evaluation`.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._atomic import write_text_atomic
from meshmocap._tolerances import SAME_FPS
from meshmocap.analysis.gait import (
    CYCLE_SAMPLES,
    SIDES,
    SUMMARY_FIELDS,
    Gait,
    GaitComparison,
    capture_gait,
    compare_gaits,
    track_gait,
)
from meshmocap.apps.figures.evaluation import new_figure, save_figure
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture
from meshmocap.io.results import input_frame, read_track

_COLOURS = {"left": "tab:red", "right": "tab:blue"}
#: Columns of ``gait.csv``: one row per cycle, then the summaries of each side.
CYCLE_COLUMNS = (
    "side",
    "cycle",
    "strike_frame",
    "foot_off_frame",
    "end_frame",
    "start_s",
    "stride_time_s",
    "stride_length_m",
    "speed_m_per_s",
    "step_time_s",
    "step_length_m",
    "stance_pct",
    "swing_pct",
    "cadence_steps_per_min",
)


# --------------------------------------------------------------------------- plots


def plot_gait(
    gait: Gait, path: str | os.PathLike, *, reference: Gait | None = None, title: str = ""
) -> Path:
    """Fig. 11 of the cage paper: absolute ankle heights over the frames with foot strikes
    (▼) and foot offs (▲) and the left cycles shaded, and the wrists' paths relative to the
    pelvis in the sagittal plane; ``reference`` dashed."""
    fig = new_figure(11, 4.2)
    a, b = fig.subplots(1, 2, width_ratios=(1.6, 1))
    for c in gait.side_cycles("left"):
        a.axvspan(*gait.frame_numbers(np.array([c.strike, c.end])), color="0.93", zorder=0)
    for k, side in enumerate(SIDES):
        col = _COLOURS[side]
        for g, dashed in ((reference, True), (gait, False)):
            if g is None:
                continue
            style = dict(
                color=col,
                linewidth=1,
                alpha=0.55 if dashed else 0.9,
                linestyle="--" if dashed else "-",
            )
            who = "truth " if dashed else ""
            h = np.where(g.valid, g.ankle_height[:, k], np.nan) * 100
            a.plot(g.frames, h, label=f"{who}{side} ankle", **style)
            w = np.where(g.valid[:, None], g.wrist_sagittal[:, k], np.nan) * 100
            b.plot(w[:, 0], w[:, 1], label=f"{who}{side} wrist", **style)
        for ev, marker in (("strikes", "v"), ("foot_offs", "^")):
            pos = getattr(gait, ev)[k]
            y = np.interp(pos, np.arange(len(gait.frames)), gait.ankle_height[:, k]) * 100
            a.plot(gait.frame_numbers(pos), y, marker, color=col, markersize=6, linestyle="none")
    a.set(xlabel="frame", ylabel="ankle height above the floor (cm)")
    a.set_title(f"ankle heights: ▼ foot strike, ▲ foot off ({len(gait.cycles)} cycles)")
    b.set(
        xlabel="forward of the pelvis (cm)",
        ylabel="above the pelvis (cm)",
        title="wrists, sagittal plane",
    )
    b.set_aspect("equal", adjustable="datalim")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


def plot_flexion(
    gait: Gait, path: str | os.PathLike, *, reference: Gait | None = None, title: str = ""
) -> Path:
    """Hip and knee flexion (degrees) over the gait cycle (0–100 %, from a foot strike to
    the next of the same foot), left and right: each cycle thin, the mean thick, the mean
    foot off as a dotted line; ``reference``'s mean dashed."""
    fig = new_figure(10, 6)
    axes = fig.subplots(2, 2, sharex=True)
    pct = np.linspace(0, 100, CYCLE_SAMPLES)
    for j, side in enumerate(SIDES):
        col = _COLOURS[side]
        cycles = gait.side_cycles(side)
        ref = reference.side_cycles(side) if reference is not None else ()
        for i, what in enumerate(("hip", "knee")):
            ax = axes[i, j]
            for c in cycles:
                ax.plot(pct, getattr(c, what), color=col, linewidth=0.8, alpha=0.35)
            if cycles:
                ax.plot(
                    pct,
                    np.mean([getattr(c, what) for c in cycles], axis=0),
                    color=col,
                    linewidth=2,
                    label=f"mean of {len(cycles)} cycles",
                )
                ax.axvline(
                    np.mean([c.stance_pct for c in cycles]),
                    color=col,
                    linestyle=":",
                    linewidth=1,
                    label="foot off",
                )
            if ref:
                ax.plot(
                    pct,
                    np.mean([getattr(c, what) for c in ref], axis=0),
                    "--",
                    color="0.2",
                    linewidth=1.5,
                    label=f"truth, mean of {len(ref)}",
                )
            if not cycles and not ref:
                ax.text(0.5, 0.5, "no full cycle", ha="center", transform=ax.transAxes)
            ax.set_title(f"{side} {what} flexion")
            ax.set_ylabel("degrees (+ flexion)")
            ax.grid(alpha=0.3)
            if cycles or ref:
                ax.legend(fontsize="small", loc="upper left")
    for ax in axes[1]:
        ax.set_xlabel("% of the gait cycle (foot strike → next foot strike)")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


# --------------------------------------------------------------------------- tables


def _num(x: float, digits: int) -> str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _write_csv(path: Path, rows: list[list[object]]) -> Path:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    write_text_atomic(path, buf.getvalue())
    return path


def cycle_rows(gait: Gait) -> list[list[str]]:
    """Rows of ``gait.csv`` under :data:`CYCLE_COLUMNS`: one per cycle, then the summaries of
    the left, the right and both sides (``cycle`` = ``all``)."""
    rows: list[list[str]] = []
    count = dict.fromkeys(SIDES, 0)
    fr = lambda p: _num(float(gait.frame_numbers(p)), 2)  # noqa: E731
    for c in gait.cycles:
        count[c.side] += 1
        rows.append(
            [
                c.side,
                str(count[c.side]),
                fr(c.strike),
                fr(c.foot_off),
                fr(c.end),
                _num(c.strike / gait.fps, 4),
                _num(c.stride_time, 4),
                _num(c.stride_length, 4),
                _num(c.speed, 4),
                _num(c.step_time, 4),
                _num(c.step_length, 4),
                _num(c.stance_pct, 2),
                _num(c.swing_pct, 2),
                _num(120.0 / c.stride_time, 2),
            ]
        )
    for side in (*SIDES, "both"):
        s = gait.summary(side).as_dict()
        rows.append(
            [
                side,
                "all",
                "",
                "",
                "",
                "",
                _num(s["stride_time_s"], 4),
                _num(s["stride_length_m"], 4),
                _num(s["speed_m_per_s"], 4),
                _num(s["step_time_s"], 4),
                _num(s["step_length_m"], 4),
                _num(s["stance_pct"], 2),
                _num(s["swing_pct"], 2),
                _num(s["cadence_steps_per_min"], 2),
            ]
        )
    return rows


def summary_rows(gait: Gait) -> list[list[object]]:
    """Per side (both, left, right): cycles, steps and the :data:`SUMMARY_FIELDS`."""
    out = []
    for side in ("both", *SIDES):
        s = gait.summary(side)
        out.append([side, s.n_cycles, s.n_steps, *s.as_dict().values()])
    return out


SUMMARY_HEADERS = (
    "side",
    "cycles",
    "steps",
    "cadence (steps/min)",
    "stride time (s)",
    "stride length (m)",
    "speed (m/s)",
    "step time (s)",
    "step length (m)",
    "stance (%)",
    "swing (%)",
)
assert len(SUMMARY_HEADERS) == 3 + len(SUMMARY_FIELDS)


def write_gait(
    gait: Gait,
    out: str | os.PathLike,
    *,
    reference: Gait | None = None,
    title: str = "",
) -> list[Path]:
    """Write the CSV tables and PNG plots of ``gait`` (module docstring) into the folder
    ``out`` (created); ``reference`` (the truth) is drawn in the plots. Raises
    :class:`InputError` when ``gait`` found no step (its message says why)."""
    if not gait.found:
        raise InputError(f"gait: no walking or running found: {gait.message}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = [_write_csv(out / "gait.csv", [list(CYCLE_COLUMNS), *cycle_rows(gait)])]
    events = sorted(
        (p, side, kind)
        for k, side in enumerate(SIDES)
        for kind, ev in (("foot_strike", gait.strikes[k]), ("foot_off", gait.foot_offs[k]))
        for p in ev
    )
    rows = [["frame", "time_s", "side", "event"]]
    rows += [
        [_num(float(gait.frame_numbers(p)), 2), _num(p / gait.fps, 4), side, kind]
        for p, side, kind in events
    ]
    files.append(_write_csv(out / "gait_events.csv", rows))
    rows = [["side", "cycle", "percent", "hip_flexion_deg", "knee_flexion_deg"]]
    count = dict.fromkeys(SIDES, 0)
    for c in gait.cycles:
        count[c.side] += 1
        rows += [
            [c.side, count[c.side], p, _num(h, 3), _num(kn, 3)]
            for p, h, kn in zip(range(CYCLE_SAMPLES), c.hip, c.knee, strict=True)
        ]
    files.append(_write_csv(out / "gait_curves.csv", rows))
    head = ["frame", "time_s", "valid"] + [
        f"{s}_{q}"
        for s in SIDES
        for q in (
            "ankle_height_m",
            "ankle_speed_m_per_s",
            "wrist_forward_m",
            "wrist_up_m",
            "hip_flexion_deg",
            "knee_flexion_deg",
        )
    ]
    rows = [head]
    for t in range(len(gait.frames)):
        row = [int(gait.frames[t]), _num(gait.times[t], 4), int(gait.valid[t])]
        for k in range(2):
            vals = (
                gait.ankle_height[t, k],
                gait.ankle_speed[t, k],
                *gait.wrist_sagittal[t, k],
                gait.hip_flexion[t, k],
                gait.knee_flexion[t, k],
            )
            row += [_num(float(v), 4) if gait.valid[t] else "" for v in vals]
        rows.append(row)
    files.append(_write_csv(out / "gait_frames.csv", rows))
    files.append(plot_gait(gait, out / "gait.png", reference=reference, title=title))
    files.append(plot_flexion(gait, out / "gait_flexion.png", reference=reference, title=title))
    return files


# --------------------------------------------------------------------------- a source


@dataclass(frozen=True, eq=False)
class GaitRun:
    """What :func:`gait_of` read and measured.

    Attributes
    ----------
    gait : Gait, of the track (or of the capture's truth)
    what : str, a one-line description of the source
    reference : Gait or None, the ground truth of the track's capture
    comparison : GaitComparison or None, ``gait`` against ``reference``
    """

    gait: Gait
    what: str
    reference: Gait | None
    comparison: GaitComparison | None


def gait_of(source: str | os.PathLike, *, fps: float | None = None, truth: bool = True) -> GaitRun:
    """Gait of a track folder (its joints; frame rate from its capture's ``capture.json``
    unless ``fps`` is given; with ``truth``, compared with that capture's ground truth when
    it has one) or of a capture folder (its ground-truth joints)."""
    path = Path(source)
    if (path / "track.json").is_file():
        track = read_track(path, vertices=False)  # the joints' gait
        cap_path = Path(str(track.meta.get("capture", "")))
        cap = Capture(cap_path) if (cap_path / "capture.json").is_file() else None
        fps = input_frame(track.meta).fps if fps is None else fps  # as track recorded it
        if fps is None:
            if cap is None or "fps" not in cap.meta:
                raise InputError(
                    f"gait: the frame rate of {path} is unknown (its capture {cap_path} has "
                    "no capture.json); give it with --fps"
                )
            fps = cap.fps
        g = track_gait(track, fps)
        ref = cmp = None
        first = cap[0].truth if truth and cap is not None else None
        if first is not None and first.joints is not None:
            ref = capture_gait(cap)
            if ref.found and g.found and abs(ref.fps - fps) < SAME_FPS:
                cmp = compare_gaits(g, ref)
        what = (
            f"{path.name} ({track.meta.get('method', '?')}, {len(track.frames)} frames at "
            f"{fps:g} fps)"
        )
        return GaitRun(g, what, ref, cmp)
    if (path / "capture.json").is_file():
        cap = Capture(path)
        g = capture_gait(cap, fps=fps)
        what = f"the ground truth of {path.name} ({len(cap)} frames at {g.fps:g} fps)"
        return GaitRun(g, what, None, None)
    if not path.exists():
        raise MeshmocapFileNotFoundError(f"gait: {path} does not exist")
    raise InputError(
        f"gait: {path} is neither a track folder (track.json) nor a capture folder (capture.json)"
    )


# --------------------------------------------------------------------------- report


#: Columns of the report's gait table.
GAIT_HEADERS = (
    "source",
    "cycles",
    "steps",
    "cadence (steps/min)",
    "stride length (m)",
    "stride time (s)",
    "speed (m/s)",
    "stance (%)",
    "events matched",
    "mean offset (frames)",
    "max offset (frames)",
    "cadence error (%)",
    "stride length error (%)",
)
EVENTS_NOTE = (
    "Gait events come from the ankle joints (the 15-joint skeleton has no toe or heel): a foot "
    "is planted while its ankle moves slower than the body walks (the pelvis's median speed) "
    "in the lower 70 % of its height range; a foot strike starts a stance and a foot off ends "
    "it, to a fraction of a frame."
)


@dataclass(frozen=True)
class GaitReport:
    """The gait part of a report: table rows under :data:`GAIT_HEADERS`, notes, and
    ``(caption, PNG bytes)`` plots."""

    rows: tuple[tuple[object, ...], ...]
    notes: tuple[str, ...]
    images: tuple[tuple[str, bytes], ...]


def _has_truth(capture) -> bool:
    if not isinstance(capture, Capture) or not len(capture):
        return False
    t = capture[0].truth
    return t is not None and t.joints is not None and bool(capture.meta.get("eval_names"))


def gait_report(capture, tracks, names, folder: str | os.PathLike) -> GaitReport:
    """Gait of each track (and of the capture's ground truth, when it has one) at the
    capture's frame rate, each track compared with the truth; plots written under
    ``folder`` and returned as bytes."""
    nan = math.nan
    rows, notes, images = [], [EVENTS_NOTE], []
    said = isinstance(capture, Capture) and "fps" in capture.meta
    if not (said or getattr(capture, "fps_given", False)):
        notes.append(
            f"frame rate: the capture does not say; {capture.fps:g} fps assumed (times, "
            "speeds and cadence scale with it)"
        )
    truth = None
    if _has_truth(capture):
        try:
            truth = capture_gait(capture)
        except InputError as exc:  # e.g. a capture of two frames
            notes.append(f"ground truth: no gait: {exc}")
    if truth is not None and truth.found:
        s = truth.summary()
        rows.append(
            (
                "ground truth",
                s.n_cycles,
                s.n_steps,
                s.cadence_steps_per_min,
                s.stride_length_m,
                s.stride_time_s,
                s.speed_m_per_s,
                s.stance_pct,
                "",
                nan,
                nan,
                nan,
                nan,
            )
        )
        notes.append(
            "events matched: the truth's foot strikes and foot offs that the track reproduces "
            "(same foot and kind, within 0.2 s; +n: spurious events); offsets in frames at "
            f"{capture.fps:g} fps; errors are (track − truth) / truth."
        )
    elif truth is not None:
        notes.append(f"ground truth: no gait: {truth.message}")
    for k, (name, track) in enumerate(zip(names, tracks, strict=True)):
        try:
            g = track_gait(track, capture.fps)
        except InputError as exc:  # e.g. a track of two frames
            notes.append(f"{name}: no gait: {exc}")
            continue
        if not g.found:
            notes.append(f"{name}: no gait: {g.message}")
            continue
        s = g.summary()
        c = compare_gaits(g, truth) if truth is not None and truth.found else None
        matched = ""
        if c is not None:
            matched = f"{c.matched}/{c.reference_events}" + (f" +{c.spurious}" * bool(c.spurious))
        rows.append(
            (
                name,
                s.n_cycles,
                s.n_steps,
                s.cadence_steps_per_min,
                s.stride_length_m,
                s.stride_time_s,
                s.speed_m_per_s,
                s.stance_pct,
                matched,
                c.mean_offset if c else nan,
                c.max_offset if c else nan,
                c.cadence_error_pct if c else nan,
                c.stride_length_error_pct if c else nan,
            )
        )
        ref = truth if truth is not None and truth.found else None
        out = Path(folder) / str(k)
        out.mkdir(parents=True, exist_ok=True)
        title = f"{name}{' (dashed: truth)' if ref else ''}"
        plots = (
            (plot_gait, "gait.png", "ankle heights and wrist paths"),
            (plot_flexion, "gait_flexion.png", "hip and knee flexion"),
        )
        for plot, file, what in plots:
            p = plot(g, out / file, reference=ref, title=title)
            images.append((f"{name}: {what}", p.read_bytes()))
    return GaitReport(tuple(rows), tuple(notes), tuple(images))
