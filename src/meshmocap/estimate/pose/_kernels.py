"""Compiled loops (numba) behind :class:`~meshmocap.estimate.pose.pose_search.FrameScorer`
(imported on first use, so that importing the pose search does not import numba).

Both take candidates' points ``x`` (c, m, d) float32 and observed points ``Yt`` (d, k)
float32 (transposed), d = 2 or 3, and sum each squared distance coordinate by coordinate,
``(x₀ − y₀)² + (x₁ − y₁)² (+ (x₂ − y₂)²)`` in float32, without a (c, m, k) array.
"""

from __future__ import annotations

import numpy as np

from meshmocap._numba import njit


@njit(cache=True, nogil=True)
def nearest_d2_kernel(x, Yt):  # pragma: no cover - compiled
    """(c, k) float32: each observed point's squared distance to its nearest model point."""
    c, m, dim = x.shape
    k = Yt.shape[1]
    best = np.empty((c, k), dtype=np.float32)
    y0, y1 = Yt[0], Yt[1]
    y2 = Yt[2] if dim == 3 else Yt[1]
    for a in range(c):
        b = best[a]
        for q in range(k):
            b[q] = np.inf
        for i in range(m):
            x0, x1 = x[a, i, 0], x[a, i, 1]
            if dim == 3:
                x2 = x[a, i, 2]
                for q in range(k):
                    t0, t1, t2 = x0 - y0[q], x1 - y1[q], x2 - y2[q]
                    d = t0 * t0 + t1 * t1 + t2 * t2
                    b[q] = min(b[q], d)
            else:
                for q in range(k):
                    t0, t1 = x0 - y0[q], x1 - y1[q]
                    d = t0 * t0 + t1 * t1
                    b[q] = min(b[q], d)
    return best


@njit(cache=True, nogil=True)
def nearest_kernel(x, Yt):  # pragma: no cover - compiled
    """(c, k) float32 and (c, k) int64: each observed point's squared distance to its
    nearest model point and that point's index (the first of equals)."""
    c, m, dim = x.shape
    k = Yt.shape[1]
    best = np.empty((c, k), dtype=np.float32)
    arg = np.zeros((c, k), dtype=np.int64)
    y0, y1 = Yt[0], Yt[1]
    y2 = Yt[2] if dim == 3 else Yt[1]
    for a in range(c):
        b, g = best[a], arg[a]
        for q in range(k):
            b[q] = np.inf
        for i in range(m):
            x0, x1 = x[a, i, 0], x[a, i, 1]
            x2 = x[a, i, 2] if dim == 3 else np.float32(0.0)
            for q in range(k):
                t0, t1 = x0 - y0[q], x1 - y1[q]
                d = t0 * t0 + t1 * t1
                if dim == 3:
                    t2 = x2 - y2[q]
                    d = d + t2 * t2
                if d < b[q]:
                    b[q] = d
                    g[q] = i
    return best, arg
