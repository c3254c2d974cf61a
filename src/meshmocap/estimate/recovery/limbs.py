"""The search for a lost limb: one limb of a known pose re-seeded and fitted with only that
limb free, the rest of the body kept.

Two sources of hypotheses for the limb:

* :func:`library_limb_candidates` — the limb's joints set as in every pose of the pose
  library (what people do with that limb), all scored at once against the frame's
  occupancy (:class:`~meshmocap.estimate.pose.pose_search.FrameScorer`);
  :func:`refine_limbs_from_library` fits the best of them;
* :func:`limb_candidates` — the limb's upper bone aimed over the sphere (without a voxel
  occupancy to score library hypotheses against), straight and bent;
  :func:`refine_limbs` keeps the best.

:func:`graft_limbs` puts limbs of other tracked frames onto a frame (the two-way pass's
choice per limb, :mod:`~meshmocap.trackers.two_way`).

The re-seating of a track (:mod:`~meshmocap.estimate.recovery.reinit`) and the first
pose's search (:mod:`~meshmocap.estimate.pose.first_pose`, step 3: each candidate refined
limb by limb) both use it. Metres and radians, world frame Z up.
"""

from __future__ import annotations

import numpy as np

from meshmocap._tolerances import DEGENERATE_AXIS
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.fit import PoseFit, PoseFitter
from meshmocap.estimate.pose.library import COARSE_POINTS, DISTINCT, LibraryPoses, body_frame
from meshmocap.estimate.pose.pose_search import (
    BodySample,
    FrameScorer,
    body_sample,
    sample_positions,
)
from meshmocap.geometry.rotations import rotation_between

__all__ = [
    "LIMBS",
    "LIMB_ROOTS",
    "graft_limbs",
    "library_limb_candidates",
    "limb_candidates",
    "limb_joint_indices",
    "refine_limbs",
    "refine_limbs_from_library",
]

#: Limbs a re-initialisation can re-seed: name → (joints whose rotations it re-seeds, the
#: bone aimed (joint, child)).
LIMBS: dict[str, tuple[tuple[str, ...], tuple[str, str]]] = {
    "left_arm": (("LeftArm", "LeftForeArm", "LeftHand"), ("LeftArm", "LeftForeArm")),
    "right_arm": (("RightArm", "RightForeArm", "RightHand"), ("RightArm", "RightForeArm")),
    "left_leg": (("LeftUpLeg", "LeftLeg", "LeftFoot"), ("LeftUpLeg", "LeftLeg")),
    "right_leg": (("RightUpLeg", "RightLeg", "RightFoot"), ("RightUpLeg", "RightLeg")),
}


#: Joints above a limb's own that move with it in a library hypothesis (an arm's clavicle).
LIMB_ROOTS = {"left_arm": ("LeftShoulder",), "right_arm": ("RightShoulder",)}


def limb_joint_indices(template: Template, limb: str, *, lower: bool = False) -> np.ndarray:
    """(k,) int64: the rig joints of ``limb`` (:data:`LIMBS`, with :data:`LIMB_ROOTS`) and
    every joint they carry; with ``lower``, only its lower bone's (forearm, shank) and
    below."""
    if limb not in LIMBS:
        raise InputError(f"init: limb must be one of {list(LIMBS)}, found {limb!r}")
    sk = template.skeleton
    names = LIMBS[limb][0][1:] if lower else (*LIMB_ROOTS.get(limb, ()), *LIMBS[limb][0])
    below = [j for j in range(sk.n_joints) if any(sk.names[a] in names for a in _ancestors(sk, j))]
    return np.array(sorted({sk.index(n) for n in names if n in sk.names} | set(below)))


def _part(sample: BodySample, keep: np.ndarray) -> BodySample:
    """The points of ``sample`` where ``keep`` (m,) bool."""
    return BodySample(sample.vertex[keep], sample.joint[keep], sample.offset[keep])


def _ancestors(sk, j: int) -> list[int]:
    out = []
    while j >= 0:
        out.append(j)
        j = int(sk.parents[j])
    return out


def library_limb_candidates(
    template: Template,
    poses: LibraryPoses,
    scorer: FrameScorer,
    R: np.ndarray,
    root: np.ndarray,
    limb: str,
    *,
    n_best: int = 3,
    lower: bool = False,
) -> list[PoseFit]:
    """The pose ``(R, root)`` with ``limb``'s joints (:func:`limb_joint_indices`: the
    limb and everything it carries; with ``lower``, from its lower bone down) set as in
    each of ``poses`` (their local rotations: what people do with that limb), all scored
    at once (:meth:`FrameScorer.score`); the ``n_best`` best with some joint of the limb
    more than :data:`DISTINCT` apart, best first (``score``: the coarse score)."""
    idx = limb_joint_indices(template, limb, lower=lower)
    sample = body_sample(template)
    Rc = np.broadcast_to(R, poses.R.shape).copy()
    Rc[:, idx] = poses.R[:, idx]
    G, Pj = forward_kinematics(template.skeleton, Rc, np.broadcast_to(root, (len(Rc), 3)))
    # only the limb's sample points differ between candidates: the others are scored once
    moving = np.isin(sample.joint, idx)
    coarse = np.arange(len(moving)) < COARSE_POINTS  # the coarse score's prefix
    X = sample_positions(_part(sample, moving), G, Pj)  # (N, m_limb, 3)
    still = sample_positions(_part(sample, ~moving), G[0], Pj[0])  # (m - m_limb, 3)
    sc = scorer.score_shared(X[:, coarse[moving]], still[coarse[~moving]], n_data=COARSE_POINTS)
    top = np.argsort(sc)[: 20 * n_best]
    sc = np.full(len(sc), np.inf)
    sc[top] = scorer.score_shared(X[top], still)
    kept: list[int] = []
    for i in np.argsort(sc):
        if all(np.linalg.norm(Pj[i, idx] - Pj[k, idx], axis=1).max() > DISTINCT for k in kept):
            kept.append(int(i))
            if len(kept) == n_best:
                break
    return [PoseFit(Rc[i], np.array(root), float(sc[i]), poses.labels[i]) for i in kept]


def refine_limbs_from_library(
    fitter: PoseFitter,
    fit: PoseFit,
    poses: LibraryPoses,
    scorer: FrameScorer,
    *,
    limbs: tuple[str, ...] = tuple(LIMBS),
    n_best: int = 3,
    iterations: int = 6,
    key=None,
) -> PoseFit:
    """``fit`` with each of ``limbs`` replaced by a library hypothesis
    (:func:`library_limb_candidates`, fitted with only that limb free), then its lower
    bone likewise, where that lowers ``key`` (default: the score); limbs in turn, each
    from the pose the previous ones left."""
    key = key or (lambda f: f.score)
    t = fitter.template
    best = PoseFit(fit.R, fit.root, fitter.score(fit.R, fit.root), fit.label)
    k_best = key(best)
    for limb, lower in [(limb, lower) for limb in limbs for lower in (False, True)]:
        idx = limb_joint_indices(t, limb, lower=lower)
        cands = library_limb_candidates(
            t, poses, scorer, best.R, best.root, limb, n_best=n_best, lower=lower
        )
        for c in cands:
            f = fitter.fit(
                c.R,
                best.root,
                iterations=iterations,
                max_distance=(0.2, 0.05),
                joints=idx,
                move_root=False,
                lambda_pose=0.0,
                label=fit.label,
            )
            k = key(f)
            if k < k_best:
                best, k_best = f, k
    return best


def refine_limbs(
    fitter: PoseFitter,
    fit: PoseFit,
    *,
    limbs: tuple[str, ...],
    directions: int = 10,
    iterations: int = 6,
    key=None,
) -> PoseFit:
    """``fit`` with each of ``limbs`` re-seeded (:func:`limb_candidates`) where that lowers
    ``key`` (default: the score); limbs in turn, each from the pose the previous ones
    left."""
    key = key or (lambda f: f.score)
    best = PoseFit(fit.R, fit.root, fitter.score(fit.R, fit.root), fit.label)
    k_best = key(best)
    for limb in limbs:
        cands = limb_candidates(
            fitter, best.R, best.root, limb, directions=directions, iterations=iterations
        )
        for c in cands[:4]:  # the best few by score, checked by the key
            k = key(c)
            if k < k_best:
                best, k_best = PoseFit(c.R, c.root, c.score, fit.label), k
    return best


def limb_candidates(
    fitter: PoseFitter,
    R: np.ndarray,
    root: np.ndarray,
    limb: str,
    *,
    directions: int = 10,
    iterations: int = 10,
    lower: bool = False,
) -> list[PoseFit]:
    """Re-seed one limb of the pose ``(R, root)`` (:data:`LIMBS`) and fit it.

    The limb's upper bone is aimed along ``directions`` directions spread over the sphere
    (Fibonacci lattice), each with the limb straight and bent at its middle joint by 90°
    (an elbow towards the body's front, a knee towards its back), and each candidate is
    fitted with only that limb's joints free; the rest of the body keeps ``(R, root)``.
    With ``lower``, only the lower bone (forearm, shank) is re-seeded and fitted, the
    upper one kept.

    Returns
    -------
    list of PoseFit, best (lowest score) first.
    """
    if limb not in LIMBS:
        raise InputError(f"reinit: limb must be one of {list(LIMBS)}, found {limb!r}")
    sk = fitter.sk
    names, (upper, child) = LIMBS[limb]
    if not all(n in sk.names for n in (*names, child)):
        return []
    idx = np.array([sk.index(n) for n in names])
    j, c, m = sk.index(upper), sk.index(child), idx[1]
    tip = sk.index(names[2]) if len(names) > 2 else m
    k = np.arange(directions) + 0.5
    z = 1 - 2 * k / directions
    phi = np.pi * (1 + 5**0.5) * k
    dirs = np.stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z], 1)
    G, _ = forward_kinematics(sk, R, root)
    front = G[0] @ body_frame(fitter.template)[:, 1]
    bend = front if "arm" in limb else -front
    P0 = sk.rest_positions
    Gp = G[sk.parents[j]] if sk.parents[j] >= 0 else np.eye(3)
    out = []
    if lower:  # the lower bone along each direction, the upper one kept
        Gm = G[j]
        for d in dirs:
            Rs = R.copy()
            Rs[idx[2:]] = np.eye(3)
            Rs[m] = Gm.T @ rotation_between(P0[tip] - P0[m], d)
            out.append(
                fitter.fit(
                    Rs,
                    root,
                    iterations=iterations,
                    max_distance=(0.2, 0.05),
                    joints=idx[1:],
                    move_root=False,
                    lambda_pose=0.0,
                    label=f"{limb}:lower:{np.round(d, 2).tolist()}",
                )
            )
        return sorted(out, key=lambda f: f.score)
    for d in dirs:
        for bent in (False, True):
            Rs = R.copy()
            Rs[idx[1:]] = np.eye(3)
            Rs[j] = Gp.T @ rotation_between(P0[c] - P0[j], d)
            if bent:  # the lower bone at 90° to the upper, towards ``bend``
                b = bend - (bend @ d) * d
                if np.linalg.norm(b) < DEGENERATE_AXIS:
                    continue
                Gj = Rs[j] if sk.parents[j] < 0 else Gp @ Rs[j]
                Rs[m] = Gj.T @ rotation_between(P0[tip] - P0[m], b)
            out.append(
                fitter.fit(
                    Rs,
                    root,
                    iterations=iterations,
                    max_distance=(0.2, 0.05),
                    joints=idx,
                    move_root=False,
                    lambda_pose=0.0,
                    label=f"{limb}:{np.round(d, 2).tolist()}{':bent' if bent else ''}",
                )
            )
    return sorted(out, key=lambda f: f.score)


def graft_limbs(
    template: Template,
    R: np.ndarray,
    root: np.ndarray,
    V: np.ndarray,
    E: np.ndarray,
    source: dict[str, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One frame made of several tracks' frames: track 0's trunk, each limb of ``source``
    from the track given there, turned as that track turns it in the world and hung at
    track 0's shoulder or hip (the limb's top joints' local rotations re-fitted to its
    world rotations). Each track's surface and joints keep their own offsets from their
    skinned pose (a tracker's non-rigid detail), blended by the skinning weights.

    Parameters
    ----------
    template : Template, the tracked body (``J`` rig joints, ``n`` vertices, ``K``
        evaluation joints)
    R : (H, J, 3, 3) float64, each track's local rotations; ``root`` (H, 3) float64, metres
    V : (H, n, 3) float64, metres, each track's vertices; ``E`` (H, K, 3), its joints
    source : dict, limb (:data:`LIMBS`) → the track (0..H−1) it is taken from

    Returns
    -------
    R : (J, 3, 3) float64, the grafted frame's local rotations (root: track 0's)
    V : (n, 3) float64, metres, its vertices
    E : (K, 3) float64, metres, its evaluation joints
    """
    sk = template.skeleton
    R = np.asarray(R, dtype=np.float64)
    root = np.asarray(root, dtype=np.float64)
    G, _ = forward_kinematics(sk, R, root)  # (H, J, 3, 3) global rotations
    out = R[0].copy()
    weight = np.zeros((len(R), template.n_vertices))  # each track's share of a vertex
    eweight = np.zeros((len(R), len(template.eval_skeleton.names)))
    W = template.weights.tocsc()
    for limb, h in source.items():
        idx = limb_joint_indices(template, limb)
        out[idx] = R[h, idx]
        top = [j for j in idx if int(sk.parents[j]) not in idx]
        for j in top:  # the world rotation of track h under track 0's parent
            p = int(sk.parents[j])
            out[j] = G[h, j] if p < 0 else G[0, p].T @ G[h, j]
        weight[h] += np.asarray(W[:, idx].sum(axis=1)).ravel()
        eweight[h] += template.eval_skeleton.weights[:, idx].sum(axis=1)
    weight[0] += 1.0 - weight.sum(axis=0)
    eweight[0] += 1.0 - eweight.sum(axis=0)
    used = np.flatnonzero((weight > 0).any(axis=1) | (eweight > 0).any(axis=1))
    skinned = template.pose(R[used], root[used])  # each used track's own skinned pose
    posed = template.pose(out, root[0])
    dV = np.asarray(V, dtype=np.float64)[used] - skinned.V
    dE = np.asarray(E, dtype=np.float64)[used] - skinned.eval_joints
    Vo = posed.V + np.einsum("hn,hnc->nc", weight[used], dV)
    Eo = posed.eval_joints + np.einsum("hk,hkc->kc", eweight[used], dE)
    return out, Vo, Eo
