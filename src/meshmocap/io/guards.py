"""Checks a command makes before it writes or scores: is the output place writable and of
the right kind, does it stay out of track folders, is the capture the track's.

Each check raises one error whose message is one line naming the path, what was expected
and what was found, so a run that would fail at its last step (an unwritable ``--out``
after ten minutes of tracking) fails before it starts, and a run that would silently lie
(a walk's track scored against a jog capture, ``export TRACK --out TRACK/track.json``
overwriting the track) is refused.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import tempfile
import warnings
from pathlib import Path
from typing import Literal

import numpy as np

from meshmocap.errors import (
    CaptureMismatchError,
    FormatError,
    MeshError,
    MeshmocapFileNotFoundError,
    MeshmocapWarning,
    OutputPathError,
    ProtectedPathError,
)
from meshmocap.io.results import planned_frames

__all__ = [
    "TRACK_OWN_FILES",
    "capture_digest",
    "check_apart_from_inputs",
    "check_output_path",
    "check_resumable",
    "check_track_capture",
    "protected_track_file",
    "track_folder",
]

#: What a track folder is made of (:mod:`meshmocap.io.results`; ``subject.npz``: the
#: estimated body; ``live.rrd``: the recording of ``--follow --view``; ``.meshmocap.lock``:
#: the lock held while it is written): only ``meshmocap track`` writes in a track folder.
TRACK_OWN_FILES = (
    "track.json",
    "faces.npy",
    "frames",
    "light.npz",
    "subject.npz",
    "subject_pose.npz",
    "live.rrd",
    ".meshmocap.lock",
)

OutputKind = Literal["file", "folder"]


def track_folder(path: str | os.PathLike) -> bool:
    """True when ``path`` is a folder written by ``meshmocap track`` (its ``track.json``
    says ``meshmocap-track-1``)."""
    meta = Path(path) / "track.json"
    if not meta.is_file():
        return False
    try:
        return json.loads(meta.read_text(encoding="utf-8")).get("format") == "meshmocap-track-1"
    except (OSError, ValueError, AttributeError):
        return (Path(path) / "frames").is_dir()  # a damaged track.json is still a track's


def protected_track_file(path: str | os.PathLike) -> Path | None:
    """The track folder that ``path`` is or lies in (at any depth), or None: only
    ``meshmocap track`` writes inside a track folder, its own files
    (:data:`TRACK_OWN_FILES`) and anything else (``TRACK/walk.bvh`` too), so a track
    folder holds what the track wrote and nothing a later command put there."""
    p = Path(os.path.abspath(path))
    for folder in (p, *p.parents):
        if track_folder(folder):
            return folder
    return None


def _readonly(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):  # pragma: no cover (no statvfs: Windows)
        return False


def check_output_path(
    path: str | os.PathLike,
    *,
    kind: OutputKind,
    command: str,
    flag: str = "--out",
    track_folder_ok: bool = False,
) -> None:
    """Refuse an output ``path`` that cannot be written, before any work starts.

    ``kind`` is what the command writes there: a ``"file"`` or a ``"folder"`` (made with its
    parents when absent). ``command`` and ``flag`` name the argument in the message.
    ``track_folder_ok``: ``path`` may be a track folder itself (``meshmocap track``
    resuming its own), though still nothing inside a track folder.

    Raises
    ------
    OutputPathError
        ``path`` is a folder where a file is expected (or the reverse), a file stands where
        a folder of its path should be, or the nearest existing folder is on a read-only
        file system or not writable by this user.
    ProtectedPathError
        ``path`` is or lies in a track folder (:func:`protected_track_file`).
    """
    p = Path(path)
    head = f"{command}: {flag} {p}"
    if p.is_dir() and kind == "file":
        raise OutputPathError(f"{head}: is a folder; expected a file name to write")
    if p.exists() and not p.is_dir() and kind == "folder":
        raise OutputPathError(f"{head}: is a file; expected a folder")
    near = p if p.is_dir() else p.parent
    while not near.exists() and near != near.parent:
        near = near.parent
    if not near.is_dir():
        raise OutputPathError(f"{head}: {near} is a file, not a folder")
    if _readonly(near):
        raise OutputPathError(f"{head}: {near} is on a read-only file system")
    try:  # the true test (root ignores permission bits; /proc takes no new file)
        fd, probe = tempfile.mkstemp(prefix=".meshmocap-probe.", dir=near)
    except OSError as exc:
        raise OutputPathError(f"{head}: cannot write in {near} ({exc.strerror})") from None
    os.close(fd)
    os.unlink(probe)
    track = protected_track_file(p)
    itself = track is not None and Path(os.path.abspath(p)) == track
    if track is not None and not (itself and track_folder_ok):
        what = "is the track folder" if itself else "lies in the track folder"
        raise ProtectedPathError(
            f"{head}: {what} {track}, which only 'meshmocap track' writes; "
            "expected a path outside it"
        )


def _input_folder(source: str) -> tuple[Path, str]:
    """The folder an input ``source`` reads, and what it is: a folder (or a glob's folder)
    is read whole; a file (a mesh, an archive) is read from the folder holding it."""
    if glob.has_magic(source):
        parts = Path(source).parts
        head = next(k for k, part in enumerate(parts) if glob.has_magic(part))
        return Path(*parts[:head]) if head else Path("."), "the folder of the glob"
    if Path(source).is_dir():
        return Path(source), "the capture folder"
    return Path(source).parent, "the folder holding the input"


def check_apart_from_inputs(
    path: str | os.PathLike, sources, *, command: str, flag: str = "--out"
) -> None:
    """Refuse an output folder ``path`` that is the folder of one of the inputs
    ``sources`` (folders, globs, files, archives) or, for a folder read whole, lies inside
    it: a command never writes among what it reads (a track's ``faces.npy`` and
    ``frames/`` among the meshes would be read as frames by every later command). Beside
    input files or a glob's, in a folder of its own, is fine.

    Raises
    ------
    OutputPathError
        One line naming the flag, the input and what was expected.
    """
    out = Path(os.path.realpath(path))
    for source in map(os.fspath, sources):
        folder, what = _input_folder(source)
        real = Path(os.path.realpath(folder))
        whole = what == "the capture folder"  # a subfolder of it would be written to
        if out == real or (whole and real in out.parents):
            how = "is" if out == real else "lies in"
            raise OutputPathError(
                f"{command}: {flag} {path}: {how} {what} {source}, which {command} reads; "
                "expected a folder outside it (the input is never written to)"
            )


def check_resumable(
    path: str | os.PathLike,
    capture,
    *,
    command: str = "track",
    out: str = "--out",
    restart: str = "--restart",
) -> None:
    """Refuse to resume, in the track folder ``path``, a track of another capture than
    ``capture`` (its ``track.json`` names the capture it was made from): ``--out`` names
    another capture's track, not this one's. A folder without a readable ``track.json``
    passes (a new track, or one whose damage the driver reports). ``out`` and ``restart``
    name the argument and the way to start over in the message (the command line's flags,
    or the Python arguments).

    Raises
    ------
    OutputPathError
        One line naming both captures and what to do.
    """
    meta_path = Path(path) / "track.json"
    try:
        named = json.loads(meta_path.read_text(encoding="utf-8")).get("capture")
    except (OSError, ValueError, AttributeError):
        return
    here = Path(capture.path).resolve()
    if not isinstance(named, str) or not named or Path(named) == here:
        return
    raise OutputPathError(
        f"{command}: {out} {path} holds the track of another capture ({named}); expected a "
        f"new folder, or a track of {here} to resume: give another {out}, or {restart} to "
        "track over it"
    )


def capture_digest(capture) -> str:
    """A digest of what a capture holds: its frame numbers, ``capture.json`` and the
    observed geometry of its first, middle and last frames (vertices as float32). A copy
    of a capture has the digest of the original; another take does not.

    ``capture``: a :class:`~meshmocap.io.capture.Capture` or
    :class:`~meshmocap.io.capture.SequenceCapture`.
    """
    h = hashlib.sha256()
    h.update(json.dumps([int(i) for i in capture.indices]).encode())
    meta = {k: v for k, v in dict(getattr(capture, "meta", {}) or {}).items() if k != "path"}
    h.update(json.dumps(meta, sort_keys=True, default=str).encode())
    n = len(capture)
    for k in sorted({0, n // 2, n - 1}):
        try:
            frame = capture[k]
            if getattr(frame, "missing", None):
                h.update(b"missing")
                continue
            V = frame.hull_mesh[0]
        except (MeshmocapFileNotFoundError, FormatError, MeshError):
            h.update(b"unreadable")
            continue
        h.update(np.ascontiguousarray(V, dtype=np.float32).tobytes())
    return h.hexdigest()


def check_track_capture(
    track: str | os.PathLike, meta: dict, capture, *, force: bool = False, command: str = "eval"
) -> str | None:
    """Check that ``capture`` is the capture the track in folder ``track`` was made from.

    ``meta`` is the track's ``track.json`` contents; it names the capture's folder
    (``capture``) and the frames tracked (``frames``). The capture is the track's when it
    is that folder, or a copy of it (same :func:`capture_digest`) holding every tracked
    frame. Anything else is refused unless ``force``, which turns the refusal into a
    :class:`~meshmocap.errors.MeshmocapWarning` and returns its message (None when the
    capture is the track's).

    Raises
    ------
    CaptureMismatchError
        Another capture, or one that cannot be confirmed (the named folder is gone), and
        not ``force``.
    """
    named = meta.get("capture")
    if not named:  # a track written by hand or by an old version: nothing to compare
        return None
    here = Path(os.path.abspath(capture.path))
    if Path(os.path.abspath(named)) == here:
        return None
    frames = planned_frames(meta)  # none for a live track
    absent = sorted(set(frames) - {int(i) for i in capture.indices})
    if absent:
        why = f"{len(absent)} of its {len(frames)} frames are not in it (first {absent[0]})"
    elif not Path(named).exists():
        why = f"{named} no longer exists, so the two cannot be compared"
    else:
        from meshmocap.io.capture import open_capture

        try:
            same = capture_digest(open_capture(named)) == capture_digest(capture)
        except (MeshmocapFileNotFoundError, FormatError, MeshError):
            same = False
        if same:
            return None  # a copy of the track's capture
        why = f"its frames differ from those of {named}"
    msg = (
        f"{command}: track {track} was made from capture {named}, expected it or a copy, "
        f"found {here} ({why})"
    )
    if not force:
        raise CaptureMismatchError(f"{msg}; pass --force to score it anyway")
    warnings.warn(f"{msg}; scored anyway (--force)", MeshmocapWarning, stacklevel=2)
    return msg
