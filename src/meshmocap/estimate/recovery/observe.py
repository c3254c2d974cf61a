"""What every tracker and check reads from a frame, whatever the capture: surface points
with outward unit normals, a voxel occupancy and its signed distance (the cage tracker's
data term, the fit-quality checks, the initial pose's score).

A capture folder's frame has its hull mesh and the hull's voxels; a frame of a mesh or
point-cloud sequence has its geometry, the solid it encloses as voxels
(:attr:`~meshmocap.io.capture.SequenceFrame.hull`) and, for a point cloud, normals from the
file or estimated (:func:`~meshmocap.geometry.normals.point_normals`).
:class:`ObservedFrame` wraps any frame and computes what is derived from these once; the
sequence driver hands trackers wrapped frames. Metres, world frame Z up throughout.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from meshmocap._tolerances import NORM_FLOOR
from meshmocap.geometry.carving import VoxelHull
from meshmocap.geometry.distance_field import LazyDistanceGrid
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.normals import point_normals

__all__ = ["FIELD_PAD", "ObservedFrame", "frame_hull", "frame_points", "observed"]

#: Metres of exact signed distance around a frame's occupancy (:attr:`ObservedFrame.field`).
FIELD_PAD = 0.1


class ObservedFrame:
    """A capture frame (:class:`~meshmocap.io.capture.CaptureFrame` or
    :class:`~meshmocap.io.capture.SequenceFrame`) with its points, normals, occupancy and
    signed distance computed once. Every other attribute (``index``, ``hull_mesh``,
    ``cameras``, ``silhouettes``, ``truth``) is the frame's own.

    Parameters
    ----------
    frame : a capture frame
    """

    def __init__(self, frame):
        self.frame = frame
        self.index = frame.index

    def __getattr__(self, name: str):
        return getattr(self.__dict__["frame"], name)

    @cached_property
    def hull(self) -> VoxelHull:
        """The frame's voxel occupancy: its visual hull's, or the solid its mesh or point
        cloud encloses."""
        return self.frame.hull

    @cached_property
    def field(self) -> LazyDistanceGrid:
        """Signed distance to the occupancy's surface (metres, negative inside), computed
        where it is looked up; beyond its box (:data:`FIELD_PAD` around the occupancy) it
        grows with the distance to the box."""
        h = self.hull
        pad = 1 + int(np.ceil(FIELD_PAD / h.voxel_size))
        return LazyDistanceGrid(h.occupancy, h.origin, h.voxel_size, pad=pad)

    @cached_property
    def surface(self) -> np.ndarray:
        """(p, 3) float64: the frame's surface points (mesh vertices or cloud points),
        metres: :attr:`points` without their normals, for a reader that needs none."""
        V = np.ascontiguousarray(self.frame.hull_mesh[0], dtype=np.float64)
        return V.reshape(0, 3) if len(V) == 0 else V

    @cached_property
    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """``(P (p, 3), N (p, 3))``: the frame's surface points (mesh vertices or cloud
        points, :attr:`surface`), metres, and their outward unit normals (a mesh's vertex
        normals, a cloud's own or, without, estimated)."""
        V, F = self.surface, self.frame.hull_mesh[1]
        if len(V) == 0:
            return V, V
        if F is not None and len(F):
            return V, vertex_normals(V, np.asarray(F))
        N = getattr(self.frame, "normals", None)
        if N is None:
            return V, point_normals(V)
        N = np.asarray(N, dtype=np.float64)
        return V, N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), NORM_FLOOR)


def observed(frame) -> ObservedFrame:
    """``frame`` wrapped as an :class:`ObservedFrame` (itself when it is one already)."""
    return frame if isinstance(frame, ObservedFrame) else ObservedFrame(frame)


def frame_points(frame) -> tuple[np.ndarray, np.ndarray]:
    """Surface points (p, 3) and outward unit normals (p, 3) of any frame, metres
    (:attr:`ObservedFrame.points`)."""
    return observed(frame).points


def frame_hull(frame) -> VoxelHull:
    """The voxel occupancy of any frame (:attr:`ObservedFrame.hull`)."""
    return observed(frame).hull
