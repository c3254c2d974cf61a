"""Automatic initialisation: the template's first pose found from the capture alone.

The performer may stand anywhere in the volume, facing any way, in any pose people take. A
global search covers that (no ground truth, no hand placement):

1. **Candidates from what people do.** Every pose of the bundled CMU pose library
   (:mod:`meshmocap.body.pose_library`, 2,400 poses of walks, runs, jumps, dance, salsa and
   everyday actions, retargeted onto the template, their heading removed) and a few seed
   poses (:data:`~meshmocap.estimate.pose.library.SEEDS`), each turned to ``n_headings``
   headings about the vertical and placed with its centroid on the observations'; all
   scored at once against the frame
   (:class:`~meshmocap.estimate.pose.pose_search.FrameScorer`: model points outside the
   observed solid, and silhouette pixels — or, without cameras, observed points — far
   from the model), the best shifted by a few ICP translation steps and scored again
   (:func:`coarse_candidates`).
2. **Coarse fits.** The ``n_candidates`` best distinct candidates get a few iterations of
   the articulated Gauss–Newton (:class:`~meshmocap.estimate.pose.fit.PoseFitter`: closest
   points both ways, normals agreeing) on a subsample of the points, pulled weakly towards
   their start, and are ranked by the fit score plus the silhouette mismatch
   (:func:`ranking_key`).
3. **Limb by limb.** The ``keep`` best have each limb replaced by the library's
   hypotheses for that limb (the lost-limb search,
   :func:`~meshmocap.estimate.recovery.limbs.refine_limbs_from_library`: its joints'
   rotations as in every library pose, scored at once, the best fitted with that limb
   free) where that ranks better; then they are refined on more points with a shrinking
   pairing distance. The best wins; the best distinct other candidate is the runner-up,
   and a start whose winner has a limb lost or whose runner-up is close is uncertain
   (:func:`~meshmocap.estimate.pose.start.search_start`).

Metres and radians, world frame Z up; the template's rest frames are world-aligned
(:mod:`meshmocap.body.skeleton`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshmocap._parallel import parallel_map
from meshmocap._progress import phase
from meshmocap.body.pose_library import PoseLibrary
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.pose.fit import PoseFit, PoseFitter, silhouette_mismatch
from meshmocap.estimate.pose.library import (
    COARSE_POINTS,
    DISTINCT,
    SEEDS,
    LibraryPoses,
    library_poses,
    seed_pose,
)
from meshmocap.estimate.pose.pose_search import (
    FrameScorer,
    body_sample,
    posed_samples,
    turned_about_z,
)
from meshmocap.estimate.recovery.limbs import LIMBS, refine_limbs, refine_limbs_from_library
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.quality import fit_quality, limb_labels
from meshmocap.geometry.carving import VoxelHull
from meshmocap.geometry.distance_field import DistanceGrid
from meshmocap.geometry.rotations import so3_exp

__all__ = [
    "SILHOUETTE_WEIGHT",
    "InitResult",
    "coarse_candidates",
    "initial_pose",
    "initial_pose_of_frame",
    "ranking_key",
    "subsample_points",
]


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


#: Coarse candidates (poses × headings) from which :func:`coarse_candidates` scores its
#: headings side by side (:mod:`meshmocap._parallel`).
PARALLEL_CANDIDATES = 10_000


def subsample_points(
    P: np.ndarray, N: np.ndarray, n: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """At most ``n`` of the points (p, 3) and their normals (p, 3), a seeded subsample."""
    if len(P) <= n:
        return P, N
    pick = np.random.default_rng(seed).choice(len(P), n, replace=False)
    return P[pick], N[pick]


def coarse_candidates(
    template: Template,
    poses: LibraryPoses,
    scorer: FrameScorer,
    *,
    n_headings: int = 16,
    n_best: int = 12,
    n_shifted: int = 300,
    shifts: int = 3,
    headings: np.ndarray | None = None,
) -> list[PoseFit]:
    """The ``n_best`` most promising distinct candidates for one frame: every pose of
    ``poses`` at ``n_headings`` headings, placed with the posed sample's centroid on the
    observed points', scored at once (:meth:`FrameScorer.score`); the ``n_shifted`` best
    moved by ``shifts`` ICP translation steps (:meth:`FrameScorer.shift`) and scored
    again; the best kept greedily, each with some evaluation joint more than
    :data:`DISTINCT` from every one kept before. ``score`` of each is the coarse score.
    ``headings`` (h,) float64, radians: the headings tried instead (e.g. a few about a
    known one)."""
    sk = template.skeleton
    sample = body_sample(template)
    N = len(poses.R)
    if headings is None:
        headings = 2 * np.pi * np.arange(n_headings) / n_headings
    headings = np.atleast_1d(np.asarray(headings, dtype=np.float64))
    n_headings = len(headings)
    G, P = forward_kinematics(sk, poses.R, np.zeros((N, 3)))
    X0 = np.einsum("nmab,mb->nma", G[:, sample.joint], sample.offset) + P[:, sample.joint]
    c, s = np.cos(headings), np.sin(headings)
    Rz = np.zeros((n_headings, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0

    def heading(h: int) -> tuple[np.ndarray, np.ndarray]:  # a cheap score first (prefixes
        X = X0 @ Rz[h].T  # of both point sets)
        t = scorer.centre - X.mean(axis=1)  # (N, 3): where the root goes
        return t, scorer.score(X + t[:, None, :], n_model=COARSE_POINTS, n_data=COARSE_POINTS)

    # a whole search's headings side by side (meshmocap._parallel), the same scores; a few
    # near headings are not worth the workers' start
    each = parallel_map if N * n_headings >= PARALLEL_CANDIDATES else lambda f, x: list(map(f, x))
    roots, scores = (np.stack(a) for a in zip(*each(heading, range(n_headings)), strict=True))
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
        with phase(
            f"searching the pose library ({len(poses.R) * n_headings} candidates: "
            f"{len(poses.R)} poses × {n_headings} headings)"
        ):
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
    return refined_search(
        template,
        P,
        N,
        starts,
        poses=poses if hull is not None else None,
        scorer=scorer if hull is not None else None,
        keep=keep,
        limb_hypotheses=limb_hypotheses,
        coarse_iterations=coarse_iterations,
        iterations=iterations,
        limb_directions=limb_directions,
        cameras=cameras,
        masks=masks,
        field=field,
        seed=seed,
        coarse=coarse,
    )


def refined_search(
    template: Template,
    P: np.ndarray,
    N: np.ndarray,
    starts: list[PoseFit],
    *,
    poses: LibraryPoses | None = None,
    scorer: FrameScorer | None = None,
    limbs: tuple[str, ...] = tuple(LIMBS),
    keep: int = 3,
    limb_hypotheses: int = 3,
    coarse_iterations: int = 8,
    iterations: int = 30,
    limb_directions: int = 10,
    fine_points: int = 5000,
    fine_model_points: int = 1500,
    cameras: list | None = None,
    masks: list | None = None,
    field: DistanceGrid | None = None,
    seed: int = 0,
    coarse: PoseFitter | None = None,
) -> InitResult:
    """Steps 2 and 3 of the search (module docstring) from the coarse ``starts``: each
    fitted coarsely and ranked (:func:`ranking_key`), the ``keep`` best refined limb by
    limb (each of ``limbs``: from the library's hypotheses where ``poses`` and ``scorer``
    are given, else re-seeded over the sphere) and fitted on ``fine_points`` observed
    points; the winner, its runner-up and its lost limbs. Arguments as
    :func:`initial_pose`'s; ``coarse``, the coarse fitter where the caller has it.
    """
    if coarse is None:
        Pc, Nc = subsample_points(P, N, 2000, seed)
        coarse = PoseFitter(template, Pc, Nc, n_model_points=500, field=field, seed=seed)
    rank = ranking_key(template, cameras, masks)

    def coarse_fit(f: PoseFit) -> tuple[PoseFit, float]:
        f = _refit(coarse, f, coarse_iterations, (0.3, 0.1), 1e-3)
        return f, rank(f)

    # the candidates are independent: fitted side by side (meshmocap._parallel), the same fits
    with phase(f"fitting the best {len(starts)} candidates"):
        coarse_fits = parallel_map(coarse_fit, starts)
    fits = [coarse_fits[i][0] for i in np.argsort([k for _, k in coarse_fits])]
    Pf, Nf = subsample_points(P, N, fine_points, seed)
    fine = PoseFitter(template, Pf, Nf, n_model_points=fine_model_points, field=field, seed=seed)

    def refine(f: PoseFit) -> PoseFit:
        if poses is not None and scorer is not None:  # limb by limb from the library
            f = refine_limbs_from_library(
                coarse, f, poses, scorer, limbs=limbs, n_best=limb_hypotheses, key=rank
            )
        elif limbs:
            f = refine_limbs(coarse, f, limbs=limbs, directions=limb_directions, key=rank)
        f = _refit(fine, f, iterations, (0.15, 0.03), 1e-4)
        # then settle on the near surface, barely held (a long pull undoes small moves)
        return _refit(fine, f, max(iterations // 2, 1), (0.04, 0.01), lam=1e-6)

    with phase(f"refining the best {min(keep, len(fits))} candidates"):
        refined = parallel_map(refine, fits[:keep])
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
    if field is not None:  # about a second
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
