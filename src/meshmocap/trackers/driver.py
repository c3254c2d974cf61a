"""The sequence driver shared by every tracker: streams frames, writes results frame by
frame, shows progress, resumes interrupted runs and never emits NaN.

A frame whose fit raises a numerical error or returns non-finite values is flagged
``failed`` (``healthy = False``, with the reason), the tracker is reset to the last good
state, and tracking continues with the next frame; the flagged frame repeats the last good
result.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from meshmocap._progress import progress
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.io.capture import Capture
from meshmocap.io.results import (
    FrameResult,
    Track,
    frame_flags,
    frame_path,
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
    indices = [capture[k].index for k in positions]
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
    done = set(start_track(out, meta, template.F, resume=resume))
    first = capture[positions[0]]
    if indices[0] not in done:
        truth = first.truth
        if truth is not None and truth.rotations is not None:
            R, root = truth.rotations, truth.root
        else:  # no known pose: the template's rest pose (e.g. a template cut from frame 0)
            R = np.tile(np.eye(3), (template.skeleton.n_joints, 1, 1))
            root = template.skeleton.rest_positions[0]
        t0 = time.perf_counter()
        r = tracker.init(template, first, R, root)
        write_frame(out, replace(r, index=first.index, seconds=time.perf_counter() - t0))
        done.add(first.index)
    todo = [k for k in positions[1:] if capture[k].index not in done]
    if todo:
        last = max(
            (i for i in indices if i in done and i < capture[todo[0]].index), default=indices[0]
        )
        if getattr(tracker, "template", None) is not template:  # resuming: not initialised
            tracker.setup(template)
        tracker.set_state(read_state(out, last))
        good = last
        for k in progress(todo, label=tracker.name, enabled=show_progress):
            frame = capture[k]
            t0 = time.perf_counter()
            try:
                r = tracker.step(frame)
                if not _finite(r):
                    raise FloatingPointError("non-finite joints or vertices")
                r = replace(r, index=frame.index, seconds=time.perf_counter() - t0)
                good = frame.index
            except NUMERICAL_ERRORS as exc:
                state = read_state(out, good)
                tracker.set_state(state)
                prev = read_track_frame(out, good)
                why = f"{type(exc).__name__}: {exc}"[:200]
                dt = time.perf_counter() - t0
                r = replace(prev, index=frame.index, seconds=dt, healthy=False, message=why,
                            flags=("failed",))  # fmt: skip
            write_frame(out, r)
    return read_track(out)


def read_track_frame(out: str | os.PathLike, index: int) -> FrameResult:
    """One frame's result from a track folder."""
    with np.load(frame_path(out, index), allow_pickle=False) as z:
        return FrameResult(
            index=int(z["index"]), joints=z["joints"].astype(np.float64),
            vertices=z["vertices"].astype(np.float64),
            energies={k[7:]: float(z[k]) for k in z.files if k.startswith("energy_")},
            n_iter=int(z["n_iter"]), seconds=float(z["seconds"]), healthy=bool(z["healthy"]),
            message=str(z["message"]), flags=frame_flags(z),
            state={k[6:]: z[k] for k in z.files if k.startswith("state_")},
        )  # fmt: skip
