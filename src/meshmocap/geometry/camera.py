"""Pinhole projection in the OpenCV convention, as pure array functions.

A camera maps a world point ``X`` (metres, Z up) to pixels by ``x = K (R X + t)``: camera
axes x right, y down, z forward (depth); pixel coordinates ``(u, v) = (column, row)`` with
the centre of the top-left pixel at (0, 0).

References
----------
- D. C. Brown, *Decentering distortion of lenses*, Photogrammetric Engineering
  32(3):444–462, 1966.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from meshmocap._tolerances import DEPTH_FLOOR, ROTATION_SLACK, ZERO_EXTENT
from meshmocap.errors import InputError


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
    if np.linalg.norm(x) < ZERO_EXTENT:  # looking along `up`: pick any perpendicular
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
    safe = np.where(np.abs(depth) < DEPTH_FLOOR, DEPTH_FLOOR, depth)
    uvw = Xc @ K.T
    return uvw[..., :2] / safe[..., None], depth


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated pinhole camera in the OpenCV convention.

    Parameters
    ----------
    K : (3, 3) float64
        Intrinsics (focal lengths and principal point in pixels).
    R : (3, 3) float64
        World → camera rotation.
    t : (3,) float64
        Translation, metres: ``X_cam = R X + t``.
    width, height : int
        Image size in pixels.
    dist : (5,) float64
        OpenCV radial/tangential distortion ``(k1, k2, p1, p2, k3)``; zeros for none.
    name : str
        Identifier (e.g. ``"cam0"``).
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    name: str = ""

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=np.float64)
        R = np.asarray(self.R, dtype=np.float64)
        t = np.asarray(self.t, dtype=np.float64).reshape(-1)
        dist = np.zeros(5) if self.dist is None else np.asarray(self.dist, dtype=np.float64).ravel()
        dist = np.concatenate([dist, np.zeros(5 - len(dist))]) if len(dist) < 5 else dist
        problems = []
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            problems.append(f"K must be a finite (3, 3) matrix, found shape {K.shape}")
        if (
            R.shape != (3, 3)
            or not np.all(np.isfinite(R))
            or np.abs(R @ R.T - np.eye(3)).max() > ROTATION_SLACK
            or np.linalg.det(R) < 0
        ):
            problems.append("R must be a (3, 3) rotation matrix (orthonormal, det +1)")
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            problems.append(f"t must be 3 finite numbers, found shape {t.shape}")
        if len(dist) != 5 or not np.all(np.isfinite(dist)):
            problems.append(f"dist must be up to 5 finite coefficients, found {len(dist)}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            problems.append(f"image size must be positive, found {self.width}×{self.height}")
        if problems:
            raise InputError(f"camera {self.name!r}: {'; '.join(problems)}")
        for k, v in (("K", K), ("R", R), ("t", t), ("dist", dist)):
            v.setflags(write=False)
            object.__setattr__(self, k, v)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(height, width)`` as numpy arrays use it."""
        return (self.height, self.width)

    @property
    def centre(self) -> np.ndarray:
        """(3,) float64: the camera centre in the world frame, metres."""
        return -self.R.T @ self.t

    def project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points ``X`` (..., 3) to pixels ``uv`` (..., 2) and depths (...,).

        Applies the distortion model when ``dist`` is not zero. Points at depth ≈ 0 get
        huge (finite or infinite) pixel coordinates without a warning; use ``depth`` to
        reject points on or behind the camera plane.
        """
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return self._project(np.asarray(X, dtype=float))

    def _project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Xc = X @ self.R.T + self.t
        depth = Xc[..., 2]
        safe = np.where(np.abs(depth) < DEPTH_FLOOR, DEPTH_FLOOR, depth)
        x, y = Xc[..., 0] / safe, Xc[..., 1] / safe
        if np.any(self.dist):
            k1, k2, p1, p2, k3 = self.dist
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            x, y = (
                x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
            )
        K = self.K
        uv = np.stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]], axis=-1)
        return uv, depth


def in_view(X: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """Which points every camera sees: in front of it and inside its image.

    Parameters
    ----------
    X : (n, 3) float64
        World points, metres.
    cameras : list of Camera
        The rig; an empty list sees everything.

    Returns
    -------
    (n,) bool
        True where every camera projects the point to ``0 ≤ u ≤ width``, ``0 ≤ v ≤ height``
        at positive depth. A visual hull exists only there: carving removes what one camera
        cannot see, so a body part outside this region has no observations.

    Each camera's rotation is NumPy's, as in :meth:`Camera.project`; its projection and
    the image test one compiled pass (the operations of :meth:`Camera.project`, in their
    order), which skips the points an earlier camera does not see.
    """
    X = np.asarray(X, dtype=np.float64)
    ok = np.ones(len(X), dtype=bool)
    if not cameras or not len(X):
        return ok
    from meshmocap.geometry._mesh_kernels import in_image_kernel

    for cam in cameras:
        K = cam.K
        row = [K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2], *cam.dist, cam.width, cam.height]
        Xc = np.ascontiguousarray(X @ cam.R.T + cam.t)
        in_image_kernel(Xc, np.array(row, dtype=np.float64), ok)
    return ok
