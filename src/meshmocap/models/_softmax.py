"""The fit of :class:`~meshmocap.models.bodyparts.BodyPartClassifier`'s ``"logistic"``
method for more than two classes: the multinomial logistic (softmax) loss with an L2
penalty on the weights, minimised by Newton's method (:class:`SoftmaxRegression`); the
passes over the points (the loss, the probabilities its gradient and Hessian are sums
of) compiled.

The loss is scikit-learn's ``LogisticRegression(solver="lbfgs")``'s for more than two
classes (the mean cross-entropy plus ``l2 / 2 · |W|²`` with ``l2 = 1 / (C n)``, the
intercepts free). The parameters are ``[W | b]`` (K, d + 1) float64, C-ordered.
Internal helpers of :mod:`meshmocap.models.bodyparts`: they trust their inputs.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from meshmocap._numba import njit

_NEWTON_MAX_ITER = 100  # Newton steps at most ...
_NEWTON_TOL = 1e-7  # ... until no gradient entry exceeds this (probabilities to a few 1e-6)
_NEWTON_MIN_STEP = 1e-10  # ... shortest step fraction tried in its line search
_ARMIJO = 1e-4  # sufficient decrease of the line search
_HESSIAN_REUSE = 0.1  # a Hessian is kept while each step cuts the gradient ×10


@njit(cache=True, nogil=True)
def softmax_probabilities(Wb, Z, y):
    """The softmax probabilities (n, K) float64 of every point of ``Z`` (n, d) under
    logits ``W[k] · z + b[k]`` (``Wb`` (K, d + 1) float64), and the summed cross-entropy
    of labels ``y`` (n,) int64 (float; :func:`softmax_loss` without its mean and penalty)."""
    n, d = Z.shape
    K = Wb.shape[0]
    P = np.empty((n, K))
    loss = 0.0
    for i in range(n):
        top = -np.inf
        for k in range(K):
            r = Wb[k, d]
            for j in range(d):
                r += Wb[k, j] * Z[i, j]
            P[i, k] = r
            top = max(top, r)
        raw_y = P[i, y[i]]
        s = 0.0
        for k in range(K):
            P[i, k] = math.exp(P[i, k] - top)
            s += P[i, k]
        loss += math.log(s) + top - raw_y
        for k in range(K):
            P[i, k] /= s
    return P, loss


@njit(cache=True, nogil=True)
def pair_products(P, Q):
    """``p_i q_iᵀ`` of every row of ``P`` (n, K) and ``Q`` (n, L) float64, flattened: (n,
    K L) with ``[i, a L + b] = P[i, a] · Q[i, b]`` (the products of ``P[:, :, None] *
    Q[:, None, :]``, without its broadcast temporaries)."""
    n, K = P.shape
    L = Q.shape[1]
    out = np.empty((n, K * L))
    for i in range(n):
        for a in range(K):
            pa = P[i, a]
            for b in range(L):
                out[i, a * L + b] = pa * Q[i, b]
    return out


def softmax_loss(Wb: np.ndarray, Z: np.ndarray, y: np.ndarray, l2: float) -> float:
    """Mean softmax cross-entropy of labels ``y`` (n,) int64 in ``0…K−1`` at points ``Z``
    (n, d) float64 under logits ``W[k] · z + b[k]`` (``Wb`` (K, d + 1) float64), plus
    ``l2 / 2 · |W|²``."""
    return softmax_probabilities(Wb, Z, y)[1] / len(Z) + 0.5 * l2 * float(np.sum(Wb[:, :-1] ** 2))


def softmax_gradient(
    Wb: np.ndarray, Z: np.ndarray, y: np.ndarray, l2: float, Zt: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """:func:`softmax_loss` at ``Wb`` (K, d + 1), its gradient ``Σ_i (p_i − e_(y_i)) ⊗ z̃_i
    / n + l2 [W | 0]`` (K, d + 1), and the probabilities ``p_i`` (n, K) it is made of;
    ``Zt`` (n, d + 1) is ``[Z, 1]``."""
    n = len(Z)
    P, f = softmax_probabilities(Wb, Z, y)
    f = f / n + 0.5 * l2 * float(np.sum(Wb[:, :-1] ** 2))
    R = P.copy()
    R[np.arange(n), y] -= 1.0
    g = R.T @ Zt / n
    g[:, :-1] += l2 * Wb[:, :-1]
    return f, g, P


def softmax_hessian(P: np.ndarray, ZZ: np.ndarray, l2: float) -> np.ndarray:
    """The Hessian (K, m, K, m) of :func:`softmax_loss` where the probabilities are ``P``
    (n, K): ``Σ_i (diag p_i − p_i p_iᵀ) ⊗ z̃_i z̃_iᵀ / n + l2`` on the weights' diagonal;
    ``ZZ`` (n, m²) holds each ``z̃_i z̃_iᵀ`` (``z̃ = [z, 1]``, m = d + 1), flattened."""
    n, K = P.shape
    m = math.isqrt(ZZ.shape[1])
    # two products over the points
    P = np.ascontiguousarray(P, dtype=np.float64)
    B = (pair_products(P, P).T @ ZZ).reshape(K, K, m, m)
    H = -B.transpose(0, 2, 1, 3) / n
    H[np.arange(K), :, np.arange(K), :] += (P.T @ ZZ).reshape(K, m, m) / n
    pen = np.zeros((K, m))
    pen[:, :-1] = l2
    H += np.diag(pen.ravel()).reshape(K, m, K, m)
    return H


class SoftmaxRegression:
    """Multinomial logistic regression fitted by Newton's method (module docstring).

    Parameters
    ----------
    C : float > 0, inverse of the L2 penalty's strength (scikit-learn's ``C``)
    n_classes : int ≥ 2, ``K``: the labels are class indices ``0…K−1``

    Attributes (after :meth:`fit`): ``coef_`` (K, d), ``intercept_`` (K,), ``n_iter_`` (1,).
    """

    def __init__(self, C: float, n_classes: int) -> None:
        self.C = C
        self.n_classes = n_classes

    def fit(
        self,
        Z: np.ndarray,
        y: np.ndarray,
        start: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> SoftmaxRegression:
        """The minimum of :func:`softmax_loss` (mean cross-entropy + ``|W|² / (2 C n)``)
        for points ``Z`` (n, d) float64 and class indices ``y`` (n,) in ``0…K−1``, from
        ``start`` (W (K, d), b (K,); default zeros): Newton steps with a backtracking
        line search until no gradient entry exceeds ``_NEWTON_TOL``, the Hessian
        recomputed only where the last step did not cut the gradient tenfold. Returns
        ``self``."""
        K, C = int(self.n_classes), float(self.C)
        d = Z.shape[1]
        n, m = len(Z), K * (d + 1)
        Z = np.ascontiguousarray(Z, dtype=np.float64)
        y = np.ascontiguousarray(y, dtype=np.int64)
        Zt = np.hstack([Z, np.ones((n, 1))])  # z̃ = [z, 1]
        ZZ = (Zt[:, :, None] * Zt[:, None, :]).reshape(n, -1)  # z̃ z̃ᵀ per point
        l2 = 1.0 / (C * n)
        # the loss is flat along b + t·1 (softmax is shift-invariant); the gradient has no
        # part along it, so this term in the Hessian only makes the step unique
        gauge = np.zeros((K, d + 1))
        gauge[:, d] = 1.0
        gauge = np.outer(gauge.ravel(), gauge.ravel())
        Wb = np.zeros((K, d + 1))
        if start is not None:
            Wb[:, :d], Wb[:, d] = start
        f, g, P = softmax_gradient(Wb, Z, y, l2, Zt)
        factor, last = None, np.inf
        n_iter = 0
        while n_iter < _NEWTON_MAX_ITER:
            n_iter += 1
            top = float(np.abs(g).max())
            if top <= _NEWTON_TOL:
                break
            fresh = factor is None or top > _HESSIAN_REUSE * last
            if fresh:  # a new Hessian where the last one no longer gains ×10 a step
                factor = cho_factor(softmax_hessian(P, ZZ, l2).reshape(m, m) + gauge)
            last = top
            step = -cho_solve(factor, g.ravel()).reshape(K, d + 1)
            slope, t = float(np.vdot(g, step)), 1.0
            while t > _NEWTON_MIN_STEP:  # backtracking (Armijo) from the full step
                trial = Wb + t * step
                f_t, g_t, P_t = softmax_gradient(trial, Z, y, l2, Zt)
                if f_t <= f + _ARMIJO * t * slope:
                    break
                t *= 0.5
            else:
                if fresh:
                    break  # no decrease left to rounding: at the minimum
                factor = None  # an old Hessian's step: try a new one
                continue
            Wb, f, g, P = trial, f_t, g_t, P_t
        self.coef_, self.intercept_ = Wb[:, :d].copy(), Wb[:, d].copy()
        self.n_iter_ = np.array([n_iter], dtype=np.int32)  # as scikit-learn's
        return self

    def predict_proba(self, Z: np.ndarray) -> np.ndarray:
        """Class probabilities (m, K) float64 of points ``Z`` (m, d)."""
        z = Z @ self.coef_.T + self.intercept_
        z -= z.max(axis=1, keepdims=True)
        np.exp(z, out=z)
        z /= z.sum(axis=1, keepdims=True)
        return z
