"""Loss detection during tracking: :class:`Recovery`.

After every frame, :class:`Recovery` scores the tracked mesh against the frame's
observations (:func:`~meshmocap.estimate.recovery.quality.fit_quality`), estimates the
tracked mesh's pose in the articulated model
(:func:`~meshmocap.estimate.pose.fit.pose_of_vertices`, warm-started from the tracker's
own pose or the last frame's), follows each limb as last seen to tell a limb the
observations miss, and gathers the frame's evidence, from which the lost rule
(:mod:`meshmocap.estimate.recovery.evidence`) flags limbs ``lost``. It only scores: the
track is left as the tracker made it (a limb-only re-seat that acted on these flags made
every benchmarked case worse and was removed; a whole-body search re-seats the tracker
where one is made, ``Tracker.reseat``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from meshmocap.body.articulated import articulated_model
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.template import Template
from meshmocap.estimate.pose.fit import pose_of_vertices
from meshmocap.estimate.recovery.evidence import EVIDENCE, LostRule, lost_limbs, lost_reasons
from meshmocap.estimate.recovery.limbs import LIMB_ROOTS, LIMBS
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.quality import (
    BURIED_DEPTH,
    LIMB_PARTS,
    OUTSIDE_LOST,
    OUTSIDE_MARGIN,
    UNEXPLAINED_LOST,
    UNSEEN_LOST,
    UNSEEN_MARGIN,
    FitQuality,
    fit_quality,
    limb_labels,
    limb_shares,
)

__all__ = ["JUMP", "Recovery"]

#: Vertices the pose of the tracked mesh is fitted to (:meth:`Recovery.track_pose`).
POSE_POINTS = 600
#: Steps of that fit at most: warm-started from the last frame's pose it is within a
#: fraction of a millimetre (joint positions) of where more steps take it after three.
POSE_STEPS = 3
#: Radians (and metres of root) of a step below which that fit stops earlier.
POSE_TOL = 2e-3
#: Metres a tracked limb must stand from where it was last seen (mean over its vertices)
#: to count as having jumped away from observations that no longer show it.
JUMP = 0.08
#: Consecutive frames a missed limb, as tracked, must fit the observations well (few of its
#: vertices outside them, few unexplained points near it) to count as seen again where it
#: is now: a fast limb that the observations follow is not held as lost.
SEEN_AGAIN = 3


class Recovery:
    """Fit-quality checks and the lost flag for one tracking run (module docstring).

    Parameters
    ----------
    template : Template
        The tracking template.
    R, root : (J, 3, 3) and (3,) float64
        The first frame's pose (the warm start of the pose estimates).
    rule : LostRule, optional
        The rule that flags limbs lost from each frame's evidence
        (:func:`~meshmocap.estimate.recovery.evidence.lost_limbs`; default: the shipped one).
    assessed : bool
        ``(R, root)`` is the pose of a frame already assessed (a resumed run): the next
        frame's motion (the ``speed`` evidence) is measured from it, as in the run that
        assessed it; otherwise the first frame assessed has no motion.
    before : sequence of (L, E) float64
        The evidence of the frames assessed just before (a resumed run: as stored with
        them, oldest first), which a rule held over frames reads with the next frame's
        (:attr:`~meshmocap.estimate.recovery.evidence.LostRule.frames`).
    """

    def __init__(
        self,
        template: Template,
        R: np.ndarray,
        root: np.ndarray,
        *,
        rule: LostRule | None = None,
        assessed: bool = False,
        before: Sequence[np.ndarray] = (),
    ):
        self.template = template
        #: the rule that flags a limb lost from the frame's evidence (default: shipped)
        self.rule = rule
        self.labels = limb_labels(template)
        self.R, self.root = np.array(R, dtype=np.float64), np.array(root, dtype=np.float64)
        #: joint positions (J, 3) of the poses of the last frames assessed, oldest first
        self.history: list[np.ndarray] = (
            [forward_kinematics(template.skeleton, self.R, self.root)[1]] if assessed else []
        )
        sk = template.skeleton
        #: each limb's joints (an arm's from the clavicle), their rotations when the limb was
        #: last seen, and the limbs the observations miss now
        self.limb_joints = {
            n: np.array([sk.index(j) for j in (*LIMB_ROOTS.get(n, ()), *js) if j in sk.names])
            for n, (js, _) in LIMBS.items()
        }
        self.held: np.ndarray | None = None
        self._model = articulated_model(template, n_points=POSE_POINTS, seed=0)
        limbs = [k for k, n in enumerate(LIMB_PARTS) if n in self.limb_joints]
        self._limb_vertices = np.flatnonzero(np.isin(self.labels, limbs))
        self.missing: set[str] = set()
        self.fits_well: dict[str, int] = {}
        #: the last frame's quality as :meth:`assess` returned it (``lost``: the rule's)
        self.quality: FitQuality | None = None
        #: the evidence of the last frames assessed, oldest first (a few)
        self.recent: list[np.ndarray] = [np.asarray(e, dtype=np.float64) for e in before][-4:]

    def _inputs(self, frame):
        obs = observed(frame)
        P = obs.surface  # the points alone: their normals are not needed here
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
            sides=_sides(field, V, -BURIED_DEPTH, OUTSIDE_MARGIN),
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
        # posed as last seen (Vc) and in the pose fitted (W, its joints), skinned in one pass
        both = self.template.pose(np.stack([self.coast_pose(R), R]), np.stack([root, root]))
        (Vc, W), joints = both.V, both.joints[1]
        out = np.zeros(len(Vc), dtype=bool)  # only the limbs' vertices are looked at
        out[self._limb_vertices] = (
            _sides(observed(frame).field, Vc[self._limb_vertices], -np.inf, UNSEEN_MARGIN) > 0
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
        evidence = self._evidence(q, V, W, joints)
        self.history = [*self.history[-2:], joints]
        for n, idx in self.limb_joints.items():
            if n not in held:
                self.held[idx] = R[idx]
        lost = lost_limbs(evidence, self.rule, before=self.recent)
        reasons = lost_reasons(evidence, self.rule, before=self.recent)
        self.recent = [*self.recent[-3:], evidence]
        self.quality = replace(
            q,
            lost=lost,
            unseen={n: float(n in self.missing) for n in unseen},
            evidence=evidence,
            reasons=reasons,
        )
        return self.quality

    def _evidence(self, q: FitQuality, V, W, joints) -> np.ndarray:
        """(L, E) the frame's evidence (:data:`~meshmocap.estimate.recovery.evidence.EVIDENCE`,
        limbs in :data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS` order): the fit
        quality ``q``, the limbs missed, the RMS distance of the tracked vertices ``V`` from
        ``W``, the template in the articulated pose fitted to them (its joints ``joints``),
        and each limb's joints' motion relative to the pelvis since the last frame assessed
        (0 on the first)."""
        n = len(LIMB_PARTS)
        on = self.labels >= 0
        d2 = np.sum((V - W) ** 2, axis=1)
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


def _sides(field, V: np.ndarray, below: float, above: float) -> np.ndarray:
    """(n,) int8: where the signed distance of the observed solid at ``V`` (n, 3) lies,
    metres: +1 above ``above``, −1 below ``below``, 0 between. A frame's lazy field tells
    it from as few voxels around each vertex as the answer needs (the answers of its
    distance at the points themselves, ``at_points``); another field is looked up."""
    side = getattr(field, "side_of", None)
    if side is not None:
        return side(V, below, above)
    sd = field(V)
    return np.where(sd > above, 1, np.where(sd < below, -1, 0)).astype(np.int8)
