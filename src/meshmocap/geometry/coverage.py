"""Silhouette coverage: which silhouette pixels a set of surface points leaves uncovered,
as pure array functions.

A visual hull is the largest shape consistent with its silhouettes: it holds phantom
volumes (wedges the cameras cannot see into) that a surface can sit in while still
projecting inside every silhouette. What the hull does not tell, and the silhouettes do,
is that the true surface covers *every* silhouette pixel: a limb fitted into a phantom
wedge leaves the pixels of the true limb uncovered in some view. These functions find such
pixels and the viewing rays through them.

``X`` : (n, 3) float64 surface points, metres, world frame (Z up). Pixels ``uv`` : (m, 2)
float64, (column, row) in the OpenCV convention of :mod:`meshmocap.geometry.camera`.
"""

from __future__ import annotations

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import NEAR_DEPTH
from meshmocap.geometry.camera import Camera


def mask_samples(mask: np.ndarray, stride: int) -> np.ndarray:
    """Pixels (m, 2) float64 ``(u, v)`` of ``mask`` (H, W) bool on a grid of step ``stride``
    (every pixel whose row and column are multiples of it)."""
    sub = np.asarray(mask, dtype=bool)[::stride, ::stride]
    r, c = np.nonzero(sub)
    return np.stack([c * stride, r * stride], axis=1).astype(np.float64)


def pixel_rays(camera: Camera, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Viewing rays through pixels ``uv`` (m, 2): the camera centre (3,) and unit world
    directions (m, 3), lens distortion inverted (OpenCV model, fixed-point iteration)."""
    K = camera.K
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    if np.any(camera.dist):
        k1, k2, p1, p2, k3 = camera.dist
        xd, yd = x, y
        for _ in range(20):
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            x, y = (xd - dx) / radial, (yd - dy) / radial
    d = np.stack([x, y, np.ones_like(x)], axis=1) @ camera.R  # Rᵀ [x, y, 1] per row
    return camera.centre, d / np.linalg.norm(d, axis=1, keepdims=True)


def uncovered(
    camera: Camera,
    uv: np.ndarray,
    X: np.ndarray,
    *,
    radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Silhouette pixels ``uv`` (m, 2) that no point of ``X`` (n, 3) covers in ``camera``.

    A point covers the pixels within ``radius`` metres of it, measured at its depth (``r =
    d_px · depth / f``, ``f`` the mean focal length): about the spacing of the points, so
    that a surface sampled that densely covers its whole projection.

    Returns
    -------
    pixels : (k,) int64, indices into ``uv`` of the uncovered pixels
    nearest : (k,) int64, index into ``X`` of each one's nearest projected point
    gap : (k,) float64, metres at that point's depth from the pixel to it
    """
    xy, depth = camera.project(X)
    front = np.flatnonzero(depth > NEAR_DEPTH)
    if len(front) == 0 or len(uv) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    d, j = KDTree(xy[front]).query(uv, k=1)
    j = front[j.astype(np.int64)]
    f = 0.5 * (camera.K[0, 0] + camera.K[1, 1])
    gap = d * depth[j] / f
    out = np.flatnonzero(gap > radius)
    return out, j[out], gap[out]
