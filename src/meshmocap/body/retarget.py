"""Retargeting motion-capture clips onto a template's skeleton.

The method transfers *world* bone orientations rather than local angles, which makes it
insensitive to the two skeletons having different rest poses (T-pose vs A-pose), bone
lengths or intermediate joints:

1. **Joint-name mapping** (:func:`~meshmocap.body.names.canonical_name_map` or a user map).
2. **Rest-pose offset correction:** for each mapped joint ``j`` with source joint ``s``, the
   rotation ``Q_j`` turns the target's rest bone direction onto the source's. A posed frame
   then sets ``G_t[j] = G_s[s] Q_j`` so that every target bone points where its source bone
   points (a T-pose source drives an A-pose template). The structural bones of
   :data:`KEEP_REST` (pelvis→hip, clavicles) are the exception: they inherit their parent's
   correction, ``G_t[j] = G_s[s] Q_parent``, i.e. keep the *target's* rest orientation
   relative to their parent with the source's motion on top. Matching their directions
   would reshape the target's body: CMU's pelvis→hip bones differ from a template's by
   24–46° (82° for the bone-less BVH flavour) and its clavicles by 12–19°, which moved the
   template's hip joints 4–8 cm and its shoulders 3–4 cm inside the skin in every frame.
   Unmapped target joints also inherit, keeping the rest orientation of their nearest
   mapped ancestor.
3. **Root-height scaling:** the root trajectory is scaled by the ratio of leg lengths, so
   strides fit the target's legs (no foot sliding beyond the source's).
4. **Floor contact:** a vertical shift puts the feet on the floor (z = 0) at their lowest
   points: constant over the clip, or following slow drifts of the source's floor height
   (a rolling low percentile of the feet's height, smoothed over a few seconds).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Literal, get_args

import numpy as np
from scipy.ndimage import percentile_filter, uniform_filter1d

from meshmocap._validate import check_choice
from meshmocap.body.contact import canonical_indices, lowest_foot_heights
from meshmocap.body.motion import Motion
from meshmocap.body.names import canonical_name_map
from meshmocap.body.skeleton import Skeleton, local_rotations
from meshmocap.body.template import Template
from meshmocap.errors import SkeletonError
from meshmocap.geometry.rotations import rotation_between

Floor = Literal["feet", "constant", "none"]
_LEG = ("LeftUpLeg", "LeftLeg", "LeftFoot")
#: Percentile of the per-frame lowest foot point that is put on the floor: robust to a few
#: frames of foot-through-floor noise, and to flight phases (jumps) that cover < 90 % of the
#: window.
FLOOR_PERCENTILE = 10.0
#: Seconds over which ``floor="feet"`` follows drifts of the source's floor height.
FLOOR_WINDOW = 2.0
#: Target joints that keep the target's rest orientation relative to their parent instead of
#: turning onto the source's bone direction: bones that are body structure, not posture.
KEEP_REST = ("LHipJoint", "RHipJoint", "Spine1", "LeftShoulder", "RightShoulder")


class Retargeter:
    """A precomputed mapping from a source skeleton onto a target's (a solver, reused per clip
    or per frame).

    Parameters
    ----------
    source : Skeleton
        The clips' skeleton (metres, Z up, facing −Y at rest).
    target : Template or Skeleton
        The skeleton to drive.
    joint_map : mapping, optional
        ``{target joint name: source joint name}`` (default: the known CMU flavours).
    keep_rest : collection of str, optional
        Target joints that keep the target's rest orientation relative to their parent
        rather than turning onto their source bone's direction (default
        :data:`KEEP_REST`); ``()`` matches every mapped bone.

    Attributes
    ----------
    pairs : dict
        The joint mapping used.
    scale : float
        Target/source leg-length ratio applied to the root trajectory.
    """

    def __init__(
        self,
        source: Skeleton,
        target: Template | Skeleton,
        *,
        joint_map: Mapping[str, str] | None = None,
        keep_rest: Collection[str] = KEEP_REST,
    ):
        self.source = source
        self.target = target
        tsk = target.skeleton if isinstance(target, Template) else target
        self.skeleton = tsk
        self.pairs = _resolve_map(source, tsk, joint_map)
        t_idx = np.array([tsk.index(t) for t in self.pairs])
        s_idx = np.array([source.index(s) for s in self.pairs.values()])
        # Rest-pose offset correction: Q_j d_t = d_s.
        d_t, d_s = tsk.bone_directions[t_idx], source.bone_directions[s_idx]
        Q = rotation_between(d_t, d_s)
        unknown = (np.linalg.norm(d_t, axis=1) < 0.5) | (np.linalg.norm(d_s, axis=1) < 0.5)
        Q[unknown | (t_idx == 0)] = np.eye(3)  # root: both face −Y, Z up by convention
        own = np.array([tsk.names[j] not in keep_rest for j in t_idx], dtype=bool)
        own[t_idx == 0] = True
        # Joints in keep_rest inherit their parent's correction (target rest shape kept);
        # unmapped ones also share their parent's source rotation. One gather per frame.
        src = np.full(tsk.n_joints, -1)
        has = np.zeros(tsk.n_joints, dtype=bool)
        corr = np.empty((tsk.n_joints, 3, 3))
        src[t_idx], corr[t_idx[own]], has[t_idx[own]] = s_idx, Q[own], True
        for j in range(1, tsk.n_joints):  # parents first
            p = tsk.parents[j]
            if src[j] < 0:
                src[j] = src[p]
            if not has[j]:
                corr[j] = corr[p]
        self._src, self._corr = src, corr
        self.scale = _leg_length(tsk) / _leg_length(source)

    def __call__(self, motion: Motion, *, floor: Floor = "feet") -> Motion:
        """Return ``motion`` (on the source skeleton) replayed by the target; see
        :func:`retarget` for ``floor``."""
        check_choice("retarget", "floor", floor, get_args(Floor))
        G_t = motion.global_rotations[:, self._src] @ self._corr
        R_t = local_rotations(self.skeleton, G_t)
        root = self.scale * motion.root_positions
        out = Motion(self.skeleton, R_t, root, motion.fps)
        if floor != "none":
            low = lowest_foot_heights(out, self.target)
            root[:, 2] -= floor_offsets(low, motion.fps, constant=floor == "constant")
            out = Motion(self.skeleton, R_t, root, motion.fps)
        return out


def retarget(
    motion: Motion,
    target: Template | Skeleton,
    *,
    joint_map: Mapping[str, str] | None = None,
    keep_rest: Collection[str] = KEEP_REST,
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
    keep_rest : collection of str, optional
        Target joints that keep the target's rest shape instead of following their source
        bone's direction (default :data:`KEEP_REST`); see :class:`Retargeter`.
    floor : {"feet", "constant", "none"}
        ``"feet"`` shifts the clip vertically so the feet touch z = 0 at their lowest points,
        following slow drifts of the source floor (over :data:`FLOOR_WINDOW` seconds);
        ``"constant"`` uses one shift for the whole clip; ``"none"`` keeps the scaled source
        height.

    Returns
    -------
    Motion
        Same frames and frame rate, on ``target``'s skeleton.

    Raises
    ------
    SkeletonError
        The mapping names unknown joints or leaves the root or a leg unmapped.
    """
    return Retargeter(motion.skeleton, target, joint_map=joint_map, keep_rest=keep_rest)(
        motion, floor=floor
    )


def floor_offsets(low: np.ndarray, fps: float, *, constant: bool = False) -> np.ndarray:
    """Return (T,) heights to subtract so that the lowest foot points ``low`` (T,) touch z = 0.

    A rolling :data:`FLOOR_PERCENTILE` percentile over :data:`FLOOR_WINDOW` seconds, smoothed by
    a moving average of the same length; one value for the whole clip when ``constant`` or
    when the clip is shorter than the window.
    """
    w = round(FLOOR_WINDOW * fps)
    if constant or len(low) <= w:
        return np.full(len(low), np.percentile(low, FLOOR_PERCENTILE))
    rolled = percentile_filter(low, FLOOR_PERCENTILE, size=w, mode="nearest")
    return uniform_filter1d(rolled, size=w, mode="nearest")


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
