"""Closest points on triangle meshes: exact point–triangle distances, area-uniform surface
sampling and point-to-surface distance queries, as pure array functions.

``V`` : (n, 3) float64, metres; ``F`` : (m, 3) int triangles.

References
----------
- C. Ericson, *Real-Time Collision Detection*, Morgan Kaufmann, 2005.
"""

from __future__ import annotations

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import UNDERFLOW_FLOOR
from meshmocap.errors import InputError


def closest_points_on_triangles(
    P: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray
) -> np.ndarray:
    """Closest point of triangle ``(A[i], B[i], C[i])`` to ``P[i]``, for every ``i``.

    Exact (Ericson, *Real-Time Collision Detection*, §5.1.5: Voronoi regions of the
    vertices, edges and face), vectorised; degenerate triangles (zero area) fall back to the
    nearest of their three edges.

    ``P, A, B, C``: (n, 3) float64. Returns (n, 3) float64.
    """
    ab, ac, ap, bp, cp = B - A, C - A, P - A, P - B, P - C
    pairs = ((ab, ap), (ac, ap), (ab, bp), (ac, bp), (ab, cp), (ac, cp))
    d1, d2, d3, d4, d5, d6 = (np.einsum("ij,ij->i", u, v) for u, v in pairs)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        Q = A + ab * (vb / den)[:, None] + ac * (vc / den)[:, None]  # inside the face
        e43, e56 = d4 - d3, d5 - d6
        regions = [  # lowest priority first: later ones overwrite
            ((va <= 0) & (e43 >= 0) & (e56 >= 0), B + (C - B) * (e43 / (e43 + e56))[:, None]),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), A + ac * (d2 / (d2 - d6))[:, None]),
            ((d6 >= 0) & (d5 <= d6), C),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), A + ab * (d1 / (d1 - d3))[:, None]),
            ((d4 <= d3) & (d3 >= 0), B),
            ((d1 <= 0) & (d2 <= 0), A),
        ]
    for mask, X in regions:
        Q = np.where(mask[:, None], X, Q)
    bad = ~(np.abs(den) > 0) | ~np.isfinite(Q).all(axis=1)
    if bad.any():  # degenerate triangles: nearest point on the three edges
        p, cand = P[bad], []
        for U, W in ((A[bad], B[bad]), (B[bad], C[bad]), (C[bad], A[bad])):
            d, rel = W - U, p - U
            t = np.einsum("ij,ij->i", rel, d) / np.maximum(
                np.einsum("ij,ij->i", d, d), UNDERFLOW_FLOOR
            )
            cand.append(U + d * np.clip(t, 0.0, 1.0)[:, None])
        cand = np.stack(cand)
        best = np.argmin(((cand - p) ** 2).sum(-1), axis=0)
        Q[bad] = cand[best, np.arange(len(p))]
    return Q


def sample_surface(
    V: np.ndarray, F: np.ndarray, n: int, *, seed: int | np.random.Generator | None = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``n`` points uniformly by area on a triangle mesh (seeded).

    Returns ``points`` (n, 3) float64 (units and frame of ``V``) and ``faces`` (n,) int64,
    the triangle each point lies on.
    """
    rng = np.random.default_rng(seed)
    T = np.asarray(V, dtype=np.float64)[np.asarray(F)]
    area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    total = area.sum()
    if not total > 0:
        raise InputError("sample_surface: the mesh has zero area")
    face = np.minimum(np.searchsorted(np.cumsum(area), rng.random(n) * total), len(F) - 1)
    r1, r2 = np.sqrt(rng.random(n))[:, None], rng.random(n)[:, None]
    t = T[face]
    return (1 - r1) * t[:, 0] + r1 * (1 - r2) * t[:, 1] + r1 * r2 * t[:, 2], face


def point_to_surface(
    P: np.ndarray, V: np.ndarray, F: np.ndarray, *, tol: float | None = None, k: int = 16
) -> tuple[np.ndarray, float]:
    """Distance from each point to a triangle mesh (nearest point on any of its triangles).

    The mesh is covered by a barycentric grid of samples such that every surface point lies
    within ``δ ≤ tol`` of a sample of its own triangle (a point of a sub-triangle of
    longest edge ``e`` sees two of its corners under an angle ≥ 120°, so by the law of
    cosines it is within ``e/√3`` of one). A k-d tree (pykdtree) gives each query's ``k``
    nearest samples; the exact distance to their triangles
    (:func:`closest_points_on_triangles`) is taken. Accuracy: ``d ≤ result ≤ d + δ`` for the
    true distance ``d`` (the nearest sample is within ``d + δ`` and lies on a candidate
    triangle). In practice the true nearest triangle is among the candidates: all of 3,000
    distances between the bundled ``neutral`` and ``heavy_male`` templates (up to 11 cm) and
    of 1,000 between two 14.6k-vertex marching-cubes meshes equal brute-force exact ones
    (``k = 8``: 99.6 %, off by ≤ 0.12 mm, the mesh having many tiny triangles).

    Parameters
    ----------
    P : (n, 3) float, query points, metres
    V, F : (nv, 3) float, (m, 3) int, the mesh
    tol : float, optional
        δ in metres; default a quarter of the median longest edge of the triangles.
        Samples grow as ``(edge / tol)²`` per triangle; past 4 million, ``tol`` is raised.
    k : int, nearest samples examined per point

    Returns
    -------
    dist : (n,) float64, distances, metres
    bound : float, δ: the largest possible overestimate of any distance, metres
    """
    P = np.asarray(P, dtype=np.float64).reshape(-1, 3)
    T = np.asarray(V, dtype=np.float64)[np.asarray(F, dtype=np.int64)]
    edge = np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max(axis=1)  # longest edge, (m,)
    tol = 0.25 * float(np.median(edge)) if tol is None else float(tol)
    if not tol > 0 or int(k) < 1:
        raise InputError(f"tol and k must be positive, found tol={tol}, k={k}")
    while True:
        level = np.maximum(1, np.ceil(edge / (np.sqrt(3.0) * tol))).astype(np.int64)
        if ((level + 1) * (level + 2) // 2).sum() <= 4_000_000:
            break
        tol *= 1.5
    samples, owner = [], []
    for lev in np.unique(level):  # one vectorised pass per subdivision level
        ids = np.flatnonzero(level == lev)
        i, j = np.meshgrid(np.arange(lev + 1), np.arange(lev + 1), indexing="ij")
        keep = (i + j) <= lev
        w = np.stack([lev - i[keep] - j[keep], i[keep], j[keep]], axis=1) / lev  # (G, 3)
        samples.append(np.einsum("gc,tcd->tgd", w, T[ids]).reshape(-1, 3))
        owner.append(np.repeat(ids, len(w)))
    S, owner = np.concatenate(samples), np.concatenate(owner)
    tree, dist, k = KDTree(S), np.empty(len(P)), int(min(k, len(S)))
    step = max(1, 200_000 // k)  # (point, triangle) pairs per chunk: bounded memory
    for start in range(0, len(P), step):
        p = P[start : start + step]
        _, idx = tree.query(p, k=k)
        tri = owner[np.asarray(idx).reshape(len(p), k)].ravel()
        pp = np.repeat(p, k, axis=0)
        Q = closest_points_on_triangles(pp, T[tri, 0], T[tri, 1], T[tri, 2])
        dist[start : start + len(p)] = np.linalg.norm(pp - Q, axis=1).reshape(-1, k).min(axis=1)
    return dist, float((edge / level).max() / np.sqrt(3.0))
