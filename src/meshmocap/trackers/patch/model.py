"""The patch model of the patch tracker (patch-skeleton-tracking.txt §III), precomputed once
per template: patches, their neighbourhoods and rigidity weights, the bone each patch is
bound to, and the blending that turns patch transforms into a smooth mesh.

Notation: a patch ``k`` moves rigidly; it predicts the position of a rest vertex ``v0`` as
``x_k(v) = R_k (v0 − c0_k) + c_k`` with ``c0_k`` its rest centre and ``(R_k, c_k)`` its
current rotation and centre (Cagniart et al. 2010, the paper's ref. [5]).

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- C. Cagniart, E. Boyer, S. Ilic, *Probabilistic deformable surface tracking from
  multiple videos*, European Conference on Computer Vision (ECCV), 2010.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from meshmocap._tolerances import DIVISOR_FLOOR
from meshmocap.body.template import Template
from meshmocap.geometry.mesh import vertex_normals
from meshmocap.geometry.patches import (
    bone_labels,
    majority_labels,
    patch_adjacency,
    surface_patches,
)

#: Smallest squared patch radius (m²): a patch of one vertex still has a finite Gaussian.
_RADIUS2_FLOOR = 1e-8


@dataclass(frozen=True, eq=False)
class PatchModel:
    """Everything about the template's patches that does not change while tracking.

    Attributes
    ----------
    V0 : (n, 3) rest vertices; N0 : (n, 3) rest unit normals; F : (m, 3) faces
    labels : (n,) patch of each vertex; P : number of patches
    centres0 : (P, 3) rest patch centres
    pairs : (E, 2) neighbouring patches (k < l)
    rig_v, rig_k, rig_l, rig_w : the rigidity terms of Eq. (2): for every pair (k, l) and
        vertex v ∈ P_k ∪ P_l, the vertex, both patches and the weight w_kl(v)
    bone_of_patch : (P,) class index of each patch's bone (majority vote, §III)
    classes : (C,) evaluation joints that start a bone (the classifier's labels)
    vertex_class : (n,) class index of each vertex
    bone_j, bone_child : (P,) joint indices of each patch's bone (start, end)
    gamma : (P,) γ_k of Eq. (8)–(11): Δ_k = γ_k x_j + (1 − γ_k) x_child
    delta0 : (P, 3) rest position Δ0_k on the bone; bone_w : (P,) weights w_k of Eq. (10)
    blend : (n, P) sparse weights α_k(v) turning patch predictions into the output mesh
    """

    V0: np.ndarray
    N0: np.ndarray
    F: np.ndarray
    labels: np.ndarray
    P: int
    centres0: np.ndarray
    pairs: np.ndarray
    rig_v: np.ndarray
    rig_k: np.ndarray
    rig_l: np.ndarray
    rig_w: np.ndarray
    bone_of_patch: np.ndarray
    classes: np.ndarray
    vertex_class: np.ndarray
    bone_j: np.ndarray
    bone_child: np.ndarray
    gamma: np.ndarray
    delta0: np.ndarray
    bone_w: np.ndarray
    blend: sp.csr_matrix


#: Smallest bone-binding weight: patches at a joint still follow their bone a little.
MIN_BONE_WEIGHT = 0.1


def build_patch_model(
    template: Template, *, n_patches: int = 200, joint_rigidity: float = 1.0, seed: int = 0
) -> PatchModel:
    """Cut ``template`` into ``n_patches`` patches and precompute the tracker's structure.

    ``joint_rigidity`` scales the rigidity weights of neighbouring patches bound to
    different bones (1: Eq. 2 as printed). Er measures bending away from the rest pose, so
    across a joint it pulls every bent limb back towards the template's pose; the bone
    binding already holds such patches together through their shared joint.
    """
    V0, F = template.V, template.F
    labels = surface_patches(V0, F, n_patches=n_patches, seed=seed)
    P = int(labels.max()) + 1
    counts = np.bincount(labels, minlength=P)
    centres0 = (
        np.stack([np.bincount(labels, V0[:, a], minlength=P) for a in range(3)], 1)
        / counts[:, None]
    )
    pairs = patch_adjacency(F, labels)

    # Gaussian weight of each vertex w.r.t. a patch: α_k(v) = exp(−|v0 − c0_k|² / (2 s_k²)),
    # s_k the patch's RMS radius (Cagniart et al. 2010).
    radius2 = (
        np.bincount(labels, np.sum((V0 - centres0[labels]) ** 2, axis=1), minlength=P) / counts
    )
    radius2 = np.maximum(radius2, _RADIUS2_FLOOR)

    def alpha(v: np.ndarray, k: np.ndarray) -> np.ndarray:
        return np.exp(-np.sum((V0[v] - centres0[k]) ** 2, axis=1) / (2 * radius2[k]))

    # Rigidity terms of Eq. (2): every vertex of P_k ∪ P_l, weighted by α_k(v) + α_l(v).
    order = np.argsort(labels, kind="stable")
    start = np.concatenate([[0], np.cumsum(counts)])
    rig_v, rig_k, rig_l = [], [], []
    for side in (0, 1):  # vertices of the first, then the second patch of every pair
        owner = pairs[:, side]
        n_v = counts[owner]
        v = order[np.repeat(start[owner], n_v) + _ranges(n_v)]
        rig_v.append(v)
        rig_k.append(np.repeat(pairs[:, 0], n_v))
        rig_l.append(np.repeat(pairs[:, 1], n_v))
    rig_v, rig_k, rig_l = (np.concatenate(a) for a in (rig_v, rig_k, rig_l))
    rig_w = alpha(rig_v, rig_k) + alpha(rig_v, rig_l)

    # Output blending over each vertex's own patch and its neighbours.
    nbr = np.concatenate([pairs, pairs[:, ::-1], np.stack([np.arange(P)] * 2, 1)])
    nb_k = sp.csr_matrix((np.ones(len(nbr)), (nbr[:, 0], nbr[:, 1])), shape=(P, P))
    cand = nb_k[labels].tocoo()  # (n, P) pattern: v's own patch and its neighbours
    w = alpha(cand.row, cand.col)
    w = np.where(cand.col == labels[cand.row], np.maximum(w, 1e-3), w)  # own patch always counts
    blend = sp.csr_matrix((w, (cand.row, cand.col)), shape=(len(V0), P))
    blend = sp.csr_matrix(sp.diags(1.0 / np.asarray(blend.sum(axis=1)).ravel()) @ blend)

    # Bone binding (Eq. 8–11): each patch follows the bone of its majority class.
    ev = template.eval_skeleton
    vclass_joint, classes = bone_labels(template.part_labels, ev.parents)
    lookup = np.full(len(ev.names), -1)
    lookup[classes] = np.arange(len(classes))
    vertex_class = lookup[vclass_joint]
    bone_of_patch = majority_labels(labels, vertex_class, len(classes))
    X0 = ev.rest_positions
    j, child = _nearest_bone(X0, ev.parents, classes[bone_of_patch], centres0)
    d = X0[child] - X0[j]
    s = np.sum((centres0 - X0[j]) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), DIVISOR_FLOOR)
    gamma = 1.0 - s  # Δ = γ x_j + (1 − γ) x_child is the foot of the perpendicular (Eq. 8)
    delta0 = X0[j] + s[:, None] * d
    bone_w = np.maximum(4.0 * s * (1.0 - s), MIN_BONE_WEIGHT)  # mid-bone patches weigh more
    cross = (j[rig_k] != j[rig_l]) | (child[rig_k] != child[rig_l])
    rig_w = np.where(cross, joint_rigidity * rig_w, rig_w)
    return PatchModel(
        V0=V0,
        N0=vertex_normals(V0, F),
        F=F,
        labels=labels,
        P=P,
        centres0=centres0,
        pairs=pairs,
        rig_v=rig_v,
        rig_k=rig_k,
        rig_l=rig_l,
        rig_w=rig_w,
        bone_of_patch=bone_of_patch,
        classes=np.asarray(classes),
        vertex_class=vertex_class,
        bone_j=j,
        bone_child=child,
        gamma=gamma,
        delta0=delta0,
        bone_w=bone_w,
        blend=blend,
    )


def _ranges(n: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(n_i)`` for every ``n_i`` of ``n``."""
    return np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)


def _nearest_bone(
    X0: np.ndarray, parents: np.ndarray, label: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For patches labelled with joint ``label`` (P,), the bone attached to that joint whose
    segment is nearest to the patch centre ``c`` (P, 3) at rest: one of the joint's own
    bones (joint → child; the pelvis and thorax have several) or the bone that ends at it
    (parent → joint). Returns the bone's start and end joints, (P,) each.

    The paper binds a patch to "the attached joints j(k)" (§III-C). A skinned template's
    part boundaries do not follow the joints: the lower chest carries the ``thorax`` label
    yet lies below the thorax joint, on the spine (pelvis → thorax). Binding it to a
    thorax → shoulder bone, far above, would make the thorax follow the belly.
    """
    start = np.full(len(label), -1)
    end = np.full(len(label), -1)
    best = np.full(len(label), np.inf)
    for ch in range(len(X0)):  # every bone (parent → ch) of the 15-joint skeleton
        p = parents[ch]
        if p < 0:
            continue
        m = (label == p) | (label == ch)
        if not m.any():
            continue
        a, b = X0[p], X0[ch]
        d = b - a
        s = np.clip(((c[m] - a) @ d) / max(d @ d, DIVISOR_FLOOR), 0.0, 1.0)
        dist = np.linalg.norm(c[m] - (a + s[:, None] * d), axis=1)
        better = dist < best[m]
        idx = np.flatnonzero(m)[better]
        start[idx], end[idx], best[idx] = p, ch, dist[better]
    return start, end


def rebind_bones(model: PatchModel, R: np.ndarray, c: np.ndarray, X: np.ndarray) -> PatchModel:
    """Bind every patch to its bone in a posed configuration (the first tracked frame).

    The paper keeps each patch's bone coordinate ``β`` constant "after transformation"
    (Eq. 9–11): here ``β`` is measured where tracking starts, so ``Ebone`` is exactly zero
    there. Measuring it on the rest pose instead would leave residuals of several
    centimetres wherever skinning bends the surface (buttocks, shoulders), which the solver
    would then 'correct' by moving the joints.

    Parameters
    ----------
    R : (P, 3, 3), c : (P, 3) patch rotations and centres; X : (K, 3) joint positions.
    """
    j, child = model.bone_j, model.bone_child
    d = X[child] - X[j]
    s = np.sum((c - X[j]) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), DIVISOR_FLOOR)
    delta = X[j] + s[:, None] * d  # Eq. (8): foot of the perpendicular from the patch centre
    delta0 = np.einsum("kji,kj->ki", R, delta - c) + model.centres0  # T_k(Δ0_k) = Δ_k
    bone_w = np.maximum(4.0 * s * (1.0 - s), MIN_BONE_WEIGHT)
    return replace(model, gamma=1.0 - s, delta0=delta0, bone_w=bone_w)


def fit_patches(m: PatchModel, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best rigid transform of every patch from rest to the vertex positions ``V`` (n, 3)
    (Kabsch): rotations (P, 3, 3) and centres (P, 3)."""
    P, lab = m.P, m.labels
    n = np.bincount(lab, minlength=P)
    c = np.stack([np.bincount(lab, V[:, a], minlength=P) for a in range(3)], 1) / n[:, None]
    A = m.V0 - m.centres0[lab]
    B = V - c[lab]
    H = np.stack(
        [np.bincount(lab, A[:, a] * B[:, b], minlength=P) for a in range(3) for b in range(3)], 1
    )
    U, _, Vt = np.linalg.svd(H.reshape(P, 3, 3))
    D = np.ones((P, 3))
    D[:, 2] = np.sign(np.linalg.det(np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)))
    R = np.swapaxes(Vt, 1, 2) @ (D[:, :, None] * np.swapaxes(U, 1, 2))
    return R, c


def skeleton_floor(model: PatchModel, V: np.ndarray, X: np.ndarray) -> np.ndarray:
    """RMS error (K,) of each joint of the bone binding itself, metres: on every pose, the
    patches fitted exactly to the surface (:func:`fit_patches`) and the joints that best
    satisfy Ebone alone (Eq. 8–11, weighted least squares) against the true joints.

    A limb's patches move rigidly with its bone, so its joints come back within a few
    millimetres; the pelvis→thorax "bone" spans a bending spine that no patch follows, and
    the hips and shoulders sit among patches skinned to several bones.

    Parameters
    ----------
    V : (T, n, 3) posed template surfaces; X : (T, K, 3) their evaluation joints (metres).
    """
    K, P = X.shape[1], model.P
    A = np.zeros((P, K))  # Δ_k = γ_k x_j + (1 − γ_k) x_child, Eq. (8)
    np.add.at(A, (np.arange(P), model.bone_j), model.gamma)
    np.add.at(A, (np.arange(P), model.bone_child), 1.0 - model.gamma)
    sw = np.sqrt(model.bone_w)[:, None]
    solve = np.linalg.pinv(A * sw)  # (K, P); joints the patches do not reach stay at 0
    sq = np.zeros(K)
    for Vt, Xt in zip(V, X, strict=True):
        R, c = fit_patches(model, Vt)
        q = np.einsum("kij,kj->ki", R, model.delta0 - model.centres0) + c  # T_k(Δ0_k)
        sq += np.sum((solve @ (q * sw) - Xt) ** 2, axis=1)
    return np.sqrt(sq / max(len(V), 1))
