"""The RBF covariance of the cage paper (Eq. (3)) and the pieces its derivatives need.

Internal helpers of :mod:`meshmocap.models.gplvm`; they trust their inputs (float64 arrays
of matching widths).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack


def sqdist(A: np.ndarray, B: np.ndarray | None = None) -> np.ndarray:
    """Squared Euclidean distances between the rows of ``A`` (n, k) and ``B`` (m, k).

    Returns a float64 (n, m) array, clipped at 0; with ``B`` omitted the distances of ``A``
    to itself with an exact zero diagonal.
    """
    same = B is None
    B = A if B is None else B
    a2 = np.einsum("ij,ij->i", A, A)
    b2 = a2 if same else np.einsum("ij,ij->i", B, B)
    d2 = a2[:, None] + b2[None, :] - 2.0 * (A @ B.T)
    np.maximum(d2, 0.0, out=d2)
    if same:
        np.fill_diagonal(d2, 0.0)
    return d2


def rbf(d2: np.ndarray, alpha: float, gamma: float) -> np.ndarray:
    """RBF covariance from squared distances ``d2``: ``alpha * exp(-gamma / 2 * d2)``.

    Eq. (3): k(x_i, x_j) = α exp(-γ/2 (x_i - x_j)ᵀ(x_i - x_j)).
    """
    return alpha * np.exp(-0.5 * gamma * d2)  # Eq. (3)


def chol_inverse(K: np.ndarray, upper: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Inverse and log-determinant of a symmetric positive-definite (n, n) matrix.

    Uses LAPACK ``potrf`` + ``potri`` (faster than solving against the identity).
    ``upper``: optional precomputed (n, n) bool mask of the strict upper triangle (saves
    rebuilding it in loops). Raises ``numpy.linalg.LinAlgError`` when ``K`` is not
    positive definite.
    """
    L, info = lapack.dpotrf(K, lower=1, clean=0, overwrite_a=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"matrix not positive definite (potrf info {info})")
    logdet = 2.0 * float(np.sum(np.log(np.diagonal(L))))
    Kinv, info = lapack.dpotri(L, lower=1, overwrite_c=1)
    if info != 0:  # pragma: no cover - potrf succeeded, so potri cannot fail
        raise np.linalg.LinAlgError(f"inverse failed (potri info {info})")
    if upper is None:
        upper = np.triu(np.ones(K.shape, dtype=bool), 1)
    Kinv[upper] = Kinv.T[upper]  # potri fills the lower triangle only
    return Kinv, logdet
