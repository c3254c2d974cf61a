"""Visual hulls of a real capture folder: cameras + silhouettes → hull meshes, frame by frame."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from meshmocap._progress import progress
from meshmocap.errors import InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.carving import carve, hull_mesh
from meshmocap.io.cameras import read_cameras
from meshmocap.io.capture import Capture, frame_name, write_hull
from meshmocap.io.meshes import write_mesh
from meshmocap.io.silhouettes import read_mask


def silhouette_frames(path: Path, camera_names: list[str]) -> list[int]:
    """Return the frame numbers that every camera has a silhouette for.

    Raises
    ------
    MeshmocapFileNotFoundError
        A camera has no silhouette folder.
    InputError
        The cameras do not have the same frames (the message names the first camera and
        frame that differ).
    """
    sets = {}
    for name in camera_names:
        folder = path / "silhouettes" / name
        if not folder.is_dir():
            raise MeshmocapFileNotFoundError(
                f"hull: camera {name!r} has no silhouette folder {folder}"
            )
        sets[name] = {int(p.stem) for p in folder.glob("*.png") if p.stem.isdigit()}
    first = camera_names[0]
    for name in camera_names[1:]:
        diff = sets[first] ^ sets[name]
        if diff:
            f = min(diff)
            has, lacks = (first, name) if f in sets[first] else (name, first)
            raise InputError(
                f"hull: frame {f} has a silhouette for camera {has!r} but not for {lacks!r} "
                f"({len(diff)} frames differ)"
            )
    if not sets[first]:
        raise MeshmocapFileNotFoundError(
            f"hull: {path / 'silhouettes' / first} holds no NNNNN.png masks"
        )
    return sorted(sets[first])


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
    show_progress: bool | None = None,
) -> Capture:
    """Carve the visual hull of every frame of a capture folder and write ``hulls/``.

    Parameters
    ----------
    capture : path
        Folder with ``cameras.json`` (or ``cameras.yml``) and ``silhouettes/<camera>/NNNNN.png``.
    voxel_size : float
        Voxel edge, metres.
    overwrite : bool
        Recompute frames that already have a hull (default: keep them, so an interrupted
        run resumes).
    frames : sequence of int, optional
        Carve only these frame numbers (default: every frame with silhouettes).
    """
    path = Path(capture)
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
    for f in progress(todo, label="hull", enabled=show_progress):
        name = frame_name(f)
        masks = [
            read_mask(path / "silhouettes" / c.name / f"{name}.png", shape=c.shape) for c in cameras
        ]
        hull = carve(masks, cameras, voxel_size=voxel_size)
        write_mesh(path / "hulls" / f"{name}.ply", *hull_mesh(hull))
        write_hull(path / "hulls" / f"{name}.npz", hull)  # last: marks the frame done
    return Capture(path)
