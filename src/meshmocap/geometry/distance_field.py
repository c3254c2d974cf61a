"""Signed-distance fields on regular grids: trilinear lookups with exact gradients.

:class:`DistanceGrid` is the precomputed field a tracker minimises: the sum of the field
over the model's vertices measures how far the model is from the target mesh
(cage-manifold-tracking §5.1, Eq. 4). Values live on a regular grid; a lookup is the
trilinear interpolant and its exact (piecewise) gradient, finite everywhere in space.

Fields come from a voxel occupancy (:func:`signed_distance`, one Euclidean distance
transform) — a visual hull (:func:`meshmocap.geometry.carving.distance_grid`) or a closed
triangle mesh scan-converted into voxels (:func:`distance_grid_from_mesh`).
:class:`LazyDistanceGrid` is the same field as :func:`signed_distance` of an occupancy,
computed grid point by grid point where lookups need it (a k-d tree to the inner-boundary
voxels): what a tracker that queries a few hundred template points per frame should use.

Frames: world, metres, Z up. Grid point ``(i, j, k)`` is at ``origin + (i, j, k) * spacing``.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- J. Pineda, *A parallel algorithm for polygon rasterization*, SIGGRAPH 1988 (Computer
  Graphics 22(4):17–20).
"""

from __future__ import annotations

import time
from functools import cached_property

import numpy as np
from pykdtree.kdtree import KDTree
from scipy import ndimage

from meshmocap.errors import InputError

_MAX_VOXELS = 1 << 27  # refuse grids above ~134 M points (memory)
_CHUNK = 4_000_000  # (triangle, column) pairs per chunk when voxelising a mesh


class DistanceGrid:
    """Signed distances on a regular grid, queried by trilinear interpolation.

    A precomputed solver: build once per target, query many times. Inside the grid's box
    the value is the trilinear interpolant of the grid values and the gradient its exact
    (piecewise) derivative. Outside the box the value is that at the nearest point of the
    box plus the distance to it, so it stays finite, continuous and grows away from the
    box; the gradient's clamped components are those of the direction away from the box.

    Parameters
    ----------
    values : (nx, ny, nz) float64
        Values at the grid points, metres; each dimension ≥ 2.
    origin : (3,) float64
        Position of grid point ``(0, 0, 0)``, metres, world frame.
    spacing : float or (3,) float64
        Distance between grid points along x, y, z, metres.
    """

    def __init__(self, values: np.ndarray, origin: np.ndarray, spacing: float | np.ndarray) -> None:
        values = np.array(values, dtype=np.float64, order="C")  # own copy, made read-only
        origin = np.array(origin, dtype=np.float64).reshape(-1)
        spacing = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,)).copy()
        if values.ndim != 3 or min(values.shape) < 2 or not np.all(np.isfinite(values)):
            raise InputError(
                f"values: expected a finite (nx, ny, nz) grid, each ≥ 2, found {values.shape}"
            )
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise InputError(f"origin: expected 3 finite numbers, found {origin!r}")
        if not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
            raise InputError(f"spacing: expected positive metres, found {spacing!r}")
        for v in (values, origin, spacing):
            v.setflags(write=False)
        self.values, self.origin, self.spacing = values, origin, spacing
        self.shape = values.shape
        self.upper = origin + (np.array(values.shape) - 1) * spacing
        self._flat = values.ravel()
        self._set_strides()

    def _set_strides(self) -> None:
        _, ny, nz = self.shape
        self._strides = np.array([ny * nz, nz, 1])
        sx, sy, _ = self._strides
        # flat offsets of a cell's 8 corners: (x, y, z) = 000, 001, 010, 011, 100, ... 111
        self._corners = np.array([0, 1, sy, sy + 1, sx, sx + 1, sx + sy, sx + sy + 1])
        # per-lookup constants, as columns (a lookup of a few hundred points is overhead-bound)
        self._top = np.array(self.shape, dtype=np.float64)[:, None] - 1  # last grid point
        self._last_cell = np.array(self.shape, dtype=np.float64)[:, None] - 2
        self._col_origin, self._col_spacing = self.origin[:, None], self.spacing[:, None]

    def _gather(self, idx: np.ndarray) -> np.ndarray:
        """Values at flat grid indices ``idx`` (any shape)."""
        return self._flat[idx]

    @cached_property
    def _tree(self) -> KDTree:
        """The k-d tree of the inner-boundary voxel centres (voxel units), built on first
        use (its time booked to :attr:`seconds`)."""
        t0 = time.perf_counter()
        tree = KDTree(self._ijk)
        self.seconds += time.perf_counter() - t0
        return tree

    def _cells(self, base: np.ndarray) -> np.ndarray:
        """Values (8, n) at the corners of the cells whose corner 000 is at flat ``base`` (n,)."""
        return self._gather(self._corners[:, None] + base)

    def __repr__(self) -> str:
        return f"DistanceGrid(shape={self.shape}, origin={self.origin}, spacing={self.spacing})"

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Return the values (...,) at ``points`` (..., 3), metres."""
        return self._lookup(points, gradient=False)[0]

    def value_and_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return values (...,) and gradients (..., 3) at ``points`` (..., 3)."""
        return self._lookup(points, gradient=True)

    def _lookup(self, points, *, gradient: bool):
        P, lead = _query_points(points)
        P = P.reshape(-1, 3)
        # grid coordinates, fractions and corner values as rows, (3, n) and (8, n): the
        # arithmetic runs along n (an (n, 3) array broadcast against (3,) costs 3× more)
        g = (P.T - self._col_origin) / self._col_spacing
        gc = np.minimum(np.maximum(g, 0.0), self._top)  # np.clip, without its overhead
        i0 = np.minimum(np.floor(gc), self._last_cell)  # cell corner 000, exact in float64
        fx, fy, fz = gc - i0
        c = self._cells(self._strides @ i0.astype(np.intp))  # corners xyz = 000 … 111
        d = c[1::2] - c[0::2]  # (4, n) differences along z, at (x, y) = 00 01 10 11
        e = c[0::2] + fz * d  # along z
        ey = e[1::2] - e[0::2]  # (2, n) differences along y, at x = 0, 1
        e2 = e[0::2] + fy * ey  # along y
        gx = e2[1] - e2[0]
        value = e2[0] + fx * gx  # along x
        off = P - (self.origin + gc.T * self.spacing)  # zero inside the box (to rounding)
        dist = np.sqrt(np.einsum("ij,ij->i", off, off))
        value = value + dist
        if not gradient:
            return value.reshape(lead), None
        grad = np.empty((3, len(P)))
        grad[0] = gx
        grad[1] = ey[0] + fx * (ey[1] - ey[0])
        dz = d[0::2] + fy * (d[1::2] - d[0::2])  # (2, n) at x = 0, 1
        grad[2] = dz[0] + fx * (dz[1] - dz[0])
        grad /= self._col_spacing
        grad = np.ascontiguousarray(grad.T)
        out = g != gc
        if out.any():  # outside the box: away from it
            away = np.divide(off, dist[:, None], out=np.zeros_like(off), where=dist[:, None] > 0)
            grad = np.where(out.T, away, grad)
        return value.reshape(lead), grad.reshape(*lead, 3)


# ---------------------------------------------------------------------------------------
# Occupancy → distance, mesh → occupancy


def signed_distance(occupancy: np.ndarray, spacing: float) -> np.ndarray:
    """Return the signed distance (metres, negative inside) of a voxel occupancy.

    Parameters
    ----------
    occupancy : (nx, ny, nz) bool
        True inside; its border layer should be empty (pad it otherwise).
    spacing : float
        Voxel edge, metres.

    Returns
    -------
    values : (nx, ny, nz) float64
        At the voxel centres, metres.

    Notes
    -----
    One Euclidean distance transform to the inner boundary (occupied voxels with an empty
    6-neighbour): exact for outside voxels (their nearest occupied voxel is always on the
    inner boundary), and within one voxel of the distance to the nearest empty voxel
    inside. The zero level lies halfway between inside and outside voxel centres.
    """
    occ = np.asarray(occupancy, dtype=bool)
    inner = np.zeros_like(occ)
    for axis in range(3):
        for sl_a, sl_b in ((slice(1, None), slice(None, -1)), (slice(None, -1), slice(1, None))):
            a = [slice(None)] * 3
            b = [slice(None)] * 3
            a[axis], b[axis] = sl_a, sl_b
            inner[tuple(a)] |= ~occ[tuple(b)]
    inner &= occ
    e = ndimage.distance_transform_edt(~inner)
    return np.where(occ, -0.5 - e, e - 0.5) * spacing


def inner_boundary(occ: np.ndarray) -> np.ndarray:
    """(nx, ny, nz) bool: the occupied voxels of ``occ`` (nx, ny, nz) bool with an empty
    6-neighbour (beyond the grid counts as empty).

    Computed on the flat array: a voxel's neighbours are at flat offsets ±1, ±nz, ±ny nz,
    which wrap around on the grid's border layers, so those are set apart (every occupied
    voxel there is inner: it has a neighbour beyond the grid). Byte operations into one
    buffer: 5× faster than the same with 3-D slices and temporaries (2.5 → 0.5 ms, 1.4 M
    voxels).
    """
    occ = np.ascontiguousarray(occ, dtype=bool)
    if min(occ.shape) < 3:
        return occ.copy()  # every voxel is on the border
    _, ny, nz = occ.shape
    f = occ.reshape(-1).view(np.uint8)
    lo, hi = ny * nz, f.size - ny * nz  # voxels with x in 1 … nx − 2
    t = np.bitwise_and(f[: hi - lo], f[2 * lo :])  # the x − 1 and x + 1 neighbours
    for s in (nz, 1):
        np.bitwise_and(t, f[lo - s : hi - s], out=t)
        np.bitwise_and(t, f[lo + s : hi + s], out=t)
    inner = np.empty_like(occ)
    flat = inner.reshape(-1)
    np.greater(f[lo:hi], t, out=flat[lo:hi].view(np.uint8))  # occupied, not all 6 neighbours
    flat[:lo], flat[hi:] = occ.reshape(-1)[:lo], occ.reshape(-1)[hi:]  # x borders
    for border in ((slice(None), 0), (slice(None), -1), (Ellipsis, 0), (Ellipsis, -1)):
        inner[border] = occ[border]  # y and z borders (wrapped above)
    return inner


#: Rings of voxels around a point :meth:`LazyDistanceGrid.at_points` looks at before its
#: k-d tree (a point farther than ``AT_POINTS_RINGS + ½`` voxels from the surface goes to
#: the tree).
AT_POINTS_RINGS = 2

#: Rings looked at for the points the first :data:`AT_POINTS_RINGS` leave, while the k-d
#: tree is not built yet and they are at most :data:`AT_POINTS_FEW` of the points: a
#: tracked body's vertices lie within a few voxels of its observations, and building the
#: tree for the last few costs more than looking further around them.
AT_POINTS_FAR_RINGS = 12
#: The largest share of the points left by the first rings that
#: :data:`AT_POINTS_FAR_RINGS` are looked at for (more: the k-d tree answers them).
AT_POINTS_FEW = 0.2


class LazyDistanceGrid(DistanceGrid):
    """:func:`signed_distance` of a padded occupancy, computed only where it is looked up.

    The same field, value for value, as
    ``DistanceGrid(signed_distance(np.pad(occupancy, pad), spacing)[::stride, ::stride,
    ::stride], origin - pad * spacing, stride * spacing)``, but a grid point's value is
    computed the first time a lookup needs it (one k-d tree query to the inner-boundary
    voxel centres, the point set the distance transform measures to) and then kept. A
    tracker querying a few hundred points near the surface touches a few thousand grid
    points instead of the whole box: milliseconds instead of the ~0.2–0.4 s of a full
    Euclidean distance transform.

    Parameters
    ----------
    occupancy : (nx, ny, nz) bool
        True inside (e.g. :attr:`~meshmocap.geometry.carving.VoxelHull.occupancy`); not
        empty.
    origin : (3,) float64
        Centre of voxel ``(0, 0, 0)`` of ``occupancy``, metres, world frame.
    spacing : float
        Voxel edge, metres.
    pad : int
        Empty voxel layers around ``occupancy`` (≥ 1); the grid spans ``occupancy.shape +
        2 pad`` voxels from ``origin - pad * spacing``.
    stride : int
        Grid points at every ``stride``-th voxel centre along each axis (≥ 1): ``stride³``
        times fewer distances to compute, for a field that is exact at the grid points
        and interpolated between them (the signed distance is smooth away from the
        medial axis: near a limb of radius ρ trilinear interpolation over a spacing ``s``
        errs by about ``s² / 8ρ``, 1 mm for 2 cm over a 5 cm limb).

    Attributes
    ----------
    boundary : (m, 3) float64
        Centres of the inner-boundary voxels (occupied, with an empty 6-neighbour), metres,
        world frame: the points the distances are measured to, a sampling of the target's
        surface half a voxel inside it.
    n_evaluated : int
        Grid points computed so far.
    seconds : float
        Wall time spent building the tree and computing grid points, seconds.
    values : (⌈(nx + 2 pad) / stride⌉, …) float64
        Every grid value (computing all of them: for inspection and tests).
    """

    def __init__(
        self,
        occupancy: np.ndarray,
        origin: np.ndarray,
        spacing: float,
        *,
        pad: int = 1,
        stride: int = 1,
    ) -> None:
        t0 = time.perf_counter()
        occ = np.asarray(occupancy, dtype=bool)
        origin = np.array(origin, dtype=np.float64).reshape(-1)
        h = float(spacing)
        if occ.ndim != 3 or not occ.any():
            raise InputError(f"occupancy: expected a non-empty 3-D grid, found {occ.shape}")
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise InputError(f"origin: expected 3 finite numbers, found {origin!r}")
        if not np.isfinite(h) or h <= 0:
            raise InputError(f"spacing: expected positive metres, found {spacing!r}")
        if int(pad) != pad or pad < 1:
            raise InputError(f"pad: expected an integer ≥ 1, found {pad!r}")
        if int(stride) != stride or stride < 1:
            raise InputError(f"stride: expected an integer ≥ 1, found {stride!r}")
        k, m = int(pad), int(stride)
        self._occ, self._pad, self._h, self._stride = occ, k, h, m
        self.shape = tuple(-(-(int(n) + 2 * k) // m) for n in occ.shape)
        self.origin = origin - k * h
        self.spacing = np.full(3, m * h)
        for v in (self.origin, self.spacing):
            v.setflags(write=False)
        self.upper = self.origin + (np.array(self.shape) - 1) * m * h
        self._set_strides()
        self._inner = inner_boundary(occ)
        self._occ_origin = origin
        size = int(np.prod(self.shape))
        self._known = np.zeros(size, dtype=bool)  # grid points computed
        self._cell_known = np.zeros(size, dtype=bool)  # cells (by corner 000) all computed
        self._flat = np.empty(size)
        self.n_evaluated = 0
        self.seconds = time.perf_counter() - t0

    @cached_property
    def _ijk(self) -> np.ndarray:
        """(m, 3) float64: the inner-boundary voxels, voxel units (what the k-d tree holds;
        made on first need: the signed distance at points near the surface needs neither)."""
        flat = np.flatnonzero(self._inner)
        ijk = np.empty((len(flat), 3))  # np.unravel_index, without int → float copies
        _, ny, nz = self._occ.shape
        ijk[:, 0], rest = np.divmod(flat, ny * nz)
        ijk[:, 1], ijk[:, 2] = np.divmod(rest, nz)
        return ijk

    @cached_property
    def boundary(self) -> np.ndarray:
        """(m, 3) float64: the inner-boundary voxel centres, metres, world frame (made on
        first use)."""
        boundary = self._ijk * self._h + self._occ_origin
        boundary.setflags(write=False)
        return boundary

    def __repr__(self) -> str:
        return (
            f"LazyDistanceGrid(shape={self.shape}, origin={self.origin}, "
            f"spacing={self.spacing}, evaluated={self.n_evaluated})"
        )

    @property
    def values(self) -> np.ndarray:  # type: ignore[override]
        out = self._gather(np.arange(self._flat.size)).reshape(self.shape)
        out.setflags(write=False)
        return out

    def prefetch(self, points: np.ndarray) -> None:
        """Compute now, in one batch, the grid values at the corners of the cells holding
        ``points`` (..., 3) (the nearest cell for points outside the box; non-finite
        points are skipped). Lookups return the same values either way; this only moves
        the work: a k-d tree query costs about 3× less per point in one batch of thousands
        than in the many small ones of an optimisation, where the tree has left the cache
        between them (measured: 0.6 against 2 µs a grid point)."""
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        g = (P[np.all(np.isfinite(P), axis=1)].T - self._col_origin) / self._col_spacing
        i0 = np.minimum(np.floor(np.minimum(np.maximum(g, 0.0), self._top)), self._last_cell)
        self._cells(_unique(self._strides @ i0.astype(np.intp)))

    def at_points(self, points: np.ndarray) -> np.ndarray:
        """The signed distance (...,) at ``points`` (..., 3) themselves, metres, computed
        as a grid point's is (the distance to the nearest inner-boundary voxel centre less
        half a voxel, negative where the voxel holding the point is occupied) instead of
        interpolated between grid points: one k-d tree query per point where a lookup
        (``__call__``) computes the eight corners of each new cell it touches (about
        4× the work for a mesh's vertices at the voxels' spacing), and exact beyond the
        grid's box. It differs from the lookup by the interpolation's error (a fraction of
        a voxel), not used for gradients."""
        from meshmocap.geometry._mesh_kernels import boundary_distance_kernel

        P, lead = _query_points(points)
        g, inside = self._voxel_points(P)
        # the voxels around each point first (most points lie within a few of the
        # surface), the k-d tree for the others: the same distances
        e = np.empty(len(g))
        boundary_distance_kernel(g, self._inner, AT_POINTS_RINGS, e)
        rest = np.flatnonzero(np.isnan(e))
        if 0 < len(rest) <= AT_POINTS_FEW * len(g) and "_tree" not in self.__dict__:
            far = np.empty(len(rest))
            boundary_distance_kernel(g[rest], self._inner, AT_POINTS_FAR_RINGS, far)
            e[rest] = far
            rest = rest[np.isnan(far)]
        if len(rest):
            e[rest] = self._tree.query(np.ascontiguousarray(g[rest]), k=1)[0]
        return (np.where(inside, -0.5 - e, e - 0.5) * self._h).reshape(lead)

    def _voxel_points(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``P`` (..., 3) in voxel units, (n, 3) C-ordered, and (n,) whether the voxel
        holding each point is occupied (False beyond the occupancy)."""
        from meshmocap.geometry._mesh_kernels import occupied_kernel

        g = (P.reshape(-1, 3) - (self.origin + self._pad * self._h)) / self._h
        g = np.ascontiguousarray(g)
        inside = np.empty(len(g), dtype=bool)
        occupied_kernel(g, np.ascontiguousarray(self._occ, dtype=bool), inside)
        return g, inside

    def side_of(self, points: np.ndarray, below: float, above: float) -> np.ndarray:
        """(...,) int8: where the signed distance :meth:`at_points` computes at ``points``
        (..., 3) lies: +1 above ``above``, −1 below ``below``, 0 between (metres) — the
        same answers as comparing its values, from voxels looked at only as far around
        each point as the answer needs (a point deep inside is below a small negative
        ``below`` long before its nearest surface voxel is found); the points the first
        :data:`AT_POINTS_FAR_RINGS` rings do not tell are given :meth:`at_points`."""
        from meshmocap.geometry._mesh_kernels import boundary_side_kernel

        P, lead = _query_points(points)
        g, inside = self._voxel_points(P)
        out = np.empty(len(g), dtype=np.int8)
        low, high = float(below), float(above)
        boundary_side_kernel(g, self._inner, inside, self._h, low, high, AT_POINTS_FAR_RINGS, out)
        rest = np.flatnonzero(out == 2)
        if len(rest):
            sd = self.at_points(P.reshape(-1, 3)[rest])
            out[rest] = np.where(sd > high, 1, np.where(sd < low, -1, 0))
        return out.reshape(lead)

    def _cells(self, base: np.ndarray) -> np.ndarray:
        # known is checked per cell, not per corner: 8× fewer flags to read on a lookup
        todo = base[~self._cell_known[base]]
        if todo.size:
            self._gather((todo[:, None] + self._corners).ravel())
            self._cell_known[todo] = True
        return self._flat[self._corners[:, None] + base]

    def _gather(self, idx: np.ndarray) -> np.ndarray:
        new = idx[~self._known[idx]]
        if new.size:
            t0 = time.perf_counter()
            new = _unique(new)
            ijk = np.empty((len(new), 3), dtype=np.intp)  # np.unravel_index, into one array
            ijk[:, 0], rest = np.divmod(new, self._strides[0])
            ijk[:, 1], ijk[:, 2] = np.divmod(rest, self._strides[1])
            ijk *= self._stride
            ijk -= self._pad  # voxel indices of the grid points
            e = self._tree.query(ijk.astype(np.float64), k=1)[0]
            n = self._occ.shape
            ok = np.all((ijk >= 0) & (ijk < n), axis=1)
            inside = np.zeros(len(new), dtype=bool)
            inside[ok] = self._occ.reshape(-1)[np.ravel_multi_index(tuple(ijk[ok].T), n)]
            self._flat[new] = np.where(inside, -0.5 - e, e - 0.5) * self._h  # as signed_distance
            self._known[new] = True
            self.n_evaluated += len(new)
            self.seconds += time.perf_counter() - t0
        return self._flat[idx]


def _query_points(points) -> tuple[np.ndarray, tuple[int, ...]]:
    """``points`` (..., 3) as float64 and their leading shape; one line if not finite."""
    P = np.asarray(points, dtype=np.float64)
    if P.shape[-1:] != (3,):
        raise InputError(f"points: expected shape (..., 3), found {P.shape}")
    if not np.all(np.isfinite(P)):
        raise InputError("points: expected finite coordinates, found NaN or infinity")
    return P, P.shape[:-1]


def _unique(a: np.ndarray) -> np.ndarray:
    """``np.unique`` of a 1-D integer array by sorting: numpy 2's hash-based unique costs
    10–15× more on the few hundred to 20 k indices of a lookup (0.7 ms against 50 µs at 5 k)."""
    a = np.sort(a)
    return a[np.concatenate(([True], a[1:] != a[:-1]))]


def _voxelize(V: np.ndarray, F: np.ndarray, origin: np.ndarray, h: float, n) -> np.ndarray:
    """Occupancy (nx, ny, nz) of voxel centres by the non-zero winding rule along +z.

    Each vertical line through a column of voxel centres is crossed with the triangles
    covering it in the xy-plane (edge functions made exactly antisymmetric by evaluating
    every edge from its lower vertex index, and a top-left ownership rule for lines
    through edges or vertices, so that each crossing of a closed surface counts once);
    each crossing adds ±1 (by the triangle's facing) to the voxels above it, and a
    cumulative sum gives the winding number.
    """
    nx, ny, nz = (int(k) for k in n)
    G = (V - origin) / h  # grid units; same value for a vertex in every triangle
    F = np.asarray(F, dtype=np.int64)
    xy = G[:, :2]
    e = xy[F[:, [1, 2, 0]]] - xy[F]  # (m, 3, 2) edge vectors
    area2 = e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]  # twice the signed xy area
    ccw = area2 > 0
    F = np.where(ccw[:, None], F, F[:, [0, 2, 1]])
    weight = np.where(ccw, -1, 1)[area2 != 0]  # entering through a down-facing triangle: +1
    F = F[area2 != 0]
    T = G[F]
    lo = np.maximum(np.ceil(T[:, :, :2].min(axis=1)), 0).astype(np.int64)
    hi = np.minimum(np.floor(T[:, :, :2].max(axis=1)), [nx - 1, ny - 1]).astype(np.int64)
    size = np.clip(hi - lo + 1, 0, None)
    count = size[:, 0] * size[:, 1]
    acc = np.zeros(nx * ny * (nz + 1), dtype=np.int64)
    ids = np.flatnonzero(count)
    splits = np.searchsorted(np.cumsum(count[ids]), np.arange(_CHUNK, count[ids].sum(), _CHUNK))
    for chunk in np.split(ids, splits + 1):
        if chunk.size == 0:
            continue
        c = count[chunk]
        t = np.repeat(chunk, c)
        k = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)
        px = lo[t, 0] + k % size[t, 0]
        py = lo[t, 1] + k // size[t, 0]
        Et = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            ia, ib = F[t, a], F[t, b]
            swap = ia > ib
            p = np.where(swap[:, None], xy[ib], xy[ia])
            q = np.where(swap[:, None], xy[ia], xy[ib])
            val = (q[:, 0] - p[:, 0]) * (py - p[:, 1]) - (q[:, 1] - p[:, 1]) * (px - p[:, 0])
            val = np.where(swap, -val, val)
            d = xy[ib] - xy[ia]
            owns = (d[:, 1] < 0) | ((d[:, 1] == 0) & (d[:, 0] < 0))
            Et.append((val, (val > 0) | ((val == 0) & owns)))
        hit = Et[0][1] & Et[1][1] & Et[2][1]
        w0, w1, w2 = Et[1][0][hit], Et[2][0][hit], Et[0][0][hit]  # opposite vertices 0, 1, 2
        th = t[hit]
        zc = (w0 * T[th, 0, 2] + w1 * T[th, 1, 2] + w2 * T[th, 2, 2]) / (w0 + w1 + w2)
        kz = np.clip(np.floor(zc) + 1, 0, nz).astype(np.int64)
        flat = (px[hit] * ny + py[hit]) * (nz + 1) + kz
        acc += np.bincount(flat, weights=weight[th], minlength=acc.size).astype(np.int64)
    winding = np.cumsum(acc.reshape(nx, ny, nz + 1)[:, :, :nz], axis=2)
    return winding != 0


def distance_grid_from_mesh(
    V: np.ndarray, F: np.ndarray, *, spacing: float = 0.01, margin: float = 0.05
) -> DistanceGrid:
    """Return the signed distance field of a closed triangle mesh (negative inside).

    The mesh is scan-converted into voxel occupancy (non-zero winding number along
    vertical lines, so overlapping parts are united and either orientation works), then
    :func:`signed_distance` is applied. Accuracy: the surface is represented by voxel
    centres, so values are within about one voxel of the true signed distance (1.2 voxels
    at worst on the bundled template's vertices at 1 cm); parts thinner than a voxel may
    vanish, and voxel centres exactly on the surface may fall either side.

    Parameters
    ----------
    V : (n, 3) float64
        Vertices, metres, world frame (Z up).
    F : (m, 3) int
        Triangles of a closed mesh (consistently oriented).
    spacing : float
        Grid spacing, metres.
    margin : float
        Space around the mesh's bounding box, metres (at least one voxel is used).

    Returns
    -------
    DistanceGrid
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0 or not np.all(np.isfinite(V)):
        raise InputError(f"V: expected finite (n, 3) vertices with n > 0, found {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0 or not np.issubdtype(F.dtype, np.integer):
        raise InputError(f"F: expected (m, 3) integer faces with m > 0, found {F.shape}")
    if F.min() < 0 or F.max() >= len(V):
        raise InputError(f"F: indices must lie in [0, {len(V) - 1}], found [{F.min()}, {F.max()}]")
    h = float(spacing)
    if not np.isfinite(h) or h <= 0:
        raise InputError(f"spacing: expected a positive number of metres, found {spacing!r}")
    if not np.isfinite(margin) or margin < 0:
        raise InputError(f"margin: expected a non-negative number of metres, found {margin!r}")
    m = max(float(margin), h)
    origin = V.min(axis=0) - m
    n = np.ceil((V.max(axis=0) + m - origin) / h).astype(np.int64) + 1
    if np.prod(n) > _MAX_VOXELS:
        raise InputError(
            f"spacing: {n[0]}×{n[1]}×{n[2]} grid points is too many; use a coarser one"
        )
    occ = _voxelize(V, F, origin, h, n)
    if not occ.any():
        raise InputError("F: the mesh encloses no grid point (open, flat or too thin)")
    return DistanceGrid(signed_distance(occ, h), origin, h)
