"""Compiled loops (numba) behind the cage tracker's two most frequent evaluations.

* :func:`silhouette_residuals`, behind
  :meth:`~meshmocap.trackers.cage.residuals.SilhouetteCoverage.residuals`: every contour
  sample's nearest projected model point, found in a grid of cells half the outlier cap
  wide around the samples (a sample only looks at the cells within the cap; farther points
  are outliers, which cost nothing), then its residual and gradient, in one pass;
* :func:`quad_skinning_transforms`, behind
  :meth:`~meshmocap.trackers.cage.oqr_skinning.QuadSkinning.transforms`: the rig's joint
  frames from the quads' (a few dozen 3 × 3 products and one small Procrustes fit).

Both are the array code they replace written as loops, to rounding
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

__all__ = ["quad_skinning_transforms", "silhouette_residuals"]


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
                if bi >= 0 and np.sqrt(best) <= ring * cell:
                    break  # a point in a farther ring lies at least ring · cell away
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
