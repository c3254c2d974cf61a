"""Compiled loops (numba) behind the cage tracker's most frequent evaluations.

* :func:`silhouette_residuals`, behind
  :meth:`~meshmocap.trackers.cage.residuals.SilhouetteCoverage.residuals`: every contour
  sample's nearest projected model point, found in a grid of cells half the outlier cap
  wide around the samples (a sample only looks at the cells within the cap; farther points
  are outliers, which cost nothing), then its residual and gradient, in one pass;
* :func:`quad_skinning_transforms`, behind
  :meth:`~meshmocap.trackers.cage.oqr_skinning.QuadSkinning.transforms`: the rig's joint
  frames from the quads' (a few dozen 3 × 3 products and one small Procrustes fit);
* :func:`local_normal_equations`, behind
  :meth:`~meshmocap.trackers.cage.surface.SkinnedSurface.local_normal_equations`: the
  local adjustment's ``Jᵀ r`` and ``Jᵀ J`` from the few quads each point row touches;
* :func:`skinned_directions`, behind
  :meth:`~meshmocap.trackers.cage.surface.SkinnedSurface.directions`: the points' motion
  along the latent shape's directions (Eq. 6), pair by pair;
* :func:`contour_pixels`, behind
  :class:`~meshmocap.trackers.cage.residuals.SilhouetteCoverage`: a mask's small pieces
  dropped and its contour pixels found, as ``ndimage.label`` and ``np.nonzero(m &
  ~ndimage.binary_erosion(m))`` find them, in that order;
* :func:`gram_schmidt_frames`, behind
  :func:`~meshmocap.trackers.cage.quad_frames.gram_schmidt`: the quads' frames from their
  axes, the same operations in the same order (the same numbers), called ~70 times a frame;
* :func:`skinned_points`, behind
  :meth:`~meshmocap.trackers.cage.surface.SkinnedSurface.points`: the sampled points'
  skinning, the sparse product summed in scipy's order (the same numbers).

Each is the array code it replaces written as loops, to rounding
(``tests/trackers/cage/test_kernels.py``): the tracker calls them tens of times a frame on a
few hundred points, where numpy's per-call overhead was most of the cost.

References
----------
- E. Duveau, S. Courtemanche, L. Reveret, E. Boyer, *Cage-based motion recovery
  using manifold learning*, International Conference on 3D Imaging, Modeling,
  Processing, Visualization and Transmission (3DIMPVT), 2012.
- W. Kabsch, *A solution for the best rotation to relate two sets of vectors*,
  Acta Crystallographica A32(5):922–923, 1976.
  https://doi.org/10.1107/S0567739476001873
"""

from __future__ import annotations

import numpy as np

from meshmocap._numba import njit
from meshmocap._tolerances import ANTIPARALLEL, DEGENERATE_AXIS, DIVISOR_FLOOR, NEAR_DEPTH

__all__ = [
    "contour_pixels",
    "gram_schmidt_frames",
    "local_normal_equations",
    "quad_skinning_transforms",
    "silhouette_residuals",
    "skinned_directions",
    "skinned_points",
]

#: Relative margin (of a cell's width) by which a nearest point must lie inside the square
#: of cells searched to end :func:`silhouette_residuals`' search: a projection's cell is
#: found by rounding, so one in a farther cell may lie by a hair nearer than its side.
_EDGE_SLACK = 1e-9


@njit(cache=True, nogil=True)
def silhouette_residuals(P, R, t, K, q, ptr, margin, cap):  # pragma: no cover - compiled
    """Residuals (n,) and directions (n, 3) of the silhouette coverage term (see
    :meth:`~meshmocap.trackers.cage.residuals.SilhouetteCoverage.residuals`) at model points
    ``P`` (n, 3) for views ``R`` (C, 3, 3), ``t`` (C, 3), ``K`` (C, 3, 3) and contour
    samples ``q`` (m, 2) grouped by view (view c's are ``q[ptr[c]:ptr[c + 1]]``); ``margin``
    and ``cap`` (> 0) in pixels. Ties of the nearest point go to the lowest index."""
    n = P.shape[0]
    rr = np.zeros(n)
    g = np.zeros((n, 3))
    cell = 0.5 * cap
    reach = int(np.ceil(cap / cell)) + 1  # rings of cells that can hold a point within cap
    u = np.empty(n)
    v = np.empty(n)
    zs = np.empty(n)
    xs = np.empty(n)
    ys = np.empty(n)
    slot = np.empty(n, dtype=np.int64)
    for c in range(R.shape[0]):
        s0, s1 = ptr[c], ptr[c + 1]
        if s1 == s0:
            continue
        x0, y0, x1, y1 = np.inf, np.inf, -np.inf, -np.inf
        for s in range(s0, s1):
            x0, x1 = min(x0, q[s, 0]), max(x1, q[s, 0])
            y0, y1 = min(y0, q[s, 1]), max(y1, q[s, 1])
        x0, y0, x1, y1 = x0 - cap, y0 - cap, x1 + cap, y1 + cap
        nx, ny = int((x1 - x0) / cell) + 1, int((y1 - y0) / cell) + 1
        count = np.zeros(nx * ny + 1, dtype=np.int64)
        Rc, tc = R[c], t[c]
        f, fy, cx, cy = K[c, 0, 0], K[c, 1, 1], K[c, 0, 2], K[c, 1, 2]
        for i in range(n):
            X0 = Rc[0, 0] * P[i, 0] + Rc[0, 1] * P[i, 1] + Rc[0, 2] * P[i, 2] + tc[0]
            X1 = Rc[1, 0] * P[i, 0] + Rc[1, 1] * P[i, 1] + Rc[1, 2] * P[i, 2] + tc[1]
            X2 = Rc[2, 0] * P[i, 0] + Rc[2, 1] * P[i, 1] + Rc[2, 2] * P[i, 2] + tc[2]
            z = max(X2, NEAR_DEPTH)
            u[i] = f * X0 / z + cx
            v[i] = fy * X1 / z + cy
            zs[i], xs[i], ys[i] = z, X0 / z, X1 / z
            slot[i] = -1
            if x0 <= u[i] < x1 and y0 <= v[i] < y1:
                ix = min(int((u[i] - x0) / cell), nx - 1)
                iy = min(int((v[i] - y0) / cell), ny - 1)
                slot[i] = iy * nx + ix
                count[slot[i] + 1] += 1
        for k in range(nx * ny):
            count[k + 1] += count[k]
        order = np.empty(count[nx * ny], dtype=np.int64)
        fill = count[:-1].copy()
        for i in range(n):  # by cell, ascending index within a cell
            if slot[i] >= 0:
                order[fill[slot[i]]] = i
                fill[slot[i]] += 1
        for s in range(s0, s1):
            qx, qy = q[s, 0], q[s, 1]
            ix, iy = int((qx - x0) / cell), int((qy - y0) / cell)
            best, bi = np.inf, -1
            for ring in range(reach + 1):
                for jy in range(iy - ring, iy + ring + 1):
                    if jy < 0 or jy >= ny:
                        continue
                    step = 1 if abs(jy - iy) == ring else 2 * ring
                    for jx in range(ix - ring, ix + ring + 1, max(step, 1)):
                        if jx < 0 or jx >= nx:
                            continue
                        k = jy * nx + jx
                        for o in range(count[k], count[k + 1]):
                            i = order[o]
                            d2 = (u[i] - qx) ** 2 + (v[i] - qy) ** 2
                            if d2 < best or (d2 == best and i < bi):
                                best, bi = d2, i
                # a point in a farther ring lies beyond the nearest side of the square of
                # cells searched (at least ring · cell away; by a hair less where rounding
                # put it in a cell)
                edge = min(
                    qx - x0 - (ix - ring) * cell,
                    (ix + ring + 1) * cell - (qx - x0),
                    qy - y0 - (iy - ring) * cell,
                    (iy + ring + 1) * cell - (qy - y0),
                )
                if bi >= 0 and np.sqrt(best) < edge - _EDGE_SLACK * cell:
                    break
            if bi < 0:
                continue
            d = np.sqrt(best)
            if d <= margin or d > cap:
                continue
            i = bi
            s_ = zs[i] / f  # metres per pixel at the point
            rho = (d - margin) * s_
            ex, ey = (u[i] - qx) / d, (v[i] - qy) / d  # image direction away from the sample
            # dρ/dX_cam = s (f / z) [e_x, e_y, −e·(x, y) / z] + (d − margin) / f [0, 0, 1]
            dz = (d - margin) / f - (ex * xs[i] + ey * ys[i])
            rr[i] += rho * rho
            for a in range(3):  # ρ ∂ρ/∂P, world frame
                g[i, a] += (ex * Rc[0, a] + ey * Rc[1, a] + dz * Rc[2, a]) * rho
    r = np.sqrt(rr)
    for i in range(n):
        if r[i] > 0:
            for a in range(3):
                g[i, a] /= r[i]
    return r, g


@njit(cache=True, nogil=True)
def contour_pixels(m, min_component, r0, c0):  # pragma: no cover - compiled
    """Rows and columns (k,) int64, plus ``r0`` and ``c0`` (where ``m`` lies in its image),
    of the contour of mask ``m`` (h, w) bool, row by row (``np.nonzero``'s order): the kept
    pixels with a 4-neighbour not kept or outside ``m`` (the pixels ``binary_erosion``,
    cross structure and border unset, clears). With ``min_component`` > 0 and more than one
    4-connected piece (``ndimage.label``'s), a piece is kept where its size is at least
    ``min_component`` times the largest's; else every set pixel is."""
    h, w = m.shape
    keep = m.copy()
    if min_component > 0:
        lab = np.zeros((h, w), dtype=np.int64)
        size = np.zeros(h * w + 1, dtype=np.int64)
        stack = np.empty(h * w, dtype=np.int64)
        n = 0
        for i in range(h):
            for j in range(w):
                if not m[i, j] or lab[i, j]:
                    continue
                n += 1
                lab[i, j] = n
                top, stack[0] = 1, i * w + j
                while top:
                    top -= 1
                    a, b = stack[top] // w, stack[top] % w
                    size[n] += 1
                    for da, db in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                        x, y = a + da, b + db
                        if 0 <= x < h and 0 <= y < w and m[x, y] and not lab[x, y]:
                            lab[x, y] = n
                            stack[top] = x * w + y
                            top += 1
        if n > 1:
            big = size[1 : n + 1].max()
            for i in range(h):
                for j in range(w):
                    if m[i, j] and not size[lab[i, j]] >= min_component * big:
                        keep[i, j] = False
    rows = np.empty(h * w, dtype=np.int64)
    cols = np.empty(h * w, dtype=np.int64)
    k = 0
    for i in range(h):
        for j in range(w):
            if keep[i, j] and (
                i == 0
                or j == 0
                or i == h - 1
                or j == w - 1
                or not keep[i - 1, j]
                or not keep[i + 1, j]
                or not keep[i, j - 1]
                or not keep[i, j + 1]
            ):
                rows[k], cols[k] = i + r0, j + c0
                k += 1
    return rows[:k], cols[:k]


@njit(cache=True, nogil=True)
def gram_schmidt_frames(a, b):  # pragma: no cover - compiled
    """Frames ``R = [u v u×v]`` (Q, 3, 3) of the axes ``a, b`` (Q, 3), as the array code of
    :func:`~meshmocap.trackers.cage.quad_frames.gram_schmidt` computes them: sums of
    squares and products left to right, the cross product's two products subtracted."""
    R = np.empty((a.shape[0], 3, 3))
    for q in range(a.shape[0]):
        a0, a1, a2 = a[q, 0], a[q, 1], a[q, 2]
        n = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        u0, u1, u2 = a0 / n, a1 / n, a2 / n
        b0, b1, b2 = b[q, 0], b[q, 1], b[q, 2]
        d = u0 * b0 + u1 * b1 + u2 * b2
        w0, w1, w2 = b0 - d * u0, b1 - d * u1, b2 - d * u2
        n = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        v0, v1, v2 = w0 / n, w1 / n, w2 / n
        R[q, 0, 0], R[q, 1, 0], R[q, 2, 0] = u0, u1, u2
        R[q, 0, 1], R[q, 1, 1], R[q, 2, 1] = v0, v1, v2
        R[q, 0, 2] = u1 * v2 - u2 * v1
        R[q, 1, 2] = u2 * v0 - u0 * v2
        R[q, 2, 2] = u0 * v1 - u1 * v0
    return R


@njit(cache=True, nogil=True)
def _turn(a, b):  # pragma: no cover - compiled
    """Smallest rotation (3, 3) turning direction ``a`` onto ``b`` (Rodrigues; antiparallel:
    π about an axis orthogonal to ``a``), as ``oqr_skinning``'s vectorised version."""
    a = a / np.sqrt(np.sum(a * a))
    b = b / np.sqrt(np.sum(b * b))
    v = np.cross(a, b)
    c = np.sum(a * b)
    R = np.eye(3)
    if c < -1 + ANTIPARALLEL:
        o = np.cross(a, np.array([1.0, 0.0, 0.0]))
        if np.sqrt(np.sum(o * o)) < DEGENERATE_AXIS:
            o = np.cross(a, np.array([0.0, 1.0, 0.0]))
        o = o / np.sqrt(np.sum(o * o))
        for i in range(3):
            for j in range(3):
                R[i, j] = 2 * o[i] * o[j] - (1.0 if i == j else 0.0)
        return R
    Kx = np.zeros((3, 3))
    Kx[0, 1], Kx[0, 2], Kx[1, 2] = -v[2], v[1], -v[0]
    Kx[1, 0], Kx[2, 0], Kx[2, 1] = v[2], -v[1], v[0]
    f = 1.0 / max(1.0 + c, DIVISOR_FLOOR)
    return R + Kx + (Kx @ Kx) * f


@njit(cache=True, nogil=True)
def quad_skinning_transforms(
    centres, rotations, P0, parents, own, own_quad, R0T, off, plan, fit_targets
):  # pragma: no cover - compiled
    """Skinning transforms (J, 3, 4) of a quad configuration (see
    :meth:`~meshmocap.trackers.cage.oqr_skinning.QuadSkinning.transforms`). ``plan`` (k, 3)
    int64 lists the quad-less joints in order, each with its kind (0: its parent's
    rotation, 1: the smallest turn onto its one target, 2: a Procrustes fit onto its
    targets) and its first target (kind 1) or the start of its targets in ``fit_targets``
    (kind 2, ended by −1); positions first, group by group, as the array version."""
    J = P0.shape[0]
    G = np.zeros((J, 3, 3))
    P = np.zeros((J, 3))
    for k in range(own.shape[0]):
        j, qd = own[k], own_quad[k]
        G[j] = rotations[qd] @ R0T[k]
        P[j] = centres[qd] + G[j] @ off[k]
    for k in range(plan.shape[0]):
        j, kind, a = plan[k, 0], plan[k, 1], plan[k, 2]
        p = parents[j]
        P[j] = P[p] + G[p] @ (P0[j] - P0[p])
        if kind == 0:
            G[j] = G[p]
        elif kind == 1:
            G[j] = _turn(G[p] @ (P0[a] - P0[j]), P[a] - P[j]) @ G[p]
        else:
            H = np.zeros((3, 3))
            o = a
            while fit_targets[o] >= 0:
                tj = fit_targets[o]
                H += np.outer(P0[tj] - P0[j], P[tj] - P[j])
                o += 1
            U, _, Vt = np.linalg.svd(H)
            D = np.eye(3)
            D[2, 2] = np.sign(np.linalg.det(Vt.T @ U.T))
            G[j] = Vt.T @ D @ U.T
    out = np.empty((J, 3, 4))
    for j in range(J):
        out[j, :, :3] = G[j]
        out[j, :, 3] = P[j] - G[j] @ P0[j]
    return out


@njit(cache=True, nogil=True)
def local_normal_equations(G, r, P, cp, Rp, ptr, quad, w, arm, n_quads):  # pragma: no cover
    """Gradient ``Jᵀ r`` (6 q + 6,) and Gauss–Newton matrix ``Jᵀ J`` of the local adjustment
    (see :meth:`~meshmocap.trackers.cage.surface.SkinnedSurface.local_normal_equations`),
    one point row at a time: row ``k = s n + i`` (block ``s`` of point gradients ``G``
    (S, n, 3), residuals ``r`` (S n,)) touches only the quads its point's pairs move with
    (pairs ``ptr[i]:ptr[i + 1]``: quad ``quad`` (0-based among the 20), weight ``w``,
    lever ``arm`` (m, 3) from the quad's centre, world frame) and the pelvis (the last 6
    columns: ``[(P_i − cp) × g, g]``), so each row adds a few 6 × 6 blocks, not a dense
    outer product of the 126 columns."""
    S, n = G.shape[0], G.shape[1]
    m6 = 6 * n_quads + 6
    H = np.zeros((m6, m6))
    grad = np.zeros(m6)
    qs = np.empty(16, dtype=np.int64)
    vs = np.empty((16, 6))
    for s in range(S):
        for i in range(n):
            k = s * n + i
            g0, g1, g2 = G[s, i, 0], G[s, i, 1], G[s, i, 2]
            nb = 0
            for e in range(ptr[i], ptr[i + 1]):
                b = quad[e]
                a0, a1, a2 = arm[e, 0], arm[e, 1], arm[e, 2]
                c0, c1, c2 = a1 * g2 - a2 * g1, a2 * g0 - a0 * g2, a0 * g1 - a1 * g0
                slot = -1
                for t in range(nb):
                    if qs[t] == b:
                        slot = t
                if slot < 0:
                    slot = nb
                    qs[nb] = b
                    for c in range(6):
                        vs[nb, c] = 0.0
                    nb += 1
                for c in range(3):  # w [Rpᵀ g, Rpᵀ (arm × g)]
                    vs[slot, c] += w[e] * (g0 * Rp[0, c] + g1 * Rp[1, c] + g2 * Rp[2, c])
                    vs[slot, 3 + c] += w[e] * (c0 * Rp[0, c] + c1 * Rp[1, c] + c2 * Rp[2, c])
            d0, d1, d2 = P[i, 0] - cp[0], P[i, 1] - cp[1], P[i, 2] - cp[2]
            qs[nb] = n_quads
            vs[nb, 0] = d1 * g2 - d2 * g1
            vs[nb, 1] = d2 * g0 - d0 * g2
            vs[nb, 2] = d0 * g1 - d1 * g0
            vs[nb, 3], vs[nb, 4], vs[nb, 5] = g0, g1, g2
            nb += 1
            rk = r[k]
            for ta in range(nb):
                oa = 6 * qs[ta]
                for c in range(6):
                    grad[oa + c] += vs[ta, c] * rk
                for tb in range(nb):
                    ob = 6 * qs[tb]
                    for c in range(6):
                        vc = vs[ta, c]
                        for d in range(6):
                            H[oa + c, ob + d] += vc * vs[tb, d]
    return grad, H


@njit(cache=True, nogil=True)
def skinned_directions(V, cw, Rp, R, dR, dc, pi, pb, pw, n):  # pragma: no cover - compiled
    """Point directions (k, n, 3) of the skinned surface along ``k`` configuration
    directions (see :meth:`~meshmocap.trackers.cage.surface.SkinnedSurface.directions`):
    pair ``e`` (point ``pi[e]``, world position ``V[e]``, weight ``pw[e]``) moving with quad
    ``b = pb[e] ≥ 1`` (world centre ``cw[b]``; pelvis-relative rotation ``R[b − 1]`` and its
    derivatives ``dR[b − 1]`` (k, 3, 3), centre derivatives ``dc[b − 1]`` (k, 3)) adds
    ``w Rp (dc + dR l)``, ``l`` its position in the quad's frame; pairs on the pelvis
    (``b = 0``) add nothing."""
    k = dR.shape[1]
    out = np.zeros((k, n, 3))
    x = np.empty(3)
    loc = np.empty(3)
    d = np.empty(3)
    for e in range(V.shape[0]):
        b = pb[e]
        if b <= 0:
            continue
        q = b - 1
        for a in range(3):  # (V − c_b) Rp: pelvis frame
            x[a] = (
                (V[e, 0] - cw[b, 0]) * Rp[0, a]
                + (V[e, 1] - cw[b, 1]) * Rp[1, a]
                + (V[e, 2] - cw[b, 2]) * Rp[2, a]
            )
        for a in range(3):  # quad frame: R_qᵀ x
            loc[a] = R[q, 0, a] * x[0] + R[q, 1, a] * x[1] + R[q, 2, a] * x[2]
        i, w = pi[e], pw[e]
        for j in range(k):
            for a in range(3):
                d[a] = (
                    dR[q, j, a, 0] * loc[0]
                    + dR[q, j, a, 1] * loc[1]
                    + dR[q, j, a, 2] * loc[2]
                    + dc[q, j, a]
                )
            for a in range(3):
                out[j, i, a] += w * (Rp[a, 0] * d[0] + Rp[a, 1] * d[1] + Rp[a, 2] * d[2])
    return out


@njit(cache=True, nogil=True)
def skinned_points(indptr, indices, data, A, n):  # pragma: no cover - compiled
    """``S @ A4`` of :func:`~meshmocap.body.skinning.apply_skinning` for one pose: the
    points (n, 3) from the skinning operator ``S`` (n, 4 J) in CSC form (``indptr``,
    ``indices``, ``data``) and the transforms ``A`` (J, 3, 4), summed in scipy's order
    (column by column, ``y_i += S_ij x_j``): the same numbers without its per-call cost."""
    out = np.zeros((n, 3))
    for col in range(indptr.shape[0] - 1):
        j, b = col // 4, col % 4
        x0, x1, x2 = A[j, 0, b], A[j, 1, b], A[j, 2, b]
        for e in range(indptr[col], indptr[col + 1]):
            i, s = indices[e], data[e]
            out[i, 0] += s * x0
            out[i, 1] += s * x1
            out[i, 2] += s * x2
    return out
