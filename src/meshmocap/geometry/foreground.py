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

A subject who **stays** (balancing on a force plate for the whole take) is the median
itself where it stands; :func:`restore_background` takes it out: the pixels whose history
has a second colour in a fair share of the frames make the subject's envelope, and inside it
the background is the colour (first or second) that agrees with the background around the
envelope, or that background brought in where the subject never leaves (not used by
:func:`~meshmocap.studio.from_video.silhouettes_from_video`: on a subject that moves across a
textured room it restores colours that are not the room's). What differencing
still misses (the subject against a background of its colour, a part that hardly moves) is
recovered by the subject's own colours: :func:`colour_model` learns them, against the
background around the subject, from the confident masks, and :func:`grow_mask` adds the
pixels of those colours that touch a frame's mask.

:func:`clean_mask` opens and closes the mask, fills its small holes (a large one is the
room seen between an arm and the trunk, or between the legs) and keeps its large connected
components. :func:`consistent_masks` makes the cameras agree: a pixel of one
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
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from skimage.morphology import convex_hull_image

from meshmocap._tolerances import NEAR_DEPTH
from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.carving import carve, hull_mesh
from meshmocap.geometry.silhouette import silhouette

#: Probability added to each colour bin before the log-ratio (a colour never seen in either
#: region gives a ratio of 0, not a division by zero).
_COLOUR_FLOOR = 1e-6

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


def restore_background(
    frames: np.ndarray,
    background: np.ndarray,
    noise: np.ndarray,
    *,
    tolerance: float = 30.0,
    share: float = 0.12,
    min_area: float = 2e-3,
) -> tuple[np.ndarray, np.ndarray]:
    """Take a subject who stays out of a learned background.

    Where the subject stands in most frames, the temporal median (:func:`learn_background`)
    is the subject. Such a pixel's history has a **second colour** in a fair share of the
    frames (the background while the subject leans away, or another body part); the
    pixels that have one, holes filled, are the subject's **envelope**. Inside it the
    background is whichever of the two colours agrees better with the background around the
    envelope, brought in by normalised Gaussian convolution at growing scales; at a pixel
    without a second colour whose colour is far from that estimate (a core the subject
    never leaves), the estimate itself.

    Parameters
    ----------
    frames : (n, height, width, 3) uint8
        Frames of one camera (the sample :func:`learn_background` learned from).
    background : (height, width, 3) float
        The learned background.
    noise : (height, width) float
        Its per-pixel noise (that of a pixel with two colours is their distance).
    tolerance : float
        Grey levels: a frame's colour farther than this from the background is the
        second colour's (a core pixel is restored when its colour is 40 grey levels from
        the estimate).
    share : float
        Fewest frames (a fraction) with the second colour for a pixel of the envelope.
    min_area : float
        Envelope parts smaller than this fraction of the image are dropped.

    Returns
    -------
    background : (height, width, 3) float32
    noise : (height, width) float32, twice the noise floor inside the envelope (the
        restored colours are estimates), as given elsewhere
    envelope : (height, width) bool
    """
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[1:] != np.shape(background):
        raise InputError(
            f"restore_background: frames (n, h, w, 3) and background (h, w, 3) must agree, "
            f"found {frames.shape} and {np.shape(background)}"
        )
    first = np.asarray(background, np.float32)
    n, H, W, _ = frames.shape
    second = np.empty_like(first)
    count = np.empty((H, W), np.int64)
    rows = max(1, (1 << 22) // max(1, n * W * 3))
    for r0 in range(0, H, rows):
        block = frames[:, r0 : r0 + rows].astype(np.int16)
        far = np.abs(block - first[None, r0 : r0 + rows]).max(axis=3) > tolerance
        keyed = np.where(far[..., None], block, np.int16(1000))  # the others sort last
        keyed.sort(axis=0)
        c = far.sum(axis=0)
        k = np.maximum(c - 1, 0) // 2
        second[r0 : r0 + rows] = np.take_along_axis(keyed, k[None, :, :, None].repeat(3, 3), 0)[0]
        count[r0 : r0 + rows] = c
    mixed = count >= share * n
    r = max(4, round(H / 100))  # bridges a core the subject never leaves
    envelope = ndimage.binary_fill_holes(ndimage.binary_closing(np.pad(mixed, r), _disk(r)))
    envelope = ndimage.binary_opening(envelope[r:-r, r:-r], _disk(2))
    labels, k = ndimage.label(envelope)
    if k:
        area = np.bincount(labels.ravel())[1:]
        envelope = np.isin(labels, 1 + np.flatnonzero(area >= min_area * envelope.size))
    envelope = ndimage.binary_dilation(envelope, _disk(3))
    noise = np.asarray(noise, np.float32)
    if not envelope.any():
        return first, noise, envelope
    guess = _fill_in(first, ~envelope)
    e1 = np.abs(first - guess).max(axis=2)
    e2 = np.where(mixed, np.abs(second - guess).max(axis=2), np.inf)
    out = first.copy()
    use2 = envelope & (e2 < e1)
    out[use2] = second[use2]
    never = envelope & ~mixed & (e1 > 40.0)  # a core the subject never leaves
    out[never] = guess[never]
    return out, np.where(envelope, np.float32(2 * _MIN_NOISE), noise), envelope


def _fill_in(image: np.ndarray, known: np.ndarray) -> np.ndarray:
    """``image`` with its unknown pixels filled by normalised Gaussian convolution of the
    known ones, at growing scales (2 to 64 pixels) until every pixel is reached."""
    out = image.copy()
    filled = known.copy()
    w = known.astype(np.float32)
    for sigma in (2, 4, 8, 16, 32, 64):
        den = ndimage.gaussian_filter(w, sigma)
        ok = ~filled & (den > 1e-3)
        if ok.any():
            num = [ndimage.gaussian_filter(image[..., c] * w, sigma) for c in range(3)]
            out[ok] = np.stack(num, -1)[ok] / den[ok, None]
            filled |= ok
        if filled.all():
            break
    return out


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


@dataclass(frozen=True, eq=False)
class ColourModel:
    """A camera's colours of the subject against the background around it
    (:func:`colour_model`).

    Attributes
    ----------
    log_ratio : (bins³,) float64, log p(colour | subject) − log p(colour | background) per
        quantised RGB colour (``bins`` levels a channel)
    region : (height, width) bool, where the subject may be: the convex hull of every
        given mask, grown by a margin
    bins : int
    """

    log_ratio: np.ndarray
    region: np.ndarray
    bins: int


def colour_model(images: np.ndarray, masks: np.ndarray, *, bins: int = 16) -> ColourModel:
    """Learn the subject's colours from the confident pixels of a camera's masks.

    The subject's histogram counts the masks' pixels (eroded by one pixel); the
    background's, a ring around the region the subject may be in (the convex hull of the
    union of the masks, grown by 1/40 of the image height; the ring three times as wide),
    so that it holds what lies around the subject, not the whole room. Both histograms
    are smoothed (σ = 0.7 bin).

    Parameters
    ----------
    images : (n, height, width, 3) uint8, frames of one camera
    masks : (n, height, width) bool, their foreground (the trusted part)
    bins : int, quantisation levels per channel (a power of two, 4 to 64)

    Returns
    -------
    ColourModel
    """
    images = np.asarray(images)
    masks = np.asarray(masks, bool)
    if images.ndim != 4 or masks.shape != images.shape[:3]:
        raise InputError(
            f"colour_model: images (n, h, w, 3) and masks (n, h, w) must agree, found "
            f"{images.shape} and {masks.shape}"
        )
    if bins not in (4, 8, 16, 32, 64):
        raise InputError(f"colour_model: bins must be 4, 8, 16, 32 or 64, found {bins!r}")
    H = images.shape[1]
    r = max(3, H // 40)
    union = masks.any(axis=0)
    region = (
        ndimage.binary_dilation(convex_hull_image(union), _disk(r))
        if union.any()
        else np.zeros(union.shape, bool)
    )
    ring = ndimage.binary_dilation(region, _disk(3 * r)) & ~region
    fg = np.zeros(bins**3)
    bg = np.zeros(bins**3)
    for im, m in zip(images, masks, strict=True):
        q = _quantise(im, bins)
        fg += np.bincount(q[ndimage.binary_erosion(m)], minlength=bins**3)
        bg += np.bincount(q[ring], minlength=bins**3)
    fg = ndimage.gaussian_filter(fg.reshape(bins, bins, bins), 0.7).ravel()
    bg = ndimage.gaussian_filter(bg.reshape(bins, bins, bins), 0.7).ravel()
    ratio = np.log(fg / max(fg.sum(), 1.0) + _COLOUR_FLOOR) - np.log(
        bg / max(bg.sum(), 1.0) + _COLOUR_FLOOR
    )
    return ColourModel(ratio, region, bins)


def grow_mask(
    image: np.ndarray,
    mask: np.ndarray,
    model: ColourModel,
    *,
    threshold: float = 0.5,
    blur: float = 0.0,
    max_hole: float = 0.002,
    within: np.ndarray | None = None,
) -> np.ndarray:
    """Add to a mask the pixels of the subject's colours that touch it.

    A pixel joins where, inside the model's region, the log-likelihood ratio of its colour
    (smoothed by ``blur`` pixels) exceeds ``threshold`` and it is connected to the mask;
    small holes are filled. What differencing missed where the background has the subject's
    colour or the subject stood still is recovered from the colours the subject showed
    elsewhere. Given ``within`` (the hull of the other cameras seen from this one,
    :func:`others_silhouettes`), a part the other cameras all see is recovered with a
    weaker colour evidence.

    Parameters
    ----------
    image : (height, width, 3) uint8
    mask : (height, width) bool
    model : ColourModel of the camera (:func:`colour_model`), same image size
    threshold : float, natural-log ratio
    blur : float, pixels
    max_hole : float
        Holes of at most this fraction of the mask's area are filled (see
        :func:`clean_mask`).
    within : (height, width) bool, optional
        Only pixels here join (default: the model's region; both are then required).

    Returns
    -------
    (height, width) bool, a superset of ``mask``
    """
    m = np.asarray(mask, bool)
    if m.shape != model.region.shape or np.shape(image)[:2] != m.shape:
        raise InputError(
            f"grow_mask: image, mask and model must be {model.region.shape}, found "
            f"{np.shape(image)[:2]} and {m.shape}"
        )
    if within is not None and np.shape(within) != m.shape:
        raise InputError(f"grow_mask: within must be {m.shape}, found {np.shape(within)}")
    if not m.any():
        return m
    score = model.log_ratio[_quantise(image, model.bins)]
    if blur > 0:
        score = ndimage.gaussian_filter(score, blur)
    region = model.region if within is None else model.region & np.asarray(within, bool)
    labels, _ = ndimage.label(m | (region & (score > threshold)))
    touched = np.unique(labels[m])
    return _fill_holes(np.isin(labels, touched[touched > 0]), max_hole)


def _quantise(image: np.ndarray, bins: int) -> np.ndarray:
    q = (np.asarray(image, np.uint8) // (256 // bins)).astype(np.int32)
    return (q[..., 0] * bins + q[..., 1]) * bins + q[..., 2]


def clean_mask(
    mask: np.ndarray,
    *,
    open_px: int = 1,
    close_px: int = 1,
    keep: float = 0.15,
    min_area: float = 5e-4,
    max_hole: float = 0.002,
) -> np.ndarray:
    """Open, close, fill the small holes and keep the large connected components of a mask.

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
    max_hole : float
        Fill the holes of at most this fraction of the mask's area (a part of the subject
        of the background's colour); a larger hole is the background seen between an arm
        and the trunk or between the legs, and stays (``np.inf`` fills every hole).

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
    m = _fill_holes(m, max_hole)
    labels, n = ndimage.label(m)
    if n == 0:
        return m
    area = np.bincount(labels.ravel())[1:]
    good = (area >= keep * area.max()) & (area >= min_area * m.size)
    return good[labels - 1] & (labels > 0)


def _fill_holes(mask: np.ndarray, max_hole: float) -> np.ndarray:
    """``mask`` with its holes of at most ``max_hole`` × its area filled."""
    holes = ndimage.binary_fill_holes(mask) & ~mask
    labels, n = ndimage.label(holes)
    if n == 0:
        return mask
    area = np.bincount(labels.ravel())[1:]
    small = np.concatenate([[False], area <= max_hole * np.count_nonzero(mask)])
    return mask | small[labels]


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


def others_silhouettes(
    masks: list[np.ndarray], cameras: list[Camera], *, voxel_size: float = 0.01
) -> list[np.ndarray | None]:
    """Each camera's view of the visual hull carved from all the other cameras' masks.

    Where a camera's mask lacks a part that this view holds, every other camera saw it
    there: the camera lost it (the subject against a background of its colour), and
    :func:`grow_mask` ``within`` this view recovers it; left out, the hull carved from all
    the cameras loses it too, and disagrees with every camera that saw it.

    Parameters
    ----------
    masks : list of (height, width) bool, one per camera
    cameras : list of Camera
    voxel_size : float, voxel edge of the carving, metres

    Returns
    -------
    list of (height, width) bool or None
        The silhouette of the others' hull (its surface mesh) in each camera; None where
        fewer than two other cameras have a non-empty mask or they carve nothing.
    """
    if len(masks) != len(cameras):
        raise InputError(f"others_silhouettes: {len(masks)} masks for {len(cameras)} cameras")
    out: list[np.ndarray | None] = []
    for i, cam in enumerate(cameras):
        others = [k for k in range(len(cameras)) if k != i and masks[k].any()]
        hull = (
            carve([masks[k] for k in others], [cameras[k] for k in others], voxel_size=voxel_size)
            if len(others) >= 2
            else None
        )
        if hull is None or not hull.occupancy.any():
            out.append(None)
            continue
        V, F = hull_mesh(hull)
        out.append(silhouette(V, F, cam, assume_closed=True))
    return out


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
    ok = depth > NEAR_DEPTH
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
