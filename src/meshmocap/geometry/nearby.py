"""Which points have another set's points nearby: a fixed-radius test on a uniform grid.

``farther_than(Y, X, radius=r)`` answers, for each point of ``Y``, whether every point of
``X`` lies farther than ``r`` (metres), as a nearest-neighbour k-d query bounded at ``r``
does (pykdtree's ``KDTree(X).query(Y, k=1, distance_upper_bound=r)``, then ``d > r``;
``at_radius="near"``: an unbounded query's ``d > r``, which differ only at the radius), the
same answer from a grid of cells a little larger than ``r``: only the points in the 27
cells around a query point can lie within ``r``, and most query points near ``X`` find
one in their own cell at once. No tree is built: ``X`` is sorted into the grid's cells
(a counting sort, one compiled pass with the queries).
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

from meshmocap.errors import InputError

#: What :func:`farther_than` answers for a point whose nearest distance is the radius
#: itself (to the rounding of the squared distance): far, as a k-d query bounded at the
#: radius (its bound is strict on the squared distance), or near, as ``d > radius`` of an
#: unbounded query (``d`` the square root of the least squared distance).
AtRadius = Literal["far", "near"]

#: Cells of the grid at most per point of ``X`` (plus :data:`MIN_CELLS`): a sparse ``X``
#: over a large extent gets larger cells (any cell of side ≥ r keeps the answer exact).
CELLS_PER_POINT = 4
#: Cells the grid may have whatever the number of points of ``X``.
MIN_CELLS = 4096


def farther_than(
    Y: np.ndarray, X: np.ndarray, *, radius: float, at_radius: AtRadius = "far"
) -> np.ndarray:
    """Whether each point of ``Y`` lies farther than ``radius`` from every point of ``X``.

    Parameters
    ----------
    Y : (m, 3) float, query points, metres
    X : (n, 3) float, finite, the other points, metres (none: every point of ``Y`` is far)
    radius : float > 0, metres
    at_radius : {"far", "near"}
        A point at the radius itself (:data:`AtRadius`): far as pykdtree's query bounded at
        ``radius`` answers, or near as ``d > radius`` of its unbounded query.

    Returns
    -------
    (m,) bool
        True where the nearest point of ``X`` is farther than ``radius`` (the distances
        summed as pykdtree sums them, so the answer equals ``d > radius`` of its query,
        bounded at ``radius`` or not as ``at_radius`` says).
    """
    from meshmocap.geometry._mesh_kernels import farther_kernel

    if at_radius not in get_args(AtRadius):
        raise InputError(
            f"farther_than: at_radius must be one of {list(get_args(AtRadius))}, "
            f"found {at_radius!r}"
        )
    r = float(radius)
    if not (np.isfinite(r) and r > 0):
        raise InputError(f"farther_than: radius must be a positive float, found {radius!r}")
    Y = np.ascontiguousarray(Y, dtype=np.float64).reshape(-1, 3)
    X = np.ascontiguousarray(X, dtype=np.float64).reshape(-1, 3)
    out = np.ones(len(Y), dtype=bool)
    if not len(X) or not len(Y):
        return out
    if not np.isfinite(X).all():
        raise InputError("farther_than: X must be finite")
    bounded = at_radius == "far"
    farther_kernel(Y, X, r, bounded, float(CELLS_PER_POINT * len(X) + MIN_CELLS), out)
    return out
