"""One frame tracked: the per-frame step shared by the forward pass
(:func:`~meshmocap.trackers.driver.track_sequence`), live mode
(:mod:`meshmocap.trackers.follow`) and the two-way pass (:mod:`meshmocap.trackers.two_way`).

The tracker steps on the frame (:func:`track_frame`); a frame whose fit raises a
numerical error or returns non-finite values is flagged ``failed``, a frame without
observation ``missing``, and the tracker coasts across either from the last good frame's
state (:func:`coast_frame`). With a :class:`~meshmocap.estimate.recovery.reinit.Recovery`,
the frame is scored and flagged ``lost`` by the lost rule (:func:`recovered`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from meshmocap._timing import StageTimer, touched
from meshmocap.body.skeleton import forward_kinematics
from meshmocap.body.skinning import linear_blend_skinning, skinning_transforms
from meshmocap.body.template import Template
from meshmocap.errors import FitError, FormatError, MeshError, MeshmocapFileNotFoundError
from meshmocap.estimate.pose.hold import SkeletonHold
from meshmocap.estimate.recovery.observe import observed
from meshmocap.estimate.recovery.reinit import Recovery
from meshmocap.geometry.refine import ArapRefiner, SurfaceRefiner
from meshmocap.io.results import FrameResult, frame_flags, read_frame_arrays, read_state
from meshmocap.trackers.base import Tracker

#: Errors that mean "this frame could not be fitted" rather than a bug or a user mistake:
#: a tracker's :class:`~meshmocap.errors.FitError`, and the numerical errors of numpy
#: (a singular solve; floating-point traps under ``np.errstate``).
NUMERICAL_ERRORS = (FitError, np.linalg.LinAlgError, ArithmeticError)


def is_finite_result(r: FrameResult) -> bool:
    """Whether a frame's joints and vertices are all finite."""
    return bool(np.all(np.isfinite(r.joints)) and np.all(np.isfinite(r.vertices)))


def track_frame(
    tracker: Tracker,
    read: Callable[[], object],
    index: int,
    out: str | os.PathLike,
    good: int,
    *,
    recovery: Recovery | None = None,
    retry: Callable[[], bool] | None = None,
    timer: StageTimer | None = None,
    refiner: SurfaceRefiner | ArapRefiner | None = None,
    holder: SkeletonHold | None = None,
) -> FrameResult | None:
    """Track one frame: the per-frame step of the driver and of live mode
    (:mod:`meshmocap.trackers.follow`).

    Parameters
    ----------
    tracker : Tracker, in the state of the frame before
    read : callable returning the frame (a mesh sequence reads its file here)
    index : int, its frame number
    out : path, the track folder; ``good`` : int, its last well-fitted frame
    recovery : Recovery, optional
        Scores the frame and flags lost limbs (:func:`recovered`).
    retry : callable, optional
        Asked when the frame cannot be read: True means "not yet" (live mode: a file still
        being written), and None is returned for the caller to try again later.
    timer : StageTimer, optional
        Starts a frame's record and books read, observe, step (and the tracker's own
        stages) and checks to it (:mod:`meshmocap._timing`); the caller books the write.
    refiner : SurfaceRefiner or ArapRefiner, optional
        Refines the result's vertices towards the frame's observed points (booked to
        ``refine``); the tracker's state is left as the fit made it.
    holder : SkeletonHold, optional
        Fits the pose against the frame's observed points together with the tracker's
        surface, and moves the tracker there (:func:`held`; booked to ``hold``).

    Returns
    -------
    FrameResult
        The fit, or (flagged ``failed``, with the reason, after a :class:`FitError` or
        another numerical error) or (flagged ``missing``, when the frame has no
        observation) a copy of frame ``good``'s result, the tracker reset to its state.
    """
    t0 = time.perf_counter()
    if timer is not None:
        timer.start()
    try:
        raw = read()
        reason = missing_reason(raw)
        if reason is None:
            frame = observed(raw)  # points, normals, occupancy: made once
            if timer is not None:
                _read_and_observe(timer, raw, frame)
            r = _step(tracker, frame, timer)
            if not is_finite_result(r):
                raise FitError("non-finite joints or vertices")
            if holder is not None:
                r = held(tracker, holder, frame, r, refiner=refiner, index=index)
            if timer is not None:
                timer.lap("hold")
            if recovery is not None:
                r = recovered(recovery, frame, r)
                if timer is not None:
                    timer.lap("checks")
            if refiner is not None:
                r = replace(r, vertices=refiner.refine(r.vertices, *frame.points, key=index))
            if timer is not None:
                timer.lap("refine")
            if timer is not None:  # what this frame read and derived, the next reads first
                timer.reads = touched(raw, FRAME_READS)
                timer.derived = touched(frame, FRAME_DERIVED)
            return replace(r, index=index, seconds=time.perf_counter() - t0)
    except NUMERICAL_ERRORS as exc:
        return coast_frame(tracker, out, good, index, t0, "failed", failure_reason(exc))
    except FRAME_ERRORS as exc:  # this frame's file is absent or unreadable
        if retry is not None and retry():
            return None
        reason = file_reason(exc)
    return coast_frame(tracker, out, good, index, t0, "missing", reason)


#: A capture frame's lazily read files, and what its observed wrapper derives from them
#: once (cached properties of :class:`~meshmocap.io.capture.CaptureFrame` and
#: :class:`~meshmocap.estimate.recovery.observe.ObservedFrame`). With a timer, the driver computes
#: up front those the frame before used (``_read_and_observe``).
FRAME_READS = ("hull_mesh", "hull")
FRAME_DERIVED = ("surface", "points", "field")


def _read_and_observe(timer: StageTimer, raw, frame) -> None:
    """Read the frame's files and derive its observations as the frame before used them
    (the same work the step and the checks would ask for), booked to ``read`` and
    ``observe``."""
    for name in timer.reads:
        getattr(raw, name)
    timer.lap("read")
    for name in timer.derived:
        getattr(frame, name)
    timer.lap("observe")


def _step(tracker: Tracker, frame, timer: StageTimer | None) -> FrameResult:
    """``tracker.step(frame)``; with a timer, booked to ``step`` and the tracker's own
    stages (its ``stage_seconds``, where it keeps them) to ``step.NAME``."""
    if timer is None:
        return tracker.step(frame)
    before = dict(getattr(tracker, "stage_seconds", {}))
    r = tracker.step(frame)
    timer.lap("step")
    for name, total in getattr(tracker, "stage_seconds", {}).items():
        timer.add(f"step.{name}", total - before.get(name, 0.0))
    return r


#: Errors reading one frame's observation (an absent, empty or corrupt hull or mesh file):
#: the frame is flagged ``missing`` and tracking goes on.
FRAME_ERRORS = (MeshmocapFileNotFoundError, FormatError, MeshError)


def missing_reason(frame: object) -> str | None:
    """Why ``frame`` has no observation (its capture says so), or None."""
    reason = getattr(frame, "missing", None)
    return str(reason) if reason else None


def failure_reason(exc: BaseException) -> str:
    """One line (at most 200 characters) naming why a frame failed, for its flag."""
    return f"{type(exc).__name__}: {exc}".splitlines()[0][:200]


def file_reason(exc: BaseException) -> str:
    """One line (at most 200 characters) naming why a frame's file could not be read: the
    error's own words, which name the file (:data:`FRAME_ERRORS`), for its flag."""
    return (str(exc).splitlines() or [type(exc).__name__])[0][:200]


def coast_frame(
    tracker: Tracker, out, good: int, index: int, t0: float, flag: str, why: str
) -> FrameResult:
    """Coast across frame ``index``: the tracker goes back to the state of the last good
    frame, and the frame repeats that frame's result, flagged ``flag`` with the reason (the
    next real frame is fitted from there)."""
    tracker.set_state(read_state(out, good))
    prev = read_track_frame(out, good)
    return replace(
        prev,
        index=index,
        seconds=time.perf_counter() - t0,
        healthy=False,
        message=why,
        flags=(flag,),
    )


def read_track_frame(out: str | os.PathLike, index: int) -> FrameResult:
    """One frame's result from a track folder."""
    z = read_frame_arrays(out, index)
    return FrameResult(
        index=int(z["index"]),
        joints=z["joints"].astype(np.float64),
        vertices=z["vertices"].astype(np.float64),
        energies={k[7:]: float(v) for k, v in z.items() if k.startswith("energy_")},
        n_iter=int(z["n_iter"]),
        seconds=float(z["seconds"]),
        healthy=bool(z["healthy"]),
        message=str(z["message"]),
        flags=frame_flags(z),
        state={k[6:]: v for k, v in z.items() if k.startswith("state_")},
    )


def recovered(recovery: Recovery, frame, r: FrameResult) -> FrameResult:
    """``r`` scored against ``frame``: flagged ``lost`` with the limbs concerned. The
    frame's quality (``fit_outside``, ``fit_unexplained``) joins its energies, the
    articulated pose of the tracked mesh its state (``pose_R``, ``pose_root``)."""
    q = recovery.assess(frame, r.vertices, start=_tracker_pose(recovery, r))
    flags, message = tuple(r.flags), r.message
    if q.lost:
        flags += ("lost",)
        message = f"lost {q.describe()}"
    state = {**r.state, "pose_R": recovery.R, "pose_root": recovery.root}
    if q.evidence is not None:  # what the two-way pass weighs its hypotheses by
        state["evidence"] = q.evidence
    return replace(
        r, flags=flags, message=message, energies={**r.energies, **q.energies()}, state=state
    )


def held(
    tracker: Tracker,
    holder: SkeletonHold,
    frame,
    r: FrameResult,
    *,
    refiner: SurfaceRefiner | ArapRefiner | None = None,
    index: int | None = None,
) -> FrameResult:
    """``r`` with the tracker moved onto the pose ``holder`` fits against ``frame``'s
    observed points together with the tracker's surface (:mod:`meshmocap.estimate.pose.hold`),
    from the pose of that surface; the frame's energies, flags and message are kept. Where
    ``refiner`` refined the frame next to ``index`` last, and that frame was held too, the
    body fitted is its refined surface put back in the rest pose (:func:`held_rest`). On a
    clean 4D capture (``holder.surface``), where the tracker's surface is not its own
    articulated fit (the patch cloud, which slides along a loose surface such as a skirt,
    and whose pose then starts the fit far off), the fit is also started from the last held
    pose, directly and through the template's own skin (``_last_pose_fits``), the pose of
    lowest :meth:`~meshmocap.estimate.pose.hold.SkeletonHold.cost` is kept, and the
    tracker is placed on that body in the held pose with its parts' own translations
    (``held_rest(..., rigid=False)``), which the fit leaves out."""
    rest = held_rest(holder, refiner, index)
    R, root = holder.start(r.vertices, *holder.last)
    R, root = holder.fit(*frame.points, r.vertices, R, root, rest=rest)
    body = None
    if holder.surface and not _own_pose(r, holder):  # a clean 4D capture's slid surface
        R, root = _lowest_cost(
            holder, frame, [(R, root), *_last_pose_fits(holder, frame, r, rest)], rest
        )
        if rest is not None:  # the patches onto the body fitted, not the template's skin,
            # with the parts' own translations the fit's body leaves out (their place on it)
            whole = held_rest(holder, refiner, index, rigid=False)
            body = posed_body(holder.template, whole, R, root)
    holder.last, holder.key = (R, root), index
    h = tracker.hold(frame, R, root) if body is None else tracker.hold(frame, R, root, surface=body)
    if not is_finite_result(h):
        raise FitError("non-finite joints or vertices after holding the skeleton")
    return replace(r, joints=h.joints, vertices=h.vertices, state={**r.state, **h.state})


def posed_body(template: Template, rest: np.ndarray, R: np.ndarray, root: np.ndarray) -> np.ndarray:
    """The rest surface ``rest`` (n, 3) skinned with ``template``'s weights in the pose
    ``R`` (J, 3, 3), ``root`` (3,): (n, 3) float64, metres (the body
    :meth:`~meshmocap.estimate.pose.hold.SkeletonHold.fit` fits with ``rest``)."""
    sk = template.skeleton
    G, P = forward_kinematics(sk, np.asarray(R, dtype=np.float64), root)
    A = skinning_transforms(G, P, sk.rest_positions)
    return linear_blend_skinning(np.asarray(rest, dtype=np.float64), template.weights, A)


def _last_pose_fits(
    holder: SkeletonHold, frame, r: FrameResult, rest: np.ndarray | None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The held fits of ``frame`` started from the last held pose: one of the body
    ``rest`` (n, 3) directly, and one first fitted with the template's own skin, as
    articulated ICP's step fits it, then with ``rest`` from there (the skin that the rig
    carries is fitted before the body's own offsets, which can pull a fit along the
    surface). Each a pose (R (J, 3, 3), root (3,))."""
    pts = frame.points
    direct = holder.fit(*pts, r.vertices, *holder.last, rest=rest)
    skin = holder.fit(*pts, r.vertices, *holder.last)
    return [direct, holder.fit(*pts, r.vertices, *skin, rest=rest)]


def _lowest_cost(
    holder: SkeletonHold, frame, fits: list[tuple[np.ndarray, np.ndarray]], rest
) -> tuple[np.ndarray, np.ndarray]:
    """The pose of ``fits`` of lowest :meth:`~meshmocap.estimate.pose.hold.SkeletonHold.cost`
    against ``frame``'s observed points (the first of equal ones)."""
    costs = [holder.cost(*frame.points, R, root, rest=rest) for R, root in fits]
    return fits[int(np.argmin(costs))]


def _own_pose(r: FrameResult, holder: SkeletonHold) -> bool:
    """Whether the tracker's result ``r`` carries an articulated pose of the holder's
    skeleton (its state's ``R`` (J, 3, 3) and ``root``: articulated ICP's, a fit against
    the observations already)."""
    return "root" in r.state and np.shape(r.state.get("R")) == np.shape(holder.last[0])


def held_rest(
    holder: SkeletonHold,
    refiner: SurfaceRefiner | ArapRefiner | None,
    index: int | None,
    *,
    rigid: bool = True,
) -> np.ndarray | None:
    """The rest surface (n, 3) the frame ``index``'s held pose skins: the refined surface
    of the frame next to it (``index ± 1``, the refiner's last, an
    :class:`~meshmocap.geometry.refine.ArapRefiner`'s) in the pose the holder held it in,
    put back in the rest pose (:meth:`~meshmocap.estimate.pose.hold.SkeletonHold.rest_of`,
    ``rigid`` passed on); None where there is none (the template's own surface)."""
    last = getattr(refiner, "last_", None)
    if index is None or last is None or holder.key != last[0] or abs(index - last[0]) != 1:
        return None
    if not holder.surface:  # the driver holds with the template's own surface
        return None
    return holder.rest_of(last[2], *holder.last, rigid=rigid)


def _tracker_pose(recovery: Recovery, r: FrameResult) -> tuple[np.ndarray, np.ndarray] | None:
    """The tracker's own articulated pose of ``r`` (its state's ``R``, ``root``) where it is
    one of the recovery's skeleton (the articulated ICP's): the pose fit of the tracked
    mesh starts there, at its answer."""
    R, root = r.state.get("R"), r.state.get("root")
    if R is None or root is None or np.shape(R) != recovery.R.shape or np.shape(root) != (3,):
        return None
    return np.asarray(R, dtype=np.float64), np.asarray(root, dtype=np.float64)
