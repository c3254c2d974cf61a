"""Visual hulls of a real capture folder: cameras + silhouettes → hull meshes, frame by frame."""

from __future__ import annotations

import os
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


def compute_hulls(
    capture: str | os.PathLike,
    *,
    voxel_size: float = 0.01,
    overwrite: bool = False,
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
    """
    path = Path(capture)
    cam_file = next(
        (path / n for n in ("cameras.json", "cameras.yml", "cameras.yaml") if (path / n).is_file()),
        None,
    )
    if cam_file is None:
        raise MeshmocapFileNotFoundError(f"hull: {path} has no cameras.json or cameras.yml")
    cameras = read_cameras(cam_file)
    frames = silhouette_frames(path, [c.name for c in cameras])
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
