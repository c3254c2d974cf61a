"""Mesh checks and basic quantities as pure array functions.

``V`` : (n, 3) float64 vertex positions, metres. ``F`` : (m, 3) int triangle indices,
counter-clockwise seen from outside.
"""

from __future__ import annotations

import numpy as np


def edges_unique(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the undirected edges of ``F`` and how many faces use each.

    Returns
    -------
    E : (k, 2) int64
        Unique edges, smaller index first.
    counts : (k,) int64
        Number of faces each edge belongs to (2 everywhere for a closed 2-manifold).
    """
    F = np.asarray(F, dtype=np.int64)
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    n = int(F.max()) + 1 if len(F) else 1
    # one 1-D unique on i·n + j: ~7× faster than a row-wise unique
    key, counts = np.unique(E[:, 0] * n + E[:, 1], return_counts=True)
    E = np.stack([key // n, key % n], axis=1)
    return E, counts


def face_normals(V: np.ndarray, F: np.ndarray, *, normalize: bool = True) -> np.ndarray:
    """Return (m, 3) face normals (unit, or area-weighted ×2 if ``normalize`` is False)."""
    V = np.asarray(V, dtype=float)
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if normalize:
        n = np.linalg.norm(N, axis=1, keepdims=True)
        N = np.divide(N, n, out=np.zeros_like(N), where=n > 0)
    return N


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Return (n, 3) unit vertex normals, area-weighted averages of the face normals
    ``(V1 − V0) × (V2 − V0)``, summed corner by corner (every face's first corner, then
    second, third) in one compiled pass: 7× faster than NumPy's cross products and
    bincounts for a 41k-vertex hull, the same sums in the same order."""
    from meshmocap.geometry._mesh_kernels import normals_at_kernel

    # writeable C arrays: the one signature compiled ahead (meshmocap.apps.kernels)
    V = np.require(V, dtype=np.float64, requirements=["C", "W"])
    F = np.require(F, dtype=np.int64, requirements=["C", "W"])
    out = normals_at_kernel(V, F, np.arange(len(V), dtype=np.int64), len(V))
    n = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, n, out=np.zeros_like(out), where=n > 0)


def vertex_normals_at(V: np.ndarray, F: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Return (k, 3) unit vertex normals of the vertices ``idx`` (k,) only: the same values
    as ``vertex_normals(V, F)[idx]`` (the same sums in the same order), from one pass over
    the faces that touches only those around ``idx`` (a 5,000-vertex sample of a
    42k-vertex hull: 10× faster than every normal)."""
    from meshmocap.geometry._mesh_kernels import normals_at_kernel

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    idx = np.asarray(idx, dtype=np.int64)
    want, inverse = np.unique(idx, return_inverse=True)
    slot = np.full(len(V), -1, dtype=np.int64)
    slot[want] = np.arange(len(want))
    out = normals_at_kernel(V, F, slot, len(want))
    n = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, n, out=np.zeros_like(out), where=n > 0)[inverse]


def signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    """Return the signed volume (m³) enclosed by a closed mesh (positive if normals point out)."""
    V = np.asarray(V, dtype=float)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def mesh_problems(V: np.ndarray, F: np.ndarray) -> list[str]:
    """Return human-readable problems of a mesh meant to be a closed 2-manifold.

    Checks: finite vertices, face indices in range, no degenerate (repeated-index) faces,
    every edge shared by exactly two faces. An empty list means the mesh is usable.
    """
    V = np.asarray(V)
    F = np.asarray(F)
    problems: list[str] = []
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        return [f"vertices must have shape (n, 3) with n > 0, found {V.shape}"]
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        return [f"faces must have shape (m, 3) with m > 0, found {F.shape}"]
    bad = ~np.isfinite(V).all(axis=1)
    if bad.any():
        problems.append(
            f"{int(bad.sum())} vertices are NaN or infinite (first: {int(np.flatnonzero(bad)[0])})"
        )
    if F.min() < 0 or F.max() >= len(V):
        problems.append(f"face indices must lie in [0, {len(V) - 1}], found [{F.min()}, {F.max()}]")
        return problems
    degenerate = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if degenerate.any():
        problems.append(f"{int(degenerate.sum())} faces repeat a vertex")
    _, counts = edges_unique(F)
    if (counts > 2).any():
        problems.append(
            f"{int((counts > 2).sum())} edges are shared by more than two faces (non-manifold)"
        )
    if (counts == 1).any():
        problems.append(f"{int((counts == 1).sum())} boundary edges (the mesh has holes)")
    return problems
