"""A live view of a track as it is made: ``meshmocap track FOLDER --follow --view``.

Each tracked frame goes to a `rerun <https://rerun.io>`_ recording (``rerun-sdk``, the
``view`` extra): the tracked body (the template's mesh as the tracker deformed it), the
evaluation joints and their skeleton, on the timeline ``frame`` (capture frame numbers), in
metres with Z up; a frame's message (why it is flagged) goes to the log. Where a display
is available the rerun viewer opens and shows each frame as it arrives; headless (no
``DISPLAY`` or ``WAYLAND_DISPLAY``), or when a file is named, the recording is saved as an
``.rrd`` file that ``rerun FILE.rrd`` opens later (the viewer comes with the package).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from meshmocap.errors import InputError
from meshmocap.io.results import read_frame_arrays

__all__ = ["RECORDING_FILE", "LiveView"]

#: The recording a headless live view writes into the track folder.
RECORDING_FILE = "live.rrd"


def _rerun():
    try:
        import rerun
    except ImportError:
        raise InputError(
            'track --view: the live view needs rerun-sdk: pip install -e ".[view]"'
        ) from None
    return rerun


class LiveView:
    """Log a track's frames to rerun as they are written.

    Parameters
    ----------
    out : path, the track folder (``faces.npy`` there gives the body's triangles)
    parents : sequence of int, optional, the evaluation skeleton (-1: root)
    recording : path, optional
        Save the recording to this ``.rrd`` file (default: ``out/live.rrd`` when no
        viewer is spawned).
    spawn : bool, optional
        Open the rerun viewer (default: when a display is available).

    Attributes
    ----------
    path : Path or None, the recording file written
    frames : int, frames shown so far
    """

    def __init__(
        self,
        out: str | os.PathLike,
        *,
        parents: Sequence[int] | None = None,
        recording: str | os.PathLike | None = None,
        spawn: bool | None = None,
    ):
        rr = self._rr = _rerun()
        self.out = Path(out)
        self.parents = None if parents is None else [int(p) for p in parents]
        if spawn is None:
            spawn = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        self.rec = rr.RecordingStream("meshmocap", recording_id=str(self.out.resolve()))
        self.path: Path | None = None
        if spawn:
            self.rec.spawn()
        if recording is not None or not spawn:
            self.path = Path(recording) if recording is not None else self.out / RECORDING_FILE
            self.rec.save(str(self.path))
        self.rec.log("track", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._faces: np.ndarray | None = None
        self.frames = 0

    def show(self, index: int) -> None:
        """Log frame ``index`` of the track folder (written by the tracker just before)."""
        rr = self._rr
        z = read_frame_arrays(self.out, index)
        V = np.asarray(z["vertices"], dtype=np.float32)
        J = np.asarray(z["joints"], dtype=np.float32)
        self.rec.set_time("frame", sequence=int(index))
        if self._faces is None:
            self._faces = np.load(self.out / "faces.npy").astype(np.uint32)
            self.rec.log("track/body", rr.Mesh3D.from_fields(triangle_indices=self._faces))
        self.rec.log("track/body", rr.Mesh3D.from_fields(vertex_positions=V))
        self.rec.log("track/joints", rr.Points3D(J, radii=0.015, colors=[220, 60, 40]))
        if self.parents is not None and len(self.parents) == len(J):
            bones = [[J[p], J[k]] for k, p in enumerate(self.parents) if p >= 0]
            self.rec.log("track/skeleton", rr.LineStrips3D(bones, colors=[220, 60, 40]))
        message = str(z["message"])
        if message:  # why a frame is flagged (or, on the first, how its pose was found)
            level = "INFO" if bool(z["healthy"]) else "WARN"
            self.rec.log("track/status", rr.TextLog(f"frame {index}: {message}", level=level))
        self.frames += 1

    def close(self) -> None:
        """Write what is pending (the recording file is complete afterwards)."""
        self.rec.flush()
