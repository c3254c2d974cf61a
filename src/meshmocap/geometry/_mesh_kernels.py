"""Compiled loops (numba) behind :mod:`meshmocap.geometry.mesh` (imported on first use, so
that importing the geometry layer does not import numba)."""

from __future__ import annotations

import numpy as np

from meshmocap._numba import njit


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
