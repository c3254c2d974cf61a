"""Linear-blend skinning, vectorised over vertices and frames.

A skinning transform per joint maps rest positions to posed positions:
``A_j = [G_j | P_j − G_j P0_j]`` (3 × 4), where ``G_j``/``P_j`` are the joint's global
rotation and world position and ``P0_j`` its rest position. A vertex moves by the
weight-blended transform ``Σ_j w_ij A_j``.

References
----------
- N. Magnenat-Thalmann, R. Laperrière, D. Thalmann, *Joint-dependent local
  deformations for hand animation and object grasping*, Graphics Interface, 26–33, 1988.
- B. H. Le, Z. Deng, *Smooth skinning decomposition with rigid bones*, ACM Transactions
  on Graphics 31(6):199, 2012. https://doi.org/10.1145/2366145.2366218 (the weights'
  update with the bones given, as :func:`fit_weights` does).
- M. Held, P. Wolfe, H. P. Crowder, *Validation of subgradient optimization*,
  Mathematical Programming 6:62–88, 1974. https://doi.org/10.1007/BF01580223
- A. Beck, M. Teboulle, *A fast iterative shrinkage-thresholding algorithm for linear
  inverse problems*, SIAM Journal on Imaging Sciences 2(1):183–202, 2009.
  https://doi.org/10.1137/080716542
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from meshmocap._tolerances import UNDERFLOW_FLOOR
from meshmocap.errors import InputError
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


def weight_candidates(
    W: sp.spmatrix, F: np.ndarray, parents: np.ndarray, *, spread: int = 40, count: int = 8
) -> np.ndarray:
    """The joints each vertex's weights may be fitted over (:func:`fit_weights`): the
    ``count`` largest of its weights ``W`` (n, J) diffused ``spread`` times over the mesh's
    edges (:func:`smooth_weights`; triangles ``F`` (m, 3)), and the parents of those
    (``parents`` (J,) int, −1 for the root).

    Returns (n, K) int64 joint indices, each row's distinct ones first, −1 padded."""
    S = smooth_weights(W, F, iterations=spread, max_weights=count)
    has = np.asarray(S.todense()) > 0
    parents = np.asarray(parents, dtype=np.int64)
    rows, cols = np.nonzero(has)
    up = parents[cols]
    ok = up >= 0
    has[rows[ok], up[ok]] = True
    K = int(has.sum(axis=1).max())
    order = np.argsort(~has, axis=1, kind="stable")[:, :K]  # the candidates first
    out = np.where(np.take_along_axis(has, order, axis=1), order, -1)
    return out.astype(np.int64)


def simplex_projection(X: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Each row of ``X`` (n, K) float64 projected onto the probability simplex of its
    ``valid`` (n, K) bool entries (the others 0; each row needs one): the nearest
    non-negative row summing to 1, ``max(x − θ, 0)`` with one ``θ`` a row, by sorting
    (Held, Wolfe and Crowder 1974). Returns (n, K) float64."""
    U = np.where(valid, X, -np.inf)
    U = -np.sort(-U, axis=1)
    U = np.where(np.isfinite(U), U, 0.0)
    css = np.cumsum(U, axis=1)
    j = np.arange(1, X.shape[1] + 1)
    m = valid.sum(axis=1)
    cond = (U - (css - 1.0) / j > 0) & (j <= m[:, None])
    rho = np.maximum(cond.shape[1] - np.argmax(cond[:, ::-1], axis=1), 1)
    theta = (np.take_along_axis(css, (rho - 1)[:, None], axis=1)[:, 0] - 1.0) / rho
    return np.where(valid, np.maximum(X - theta[:, None], 0.0), 0.0)


def fit_weights(
    V0: np.ndarray,
    A: np.ndarray,
    X: np.ndarray,
    W: sp.spmatrix,
    candidates: np.ndarray,
    *,
    prior: float = 1e-5,
    max_weights: int = 4,
    iterations: int = 300,
) -> sp.csr_matrix:
    """Skinning weights fitted to surfaces in known poses (a skinning decomposition with
    the skeleton given): for each vertex ``i`` the weights ``w`` (non-negative, summing to
    1, over its ``candidates`` joints) minimising::

        Σ_t |Σ_k w_k A_t,k [v_i; 1] − x_t,i|²  +  prior · T · |w − w⁰|²

    (``w⁰`` its weights in ``W``, the pull where the frames do not tell the joints apart),
    by accelerated projected gradient (Beck and Teboulle 2009) over all vertices at once;
    then its ``max_weights`` largest weights, renormalised.

    Parameters
    ----------
    V0 : (n, 3) float64
        Rest vertices, metres.
    A : (T, J, 3, 4) float64
        The frames' skinning transforms (:func:`skinning_transforms`).
    X : (T, n, 3) float64
        The surfaces the skinned vertices should reach, metres (the same vertices).
    W : (n, J) sparse
        The weights to start from and pull towards, rows summing to 1.
    candidates : (n, K) int64
        Each vertex's joints, −1 padded (:func:`weight_candidates`).
    prior : float
        m² per frame: the squared distance a unit change of one weight costs as much as.
    max_weights, iterations : int
        Weights kept per vertex; gradient steps.

    Returns
    -------
    (n, J) scipy.sparse CSR float64, rows summing to 1.
    """
    V0 = np.asarray(V0, dtype=np.float64)
    A = np.asarray(A, dtype=np.float64)
    X = np.asarray(X, dtype=np.float64)
    C = np.asarray(candidates, dtype=np.int64)
    n, K = C.shape
    T, J = A.shape[:2]
    if X.shape != (T, n, 3) or V0.shape != (n, 3) or A.shape[2:] != (3, 4):
        raise InputError(
            f"fit_weights: V0 (n, 3), A (T, J, 3, 4) and X (T, n, 3) must agree, found "
            f"{V0.shape}, {A.shape}, {X.shape}"
        )
    if not (np.isfinite(prior) and prior > 0):
        raise InputError(f"fit_weights: prior must be > 0, found {prior!r}")
    valid = C >= 0
    Cv = np.where(valid, C, 0)
    Vh = np.concatenate([V0, np.ones((n, 1))], axis=1)
    M = np.zeros((n, K, K))
    b = np.zeros((n, K))
    rows = np.arange(n)[:, None]
    for t in range(T):  # per frame: (n, K, 3) each candidate joint's image of each vertex
        Y = np.einsum("jab,nb->nja", A[t], Vh)[rows, Cv] * valid[..., None]
        M += np.einsum("nka,nla->nkl", Y, Y)
        b += np.einsum("nka,na->nk", Y, X[t])
    W0 = np.asarray(sp.csr_matrix(W)[rows, Cv].todense()) * valid
    lam = float(prior) * T
    M += lam * np.eye(K)
    b += lam * W0
    # 1 / the Lipschitz constant of the gradient along the simplex's plane (Σ w = 1): the
    # candidates' images lie close together, so M's largest eigenvalue (along 1) is far
    # above those within the plane, which alone bound the steps there
    v = valid.astype(np.float64)
    P = v[:, :, None] * np.eye(K) - v[:, :, None] * v[:, None, :] / v.sum(axis=1)[:, None, None]
    step = 1.0 / np.maximum(np.linalg.eigvalsh(P @ M @ P)[:, -1], lam)
    w = simplex_projection(W0, valid)
    z, s = w.copy(), 1.0
    for _ in range(int(iterations)):
        g = np.einsum("nkl,nl->nk", M, z) - b
        w_next = simplex_projection(z - step[:, None] * g, valid)
        s_next = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * s * s))
        z = w_next + ((s - 1.0) / s_next) * (w_next - w)
        w, s = w_next, s_next
    out = np.zeros((n, J))
    np.add.at(out, (np.broadcast_to(rows, C.shape)[valid], C[valid]), w[valid])
    keep = min(int(max_weights), J)
    cut = np.argpartition(-out, keep - 1, axis=1)[:, :keep]
    kept = np.zeros_like(out)
    kept[rows, cut] = out[rows, cut]
    kept /= np.maximum(kept.sum(axis=1, keepdims=True), UNDERFLOW_FLOOR)
    return sp.csr_matrix(kept)
