"""Automatic initialisation: the template's first pose found from the capture alone.

The performer may stand anywhere in the volume, facing any way, in any reasonable pose. A
global search covers that (no ground truth, no hand placement):

1. **Candidates.** A few seed poses (:data:`SEEDS`: the template's rest pose, a T-pose,
   arms up, a stride either way; bones aimed in the template's own body frame, so any
   template with the CMU MotionBuilder joint names gets them), each turned to
   ``n_headings`` headings about the vertical axis through the root, and placed so that the
   posed model's centroid falls on the observed points' centroid.
2. **Coarse fits.** Every candidate gets a few iterations of the articulated Gauss–Newton
   (:class:`~meshmocap.estimate.fit.PoseFitter`: closest points both ways, normals
   agreeing) on a subsample of the points, pulled weakly towards its seed.
3. **Refinement.** The ``keep`` best by the symmetric fit score are refined on more points
   with a shrinking pairing distance; the lowest score wins.

:func:`limb_candidates` re-seeds single limbs of a known pose the same way (the
re-initialisation of a lost limb). Metres and radians, world frame Z up; the template's
rest frames are world-aligned (:mod:`meshmocap.body.skeleton`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.fit import PoseFit, PoseFitter, silhouette_mismatch
from meshmocap.geometry.distance_field import DistanceGrid
from meshmocap.geometry.rotations import rotation_between, so3_exp

__all__ = [
    "LIMBS",
    "SEEDS",
    "InitResult",
    "body_frame",
    "initial_pose",
    "limb_candidates",
    "ranking_key",
    "refine_limbs",
    "seed_pose",
    "subsample_points",
]

#: Seed poses: name → {joint: (child, direction in the body frame (left, front, up))}.
#: Aimed in order, each relative to its already-aimed parent.
SEEDS: dict[str, dict[str, tuple[str, tuple[float, float, float]]]] = {
    "rest": {},
    "t_pose": {
        "LeftArm": ("LeftForeArm", (1.0, 0.0, 0.0)),
        "RightArm": ("RightForeArm", (-1.0, 0.0, 0.0)),
    },
    "arms_up": {
        "LeftArm": ("LeftForeArm", (0.25, 0.0, 1.0)),
        "RightArm": ("RightForeArm", (-0.25, 0.0, 1.0)),
    },
    "stride_left": {
        "LeftUpLeg": ("LeftLeg", (0.0, 0.45, -1.0)),
        "RightUpLeg": ("RightLeg", (0.0, -0.45, -1.0)),
        "RightLeg": ("RightFoot", (0.0, -0.9, -1.0)),
    },
    "stride_right": {
        "RightUpLeg": ("RightLeg", (0.0, 0.45, -1.0)),
        "LeftUpLeg": ("LeftLeg", (0.0, -0.45, -1.0)),
        "LeftLeg": ("LeftFoot", (0.0, -0.9, -1.0)),
    },
    "crouch": {
        "LowerBack": ("Spine", (0.0, 0.5, 1.0)),
        "LeftUpLeg": ("LeftLeg", (0.05, 1.0, -0.7)),
        "RightUpLeg": ("RightLeg", (-0.05, 1.0, -0.7)),
        "LeftLeg": ("LeftFoot", (0.0, -0.6, -1.0)),
        "RightLeg": ("RightFoot", (0.0, -0.6, -1.0)),
    },
}

#: Limbs a re-initialisation can re-seed: name → (joints whose rotations it re-seeds, the
#: bone aimed (joint, child)).
LIMBS: dict[str, tuple[tuple[str, ...], tuple[str, str]]] = {
    "left_arm": (("LeftArm", "LeftForeArm", "LeftHand"), ("LeftArm", "LeftForeArm")),
    "right_arm": (("RightArm", "RightForeArm", "RightHand"), ("RightArm", "RightForeArm")),
    "left_leg": (("LeftUpLeg", "LeftLeg", "LeftFoot"), ("LeftUpLeg", "LeftLeg")),
    "right_leg": (("RightUpLeg", "RightLeg", "RightFoot"), ("RightUpLeg", "RightLeg")),
}


def body_frame(template: Template) -> np.ndarray:
    """(3, 3) float64: the template's rest body axes as columns (left, front, up), world
    frame: up is +Z, left the horizontal direction from the right hip and shoulder to the
    left ones, front = left × up (−Y for the bundled templates)."""
    sk = template.skeleton
    P = sk.rest_positions
    names = ("LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm")
    if not all(n in sk.names for n in names):
        raise InputError(f"init: template {template.name!r} lacks the joints {list(names)}")
    i = [sk.index(n) for n in names]
    left = P[i[0]] - P[i[1]] + P[i[2]] - P[i[3]]
    left[2] = 0.0
    left /= max(float(np.linalg.norm(left)), 1e-12)
    up = np.array([0.0, 0.0, 1.0])
    return np.stack([left, np.cross(left, up), up], axis=1)


def _aim(template: Template, R: np.ndarray, aims: dict, frame: np.ndarray) -> np.ndarray:
    """``R`` with each joint of ``aims`` turned so that its bone points along the given
    body-frame direction (world rest frames: a joint's global rotation maps its rest bone
    direction to the world)."""
    sk = template.skeleton
    R = R.copy()
    P0 = sk.rest_positions
    for name, (child, d) in aims.items():
        if name not in sk.names or child not in sk.names:
            continue
        j, c = sk.index(name), sk.index(child)
        G, _ = forward_kinematics(sk, R, np.zeros(3))
        Gp = G[sk.parents[j]] if sk.parents[j] >= 0 else np.eye(3)
        want = rotation_between(P0[c] - P0[j], frame @ np.asarray(d, dtype=np.float64))
        # keep the bone's twist: turn its current direction onto the wanted one
        Gj = rotation_between(G[j] @ (P0[c] - P0[j]), want @ (P0[c] - P0[j])) @ G[j]
        R[j] = Gp.T @ Gj
    return R


def seed_pose(template: Template, name: str) -> np.ndarray:
    """Local rotations (J, 3, 3) of seed pose ``name`` (:data:`SEEDS`), heading 0."""
    if name not in SEEDS:
        raise InputError(f"init: seed must be one of {list(SEEDS)}, found {name!r}")
    R = np.tile(np.eye(3), (template.skeleton.n_joints, 1, 1))
    return _aim(template, R, SEEDS[name], body_frame(template))


def _turned(R: np.ndarray, heading: float) -> np.ndarray:
    R = R.copy()
    R[0] = so3_exp(np.array([0.0, 0.0, heading])) @ R[0]
    return R


def _centred_root(fitter: PoseFitter, R: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The root position putting the posed model points' centroid on ``centre``."""
    root0 = fitter.sk.rest_positions[0]
    return root0 + centre - fitter.points(R, root0).mean(axis=0)


@dataclass(frozen=True, eq=False)
class InitResult:
    """What :func:`initial_pose` found.

    Attributes
    ----------
    R : (J, 3, 3) float64, local rotations; ``root`` (3,) float64, metres
    score : float, the winner's fit score (metres, :meth:`PoseFitter.score`)
    label : str, the winning candidate (seed and heading)
    candidates : tuple of PoseFit, the refined candidates, best first
    """

    R: np.ndarray
    root: np.ndarray
    score: float
    label: str
    candidates: tuple[PoseFit, ...]


#: Metres of 3-D score a silhouette mismatch of 1 (the whole silhouette) weighs.
SILHOUETTE_WEIGHT = 0.1


def ranking_key(template: Template, cameras, masks):
    """Key ranking candidate fits: the 3-D score, plus the silhouette mismatch weighted by
    :data:`SILHOUETTE_WEIGHT` where cameras and masks are given."""
    if not cameras or masks is None:
        return lambda f: f.score

    def key(f: PoseFit) -> float:
        V = template.pose(f.R, f.root).V
        return f.score + SILHOUETTE_WEIGHT * silhouette_mismatch(V, template.F, cameras, masks)

    return key


def subsample_points(
    P: np.ndarray, N: np.ndarray, n: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """At most ``n`` of the points (p, 3) and their normals (p, 3), a seeded subsample."""
    if len(P) <= n:
        return P, N
    pick = np.random.default_rng(seed).choice(len(P), n, replace=False)
    return P[pick], N[pick]


def initial_pose(
    template: Template,
    P: np.ndarray,
    N: np.ndarray,
    *,
    n_headings: int = 8,
    seeds: tuple[str, ...] = tuple(SEEDS),
    keep: int = 3,
    coarse_iterations: int = 8,
    iterations: int = 30,
    limb_directions: int = 10,
    cameras: list | None = None,
    masks: list | None = None,
    field: DistanceGrid | None = None,
    seed: int = 0,
) -> InitResult:
    """Find the template's pose on observed points by a global search (module docstring).

    Parameters
    ----------
    template : Template
        The tracking template (rest frames world-aligned, CMU MotionBuilder joint names).
    P, N : (p, 3) float64
        Observed surface points (metres, world frame Z up) and outward unit normals, e.g.
        :func:`~meshmocap.estimate.observe.frame_points` of the first frame.
    n_headings : int
        Headings tried per seed, evenly spaced over 360°.
    seeds : tuple of str
        Seed poses (:data:`SEEDS`).
    keep : int
        Candidates refined after the coarse fits.
    coarse_iterations, iterations : int
        Gauss–Newton iterations of each coarse fit and of each refinement.
    cameras, masks : list of Camera and of (height, width) bool, optional
        The capture's cameras and this frame's silhouettes: candidates are then ranked by
        their silhouette mismatch (:func:`~meshmocap.estimate.fit.silhouette_mismatch`)
        plus the 3-D score, which tells a torso turned 90° in a 4-camera hull apart
        where the points alone hardly do.
    field : DistanceGrid, optional
        Signed distance of the observed solid (e.g. of the frame's hull): model points
        outside it cost in the score (:class:`~meshmocap.estimate.fit.PoseFitter`).
    seed : int
        Seed of the point subsamples.

    Returns
    -------
    InitResult
    """
    P = np.asarray(P, dtype=np.float64)
    N = np.asarray(N, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 50 or N.shape != P.shape:
        raise InputError(
            f"init: expected (p, 3) points and normals with p ≥ 50, found {P.shape} and {N.shape}"
        )
    if not (isinstance(n_headings, int) and n_headings >= 1 and keep >= 1):
        raise InputError(f"init: n_headings and keep must be ≥ 1, found {n_headings}, {keep}")
    Pc, Nc = subsample_points(P, N, 2000, seed)
    coarse = PoseFitter(template, Pc, Nc, n_model_points=500, field=field, seed=seed)
    centre = P.mean(axis=0)
    fits = []
    for name in seeds:
        R0 = seed_pose(template, name)
        for h in range(n_headings):
            deg = 360.0 * h / n_headings
            R = _turned(R0, np.deg2rad(deg))
            root = _centred_root(coarse, R, centre)
            fits.append(
                coarse.fit(
                    R,
                    root,
                    iterations=coarse_iterations,
                    max_distance=(0.3, 0.1),
                    lambda_pose=1e-3,
                    label=f"{name}@{deg:.0f}°",
                )
            )
    rank = ranking_key(template, cameras, masks)
    fits.sort(key=rank)
    Pf, Nf = subsample_points(P, N, 5000, seed)
    fine = PoseFitter(template, Pf, Nf, n_model_points=1500, field=field, seed=seed)
    refined = []
    for f in fits[:keep]:
        f = refine_limbs(coarse, f, limbs=tuple(LIMBS), directions=limb_directions, key=rank)
        f = fine.fit(
            f.R,
            f.root,
            iterations=iterations,
            max_distance=(0.15, 0.03),
            lambda_pose=1e-4,
            label=f.label,
        )
        # then settle on the near surface, barely held (a long pull undoes small moves)
        f = fine.fit(
            f.R,
            f.root,
            iterations=iterations // 2,
            max_distance=(0.04, 0.01),
            lambda_pose=1e-6,
            label=f.label,
        )
        refined.append(f)
    refined.sort(key=rank)
    best = refined[0]
    return InitResult(best.R, best.root, best.score, best.label, tuple(refined))


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
                if np.linalg.norm(b) < 1e-6:
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
