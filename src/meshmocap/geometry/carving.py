"""Visual hulls by voxel carving of calibrated silhouettes, and signed-distance grids.

A voxel belongs to the visual hull when its centre projects, in front of every camera,
onto a silhouette pixel of every view: the pixel whose centre is nearest to the pinhole
projection ``K (R X + t)`` (to :meth:`Camera.project`, distortion included, for cameras
with distortion). A point projecting outside an image is outside the hull: the studio sees
everything.

Carving is coarse to fine. Blocks of 2^L × 2^L × 2^L voxels are tested camera by camera
against the integral image of each mask: the block's voxel centres project inside the
convex polygon of its 8 projected corners, hence inside the pixel rectangle around them;
no silhouette pixel in that rectangle rejects the whole block, all of them accepts it for
that camera. Only blocks that no camera rejects and not all cameras accept are split in 8,
and at the finest level only the voxel centres of undecided blocks are projected. The work
is proportional to the hull's surface, not its volume, and the result is the same as
projecting every voxel centre (for distorted cameras the rectangle gets a 2-pixel slack,
which covers the bending of block edges by any ordinary lens).

:func:`distance_grid` turns a hull into the :class:`DistanceGrid` a tracker minimises
(cage-manifold-tracking §5.1); :class:`DistanceGrid` and :func:`distance_grid_from_mesh`
live in :mod:`meshmocap.geometry.distance_field` and are re-exported here.

Frames: world, metres, Z up. Voxel ``(i, j, k)`` has its centre at
``origin + (i, j, k) * voxel_size``.

References
----------
- A. Laurentini, *The visual hull concept for silhouette-based image
  understanding*, IEEE Transactions on Pattern Analysis and Machine Intelligence
  16(2):150–162, 1994. https://doi.org/10.1109/34.273735
- R. Szeliski, *Rapid octree construction from image sequences*, CVGIP: Image
  Understanding 58(1):23–32, 1993.
- F. C. Crow, *Summed-area tables for texture mapping*, SIGGRAPH 1984 (Computer
  Graphics 18(3):207–212).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from meshmocap._tolerances import ROUNDING_SLACK, ZERO_EXTENT
from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.distance_field import DistanceGrid, distance_grid_from_mesh, signed_distance

__all__ = [
    "DistanceGrid",
    "VoxelHull",
    "carve",
    "distance_grid",
    "distance_grid_from_mesh",
    "hull_bounds",
    "hull_mesh",
]

_MAX_VOXELS = 1 << 27  # refuse grids above ~134 M voxels (memory), asking for bounds
_SLACK_PX = 1e-3  # pixel slack of the block tests (rounding of the projections)
_DISTORTED_SLACK_PX = 2.0  # extra slack where the lens bends straight block edges
_CORNERS = np.array([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)], dtype=bool)
_OCTANTS = _CORNERS.astype(np.int64)  # child offsets of a block split in 8
_MIN_BLOCK = 2  # finest carving blocks (voxels wide, ≥ 2) before testing voxel centres
_MAX_LEVEL = 4  # coarsest carving blocks: 2**4 = 16 voxels wide

# ---------------------------------------------------------------------------------------
# Views: a camera, its silhouette and the silhouette's integral image


class _View:
    """A silhouette prepared for carving (mask, summed-area table, pixel slack)."""

    __slots__ = ("H", "P", "W", "box", "camera", "mask", "slack", "table")

    def __init__(self, mask: np.ndarray, camera: Camera) -> None:
        self.camera = camera
        self.mask = mask
        self.H, self.W = mask.shape
        rows = np.flatnonzero(mask.any(axis=1))
        cols = np.flatnonzero(mask.any(axis=0))
        self.box = (rows[0], rows[-1] + 1, cols[0], cols[-1] + 1)  # the mask's bounding box
        crop = mask[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
        table = np.zeros((crop.shape[0] + 1, crop.shape[1] + 1), dtype=np.int32)
        np.cumsum(np.cumsum(crop, axis=0, dtype=np.int32), axis=1, out=table[1:, 1:])
        self.table = table  # summed-area table of the bounding box
        self.P = camera.K @ np.column_stack([camera.R, camera.t])  # (3, 4) projection
        self.slack = _SLACK_PX + (_DISTORTED_SLACK_PX if np.any(camera.dist) else 0.0)

    def point_in(self, X: np.ndarray) -> np.ndarray:
        """(m,) bool: points ``X`` (3, m) project in front of the camera onto the silhouette."""
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            if np.any(self.camera.dist):
                uv, depth = self.camera.project(X.T)
                u, v = uv[:, 0], uv[:, 1]
            else:
                uvw = self.P[:, :3] @ X + self.P[:, 3:]
                depth = uvw[2]
                u, v = uvw[0] / depth, uvw[1] / depth
            c = np.floor(u + 0.5)
            r = np.floor(v + 0.5)
            ok = (depth > 0) & (c >= 0) & (c < self.W) & (r >= 0) & (r < self.H)
        ok[ok] = self.mask.ravel()[(r[ok] * self.W + c[ok]).astype(np.intp)]
        return ok

    def boxes(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Classify the boxes ``[lo, hi]`` (3, m) against this silhouette.

        Returns ``(out, full)`` (m,) bool: no point of the box projects onto the
        silhouette; every point of the box does.
        """
        m = lo.shape[1]
        P = self.P[:, :, None, None]  # homogeneous pixels of the 8 corners, separably
        xy = (P[:, 0] * np.stack([lo[0], hi[0]]))[:, :, None] + (
            P[:, 1] * np.stack([lo[1], hi[1]])
        )[:, None]
        z = P[:, 2] * np.stack([lo[2], hi[2]]) + P[:, 3]
        uvw = np.empty((3, 2, 2, 2, m))  # in place from here: temporaries cost more than maths
        np.add(xy[:, :, :, None], z[:, None, None], out=uvw)
        uvw = uvw.reshape(3, 8, m)
        depth = uvw[2]  # K's last row is (0, 0, 1)
        front = depth.min(axis=0) > 0
        behind = depth.max(axis=0) <= 0
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            if np.any(self.camera.dist):
                corners = np.where(_CORNERS[:, :, None], hi[None], lo[None]).transpose(0, 2, 1)
                uv = self.camera.project(corners)[0]
                u, v = uv[..., 0], uv[..., 1]
            else:  # only blocks wholly in front of the camera use u, v
                np.divide(uvw[:2], np.maximum(depth, ZERO_EXTENT, out=depth), out=uvw[:2])
                u, v = uvw[0], uvw[1]
            s, W, H = self.slack, self.W, self.H
            # Pixel index ranges that the box can reach (nearest pixel centre).
            c0 = np.floor(np.clip(u.min(axis=0), -2.0, W + 1.0) + (0.5 - s))
            c1 = np.floor(np.clip(u.max(axis=0), -2.0, W + 1.0) + (0.5 + s))
            r0 = np.floor(np.clip(v.min(axis=0), -2.0, H + 1.0) + (0.5 - s))
            r1 = np.floor(np.clip(v.max(axis=0), -2.0, H + 1.0) + (0.5 + s))
        # Count the silhouette pixels of the rectangle inside the mask's bounding box.
        top, bottom, left, right = self.box
        in_box = (c0 >= left) & (c1 < right) & (r0 >= top) & (r1 < bottom)
        a0 = (np.clip(c0, left, right) - left).astype(np.intp)
        a1 = (np.clip(c1 + 1, left, right) - left).astype(np.intp)
        b0 = (np.clip(r0, top, bottom) - top).astype(np.intp)
        b1 = (np.clip(r1 + 1, top, bottom) - top).astype(np.intp)
        empty = (a1 <= a0) | (b1 <= b0)
        a1, b1 = np.maximum(a1, a0), np.maximum(b1, b0)
        T = self.table
        count = T[b1, a1] - T[b0, a1] - T[b1, a0] + T[b0, a0]
        out = behind | (front & (empty | (count == 0)))
        full = front & in_box & (count == (a1 - a0) * (b1 - b0))
        return out, full


def _views(masks, cameras) -> list[_View]:
    """Validate masks and cameras once; return the prepared views."""
    cameras = list(cameras) if not isinstance(cameras, Camera) else [cameras]
    masks = [masks] if isinstance(masks, np.ndarray) and masks.ndim == 2 else list(masks)
    if not cameras:
        raise InputError("cameras: expected at least one Camera, found none")
    if len(masks) != len(cameras):
        raise InputError(
            f"masks: expected one per camera ({len(cameras)}), found {len(masks)} masks"
        )
    views = []
    for i, (m, cam) in enumerate(zip(masks, cameras, strict=True)):
        if not isinstance(cam, Camera):
            raise InputError(f"cameras[{i}]: expected a Camera, found {type(cam).__name__}")
        m = np.asarray(m)
        m = m if m.dtype == bool else m != 0
        who = f"masks[{i}] (camera {cam.name or i!r})"
        if m.shape != cam.shape:
            raise InputError(
                f"{who}: expected the camera's image shape (height, width) = {cam.shape},"
                f" found {m.shape}"
            )
        if not m.any():
            raise InputError(f"{who} is empty: no silhouette pixel")
        views.append(_View(np.ascontiguousarray(m), cam))
    return views


def _classify(views: list[_View], lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """State of boxes ``[lo, hi]`` (3, m): 0 outside the hull, 1 inside, 2 undecided.

    Camera by camera, on the boxes no previous camera rejected.
    """
    alive = np.arange(lo.shape[1])
    full = np.ones(lo.shape[1], dtype=bool)
    for view in views:
        out, f = view.boxes(lo[:, alive], hi[:, alive])
        full[alive] &= f
        alive = alive[~out]
        if alive.size == 0:
            break
    state = np.zeros(lo.shape[1], dtype=np.int8)
    state[alive] = np.where(full[alive], 1, 2)
    return state


def _points_in(views: list[_View], X: np.ndarray) -> np.ndarray:
    """(m,) bool: points ``X`` (3, m) inside every silhouette (early rejection)."""
    alive = np.arange(X.shape[1])
    for view in views:
        alive = alive[view.point_in(X[:, alive])]
        if alive.size == 0:
            break
    inside = np.zeros(X.shape[1], dtype=bool)
    inside[alive] = True
    return inside


# ---------------------------------------------------------------------------------------
# Bounds


def _undistort(view: _View, uv: np.ndarray) -> np.ndarray:
    """Normalised image coordinates (k, 2) of pixels ``uv`` (k, 2) (fixed-point inverse)."""
    K = view.camera.K
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    if not np.any(view.camera.dist):
        return np.stack([x, y], axis=1)
    k1, k2, p1, p2, k3 = view.camera.dist
    xd, yd = x, y
    for _ in range(30):
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x, y = (xd - dx) / radial, (yd - dy) / radial
    return np.stack([x, y], axis=1)


def _cone_box(view: _View, max_depth: float) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box of the cone of the mask's bounding rectangle, depth ≤ max_depth."""
    top, bottom, left, right = view.box
    pad = 0.5 + view.slack
    u0, u1 = left - pad, right - 1 + pad
    v0, v1 = top - pad, bottom - 1 + pad
    s = np.linspace(0.0, 1.0, 17)
    ring = np.concatenate(
        [
            np.stack([u0 + (u1 - u0) * s, np.full_like(s, v0)], axis=1),
            np.stack([u0 + (u1 - u0) * s, np.full_like(s, v1)], axis=1),
            np.stack([np.full_like(s, u0), v0 + (v1 - v0) * s], axis=1),
            np.stack([np.full_like(s, u1), v0 + (v1 - v0) * s], axis=1),
        ]
    )
    xy = _undistort(view, ring)
    if np.any(view.camera.dist):  # cover the boundary between samples generously
        centre = xy.mean(axis=0)
        xy = centre + 1.05 * (xy - centre)
    cam = view.camera
    far = max_depth * np.column_stack([xy, np.ones(len(xy))])  # camera frame
    P = np.vstack([(far - cam.t) @ cam.R, cam.centre])  # X = Rᵀ (X_cam − t)
    return P.min(axis=0), P.max(axis=0)


def _bounds(views, floor, margin, max_depth, resolution) -> np.ndarray:
    lo = np.full(3, -np.inf)
    hi = np.full(3, np.inf)
    for view in views:
        a, b = _cone_box(view, max_depth)
        lo, hi = np.maximum(lo, a), np.minimum(hi, b)
    if floor is not None:
        lo[2] = max(lo[2], floor)
    no_hull = "the silhouettes' viewing cones do not meet (no point projects into all masks)"
    if np.any(lo > hi):
        raise InputError(f"masks: {no_hull}")
    edge = max(float((hi - lo).max()) / 16, ZERO_EXTENT)
    nb = np.maximum(np.ceil((hi - lo) / edge), 1).astype(np.int64)
    blocks = np.indices(nb).reshape(3, -1).T
    found_lo, found_hi = np.full(3, np.inf), np.full(3, -np.inf)
    for level in range(16):
        blo = lo + blocks * edge
        bhi = np.minimum(blo + edge, hi)
        state = _classify(views, blo.T, bhi.T)
        # Points known to be in the hull: accepted blocks and undecided blocks' centres.
        mid = 0.5 * (blo + bhi)[state == 2]
        mid = mid[_points_in(views, mid.T)]
        found_lo = np.vstack([found_lo, blo[state == 1], mid]).min(axis=0)
        found_hi = np.vstack([found_hi, bhi[state == 1], mid]).max(axis=0)
        # Undecided blocks inside the box of the known points cannot change the answer.
        sticks_out = np.any(blo < found_lo, axis=1) | np.any(bhi > found_hi, axis=1)
        blocks = blocks[(state == 2) & sticks_out]
        if edge <= resolution or level == 15 or blocks.size == 0:
            break
        blocks = (2 * blocks[:, None, :] + _OCTANTS).reshape(-1, 3)
        edge /= 2
        blocks = blocks[np.all(lo + blocks * edge < hi, axis=1)]
    if blocks.size:
        found_lo = np.minimum(found_lo, (lo + blocks * edge).min(axis=0))
        found_hi = np.maximum(found_hi, np.minimum(lo + (blocks + 1) * edge, hi).max(axis=0))
    if np.any(found_lo > found_hi):
        raise InputError(f"masks: {no_hull}")
    found_lo -= margin
    found_hi += margin
    if floor is not None:
        found_lo[2] = max(found_lo[2], floor)
    return np.stack([found_lo, found_hi])


def hull_bounds(
    masks,
    cameras,
    *,
    floor: float | None = 0.0,
    margin: float = 0.02,
    max_depth: float = 20.0,
    resolution: float = 0.02,
) -> np.ndarray:
    """Return a tight axis-aligned box around the visual hull of the silhouettes.

    Starts from the intersection of the boxes of each mask's viewing cone (the pyramid of
    the mask's bounding rectangle, out to ``max_depth``), then keeps the blocks that no
    camera rejects, splitting them until they are ``resolution`` wide. The box is
    conservative: every point of space that projects into every silhouette lies inside.

    Parameters
    ----------
    masks : sequence of (height, width) bool arrays, one per camera
        Silhouettes (True = foreground).
    cameras : sequence of Camera
        Calibrated cameras, ``masks[i]`` seen by ``cameras[i]``.
    floor : float or None
        Height of the floor, metres: nothing lies below it. None for no floor.
    margin : float
        Added around the hull on every side (not below the floor), metres.
    max_depth : float
        Farthest distance along a camera's axis where the subject may be, metres; it only
        matters where fewer than two cameras bound the cones.
    resolution : float
        Size of the finest blocks tested, metres (the box is at most this much too large
        on each side before the margin).

    Returns
    -------
    bounds : (2, 3) float64
        ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, metres, world frame (Z up).

    Raises
    ------
    InputError
        Mismatched counts or shapes, an empty mask, or silhouettes whose cones do not meet.
    """
    views = _views(masks, cameras)
    for name, value in (("margin", margin), ("max_depth", max_depth), ("resolution", resolution)):
        if not np.isfinite(value) or value < 0 or (name != "margin" and value == 0):
            raise InputError(f"{name}: expected a positive number of metres, found {value!r}")
    return _bounds(views, floor, float(margin), float(max_depth), float(resolution))


# ---------------------------------------------------------------------------------------
# Carving


@dataclass(frozen=True, eq=False)
class VoxelHull:
    """A visual hull as a voxel occupancy grid.

    Parameters
    ----------
    occupancy : (nx, ny, nz) bool
        True where the voxel centre is inside the hull.
    origin : (3,) float64
        Centre of voxel ``(0, 0, 0)``, metres, world frame (Z up).
    voxel_size : float
        Edge of a voxel, metres.
    """

    occupancy: np.ndarray
    origin: np.ndarray
    voxel_size: float
    _fields: dict = field(default_factory=dict, init=False, repr=False)  # distance grids

    def __post_init__(self) -> None:
        occ = np.array(self.occupancy, dtype=bool)  # own copy, made read-only
        origin = np.array(self.origin, dtype=np.float64).reshape(-1)
        if occ.ndim != 3 or origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise InputError(
                f"VoxelHull: expected a 3-D occupancy and a (3,) origin, found {occ.shape}"
                f" and {origin.shape}"
            )
        if not np.isfinite(self.voxel_size) or self.voxel_size <= 0:
            raise InputError(f"voxel_size: expected positive metres, found {self.voxel_size!r}")
        for k, v in (("occupancy", occ), ("origin", origin)):
            v.setflags(write=False)
            object.__setattr__(self, k, v)
        object.__setattr__(self, "voxel_size", float(self.voxel_size))

    @property
    def volume(self) -> float:
        """Occupied volume, m³ (voxel count × voxel volume)."""
        return float(np.count_nonzero(self.occupancy)) * self.voxel_size**3

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: centres of the first and last voxels, metres."""
        n = np.array(self.occupancy.shape)
        return np.stack([self.origin, self.origin + (n - 1) * self.voxel_size])

    def centres(self) -> np.ndarray:
        """(k, 3) float64: centres of the occupied voxels, metres, world frame."""
        return self.origin + np.argwhere(self.occupancy) * self.voxel_size


def _block_offsets(size: int) -> np.ndarray:
    """(3, size³) int64: voxel offsets inside a block ``size`` voxels wide."""
    return np.indices((size, size, size)).reshape(3, -1)


def carve(
    masks,
    cameras,
    *,
    voxel_size: float = 0.01,
    bounds: np.ndarray | None = None,
    floor: float | None = 0.0,
) -> VoxelHull:
    """Carve the visual hull of calibrated silhouettes into a voxel grid.

    Parameters
    ----------
    masks : sequence of (height, width) bool arrays, one per camera
        Silhouettes (True = foreground); ``masks[i].shape == cameras[i].shape``.
    cameras : sequence of Camera
        One or more calibrated cameras.
    voxel_size : float
        Voxel edge, metres.
    bounds : (2, 3) float64, optional
        ``[lower, upper]`` corners of the volume to carve, metres, world frame. Voxel
        ``(0, 0, 0)`` is centred on ``lower``. By default :func:`hull_bounds` with
        ``margin = 2 * voxel_size`` (give bounds with a single camera: its cone is long).
    floor : float or None
        Floor height used by the default bounds, metres.

    Returns
    -------
    VoxelHull
        Occupancy of every voxel centre: inside every silhouette, in front of every camera.
    """
    views = _views(masks, cameras)
    vs = float(voxel_size)
    if not np.isfinite(vs) or vs <= 0:
        raise InputError(f"voxel_size: expected a positive number of metres, found {voxel_size!r}")
    if bounds is None:
        bounds = _bounds(views, floor, 2 * vs, 20.0, max(2 * vs, 0.02))
    try:
        bounds = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        bounds = np.full(1, np.nan)
    if bounds.shape != (2, 3) or not np.all(np.isfinite(bounds)) or np.any(bounds[0] > bounds[1]):
        raise InputError(f"bounds: expected finite [lower, upper] (2, 3) metres, found {bounds!r}")
    origin = bounds[0]
    n = np.floor((bounds[1] - bounds[0]) / vs + ROUNDING_SLACK).astype(np.int64) + 1
    if np.prod(n) > _MAX_VOXELS:
        raise InputError(
            f"bounds: {n[0]}×{n[1]}×{n[2]} voxels of {vs} m is too many (max {_MAX_VOXELS});"
            " give tighter bounds or a larger voxel_size"
        )
    levels = int(np.clip(np.floor(np.log2(n.max() / 4)), 0, _MAX_LEVEL))
    nb = -(-n // 2**levels)
    n_pad = nb * 2**levels  # carve whole blocks, crop at the end
    o = origin[:, None]
    occ = np.zeros(n_pad, dtype=bool)
    blocks = np.indices(nb).reshape(3, -1)  # (3, m) block indices, structure of arrays
    size = 2**levels
    while size >= _MIN_BLOCK:
        lo = o + blocks * (size * vs)
        state = _classify(views, lo, lo + (size - 1) * vs)
        bi, bj, bk = blocks[:, state == 1]  # accepted: fill whole blocks through a view
        occ.reshape(n_pad[0] // size, size, n_pad[1] // size, size, -1, size)[
            bi, :, bj, :, bk, :
        ] = True
        blocks = blocks[:, state == 2]
        if size // 2 < _MIN_BLOCK:
            break
        blocks = (2 * blocks[:, :, None] + _OCTANTS.T[:, None, :]).reshape(3, -1)
        size //= 2
    if size > 1:  # voxels of the undecided blocks
        blocks = (size * blocks[:, :, None] + _block_offsets(size)[:, None, :]).reshape(3, -1)
    occ[tuple(blocks[:, _points_in(views, o + blocks * vs)])] = True
    occ = np.ascontiguousarray(occ[: n[0], : n[1], : n[2]])
    return VoxelHull(occ, origin, vs)


# ---------------------------------------------------------------------------------------
# Surfaces and distances


def hull_mesh(hull: VoxelHull) -> tuple[np.ndarray, np.ndarray]:
    """Return the closed surface of a hull by marching cubes (scikit-image, Lewiner).

    The occupancy is padded with a layer of empty voxels, so the surface is closed even
    where the hull touches the grid's border (e.g. cut by the floor); the iso-level 0.5
    puts vertices halfway between inside and outside voxel centres.

    Returns
    -------
    V : (n, 3) float64
        Vertices, metres, world frame (Z up).
    F : (m, 3) int64
        Triangles, counter-clockwise seen from outside (positive signed volume). Both are
        empty for an empty hull.
    """
    from skimage.measure import marching_cubes

    occ = hull.occupancy
    if not occ.any():
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    idx = np.argwhere(occ)
    a, b = idx.min(axis=0), idx.max(axis=0) + 1
    crop = np.pad(occ[a[0] : b[0], a[1] : b[1], a[2] : b[2]], 1).astype(np.float32)
    verts, faces, _, _ = marching_cubes(crop, 0.5, allow_degenerate=False)
    V = hull.origin + (verts.astype(np.float64) + (a - 1)) * hull.voxel_size
    return V, np.ascontiguousarray(faces[:, ::-1], dtype=np.int64)


def distance_grid(hull: VoxelHull, *, pad: float = 0.0) -> DistanceGrid:
    """Return the signed distance field of a hull, metres, negative inside.

    Parameters
    ----------
    hull : VoxelHull
        A non-empty hull.
    pad : float
        Extra empty space added around the hull's grid, metres (at least one voxel is
        always added, so the field's zero level matches :func:`hull_mesh`).

    Returns
    -------
    DistanceGrid
        Computed once per hull and padding, then kept on the hull: a tracker and the
        studio asking for the same field share it. On the hull's voxel centres (plus the
        padding). Outside voxels hold their exact
        Euclidean distance to the nearest occupied voxel minus half a voxel; inside ones
        minus the distance to the nearest empty voxel plus half a voxel, to within one
        voxel (see :func:`~meshmocap.geometry.distance_field.signed_distance`).
    """
    if not hull.occupancy.any():
        raise InputError("hull: the hull is empty; there is no surface to measure from")
    if not np.isfinite(pad) or pad < 0:
        raise InputError(f"pad: expected a non-negative number of metres, found {pad!r}")
    k = 1 + int(np.ceil(pad / hull.voxel_size - ROUNDING_SLACK))
    if k not in hull._fields:
        values = signed_distance(np.pad(hull.occupancy, k), hull.voxel_size)
        hull._fields[k] = DistanceGrid(values, hull.origin - k * hull.voxel_size, hull.voxel_size)
    return hull._fields[k]
