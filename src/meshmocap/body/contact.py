"""Where a posed body touches the floor (z = 0)."""

from __future__ import annotations

import numpy as np

from meshmocap.body.motion import Motion
from meshmocap.body.names import canonical_name_map
from meshmocap.body.skeleton import Skeleton
from meshmocap.body.skinning import skinning_transforms
from meshmocap.body.template import Template

FEET_JOINTS = ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")


def canonical_indices(sk: Skeleton, names: tuple[str, ...]) -> np.ndarray | None:
    """Indices in ``sk`` of the joints with canonical (MotionBuilder) ``names``, or None."""
    inv = canonical_name_map(sk.names)
    if not all(n in inv for n in names):
        return None
    return np.array([sk.index(inv[n]) for n in names])


def foot_heights(motion: Motion, target: Template | Skeleton) -> np.ndarray:
    """Return the lowest height of each foot per frame.

    Parameters
    ----------
    motion : Motion
        ``T`` frames on ``target``'s skeleton.
    target : Template or Skeleton
        With a template, the skinned surface of each foot (vertices labelled
        ``left_ankle``/``right_ankle``); with a skeleton, the foot joints and toe tips.

    Returns
    -------
    (T, 2) float64
        Lowest z (metres) of the left and right foot.
    """
    G, P = motion.global_rotations, motion.joint_positions
    if isinstance(target, Template):
        ev = target.eval_skeleton.names
        A = skinning_transforms(G, P, target.skeleton.rest_positions)[..., 2, :]  # z rows only
        J = A.shape[1]
        A = A.transpose(1, 0, 2).reshape(J, -1)
        out = []
        for side in ("left_ankle", "right_ankle"):
            rows = np.flatnonzero(target.part_labels == ev.index(side))
            B = (target.weights[rows] @ A).reshape(len(rows), -1, 4)
            z = np.einsum("ntb,nb->tn", B[..., :3], target.V[rows]) + B[..., 3].T
            out.append(z.min(axis=1))
        return np.stack(out, axis=1)
    idx = canonical_indices(target, FEET_JOINTS)
    if idx is None:
        low = P[..., 2].min(axis=1)
        return np.stack([low, low], axis=1)
    tips = P[:, idx] + np.einsum("tjab,jb->tja", G[:, idx], target.end_offsets[idx])
    z = np.minimum(P[:, idx, 2], tips[..., 2])
    return np.stack([z[:, :2].min(axis=1), z[:, 2:].min(axis=1)], axis=1)


def lowest_foot_heights(motion: Motion, target: Template | Skeleton) -> np.ndarray:
    """Return (T,) float64: the lowest point of both feet per frame, metres."""
    return foot_heights(motion, target).min(axis=1)
