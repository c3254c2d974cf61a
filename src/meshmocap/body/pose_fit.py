"""Skeleton poses from tracked surfaces: the rig rotations whose skinning reproduces them.

A tracker deforms the template's own vertices, so every tracked vertex has a known rest
vertex: the pose that explains a frame is the least-squares fit

    ``min_{t, R}  (1/p) Σ_i |v_i(t, R) − y_i|²  +  λ (1/K) Σ_k |e_k(t, R) − x_k|²``

of linear-blend skinning ``v_i = Σ_j w_ij A_j ṽ_i`` (:mod:`meshmocap.body.skinning`) to the
tracked vertices ``y_i`` (a fixed, area-weighted sample of ``p`` of them), plus, optionally,
of the skinned evaluation joints ``e_k`` to the tracked joints ``x_k`` (weight λ): a tracker
that reads its joints off the surface by another rule (the patch tracker's blended
read-out) reports joints that the rig places a few millimetres away, and the second term
pulls the fit onto them. Known correspondences make it a plain Levenberg–Marquardt
(Gauss–Newton with an adaptive damping) on the root translation and a world-frame rotation
increment per joint, with the exact lever arms of :mod:`meshmocap.body.articulated`;
each frame starts from the previous frame's pose (the first from a rigid alignment of
the rest template, Kabsch).

What it is for: exports (BVH, glTF) whose skeleton animation, played on the template,
gives back the tracked surface (see :func:`pose_from_surface`'s errors).

Units: metres and radians, world frame Z up.

References
----------
- N. Magnenat-Thalmann, R. Laperrière, D. Thalmann, *Joint-dependent local
  deformations for hand animation and object grasping*, Graphics Interface, 26–33, 1988.
- D. W. Marquardt, *An algorithm for least-squares estimation of nonlinear
  parameters*, Journal of the Society for Industrial and Applied Mathematics
  11(2):431–441, 1963. https://doi.org/10.1137/0111030
- W. Kabsch, *A solution for the best rotation to relate two sets of vectors*,
  Acta Crystallographica A32(5):922–923, 1976.
  https://doi.org/10.1107/S0567739476001873
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from meshmocap.body.articulated import (
    ArticulatedModel,
    apply_increment,
    articulated_model,
    damped_solve,
    pose_points,
    subtree_matrix,
)
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.geometry.levenberg_marquardt import DAMPING, AdaptiveDamping

#: Smallest cost the fit's relative decrease is measured against (a perfect fit's cost is 0).
_COST_FLOOR = 1e-30
#: Largest parameter update (radians, metres) that still counts as a step: below it the fit
#: has converged.
_STEP_DONE = 1e-7

__all__ = [
    "PoseFit",
    "eval_joint_model",
    "normal_equations",
    "pose_from_surface",
    "rigid_alignment",
]


@dataclass(frozen=True, eq=False)
class PoseFit:
    """Skeleton poses fitted to tracked surfaces (:func:`pose_from_surface`).

    Attributes
    ----------
    rotations : (T, J, 3, 3) float64, local rotations of the template's rig
    root_positions : (T, 3) float64, metres, world frame (Z up)
    vertex_error : (T,) float64, mean distance between the re-skinned and the given
        vertices (all of them), metres
    joint_error : (T,) float64, mean distance between the re-skinned evaluation joints and
        the given joints, metres (NaN when no joints were given)
    n_iter : (T,) int64, iterations per frame
    """

    rotations: np.ndarray
    root_positions: np.ndarray
    vertex_error: np.ndarray
    joint_error: np.ndarray
    n_iter: np.ndarray


def eval_joint_model(template: Template) -> ArticulatedModel:
    """The template's evaluation joints as articulated model points: each is skinned by its
    rig weights (``eval_weights``) from its rest position, like a vertex."""
    ev = template.eval_skeleton
    W = sp.csr_matrix(ev.weights)
    W.sort_indices()
    coo = W.tocoo()
    D = subtree_matrix(template.skeleton)
    K = len(ev.names)
    return ArticulatedModel(
        template=template,
        sample=np.arange(K),
        W=W,
        rows=coo.row.astype(np.int64),
        cols=coo.col.astype(np.int64),
        X=ev.rest_positions,
        N0=np.zeros((K, 3)),
        W_acc=np.asarray(W @ D),
        D=D,
    )


def rigid_alignment(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``R`` (3, 3) and translation ``t`` (3,) minimising ``Σ |R x + t − y|²``
    (Kabsch; X, Y (n, 3) float64 in corresponding order)."""
    mx, my = X.mean(axis=0), Y.mean(axis=0)
    U, _, Vt = np.linalg.svd((Y - my).T @ (X - mx))
    d = np.sign(np.linalg.det(U @ Vt))
    R = U @ np.diag([1.0, 1.0, d]) @ Vt
    return R, my - R @ mx


def normal_equations(
    v: np.ndarray, a: np.ndarray, Y: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """Cost ``Σ_i |v_i − y_i|²``, Gauss–Newton matrix ``H`` (3 + 3J, 3 + 3J) and gradient
    ``g`` (3 + 3J,) (half the cost's) of known-correspondence point-to-point residuals.

    With ``∂v_i = t + Σ_j ω_j × a_ij`` (:func:`~meshmocap.body.articulated.pose_points`),
    the Jacobian block of joint j is ``−[a_ij]×``, so without forming it:
    ``H_tt = p I``, ``H_tω_k = −[Σ_i a_ik]×``, ``H_ω_jω_k = Σ_i (a_ij·a_ik) I − a_ik a_ijᵀ``
    (from ``[a]×[b]× = b aᵀ − (a·b) I``), ``g_t = Σ_i r_i``, ``g_ω_j = Σ_i a_ij × r_i``.

    Parameters
    ----------
    v : (p, 3) float64, model points; a : (p, J, 3) float64, their lever arms
    Y : (p, 3) float64, target of each point, metres
    """
    p, J = a.shape[:2]
    r = v - Y
    M = a.reshape(p, 3 * J)
    C = (M.T @ M).reshape(J, 3, J, 3)  # C[j, c, k, d] = Σ_i a_ij[c] a_ik[d]
    tr = np.einsum("jckc->jk", C)
    H = np.zeros((3 + 3 * J, 3 + 3 * J))
    Hww = tr[:, None, :, None] * np.eye(3)[None, :, None, :] - C.transpose(0, 3, 2, 1)
    H[3:, 3:] = Hww.reshape(3 * J, 3 * J)
    H[:3, :3] = p * np.eye(3)
    s = a.sum(axis=0)  # (J, 3)
    Htw = np.zeros((3, J, 3))  # −[s_k]× for each k
    Htw[0, :, 1], Htw[0, :, 2] = s[:, 2], -s[:, 1]
    Htw[1, :, 0], Htw[1, :, 2] = -s[:, 2], s[:, 0]
    Htw[2, :, 0], Htw[2, :, 1] = s[:, 1], -s[:, 0]
    H[:3, 3:] = Htw.reshape(3, 3 * J)
    H[3:, :3] = H[:3, 3:].T
    g = np.concatenate([r.sum(axis=0), np.cross(a, r[:, None, :]).sum(axis=0).ravel()])
    return float(np.sum(r * r)), H, g


def _fit_frame(
    models: list[tuple[ArticulatedModel, np.ndarray, float]],
    R: np.ndarray,
    root: np.ndarray,
    *,
    max_iter: int,
    tol: float,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Levenberg–Marquardt on ``Σ_m weight_m Σ |v − y|²`` over (model, targets, weight)."""
    sk = models[0][0].template.skeleton

    def system(R, root):
        cost, H, g = 0.0, 0.0, 0.0
        for model, Y, w in models:
            v, _, a = pose_points(model, R, root)
            c, h, gg = normal_equations(v, a, Y)
            cost, H, g = cost + w * c, H + w * h, g + w * gg
        return cost, H, g

    mu = AdaptiveDamping(DAMPING["pose_fit"].lam)
    cost, H, g = system(R, root)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        delta = damped_solve(H, g, damping=mu.lam)
        R_new, root_new = apply_increment(sk, R, root, delta)
        new, H_new, g_new = system(R_new, root_new)
        if new > cost:  # reject, damp more (or give up)
            if not mu.rejected():
                break
            continue
        mu.accepted()
        done = cost - new <= tol * max(cost, _COST_FLOOR) or np.abs(delta).max() < _STEP_DONE
        R, root, cost, H, g = R_new, root_new, new, H_new, g_new
        if done:
            break
    return R, root, it


def pose_from_surface(
    template: Template,
    V: np.ndarray,
    *,
    joints: np.ndarray | None = None,
    joint_weight: float = 2.0,
    n_points: int = 2000,
    max_iter: int = 30,
    tol: float = 1e-6,
    seed: int = 0,
) -> PoseFit:
    """Fit the template's rig pose to each frame of tracked template vertices.

    Parameters
    ----------
    template : Template
        ``n`` vertices, ``J`` rig joints, ``K`` evaluation joints.
    V : (T, n, 3) or (n, 3) float64
        Tracked vertices of the template (its connectivity), metres, world frame (Z up).
    joints : (T, K, 3) or (K, 3) float64, optional
        Tracked evaluation joints to fit as well (see the module docstring).
    joint_weight : float
        λ ≥ 0: weight of the mean squared joint distance against the mean squared vertex
        distance.
    n_points : int
        Vertices fitted per frame (an area-weighted sample; all when the template has
        fewer). The errors reported use all vertices.
    max_iter : int
        Levenberg–Marquardt iterations per frame at most (≥ 1).
    tol : float
        Stop once an iteration lowers the cost by less than this fraction.
    seed : int
        Seeds the sample.

    Returns
    -------
    PoseFit
        One pose per frame (a leading axis even for one frame).

    Raises
    ------
    InputError
        Shapes that do not match the template, non-finite values, bad options.
    """
    n, K = template.n_vertices, len(template.eval_skeleton.names)
    V = np.asarray(V, dtype=np.float64)
    V = V[None] if V.ndim == 2 else V
    if V.ndim != 3 or V.shape[1:] != (n, 3) or len(V) == 0:
        raise InputError(
            f"pose_from_surface: V must have shape (T, {n}, 3) (template {template.name!r}), "
            f"found {V.shape}"
        )
    if not np.all(np.isfinite(V)):
        raise InputError("pose_from_surface: V contains NaN or infinite values")
    if joints is not None:
        X = np.asarray(joints, dtype=np.float64)
        X = X[None] if X.ndim == 2 else X
        if X.shape != (len(V), K, 3) or not np.all(np.isfinite(X)):
            raise InputError(
                f"pose_from_surface: joints must be finite with shape ({len(V)}, {K}, 3), "
                f"found {X.shape}"
            )
    if not (np.isfinite(joint_weight) and joint_weight >= 0):
        raise InputError(f"pose_from_surface: joint_weight must be ≥ 0, found {joint_weight!r}")
    if int(max_iter) < 1 or int(n_points) < 1:
        raise InputError(
            f"pose_from_surface: max_iter and n_points must be ≥ 1, found {max_iter}, {n_points}"
        )
    model = articulated_model(template, n_points=int(n_points), seed=seed)
    jmodel = eval_joint_model(template) if joints is not None and joint_weight > 0 else None
    sk = template.skeleton
    T, J = len(V), sk.n_joints
    Rs, roots = np.empty((T, J, 3, 3)), np.empty((T, 3))
    iters = np.zeros(T, np.int64)
    p = len(model.sample)
    Q, t = rigid_alignment(template.V, V[0])
    R = np.broadcast_to(np.eye(3), (J, 3, 3)).copy()
    R[0] = Q
    root = Q @ sk.rest_positions[0] + t
    for f in range(T):
        terms = [(model, V[f, model.sample], 1.0 / p)]
        if jmodel is not None:
            terms.append((jmodel, X[f], joint_weight / K))
        R, root, iters[f] = _fit_frame(terms, R, root, max_iter=int(max_iter), tol=tol)
        Rs[f], roots[f] = R, root
    posed = template.pose(Rs, roots)
    verr = np.linalg.norm(posed.V - V, axis=2).mean(axis=1)
    jerr = (
        np.linalg.norm(posed.eval_joints - X, axis=2).mean(axis=1)
        if joints is not None
        else np.full(T, np.nan)
    )
    return PoseFit(Rs, roots, verr, jerr, iters)
