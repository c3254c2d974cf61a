"""Normals and solid occupancy of point clouds, as pure array functions.

A tracker fitting a surface to observed points needs their normals, and the cage tracker a
voxel occupancy; a point-cloud capture (a scanner's PLY without faces) has neither.

* :func:`solid_occupancy` voxelises the points, closes one-voxel gaps (binary closing) and
  fills the enclosed volume (``scipy.ndimage.binary_fill_holes``): the inside of a closed
  scan, as a voxel hull would hold it.
* :func:`point_normals` fits a plane to each point's ``k`` nearest neighbours (the
  eigenvector of the smallest eigenvalue of their covariance; Hoppe et al., *Surface
  reconstruction from unorganized points*, SIGGRAPH 1992, §3.2) and orients it outwards:
  towards the side of the point where the solid occupancy is empty, or, where the test is
  undecided (an open scan), away from the cloud's centroid.

Units: metres; world frame.

References
----------
- H. Hoppe, T. DeRose, T. Duchamp, J. McDonald, W. Stuetzle, *Surface reconstruction
  from unorganized points*, SIGGRAPH 1992. https://doi.org/10.1145/133994.134011
"""

from __future__ import annotations

import numpy as np
from pykdtree.kdtree import KDTree
from scipy import ndimage

from meshmocap.errors import InputError

#: Most voxels :func:`solid_occupancy` builds (its memory: one byte each).
MAX_SOLID_VOXELS = 1 << 27


def solid_occupancy(P: np.ndarray, voxel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The solid a closed point cloud encloses, as voxels.

    Parameters
    ----------
    P : (n, 3) float64, points sampling a closed surface at most ~1 voxel apart, metres
    voxel_size : float, metres

    Returns
    -------
    occupancy : (nx, ny, nz) bool, True inside or on the surface
    origin : (3,) float64, centre of voxel (0, 0, 0), metres
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or not len(P) or not np.isfinite(P).all():
        raise InputError(f"solid_occupancy: P must be finite (n, 3) points, found {P.shape}")
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise InputError(f"solid_occupancy: voxel_size must be > 0 metres, found {voxel_size}")
    origin = P.min(axis=0) - 2 * voxel_size
    ijk = np.floor((P - origin) / voxel_size + 0.5).astype(np.int64)
    shape = ijk.max(axis=0) + 3
    if np.prod(shape.astype(np.float64)) > MAX_SOLID_VOXELS:
        raise InputError(
            f"solid_occupancy: {shape[0]}×{shape[1]}×{shape[2]} voxels of {voxel_size} m is "
            f"too many (max {MAX_SOLID_VOXELS}); the points span {np.ptp(P, axis=0)} m"
        )
    occ = np.zeros(tuple(shape), dtype=bool)
    occ[tuple(ijk.T)] = True
    occ = _cross_erosion(_cross_dilation(occ)) | occ  # binary closing (6-neighbourhood)
    return _filled(occ), origin


def _cross_dilation(occ: np.ndarray) -> np.ndarray:
    """``occ`` (bool, 3D) dilated by its 6-neighbourhood (``scipy.ndimage``'s default
    structure), by six shifted ORs."""
    d = occ.copy()
    for ax in range(3):
        lo, hi = [slice(None)] * 3, [slice(None)] * 3
        lo[ax], hi[ax] = slice(None, -1), slice(1, None)
        d[tuple(hi)] |= occ[tuple(lo)]
        d[tuple(lo)] |= occ[tuple(hi)]
    return d


def _cross_erosion(occ: np.ndarray) -> np.ndarray:
    """``occ`` (bool, 3D) eroded by its 6-neighbourhood, nothing outside the array (as
    ``scipy.ndimage.binary_erosion(..., border_value=0)``)."""
    e = occ.copy()
    for ax in range(3):
        lo, hi = [slice(None)] * 3, [slice(None)] * 3
        lo[ax], hi[ax] = slice(None, -1), slice(1, None)
        e[tuple(hi)] &= occ[tuple(lo)]
        e[tuple(lo)] &= occ[tuple(hi)]
        first, last = [slice(None)] * 3, [slice(None)] * 3
        first[ax], last[ax] = 0, -1
        e[tuple(first)] = False
        e[tuple(last)] = False
    return e


def _filled(occ: np.ndarray) -> np.ndarray:
    """``occ`` (bool, 3D) with its holes filled: every empty voxel not 6-connected to the
    array's border made full (``scipy.ndimage.binary_fill_holes``, by one labelling of the
    empty voxels instead of a dilation run to convergence)."""
    label, n = ndimage.label(~occ)
    outside = np.zeros(n + 1, dtype=bool)
    for ax in range(3):
        outside[np.take(label, [0, -1], axis=ax).ravel()] = True
    outside[0] = False  # label 0: the full voxels
    return ~outside[label]


def point_normals(P: np.ndarray, *, k: int = 12, voxel_size: float | None = None) -> np.ndarray:
    """Unit normals of a point cloud, oriented outwards.

    Parameters
    ----------
    P : (n, 3) float64, points, metres
    k : int, neighbours of each point's plane fit (≥ 3)
    voxel_size : float, optional
        Voxel edge of the inside/outside test, metres (default: twice the median distance
        to the nearest neighbour).

    Returns
    -------
    N : (n, 3) float64, unit normals (see the module docstring for the orientation)
    """
    P = np.ascontiguousarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 3 or not np.isfinite(P).all():
        raise InputError(f"point_normals: P must be ≥ 3 finite (n, 3) points, found {P.shape}")
    k = int(min(max(k, 3), len(P)))
    dist, idx = KDTree(P).query(P, k=k)
    idx = idx.astype(np.int64)
    Q = P[idx] - P[idx].mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", Q, Q))
    N = np.ascontiguousarray(vecs[:, :, 0])  # smallest eigenvalue: the plane normal
    # which way is out: the solid test at the finest scale that decides, else the centroid
    out = np.einsum("ni,ni->n", N, P - P.mean(axis=0)) > 0
    undecided = np.ones(len(P), dtype=bool)
    h0 = voxel_size or max(2.0 * float(np.median(dist[:, 1])), 1e-4)
    for h in (h0, 2 * h0, 4 * h0):
        try:
            occ, origin = solid_occupancy(P, h)
        except InputError:  # too large a grid
            break
        front, back = (_occupied(occ, origin, h, P + s * 2.0 * h * N) for s in (1.0, -1.0))
        decided = undecided & (front != back)
        out[decided] = back[decided]
        undecided &= ~decided
    N[~out] *= -1.0
    for _ in range(3):  # neighbours vote: an isolated wrong orientation is turned round
        agree = np.einsum("nki,ni->n", N[idx], N)
        N[agree < 0] *= -1.0
    return N


def _occupied(occ: np.ndarray, origin: np.ndarray, h: float, X: np.ndarray) -> np.ndarray:
    ijk = np.floor((X - origin) / h + 0.5).astype(np.int64)
    ok = np.all((ijk >= 0) & (ijk < np.array(occ.shape)), axis=1)
    out = np.zeros(len(X), dtype=bool)
    out[ok] = occ[tuple(ijk[ok].T)]
    return out


def surface_samples(V: np.ndarray, F: np.ndarray, spacing: float) -> np.ndarray:
    """Points on the triangles ``(V, F)`` at most about ``spacing`` apart (the vertices plus
    a regular barycentric grid on each large triangle), metres."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    edge = np.max(
        np.stack(
            [
                np.linalg.norm(B - A, axis=1),
                np.linalg.norm(C - B, axis=1),
                np.linalg.norm(A - C, axis=1),
            ]
        ),
        axis=0,
    )
    m = np.clip(np.ceil(edge / spacing), 1, 64).astype(np.int64)  # subdivisions per face
    big = np.flatnonzero(m > 1)
    if not len(big):
        return V
    out = [V]
    for s in np.unique(m[big]):  # faces of one subdivision count share one barycentric grid
        p, q = np.indices((s + 1, s + 1)).reshape(2, -1)
        keep = p + q <= s
        u, w = p[keep] / s, q[keep] / s
        f = big[m[big] == s]
        out.append(
            (
                A[f, None] * (1 - u - w)[None, :, None]
                + B[f, None] * u[None, :, None]
                + C[f, None] * w[None, :, None]
            ).reshape(-1, 3)
        )
    return np.concatenate(out)
