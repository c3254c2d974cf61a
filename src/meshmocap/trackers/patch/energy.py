"""The patch tracker's energy as a list of terms (patch-skeleton-tracking.txt §III)

    E(Θ, J) = λr Er(Θ) + λd Edata(Θ) + λb Ebone(Θ, J)                              # Eq. (1)

and, beyond the paper, any of the extension terms below. A term is a small frozen
dataclass with a ``name`` and a ``weight``: :meth:`Term.add` adds its rows to one
Gauss–Newton :class:`~meshmocap.trackers.patch.solver.System` and returns its value (a
mean squared residual, metres²). A step assembles every term of the list into one system
(:func:`assemble`) and solves it; the frame's total energy is the sum over the same list
(:func:`total_energy`), each value times the term's :attr:`Term.coefficient`.

The terms of Eq. (1) (:func:`paper_terms`): :class:`DataTerm` (Eq. 7), :class:`RigidityTerm`
(Eq. 2), :class:`BoneTerm` (Eq. 11). The extensions: :class:`ReverseTerm`,
:class:`LengthTerm`, :class:`SilhouetteTerm`, :class:`TemporalTerm`. Which terms a tracker
uses follows from its :class:`~meshmocap.trackers.patch.options.PatchOptions`
(:func:`energy_terms`): a zero weight leaves a term out.

Each term is normalised by its own total weight (a mean squared residual, metres²), so the
weights compare mean squared residuals whatever the number of points, patches or vertices.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar, Protocol

import numpy as np
from pykdtree.kdtree import KDTree

from meshmocap.geometry.camera import Camera, in_view
from meshmocap.io.capture import CaptureFrame
from meshmocap.trackers.patch.model import PatchModel
from meshmocap.trackers.patch.options import PatchOptions
from meshmocap.trackers.patch.solver import (
    RigidityMoments,
    System,
    add_bone,
    add_bone_lengths,
    add_plane_terms,
    add_point_terms,
    add_rigidity,
)
from meshmocap.trackers.patch.terms import (
    SilhouetteRays,
    add_joint_prior,
    add_silhouette,
    silhouette_rays,
)

#: Scale of the rigidity and bone terms relative to the data term after each is normalised
#: by its total weight (mean squared residuals). Neighbouring patches' predictions and the
#: bone points stay within millimetres, the data within centimetres: without this factor the
#: paper's λr = λb = 1 against λd = 10 lets patches drift apart (tuned on synthetic walks;
#: see benchmarks/bench_patch.py).
RIGIDITY_SCALE = 10.0
BONE_SCALE = 100.0
#: Weight of the point-to-point pull that keeps point-to-plane residuals from sliding freely.
PLANE_POINT_MIX = 0.1


@dataclass(frozen=True, eq=False)
class Correspondences:
    """The E-step's soft assignments: one row per (observed point, patch) pair.

    Attributes
    ----------
    patch : (m,) int, the patch; vertex : (m,) int, its candidate vertex
    weight : (m,) float64, the posterior weight w_i^k of Eq. (7)
    point : (m, 3) float64, the observed point, metres; normal : (m, 3) its unit normal
    """

    patch: np.ndarray
    vertex: np.ndarray
    weight: np.ndarray
    point: np.ndarray
    normal: np.ndarray


@dataclass(eq=False)
class FrameData:
    """What the terms read that stays fixed over one frame's iterations.

    Attributes
    ----------
    model : PatchModel; moments : RigidityMoments (Eq. 2's precomputed sums)
    Y : (m, 3) kept observed points, metres; NY : (m, 3) their unit normals
    cameras : list of Camera (empty for a mesh or point-cloud sequence)
    frame : CaptureFrame or None, where the silhouettes are read (SilhouetteTerm)
    X_hat : (K, 3) joints' constant-velocity prediction, metres (TemporalTerm)
    pairs : (p, 2) int, joint pairs whose distance the length prior holds; lengths : (p,)
    reverse_sample : (r,) int, template vertices of the reverse term
    cover_sample : (s,) int, template vertices of the silhouette term; cover_radius : metres
    normal_cos : float, normal compatibility of correspondences (``PatchOptions.normal_cos``)
    """

    model: PatchModel
    moments: RigidityMoments
    Y: np.ndarray
    NY: np.ndarray
    cameras: list[Camera]
    frame: CaptureFrame | None
    X_hat: np.ndarray
    pairs: np.ndarray
    lengths: np.ndarray
    reverse_sample: np.ndarray
    cover_sample: np.ndarray
    cover_radius: float
    normal_cos: float

    @cached_property
    def tree(self) -> KDTree:
        """k-d tree of the kept observed points (built at first use, once a frame)."""
        return KDTree(self.Y)

    @cached_property
    def rays(self) -> SilhouetteRays | None:
        """The frame's silhouette samples and rays, or None without cameras and masks."""
        masks = frame_masks(self.frame) if self.frame is not None and self.cameras else []
        return silhouette_rays(self.cameras, masks) if masks else None


@dataclass(frozen=True, eq=False)
class Iterate:
    """One Gauss–Newton iteration's linearisation point.

    Attributes
    ----------
    frame : FrameData
    R : (P, 3, 3) patch rotations; c : (P, 3) patch centres; X : (K, 3) joints (metres)
    V : (n, 3) each vertex as its own patch predicts it; N : (n, 3) its unit normal
    corr : Correspondences, this iteration's E-step
    """

    frame: FrameData
    R: np.ndarray
    c: np.ndarray
    X: np.ndarray
    V: np.ndarray
    N: np.ndarray
    corr: Correspondences


class Term(Protocol):
    """One term of the energy.

    Attributes
    ----------
    name : str, its key in a frame's energies
    weight : float, its λ
    scale : float (class constant), fixed factor on ``weight`` (:data:`RIGIDITY_SCALE`…)
    """

    name: ClassVar[str]
    scale: ClassVar[float]
    weight: float

    @property
    def coefficient(self) -> float:
        """``weight · scale``: the factor on :meth:`add`'s value in the total energy."""
        ...

    def add(self, sys: System, it: Iterate) -> float:
        """Add ``coefficient · value`` to ``sys`` (its Gauss–Newton rows) and return the
        value at ``it`` (metres²)."""
        ...


class _Weighted:
    """Mixin: :attr:`Term.coefficient` from ``weight`` and the class's ``scale``."""

    scale: ClassVar[float] = 1.0
    weight: float

    @property
    def coefficient(self) -> float:
        return self.weight * self.scale


@dataclass(frozen=True)
class DataTerm(_Weighted):
    """Edata of Eq. (7): ``Σ w_i^k |y_i − x(v_i^k)|² / Σ w`` over the E-step's pairs;
    ``residual="point_to_plane"`` measures along the observed normals instead (plus
    :data:`PLANE_POINT_MIX` of the Euclidean pull, not counted in the value)."""

    name: ClassVar[str] = "data"
    weight: float = 10.0
    residual: str = "point_to_point"

    def add(self, sys: System, it: Iterate) -> float:
        k = it.corr
        patch, v, w, y = k.patch, k.vertex, k.weight, k.point
        q = it.V[v] - it.c[patch]  # R_k (v0 − c0_k): v is a vertex of its patch k
        r = it.V[v] - y
        wd = max(float(w.sum()), 1e-12)
        if self.residual == "point_to_plane":  # slide along the surface, with a little pull
            s_n = np.sum(k.normal * r, axis=1)
            e = add_plane_terms(sys, patch, q, k.normal, s_n, w, self.coefficient / wd)
            add_point_terms(sys, patch, q, r, w, PLANE_POINT_MIX * self.coefficient / wd)
        else:  # Eq. (7) as printed
            e = add_point_terms(sys, patch, q, r, w, self.coefficient / wd)
        return e / wd


@dataclass(frozen=True)
class RigidityTerm(_Weighted):
    """Er of Eq. (2), divided by the total rigidity weight ``Σ w_kl(v)``."""

    name: ClassVar[str] = "rigidity"
    scale: ClassVar[float] = RIGIDITY_SCALE
    weight: float = 1.0

    def add(self, sys: System, it: Iterate) -> float:
        m = it.frame.model
        total = m.rig_w.sum()
        return add_rigidity(sys, m, it.frame.moments, it.R, it.c, self.coefficient / total) / total


@dataclass(frozen=True)
class BoneTerm(_Weighted):
    """Ebone of Eq. (11), divided by the total bone weight ``Σ w_k``."""

    name: ClassVar[str] = "bone"
    scale: ClassVar[float] = BONE_SCALE
    weight: float = 1.0

    def add(self, sys: System, it: Iterate) -> float:
        m = it.frame.model
        total = m.bone_w.sum()
        return add_bone(sys, m, it.R, it.c, it.X, self.coefficient / total) / total


@dataclass(frozen=True)
class ReverseTerm(_Weighted):
    """Not in the paper: each sampled template vertex (as its own patch predicts it) pulled
    to its nearest kept observation, with Cauchy weights ``1 / (1 + (d/scale)²)``, where
    their normals agree, they lie within ``cap`` metres and every camera sees the vertex
    (carving removes what a camera does not see). Value: the weighted sum of squared
    distances over the used vertices, divided by their number (metres²)."""

    name: ClassVar[str] = "reverse"
    weight: float = 10.0
    cap: float = 0.3
    cauchy_scale: float = 0.03

    def add(self, sys: System, it: Iterate) -> float:
        fd, m = it.frame, it.frame.model
        v = fd.reverse_sample
        d, j = fd.tree.query(it.V[v], k=1)
        j = j.astype(np.int64)
        ok = (np.einsum("ij,ij->i", it.N[v], fd.NY[j]) > fd.normal_cos) & (d < self.cap)
        ok &= in_view(it.V[v], fd.cameras)
        v, y = v[ok], fd.Y[j[ok]]
        if len(v) == 0:
            return 0.0
        patch = m.labels[v]
        q = it.V[v] - it.c[patch]  # R_k (v0 − c0_k)
        w = 1.0 / (1.0 + (d[ok] / self.cauchy_scale) ** 2)  # Cauchy IRLS weights
        e = add_point_terms(sys, patch, q, it.V[v] - y, w, self.coefficient / len(v))
        return e / len(v)


@dataclass(frozen=True)
class LengthTerm(_Weighted):
    """Not in the paper (which leaves bone lengths free): the mean squared change of each
    held joint pair's distance (every bone, the hip and shoulder spans) from the first
    tracked frame (:func:`~meshmocap.trackers.patch.solver.add_bone_lengths`)."""

    name: ClassVar[str] = "length"
    weight: float = 100.0

    def add(self, sys: System, it: Iterate) -> float:
        fd = it.frame
        n = len(fd.pairs)
        return add_bone_lengths(sys, it.X, fd.pairs, fd.lengths, self.coefficient / n) / max(n, 1)


@dataclass(frozen=True)
class SilhouetteTerm(_Weighted):
    """Not in the paper: silhouette pixels that no model vertex covers pull their nearest
    projected vertex onto their viewing ray, Cauchy-weighted with ``cauchy_scale``
    (:func:`~meshmocap.trackers.patch.terms.add_silhouette`); nothing where the frame has
    no cameras or silhouettes."""

    name: ClassVar[str] = "silhouette"
    weight: float = 10.0
    cauchy_scale: float = 0.05

    def add(self, sys: System, it: Iterate) -> float:
        fd, m = it.frame, it.frame.model
        if fd.rays is None:
            return 0.0
        s = fd.cover_sample
        lab = m.labels[s]
        qs = it.V[s] - it.c[lab]  # R_k (v0 − c0_k)
        value, _ = add_silhouette(
            sys,
            fd.rays,
            it.V[s],
            lab,
            qs,
            radius=fd.cover_radius,
            scale=self.cauchy_scale,
            weight=self.coefficient,
        )
        return value


@dataclass(frozen=True)
class TemporalTerm(_Weighted):
    """Not in the paper: the mean squared distance of the joints from their
    constant-velocity prediction (an acceleration penalty,
    :func:`~meshmocap.trackers.patch.terms.add_joint_prior`)."""

    name: ClassVar[str] = "temporal"
    weight: float = 1.0

    def add(self, sys: System, it: Iterate) -> float:
        K = len(it.X)
        return add_joint_prior(sys, it.X, it.frame.X_hat, self.coefficient / K) / K


def paper_terms(o: PatchOptions) -> tuple[Term, ...]:
    """The terms of Eq. (1) with ``o``'s weights: data (Eq. 7), rigidity (Eq. 2) and bone
    binding (Eq. 11)."""
    return (
        DataTerm(o.lambda_data, o.residual),
        RigidityTerm(o.lambda_rigid),
        BoneTerm(o.lambda_bone),
    )


def energy_terms(o: PatchOptions) -> tuple[Term, ...]:
    """The terms a tracker with options ``o`` minimises: Eq. (1)'s (:func:`paper_terms`),
    then each extension whose weight is above zero."""
    extensions: tuple[Term, ...] = (
        ReverseTerm(o.lambda_reverse, o.reverse_cap, o.reverse_scale),
        LengthTerm(o.lambda_length),
        SilhouetteTerm(o.lambda_silhouette, o.silhouette_scale),
        TemporalTerm(o.lambda_temporal),
    )
    return (*paper_terms(o), *(t for t in extensions if t.weight > 0))


def assemble(terms: tuple[Term, ...], sys: System, it: Iterate) -> dict[str, float]:
    """Add every term of ``terms`` at ``it`` to ``sys``; returns each term's value by name."""
    return {t.name: t.add(sys, it) for t in terms}


def total_energy(terms: tuple[Term, ...], values: dict[str, float]) -> float:
    """The energy: the sum over ``terms`` of coefficient × value (``values`` by name)."""
    return float(sum(t.coefficient * values[t.name] for t in terms))


def frame_masks(frame: CaptureFrame) -> list[np.ndarray]:
    """The frame's silhouettes, one per camera, or [] where the capture has none."""
    try:
        masks = frame.silhouettes
    except (OSError, AttributeError, ValueError):
        return []
    return masks if len(masks) == len(frame.cameras) else []
