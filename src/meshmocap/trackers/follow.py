"""Live tracking: frames tracked as a studio writes them into a folder (``track --follow``).

Live mode is ordinary tracking of a capture that grows
(:class:`~meshmocap.io.live.LiveCapture`): :func:`open_live` opens the folder as
:func:`meshmocap.api.open_capture` opens a finished one (a mesh folder's up axis and units
detected from its first frame with a body, :func:`~meshmocap.io.axes.detect_axes`),
and :func:`meshmocap.api.track` tracks it with the driver
(:func:`~meshmocap.trackers.driver.track_sequence`): the same template choice (the
performer's body estimated from the first frames, :func:`body_capture`), the same light
body, first pose, recovery and ``track.json`` (with ``"live": true`` instead of a list of
frames), each frame tracked and written as soon as it appears, in frame order. It stops
after ``idle`` seconds without a new frame, when ``stop()`` says so, or on Ctrl-C
(``KeyboardInterrupt``: every frame finished so far is on disk); run again into the same
folder, it resumes after the last frame written. The track reads like any other
(``eval``, ``report``, ``export``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

from meshmocap._validate import check_choice
from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError
from meshmocap.io.axes import UNITS, Axes, detect_axes, open_oriented
from meshmocap.io.live import LiveCapture
from meshmocap.io.meshes import MeshSequence

__all__ = ["BODY_FRAMES", "BODY_SECONDS", "body_capture", "open_live"]

#: Frames of a live capture the performer's body is estimated from (the estimators spread
#: their few frames over them) ...
BODY_FRAMES = 10
#: ... or those that appeared within this many seconds of the first.
BODY_SECONDS = 5.0

_READ_ERRORS = (MeshmocapFileNotFoundError, FormatError, MeshError)


def open_live(
    source: str | os.PathLike,
    *,
    up: str = "auto",
    units: str = "auto",
    fps: float | None = None,
    idle: float | None = None,
    poll: float = 0.02,
    stop: Callable[[], bool] | None = None,
) -> tuple[LiveCapture, Axes | None]:
    """Open the folder ``source`` that a studio is writing frames into, in metres with Z up,
    once it holds a frame with a body.

    A capture folder is metres and Z up by its format (``up``/``units`` other than
    ``"auto"`` are refused, as is an ``fps`` other than its ``capture.json``'s:
    :func:`~meshmocap.io.axes.open_oriented`, once it holds a frame); a mesh
    folder has its up axis and units detected from its first frame with a body, where not
    given (:func:`~meshmocap.io.axes.detect_axes`), and its rate ``fps`` (default
    30, assumed). ``idle``, ``poll``, ``stop``: as for :class:`~meshmocap.io.live.LiveCapture`.

    Returns
    -------
    The :class:`~meshmocap.io.live.LiveCapture`, and the :class:`Axes` read (None for a
    capture folder).

    Raises
    ------
    InputError
        No frame with a body appeared before ``idle`` seconds without a new frame (or
        ``stop()``); a bad option.
    """
    check_choice("track", "--up", up, ("auto", "z", "y"))
    check_choice("track", "--units", units, ("auto", *UNITS))
    live = LiveCapture(source, fps=fps, idle=idle, poll=poll, stop=stop)
    k = _first_body(live)
    if live.is_capture:  # its own checks (metres and Z up, its rate), as track makes them
        live.meta = open_oriented(source, up=up, units=units, fps=fps)[0].meta
        return live, None
    raw = MeshSequence([live.files[k].path])[0].V  # as stored: no turn, no scale
    axes = detect_axes(raw, up=up, units=units, source=str(source))
    live.up, live.scale = axes.up, UNITS[axes.units]
    return live, axes


def _first_body(live: LiveCapture) -> int:
    """Wait for the first frame with a body (10 points or more) and return its position."""
    k = 0
    while True:
        if not live.wait(k + 1):
            why = (
                f"no new frame for {live.idle:g} s (--idle)" if live.idle is not None else "stopped"
            )
            raise InputError(
                f"track --follow: no frame of {live.path} holds a body yet ({len(live)} "
                f"frames, {len(live.skipped)} left out); {why}"
            )
        try:
            frame = live[k]
            body = not frame.missing and len(frame.hull_mesh[0]) >= 10
        except _READ_ERRORS:
            if live.young(k):  # still being written in place: read it again
                time.sleep(live.poll)
                continue
            body = False
        if body:
            return k
        k += 1


def body_capture(live: LiveCapture, *, frames: int = BODY_FRAMES, seconds: float = BODY_SECONDS):
    """The frames of ``live`` its performer's body is estimated from: an ordinary capture
    of its first ``frames`` frames, or of those that appeared within ``seconds`` (or
    before the folder went idle), whichever comes first
    (:meth:`~meshmocap.io.live.LiveCapture.snapshot`)."""
    live.wait(frames, timeout=seconds)
    return live.snapshot()
