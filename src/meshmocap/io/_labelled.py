"""Checks shared by the writers of labelled 3D points (C3D, TRC)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from meshmocap.errors import InputError


def labelled_points(
    func: str, points, labels: Sequence[str], fps: float
) -> tuple[np.ndarray, list[str]]:
    """Return ``points`` as (T, P, 3) float64 and ``labels`` as P str, or raise
    :class:`InputError`: empty or non-finite points, labels not distinct (or holding tabs or
    line breaks), a frame rate that is not positive."""
    X = np.asarray(points, dtype=np.float64)
    if X.ndim != 3 or X.shape[2] != 3 or X.shape[0] == 0 or X.shape[1] == 0:
        raise InputError(f"{func}: points must have shape (T, P, 3) with T, P > 0, found {X.shape}")
    if not np.all(np.isfinite(X)):
        raise InputError(f"{func}: points contain NaN or infinite values")
    names = [str(s) for s in labels]
    bad = any(not s or any(c in s for c in "\t\r\n") for s in names)
    if len(names) != X.shape[1] or len(set(names)) != len(names) or bad:
        raise InputError(
            f"{func}: expected {X.shape[1]} distinct labels without tabs, found {names}"
        )
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"{func}: fps must be a positive number, found {fps!r}")
    return X, names


def valid_mask(func: str, X: np.ndarray, valid) -> np.ndarray:
    """``valid`` ((T,) or (T, P) bool, None: all) as a (T, P) bool mask over ``X``
    (T, P, 3), or raise :class:`InputError`."""
    ok = np.ones(X.shape[:2], bool) if valid is None else np.asarray(valid, dtype=bool)
    if ok.shape == (X.shape[0],):
        ok = np.repeat(ok[:, None], X.shape[1], axis=1)
    if ok.shape != X.shape[:2]:
        raise InputError(f"{func}: valid must have shape (T,) or (T, P), found {ok.shape}")
    return ok
