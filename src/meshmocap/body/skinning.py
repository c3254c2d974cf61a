"""Linear-blend skinning, vectorised over vertices and frames.

A skinning transform per joint maps rest positions to posed positions:
``A_j = [G_j | P_j − G_j P0_j]`` (3 × 4), where ``G_j``/``P_j`` are the joint's global
rotation and world position and ``P0_j`` its rest position. A vertex moves by the
weight-blended transform ``Σ_j w_ij A_j``.

References
----------
- N. Magnenat-Thalmann, R. Laperrière, D. Thalmann, *Joint-dependent local
  deformations for hand animation and object grasping*, Graphics Interface, 26–33, 1988.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from meshmocap._tolerances import UNDERFLOW_FLOOR
from meshmocap.geometry.mesh import edges_unique


def skinning_transforms(G: np.ndarray, P: np.ndarray, P0: np.ndarray) -> np.ndarray:
    """Return per-joint skinning transforms.

    Parameters
    ----------
    G : (..., J, 3, 3) float64
        Global joint rotations (from :func:`~meshmocap.body.skeleton.forward_kinematics`).
    P : (..., J, 3) float64
        Posed world joint positions, metres.
    P0 : (J, 3) float64
        Rest world joint positions, metres.

    Returns
    -------
    (..., J, 3, 4) float64
        ``[G_j | P_j − G_j P0_j]``.
    """
    t = P - np.einsum("...jab,jb->...ja", G, P0)
    return np.concatenate([G, t[..., None]], axis=-1)


def skinning_operator(V0: np.ndarray, W: sp.spmatrix) -> sp.csc_matrix:
    """Return the sparse operator ``S`` (n, 4J) with ``V = S @ A4`` for any pose.

    Linear-blend skinning is linear in the transforms: ``V_i = Σ_j w_ij A_j [v_i; 1]``, so
    ``S[i, 4j + b] = w_ij ṽ_ib`` with ``ṽ = [v, 1]`` and ``A4[4j + b, a] = A_j[a, b]``.
    Precompute it once per template; each pose is then one sparse product.

    Parameters
    ----------
    V0 : (n, 3) float64
        Rest vertex positions, metres.
    W : (n, J) scipy.sparse matrix
        Skinning weights.
    """
    Wc = sp.coo_matrix(W)
    J = W.shape[1]
    Vt = np.concatenate([V0, np.ones((len(V0), 1))], axis=1)
    rows = np.repeat(Wc.row, 4)
    cols = (Wc.col[:, None] * 4 + np.arange(4)).ravel()
    vals = (Wc.data[:, None] * Vt[Wc.row]).ravel()
    return sp.csc_matrix((vals, (rows, cols)), shape=(len(V0), 4 * J))


def apply_skinning(S: sp.csc_matrix, A: np.ndarray) -> np.ndarray:
    """Return skinned positions ``(n, 3)`` or ``(T, n, 3)`` from :func:`skinning_operator`
    ``S`` and transforms ``A`` ``(J, 3, 4)`` or ``(T, J, 3, 4)``."""
    single = A.ndim == 3
    A = A[None] if single else A
    T, J = A.shape[:2]
    A4 = A.transpose(1, 3, 0, 2).reshape(4 * J, T * 3)  # rows (j, b), columns (t, a)
    out = (S @ A4).reshape(S.shape[0], T, 3).transpose(1, 0, 2)
    return out[0] if single else out


def linear_blend_skinning(V0: np.ndarray, W: sp.csr_matrix, A: np.ndarray) -> np.ndarray:
    """Return skinned vertex positions.

    Parameters
    ----------
    V0 : (n, 3) float64
        Rest vertex positions, metres.
    W : (n, J) scipy.sparse CSR matrix
        Skinning weights, rows summing to 1.
    A : (J, 3, 4) or (T, J, 3, 4) float64
        Skinning transforms (:func:`skinning_transforms`).

    Returns
    -------
    (n, 3) or (T, n, 3) float64
        Posed positions (one set per frame when ``A`` has a frame axis).
    """
    single = A.ndim == 3
    A = A[None] if single else A
    T, J = A.shape[:2]
    # Blend the 3×4 matrices of all frames in one sparse product: (n, J) @ (J, T·12).
    B = (W @ A.transpose(1, 0, 2, 3).reshape(J, T * 12)).reshape(len(V0), T, 3, 4)
    out = np.einsum("ntab,nb->tna", B[..., :3], V0) + B[..., 3].transpose(1, 0, 2)
    return out[0] if single else out


def smooth_weights(
    W: sp.spmatrix, F: np.ndarray, *, iterations: int, max_weights: int = 4
) -> sp.csr_matrix:
    """Skinning weights ``W`` (n, J) diffused over a mesh's edges: ``iterations`` times
    ``W ← ½ W + ½ D⁻¹ A W`` (``A`` the adjacency of triangles ``F`` (m, 3), ``D`` the
    degrees); then the ``max_weights`` largest weights of each vertex, renormalised to
    sum to 1. Weights copied onto a mesh vertex by vertex (a rig transferred from another
    body) jump where neighbouring vertices took them from different parts; diffused, a
    skinned joint bends the surface around it instead of tearing it along the jump.

    Returns (n, J) float64 sparse rows with at most ``max_weights`` non-zeros, sum 1."""
    n = W.shape[0]
    E, _ = edges_unique(np.asarray(F, dtype=np.int64))
    A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    A = (A + A.T).tocsr()
    P = (sp.diags(1.0 / np.maximum(np.asarray(A.sum(axis=1)).ravel(), 1.0)) @ A).tocsr()
    X = np.asarray(W.todense(), dtype=np.float64)  # (n, J): J is small
    for _ in range(int(iterations)):
        X = 0.5 * X + 0.5 * (P @ X)
    keep = min(int(max_weights), X.shape[1])
    cut = np.argpartition(-X, keep - 1, axis=1)[:, :keep]
    rows = np.arange(n)[:, None]
    out = np.zeros_like(X)
    out[rows, cut] = X[rows, cut]
    out /= np.maximum(out.sum(axis=1, keepdims=True), UNDERFLOW_FLOOR)
    return sp.csr_matrix(out)
