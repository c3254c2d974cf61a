"""A linear shape space: the principal components of body vectors (scikit-learn contract).

A body vector stacks everything about a body that moves with its shape (for the bundled
space: rest vertices, bone heads and tails, one evaluation joint; see
:mod:`meshmocap.body.shape_space`). :class:`ShapeSpace` keeps the mean and the first
``n_components`` principal directions of a set of such vectors and writes a body as

    ``x(z) = mean_ + Σ_k z_k std_k c_k``                                        (PCA)

with **standardised** coefficients ``z`` (each of unit variance over the training bodies),
so that ``‖z‖²`` is the Gaussian prior's negative log-likelihood (up to a constant and a
factor 2) and the derivative ``∂x/∂z = (std_ · components_)ᵀ`` is constant.

References
----------
- I. T. Jolliffe, *Principal Component Analysis*, 2nd ed., Springer, 2002.
"""

from __future__ import annotations

import numpy as np

from meshmocap.errors import InputError

__all__ = ["ShapeSpace"]


class ShapeSpace:
    """Principal components of body vectors.

    Parameters
    ----------
    n_components : int
        Components kept (at most ``min(n_samples - 1, n_features)``).

    Attributes
    ----------
    mean_ : (d,) float64, set by :meth:`fit` like the others
    components_ : (K, d) float64, orthonormal rows
    std_ : (K,) float64, standard deviation of the training bodies along each component
    explained_variance_ratio_ : (K,) float64, fraction of the total variance each explains
    n_samples_ : int
    """

    def __init__(self, n_components: int = 16):
        self.n_components = n_components

    def fit(self, X: np.ndarray) -> ShapeSpace:
        """Fit to ``X`` (N, d) float64 body vectors (one per row); returns ``self``."""
        X = np.asarray(X, dtype=np.float64)
        k = self.n_components
        if X.ndim != 2 or len(X) < 2 or not np.all(np.isfinite(X)):
            raise InputError(f"ShapeSpace.fit: X must be finite (N ≥ 2, d), found {X.shape}")
        if not (isinstance(k, int | np.integer) and 1 <= k <= min(len(X) - 1, X.shape[1])):
            raise InputError(
                f"ShapeSpace: n_components must be in 1..{min(len(X) - 1, X.shape[1])}, found {k!r}"
            )
        mean = X.mean(axis=0)
        _, s, Vt = np.linalg.svd(X - mean, full_matrices=False)
        var = s**2 / (len(X) - 1)
        self.mean_ = mean
        self.components_ = Vt[:k]
        self.std_ = np.sqrt(var[:k])
        self.explained_variance_ratio_ = var[:k] / var.sum()
        self.n_samples_ = len(X)
        return self

    @property
    def basis_(self) -> np.ndarray:
        """(K, d) float64: ``std_[:, None] * components_``, the derivative ``∂x/∂z`` (rows)."""
        return self.std_[:, None] * self.components_

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Standardised coefficients (N, K) of body vectors ``X`` (N, d): the least-squares
        projection onto the space."""
        X = np.asarray(X, dtype=np.float64)
        return ((X - self.mean_) @ self.components_.T) / self.std_

    def inverse_transform(self, Z: np.ndarray) -> np.ndarray:
        """Body vectors (..., d) of standardised coefficients ``Z`` (..., K)."""
        return self.mean_ + np.asarray(Z, dtype=np.float64) @ self.basis_
