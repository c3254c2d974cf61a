"""Triangle rasterisation with a depth buffer, vectorised over triangles and pixels.

Each triangle's bounding box is expanded into candidate pixels in one flat array, pixel
centres are tested against the triangle by barycentric coordinates, and the nearest
triangle wins each pixel (a stable sort on (pixel, depth)). Work is proportional to the
summed bounding-box areas; big meshes are processed in chunks to bound memory.

References
----------
- E. Catmull, *A subdivision algorithm for computer display of curved surfaces*,
  PhD thesis, University of Utah, 1974.
"""

from __future__ import annotations

import numpy as np

from meshmocap._tolerances import BARYCENTRIC_SLACK, DIVISOR_FLOOR, ROUNDING_SLACK

_CHUNK = 4_000_000  # candidate (triangle, pixel) pairs per chunk


def rasterize(
    uv: np.ndarray, depth: np.ndarray, F: np.ndarray, shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Return, per pixel, the nearest triangle covering its centre and that depth.

    Parameters
    ----------
    uv : (n, 2) float64
        Projected vertices, pixel coordinates (column, row), pixel centres at integers.
    depth : (n,) float64
        Vertex depths along the optical axis, metres; triangles with a vertex at depth
        ≤ 0 (behind the camera) are skipped.
    F : (m, 3) int
        Triangles.
    shape : (height, width)
        Image size in pixels.

    Returns
    -------
    face : (height, width) int64
        Index of the visible triangle, −1 for background.
    zbuf : (height, width) float64
        Depth of the visible surface (linearly interpolated in screen space), ``inf`` for
        background.
    """
    H, W = shape
    face = np.full(H * W, -1, dtype=np.int64)
    zbuf = np.full(H * W, np.inf)
    F = np.asarray(F, dtype=np.int64)
    tri = uv[F]  # (m, 3, 2)
    ok = (depth[F] > 0).all(axis=1)
    # the first pixel centre ≥ min
    lo = np.floor(tri.min(axis=1) + 1.0 - ROUNDING_SLACK).astype(np.int64)
    hi = np.floor(tri.max(axis=1)).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [W - 1, H - 1])
    size = np.clip(hi - lo + 1, 0, None)
    count = size[:, 0] * size[:, 1] * ok
    ids = np.flatnonzero(count)
    if ids.size == 0:
        return face.reshape(H, W), zbuf.reshape(H, W)
    bounds = np.searchsorted(np.cumsum(count[ids]), np.arange(_CHUNK, count[ids].sum(), _CHUNK))
    for chunk in np.split(ids, bounds + 1):
        _raster_chunk(chunk, count, size, lo, tri, depth[F], W, face, zbuf)
    return face.reshape(H, W), zbuf.reshape(H, W)


def _raster_chunk(ids, count, size, lo, tri, tdepth, W, face, zbuf) -> None:
    c = count[ids]
    f = np.repeat(ids, c)
    k = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)  # index inside each bbox
    w = size[f, 0]
    x = lo[f, 0] + k % w
    y = lo[f, 1] + k // w
    a, b, d = tri[f, 0], tri[f, 1], tri[f, 2]
    # Barycentric coordinates of pixel centres (x, y).
    v0, v1 = b - a, d - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    px, py = x - a[:, 0], y - a[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = (px * v1[:, 1] - v1[:, 0] * py) / den
        l2 = (v0[:, 0] * py - px * v0[:, 1]) / den
    l0 = 1.0 - l1 - l2
    eps = -BARYCENTRIC_SLACK
    inside = (l0 >= eps) & (l1 >= eps) & (l2 >= eps) & (np.abs(den) > DIVISOR_FLOOR)
    if not inside.any():
        return
    z = l0 * tdepth[f, 0] + l1 * tdepth[f, 1] + l2 * tdepth[f, 2]
    pix = (y * W + x)[inside]
    z, f = z[inside], f[inside]
    order = np.lexsort((z, pix))
    pix, z, f = pix[order], z[order], f[order]
    first = np.ones(len(pix), dtype=bool)
    first[1:] = pix[1:] != pix[:-1]
    pix, z, f = pix[first], z[first], f[first]
    closer = z < zbuf[pix]
    zbuf[pix[closer]] = z[closer]
    face[pix[closer]] = f[closer]


def coverage(uv: np.ndarray, F: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Return a (height, width) bool mask of the pixels whose centre some triangle covers.

    ``uv`` (n, 2) are pixel coordinates; no depth test (a silhouette).
    """
    face, _ = rasterize(uv, np.ones(len(uv)), F, shape)
    return face >= 0
