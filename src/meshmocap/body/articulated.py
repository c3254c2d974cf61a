"""The articulated body model and its Gauss–Newton pieces: a template driven by its
skeleton through linear-blend skinning, posed on a fixed subset of model points, with the
exact derivatives of every point with respect to a root translation and a rotation
increment per joint.

Shared by the articulated ICP baseline (:mod:`meshmocap.trackers.articulated_icp`, the
skeleton-based baseline of patch-skeleton-tracking.txt §IV-B) and automatic rigging
(:mod:`meshmocap.body.autorig`). Everything is in metres and radians, world frame Z up.

**Parametrisation** (documented choice): ω_j is a *world-frame* rotation increment
left-multiplying joint j's global rotation and rotating its whole subtree about the joint's
world position p_j, i.e. the local rotation is updated as ``R_j ← exp(G_parentᵀ ω_j) R_j``
(``G_parent = I`` for the root, which turns about its own position; t moves it). The
derivative of a skinned vertex ``v_i = Σ_k w_ik A_k ṽ_i`` is then exactly

    ∂v_i/∂t = I,   ∂v_i/∂ω_j · ω = ω × a_ij,   a_ij = Σ_{k ∈ subtree(j)} w_ik (A_k ṽ_i − p_j)

a "subtree-accumulated" blend: with ``D[k, j] = 1`` when j is an ancestor-or-self of k,
``a_ij = ((W ∘ Y) D)_ij − (W D)_ij p_j`` where ``Y_ik = A_k ṽ_i`` (only over the sparse
weights). The shortcut ``(W D)_ij (v_i − p_j)`` is exact only for vertices whose weights all
lie inside or all outside subtree(j); the exact form costs the same (three sparse
products per iteration) and is what the finite-difference test checks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from pykdtree.kdtree import KDTree

from meshmocap.body.skeleton import Skeleton, forward_kinematics
from meshmocap.body.skinning import skinning_transforms
from meshmocap.body.template import Template
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import cross, so3_exp, so3_log

__all__ = [
    "FIXED_JOINTS",
    "ArticulatedModel",
    "Residual",
    "apply_increment",
    "articulated_model",
    "limit_step",
    "nearest_compatible",
    "pose_points",
    "residual_jacobian",
    "rest_rotation_error",
    "subtree_matrix",
]

Residual = Literal["point_to_plane", "point_to_point"]

#: Rig joints held at their initial rotation by default: CMU-style structural joints that
#: carry no degrees of freedom in motion capture (hip offsets, fingers, thumbs, toes). Free,
#: they are barely observed by a visual hull and drift in the data term's near-null space
#: (e.g. LHipJoint swings the whole leg sideways into the hull's phantom volume).
FIXED_JOINTS = (
    "LHipJoint",
    "RHipJoint",
    "LeftToeBase",
    "RightToeBase",
    "LeftFingerBase",
    "LeftHandIndex1",
    "LThumb",
    "RightFingerBase",
    "RightHandIndex1",
    "RThumb",
)


def subtree_matrix(skeleton: Skeleton) -> np.ndarray:
    """Return ``D`` (J, J) float64 with ``D[k, j] = 1`` when j is an ancestor-or-self of k."""
    J = skeleton.n_joints
    D = np.eye(J)
    for k in range(1, J):  # parents precede children: copy the parent's row
        D[k] += D[skeleton.parents[k]]
    return D


@dataclass(frozen=True, eq=False)
class ArticulatedModel:
    """The model points of a template and the constant parts of their Jacobian.

    Attributes
    ----------
    template : Template
    sample : (m,) int64, template vertex index of each model point
    W : (m, J) scipy.sparse.csr_matrix, their skinning weights (sorted indices)
    rows, cols : (nnz,) int64, the nonzeros of ``W`` in storage order
    X : (m, 3) float64, rest positions (metres); ``N0`` (m, 3) rest unit normals
    W_acc : (m, J) float64, subtree-accumulated weights ``W @ D``
    D : (J, J) float64, :func:`subtree_matrix`
    """

    template: Template
    sample: np.ndarray
    W: sp.csr_matrix
    rows: np.ndarray
    cols: np.ndarray
    X: np.ndarray
    N0: np.ndarray
    W_acc: np.ndarray
    D: np.ndarray


def articulated_model(
    template: Template, *, n_points: int = 1500, seed: int = 0
) -> ArticulatedModel:
    """Sample ``n_points`` template vertices (probability ∝ vertex area, no repeats; all
    vertices when the template has fewer) and precompute their weights."""
    V, F = template.V, template.F
    tri = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    area = np.bincount(F.ravel(), np.repeat(tri / 6.0, 3), minlength=len(V)) + 1e-12
    if n_points >= len(V):
        sample = np.arange(len(V))
    else:
        rng = np.random.default_rng(seed)
        sample = np.sort(rng.choice(len(V), n_points, replace=False, p=area / area.sum()))
    W = sp.csr_matrix(template.weights[sample])
    W.sort_indices()
    coo = W.tocoo()
    D = subtree_matrix(template.skeleton)
    return ArticulatedModel(
        template=template,
        sample=sample,
        W=W,
        rows=coo.row.astype(np.int64),
        cols=coo.col.astype(np.int64),
        X=V[sample],
        N0=vertex_normals(V, F)[sample],
        W_acc=np.asarray(W @ D),
        D=D,
    )


def pose_points(
    model: ArticulatedModel, R: np.ndarray, root: np.ndarray, *, jacobian: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Skin the model points and return what the Gauss–Newton step needs.

    Parameters
    ----------
    R : (J, 3, 3) float64, local joint rotations; ``root`` (3,) float64, metres.

    Returns
    -------
    v : (m, 3) float64, posed model points, metres, world frame
    n : (m, 3) float64, their unit normals (rest normals turned by the blended rotation)
    a : (m, J, 3) float64 or None
        Lever arms: ``∂v_i = t + Σ_j ω_j × a[i, j]`` for the increments of
        :func:`apply_increment` (see the module docstring).
    """
    sk = model.template.skeleton
    G, P = forward_kinematics(sk, R, root)
    A = skinning_transforms(G, P, sk.rest_positions)  # (J, 3, 4)
    rows, cols, w = model.rows, model.cols, model.W.data
    Y = np.einsum("nab,nb->na", A[cols, :, :3], model.X[rows]) + A[cols, :, 3]  # (nnz, 3)
    m = len(model.sample)
    wY = w[:, None] * Y
    v = np.stack([np.bincount(rows, wY[:, c], minlength=m) for c in range(3)], 1)
    B = (model.W @ G.reshape(-1, 9)).reshape(m, 3, 3)  # blended linear parts
    n = np.einsum("mab,mb->ma", B, model.N0)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    if not jacobian:
        return v, n, None
    S = model.W.copy()
    U = np.empty((m, sk.n_joints, 3))
    for c in range(3):  # U[i, j] = Σ_{k ∈ subtree(j)} w_ik Y_ik
        S.data = wY[:, c]
        U[:, :, c] = S @ model.D
    a = U - model.W_acc[:, :, None] * P[None]
    return v, n, a


def apply_increment(
    skeleton: Skeleton,
    R: np.ndarray,
    root: np.ndarray,
    delta: np.ndarray,
    *,
    G: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the pose ``(R', root')`` after the increment ``delta`` = (t, ω_0 … ω_{J−1}).

    Parameters
    ----------
    R : (J, 3, 3) float64, local rotations; ``root`` (3,) float64, metres
    delta : (3 + 3J,) float64: root translation (metres), then world-frame rotation
        vectors (radians) applied at each joint: ``R_j ← exp(G_parentᵀ ω_j) R_j``.
    G : (J, 3, 3) float64, optional
        The global rotations of ``R`` when the caller has them (saves forward kinematics).
    """
    J = skeleton.n_joints
    if G is None:
        G, _ = forward_kinematics(skeleton, R, root)
    Gp = np.concatenate([np.eye(3)[None], G[skeleton.parents[1:]]])
    omega = delta[3:].reshape(J, 3)
    local = np.einsum("jba,jb->ja", Gp, omega)  # G_parentᵀ ω_j
    return so3_exp(local) @ R, root + delta[:3]


def limit_step(delta: np.ndarray, max_angle: float) -> np.ndarray:
    """Shorten each joint's rotation in an increment ``delta`` (3 + 3J,) (as in
    :func:`apply_increment`) to at most ``max_angle`` radians; returns a new array."""
    out = np.array(delta, dtype=np.float64)
    w = out[3:].reshape(-1, 3)
    ang = np.linalg.norm(w, axis=1, keepdims=True)
    out[3:] = (w * np.minimum(1.0, max_angle / np.maximum(ang, 1e-12))).ravel()
    return out


def rest_rotation_error(skeleton: Skeleton, R: np.ndarray, root: np.ndarray) -> np.ndarray:
    """(J, 3) float64: each joint's rotation away from its rest, as a world-frame rotation
    vector ``G_parent log(R_j)`` (radians), the residual of a weak pull towards the rest
    pose whose derivative with respect to the increments of :func:`apply_increment` is about
    the identity."""
    G, _ = forward_kinematics(skeleton, R, root)
    Gp = np.concatenate([np.eye(3)[None], G[skeleton.parents[1:]]])
    return np.einsum("jab,jb->ja", Gp, so3_log(R))


def residual_jacobian(
    v: np.ndarray,
    a: np.ndarray,
    i: np.ndarray,
    y: np.ndarray,
    ny: np.ndarray,
    residual: Residual,
) -> tuple[np.ndarray, np.ndarray]:
    """Residuals and their Jacobian for pairs (model point ``i``, observed point ``y``).

    Parameters
    ----------
    v : (m, 3) and a : (m, J, 3) float64 from :func:`pose_points`
    i : (p,) int64, model point of each pair
    y, ny : (p, 3) float64, observed point (metres) and its unit normal
    residual : {"point_to_plane", "point_to_point"}

    Returns
    -------
    r : (p,) or (3p,) float64, metres: ``ny · (v_i − y)`` or the coordinates of ``v_i − y``
    Jr : (p, 3 + 3J) or (3p, 3 + 3J) float64, derivatives w.r.t. (t, ω_0 … ω_{J−1})
    """
    ai = a[i]  # (p, J, 3)
    p, J = ai.shape[:2]
    d = v[i] - y
    if residual == "point_to_plane":  # ∂(n·v)/∂ω_j = n·(ω_j × a_ij) = ω_j·(a_ij × n)
        r = np.sum(ny * d, axis=1)
        Jr = np.concatenate([ny, cross(ai, ny[:, None, :]).reshape(p, 3 * J)], axis=1)
        return r, Jr
    # ∂v/∂ω_j = −[a_ij]× : row c of the cross-product matrix of −a_ij, for each axis c
    Jw = np.zeros((p, 3, J, 3))
    ax, ay, az = ai[..., 0], ai[..., 1], ai[..., 2]
    Jw[:, 0, :, 1], Jw[:, 0, :, 2] = az, -ay
    Jw[:, 1, :, 0], Jw[:, 1, :, 2] = -az, ax
    Jw[:, 2, :, 0], Jw[:, 2, :, 1] = ay, -ax
    It = np.broadcast_to(np.eye(3), (p, 3, 3))
    Jr = np.concatenate([It, Jw.reshape(p, 3, 3 * J)], axis=2)
    return d.reshape(-1), Jr.reshape(3 * p, 3 + 3 * J)


def nearest_compatible(
    tree: KDTree,
    n_tree: np.ndarray,
    q: np.ndarray,
    n_q: np.ndarray,
    *,
    k: int,
    max_distance: float,
    normal_cos: float,
) -> tuple[np.ndarray, np.ndarray]:
    """For each query point, the nearest tree point within ``max_distance`` whose normal
    agrees (``n_tree · n_q > normal_cos``), among the ``k`` nearest.

    Returns the indices of the queries that found one (q,) and of their partners (q,).
    """
    from meshmocap.body._articulated_kernels import compatible_kernel, first_compatible_kernel

    k = min(k, tree.n)
    n_tree = np.ascontiguousarray(n_tree, dtype=np.float64)
    n_q = np.ascontiguousarray(n_q, dtype=np.float64)
    # the nearest point first (4× cheaper than k of them): most queries stop there; the
    # others search their k nearest, with the same result as one search of k for all
    _, idx = tree.query(q, k=1, distance_upper_bound=max_distance)
    partner, retry = compatible_kernel(idx.astype(np.int64), n_tree, n_q, normal_cos, tree.n)
    if len(retry) and k > 1:
        _, idx = tree.query(q[retry], k=k, distance_upper_bound=max_distance)
        idx = idx.reshape(len(retry), k).astype(np.int64)
        first_compatible_kernel(idx, n_tree, n_q, retry, normal_cos, tree.n, partner)
    queries = np.flatnonzero(partner >= 0)
    return queries, partner[queries]
