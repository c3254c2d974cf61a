"""Preset camera rigs of the synthetic capture studio.

Every preset sees a whole **capture volume**: a vertical cylinder of radius
``volume_radius`` (1.5 m) around ``centre``, from the floor (z = 0) to
:data:`VOLUME_HEIGHT` (2 m) — room for a 2 m tall person standing anywhere within
1.5 m of the centre. The focal length (the same for every camera of a rig, square pixels,
principal point at the image centre, no distortion) is the longest that keeps that volume
inside every image with ``margin`` of free border, so the subject is as large as possible.

* ``"humaneva4"`` — four cameras high in the corners of the room looking down at the
  volume, as in HumanEva-II: 2.5–2.9 m high, about ``radius`` = 4.5 m from the centre,
  slightly irregular (real rigs are; exactly opposite cameras would see mirror-image
  silhouettes and add nothing). Such sparse views carve visual hulls with the phantom
  volumes real studios suffer.
* ``"ring8"`` — eight cameras evenly spaced on a circle of ``radius`` = 4 m, 1.6 m high
  (a little above chest height), all looking at ``centre``; camera ``C1`` faces the
  front of a template facing −Y.

Camera names are ``C1``, ``C2``, ... Rigs from calibration files are read with
:func:`meshmocap.io.cameras.read_cameras`.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera, look_at

#: Names of the preset rigs.
RigName = Literal["humaneva4", "ring8"]
#: Height of the capture volume (metres above the floor, z = 0) every preset sees whole.
VOLUME_HEIGHT = 2.0

# Per camera: azimuth (degrees, counter-clockwise from +X, about the centre), horizontal
# distance as a factor of `radius`, height above the floor (metres).
_LAYOUTS: dict[str, tuple[float, np.ndarray]] = {
    "humaneva4": (
        4.5,
        np.array(
            [[47.0, 1.00, 2.85], [133.0, 0.93, 2.60], [221.0, 1.06, 2.75], [316.0, 0.97, 2.50]]
        ),
    ),
    "ring8": (
        4.0,
        np.column_stack([-90.0 + 45.0 * np.arange(8), np.ones(8), np.full(8, 1.6)]),
    ),
}


def camera_rig(
    name: RigName,
    *,
    width: int = 640,
    height: int = 480,
    centre: tuple[float, float, float] = (0.0, 0.0, 0.9),
    radius: float | None = None,
    volume_radius: float = 1.5,
    margin: float = 0.05,
) -> list[Camera]:
    """Return the cameras of a preset rig.

    Parameters
    ----------
    name : {"humaneva4", "ring8"}
        The preset (see the module docstring).
    width, height : int
        Image size, pixels.
    centre : (3,) float
        Point every camera looks at, metres, world frame (Z up); its (x, y) is the axis of
        the capture volume. The volume always stands on the floor, z = 0.
    radius : float, optional
        Horizontal distance of the cameras from the centre, metres (per-camera factors
        near 1 keep ``humaneva4`` irregular); default 4.5 (humaneva4) or 4.0 (ring8).
    volume_radius : float
        Radius of the capture volume, metres; must be well inside ``radius``.
    margin : float
        Free border around the volume's image, as a fraction of the image size per side.

    Returns
    -------
    list of Camera
        Named ``C1``, ``C2``, ...; ``X_cam = R X + t`` with ``X`` in metres, world frame.

    Raises
    ------
    InputError
        Unknown ``name`` (the message lists the presets) or bad sizes.
    """
    choices = list(get_args(RigName))
    if not isinstance(name, str) or name not in choices:
        raise InputError(
            f"camera_rig: name must be one of {choices}, found {name!r} "
            f"(read rigs from files with meshmocap.io.cameras.read_cameras)"
        )
    if not (_positive_int(width) and _positive_int(height)):
        raise InputError(f"camera_rig: width and height must be positive, found {width}×{height}")
    c = np.asarray(centre, dtype=float)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise InputError(f"camera_rig: centre must be 3 finite numbers, found {centre!r}")
    default_radius, layout = _LAYOUTS[name]
    radius = default_radius if radius is None else float(radius)
    if not (np.isfinite(volume_radius) and volume_radius > 0):
        raise InputError(f"camera_rig: volume_radius must be positive, found {volume_radius}")
    if not (np.isfinite(radius) and radius * layout[:, 1].min() > volume_radius + 0.5):
        raise InputError(
            f"camera_rig: radius must keep the cameras at least 0.5 m outside the capture "
            f"volume (volume_radius {volume_radius} m), found {radius}"
        )
    if not 0 <= margin < 0.5:
        raise InputError(f"camera_rig: margin must be in [0, 0.5), found {margin}")
    az = np.deg2rad(layout[:, 0])
    eyes = np.column_stack(
        [
            c[0] + radius * layout[:, 1] * np.cos(az),
            c[1] + radius * layout[:, 1] * np.sin(az),
            layout[:, 2],
        ]
    )
    poses = [look_at(eye, c) for eye in eyes]
    f = _fit_focal(poses, c, volume_radius, int(width), int(height), margin)
    K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
    return [Camera(K, R, t, width, height, None, f"C{i + 1}") for i, (R, t) in enumerate(poses)]


def volume_points(centre, volume_radius: float, n: int = 720) -> np.ndarray:
    """Return (2n, 3) points on the rims of the capture volume (its convex hull's extremes).

    Two circles of radius ``volume_radius`` about ``centre``'s vertical axis, at z = 0 and
    z = :data:`VOLUME_HEIGHT`; metres, world frame.
    """
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = np.column_stack([np.cos(a), np.sin(a)]) * volume_radius + np.asarray(centre)[:2]
    return np.concatenate(
        [np.column_stack([ring, np.full(n, z)]) for z in (0.0, VOLUME_HEIGHT)], axis=0
    )


def _fit_focal(poses, centre, volume_radius, width, height, margin) -> float:
    """Longest focal length (pixels) keeping the capture volume inside every image."""
    P = volume_points(centre, volume_radius)
    f = np.inf
    for R, t in poses:  # a handful of cameras
        Xc = P @ R.T + t
        if np.any(Xc[:, 2] <= 0.1):
            raise InputError("camera_rig: the capture volume reaches behind a camera")
        for axis, size in ((0, width), (1, height)):
            extent = np.abs(Xc[:, axis] / Xc[:, 2]).max()
            # The rim circles are sampled every 0.5°: their extremes are within 1e-5 of
            # the samples, far inside the margin; 0.999 makes it a strict bound.
            f = min(f, 0.999 * (1 - 2 * margin) * (size - 1) / 2 / extent)
    return float(f)


def _positive_int(x) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool) and x > 0
