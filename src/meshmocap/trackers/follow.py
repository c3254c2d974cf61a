"""Live tracking: frames tracked as a studio writes them into a folder (``track --follow``).

:func:`follow_sequence` watches a capture folder's ``hulls/`` or a folder of meshes
(:class:`~meshmocap.io.live.FrameFolder`: complete files only, written then renamed),
tracks each new frame as soon as it appears, in frame order, and writes its result into the
track folder at once, exactly as :func:`~meshmocap.trackers.driver.track_sequence` would
(the same per-frame function, :func:`~meshmocap.trackers.driver.track_frame`): the same
initialisation on the first frame with an observation, the same ``failed`` and
``missing`` flags, the same results. A frame that arrives after a later one has been
tracked is left out (tracking goes forwards in time). It stops when ``stop()`` says so,
after ``idle`` seconds without a new frame, or on Ctrl-C (``KeyboardInterrupt``: every
frame finished so far is on disk); run again into the same folder, it resumes after the
last frame written.

The track folder records ``"frames": "follow"`` in ``track.json``: it resumes with
``--follow``, and reads like any track (``eval``, ``report``, ``export``).
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from meshmocap._atomic import folder_lock
from meshmocap._threads import blas_threads
from meshmocap.body.light import LIGHT_VERTICES, tracking_body
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.io.live import FrameFile, FrameFolder, young
from meshmocap.io.results import done_frames, start_track, write_frame, write_light_binding
from meshmocap.trackers.base import Tracker
from meshmocap.trackers.driver import (
    initialise_tracker,
    read_track_frame,
    resume_tracker,
    track_frame,
)

__all__ = ["FollowedFrame", "follow_sequence"]


@dataclass(frozen=True)
class FollowedFrame:
    """One frame tracked live.

    Attributes
    ----------
    index : int, the frame number
    seconds : float, reading and fitting it (the driver's time of the frame)
    latency : float, from the file's modification time (when the studio finished writing
        it) to its result written, seconds
    flags : tuple of str, as in the track (``failed``, ``missing``; empty when healthy)
    message : str, why a flagged frame is flagged
    """

    index: int
    seconds: float
    latency: float
    flags: tuple[str, ...]
    message: str


class _Pending:
    """The frames listed but not yet tracked, as a capture-like sequence for the driver."""

    def __init__(self, folder: FrameFolder, files: list[FrameFile]):
        self.folder, self.files, self.path = folder, files, folder.path
        self.indices = [f.index for f in files]

    def __len__(self) -> int:
        return len(self.files)

    def __getitem__(self, k: int):
        return self.folder.frame(self.files[k])


def follow_sequence(
    tracker: Tracker,
    template: Template,
    source: str | os.PathLike,
    out: str | os.PathLike,
    *,
    idle: float | None = None,
    poll: float = 0.02,
    up: str = "z",
    resume: bool = True,
    stop: Callable[[], bool] | None = None,
    report: Callable[[FollowedFrame], None] | None = None,
    template_info: dict | None = None,
    light: int | None = LIGHT_VERTICES,
) -> list[int]:
    """Track the frames written into the folder ``source`` as they arrive.

    Parameters
    ----------
    tracker, template : as for :func:`~meshmocap.trackers.driver.track_sequence`
    source : path
        A capture folder or a folder of mesh files, being written
        (:class:`~meshmocap.io.live.FrameFolder`).
    out : path
        Track folder.
    idle : float, optional
        Stop after this many seconds without a new frame (default: never).
    poll : float
        Seconds between looks at the folder while waiting.
    up : {"z", "y"}
        A mesh folder's up axis.
    resume : bool
        Continue a track in ``out`` made by an earlier run (same settings).
    stop : callable, optional
        Called between frames and while waiting; tracking ends when it returns True.
    report : callable, optional
        Called with a :class:`FollowedFrame` after each frame is written.
    template_info : dict, optional
        How the template was chosen, kept in ``track.json`` (as for
        :func:`~meshmocap.trackers.driver.track_sequence`).
    light : int or None
        The light body tracked (as for :func:`~meshmocap.trackers.driver.track_sequence`).

    Returns
    -------
    list of int
        The frame numbers tracked by this call, in order.
    """
    if idle is not None and not idle > 0:
        raise InputError(f"track: --idle must be a positive number of seconds, found {idle}")
    folder = FrameFolder(source, up=up)
    meta = {
        "method": tracker.name,
        "template": template.name,
        "capture": str(Path(source).resolve()),
        "frames": "follow",
        "eval_names": list(template.eval_skeleton.names),
        "eval_parents": template.eval_skeleton.parents.tolist(),
        "options": tracker.options(),
        **(template_info or {}),
    }
    body = tracking_body(template, n_vertices=light)
    meta["tracked_vertices"] = body.light.n_vertices
    Path(out).mkdir(parents=True, exist_ok=True)
    tracked: list[int] = []
    with blas_threads(), folder_lock(out, "track"):
        done = start_track(out, meta, template.F, resume=resume)
        if body.binding is not None:  # frames hold the light body; read_track reads out
            write_light_binding(out, body.binding)
        last = good = done[-1] if done else -1
        if done:  # resuming: continue from the state saved with the last frame
            resume_tracker(tracker, body.light, out, last)
        waited = time.monotonic()
        while not (stop is not None and stop()):
            files = folder.poll(after=last)
            new = []
            if files and not done:  # the first frame with an observation starts the track
                new = _start(tracker, body, folder, files, out)
                done = done_frames(out)
            for f in files if done and not new else ():
                if stop is not None and stop():
                    break
                r = track_frame(
                    tracker,
                    functools.partial(folder.frame, f),  # a mesh file is read here
                    f.index,
                    out,
                    good,
                    retry=functools.partial(young, f),
                )
                if r is None:  # still being written in place: try again at the next poll
                    break
                write_frame(out, r)
                good = f.index if r.healthy else good
                new.append((f, r))
            for f, r in new:
                if f.index not in done:
                    done.append(f.index)
                tracked.append(f.index)
                if report is not None:
                    latency = time.time() - f.mtime
                    report(FollowedFrame(f.index, r.seconds, latency, tuple(r.flags), r.message))
            if new:
                last = max(last, new[-1][0].index)
                waited = time.monotonic()
                continue
            if idle is not None and time.monotonic() - waited > idle:
                break
            time.sleep(poll)
    return tracked


def _start(tracker, body, folder, files: list[FrameFile], out) -> list:
    """Initialise on the first of ``files`` with an observation (the driver's way); the
    frames written, with their results, or none when no file has an observation yet."""
    try:
        initialise_tracker(tracker, body, _Pending(folder, files), out, list(range(len(files))))
    except InputError:  # no observation in any of them: wait for more frames
        return []
    written = set(done_frames(out))
    return [(f, read_track_frame(out, f.index)) for f in files if f.index in written]
