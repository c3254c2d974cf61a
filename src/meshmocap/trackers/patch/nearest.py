"""The k nearest template vertices of each observed point, over a frame's EM iterations.

The E-step (:meth:`~meshmocap.trackers.patch.tracker.PatchTracker.correspondences`) needs,
every iteration, each observed point's ``k`` nearest vertices of the moving model. Between
two iterations the vertices move little, so a point's nearest vertices rarely change: a
query keeps ``k + spare`` of them, and a later iteration ranks those candidates again at
the vertices' new positions. The result is the one a new k-d query would give whenever it
provably is: every vertex outside the candidates was at least ``far`` (the last
candidate's distance) from the point at the query, and has moved at most ``δ_p`` since
(its patch ``p`` is rigid: ``δ_p = |Δc_p| + ρ_p |R_p − R_p'|₂`` with ``ρ_p`` the patch's
radius), so it lies at least ``far − δ_p`` away now. A patch whose ``δ_p`` is below
``far − d_k`` (``d_k`` the k-th candidate's distance now) cannot bring a vertex nearer
than the k-th candidate, nor can a patch whose bounding sphere lies farther than ``d_k``;
if every patch is one or the other, the k nearest are all candidates. The points for
which this fails are queried again.
"""

from __future__ import annotations

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import ZERO_EXTENT
from meshmocap.trackers.patch.kernels import nearest_among, stale_rows


def k_nearest(V: np.ndarray, Y: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest points of ``V`` (n, 3) to each point of ``Y`` (m, 3) by a k-d
    query, by increasing distance: distances (m, k) float64 and indices (m, k) int64."""
    return k_nearest_on(KDTree(V), Y, k)


def k_nearest_on(tree: KDTree, Y: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`k_nearest` on a built k-d ``tree``."""
    d, i = tree.query(Y, k=k)
    return d.reshape(len(Y), k).astype(np.float64), i.reshape(len(Y), k).astype(np.int64)


class NearestVertices:
    """Nearest vertices of fixed points ``Y`` (m, 3) while the vertices move.

    Parameters
    ----------
    Y : (m, 3) float64, the observed points, metres
    radius : (P,) float64, metres, the largest distance of a patch's vertices from its
        centre (the patches are rigid)
    k : int, neighbours returned per point
    spare : int, extra candidates kept per point (0: a new k-d query every call)

    Attributes
    ----------
    n_queried : int, points queried on a k-d tree so far (the rest were re-ranked)
    """

    def __init__(self, Y: np.ndarray, radius: np.ndarray, *, k: int, spare: int):
        self.Y = np.ascontiguousarray(Y, dtype=np.float64)
        self.radius = np.ascontiguousarray(radius, dtype=np.float64)
        self.k, self.spare = k, spare
        self.cand: np.ndarray | None = None  # (m, K) int64 candidates per point
        self.far = np.zeros(len(Y))  # distance of each point's last candidate at its query
        self.epoch = np.zeros(len(Y), dtype=np.int64)  # which snapshot it was queried on
        self.snapshots: list[tuple] = []  # patch rotations and centres at each query
        self.n_queried = 0

    def query(self, V: np.ndarray, R: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest vertices of ``V`` (n, 3) to every point, by increasing
        distance: distances (m, k) float64, metres, and indices (m, k) int64. ``R``
        (P, 3, 3), ``c`` (P, 3): the patch rotations and centres that place ``V``."""
        V = np.ascontiguousarray(V, dtype=np.float64)
        m, n = len(self.Y), len(V)
        k, K = min(self.k, n), min(self.k + self.spare, n)
        if self.cand is None or self.spare == 0:
            d, idx = np.empty((m, k)), np.empty((m, k), dtype=np.int64)
            rows = np.arange(m)
        else:
            moved = np.stack([_patch_moves(R, c, Rs, cs, self.radius) for Rs, cs in self.snapshots])
            d, idx = nearest_among(self.Y, V, self.cand, k)
            stale = stale_rows(
                self.Y,
                d[:, k - 1],
                self.far,
                self.epoch,
                moved,
                np.argsort(-moved, axis=1, kind="stable"),
                np.ascontiguousarray(c),
                self.radius,
            )
            rows = np.flatnonzero(stale)
        if len(rows):
            dq, iq = k_nearest(V, self.Y[rows], K)
            if self.cand is None:
                self.cand = np.empty((m, K), dtype=np.int64)
            self.cand[rows] = iq
            # with every vertex a candidate, no other vertex can come nearer
            self.far[rows] = dq[:, -1] if n > K else np.inf
            self.epoch[rows] = len(self.snapshots)
            self.snapshots.append((R.copy(), c.copy()))
            d[rows], idx[rows] = dq[:, :k], iq[:, :k]
            self.n_queried += len(rows)
        return d, idx


def _patch_moves(
    R: np.ndarray, c: np.ndarray, R0: np.ndarray, c0: np.ndarray, radius: np.ndarray
) -> np.ndarray:
    """Largest displacement (P,) of a vertex of each rigid patch from ``R0``, ``c0`` to
    ``R``, ``c`` (a bound): ``|c − c0| + ρ |R − R0|₂``, with ``|R − R0|₂ = 2 sin(θ/2) =
    sqrt(3 − tr(R R0ᵀ))`` for the angle θ between them; plus a nanometre for rounding."""
    tr = np.einsum("pij,pij->p", R, R0)
    turn = np.sqrt(np.maximum(3.0 - tr, 0.0))
    return np.linalg.norm(c - c0, axis=1) + radius * turn + ZERO_EXTENT


class NearestPoints:
    """Nearest of fixed points ``Y`` (m, 3) to query points that move (the reverse term's
    template vertices over a frame's iterations): each query point keeps ``1 + spare``
    candidates, and is queried again only where it moved more than the gap between its
    nearest candidate now and its last candidate at the query (every other point was at
    least that far, and the query point moved by a known amount).

    Parameters
    ----------
    Y : (m, 3) float64, the fixed points, metres; spare : int, extra candidates per query
    """

    def __init__(self, Y: np.ndarray, *, spare: int):
        self.Y = np.ascontiguousarray(Y, dtype=np.float64)
        self.tree = KDTree(self.Y)
        self.K = min(1 + spare, len(self.Y))
        self.cand: np.ndarray | None = None
        self.ref = np.zeros((0, 3))  # each query point where it was last queried
        self.far = np.zeros(0)
        self.n_queried = 0

    def query(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The nearest point of ``Y`` to each of ``X`` (r, 3) (the same ``r`` points every
        call): distances (r,) float64, metres, and indices (r,) int64."""
        X = np.ascontiguousarray(X, dtype=np.float64)
        if self.cand is None:
            self.cand = np.empty((len(X), self.K), dtype=np.int64)
            self.ref, self.far = X.copy(), np.zeros(len(X))
            d, j = np.empty((len(X), 1)), np.empty((len(X), 1), dtype=np.int64)
            rows = np.arange(len(X))
        else:
            d, j = nearest_among(X, self.Y, self.cand, 1)
            moved = np.sqrt(np.einsum("ij,ij->i", X - self.ref, X - self.ref))
            rows = np.flatnonzero(~(d[:, 0] < self.far - moved))
        if len(rows):
            dq, jq = k_nearest_on(self.tree, X[rows], self.K)
            self.cand[rows], self.ref[rows] = jq, X[rows]
            self.far[rows] = dq[:, -1] if len(self.Y) > self.K else np.inf
            d[rows], j[rows] = dq[:, :1], jq[:, :1]
            self.n_queried += len(rows)
        return d[:, 0], j[:, 0]
