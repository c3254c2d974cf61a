"""A folder that a studio writes frames into while it is being tracked (``track --follow``).

Two layouts are followed: a **capture folder** (``capture.json`` or ``hulls/``), whose
frames are its hull files ``hulls/NNNNN.npz`` (frame number NNNNN), and a **mesh folder**
of one mesh or point-cloud file per frame (any name; frames are numbered by their position
in the natural order of the names, ``mesh_2`` before ``mesh_10``, as
:class:`~meshmocap.io.meshes.MeshSequence` numbers them).

**Complete files only.** A frame is read once, when its file appears under its final name,
so the writer must make a file appear complete: write it under a hidden name (``.name``) or
with a ``.tmp`` / ``.part`` suffix in the same folder, then rename it to its final name
(``os.replace``: atomic on one file system); hidden names are never read as frames.
meshmocap's own writers do this. As a safety
net for writers that write in place, a file that cannot be read yet (a truncated PLY or
``.npz``) while it is younger than :data:`SETTLE_SECONDS` is tried again at the next poll
instead of being taken as a damaged frame; a text format cut at a line end (OBJ, XYZ) can
still be read short, which only the rename prevents. A mesh file whose name sorts before
frames already seen would renumber them: it is left out (:attr:`FrameFolder.skipped`).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap.errors import MeshmocapFileNotFoundError
from meshmocap.io.capture import (
    Capture,
    CaptureFrame,
    SequenceCapture,
    SequenceFrame,
    frame_name,
)
from meshmocap.io.meshes import is_frame_file, natural_key

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


class FrameFolder:
    """The frames of a folder being written, listed again at every :meth:`poll`.

    Parameters
    ----------
    path : path
        A capture folder (``capture.json`` or ``hulls/``) or a folder of mesh or
        point-cloud files (see the module docstring).
    up : {"z", "y"}
        A mesh folder's up axis.

    Raises
    ------
    MeshmocapFileNotFoundError
        ``path`` is not a folder.
    """

    def __init__(self, path: str | os.PathLike, *, up: str = "z"):
        self.path = Path(path)
        if not self.path.is_dir():
            raise MeshmocapFileNotFoundError(f"track --follow: {self.path} is not a folder")
        self.up = up
        self.is_capture = any((self.path / n).exists() for n in ("capture.json", "hulls"))
        #: Mesh files left out because they sorted before frames already seen.
        self.skipped: list[Path] = []
        self._names: list[str] = []  # a mesh folder's frame files, in frame order
        self._capture: Capture | None = None
        self._scanned = -np.inf  # when the capture folder was last listed (monotonic)

    def poll(self, after: int = -1) -> list[FrameFile]:
        """The complete frame files now in the folder with a frame number above ``after``,
        in frame order. A capture folder's next hull file is looked up directly; the whole
        folder is listed again at most every :data:`RESCAN_SECONDS` otherwise."""
        if not self.is_capture:
            return [f for f in self._mesh_files() if f.index > after]
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
        names = sorted(
            (p.name for p in _listing(self.path) if is_frame_file(p.name)), key=natural_key
        )
        known = set(self._names)
        for name in names:
            if name in known:
                continue
            if self._names and natural_key(name) < natural_key(self._names[-1]):
                if self.path / name not in self.skipped:
                    self.skipped.append(self.path / name)
                continue
            self._names.append(name)
            known.add(name)
        return [f for f in (_stat(i, self.path / n) for i, n in enumerate(self._names)) if f]

    def frame(self, f: FrameFile) -> CaptureFrame | SequenceFrame:
        """The capture frame of ``f`` (a mesh file is read here)."""
        if self.is_capture:
            if self._capture is None:
                self._capture = Capture(self.path)
            return CaptureFrame(f.index, self._capture)
        frame = SequenceCapture([f.path], up=self.up)[0]
        return SequenceFrame(f.index, frame.hull_mesh, frame.normals)


def young(f: FrameFile) -> bool:
    """Whether ``f`` was written less than :data:`SETTLE_SECONDS` ago (or is still being
    written: its size or time changed since it was listed)."""
    now = _stat(f.index, f.path)
    return now is None or now.mtime != f.mtime or time.time() - f.mtime < SETTLE_SECONDS


def _listing(folder: Path) -> list[Path]:
    try:  # closed even when a Ctrl-C lands mid-listing
        with os.scandir(folder) as entries:
            return [Path(e.path) for e in entries if e.is_file()]
    except FileNotFoundError:  # hulls/ not made yet
        return []


def _stat(index: int, path: Path) -> FrameFile | None:
    try:
        return FrameFile(index, path, path.stat().st_mtime)
    except FileNotFoundError:  # renamed away between the listing and now
        return None
