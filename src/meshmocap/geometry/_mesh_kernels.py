"""Compiled loops (numba) behind :mod:`meshmocap.geometry.mesh` and its neighbours (the
silhouette fill, the ARAP refinement, :func:`~meshmocap.geometry.camera.in_view`), imported
on first use, so that importing the geometry layer does not import numba."""

from __future__ import annotations

import numpy as np

from meshmocap._numba import njit
from meshmocap._tolerances import DEPTH_FLOOR, NORM_FLOOR, UNDERFLOW_FLOOR


@njit(cache=True, nogil=True)
def normals_at_kernel(V, F, slot, k):  # pragma: no cover - compiled
    """(k, 3) area-weighted normal sums of the vertices with ``slot[v] ≥ 0`` (their row),
    added corner by corner (every face's first corner, then second, third) as
    :func:`~meshmocap.geometry.mesh.vertex_normals` adds them, with the same face normals
    ``(V1 − V0) × (V2 − V0)``."""
    out = np.zeros((k, 3))
    for c in range(3):
        for f in range(F.shape[0]):
            s = slot[F[f, c]]
            if s < 0:
                continue
            i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
            a0, a1, a2 = V[i1, 0] - V[i0, 0], V[i1, 1] - V[i0, 1], V[i1, 2] - V[i0, 2]
            b0, b1, b2 = V[i2, 0] - V[i0, 0], V[i2, 1] - V[i0, 1], V[i2, 2] - V[i0, 2]
            out[s, 0] += a1 * b2 - a2 * b1
            out[s, 1] += a2 * b0 - a0 * b2
            out[s, 2] += a0 * b1 - a1 * b0
    return out


@njit(cache=True, nogil=True)
def arap_rotations_kernel(V, E, D0, G, T, iterations):  # pragma: no cover - compiled
    """(n, 3, 3): each vertex's rotation of its neighbourhood from rest to ``V``: the
    rotational part of ``Aᵢ = Σ_j (vᵢ − vⱼ)(rᵢ − rⱼ)ᵀ`` over its edges ``E`` (e, 2) with
    rest vectors ``D0`` (e, 3). It starts from the rotation a rigid turn would have:
    ``Tᵢ`` (n, 3, 3) holds the rest neighbourhood's principal axes (its two widest first,
    the normal last, a right-handed frame), ``Gᵢ`` (n, 3, 2) the first two divided by their
    spread, so that ``Aᵢ Gᵢ`` are the turned axes; made orthonormal (Gram–Schmidt) they
    give ``Rᵢ Tᵢ``. Then ``iterations`` of Müller et al. 2016's update
    (:func:`~meshmocap.geometry.refine.rotational_part`) turn it to ``Aᵢ``'s polar
    rotation."""
    n = V.shape[0]
    A = np.zeros((n, 3, 3))
    for e in range(E.shape[0]):
        i, j = E[e, 0], E[e, 1]
        for r in range(3):
            d = V[i, r] - V[j, r]
            for c in range(3):
                x = d * D0[e, c]
                A[i, r, c] += x
                A[j, r, c] += x
    out = np.empty((n, 3, 3))
    Q = np.empty((3, 3))
    M = np.empty((3, 3))
    for v in range(n):
        x0 = x1 = x2 = y0 = y1 = y2 = 0.0
        for c in range(3):
            x0 += A[v, 0, c] * G[v, c, 0]
            x1 += A[v, 1, c] * G[v, c, 0]
            x2 += A[v, 2, c] * G[v, c, 0]
            y0 += A[v, 0, c] * G[v, c, 1]
            y1 += A[v, 1, c] * G[v, c, 1]
            y2 += A[v, 2, c] * G[v, c, 1]
        t = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2) + UNDERFLOW_FLOOR
        x0, x1, x2 = x0 / t, x1 / t, x2 / t
        p = x0 * y0 + x1 * y1 + x2 * y2
        y0, y1, y2 = y0 - p * x0, y1 - p * x1, y2 - p * x2
        u = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2) + UNDERFLOW_FLOOR
        y0, y1, y2 = y0 / u, y1 / u, y2 / u
        M[0, 0], M[1, 0], M[2, 0] = x0, x1, x2
        M[0, 1], M[1, 1], M[2, 1] = y0, y1, y2
        M[0, 2], M[1, 2], M[2, 2] = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
        for a in range(3):  # R = (R T) Tᵀ
            for b in range(3):
                out[v, a, b] = M[a, 0] * T[v, b, 0] + M[a, 1] * T[v, b, 1] + M[a, 2] * T[v, b, 2]
        for _ in range(iterations):
            w0 = w1 = w2 = 0.0
            den = 0.0
            for c in range(3):  # Σ_c r_c × a_c and Σ_c r_c · a_c
                r0, r1, r2 = out[v, 0, c], out[v, 1, c], out[v, 2, c]
                a0, a1, a2 = A[v, 0, c], A[v, 1, c], A[v, 2, c]
                w0 += r1 * a2 - r2 * a1
                w1 += r2 * a0 - r0 * a2
                w2 += r0 * a1 - r1 * a0
                den += r0 * a0 + r1 * a1 + r2 * a2
            den = abs(den) + UNDERFLOW_FLOOR
            w0, w1, w2 = w0 / den, w1 / den, w2 / den
            t = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            if t < NORM_FLOOR:
                break
            k0, k1, k2 = w0 / t, w1 / t, w2 / t
            s, c1 = np.sin(t), 1.0 - np.cos(t)
            # Rodrigues: I + s K + (1 − cos) K²
            Q[0, 0] = 1.0 - c1 * (k1 * k1 + k2 * k2)
            Q[1, 1] = 1.0 - c1 * (k0 * k0 + k2 * k2)
            Q[2, 2] = 1.0 - c1 * (k0 * k0 + k1 * k1)
            Q[0, 1] = -s * k2 + c1 * k0 * k1
            Q[1, 0] = s * k2 + c1 * k0 * k1
            Q[0, 2] = s * k1 + c1 * k0 * k2
            Q[2, 0] = -s * k1 + c1 * k0 * k2
            Q[1, 2] = -s * k0 + c1 * k1 * k2
            Q[2, 1] = s * k0 + c1 * k1 * k2
            for a in range(3):
                for b in range(3):
                    M[a, b] = (
                        Q[a, 0] * out[v, 0, b] + Q[a, 1] * out[v, 1, b] + Q[a, 2] * out[v, 2, b]
                    )
            out[v] = M
    return out


@njit(cache=True, nogil=True)
def arap_rhs_kernel(R, E, D0, n):  # pragma: no cover - compiled
    """(n, 3): Σ over each vertex's edges of ``±½ (Rᵢ + Rⱼ)(rᵢ − rⱼ)`` (ARAP's global step,
    Sorkine & Alexa 2007 Eq. 9), + at an edge's first vertex, − at its second."""
    b = np.zeros((n, 3))
    for e in range(E.shape[0]):
        i, j = E[e, 0], E[e, 1]
        for r in range(3):
            x = 0.0
            for c in range(3):
                x += 0.5 * (R[i, r, c] + R[j, r, c]) * D0[e, c]
            b[i, r] += x
            b[j, r] -= x
    return b


@njit(cache=True, nogil=True)
def _maximum(a, b):  # pragma: no cover - compiled
    """``np.maximum`` of two floats: NaN where either is."""
    if a != a or b != b:
        return np.nan
    return a if a >= b else b


@njit(cache=True, nogil=True)
def _minimum(a, b):  # pragma: no cover - compiled
    """``np.minimum`` of two floats: NaN where either is."""
    if a != a or b != b:
        return np.nan
    return a if a <= b else b


@njit(cache=True, nogil=True)
def fill_kernel(uv, F, valid, positive, floor, mask):  # pragma: no cover - compiled
    """Set, in ``mask`` (H, W) bool, the pixel centres covered by the triangles ``F``
    (m, 3) int64 of 2D vertices ``uv`` (n, 2) float64: the rule and the arithmetic of
    :func:`~meshmocap.geometry.silhouette.fill_triangles` (its triangles, edge bounds and
    spans, in the same floating-point operations), a triangle at a time. Skipped: a
    triangle with a vertex not ``valid`` (n,) bool, or a signed area not finite or not
    above ``floor`` (in absolute value unless ``positive``)."""
    H, W = mask.shape
    m = F.shape[0]
    ok = np.zeros(m, dtype=np.bool_)
    top = np.empty(m)
    bottom = np.empty(m)
    area = np.empty(m)
    xmin, xmax = np.inf, -np.inf
    for f in range(m):
        i0, i1, i2 = F[f, 0], F[f, 1], F[f, 2]
        x0, x1, x2 = uv[i0, 0], uv[i1, 0], uv[i2, 0]
        y0, y1, y2 = uv[i0, 1], uv[i1, 1], uv[i2, 1]
        a = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if not np.isfinite(a):
            continue
        if positive:
            if not a > floor:
                continue
        elif not abs(a) > floor:
            continue
        if not (valid[i0] and valid[i1] and valid[i2]):
            continue
        t = _maximum(np.ceil(_minimum(_minimum(y0, y1), y2)), 0.0)
        b = _minimum(np.floor(_maximum(_maximum(y0, y1), y2)), H - 1.0)
        if not b >= t:
            continue
        ok[f], top[f], bottom[f], area[f] = True, t, b, a
        xmin = min(xmin, _minimum(_minimum(x0, x1), x2))
        xmax = max(xmax, _maximum(_maximum(x0, x1), x2))
    if xmin > xmax:  # no triangle
        return
    c0 = max(np.ceil(xmin), 0.0)
    c1 = min(np.floor(xmax), W - 1.0)
    if c1 < c0:
        return
    xs = np.empty(3)
    ys = np.empty(3)
    s = np.empty(3)
    lower = np.empty(3, dtype=np.bool_)
    upper = np.empty(3, dtype=np.bool_)
    for f in range(m):
        if not ok[f]:
            continue
        for i in range(3):
            xs[i], ys[i] = uv[F[f, i], 0], uv[F[f, i], 1]
        pos = area[f] > 0
        for i in range(3):  # edge i: vertex i to i + 1 (silhouette._edge_bounds)
            j = (i + 1) % 3
            dy = ys[j] - ys[i]
            s[i] = 0.0 if dy == 0 else (xs[j] - xs[i]) / dy
            lower[i] = dy < 0 if pos else dy > 0
            upper[i] = dy > 0 if pos else dy < 0
        # the first and the last edge of each kind (the same where there is one)
        lf = 0 if lower[0] else (1 if lower[1] else 2)
        ll = 2 if lower[2] else (1 if lower[1] else 0)
        uf = 0 if upper[0] else (1 if upper[1] else 2)
        ul = 2 if upper[2] else (1 if upper[1] else 0)
        for r in range(int(bottom[f] - top[f]) + 1):
            row = top[f] + r
            left = _maximum(xs[lf] + (row - ys[lf]) * s[lf], xs[ll] + (row - ys[ll]) * s[ll])
            right = _minimum(xs[uf] + (row - ys[uf]) * s[uf], xs[ul] + (row - ys[ul]) * s[ul])
            a = _maximum(np.ceil(left), c0)
            b = _minimum(np.floor(right), c1)
            if a <= b:
                y = int(row)
                for x in range(int(a), int(b) + 1):
                    mask[y, x] = True


#: Relative slack taken off the least distance a voxel centre not looked at yet can have
#: (``r + ½`` after ring ``r``, :func:`boundary_side_kernel`): the rounding of the distances
#: summed (a few 1e-16 relative) cannot bring one below it.
RING_BOUND_SLACK = 1e-9


@njit(cache=True, nogil=True)
def _searchable(g0, g1, g2):  # pragma: no cover - compiled
    """Whether a point (voxel units) is finite and not far beyond any grid."""
    if not (np.isfinite(g0) and np.isfinite(g1) and np.isfinite(g2)):
        return False
    return max(abs(g0), abs(g1), abs(g2)) <= 1e9


@njit(cache=True, nogil=True)
def _ring_nearest(g0, g1, g2, c0, c1, c2, r, mask, best):  # pragma: no cover - compiled
    """The least of ``best`` and the squared distances from ``(g0, g1, g2)`` to the voxel
    centres of ``mask`` on ring ``r`` around voxel ``(c0, c1, c2)`` (those at Chebyshev
    distance ``r``), summed axis by axis as a k-d tree sums them."""
    nx, ny, nz = mask.shape
    for i in range(max(c0 - r, 0), min(c0 + r, nx - 1) + 1):
        di = abs(i - c0)
        for j in range(max(c1 - r, 0), min(c1 + r, ny - 1) + 1):
            dij = max(di, abs(j - c1))
            if dij == r:  # on the ring: every k
                k0, k1, step = c2 - r, c2 + r, 1
            else:  # inside it: its two faces only
                k0, k1, step = c2 - r, c2 + r, 2 * r
            k = k0
            while k <= k1:
                if 0 <= k < nz and mask[i, j, k]:
                    a0 = g0 - i
                    a1 = g1 - j
                    a2 = g2 - k
                    d = a0 * a0
                    d += a1 * a1
                    d += a2 * a2
                    if d < best:
                        best = d
                if step == 0:
                    break
                k += step
    return best


@njit(cache=True, nogil=True)
def boundary_distance_kernel(g, mask, rings, out):  # pragma: no cover - compiled
    """``out[t]`` ← the distance from ``g[t]`` (voxel units) to the nearest voxel centre
    of ``mask`` (nx, ny, nz) bool (centres at integer coordinates), squared distances
    summed axis by axis as a k-d tree sums them; NaN where the voxels within ``rings``
    rings of the nearest voxel do not settle it (a voxel beyond ring ``r`` is farther than
    ``r + ½``)."""
    for t in range(g.shape[0]):
        out[t] = np.nan
        g0, g1, g2 = g[t, 0], g[t, 1], g[t, 2]
        if not _searchable(g0, g1, g2):
            continue
        c0, c1, c2 = int(np.floor(g0 + 0.5)), int(np.floor(g1 + 0.5)), int(np.floor(g2 + 0.5))
        best = np.inf
        for r in range(rings + 1):
            best = _ring_nearest(g0, g1, g2, c0, c1, c2, r, mask, best)
            h = r + 0.5
            if best <= h * h:
                out[t] = np.sqrt(best)
                break


@njit(cache=True, nogil=True)
def boundary_side_kernel(g, mask, inside, h, below, above, rings, out):  # pragma: no cover
    """``out[t]`` ← where the signed distance at ``g[t]`` (voxel units) lies: +1 above
    ``above``, −1 below ``below``, 0 between (metres), 2 where ``rings`` rings do not tell.
    The signed distance is :func:`boundary_distance_kernel`'s distance ``e`` to the nearest
    voxel centre of ``mask`` made ``(−½ − e) h`` where ``inside[t]``, else ``(e − ½) h``
    (:meth:`~meshmocap.geometry.distance_field.LazyDistanceGrid.at_points`). The same
    rings are searched, but only until the answer is known: from the nearest centre found
    so far and the least distance of any centre not looked at yet (``r + ½`` after ring
    ``r``, less :data:`RING_BOUND_SLACK` for the rounding of the distances summed), since the signed
    distance's rounded arithmetic is monotone in ``e``; where the distance is settled, from
    it, as ``at_points`` compares it."""
    for t in range(g.shape[0]):
        out[t] = 2
        g0, g1, g2 = g[t, 0], g[t, 1], g[t, 2]
        if not _searchable(g0, g1, g2):
            continue
        c0, c1, c2 = int(np.floor(g0 + 0.5)), int(np.floor(g1 + 0.5)), int(np.floor(g2 + 0.5))
        best = np.inf
        for r in range(rings + 1):
            best = _ring_nearest(g0, g1, g2, c0, c1, c2, r, mask, best)
            bound = r + 0.5
            if best <= bound * bound:  # settled: the distance itself
                e = np.sqrt(best)
                sd = (-0.5 - e) * h if inside[t] else (e - 0.5) * h
                out[t] = 1 if sd > above else (-1 if sd < below else 0)
                break
            far = np.sqrt(best)  # the distance lies between near and far
            near = bound * (1.0 - RING_BOUND_SLACK)
            if inside[t]:
                lo, hi = (-0.5 - far) * h, (-0.5 - near) * h
            else:
                lo, hi = (near - 0.5) * h, (far - 0.5) * h
            if lo > above:
                out[t] = 1
                break
            if hi < below:
                out[t] = -1
                break
            if lo >= below and hi <= above:
                out[t] = 0
                break


@njit(cache=True, nogil=True)
def occupied_kernel(g, occ, out):  # pragma: no cover - compiled
    """In place, ``out`` (n,) bool: whether ``occ`` (a, b, c) bool holds the voxel of each
    point ``g`` (n, 3) (voxel units: the voxel of its coordinates rounded half to even, as
    ``np.round``), False beyond the grid."""
    n0, n1, n2 = occ.shape
    for t in range(g.shape[0]):
        i, j, k = np.rint(g[t, 0]), np.rint(g[t, 1]), np.rint(g[t, 2])
        out[t] = (0 <= i < n0 and 0 <= j < n1 and 0 <= k < n2) and occ[int(i), int(j), int(k)]


@njit(cache=True, nogil=True)
def in_image_kernel(Xc, cam, ok):  # pragma: no cover - compiled
    """In place, ``ok`` (n,) bool and-ed with whether a camera sees each point
    (:func:`~meshmocap.geometry.camera.in_view`): camera-frame points ``Xc`` (n, 3)
    (``X @ R.T + t``) at positive depth that project into the image (``0 ≤ u ≤ width``,
    ``0 ≤ v ≤ height``), the camera given as ``cam`` (12,) float64: ``K[0, 0], K[0, 1],
    K[0, 2], K[1, 1], K[1, 2]``, the distortion ``k1, k2, p1, p2, k3``, ``width, height``.
    The operations of :meth:`~meshmocap.geometry.camera.Camera.project` in the same order;
    points already False are skipped."""
    fx, skew, cx, fy, cy = cam[0], cam[1], cam[2], cam[3], cam[4]
    k1, k2, p1, p2, k3 = cam[5], cam[6], cam[7], cam[8], cam[9]
    width, height = cam[10], cam[11]
    distort = k1 != 0 or k2 != 0 or p1 != 0 or p2 != 0 or k3 != 0
    for i in range(Xc.shape[0]):
        if not ok[i]:
            continue
        depth = Xc[i, 2]
        safe = DEPTH_FLOOR if np.abs(depth) < DEPTH_FLOOR else depth
        x = Xc[i, 0] / safe
        y = Xc[i, 1] / safe
        if distort:
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            x, y = (
                x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
            )
        u = fx * x + skew * y + cx
        v = fy * y + cy
        ok[i] = depth > 0 and u >= 0 and u <= width and v >= 0 and v <= height


#: Relative margin by which :func:`farther_kernel`'s cells exceed the radius: rounding
#: never puts a point within the radius two cells away.
CELL_MARGIN = 1e-6
#: Relative slack below the squared radius under which :func:`farther_kernel` takes a
#: point as surely within the radius: the square root of such a sum cannot round past it.
SURE_SLACK = 1e-9


@njit(cache=True, nogil=True)
def farther_kernel(Y, X, r, bounded, max_cells, out):  # pragma: no cover - compiled
    """In place, ``out`` (m,) bool: whether each point of ``Y`` (m, 3) lies farther than
    ``r`` from every point of ``X`` (n ≥ 1, 3), finite. ``X`` is sorted by cell of a grid
    over its box, cubic cells of side a little over ``r`` (doubled until there are at most
    ``max_cells``); a point looks into its cell and the 26 around it, its own first, and
    stops at the first point surely within ``r``. Squared distances as pykdtree sums them
    (``(dx² + dy²) + dz²``), so the answer is pykdtree's ``d > r`` of a nearest-neighbour
    query: with ``distance_upper_bound=r`` where ``bounded`` (its bound is strict on the
    squared distance; a miss: ``d = ∞``), of an unbounded one (``d``, the square root of
    the least squared distance) otherwise."""
    n = X.shape[0]
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        lo[a] = X[0, a]
        hi[a] = X[0, a]
    for s in range(1, n):
        for a in range(3):
            lo[a] = min(lo[a], X[s, a])
            hi[a] = max(hi[a], X[s, a])
    cell = r * (1.0 + CELL_MARGIN)
    dims = np.empty(3, dtype=np.int64)
    while True:
        total = 1.0
        for a in range(3):
            total *= np.floor((hi[a] - lo[a]) / cell) + 1.0
        if total <= max_cells:
            break
        cell *= 2.0
    for a in range(3):
        dims[a] = int(np.floor((hi[a] - lo[a]) / cell)) + 1
    nx, ny, nz = dims[0], dims[1], dims[2]
    key = np.empty(n, dtype=np.int64)
    cstart = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    for s in range(n):
        i = min(int(np.floor((X[s, 0] - lo[0]) / cell)), nx - 1)
        j = min(int(np.floor((X[s, 1] - lo[1]) / cell)), ny - 1)
        k = min(int(np.floor((X[s, 2] - lo[2]) / cell)), nz - 1)
        key[s] = (i * ny + j) * nz + k
        cstart[key[s] + 1] += 1
    for c in range(nx * ny * nz):
        cstart[c + 1] += cstart[c]
    fill = cstart[:-1].copy()
    Xs = np.empty((n, 3))
    for s in range(n):  # counting sort by cell
        u = fill[key[s]]
        fill[key[s]] += 1
        for a in range(3):
            Xs[u, a] = X[s, a]
    r2 = r * r
    sure = r2 * (1.0 - SURE_SLACK)
    for t in range(Y.shape[0]):
        y0, y1, y2 = Y[t, 0], Y[t, 1], Y[t, 2]
        f0 = (y0 - lo[0]) / cell
        f1 = (y1 - lo[1]) / cell
        f2 = (y2 - lo[2]) / cell
        if not (-1.0 <= f0 < nx + 1.0 and -1.0 <= f1 < ny + 1.0 and -1.0 <= f2 < nz + 1.0):
            out[t] = True  # no cell of the grid within one cell
            continue
        g0, g1, g2 = int(np.floor(f0)), int(np.floor(f1)), int(np.floor(f2))
        best = np.inf
        for o in range(27):
            # o = 0 is the point's own cell, then the 26 around it
            a = (o + 13) % 27
            i, j, k = g0 + a // 9 - 1, g1 + (a // 3) % 3 - 1, g2 + a % 3 - 1
            if i < 0 or i >= nx or j < 0 or j >= ny or k < 0 or k >= nz:
                continue
            c = (i * ny + j) * nz + k
            for s in range(cstart[c], cstart[c + 1]):
                dx = Xs[s, 0] - y0
                dy = Xs[s, 1] - y1
                dz = Xs[s, 2] - y2
                d2 = (dx * dx + dy * dy) + dz * dz
                if d2 < best:
                    best = d2
                    if best < sure:
                        break
            if best < sure:
                break
        out[t] = (bounded and not best < r2) or np.sqrt(best) > r


#: Relative slack under which :func:`agreeing_kernel` still searches a box whose lower bound
#: on the squared distance, summed over the splits, reaches the search's bound: rounding in
#: that sum never prunes a point that lies within it.
PRUNE_SLACK = 1e-9


@njit(cache=True, nogil=True)
def point_tree_kernel(X, N, leaf_size):  # pragma: no cover - compiled
    """The k-d tree of :func:`~meshmocap.geometry.point_tree.point_tree` over ``X`` (n ≥ 1,
    3) with normals ``N`` (n, 3): a node's points split at the middle of their box's widest
    side until at most ``leaf_size`` are left (or they cannot be split). Returns the points
    and normals in tree order, ``order`` (n,) (the input index of each), ``rank`` (n,) (its
    inverse), per node ``start``, ``stop`` (its points' range), ``dim`` (the split's axis,
    −1 at a leaf), ``split`` (its value), ``left`` (the first child, the second after it)
    and the tree's depth."""
    n = X.shape[0]
    order = np.arange(n)
    start = np.empty(2 * n, dtype=np.int64)
    stop = np.empty(2 * n, dtype=np.int64)
    dim = np.full(2 * n, -1, dtype=np.int64)
    split = np.zeros(2 * n)
    left = np.full(2 * n, -1, dtype=np.int64)
    level = np.zeros(2 * n, dtype=np.int64)
    start[0], stop[0] = 0, n
    stack = np.empty(2 * n, dtype=np.int64)
    stack[0] = 0
    sp, nodes, depth = 1, 1, 0
    while sp > 0:
        sp -= 1
        node = stack[sp]
        a, b = start[node], stop[node]
        depth = max(depth, level[node])
        if b - a <= leaf_size:
            continue
        lo0, lo1, lo2 = X[order[a], 0], X[order[a], 1], X[order[a], 2]
        hi0, hi1, hi2 = lo0, lo1, lo2
        for s in range(a + 1, b):
            p = order[s]
            lo0, hi0 = min(lo0, X[p, 0]), max(hi0, X[p, 0])
            lo1, hi1 = min(lo1, X[p, 1]), max(hi1, X[p, 1])
            lo2, hi2 = min(lo2, X[p, 2]), max(hi2, X[p, 2])
        d, extent, mid = 0, hi0 - lo0, 0.5 * (lo0 + hi0)
        if hi1 - lo1 > extent:
            d, extent, mid = 1, hi1 - lo1, 0.5 * (lo1 + hi1)
        if hi2 - lo2 > extent:
            d, extent, mid = 2, hi2 - lo2, 0.5 * (lo2 + hi2)
        i, j = a, b - 1
        while i <= j:  # those below the middle first
            if X[order[i], d] < mid:
                i += 1
            else:
                order[i], order[j] = order[j], order[i]
                j -= 1
        if i <= a or i >= b:  # one point repeated, or a box one rounding step wide
            continue
        child = nodes
        nodes += 2
        start[child], stop[child] = a, i
        start[child + 1], stop[child + 1] = i, b
        level[child] = level[child + 1] = level[node] + 1
        dim[node], split[node], left[node] = d, mid, child
        stack[sp] = child
        stack[sp + 1] = child + 1
        sp += 2
    Xs = np.empty((n, 3))
    Ns = np.empty((n, 3))
    rank = np.empty(n, dtype=np.int64)
    for s in range(n):
        p = order[s]
        rank[p] = s
        for c in range(3):
            Xs[s, c] = X[p, c]
            Ns[s, c] = N[p, c]
    return (
        Xs,
        Ns,
        order,
        rank,
        start[:nodes].copy(),
        stop[:nodes].copy(),
        dim[:nodes].copy(),
        split[:nodes].copy(),
        left[:nodes].copy(),
        depth,
    )


@njit(cache=True, nogil=True)
def agreeing_kernel(
    Xs,
    Ns,
    order,
    rank,
    start,
    stop,
    dim,
    split,
    left,
    depth,
    Q,
    NQ,
    hint,
    k,
    max_distance,
    normal_cos,
):  # pragma: no cover - compiled
    """``partner`` (q,) int64, per query point ``Q[t]`` (normal ``NQ[t]``): the point of
    :func:`~meshmocap.geometry.point_tree.nearest_agreeing` (its input index, ``order`` of
    its tree position), −1 where none. One depth-first search per query, nearer child
    first, that keeps the ``k`` nearest points within ``max_distance`` in order of distance
    and prunes every box farther than the ``k``-th of them or the nearest agreeing one
    found (the answer cannot lie beyond either). ``hint[t]`` (an input index, ``rank`` its
    tree position; −1: none), a guess such as the previous answer: where it agrees, it
    bounds the search from the start. Squared distances as pykdtree sums them
    (``(dx² + dy²) + dz²``), a point within the bound where that sum is below
    ``max_distance²``."""
    m = Q.shape[0]
    partner = np.full(m, -1, dtype=np.int64)
    best_d = np.empty(k)
    best_s = np.empty(k, dtype=np.int64)
    stack = np.empty(depth + 2, dtype=np.int64)
    stack_d = np.empty(depth + 2)
    stack_off = np.empty((depth + 2, 3))
    keep = 1.0 - PRUNE_SLACK
    r2 = max_distance * max_distance
    for t in range(m):
        q0, q1, q2 = Q[t, 0], Q[t, 1], Q[t, 2]
        n0, n1, n2 = NQ[t, 0], NQ[t, 1], NQ[t, 2]
        count, bound, agreeing, skip = 0, r2, np.inf, -1
        if hint[t] >= 0:  # the guess, where it still agrees: the bound from the start
            s = rank[hint[t]]
            dx, dy, dz = Xs[s, 0] - q0, Xs[s, 1] - q1, Xs[s, 2] - q2
            d2 = (dx * dx + dy * dy) + dz * dz
            if d2 < r2 and (Ns[s, 0] * n0 + Ns[s, 1] * n1) + Ns[s, 2] * n2 > normal_cos:
                best_d[0], best_s[0], count, bound, agreeing, skip = d2, s, 1, d2, d2, s
        stack[0], stack_d[0] = 0, 0.0
        stack_off[0, 0] = stack_off[0, 1] = stack_off[0, 2] = 0.0
        sp = 1
        while sp > 0:
            sp -= 1
            node, rd = stack[sp], stack_d[sp]
            if rd * keep >= bound:
                continue
            o0, o1, o2 = stack_off[sp, 0], stack_off[sp, 1], stack_off[sp, 2]
            while dim[node] >= 0:  # down to the leaf on the query's side, the far sides kept
                d = dim[node]
                qd = q0 if d == 0 else (q1 if d == 1 else q2)
                od = o0 if d == 0 else (o1 if d == 1 else o2)
                diff = qd - split[node]
                near, far = (
                    (left[node], left[node] + 1) if diff < 0 else (left[node] + 1, left[node])
                )
                far_d = rd - od * od + diff * diff
                if far_d * keep < bound:
                    stack[sp], stack_d[sp] = far, far_d
                    stack_off[sp, 0], stack_off[sp, 1], stack_off[sp, 2] = o0, o1, o2
                    stack_off[sp, d] = diff
                    sp += 1
                node = near
            for s in range(start[node], stop[node]):
                if s == skip:
                    continue
                dx, dy, dz = Xs[s, 0] - q0, Xs[s, 1] - q1, Xs[s, 2] - q2
                d2 = (dx * dx + dy * dy) + dz * dz
                if not d2 < bound:
                    continue
                u = count if count < k else k - 1  # insert in order of distance
                while u > 0 and best_d[u - 1] > d2:
                    if u < k:
                        best_d[u], best_s[u] = best_d[u - 1], best_s[u - 1]
                    u -= 1
                best_d[u], best_s[u] = d2, s
                count = min(count + 1, k)
                if d2 < agreeing and (Ns[s, 0] * n0 + Ns[s, 1] * n1) + Ns[s, 2] * n2 > normal_cos:
                    agreeing = d2
                bound = min(agreeing, r2)
                if count == k:
                    bound = min(bound, best_d[k - 1])
        for u in range(count):  # the first that agrees among the k nearest
            s = best_s[u]
            if (Ns[s, 0] * n0 + Ns[s, 1] * n1) + Ns[s, 2] * n2 > normal_cos:
                partner[t] = order[s]
                break
    return partner
