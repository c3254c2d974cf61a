"""The candidate poses of a search: the bundled pose library on a template, facing one
way, and a few seed poses, each aimed in the template's body frame.

Shared by the first pose's search (:mod:`~meshmocap.estimate.pose.first_pose`) and the
lost-limb search (:mod:`~meshmocap.estimate.recovery.limbs`). Metres and radians, world
frame Z up; the template's rest frames are world-aligned (:mod:`meshmocap.body.skeleton`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap._tolerances import NORM_FLOOR
from meshmocap.body.pose_library import PoseLibrary, load_pose_library
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.pose_search import headings_removed
from meshmocap.geometry.rotations import rotation_between

__all__ = [
    "COARSE_POINTS",
    "DISTINCT",
    "HANDS",
    "SEEDS",
    "LibraryPoses",
    "body_frame",
    "hand_joints",
    "library_poses",
    "seed_pose",
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
    left /= max(float(np.linalg.norm(left)), NORM_FLOOR)
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


#: Model and observed points of the first, cheapest score of every library candidate.
COARSE_POINTS = 64
#: Metres some evaluation joint must differ by for two candidate poses to count as distinct.
DISTINCT = 0.1


@dataclass(frozen=True, eq=False)
class LibraryPoses:
    """Candidate poses of a template, facing heading 0 (:func:`library_poses`).

    Attributes
    ----------
    R : (N, J, 3, 3) float64, local rotations of the template's skeleton
    labels : tuple of str, where each comes from (``"SS_TT:frame"``, or a seed's name)
    """

    R: np.ndarray
    labels: tuple[str, ...]


_LIBRARY_CACHE: dict[tuple, LibraryPoses] = {}

#: Joints whose library rotations a candidate does not take, with every joint below them.
#: A 1 cm hull seen by a few cameras resolves little of a hand's orientation, so the fits
#: keep whatever hand a candidate brings, and the library's are other performers' hands in
#: other actions; a tracker started from such a hand can lose the wrist
#: (``docs/measurements.rst``). At rest, a hand starts from the middle of what hands do.
HANDS = ("LeftHand", "RightHand")


def hand_joints(template: Template) -> np.ndarray:
    """(k,) int64: the joints of :data:`HANDS` and every joint they carry (fingers, thumbs)
    in ``template``'s skeleton, ascending."""
    sk = template.skeleton
    below = np.zeros(sk.n_joints, dtype=bool)
    for j in range(sk.n_joints):  # parents come before their children
        below[j] = sk.names[j] in HANDS or (j > 0 and below[sk.parents[j]])
    return np.flatnonzero(below).astype(np.int64)


def library_poses(
    template: Template,
    *,
    library: PoseLibrary | None = None,
    n: int | None = None,
    exclude_trials: tuple[str, ...] = (),
    seeds: tuple[str, ...] = tuple(SEEDS),
) -> LibraryPoses:
    """The pose library's poses (default: the bundled CMU library, all of them or its
    first ``n``: a diverse subset) on ``template``'s skeleton, with their heading removed
    (:func:`~meshmocap.estimate.pose.pose_search.headings_removed`), plus the seed poses
    ``seeds`` (:data:`SEEDS`), the hands of every library pose at rest (:data:`HANDS`).
    Poses of the trials ``exclude_trials`` are left out (a
    motion that trains the prior must not be scored by it). Cached per template."""
    lib = load_pose_library() if library is None else library
    key = (
        template.name,
        template.n_vertices,
        template.skeleton.offsets.tobytes(),
        lib.digest,
        n,
        tuple(sorted(exclude_trials)),
        seeds,
    )
    if key in _LIBRARY_CACHE:
        return _LIBRARY_CACHE[key]
    R = lib.on(template, n)
    R[:, hand_joints(template)] = np.eye(3)  # hands at rest (HANDS)
    keep = ~np.isin(lib.trials[: len(R)], list(exclude_trials))
    labels = [f"{t}:{f}" for t, f in zip(lib.trials[: len(R)], lib.frames[: len(R)], strict=True)]
    front = body_frame(template)[:, 1]
    R = headings_removed(R[keep], front)
    labels = [lab for lab, k in zip(labels, keep, strict=True) if k]
    if seeds:
        R = np.concatenate([np.stack([seed_pose(template, s) for s in seeds]), R])
        labels = list(seeds) + labels
    out = LibraryPoses(R, tuple(labels))
    if len(_LIBRARY_CACHE) > 8:
        _LIBRARY_CACHE.clear()
    _LIBRARY_CACHE[key] = out
    return out
