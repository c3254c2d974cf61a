"""GreenDeformer derivatives for trackers: batched jvp and per-point vjp (float64 FD checks)."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from meshmocap.errors import InputError
from meshmocap.geometry.green import GreenDeformer


def _sphere_cage(n: int = 42, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    u = np.random.default_rng(seed).normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    F = ConvexHull(u).simplices.copy()
    N = np.cross(u[F[:, 1]] - u[F[:, 0]], u[F[:, 2]] - u[F[:, 0]])
    flip = np.einsum("ij,ij->i", N, u[F].mean(axis=1)) < 0
    F[flip] = F[flip][:, ::-1]
    return u, F


V, F = _sphere_cage()
RNG = np.random.default_rng(5)
P = RNG.normal(size=(30, 3))
P *= (RNG.uniform(0.1, 0.85, 30) / np.linalg.norm(P, axis=1))[:, None]  # inside the cage
VN = V + 0.1 * RNG.normal(size=V.shape)  # a deformed cage


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_batched_jvp_matches_single_directions(dtype):
    d = GreenDeformer(V, F, P, dtype=dtype)
    dV = RNG.normal(size=(4, *V.shape))
    X = d.jvp(VN, dV)
    assert X.shape == (4, len(P), 3)
    for k in range(4):
        np.testing.assert_allclose(X[k], d.jvp(VN, dV[k]), rtol=0, atol=1e-12)


def test_pointwise_vjp_matches_finite_differences_and_vjp():
    d = GreenDeformer(V, F, P)
    G = RNG.normal(size=P.shape)
    W = d.pointwise_vjp(VN, G)
    assert W.shape == (len(P), len(V), 3)
    np.testing.assert_allclose(W.sum(axis=0), d.vjp(VN, G), rtol=0, atol=1e-12)
    # each point's own scalar g_p · x'_p, by central differences along random cage moves:
    # O(h²) ≈ 1e-12 truncation plus ~1e-16 / 1e-6 rounding
    eps = 1e-6
    for _ in range(3):
        dV = RNG.normal(size=V.shape)
        fd = np.sum(G * (d.deform(VN + eps * dV) - d.deform(VN - eps * dV)), axis=1) / (2 * eps)
        np.testing.assert_allclose(np.einsum("pvb,vb->p", W, dV), fd, rtol=0, atol=1e-7)


def test_bad_directions_and_gradients_raise_one_line_errors():
    d = GreenDeformer(V, F, P)
    cases = [
        (lambda: d.jvp(VN, np.zeros((2, 3, *V.shape))), "dV must be finite with shape"),
        (lambda: d.jvp(VN, np.full(V.shape, np.nan)), "dV must be finite"),
        (lambda: d.pointwise_vjp(VN, np.zeros((3, 3))), "grad_points must have shape"),
    ]
    for call, pattern in cases:
        with pytest.raises(InputError, match=pattern) as info:
            call()
        assert "\n" not in str(info.value)
