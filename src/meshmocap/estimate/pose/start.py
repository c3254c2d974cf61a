"""How a track starts, decided once and kept as a record
(:class:`~meshmocap.io.start.Start`): made here from the first pose's search
(:func:`search_start`: whether the start is trusted), and turned into the first frame's
flags (:func:`start_flags`) and its message (:func:`start_message`), both from the record.
Nothing reads a decision back out of a message.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from meshmocap.io.start import Start

if TYPE_CHECKING:  # the search's result, read here; importing the search is not needed
    from meshmocap.estimate.pose.first_pose import InitResult

__all__ = ["START_MARGIN", "search_start", "start_description", "start_flags", "start_message"]

#: Least margin (metres of ranking key) between the start and a distinct runner-up for a
#: confident start.
START_MARGIN = 0.002


def search_start(frame: int, res: InitResult) -> Start:
    """The start that the first pose's search ``res``
    (:func:`~meshmocap.estimate.pose.first_pose.initial_pose`) found on frame number
    ``frame``: confident unless the fit-quality check finds a limb of the winner lost or a
    distinct runner-up ranks within :data:`START_MARGIN` of it."""
    close = res.runner_up is not None and res.margin < START_MARGIN
    return Start(
        frame=int(frame),
        R=res.R,
        root=res.root,
        source="search",
        confident=not res.lost and not close,
        label=res.label,
        score=float(res.score),
        key=float(res.key),
        runner_up=None if res.runner_up is None else res.runner_up.label,
        runner_up_key=None if res.runner_up is None else float(res.runner_up_key),
        lost=tuple(res.lost),
    )


def start_flags(start: Start) -> tuple[str, ...]:
    """The first frame's flags: ``("lost",)`` for an uncertain start (not
    :attr:`~meshmocap.io.start.Start.confident`), else none."""
    return () if start.confident else ("lost",)


#: What each source of a start says, after ``init`` (:func:`start_description`).
_SAYS = {
    "truth": "truth: the first pose from ground truth",
    "rest": "truth: the template is this frame, in its rest pose",
    "subject-rest": "template: the template was made from frame {frame}, in its rest pose",
    "subject-fit": "template: the template was made from frame {frame}, in the pose fitted "
    "with the body",
}


def start_description(start: Start | None) -> str:
    """How a track's first pose was found, in words, from its record: for a search, the
    winner, its fit score and ranking key, the runner-up and its margin, and why the start
    is uncertain (the limbs lost, a runner-up within :data:`START_MARGIN`); None (a track
    that does not record its start): ``"unknown"``."""
    if start is None:
        return "unknown"
    if start.source != "search":
        return _SAYS[start.source].format(frame=start.frame)
    score, key = 1000 * (start.score or 0.0), 1000 * (start.key or 0.0)
    text = f"auto: {start.label}, fit score {score:.1f} mm, key {key:.1f}"
    margin = start.margin
    if start.runner_up is not None and margin is not None:
        text += f"; runner-up {start.runner_up} (+{1000 * margin:.1f} mm)"
    if not start.confident:
        why = [f"{limb} lost" for limb in start.lost]
        if margin is not None and margin < START_MARGIN:
            why.append(f"runner-up within {1000 * START_MARGIN:.0f} mm")
        text += "; uncertain start" + (f" ({', '.join(why)})" if why else "")
    return text


def start_message(start: Start) -> str:
    """The first frame's message: ``"init "`` and :func:`start_description`."""
    return f"init {start_description(start)}"
