"""A capture that a studio writes frames into while it is being tracked (``track --follow``).

:class:`LiveCapture` is a capture whose length grows: its frames are the frame files that
have appeared so far, and :meth:`LiveCapture.wait` waits for more. The tracking driver
tracks it like any other capture (:func:`~meshmocap.trackers.driver.track_sequence`), one
frame as soon as it appears.

Two layouts are followed: a **capture folder** (``capture.json`` or ``hulls/``), whose
frames are its hull files ``hulls/NNNNN.npz`` (frame number NNNNN), and a **mesh folder**
of one mesh or point-cloud file per frame, numbered as ``meshmocap track`` numbers them
(:func:`~meshmocap.io.meshes.frame_numbers`: ``mesh_0042.obj`` is frame 42), in the files'
up axis and units (``up``, ``scale``; detected by :func:`meshmocap.api.open_capture`).

**Complete files only.** A frame is read once, when its file appears under its final name,
so the writer must make a file appear complete: write it under a hidden name (``.name``) or
with a ``.tmp`` / ``.part`` suffix in the same folder, then rename it to its final name
(``os.replace``: atomic on one file system); hidden names are never read as frames.
meshmocap's own writers do this. As a safety
net for writers that write in place, a file that cannot be read yet (a truncated PLY or
``.npz``) while it is younger than :data:`SETTLE_SECONDS` is tried again
(:meth:`LiveCapture.young`) instead of being taken as a damaged frame; a text format cut at
a line end (OBJ, XYZ) can still be read short, which only the rename prevents. A frame
that appears after a later one would go back in time: it is left out
(:attr:`LiveCapture.skipped`), and so is a mesh file not numbered like the first one.
"""

from __future__ import annotations

import math
import os
import stat
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera
from meshmocap.io.cameras import read_cameras
from meshmocap.io.capture import (
    UNIT_NAMES,
    Capture,
    CaptureFrame,
    SequenceCapture,
    SequenceFrame,
    frame_name,
    hull_note,
    meta_fps,
    read_meta,
)
from meshmocap.io.meshes import frame_numbers, is_frame_file, natural_key

__all__ = ["RESCAN_SECONDS", "SETTLE_SECONDS", "FrameFile", "LiveCapture"]

#: A file that fails to read while younger than this (seconds) is tried again later.
SETTLE_SECONDS = 2.0

#: A capture folder is listed again (for frames after a gap) at most this often, seconds.
RESCAN_SECONDS = 0.5


@dataclass(frozen=True)
class FrameFile:
    """A frame file that has appeared in a followed folder.

    Attributes
    ----------
    index : int, the frame number
    path : Path, the file
    mtime : float, its modification time (seconds since the epoch): when it was written
    """

    index: int
    path: Path
    mtime: float


class LiveCapture:
    """A capture being written: ``len()`` grows as frame files appear (module docstring).

    Parameters
    ----------
    path : path
        A capture folder (``capture.json`` or ``hulls/``) or a folder of mesh or
        point-cloud files.
    up : {"z", "y"}
        A mesh folder's up axis.
    scale : float
        A mesh folder's metres per file unit.
    fps : float, optional
        A mesh folder's frame rate (default 30, ``fps_given`` False).
    offset : (3,) float, optional
        Metres subtracted from every point of a mesh frame after scaling (default 0).
    idle : float, optional
        :meth:`wait` gives up after this many seconds without a new frame (default: never).
    poll : float
        Seconds between looks at the folder while waiting.
    stop : callable, optional
        Asked while waiting; :meth:`wait` gives up when it returns True.

    Raises
    ------
    MeshmocapFileNotFoundError
        ``path`` is not a folder.
    InputError
        ``idle``, ``poll`` or ``up`` out of range.
    FormatError
        A capture folder's ``capture.json`` that cannot be read.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        up: str = "z",
        scale: float = 1.0,
        fps: float | None = None,
        offset=None,
        idle: float | None = None,
        poll: float = 0.02,
        stop: Callable[[], bool] | None = None,
    ):
        self.path = Path(path)
        if not self.path.is_dir():
            raise MeshmocapFileNotFoundError(f"track --follow: {self.path} is not a folder")
        if idle is not None and not (isinstance(idle, int | float) and idle > 0):
            raise InputError(f"track: --idle must be a positive number of seconds, found {idle!r}")
        if not (isinstance(poll, int | float) and 0 < poll <= 60):
            raise InputError(f"LiveCapture: poll must be 0 to 60 seconds, found {poll!r}")
        if up not in ("z", "y"):
            raise InputError(f"LiveCapture: up must be 'z' or 'y', found {up!r}")
        self.is_capture = any((self.path / n).exists() for n in ("capture.json", "hulls"))
        self.meta: dict = read_meta(self.path) if self.is_capture else {}
        self.up, self.scale = up, float(scale)
        self.offset = np.zeros(3) if offset is None else np.asarray(offset, np.float64).reshape(3)
        if fps is not None and not (isinstance(fps, int | float) and 0 < fps < 1e5):
            raise InputError(f"capture: fps must be a positive number, found {fps!r}")
        self._fps = None if fps is None else float(fps)
        self.idle, self.poll, self.stop = idle, float(poll), stop
        #: The frame files that have appeared, in frame order (``capture[k]`` reads ``files[k]``).
        self.files: list[FrameFile] = []
        #: Their frame numbers.
        self.indices: list[int] = []
        #: Files left out: they appeared after a later frame, or are not numbered like the
        #: first mesh file.
        self.skipped: list[Path] = []
        self._seen: set[str] = set()  # a mesh folder's names already looked at
        self._file_of: dict[int, FrameFile] = {}
        self._scanned = -math.inf  # when the capture folder was last listed (monotonic)
        self._folder: Capture | None = None

    # ------------------------------------------------------------------ as a capture

    @property
    def fps(self) -> float:
        """Frames per second: a capture folder's ``capture.json`` (30 when unknown), a mesh
        folder's ``fps`` (default 30)."""
        if self.is_capture:
            return meta_fps(self.meta, self.path)
        return 30.0 if self._fps is None else self._fps

    @property
    def fps_given(self) -> bool:
        """Whether the rate is known (given, or in ``capture.json``), not assumed."""
        return "fps" in self.meta if self.is_capture else self._fps is not None

    @property
    def units(self) -> str:
        """A mesh folder's length unit (``"m"``, ``"cm"``, ``"mm"``; else metres per unit)."""
        return UNIT_NAMES.get(self.scale, f"{self.scale:g} m")

    @property
    def cameras(self) -> list[Camera]:
        """A capture folder's rig (empty without ``cameras.json``, and for meshes)."""
        path = self.path / "cameras.json"
        return read_cameras(path) if self.is_capture and path.is_file() else []

    def notes(self) -> dict[int, str]:
        """Frames carved from fewer cameras or without hull, and why (as
        :meth:`~meshmocap.io.capture.Capture.notes`), of the frames so far."""
        if not self.is_capture:
            return {}
        notes = {i: hull_note(self.path / "hulls" / f"{frame_name(i)}.npz") for i in self.indices}
        return {i: n for i, n in notes.items() if n}

    def __len__(self) -> int:
        return len(self.files)

    def __getitem__(self, k: int) -> CaptureFrame | SequenceFrame:
        if not -len(self) <= k < len(self):
            raise InputError(f"capture: frame position {k} out of range for {len(self)} frames")
        f = self.files[k]
        if self.is_capture:
            if self._folder is None:
                self._folder = Capture(self.path)
            return CaptureFrame(f.index, self._folder)
        one = SequenceCapture([f.path], up=self.up, scale=self.scale, offset=self.offset)[0]
        return SequenceFrame(f.index, one.hull_mesh, one.normals)

    def __repr__(self) -> str:
        return f"LiveCapture({str(self.path)!r}, {len(self)} frames so far)"

    def snapshot(self) -> Capture | SequenceCapture:
        """The frames that have appeared so far, as an ordinary capture (the same frame
        numbers, read the same way): what the performer's body is estimated from."""
        if not self.files:
            raise InputError(f"track --follow: no frame in {self.path} yet")
        if self.is_capture:
            cap = Capture(self.path)
            cap.indices = list(self.indices)  # only the frames written so far
            return cap
        return SequenceCapture(
            [f.path for f in self.files],
            up=self.up,
            scale=self.scale,
            fps=self._fps,
            offset=self.offset,
        )

    # ------------------------------------------------------------------ growing

    def grow(self) -> int:
        """Look at the folder once; return how many frames appeared."""
        new = self._capture_files() if self.is_capture else self._mesh_files()
        self.files += new
        self.indices += [f.index for f in new]
        self._file_of.update((f.index, f) for f in new)
        return len(new)

    def wait(self, n: int, *, timeout: float | None = None) -> bool:
        """Wait until the capture holds ``n`` frames: True then, False when ``idle`` seconds
        pass without a new frame, ``timeout`` seconds pass, or ``stop()`` says so."""
        start = last = time.monotonic()
        while len(self) < n:
            if self.stop is not None and self.stop():
                return False
            if self.grow():
                last = time.monotonic()
                continue
            now = time.monotonic()
            if self.idle is not None and now - last > self.idle:
                return False
            if timeout is not None and now - start > timeout:
                return False
            time.sleep(self.poll)
        return True

    def young(self, k: int) -> bool:
        """Whether frame ``k``'s file was written less than :data:`SETTLE_SECONDS` ago (or
        is still being written: its time changed since it was listed): a frame that
        cannot be read yet is tried again rather than taken as damaged."""
        f = self.files[k]
        now = _stat(f.index, f.path)
        return now is None or now.mtime != f.mtime or time.time() - f.mtime < SETTLE_SECONDS

    def written(self, index: int) -> float | None:
        """When frame ``index``'s file was written (its modification time, seconds since
        the epoch); None for a frame without a file."""
        f = self._file_of.get(index)
        return None if f is None else f.mtime

    def _capture_files(self) -> list[FrameFile]:
        """A capture folder's hull files after the last frame: the next one is looked up
        directly; the folder is listed again at most every :data:`RESCAN_SECONDS`."""
        after = self.indices[-1] if self.indices else -1
        hulls = self.path / "hulls"
        nxt = _stat(after + 1, hulls / f"{frame_name(after + 1)}.npz")
        if nxt is not None:  # the usual case: the next frame, and maybe more after it
            out = [nxt]
            while f := _stat(out[-1].index + 1, hulls / f"{frame_name(out[-1].index + 1)}.npz"):
                out.append(f)
            return out
        if time.monotonic() - self._scanned < RESCAN_SECONDS:
            return []
        self._scanned = time.monotonic()
        found = sorted(
            int(p.stem) for p in _listing(hulls) if p.suffix == ".npz" and p.stem.isdigit()
        )
        files = (_stat(i, hulls / f"{frame_name(i)}.npz") for i in found if i > after)
        return [f for f in files if f is not None]

    def _mesh_files(self) -> list[FrameFile]:
        """A mesh folder's new frame files, numbered by their names; a file numbered before
        the last frame, or not like the first file, is left out."""
        listed = (p.name for p in _listing(self.path))
        names = sorted(
            (n for n in listed if is_frame_file(n) and n not in self._seen), key=natural_key
        )
        first = self.files[0].path.name if self.files else None
        out: list[FrameFile] = []
        last = self.indices[-1] if self.indices else -1
        for name in names:
            try:  # numbered as `track` numbers the folder (one prefix, a number last)
                index = frame_numbers([first, name] if first else [name])[-1]
            except InputError:
                index = -1
            if index <= last:
                self._seen.add(name)
                self.skipped.append(self.path / name)
                continue
            f = _stat(index, self.path / name)
            if f is None:  # renamed away since the listing
                continue
            self._seen.add(name)
            out.append(f)
            first, last = first or name, index
        return out


def _listing(folder: Path) -> list[Path]:
    """The entries of ``folder``, as a list made at once: no directory iterator is left open
    when a Ctrl-C lands mid-listing (:func:`_stat` keeps the files)."""
    try:
        return [folder / name for name in os.listdir(folder)]
    except FileNotFoundError:  # hulls/ not made yet
        return []


def _stat(index: int, path: Path) -> FrameFile | None:
    """The frame file ``path`` numbered ``index``; None when it is gone or not a file."""
    try:
        st = path.stat()
    except FileNotFoundError:  # renamed away between the listing and now
        return None
    return FrameFile(index, path, st.st_mtime) if stat.S_ISREG(st.st_mode) else None
