"""Automatic initialisation: the template's first pose found from the capture alone.

The performer may stand anywhere in the volume, facing any way, in any pose people take. A
global search covers that (no ground truth, no hand placement):

1. **Candidates from what people do.** Every pose of the bundled CMU pose library
   (:mod:`meshmocap.body.pose_library`, 2,400 poses of walks, runs, jumps, dance, salsa and
   everyday actions, retargeted onto the template, their heading removed) and a few seed
   poses (:data:`SEEDS`), each turned to ``n_headings`` headings about the vertical and
   placed with its centroid on the observations'; all scored at once against the frame
   (:class:`~meshmocap.estimate.pose.pose_search.FrameScorer`: model points outside the
   observed solid, and silhouette pixels — or, without cameras, observed points — far
   from the model), the best shifted by a few ICP translation steps and scored again
   (:func:`coarse_candidates`).
2. **Coarse fits.** The ``n_candidates`` best distinct candidates get a few iterations of
   the articulated Gauss–Newton (:class:`~meshmocap.estimate.pose.fit.PoseFitter`: closest points
   both ways, normals agreeing) on a subsample of the points, pulled weakly towards their
   start, and are ranked by the fit score plus the silhouette mismatch
   (:func:`ranking_key`).
3. **Limb by limb.** The ``keep`` best have each limb replaced by the library's
   hypotheses for that limb (:func:`library_limb_candidates`: its joints' rotations as in
   every library pose, scored at once, the best fitted with that limb free) where that
   ranks better; then they are refined on more points with a shrinking pairing distance.
   The best wins; the best distinct other candidate is the runner-up, and a start whose
   key is high or whose runner-up is close is uncertain (:func:`start_message`).

:func:`limb_candidates` re-seeds single limbs of a known pose over the sphere (without a
voxel occupancy to score library hypotheses against). Metres and radians, world frame Z
up; the template's rest frames are world-aligned (:mod:`meshmocap.body.skeleton`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap.body.pose_library import PoseLibrary, load_pose_library
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.fit import PoseFit, PoseFitter, silhouette_mismatch
from meshmocap.estimate.pose.pose_search import (
    FrameScorer,
    body_sample,
    headings_removed,
    posed_samples,
    turned_about_z,
)
from meshmocap.estimate.recovery.quality import fit_quality, limb_labels
from meshmocap.geometry.carving import VoxelHull
from meshmocap.geometry.distance_field import DistanceGrid
from meshmocap.geometry.rotations import rotation_between, so3_exp

__all__ = [
    "LIMBS",
    "SEEDS",
    "InitResult",
    "LibraryPoses",
    "body_frame",
    "coarse_candidates",
    "initial_pose",
    "initial_pose_of_frame",
    "library_limb_candidates",
    "library_poses",
    "limb_candidates",
    "ranking_key",
    "refine_limbs",
    "seed_pose",
    "start_flags",
    "start_message",
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
    label : str, the winning candidate (library pose or seed, and heading)
    candidates : tuple of PoseFit, the refined candidates, best first
    key : float, the winner's ranking key (:func:`ranking_key`, metres)
    runner_up : PoseFit or None, the best refined candidate in another pose than the
        winner's (some evaluation joint more than :data:`DISTINCT` away)
    runner_up_key : float, its ranking key (inf without one)
    mismatch : float, the winner's silhouette mismatch
        (:func:`~meshmocap.estimate.pose.fit.silhouette_mismatch`; nan without silhouettes)
    lost : tuple of str, the winner's limbs that the fit-quality check
        (:func:`~meshmocap.estimate.recovery.quality.fit_quality`) finds lost (empty without a
        signed distance of the observed solid)
    """

    R: np.ndarray
    root: np.ndarray
    score: float
    label: str
    candidates: tuple[PoseFit, ...]
    key: float = float("nan")
    runner_up: PoseFit | None = None
    runner_up_key: float = float("inf")
    mismatch: float = float("nan")
    lost: tuple[str, ...] = ()

    @property
    def margin(self) -> float:
        """How much worse the runner-up ranks than the winner (metres of ranking key)."""
        return float(self.runner_up_key - self.key)


#: Model and observed points of the first, cheapest score of every library candidate.
COARSE_POINTS = 64
#: Metres some evaluation joint must differ by for two candidate poses to count as distinct.
DISTINCT = 0.1
#: Metres of 3-D score a silhouette mismatch of 1 (the whole silhouette) weighs.
SILHOUETTE_WEIGHT = 0.3


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
    ``seeds`` (:data:`SEEDS`). Poses of the trials ``exclude_trials`` are left out (a
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


def coarse_candidates(
    template: Template,
    poses: LibraryPoses,
    scorer: FrameScorer,
    *,
    n_headings: int = 16,
    n_best: int = 12,
    n_shifted: int = 300,
    shifts: int = 3,
) -> list[PoseFit]:
    """The ``n_best`` most promising distinct candidates for one frame: every pose of
    ``poses`` at ``n_headings`` headings, placed with the posed sample's centroid on the
    observed points', scored at once (:meth:`FrameScorer.score`); the ``n_shifted`` best
    moved by ``shifts`` ICP translation steps (:meth:`FrameScorer.shift`) and scored
    again; the best kept greedily, each with some evaluation joint more than
    :data:`DISTINCT` from every one kept before. ``score`` of each is the coarse score."""
    sk = template.skeleton
    sample = body_sample(template)
    N = len(poses.R)
    headings = 2 * np.pi * np.arange(n_headings) / n_headings
    G, P = forward_kinematics(sk, poses.R, np.zeros((N, 3)))
    X0 = np.einsum("nmab,mb->nma", G[:, sample.joint], sample.offset) + P[:, sample.joint]
    c, s = np.cos(headings), np.sin(headings)
    Rz = np.zeros((n_headings, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    scores = np.empty((n_headings, N))
    roots = np.empty((n_headings, N, 3))
    for h in range(n_headings):  # a cheap score first (prefixes of both point sets)
        X = X0 @ Rz[h].T
        t = scorer.centre - X.mean(axis=1)  # (N, 3): where the root goes
        roots[h] = t
        scores[h] = scorer.score(X + t[:, None, :], n_model=COARSE_POINTS, n_data=COARSE_POINTS)
    order = np.argsort(scores, axis=None)[: 8 * n_shifted]
    hh, nn = np.unravel_index(order, scores.shape)
    X = np.einsum("cma,cba->cmb", X0[nn], Rz[hh]) + roots[hh, nn][:, None, :]
    order = order[np.argsort(scorer.score(X))[:n_shifted]]
    hh, nn = np.unravel_index(order, scores.shape)
    R = turned_about_z(poses.R[nn], headings[hh])
    root = roots[hh, nn]
    for _ in range(shifts):
        X, _ = posed_samples(template, sample, R, root)
        root = root + scorer.shift(X)
    X, Pj = posed_samples(template, sample, R, root)
    sc = scorer.score(X)
    ev = template.eval_skeleton.weights
    E = np.einsum("kj,cja->cka", ev, Pj)  # evaluation joints (rest offsets aside)
    kept: list[int] = []
    for i in np.argsort(sc):
        if all(np.linalg.norm(E[i] - E[k], axis=1).max() > DISTINCT for k in kept):
            kept.append(int(i))
            if len(kept) == n_best:
                break
    return [
        PoseFit(
            R[i],
            root[i],
            float(sc[i]),
            f"{poses.labels[nn[i]]}@{np.rad2deg(headings[hh[i]]):.0f}°",
        )
        for i in kept
    ]


def initial_pose(
    template: Template,
    P: np.ndarray,
    N: np.ndarray,
    *,
    n_headings: int = 16,
    seeds: tuple[str, ...] = tuple(SEEDS),
    library: PoseLibrary | None = None,
    library_size: int | None = None,
    exclude_trials: tuple[str, ...] = (),
    n_candidates: int = 12,
    keep: int = 3,
    limb_hypotheses: int = 3,
    coarse_iterations: int = 8,
    iterations: int = 30,
    limb_directions: int = 10,
    cameras: list | None = None,
    masks: list | None = None,
    field: DistanceGrid | None = None,
    hull: VoxelHull | None = None,
    seed: int = 0,
) -> InitResult:
    """Find the template's pose on observed points by a global search (module docstring).

    Parameters
    ----------
    template : Template
        The tracking template (rest frames world-aligned, CMU MotionBuilder joint names).
    P, N : (p, 3) float64
        Observed surface points (metres, world frame Z up) and outward unit normals, e.g.
        :func:`~meshmocap.estimate.recovery.observe.frame_points` of the first frame.
    n_headings : int
        Headings tried per candidate pose, evenly spaced over 360°.
    seeds : tuple of str
        Seed poses (:data:`SEEDS`) tried besides the library's.
    library : PoseLibrary, optional
        The poses searched (default: the bundled CMU library).
    library_size : int, optional
        Search only its first poses (a diverse subset); default all.
    exclude_trials : tuple of str
        Library trials left out of the search (:func:`library_poses`).
    n_candidates : int
        Distinct candidates of the coarse search fitted (:func:`coarse_candidates`).
    keep : int
        Candidates refined after those fits.
    limb_hypotheses : int
        Library hypotheses fitted per limb of each (:func:`refine_limbs_from_library`).
    coarse_iterations, iterations : int
        Gauss–Newton iterations of each coarse fit and of each refinement.
    cameras, masks : list of Camera and of (height, width) bool, optional
        The capture's cameras and this frame's silhouettes: candidates are then ranked by
        their silhouette mismatch (:func:`~meshmocap.estimate.pose.fit.silhouette_mismatch`)
        plus the 3-D score, which tells a torso turned 90° in a 4-camera hull apart
        where the points alone hardly do.
    field : DistanceGrid, optional
        Signed distance of the observed solid (e.g. of the frame's hull): model points
        outside it cost in the score (:class:`~meshmocap.estimate.pose.fit.PoseFitter`).
    hull : VoxelHull, optional
        The observed solid as voxels: the coarse search scores its candidates against it
        (:class:`~meshmocap.estimate.pose.pose_search.FrameScorer`); without it only the seed
        poses are searched, each fitted.
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
    if hull is not None:
        scorer = FrameScorer(
            hull.occupancy, hull.origin, hull.voxel_size, P, cameras=cameras, masks=masks
        )
        poses = library_poses(
            template, library=library, n=library_size, exclude_trials=exclude_trials, seeds=seeds
        )
        starts = coarse_candidates(
            template, poses, scorer, n_headings=n_headings, n_best=n_candidates
        )
    else:
        starts = []
        for name in seeds:
            R0 = seed_pose(template, name)
            for h in range(n_headings):
                deg = 360.0 * h / n_headings
                R = _turned(R0, np.deg2rad(deg))
                starts.append(
                    PoseFit(R, _centred_root(coarse, R, centre), 0.0, f"{name}@{deg:.0f}°")
                )
    fits = [_refit(coarse, f, coarse_iterations, (0.3, 0.1), 1e-3) for f in starts]
    rank = ranking_key(template, cameras, masks)
    keys = [rank(f) for f in fits]
    fits = [fits[i] for i in np.argsort(keys)]
    Pf, Nf = subsample_points(P, N, 5000, seed)
    fine = PoseFitter(template, Pf, Nf, n_model_points=1500, field=field, seed=seed)
    refined = []
    for f in fits[:keep]:
        if hull is not None:
            f = refine_limbs_from_library(
                coarse, f, poses, scorer, n_best=limb_hypotheses, key=rank
            )
        else:
            f = refine_limbs(coarse, f, limbs=tuple(LIMBS), directions=limb_directions, key=rank)
        f = _refit(fine, f, iterations, (0.15, 0.03), 1e-4)
        # then settle on the near surface, barely held (a long pull undoes small moves)
        f = _refit(fine, f, iterations // 2, (0.04, 0.01), 1e-6)
        refined.append(f)
    rk = [rank(f) for f in refined]
    order = np.argsort(rk)
    refined = [refined[i] for i in order]
    rk = [rk[i] for i in order]
    best = refined[0]
    # the runner-up: the best other candidate (refined, else coarse) in a distinct pose
    E = template.pose(best.R, best.root).eval_joints
    runner, runner_key = None, float("inf")
    for f, k in [*zip(refined[1:], rk[1:], strict=True), *((f, None) for f in fits[keep:])]:
        if np.linalg.norm(template.pose(f.R, f.root).eval_joints - E, axis=1).max() > DISTINCT:
            runner, runner_key = f, (rank(f) if k is None else k)
            break
    mismatch = (rk[0] - best.score) / SILHOUETTE_WEIGHT if cameras and masks else float("nan")
    lost: tuple[str, ...] = ()
    if field is not None:
        V = template.pose(best.R, best.root).V
        labels = limb_labels(template)
        q = fit_quality(V, labels, P, field, F=template.F, cameras=cameras, masks=masks, seed=seed)
        lost = q.lost
    return InitResult(
        best.R,
        best.root,
        best.score,
        best.label,
        tuple(refined),
        rk[0],
        runner,
        runner_key,
        mismatch,
        lost,
    )


#: Least margin (metres of ranking key) between the start and a distinct runner-up for a
#: confident start.
START_MARGIN = 0.002
#: What a start's message says when it is uncertain (the first frame is flagged ``lost``).
UNCERTAIN_START = "uncertain start"


def start_message(res: InitResult) -> str:
    """One line saying how the first pose was found: the winner, its score and ranking
    key, the runner-up and its margin, and whether the start is uncertain (a limb the
    fit-quality check finds lost, or a distinct runner-up within :data:`START_MARGIN`)."""
    msg = f"init auto: {res.label}, fit score {1000 * res.score:.1f} mm, key {1000 * res.key:.1f}"
    if res.runner_up is not None:
        msg += f"; runner-up {res.runner_up.label} (+{1000 * res.margin:.1f} mm)"
    why = [f"{limb} lost" for limb in res.lost]
    if res.margin < START_MARGIN:
        why.append(f"runner-up within {1000 * START_MARGIN:.0f} mm")
    if why:
        msg += f"; {UNCERTAIN_START} ({', '.join(why)})"
    return msg


def start_flags(message: str) -> tuple[str, ...]:
    """The first frame's flags from its :func:`start_message`: ``("lost",)`` for an
    uncertain start."""
    return ("lost",) if UNCERTAIN_START in message else ()


def _refit(fitter: PoseFitter, f: PoseFit, iterations: int, distance, lam: float) -> PoseFit:
    """``f`` fitted again by ``fitter`` from where it stands, keeping its label."""
    return fitter.fit(
        f.R, f.root, iterations=iterations, max_distance=distance, lambda_pose=lam, label=f.label
    )


def initial_pose_of_frame(template: Template, frame, **options) -> InitResult:
    """:func:`initial_pose` on a capture frame (any frame
    :func:`~meshmocap.estimate.recovery.observe.observed` reads): its points and normals, occupancy,
    signed distance and, where it has cameras, silhouettes. ``options`` go to
    :func:`initial_pose`."""
    from meshmocap.estimate.recovery.observe import observed

    obs = observed(frame)
    P, N = obs.points
    masks = obs.silhouettes if obs.cameras else None
    return initial_pose(
        template,
        P,
        N,
        cameras=obs.cameras,
        masks=masks,
        field=obs.field,
        hull=obs.hull,
        **options,
    )


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
    X, Pj = posed_samples(template, sample, Rc, np.broadcast_to(root, (len(Rc), 3)))
    sc = scorer.score(X, n_model=COARSE_POINTS, n_data=COARSE_POINTS)
    top = np.argsort(sc)[: 20 * n_best]
    sc = np.full(len(sc), np.inf)
    sc[top] = scorer.score(X[top])
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
