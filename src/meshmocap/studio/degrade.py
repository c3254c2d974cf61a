"""Seeded degradations of binary silhouettes, imitating background-subtraction errors.

Each function is pure (the input mask is never modified) and deterministic for a given
``seed`` (an int, a :class:`numpy.random.SeedSequence` or a :class:`numpy.random.Generator`):

* :func:`jitter_boundary` — the outline wanders in and out by a smooth random offset
  (shadows, colour bleeding, compression);
* :func:`punch_holes` — blobs missing inside the body (clothes matching the background);
* :func:`add_blobs` — spurious blobs near the body (shadows, reflections, moving clutter);
* :func:`remove_limb` — a connected chunk of the silhouette gone (a limb against a
  similar background), by default at an extremity of the silhouette (hand, foot, head);
* :func:`degrade` — a combination described by a :class:`Degradation`.

Sizes are in pixels; masks are (height, width) bool arrays. Blobs are ellipses with
random axes between half and all of the given radius and a random orientation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from meshmocap.errors import InputError

#: Largest boundary jitter, pixels: beyond it the silhouette is noise, not a body.
MAX_JITTER = 20.0

#: What ``seed`` arguments accept.
Seed = int | np.random.SeedSequence | np.random.Generator


@dataclass(frozen=True)
class Degradation:
    """A combination of silhouette degradations, applied by :func:`degrade`.

    Parameters
    ----------
    jitter : float
        Standard deviation (pixels) of the boundary offset of :func:`jitter_boundary`;
        0 for none.
    holes : int
        Number of holes punched inside the body (:func:`punch_holes`).
    blobs : int
        Number of spurious blobs added near the body (:func:`add_blobs`).
    missed_limb : bool
        Remove a chunk at an extremity of the silhouette (:func:`remove_limb`).
    hole_radius, blob_radius : float
        Largest semi-axis of holes and blobs, pixels.
    missed_limb_frames : (int, int), optional
        Frame numbers ``[start, stop)`` of the capture in which the limb is missed (default:
        every frame).
    missed_limb_joint : str, optional
        An evaluation joint (e.g. ``"left_elbow"``): the body parts of that joint and the
        joints below it are seen by no camera (their pixels off the rest of the body are
        lost in every view, :func:`meshmocap.studio.synth.write_frame`), so the visual hull
        misses that limb (default: a random extremity cut from each camera's silhouette).
    """

    jitter: float = 0.0
    holes: int = 0
    blobs: int = 0
    missed_limb: bool = False
    hole_radius: float = 4.0
    blob_radius: float = 6.0
    missed_limb_frames: tuple[int, int] | None = None
    missed_limb_joint: str | None = None

    def as_dict(self) -> dict:
        """JSON-ready fields (the missed limb's frames and joint only where set, so
        captures made before they existed keep their parameters)."""
        d = dataclasses.asdict(self)
        for key in ("missed_limb_frames", "missed_limb_joint"):
            if d[key] is None:
                del d[key]
        if "missed_limb_frames" in d:
            d["missed_limb_frames"] = [int(v) for v in d["missed_limb_frames"]]
        return d

    def misses_limb(self, frame: int) -> bool:
        """Whether the missed limb applies to frame number ``frame``."""
        r = self.missed_limb_frames
        return self.missed_limb and (r is None or r[0] <= frame < r[1])

    def __post_init__(self) -> None:
        if not (np.isfinite(self.jitter) and 0 <= self.jitter <= MAX_JITTER):
            raise InputError(
                f"Degradation: jitter must be from 0 to {MAX_JITTER:g} pixels, found {self.jitter}"
            )
        for name in ("holes", "blobs"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or isinstance(v, bool) or not 0 <= v <= 100:
                raise InputError(
                    f"Degradation: {name} must be a whole number from 0 to 100, found {v!r}"
                )
        for name in ("hole_radius", "blob_radius"):
            v = getattr(self, name)
            if not (np.isfinite(v) and 1 <= v <= 100):
                raise InputError(f"Degradation: {name} must be from 1 to 100 pixels, found {v}")
        r = self.missed_limb_frames
        if r is not None:
            ok = len(r) == 2 and all(isinstance(v, int | np.integer) for v in r) and r[0] < r[1]
            if not ok:
                raise InputError(
                    f"Degradation: missed_limb_frames must be (start, stop) frame numbers with "
                    f"start < stop, found {r!r}"
                )
            object.__setattr__(self, "missed_limb_frames", (int(r[0]), int(r[1])))
        if (r is not None or self.missed_limb_joint is not None) and not self.missed_limb:
            raise InputError(
                "Degradation: missed_limb_frames and missed_limb_joint need missed_limb=True"
            )


def degrade(
    mask: np.ndarray, spec: Degradation, *, seed: Seed, frame: int | None = None
) -> np.ndarray:
    """Apply the degradations of ``spec``: missed limb, holes, blobs, then boundary jitter.

    Each step draws from its own stream spawned from ``seed``, so switching one
    degradation on or off does not change the random draws of the others. ``frame`` (the
    frame number) selects whether ``spec.missed_limb_frames`` applies (None: it does); a
    ``missed_limb_joint`` is not cut here (the renderer leaves that limb out).

    Returns
    -------
    mask : (height, width) bool, a new array
    """
    if not isinstance(spec, Degradation):
        raise InputError(f"degrade: spec must be a Degradation, found {type(spec).__name__}")
    out = _check_mask(mask, "degrade").copy()
    streams = _seed_sequence(seed, "degrade").spawn(4)
    missed = spec.missed_limb if frame is None else spec.misses_limb(frame)
    if missed and spec.missed_limb_joint is None:
        out = remove_limb(out, seed=streams[0])
    if spec.holes:
        out = punch_holes(out, count=spec.holes, radius=spec.hole_radius, seed=streams[1])
    if spec.blobs:
        out = add_blobs(out, count=spec.blobs, radius=spec.blob_radius, seed=streams[2])
    if spec.jitter > 0:
        out = jitter_boundary(out, amplitude=spec.jitter, seed=streams[3])
    return out


def jitter_boundary(
    mask: np.ndarray, *, amplitude: float, seed: Seed, correlation: float = 4.0
) -> np.ndarray:
    """Randomly erode and dilate the silhouette along its boundary.

    A smooth Gaussian random field ``n`` (standard deviation ``amplitude`` pixels,
    correlation length ``correlation`` pixels) is added to the signed distance ``d`` to
    the boundary (positive inside, ±0.5 at the pixels next to it), and the new mask is
    ``d + n > 0``: the outline moves outwards where ``n > 0`` and inwards where ``n < 0``.
    About ``perimeter × amplitude × √(2/π)`` pixels change (the mean of ``|n|``).

    Parameters
    ----------
    mask : (height, width) bool
    amplitude : float
        Standard deviation of the boundary offset, pixels.
    seed : int, SeedSequence or Generator
    correlation : float
        Standard deviation of the Gaussian smoothing the white noise, pixels: the length
        over which the offset changes.
    """
    m = _check_mask(mask, "jitter_boundary")
    if not (np.isfinite(amplitude) and amplitude >= 0 and np.isfinite(correlation)):
        raise InputError(f"jitter_boundary: amplitude must be ≥ 0 pixels, found {amplitude}")
    if correlation < 0.5:
        raise InputError(f"jitter_boundary: correlation must be ≥ 0.5 px, found {correlation}")
    rng = np.random.default_rng(_seed_sequence(seed, "jitter_boundary"))
    if amplitude == 0 or not m.any() or m.all():
        return m.copy()
    # Only pixels within 5 σ of the boundary can flip: work in that box.
    reach = int(np.ceil(5 * amplitude)) + 1
    (r0, r1), (c0, c1) = _bbox(m, reach)
    box = m[r0:r1, c0:c1]
    inside = ndimage.distance_transform_edt(box) - 0.5
    outside = ndimage.distance_transform_edt(~box) - 0.5
    d = np.where(box, inside, -outside)
    noise = ndimage.gaussian_filter(rng.standard_normal(box.shape), correlation, mode="wrap")
    noise *= amplitude / _smoothed_noise_std(correlation)
    out = m.copy()
    out[r0:r1, c0:c1] = d + noise > 0
    return out


def punch_holes(mask: np.ndarray, *, count: int, radius: float, seed: Seed) -> np.ndarray:
    """Remove ``count`` elliptical blobs inside the silhouette.

    Centres are drawn uniformly among the pixels at least ``radius + 2`` pixels inside the
    boundary (the deepest pixels if there are none), so that holes leave the outline and
    the pixels next to it intact (the distance to the background is 1-Lipschitz).
    The number of pixels removed is at most ``count × π radius²`` (less where blobs
    overlap each other).
    """
    m = _check_mask(mask, "punch_holes")
    count, radius = _check_blobs("punch_holes", count, radius)
    rng = np.random.default_rng(_seed_sequence(seed, "punch_holes"))
    if count == 0 or not m.any():
        return m.copy()
    (r0, r1), (c0, c1) = _bbox(m, 0)
    depth = ndimage.distance_transform_edt(np.pad(m[r0:r1, c0:c1], 1))[1:-1, 1:-1]
    iy, ix = np.nonzero(depth >= min(radius + 2, depth.max()))
    pick = rng.choice(iy.size, size=count)
    return m & ~_ellipses(m.shape, (iy[pick] + r0, ix[pick] + c0), radius, rng)


def add_blobs(
    mask: np.ndarray, *, count: int, radius: float, seed: Seed, distance: float | None = None
) -> np.ndarray:
    """Add ``count`` spurious elliptical blobs near the silhouette.

    Centres are drawn uniformly among the background pixels whose distance to the
    silhouette is between ``1.5 radius`` (so blobs are usually separate pieces) and
    ``distance`` (default: a quarter of the silhouette's bounding-box diagonal).
    """
    m = _check_mask(mask, "add_blobs")
    count, radius = _check_blobs("add_blobs", count, radius)
    rng = np.random.default_rng(_seed_sequence(seed, "add_blobs"))
    if count == 0 or not m.any():
        return m.copy()
    if distance is None:
        (r0, r1), (c0, c1) = _bbox(m, 0)
        distance = 0.25 * float(np.hypot(r1 - r0, c1 - c0))
    if not (np.isfinite(distance) and distance > 0):
        raise InputError(f"add_blobs: distance must be positive pixels, found {distance}")
    far = max(distance, 1.5 * radius)
    (r0, r1), (c0, c1) = _bbox(m, int(np.ceil(far)) + 1)
    away = ndimage.distance_transform_edt(~m[r0:r1, c0:c1])
    iy, ix = np.nonzero((away >= 1.5 * radius) & (away <= far))
    if iy.size == 0:  # the silhouette fills the image: anywhere outside
        (iy, ix), r0, c0 = np.nonzero(~m), 0, 0
        if iy.size == 0:
            return m.copy()
    pick = rng.choice(iy.size, size=count)
    return m | _ellipses(m.shape, (iy[pick] + r0, ix[pick] + c0), radius, rng)


def remove_limb(
    mask: np.ndarray,
    *,
    seed: Seed,
    point: tuple[float, float] | None = None,
    radius: float | None = None,
) -> np.ndarray:
    """Remove a connected chunk of the silhouette, as when a limb is missed.

    The chunk is the connected part, containing the silhouette pixel nearest ``point``,
    of the silhouette within ``radius`` pixels of that pixel. Without ``point`` it is an
    extremity (a hand, a foot, the head): the silhouette pixel reaching farthest in a
    random direction from the silhouette's centroid. The rest of the silhouette is
    unchanged.

    Parameters
    ----------
    mask : (height, width) bool
    seed : int, SeedSequence or Generator
        Draws the direction when ``point`` is None.
    point : (column, row), optional
        Image point, pixels (u, v).
    radius : float, optional
        Pixels; default 15 % of the silhouette's bounding-box height (about a forearm
        and hand, or a lower leg, of a standing person).
    """
    m = _check_mask(mask, "remove_limb")
    rng = np.random.default_rng(_seed_sequence(seed, "remove_limb"))
    if not m.any():
        return m.copy()
    rows, cols = np.nonzero(m)
    if radius is None:
        radius = 0.15 * (rows.max() - rows.min() + 1)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"remove_limb: radius must be positive pixels, found {radius}")
    if point is None:
        angle = rng.uniform(0.0, 2 * np.pi)
        reach = (cols - cols.mean()) * np.cos(angle) + (rows - rows.mean()) * np.sin(angle)
        k = int(np.argmax(reach))
    else:
        p = np.asarray(point, dtype=float)
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise InputError(f"remove_limb: point must be (column, row) pixels, found {point!r}")
        k = int(np.argmin((cols - p[0]) ** 2 + (rows - p[1]) ** 2))
    r, c = rows[k], cols[k]
    near = (rows - r) ** 2 + (cols - c) ** 2 <= radius**2
    chunk = np.zeros_like(m)
    chunk[rows[near], cols[near]] = True
    labels, _ = ndimage.label(chunk, structure=np.ones((3, 3), dtype=bool))
    out = m.copy()
    out[labels == labels[r, c]] = False
    return out


# ----------------------------------------------------------------------------- helpers
def _ellipses(shape, centres, radius: float, rng: np.random.Generator) -> np.ndarray:
    """Union of ellipses (semi-axes in [radius/2, radius], random angle) at ``centres``."""
    n = len(centres[0])
    axes = rng.uniform(0.5 * radius, radius, size=(n, 2))
    angle = rng.uniform(0.0, np.pi, size=n)
    R = int(np.ceil(radius))
    dy, dx = np.mgrid[-R : R + 1, -R : R + 1].astype(float)  # (2R+1)² offsets per blob
    cos, sin = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    u = (cos * dx + sin * dy) / axes[:, 0, None, None]
    v = (-sin * dx + cos * dy) / axes[:, 1, None, None]
    inside = u * u + v * v <= 1.0
    k, iy, ix = np.nonzero(inside)
    y = centres[0][k] + iy - R
    x = centres[1][k] + ix - R
    ok = (y >= 0) & (y < shape[0]) & (x >= 0) & (x < shape[1])
    out = np.zeros(shape, dtype=bool)
    out[y[ok], x[ok]] = True
    return out


def _smoothed_noise_std(sigma: float) -> float:
    """Standard deviation of unit white noise after ``gaussian_filter(·, sigma)`` (exact)."""
    delta = np.zeros((2 * int(np.ceil(4 * sigma)) + 1,) * 2)
    delta[delta.shape[0] // 2, delta.shape[1] // 2] = 1.0
    return float(np.sqrt((ndimage.gaussian_filter(delta, sigma, mode="constant") ** 2).sum()))


def _bbox(m: np.ndarray, pad: int) -> tuple[tuple[int, int], tuple[int, int]]:
    rows = np.flatnonzero(m.any(axis=1))
    cols = np.flatnonzero(m.any(axis=0))
    H, W = m.shape
    return (
        (max(rows[0] - pad, 0), min(rows[-1] + pad + 1, H)),
        (max(cols[0] - pad, 0), min(cols[-1] + pad + 1, W)),
    )


def _check_mask(mask, func: str) -> np.ndarray:
    m = np.asarray(mask)
    if m.ndim != 2 or m.dtype != bool:
        raise InputError(
            f"{func}: mask must be a (height, width) bool array, found shape {m.shape} "
            f"of dtype {m.dtype}"
        )
    return m


def _check_blobs(func: str, count, radius) -> tuple[int, float]:
    if not isinstance(count, int | np.integer) or isinstance(count, bool) or count < 0:
        raise InputError(f"{func}: count must be a whole number ≥ 0, found {count!r}")
    if not (np.isfinite(radius) and radius >= 1):
        raise InputError(f"{func}: radius must be ≥ 1 pixel, found {radius}")
    return int(count), float(radius)


def _seed_sequence(seed, func: str) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, np.random.Generator):  # draws from (advances) the generator
        return np.random.SeedSequence(int(seed.integers(2**63)))
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed >= 0:
        return np.random.SeedSequence(int(seed))
    raise InputError(f"{func}: seed must be an int ≥ 0, SeedSequence or Generator, found {seed!r}")
