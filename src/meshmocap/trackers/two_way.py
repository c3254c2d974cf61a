"""The two-way pass: after the forward pass over a capture on disk, the frames it flagged
``lost`` are tracked again from whole-body searches at keyframes inside and after each run,
backward and forward, and per frame the hypothesis the evidence prefers is kept.

1. **Runs.** Runs of frames the forward pass flagged ``lost`` (in the track's frame order;
   runs closer than :data:`MERGE_GAP` frames are one run; runs shorter than
   :data:`MIN_RUN` frames are left as they are).
2. **Keyframes.** For each run, whole-body searches (:func:`keyframe_search`, for the
   limbs lost anywhere in the run, the torso where lost at the keyframe: the forward
   track may still be off where it is no longer flagged) at the first frame after the
   run, then at the middle of the longest stretch of the run that no kept hypothesis
   explains yet (passes the lost rule within :data:`EXPLAINS` frames of its keyframe,
   clearly on the run's lost limbs: :data:`CLEAR`), until every stretch is explained or
   :func:`max_keyframes` are kept. A
   keyframe is kept only where the tracker seated at the found pose passes the lost rule
   on that frame (:meth:`~meshmocap.estimate.recovery.reinit.Recovery.assess`, the same
   rule as the forward pass's flags).
3. **Hypotheses.** From each kept keyframe the same tracker (the forward pass's state at
   that frame, re-seated at the found pose, :meth:`~meshmocap.trackers.base.Tracker.reseat`)
   tracks backward past the run's first frame and forward past its last, each frame scored
   by its own :class:`~meshmocap.estimate.recovery.reinit.Recovery`. Past the run it goes
   on at least :data:`MARGIN` frames and until it meets the forward track (mean joint
   distance under :data:`MEET`), at most :data:`REACH` frames and never into the next
   run's frames: the forward track often drifts off some frames before it is flagged, and
   the choice switches where the two agree. A hypothesis stops early once it has been lost
   itself for :data:`STOP_LOST` frames in a row.
4. **Choice.** Per frame, the forward track or a hypothesis: dynamic programming over the
   frames (:func:`choose`) of the evidence's cost (:func:`evidence_cost`: limbs lost, then
   how far the fit is off the observations) plus a cost per switch that grows with the
   distance between the two poses at the switch (the choice switches where they agree);
   before the run the forward track costs :data:`DRIFT` more (it often drifts off before it
   is flagged). Then each limb (arms, legs) is chosen the same way on its own evidence
   (:func:`limb_costs`, a limb charged where the rule names it lost, the switch priced by
   the limb's joints), a track other than the frame's costing :data:`GRAFT` more a frame:
   two tracks that each lost a different limb give one frame with neither lost. Where a
   limb's choice differs from the frame's, the limb is grafted onto the frame's trunk
   (:func:`~meshmocap.estimate.recovery.limbs.graft_limbs`: its world rotations from its
   track, hung at the frame's shoulder or hip); elsewhere the chosen track's vertices,
   joints and state as tracked.
5. **Result.** The chosen frames are written into the track folder (the forward pass's
   frame kept in ``two_way/forward/``), the flags of every frame of the run's span
   recomputed by the same rule on the result, a chosen frame flagged ``lost`` too where the
   other tracks that the evidence does not rule out disagree with it on a limb by more than
   the rule's disagreement thresholds
   (:func:`ambiguous_limbs`, :attr:`~meshmocap.estimate.recovery.evidence.LostRule.disagree`:
   a limb wrong inside the visual hull passes every measure; the disagreement is what shows
   it), and ``track.json`` records the pass
   (``"two_way"``: the runs, each keyframe and whether it was kept, which frames changed,
   from which keyframe and direction, the limbs the forward pass had lost there, each limb
   grafted from another track, the frames flagged ambiguous, and each chosen frame's
   disagreement). Where
   no keyframe is kept, the frames stay as they were, flagged.

Everything the pass makes is kept under ``TRACK/two_way/`` (keyframe searches in
``keys/``, each hypothesis track in ``kNNNNN-backward/`` or ``kNNNNN-forward/``, written
frame by frame atomically), so a pass killed midway resumes where it stopped: a finished
search or hypothesis is read back, an unfinished hypothesis is tracked again.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from meshmocap._atomic import atomic_open, write_text_atomic
from meshmocap._npz import read_npz
from meshmocap._progress import phase
from meshmocap.body.light import TrackingBody
from meshmocap.estimate.pose.first_pose import InitResult
from meshmocap.estimate.pose.hold import SkeletonHold
from meshmocap.estimate.pose.keyframe import keyframe_pose
from meshmocap.estimate.recovery.evidence import (
    DISAGREEMENT,
    EVIDENCE,
    LostRule,
    lost_limbs,
    shipped_rule,
)
from meshmocap.estimate.recovery.limbs import LIMBS, graft_limbs
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.quality import LIMB_PARTS
from meshmocap.estimate.recovery.reinit import Recovery
from meshmocap.geometry.refine import SurfaceRefiner
from meshmocap.io.results import (
    TWO_WAY_FOLDER,
    FrameResult,
    frame_path,
    read_two_way,
    write_frame,
    write_two_way,
)
from meshmocap.trackers.base import Tracker
from meshmocap.trackers.frame_step import read_track_frame, recovered, track_frame

__all__ = [
    "CLEAR",
    "DRIFT",
    "EXPLAINS",
    "FIT_WEIGHT",
    "FOLDER",
    "FRAMES_PER_KEY",
    "GRAFT",
    "MARGIN",
    "MEET",
    "MERGE_GAP",
    "MIN_RUN",
    "PREFER_FORWARD",
    "REACH",
    "STOP_LOST",
    "SWITCH",
    "SWITCH_PER_METRE",
    "TwoWay",
    "ambiguous_limbs",
    "choose",
    "choose_limbs",
    "clearly_passes",
    "evidence_cost",
    "fit_margin",
    "flagged_runs",
    "keyframe_search",
    "limb_costs",
    "max_keyframes",
    "two_way_pass",
]

#: Flagged runs this many frames apart or closer are one run.
MERGE_GAP = 3
#: Runs of fewer flagged frames are left as the forward pass made them.
MIN_RUN = 3
#: Frames a hypothesis tracks past its run at each end at least.
MARGIN = 4
#: Frames a hypothesis tracks past its run at each end at most, until it meets the
#: forward track.
REACH = 24
#: Metres of mean joint distance under which a hypothesis meets the forward track (past
#: the run, it stops there: the choice can switch back).
MEET = 0.02
#: A hypothesis stops once it has been lost itself for this many frames in a row.
STOP_LOST = 6
#: Cost of a switch between two tracks (in lost limbs), plus :data:`SWITCH_PER_METRE`
#: per metre of mean joint distance between them at the switch.
SWITCH = 0.5
#: Cost of a switch per metre of mean joint distance between the two tracks at the switch.
SWITCH_PER_METRE = 10.0
#: Cost per frame of a hypothesis over the forward track (the forward track wins ties).
PREFER_FORWARD = 0.05
#: Cost per frame of the forward track over a hypothesis on the frames before its run (a
#: forward track drifts off some frames before the rule flags it: where the evidence ties,
#: the hypothesis tracked back from a keyframe that passes is kept).
DRIFT = 0.1
#: Weight of the fit's continuous evidence (the largest share of a limb outside, buried or
#: unexplained, in units of its threshold, at most 1 per limb) next to the lost limbs.
FIT_WEIGHT = 0.1
#: Cost per frame and limb of taking the limb from a track other than the frame's (ties stay
#: with the frame's track).
GRAFT = 0.05
#: Frames from its keyframe within which a hypothesis that passes the lost rule explains a
#: frame of its run: frames of a long run farther from every kept keyframe get another
#: keyframe (a hypothesis far from its keyframe may pass the rule with a limb wrong).
EXPLAINS = 12
#: A hypothesis explains a frame of its run only where, on the limbs lost in the run, its
#: fit measures (outside, buried, unexplained) stay under this share of their thresholds
#: (the recovery's own "fits well", :meth:`~meshmocap.estimate.recovery.reinit.Recovery.assess`):
#: a hypothesis drifting off a fast limb passes the rule barely before it fails it, and
#: such frames get a keyframe of their own.
CLEAR = 0.5
#: Frames of a run per kept keyframe (:func:`max_keyframes`).
FRAMES_PER_KEY = 50
#: The folder of the pass's intermediate results, inside the track folder.
FOLDER = TWO_WAY_FOLDER


@dataclass(frozen=True)
class TwoWay:
    """What the two-way pass did (also in ``track.json``'s ``"two_way"``).

    Attributes
    ----------
    runs : tuple of (int, int), first and last frame of each run of flagged frames worked on
    keyframes : tuple of dict, each searched keyframe: ``frame``, ``run`` (its first frame),
        ``kept`` (bool), ``label`` (the search's winner), ``lost`` (limbs the lost rule
        found on it, where not kept)
    changed : tuple of dict, each stretch of frames replaced: ``frames`` (first, last),
        ``keyframe``, ``direction`` (``"backward"`` or ``"forward"``), ``limbs`` (those the
        forward pass had flagged lost there; the whole frame is replaced)
    grafted : tuple of dict, each stretch of frames where a limb was taken from another
        track than the frame's: ``frames`` (first, last), ``limb``, ``track``
        (``"forward"`` or ``"keyframe K backward|forward"``)
    ambiguous : tuple of dict, each frame flagged ``lost`` because the tracks disagree
        there (:func:`ambiguous_limbs`): ``frame``, ``limbs``, ``mm`` (the largest
        disagreement), ``track`` (``"forward"`` or ``"keyframe K backward|forward"``, the
        track that disagrees most)
    disagreement : tuple of dict, each chosen frame that has other tracks: ``frame`` and,
        in mm, its disagreement measures
        (:data:`~meshmocap.estimate.recovery.evidence.DISAGREEMENT`: ``forward``,
        ``keyframe``), what :attr:`~meshmocap.estimate.recovery.evidence.LostRule.disagree`
        is fitted to
    flagged : (int, int), frames flagged ``lost`` before and after the pass
    seconds : float, wall time of the pass
    """

    runs: tuple[tuple[int, int], ...] = ()
    keyframes: tuple[dict, ...] = ()
    changed: tuple[dict, ...] = ()
    grafted: tuple[dict, ...] = ()
    ambiguous: tuple[dict, ...] = ()
    disagreement: tuple[dict, ...] = ()
    flagged: tuple[int, int] = (0, 0)
    seconds: float = 0.0

    def as_json(self) -> dict:
        """JSON-ready, with ``"complete": true``."""
        return {
            "runs": [list(r) for r in self.runs],
            "keyframes": list(self.keyframes),
            "changed": list(self.changed),
            "grafted": list(self.grafted),
            "ambiguous": list(self.ambiguous),
            "disagreement": list(self.disagreement),
            "flagged": list(self.flagged),
            "seconds": round(float(self.seconds), 3),
            "complete": True,
        }

    def describe(self) -> str:
        """One line: runs, keyframes kept, frames changed, flags before → after."""
        n = sum(c["frames"][1] - c["frames"][0] + 1 for c in self.changed)
        kept = sum(bool(k["kept"]) for k in self.keyframes)
        return (
            f"two-way pass: {len(self.runs)} lost runs, {kept} of {len(self.keyframes)} "
            f"keyframes kept, {n} frames changed, {len(self.grafted)} limb stretches grafted, "
            f"{len(self.ambiguous)} flagged ambiguous, "
            f"frames flagged lost {self.flagged[0]} → {self.flagged[1]} ({self.seconds:.0f} s)"
        )


def keyframe_search(
    template,
    frame,
    *,
    near: tuple[np.ndarray, np.ndarray] | None = None,
    lost: tuple[str, ...] = (),
    exclude_trials: tuple[str, ...] = (),
) -> InitResult:
    """The whole-body pose of ``frame`` found from the frame alone (the pass's one call of a
    search): ``template`` the full body; ``near`` the tracked pose ``(R (J, 3, 3), root
    (3,))`` at that frame and ``lost`` its lost limbs (hints a search may use);
    ``exclude_trials`` pose-library trials left out
    (:func:`~meshmocap.estimate.pose.keyframe.keyframe_pose`)."""
    return keyframe_pose(template, frame, near=near, lost=lost, exclude_trials=exclude_trials)


def flagged_runs(
    flagged: Sequence[bool], *, merge_gap: int = MERGE_GAP, min_run: int = MIN_RUN
) -> list[tuple[int, int]]:
    """Runs ``(first, last)`` (positions, inclusive) of True in ``flagged`` (T,), runs at
    most ``merge_gap`` positions apart merged, runs shorter than ``min_run`` dropped."""
    f = np.asarray(flagged, dtype=bool)
    d = np.diff(np.concatenate([[0], f.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    runs: list[list[int]] = []
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        if runs and a - runs[-1][1] - 1 <= merge_gap:
            runs[-1][1] = b
        else:
            runs.append([a, b])
    return [(a, b) for a, b in runs if b - a + 1 >= min_run]


def max_keyframes(length: int) -> int:
    """Keyframes kept at most for a run of ``length`` frames: one after it, one per
    :data:`FRAMES_PER_KEY` frames of it (at least one), and one more for a stretch that
    the others' hypotheses explain only barely (:data:`CLEAR`)."""
    return 2 + max(1, -(-int(length) // FRAMES_PER_KEY))


def fit_margin(evidence: np.ndarray, rule: LostRule | None = None) -> np.ndarray:
    """(..., L) float64: per limb of ``evidence`` (..., L, E) its largest fit measure
    (outside, buried, unexplained) in units of ``rule``'s threshold (0 for a measure that
    never flags): 1 and above, the rule finds the limb lost on it."""
    rule = rule or shipped_rule()
    th = np.asarray(rule.thresholds, dtype=np.float64)
    e = np.asarray(evidence, dtype=np.float64)
    fit = [EVIDENCE.index(m) for m in ("outside", "buried", "unexplained")]
    finite = np.isfinite(th[fit])
    return np.where(finite, e[..., fit] / np.where(finite, th[fit], 1.0), 0.0).max(axis=-1)


def clearly_passes(
    evidence: np.ndarray, limbs: Sequence[str], rule: LostRule | None = None
) -> bool:
    """Whether the frame of ``evidence`` (L, E) fits the observations clearly on ``limbs``
    (:data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS` keys): each one's fit
    measures under :data:`CLEAR` of ``rule``'s thresholds (:func:`fit_margin`); True
    without limbs."""
    k = [list(LIMB_PARTS).index(n) for n in limbs]
    return bool(np.all(fit_margin(evidence, rule)[k] < CLEAR))


def limb_costs(
    evidence: np.ndarray, rule: LostRule | None = None, *, named: bool = False
) -> np.ndarray:
    """(..., L) float64: per limb the terms of :func:`evidence_cost` (1 where ``rule`` finds
    the limb lost, plus :data:`FIT_WEIGHT` times its largest fit measure in units of its
    threshold, at most 1) of ``evidence`` (..., L, E). With ``named``, a limb is lost where
    the rule names it (:meth:`~meshmocap.estimate.recovery.evidence.LostRule.named`: the
    points another limb leaves unexplained charged to that limb)."""
    rule = rule or shipped_rule()
    e = np.asarray(evidence, dtype=np.float64)
    lost = rule.named(e) if named else rule.limb_lost(e)
    return lost + FIT_WEIGHT * np.minimum(fit_margin(e, rule), 1.0)


def evidence_cost(evidence: np.ndarray, rule: LostRule | None = None) -> np.ndarray:
    """(...) float64: the cost of frames of ``evidence`` (..., L, E)
    (:data:`~meshmocap.estimate.recovery.evidence.EVIDENCE`): the number of limbs
    ``rule`` finds lost, plus :data:`FIT_WEIGHT` times the sum over limbs of the largest
    fit measure (outside, buried, unexplained) in units of its threshold (at most 1 each):
    fewer lost limbs first, then the closer fit (:func:`limb_costs` summed over limbs)."""
    return limb_costs(evidence, rule).sum(axis=-1)


def choose(
    cost: np.ndarray,
    joints: np.ndarray,
    *,
    switch: float = SWITCH,
    per_metre: float = SWITCH_PER_METRE,
    start: int | None = None,
    end: int | None = None,
) -> np.ndarray:
    """The track chosen per frame: the path through ``cost`` of least total cost plus, per
    switch from track ``h`` to ``g`` at frame ``t``, ``switch + per_metre ·`` the mean
    distance between their joints at ``t`` (dynamic programming over the frames).

    Parameters
    ----------
    cost : (T, H) float64, each track's cost per frame (``inf`` where it has no frame)
    joints : (T, H, K, 3) float64, metres, each track's joints (anything where absent)
    start, end : int, optional, the track the path must begin (end) on

    Returns
    -------
    (T,) int64, the chosen track per frame
    """
    c = np.asarray(cost, dtype=np.float64)
    T, H = c.shape
    J = np.nan_to_num(np.asarray(joints, dtype=np.float64))
    # (T, H, H) mean joint distance between every pair of tracks per frame
    D = np.linalg.norm(J[:, :, None] - J[:, None, :], axis=-1).mean(axis=-1)
    step = switch + per_metre * D
    step[:, np.arange(H), np.arange(H)] = 0.0
    acc = c[0].copy()
    if start is not None:
        acc[np.arange(H) != start] = np.inf
    back = np.zeros((T, H), dtype=np.int64)
    for t in range(1, T):  # over frames (not points): T is a run's length
        total = acc[:, None] + step[t]  # from h (rows) to g (columns)
        back[t] = np.argmin(total, axis=0)
        acc = total[back[t], np.arange(H)] + c[t]
    h = int(end) if end is not None else int(np.argmin(acc))
    path = np.empty(T, dtype=np.int64)
    for t in range(T - 1, -1, -1):
        path[t] = h
        h = back[t, h]
    return path


def choose_limbs(
    cost: np.ndarray,
    joints: np.ndarray,
    path: np.ndarray,
    limb_of: np.ndarray,
    *,
    graft: float = GRAFT,
    start: int | None = None,
    end: int | None = None,
) -> dict[str, np.ndarray]:
    """Per limb (arms and legs, :data:`~meshmocap.estimate.recovery.limbs.LIMBS`) the
    track chosen per frame: :func:`choose` on that limb's costs and joints, a track other
    than the frame's (``path``) costing ``graft`` more a frame.

    Parameters
    ----------
    cost : (T, H, L) float64, each track's cost per frame and limb
        (:data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS` order; ``inf`` where the
        track has no frame)
    joints : (T, H, K, 3) float64, metres, each track's joints
    path : (T,) int, the track chosen for each whole frame
    limb_of : (K,) int, each joint's limb
    start, end : int, optional, the track each limb's path must begin (end) on

    Returns
    -------
    dict, limb name → (T,) int64, its track per frame
    """
    c = np.asarray(cost, dtype=np.float64)
    names = list(LIMB_PARTS)
    c = c + graft * (np.arange(c.shape[1])[None, :] != np.asarray(path)[:, None])[..., None]
    limb_of = np.asarray(limb_of)
    return {
        n: choose(
            c[..., names.index(n)],
            np.asarray(joints)[:, :, limb_of == names.index(n)],
            start=start,
            end=end,
        )
        for n in LIMBS
    }


def ambiguous_limbs(
    joints: np.ndarray,
    others: np.ndarray,
    frame_lost: np.ndarray,
    limb_lost: np.ndarray,
    limb_of: np.ndarray,
    *,
    forward: np.ndarray,
    rule: LostRule | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The limbs of a chosen frame that other tracks, which the evidence does not rule
    out, place elsewhere: the frame is then ambiguous (the evidence cannot tell which track
    is right, and the chosen one may be the wrong one: a limb wrong inside the visual hull
    passes every measure).

    Parameters
    ----------
    joints : (K, 3) float64, metres, the chosen frame's evaluation joints
    others : (H, K, 3) float64, metres, the other tracks' joints on that frame
    frame_lost : (H,) bool, whether the lost rule flags each other track's frame
    limb_lost : (H, L) bool, whether it finds each other track's limb lost
    limb_of : (K,) int, the limb (:data:`~meshmocap.estimate.recovery.quality.LIMB_PARTS`
        order) of each joint
    forward : (H,) bool, which of the other tracks is the forward track: it counts where
        its frame is not flagged (a flagged forward frame is what the pass replaces, its
        other limbs carry the drift that lost it); a keyframe's track counts on the limbs
        the rule passes
    rule : LostRule, optional
        Its disagreement thresholds
        (:attr:`~meshmocap.estimate.recovery.evidence.LostRule.disagree`, per measure of
        :data:`~meshmocap.estimate.recovery.evidence.DISAGREEMENT`; default the shipped
        rule's)

    Returns
    -------
    ambiguous : (L,) bool, per limb: a track that counts places it farther off than its
        measure's threshold (largest joint distance on the limb)
    distance : (L, H) float64, metres, the largest joint distance per limb and track where
        it makes the limb ambiguous (0 elsewhere)
    measures : (L, D) float64, metres, per limb the disagreement measures: the largest
        distance to a forward track and to a keyframe's track that count
    """
    rule = rule or shipped_rule()
    L = len(LIMB_PARTS)
    d = np.linalg.norm(np.asarray(others, np.float64) - joints, axis=-1)  # (H, K)
    per = np.stack([d[:, limb_of == k].max(axis=1, initial=0.0) for k in range(L)])  # (L, H)
    fw = np.asarray(forward, dtype=bool)
    counts = np.where(fw, ~np.asarray(frame_lost, dtype=bool), ~np.asarray(limb_lost, bool).T)
    per_c = np.where(counts, per, 0.0)
    measures = np.stack(
        [
            np.where(fw, per_c, 0.0).max(axis=1, initial=0.0),
            np.where(fw, 0.0, per_c).max(axis=1, initial=0.0),
        ],
        axis=1,
    )
    amb = per_c > np.where(fw, rule.disagree[0], rule.disagree[1])  # (L, H)
    return amb.any(axis=1), np.where(amb, per, 0.0), measures


# --- the pass over a track folder ------------------------------------------------------


def two_way_pass(
    tracker: Tracker,
    body: TrackingBody,
    capture,
    out: str | os.PathLike,
    *,
    frames: Sequence[int],
    refiner: SurfaceRefiner | None = None,
    hold: bool = False,
    hold_surface: bool = True,
    exclude_trials: tuple[str, ...] = (),
    rule: LostRule | None = None,
    show_progress: bool | None = None,
) -> TwoWay:
    """Run the two-way pass (module docstring) over the finished forward track in ``out``.

    Parameters
    ----------
    tracker : Tracker
        The forward pass's tracker (set up for ``body.light``; its state is changed).
    body : TrackingBody, the tracked body (searches on its template, tracking on its light)
    capture : Capture or SequenceCapture, the frames the track was made from
    out : path, the track folder
    frames : sequence of int, the positions in ``capture`` tracked, in the track's order
    refiner : SurfaceRefiner, optional, as the forward pass refined its surfaces
    hold : bool, hold each hypothesis's skeleton against the observed surface, as the
        forward pass does on a 4D capture (:class:`~meshmocap.estimate.pose.hold.SkeletonHold`)
    hold_surface : bool, the hold fits the frame before's refined surface, as the forward
        pass does on a clean 4D capture (``SkeletonHold``'s ``surface``), or the template's own
    exclude_trials : tuple of str, pose-library trials the searches leave out
    rule : LostRule, optional, the lost rule (default: the shipped one)

    Returns
    -------
    TwoWay
        What the pass did; also written to ``track.json`` (``"two_way"``). A folder whose
        pass is complete is returned as recorded.
    """
    done = read_two_way(out)
    if done is not None and done.get("complete"):
        return _of_json(done)
    t0 = time.perf_counter()
    work = Path(out) / FOLDER
    order = [int(capture.indices[k]) for k in frames]
    where = {i: k for i, k in zip(order, frames, strict=True)}
    fwd = [_forward_frame(out, i) for i in order]
    flagged = np.array(["lost" in r.flags for r in fwd])
    runs = flagged_runs(flagged)
    keys: list[dict] = []
    changed: list[dict] = []
    run = _Run(tracker, body, capture, out, work, order, where, refiner, exclude_trials, rule)
    run.hold, run.hold_surface = hold, hold_surface
    for k, (a, b) in enumerate(runs):
        # a run's hypotheses and choice stay on its side of the gaps to its neighbours
        run.floor = (runs[k - 1][1] + a) // 2 + 1 if k else 0
        run.ceiling = (b + runs[k + 1][0]) // 2 if k + 1 < len(runs) else len(order) - 1
        with phase(
            f"two-way pass: lost frames {order[a]}–{order[b]}, searching and tracking",
            enabled=show_progress,
        ):
            k, c = run.revise(fwd, a, b)
        keys += k
        changed += c
    after = sum("lost" in read_track_frame(out, i).flags for i in order)
    result = TwoWay(
        runs=tuple((order[a], order[b]) for a, b in runs),
        keyframes=tuple(keys),
        changed=tuple(changed),
        grafted=tuple(run.grafted),
        ambiguous=tuple(run.ambiguous),
        disagreement=tuple(run.disagreement),
        flagged=(int(flagged.sum()), int(after)),
        seconds=time.perf_counter() - t0,
    )
    write_two_way(out, result.as_json())
    return result


def _of_json(d: dict) -> TwoWay:
    return TwoWay(
        runs=tuple(tuple(r) for r in d.get("runs", ())),
        keyframes=tuple(d.get("keyframes", ())),
        changed=tuple(d.get("changed", ())),
        grafted=tuple(d.get("grafted", ())),
        ambiguous=tuple(d.get("ambiguous", ())),
        disagreement=tuple(d.get("disagreement", ())),
        flagged=tuple(d.get("flagged", (0, 0))),
        seconds=float(d.get("seconds", 0.0)),
    )


def _forward_frame(out, index: int) -> FrameResult:
    """Frame ``index`` as the forward pass made it (kept in ``two_way/forward/`` once the
    pass has replaced it)."""
    kept = Path(out) / FOLDER / "forward"
    if frame_path(kept, index).is_file():
        return read_track_frame(kept, index)
    return read_track_frame(out, index)


@dataclass
class _Hyp:
    """A hypothesis track: its frames by frame number (cost, joints, result)."""

    keyframe: int
    direction: str
    results: dict[int, FrameResult]


def _track_labels(hyps: list[_Hyp]) -> list[str]:
    """The names the record gives the tracks of a run: the forward track, then each
    hypothesis by its keyframe and direction."""
    return ["forward"] + [f"keyframe {y.keyframe} {y.direction}" for y in hyps]


class _Run:
    """The pass over one run at a time (:func:`two_way_pass`)."""

    def __init__(self, tracker, body, capture, out, work, order, where, refiner, excl, rule):
        self.tracker, self.body, self.capture = tracker, body, capture
        self.out, self.work = Path(out), Path(work)
        self.order, self.where = order, where
        self.refiner, self.exclude, self.rule = refiner, tuple(excl), rule
        self.hold, self.hold_surface = False, True
        self.pos = {i: p for p, i in enumerate(order)}
        self.floor, self.ceiling = 0, len(order) - 1
        self.ambiguous: list[dict] = []
        self.disagreement: list[dict] = []
        self.grafted: list[dict] = []
        self.checker: Recovery | None = None
        names = body.template.eval_skeleton.names
        self.limb_of = np.array(
            [next(k for k, v in enumerate(LIMB_PARTS.values()) if n in v) for n in names]
        )

    def frame(self, i: int):
        return self.capture[self.where[i]]

    def revise(self, fwd: list[FrameResult], a: int, b: int) -> tuple[list[dict], list[dict]]:
        """Search keyframes for the run ``a..b`` (positions in the order), track hypotheses
        from the kept ones, choose per frame and write; returns (keyframes, changed)."""
        T = len(self.order)
        lo, hi = max(a - REACH, self.floor, 0), min(b + REACH, self.ceiling, T - 1)
        hyps: list[_Hyp] = []
        keys: list[dict] = []
        tried: set[int] = set()
        explained = np.zeros(b - a + 1, dtype=bool)
        candidates = [b + 1] if b + 1 < T else []
        most = max_keyframes(b - a + 1)
        # the limbs lost anywhere in the run: searched at each of its keyframes (after the
        # run, too, where the forward track is no longer flagged but may still be off);
        # the torso only where it is lost at the keyframe itself (a lost torso drops the
        # tracked heading, and the search is then the slow one all around)
        lost = {n for q in range(a, b + 1) for n in self.lost_limbs(fwd[q])} - {"torso"}
        run_lost = tuple(n for n in LIMB_PARTS if n in lost)
        while sum(bool(k["kept"]) for k in keys) < most and len(tried) < most + 2:
            if candidates:
                p = candidates.pop()
            else:
                p = _middle_of_longest(explained, tried, a)
                if p is None:
                    break
            tried.add(p)
            key, seated = self.keyframe(fwd, p, a, run_lost)
            keys.append(key)
            if seated is None:
                continue
            past = (fwd, a - MARGIN, b + MARGIN)
            # the keyframe for a stretch barely explained (the last one kept) tracks only as
            # far as it can explain (:data:`EXPLAINS`)
            last = sum(bool(k["kept"]) for k in keys) == most
            first, stop = (max(lo, p - EXPLAINS), min(hi, p + EXPLAINS)) if last else (lo, hi)
            hyps.append(self.hypothesis(seated, p, range(p - 1, first - 1, -1), "backward", past))
            hyps.append(self.hypothesis(seated, p, range(p + 1, stop + 1), "forward", past))
            for h in hyps:
                for i, r in h.results.items():
                    k = self.pos[i] - a
                    near = abs(self.pos[i] - self.pos[h.keyframe]) <= EXPLAINS
                    if 0 <= k < len(explained) and near and self.clear(r, run_lost):
                        explained[k] = True
            if explained.all():
                break
        if not hyps:
            return keys, []
        # the choice from the frame before the hypotheses' first to the frame after their
        # last (the forward track's at both ends where there is one)
        have = [self.pos[i] for h in hyps for i in h.results]
        lo, hi = max(min(have) - 1, self.floor), min(max(have) + 1, self.ceiling)
        return keys, self.write_choice(fwd, hyps, lo, hi, first=a)

    def clear(self, r: FrameResult, limbs: tuple[str, ...]) -> bool:
        """Whether a hypothesis's frame ``r`` passes the lost rule, clearly on ``limbs``
        (:func:`clearly_passes`; a frame without recorded evidence: its flag)."""
        if "lost" in r.flags:
            return False
        ev = r.state.get("evidence")
        if ev is None or np.shape(ev) != (len(LIMB_PARTS), len(EVIDENCE)):
            return True
        return clearly_passes(ev, limbs, self.rule)

    def keyframe(
        self, fwd, p: int, a: int, run_lost: tuple[str, ...] = ()
    ) -> tuple[dict, FrameResult | None]:
        """Search frame at position ``p`` for the limbs ``run_lost`` and those lost there;
        the seated result where kept (else None). A frame the forward pass found without
        observation (``missing``) is not searched."""
        i = self.order[p]
        if "missing" in fwd[p].flags:
            return {"frame": i, "run": self.order[a], "kept": False, "label": "missing"}, None
        frame = self.frame(i)
        state = fwd[p].state
        near = (state["pose_R"], state["pose_root"]) if "pose_R" in state else None
        cached = self.work / "keys" / f"{i:05d}.npz"
        if cached.is_file():
            z = read_npz(cached, "two-way keyframe")
            R, root, label = z["R"], z["root"], str(z["label"])
        else:
            own = set(self.lost_limbs(fwd[p])) | set(run_lost)
            lost = tuple(n for n in LIMB_PARTS if n in own)
            res = keyframe_search(
                self.body.template, frame, near=near, lost=lost, exclude_trials=self.exclude
            )
            R, root, label = res.R, res.root, res.label
            cached.parent.mkdir(parents=True, exist_ok=True)
            with atomic_open(cached) as f:
                np.savez(f, R=R, root=root, label=np.str_(label))
        self.tracker.set_state(fwd[p].state)
        r = self.tracker.reseat(frame, R, root)
        recovery = Recovery(self.body.light, R, root, rule=self.rule)
        r = replace(recovered(recovery, frame, r), index=i)
        if self.refiner is not None:
            r = replace(r, vertices=self.refiner.refine(r.vertices, *observed(frame).points, key=i))
        kept = "lost" not in r.flags
        key = {"frame": i, "run": self.order[a], "kept": kept, "label": label}
        if not kept:
            key["lost"] = list(self.lost_limbs(r))
        return key, (r if kept else None)

    def hypothesis(
        self, seated: FrameResult, p: int, steps: range, direction: str, past=None
    ) -> _Hyp:
        """Track from the seated keyframe at position ``p`` over ``steps`` (positions);
        ``past`` ``(fwd, first, last)``: stop at a frame outside positions ``first..last``
        where the track meets the forward track ``fwd`` (:data:`MEET`)."""
        i0 = self.order[p]
        folder = self.work / f"k{i0:05d}-{direction}"
        marker = folder / "done.json"
        if marker.is_file():
            done = [i for i in json.loads(marker.read_text())["frames"] if i in self.pos]
            return _Hyp(i0, direction, {i: read_track_frame(folder, i) for i in done})
        if folder.exists():  # an unfinished hypothesis: tracked again
            shutil.rmtree(folder)
        (folder / "frames").mkdir(parents=True)
        write_frame(folder, seated)
        self.tracker.set_state(seated.state)
        R, root = seated.state["pose_R"], seated.state["pose_root"]
        recovery = Recovery(self.body.light, R, root, rule=self.rule)
        recovery.assess(self.frame(i0), seated.vertices)  # its history starts at the keyframe
        holder = SkeletonHold(self.body.light, surface=self.hold_surface) if self.hold else None
        if holder is not None:
            holder.last = (np.asarray(R, dtype=np.float64), np.asarray(root, dtype=np.float64))
        results: dict[int, FrameResult] = {i0: seated}
        good, lost_in_row = i0, 0
        for q in steps:
            i = self.order[q]
            r = track_frame(
                self.tracker,
                lambda i=i: self.frame(i),
                i,
                folder,
                good,
                recovery=recovery,
                refiner=self.refiner,
                holder=holder,
            )
            write_frame(folder, r)
            results[i] = r
            good = i if r.healthy else good
            lost_in_row = lost_in_row + 1 if "lost" in r.flags else 0
            if lost_in_row >= STOP_LOST:
                break
            if past is not None and not past[1] <= q <= past[2] and _meets(r, past[0][q]):
                break
        write_text_atomic(marker, json.dumps({"frames": sorted(results)}) + "\n")
        return _Hyp(i0, direction, results)

    def write_choice(
        self, fwd, hyps: list[_Hyp], lo: int, hi: int, *, first: int | None = None
    ) -> list[dict]:
        """Choose per frame over positions ``lo..hi`` (:func:`choose`), write the chosen
        frames and the span's recomputed flags; returns the stretches changed. ``first``:
        the run's first position (the forward track costs :data:`DRIFT` more before it)."""
        span = self.order[lo : hi + 1]
        T, H = len(span), 1 + len(hyps)
        K = fwd[lo].joints.shape[0]
        cost = np.full((T, H), np.inf)
        joints = np.zeros((T, H, K, 3))
        for t, i in enumerate(span):
            cost[t, 0] = self.cost(fwd[lo + t])
            if first is not None and lo + t < first:
                cost[t, 0] += DRIFT  # the forward track drifts off before it is flagged
            joints[t, 0] = fwd[lo + t].joints
            for h, hyp in enumerate(hyps, start=1):
                r = hyp.results.get(i)
                if r is not None:
                    cost[t, h] = self.cost(r) + PREFER_FORWARD
                    joints[t, h] = r.joints
        start = 0 if lo > 0 else None
        end = 0 if hi < len(self.order) - 1 else None
        path = choose(cost, joints, start=start, end=end)
        tracks = [[fwd[lo + t]] + [y.results.get(i) for y in hyps] for t, i in enumerate(span)]
        chosen = [tracks[t][h] for t, h in enumerate(path.tolist())]
        before = 0 if first is None else max(first - lo, 0)  # frames before the run
        limbs = self.limb_choice(tracks, joints, path, before, start=start, end=end)
        chosen, grafts = self.grafted_frames(tracks, path, limbs, chosen, hyps)
        chosen = self.reflagged(fwd, lo, chosen)
        chosen = self.flag_ambiguous(fwd, hyps, lo, path, chosen)
        kept = self.out / FOLDER / "forward"
        (kept / "frames").mkdir(parents=True, exist_ok=True)
        for t, (i, h) in enumerate(zip(span, path.tolist(), strict=True)):
            r = chosen[t]
            if h > 0:
                hyp = hyps[h - 1]
                note = f"two-way: from keyframe {hyp.keyframe} ({hyp.direction})"
                r = replace(r, message=f"{r.message}; {note}" if r.message else note)
            if t in grafts:
                r = replace(r, message=f"{r.message}; {grafts[t]}" if r.message else grafts[t])
            old = fwd[lo + t]
            if h == 0 and t not in grafts and r.flags == old.flags and r.message == old.message:
                continue
            if not frame_path(kept, i).is_file():
                write_frame(kept, old)
            write_frame(self.out, replace(r, index=i))
        lost = [self.lost_limbs(r) for r in fwd[lo : hi + 1]]
        return _stretches(span, path, hyps, lost)

    def limb_choice(
        self, tracks, joints, path, before: int, *, start, end
    ) -> dict[str, np.ndarray]:
        """Per limb (:data:`~meshmocap.estimate.recovery.limbs.LIMBS`) the track chosen per
        frame (:func:`choose` on the limb's own costs, :func:`limb_costs`, and joints; a
        track other than the frame's ``path`` costs :data:`GRAFT` more, the forward track
        :data:`DRIFT` more on the ``before`` frames before the run, as for whole frames)."""
        T, H = len(tracks), len(tracks[0])
        cost = np.full((T, H, len(LIMB_PARTS)), np.inf)
        for t, row in enumerate(tracks):
            for h, r in enumerate(row):
                if r is not None:
                    cost[t, h] = self.limb_cost(r)
        cost[:before, 0] += DRIFT
        return choose_limbs(cost, joints, path, self.limb_of, start=start, end=end)

    def grafted_frames(
        self, tracks, path, limbs, chosen, hyps
    ) -> tuple[list[FrameResult], dict[int, str]]:
        """The chosen frames with each limb whose choice differs from the frame's grafted
        from its track (:func:`~meshmocap.estimate.recovery.limbs.graft_limbs`), the
        grafts recorded in ``self.grafted``, and a note per grafted frame (by position in
        the span). A graft is kept only where the grafted frame fits the observations at
        least as well as the frame's own (:meth:`fit_cost`: a limb hung at another trunk
        may stand off the observations); else each limb alone is tried, the best kept. A
        frame whose tracks carry no pose keeps its own limbs."""
        label = _track_labels(hyps)
        out: list[FrameResult] = []
        notes: dict[int, str] = {}
        for t, (r, h) in enumerate(zip(chosen, path.tolist(), strict=True)):
            want = {n: int(c[t]) for n, c in limbs.items() if int(c[t]) != h}
            if not want or not all(
                f.healthy and "pose_R" in f.state
                for f in [r] + [tracks[t][g] for g in want.values()]
            ):
                out.append(r)
                continue
            frame = self.frame(r.index)
            own = self.fit_cost(frame, r.vertices)
            best = None
            tries = [want] + ([{n: g} for n, g in want.items()] if len(want) > 1 else [])
            for other in tries:
                graft = self.graft(r, h, tracks[t], other)
                c = self.fit_cost(frame, graft[1])
                if c <= own and (best is None or c < best[0]):
                    best = (c, other, graft)
                if best is not None and other is want:
                    break  # every limb grafted fits as well: kept
            if best is None:
                out.append(r)
                continue
            _, other, (R, V, E) = best
            for n, g in other.items():
                last = next((x for x in reversed(self.grafted) if x["limb"] == n), None)
                if (
                    last
                    and last["track"] == label[g]
                    and last["frames"][1] == self.order[self.pos[r.index] - 1]
                ):
                    last["frames"][1] = r.index
                else:
                    self.grafted.append(
                        {"frames": [r.index, r.index], "limb": n, "track": label[g]}
                    )
            state = {**r.state, "pose_R": R, "pose_root": r.state["pose_root"]}
            out.append(replace(r, vertices=V, joints=E, state=state))
            notes[t] = "grafted: " + ", ".join(
                f"{n} from the {label[g]} track" for n, g in other.items()
            )
        return out, notes

    def graft(self, r: FrameResult, h: int, row: list, other: dict[str, int]):
        """``(R, V, E)`` of frame ``r`` (track ``h``) with the limbs ``other`` (limb →
        track) taken from ``row`` (each track's frame)
        (:func:`~meshmocap.estimate.recovery.limbs.graft_limbs`)."""
        used = [h, *dict.fromkeys(other.values())]
        rs = [row[g] for g in used]
        return graft_limbs(
            self.body.light,
            np.stack([f.state["pose_R"] for f in rs]),
            np.stack([f.state["pose_root"] for f in rs]),
            np.stack([f.vertices for f in rs]),
            np.stack([f.joints for f in rs]),
            {n: used.index(g) for n, g in other.items()},
        )

    def fit_cost(self, frame, V: np.ndarray) -> float:
        """How badly the vertices ``V`` fit ``frame``'s observations: :func:`limb_costs`
        summed over limbs, of the fit measures alone (outside, buried, unexplained; the
        measures of motion and of what was missed need the frames before)."""
        if self.checker is None:
            light = self.body.light
            eye = np.tile(np.eye(3), (light.skeleton.n_joints, 1, 1))
            self.checker = Recovery(light, eye, np.zeros(3))
        q = self.checker.check(frame, V)
        ev = np.zeros((len(LIMB_PARTS), len(EVIDENCE)))
        for m in ("outside", "buried", "unexplained"):
            ev[:, EVIDENCE.index(m)] = [getattr(q, m)[n] for n in LIMB_PARTS]
        return float(limb_costs(ev, self.rule).sum())

    def flag_ambiguous(
        self, fwd, hyps: list[_Hyp], lo: int, path: np.ndarray, chosen: list[FrameResult]
    ) -> list[FrameResult]:
        """The chosen frames flagged ``lost`` where the other tracks disagree on a limb
        (:func:`ambiguous_limbs`); each such frame recorded in ``self.ambiguous``, each
        frame's disagreement in ``self.disagreement``."""
        names = list(LIMB_PARTS)
        tracks = _track_labels(hyps)
        out = []
        for t, (r, h) in enumerate(zip(chosen, path.tolist(), strict=True)):
            i = r.index
            alt = [
                (g, f)
                for g, f in enumerate([fwd[lo + t]] + [y.results.get(i) for y in hyps])
                if g != h and f is not None and f.healthy
            ]
            if not r.healthy or not alt:
                out.append(r)
                continue
            ev = [f.state.get("evidence") for _, f in alt]
            # the forward track where flagged is what the pass replaces: none of its limbs
            # counts on its own (its other limbs carry the drift that lost it)
            limb_lost = np.array(
                [
                    self.rule_of().limb_lost(e)
                    if g > 0 and e is not None and np.shape(e) == (len(LIMB_PARTS), len(EVIDENCE))
                    else np.full(len(LIMB_PARTS), "lost" in f.flags)
                    for e, (g, f) in zip(ev, alt, strict=True)
                ]
            )
            amb, per, measures = ambiguous_limbs(
                r.joints,
                np.stack([f.joints for _, f in alt]),
                np.array(["lost" in f.flags for _, f in alt]),
                limb_lost,
                self.limb_of,
                forward=np.array([g == 0 for g, _ in alt]),
                rule=self.rule_of(),
            )
            far = np.round(1000 * measures.max(axis=0)).astype(int).tolist()
            self.disagreement.append({"frame": i, **dict(zip(DISAGREEMENT, far, strict=True))})
            if not amb.any():
                out.append(r)
                continue
            limbs = [names[k] for k in np.flatnonzero(amb)]
            worst = per[amb].max(axis=0)
            g = int(np.argmax(worst))
            mm = round(1000 * float(worst[g]))
            src = tracks[alt[g][0]]
            self.ambiguous.append({"frame": i, "limbs": limbs, "mm": mm, "track": src})
            note = f"ambiguous: {', '.join(limbs)} {mm} mm off in the {src} track"
            flags = r.flags if "lost" in r.flags else (*r.flags, "lost")
            out.append(
                replace(r, flags=flags, message=f"{r.message}; {note}" if r.message else note)
            )
        return out

    def rule_of(self) -> LostRule:
        """The lost rule (the shipped one where none was given)."""
        return self.rule or shipped_rule()

    def lost_limbs(self, r: FrameResult) -> tuple[str, ...]:
        """The limbs the lost rule finds lost on a frame, from its recorded evidence."""
        ev = r.state.get("evidence")
        if "lost" not in r.flags or ev is None:
            return ()
        return lost_limbs(ev, self.rule)

    def limb_cost(self, r: FrameResult) -> np.ndarray:
        """(L,) the evidence's cost of each limb of a frame (:func:`limb_costs`, the limbs the
        rule names lost: those the flag names); a frame without recorded evidence: its lost
        flag on every limb."""
        ev = r.state.get("evidence")
        if ev is None or np.shape(ev) != (len(LIMB_PARTS), len(EVIDENCE)):
            return np.full(len(LIMB_PARTS), float("lost" in r.flags))
        return limb_costs(ev, self.rule, named=True)

    def cost(self, r: FrameResult) -> float:
        """The evidence's cost of a frame (:func:`evidence_cost`); a frame without recorded
        evidence: its lost flag."""
        ev = r.state.get("evidence")
        if ev is None or np.shape(ev) != (len(LIMB_PARTS), len(EVIDENCE)):
            return float(len(LIMB_PARTS)) if "lost" in r.flags else 0.0
        return float(evidence_cost(ev, self.rule))

    def reflagged(self, fwd, lo: int, chosen: list[FrameResult]) -> list[FrameResult]:
        """The chosen frames flagged again by the lost rule, in time order, by one
        :class:`Recovery` started at the frame before the span."""
        first = fwd[max(lo - 1, 0)]
        st = first.state
        if "pose_R" not in st:
            return chosen
        recovery = Recovery(
            self.body.light,
            st["pose_R"],
            st["pose_root"],
            rule=self.rule,
        )
        if lo > 0:
            recovery.assess(self.frame(first.index), first.vertices)
        out = []
        for r, old in zip(chosen, fwd[lo:], strict=False):
            q = recovery.assess(self.frame(r.index), r.vertices)
            if not r.healthy or (r is old and r.index == self.order[0]):
                out.append(r)  # failed or missing, or the start as found: as it is
                continue
            flags = tuple(f for f in r.flags if f != "lost") + (("lost",) if q.lost else ())
            message = f"lost {q.describe()}" if q.lost else ""
            state = {**r.state, "pose_R": recovery.R, "pose_root": recovery.root}
            state["evidence"] = q.evidence
            out.append(replace(r, flags=flags, message=message, state=state))
        return out


def _meets(r: FrameResult, f: FrameResult) -> bool:
    """Whether the frames ``r`` and ``f`` (both fitted) agree: mean joint distance under
    :data:`MEET`."""
    if not (r.healthy and f.healthy):
        return False
    return bool(np.linalg.norm(r.joints - f.joints, axis=1).mean() < MEET)


def _middle_of_longest(explained: np.ndarray, tried: set[int], a: int) -> int | None:
    """The position (``a`` + offset) of the middle of the longest stretch of False in
    ``explained`` at least :data:`MIN_RUN` long and at least :data:`MIN_RUN` from every
    tried position; None when there is none."""
    runs = flagged_runs(~explained, merge_gap=0, min_run=MIN_RUN)
    for s, e in sorted(runs, key=lambda r: r[0] - r[1]):
        p = a + (s + e) // 2
        if all(abs(p - q) >= MIN_RUN for q in tried):
            return p
    return None


def _stretches(span, path, hyps, lost_per_frame) -> list[dict]:
    """Stretches of consecutive frames taken from one hypothesis (``changed``)."""
    out: list[dict] = []
    for t, (i, h) in enumerate(zip(span, path.tolist(), strict=True)):
        if h == 0:
            continue
        lost = list(lost_per_frame[t])
        last = out[-1] if out else None
        if last and last["_h"] == h and last["frames"][1] == span[t - 1]:
            last["frames"][1] = i
            last["limbs"] = sorted(set(last["limbs"]) | set(lost), key=list(LIMB_PARTS).index)
        else:
            hyp = hyps[h - 1]
            out.append(
                {
                    "frames": [i, i],
                    "keyframe": hyp.keyframe,
                    "direction": hyp.direction,
                    "limbs": lost,
                    "_h": h,
                }
            )
    return [{k: v for k, v in c.items() if k != "_h"} for c in out]
