"""The sequence driver shared by every tracker: streams frames, writes results frame by
frame, shows progress, resumes interrupted runs and never emits NaN.

A frame whose fit raises a numerical error or returns non-finite values is flagged
``failed`` (``healthy = False``, with the reason), the tracker is reset to the last good
state, and tracking continues with the next frame; the flagged frame repeats the last good
result. A frame without observation (the capture records it as dropped, or its hull or mesh
file is absent or unreadable) is flagged ``missing`` with the reason, and the tracker
coasts across it the same way: the next real frame is fitted from the last good state.

Only one process writes into a track folder at a time: a second one is refused in one line
(``meshmocap._atomic.folder_lock``, released by the kernel when a run dies).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from meshmocap._atomic import folder_lock
from meshmocap._progress import progress
from meshmocap.body.template import Template
from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError
from meshmocap.io.capture import Capture
from meshmocap.io.results import (
    FrameResult,
    Track,
    done_frames,
    frame_flags,
    read_frame_arrays,
    read_state,
    read_track,
    start_track,
    write_frame,
)
from meshmocap.trackers.base import Tracker

#: Errors that mean "this frame could not be fitted" rather than a bug or a user mistake.
NUMERICAL_ERRORS = (np.linalg.LinAlgError, FloatingPointError, ArithmeticError)


def _finite(r: FrameResult) -> bool:
    return bool(np.all(np.isfinite(r.joints)) and np.all(np.isfinite(r.vertices)))


def track_sequence(
    tracker: Tracker,
    template: Template,
    capture: Capture,
    out: str | os.PathLike,
    *,
    frames: Sequence[int] | None = None,
    resume: bool = True,
    show_progress: bool | None = None,
    vertices: bool = True,
    template_info: dict | None = None,
) -> Track:
    """Track ``capture`` with ``tracker`` and write the results to the folder ``out``.

    Parameters
    ----------
    tracker : Tracker
    template : Template
        The tracking template.
    capture : Capture
        Frames to track. The first one (of ``frames``) initialises the template's pose from
        its ground truth when it has one (the protocol of the papers' evaluations), else the
        template starts in its rest pose (right for a template made from that frame).
    out : path
        Track folder (:mod:`meshmocap.io.results`).
    frames : sequence of int, optional
        Positions in the capture to track (default: all).
    resume : bool
        Continue an interrupted run in ``out`` (same settings) instead of starting over.
    vertices : bool
        Read the tracked vertices back into the returned track (False for long runs: see
        :func:`~meshmocap.io.results.read_track`).
    template_info : dict, optional
        How the template was chosen, kept in ``track.json`` (``template_source``: ``"given"``,
        ``"capture"`` or ``"estimated"``; ``template_file``); see
        :func:`meshmocap.estimate.tracking_template.tracking_template`.

    Returns
    -------
    Track
        Every frame's result, read back from ``out``.
    """
    positions = list(range(len(capture))) if frames is None else list(frames)
    if not positions:
        raise InputError("track: no frames to track")
    indices = [int(capture.indices[k]) for k in positions]  # without reading the frames
    meta = {
        "method": tracker.name,
        "template": template.name,
        "capture": str(Path(capture.path).resolve()),
        "frames": indices,
        "eval_names": list(template.eval_skeleton.names),
        "eval_parents": template.eval_skeleton.parents.tolist(),
        "options": tracker.options(),
        **(template_info or {}),
    }
    Path(out).mkdir(parents=True, exist_ok=True)
    with folder_lock(out, "track"):  # a second run into the same folder is refused
        done = set(start_track(out, meta, template.F, resume=resume))
        if indices[0] not in done:
            _initialise(tracker, template, capture, out, positions)
            done = set(done_frames(out))
        todo = [k for k in positions[1:] if capture.indices[k] not in done]
        if todo:
            last = max(
                (i for i in indices if i in done and i < capture.indices[todo[0]]),
                default=indices[0],
            )
            if getattr(tracker, "template", None) is not template:  # resuming: not initialised
                tracker.setup(template)
            tracker.set_state(read_state(out, last))
            good = last
            for k in progress(todo, label=tracker.name, enabled=show_progress):
                index, reason = int(capture.indices[k]), None
                t0 = time.perf_counter()
                try:
                    frame = capture[k]  # a mesh sequence reads the file here
                    reason = missing_reason(frame)
                    if reason is None:
                        r = tracker.step(frame)
                        if not _finite(r):
                            raise FloatingPointError("non-finite joints or vertices")
                        r = replace(r, index=index, seconds=time.perf_counter() - t0)
                        good = index
                except NUMERICAL_ERRORS as exc:
                    r = _carry(tracker, out, good, index, t0, "failed", _why(exc))
                except FRAME_ERRORS as exc:  # this frame's file is absent or unreadable
                    reason = _why(exc)
                if reason is not None:
                    r = _carry(tracker, out, good, index, t0, "missing", reason)
                write_frame(out, r)
    return read_track(out, vertices=vertices)


#: Errors reading one frame's observation (an absent, empty or corrupt hull or mesh file):
#: the frame is flagged ``missing`` and tracking goes on.
FRAME_ERRORS = (MeshmocapFileNotFoundError, FormatError, MeshError)


def missing_reason(frame: object) -> str | None:
    """Why ``frame`` has no observation (its capture says so), or None."""
    reason = getattr(frame, "missing", None)
    return str(reason) if reason else None


def _why(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".splitlines()[0][:200]


def _carry(
    tracker: Tracker, out, good: int, index: int, t0: float, flag: str, why: str
) -> FrameResult:
    """Coast across frame ``index``: the tracker goes back to the state of the last good
    frame, and the frame repeats that frame's result, flagged ``flag`` with the reason (the
    next real frame is fitted from there)."""
    tracker.set_state(read_state(out, good))
    prev = read_track_frame(out, good)
    return replace(prev, index=index, seconds=time.perf_counter() - t0, healthy=False,
                   message=why, flags=(flag,))  # fmt: skip


def _initialise(tracker: Tracker, template: Template, capture, out, positions: list[int]) -> None:
    """Start on the first frame that has an observation: from its ground truth pose when it
    has one, else from the template's rest pose. Frames before it are written as copies of
    it, flagged ``missing``."""
    skipped: list[tuple[int, str]] = []
    for k in positions:
        index = int(capture.indices[k])
        try:
            frame = capture[k]  # a mesh sequence reads the file here
            reason = missing_reason(frame)
        except FRAME_ERRORS as exc:
            reason = _why(exc)
        if reason is None:
            truth = _truth(frame)
            if truth is not None and truth.rotations is not None:
                R, root = truth.rotations, truth.root
            else:  # no known pose: the rest pose (e.g. a template cut from that frame)
                R = np.tile(np.eye(3), (template.skeleton.n_joints, 1, 1))
                root = template.skeleton.rest_positions[0]
            t0 = time.perf_counter()
            try:
                r = tracker.init(template, frame, R, root)
            except FRAME_ERRORS as exc:
                reason = _why(exc)
        if reason is not None:
            skipped.append((index, reason))
            continue
        write_frame(out, replace(r, index=index, seconds=time.perf_counter() - t0))
        for index, why in skipped:
            write_frame(out, replace(r, index=index, seconds=0.0, healthy=False, message=why,
                                     flags=("missing",)))  # fmt: skip
        return
    raise InputError(f"track: no frame of {capture.path} has an observation to start from "
                     f"(frame {skipped[0][0]}: {skipped[0][1]})")  # fmt: skip


def _truth(frame):
    try:
        return frame.truth
    except FRAME_ERRORS:  # a damaged truth file: start from the rest pose
        return None


def read_track_frame(out: str | os.PathLike, index: int) -> FrameResult:
    """One frame's result from a track folder."""
    z = read_frame_arrays(out, index)
    return FrameResult(
        index=int(z["index"]), joints=z["joints"].astype(np.float64),
        vertices=z["vertices"].astype(np.float64),
        energies={k[7:]: float(v) for k, v in z.items() if k.startswith("energy_")},
        n_iter=int(z["n_iter"]), seconds=float(z["seconds"]), healthy=bool(z["healthy"]),
        message=str(z["message"]), flags=frame_flags(z),
        state={k[6:]: v for k, v in z.items() if k.startswith("state_")},
    )  # fmt: skip
