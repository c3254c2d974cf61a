"""Binary silhouettes of triangle meshes: a fast coverage-only scanline rasteriser.

No depth is needed for a silhouette, so every triangle is filled independently. Each
triangle is cut into the pixel rows whose centres it spans; on each row the span of
covered pixel centres is the intersection of the three edges' half-planes, which on a
horizontal line are one-sided bounds on ``x``::

    x ≥ x_i + (y − y_i) · dx_i / dy_i   or   x ≤ ...   (which one: the sign of dy_i · area)

so a span costs four multiply-adds whatever its length. Spans are written into a row-wise
difference image (+1 at the first pixel, −1 after the last) with two ``np.bincount`` calls
and integrated by a cumulative sum along rows. Work is proportional to the number of
(triangle, row) pairs plus the image size: about 10–20 ms for a 28k-face body at 640×480.

The rule is the same as :func:`meshmocap.geometry.raster.coverage` (a pixel whose centre
lies inside a triangle or on its boundary is set), and the two agree exactly up to pixel
centres within rounding error (~1e-12 px) of an edge. Pixel centres are at integer
coordinates ``(u, v) = (column, row)``, as in :mod:`meshmocap.geometry.camera`.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

from meshmocap._tolerances import DIVISOR_FLOOR
from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera

#: Triangles :func:`fill_triangles` fills: all, or those of positive signed area.
Orientation = Literal["any", "positive"]
#: :func:`covered_pixels` cuts only its pixels' rows up to this many distinct rows, and
#: fills the whole image beyond (as fast for a 12k-vertex body's ~250 rows at 640×480).
_FEW_ROWS = 100


def silhouette(
    V: np.ndarray, F: np.ndarray, camera: Camera, *, assume_closed: bool = False
) -> np.ndarray:
    """Rasterise the silhouette of a posed mesh seen by ``camera``.

    Parameters
    ----------
    V : (n, 3) float
        Vertices, metres, world frame (Z up).
    F : (m, 3) int
        Triangles (indices into ``V``). Any triangle soup is accepted.
    camera : Camera
        Calibrated camera; the mask has its image size.
    assume_closed : bool, keyword-only
        Promise that ``F`` is closed (watertight) and consistently oriented, or a union of
        such pieces (they may overlap). Then only the triangles with a positive signed
        area in the image are filled: for a closed mesh the union of its front-facing
        triangles, and also that of its back-facing ones, is the whole silhouette,
        whichever way the faces are oriented. About 1.5–2× faster; wrong (holes) for open
        meshes, meshes crossing the camera plane and image regions folded by distortion.

    Returns
    -------
    mask : (height, width) bool
        True where the centre of a pixel is covered by a projected triangle.

    Notes
    -----
    * Distortion: vertices are projected with the camera's distortion model
      (:meth:`Camera.project`), and triangles are filled as straight-edged triangles
      between the distorted vertices. The error is the deviation of a distorted edge from
      its chord, about ``L² |d²u/du²| / 8`` for an edge of ``L`` pixels: 0.02 px for a
      10 px edge in the corner of a 640×480 image with ``f`` = 500 px and ``k1`` = −0.2.
    * Triangles with a vertex at depth ≤ 0 (on or behind the camera plane) are skipped, as
      in :func:`meshmocap.geometry.raster.rasterize`; meshes should lie in front of the
      camera.
    * Parts of the mesh outside the image are clipped.
    """
    V = np.asarray(V)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or not np.issubdtype(V.dtype, np.number):
        raise InputError(f"silhouette: V must be an (n, 3) float array, found shape {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or not np.issubdtype(F.dtype, np.integer):
        raise InputError(
            f"silhouette: F must be an (m, 3) integer array, found shape {F.shape} "
            f"of dtype {F.dtype}"
        )
    if not np.all(np.isfinite(V)):
        raise InputError("silhouette: V must be finite, found NaN or infinite coordinates")
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise InputError(
            f"silhouette: F must index V (0..{len(V) - 1}), found indices {F.min()}..{F.max()}"
        )
    if not isinstance(camera, Camera):
        raise InputError(f"silhouette: camera must be a Camera, found {type(camera).__name__}")
    with np.errstate(over="ignore", invalid="ignore"):  # handled: non-finite uv are skipped
        uv, depth = camera.project(V)
    return fill_triangles(
        uv, F, camera.shape, valid=depth > 0, orientation="positive" if assume_closed else "any"
    )


def fill_triangles(
    uv: np.ndarray,
    F: np.ndarray,
    shape: tuple[int, int],
    *,
    valid: np.ndarray | None = None,
    orientation: Orientation = "any",
) -> np.ndarray:
    """Return the (height, width) bool mask of pixel centres covered by 2D triangles.

    Parameters
    ----------
    uv : (n, 2) float
        Vertex positions, pixels (column, row), pixel centres at integers. Triangles with a
        non-finite vertex are skipped.
    F : (m, 3) int
        Triangles, trusted to index ``uv``.
    shape : (height, width)
        Image size, pixels.
    valid : (n,) bool, optional
        Vertices that may be used; triangles with an invalid vertex are skipped.
    orientation : {"any", "positive"}
        ``"positive"``: fill only the triangles with a positive signed area
        ``(b − a) × (c − a) > 0`` in (u, v) (see ``assume_closed`` of :func:`silhouette`).

    Returns
    -------
    mask : (height, width) bool
    """
    if orientation not in get_args(Orientation):
        raise InputError(
            f"fill_triangles: orientation must be one of {list(get_args(Orientation))}, "
            f"found {orientation!r}"
        )
    from meshmocap.geometry._mesh_kernels import fill_kernel

    H, W = int(shape[0]), int(shape[1])
    mask = np.zeros((H, W), dtype=bool)
    uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    valid = np.ones(len(uv), dtype=bool) if valid is None else valid
    valid = np.ascontiguousarray(valid, dtype=bool)
    # a triangle at a time, compiled: the spans _prepare, _edge_bounds and _spans cut
    fill_kernel(uv, F, valid, orientation == "positive", DIVISOR_FLOOR, mask)
    return mask


def covered_pixels(
    uv: np.ndarray,
    F: np.ndarray,
    pixels: np.ndarray,
    shape: tuple[int, int],
    *,
    valid: np.ndarray | None = None,
    orientation: Orientation = "any",
) -> np.ndarray:
    """Which of ``pixels`` :func:`fill_triangles` would set, without filling the image:
    only the rows holding a pixel are cut into spans (the same arithmetic, so the same
    answer). For a few pixels of a large mesh's image, a fraction of the work.

    Parameters
    ----------
    uv, F, shape, valid, orientation : as for :func:`fill_triangles`
    pixels : (p, 2) int
        Pixels (column, row), inside the image.

    Returns
    -------
    (p,) bool
    """
    if orientation not in get_args(Orientation):
        raise InputError(
            f"covered_pixels: orientation must be one of {list(get_args(Orientation))}, "
            f"found {orientation!r}"
        )
    pixels = np.asarray(pixels, dtype=np.int64).reshape(-1, 2)
    out = np.zeros(len(pixels), dtype=bool)
    H, W = int(shape[0]), int(shape[1])
    seen = np.zeros(H, dtype=bool)  # the rows holding a pixel, counted without sorting
    seen[pixels[:, 1]] = True
    if np.count_nonzero(seen) > _FEW_ROWS:  # most of the image's rows: filling it whole is cheaper
        mask = fill_triangles(uv, F, shape, valid=valid, orientation=orientation)
        return mask[pixels[:, 1], pixels[:, 0]]
    rows, where = np.unique(pixels[:, 1], return_inverse=True)
    prep = _prepare(uv, F, H, W, valid, orientation, rows=rows)
    if prep is None or len(pixels) == 0:
        return out
    ids, counts, top, bounds, (_, _, c0, c1) = prep
    bottom = top + counts - 1
    first = np.searchsorted(rows, top, side="left")  # each triangle's rows among them
    n = np.searchsorted(rows, bottom, side="right") - first
    f = np.repeat(np.arange(ids.size), n)
    k = first[f] + (np.arange(f.size) - np.repeat(np.cumsum(n) - n, n))
    a, b = _spans(bounds, f, rows[k].astype(np.float64), c0, c1)
    keep = a <= b
    bw = W + 1
    base = k[keep] * bw
    diff = np.bincount(base + a[keep].astype(np.int64), minlength=len(rows) * bw)
    diff -= np.bincount(base + b[keep].astype(np.int64) + 1, minlength=len(rows) * bw)
    cover = np.cumsum(diff.reshape(len(rows), bw), axis=1) > 0
    return cover[where.ravel(), pixels[:, 0]]


def _prepare(uv, F, H: int, W: int, valid, orientation, rows=None):
    """The triangles :func:`fill_triangles` fills: their indices ``ids``, their numbers of
    pixel rows and first rows (float), their edge bounds (:func:`_edge_bounds`) and the
    bounding box ``(r0, r1, c0, c1)`` of them all; None where none covers a pixel.
    ``rows`` (sorted int, optional): only the triangles spanning one of these rows are
    returned (the box is still that of them all)."""
    uv = np.asarray(uv, dtype=np.float64)
    F = np.asarray(F, dtype=np.intp)
    # Column arrays (m,) are much faster to combine than (m, 3) reductions.
    u, v = uv[:, 0], uv[:, 1]
    x0, x1, x2 = u[F[:, 0]], u[F[:, 1]], u[F[:, 2]]
    y0, y1, y2 = v[F[:, 0]], v[F[:, 1]], v[F[:, 2]]
    with np.errstate(invalid="ignore", over="ignore"):  # inf coordinates: area inf or nan
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    # Skipped: degenerate triangles and those whose projection overflowed (a vertex a
    # hair's breadth in front of the camera plane); the rest have finite coordinates.
    ok = np.isfinite(area) & (
        area > DIVISOR_FLOOR if orientation == "positive" else np.abs(area) > DIVISOR_FLOOR
    )
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        ok &= valid[F[:, 0]] & valid[F[:, 1]] & valid[F[:, 2]]
    top = np.maximum(np.ceil(np.minimum(np.minimum(y0, y1), y2)), 0.0)
    bottom = np.minimum(np.floor(np.maximum(np.maximum(y0, y1), y2)), H - 1.0)
    ok &= bottom >= top
    n_rows = np.zeros(len(F), dtype=np.int64)
    n_rows[ok] = bottom[ok] - top[ok] + 1
    ids = np.flatnonzero(n_rows)
    if ids.size == 0:
        return None
    # Work in the bounding box of the filled triangles: the difference image and its
    # cumulative sum are then as small as the silhouette, not the whole picture.
    r0, r1 = int(top[ids].min()), int(bottom[ids].max())
    xmin = np.minimum(np.minimum(x0[ids], x1[ids]), x2[ids]).min()
    xmax = np.maximum(np.maximum(x0[ids], x1[ids]), x2[ids]).max()
    c0, c1 = int(max(np.ceil(xmin), 0)), int(min(np.floor(xmax), W - 1))
    if c1 < c0:
        return None
    if rows is not None:
        span = np.searchsorted(rows, bottom[ids], "right") - np.searchsorted(rows, top[ids])
        ids = ids[span > 0]
    bounds = _edge_bounds((x0[ids], x1[ids], x2[ids]), (y0[ids], y1[ids], y2[ids]), area[ids])
    return ids, n_rows[ids], top[ids], bounds, (r0, r1, c0, c1)


def _spans(bounds, f: np.ndarray, row: np.ndarray, c0: int, c1: int):
    """First and last covered column (float) of triangle ``f`` (index into the prepared
    triangles) on pixel row ``row`` (float), clipped to ``c0 .. c1``; empty where a > b."""
    lo_x, lo_y, lo_s, hi_x, hi_y, hi_s = bounds
    # Two lower and two upper bounds per triangle (see _edge_bounds).
    left = np.maximum(
        lo_x[0][f] + (row - lo_y[0][f]) * lo_s[0][f],
        lo_x[1][f] + (row - lo_y[1][f]) * lo_s[1][f],
    )
    right = np.minimum(
        hi_x[0][f] + (row - hi_y[0][f]) * hi_s[0][f],
        hi_x[1][f] + (row - hi_y[1][f]) * hi_s[1][f],
    )
    return np.maximum(np.ceil(left), c0), np.minimum(np.floor(right), c1)


def _edge_bounds(xs, ys, area):
    """Per triangle, the edges bounding a row's span from the left and from the right.

    Edge ``i`` runs from vertex ``i`` to vertex ``i + 1``; on row ``y`` it meets
    ``x = x_i + (y − y_i) s_i`` with ``s_i = dx_i / dy_i``. For a triangle of positive area
    the inside is ``dy_i (x − x_i) ≤ dx_i (y − y_i)``: a lower bound on x where ``dy_i < 0``,
    an upper bound where ``dy_i > 0`` (reversed for a negative area); horizontal edges bound
    nothing within the triangle's rows. As the ``dy_i`` sum to zero, a non-degenerate
    triangle has one or two edges of each kind: slots 0 and 1 hold the first and the last
    edge of the kind (the same edge when there is one).

    Returns six pairs of (k,) arrays: ``lo_x, lo_y, lo_s, hi_x, hi_y, hi_s``.
    """
    positive = area > 0
    edges = []
    for i in range(3):
        j = (i + 1) % 3
        dy = ys[j] - ys[i]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(dy == 0, 0.0, (xs[j] - xs[i]) / dy)
        lower = np.where(positive, dy < 0, dy > 0)  # both False where dy == 0
        upper = np.where(positive, dy > 0, dy < 0)
        edges.append((lower, upper, (xs[i], ys[i], s)))
    out = []
    for kind in (0, 1):  # 0: lower bounds (left), 1: upper bounds (right)
        k0, k1 = edges[0][kind], edges[1][kind]
        k2 = edges[2][kind]
        for a in range(3):
            e0, e1, e2 = edges[0][2][a], edges[1][2][a], edges[2][2][a]
            first = np.where(k0, e0, np.where(k1, e1, e2))
            last = np.where(k2, e2, np.where(k1, e1, e0))
            out.append((first, last))
    return tuple(out)
