"""Each query point's nearest point whose normal agrees, on a k-d tree searched in one
compiled pass.

``nearest_agreeing(point_tree(X, N), Q, NQ, k=k, max_distance=r, normal_cos=c)`` answers,
for each query point ``Q[t]`` with unit normal ``NQ[t]``, the nearest point of ``X`` that
lies within ``r`` (metres) and whose normal agrees (``N[j] · NQ[t] > c``), among the ``k``
nearest points within ``r`` (none where none of those agrees): the answer of a k-d tree's
nearest-point query followed by a ``k``-nearest query for the queries whose nearest point
disagrees (:func:`~meshmocap.body.articulated.nearest_compatible` on pykdtree), in one
search. The search prunes by the nearest agreeing point found so far as well as by the
``k``-th nearest, and a guess (``hint``: the answer of an iteration before, where the
points moved little since) bounds it from the start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap.errors import InputError

#: Points a leaf of the tree holds at most (fewer, deeper trees search no faster).
LEAF_SIZE = 32


@dataclass(frozen=True)
class PointTree:
    """A k-d tree over ``n`` points with their normals (:func:`point_tree`).

    Attributes
    ----------
    points, normals : (n, 3) float64, in tree order (metres; unit normals)
    order : (n,) int64, the input index of each point in tree order; ``rank`` (n,) its
        inverse (the tree position of each input point)
    start, stop, dim, split, left : (nodes,) per node, its points' range in tree order, the
        axis its points split on (−1: a leaf), where (metres), its first child (the second
        follows it)
    depth : int, the longest path from the root to a leaf
    """

    points: np.ndarray
    normals: np.ndarray
    order: np.ndarray
    rank: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    dim: np.ndarray
    split: np.ndarray
    left: np.ndarray
    depth: int

    @property
    def n(self) -> int:
        """The number of points."""
        return len(self.points)


def point_tree(X: np.ndarray, N: np.ndarray, *, leaf_size: int = LEAF_SIZE) -> PointTree:
    """The k-d tree of the points ``X`` with normals ``N``: each node's points split at the
    middle of their bounding box's widest side.

    Parameters
    ----------
    X : (n ≥ 1, 3) float, finite, metres
    N : (n, 3) float, their unit normals
    leaf_size : int ≥ 1, points a leaf holds at most (more where they cannot be split)
    """
    from meshmocap.geometry._mesh_kernels import point_tree_kernel

    X = np.ascontiguousarray(X, dtype=np.float64)
    N = np.ascontiguousarray(N, dtype=np.float64)
    if X.ndim != 2 or X.shape[1:] != (3,) or not len(X) or N.shape != X.shape:
        raise InputError(
            f"point_tree: expected points (n ≥ 1, 3) and normals of the same shape, "
            f"found {X.shape} and {N.shape}"
        )
    if not np.isfinite(X).all():
        raise InputError("point_tree: the points must be finite")
    if int(leaf_size) < 1:
        raise InputError(f"point_tree: leaf_size must be at least 1, found {leaf_size!r}")
    *arrays, depth = point_tree_kernel(X, N, int(leaf_size))
    return PointTree(*arrays, depth=int(depth))


def nearest_agreeing(
    tree: PointTree,
    Q: np.ndarray,
    NQ: np.ndarray,
    *,
    k: int,
    max_distance: float,
    normal_cos: float,
    hint: np.ndarray | None = None,
) -> np.ndarray:
    """For each query point, the nearest tree point within ``max_distance`` whose normal
    agrees (``n_tree · n_q > normal_cos``), among the ``k`` nearest within ``max_distance``.

    Parameters
    ----------
    tree : PointTree of the points ``X`` (n, 3) and their normals
    Q, NQ : (q, 3) float, query points (metres) and their unit normals
    k : int ≥ 1, candidates (the nearest first); ``max_distance`` (metres) > 0;
        ``normal_cos`` in [−1, 1)
    hint : (q,) int, optional
        A guess of each answer (an index into ``X``; −1: none), e.g. the answer of an
        iteration before: the search starts bounded by it where it agrees. Any guess gives
        the same answer; a good one gives it sooner.

    Returns
    -------
    (q,) int64
        The index into ``X`` of each query's point, −1 where none. The distances are
        summed as pykdtree sums them, so the answer equals that of pykdtree's nearest
        query and ``k``-nearest query where it disagrees
        (:func:`~meshmocap.body.articulated.nearest_compatible`), but for points at equal
        distances.
    """
    from meshmocap.geometry._mesh_kernels import agreeing_kernel

    Q = np.ascontiguousarray(Q, dtype=np.float64)
    NQ = np.ascontiguousarray(NQ, dtype=np.float64)
    if Q.ndim != 2 or Q.shape[1:] != (3,) or NQ.shape != Q.shape:
        raise InputError(
            f"nearest_agreeing: expected query points (q, 3) and normals of the same shape, "
            f"found {Q.shape} and {NQ.shape}"
        )
    if not (int(k) >= 1 and max_distance > 0):
        raise InputError(
            f"nearest_agreeing: k ≥ 1 and max_distance > 0 expected, found {k!r}, {max_distance!r}"
        )
    if hint is None:
        hint = np.full(len(Q), -1, dtype=np.int64)
    hint = np.ascontiguousarray(hint, dtype=np.int64)
    if hint.shape != (len(Q),) or not ((hint >= -1) & (hint < tree.n)).all():
        raise InputError(
            f"nearest_agreeing: hint must be ({len(Q)},) indices into the tree's "
            f"{tree.n} points or −1"
        )
    t = tree
    return agreeing_kernel(
        t.points,
        t.normals,
        t.order,
        t.rank,
        t.start,
        t.stop,
        t.dim,
        t.split,
        t.left,
        t.depth,
        Q,
        NQ,
        hint,
        int(k),
        float(max_distance),
        float(normal_cos),
    )
