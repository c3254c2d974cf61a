"""A whole-body search cheap enough to run many times: the pose of one frame inside a run
of lost frames (a keyframe), found again from the frame alone, helped by the tracked pose
where there is one.

The first pose's search (:func:`~meshmocap.estimate.pose.first_pose.initial_pose`) knows
nothing of the performer; a keyframe search usually knows where the track stood at (or
near) the frame and which of its limbs are lost. :func:`keyframe_pose` uses that:

* **Headings.** The tracked torso gives the heading: the library is tried at
  :data:`NEAR_HEADINGS` about it instead of all around.
* **The library.** The tracked limbs that are not lost narrow it: the poses whose kept
  limbs (elbows, wrists, knees, ankles relative to the pelvis) are nearest to the tracked
  ones (:data:`NEAR_POSES` of them), with the library's first poses (a diverse subset,
  :data:`DIVERSE_POSES`) besides, in case the track is wrong where it is not flagged.
* **The tracked pose itself**, with its lost limbs set as in every library pose, all
  scored at once: the best few distinct (:data:`HYBRIDS`) join the candidates.
* **Fewer fits.** Fewer candidates fitted coarsely, one refined, limb by limb only over
  the lost limbs (:data:`SEARCH`); the candidates' scorer samples a subsample of the
  observed points (:data:`SCORER_POINTS`).

Without a tracked pose it searches all around, as the first pose's search does, with the
same fewer fits (every limb refined). ``benchmarks/bench_keyframe.py`` measures both
against the first pose's search on frames inside failure runs (``docs/measurements.rst``).
Metres and radians, world frame Z up.
"""

from __future__ import annotations

import numpy as np

from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.first_pose import (
    InitResult,
    coarse_candidates,
    refined_search,
    subsample_points,
)
from meshmocap.estimate.pose.fit import PoseFit, PoseFitter
from meshmocap.estimate.pose.library import (
    COARSE_POINTS,
    DISTINCT,
    LibraryPoses,
    body_frame,
    library_poses,
)
from meshmocap.estimate.pose.pose_search import (
    FrameScorer,
    body_sample,
    posed_samples,
)
from meshmocap.estimate.recovery.limbs import LIMBS, limb_joint_indices
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.quality import LIMB_PARTS

__all__ = [
    "DIVERSE_POSES",
    "HYBRIDS",
    "NEAR_HEADINGS",
    "NEAR_POSES",
    "SCORER_POINTS",
    "SEARCH",
    "keyframe_pose",
    "near_heading",
    "nearest_library_poses",
]

#: Degrees about the tracked heading the library is tried at.
NEAR_HEADINGS = (-30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0)
#: Library poses nearest to the tracked pose's kept limbs that are searched.
NEAR_POSES = 300
#: The library's first poses (a diverse subset) searched besides.
DIVERSE_POSES = 200
#: Observed points (a seeded subsample) the candidates' scorer samples from.
SCORER_POINTS = 5000
#: Candidates made of the tracked pose with its lost limbs from the library.
HYBRIDS = 2
#: Options of the search's stages (:func:`~meshmocap.estimate.pose.first_pose.refined_search`
#: and :func:`~meshmocap.estimate.pose.first_pose.coarse_candidates`): coarse candidates
#: fitted with a tracked pose and without, candidates refined, limb hypotheses per limb,
#: iterations, observed points of the refinement.
SEARCH = dict(
    n_near=2,
    n_far=6,
    n_shifted=100,
    keep=1,
    limb_hypotheses=3,
    coarse_iterations=8,
    iterations=30,
    fine_points=5000,
    fine_model_points=1500,
)


def near_heading(template: Template, R: np.ndarray) -> float:
    """Radians: the heading of the pose ``R`` (J, 3, 3) (its root's front, turned about the
    vertical from the template's rest front; the library's poses face heading 0)."""
    f = body_frame(template)[:, 1]
    g = np.asarray(R, dtype=np.float64)[0] @ f
    return float(np.arctan2(g[1], g[0]) - np.arctan2(f[1], f[0]))


def _limb_points(template: Template, R: np.ndarray) -> np.ndarray:
    """(N, 4, 2, 3) float64: each limb's middle and end joint (elbow and wrist, knee and
    ankle) of the poses ``R`` (N, J, 3, 3), in the root's frame, metres."""
    sk = template.skeleton
    G, P = forward_kinematics(sk, R, np.zeros((len(R), 3)))
    idx = np.array([[sk.index(n) for n in LIMBS[limb][0][1:]] for limb in LIMBS])
    rel = P[:, idx] - P[:, None, None, 0]
    return np.einsum("nba,nlkb->nlka", G[:, 0], rel)  # G₀ᵀ (p − p₀)


def nearest_library_poses(
    template: Template, poses: LibraryPoses, R: np.ndarray, *, lost: tuple[str, ...], n: int
) -> np.ndarray:
    """(min(n, N),) int64: the indices of the ``n`` poses of ``poses`` whose limbs not in
    ``lost`` are nearest to those of ``R`` (J, 3, 3): the mean distance of their elbows,
    wrists, knees and ankles relative to the pelvis, in its frame; every pose's
    distance is 0 when all limbs are lost (the first ``n`` then)."""
    kept = [i for i, limb in enumerate(LIMBS) if limb not in lost]
    n = min(int(n), len(poses.R))
    if not kept:
        return np.arange(n)
    L = _limb_points(template, poses.R)[:, kept]
    x = _limb_points(template, np.asarray(R, dtype=np.float64)[None])[0, kept]
    d = np.linalg.norm(L - x, axis=-1).mean(axis=(1, 2))
    return np.sort(np.argsort(d, kind="stable")[:n])


def _hybrids(
    template: Template,
    poses: LibraryPoses,
    scorer: FrameScorer,
    R: np.ndarray,
    root: np.ndarray,
    lost: tuple[str, ...],
    n_best: int,
) -> list[PoseFit]:
    """The tracked pose ``(R, root)`` with its ``lost`` limbs' joints set as in each of
    ``poses`` (the limb and everything it carries), all scored at once
    (:meth:`FrameScorer.score`): the ``n_best`` best distinct, best first; the tracked
    pose alone without a lost limb."""
    if not lost:
        X, _ = posed_samples(template, body_sample(template), R[None], root[None])
        return [PoseFit(R, root, float(scorer.score(X)[0]), "tracked")]
    idx = np.unique(np.concatenate([limb_joint_indices(template, limb) for limb in lost]))
    Rc = np.broadcast_to(R, poses.R.shape).copy()
    Rc[:, idx] = poses.R[:, idx]
    X, Pj = posed_samples(template, body_sample(template), Rc, np.broadcast_to(root, (len(Rc), 3)))
    sc = scorer.score(X, n_model=COARSE_POINTS, n_data=COARSE_POINTS)
    top = np.argsort(sc)[: 20 * n_best]
    sc = np.full(len(sc), np.inf)
    sc[top] = scorer.score(X[top])
    kept: list[int] = []
    for i in np.argsort(sc)[: len(top)]:
        if all(np.linalg.norm(Pj[i, idx] - Pj[k, idx], axis=1).max() > DISTINCT for k in kept):
            kept.append(int(i))
            if len(kept) == n_best:
                break
    return [
        PoseFit(Rc[i], np.array(root), float(sc[i]), f"tracked+{poses.labels[i]}") for i in kept
    ]


def keyframe_pose(
    template: Template,
    frame,
    *,
    near: tuple[np.ndarray, np.ndarray] | None = None,
    lost: tuple[str, ...] = (),
    exclude_trials: tuple[str, ...] = (),
) -> InitResult:
    """The pose of ``frame`` found by a whole-body search (module docstring), helped by a
    tracked pose ``near`` where given.

    Parameters
    ----------
    template : Template
        The tracking template.
    frame : a capture frame
        Any frame :func:`~meshmocap.estimate.recovery.observe.observed` reads (its points,
        occupancy, signed distance and, where it has cameras, silhouettes).
    near : (R (J, 3, 3) float64, root (3,) float64), optional
        A tracked pose at or near the frame (local rotations; root position, metres): its
        torso gives the heading, its limbs not in ``lost`` narrow the library, and it is
        itself a candidate with its lost limbs from the library. Without it, every
        heading and the whole library are searched.
    lost : tuple of str
        The limbs of ``near`` that are lost (:data:`~meshmocap.estimate.recovery.limbs.LIMBS`
        keys): those are searched limb by limb (without ``near``: every limb). The lost
        rule's other parts (:data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS`) are
        taken too: a lost ``"torso"`` leaves ``near`` out (its heading is not trusted), a
        lost ``"head"`` changes nothing.
    exclude_trials : tuple of str
        Library trials left out of the search
        (:func:`~meshmocap.estimate.pose.library.library_poses`).

    Returns
    -------
    InitResult
        As the first pose's search's (its ``lost``: the winner's limbs that the fit-quality
        check finds lost).
    """
    lost = tuple(lost)
    bad = [limb for limb in lost if limb not in LIMB_PARTS]
    if bad:
        raise InputError(f"keyframe: lost limbs must be among {list(LIMB_PARTS)}, found {bad}")
    if "torso" in lost:  # the tracked heading is not to be trusted either
        near = None
    lost = tuple(limb for limb in lost if limb in LIMBS)
    obs = observed(frame)
    P, N = obs.points
    if len(P) < 50:
        raise InputError(
            f"keyframe: frame {obs.index} has {len(P)} observed points; a search needs ≥ 50"
        )
    J = template.skeleton.n_joints
    if near is not None:
        R_near = np.asarray(near[0], dtype=np.float64)
        root_near = np.asarray(near[1], dtype=np.float64)
        if R_near.shape != (J, 3, 3) or root_near.shape != (3,):
            raise InputError(
                f"keyframe: near must be (R ({J}, 3, 3), root (3,)), found "
                f"{R_near.shape} and {root_near.shape}"
            )
    cameras = obs.cameras or None
    masks = obs.silhouettes if cameras else None
    hull = obs.hull
    # the scorer's farthest-point sample drawn from a random one (as spread, 10× cheaper)
    Ps, _ = subsample_points(P, N, SCORER_POINTS, 0)
    scorer = FrameScorer(
        hull.occupancy, hull.origin, hull.voxel_size, Ps, cameras=cameras, masks=masks
    )
    poses = library_poses(template, exclude_trials=exclude_trials)
    o = SEARCH
    if near is None:
        starts = coarse_candidates(
            template, poses, scorer, n_headings=16, n_best=o["n_far"], n_shifted=o["n_shifted"]
        )
        limbs = tuple(LIMBS)
    else:
        pick = np.union1d(
            nearest_library_poses(template, poses, R_near, lost=lost, n=NEAR_POSES),
            np.arange(min(DIVERSE_POSES, len(poses.R))),
        )
        sub = LibraryPoses(poses.R[pick], tuple(poses.labels[i] for i in pick))
        h0 = near_heading(template, R_near)
        starts = _hybrids(template, poses, scorer, R_near, root_near, lost, HYBRIDS)
        starts += coarse_candidates(
            template,
            sub,
            scorer,
            n_best=o["n_near"],
            n_shifted=o["n_shifted"],
            headings=h0 + np.deg2rad(NEAR_HEADINGS),
        )
        limbs = lost
    Pc, Nc = subsample_points(P, N, 2000, 0)
    coarse = PoseFitter(template, Pc, Nc, n_model_points=500, field=obs.field, seed=0)
    return refined_search(
        template,
        P,
        N,
        starts,
        poses=poses,
        scorer=scorer,
        limbs=limbs,
        keep=o["keep"],
        limb_hypotheses=o["limb_hypotheses"],
        coarse_iterations=o["coarse_iterations"],
        iterations=o["iterations"],
        fine_points=o["fine_points"],
        fine_model_points=o["fine_model_points"],
        cameras=cameras,
        masks=masks,
        field=obs.field,
        coarse=coarse,
    )
