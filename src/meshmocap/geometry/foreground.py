"""Foreground segmentation of studio footage: background models, shadow-aware differencing,
mask clean-up and multi-view consistency, as pure array functions.

The background of a camera is either an **empty-scene plate** (the studio standard: one
image of the scene without the subject) or a **model learned over the footage**: the
per-pixel temporal median, then the median again over the frames where the pixel was not
foreground (:func:`learn_background`), which removes the ghost a slow subject leaves in a
plain median. The pixel noise is the temporal median absolute deviation (1.4826·MAD,
floored), so a flickering screen or a compressed texture needs a larger difference.

A pixel is foreground when its colour ``I`` differs from the background ``B`` by more than
the noise in **chromaticity or brightness** (Horprasert, Harwood & Davis, "A statistical
approach for real-time robust background subtraction and shadow detection", ICCV FRAME-RATE
workshop 1999): with the brightness distortion ``α = ⟨I, B⟩ / ⟨B, B⟩`` and the chromaticity
distortion ``CD = |I − α B|``, a pixel is background when ``CD`` is within the noise and
``α`` is near 1; a **shadow** (``shadow_low ≤ α < 1`` with the same chromaticity) is
background too; darker than any shadow or brighter than the background is foreground.

:func:`clean_mask` opens and closes the mask, fills its holes and keeps its large
connected components. :func:`consistent_masks` makes the cameras agree: a pixel of one
camera whose ray misses the volume carved from the other cameras is dropped (the volume
tolerates one other camera that lost the subject: it is the union of the hulls of the
others without one of them).

Images: ``(height, width, 3)`` uint8 RGB or float; masks ``(height, width)`` bool.

References
----------
- T. Horprasert, D. Harwood, L. S. Davis, *A statistical approach for real-time robust
  background subtraction and shadow detection*, ICCV Frame-Rate Workshop, 1999.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage

from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.carving import carve

_MAD = 1.4826  # MAD → standard deviation of a normal distribution
_MIN_NOISE = 3.0  # grey levels: the noise floor of 8-bit compressed footage


def learn_background(
    frames: np.ndarray, *, masks: np.ndarray | None = None, min_frames: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    """Learn a camera's background over its footage.

    Parameters
    ----------
    frames : (n, height, width, 3) uint8
        Frames of one camera (a sample of the footage is enough).
    masks : (n, height, width) bool, optional
        Foreground of each frame: those pixels are left out of the median where at least
        ``min_frames`` frames see the background there (elsewhere the plain median stays).
    min_frames : int
        Fewest background frames for the masked median of a pixel.

    Returns
    -------
    background : (height, width, 3) float32, the temporal median colour
    noise : (height, width) float32, per-pixel noise (1.4826·MAD over time and channels,
        at least 3 grey levels)
    """
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0:
        raise InputError(f"learn_background: frames must be (n, h, w, 3), found {frames.shape}")
    n, H, W, _ = frames.shape
    if masks is not None and np.shape(masks) != (n, H, W):
        raise InputError(f"learn_background: masks must be {(n, H, W)}, found {np.shape(masks)}")
    background = np.empty((H, W, 3), np.float32)
    noise = np.empty((H, W), np.float32)
    rows = max(1, (1 << 22) // max(1, n * W * 3))  # ~4 M values a block
    for r0 in range(0, H, rows):
        block = frames[:, r0 : r0 + rows].astype(np.int16)
        med = np.median(block, axis=0)
        if masks is not None:
            fg = np.asarray(masks[:, r0 : r0 + rows], bool)
            valid = (~fg).sum(axis=0)
            keyed = np.where(fg[..., None], np.int16(1000), block)  # foreground sorts last
            keyed.sort(axis=0)
            k = np.maximum(valid - 1, 0) // 2
            masked = np.take_along_axis(keyed, k[None, :, :, None].repeat(3, axis=3), 0)[0]
            med = np.where((valid >= min_frames)[..., None], masked, med)
        background[r0 : r0 + rows] = med
        dev = np.abs(block - med[None]).max(axis=3)
        noise[r0 : r0 + rows] = _MAD * np.median(dev, axis=0)
    np.maximum(noise, _MIN_NOISE, out=noise)
    return background, noise


def foreground_mask(
    image: np.ndarray,
    background: np.ndarray,
    noise: np.ndarray | float = _MIN_NOISE,
    *,
    threshold: float = 4.0,
    min_difference: float = 25.0,
    shadow_low: float = 0.45,
    blur: float = 0.0,
) -> np.ndarray:
    """Foreground of one image against its background, shadows removed.

    Parameters
    ----------
    image : (height, width, 3) uint8 or float, RGB
    background : (height, width, 3), RGB, same scale as ``image``
    noise : (height, width) float or float
        Per-pixel noise, grey levels (:func:`learn_background`).
    threshold : float
        Foreground where the chromaticity distortion exceeds ``threshold × noise``.
    min_difference : float
        ...and exceeds this many grey levels (compression blocks, sensor noise).
    shadow_low : float
        Darkest brightness ratio ``α`` still taken for a shadow (0.45: 55 % darker).
    blur : float
        Gaussian smoothing of the distortions, pixels (0 for none).

    Returns
    -------
    (height, width) bool
    """
    I = np.asarray(image, np.float32)
    B = np.asarray(background, np.float32)
    if I.shape != B.shape or I.ndim != 3 or I.shape[2] != 3:
        raise InputError(
            f"foreground_mask: image and background must be (h, w, 3) alike, found "
            f"{I.shape} and {B.shape}"
        )
    alpha = (I * B).sum(axis=2) / np.maximum((B * B).sum(axis=2), 1.0)
    cd = np.linalg.norm(I - alpha[..., None] * B, axis=2)
    diff = np.abs(I - B).max(axis=2)
    if blur > 0:
        alpha = ndimage.gaussian_filter(alpha, blur)
        cd = ndimage.gaussian_filter(cd, blur)
        diff = ndimage.gaussian_filter(diff, blur)
    limit = np.maximum(threshold * np.asarray(noise, np.float32), min_difference)
    chroma = cd > limit
    # brightness: darker than a shadow, or brighter than the background by more than noise
    gap = np.abs(1.0 - alpha) * np.sqrt((B * B).sum(axis=2))  # |I − B| along B, grey levels
    bright = (alpha < shadow_low) | ((alpha > 1.0) & (gap > limit))
    return (chroma | bright) & (diff > min_difference)


def clean_mask(
    mask: np.ndarray,
    *,
    open_px: int = 1,
    close_px: int = 1,
    keep: float = 0.15,
    min_area: float = 5e-4,
) -> np.ndarray:
    """Open, close, fill holes and keep the large connected components of a mask.

    Parameters
    ----------
    mask : (height, width) bool
    open_px, close_px : int
        Radii (pixels) of the opening (removes specks) and closing (joins limbs cut by a
        background of the same colour).
    keep : float
        Keep components of at least this fraction of the largest one's area...
    min_area : float
        ...and at least this fraction of the image's area.

    Returns
    -------
    (height, width) bool
    """
    m = np.asarray(mask, bool)
    if m.ndim != 2:
        raise InputError(f"clean_mask: mask must be (h, w), found {m.shape}")
    if open_px > 0:
        m = ndimage.binary_opening(m, _disk(open_px))
    if close_px > 0:  # pad so that the closing does not glue the mask to the border
        p = close_px
        m = ndimage.binary_closing(np.pad(m, p), _disk(close_px))[p:-p, p:-p]
    m = ndimage.binary_fill_holes(m)
    labels, n = ndimage.label(m)
    if n == 0:
        return m
    area = np.bincount(labels.ravel())[1:]
    good = (area >= keep * area.max()) & (area >= min_area * m.size)
    return good[labels - 1] & (labels > 0)


def consistent_masks(
    masks: list[np.ndarray],
    cameras: list[Camera],
    *,
    voxel_size: float = 0.03,
    misses: int = 1,
) -> list[np.ndarray]:
    """Drop the pixels of each camera whose rays miss the volume carved from the others.

    Parameters
    ----------
    masks : list of (height, width) bool, one per camera (``cameras[i].shape``)
    cameras : list of Camera, at least 3 (two others to carve from)
    voxel_size : float
        Voxel edge of the carving, metres; a pixel is kept when it lies within about one
        voxel's image of a carved voxel.
    misses : int
        Other cameras whose mask may miss a point of the volume (a camera that lost the
        subject in that frame must not erase it from the others); at least two cameras
        carve.

    Returns
    -------
    list of (height, width) bool
        Each mask with the pixels the other cameras do not confirm removed (a camera
        whose others carve nothing is returned as it was).
    """
    reaches = others_reach(masks, cameras, voxel_size=voxel_size, misses=misses)
    return [m if r is None else m & r for m, r in zip(masks, reaches, strict=True)]


def others_reach(
    masks: list[np.ndarray],
    cameras: list[Camera],
    *,
    voxel_size: float = 0.03,
    misses: int = 1,
) -> list[np.ndarray | None]:
    """Where, in each camera, the volume carved from the other cameras' masks projects.

    Parameters
    ----------
    masks : list of (height, width) bool, one per camera
    cameras : list of Camera
    voxel_size : float, voxel edge of the carving, metres
    misses : int
        The volume is the union of the hulls carved from every subset of the others
        without up to ``misses`` of them (never fewer than two cameras).

    Returns
    -------
    list of (height, width) bool or None
        None where fewer than two other cameras have a non-empty mask or they carve
        nothing.
    """
    if len(masks) != len(cameras):
        raise InputError(f"consistent_masks: {len(masks)} masks for {len(cameras)} cameras")
    out: list[np.ndarray | None] = []
    for i, cam in enumerate(cameras):
        others = [k for k in range(len(cameras)) if k != i and masks[k].any()]
        if len(others) < 2:
            out.append(None)
            continue
        size = max(2, len(others) - max(0, int(misses)))
        hit = None
        for subset in itertools.combinations(others, size):
            hull = carve(
                [masks[k] for k in subset], [cameras[k] for k in subset], voxel_size=voxel_size
            )
            if hull.occupancy.any():
                r = reach(hull.centres(), cam, voxel_size)
                hit = r if hit is None else hit | r
        out.append(hit)
    return out


def reach(X: np.ndarray, camera: Camera, size: float) -> np.ndarray:
    """Pixels of ``camera`` covered by cubes of edge ``size`` (metres) centred on ``X``.

    Parameters
    ----------
    X : (n, 3) float64, cube centres, metres
    camera : Camera
    size : float, cube edge, metres

    Returns
    -------
    (height, width) bool
        Conservative: each cube covers a square of its largest image half-diagonal.
    """
    uv, depth = camera.project(X)
    H, W = camera.shape
    ok = depth > 1e-6
    uv, depth = uv[ok], depth[ok]
    out = np.zeros((H, W), bool)
    if not len(uv):
        return out
    f = max(camera.K[0, 0], camera.K[1, 1])
    radius = 0.87 * size * f / depth + 1.0  # half-diagonal of the cube's image, pixels
    cell = max(1, int(np.floor(radius.min())))
    gh, gw = -(-H // cell), -(-W // cell)
    c = np.floor((uv[:, 0] + 0.5) / cell).astype(np.int64)
    r = np.floor((uv[:, 1] + 0.5) / cell).astype(np.int64)
    grid = np.zeros((gh, gw), np.int32)  # largest radius (in cells) of the cubes per cell
    inside = (c >= -8) & (c < gw + 8) & (r >= -8) & (r < gh + 8)
    rc = np.ceil(radius[inside] / cell).astype(np.int32)
    c, r = np.clip(c[inside], 0, gw - 1), np.clip(r[inside], 0, gh - 1)
    np.maximum.at(grid, (r, c), rc)
    covered = np.zeros((gh, gw), bool)
    for k in np.unique(grid[grid > 0]):  # a dilation per radius (a handful)
        covered |= ndimage.binary_dilation(grid == k, np.ones((2 * k + 1, 2 * k + 1), bool))
    return np.repeat(np.repeat(covered, cell, axis=0), cell, axis=1)[:H, :W]


def _disk(r: int) -> np.ndarray:
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    return x * x + y * y <= r * r
