"""The first frame's pose on the default path: the search's or the body fit's, by evidence.

A studio capture (cameras and silhouettes) tracked with its estimated body
(:mod:`~meshmocap.estimate.performer.tracking_template`) has two candidate poses for its
first frame:

* the first-pose search's (:func:`~meshmocap.estimate.pose.first_pose.initial_pose`), which
  scores whole-body candidates on the visual hull's points;
* the pose the body was fitted in on that frame, together with its shape, to the
  silhouettes (:func:`~meshmocap.estimate.performer.shape_fit.fit_shape`; a
  :class:`~meshmocap.io.start.Start` of source ``subject-fit``).

Neither is always right: the body fit lands closer where it converged (it reads the
silhouettes at pixel resolution, where the hull's points are a superset of the body) but
can settle with a limb or the heading wrong; the search is rarely wrong but seldom close.
Each candidate is fitted to the frame's silhouettes with the body held
(:func:`~meshmocap.estimate.performer.shape_fit.fit_pose`, a few Gauss–Newton iterations),
and the one whose fit leaves the smaller silhouette objective is kept: the same measure
the body fit minimises, compared on the same frame and body. The evidence never reads the
truth. ``docs/measurements.rst`` has the numbers (section "The first frame's pose").

Without silhouettes (meshes, point clouds) nothing is refined: a given start is used as it
is, else the search's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

from meshmocap._parallel import parallel_map
from meshmocap.body.template import Template
from meshmocap.estimate.performer.shape_fit import SilhouetteView, fit_pose, silhouette_view
from meshmocap.io.start import Start

__all__ = ["REFINE_ITERATIONS", "frame_views", "refined_start", "start_of_frame"]

#: Gauss–Newton iterations of each candidate's silhouette fit (more changed the chosen
#: start's error by < 2 mm on the measured captures, at twice the cost).
REFINE_ITERATIONS = 10


def frame_views(frame) -> list[SilhouetteView] | None:
    """The silhouette views of a capture frame (its cameras and masks), or None when the
    frame has none (a mesh or point-cloud frame, a capture without cameras)."""
    cameras = getattr(frame, "cameras", None)
    if not cameras:
        return None
    try:
        masks = frame.silhouettes
    except (FileNotFoundError, AttributeError):
        return None
    if not masks or len(masks) != len(cameras):
        return None
    return [silhouette_view(m, c) for m, c in zip(masks, cameras, strict=True)]


def refined_start(
    template: Template,
    views: list[SilhouetteView],
    candidates: Sequence[Start],
    *,
    iterations: int = REFINE_ITERATIONS,
) -> Start:
    """Each of ``candidates`` (starts of one frame, for ``template``) fitted to ``views``
    with the body held; the candidate whose fit leaves the least objective, at its fitted
    pose, with :attr:`~meshmocap.io.start.Start.silhouette_cost` (and ``rival_cost``, the
    best other candidate's) recorded. Its other fields (source, confidence, label) stay
    the candidate's."""
    if not candidates:
        raise ValueError("refined_start: no candidate")
    # the candidates side by side (meshmocap._parallel): the same fits
    fits = parallel_map(
        lambda s: fit_pose(template, views, s.R, s.root, iterations=iterations), candidates
    )
    order = sorted(range(len(fits)), key=lambda i: fits[i].cost)
    best = order[0]
    rival = fits[order[1]].cost if len(order) > 1 else None
    f = fits[best]
    return replace(candidates[best], R=f.R, root=f.root, silhouette_cost=f.cost, rival_cost=rival)


def start_of_frame(
    template: Template, frame, given: Start | None, search: Callable[[], Start]
) -> Start:
    """The automatic start of ``frame`` (module docstring).

    Parameters
    ----------
    template : Template, the tracked body
    frame : a capture frame
    given : Start or None, a start made with the template for this frame (its pose kept
        beside an estimated template); a ``subject-fit`` one competes with the search on
        a frame with silhouettes, any other is used as it is, and so is one this function
        chose already (its :attr:`~meshmocap.io.start.Start.silhouette_cost` recorded: the
        demo finds its start once for its three trackers)
    search : callable returning the search's Start (called only when needed)
    """
    if given is not None and given.silhouette_cost is not None:  # chosen so already
        return given
    views = None
    if given is None or given.source == "subject-fit":
        views = frame_views(frame)
    if given is not None and views is None:
        return given
    found = search()
    if views is None:
        return found
    return refined_start(template, views, [found, *([given] if given is not None else [])])
