"""Pinhole projection in the OpenCV convention, as pure array functions.

A camera maps a world point ``X`` (metres, Z up) to pixels by ``x = K (R X + t)``: camera
axes x right, y down, z forward (depth); pixel coordinates ``(u, v) = (column, row)`` with
the centre of the top-left pixel at (0, 0).
"""

from __future__ import annotations

import numpy as np


def intrinsics(width: int, height: int, fov_deg: float) -> np.ndarray:
    """Return the (3, 3) matrix ``K`` of a camera with a horizontal field of view ``fov_deg``."""
    f = 0.5 * width / np.tan(0.5 * np.deg2rad(fov_deg))
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])


def look_at(
    eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Return extrinsics ``(R, t)`` of a camera at ``eye`` looking at ``target``.

    Parameters
    ----------
    eye, target : (3,) float64
        Camera centre and look-at point, metres, world frame (Z up).
    up : (3,) float64
        World direction that appears up in the image.

    Returns
    -------
    R : (3, 3) float64, world → camera rotation (rows: camera x, y, z axes in world)
    t : (3,) float64, so that ``X_cam = R X + t``
    """
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=float))
    if np.linalg.norm(x) < 1e-9:  # looking along `up`: pick any perpendicular
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ eye


def project(
    X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Project world points into pixels.

    Parameters
    ----------
    X : (..., 3) float64, metres, world frame
    K : (3, 3) intrinsics; R : (3, 3), t : (3,) extrinsics (``X_cam = R X + t``)

    Returns
    -------
    uv : (..., 2) float64, pixel coordinates (column, row)
    depth : (...,) float64, metres along the optical axis (≤ 0 behind the camera)
    """
    Xc = np.asarray(X, dtype=float) @ R.T + t
    depth = Xc[..., 2]
    safe = np.where(np.abs(depth) < 1e-12, 1e-12, depth)
    uvw = Xc @ K.T
    return uvw[..., :2] / safe[..., None], depth
