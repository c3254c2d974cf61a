"""Capture folders: cameras, silhouettes, visual hulls and ground truth, frame by frame.

Layout (``capture.json`` holds ``"format": "meshmocap-capture-1"``)::

    CAPTURE/
      capture.json                     metadata: fps, frame count, how it was made
      cameras.json                     the rig (see meshmocap.io.cameras)
      silhouettes/<camera>/NNNNN.png   one binary mask per camera and frame
      hulls/NNNNN.ply                  visual-hull mesh, metres, Z up (optional beside the .npz)
      hulls/NNNNN.npz                  its voxel occupancy (bit-packed), origin, voxel size
      truth/NNNNN.npz                  ground truth of synthetic captures: posed vertices
                                       (n, 3), evaluation joints (K, 3), local rotations
                                       (J, 3, 3), root position (3,)
      truth/faces.npy                  triangles (m, 3) of the true surface

Every file is written atomically; a synthetic frame is complete when its truth file exists,
so an interrupted run keeps every finished frame and resumes where it stopped. Real
captures need only ``cameras.json`` and ``silhouettes/`` (``meshmocap hull`` adds
``hulls/``), or only meshes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open, write_text_atomic
from meshmocap.errors import FormatError, InputError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.carving import VoxelHull, hull_mesh
from meshmocap.io.cameras import read_cameras
from meshmocap.io.meshes import read_mesh
from meshmocap.io.silhouettes import read_mask

FORMAT = "meshmocap-capture-1"


def frame_name(index: int) -> str:
    """Return the file stem of frame ``index`` (``00042``)."""
    return f"{index:05d}"


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of one synthetic frame.

    Attributes
    ----------
    vertices : (n, 3) float64, the subject's surface (fixed connectivity over the capture)
    joints : (K, 3) float64 or None, evaluation joints, metres, world frame (Z up)
    rotations : (J, 3, 3) float64 or None, local joint rotations of the subject's rig
    root : (3,) float64 or None, root joint position

    Captures made from a mesh sequence (e.g. the crane) have vertices only.
    """

    vertices: np.ndarray
    joints: np.ndarray | None = None
    rotations: np.ndarray | None = None
    root: np.ndarray | None = None


def write_truth(path: str | os.PathLike, truth: Truth) -> None:
    """Write ``truth`` to ``path`` (``.npz``) atomically."""
    arrays = {"vertices": truth.vertices.astype(np.float32)}
    for key in ("joints", "rotations", "root"):
        if getattr(truth, key) is not None:
            arrays[key] = getattr(truth, key)
    with atomic_open(path) as f:
        np.savez_compressed(f, **arrays)


def read_truth(path: str | os.PathLike) -> Truth:
    """Read a truth file written by :func:`write_truth`."""
    d = _load_npz(path, ("vertices",), optional=("joints", "rotations", "root"))
    return Truth(
        d["vertices"].astype(np.float64), d.get("joints"), d.get("rotations"), d.get("root")
    )


def write_hull(path: str | os.PathLike, hull: VoxelHull) -> None:
    """Write a hull's occupancy (bit-packed), origin and voxel size to ``path`` (``.npz``)."""
    with atomic_open(path) as f:
        np.savez_compressed(
            f, bits=np.packbits(hull.occupancy.ravel()), shape=np.array(hull.occupancy.shape),
            origin=hull.origin, voxel_size=np.float64(hull.voxel_size),
        )  # fmt: skip


def read_hull(path: str | os.PathLike) -> VoxelHull:
    """Read a voxel hull written by :func:`write_hull`."""
    d = _load_npz(path, ("bits", "shape", "origin", "voxel_size"))
    shape = tuple(int(s) for s in d["shape"])
    occ = np.unpackbits(d["bits"], count=int(np.prod(shape))).astype(bool).reshape(shape)
    return VoxelHull(occ, d["origin"], float(d["voxel_size"]))


def _load_npz(
    path: str | os.PathLike, keys: tuple[str, ...], optional: tuple[str, ...] = ()
) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in keys} | {k: z[k] for k in optional if k in z.files}
    except FileNotFoundError:
        raise MeshmocapFileNotFoundError(f"{path}: no such file") from None
    except KeyError as exc:
        raise FormatError(f"{path}: missing key {exc}") from None
    except (OSError, ValueError) as exc:
        raise FormatError(f"{path}: not a readable .npz file ({exc})") from None


@dataclass(frozen=True, eq=False)
class CaptureFrame:
    """One frame of a capture folder; heavy parts are read on access.

    Attributes
    ----------
    index : int, frame number
    capture : Capture, the folder it belongs to
    """

    index: int
    capture: Capture

    @cached_property
    def hull_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """``(V (n, 3), F (m, 3))`` of the visual hull, metres, Z up; rebuilt from the voxel
        occupancy (marching cubes) where the ``.ply`` was removed to save space."""
        ply = self.capture.path / "hulls" / f"{frame_name(self.index)}.ply"
        if not ply.is_file() and ply.with_suffix(".npz").is_file():
            return hull_mesh(self.hull)
        return read_mesh(ply)

    @cached_property
    def hull(self) -> VoxelHull:
        """The visual hull's voxel occupancy (a distance field without re-carving)."""
        return read_hull(self.capture.path / "hulls" / f"{frame_name(self.index)}.npz")

    @property
    def cameras(self) -> list[Camera]:
        """The capture's rig (empty without ``cameras.json``)."""
        return self.capture.cameras

    @cached_property
    def silhouettes(self) -> list[np.ndarray]:
        """One (height, width) bool mask per camera, in camera order."""
        return [read_mask(p) for p in self.capture.silhouette_paths(self.index)]

    @cached_property
    def truth(self) -> Truth | None:
        """Ground truth, or None for a capture without it."""
        path = self.capture.path / "truth" / f"{frame_name(self.index)}.npz"
        return read_truth(path) if path.is_file() else None


class Capture:
    """A capture folder (see the module docstring), read lazily frame by frame.

    Parameters
    ----------
    path : path
        The folder. ``capture.json`` is optional for real captures: the frame count then
        comes from the silhouettes of the first camera or from ``hulls/``.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        if not self.path.is_dir():
            raise MeshmocapFileNotFoundError(f"capture: {self.path} is not a folder")
        meta_path = self.path / "capture.json"
        self.meta: dict = {}
        if meta_path.is_file():
            try:
                self.meta = json.loads(meta_path.read_text())
            except json.JSONDecodeError as exc:
                raise FormatError(
                    f"{meta_path}: not valid JSON ({exc.msg}, line {exc.lineno})"
                ) from None
            if self.meta.get("format") != FORMAT:
                raise FormatError(
                    f"{meta_path}: expected format {FORMAT!r}, found {self.meta.get('format')!r}"
                )
        self.indices = self._frames()

    def _frames(self) -> list[int]:
        if "frames" in self.meta:
            return [int(i) for i in self.meta["frames"]]
        for folder, suffix in (("truth", ".npz"), ("hulls", ".npz")):
            found = sorted(
                int(p.stem) for p in (self.path / folder).glob(f"*{suffix}") if p.stem.isdigit()
            )
            if found:
                return found
        if self.cameras:
            first = self.path / "silhouettes" / self.cameras[0].name
            found = sorted(int(p.stem) for p in first.glob("*.png") if p.stem.isdigit())
            if found:
                return found
        raise MeshmocapFileNotFoundError(
            f"capture: {self.path} holds no frames (no hulls/, truth/ or silhouettes/)"
        )

    @cached_property
    def cameras(self) -> list[Camera]:
        """The rig, or an empty list when the folder has no ``cameras.json``."""
        path = self.path / "cameras.json"
        return read_cameras(path) if path.is_file() else []

    @cached_property
    def truth_faces(self) -> np.ndarray | None:
        """(m, 3) int64 triangles of the true surface, or None without truth."""
        path = self.path / "truth" / "faces.npy"
        return np.load(path).astype(np.int64) if path.is_file() else None

    @property
    def fps(self) -> float:
        """Frames per second (``capture.json``; 30 when unknown)."""
        return float(self.meta.get("fps", 30.0))

    def silhouette_paths(self, index: int) -> list[Path]:
        """Mask files of frame ``index``, one per camera; raises if one is missing."""
        paths = [
            self.path / "silhouettes" / c.name / f"{frame_name(index)}.png" for c in self.cameras
        ]
        missing = [p for p in paths if not p.is_file()]
        if missing:
            raise MeshmocapFileNotFoundError(
                f"capture: frame {index} has no silhouette {missing[0]}"
            )
        return paths

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, k: int) -> CaptureFrame:
        if not -len(self) <= k < len(self):
            raise InputError(f"capture: frame position {k} out of range for {len(self)} frames")
        return CaptureFrame(self.indices[k], self)

    def __iter__(self) -> Iterator[CaptureFrame]:
        for i in self.indices:
            yield CaptureFrame(i, self)

    def __repr__(self) -> str:
        return f"Capture({str(self.path)!r}, {len(self)} frames, {len(self.cameras)} cameras)"


def write_truth_faces(capture: str | os.PathLike, F: np.ndarray) -> None:
    """Write the true surface's triangles (``truth/faces.npy``)."""
    with atomic_open(Path(capture) / "truth" / "faces.npy") as f:
        np.save(f, np.asarray(F, dtype=np.int32))


def write_meta(path: str | os.PathLike, meta: dict) -> None:
    """Write ``capture.json`` (adds the format tag)."""
    write_text_atomic(path, json.dumps({"format": FORMAT, **meta}, indent=2) + "\n")


@dataclass(frozen=True, eq=False)
class SequenceFrame:
    """A frame of a plain mesh or point-cloud sequence, with the same attributes as
    :class:`CaptureFrame` (``hull_mesh`` holds the frame's geometry; ``F`` is None for a
    point cloud)."""

    index: int
    hull_mesh: tuple[np.ndarray, np.ndarray | None]
    normals: np.ndarray | None
    silhouettes: list[np.ndarray] | None = None
    truth: Truth | None = None
    cameras: list[Camera] = field(default_factory=list)


class SequenceCapture:
    """Any folder, glob or archive of meshes or point clouds, read as a capture, frame by frame.

    Parameters
    ----------
    source : path or glob
        See :class:`~meshmocap.io.meshes.MeshSequence`.
    cameras : path, optional
        A camera file; with ``silhouettes`` (a folder of ``<camera>/NNNNN.png``) the frames
        also carry their masks (for the silhouette overlap error).
    up : {"z", "y"}
        The files' up axis.
    """

    def __init__(self, source, *, cameras=None, silhouettes=None, up: str = "z", frames=None):
        from meshmocap.io.meshes import MeshSequence

        self.seq = MeshSequence(source, up=up, frames=frames)
        self.path = Path(os.fspath(source))
        self.meta: dict = {}
        self.cameras = read_cameras(cameras) if cameras else []
        self.silhouette_dir = Path(silhouettes) if silhouettes else None
        self.indices = [int(i) for i in self.seq.indices]
        self.truth_faces = None
        self.fps = 30.0

    def __len__(self) -> int:
        return len(self.seq)

    def __getitem__(self, k: int) -> SequenceFrame:
        f = self.seq[k]
        masks = None
        if self.silhouette_dir is not None and self.cameras:
            masks = [
                read_mask(self.silhouette_dir / c.name / f"{frame_name(f.index)}.png")
                for c in self.cameras
            ]
        return SequenceFrame(f.index, (f.V, f.F), f.normals, masks, cameras=self.cameras)

    def __iter__(self) -> Iterator[SequenceFrame]:
        for k in range(len(self)):
            yield self[k]


def open_capture(source: str | os.PathLike, **kwargs) -> Capture | SequenceCapture:
    """Open a capture folder (``capture.json``, ``hulls/`` or ``silhouettes/``) or, for any
    other folder, glob or archive of meshes/point clouds, a :class:`SequenceCapture`."""
    path = Path(os.fspath(source))
    if path.is_dir() and any((path / n).exists() for n in ("capture.json", "hulls", "truth")):
        return Capture(path)
    return SequenceCapture(source, **kwargs)
