"""Tracks out of the tool (``meshmocap export``): BVH, C3D, TRC, glTF/GLB and CSV.

One function, :func:`export_track`, turns a track folder into one file; the format comes
from the file's extension unless given. What each format holds, in which units and axes,
is documented in its writer's module:

========  ======================================================  ============================
format    content                                                 writer
========  ======================================================  ============================
``bvh``   the template's 31-bone rig, rotations solved from the   :mod:`meshmocap.io.bvh`
          tracked surface; Y up, centimetres, the capture's rate
``glb``   the template as a skinned mesh with the same            :mod:`meshmocap.io.gltf`
``gltf``  animation; Y up, metres (one file, buffer embedded)
``c3d``   the 15 evaluation joints (plus virtual markers) as      :mod:`meshmocap.io.c3d`
          labelled points; Z up, millimetres
``trc``   the same points for OpenSim; its Y-up frame, mm         :mod:`meshmocap.io.trc`
``csv``   the evaluation joints per frame (or per frame and       :mod:`meshmocap.io.joints_csv`
          joint), health and flags; Z up, metres
========  ======================================================  ============================

Frames without a fit are never passed off as tracked. A frame the tracker coasted across
(flagged ``missing`` or ``failed``: it holds the last good values) and a frame that
``track.json`` planned but the run never reached, between the first and last exported, are
*gaps*: no value in TRC, residual −1 in C3D, empty coordinate cells in CSV; BVH and glTF
have no gaps, so the rig holds its last tracked pose there, and :attr:`ExportResult.gaps`
lists those frames (the command prints them). Planned frames never tracked are listed in
:attr:`ExportResult.untracked` and warned about (a run killed after 4 of 12 frames exports
4 and says the other 8 were never tracked).

The rig rotations (BVH, glTF) come from :func:`meshmocap.body.pose_fit.pose_from_surface`:
per frame, the pose whose skinning of the template reproduces the tracked vertices and
joints; the result reports how closely (``vertex_error_mm``, ``joint_error_mm``).
"""

from __future__ import annotations

import json
import os
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from meshmocap._validate import check_choice
from meshmocap.body.markers import MARKER_SETS, marker_vertices
from meshmocap.body.motion import Motion
from meshmocap.body.pose_fit import PoseFit, pose_from_surface
from meshmocap.body.template import Template, load_template
from meshmocap.errors import InputError, MeshmocapFileNotFoundError, MissingFrameWarning
from meshmocap.io.bvh import LengthUnit, write_bvh
from meshmocap.io.c3d import write_c3d
from meshmocap.io.gltf import skinned_gltf, write_gltf
from meshmocap.io.joints_csv import write_joints_csv
from meshmocap.io.results import Track, planned_frames, read_track, tracked_template
from meshmocap.io.trc import write_trc

__all__ = [
    "GAP_FLAGS",
    "ExportFormat",
    "ExportFrames",
    "ExportResult",
    "capture_fps",
    "export_format",
    "export_frames",
    "export_track",
    "frame_ranges",
    "track_fps",
    "track_gltf",
    "track_motion",
    "track_rows",
    "track_template",
]

ExportFormat = Literal["bvh", "c3d", "trc", "gltf", "glb", "csv"]
#: Marker options: none, or a set of :data:`meshmocap.body.markers.MARKER_SETS`.
Markers = Literal["none", "lower_body"]
#: Frame rate assumed when neither the track nor its capture states one.
DEFAULT_FPS = 30.0


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export_track` wrote.

    Attributes
    ----------
    path : Path; format : str; n_frames : int; fps : float
    size_bytes : int; seconds : float, wall time of the whole export
    vertex_error_mm, joint_error_mm : float
        Mean distance between the re-skinned template and the tracked vertices / joints
        (BVH and glTF; NaN for the point formats, which copy the track's values)
    points : tuple of str, the labelled points written (C3D, TRC, CSV)
    fps_source : str, where the frame rate came from (``capture.json``, ``given``, ...)
    gaps : tuple of int
        Frame numbers written as gaps (TRC, C3D, CSV) or held at the last tracked pose
        (BVH, glTF): coasted frames and planned frames never tracked inside the range
    untracked : tuple of int
        Frames ``track.json`` planned (within ``frames``) that have no result
    planned : int, frames ``track.json`` planned within ``frames`` (0 when it lists none)
    fit : PoseFit or None, the rig's poses fitted to the frames (BVH and glTF): another rig
        export of the same frames can take it (:func:`export_track`'s ``fit``)
    """

    path: Path
    format: str
    n_frames: int
    fps: float
    size_bytes: int
    seconds: float
    vertex_error_mm: float = float("nan")
    joint_error_mm: float = float("nan")
    points: tuple[str, ...] = ()
    fps_source: str = ""
    gaps: tuple[int, ...] = ()
    untracked: tuple[int, ...] = ()
    planned: int = 0
    fit: PoseFit | None = field(default=None, compare=False, repr=False)


def export_format(
    path: str | os.PathLike, format: str | None = None, *, given_as: str = "format="
) -> str:
    """The format of ``path``: ``format`` when given (checked), else its extension;
    ``given_as`` names the way to give it in the message (``--format`` on the command
    line)."""
    choices = get_args(ExportFormat)
    if format is not None:
        check_choice("export", "format", format, choices)
        return format
    ext = Path(path).suffix.lower().lstrip(".")
    if ext not in choices:
        raise InputError(
            f"export: cannot tell the format of {Path(path).name!r} from its extension; "
            f"use one of {['.' + c for c in choices]} or give {given_as}"
        )
    return ext


def capture_fps(meta: dict, fps: float | None = None) -> tuple[float, str]:
    """The frame rate of a track from its ``track.json`` contents ``meta`` and where it
    comes from: ``fps`` when given, else ``meta["fps"]``, else its capture's
    ``capture.json``, else :data:`DEFAULT_FPS`."""
    if fps is not None:
        if not (np.isfinite(fps) and fps > 0):
            raise InputError(f"export: fps must be a positive number, found {fps!r}")
        return float(fps), "given"
    if meta.get("fps"):
        return float(meta["fps"]), "track.json"
    cap = meta.get("capture")
    if cap:
        try:
            value = json.loads((Path(cap) / "capture.json").read_text()).get("fps")
        except (OSError, ValueError, AttributeError):
            value = None
        if value:
            return float(value), "capture.json"
    return DEFAULT_FPS, "default"


def track_fps(track: Track, fps: float | None = None) -> tuple[float, str]:
    """The frame rate of ``track`` and where it comes from (:func:`capture_fps`)."""
    return capture_fps(track.meta, fps)


def track_template(track: Track, template: Template | str | None = None) -> Template:
    """The template ``track`` deformed: ``template`` when given, else the one named in
    ``track.json``; its vertex count must match the track's."""
    if template is None or isinstance(template, str | os.PathLike):
        name = template if template is not None else track.meta.get("template")
        try:
            template = load_template(str(name))
        except MeshmocapFileNotFoundError:
            raise MeshmocapFileNotFoundError(
                f"export: the track was made with template {name!r}, which is not bundled; "
                "pass its file (template=, --template)"
            ) from None
    if template.n_vertices != track.vertices.shape[1]:
        raise InputError(
            f"export: template {template.name!r} has {template.n_vertices} vertices, the track "
            f"{track.vertices.shape[1]}"
        )
    return template


def track_rows(track: Track, frames: slice | None = None) -> np.ndarray:
    """Rows of ``track`` whose frame numbers lie in ``frames`` (a slice over capture frame
    numbers, ``slice(0, 60, 2)``; all rows when None)."""
    rows = np.arange(len(track.frames))
    if frames is not None:
        stop = int(track.frames.max()) + 1
        wanted = np.arange(*frames.indices(stop))
        rows = rows[np.isin(track.frames, wanted)]
    if len(rows) == 0:
        raise InputError(
            f"export: no track frame in {frames} (the track has frames "
            f"{int(track.frames[0])}..{int(track.frames[-1])})"
        )
    return rows


def _step(numbers: np.ndarray, fmt: str) -> int:
    """The constant spacing of the frame numbers ``numbers`` (formats with a fixed rate)."""
    d = np.diff(numbers)
    if len(d) and not np.all(d == d[0]):
        raise InputError(
            f"export: {fmt} needs evenly spaced frames, found gaps in "
            f"{numbers[:8].tolist()}...; select a run with --frames"
        )
    return int(d[0]) if len(d) else 1


#: Flags of frames that hold the last good values instead of a fit (exported as gaps).
GAP_FLAGS = ("missing", "failed")


@dataclass(frozen=True, eq=False)
class ExportFrames:
    """The frames an export writes, gaps included (:func:`export_frames`).

    Attributes
    ----------
    frames : (G,) int64, frame numbers, increasing
    rows : (G,) int64, each frame's own track row (−1: never tracked)
    values : (G,) int64, the track row each frame's values come from: its own, or for a
        gap the last row with a fit of its own before it, held (the first, before it)
    gap : (G,) bool, True where the frame has no fit of its own
    untracked : tuple of int, planned frames (within the selection) without a result
    planned : int, frames ``track.json`` planned within the selection (0: it lists none)
    """

    frames: np.ndarray
    rows: np.ndarray
    values: np.ndarray
    gap: np.ndarray
    untracked: tuple[int, ...]
    planned: int


def export_frames(track: Track, frames: slice | None = None) -> ExportFrames:
    """The frames to export from ``track`` within ``frames`` (capture frame numbers): its
    tracked rows, plus the frames ``track.json`` planned but that have no result, between
    the first and last tracked ones; gaps are those and the coasted frames
    (:data:`GAP_FLAGS`)."""
    rows = track_rows(track, frames)
    done = track.frames[rows]
    planned = np.unique(np.asarray(planned_frames(track.meta), dtype=np.int64))
    if frames is not None and len(planned):
        stop = int(max(planned.max(), track.frames.max())) + 1
        planned = planned[np.isin(planned, np.arange(*frames.indices(stop)))]
    untracked = np.setdiff1d(planned, track.frames)
    inside = untracked[(untracked > done[0]) & (untracked < done[-1])]
    numbers = np.union1d(done, inside)
    never = np.isin(numbers, inside)
    src = rows[np.searchsorted(done, numbers, side="right") - 1]  # a frame, or the one before
    if track.flags:
        coasted = np.array([bool(set(track.flags[r]) & set(GAP_FLAGS)) for r in src], bool)
    else:
        coasted = ~track.healthy[src]
    gap = coasted | never
    values = src
    own = np.flatnonzero(~gap)
    if len(own):  # a gap holds the last frame with a fit of its own (the first, before it)
        values = src[own[np.maximum(np.searchsorted(own, np.arange(len(src)), "right") - 1, 0)]]
    return ExportFrames(
        numbers,
        np.where(never, -1, src),
        values,
        gap,
        tuple(int(i) for i in untracked),
        len(planned),
    )


def frame_ranges(frames: Sequence[int]) -> str:
    """``"3, 7–11, 20"``: frame numbers as runs of consecutive numbers."""
    out: list[str] = []
    f = sorted(int(i) for i in frames)
    k = 0
    while k < len(f):
        j = k
        while j + 1 < len(f) and f[j + 1] == f[j] + 1:
            j += 1
        out.append(str(f[k]) if j == k else f"{f[k]}–{f[j]}")
        k = j + 1
    return ", ".join(out)


def track_motion(
    track: Track,
    template: Template,
    rows: np.ndarray,
    fps: float,
    *,
    joint_weight: float = 2.0,
    step: int | None = None,
    fit: PoseFit | None = None,
) -> tuple[Motion, PoseFit]:
    """The template's rig animated by the poses fitted to the track's rows (frame rate
    ``fps`` divided by the rows' spacing, or by ``step`` when given: rows may then repeat,
    holding a pose across frames without a result), and the fit (``fit``: made already).

    The motion's skeleton is the template's (:func:`~meshmocap.io.bvh.write_bvh` writes
    the root's positions absolute, as every BVH reader understands them).
    """
    if fit is None:
        fit = pose_from_surface(
            template, track.vertices[rows], joints=track.joints[rows], joint_weight=joint_weight
        )
    step = _step(track.frames[rows], "a motion") if step is None else int(step)
    return Motion(template.skeleton, fit.rotations, fit.root_positions, fps / step), fit


def track_gltf(
    track: Track,
    template: Template,
    rows: np.ndarray,
    fps: float,
    *,
    fit: PoseFit | None = None,
    color: tuple[float, float, float] = (0.7, 0.7, 0.7),
    name: str | None = None,
    frames: np.ndarray | None = None,
):
    """The skinned template animated by the track's rows as a ``pygltflib.GLTF2`` (times:
    frame number minus the first row's, over ``fps``; ``frames`` gives each row's frame
    number when rows repeat to hold a pose) and the fit it comes from."""
    if fit is None:
        fit = pose_from_surface(template, track.vertices[rows], joints=track.joints[rows])
    numbers = track.frames[rows] if frames is None else np.asarray(frames)
    times = (numbers - numbers[0]) / fps
    g = skinned_gltf(
        template.V,
        template.F,
        template.skeleton,
        template.weights,
        fit.rotations,
        fit.root_positions,
        times,
        name=name or template.name,
        color=color,
    )
    return g, fit


def _points(track: Track, rows, joints, markers, template_arg):
    names = list(
        track.meta.get("eval_names") or [f"joint{k}" for k in range(track.joints.shape[1])]
    )
    keep = list(range(len(names)))
    if joints is not None:
        unknown = [j for j in joints if j not in names]
        if unknown:
            raise InputError(f"export: unknown joints {unknown}; the track has {names}")
        keep = [names.index(j) for j in joints]
    X = track.joints[rows][:, keep]
    labels = [names[k] for k in keep]
    if markers != "none":
        template = track_template(track, template_arg)
        mnames, idx = marker_vertices(template, MARKER_SETS[markers])
        X = np.concatenate([X, track.vertices[rows][:, idx]], axis=1)
        labels += list(mnames)
    return X, labels


def export_track(
    track: str | os.PathLike | Track,
    out: str | os.PathLike,
    *,
    format: ExportFormat | None = None,
    frames: slice | None = None,
    joints: Sequence[str] | None = None,
    markers: Markers = "none",
    long: bool = False,
    fps: float | None = None,
    template: Template | str | None = None,
    bvh_unit: LengthUnit = "cm",
    joint_weight: float = 2.0,
    fit: PoseFit | None = None,
) -> ExportResult:
    """Write a track (a folder or a read :class:`~meshmocap.io.results.Track`) as ``out``.

    Parameters
    ----------
    format : {"bvh", "c3d", "trc", "gltf", "glb", "csv"}, optional
        Default: ``out``'s extension.
    frames : slice, optional
        Capture frame numbers to keep (``slice(0, 60, 2)``).
    joints : sequence of str, optional
        Evaluation joints to keep (C3D, TRC, CSV; the rig formats always hold the rig).
    markers : {"none", "lower_body"}
        Virtual markers added to C3D and TRC (:mod:`meshmocap.body.markers`).
    long : bool
        CSV: one row per frame and joint.
    fps : float, optional
        Frame rate (default: the track's capture's, see :func:`track_fps`).
    template : Template or name or path, optional
        The tracking template when it is not the bundled one named in ``track.json``.
    bvh_unit : {"m", "cm", "mm", "inch", "cmu"}
        Length unit of a BVH file.
    joint_weight : float
        Weight of the tracked joints in the pose fit (BVH, glTF; see
        :func:`~meshmocap.body.pose_fit.pose_from_surface`).
    fit : PoseFit, optional
        BVH, glTF: the rig's poses already fitted to these frames with this template and
        ``joint_weight`` (:attr:`ExportResult.fit` of another rig export of the track: a
        BVH and a GLB of one track fit it once).

    Raises
    ------
    InputError
        An unknown format or extension, joints, markers or frames; options that do not
        apply to the format; unevenly spaced frames for BVH, C3D, TRC.
    MeshmocapFileNotFoundError
        No track, or an output folder that does not exist.
    """
    t0 = time.perf_counter()
    out = Path(out)
    fmt = export_format(out, format)
    check_choice("export", "markers", markers, get_args(Markers))
    if not out.parent.is_dir():
        raise MeshmocapFileNotFoundError(f"export: folder {out.parent} does not exist")
    if fmt in ("bvh", "gltf", "glb") and (joints is not None or markers != "none"):
        raise InputError(f"export: joints and markers select points of c3d, trc and csv, not {fmt}")
    if fmt == "csv" and markers != "none":
        raise InputError("export: markers go to c3d and trc, not csv")
    if long and fmt != "csv":
        raise InputError(f"export: long applies to csv, not {fmt}")
    if fit is not None and fmt not in ("bvh", "gltf", "glb"):
        raise InputError(f"export: a fit applies to bvh, gltf and glb, not {fmt}")
    tr = track if isinstance(track, Track) else read_track(track)
    posed = fmt in ("bvh", "gltf", "glb") or markers != "none"  # these need the template
    if template is None and posed and not isinstance(track, Track):
        template = tracked_template(track, tr.meta)  # an estimated subject: its file
    ex = export_frames(tr, frames)
    rows, idx = ex.values, ex.frames
    rate, source = track_fps(tr, fps)
    if ex.untracked:
        n = len(ex.untracked)
        warnings.warn(
            f"export: {'the track' if isinstance(track, Track) else track}: {n} of the "
            f"{ex.planned} frames "
            f"track.json planned were never tracked ({frame_ranges(ex.untracked)}); "
            "'meshmocap track' with the same arguments resumes them",
            MissingFrameWarning,
            stacklevel=2,
        )
    verr = jerr = float("nan")
    labels: list[str] = []
    if fmt in ("bvh", "gltf", "glb"):
        tpl = track_template(tr, template)
        step = _step(idx, fmt)
        if fit is not None and len(fit.rotations) != len(rows):
            raise InputError(
                f"export: the fit given holds {len(fit.rotations)} frames, the export {len(rows)}"
            )
        if fmt == "bvh":
            motion, fit = track_motion(
                tr, tpl, rows, rate, joint_weight=joint_weight, step=step, fit=fit
            )
            write_bvh(out, motion, unit=bvh_unit)
        else:
            if fit is None:
                fit = pose_from_surface(
                    tpl, tr.vertices[rows], joints=tr.joints[rows], joint_weight=joint_weight
                )
            g, _ = track_gltf(tr, tpl, rows, rate, fit=fit, frames=idx)
            write_gltf(out, g)
        own = ~ex.gap  # the pose fit's error on frames with a fit of their own
        if own.any():
            verr = float(fit.vertex_error[own].mean() * 1e3)
            jerr = float(fit.joint_error[own].mean() * 1e3)
    elif fmt in ("c3d", "trc"):
        step = _step(idx, fmt)
        X, labels = _points(tr, rows, joints, markers, template)
        if fmt == "c3d":
            write_c3d(out, X, labels, rate / step, first_frame=int(idx[0]), valid=~ex.gap)
        else:
            write_trc(
                out,
                X,
                labels,
                rate / step,
                first_frame=int(idx[0]),
                start_time=idx[0] / rate,
                valid=~ex.gap,
            )
    else:
        X, labels = _points(tr, rows, joints, "none", template)
        own = [int(r) for r in ex.rows]
        write_joints_csv(
            out,
            X,
            labels,
            idx,
            rate,
            healthy=~ex.gap & tr.healthy[np.maximum(ex.rows, 0)],
            flags=[tr.flags[r] if r >= 0 and tr.flags else () for r in own],
            messages=[
                "never tracked" if r < 0 else tr.messages[r] if tr.messages else "" for r in own
            ],
            long=long,
            valid=~ex.gap,
        )
    return ExportResult(
        out,
        fmt,
        len(idx),
        rate,
        out.stat().st_size,
        time.perf_counter() - t0,
        verr,
        jerr,
        tuple(labels),
        source,
        tuple(int(i) for i in idx[ex.gap]),
        ex.untracked,
        ex.planned,
        fit if fmt in ("bvh", "gltf", "glb") else None,
    )
