"""Visual hulls of a real capture folder: cameras + silhouettes → hull files, frame by frame.

A studio drops frames and loses cameras for a while: a camera whose mask is empty (the
subject left its view), missing (a dropped frame) or implausible (mostly foreground: an
inverted mask, :func:`~meshmocap.io.plausibility.mask_problems`) is left out of that
frame's carving, which uses the cameras that see the subject, and the hull file records it
(its ``note``). Carving inverted masks would take the whole studio for the subject, slowly.
A frame seen by fewer than ``min_cameras`` cameras has no hull: its file records why
(:func:`~meshmocap.io.capture.write_missing_hull`), and trackers coast across it, flagging
it ``missing``. Nothing else of the capture is lost.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshmocap._progress import progress
from meshmocap._validate import counted
from meshmocap.errors import (
    GreyMaskWarning,
    InputError,
    MeshmocapFileNotFoundError,
    MissingFrameWarning,
)
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.carving import VoxelHull, carve
from meshmocap.io.cameras import read_cameras
from meshmocap.io.capture import Capture, frame_name, write_hull, write_missing_hull
from meshmocap.io.plausibility import mask_problems
from meshmocap.io.silhouettes import read_mask

#: Fewest cameras that must see the subject for a frame to be carved (one camera's hull is
#: an unbounded cone).
MIN_CAMERAS = 2


@dataclass(frozen=True)
class CarvedFrame:
    """A frame's carving: the hull (None when too few cameras see the subject) and a note
    naming the cameras left out and why (empty when every camera was used)."""

    hull: VoxelHull | None
    note: str


def carve_seen(
    masks: list[np.ndarray | None],
    cameras: list[Camera],
    *,
    voxel_size: float = 0.01,
    min_cameras: int = MIN_CAMERAS,
) -> CarvedFrame:
    """Carve a frame from the cameras that see the subject.

    Parameters
    ----------
    masks : list of (height, width) bool or None, one per camera (None: no silhouette file)
    cameras : list of Camera
    voxel_size : float, voxel edge, metres
    min_cameras : int, fewest cameras with a non-empty mask needed to carve
    """
    why = {
        c.name: "no silhouette file" if m is None else "empty mask"
        for m, c in zip(masks, cameras, strict=True)
        if m is None or not m.any()
    }
    why |= mask_problems(masks, [c.name for c in cameras])  # inverted: left out too
    used = [k for k, c in enumerate(cameras) if c.name not in why]
    left_out = ", ".join(f"{n}: {w}" for n, w in why.items())
    if len(used) < min_cameras:
        return CarvedFrame(
            None,
            f"only {len(used)} of {len(cameras)} cameras see the subject "
            f"({left_out}); at least {min_cameras} needed",
        )
    hull = carve([masks[k] for k in used], [cameras[k] for k in used], voxel_size=voxel_size)
    if not hull.occupancy.any():
        return CarvedFrame(None, "the silhouettes do not intersect: the hull is empty")
    note = f"carved from {len(used)} of {len(cameras)} cameras ({left_out})" if why else ""
    return CarvedFrame(hull, note)


def write_carved(path: Path, carved: CarvedFrame) -> None:
    """Write a carved frame to the hull file ``path`` (hull with its note, or the reason it
    has none)."""
    if carved.hull is None:
        write_missing_hull(path, carved.note)
    else:
        write_hull(path, carved.hull, note=carved.note)


def silhouette_frames(path: Path, camera_names: list[str]) -> list[int]:
    """Return the frame numbers that any camera has a silhouette for.

    Raises
    ------
    MeshmocapFileNotFoundError
        A camera has no silhouette folder, or no camera has a mask.
    InputError
        ``silhouettes/`` holds folders of cameras that the camera file does not list.
    """
    root = path / "silhouettes"
    if root.is_dir():
        extra = sorted(p.name for p in root.iterdir() if p.is_dir() and p.name not in camera_names)
        if extra:
            raise InputError(
                f"hull: {root} holds {len(extra) + len(camera_names)} camera folders but the "
                f"camera file lists {len(camera_names)} ({camera_names}); not in it: {extra}"
            )
    frames: set[int] = set()
    for name in camera_names:
        folder = root / name
        if not folder.is_dir():
            raise MeshmocapFileNotFoundError(
                f"hull: camera {name!r} has no silhouette folder {folder}"
            )
        frames |= {int(p.stem) for p in folder.glob("*.png") if p.stem.isdigit()}
    if not frames:
        raise MeshmocapFileNotFoundError(f"hull: {root} holds no <camera>/NNNNN.png masks")
    return sorted(frames)


@dataclass(frozen=True)
class HullRun:
    """What :func:`compute_hulls` did: the capture, frames carved by this run, and the notes
    of frames carved from fewer cameras (``partial``) or left without hull (``missing``),
    frame number → note, and the number of masks that were not binary."""

    capture: Capture
    carved: int
    partial: dict[int, str]
    missing: dict[int, str]
    grey_masks: int


def camera_file(path: Path) -> Path:
    """The rig file of a capture folder: ``cameras.json``, ``cameras.yml`` or ``cameras.yaml``."""
    for name in ("cameras.json", "cameras.yml", "cameras.yaml"):
        if (path / name).is_file():
            return path / name
    raise MeshmocapFileNotFoundError(f"hull: {path} has no cameras.json or cameras.yml")


def compute_hulls(
    capture: str | os.PathLike,
    *,
    voxel_size: float = 0.01,
    overwrite: bool = False,
    frames: Sequence[int] | None = None,
    min_cameras: int = MIN_CAMERAS,
    show_progress: bool | None = None,
) -> HullRun:
    """Carve the visual hull of every frame of a capture folder and write ``hulls/``.

    Parameters
    ----------
    capture : path
        Folder with ``cameras.json`` (or ``cameras.yml``) and ``silhouettes/<camera>/NNNNN.png``.
    voxel_size : float
        Voxel edge, metres (0.002 to 0.1).
    overwrite : bool
        Recompute frames that already have a hull (default: keep them, so an interrupted
        run resumes).
    frames : sequence of int, optional
        Carve only these frame numbers (default: every frame with silhouettes).
    min_cameras : int
        Fewest cameras that must see the subject (see the module docstring).

    Warns
    -----
    MissingFrameWarning
        Once, when frames were carved from fewer cameras or left without hull.
    GreyMaskWarning
        Once, when masks were not binary (they are thresholded at 50 %).
    """
    if not (isinstance(voxel_size, int | float) and 0.002 <= voxel_size <= 0.1):
        raise InputError(f"hull: --voxel-size must be between 0.002 and 0.1 m, found {voxel_size}")
    if not (isinstance(min_cameras, int) and min_cameras >= 1):
        raise InputError(f"hull: min_cameras must be a positive integer, found {min_cameras!r}")
    path = Path(capture)
    if not path.is_dir():
        raise MeshmocapFileNotFoundError(f"hull: {path} is not a folder")
    cameras = read_cameras(camera_file(path))
    available = silhouette_frames(path, [c.name for c in cameras])
    if frames is not None:
        absent = sorted(set(frames) - set(available))
        if absent:
            raise InputError(f"hull: frames {absent[:5]} have no silhouettes in {path}")
    frames = available if frames is None else sorted(set(frames))
    (path / "hulls").mkdir(exist_ok=True)
    todo = [
        f for f in frames if overwrite or not (path / "hulls" / f"{frame_name(f)}.npz").is_file()
    ]
    partial: dict[int, str] = {}
    missing: dict[int, str] = {}
    grey = 0
    # no folder lock: `meshmocap batch` carves chunks of one capture in parallel (each
    # frame's file is written atomically, so concurrent runs cannot corrupt one)
    for f in progress(todo, label="hull", enabled=show_progress):
        name = frame_name(f)
        files = [path / "silhouettes" / c.name / f"{name}.png" for c in cameras]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", GreyMaskWarning)
            masks = [
                read_mask(p, shape=c.shape) if p.is_file() else None
                for p, c in zip(files, cameras, strict=True)
            ]
        grey += sum(issubclass(w.category, GreyMaskWarning) for w in caught)
        carved = carve_seen(masks, cameras, voxel_size=voxel_size, min_cameras=min_cameras)
        write_carved(path / "hulls" / f"{name}.npz", carved)  # marks the frame done
        if carved.note:
            (missing if carved.hull is None else partial)[f] = carved.note
    if grey:
        warnings.warn(
            f"hull: {grey} masks in {path / 'silhouettes'} are not binary (grey "
            "levels); thresholded at 50 % of full scale",
            GreyMaskWarning,
            stacklevel=2,
        )
    if partial or missing:
        warnings.warn(frames_note(partial, missing), MissingFrameWarning, stacklevel=2)
    return HullRun(Capture(path), len(todo), partial, missing, grey)


def frames_note(partial: dict[int, str], missing: dict[int, str]) -> str:
    """One line: how many frames were carved from fewer cameras or left without hull, with
    the first of each."""
    parts = []
    for what, notes in (
        ("without hull (trackers coast across them)", missing),
        ("carved from fewer cameras", partial),
    ):
        if notes:
            first = min(notes)
            head = f"{counted(len(notes), 'frame')} {what}"
            parts.append(f"{head}, first {frame_name(first)}: {notes[first]}")
    return "; ".join(parts)
