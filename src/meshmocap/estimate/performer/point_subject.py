"""The performer's body fitted to a capture's points: a folder of visual hulls (never quite
manifold, with holes) or of point clouds, without cameras.

The body is a point of the bundled shape space (:mod:`meshmocap.body.shape_space`), as for
a studio capture's silhouettes (:mod:`meshmocap.estimate.performer.subject`); without
silhouettes the points only bound the body (a hull's phantom volumes widen it), so what is
fitted is its size, the first of the space's directions (nearly all of its variance), along
the scaled mean body:

1. **Surfaces.** The chosen frames (the first with points, and others evenly spread) are
   observed as the automatic initialisation observes them
   (:class:`~meshmocap.estimate.recovery.observe.ObservedFrame`: points, normals, the solid they
   enclose and its signed distance); a closed surface of that solid (Gaussian-smoothed
   occupancy cut by marching cubes) serves the heading search.
2. **First pose.** The mean body is fitted with its size to the first frame's surface from
   8 headings (:func:`~meshmocap.estimate.performer.subject.initial_body_pose`), then refined as
   the automatic initialisation refines its candidates, model points held inside the
   observed solid (:class:`~meshmocap.estimate.pose.fit.PoseFitter` with its signed distance);
   the other frames start from that pose, moved to their points.
3. **Size.** In each frame, the size that gives the posed body the height of the points
   (a hull is as tall as the body: phantom volumes widen it, never heighten it), the pose
   refitted at each size. A pose fitted into a hull's spare room comes out bent more than
   the body is (shorter, so sized up): the smallest size, the least bent frame's, is kept.

The result's template is in the bundled topology and A-pose rest; its first frame's pose
(``R[0]``, ``root[0]``), refitted on the final body, is where tracking starts.
"""

from __future__ import annotations

import time

import numpy as np
from scipy import ndimage

from meshmocap.body.shape_space import BodyShapeSpace, load_shape_space
from meshmocap.body.template import Template
from meshmocap.errors import FormatError, InputError, MeshError, MeshmocapFileNotFoundError
from meshmocap.estimate.performer.subject import SubjectEstimate, initial_body_pose
from meshmocap.estimate.pose.first_pose import subsample_points
from meshmocap.estimate.pose.fit import PoseFit, PoseFitter
from meshmocap.estimate.recovery.observe import observed

__all__ = ["closed_surface", "fit_body_to_points", "readable_frame"]


def closed_surface(frame) -> tuple[np.ndarray, np.ndarray]:
    """``(V (n, 3) float64 metres, F (m, 3) int64)``: a closed 2-manifold surface of what a
    frame's points enclose (module docstring, step 1), faces outwards.

    Raises
    ------
    InputError : the frame encloses no solid.
    """
    from skimage.measure import marching_cubes

    hull = frame.hull
    occ = ndimage.gaussian_filter(np.pad(hull.occupancy, 2).astype(np.float32), 0.8)
    if occ.max() <= 0.5:
        raise InputError(f"frame {frame.index}: its points enclose no solid to fit a body to")
    V, F, _, _ = marching_cubes(occ, 0.5, allow_degenerate=False)
    return hull.origin + (V.astype(np.float64) - 2) * hull.voxel_size, F[:, ::-1].astype(np.int64)


def _pose_fit(template: Template, obs, R, root, *, seed: int, settle: bool = True) -> PoseFit:
    """The pose of ``template`` on an observed frame from ``(R, root)``: the refinement of
    the automatic initialisation (:func:`~meshmocap.estimate.pose.first_pose.initial_pose`, step 3),
    model points held inside the observed solid (its signed distance)."""
    P, N = subsample_points(*obs.points, 5000, seed)
    fitter = PoseFitter(template, P, N, n_model_points=1500, field=obs.field, seed=seed)
    fit = fitter.fit(R, root, iterations=30, max_distance=(0.15, 0.03), lambda_pose=1e-4)
    if settle:  # then settle on the near surface, barely held
        fit = fitter.fit(
            fit.R, fit.root, iterations=15, max_distance=(0.04, 0.01), lambda_pose=1e-6
        )
    return fit


def _posed_height(template: Template, R, root) -> float:
    return float(np.ptp(template.pose(R, root).V[:, 2]))


def readable_frame(capture, k: int):
    """Capture frame position ``k`` with its points read, or None where it has none (a
    missing frame, an unreadable or empty file: the driver's ``missing`` frames)."""
    try:
        frame = capture[k]
        if getattr(frame, "missing", None) or len(frame.hull_mesh[0]) < 10:
            return None
    except (MeshmocapFileNotFoundError, FormatError, MeshError):
        return None
    return frame


def _spread_frames(capture, n: int) -> list:
    """Up to ``n`` readable frames: the first, and others evenly spread after it (a frame
    that cannot be read is replaced by the next one that can)."""
    first = next((k for k in range(len(capture)) if readable_frame(capture, k)), None)
    if first is None:
        return []
    out, taken = [], set()
    for k in np.unique(np.linspace(first, len(capture) - 1, n).round().astype(int)):
        for j in range(int(k), len(capture)):
            frame = None if j in taken else readable_frame(capture, j)
            if frame is not None:
                out.append(frame)
                taken.add(j)
                break
    return out


def _scaled_mean(space: BodyShapeSpace, scale: float) -> np.ndarray:
    """``z`` (K,) of the mean body scaled by ``scale`` (projected onto the space)."""
    return space.model.transform(scale * space.model.mean_[None])[0]


def fit_body_to_points(
    capture,
    *,
    n_frames: int = 5,
    size_rounds: int = 3,
    space: BodyShapeSpace | None = None,
    name: str = "subject",
    seed: int = 0,
) -> SubjectEstimate:
    """Estimate the performer's rigged body from a capture's points (module docstring).

    Parameters
    ----------
    capture : a capture whose frames have points (``hull_mesh``) and the solid they enclose
        (``hull``): a :class:`~meshmocap.io.capture.SequenceCapture` of hulls or point
        clouds, or a capture folder.
    n_frames : int
        Frames fitted together: the first one with points, and others evenly spread.
    size_rounds : int
        Pose refits and size updates per frame (step 3).
    space : BodyShapeSpace, optional (default: the bundled one)
    name : str, the template's name
    seed : int, seed of the samples

    Returns
    -------
    SubjectEstimate
        ``kind`` ``"points"``; ``R``, ``root``: each fitted frame's pose, the first frame's
        first; ``rms``: the first pose's fit score
        (:meth:`~meshmocap.estimate.pose.fit.PoseFitter.score`), metres.

    Raises
    ------
    InputError : bad options, or no frame with points.
    """
    func = "fit_body_to_points"
    for what, value in (("n_frames", n_frames), ("size_rounds", size_rounds)):
        if not (isinstance(value, int | np.integer) and value >= 1):
            raise InputError(f"{func}: {what} must be a positive integer, found {value!r}")
    t0 = time.perf_counter()
    space = load_shape_space() if space is None else space
    frames = _spread_frames(capture, n_frames)
    if not frames:
        raise InputError(f"{func}: no frame of {capture.path} has points to fit a body to")
    observed_frames = [observed(f) for f in frames]
    centres = [obs.points[0].mean(axis=0) for obs in observed_frames]
    mean = space.template(np.zeros(space.n_components))
    first = initial_body_pose(mean, *closed_surface(frames[0]), seed=seed)
    # the size that gives each frame's posed body the height of its points (a hull's
    # phantom volumes widen it, never heighten it: a size fitted to the whole hull comes
    # out too large), each pose refitted at each size, the first frame's from the
    # search, the others' from it moved to their points
    scale, poses = first.scale, []
    for k, obs in enumerate(observed_frames):
        R, root = first.R, first.root + centres[k] - centres[0]
        s_k = scale
        for _ in range(size_rounds):
            body = space.template(_scaled_mean(space, s_k))
            fit = _pose_fit(body, obs, R, root, seed=seed, settle=False)
            R, root = fit.R, fit.root
            s_k *= float(np.ptp(obs.points[0][:, 2])) / _posed_height(body, R, root)
        poses.append((R, root, s_k))
    # a pose fitted into a hull's spare room comes out bent more than the body is (shorter,
    # so sized up): the smallest size is the least bent frame's
    scale = float(min(p[2] for p in poses))
    z = _scaled_mean(space, scale)
    template = space.template(z, name=name)
    poses = [(R, root) for R, root, _ in poses]
    final = _pose_fit(template, observed_frames[0], *poses[0], seed=seed)
    poses[0] = (final.R, final.root)
    return SubjectEstimate(
        template,
        "points",
        tuple(int(f.index) for f in frames),
        z,
        np.stack([p[0] for p in poses]),
        np.stack([p[1] for p in poses]),
        float(final.score),
        time.perf_counter() - t0,
        {"scale": scale, "first_score": float(first.rms)},
    )
