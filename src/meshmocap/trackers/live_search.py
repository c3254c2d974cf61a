"""Live mode's way back from a lost limb: a whole-body search at the current frame, kept only
on its own evidence (``track --follow``; issue 42 item 4).

A capture on disk has its lost runs put back afterwards, from frames on both sides (the
two-way pass). Live, only the frames so far exist, so the search is causal: once
:data:`RUN` frames in a row are flagged ``lost`` and :data:`COOLDOWN` frames have passed
since the last search, the current frame is searched
(:func:`~meshmocap.estimate.pose.keyframe.keyframe_pose`, helped by the tracked pose: its
heading, its limbs that are not lost; without it where the torso is lost). The tracker is
re-seated at the found pose (``Tracker.reseat``) and that result is flagged by the lost
rule afresh (a new
:class:`~meshmocap.estimate.recovery.reinit.Recovery` started at the found pose, as the
two-way pass judges its keyframes); it is kept only where the rule finds nothing lost, which
the tracked frame, flagged, did not pass. A kept search flags the frame ``reinit`` and says
so in its message, and tracking goes on from there; otherwise the tracker is set back to
the tracked frame's state and the message notes the search.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from meshmocap.body.template import Template
from meshmocap.estimate.pose.keyframe import keyframe_pose
from meshmocap.estimate.recovery.limbs import LIMBS
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.reinit import Recovery
from meshmocap.io.results import FrameResult
from meshmocap.trackers.base import Tracker
from meshmocap.trackers.frame_step import recovered

__all__ = ["COOLDOWN", "RUN", "LiveSearch"]

#: Frames in a row flagged ``lost`` before a search.
RUN = 3
#: Frames after a search (kept or not) before the next one.
COOLDOWN = 10


class LiveSearch:
    """The causal whole-body search of one live run (module docstring).

    Parameters
    ----------
    template : Template
        The tracking template (the driver's light body).
    exclude_trials : tuple of str
        Pose-library trials the search leaves out.
    run, cooldown : int
        :data:`RUN` and :data:`COOLDOWN`.
    judge : callable, optional
        ``judge(recovery, frame, r)``: ``r`` flagged by ``recovery`` (default the per-frame
        step's :func:`~meshmocap.trackers.frame_step.recovered`: the searched pose judged
        as every tracked frame is).
    search : callable
        ``search(template, frame, near=..., lost=..., exclude_trials=...)`` returning an
        :class:`~meshmocap.estimate.pose.first_pose.InitResult` (default
        :func:`~meshmocap.estimate.pose.keyframe.keyframe_pose`).
    """

    def __init__(
        self,
        template: Template,
        *,
        exclude_trials: tuple[str, ...] = (),
        run: int = RUN,
        cooldown: int = COOLDOWN,
        judge: Callable[[Recovery, object, FrameResult], FrameResult] | None = None,
        search: Callable | None = None,
    ):
        self.template = template
        self.judge = recovered if judge is None else judge
        self.exclude_trials = tuple(exclude_trials)
        self.run, self.cooldown = int(run), int(cooldown)
        self.search = keyframe_pose if search is None else search
        #: frames flagged ``lost`` in a row so far; frames to wait before the next search
        self.lost_in_row, self.wait = 0, 0
        #: searches made and kept so far
        self.searched, self.kept = 0, 0

    def after(
        self, tracker: Tracker, recovery: Recovery, read: Callable[[], object], r: FrameResult
    ) -> tuple[FrameResult, Recovery]:
        """The frame's result ``r`` (flagged by ``recovery``), or the tracker re-seated at a
        search's pose of the frame ``read()`` returns where that is kept (flag ``reinit``);
        with the recovery to go on with (a new one started at a kept pose)."""
        lost = "lost" in r.flags and r.healthy
        self.lost_in_row = self.lost_in_row + 1 if lost else 0
        if self.wait > 0:
            self.wait -= 1
        if not lost or self.lost_in_row < self.run or self.wait > 0:
            return r, recovery
        self.wait = self.cooldown
        self.searched += 1
        frame = observed(read())
        q = recovery.quality
        limbs = tuple(n for n in (q.lost if q is not None else ()) if n in LIMBS)
        # a lost torso: the tracked heading is not to be trusted either
        trunk = q is not None and "torso" in q.lost
        near = None if trunk else (recovery.R.copy(), recovery.root.copy())
        res = self.search(
            self.template, frame, near=near, lost=limbs, exclude_trials=self.exclude_trials
        )
        seated = tracker.reseat(frame, res.R, res.root)
        fresh = Recovery(self.template, res.R, res.root, rule=recovery.rule)
        judged = self.judge(fresh, frame, seated)
        was = ", ".join(q.lost) if q is not None and q.lost else "a limb"
        if "lost" in judged.flags:  # not kept: the track goes on as it was
            tracker.set_state(r.state)
            note = f"whole-body search ({res.label}) not kept: {fresh.quality.describe()}"
            return replace(r, message=f"{r.message}; {note}" if r.message else note), recovery
        self.kept += 1
        self.lost_in_row = 0
        message = f"re-initialised by a whole-body search ({res.label}; {was} lost)"
        flags = (*(f for f in judged.flags if f != "reinit"), "reinit")
        return replace(judged, index=r.index, flags=flags, message=message), fresh
