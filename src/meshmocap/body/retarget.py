"""Retargeting motion-capture clips onto a template's skeleton.

The method transfers *world* bone orientations rather than local angles, which makes it
insensitive to the two skeletons having different rest poses (T-pose vs A-pose), bone
lengths or intermediate joints:

1. **Joint-name mapping** (:func:`~meshmocap.body.names.canonical_name_map` or a user map).
2. **Rest-pose offset correction:** for each mapped joint ``j`` with source joint ``s``, the
   rotation ``Q_j`` turns the target's rest bone direction onto the source's. A posed frame
   then sets ``G_t[j] = G_s[s] Q_j`` so that every target bone points where its source bone
   points. Unmapped target joints keep their rest orientation relative to their parent.
3. **Root-height scaling:** the root trajectory is scaled by the ratio of leg lengths, so
   strides fit the target's legs (no foot sliding beyond the source's).
4. **Floor contact:** a constant vertical shift puts the feet on the floor (z = 0) at their
   lowest points.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

import numpy as np

from meshmocap.body.contact import canonical_indices, lowest_foot_heights
from meshmocap.body.motion import Motion
from meshmocap.body.names import canonical_name_map
from meshmocap.body.skeleton import Skeleton, local_rotations
from meshmocap.body.template import Template
from meshmocap.errors import InputError, SkeletonError
from meshmocap.geometry.rotations import rotation_between

Floor = Literal["feet", "none"]
_LEG = ("LeftUpLeg", "LeftLeg", "LeftFoot")
#: Percentile of the per-frame lowest foot point that is put on the floor: robust to a few
#: frames of foot-through-floor noise, and to flight phases (jumps) that cover < 95 % of a clip.
FLOOR_PERCENTILE = 5.0


def retarget(
    motion: Motion,
    target: Template | Skeleton,
    *,
    joint_map: Mapping[str, str] | None = None,
    floor: Floor = "feet",
) -> Motion:
    """Return ``motion`` replayed by ``target``'s skeleton.

    Parameters
    ----------
    motion : Motion
        Source clip in metres, world frame Z up, subject facing −Y at rest (what the
        readers in :mod:`meshmocap.io` return).
    target : Template or Skeleton
        The skeleton to drive. With a template, floor contact uses the skinned foot
        surface; with a bare skeleton, the foot joints.
    joint_map : mapping, optional
        ``{target joint name: source joint name}``. Default: the known CMU flavours
        (ASF/AMC, MotionBuilder BVH, Daz BVH) mapped onto the MotionBuilder names.
    floor : {"feet", "none"}
        ``"feet"`` shifts the clip vertically so the feet touch z = 0 at their lowest
        points; ``"none"`` keeps the scaled source height.

    Returns
    -------
    Motion
        Same frames and frame rate, on ``target``'s skeleton.

    Raises
    ------
    SkeletonError
        The mapping names unknown joints or leaves the root or a leg unmapped.
    """
    if floor not in ("feet", "none"):
        raise InputError(f"retarget: floor must be one of ['feet', 'none'], found {floor!r}")
    tsk = target.skeleton if isinstance(target, Template) else target
    ssk = motion.skeleton
    pairs = _resolve_map(ssk, tsk, joint_map)
    t_idx = np.array([tsk.index(t) for t in pairs])
    s_idx = np.array([ssk.index(s) for s in pairs.values()])

    # Rest-pose offset correction: Q_j d_t = d_s.
    d_t, d_s = tsk.bone_directions[t_idx], ssk.bone_directions[s_idx]
    Q = rotation_between(d_t, d_s)
    unknown = (np.linalg.norm(d_t, axis=1) < 0.5) | (np.linalg.norm(d_s, axis=1) < 0.5)
    Q[unknown | (t_idx == 0)] = np.eye(3)  # root: both face −Y, Z up by convention

    G_s = motion.global_rotations
    G_t = np.empty((motion.n_frames, tsk.n_joints, 3, 3))
    mapped = np.full(tsk.n_joints, -1)
    mapped[t_idx] = np.arange(len(t_idx))
    for level in tsk.levels:
        m = mapped[level]
        has = m >= 0
        if has.any():
            G_t[:, level[has]] = G_s[:, s_idx[m[has]]] @ Q[m[has]]
        if (~has).any():
            G_t[:, level[~has]] = G_t[:, tsk.parents[level[~has]]]
    R_t = local_rotations(tsk, G_t)

    scale = _leg_length(tsk) / _leg_length(ssk)
    root = scale * motion.root_positions
    out = Motion(tsk, R_t, root, motion.fps)
    if floor == "feet":
        low = lowest_foot_heights(out, target)
        root = root - np.array([0.0, 0.0, np.percentile(low, FLOOR_PERCENTILE)])
        out = Motion(tsk, R_t, root, motion.fps)
    return out


def _resolve_map(
    ssk: Skeleton, tsk: Skeleton, joint_map: Mapping[str, str] | None
) -> dict[str, str]:
    if joint_map is None:
        pairs = {t: s for t, s in canonical_name_map(ssk.names).items() if t in tsk.names}
    else:
        pairs = dict(joint_map)
        for t, s in pairs.items():
            if t not in tsk.names:
                raise SkeletonError(
                    f"retarget: joint_map names target joint {t!r}, not in the target skeleton"
                )
            if s not in ssk.names:
                raise SkeletonError(
                    f"retarget: joint_map names source joint {s!r}, not in the source skeleton"
                )
    root = tsk.names[0]
    missing = [n for n in (root, *_LEG) if n not in pairs]
    if missing:
        raise SkeletonError(
            f"retarget: source joints {list(ssk.names[:6])}... do not map target joints {missing}; "
            "pass joint_map={target: source}"
        )
    return pairs


def _leg_length(sk: Skeleton) -> float:
    """Rest length of the hip→knee→ankle chain, or the root height if it cannot be found."""
    idx = canonical_indices(sk, _LEG)
    P = sk.rest_positions
    if idx is not None:
        return float(np.linalg.norm(np.diff(P[idx], axis=0), axis=1).sum())
    return float(P[0, 2] - P[:, 2].min())
