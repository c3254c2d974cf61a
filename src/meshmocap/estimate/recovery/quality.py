"""How well a tracked frame explains its observations, limb by limb: the fit-quality score
that flags a frame ``lost`` (:data:`meshmocap.io.results.FRAME_FLAGS`).

Three measures, each per limb (:data:`LIMB_PARTS`, from the template's per-vertex body
parts):

* **outside** — the fraction of the limb's vertices standing more than
  :data:`OUTSIDE_MARGIN` outside the observed solid (the visual hull, or the solid a mesh or
  point cloud bounds). A visual hull contains the body, so a limb tracked where the
  performer's limb is stands inside it; a limb outside it is not where the data says.
* **buried** — the fraction of the limb's vertices deeper than :data:`BURIED_DEPTH` inside
  the observed solid. A tracked surface lies on the observations' surface (a visual
  hull's a few millimetres out, more in its phantom volumes); a limb sunk into the trunk
  explains no observation (typically while the observations miss that limb: nothing pulls
  it out, and nothing outside it shows it is wrong).
* **unexplained** — observed surface points farther than :data:`UNEXPLAINED_DISTANCE`
  from every tracked vertex, as a fraction of all observed points, each counted for the
  limb of its nearest tracked vertex (the trunk's for the nearest vertex of another limb,
  :data:`UNEXPLAINED_ELSEWHERE`). Something is there that no part of the model explains:
  typically the real limb, while the model's is elsewhere. A hull's phantom volumes leave
  some such points on every frame, so the threshold sits above them.

:func:`fit_quality` names a limb lost when any measure passes its threshold here
(:data:`OUTSIDE_LOST`, :data:`BURIED_LOST`, :data:`UNEXPLAINED_LOST`): what the recovery
holds and searches again. The ``lost`` flag a track carries comes from these measures and
others through the calibrated rule of :mod:`~meshmocap.estimate.recovery.evidence`.
Metres, world frame Z up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap.body.template import Template
from meshmocap.geometry.camera import Camera, project
from meshmocap.geometry.distance_field import DistanceGrid
from meshmocap.geometry.nearby import farther_than
from meshmocap.geometry.silhouette import covered_pixels

__all__ = [
    "BURIED_DEPTH",
    "BURIED_LOST",
    "LIMB_PARTS",
    "OUTSIDE_LOST",
    "OUTSIDE_MARGIN",
    "UNEXPLAINED_DISTANCE",
    "UNEXPLAINED_ELSEWHERE",
    "UNEXPLAINED_LOST",
    "UNSEEN_LOST",
    "UNSEEN_MARGIN",
    "FitQuality",
    "fit_quality",
    "limb_labels",
    "limb_shares",
    "uncovered_points",
]

#: Limbs named in flags → the evaluation joints whose body parts make them.
LIMB_PARTS: dict[str, tuple[str, ...]] = {
    "torso": ("pelvis", "thorax"),
    "head": ("head",),
    "left_arm": ("left_shoulder", "left_elbow", "left_wrist"),
    "right_arm": ("right_shoulder", "right_elbow", "right_wrist"),
    "left_leg": ("left_hip", "left_knee", "left_ankle"),
    "right_leg": ("right_hip", "right_knee", "right_ankle"),
}
#: Metres a vertex may stand outside the observed solid before it counts as outside (the
#: voxels' rounding, a performer slimmer than the template).
OUTSIDE_MARGIN = 0.03
#: Fraction of a limb's vertices outside beyond which the limb is lost.
OUTSIDE_LOST = 0.4
#: Metres inside the observed solid beyond which a vertex counts as buried.
BURIED_DEPTH = 0.04
#: Fraction of a limb's vertices buried beyond which the limb is lost.
BURIED_LOST = 0.5
#: Metres outside the observed solid beyond which a vertex of a limb posed as when last
#: seen counts as unseen (wider than OUTSIDE_MARGIN: the limb has moved for a frame since).
UNSEEN_MARGIN = 0.05
#: Fraction of such a limb outside beyond which the observations miss it.
UNSEEN_LOST = 0.4
#: Metres from the nearest tracked vertex beyond which an observed point is unexplained.
UNEXPLAINED_DISTANCE = 0.08
#: Metres from the nearest tracked vertex beyond which an observed point imaging into
#: uncovered silhouette pixels is unexplained.
SILHOUETTE_DISTANCE = 0.03
#: Fraction of all observed points, unexplained and nearest to one limb, beyond which that
#: limb is lost.
UNEXPLAINED_LOST = 0.1
#: Limbs whose unexplained points are counted for the nearest vertex of the other limbs. An
#: observed point by the tracked trunk that no vertex explains is nearly always a limb the
#: tracker has put elsewhere (an arm hanging by the trunk while the tracked arm points
#: away, or stuck inside the trunk), seldom the trunk itself, which every tracker fits
#: first: counted for the trunk, they named the trunk when an arm was lost
#: (``docs/measurements.rst``).
UNEXPLAINED_ELSEWHERE = ("torso",)


def limb_labels(template: Template) -> np.ndarray:
    """(n,) int64: each template vertex's limb, an index into ``list(LIMB_PARTS)`` (−1 for
    a part no limb lists)."""
    names = template.eval_skeleton.names
    part_limb = np.full(len(names), -1, dtype=np.int64)
    for k, parts in enumerate(LIMB_PARTS.values()):
        for p in parts:
            if p in names:
                part_limb[names.index(p)] = k
    return part_limb[template.part_labels]


@dataclass(frozen=True, eq=False)
class FitQuality:
    """The fit quality of one frame.

    Attributes
    ----------
    outside : dict of limb → float, fraction of the limb's vertices outside the solid
    buried : dict of limb → float, fraction of the limb's vertices deep inside it
    unexplained : dict of limb → float, fraction of the observed points unexplained and
        nearest to the limb
    lost : tuple of str, the limbs past a threshold, in :data:`LIMB_PARTS` order
    unseen : dict of limb → float, where known: fraction of the limb, posed as when last
        seen on the tracked trunk, outside the observations (the observations miss it:
        :class:`~meshmocap.estimate.recovery.reinit.Recovery`)
    evidence : (L, E) float64 or None, where known: each limb's evidence
        (:data:`~meshmocap.estimate.recovery.evidence.EVIDENCE`), from which ``lost`` was
        decided (:func:`~meshmocap.estimate.recovery.evidence.lost_limbs`)
    reasons : dict of limb → str, where known: why each lost limb is lost
    """

    outside: dict[str, float]
    buried: dict[str, float]
    unexplained: dict[str, float]
    lost: tuple[str, ...]
    unseen: dict[str, float] = field(default_factory=dict)
    evidence: np.ndarray | None = None
    reasons: dict[str, str] = field(default_factory=dict)

    @property
    def total_unexplained(self) -> float:
        """Fraction of the observed points no tracked vertex explains."""
        return float(sum(self.unexplained.values()))

    def energies(self) -> dict[str, float]:
        """The frame's quality as energy terms of its result: the largest outside fraction
        of any limb and the total unexplained fraction."""
        return {
            "fit_outside": max(self.outside.values(), default=0.0),
            "fit_buried": max(self.buried.values(), default=0.0),
            "fit_unexplained": self.total_unexplained,
        }

    def describe(self) -> str:
        """One line naming each lost limb and why (empty when none is lost)."""
        parts = []
        for limb in self.lost:
            if limb in self.reasons:
                parts.append(f"{limb} ({self.reasons[limb]})")
                continue
            why = []
            if self.outside[limb] > OUTSIDE_LOST:
                why.append(f"{100 * self.outside[limb]:.0f}% outside the observations")
            if self.buried[limb] > BURIED_LOST:
                why.append(f"{100 * self.buried[limb]:.0f}% buried in the body")
            if self.unexplained[limb] > UNEXPLAINED_LOST:
                why.append(f"{100 * self.unexplained[limb]:.1f}% of the points unexplained")
            if self.unseen.get(limb, 0.0) > UNSEEN_LOST:
                why.append("not observed where it was last seen")
            parts.append(f"{limb} ({', '.join(why)})")
        return "; ".join(parts)


def limb_shares(labels: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Per limb, the fraction of its vertices (``labels``, :func:`limb_labels`) where
    ``mask`` (n,) bool holds."""
    n = len(LIMB_PARTS)
    on = labels >= 0
    counts = np.maximum(np.bincount(labels[on], minlength=n), 1)
    hits = np.bincount(labels[mask & on], minlength=n)
    return {name: float(hits[k] / counts[k]) for k, name in enumerate(LIMB_PARTS)}


def uncovered_points(
    V: np.ndarray,
    F: np.ndarray,
    P: np.ndarray,
    cameras: list[Camera],
    masks: list[np.ndarray],
) -> np.ndarray:
    """(p,) bool: the observed points that image into silhouette pixels the tracked mesh
    leaves uncovered, in at least one camera. A visual hull's phantom volume images into
    pixels the body covers (along other rays), so with a good fit only rounding at the
    silhouettes' edges (their outermost pixel is not counted) is left.

    Parameters
    ----------
    V : (n, 3) float64, tracked vertices, metres; ``F`` (m, 3) int, the template's faces
    P : (p, 3) float64, observed points, metres
    cameras : list of Camera; ``masks`` : list of (height, width) bool, one per camera
    """
    hit = np.zeros(len(P), dtype=bool)
    for cam, mask in zip(cameras, masks, strict=True):
        todo = np.flatnonzero(~hit)
        if todo.size == 0:
            break
        uv, depth = project(P[todo], cam.K, cam.R, cam.t)
        px = np.round(uv).astype(np.int64)
        h, w = mask.shape
        # inside the mask eroded by its 4-neighbours (ndimage.binary_erosion's default,
        # border pixels eroded), looked up at the points' pixels only
        ok = (depth > 0) & (px[:, 0] >= 1) & (px[:, 0] < w - 1)
        ok &= (px[:, 1] >= 1) & (px[:, 1] < h - 1)
        x, y = px[ok, 0], px[ok, 1]
        core = mask[y, x] & mask[y - 1, x] & mask[y + 1, x] & mask[y, x - 1] & mask[y, x + 1]
        sel = np.flatnonzero(ok)[core]
        if sel.size == 0:  # no point images into the silhouette: nothing to render
            continue
        # the tracked mesh's silhouette (assume_closed) at those pixels only
        with np.errstate(over="ignore", invalid="ignore"):
            uvm, zm = cam.project(V)
        covered = covered_pixels(uvm, F, px[sel], cam.shape, valid=zm > 0, orientation="positive")
        hit[todo[sel]] = ~covered
    return hit


def _elsewhere(near: np.ndarray, V: np.ndarray, labels: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(q,) int64: the limbs ``near`` of the unexplained points ``Q`` (q, 3), those of the
    limbs of :data:`UNEXPLAINED_ELSEWHERE` replaced by the limb of the nearest vertex of
    ``V`` (n, 3) on another limb (``labels``, :func:`limb_labels`)."""
    names = list(LIMB_PARTS)
    moved = np.isin(near, [names.index(n) for n in UNEXPLAINED_ELSEWHERE])
    others = np.flatnonzero(
        np.isin(labels, [k for k, n in enumerate(names) if n not in UNEXPLAINED_ELSEWHERE])
    )
    if not moved.any() or others.size == 0:
        return near
    _, j = KDTree(np.ascontiguousarray(V[others])).query(np.ascontiguousarray(Q[moved]), k=1)
    out = near.copy()
    out[moved] = labels[others[np.asarray(j, dtype=np.int64)]]
    return out


def fit_quality(
    V: np.ndarray,
    labels: np.ndarray,
    P: np.ndarray,
    field: DistanceGrid,
    *,
    F: np.ndarray | None = None,
    cameras: list[Camera] | None = None,
    masks: list[np.ndarray] | None = None,
    max_points: int = 4000,
    seed: int = 0,
    sdf: np.ndarray | None = None,
    sides: np.ndarray | None = None,
) -> FitQuality:
    """Score a tracked frame against its observations (module docstring).

    Parameters
    ----------
    V : (n, 3) float64
        Tracked template vertices, metres, world frame.
    labels : (n,) int64
        Each vertex's limb (:func:`limb_labels`).
    P : (p, 3) float64
        Observed surface points, metres.
    field : DistanceGrid
        Signed distance of the observed solid (negative inside), metres.
    F, cameras, masks : optional
        The template's faces, the capture's cameras and the frame's silhouettes: where
        given, an observed point far from the tracked mesh is unexplained only if it
        also images into silhouette pixels the mesh leaves uncovered
        (:func:`uncovered_points`): a visual hull's phantom volume is far from the body
        but covered by it in every image.
    max_points : int
        At most this many observed points are checked (a seeded subsample).
    seed : int
        Seed of that subsample.
    sdf : (n,) float64, optional
        The signed distance of the observed solid at ``V``, metres, where the caller has
        it (default: ``field(V)``).
    sides : (n,) int8, optional
        Instead of ``sdf``, where it stands at ``V``: +1 more than :data:`OUTSIDE_MARGIN`
        outside, −1 deeper than :data:`BURIED_DEPTH` inside, 0 between (all this score
        reads of it: :meth:`~meshmocap.geometry.distance_field.LazyDistanceGrid.side_of`).

    Returns
    -------
    FitQuality
    """
    limbs = list(LIMB_PARTS)
    if len(P) > max_points:
        # the seeded sample in the points' own order (a mesh's vertex order, spatially
        # coherent: the nearest vertices and the silhouettes are looked up faster); every
        # measure counts points, so their order changes no answer
        P = P[np.sort(np.random.default_rng(seed).choice(len(P), max_points, replace=False))]
    if sides is None:
        sdf = field(V) if sdf is None else sdf
        sides = np.where(sdf > OUTSIDE_MARGIN, 1, np.where(sdf < -BURIED_DEPTH, -1, 0))
    outside = limb_shares(labels, sides > 0)
    buried = limb_shares(labels, sides < 0)
    # the points far from every tracked vertex (pykdtree's unbounded d > r: the answers of
    # its nearest distances), then the nearest vertex of the unexplained ones alone
    if cameras and masks is not None and F is not None:
        # only the points this far can be unexplained: only they are imaged
        far = farther_than(P, V, radius=SILHOUETTE_DISTANCE, at_radius="near")
        far[far] = uncovered_points(V, F, P[far], cameras, masks)
    else:
        far = farther_than(P, V, radius=UNEXPLAINED_DISTANCE, at_radius="near")
    near = np.zeros(0, dtype=np.int64)
    if far.any():
        tree = KDTree(np.ascontiguousarray(V))
        near = labels[np.asarray(tree.query(np.ascontiguousarray(P[far]), k=1)[1], dtype=np.int64)]
    near = _elsewhere(near, V, labels, P[far])
    votes = np.bincount(near[near >= 0], minlength=len(limbs)) / max(len(P), 1)
    unexplained = {n: float(votes[k]) for k, n in enumerate(limbs)}
    lost = tuple(
        n
        for n in limbs
        if outside[n] > OUTSIDE_LOST or buried[n] > BURIED_LOST or unexplained[n] > UNEXPLAINED_LOST
    )
    return FitQuality(outside, buried, unexplained, lost)
