"""What every tracker and check reads from a frame, whatever the capture: surface points
with outward unit normals, and a voxel occupancy (the distance field of the cage tracker
and of the fit-quality checks).

A capture folder's frame has both (its hull mesh and the hull's voxels). A frame of a mesh
or point-cloud sequence has only its geometry: the occupancy is made from it here —
surface points splatted into voxels, closed (gaps between samples) and filled (the
inside) — and a point cloud without normals gets them from its points' neighbourhoods,
turned out of that occupancy (the gradient of its signed distance).

:class:`ObservedFrame` wraps any frame and computes each of these once; the sequence
driver hands trackers wrapped frames. Metres, world frame Z up throughout.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from pykdtree.kdtree import KDTree
from scipy import ndimage

from meshmocap.errors import InputError
from meshmocap.geometry.carving import VoxelHull
from meshmocap.geometry.distance_field import LazyDistanceGrid
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.proximity import sample_surface

__all__ = [
    "VOXEL_SIZE",
    "ObservedFrame",
    "frame_hull",
    "frame_points",
    "observed",
    "occupancy_from_points",
    "plane_normals",
]

#: Voxel edge (metres) of occupancies made from meshes and point clouds (as the studio's
#: visual hulls).
VOXEL_SIZE = 0.01
#: Voxels of closing: gaps up to about twice this between surface samples are bridged.
CLOSING = 2
#: Metres of exact signed distance around a frame's occupancy (:attr:`ObservedFrame.field`).
FIELD_PAD = 0.1
#: Surface samples per voxel face area when a mesh is splatted.
SAMPLES_PER_VOXEL = 4


def occupancy_from_points(P: np.ndarray, *, voxel_size: float = VOXEL_SIZE) -> VoxelHull:
    """The solid a sampled closed surface bounds, as voxels.

    Parameters
    ----------
    P : (p, 3) float64
        Points on the surface, metres, world frame, dense enough that neighbours lie within
        about ``2 * CLOSING`` voxels of each other.
    voxel_size : float
        Voxel edge, metres.

    Returns
    -------
    VoxelHull
        Voxels holding a point, dilated by :data:`CLOSING` voxels, the inside filled
        (``scipy.ndimage.binary_fill_holes``), eroded back (a closing that fills). A surface
        with a hole wider than the dilation bridges stays a shell.
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0 or not np.all(np.isfinite(P)):
        raise InputError(f"occupancy: expected finite (p, 3) points with p > 0, found {P.shape}")
    h = float(voxel_size)
    pad = CLOSING + 2
    origin = P.min(axis=0) - pad * h
    ijk = np.floor((P - origin) / h).astype(np.int64)
    shape = tuple(int(v) for v in ijk.max(axis=0) + pad + 1)
    if np.prod(shape, dtype=np.float64) > 1 << 27:
        raise InputError(
            f"occupancy: the points span {np.ptp(P, axis=0).round(1).tolist()} m, too large for "
            f"{h} m voxels (are they in metres?)"
        )
    occ = np.zeros(shape, dtype=bool)
    occ[tuple(ijk.T)] = True
    ball = ndimage.generate_binary_structure(3, 1)
    occ = ndimage.binary_dilation(occ, ball, iterations=CLOSING)  # bridge the gaps, ...
    occ = ndimage.binary_fill_holes(occ)  # ... fill the inside, ...
    occ = ndimage.binary_erosion(occ, ball, iterations=CLOSING)  # ... and shrink back
    return VoxelHull(occ, origin + 0.5 * h, h)  # VoxelHull's origin: the first voxel's centre


def plane_normals(P: np.ndarray, out: np.ndarray, *, k: int = 16) -> np.ndarray:
    """Unit normals (p, 3) of points ``P`` (p, 3): the least-variance axis of each point's
    ``k`` nearest neighbours (principal component analysis), signed to agree with the
    rough outward directions ``out`` (p, 3) (e.g. a distance field's gradient)."""
    k = min(k, len(P))
    _, idx = KDTree(P).query(P, k=k)
    Q = P[np.asarray(idx, dtype=np.int64).reshape(len(P), k)]
    Q = Q - Q.mean(axis=1, keepdims=True)
    _, U = np.linalg.eigh(np.einsum("pki,pkj->pij", Q, Q))
    N = U[:, :, 0]
    return N * np.where(np.sum(N * out, axis=1) < 0, -1.0, 1.0)[:, None]


def _dense_samples(V: np.ndarray, F: np.ndarray, h: float, seed: int) -> np.ndarray:
    """Surface samples of a mesh, :data:`SAMPLES_PER_VOXEL` per voxel face area, with the
    vertices."""
    T = V[F]
    area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1).sum()
    n = int(min(max(SAMPLES_PER_VOXEL * area / h**2, 1000), 2_000_000))
    return np.concatenate([V, sample_surface(V, F, n, seed=seed)[0]])


class ObservedFrame:
    """A capture frame (:class:`~meshmocap.io.capture.CaptureFrame` or
    :class:`~meshmocap.io.capture.SequenceFrame`) with its points, normals and occupancy
    computed once. Every other attribute (``index``, ``hull_mesh``, ``cameras``,
    ``silhouettes``, ``truth``) is the frame's own.

    Parameters
    ----------
    frame : a capture frame
    voxel_size : float
        Voxel edge (metres) of an occupancy made from the frame's geometry.
    """

    def __init__(self, frame, *, voxel_size: float = VOXEL_SIZE):
        self.frame = frame
        self.index = frame.index
        self.voxel_size = voxel_size

    def __getattr__(self, name: str):
        return getattr(self.__dict__["frame"], name)

    @cached_property
    def hull(self) -> VoxelHull:
        """The frame's voxel occupancy: its visual hull's, or made from its geometry
        (:func:`occupancy_from_points`)."""
        if "hull" in dir(type(self.frame)):  # a capture folder's frame: its hull's voxels
            return self.frame.hull
        V, F = self.frame.hull_mesh
        V = np.asarray(V, dtype=np.float64)
        P = V if F is None else _dense_samples(V, np.asarray(F), self.voxel_size, self.index)
        return occupancy_from_points(P, voxel_size=self.voxel_size)

    @cached_property
    def field(self) -> LazyDistanceGrid:
        """Signed distance to the occupancy's surface (metres, negative inside), computed
        where it is looked up; beyond its box (:data:`FIELD_PAD` around the occupancy) it
        grows with the distance to the box."""
        h = self.hull
        pad = 1 + int(np.ceil(FIELD_PAD / h.voxel_size))
        return LazyDistanceGrid(h.occupancy, h.origin, h.voxel_size, pad=pad)

    @cached_property
    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """``(P (p, 3), N (p, 3))``: the frame's surface points (mesh vertices or cloud
        points), metres, and their outward unit normals."""
        V, F = self.frame.hull_mesh
        V = np.ascontiguousarray(V, dtype=np.float64)
        if len(V) == 0:
            return V.reshape(0, 3), V.reshape(0, 3)
        if F is not None and len(F):
            return V, vertex_normals(V, np.asarray(F))
        N = getattr(self.frame, "normals", None)
        if N is not None:
            N = np.asarray(N, dtype=np.float64)
            norm = np.linalg.norm(N, axis=1, keepdims=True)
            if np.all(norm > 1e-12):
                return V, N / norm
        # no normals: each point's neighbourhood plane, turned out of the occupancy
        _, g = self.field.value_and_gradient(V)
        return V, plane_normals(V, g)


def observed(frame, *, voxel_size: float = VOXEL_SIZE) -> ObservedFrame:
    """``frame`` wrapped as an :class:`ObservedFrame` (itself when it is one already)."""
    return (
        frame if isinstance(frame, ObservedFrame) else ObservedFrame(frame, voxel_size=voxel_size)
    )


def frame_points(frame) -> tuple[np.ndarray, np.ndarray]:
    """Surface points (p, 3) and outward unit normals (p, 3) of any frame, metres
    (:attr:`ObservedFrame.points`)."""
    return observed(frame).points


def frame_hull(frame) -> VoxelHull:
    """The voxel occupancy of any frame (:attr:`ObservedFrame.hull`)."""
    return observed(frame).hull
