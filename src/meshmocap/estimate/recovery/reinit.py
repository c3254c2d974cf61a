"""Loss detection and re-initialisation during tracking.

After every frame, :class:`Recovery` scores the tracked mesh against the frame's
observations (:func:`~meshmocap.estimate.recovery.quality.fit_quality`). When a limb is
lost it searches, from the frame alone, for a better pose with the machinery of the
automatic initialisation (:mod:`meshmocap.estimate.pose`) and the lost-limb search
(:mod:`meshmocap.estimate.recovery.limbs`):

1. the tracked mesh's pose in the articulated model
   (:func:`~meshmocap.estimate.pose.fit.pose_of_vertices`, warm-started from the last
   frame's);
2. each limb lost for what the observations show (outside them, buried, or leaving
   observations unexplained) re-fitted from the pose library's hypotheses for that limb
   (:func:`~meshmocap.estimate.recovery.limbs.library_limb_candidates`: what people do
   with it, scored on this frame), each fitted with only that limb free, and the limb as
   tracked fitted alike; each is ranked by the fit score plus the silhouette mismatch plus
   how far the limb stands from where its recent motion puts it
   (:meth:`Recovery.motion_cost`: a fast limb moving on as it moved is kept), and a
   hypothesis replaces the limb only when it ranks better by more than :data:`MIN_GAIN`;
3. when the body itself is outside the observations (the torso more than
   :data:`TORSO_OUT` outside: the performer leaving the cameras' view, a truncated hull),
   nothing (a whole-body search re-seated there ran 1.2 m off on a run leaving the view);
4. a short fit of the whole body from the result, accepted only if it leaves fewer limbs
   lost (or as many, with less unexplained).

The tracker is then re-seated at that pose (``Tracker.reseat``); the frame carries the
flags ``lost`` and ``reinit`` and a message naming the limbs. A limb lost where nothing
unexplained is left to fit it to (the observations miss it, e.g. a limb the silhouettes
dropped) is flagged and left to the tracker. After a search that finds nothing better,
the next :data:`COOLDOWN` frames are only flagged, not searched again.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from meshmocap.body.articulated import articulated_model
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.estimate.pose.first_pose import ranking_key, subsample_points
from meshmocap.estimate.pose.fit import PoseFit, PoseFitter, pose_of_vertices
from meshmocap.estimate.pose.library import library_poses
from meshmocap.estimate.pose.pose_search import FrameScorer
from meshmocap.estimate.recovery.evidence import EVIDENCE, LostRule, lost_limbs, lost_reasons
from meshmocap.estimate.recovery.limbs import (
    LIMB_ROOTS,
    LIMBS,
    library_limb_candidates,
    limb_joint_indices,
)
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.quality import (
    BURIED_LOST,
    LIMB_PARTS,
    OUTSIDE_LOST,
    UNEXPLAINED_LOST,
    UNSEEN_LOST,
    UNSEEN_MARGIN,
    FitQuality,
    fit_quality,
    limb_labels,
    limb_shares,
)

__all__ = ["COOLDOWN", "JUMP", "MIN_GAIN", "Recovery", "Reinit"]

#: Least decrease of the ranking key (metres of fit score, with the motion cost) that
#: makes a re-seeded limb win: nothing is re-seated on weak evidence.
MIN_GAIN = 0.003
#: Fraction of the torso outside the observations beyond which nothing is re-seated.
TORSO_OUT = 0.25
#: Library hypotheses fitted per lost limb.
LIMB_HYPOTHESES = 4
#: Metres of ranking key per metre (RMS over the limb's joints) that a re-seeded limb
#: stands from where its recent motion (constant velocity over the last two frames) puts
#: it, counted up to :data:`MOTION_REACH`: a fast limb that moves on as it moved is kept.
MOTION_WEIGHT = 0.05
#: Metres (RMS over the limb's joints) past which a re-seeded limb's distance from its
#: predicted motion costs no more (:data:`MOTION_WEIGHT`).
MOTION_REACH = 0.3
#: Vertices the pose of the tracked mesh is fitted to (:meth:`Recovery.track_pose`).
POSE_POINTS = 600
#: Steps of that fit at most: warm-started from the last frame's pose it is within a
#: fraction of a millimetre (joint positions) of where more steps take it after three.
POSE_STEPS = 3
#: Radians (and metres of root) of a step below which that fit stops earlier.
POSE_TOL = 2e-3
#: Frames only flagged after a search that found no better pose.
COOLDOWN = 3
#: Metres a tracked limb must stand from where it was last seen (mean over its vertices)
#: to count as having jumped away from observations that no longer show it.
JUMP = 0.08
#: Consecutive frames a missed limb, as tracked, must fit the observations well (few of its
#: vertices outside them, few unexplained points near it) to count as seen again where it
#: is now: a fast limb that the observations follow is not held as lost.
SEEN_AGAIN = 3


@dataclass(frozen=True, eq=False)
class Reinit:
    """A re-initialisation found by :meth:`Recovery.reinitialise`.

    Attributes
    ----------
    R : (J, 3, 3) float64, local rotations; ``root`` (3,) float64, metres
    limbs : tuple of str, the limbs re-seeded (``("body",)`` for a whole-body search)
    quality : FitQuality, of the template posed there
    """

    R: np.ndarray
    root: np.ndarray
    limbs: tuple[str, ...]
    quality: FitQuality


class Recovery:
    """Fit-quality checks and re-initialisation for one tracking run (module docstring).

    Parameters
    ----------
    template : Template
        The tracking template.
    R, root : (J, 3, 3) and (3,) float64
        The first frame's pose (the warm start of the pose estimates).
    exclude_trials : tuple of str
        Pose-library trials the limb hypotheses leave out
        (:func:`~meshmocap.estimate.pose.first_pose.library_poses`).
    rule : LostRule, optional
        The rule that flags limbs lost from each frame's evidence
        (:func:`~meshmocap.estimate.recovery.evidence.lost_limbs`; default: the shipped one).
    """

    def __init__(
        self,
        template: Template,
        R: np.ndarray,
        root: np.ndarray,
        *,
        exclude_trials: tuple[str, ...] = (),
        rule: LostRule | None = None,
    ):
        self.template = template
        #: the rule that flags a limb lost from the frame's evidence (default: shipped)
        self.rule = rule
        self.exclude_trials = tuple(exclude_trials)
        #: joint positions (J, 3) of the poses of the last frames assessed, oldest first
        self.history: list[np.ndarray] = []
        self.labels = limb_labels(template)
        self.R, self.root = np.array(R, dtype=np.float64), np.array(root, dtype=np.float64)
        self.cooldown = 0
        sk = template.skeleton
        #: each limb's joints (an arm's from the clavicle), their rotations when the limb was
        #: last seen, and the limbs the observations miss now
        self.limb_joints = {
            n: np.array([sk.index(j) for j in (*LIMB_ROOTS.get(n, ()), *js) if j in sk.names])
            for n, (js, _) in LIMBS.items()
        }
        self.held: np.ndarray | None = None
        #: the last frame's quality with ``lost`` the limbs the re-seating acts on (past the
        #: fit quality's own thresholds, or missed), whatever the calibrated flag says
        self.suspect: FitQuality | None = None
        self._model = articulated_model(template, n_points=POSE_POINTS, seed=0)
        limbs = [k for k, n in enumerate(LIMB_PARTS) if n in self.limb_joints]
        self._limb_vertices = np.flatnonzero(np.isin(self.labels, limbs))
        self.missing: set[str] = set()
        self.fits_well: dict[str, int] = {}

    def _inputs(self, frame):
        obs = observed(frame)
        P, _ = obs.points
        field = obs.field
        masks = obs.silhouettes if obs.cameras else None
        return obs, P, field, obs.cameras, masks

    def check(self, frame, V: np.ndarray) -> FitQuality:
        """The fit quality of the tracked vertices ``V`` (n, 3) on ``frame``."""
        _, P, field, cameras, masks = self._inputs(frame)
        return fit_quality(
            V,
            self.labels,
            P,
            field,
            F=self.template.F,
            cameras=cameras,
            masks=masks,
            seed=int(frame.index),
            sdf=_signed_distance(field, V),
        )

    def assess(
        self, frame, V: np.ndarray, *, start: tuple[np.ndarray, np.ndarray] | None = None
    ) -> FitQuality:
        """The fit quality of ``V`` on ``frame`` (:meth:`check`), with each limb also posed
        as when last seen (its joints' rotations then, on the trunk tracked now) and
        checked against the observations. A limb is missed (``unseen``, lost however well
        the tracked mesh fits) when, posed as last seen, it stands outside the observations
        while the tracked limb has jumped away from there (the tracker put it where the
        observations have something else); it is seen again when, posed as last seen, it is
        inside them again or the tracked limb is back there. Updates the pose estimate
        (:meth:`track_pose`, from ``start`` where given)."""
        q = self.check(frame, V)
        R, root = self.track_pose(V, start)
        if self.held is None:  # the first frame checked: every limb as tracked
            self.held = R.copy()
        Vc = self.template.pose(self.coast_pose(R), root).V
        out = np.zeros(len(Vc), dtype=bool)  # only the limbs' vertices are looked at
        out[self._limb_vertices] = (
            _signed_distance(observed(frame).field, Vc[self._limb_vertices]) > UNSEEN_MARGIN
        )
        unseen = {n: v for n, v in limb_shares(self.labels, out).items() if n in self.limb_joints}
        moved = self._limb_moves(V, Vc)
        for n, v in unseen.items():  # hysteresis: missed until clearly seen again
            good = q.outside[n] < OUTSIDE_LOST / 2 and q.unexplained[n] < UNEXPLAINED_LOST / 2
            # frames in a row a missed limb, as tracked, has fitted the observations well
            self.fits_well[n] = self.fits_well.get(n, 0) + 1 if good and n in self.missing else 0
            if self.fits_well[n] > SEEN_AGAIN:  # the observations follow it where it is
                self.missing.discard(n)
            elif v > UNSEEN_LOST and moved[n] > JUMP:
                self.missing.add(n)
            elif v < UNSEEN_LOST / 2 or moved[n] < JUMP / 2:
                self.missing.discard(n)
        # the limbs held as last seen: past the fit quality's own thresholds, or missed
        held = tuple(n for n in LIMB_PARTS if n in q.lost or n in self.missing)
        self.suspect = replace(q, lost=held)
        joints = forward_kinematics(self.template.skeleton, R, root)[1]
        evidence = self._evidence(q, V, R, root, joints)
        self.history = [*self.history[-2:], joints]
        for n, idx in self.limb_joints.items():
            if n not in held:
                self.held[idx] = R[idx]
        lost = lost_limbs(evidence, self.rule)
        reasons = lost_reasons(evidence, self.rule)
        return replace(
            q,
            lost=lost,
            unseen={n: float(n in self.missing) for n in unseen},
            evidence=evidence,
            reasons=reasons,
        )

    def _evidence(self, q: FitQuality, V, R, root, joints) -> np.ndarray:
        """(L, E) the frame's evidence (:data:`~meshmocap.estimate.recovery.evidence.EVIDENCE`,
        limbs in :data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS` order): the fit
        quality ``q``, the limbs missed, the RMS distance of the tracked vertices ``V`` from
        the articulated pose ``(R, root)`` fitted to them, and each limb's joints' motion
        relative to the pelvis since the last frame assessed (0 on the first)."""
        n = len(LIMB_PARTS)
        on = self.labels >= 0
        d2 = np.sum((V - self.template.pose(R, root).V) ** 2, axis=1)
        counts = np.maximum(np.bincount(self.labels[on], minlength=n), 1)
        residual = np.sqrt(np.bincount(self.labels[on], d2[on], minlength=n) / counts)
        speed = np.zeros(n)
        if self.history:
            move = np.linalg.norm(
                (joints - joints[0]) - (self.history[-1] - self.history[-1][0]), axis=1
            )
            for k, name in enumerate(LIMB_PARTS):
                idx = self.limb_joints.get(name)
                if idx is not None and len(idx):
                    speed[k] = move[idx].max()
        cols = {
            "outside": [q.outside[m] for m in LIMB_PARTS],
            "buried": [q.buried[m] for m in LIMB_PARTS],
            "unexplained": [q.unexplained[m] for m in LIMB_PARTS],
            "unseen": [float(m in self.missing) for m in LIMB_PARTS],
            "residual": residual,
            "speed": speed,
        }
        return np.column_stack([np.asarray(cols[e], dtype=np.float64) for e in EVIDENCE])

    def coast_pose(self, R: np.ndarray | None = None) -> np.ndarray:
        """Local rotations (J, 3, 3): ``R`` (default: the pose estimate) with each limb's
        joints as when the limb was last seen (its missed limbs held, the others as of the
        last frame)."""
        coast = (self.R if R is None else R).copy()
        if self.held is not None:
            for idx in self.limb_joints.values():
                coast[idx] = self.held[idx]
        return coast

    def _limb_moves(self, V: np.ndarray, W: np.ndarray) -> dict[str, float]:
        """Per limb, the mean distance (metres) between its vertices in ``V`` and ``W``."""
        d = np.linalg.norm(V - W, axis=1)
        n = len(LIMB_PARTS)
        on = self.labels >= 0
        mean = np.bincount(self.labels[on], d[on], minlength=n) / np.maximum(
            np.bincount(self.labels[on], minlength=n), 1
        )
        return {name: float(mean[k]) for k, name in enumerate(LIMB_PARTS)}

    def motion_cost(self, R: np.ndarray, root: np.ndarray, limb: str) -> float:
        """Ranking-key metres for ``limb`` of the pose ``(R, root)`` standing away from
        where its recent motion puts it (:data:`MOTION_WEIGHT`; 0 without two earlier
        frames)."""
        if len(self.history) < 3:
            return 0.0
        idx = self.limb_joints[limb]
        a, b = self.history[-3][idx], self.history[-2][idx]
        P = forward_kinematics(self.template.skeleton, R, root)[1][idx]
        rms = float(np.sqrt(np.mean(np.sum((P - (2 * b - a)) ** 2, axis=1))))
        return MOTION_WEIGHT * min(rms, MOTION_REACH)

    def track_pose(
        self, V: np.ndarray, start: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The articulated pose of the tracked vertices ``V``, warm-started from ``start``
        (the tracker's own pose of this frame, where it has one on the same skeleton) or
        else the last frame's (:data:`POSE_STEPS`, :data:`POSE_TOL`)."""
        R, root = (self.R, self.root) if start is None else start
        self.R, self.root = pose_of_vertices(
            self.template,
            V,
            R,
            root,
            iterations=POSE_STEPS,
            n_points=POSE_POINTS,
            tol=POSE_TOL,
            model=self._model,
        )
        return self.R, self.root

    def reinitialise(self, frame, V: np.ndarray, quality: FitQuality) -> Reinit | None:
        """A better pose for ``frame`` than the tracked vertices ``V``, or None (module
        docstring); None too while cooling down after a fruitless search."""
        if self.cooldown > 0:
            self.cooldown -= 1
            return None
        obs, _, field, cameras, masks = self._inputs(frame)
        t = self.template
        R, root = self.R, self.root  # the tracked mesh's pose (assess)
        if all(n in self.missing and n not in _evidence(quality) for n in quality.lost):
            return None  # only limbs the observations miss: nothing to fit them to
        Pn, Nn = subsample_points(*obs.points, 2000, int(frame.index))
        fitter = PoseFitter(t, Pn, Nn, n_model_points=500, field=field, seed=0)
        key = ranking_key(t, cameras, masks)
        best = PoseFit(R, root, fitter.score(R, root))
        k_best, changed = key(best), []
        if quality.outside.get("torso", 0.0) > TORSO_OUT:
            # the body itself stands outside the observations (leaving the cameras' view,
            # a truncated hull): a whole-body search there re-seated runs far off, so
            # nothing is re-seated on such evidence
            self.cooldown = COOLDOWN
            return None
        P = obs.points[0]
        h = obs.hull
        scorer = FrameScorer(h.occupancy, h.origin, h.voxel_size, P, cameras=cameras, masks=masks)
        poses = library_poses(t, exclude_trials=self.exclude_trials)
        for limb in [n for n in LIMBS if n in _evidence(quality)]:
            idx = limb_joint_indices(t, limb)
            starts = library_limb_candidates(
                t, poses, scorer, best.R, best.root, limb, n_best=LIMB_HYPOTHESES
            )
            fits = [
                fitter.fit(
                    c.R,
                    best.root,
                    iterations=8,
                    max_distance=(0.2, 0.05),
                    joints=idx,
                    move_root=False,
                    lambda_pose=0.0,
                )
                for c in [best, *starts]  # the limb as tracked, fitted alike: fair
            ]
            cost = [key(f) + self.motion_cost(f.R, f.root, limb) for f in fits]
            i = int(np.argmin(cost))
            if i > 0 and cost[0] - cost[i] > MIN_GAIN:
                best, k_best = fits[i], key(fits[i])
                changed.append(limb)
        if not changed:
            self.cooldown = COOLDOWN
            return None
        fit = fitter.fit(
            best.R, best.root, iterations=8, max_distance=(0.1, 0.03), lambda_pose=1e-3
        )
        if key(fit) < k_best:
            best = fit
        q = self.check(frame, t.pose(best.R, best.root).V)
        better = len(q.lost) < len(quality.lost) or (
            len(q.lost) == len(quality.lost) and q.total_unexplained < quality.total_unexplained
        )
        if not better:
            self.cooldown = COOLDOWN
            return None
        self.R, self.root = best.R.copy(), best.root.copy()
        for n in changed:
            if n in self.limb_joints and self.held is not None:
                self.held[self.limb_joints[n]] = best.R[self.limb_joints[n]]
                self.missing.discard(n)
        return Reinit(best.R, best.root, tuple(changed), q)


def _signed_distance(field, V: np.ndarray) -> np.ndarray:
    """(n,) the signed distance of the observed solid at ``V`` (n, 3), metres: at the points
    themselves where the field offers it (a frame's lazy field: one query per vertex instead
    of every new cell's corners), else looked up."""
    at = getattr(field, "at_points", None)
    return at(V) if at is not None else field(V)


def _evidence(q: FitQuality) -> set[str]:
    """Limbs lost for what the observations show (outside, buried or unexplained), not only
    because they miss the limb."""
    return {
        n
        for n in q.lost
        if q.outside[n] > OUTSIDE_LOST
        or q.buried[n] > BURIED_LOST
        or q.unexplained[n] > UNEXPLAINED_LOST
    }
