"""The distance field of the cage tracker's data term (cage-manifold-tracking §5.1, Eq. 4),
evaluated where it is looked up, in compiled loops.

The values are those of :class:`~meshmocap.geometry.distance_field.LazyDistanceGrid`
(signed distance, metres, to the centres of the hull's inner-boundary voxels, minus half
a voxel; negative inside), on the same grid (``pad`` voxels around the occupancy,
``stride`` voxels apart), and lookups interpolate them the same way (trilinear, distance
to the box added outside it). Only the search differs: the nearest boundary voxels of a
grid cell's new corners are found together, in buckets of ``bucket`` voxels, ring by
ring, inside the compiled lookup, instead of by a k-d tree between numpy calls; the
tracker looks up a few hundred points tens of times a frame, where the calls' overhead and
the tree's cache misses were most of the cost. The nearest distance is unique, so the
values are bit-identical (``tests/trackers/cage/test_field.py``).

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


#: Squared voxel distances start above any a grid holds (:func:`_nearest_cell`).
_NONE = 1 << 62


@njit(cache=True, nogil=True)
def _nearest_cell(x, y, z, s, need, best, pts, start, bshape, b):  # pragma: no cover - compiled
    """Squared distances (voxels²) from the 8 corners ``(x + i s, y + j s, z + k s)`` of a
    grid cell (``i, j, k`` in {0, 1}, corner ``4 i + 2 j + k``; any integers) to their
    nearest boundary voxels, for the corners where ``need`` holds, into ``best`` (8,) int64
    (:data:`_NONE` where there is no boundary voxel): one pass over the buckets, ring by
    ring (Chebyshev distance ``r`` from corner 0's bucket), for all of them (a lookup's
    new corners come 4 to 8 to a cell, and their own searches would visit nearly the same
    buckets), until every unvisited bucket lies farther from each corner than its best
    so far. ``pts`` (3, m): the boundary voxels' coordinates, one row per axis. The
    minima are exact (integers): the same whichever corners are searched together."""
    bx, by, bz = bshape[0], bshape[1], bshape[2]
    qx, qy, qz = x // b, y // b, z // b  # the rings are centred on corner 0's bucket
    px, py, pz = pts[0], pts[1], pts[2]
    # each corner's best so far; -1 for a corner not searched (never above a bound: done)
    b0 = _NONE if need[0] else -1
    b1 = _NONE if need[1] else -1
    b2 = _NONE if need[2] else -1
    b3 = _NONE if need[3] else -1
    b4 = _NONE if need[4] else -1
    b5 = _NONE if need[5] else -1
    b6 = _NONE if need[6] else -1
    b7 = _NONE if need[7] else -1
    far = max(abs(qx), abs(qx - bx + 1), abs(qy), abs(qy - by + 1), abs(qz), abs(qz - bz + 1))
    for r in range(far + 1):
        for i in range(max(qx - r, 0), min(qx + r, bx - 1) + 1):
            ei = abs(i - qx) == r
            lx0 = max(i * b - x, 0, x - i * b - b + 1)
            lx1 = max(i * b - x - s, 0, x + s - i * b - b + 1)
            lx0, lx1 = lx0 * lx0, lx1 * lx1
            for j in range(max(qy - r, 0), min(qy + r, by - 1) + 1):
                ej = ei or abs(j - qy) == r
                ly0 = max(j * b - y, 0, y - j * b - b + 1)
                ly1 = max(j * b - y - s, 0, y + s - j * b - b + 1)
                ly0, ly1 = ly0 * ly0, ly1 * ly1
                kk0, kk1 = max(qz - r, 0), min(qz + r, bz - 1)
                k = kk0
                while k <= kk1:
                    if ej or abs(k - qz) == r:  # on the ring
                        q = (i * by + j) * bz + k
                        s0, s1 = start[q], start[q + 1]
                        if s0 == s1:  # an empty bucket (most of them)
                            k += 1
                            continue
                        # skip a bucket whose box lies no nearer to any corner than that
                        # corner's best so far
                        lz0 = max(k * b - z, 0, z - k * b - b + 1)
                        lz1 = max(k * b - z - s, 0, z + s - k * b - b + 1)
                        lz0, lz1 = lz0 * lz0, lz1 * lz1
                        if (
                            lx0 + ly0 + lz0 >= b0
                            and lx0 + ly0 + lz1 >= b1
                            and lx0 + ly1 + lz0 >= b2
                            and lx0 + ly1 + lz1 >= b3
                            and lx1 + ly0 + lz0 >= b4
                            and lx1 + ly0 + lz1 >= b5
                            and lx1 + ly1 + lz0 >= b6
                            and lx1 + ly1 + lz1 >= b7
                        ):
                            k += 1
                            continue
                        for o in range(s0, s1):
                            dx, dy, dz = px[o] - x, py[o] - y, pz[o] - z
                            ax0, ay0, az0 = dx * dx, dy * dy, dz * dz
                            dx, dy, dz = dx - s, dy - s, dz - s
                            ax1, ay1, az1 = dx * dx, dy * dy, dz * dz
                            b0 = min(b0, ax0 + ay0 + az0)
                            b1 = min(b1, ax0 + ay0 + az1)
                            b2 = min(b2, ax0 + ay1 + az0)
                            b3 = min(b3, ax0 + ay1 + az1)
                            b4 = min(b4, ax1 + ay0 + az0)
                            b5 = min(b5, ax1 + ay0 + az1)
                            b6 = min(b6, ax1 + ay1 + az0)
                            b7 = min(b7, ax1 + ay1 + az1)
                        k += 1
                    else:  # inside the ring: only its two z faces remain
                        k = qz + r if qz + r <= kk1 else kk1 + 1
        # an unvisited boundary voxel lies in a bucket r + 1 rings from corner 0's: ≥ r b + 1
        # voxels from corner 0 along some axis, ≥ r b + 1 − s from any corner
        lim = r * b + 1 - s
        if lim > 0 and max(b0, b1, b2, b3, b4, b5, b6, b7) <= lim * lim:
            break
    best[0], best[1], best[2], best[3] = b0, b1, b2, b3
    best[4], best[5], best[6], best[7] = b4, b5, b6, b7


@njit(cache=True, nogil=True)
def _evaluate_cell(base, need, flat, known, occ, pts, start, bshape, b, shape, pad, stride, h):
    """Compute the grid values of the corners ``need`` (8,) bool of the cell whose corner 0
    has flat index ``base`` into ``flat`` (LazyDistanceGrid's values: the distance to the
    nearest boundary voxel's centre, minus half a voxel, negative inside; metres) and mark
    them ``known``."""
    syz = shape[1] * shape[2]
    a, rest = base // syz, base % syz
    x = a * stride - pad
    y = (rest // shape[2]) * stride - pad
    z = (rest % shape[2]) * stride - pad
    best = np.empty(8, dtype=np.int64)
    _nearest_cell(x, y, z, stride, need, best, pts, start, bshape, b)
    nx, ny, nz = occ.shape
    for c in range(8):
        if not need[c]:
            continue
        dx, dy, dz = c >> 2, (c >> 1) & 1, c & 1
        cx, cy, cz = x + dx * stride, y + dy * stride, z + dz * stride
        e = np.sqrt(float(best[c]) if best[c] < _NONE else np.inf)
        inside = 0 <= cx < nx and 0 <= cy < ny and 0 <= cz < nz and occ[cx, cy, cz]
        g = base + dx * syz + dy * shape[2] + dz
        flat[g] = (-0.5 - e if inside else e - 0.5) * h
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
    need = np.empty(8, dtype=np.bool_)
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
        unknown = 0
        for corner in range(8):
            dx, dy, dz = corner >> 2, (corner >> 1) & 1, corner & 1
            need[corner] = not known[base + dx * s0 + dy * s1 + dz]
            unknown += need[corner]
        if unknown:  # the cell's new corners, in one search
            new += unknown
            _evaluate_cell(
                base, need, flat, known, occ, pts, start, bshape, b, shape, pad, stride, h
            )
        for corner in range(8):
            dx, dy, dz = corner >> 2, (corner >> 1) & 1, corner & 1
            c8[corner] = flat[base + dx * s0 + dy * s1 + dz]
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
        self._axes = np.ascontiguousarray(self._pts.T)  # (3, m): _nearest_cell's layout
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
