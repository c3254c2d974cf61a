"""The articulated body model and its Gauss–Newton pieces: a template driven by its
skeleton through linear-blend skinning, posed on a fixed subset of model points, with the
exact derivatives of every point with respect to a root translation and a rotation
increment per joint.

**One Gauss–Newton step for every articulated fit**: the articulated ICP baseline
(:mod:`meshmocap.trackers.articulated_icp`, the skeleton-based baseline of
patch-skeleton-tracking.txt §IV-B), the first-pose search (:mod:`meshmocap.estimate.pose.fit`),
automatic rigging (:mod:`meshmocap.body.autorig`) and the shape fit
(:mod:`meshmocap.estimate.performer.shape_fit`) assemble their normal equations from the pieces here
(closest pairs both ways, :func:`closest_pairs`; their point-to-plane plus point-to-point
system, :func:`closest_point_system`; the pull towards a reference pose,
:func:`add_pose_pull`) and take :func:`articulated_step`: one Levenberg–Marquardt damping
(:func:`damped_solve`, :data:`DAMPING`: the rule of
:mod:`meshmocap.geometry.levenberg_marquardt`) and one step limit
(:func:`limit_step`, :data:`MAX_STEP_ANGLE`). Everything is in metres and radians, world
frame Z up.

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

References
----------
- P. J. Besl, N. D. McKay, *A method for registration of 3-D shapes*, IEEE
  Transactions on Pattern Analysis and Machine Intelligence 14(2):239–256, 1992.
  https://doi.org/10.1109/34.121791
- Y. Chen, G. Medioni, *Object modelling by registration of multiple range
  images*, Image and Vision Computing 10(3):145–155, 1992.
  https://doi.org/10.1016/0262-8856(92)90066-C
- N. Magnenat-Thalmann, R. Laperrière, D. Thalmann, *Joint-dependent local
  deformations for hand animation and object grasping*, Graphics Interface, 26–33, 1988.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from pykdtree.kdtree import KDTree

from meshmocap._tolerances import DIVISOR_FLOOR, NORM_FLOOR
from meshmocap.body.skeleton import Skeleton, forward_kinematics
from meshmocap.body.skinning import skinning_transforms
from meshmocap.body.template import Template
from meshmocap.geometry import levenberg_marquardt as lm
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.rotations import cross, so3_exp, so3_log

__all__ = [
    "DAMPING",
    "FIXED_JOINTS",
    "MAX_STEP_ANGLE",
    "POINT_MIX",
    "ArticulatedModel",
    "Residual",
    "add_pose_pull",
    "apply_increment",
    "articulated_model",
    "articulated_step",
    "closest_pairs",
    "closest_point_system",
    "damped_solve",
    "limit_step",
    "model_subset",
    "nearest_compatible",
    "pose_points",
    "residual_jacobian",
    "rotation_error",
    "subtree_matrix",
]

Residual = Literal["point_to_plane", "point_to_point"]

#: Largest rotation (radians) of any joint in one Gauss–Newton step: the step is
#: linearised in the rotations, and a longer one overshoots (:func:`limit_step`).
MAX_STEP_ANGLE = 0.3
#: Levenberg–Marquardt λ of the articulated fits (relative to the diagonal,
#: :func:`damped_solve`; :data:`~meshmocap.geometry.levenberg_marquardt.DAMPING`
#: ``"articulated"``); the ICP tracker makes it an option.
DAMPING = lm.DAMPING["articulated"].lam
#: Weight of the point-to-point pull added to the point-to-plane closest-point residuals
#: (:func:`closest_point_system`): it holds a body part where its surface is flat.
POINT_MIX = 0.1
#: Pairs of each direction that the point-to-point pull uses (a weak pull: a subsample).
POINT_MIX_PAIRS = 500

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
    area = np.bincount(F.ravel(), np.repeat(tri / 6.0, 3), minlength=len(V)) + DIVISOR_FLOOR
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


def model_subset(model: ArticulatedModel, keep: np.ndarray) -> ArticulatedModel:
    """The model restricted to its points ``keep`` (k,) int64 (positions in
    ``model.sample``, sorted): :func:`pose_points` gives those points the same values as
    the whole model does (each point's sums run over its own weights alone)."""
    W = model.W[keep]
    W.sort_indices()
    coo = W.tocoo()
    return ArticulatedModel(
        template=model.template,
        sample=model.sample[keep],
        W=W,
        rows=coo.row.astype(np.int64),
        cols=coo.col.astype(np.int64),
        X=model.X[keep],
        N0=model.N0[keep],
        W_acc=model.W_acc[keep],
        D=model.D,
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
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), NORM_FLOOR)
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


def limit_step(delta: np.ndarray, max_angle: float = MAX_STEP_ANGLE) -> np.ndarray:
    """Shorten each joint's rotation in a pose increment ``delta`` (3 + 3J,) (as in
    :func:`apply_increment`) to at most ``max_angle`` radians; returns a new array."""
    out = np.array(delta, dtype=np.float64)
    w = out[3:].reshape(-1, 3)
    ang = np.linalg.norm(w, axis=1, keepdims=True)
    out[3:] = (w * np.minimum(1.0, max_angle / np.maximum(ang, NORM_FLOOR))).ravel()
    return out


def rotation_error(
    skeleton: Skeleton, R: np.ndarray, root: np.ndarray, R_ref: np.ndarray | None = None
) -> np.ndarray:
    """(J, 3) float64: each joint's rotation away from ``R_ref`` (J, 3, 3) (default: the
    rest pose), as a world-frame rotation vector ``G_parent log(R_j R̂_jᵀ)`` (radians): the
    residual of a pull towards ``R_ref`` whose derivative with respect to the increments of
    :func:`apply_increment` is about the identity (:func:`add_pose_pull`)."""
    G, _ = forward_kinematics(skeleton, R, root)
    Gp = np.concatenate([np.eye(3)[None], G[skeleton.parents[1:]]])
    rel = R if R_ref is None else R @ np.swapaxes(R_ref, 1, 2)
    return np.einsum("jab,jb->ja", Gp, so3_log(rel))


def add_pose_pull(
    H: np.ndarray, g: np.ndarray, e: np.ndarray, lam: float | np.ndarray, *, start: int = 3
) -> None:
    """Add the linearised pull ``Σ_j λ_j |e_j + ω_j|²`` to the normal equations in place.

    Parameters
    ----------
    H : (n, n) float64, g : (n,) float64, the Gauss–Newton system (``H = Σ JᵀJ``, ``g = Σ Jᵀr``)
    e : (k, 3) float64, rotation errors (:func:`rotation_error`), radians
    lam : float or (k,) float64, weight of each joint's squared error, m²/rad²
    start : int, the column of the first joint's ω (its three columns follow, then the
        next joint's)
    """
    lam3 = np.repeat(np.broadcast_to(np.asarray(lam, dtype=np.float64), (len(e),)), 3)
    idx = np.arange(start, start + 3 * len(e))
    H[idx, idx] += lam3
    g[idx] += lam3 * np.ravel(e)


def damped_solve(H: np.ndarray, g: np.ndarray, *, damping: float) -> np.ndarray:
    """The Levenberg–Marquardt increment ``x`` of ``(H + damping·diag(H) + ε·I) x = −g``
    (:func:`~meshmocap.geometry.levenberg_marquardt.damped_solve` with the articulated
    fits' floor ε, which keeps a parameter that nothing constrains at zero). ``H`` (n, n)
    and ``g`` (n,) float64 are not changed.

    Raises
    ------
    FitError
        The system is singular or the increment not finite.
    """
    return lm.damped_solve(H, g, lam=damping, floor=lm.DAMPING["articulated"].floor)


def articulated_step(
    skeleton: Skeleton,
    R: np.ndarray,
    root: np.ndarray,
    H: np.ndarray,
    g: np.ndarray,
    *,
    active: np.ndarray,
    damping: float = DAMPING,
    n_params: int | None = None,
    max_angle: float = MAX_STEP_ANGLE,
    G: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One damped Gauss–Newton step of the articulated pose: every articulated fit in
    meshmocap takes this step (the ICP tracker, the first-pose search, automatic rigging,
    the shape fit).

    Parameters
    ----------
    R : (J, 3, 3) float64, local rotations; ``root`` (3,) float64, metres
    H : (a, a) float64, g : (a,) float64
        ``Σ JᵀJ`` and ``Σ Jᵀr`` over the estimated parameters ``active``.
    active : (a,) int64
        Their indices in the parameter vector: (t, ω_0 … ω_{J−1}) of :func:`apply_increment`
        first, then any parameters of the caller's own (e.g. a scale).
    damping : float
        Levenberg–Marquardt damping relative to the diagonal (:func:`damped_solve`).
    n_params : int, optional
        Length of the parameter vector (default ``3 + 3J``).
    max_angle : float
        No joint turns by more than this in one step, radians (:func:`limit_step`).
    G : (J, 3, 3) float64, optional, the global rotations of ``R`` if known.

    Returns
    -------
    R, root : the pose after the step
    delta : (n_params,) float64, the step (rotations limited; zero off ``active``)

    Raises
    ------
    FitError
        Singular normal equations.
    """
    n_pose = 3 + 3 * skeleton.n_joints
    delta = np.zeros(n_pose if n_params is None else n_params)
    delta[active] = damped_solve(H, g, damping=damping)
    delta[:n_pose] = limit_step(delta[:n_pose], max_angle)
    R, root = apply_increment(skeleton, R, root, delta[:n_pose], G=G)
    return R, root, delta


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


def closest_pairs(
    tree: KDTree,
    Y: np.ndarray,
    NY: np.ndarray,
    v: np.ndarray,
    nv: np.ndarray,
    *,
    max_distance: float,
    normal_cos: float,
    k: int = 8,
    moving: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Closest compatible points both ways between model points and observed points
    (:func:`nearest_compatible`: within ``max_distance``, normals agreeing).

    Parameters
    ----------
    tree : KDTree of ``Y`` (p, 3), observed points (metres); ``NY`` (p, 3) their unit normals
    v, nv : (m, 3) float64, model points (metres) and their unit normals
    moving : (m,) bool, optional
        Only these model points take part (both ways), e.g. those a partial fit moves.

    Returns
    -------
    [(i, k), (i2, k2)] : the model→data pairs and the data→model pairs, each as model point
        indices and observed point indices (int64)
    """
    cand = dict(k=k, max_distance=max_distance, normal_cos=normal_cos)
    if moving is None:
        i, kk = nearest_compatible(tree, NY, v, nv, **cand)
        k2, i2 = nearest_compatible(KDTree(v), nv, Y, NY, **cand)
        return [(i, kk), (i2, k2)]
    on = np.flatnonzero(moving)
    i, kk = nearest_compatible(tree, NY, v[on], nv[on], **cand)
    k2, i2 = nearest_compatible(KDTree(v), nv, Y, NY, **cand)
    keep = moving[i2]
    return [(on[i], kk), (i2[keep], k2[keep])]


def closest_point_system(
    v: np.ndarray,
    a: np.ndarray,
    pairs: list[tuple[np.ndarray, np.ndarray]],
    weights: tuple[float, ...],
    Y: np.ndarray,
    NY: np.ndarray,
    *,
    extra: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Newton system of closest-point pairs: for each direction (weight w, p pairs)
    w times the mean squared point-to-plane residual ``n_y · (v_i − y)`` plus w times
    :data:`POINT_MIX` times the mean squared point-to-point residual ``v_i − y`` (over a
    subsample of :data:`POINT_MIX_PAIRS` pairs).

    Parameters
    ----------
    v : (m, 3) float64, model points; ``a`` (m, J', 3) their lever arms
        (:func:`pose_points`, possibly of a subset of J' joints)
    pairs : list of (model point indices, observed point indices), e.g. :func:`closest_pairs`
    weights : tuple of float, the weight of each direction
    Y, NY : (p, 3) float64, observed points (metres) and unit normals
    extra : (m, 3) float64, optional
        Every model point's derivative with respect to one more parameter (e.g. the log of a
        scale), appended as the last column.

    Returns
    -------
    H : (n, n) float64 and g : (n,) float64, ``n = 3 + 3J'`` (+1 with ``extra``): ``Σ JᵀJ``
    and ``Σ Jᵀr`` over (t, ω_0 … ω_{J'−1}[, extra])
    """
    n = 3 + 3 * a.shape[1] + (extra is not None)
    H, g = np.zeros((n, n)), np.zeros(n)
    for (ii, kk), w in zip(pairs, weights, strict=True):
        if len(ii) == 0:
            continue
        y, ny = Y[kk], NY[kk]
        r, Jr = residual_jacobian(v, a, ii, y, ny, "point_to_plane")
        if extra is not None:
            Jr = np.concatenate([Jr, np.sum(ny * extra[ii], axis=1)[:, None]], axis=1)
        H += (w / len(ii)) * (Jr.T @ Jr)
        g += (w / len(ii)) * (Jr.T @ r)
        sub = slice(None, None, max(1, len(ii) // POINT_MIX_PAIRS))
        r, Jr = residual_jacobian(v, a, ii[sub], y[sub], ny[sub], "point_to_point")
        if extra is not None:
            Jr = np.concatenate([Jr, extra[ii[sub]].reshape(-1, 1)], axis=1)
        s = w * POINT_MIX / len(ii[sub])
        H += s * (Jr.T @ Jr)
        g += s * (Jr.T @ r)
    return H, g
