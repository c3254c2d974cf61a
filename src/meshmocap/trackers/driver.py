"""The sequence driver shared by every tracker: streams frames, writes results frame by
frame, shows progress, resumes interrupted runs and never emits NaN.

One function tracks a frame, here, in live mode and in the two-way pass
(:func:`~meshmocap.trackers.frame_step.track_frame`). A frame whose fit
raises :class:`~meshmocap.errors.FitError` (or a numerical error) or returns non-finite
values is flagged ``failed`` (``healthy = False``, with the reason), the tracker is reset
to the last good state, and tracking continues with the next frame; the flagged frame
repeats the last good result. A frame without observation (the capture records it as
dropped, or its hull or mesh file is absent or unreadable) is flagged ``missing`` with the
reason, and the tracker coasts across it the same way: the next real frame is fitted from
the last good state.

After the forward pass over a capture on disk, the two-way pass
(:mod:`meshmocap.trackers.two_way`, ``TrackOptions.passes``) tracks the runs of frames it
flagged ``lost`` again from whole-body searches at keyframes, backward and forward.

Only one process writes into a track folder at a time: a second one is refused in one line
(``meshmocap._atomic.folder_lock``, released by the kernel when a run dies).

The first frame's pose comes from the capture alone (``init="auto"``,
:func:`~meshmocap.estimate.pose.first_pose.initial_pose`) or, the papers' protocol, from its
ground truth (``init="truth"``); how is recorded (:class:`~meshmocap.io.start.Start`, in
``track.json``), and an uncertain start flags its frame ``lost``. With ``recover``, every
fitted frame is scored (:class:`~meshmocap.estimate.recovery.reinit.Recovery`): a frame
with a limb lost is flagged ``lost`` (the message names the limbs); the track is left as
the tracker made it, except live: there a run of lost frames is searched for again at its
current frame and the tracker re-seated where the search's pose passes the same rule
(:mod:`~meshmocap.trackers.live_search`, flag ``reinit``).

How a capture is tracked (its frames, the start, resuming, recovery, the surface
refinement) is one record, :class:`~meshmocap.trackers.options.TrackOptions`, shared
with :func:`meshmocap.api.track` and the commands.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from meshmocap._atomic import folder_lock
from meshmocap._progress import phase, progress
from meshmocap._threads import blas_threads
from meshmocap._timing import StageTimer
from meshmocap._validate import check_type
from meshmocap.body.light import TrackingBody, tracking_body
from meshmocap.body.template import Template
from meshmocap.errors import InputError
from meshmocap.estimate.performer.capture_cache import cached_first_pose
from meshmocap.estimate.performer.first_frame import start_of_frame
from meshmocap.estimate.performer.tracking_template import frames_kind
from meshmocap.estimate.pose.first_pose import initial_pose_of_frame
from meshmocap.estimate.pose.hold import SkeletonHold
from meshmocap.estimate.pose.start import search_start, start_flags, start_message
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.reinit import Recovery
from meshmocap.geometry.refine import ArapRefiner, SurfaceRefiner
from meshmocap.io.capture import Capture
from meshmocap.io.live import LiveCapture
from meshmocap.io.results import (
    FrameResult,
    Track,
    done_frames,
    read_state,
    read_track,
    start_track,
    write_frame,
    write_light_binding,
    write_start,
)
from meshmocap.io.start import Start
from meshmocap.trackers.base import Tracker
from meshmocap.trackers.frame_step import (
    FRAME_ERRORS,
    file_reason,
    missing_reason,
    read_track_frame,
    track_frame,
)
from meshmocap.trackers.live_search import LiveSearch
from meshmocap.trackers.options import Init, Refine, TrackOptions
from meshmocap.trackers.two_way import two_way_pass

#: ``track.json``'s ``refine_surface`` for each refinement (None: none ran).
REFINE_SURFACE = {type(None): False, SurfaceRefiner: True, ArapRefiner: "arap"}
#: The ARAP refinement's local and global steps on a clean 4D capture (closed meshes of one
#: connectivity; elsewhere :class:`~meshmocap.geometry.refine.ArapRefiner`'s default):
#: there the slow, smooth part of its error is what slides the vertices along the body.
CLEAN_4D_ITERATIONS = 40


def track_sequence(
    tracker: Tracker,
    template: Template,
    capture: Capture,
    out: str | os.PathLike,
    options: TrackOptions | None = None,
    *,
    on_frame: Callable[[FrameResult], object] | None = None,
    timer: StageTimer | None = None,
) -> Track:
    """Track ``capture`` with ``tracker`` and write the results to the folder ``out``.

    Parameters
    ----------
    tracker : Tracker
    template : Template
        The tracking template.
    capture : Capture, SequenceCapture or LiveCapture
        Frames to track (a capture folder or a sequence of meshes or point clouds), or a
        capture being written (:class:`~meshmocap.io.live.LiveCapture`: each frame is
        tracked as it appears, until the capture stops growing; ``track.json`` records
        ``"live": true`` instead of the frames).
    out : path
        Track folder (:mod:`meshmocap.io.results`).
    options : TrackOptions, optional
        How to track (:class:`~meshmocap.trackers.options.TrackOptions`: the frames, the
        start, resuming, recovery, the surface refinement...; default: its defaults).
    on_frame : callable, optional
        Called with each frame's result once it is written (live mode reports them).
    timer : StageTimer, optional
        Records the seconds of each frame tracked (not the first) per stage: read,
        observe, the tracker's step and its own stages, the checks, the write
        (:mod:`meshmocap._timing`). None records nothing.

    Returns
    -------
    Track
        Every frame's result, read back from ``out``.
    """
    opts = TrackOptions() if options is None else options
    check_type("track_sequence", "options", opts, TrackOptions, "a TrackOptions")
    live = isinstance(capture, LiveCapture)
    chosen = opts.positions_in(capture)
    positions = list(range(len(capture))) if chosen is None else chosen
    if not positions:
        raise InputError(f"track: {capture.path} has no frames to track")
    init, recover, init_options = opts.init, opts.recover, opts.init_options
    two_way = opts.passes == "two-way" and recover and not live
    indices = [int(capture.indices[k]) for k in positions]  # without reading the frames
    meta = {
        "method": tracker.name,
        "template": template.name,
        "capture": str(Path(capture.path).resolve()),
        **({"live": True} if live else {"frames": indices}),
        "eval_names": list(template.eval_skeleton.names),
        "eval_parents": template.eval_skeleton.parents.tolist(),
        "options": tracker.options(),
        "init": init,
        "recover": recover,
        "passes": "two-way" if two_way else "forward",
        **(opts.template_info or {}),
    }
    body = tracking_body(template, n_vertices=opts.light)
    meta["tracked_vertices"] = body.light.n_vertices
    meta.update(_built_on(tracker, body.light))
    four_d = not getattr(capture, "cameras", None)  # mesh or point files: the surface itself
    # a 4D capture's surface is the performer's: the skeleton is held against it each frame;
    # with the frame before's refined surface where the files are a clean 4D capture (closed
    # meshes of one connectivity; hulls as files are larger than the body, and a surface
    # refined into them would swell the body the hold fits)
    clean = four_d and frames_kind(capture.snapshot() if live else capture) == "mesh"
    refiner = output_refiner(body.light, refine=opts.refine, four_d=four_d, clean=clean)
    meta["refine_surface"] = REFINE_SURFACE[type(refiner)]
    holds = four_d and hasattr(tracker, "hold")
    holds = holds and (clean or not getattr(tracker, "hold_surface_only", False))
    holder = SkeletonHold(body.light, surface=clean) if holds else None
    meta["hold_skeleton"] = holder is not None
    Path(out).mkdir(parents=True, exist_ok=True)
    report = on_frame or (lambda r: None)
    # one BLAS thread while tracking; a second run into the same folder is refused
    with blas_threads(), folder_lock(out, "track"):
        done = set(start_track(out, meta, template.F, resume=opts.resume))
        if body.binding is not None:  # frames hold the light body; read_track reads out
            write_light_binding(out, body.binding)
        if indices[0] not in done:
            # a live capture starts from the frames there now, as an ordinary capture
            first = capture.snapshot() if live else capture
            initialise_tracker(
                tracker,
                body,
                first,
                out,
                list(range(len(first))) if live else positions,
                init,
                init_options,
                start=opts.start,
                show_progress=opts.show_progress,
            )
            started = set(done_frames(out))
            for i in sorted(started - done):
                report(read_track_frame(out, i))
            done = started
        todo: Iterable[int]
        if live:  # frames that appear while tracking join a live capture's positions
            todo = (k for k in _growing(capture, 1) if capture.indices[k] not in done)
        else:
            todo = [k for k in positions[1:] if capture.indices[k] not in done]
        pool = capture.indices if live else indices
        recovery, good = None, None
        # live, a lost run is searched for again at its current frame (causal: live_search)
        exclude = tuple((init_options or {}).get("exclude_trials", ()))
        searcher = LiveSearch(body.light, exclude_trials=exclude) if live and recover else None
        for k in progress(todo, label=tracker.name, enabled=opts.show_progress):
            index = int(capture.indices[k])
            if good is None:  # the first frame to track: from the state of the one before
                order = list(pool)
                before = [i for i in order[: order.index(index)] if i in done]  # track's order
                last = before[-1] if before else indices[0]
                resume_tracker(tracker, body.light, out, last)
                if recover:
                    pose, evidence = _last_pose(out, before)
                    recovery = Recovery(
                        body.light,
                        *pose,
                        assessed=evidence is not None,
                        before=() if evidence is None else (evidence,),
                    )
                if holder is not None:
                    holder.last = _hold_start(body.light, out, before)
                good = last
            while True:
                r = track_frame(
                    tracker,
                    functools.partial(capture.__getitem__, k),  # a mesh sequence reads here
                    index,
                    out,
                    good,
                    recovery=recovery,
                    retry=functools.partial(capture.young, k) if live else None,
                    timer=timer,
                    refiner=refiner,
                    holder=holder,
                )
                if r is not None:
                    break
                time.sleep(capture.poll)  # a live file still being written: read it again
            if searcher is not None and recovery is not None:
                read = functools.partial(capture.__getitem__, k)
                r, recovery = searcher.after(tracker, recovery, read, r)
            good = index if r.healthy else good
            write_frame(out, r)
            if timer is not None:
                timer.lap("write")
            report(r)
        if two_way:
            if tracker.template is not body.light:  # a finished run resumed: nothing set up
                tracker.setup(body.light)
            two_way_pass(
                tracker,
                body,
                capture,
                out,
                frames=positions,
                refiner=refiner,
                hold=holder is not None,
                hold_surface=clean,
                exclude_trials=exclude,
                show_progress=opts.show_progress,
            )
    return read_track(out, vertices=opts.vertices)


def output_refiner(
    light: Template, *, refine: Refine = "auto", four_d: bool, clean: bool = False
) -> SurfaceRefiner | ArapRefiner | None:
    """The output surface's refinement of the tracked body ``light`` (its vertices, metres),
    or None: ``refine`` as :class:`~meshmocap.trackers.options.TrackOptions`' (checked
    there); ``four_d``: the capture is mesh or point files; ``clean``: closed meshes of one
    connectivity, whose refinement, anchored frame to frame, is given
    ``CLEAN_4D_ITERATIONS`` local and global steps."""
    if refine == "auto":
        refine = "arap" if four_d else "off"
    if refine == "on":
        return SurfaceRefiner(light.F, light.n_vertices)
    if refine == "arap":
        if clean:
            return ArapRefiner(light.V, light.F, iterations=CLEAN_4D_ITERATIONS)
        return ArapRefiner(light.V, light.F)
    return None


def _built_on(tracker: Tracker, template: Template) -> dict:
    """``{"cage_body": "template" | "reference"}`` for a tracker that builds a rig on a
    body (the cage: on the performer's template or on the reference body,
    :mod:`meshmocap.trackers.cage.body`), set up for ``template`` first (its ``init``
    would); empty for the others."""
    if not hasattr(type(tracker), "built_on"):
        return {}
    if tracker.template is not template:
        tracker.setup(template)
    return {"cage_body": tracker.built_on}


def _growing(capture: LiveCapture, start: int) -> Iterator[int]:
    """Positions ``start``, ``start + 1``, ... of a live capture, each once it has appeared;
    ends when the capture stops growing (:meth:`~meshmocap.io.live.LiveCapture.wait`)."""
    k = start
    while capture.wait(k + 1):
        yield k
        k += 1


def resume_tracker(tracker: Tracker, template: Template, out, last: int) -> None:
    """Set ``tracker`` up for ``template`` (a resumed run has not initialised it) and
    restore the state saved with frame ``last`` of the track folder ``out``."""
    if tracker.template is not template:
        tracker.setup(template)
    tracker.set_state(read_state(out, last))


def initialise_tracker(
    tracker: Tracker,
    body: TrackingBody,
    capture,
    out,
    positions: list[int],
    init: Init = "auto",
    init_options: dict | None = None,
    *,
    start: Start | None = None,
    show_progress: bool | None = None,
) -> None:
    """Start on the first frame that has an observation, at the pose :func:`first_pose`
    finds for the full body, or at ``start``'s where that is this frame
    (:func:`track_sequence`), the tracker on ``body.light``. With ``init="auto"`` on a
    frame with silhouettes the search's pose and a ``subject-fit`` start compete, each
    fitted to the silhouettes
    (:func:`~meshmocap.estimate.performer.first_frame.start_of_frame`). The start is
    recorded in ``track.json`` (:func:`~meshmocap.io.results.write_start`); the frame's message and
    flags (``lost`` for an uncertain start) are made from it
    (:mod:`~meshmocap.estimate.pose.start`). Frames before it are written as copies of
    it, flagged ``missing``. A placement of more than a few seconds says so
    (``show_progress`` False: nothing)."""
    skipped: list[tuple[int, str]] = []
    for k in positions:
        index = int(capture.indices[k])
        try:
            frame = capture[k]  # a mesh sequence reads the file here
            reason = missing_reason(frame)
        except FRAME_ERRORS as exc:
            reason = file_reason(exc)
        if reason is None:
            t0 = time.perf_counter()
            try:
                if init == "auto":  # the search's or the given start's, by evidence
                    given = start if start is not None and start.frame == index else None
                    found = start_of_frame(
                        body.template,
                        frame,
                        given,
                        functools.partial(
                            first_pose,
                            body.template,
                            frame,
                            init,
                            capture=capture,
                            options=init_options,
                        ),
                    )
                else:
                    found = first_pose(
                        body.template, frame, init, capture=capture, options=init_options
                    )
                with phase(
                    f"placing the {tracker.name} tracker on frame {index}", enabled=show_progress
                ):
                    r = tracker.init(body.light, frame, found.R, found.root)
            except FRAME_ERRORS as exc:
                reason = file_reason(exc)
        if reason is not None:
            skipped.append((index, reason))
            continue
        # the recovery's first pose
        state = {**r.state, "pose_R": found.R, "pose_root": found.root}
        message = start_message(found)
        r = replace(r, index=index, seconds=time.perf_counter() - t0, message=message, state=state)
        write_start(out, found)  # before the frame: a folder whose first frame is done has it
        write_frame(out, replace(r, flags=(*r.flags, *start_flags(found))))
        for index, why in skipped:
            write_frame(
                out,
                replace(
                    r, index=index, seconds=0.0, healthy=False, message=why, flags=("missing",)
                ),
            )
        return
    raise InputError(
        f"track: no frame of {capture.path} has an observation to start from "
        f"(frame {skipped[0][0]}: {skipped[0][1]})"
    )


def _truth(frame):
    try:
        return frame.truth
    except FRAME_ERRORS:  # a damaged truth file: start from the rest pose
        return None


def first_pose(
    template: Template, frame, init: Init, *, capture=None, options: dict | None = None
) -> Start:
    """The first frame's pose and how it was found. An automatic search is made once per
    capture, frame and template, and cached for the capture
    (:func:`~meshmocap.estimate.performer.capture_cache.cached_first_pose`)."""
    if init == "truth":
        truth = _truth(frame)
        index = int(frame.index)
        if _is_rest(template, truth):  # a template cut from this frame (the crane's rig)
            rest = np.tile(np.eye(3), (template.skeleton.n_joints, 1, 1))
            return Start(index, rest, template.skeleton.rest_positions[0], "rest")
        if truth is None or truth.rotations is None:
            raise InputError(
                "track: --init truth needs a capture with ground-truth poses "
                "(a synthetic capture); this one has none: use --init auto"
            )
        return Start(index, truth.rotations, truth.root, "truth")
    if capture is None:
        return _search_first_pose(template, frame, options)
    return cached_first_pose(
        capture,
        template,
        frame.index,
        functools.partial(_search_first_pose, template, frame, options),
        options=options,
    )


def _search_first_pose(template: Template, frame, options: dict | None = None) -> Start:
    """The automatic first pose of ``frame`` (:func:`first_pose`)."""
    obs = observed(frame)
    P = obs.points[0]
    if len(P) < 50:
        raise InputError(
            f"track: frame {frame.index} has {len(P)} observed points; "
            "--init auto needs a body to start from"
        )
    res = initial_pose_of_frame(template, obs, **(options or {}))
    return search_start(frame.index, res)


def _is_rest(template: Template, truth) -> bool:
    """Whether a truth without pose is the template's own rest mesh (within 1 mm)."""
    if truth is None or truth.rotations is not None or truth.vertices is None:
        return False
    V = np.asarray(truth.vertices)
    return V.shape == template.V.shape and float(np.abs(V - template.V).max()) < 1e-3


def _hold_start(template: Template, out, indices: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Where the skeleton hold starts: the articulated pose stored with the latest of
    ``indices`` (the recovery's), else the template's rest pose."""
    try:
        return _last_pose(out, indices)[0]
    except InputError:
        sk = template.skeleton
        return np.tile(np.eye(3), (sk.n_joints, 1, 1)), sk.rest_positions[0].copy()


def _last_pose(out, indices: list[int]) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray | None]:
    """The articulated pose stored with the latest of ``indices`` that has one, and the
    evidence the recovery stored there where it assessed that frame (else None): a resumed
    run measures the next frame's motion from there and holds the lost rule over that
    frame's evidence, as the run that wrote it would have."""
    for i in reversed(indices):
        st = read_state(out, i)
        if "pose_R" in st:
            pose = st["pose_R"].astype(np.float64), st["pose_root"].astype(np.float64)
            ev = st.get("evidence")
            return pose, None if ev is None else np.asarray(ev, dtype=np.float64)
    raise InputError(f"track: {out} holds no pose to resume recovery from; use --restart")
