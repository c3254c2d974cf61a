"""Capture folders: cameras, silhouettes, visual hulls and ground truth, frame by frame.

Layout (``capture.json`` holds ``"format": "meshmocap-capture-1"``)::

    CAPTURE/
      capture.json                     metadata: fps, frame count, how it was made
      cameras.json                     the rig (see meshmocap.io.cameras)
      silhouettes/<camera>/NNNNN.png   one binary mask per camera and frame
      hulls/NNNNN.npz                  visual hull: voxel occupancy (bit-packed), origin,
                                       voxel size and surface mesh (compact, lossless), or
                                       the reason the frame has none (``missing``)
      truth/NNNNN.npz                  ground truth of synthetic captures: posed vertices
                                       (n, 3) float32 (byte-shuffled, vertices.f4s), evaluation
                                       joints (K, 3), local rotations (J, 3, 3), root
                                       position (3,)
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
from pykdtree.kdtree import KDTree

from meshmocap._atomic import atomic_open, write_text_atomic
from meshmocap._npz import SHUFFLED, open_npz, shuffled_float32
from meshmocap._validate import counted
from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.carving import VoxelHull, hull_mesh
from meshmocap.geometry.normals import point_normals, solid_occupancy, surface_samples
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
    """Write ``truth`` to ``path`` (``.npz``) atomically, the vertices float32 stored
    byte-shuffled (``vertices.f4s``, ``shuffled_float32`` in ``meshmocap._npz``)."""
    arrays = {f"vertices{SHUFFLED}": shuffled_float32(truth.vertices)}
    for key in ("joints", "rotations", "root"):
        if getattr(truth, key) is not None:
            arrays[key] = getattr(truth, key)
    with atomic_open(path) as f:
        np.savez_compressed(f, **arrays)


def read_truth(path: str | os.PathLike) -> Truth:
    """Read a truth file written by :func:`write_truth`."""
    d = _load_npz(path, ("vertices",), optional=("joints", "rotations", "root"))
    shapes = {"vertices": (-1, 3), "joints": (-1, 3), "rotations": (-1, 3, 3), "root": (3,)}
    for key, shape in shapes.items():
        a = d.get(key)
        if a is None:
            continue
        bad = a.dtype.kind not in "fiu" or a.ndim != len(shape) or not a.size
        if bad or any(s not in (-1, n) for s, n in zip(shape, a.shape, strict=True)):
            raise FormatError(f"{path}: {key} must be numbers of shape {shape}, found {a.shape}")
        if not np.isfinite(a).all():
            raise FormatError(f"{path}: {key} hold NaN or infinite values")
    return Truth(
        d["vertices"].astype(np.float64), d.get("joints"), d.get("rotations"), d.get("root")
    )


def write_hull(
    path: str | os.PathLike,
    hull: VoxelHull,
    *,
    mesh: tuple[np.ndarray, np.ndarray] | None = None,
    note: str = "",
) -> None:
    """Write a hull to ``path`` (``.npz``, atomically): its occupancy (bit-packed), origin
    and voxel size, and its surface mesh (:func:`~meshmocap.geometry.carving.hull_mesh`,
    computed unless given) stored compactly and losslessly.

    The mesh of a voxel hull has its vertices on a half-voxel grid, so they are stored as
    differences of integer half-voxel coordinates, and each triangle's corners as offsets
    below the running maximum vertex index (small numbers that deflate well): a 41k-vertex
    hull takes 0.25 MB where a binary PLY took 1.56 MB. ``note`` records how the frame was
    carved (e.g. the cameras left out).
    """
    V, F = hull_mesh(hull) if mesh is None else mesh
    arrays = {
        "bits": np.packbits(hull.occupancy.ravel()),
        "shape": np.array(hull.occupancy.shape),
        "origin": hull.origin,
        "voxel_size": np.float64(hull.voxel_size),
        "note": np.str_(note),
    }
    arrays.update(_pack_mesh(np.asarray(V, np.float64), np.asarray(F, np.int64), hull))
    with atomic_open(path) as f:
        np.savez_compressed(f, **arrays)
    Path(path).with_suffix(".ply").unlink(missing_ok=True)  # an old layout's mesh: stale now


def write_missing_hull(path: str | os.PathLike, reason: str) -> None:
    """Record at ``path`` (``.npz``) that a frame has no hull, and why (a dropped frame, no
    camera seeing the subject); trackers coast across such a frame (flag ``missing``)."""
    with atomic_open(path) as f:
        np.savez_compressed(f, missing=np.str_(reason))
    Path(path).with_suffix(".ply").unlink(missing_ok=True)


def _small_int(a: np.ndarray, signed: bool) -> np.ndarray:
    for t in (np.int16, np.int32) if signed else (np.uint8, np.uint16, np.uint32):
        info = np.iinfo(t)
        if not a.size or (a.min() >= info.min and a.max() <= info.max):
            return a.astype(t)
    return a.astype(np.int64)


def _pack_mesh(V: np.ndarray, F: np.ndarray, hull: VoxelHull) -> dict[str, np.ndarray]:
    if not len(V) or not len(F):
        return {}
    K = np.rint((V - hull.origin) / hull.voxel_size * 2).astype(np.int64)
    if not np.array_equal(hull.origin + K / 2 * hull.voxel_size, V):  # not on the grid
        return {"mesh_V": V.astype(np.float32), "mesh_F": F.astype(np.int32)}
    top = np.maximum.accumulate(F.max(axis=1))  # running maximum vertex index per face
    return {
        "mesh_dK": _small_int(np.diff(K, axis=0, prepend=0), True),
        "mesh_dtop": _small_int(np.diff(top, prepend=0), False),
        "mesh_below": _small_int(top[:, None] - F, False),
    }


def _unpack_mesh(d: dict, origin: np.ndarray, voxel_size: float) -> tuple[np.ndarray, np.ndarray]:
    kinds = {"mesh_V": "f", "mesh_F": "iu", "mesh_dK": "iu", "mesh_dtop": "iu", "mesh_below": "iu"}
    for key, kind in kinds.items():
        if key in d and d[key].dtype.kind not in kind:
            raise ValueError(f"{key} has dtype {d[key].dtype}")
    if "mesh_V" in d:
        return d["mesh_V"].astype(np.float64), d["mesh_F"].astype(np.int64)
    dK, dtop, below = d["mesh_dK"], d["mesh_dtop"], d["mesh_below"]
    if dK.ndim != 2 or dK.shape[1] != 3 or below.ndim != 2 or below.shape != (dtop.size, 3):
        raise ValueError(f"mesh arrays of shapes {dK.shape}, {dtop.shape}, {below.shape}")
    native = all(a.dtype.isnative for a in (dK, dtop, below))  # as compiled code reads
    # the types a hull written by write_hull has: those the background compiler compiles
    small = dtop.dtype == np.uint8 and below.dtype in (np.uint8, np.uint16, np.uint32)
    if len(dK) and len(dtop) and native and small and dK.dtype in (np.int16, np.int32):
        fast = _unpack_compiled(dK, dtop, below, origin, voxel_size)
        if fast is not None:
            return fast
    narrow = dK.dtype == np.int16 and len(dK) < 1 << 16  # its sums fit in int32
    K = np.cumsum(dK, axis=0, dtype=np.int32 if narrow else np.int64)
    top = np.cumsum(dtop.ravel(), dtype=np.int64)
    F = top[:, None] - (below.astype(np.int64) if below.dtype == np.uint64 else below)  # int64
    if not len(K):
        return np.empty((0, 3)), F
    # each axis holds few distinct half-voxel steps: map them through a table of their
    # coordinates, float32 as the PLY files held them (the same values as computing
    # origin + K / 2 · voxel_size per vertex, 5× faster)
    V = np.empty(K.shape)
    for c in range(3):
        lo, hi = int(K[:, c].min()), int(K[:, c].max())
        if hi - lo > 4 * len(K):  # scattered: compute per vertex
            V[:, c] = (origin[c] + K[:, c] / 2 * voxel_size).astype(np.float32)
            continue
        table = (origin[c] + np.arange(lo, hi + 1) / 2 * voxel_size).astype(np.float32)
        V[:, c] = table[K[:, c] - lo]
    return V, F


def _unpack_compiled(
    dK: np.ndarray, dtop: np.ndarray, below: np.ndarray, origin: np.ndarray, voxel_size: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`_unpack_mesh`'s vertices and triangles by compiled passes over the stored
    integers (the same running sums, tables and values, without the intermediate arrays);
    None where a column's half-voxel steps are scattered (:func:`_unpack_mesh` computes
    those per vertex)."""
    from meshmocap.io._kernels import mesh_extent_kernel, mesh_faces_kernel, mesh_vertices_kernel

    dK = np.ascontiguousarray(dK)
    lo, hi = np.empty(3, dtype=np.int64), np.empty(3, dtype=np.int64)
    mesh_extent_kernel(dK, lo, hi)
    if np.any(hi - lo > 4 * len(dK)):
        return None
    tables = [
        (origin[c] + np.arange(lo[c], hi[c] + 1) / 2 * voxel_size).astype(np.float32)
        for c in range(3)
    ]
    V = np.empty((len(dK), 3))
    mesh_vertices_kernel(dK, *tables, lo, V)
    F = np.empty(below.shape, dtype=np.int64)
    mesh_faces_kernel(np.ascontiguousarray(dtop.ravel()), np.ascontiguousarray(below), F)
    return V, F


def read_hull(path: str | os.PathLike) -> VoxelHull:
    """Read a voxel hull written by :func:`write_hull`.

    Raises
    ------
    FormatError
        Not a hull file, or the record of a frame without hull (:func:`write_missing_hull`).
    """
    with open_npz(path, _FRAME_FILE) as z:  # the occupancy only, not the mesh
        return _hull_of({k: z[k] for k in ("missing", *_HULL_KEYS) if k in z}, path)


def _hull_of(d: dict, path) -> VoxelHull:
    if "missing" in d:
        raise FormatError(f"{path}: the frame has no hull ({d['missing']})")
    for k in ("bits", "shape", "origin", "voxel_size"):
        if k not in d:
            raise FormatError(f"{path}: missing key {k!r}")
    raw = np.ravel(d["shape"])
    shape = tuple(int(s) for s in raw) if raw.dtype.kind in "iu" else ()
    n = int(np.prod(shape, dtype=np.int64)) if len(shape) == 3 and 0 < min(shape) < 1 << 20 else -1
    if n < 0 or d["bits"].dtype != np.uint8 or d["bits"].size != -(-n // 8):
        raise FormatError(f"{path}: occupancy of {d['bits'].size} bytes does not fit {shape}")
    occ = np.unpackbits(d["bits"].ravel(), count=n).view(bool).reshape(shape)  # 0 and 1
    origin, vs = d["origin"], d["voxel_size"]
    if origin.dtype.kind not in "fiu" or vs.dtype.kind not in "fiu" or vs.size != 1:
        raise FormatError(f"{path}: origin and voxel_size must be numbers")
    try:
        return VoxelHull(occ, origin.astype(np.float64), float(vs.ravel()[0]))
    except (InputError, TypeError, ValueError) as exc:
        raise FormatError(f"{path}: not a voxel hull ({exc})") from None


def read_hull_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """``(V (n, 3) float64 metres, F (m, 3) int64)``: the surface of the hull at ``path``
    (``hulls/NNNNN.npz``). Captures written before the mesh was stored in the ``.npz``
    have it in ``hulls/NNNNN.ply`` beside it, which is read instead. Only the mesh's arrays
    are inflated (not the occupancy, unless the file holds no mesh)."""
    path = Path(path)
    ply = path.with_suffix(".ply")
    if ply.is_file():  # a capture written the old way
        return read_mesh(ply)
    with open_npz(path, _FRAME_FILE) as z:
        if "missing" in z:
            raise FormatError(f"{path}: the frame has no hull ({z['missing']})")
        try:
            with np.errstate(over="raise", invalid="raise"):
                if "mesh_V" in z or "mesh_dK" in z:  # no need to unpack the occupancy
                    d = {k: z[k] for k in _MESH_KEYS if k in z}
                    if any(d[k].dtype.kind not in "fiu" for k in ("origin", "voxel_size")):
                        raise ValueError("origin and voxel_size must be real numbers")
                    origin, vs = d["origin"].astype(np.float64), float(d["voxel_size"])
                    if origin.shape != (3,) or not np.isfinite(origin).all() or not vs > 0:
                        raise ValueError("origin must be 3 finite numbers, voxel_size > 0")
                    V, F = _unpack_mesh(d, origin, vs)
                else:
                    V, F = hull_mesh(_hull_of({k: z[k] for k in _HULL_KEYS if k in z}, path))
                    V = V.astype(np.float32).astype(np.float64)
        except (KeyError, ValueError, TypeError, IndexError, ArithmeticError) as exc:
            raise FormatError(f"{path}: corrupt hull mesh ({type(exc).__name__}: {exc})") from None
    bad = V.ndim != 2 or V.shape[-1] != 3 or not np.isfinite(V).all()
    if bad or not len(F) or F.ndim != 2 or F.shape[1] != 3 or F.min() < 0 or F.max() >= len(V):
        raise FormatError(f"{path}: corrupt or empty hull mesh ({len(V)} vertices)")
    return V, F


def hull_missing(path: str | os.PathLike) -> str | None:
    """Why the frame of hull file ``path`` has no hull, or None when it has one (or the file
    is absent: that is reported when the hull is read)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            return str(z["missing"]) if "missing" in z.files else None
    except Exception:  # any damage is reported when the hull is read
        return None


def hull_note(path: str | os.PathLike) -> str:
    """How the frame of hull file ``path`` was carved (empty when from every camera)."""
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            for key in ("missing", "note"):
                if key in z.files and str(z[key]):
                    return str(z[key])
    except Exception:  # a damaged file is reported when it is read
        return ""
    return ""


_FRAME_FILE = "meshmocap frame file"
_HULL_KEYS = ("bits", "shape", "origin", "voxel_size")
_MESH_KEYS = ("origin", "voxel_size", "mesh_V", "mesh_F", "mesh_dK", "mesh_dtop", "mesh_below")


def _load_npz(
    path: str | os.PathLike, keys: tuple[str, ...], optional: tuple[str, ...] = ()
) -> dict[str, np.ndarray]:
    with open_npz(path, _FRAME_FILE) as z:
        missing = [k for k in keys if k not in z]
        if missing:
            names = ", ".join(map(repr, missing))
            raise FormatError(f"{path}: not a {_FRAME_FILE}: missing {names}")
        return {k: z[k] for k in (*keys, *optional) if k in z}


def read_meta(folder: str | os.PathLike) -> dict:
    """The contents of the capture folder's ``capture.json`` (empty when it has none).

    Raises
    ------
    FormatError
        Not UTF-8 JSON, not an object, or not of this format.
    """
    meta_path = Path(folder) / "capture.json"
    if not meta_path.is_file():
        return {}
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise FormatError(f"{meta_path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    except UnicodeDecodeError:
        raise FormatError(f"{meta_path}: not UTF-8 text, expected JSON") from None
    if not isinstance(meta, dict):
        raise FormatError(f"{meta_path}: expected a JSON object")
    if meta.get("format") != FORMAT:
        raise FormatError(f"{meta_path}: expected format {FORMAT!r}, found {meta.get('format')!r}")
    return meta


def meta_fps(meta: dict, folder: str | os.PathLike) -> float:
    """Frames per second that ``capture.json``'s contents ``meta`` say (30 when they do
    not); ``folder`` is named in the error.

    Raises
    ------
    FormatError
        A rate that is not a positive number.
    """
    fps = meta.get("fps", 30.0)
    ok = isinstance(fps, int | float) and not isinstance(fps, bool) and 0 < fps < 1e5
    if not ok:
        raise FormatError(f"{Path(folder) / 'capture.json'}: fps must be a positive number")
    return float(fps)


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
        """``(V (n, 3), F (m, 3))`` of the visual hull, metres, Z up."""
        return read_hull_mesh(self._hull_path)

    @cached_property
    def hull(self) -> VoxelHull:
        """The visual hull's voxel occupancy (a distance field without re-carving)."""
        return read_hull(self._hull_path)

    @property
    def _hull_path(self) -> Path:
        return self.capture.path / "hulls" / f"{frame_name(self.index)}.npz"

    @cached_property
    def missing(self) -> str | None:
        """Why this frame has no hull (a dropped frame, no camera seeing the subject), or None.
        Trackers coast across such a frame and flag it ``missing``."""
        return hull_missing(self._hull_path)

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
        self.meta: dict = read_meta(self.path)
        self.indices = self._frames()

    def _frames(self) -> list[int]:
        if "frames" in self.meta:
            found = self.meta["frames"]
            if not isinstance(found, list) or not all(
                isinstance(i, int) and not isinstance(i, bool) and 0 <= i < 10**7 for i in found
            ):
                raise FormatError(
                    f"{self.path / 'capture.json'}: 'frames' must be a list of frame numbers"
                )
            if not found:
                raise MeshmocapFileNotFoundError(f"capture: {self.path} holds no frames")
            return sorted(set(found))
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
        if not path.is_file():
            return None
        try:
            F = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise FormatError(f"{path}: not a readable .npy array ({exc})") from None
        if F.ndim != 2 or F.shape[1] != 3 or F.dtype.kind not in "iu" or not len(F):
            raise FormatError(f"{path}: expected (m, 3) integer triangles, found {F.shape}")
        return F.astype(np.int64)

    @property
    def fps(self) -> float:
        """Frames per second (``capture.json``; 30 when unknown)."""
        return meta_fps(self.meta, self.path)

    def notes(self) -> dict[int, str]:
        """Frames carved from fewer cameras or without hull, and why (frame number → note)."""
        out = {}
        for i in self.indices:
            note = hull_note(self.path / "hulls" / f"{frame_name(i)}.npz")
            if note:
                out[i] = note
        return out

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
    missing: str | None = None

    @cached_property
    def hull(self) -> VoxelHull:
        """The solid the frame's surface encloses, as 1 cm voxels (coarser for a sparse point
        cloud; :func:`~meshmocap.geometry.normals.solid_occupancy`), for trackers that fit a
        distance field."""
        V, F = self.hull_mesh
        vs = 0.01
        if F is not None:
            P = surface_samples(V, F, vs / 2)
        else:
            P = V
            gap = KDTree(P).query(P, k=2)[0][:, 1] if len(P) > 1 else np.zeros(1)
            vs = max(vs, 2.0 * float(np.median(gap)))
        occ, origin = solid_occupancy(P, vs)
        return VoxelHull(occ, origin, vs)


#: Names of the length units a mesh sequence may be scaled from (metres per unit).
UNIT_NAMES = {1.0: "m", 0.01: "cm", 0.001: "mm"}


class SequenceCapture:
    """Any folder, glob or archive of meshes or point clouds, read as a capture, frame by frame.

    Frames are numbered by their file names (:func:`~meshmocap.io.meshes.frame_numbers`:
    ``00005.ply`` is frame 5). A number missing between the first and the last file, at
    the files' stride (the greatest common divisor of the steps between their numbers: 1,
    or 2 for files of every other frame), is a frame without observation (``missing`` says
    so): trackers coast across it and keep it in the numbering.

    A sequence of fixed connectivity (a clean 4D capture: :attr:`connectivity`) keeps it
    in every frame: a file of other vertices or triangles (another performer's mesh, a file
    cut off in its faces) is a frame without observation too, ``missing`` naming the file,
    what it holds and what the others hold.

    Parameters
    ----------
    source : path or glob
        See :class:`~meshmocap.io.meshes.MeshSequence`.
    cameras : path, optional
        A camera file; with ``silhouettes`` (a folder of ``<camera>/NNNNN.png``) the frames
        also carry their masks (for the silhouette overlap error).
    up : {"z", "y"}
        The files' up axis.
    frames : positions in the files' sorted listing to keep (no gap is filled then)
    scale : float
        Metres per file unit (0.001 for millimetres).
    fps : float, optional
        Frames per second (default 30, ``fps_given`` False).
    offset : (3,) float, optional
        Metres subtracted from every point after scaling and turning Z up (default 0).
    """

    def __init__(
        self,
        source,
        *,
        cameras=None,
        silhouettes=None,
        up: str = "z",
        frames=None,
        scale: float = 1.0,
        fps: float | None = None,
        offset=None,
    ):
        from meshmocap.io.meshes import MeshSequence

        self.seq = MeshSequence(source, up=up, frames=frames)
        self.up = up
        self.scale = float(scale)
        self.offset = np.zeros(3) if offset is None else np.asarray(offset, np.float64).reshape(3)
        one = isinstance(source, str | os.PathLike)
        self.path = Path(
            os.fspath(source) if one else os.path.commonpath([os.path.abspath(p) for p in source])
        )
        self.meta: dict = {}
        self.cameras = read_cameras(cameras) if cameras else []
        self.silhouette_dir = Path(silhouettes) if silhouettes else None
        numbers = [int(n) for n in self.seq.numbers]
        self._position = {n: k for k, n in enumerate(numbers)}
        if frames is None:  # every number from the first file's to the last's, at the
            # files' own stride (files of every other frame: no odd frame is missing)
            step = int(np.gcd.reduce(np.diff(sorted(numbers)))) if len(numbers) > 1 else 1
            self.indices = list(range(min(numbers), max(numbers) + 1, max(step, 1)))
        else:
            self.indices = sorted(numbers)
        #: Frame numbers without a file (gaps in the numbering).
        self.gaps = [i for i in self.indices if i not in self._position]
        self.truth_faces = None
        if fps is not None and not (isinstance(fps, int | float) and 0 < fps < 1e5):
            raise InputError(f"capture: fps must be a positive number, found {fps!r}")
        self.fps_given = fps is not None
        self.fps = 30.0 if fps is None else float(fps)

    @property
    def units(self) -> str:
        """The files' length unit (``"m"``, ``"cm"``, ``"mm"``; else metres per unit)."""
        return UNIT_NAMES.get(self.scale, f"{self.scale:g} m")

    @cached_property
    def connectivity(self) -> tuple[int, np.ndarray] | None:
        """``(n_vertices, F (m, 3) int64)`` that the frames of a fixed-connectivity mesh
        sequence share (vertex ``i`` is the same point of the body in every file), or None
        (point clouds, visual hulls, a mesh per frame). Read from files spread over the
        sequence (the first, middle and last; the quartiles too where one differs): where
        every one, or all but one of at least three, have the same vertex count and
        triangles. Files that cannot be read are left out."""
        n = len(self.seq)
        if n < 2:  # one file (a live frame): nothing to compare, nothing read twice
            return None
        groups: dict[tuple, list[tuple[int, np.ndarray]]] = {}  # connectivity → its files

        def read(positions) -> tuple[int, int]:
            """Files read into ``groups``; the largest group's size and all files read."""
            for k in positions:
                try:
                    f = self.seq[k]
                except (MeshmocapFileNotFoundError, FormatError, MeshError, InputError):
                    continue  # an unreadable file: the driver's missing frame
                if f.F is not None:
                    key = (len(f.V), f.F.shape, hash(f.F.tobytes()))
                    groups.setdefault(key, []).append((len(f.V), f.F))
            sizes = [len(g) for g in groups.values()]
            return max(sizes, default=0), sum(sizes)

        picks = {0, n // 2, n - 1}
        agree, total = read(sorted(picks))
        if 2 <= agree < total == agree + 1:  # one differs: the quartiles decide
            agree, total = read(sorted({n // 4, (3 * n) // 4} - picks))
            if total >= 3 and agree >= total - 1:
                agree = total  # all but one agree
        if agree < 2 or agree != total:
            return None
        return max(groups.values(), key=len)[0]

    def foreign(self, path: str, V: np.ndarray, F: np.ndarray | None) -> str | None:
        """Why the file ``path`` (its vertices ``V`` and triangles ``F``, None for points)
        is not a frame of this sequence of fixed :attr:`connectivity`, or None: one line
        naming the file, what it holds and what the other frames hold."""
        ref = self.connectivity
        if ref is None:
            return None
        n, F0 = ref
        if F is None:
            found = f"a point cloud of {counted(len(V), 'point')}"
        elif len(V) == n and np.array_equal(F, F0):
            return None
        elif len(V) == n and len(F) == len(F0):
            found = f"a mesh of {n} vertices and {len(F)} triangles, but other triangles"
        else:
            found = (
                f"a mesh of {counted(len(V), 'vertex', 'vertices')} and "
                f"{counted(len(F), 'triangle')}"
            )
        return (
            f"{path}: {found}; expected {n} vertices and {len(F0)} triangles as in the other "
            "frames of this fixed-connectivity sequence (another performer's mesh, or a file "
            "cut off or damaged)"
        )

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, k: int) -> SequenceFrame:
        if not -len(self) <= k < len(self):
            raise InputError(f"capture: frame position {k} out of range for {len(self)} frames")
        index = self.indices[k]
        if index not in self._position:
            before = max(i for i in self._position if i < index)
            after = min(i for i in self._position if i > index)
            why = f"no file of frame {index} (the files skip from frame {before} to {after})"
            return SequenceFrame(index, (np.zeros((0, 3)), None), None, missing=why)
        f = self.seq[self._position[index]]
        why = self.foreign(f.path, f.V, f.F)
        if why is not None:  # another connectivity than the sequence's: not one of its frames
            return SequenceFrame(index, (np.zeros((0, 3)), None), None, missing=why)
        V = f.V if self.scale == 1.0 else f.V * self.scale  # in metres
        if self.offset.any():
            V = V - self.offset
        normals = f.normals
        if f.F is None and normals is None:  # a point cloud without normals: estimate them
            normals = point_normals(V)
        masks = None
        if self.silhouette_dir is not None and self.cameras:
            masks = [
                read_mask(self.silhouette_dir / c.name / f"{frame_name(index)}.png")
                for c in self.cameras
            ]
        return SequenceFrame(index, (V, f.F), normals, masks, cameras=self.cameras)

    def __iter__(self) -> Iterator[SequenceFrame]:
        for k in range(len(self)):
            yield self[k]


def open_capture(source: str | os.PathLike, **kwargs) -> Capture | SequenceCapture:
    """Open a capture folder (``capture.json``, ``hulls/`` or ``silhouettes/``) or, for any
    other folder, glob or archive of meshes/point clouds, a :class:`SequenceCapture`."""
    if not isinstance(source, str | os.PathLike):  # a list of frame files
        return SequenceCapture(source, **kwargs)
    path = Path(os.fspath(source))
    if path.is_dir() and any((path / n).exists() for n in ("capture.json", "hulls", "truth")):
        return Capture(path)
    if path.is_dir() and (path / "silhouettes").is_dir():
        raise MeshmocapFileNotFoundError(
            f"capture: {path} has silhouettes but no hulls; run 'meshmocap hull {path}' first"
        )
    return SequenceCapture(source, **kwargs)
