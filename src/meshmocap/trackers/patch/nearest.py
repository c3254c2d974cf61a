"""The k nearest template vertices of each observed point, over a frame's EM iterations.

The E-step (:meth:`~meshmocap.trackers.patch.tracker.PatchTracker.correspondences`) needs,
every iteration, each observed point's ``k`` nearest vertices of the moving model. Between
two iterations the vertices move little, so a point's nearest vertices rarely change: a
query keeps ``k + spare`` of them, and a later iteration ranks those candidates again at
the vertices' new positions. The result is the one a new k-d query would give whenever it
provably is: every vertex outside the candidates was at least ``far`` (the last
candidate's distance) from the point at the query, and lies at least ``far − δ_v`` away
now, ``δ_v`` its distance from where it was then. Only a vertex with ``δ_v`` above
``far − d_k`` (``d_k`` the k-th candidate's distance now) can have come nearer than the
k-th candidate; such vertices are looked at one by one, in the patches that moved that
much (their largest ``δ_v``) and whose bounding box reaches within ``d_k``, and there in
the chunks of a few neighbouring vertices (:data:`CHUNK`) that moved that much and whose
box reaches (a patch is rigid: vertices close at rest stay close). If none
outside the candidates lies within ``d_k``, the k nearest are all candidates; the points
for which this fails are queried again (on the 12k walk about a tenth of the points a
bound on each rigid patch's motion alone would re-query).
"""

from __future__ import annotations

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import ZERO_EXTENT
from meshmocap.trackers.patch.kernels import nearest_among, stale_rows, vertex_moves

#: Vertices per chunk of a patch in the re-query test (:class:`NearestVertices`).
CHUNK = 8
#: Bits per axis of the rest positions' Morton code that orders a patch's vertices.
MORTON_BITS = 10
#: Points per leaf of the vertices' k-d tree (pykdtree's default 16; the same neighbours,
#: a little faster on ~5,000 vertices and 16 neighbours: ``docs/measurements.rst``).
KD_LEAFSIZE = 32


def k_nearest(V: np.ndarray, Y: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest points of ``V`` (n, 3) to each point of ``Y`` (m, 3) by a k-d
    query, by increasing distance: distances (m, k) float64 and indices (m, k) int64."""
    return k_nearest_on(KDTree(V, leafsize=KD_LEAFSIZE), Y, k)


def k_nearest_on(tree: KDTree, Y: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`k_nearest` on a built k-d ``tree``."""
    d, i = tree.query(Y, k=k)
    return d.reshape(len(Y), k).astype(np.float64), i.reshape(len(Y), k).astype(np.int64)


def _members(labels: np.ndarray, key: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The items of each label ``0 … L − 1`` of ``labels`` (n,) int64: ``items
    [first[j]:first[j + 1]]`` for label ``j``, by increasing ``key`` (n,) (default:
    ascending items); returns ``items`` (n,) and ``first`` (L + 1,), int64."""
    if key is None:
        items = np.argsort(labels, kind="stable").astype(np.int64)
    else:
        items = np.lexsort((key, labels)).astype(np.int64)
    L = int(labels.max()) + 1 if len(labels) else 0
    first = np.searchsorted(labels[items], np.arange(L + 1)).astype(np.int64)
    return items, first


def morton_codes(X: np.ndarray, bits: int = MORTON_BITS) -> np.ndarray:
    """Morton (Z-order) codes (n,) uint64 of points ``X`` (n, 3) on a grid of ``2**bits``
    cells per axis over their bounding box: points with near codes lie close together."""
    lo, hi = X.min(axis=0), X.max(axis=0)
    cells = (X - lo) / np.maximum(hi - lo, ZERO_EXTENT) * (2**bits - 1)
    q = np.clip(cells, 0, 2**bits - 1).astype(np.uint64)
    code = np.zeros(len(X), dtype=np.uint64)
    for b in range(bits):
        for a in range(3):
            code |= ((q[:, a] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + a)
    return code


def _chunks(start: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Each patch's rows ``start[p]:start[p + 1]`` (``start`` (P + 1,)) cut into runs of at
    most ``size``: the runs' first rows (C + 1,) (the last: the end) and each patch's
    first run (P + 1,), int64."""
    count = -(-np.diff(start) // size)  # runs per patch
    pchunk = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    first = np.repeat(start[:-1], count) + size * (
        np.arange(pchunk[-1]) - np.repeat(pchunk[:-1], count)
    )
    return np.concatenate([first, start[-1:]]).astype(np.int64), pchunk


class NearestVertices:
    """Nearest vertices of fixed points ``Y`` (m, 3) while the vertices move.

    Parameters
    ----------
    Y : (m, 3) float64, the observed points, metres
    labels : (n,) int, each vertex's patch (``0 … P − 1``)
    k : int, neighbours returned per point
    spare : int, extra candidates kept per point (0: a new k-d query every call)
    groups : (P,) int, optional
        A group of each patch (e.g. its bone): the test for vertices that may have come
        nearer looks into a group only where the group's box reaches (default: one group)
    key : (n,) optional
        The order of each patch's vertices before they are cut into chunks of
        :data:`CHUNK`: e.g. the vertices' :func:`morton_codes` at rest, so that a chunk is
        compact in every pose (default: index order; the results are the same)

    Attributes
    ----------
    n_queried : int, points queried on a k-d tree so far (the rest were re-ranked)
    """

    def __init__(
        self,
        Y: np.ndarray,
        labels: np.ndarray,
        *,
        k: int,
        spare: int,
        groups: np.ndarray | None = None,
        key: np.ndarray | None = None,
    ):
        self.Y = np.ascontiguousarray(Y, dtype=np.float64)
        labels = np.asarray(labels, dtype=np.int64)
        # each patch's vertices: members[start[p]:start[p + 1]], in chunks cstart[c]:
        # cstart[c + 1] (patch p's chunks pchunk[p]:pchunk[p + 1])
        self.members, self.start = _members(labels, key)
        self.cstart, self.pchunk = _chunks(self.start, CHUNK)
        P = len(self.start) - 1
        groups = np.zeros(P, np.int64) if groups is None else np.asarray(groups, np.int64)
        self.gmembers, self.gstart = _members(groups)  # each group's patches
        self.k, self.spare = k, spare
        self.cand: np.ndarray | None = None  # (m, K) int64 candidates per point
        self.far = np.zeros(len(Y))  # distance of each point's last candidate at its query
        self.epoch = np.zeros(len(Y), dtype=np.int64)  # which snapshot it was queried on
        self.snapshots = np.zeros((0, len(labels), 3))  # the vertices (patch order) then
        self.n_snapshots = 0
        self.n_queried = 0

    def query(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest vertices of ``V`` (n, 3) to every point, by increasing
        distance: distances (m, k) float64, metres, and indices (m, k) int64."""
        V = np.ascontiguousarray(V, dtype=np.float64)
        m, n = len(self.Y), len(V)
        k, K = min(self.k, n), min(self.k + self.spare, n)
        Vm = V[self.members]
        if self.cand is None or self.spare == 0:
            d, idx = np.empty((m, k)), np.empty((m, k), dtype=np.int64)
            rows = np.arange(m)
        else:
            dv, moved, box, cmoved, cbox = vertex_moves(
                Vm, self.snapshots[: self.n_snapshots], self.start, self.cstart
            )
            d, idx = nearest_among(self.Y, V, self.cand, k)
            stale = stale_rows(
                self.Y,
                d[:, k - 1],
                self.far,
                self.epoch,
                moved,
                dv,
                box,
                Vm,
                self.cand,
                self.start,
                self.members,
                self.gstart,
                self.gmembers,
                self.pchunk,
                self.cstart,
                cmoved,
                cbox,
            )
            rows = np.flatnonzero(stale)
        if len(rows):
            dq, iq = k_nearest(V, self.Y[rows], K)
            if self.cand is None:
                self.cand = np.empty((m, K), dtype=np.int64)
            self.cand[rows] = iq
            # with every vertex a candidate, no other vertex can come nearer
            self.far[rows] = dq[:, -1] if n > K else np.inf
            self.epoch[rows] = self.n_snapshots
            self._snapshot(Vm)
            d[rows], idx[rows] = dq[:, :k], iq[:, :k]
            self.n_queried += len(rows)
        return d, idx

    def _snapshot(self, Vm: np.ndarray) -> None:
        """Keep the vertices ``Vm`` (n, 3, patch order) of a query (room doubled as needed)."""
        if self.n_snapshots == len(self.snapshots):
            grown = np.empty((max(4, 2 * len(self.snapshots)), *Vm.shape))
            grown[: self.n_snapshots] = self.snapshots[: self.n_snapshots]
            self.snapshots = grown
        self.snapshots[self.n_snapshots] = Vm
        self.n_snapshots += 1


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
