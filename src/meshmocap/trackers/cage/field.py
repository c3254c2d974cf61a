"""The distance field of the cage tracker's data term (cage-manifold-tracking §5.1, Eq. 4),
evaluated where it is looked up, in compiled loops.

The values are those of :class:`~meshmocap.geometry.distance_field.LazyDistanceGrid`
(signed distance, metres, to the centres of the hull's inner-boundary voxels, minus half
a voxel; negative inside), on the same grid (``pad`` voxels around the occupancy,
``stride`` voxels apart), and lookups interpolate them the same way (trilinear, distance
to the box added outside it). Only the search differs: a grid point's nearest boundary
voxel is found in buckets of ``bucket`` voxels, ring by ring, inside the compiled lookup,
instead of by a k-d tree between numpy calls; the tracker looks up a few hundred points
tens of times a frame, where the calls' overhead and the tree's cache misses were most of
the cost. The nearest distance is unique, so the values are bit-identical
(``tests/trackers/cage/test_field.py``).

Frames and units: world frame, metres; grid indices ``(x, y, z)`` as the occupancy's.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
"""

from __future__ import annotations

import time

import numpy as np

from meshmocap._numba import njit
from meshmocap.errors import InputError

__all__ = ["HullDistanceField"]

_BUCKET = 6  # voxels per bucket side of the nearest-boundary search


@njit(cache=True, nogil=True)
def _boundary_buckets(occ, b):  # pragma: no cover - compiled
    """Inner-boundary voxels (occupied, with an empty 6-neighbour; beyond the grid is
    empty) sorted by bucket of ``b`` voxels: their indices (m, 3) and each bucket's start
    (nb + 1,) in bucket order ``(x, y, z)`` row-major, with the bucket grid's shape."""
    nx, ny, nz = occ.shape
    bx, by, bz = (nx + b - 1) // b, (ny + b - 1) // b, (nz + b - 1) // b
    count = np.zeros(bx * by * bz + 1, dtype=np.int64)
    m = 0
    found = np.empty(nx * ny * nz, dtype=np.int64)  # flat indices, in scan order
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if not occ[i, j, k]:
                    continue
                if (
                    i == 0
                    or j == 0
                    or k == 0
                    or i == nx - 1
                    or j == ny - 1
                    or k == nz - 1
                    or not occ[i - 1, j, k]
                    or not occ[i + 1, j, k]
                    or not occ[i, j - 1, k]
                    or not occ[i, j + 1, k]
                    or not occ[i, j, k - 1]
                    or not occ[i, j, k + 1]
                ):
                    found[m] = (i * ny + j) * nz + k
                    count[((i // b) * by + j // b) * bz + k // b + 1] += 1
                    m += 1
    for q in range(bx * by * bz):
        count[q + 1] += count[q]
    fill = count[:-1].copy()
    pts = np.empty((m, 3), dtype=np.int64)
    for e in range(m):  # into their buckets, in scan order within each: no second scan
        f = found[e]
        i, j, k = f // (ny * nz), (f // nz) % ny, f % nz
        q = ((i // b) * by + j // b) * bz + k // b
        pts[fill[q], 0], pts[fill[q], 1], pts[fill[q], 2] = i, j, k
        fill[q] += 1
    return pts, count, np.array([bx, by, bz], dtype=np.int64)


#: Squared voxel distances start above any a grid holds (:func:`_nearest`).
_NONE = 1 << 62


@njit(cache=True, nogil=True)
def _nearest(x, y, z, pts, start, bshape, b):  # pragma: no cover - compiled
    """Squared distance (voxels²) from voxel ``(x, y, z)`` (any integers) to the nearest
    boundary voxel: buckets ring by ring (Chebyshev distance ``r`` from the query's bucket)
    until every unvisited bucket lies farther than the best so far. ``pts`` (3, m): the
    boundary voxels' coordinates, one row per axis (a bucket's scan is then a vectorised
    minimum of integers, exact)."""
    bx, by, bz = bshape[0], bshape[1], bshape[2]
    qx, qy, qz = x // b, y // b, z // b  # floor division: buckets of points outside too
    px, py, pz = pts[0], pts[1], pts[2]
    best = _NONE
    # the rings needed at most: to the far corner of the bucket grid
    far = max(abs(qx), abs(qx - bx + 1), abs(qy), abs(qy - by + 1), abs(qz), abs(qz - bz + 1))
    for r in range(far + 1):
        for i in range(max(qx - r, 0), min(qx + r, bx - 1) + 1):
            ei = abs(i - qx) == r
            for j in range(max(qy - r, 0), min(qy + r, by - 1) + 1):
                ej = ei or abs(j - qy) == r
                kk0, kk1 = max(qz - r, 0), min(qz + r, bz - 1)
                k = kk0
                while k <= kk1:
                    if ej or abs(k - qz) == r:  # on the ring
                        q = (i * by + j) * bz + k
                        s0, s1 = start[q], start[q + 1]
                        if s0 == s1:  # an empty bucket (most of them)
                            k += 1
                            continue
                        # skip a bucket whose box lies no nearer than the best so far
                        lo = max(i * b - x, 0, x - i * b - b + 1)
                        box = lo * lo
                        lo = max(j * b - y, 0, y - j * b - b + 1)
                        box += lo * lo
                        lo = max(k * b - z, 0, z - k * b - b + 1)
                        box += lo * lo
                        if box >= best:
                            k += 1
                            continue
                        for o in range(s0, s1):
                            dx, dy, dz = px[o] - x, py[o] - y, pz[o] - z
                            best = min(best, dx * dx + dy * dy + dz * dz)
                        k += 1
                    else:  # inside the ring: only its two z faces remain
                        k = qz + r if qz + r <= kk1 else kk1 + 1
        # an unvisited boundary voxel lies in a bucket r + 1 rings away: ≥ r b + 1 voxels
        if best <= (r * b + 1) ** 2:
            break
    return float(best) if best < _NONE else np.inf


@njit(cache=True, nogil=True)
def _evaluate(g, flat, known, occ, pts, start, bshape, b, shape, pad, stride, h):
    """Compute the grid value at flat index ``g`` (LazyDistanceGrid's) into ``flat``."""
    syz = shape[1] * shape[2]
    a, rest = g // syz, g % syz
    x = a * stride - pad
    y = (rest // shape[2]) * stride - pad
    z = (rest % shape[2]) * stride - pad
    e = np.sqrt(_nearest(x, y, z, pts, start, bshape, b))
    nx, ny, nz = occ.shape
    inside = 0 <= x < nx and 0 <= y < ny and 0 <= z < nz and occ[x, y, z]
    v = (-0.5 - e if inside else e - 0.5) * h
    flat[g] = v
    known[g] = True


@njit(cache=True, nogil=True)
def _lookup(P, origin, spacing, shape, flat, known, occ, pts, start, bshape, b, pad, stride, h):
    """Values (n,) and gradients (n, 3) at ``P`` (n, 3), as ``DistanceGrid._lookup``
    (trilinear inside the box; outside, at the nearest box point plus the distance to
    it, the gradient's components along the axes it lies outside of pointing away),
    and the number of grid points computed on the way."""
    n = P.shape[0]
    value = np.empty(n)
    grad = np.empty((n, 3))
    s0, s1 = shape[1] * shape[2], shape[2]
    new = 0
    gc = np.empty(3)
    fr = np.empty(3)
    i0 = np.empty(3, dtype=np.int64)
    out = np.zeros(3, dtype=np.bool_)
    c8 = np.empty(8)
    for p in range(n):
        off2 = 0.0
        for a in range(3):
            g = (P[p, a] - origin[a]) / spacing
            c = min(max(g, 0.0), float(shape[a] - 1))
            out[a] = g != c
            f0 = min(np.floor(c), float(shape[a] - 2))
            gc[a], fr[a], i0[a] = c, c - f0, int(f0)
            o = P[p, a] - (origin[a] + c * spacing)
            off2 += o * o
        base = i0[0] * s0 + i0[1] * s1 + i0[2]
        for corner in range(8):
            dx, dy, dz = corner >> 2, (corner >> 1) & 1, corner & 1
            g = base + dx * s0 + dy * s1 + dz
            if not known[g]:
                new += 1
                _evaluate(g, flat, known, occ, pts, start, bshape, b, shape, pad, stride, h)
            c8[corner] = flat[g]
        fx, fy, fz = fr[0], fr[1], fr[2]
        # along z at (x, y) = 00 01 10 11, then y, then x: DistanceGrid._lookup's order
        d00, d01, d10, d11 = c8[1] - c8[0], c8[3] - c8[2], c8[5] - c8[4], c8[7] - c8[6]
        e00, e01 = c8[0] + fz * d00, c8[2] + fz * d01
        e10, e11 = c8[4] + fz * d10, c8[6] + fz * d11
        ey0, ey1 = e01 - e00, e11 - e10
        e20, e21 = e00 + fy * ey0, e10 + fy * ey1
        gx = e21 - e20
        dist = np.sqrt(off2)
        value[p] = e20 + fx * gx + dist
        dz0, dz1 = d00 + fy * (d01 - d00), d10 + fy * (d11 - d10)
        gr = (gx / spacing, (ey0 + fx * (ey1 - ey0)) / spacing, (dz0 + fx * (dz1 - dz0)) / spacing)
        for a in range(3):
            if out[a]:  # outside the box: away from it
                o = P[p, a] - (origin[a] + gc[a] * spacing)
                grad[p, a] = o / dist if dist > 0 else 0.0
            else:
                grad[p, a] = gr[a]
    return value, grad, new


class HullDistanceField:
    """Signed distance to a voxel hull, evaluated where looked up (module docstring).

    Parameters
    ----------
    occupancy : (nx, ny, nz) bool
        The hull's voxels.
    origin : (3,) float64
        Centre of voxel (0, 0, 0), metres.
    spacing : float
        Voxel size, metres.
    pad : int
        Voxels of grid around the occupancy (≥ 1).
    stride : int
        Voxels between grid points (≥ 1).

    Attributes
    ----------
    shape : tuple of int
        Grid points along x, y, z.
    origin, spacing : (3,) float64
        Position of grid point (0, 0, 0) and the spacing, metres.
    n_evaluated : int
        Grid points computed so far.
    seconds : float
        Wall time of the construction (the buckets of boundary voxels), seconds; grid
        points are computed inside lookups, and count as theirs.
    """

    def __init__(self, occupancy, origin, spacing, *, pad: int = 1, stride: int = 1) -> None:
        t0 = time.perf_counter()
        # a read-only view whatever the caller passed (a hull read from disk is read-only, one
        # carved in memory is not): the compiled kernels meet one signature, the one
        # apps.kernels compiles ahead
        occ = np.ascontiguousarray(occupancy, dtype=bool).view()
        occ.flags.writeable = False
        origin = np.array(origin, dtype=np.float64).reshape(-1)
        h = float(spacing)
        good = (
            occ.ndim == 3
            and occ.any()
            and origin.shape == (3,)
            and np.all(np.isfinite(origin))
            and np.isfinite(h)
            and h > 0
            and int(pad) == pad >= 1
            and int(stride) == stride >= 1
        )
        if not good:
            raise InputError(
                "HullDistanceField: expected a non-empty 3-D occupancy, 3 finite origin "
                "coordinates, a positive spacing and integers pad, stride ≥ 1; found shape "
                f"{occ.shape}, origin {origin}, spacing {spacing!r}, pad {pad!r}, stride {stride!r}"
            )
        k, m = int(pad), int(stride)
        self._occ, self._pad, self._h, self._stride = occ, k, h, m
        self.shape = tuple(-(-(int(n) + 2 * k) // m) for n in occ.shape)
        self._shape = np.array(self.shape, dtype=np.int64)
        self.origin = origin - k * h
        self.spacing = np.full(3, m * h)
        self._pts, self._start, self._bshape = _boundary_buckets(occ, _BUCKET)
        self._axes = np.ascontiguousarray(self._pts.T)  # (3, m): _nearest's layout
        self._origin0 = origin
        size = int(np.prod(self.shape))
        self._known = np.zeros(size, dtype=np.bool_)
        self._flat = np.empty(size)
        self.n_evaluated = 0
        self.seconds = time.perf_counter() - t0

    @property
    def boundary(self) -> np.ndarray:
        """Centres (m, 3) of the inner-boundary voxels, metres, in the occupancy's order
        (x, then y, then z: as ``LazyDistanceGrid.boundary``)."""
        _, ny, nz = self._occ.shape
        ijk = self._pts[np.argsort((self._pts[:, 0] * ny + self._pts[:, 1]) * nz + self._pts[:, 2])]
        return ijk * self._h + self._origin0

    def value_and_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (n,) and gradients (n, 3) at ``points`` (n, 3), metres."""
        P = np.ascontiguousarray(points, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3:
            raise InputError(f"points: expected shape (n, 3), found {P.shape}")
        if not np.all(np.isfinite(P)):
            raise InputError("points: expected finite coordinates, found NaN or infinity")
        value, grad, new = _lookup(
            P,
            self.origin,
            float(self.spacing[0]),
            self._shape,
            self._flat,
            self._known,
            self._occ,
            self._axes,
            self._start,
            self._bshape,
            _BUCKET,
            self._pad,
            self._stride,
            self._h,
        )
        self.n_evaluated += int(new)
        return value, grad

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Values (n,) at ``points`` (n, 3), metres."""
        return self.value_and_gradient(points)[0]
