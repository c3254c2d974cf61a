"""The Gauss–Newton normal equations of the articulated model, assembled from per-point
moments instead of a dense Jacobian.

:func:`~meshmocap.body.articulated.residual_jacobian` builds one dense row of ``3 + 3J``
derivatives per pair (most of them zero: a point moves with the few joints above the bones
that skin it), and ``JᵀJ`` then costs ``p (3 + 3J)²``: 40 MFLOP a Gauss–Newton iteration for
the 5,500 pairs of an ICP frame. Here the same ``H = JᵀJ`` and ``g = Jᵀr`` come from sums
that touch only the nonzero skinning weights:

1. every pair (model point i, observed point y with unit normal n, weight s) adds to its
   model point's ``S_i = Σ s n nᵀ`` and ``b_i = Σ s r n`` (point-to-plane; point-to-point
   adds ``s I`` and ``s (v_i − y)``), so a pair's row is ``M_i n`` with
   ``M_i = [I; [a_i0]×; …; [a_i,J−1]×]`` and ``H = Σ_i M_i S_i M_iᵀ``, ``g = Σ_i M_i b_i``;
2. the lever arms are sums over the point's nonzero weights e = (i, k):
   ``a_ij = Σ_{e: k ∈ subtree(j)} (q_e − w_e p_j)`` with ``q_e = w_e A_k ṽ_i``
   (:mod:`meshmocap.body.articulated`), so every block of ``H`` expands into moments over
   pairs (e, e') of weights of the same point, binned by their joints (k, k'):
   ``A = Σ [q_e]× S_i [q_e']×ᵀ``, ``B = Σ w_e S_i [q_e']×ᵀ``, ``D = Σ w_e w_e' S_i``, then
   summed over subtrees (``Ā_jl = Σ_{k ∈ sub(j), k' ∈ sub(l)} A_kk'``) and

       H_jl = Ā_jl − [p_j]× B̄_jl − ([p_l]× B̄_lj)ᵀ − [p_j]× D̄_jl [p_l]×
       H_tj = Ē_j + F̄_j [p_j]×,   E_k = Σ_{e: k} S_i [q_e]×ᵀ,  F_k = Σ_{e: k} w_e S_i
       g_j = Σ_{k ∈ sub(j)} Σ_{e: k} q_e × b_i − p_j × Σ_{k ∈ sub(j)} Σ_{e: k} w_e b_i

   (``[x]×ᵀ = −[x]×``). The cost is about 11,000 3×3 products for 1,500 model points
   whatever the number of pairs: 0.3–0.6 ms instead of 10–30.

The result equals the dense ``Σ JᵀJ`` to rounding (``tests/trackers/test_articulated_icp.py``).

References
----------
- P. J. Besl, N. D. McKay, *A method for registration of 3-D shapes*, IEEE
  Transactions on Pattern Analysis and Machine Intelligence 14(2):239–256, 1992.
  https://doi.org/10.1109/34.121791
- Y. Chen, G. Medioni, *Object modelling by registration of multiple range
  images*, Image and Vision Computing 10(3):145–155, 1992.
  https://doi.org/10.1016/0262-8856(92)90066-C
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from meshmocap.body._articulated_kernels import (
    normal_equations_kernel,
    pair_moments_kernel,
    point_motion_kernel,
    posed_kernel,
    rotation_error_kernel,
)
from meshmocap.body.articulated import POINT_MIX, POINT_MIX_PAIRS, ArticulatedModel

__all__ = [
    "MomentPlan",
    "PosedModel",
    "closest_point_moments",
    "moment_plan",
    "normal_equations",
    "pair_moments",
    "point_motion",
    "posed_model",
    "rotation_error",
]


@dataclass(frozen=True, eq=False)
class MomentPlan:
    """What :func:`normal_equations` precomputes once per model.

    Attributes
    ----------
    model : ArticulatedModel
    Xe : (nnz, 3) float64, rest position of the model point of each nonzero weight
    indptr : (m + 1,) int64, where each model point's nonzero weights start
    parents : (J,) int64, the skeleton's parents (−1 at the root)
    """

    model: ArticulatedModel
    Xe: np.ndarray
    indptr: np.ndarray
    parents: np.ndarray


def moment_plan(model: ArticulatedModel) -> MomentPlan:
    """Precompute what :func:`normal_equations` needs of ``model``."""
    return MomentPlan(
        model=model,
        Xe=model.X[model.rows],
        indptr=model.W.indptr.astype(np.int64),
        parents=model.template.skeleton.parents.astype(np.int64),
    )


@dataclass(frozen=True, eq=False)
class PosedModel:
    """The model points in one pose.

    Attributes
    ----------
    G : (J, 3, 3) float64, global joint rotations; ``P`` (J, 3) float64, joint positions
    q : (nnz, 3) float64, ``w_e A_k ṽ_i`` per nonzero weight e = (i, k), metres
    v : (m, 3) float64, posed model points (``Σ_e q_e``), metres, world frame
    n : (m, 3) float64, their unit normals (rest normals turned by the blended rotation)
    """

    G: np.ndarray
    P: np.ndarray
    q: np.ndarray
    v: np.ndarray
    n: np.ndarray


def posed_model(plan: MomentPlan, R: np.ndarray, root: np.ndarray) -> PosedModel:
    """Skin the model points of ``plan`` in the pose ``R`` (J, 3, 3) local rotations,
    ``root`` (3,) metres; the same positions and normals as
    :func:`~meshmocap.body.articulated.pose_points`."""
    model, sk = plan.model, plan.model.template.skeleton
    G, P, q, v, n = posed_kernel(
        np.ascontiguousarray(R, dtype=np.float64),
        np.asarray(root, dtype=np.float64),
        plan.parents,
        sk.offsets,
        sk.rest_positions,
        plan.indptr,
        model.cols,
        model.W.data,
        plan.Xe,
        model.N0,
    )
    return PosedModel(G=G, P=P, q=q, v=v, n=n)


def pair_moments(
    v: np.ndarray,
    i: np.ndarray,
    y: np.ndarray,
    ny: np.ndarray,
    s: np.ndarray,
    residual: Literal["point_to_plane", "point_to_point"],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-model-point moments of the pairs (model point ``i``, observed point ``y``).

    Parameters
    ----------
    v : (m, 3) float64, model points, metres; ``i`` (p,) int64, model point of each pair
    y, ny : (p, 3) float64, observed points (metres) and unit normals
    s : (p,) float64, weight of each pair's squared residual
    residual : {"point_to_plane", "point_to_point"}

    Returns
    -------
    S : (m, 3, 3) float64, ``Σ s n nᵀ`` (point-to-plane) or ``Σ s I``
    b : (m, 3) float64, ``Σ s r n`` or ``Σ s (v_i − y)``, metres
    r2 : (p,) float64, each pair's squared residual, metres²
    """
    return pair_moments_kernel(
        np.ascontiguousarray(v, dtype=np.float64),
        np.ascontiguousarray(i, dtype=np.int64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(ny, dtype=np.float64),
        np.ascontiguousarray(s, dtype=np.float64),
        residual == "point_to_plane",
    )


def closest_point_moments(
    v: np.ndarray,
    pairs: list[tuple[np.ndarray, np.ndarray]],
    weights: tuple[float, ...],
    Y: np.ndarray,
    NY: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The per-model-point moments (:func:`pair_moments`, summed) of the energy of
    :func:`~meshmocap.body.articulated.closest_point_system`: for each direction (weight
    w, p pairs) w times the mean squared point-to-plane residual plus w times
    :data:`~meshmocap.body.articulated.POINT_MIX` times the mean squared point-to-point
    residual over the same subsample of pairs.

    Parameters
    ----------
    v : (m, 3) float64, model points, metres
    pairs : list of (model point indices, observed point indices) (int64), e.g.
        :func:`~meshmocap.body.articulated.closest_pairs`
    weights : tuple of float, the weight of each direction
    Y, NY : (p, 3) float64, observed points (metres) and unit normals

    Returns
    -------
    S : (m, 3, 3) float64 and b : (m, 3) float64, for :func:`normal_equations`
    """
    m = len(v)
    S, b = np.zeros((m, 3, 3)), np.zeros((m, 3))
    for (ii, kk), w in zip(pairs, weights, strict=True):
        if not len(ii):
            continue
        ws = np.full(len(ii), w / len(ii))
        S1, b1, _ = pair_moments(v, ii, Y[kk], NY[kk], ws, "point_to_plane")
        sub = slice(None, None, max(1, len(ii) // POINT_MIX_PAIRS))
        ws = np.full(len(ii[sub]), w * POINT_MIX / len(ii[sub]))
        S2, b2, _ = pair_moments(v, ii[sub], Y[kk[sub]], NY[kk[sub]], ws, "point_to_point")
        S, b = S + S1 + S2, b + b1 + b2
    return S, b


def normal_equations(
    plan: MomentPlan, posed: PosedModel, S: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``H = Σ JᵀJ`` (3 + 3J, 3 + 3J) and ``g = Σ Jᵀr`` (3 + 3J,) of the pairs summarised
    by the moments ``S`` (m, 3, 3) and ``b`` (m, 3) (:func:`pair_moments`), for the pose
    parameters (t, ω_0 … ω_{J−1}) of :func:`~meshmocap.body.articulated.apply_increment`
    (see the module docstring)."""
    model = plan.model
    return normal_equations_kernel(
        plan.indptr, model.cols, model.W.data, posed.q, S, b, posed.P, plan.parents
    )


def point_motion(plan: MomentPlan, posed: PosedModel, delta: np.ndarray) -> np.ndarray:
    """(m, 3) float64: the first-order displacement ``t + Σ_j ω_j × a_ij`` of every model
    point under the increment ``delta`` = (t, ω_0 … ω_{J−1}) (metres)."""
    model = plan.model
    return point_motion_kernel(
        np.asarray(delta, dtype=np.float64),
        posed.P,
        posed.q,
        plan.indptr,
        model.cols,
        model.W.data,
        plan.parents,
    )


def rotation_error(
    plan: MomentPlan, posed: PosedModel, R: np.ndarray, R_ref: np.ndarray
) -> np.ndarray:
    """(J, 3) float64: ``G_parent log(R_j R̂_jᵀ)``, every joint's rotation (local ``R``
    (J, 3, 3), posed as ``posed``) away from ``R_ref`` (J, 3, 3), as a world-frame rotation
    vector (radians), the residual of a pull towards ``R_ref`` whose derivative with respect
    to the increments of :func:`~meshmocap.body.articulated.apply_increment` is about the
    identity."""
    return rotation_error_kernel(
        np.ascontiguousarray(R, dtype=np.float64),
        np.ascontiguousarray(R_ref, dtype=np.float64),
        posed.G,
        plan.parents,
    )
