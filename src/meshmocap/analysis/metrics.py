"""Accuracy metrics of a capture against ground truth, as pure functions.

Inputs are in the library's units (metres, world frame Z up); joint, bone and
correspondence results are in **millimetres**, surface distances in **metres**, silhouette
errors are ratios (0.05 = 5 %). Results are small frozen dataclasses that
:mod:`meshmocap.analysis.tables` prints or writes as CSV and
:mod:`meshmocap.apps.figures.evaluation` draws.

Frames whose prediction holds NaN or infinite values (a tracker that lost the subject) are
**failures**: listed in ``failed`` and left out of every statistic, never propagated as
NaN. Frames whose ground truth holds NaN (corrupt mocap such as HumanEva-II S4 frames
298–335) are **skipped** and listed in ``skipped``.

The metrics follow the patch-tracking paper (``papers/patch-skeleton-tracking.txt`` §IV):
mean 3D joint error (14 joints without the pelvis: ``exclude=("pelvis",)``), the pixel
overlap error of Table II, bone-length mean and spread (Fig. 6), and per-vertex error on
the fixed connectivity of the crane sequence (Table I's data).

References
----------
- C.-H. Huang, E. Boyer, S. Ilic, *Robust human body shape and pose tracking*,
  International Conference on 3D Vision (3DV), 2013.
- L. Sigal, A. O. Balan, M. J. Black, *HumanEva: synchronized video and motion
  capture dataset and baseline algorithm for evaluation of articulated human motion*,
  International Journal of Computer Vision 87(1–2):4–27, 2010.
  https://doi.org/10.1007/s11263-009-0273-6
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from meshmocap.body.template import EVAL_NAMES
from meshmocap.errors import InputError
from meshmocap.geometry.camera import Camera
from meshmocap.geometry.proximity import point_to_surface, sample_surface
from meshmocap.geometry.silhouette import silhouette

_MM = 1000.0


@dataclass(frozen=True)
class Stats:
    """Mean, median, standard deviation and maximum of some values (units of the data);
    all NaN when there is no value (every frame failed)."""

    mean: float
    median: float
    std: float
    max: float

    @classmethod
    def of(cls, x: np.ndarray) -> Stats:
        x = np.asarray(x, dtype=np.float64).ravel()
        if x.size == 0:
            return cls(np.nan, np.nan, np.nan, np.nan)
        return cls(float(x.mean()), float(np.median(x)), float(x.std()), float(x.max()))


def _names(K: int, names: Sequence[str] | None) -> tuple[str, ...]:
    if names is None:
        names = EVAL_NAMES if len(EVAL_NAMES) == K else [f"joint_{k}" for k in range(K)]
    names = tuple(str(n) for n in names)
    if len(names) != K or len(set(names)) != K:
        raise InputError(f"names must be {K} distinct joint names, found {len(names)}: {names}")
    return names


def _pairs(pred, true, name: str, what: str) -> tuple[np.ndarray, ...]:
    """Validate (T, K, 3) pairs; return P, G and the evaluated, failed and skipped frames."""
    P, G = np.asarray(pred, dtype=np.float64), np.asarray(true, dtype=np.float64)
    P, G = (P[None], G[None]) if P.ndim == 2 and G.ndim == 2 else (P, G)
    if P.ndim != 3 or P.shape[-1] != 3 or P.shape != G.shape:
        raise InputError(
            f"{name}: prediction and truth must both be (T, {what}, 3), "
            f"found {np.shape(pred)} and {np.shape(true)}"
        )
    skipped = ~np.isfinite(G).all(axis=(1, 2))
    failed = ~np.isfinite(P).all(axis=(1, 2)) & ~skipped
    ok = np.flatnonzero(~skipped & ~failed)
    return P, G, ok, np.flatnonzero(failed), np.flatnonzero(skipped)


@dataclass(frozen=True, eq=False)
class _FrameErrors:
    frames: np.ndarray
    errors: np.ndarray
    failed: np.ndarray
    skipped: np.ndarray

    @property
    def per_frame(self) -> np.ndarray:
        """(T',) float64: mean error of each evaluated frame, mm."""
        return self.errors.mean(axis=1) if self.errors.size else np.zeros(len(self.frames))

    @property
    def overall(self) -> Stats:
        """Statistics over all (frame, item) pairs, mm."""
        return Stats.of(self.errors)


# --------------------------------------------------------------------------- joints


@dataclass(frozen=True, eq=False)
class JointErrors(_FrameErrors):
    """Euclidean 3D joint errors, millimetres.

    Attributes
    ----------
    frames : (T',) int64, evaluated frames (indices into the inputs' first axis)
    errors : (T', K) float64, error of each joint in each evaluated frame, mm
    failed, skipped : (·,) int64, frames with non-finite prediction / non-finite truth
    names : tuple of str, length K
    per_frame : (T',) float64, mean over the joints, mm
    per_joint : tuple of K Stats, over the evaluated frames, mm
    overall : Stats over all (frame, joint) pairs, mm; ``overall.mean`` is the papers'
        mean joint error
    """

    names: tuple[str, ...] = ()

    @property
    def per_joint(self) -> tuple[Stats, ...]:
        return tuple(Stats.of(e) for e in self.errors.T)

    def excluding(self, *names: str) -> JointErrors:
        """Return the errors without joints ``names`` (``"pelvis"``: the 14-joint variant)."""
        unknown = [n for n in names if n not in self.names]
        if unknown:
            raise InputError(f"exclude: unknown joints {unknown}; joints are {list(self.names)}")
        keep = [i for i, n in enumerate(self.names) if n not in names]
        return JointErrors(
            self.frames,
            self.errors[:, keep],
            self.failed,
            self.skipped,
            tuple(self.names[i] for i in keep),
        )


def joint_errors(
    pred: np.ndarray,
    true: np.ndarray,
    *,
    names: Sequence[str] | None = None,
    exclude: Sequence[str] = (),
) -> JointErrors:
    """Per-frame, per-joint Euclidean error between predicted and true joints.

    Parameters
    ----------
    pred, true : (T, K, 3) float
        Joint positions, metres, one world frame; ``(K, 3)`` for one frame. Non-finite
        values in ``pred`` make the frame a failure, in ``true`` a skipped frame.
    names : sequence of K str, optional
        Default :data:`meshmocap.body.template.EVAL_NAMES` when K = 15, else ``joint_k``.
    exclude : sequence of str
        Joints left out, e.g. ``("pelvis",)`` for the 14 joints of the patch-tracking paper.
    """
    P, G, ok, failed, skipped = _pairs(pred, true, "joint_errors", "K")
    err = np.linalg.norm(P[ok] - G[ok], axis=-1) * _MM
    result = JointErrors(ok, err, failed, skipped, _names(P.shape[1], names))
    return result.excluding(*exclude) if exclude else result


# --------------------------------------------------------------------------- vertices


@dataclass(frozen=True, eq=False)
class CorrespondenceErrors(_FrameErrors):
    """Per-vertex errors of a tracked fixed-connectivity surface, millimetres.

    Attributes
    ----------
    frames, failed, skipped : as in :class:`JointErrors`
    errors : (T', n) float64, distance of each tracked vertex to its true position, mm
    per_frame : (T',) float64, mean over the vertices of each frame, mm
    per_vertex : (n,) float64, mean over the frames (where the tracker drifts), mm
    overall : Stats over all (frame, vertex) pairs, mm
    """

    @property
    def per_vertex(self) -> np.ndarray:
        return (
            self.errors.mean(axis=0) if len(self.errors) else np.full(self.errors.shape[1], np.nan)
        )


def correspondence_error(V_tracked: np.ndarray, V_true: np.ndarray) -> CorrespondenceErrors:
    """Euclidean distance between tracked and true positions of every vertex, mm.

    Parameters
    ----------
    V_tracked, V_true : (T, n, 3) float
        Vertices in corresponding order (e.g. the crane sequence, whose connectivity is the
        same in every frame), metres; ``(n, 3)`` for one frame.
    """
    P, G, ok, failed, skipped = _pairs(V_tracked, V_true, "correspondence_error", "n")
    return CorrespondenceErrors(ok, np.linalg.norm(P[ok] - G[ok], axis=-1) * _MM, failed, skipped)


# --------------------------------------------------------------------------- silhouettes


def silhouette_overlap_error(mask_pred: np.ndarray, mask_true: np.ndarray) -> float:
    """Pixels of ``mask_pred XOR mask_true`` over pixels of ``mask_true``.

    The pixel overlap error of Table II of the patch-tracking paper ("the ratio of erroneous
    pixels and the total number of pixels in the original silhouette"): 0 for identical
    masks, may exceed 1. ``mask_pred``, ``mask_true``: (H, W) bool, one camera.
    """
    x, n = _xor_true(mask_pred, mask_true)
    return x / n


def _xor_true(mask_pred, mask_true) -> tuple[int, int]:
    A, B = np.asarray(mask_pred, dtype=bool), np.asarray(mask_true, dtype=bool)
    if A.shape != B.shape or A.ndim != 2:
        raise InputError(
            f"masks must be two (H, W) arrays of one shape, found {A.shape}, {B.shape}"
        )
    n = int(np.count_nonzero(B))
    if n == 0:
        raise InputError("mask_true is empty: the overlap error is undefined")
    return int(np.count_nonzero(A ^ B)), n


@dataclass(frozen=True, eq=False)
class SilhouetteErrors:
    """Pixel overlap errors per frame and camera (ratios, 0.05 = 5 %).

    Attributes
    ----------
    cameras : tuple of C str
    xor_pixels, true_pixels : (T, C) int64, the counts behind each ratio
    errors : (T, C) float64, XOR pixels / true silhouette pixels
    per_camera : (C,) float64, mean ratio of each camera over the frames
    overall : float, mean ratio over all frames and cameras (the paper's figure)
    pooled : float, all XOR pixels over all true pixels (big silhouettes weigh more)
    """

    cameras: tuple[str, ...]
    xor_pixels: np.ndarray
    true_pixels: np.ndarray

    @property
    def errors(self) -> np.ndarray:
        """(T, C) ratios; NaN where the camera does not see the subject (empty true mask)."""
        seen = self.true_pixels > 0
        return np.divide(
            self.xor_pixels, self.true_pixels, out=np.full(seen.shape, np.nan), where=seen
        )

    @property
    def per_camera(self) -> np.ndarray:
        return np.array([nan_mean(e) for e in self.errors.T])

    @property
    def overall(self) -> float:
        return nan_mean(self.errors)

    @property
    def pooled(self) -> float:
        n = self.true_pixels.sum()
        return float(self.xor_pixels.sum() / n) if n else math.nan  # nothing scored: NaN


def nan_mean(x: np.ndarray) -> float:
    """Mean of the finite entries of ``x`` (NaN when there is none), without a warning."""
    x = np.asarray(x, dtype=np.float64)
    ok = ~np.isnan(x)
    return float(x.mean()) if ok.all() else float(x[ok].mean()) if ok.any() else math.nan


def silhouette_errors(
    masks_pred: Iterable[Sequence[np.ndarray]],
    masks_true: Iterable[Sequence[np.ndarray]],
    *,
    cameras: Sequence[str] | None = None,
    skip: Sequence[int] = (),
) -> SilhouetteErrors:
    """Overlap errors of many frames, each seen by the same C cameras.

    Parameters
    ----------
    masks_pred, masks_true : iterables over frames of C (H_c, W_c) bool masks
        Arrays (T, C, H, W), or generators yielding one frame's masks at a time (cameras
        may differ in image size); both yield the same number of frames.
    cameras : sequence of C str, optional
        Camera names; default ``cam0 ...``.
    skip : sequence of int
        Positions of frames not scored (NaN in every camera, like a camera that does not
        see the subject): frames where the subject leaves a view; their predicted masks
        may be None.
    """
    counts = []
    skipped = {int(k) for k in skip}
    for t, (mp, mt) in enumerate(zip(masks_pred, masks_true, strict=True)):
        if t in skipped:
            counts.append([(0, 0)] * len(mt))
            continue
        if len(mp) != len(mt) or (counts and len(mp) != len(counts[0])):
            want = len(counts[0]) if counts else len(mt)
            raise InputError(f"frame {t}: {len(mp)} predicted, {len(mt)} true masks; want {want}")
        # a camera that does not see the subject (empty true mask) is not scored: (0, 0)
        counts.append(
            [_xor_true(a, b) if np.any(b) else (0, 0) for a, b in zip(mp, mt, strict=True)]
        )
    if not counts or not counts[0]:
        raise InputError("silhouette_errors: no frames or no cameras given")
    X = np.array(counts, dtype=np.int64)  # (T, C, 2)
    C = X.shape[1]
    names = tuple(cameras) if cameras is not None else tuple(f"cam{c}" for c in range(C))
    if len(names) != C:
        raise InputError(f"cameras must name {C} cameras, found {len(names)}")
    return SilhouetteErrors(names, X[..., 0], X[..., 1])


def mesh_silhouette(V: np.ndarray, F: np.ndarray, camera: Camera) -> np.ndarray:
    """Return the (H, W) bool silhouette of mesh ``(V, F)`` (metres, world) seen by ``camera``."""
    return silhouette(np.asarray(V, dtype=np.float64), np.asarray(F), camera)


def mesh_silhouette_errors(
    meshes_pred: Iterable[tuple[np.ndarray, np.ndarray]],
    masks_true: Iterable[Sequence[np.ndarray]],
    cameras: Sequence[Camera],
    *,
    skip: Sequence[int] = (),
) -> SilhouetteErrors:
    """Overlap errors of tracked meshes reprojected into calibrated cameras.

    Parameters
    ----------
    meshes_pred : iterable of (V (n, 3), F (m, 3)), the tracked surface of each frame,
        metres, world frame; streamed (one frame's silhouettes in memory at a time)
    masks_true : iterable over frames of C (H, W) bool masks, in the order of ``cameras``
    cameras : sequence of C Camera
    skip : sequence of int
        Positions of frames not scored (not rendered): see :func:`silhouette_errors`.
    """
    skipped = {int(k) for k in skip}
    pred = (
        None if t in skipped else [mesh_silhouette(V, F, cam) for cam in cameras]
        for t, (V, F) in enumerate(meshes_pred)
    )
    names = [c.name or f"cam{i}" for i, c in enumerate(cameras)]
    return silhouette_errors(pred, masks_true, cameras=names, skip=sorted(skipped))


# --------------------------------------------------------------------------- bones


def bone_lengths(joints: np.ndarray, parents: Sequence[int]) -> np.ndarray:
    """Length of each bone (joint to parent), per frame.

    Parameters
    ----------
    joints : (T, K, 3) or (K, 3) float, any unit (the result has the same)
    parents : (K,) int, parent of each joint, −1 for the root

    Returns
    -------
    (T, B) or (B,) float64: bones in the order of their child joint (B = K − 1 for a tree).
    """
    J, par = np.asarray(joints, dtype=np.float64), np.asarray(parents, dtype=np.int64)
    if J.ndim not in (2, 3) or J.shape[-1] != 3 or par.shape != (J.shape[-2],):
        raise InputError(
            f"joints must be (T, K, 3) with K = len(parents) = {par.size}, found {J.shape}"
        )
    if (par >= len(par)).any() or (par < -1).any():
        raise InputError(f"parents must lie in [-1, {len(par) - 1}], found {par.tolist()}")
    child = np.flatnonzero(par >= 0)
    return np.linalg.norm(J[..., child, :] - J[..., par[child], :], axis=-1)


@dataclass(frozen=True, eq=False)
class BoneLengths:
    """Bone lengths over a sequence, millimetres (Fig. 6 of the patch-tracking paper).

    Attributes
    ----------
    names : tuple of B str, ``"parent-child"`` joint names of each bone
    frames, failed : (·,) int64, evaluated frames / frames with non-finite joints
    lengths : (T', B) float64, mm
    mean, std : (B,) float64, each bone's mean length and its standard deviation over the
        frames, mm: 0 for a rigid skeleton; the spread shows how much a tracker stretches.
    """

    names: tuple[str, ...]
    frames: np.ndarray
    failed: np.ndarray
    lengths: np.ndarray

    @property
    def mean(self) -> np.ndarray:
        return self.lengths.mean(axis=0) if len(self.lengths) else np.full(len(self.names), np.nan)

    @property
    def std(self) -> np.ndarray:
        return self.lengths.std(axis=0) if len(self.lengths) else np.full(len(self.names), np.nan)


def bone_length_stats(
    joints: np.ndarray, parents: Sequence[int], *, names: Sequence[str] | None = None
) -> BoneLengths:
    """Bone lengths of a joint sequence with their mean and spread, millimetres.

    Parameters
    ----------
    joints : (T, K, 3) float, metres; frames with non-finite joints are failures
    parents : (K,) int, −1 for the root (e.g. :data:`~meshmocap.body.template.EVAL_PARENTS`)
    names : sequence of K str, optional (default as in :func:`joint_errors`)
    """
    J = np.asarray(joints, dtype=np.float64)
    J = J[None] if J.ndim == 2 else J
    L = bone_lengths(J, parents)
    names, par = _names(J.shape[1], names), np.asarray(parents)
    bones = tuple(f"{names[par[k]]}-{names[k]}" for k in np.flatnonzero(par >= 0))
    ok = np.isfinite(J).all(axis=(1, 2))
    return BoneLengths(bones, np.flatnonzero(ok), np.flatnonzero(~ok), L[ok] * _MM)


# --------------------------------------------------------------------------- surfaces


@dataclass(frozen=True)
class DistanceStats:
    """Distances from samples of one surface to another, metres: mean, RMS, 95th
    percentile, maximum, and the number of samples ``n``."""

    mean: float
    rms: float
    p95: float
    max: float
    n: int

    @classmethod
    def of(cls, d: np.ndarray) -> DistanceStats:
        return cls(
            float(d.mean()),
            float(np.sqrt((d**2).mean())),
            float(np.percentile(d, 95)),
            float(d.max()),
            int(d.size),
        )


@dataclass(frozen=True)
class SurfaceDistance:
    """Two-sided surface distance between meshes A and B, metres.

    Attributes
    ----------
    a_to_b : DistanceStats, samples of A → surface B (how far A strays from B)
    b_to_a : DistanceStats, samples of B → surface A (what of B that A misses)
    bound : float, metres: no sampled distance overestimates the exact one by more
    """

    a_to_b: DistanceStats
    b_to_a: DistanceStats
    bound: float

    @property
    def mean(self) -> float:
        """Symmetric mean (average of both directions), metres."""
        return 0.5 * (self.a_to_b.mean + self.b_to_a.mean)

    @property
    def hausdorff(self) -> float:
        """Sampled Hausdorff distance (larger of both maxima), metres."""
        return max(self.a_to_b.max, self.b_to_a.max)


def surface_distance(
    V_a: np.ndarray,
    F_a: np.ndarray,
    V_b: np.ndarray,
    F_b: np.ndarray,
    *,
    n_samples: int = 20_000,
    seed: int | None = 0,
    tol: float | None = None,
) -> SurfaceDistance:
    """Distances between two surfaces, sampled in both directions.

    ``n_samples`` points drawn uniformly by area on A (seeded) are measured to the surface
    of B with :func:`point_to_surface`, and as many on B to A.

    Parameters
    ----------
    V_a, F_a, V_b, F_b : (n, 3) float and (m, 3) int, the meshes, metres, same frame
    n_samples : int, samples per direction (sampling noise of the statistics ~ 1/√n)
    seed : int, seed of the sampling (results are reproducible)
    tol : float, optional, accuracy of each distance (see :func:`point_to_surface`)
    """
    (Va, Fa), (Vb, Fb) = _mesh(V_a, F_a, "a"), _mesh(V_b, F_b, "b")
    if int(n_samples) < 1:
        raise InputError(f"n_samples must be positive, found {n_samples}")
    rng = np.random.default_rng(seed)
    pa, _ = sample_surface(Va, Fa, int(n_samples), seed=rng)
    pb, _ = sample_surface(Vb, Fb, int(n_samples), seed=rng)
    d_ab, bound_b = point_to_surface(pa, Vb, Fb, tol=tol)
    d_ba, bound_a = point_to_surface(pb, Va, Fa, tol=tol)
    return SurfaceDistance(DistanceStats.of(d_ab), DistanceStats.of(d_ba), max(bound_a, bound_b))


def _mesh(V, F, name: str) -> tuple[np.ndarray, np.ndarray]:
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or not np.isfinite(V).all():
        raise InputError(f"V_{name} must be finite (n, 3) vertices, found {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or not len(F) or F.min() < 0 or F.max() >= len(V):
        raise InputError(f"F_{name} must be (m, 3) indices into V_{name}, found {F.shape}")
    return V, F.astype(np.int64)
